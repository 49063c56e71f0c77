"""The fixed-step loop between two events: one generic loop, and fused kernels for the usual case.

Why it exists: behind a live bus the model must run far ahead of the wall
clock (goals: 100x real time for one servo, 20x for 253, one core; tools/bench_physics.py).  The
generic loop composes the one-job step functions (:mod:`.setpoint`,
:mod:`.controller`, :mod:`.motor`) and runs every configuration; it is the
reference.  It costs about 50 numpy calls per step, each about a
microsecond whatever N, most of them allocating a fresh array or converting a
Python float.  The fused kernels do the *same arithmetic in the same order*
(so their results are bitwise equal to the generic loop's; the tests compare
them) for what nearly every bus runs: joint mode with symmetric compliance,
or every servo in wheel mode (torque off, an external torque, an arm and a
blocked shaft included).  The numpy one works in place in preallocated
buffers with its constants already broadcast, the scalar one (one servo) on
plain floats with no function calls.  PID, asymmetric compliance and a mix
of wheel and joint mode run the generic loop.

So the step's arithmetic is written three times, on purpose: the step
functions return fresh values (clear, and the reference), the numpy kernel
needs every call in place, and the scalar one cannot afford a call (a
Python call costs about as much as its whole step).  What the three share
costs nothing a step: the rule that picks a kernel (:func:`fusable`,
:func:`step_kernel`), the constants derived once (:class:`StepConstants`),
and the one typed plan they all read (:class:`StepPlan`).

The numpy kernel also skips what provably repeats: every ``CHECK_EVERY``
steps, until it finds one, it compares the state after a step with the one
before; a reference resting on its goal is not stepped again, a state that
did not change at all (servos holding still) only accumulates heating, and
wheels whose speed did not change (cruising) only turn by the same angle and
heat.  References cruising at their speed limit (and the resting ones) are
not stepped either, for as many steps as the braking curve provably leaves
their velocity alone, counted when a step changed no velocity.  What it
found holds across calls, until the plan changes or someone rebinds a state
array the finding depends on.

The step is ordered for few calls.  Positions move first, with the
velocities the step starts from (the reference's chosen now by the setpoint
generator): ``x' = x + v dt`` for reference and shaft alike, then the
controller sees ``x'``, and the shaft's new speed follows from the torques
at ``x'`` (semi-implicit Euler, position first; the other symplectic order
than velocity first, and as stable).  Torques enter as speed changes per
step (``eta k dt / J`` folded into one constant), and dry friction is taken
implicitly (:func:`~firmware_model.motor.shaft_speed_step`), which needs no
direction test and no clamp.  One rewrite keeps every value: ``clip(x, lo,
hi)`` is ``minimum(maximum(x, lo), hi)``.

The model decodes its commands into a :class:`StepPlan` (typed, frozen:
what holds until a register, the supply or a load changes), and
:func:`step_kernel` picks the kernel for it once; a kernel advances the
model's :class:`ModelState` by ``count`` steps, and the model runs the
periodic events (heating, sampling) between calls.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from .backend import SCALAR
from .controller import PidGains, compliance_drive, pid_drive, symmetric_compliance_drive
from .motor import ARM_HORIZONTAL_RAD, DryFriction, arm_gravity_torque_nm, bridge_current_a, rail_current_a, shaft_speed_step
from .params import ServoParams
from .sensors import DelayLine
from .setpoint import setpoint_velocity
from .units import RAD_PER_POSITION_UNIT

__all__ = ["check_step", "StepConstants", "StepPlan", "ModelState", "PerServo", "Kernel", "step_kernel", "generic_steps",
           "fused_scalar_steps", "FusedNumpySteps", "fusable"]

#: While no fixed point is found, the numpy kernel looks for one after every this many steps.
CHECK_EVERY = 8

#: Per servo: a float for one servo on the scalar backend, else an array of shape (N,).
PerServo = float | np.ndarray
#: Per servo, a flag: a bool on the scalar backend, else a bool array of shape (N,).
PerServoFlag = bool | np.ndarray


def check_step(p: ServoParams, step_s: float) -> None:
    """Raise ``ValueError`` where ``p`` is too stiff for an explicit step of ``step_s`` (its losses taken per step)."""
    dt_j = step_s / p.total_inertia_kg_m2
    if p.viscous_friction_nm_s_rad * dt_j >= 1.0:
        # The viscous loss is taken explicitly, 1 - b dt / J per step: past 1 it would turn the shaft round.
        raise ValueError(
            f"viscous friction {p.viscous_friction_nm_s_rad} N m s/rad is too strong for a {step_s * 1e3:g} ms step "
            f"with inertia {p.total_inertia_kg_m2:.4g} kg m^2: it must stay below inertia / step = "
            f"{p.total_inertia_kg_m2 / step_s:.4g} N m s/rad (or use a shorter step)"
        )
    # k * k, not k ** 2: a float's power raises OverflowError past 1e308 where a product is inf (refused below)
    back_emf_per_step = p.gearbox_efficiency * p.torque_constant_nm_a * p.torque_constant_nm_a / p.winding_resistance_ohm * dt_j
    if back_emf_per_step >= 1.0:
        # The back-EMF's braking is taken explicitly as well (the current from the speed at the step's start):
        # past 1 a step would reverse the shaft, and the speed grows without bound (an overflow, not a servo).
        raise ValueError(
            f"the winding (R {p.winding_resistance_ohm:g} ohm, k {p.torque_constant_nm_a:g} N m/A) brakes the shaft "
            f"(inertia {p.total_inertia_kg_m2:.4g} kg m^2) too hard for a {step_s * 1e3:g} ms step: "
            f"eta k^2 / R x step / inertia = {back_emf_per_step:.3g} must stay below 1 "
            "(a larger resistance or inertia, or a shorter step)"
        )


@dataclass(frozen=True)
class StepConstants:
    """The parameters the step loop uses, derived once per model (SI units, output shaft).

    The setpoint curve's constants are derived here, once, rather than in each
    kernel: the scalar kernel would otherwise redo them on every call (one call
    a step behind a serving loop), and the numpy kernel and its cruise check
    must use the very same floats.
    """

    step_s: float
    accel_rad_s2: float
    unit_rad: float
    inv_unit: float
    #: Back-EMF current per rad/s, k / R.
    k_over_r: float
    #: Speed change per step per ampere, eta k step / J.
    eta_k_dv: float
    #: Step over total inertia, (rad/s) per N m.
    step_over_inertia: float
    friction: DryFriction
    #: ``1 - b step / J`` (None: no viscous friction).
    viscous_keep: float | None
    pid: bool
    gains: PidGains
    #: Share of the braking current the H-bridge passes (:func:`~firmware_model.motor.bridge_current_a`; 1: all).
    bridge_braking: float = 1.0
    #: The setpoint's largest speed change in a step, ``a dt``.
    adt_rad_s: float = field(init=False)
    #: ``(a dt / 2)**2``, ``2 a`` and ``a dt / 2``: the braking curve ``sqrt(q + 2 a d) - a dt / 2``
    #: (:func:`~firmware_model.setpoint.braking_speed`) with its products taken once.
    q_rad2_s2: float = field(init=False)
    two_a_rad_s2: float = field(init=False)
    half_adt_rad_s: float = field(init=False)
    #: ``1 / dt``: the speed that covers a distance in one step.
    inv_step_per_s: float = field(init=False)
    #: Static minus Coulomb friction's speed change per step, the Stribeck term's height.
    stribeck_dv_rad_s: float = field(init=False)

    def __post_init__(self) -> None:
        adt = self.accel_rad_s2 * self.step_s
        derived = dict(adt_rad_s=adt, q_rad2_s2=0.25 * adt * adt, two_a_rad_s2=2.0 * self.accel_rad_s2,
                       half_adt_rad_s=0.5 * adt, inv_step_per_s=1.0 / self.step_s,
                       stribeck_dv_rad_s=self.friction.static_dv_rad_s - self.friction.coulomb_dv_rad_s)
        for name, value in derived.items():
            object.__setattr__(self, name, value)  # frozen: set once here

    @classmethod
    def from_params(cls, p: ServoParams, step_s: float, controller: str, gains: PidGains) -> StepConstants:
        unit = float(RAD_PER_POSITION_UNIT)
        check_step(p, step_s)
        dt_j = step_s / p.total_inertia_kg_m2
        return cls(
            step_s=step_s, accel_rad_s2=p.max_acceleration_rad_s2, unit_rad=unit, inv_unit=1.0 / unit,
            k_over_r=p.torque_constant_nm_a / p.winding_resistance_ohm,
            eta_k_dv=(p.gearbox_efficiency * p.torque_constant_nm_a) * dt_j, step_over_inertia=dt_j,
            friction=DryFriction.per_step(p.static_friction_nm, p.coulomb_friction_nm, p.stribeck_velocity_rad_s, dt_j),
            viscous_keep=1.0 - p.viscous_friction_nm_s_rad * dt_j if p.viscous_friction_nm_s_rad else None,
            pid=controller == "pid", gains=gains,
            bridge_braking=p.bridge_braking_fraction,
        )


@dataclass(frozen=True, slots=True, eq=False)
class StepPlan:
    """The commands decoded for the step loop: what holds until a register, the supply or a load changes.

    Built by :class:`~firmware_model.physical.PhysicalModel` from the control
    table; per servo (see :data:`PerServo`) but for the flags, which pick the
    branches a kernel takes.  Frozen: a fused kernel broadcasts it once and
    keeps what it found about the state for as long as the plan lives.
    """

    enabled: PerServoFlag
    #: Wheel mode (both angle limits 0): an open-loop output instead of setpoint and position controller.
    wheel: PerServoFlag
    #: Goal Position clamped to the angle limits.
    goal_rad: PerServo
    #: The setpoint's speed limit (Moving Speed; 0 asks for the register's full scale).
    max_speed_rad_s: PerServo
    #: Wheel mode's output, a signed fraction of full drive (CCW positive): Moving Speed's ten bits over 1023.
    wheel_output: PerServo
    #: The compliance constants (:class:`~firmware_model.controller.CompliancePlan`): dead band in position
    #: units, drive per unit beyond it, punch and Torque Limit as fractions of full drive.
    cw_margin: PerServo
    ccw_margin: PerServo
    cw_gain: PerServo
    ccw_gain: PerServo
    punch: PerServo
    limit: PerServo
    #: 1.0 with torque on, 0.0 off (multiplies what an open bridge cancels).
    en: PerServo
    #: Supply over winding resistance, V / R: the current at full drive with the shaft still (0 with torque off).
    stall_current_a: PerServo
    any_wheel: bool
    any_joint: bool
    any_disabled: bool
    #: Run-time loads present (an arm's gravity, an external torque, a held shaft), read from the state.
    any_arm: bool
    any_ext: bool
    any_blocked: bool
    #: The same margin and slope both ways (the fused kernels' compliance).
    symmetric: bool
    #: Half the gear play, or None (no play).
    half_play_rad: float | None
    #: The sensing delay's line of readings, or None.
    history: DelayLine | None


@dataclass(slots=True, eq=False)
class ModelState:
    """The state of :class:`~firmware_model.physical.PhysicalModel`, per servo (see :data:`PerServo`).

    A kernel advances the first nine (the step's state; with gear play the
    generic loop also ``out``); the model's periodic events update the next
    five; the run-time loads are inputs the model sets.
    Not frozen: the generic and scalar kernels bind new values, the numpy
    kernel writes its own arrays in place (see :class:`FusedNumpySteps`).
    """

    #: Shaft (motor side) angle and speed; the setpoint's reference and its velocity.
    angle: PerServo
    speed: PerServo
    ref: PerServo
    ref_vel: PerServo
    #: Controller output (fraction of full drive, signed) and the drive it asked for before the limit.
    drive: PerServo
    demand: PerServo
    #: The PID controller's integral and last error (rad).
    integral: PerServo
    prev_error: PerServo
    #: Squared winding currents summed since the last thermal event, A**2.
    current_sq_sum: PerServo
    temperature: PerServo
    overload_timer: PerServo
    #: Angle at the last sample, and Present Speed (rad/s) and drive held from it.
    sample_angle: PerServo
    held_speed: PerServo
    held_drive: PerServo
    #: Run-time loads: an external torque, an arm's weight moment (N m), 1.0 where the shaft is held.
    ext_nm: PerServo
    weight_nm: PerServo
    blocked: PerServo
    #: The output's angle, within half the gear play of ``angle`` (with play).
    out: PerServo


#: A kernel: ``kernel(state, count)`` advances ``state`` by ``count`` steps of its plan.
Kernel = Callable[[ModelState, int], None]


def fusable(k: StepConstants, plan: StepPlan) -> bool:
    """Whether the fused kernels cover this configuration (else the generic loop runs).

    Gear play and a sensing delay need a state the kernels do not keep (the
    output's angle, each step's reading), so they run the generic loop; the
    other effects of :class:`~firmware_model.params.ServoEffects` are plan
    data the kernels already take (a lower limit, a wider margin, an arm).
    """
    if plan.half_play_rad is not None or plan.history is not None:
        return False
    if plan.any_wheel:
        return not plan.any_joint  # all in wheel mode: no position controller at all
    return not k.pid and plan.symmetric


def step_kernel(xp, plan: StepPlan, k: StepConstants, s: ModelState, fused: bool = True) -> Kernel:
    """The kernel that runs ``plan`` on backend ``xp``: a fused one where it covers it, else the generic loop.

    ``fused=False`` always gives the generic loop (the reference the tests compare with).
    """
    if not (fused and fusable(k, plan)):
        return partial(generic_steps, xp, plan, k)
    if xp is SCALAR:
        return partial(fused_scalar_steps, plan, k)
    return FusedNumpySteps(plan, k, s, len(s.angle))


def generic_steps(xp, plan: StepPlan, k: StepConstants, s: ModelState, count: int) -> None:
    """``count`` steps of any configuration: setpoint, positions, controller, motor, shaft speed.

    The state lives in locals during the loop and is written back at the end.
    """
    a, dt, unit, inv_unit = k.accel_rad_s2, k.step_s, k.unit_rad, k.inv_unit
    k_r, eta_k_dv, friction, keep = k.k_over_r, k.eta_k_dv, k.friction, k.viscous_keep
    bridge_braking = k.bridge_braking
    pid, gains, symmetric = k.pid, k.gains, plan.symmetric
    any_joint, any_wheel, any_disabled = plan.any_joint, plan.any_wheel, plan.any_disabled
    mixed = any_joint and any_wheel
    goal, max_speed, enabled, wheel, en = plan.goal_rad, plan.max_speed_rad_s, plan.enabled, plan.wheel, plan.en
    stall_a = plan.stall_current_a
    cw_margin, ccw_margin, cw_gain, ccw_gain, punch, limit = (plan.cw_margin, plan.ccw_margin, plan.cw_gain,
                                                              plan.ccw_gain, plan.punch, plan.limit)
    wheel_output = plan.wheel_output
    angle, speed, ref, ref_vel = s.angle, s.speed, s.ref, s.ref_vel
    drive, demand, integral, prev_error, i2_sum = s.drive, s.demand, s.integral, s.prev_error, s.current_sq_sum
    any_ext, any_arm = plan.any_ext, plan.any_arm
    overhaul = any_ext or any_arm  # a load that can turn a shaft past its rail (motor.rail_current_a)
    ext_dv = s.ext_nm * k.step_over_inertia if any_ext else None
    weight_dv = s.weight_nm * k.step_over_inertia if any_arm else None
    free, any_blocked = 1.0 - s.blocked, plan.any_blocked
    # Gear play: the output (where the pot sits, what the controller sees) follows the motor side only
    # once the slack is taken up; a sensing delay keeps each step's reading.
    half_play, history = plan.half_play_rad, plan.history
    out = seen = s.out if half_play is not None else None
    for _ in range(count):
        # Positions first, with the velocities the step starts from (the reference's is chosen now).
        if any_joint:
            ref_vel = setpoint_velocity(xp, ref, ref_vel, goal, max_speed, a, dt)
            if any_disabled:
                ref_vel = ref_vel * en
            ref = ref + ref_vel * dt
        angle = angle + speed * dt
        if half_play is None:
            seen = angle
        else:
            out = seen = xp.minimum(xp.maximum(out, angle - half_play), angle + half_play)
        if history is not None:
            history.push(seen)
        if any_joint:
            if any_disabled:  # torque off: the reference follows the shaft (as the pot reads it)
                ref = xp.where(enabled, ref, seen)
            error = ref * inv_unit - xp.rint(seen * inv_unit)
            if pid:
                error = error * unit
                drive, demand, integral = pid_drive(xp, error, integral, prev_error, dt, gains, limit)
                prev_error = error
            elif symmetric:
                drive, demand = symmetric_compliance_drive(xp, error, ccw_margin, ccw_gain, punch, limit)
            else:
                drive, demand = compliance_drive(xp, error, cw_margin, ccw_margin, cw_gain, ccw_gain, punch, limit)
        if any_wheel:  # the output Moving Speed asks for, within Torque Limit (no speed loop: the e-manual's)
            wheel_drive = xp.minimum(xp.maximum(wheel_output, -limit), limit)
            drive = xp.where(wheel, wheel_drive, drive) if mixed else wheel_drive
            demand = xp.where(wheel, xp.abs(wheel_output), demand) if mixed else xp.abs(wheel_output)
        if any_disabled:  # open bridge: no drive, no current (Present Load reads 0)
            drive = drive * en
            current = (drive * stall_a - k_r * speed) * en
        else:
            current = drive * stall_a - k_r * speed
        if bridge_braking != 1.0:  # the bridge passes current against the drive only in part (or not at all)
            if overhaul:  # but the diodes clamp the back-EMF at the supply, which only a load can drive a shaft past
                rail = rail_current_a(xp, k_r * speed, stall_a)
                current = bridge_current_a(current, drive, bridge_braking, rail * en if any_disabled else rail)
            else:
                current = bridge_current_a(current, drive, bridge_braking)
        applied_dv = current * eta_k_dv
        if any_ext:
            applied_dv = applied_dv + ext_dv
        if any_arm:
            applied_dv = applied_dv + arm_gravity_torque_nm(xp, angle, weight_dv)
        speed = shaft_speed_step(xp, speed, applied_dv, friction, keep)
        if any_blocked:  # a held shaft does not turn; the motor still draws current
            speed = speed * free
        i2_sum = i2_sum + current * current
    s.angle, s.speed, s.ref, s.ref_vel = angle, speed, ref, ref_vel
    s.drive, s.demand, s.integral, s.prev_error, s.current_sq_sum = drive, demand, integral, prev_error, i2_sum
    if half_play is not None:
        s.out = out


def fused_scalar_steps(plan: StepPlan, k: StepConstants, s: ModelState, count: int) -> None:
    """:func:`generic_steps` for one servo (wheel mode, or joint mode with symmetric compliance), inlined on floats.

    Inlined on purpose rather than sharing the step functions or the numpy
    kernel's pieces: a Python function call costs about as much as the whole
    step's float arithmetic, and behind a serving loop this runs one step a
    call, so even the loads' speed changes are set up here and not in a
    helper shared with the other kernels.  The comments name the function
    each part inlines; the tests hold it to them bit for bit.
    """
    sqrt, exp, cos, copysign = math.sqrt, math.exp, math.cos, math.copysign
    dt, inv_unit = k.step_s, k.inv_unit
    adt, q, two_a, half_adt, inv_dt = k.adt_rad_s, k.q_rad2_s2, k.two_a_rad_s2, k.half_adt_rad_s, k.inv_step_per_s
    k_r, eta_k_dv, keep = k.k_over_r, k.eta_k_dv, k.viscous_keep
    bridge = k.bridge_braking  # not "braking": that name is the setpoint's braking speed below
    coast, against = bridge == 0.0, 1.0 - bridge
    f = k.friction
    tc, dts, strib = f.coulomb_dv_rad_s, k.stribeck_dv_rad_s, f.stribeck_coef_s2_rad2
    goal, max_speed, enabled, en, stall_a = plan.goal_rad, plan.max_speed_rad_s, plan.enabled, plan.en, plan.stall_current_a
    wheel, wheel_output = plan.wheel, plan.wheel_output
    margin, gain, punch, limit = plan.ccw_margin, plan.ccw_gain, plan.punch, plan.limit
    ext_dv = s.ext_nm * k.step_over_inertia if plan.any_ext else 0.0
    weight_dv = s.weight_nm * k.step_over_inertia if plan.any_arm else 0.0
    overhaul = plan.any_ext or plan.any_arm  # as generic_steps
    blocked = plan.any_blocked
    angle, speed, ref, ref_vel, i2_sum = s.angle, s.speed, s.ref, s.ref_vel, s.current_sq_sum
    drive = demand = 0.0
    for _ in range(count):
        if wheel:  # the output Moving Speed asks for, within Torque Limit
            angle = angle + speed * dt
            drive, demand = min(max(wheel_output, -limit), limit) * en, abs(wheel_output)
        else:
            error = goal - ref  # setpoint.setpoint_velocity
            d = abs(error)
            braking = min(sqrt(q + two_a * d) - half_adt, d * inv_dt)
            ref_vel = ref_vel + min(max(copysign(min(max_speed, braking), error) - ref_vel, -adt), adt)
            if not enabled:
                ref_vel = ref_vel * en
            ref = ref + ref_vel * dt
            angle = angle + speed * dt
            if not enabled:
                ref = angle
            error = ref * inv_unit - round(angle * inv_unit)  # controller.symmetric_compliance_drive
            beyond = abs(error) - margin
            demand = (punch + beyond * gain) * (beyond > 0)
            drive = copysign(min(demand, limit), error) * en
        current = drive * stall_a - k_r * speed
        if not enabled:
            current = current * en
        if bridge != 1.0:  # motor.bridge_current_a with motor.rail_current_a (zero with torque off: the bridge is open)
            passes = current * drive > 0
            if overhaul and enabled and abs(emf := k_r * speed) > stall_a:  # past the rail (a load did it): else a zero
                rail = -copysign(abs(emf) - stall_a, emf)
                if coast:
                    current = current * passes + rail * (1.0 - passes)
                else:
                    current = current * (bridge + against * passes) + rail * (against * (1.0 - passes))
            elif coast:
                current = current * passes
            else:
                current = current * (bridge + against * passes)
        applied = current * eta_k_dv
        if ext_dv:
            applied = applied + ext_dv
        if weight_dv:
            applied = applied + -weight_dv * cos(angle - ARM_HORIZONTAL_RAD)
        free = (speed if keep is None else speed * keep) + applied  # motor.shaft_speed_step
        dry = tc + dts * exp(speed * speed * strib)
        speed = free - copysign(min(abs(free), dry), free)
        if blocked:
            speed = 0.0
        i2_sum = i2_sum + current * current
    if count:
        s.angle, s.speed, s.ref, s.ref_vel = angle, speed, ref, ref_vel
        s.drive, s.demand, s.current_sq_sum = drive, demand, i2_sum


@dataclass(frozen=True, slots=True, eq=False)
class _NumpyConstants:
    """Every constant of a numpy step, broadcast once per plan.

    Shape (N,), or (2, N) where one call acts on two rows of the state; a
    ufunc then takes them as they are, without converting a Python float or
    broadcasting on every call.  None where the plan has no such term (the
    step then skips its calls).
    """

    # The setpoint (StepConstants' derived constants).
    q_rad2_s2: np.ndarray
    two_a_rad_s2: np.ndarray
    half_adt_rad_s: np.ndarray
    inv_step_per_s: np.ndarray
    adt_rad_s: np.ndarray
    neg_adt_rad_s: np.ndarray
    step_s: np.ndarray
    #: (2, N): the step for the reference's velocity and the shaft's speed rows at once.
    step2_s: np.ndarray
    #: (2, N): position units per radian, for the reference and angle rows at once.
    units_per_rad2: np.ndarray
    #: Zeros: ``heaviside(x, zero)`` is ``(x > 0)`` as 0.0 / 1.0; ones.
    zero: np.ndarray
    one: np.ndarray
    #: The drive's lower bound, minus Torque Limit.
    neg_limit: np.ndarray
    #: Where torque is off (None: on everywhere).
    disabled: np.ndarray | None
    #: (2, N): k / R (A per rad/s) and V / R (A), against the speed and drive rows: back-EMF and drive currents.
    emf_stall_a: np.ndarray
    #: Speed change per step per ampere.
    eta_k_dv: np.ndarray
    #: The bridge's share of braking current (motor.bridge_current_a): None passes it all, ``zero`` none.
    bridge_share: np.ndarray | None
    bridge_against: np.ndarray
    #: The loads' speed changes per step (external torque; minus the arm's weight moment), None without.
    ext_dv_rad_s: np.ndarray | None
    neg_weight_dv_rad_s: np.ndarray | None
    arm_at_rad: np.ndarray
    #: 0.0 where the shaft is held, 1.0 where free (None: none held).
    free: np.ndarray | None
    # Friction (motor.shaft_speed_step): viscous keep (None: none), Stribeck coefficient and height, Coulomb.
    keep: np.ndarray | None
    strib_s2_rad2: np.ndarray
    stribeck_dv_rad_s: np.ndarray
    coulomb_dv_rad_s: np.ndarray

    @classmethod
    def broadcast(cls, plan: StepPlan, k: StepConstants, s: ModelState, n: int) -> _NumpyConstants:
        full = lambda value: np.full(n, float(value))  # noqa: E731
        zero = full(0.0)
        return cls(
            q_rad2_s2=full(k.q_rad2_s2), two_a_rad_s2=full(k.two_a_rad_s2), half_adt_rad_s=full(k.half_adt_rad_s),
            inv_step_per_s=full(k.inv_step_per_s), adt_rad_s=full(k.adt_rad_s), neg_adt_rad_s=full(-k.adt_rad_s),
            step_s=full(k.step_s), step2_s=np.full((2, n), k.step_s), units_per_rad2=np.full((2, n), k.inv_unit), zero=zero,
            one=full(1.0), neg_limit=-plan.limit,
            disabled=~np.asarray(plan.enabled, dtype=bool) if plan.any_disabled else None,
            emf_stall_a=np.stack([full(k.k_over_r), np.asarray(plan.stall_current_a, dtype=float)]),
            eta_k_dv=full(k.eta_k_dv),
            bridge_share=(None if k.bridge_braking == 1.0 else zero if k.bridge_braking == 0.0
                          else full(k.bridge_braking)),
            bridge_against=full(1.0 - k.bridge_braking),
            ext_dv_rad_s=s.ext_nm * k.step_over_inertia if plan.any_ext else None,
            neg_weight_dv_rad_s=-(s.weight_nm * k.step_over_inertia) if plan.any_arm else None,
            arm_at_rad=full(ARM_HORIZONTAL_RAD), free=1.0 - s.blocked if plan.any_blocked else None,
            keep=None if k.viscous_keep is None else full(k.viscous_keep),
            strib_s2_rad2=full(k.friction.stribeck_coef_s2_rad2), stribeck_dv_rad_s=full(k.stribeck_dv_rad_s),
            coulomb_dv_rad_s=full(k.friction.coulomb_dv_rad_s),
        )


@dataclass(frozen=True, slots=True, eq=False)
class _Scratch:
    """The numpy step's buffers, written in place each step (never rebound, hence frozen)."""

    #: Shape (N,): the setpoint's error (e), distances and margins (d), two temporaries (t, u), the
    #: controller's error in units (err) and the speed change, then the free speed (z).
    e: np.ndarray
    d: np.ndarray
    t: np.ndarray
    u: np.ndarray
    err: np.ndarray
    z: np.ndarray
    #: One step's squared currents, kept while a fixed point repeats it.
    i2_step: np.ndarray
    #: (2, N): reference and angle in position units; the reference's and the shaft's moves in a step
    #: (the shaft's row is what a cruising wheel turns each step); back-EMF and drive currents.
    in_units: np.ndarray
    moves: np.ndarray
    products: np.ndarray

    @classmethod
    def empty(cls, n: int) -> _Scratch:
        return cls(**{name: np.empty(n) for name in ("e", "d", "t", "u", "err", "z", "i2_step")},
                   **{name: np.empty((2, n)) for name in ("in_units", "moves", "products")})


#: What a joint-mode step does with the reference: the setpoint moves it, it keeps its velocity
#: (cruising), or it rests (only the shaft moves).  See FusedNumpySteps.__call__.
_SETPOINT, _REF_CRUISING, _REF_RESTING = range(3)


def _numpy_steps(c: _NumpyConstants, p: StepPlan, buf: _Scratch, ref_angle: np.ndarray, vel_speed_drive: np.ndarray,
                 demand: np.ndarray) -> Callable[[int, list, int, int], None]:
    """The numpy step itself, bound once per plan to its constants, buffers and state arrays.

    Returns ``steps(kind, heat_rows, first, stop)``: steps ``first .. stop - 1``
    of a call, the reference's ``kind`` (ignored in wheel mode) the same
    for all, each step's currents left in ``heat_rows[step]``.  A closure so
    that the step reads its many operands as fast as locals without loading
    them again for each run of steps (a run is often 1 to 7 steps).
    """
    sub, add, mul, absolute, sqrt, rint, exp, cos = np.subtract, np.add, np.multiply, np.abs, np.sqrt, np.rint, np.exp, np.cos
    minimum, copysign, heaviside, copyto, negative = np.minimum, np.copysign, np.heaviside, np.copyto, np.negative
    e, d, t, u, err, z, in_units, moves, products = buf.e, buf.d, buf.t, buf.u, buf.err, buf.z, buf.in_units, buf.moves, buf.products
    goal, max_speed, margin, gain, punch, limit, en = p.goal_rad, p.max_speed_rad_s, p.ccw_margin, p.ccw_gain, p.punch, p.limit, p.en
    wheel_output, wheel = p.wheel_output, p.any_wheel  # fusable(): all in wheel mode or none
    q, two_a, half_adt, inv_dt = c.q_rad2_s2, c.two_a_rad_s2, c.half_adt_rad_s, c.inv_step_per_s
    neg_adt, adt, dt, dt2, zero, units_per_rad2 = c.neg_adt_rad_s, c.adt_rad_s, c.step_s, c.step2_s, c.zero, c.units_per_rad2
    neg_limit, disabled = c.neg_limit, c.disabled
    emf_stall, eta_k_dv, bridge_share, bridge_against = c.emf_stall_a, c.eta_k_dv, c.bridge_share, c.bridge_against
    one, maximum = c.one, np.maximum
    ext_dv, neg_weight_dv, arm_at, free = c.ext_dv_rad_s, c.neg_weight_dv_rad_s, c.arm_at_rad, c.free
    keep, strib, dts, tc = c.keep, c.strib_s2_rad2, c.stribeck_dv_rad_s, c.coulomb_dv_rad_s
    # Row views made once: indexing a row costs about as much as a small ufunc call.
    ref, angle = ref_angle
    vel, speed, drive = vel_speed_drive
    vel_speed, speed_drive = vel_speed_drive[:2], vel_speed_drive[1:]
    ref_units, angle_units = in_units
    emf_product, drive_product = products
    stall_row = emf_stall[1]
    overhaul = ext_dv is not None or neg_weight_dv is not None  # as generic_steps
    step_angle = moves[1]

    def steps(kind: int, heat_rows: list, first: int, stop: int) -> None:
        for row in range(first, stop):
            cur = heat_rows[row]
            if wheel:  # the generic loop's open-loop output
                mul(speed, dt, step_angle)
                add(angle, step_angle, angle)
                _clip(wheel_output, neg_limit, limit, drive)
                absolute(wheel_output, demand)
            else:
                if kind == _REF_RESTING:  # only the shaft moves
                    mul(speed, dt, step_angle)
                    add(angle, step_angle, angle)
                elif kind == _REF_CRUISING:  # every reference keeps its velocity: both move
                    mul(vel_speed, dt2, moves)
                    add(ref_angle, moves, ref_angle)
                else:  # setpoint.setpoint_velocity, then reference and shaft move together
                    sub(goal, ref, e)
                    absolute(e, d)
                    mul(d, two_a, t)
                    add(t, q, t)
                    sqrt(t, t)
                    sub(t, half_adt, t)
                    mul(d, inv_dt, u)
                    minimum(t, u, out=t)
                    minimum(max_speed, t, out=t)
                    copysign(t, e, t)
                    sub(t, vel, t)
                    _clip(t, neg_adt, adt, t)
                    add(vel, t, vel)
                    if disabled is not None:
                        mul(vel, en, vel)
                    mul(vel_speed, dt2, moves)
                    add(ref_angle, moves, ref_angle)
                if disabled is not None:
                    copyto(ref, angle, where=disabled)
                # controller.symmetric_compliance_drive, on the error in units
                mul(ref_angle, units_per_rad2, in_units)
                rint(angle_units, t)
                sub(ref_units, t, err)
                absolute(err, d)
                sub(d, margin, d)
                mul(d, gain, demand)
                add(punch, demand, demand)
                heaviside(d, zero, t)  # (d > 0) as 0.0 / 1.0
                mul(demand, t, demand)
                minimum(demand, limit, out=drive)
                copysign(drive, err, drive)
            # motor current; an open bridge (torque off) carries none
            if disabled is not None:
                mul(drive, en, drive)
            mul(speed_drive, emf_stall, products)  # (k/R) speed and drive V/R
            sub(drive_product, emf_product, cur)
            if disabled is not None:
                mul(cur, en, cur)
            if bridge_share is not None:  # motor.bridge_current_a: (current * drive > 0) as 0.0 / 1.0
                mul(cur, drive, t)
                heaviside(t, zero, t)
                # motor.rail_current_a, on the share the bridge blocks (zero with torque off: the bridge is open),
                # as generic_steps: with a load on that can turn a shaft past its rail
                if overhaul:
                    absolute(emf_product, u)
                    sub(u, stall_row, u)
                    maximum(u, zero, out=u)
                    copysign(u, emf_product, u)
                    negative(u, u)
                    if disabled is not None:
                        mul(u, en, u)
                    sub(one, t, d)
                    if bridge_share is not zero:
                        mul(bridge_against, d, d)
                if bridge_share is not zero:
                    mul(t, bridge_against, t)
                    add(bridge_share, t, t)
                mul(cur, t, cur)
                if overhaul:
                    mul(u, d, u)
                    add(cur, u, cur)
            mul(cur, eta_k_dv, z)
            if ext_dv is not None:
                add(z, ext_dv, z)
            if neg_weight_dv is not None:  # motor.arm_gravity_torque_nm
                sub(angle, arm_at, t)
                cos(t, t)
                mul(neg_weight_dv, t, t)
                add(z, t, z)
            # motor.shaft_speed_step: the free speed, then dry friction (at the starting speed)
            if keep is None:
                add(speed, z, z)
            else:
                mul(speed, keep, t)
                add(t, z, z)
            mul(speed, speed, t)
            mul(t, strib, t)
            exp(t, t)
            mul(dts, t, t)
            add(tc, t, t)
            negative(t, u)  # copysign(minimum(|z|, F), z) is clip(z, -F, F)
            _clip(z, u, t, u)
            sub(z, u, speed)
            if free is not None:  # a held shaft does not turn
                mul(speed, free, speed)

    return steps


class FusedNumpySteps:
    """:func:`generic_steps` for N servos, all in wheel mode or all in joint mode with symmetric compliance, in place.

    Built once per plan (the commands' decoding): it broadcasts every constant
    to shape (N,) (:class:`_NumpyConstants`) and owns the scratch buffers, so
    a step is 38 numpy calls (39 with viscous friction), none allocating (25
    once the references rest or cruise), and 2 to 4 more a call.  It writes
    the state arrays of the :class:`ModelState` in place.  Work is done in
    bulk where rows of one array allow it: the reference and the shaft move
    in one pair of calls, the position error of both is scaled in one call,
    the motor's two products (back-EMF and drive) take one call, and the
    heating's squared currents are kept one row per step and summed once per
    call (a running sum over the rows adds them in step order, so the sum is
    the generic loop's to the bit).  Dry friction's ``copysign(minimum(|z|,
    F), z)`` is computed as ``clip(z, -F, F)``, the same values in one call
    fewer.

    A call is split in named parts: :meth:`_take_in` (state arrays a caller
    rebound), runs of steps of one kind (:func:`_numpy_steps`, the step
    itself), the fixed-point checks between them (:meth:`_snapshot`,
    :meth:`_check_fixed_points`, :meth:`_reference_cruise_steps`), the
    shortcut once one is found (:meth:`_repeat_fixed_point`) and the heating
    (:meth:`_add_heat`).
    """

    # Slots: the scheduling in __call__ reads and writes the findings once per run of steps.
    __slots__ = ("c", "plan", "buf", "wheel", "disabled", "ref_angle", "vel_speed_drive", "state", "n", "heat",
                 "heat_rows", "_steps", "ref_resting", "at_rest", "cruising", "ref_cruise_left", "safe_distance",
                 "can_cruise", "check_in", "rest_steps", "cruise_steps", "ref_cruise_steps")

    def __init__(self, plan: StepPlan, k: StepConstants, s: ModelState, n: int) -> None:
        self.c = _NumpyConstants.broadcast(plan, k, s, n)
        self.plan = plan
        self.buf = _Scratch.empty(n)
        #: Every servo in wheel mode (fusable() allows no mix): a speed loop instead of setpoint and compliance.
        self.wheel = plan.any_wheel
        self.disabled = self.c.disabled
        # The state the kernel updates in place.  Reference and angle are the two rows of one
        # array, and the reference's velocity, the shaft's speed and the drive the three of
        # another, so one pair of calls moves reference and shaft (velocity and speed rows) and
        # one call gives the motor's two products (speed and drive rows).  A caller that rebinds
        # a state array (an event, a new plan) is copied in at the next call; one that keeps a
        # state array must copy it.
        self.ref_angle, self.vel_speed_drive = np.empty((2, n)), np.empty((3, n))
        self.state = {"ref": self.ref_angle[0], "angle": self.ref_angle[1], "ref_vel": self.vel_speed_drive[0],
                      "speed": self.vel_speed_drive[1], "drive": self.vel_speed_drive[2],
                      **{name: np.empty(n) for name in ("demand", "current_sq_sum")}}
        self.n = n
        self._grow_heat(16)
        self._steps = _numpy_steps(self.c, plan, self.buf, self.ref_angle, self.vel_speed_drive, self.state["demand"])
        # Fixed points found by a check after a step (see __call__); they hold while the plan (this
        # object) lives and nobody rebinds the state arrays they depend on.
        self.ref_resting = self.at_rest = self.cruising = False
        #: Steps for which every reference provably keeps its velocity (see _reference_cruise_steps).
        self.ref_cruise_left = 0
        self.safe_distance = None if plan.any_wheel else _cruise_safe_distance(k, plan.max_speed_rad_s)
        #: Cruising applies when the speed update depends on the speed alone: all in wheel mode
        #: (no position controller), no arm (gravity depends on the angle), no blocked shaft.
        self.can_cruise = plan.any_wheel and not plan.any_arm and not plan.any_blocked
        #: Steps to take before the next check (0: check after the next step).
        self.check_in = 0
        #: Steps taken by each shortcut (for tests and benchmarks: that they run at all).
        self.rest_steps = self.cruise_steps = self.ref_cruise_steps = 0

    def __call__(self, s: ModelState, count: int) -> None:
        """``count`` steps: runs of steps of one kind, a fixed-point check after every ``CHECK_EVERY``th.

        Fixed points are checked after a step rather than assumed (every
        ``CHECK_EVERY`` steps while none is found): a step that leaves the
        reference (and its velocity) bit for bit unchanged leaves it so for
        good; one that leaves the whole state unchanged (reference, angle,
        speed: a servo holding still) repeats itself exactly, so later steps
        only heat; and in wheel mode, where the speed update depends on the
        speed alone, one that leaves the speed unchanged is cruising: later
        steps only turn the shaft by the same angle and heat.
        """
        self._take_in(s)
        if self.at_rest or self.cruising:  # found in an earlier call: serving loops call one step at a time
            self._repeat_fixed_point(count)
            return
        if count > len(self.heat_rows) - 1:
            self._grow_heat(count)
        steps, heat_rows, done = self._steps, self.heat_rows, 0
        while done < count:
            if self.at_rest or self.cruising:
                self._add_heat(done)
                self._repeat_fixed_point(count - done)
                return
            check = self.check_in <= 0
            run = 1 if check else min(self.check_in, count - done)
            kind = _REF_RESTING if self.ref_resting else _REF_CRUISING if self.ref_cruise_left else _SETPOINT
            if kind == _REF_CRUISING:
                run = min(run, self.ref_cruise_left)
                self.ref_cruise_left -= run
                self.ref_cruise_steps += run
            if check:
                before = self._snapshot()
                steps(kind, heat_rows, done + 1, done + 2)
                self._check_fixed_points(before)
            else:
                self.check_in -= run
                steps(kind, heat_rows, done + 1, done + 1 + run)
            done += run
        if done:
            self._add_heat(done)

    def _take_in(self, s: ModelState) -> None:
        """Copy in the state arrays a caller rebound since the last call, and forget what they invalidate."""
        for name, own in self.state.items():
            current = getattr(s, name)
            if current is not own:  # rebound since the last call: take the new values in
                np.copyto(own, current)
                setattr(s, name, own)
                if name in ("ref", "ref_vel", "angle", "speed"):
                    self.ref_resting = self.at_rest = False
                    self.ref_cruise_left = 0
                    if name == "speed":
                        self.cruising = False

    def _snapshot(self) -> tuple[bytes, bytes, bytes, bytes]:
        """The state a step may change (reference, its velocity, angle, speed), to compare after the step."""
        state = self.state
        return state["ref"].tobytes(), state["ref_vel"].tobytes(), state["angle"].tobytes(), state["speed"].tobytes()

    def _check_fixed_points(self, before: tuple[bytes, bytes, bytes, bytes]) -> None:
        """After a step from ``before``: which fixed point it found, if any (see :meth:`__call__`)."""
        state = self.state
        ref, vel = state["ref"], state["ref_vel"]
        same_ref = ref.tobytes() == before[0] and vel.tobytes() == before[1]
        same_speed = state["speed"].tobytes() == before[3]
        self.at_rest = same_ref and same_speed and state["angle"].tobytes() == before[2]
        self.cruising = same_speed and self.can_cruise
        ref_resting = self.ref_resting = same_ref and self.disabled is None  # else it follows a free shaft
        self.check_in = 0 if self.at_rest or self.cruising else CHECK_EVERY - 1
        if (not (self.wheel or ref_resting or self.ref_cruise_left) and self.disabled is None
                and vel.tobytes() == before[1]):
            self.ref_cruise_left = self._reference_cruise_steps(ref, vel)

    def _grow_heat(self, rows: int) -> None:
        """Room for ``rows`` steps' currents (row 0 takes the running sum when they are added up)."""
        self.heat = np.empty((rows + 1, self.n))
        self.heat_rows = list(self.heat)

    def _add_heat(self, rows: int) -> None:
        """Add the squares of the currents in heat rows 1..rows to the state's sum, in step order.

        While a fixed point holds, the last square is what every later step adds.
        """
        heat, i2_sum = self.heat, self.state["current_sq_sum"]
        block = heat[1:rows + 1]
        np.multiply(block, block, block)
        if self.at_rest or self.cruising:
            np.copyto(self.buf.i2_step, heat[rows])
        if rows == 1:  # one step a call (a serving loop): add it as the generic loop does
            np.add(i2_sum, heat[1], i2_sum)
            return
        np.copyto(heat[0], i2_sum)
        used = heat[:rows + 1]
        np.add.accumulate(used, axis=0, out=used)  # strictly in row order (a reduce may pair them up)
        np.copyto(i2_sum, heat[rows])

    def _reference_cruise_steps(self, ref: np.ndarray, vel: np.ndarray) -> int:
        """How many coming steps provably leave every reference's velocity as it is (0: none).

        Called after a step that changed no velocity.  A reference resting on
        its goal stays (the step is a map of reference and velocity alone, and
        it just mapped them onto themselves).  One cruising toward its goal at
        exactly its speed limit keeps that velocity while the braking curve
        allows more than the limit, that is while it is at least
        ``safe_distance`` from the goal (:func:`_cruise_safe_distance`); each
        step brings it ``|v| dt`` closer, plus rounding, allowed for, and one
        step is kept in hand.  Any other reference (accelerating, braking)
        gives 0.
        """
        p = self.plan
        error = p.goal_rad - ref
        distance = np.abs(error)
        resting = (distance == 0.0) & (vel == 0.0)
        cruising = np.copysign(p.max_speed_rad_s, error) == vel
        # Each step brings it |v| dt closer, give or take the rounding of ref + v dt: at most half
        # the spacing of floats as large as the larger of reference and goal (it moves between them).
        rounding = np.spacing(np.maximum(np.abs(ref), np.abs(p.goal_rad))) + 1e-12
        per_step = np.abs(vel) * (self.c.step_s * (1.0 + 1e-9)) + rounding
        room = np.where(cruising, np.floor((distance - self.safe_distance) / per_step), 0.0)
        steps = np.where(resting, np.inf, np.maximum(room, 0.0))
        least = float(steps.min())
        return 0 if least == np.inf else int(least)

    def _repeat_fixed_point(self, count: int) -> None:
        """``count`` steps of a fixed point found before: only heating, and for cruising wheels the same turn."""
        add, i2_sum, i2_step = np.add, self.state["current_sq_sum"], self.buf.i2_step
        if self.at_rest:
            self.rest_steps += count
            for _ in range(count):
                add(i2_sum, i2_step, i2_sum)
        else:
            self.cruise_steps += count
            angle, step_angle = self.state["angle"], self.buf.moves[1]
            for _ in range(count):
                add(angle, step_angle, angle)
                add(i2_sum, i2_step, i2_sum)


def _cruise_safe_distance(k: StepConstants, max_speed: np.ndarray) -> np.ndarray:
    """Per servo, a distance to the goal from which on the setpoint's limit is ``max_speed`` itself.

    From ``sqrt(q + 2 a d) - a dt / 2 = v`` (the braking curve, see
    :func:`~firmware_model.setpoint.braking_speed`) with a margin, then
    checked with the kernel's own operations on the same constants and
    widened until it holds.  Every operation in the check rounds
    monotonically, so it holds for every larger distance too.
    """
    q, two_a, half_adt, inv_dt = k.q_rad2_s2, k.two_a_rad_s2, k.half_adt_rad_s, k.inv_step_per_s
    v = np.asarray(max_speed, dtype=float)
    distance = ((v + half_adt) ** 2 - q) / two_a
    distance = np.maximum(distance, v / inv_dt) * (1.0 + 1e-9) + 1e-12
    for _ in range(60):
        curve = np.sqrt(distance * two_a + q) - half_adt
        ok = np.minimum(max_speed, np.minimum(curve, distance * inv_dt)) == v
        if ok.all():
            return distance
        distance = np.where(ok, distance, distance * (1.0 + 1e-6) + 1e-9)
    raise AssertionError("no safe cruise distance found")  # cannot happen for finite speeds


def _min_max_clip(x, low, high, out):
    """``minimum(maximum(x, low), high)``, for a numpy without the clip ufunc."""
    np.maximum(x, low, out=out)
    return np.minimum(out, high, out=out)


#: ``clip`` as one ufunc call (the same values as maximum then minimum, half the calls); numpy
#: exposes the ufunc only under its private core module, so fall back to the two calls.
_clip = getattr(getattr(np, "_core", getattr(np, "core", None)), "umath", None)
_clip = getattr(_clip, "clip", None) or _min_max_clip
