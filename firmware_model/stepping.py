"""The fixed-step loop between two events: one generic loop, and fused kernels for the usual case.

Why it exists: behind a live bus the model must run far ahead of the wall
clock (issue 3: 100x real time for one servo, 20x for 253, one core).  The
generic loop composes the one-job step functions (:mod:`.setpoint`,
:mod:`.controller`, :mod:`.motor`) and runs every configuration; it is the
reference.  It costs about 55 numpy calls per step, each about a
microsecond whatever N, most of them allocating a fresh array or converting a
Python float.  The fused kernels do the *same arithmetic in the same order*
(so their results are bitwise equal to the generic loop's; the tests compare
them) for what nearly every bus runs: joint mode with symmetric compliance,
or every servo in wheel mode (torque off, an external torque, an arm and a
blocked shaft included).  The numpy one works in place in preallocated
buffers with its constants already broadcast, the scalar one (one servo) on
plain floats with no function calls.  PID, asymmetric compliance and a mix
of wheel and joint mode run the generic loop.

The numpy kernel also skips what provably repeats: every ``CHECK_EVERY``
steps, until it finds one, it compares the state after a step with the one
before; a reference resting on its goal is not stepped again, a state that
did not change at all (servos holding still) only accumulates heating, and
wheels whose speed did not change (cruising) only turn by the same angle and
heat.  What it found holds across calls, until the plan changes or someone
rebinds a state array the finding depends on.

Two rewrites that keep every value: ``sign(e) * m`` with ``m >= 0`` is
``copysign(m, e)`` (zeros aside, whose sign no later step can see), and
Karnopp's stop ``v * (v d > 0)`` with ``d = +-1`` is ``max(v d, 0) d``.

A kernel advances the state namespace ``s`` of
:class:`~firmware_model.physical.PhysicalModel` by ``count`` steps; the
model runs the periodic events (heating, sampling) between calls.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from .controller import PidGains, compliance_drive, pid_drive, symmetric_compliance_drive
from .motor import ARM_HORIZONTAL_RAD, arm_gravity_torque_nm, mechanics_step
from .params import ServoParams
from .setpoint import setpoint_step
from .units import RAD_PER_POSITION_UNIT

__all__ = ["StepConstants", "generic_steps", "fused_scalar_steps", "FusedNumpySteps", "fusable"]

#: While no fixed point is found, the numpy kernel looks for one after every this many steps.
CHECK_EVERY = 8


@dataclass(frozen=True)
class StepConstants:
    """The parameters the step loop uses, derived once per model (SI units, output shaft)."""

    step_s: float
    accel_rad_s2: float
    unit_rad: float
    inv_unit: float
    #: Back-EMF current per rad/s, k / R.
    k_over_r: float
    #: Output torque per ampere, eta k.
    eta_k: float
    static_nm: float
    coulomb_nm: float
    viscous_nm_s_rad: float
    stribeck_rad_s: float
    #: Step over total inertia, (rad/s) per N m.
    step_over_inertia: float
    wheel_gain_s_rad: float
    pid: bool
    gains: PidGains

    @classmethod
    def from_params(cls, p: ServoParams, step_s: float, controller: str, gains: PidGains) -> "StepConstants":
        unit = float(RAD_PER_POSITION_UNIT)
        return cls(
            step_s=step_s, accel_rad_s2=p.max_acceleration_rad_s2, unit_rad=unit, inv_unit=1.0 / unit,
            k_over_r=p.torque_constant_nm_a / p.winding_resistance_ohm, eta_k=p.gearbox_efficiency * p.torque_constant_nm_a,
            static_nm=p.static_friction_nm, coulomb_nm=p.coulomb_friction_nm, viscous_nm_s_rad=p.viscous_friction_nm_s_rad,
            stribeck_rad_s=p.stribeck_velocity_rad_s, step_over_inertia=step_s / p.total_inertia_kg_m2,
            wheel_gain_s_rad=p.wheel_speed_gain_s_rad, pid=controller == "pid", gains=gains,
        )


def fusable(k: StepConstants, plan: SimpleNamespace) -> bool:
    """Whether the fused kernels cover this configuration (else the generic loop runs)."""
    if plan.any_wheel:
        return not plan.any_joint  # all in wheel mode: no position controller at all
    return not k.pid and plan.symmetric


def generic_steps(xp, plan: SimpleNamespace, k: StepConstants, s: SimpleNamespace, count: int) -> None:
    """``count`` steps of any configuration: setpoint, controller, motor, mechanics.

    The state lives in locals during the loop and is written back at the end.
    """
    a, dt, unit, inv_unit = k.accel_rad_s2, k.step_s, k.unit_rad, k.inv_unit
    k_r, eta_k, ts, tc, b, vs, dt_j = (k.k_over_r, k.eta_k, k.static_nm, k.coulomb_nm, k.viscous_nm_s_rad,
                                       k.stribeck_rad_s, k.step_over_inertia)
    pid, gains, symmetric = k.pid, k.gains, plan.symmetric
    any_joint, any_wheel, any_disabled = plan.any_joint, plan.any_wheel, plan.any_disabled
    mixed = any_joint and any_wheel
    goal, max_speed, enabled, wheel, en, volts_r = plan.goal_rad, plan.max_speed, plan.enabled, plan.wheel, plan.en, plan.volts_r
    cw_margin, ccw_margin, cw_gain, ccw_gain, punch, limit = (plan.cw_margin, plan.ccw_margin, plan.cw_gain,
                                                              plan.ccw_gain, plan.punch, plan.limit)
    wheel_ff, wheel_ref, kv = plan.wheel_ff, plan.wheel_ref, k.wheel_gain_s_rad
    angle, speed, ref, ref_vel = s.angle, s.speed, s.ref, s.ref_vel
    drive, demand, integral, prev_error, i2_sum = s.drive, s.demand, s.integral, s.prev_error, s.current_sq_sum
    ext, weight, any_ext, any_arm = s.ext_nm, s.weight_nm, plan.any_ext, plan.any_arm
    free, any_blocked = 1.0 - s.blocked, plan.any_blocked
    for _ in range(count):
        if any_joint:
            ref, ref_vel = setpoint_step(xp, ref, ref_vel, goal, max_speed, a, dt)
            if any_disabled:
                ref = xp.where(enabled, ref, angle)
                ref_vel = ref_vel * en
            error = ref * inv_unit - xp.rint(angle * inv_unit)
            if pid:
                error = error * unit
                drive, demand, integral = pid_drive(xp, error, integral, prev_error, dt, gains, limit)
                prev_error = error
            elif symmetric:
                drive, demand = symmetric_compliance_drive(xp, error, ccw_margin, ccw_gain, punch, limit)
            else:
                drive, demand = compliance_drive(xp, error, cw_margin, ccw_margin, cw_gain, ccw_gain, punch, limit)
        if any_wheel:
            wanted = wheel_ff + kv * (wheel_ref - speed)
            wheel_drive = xp.minimum(xp.maximum(wanted, -limit), limit)
            drive = xp.where(wheel, wheel_drive, drive) if mixed else wheel_drive
            demand = xp.where(wheel, xp.abs(wanted), demand) if mixed else xp.abs(wanted)
        if any_disabled:  # open bridge: no drive, no current (Present Load reads 0)
            drive = drive * en
            current = (drive * volts_r - k_r * speed) * en
        else:
            current = drive * volts_r - k_r * speed
        applied = eta_k * current
        if any_ext:
            applied = applied + ext
        if any_arm:
            applied = applied + arm_gravity_torque_nm(xp, angle, weight)
        if any_blocked:  # a held shaft keeps its angle; the motor still draws current
            held_angle = angle
            angle, speed = mechanics_step(xp, angle, speed, applied, ts, tc, b, vs, dt_j, dt)
            angle, speed = held_angle + (angle - held_angle) * free, speed * free
        else:
            angle, speed = mechanics_step(xp, angle, speed, applied, ts, tc, b, vs, dt_j, dt)
        i2_sum = i2_sum + current * current
    s.angle, s.speed, s.ref, s.ref_vel = angle, speed, ref, ref_vel
    s.drive, s.demand, s.integral, s.prev_error, s.current_sq_sum = drive, demand, integral, prev_error, i2_sum


def fused_scalar_steps(plan: SimpleNamespace, k: StepConstants, s: SimpleNamespace, count: int) -> None:
    """:func:`generic_steps` for one servo (wheel mode, or joint mode with symmetric compliance), inlined on floats."""
    sqrt, exp, cos, copysign = math.sqrt, math.exp, math.cos, math.copysign
    a, dt, inv_unit = k.accel_rad_s2, k.step_s, k.inv_unit
    adt = a * dt
    q, two_a, half_adt, inv_dt = 0.25 * adt * adt, 2.0 * a, 0.5 * adt, 1.0 / dt
    k_r, eta_k, dt_j = k.k_over_r, k.eta_k, k.step_over_inertia
    tc, dts, b, strib = k.coulomb_nm, k.static_nm - k.coulomb_nm, k.viscous_nm_s_rad, -1.0 / (k.stribeck_rad_s * k.stribeck_rad_s)
    goal, max_speed, enabled, en, volts_r = plan.goal_rad, plan.max_speed, plan.enabled, plan.en, plan.volts_r
    wheel, wheel_ff, wheel_ref, kv = plan.wheel, plan.wheel_ff, plan.wheel_ref, k.wheel_gain_s_rad
    margin, gain, punch, limit = plan.ccw_margin, plan.ccw_gain, plan.punch, plan.limit
    ext = s.ext_nm if plan.any_ext else 0.0
    weight = s.weight_nm if plan.any_arm else 0.0
    blocked = plan.any_blocked
    angle, speed, ref, ref_vel, i2_sum = s.angle, s.speed, s.ref, s.ref_vel, s.current_sq_sum
    drive = demand = 0.0
    for _ in range(count):
        if wheel:  # speed loop with feed-forward
            wanted = wheel_ff + kv * (wheel_ref - speed)
            drive, demand = min(max(wanted, -limit), limit) * en, abs(wanted)
        else:
            error = goal - ref  # setpoint.setpoint_step
            d = abs(error)
            braking = min(sqrt(q + two_a * d) - half_adt, d * inv_dt)
            vel = ref_vel + min(max(copysign(min(max_speed, braking), error) - ref_vel, -adt), adt)
            ref, ref_vel = ref + vel * dt, vel
            if not enabled:
                ref, ref_vel = angle, ref_vel * en
            error = ref * inv_unit - round(angle * inv_unit)  # controller.symmetric_compliance_drive
            beyond = abs(error) - margin
            demand = (punch + beyond * gain) * (beyond > 0)
            drive = copysign(min(demand, limit), error) * en
        current = drive * volts_r - k_r * speed
        if not enabled:
            current = current * en
        applied = eta_k * current
        if ext:
            applied = applied + ext
        if weight:
            applied = applied + -weight * cos(angle - ARM_HORIZONTAL_RAD)
        x = speed * 1e12 + applied  # motor.mechanics_step
        direction = float((x > 0) - (x < 0))
        friction = direction * (tc + dts * exp(speed * speed * strib))
        if b:
            friction = friction + b * speed
        new_speed = speed + (applied - friction) * dt_j
        new_speed = max(new_speed * direction, 0.0) * direction
        if blocked:
            speed = 0.0
        else:
            angle, speed = angle + new_speed * dt, new_speed
        i2_sum = i2_sum + current * current
    if count:
        s.angle, s.speed, s.ref, s.ref_vel = angle, speed, ref, ref_vel
        s.drive, s.demand, s.current_sq_sum = drive, demand, i2_sum


class FusedNumpySteps:
    """:func:`generic_steps` for N servos, all in wheel mode or all in joint mode with symmetric compliance, in place.

    Built once per plan (the commands' decoding): it broadcasts every constant
    to shape (N,) and owns the scratch buffers, so a step is about 50 numpy
    calls, none allocating (about 35 once the references rest).  It writes the state arrays of ``s`` in place.
    """

    def __init__(self, plan: SimpleNamespace, k: StepConstants, s: SimpleNamespace, n: int) -> None:
        full = lambda value: np.full(n, float(value))  # noqa: E731
        adt = k.accel_rad_s2 * k.step_s
        self.c = SimpleNamespace(
            q=full(0.25 * adt * adt), two_a=full(2.0 * k.accel_rad_s2), half_adt=full(0.5 * adt), inv_dt=full(1.0 / k.step_s),
            neg_adt=full(-adt), adt=full(adt), dt=full(k.step_s), zero=full(0.0), eta_k=full(k.eta_k),
            strib=full(-1.0 / (k.stribeck_rad_s * k.stribeck_rad_s)),
            dts=full(k.static_nm - k.coulomb_nm), tc=full(k.coulomb_nm), viscous=bool(k.viscous_nm_s_rad),
            dt_j=full(k.step_over_inertia), arm_at=full(ARM_HORIZONTAL_RAD), kv=full(k.wheel_gain_s_rad),
            # Products that share an operand are stacked into one call: speed times (1e12, k/R, b),
            # and (reference, angle) times 1/unit.
            by_speed=np.repeat([[1e12], [k.k_over_r], [k.viscous_nm_s_rad]], n, axis=1),
            inv_unit2=np.full((2, n), k.inv_unit),
        )
        self.plan = plan
        #: Every servo in wheel mode (fusable() allows no mix): a speed loop instead of setpoint and compliance.
        self.wheel = plan.any_wheel
        self.neg_limit = -plan.limit
        self.disabled = ~np.asarray(plan.enabled, dtype=bool) if plan.any_disabled else None
        self.ext = s.ext_nm.copy() if plan.any_ext else None
        self.neg_weight = -s.weight_nm if plan.any_arm else None
        self.free = 1.0 - s.blocked if plan.any_blocked else None
        self.buf = SimpleNamespace(**{name: np.empty(n) for name in ("e", "d", "t", "u", "err", "cur", "applied", "dirn", "fric", "held")})
        self.buf.speed_products, self.buf.in_units = np.empty((3, n)), np.empty((2, n))
        # The state the kernel updates in place.  Reference and angle are the two rows of one
        # array, so one call scales both.  A caller that rebinds a state array (an event, a new
        # plan) is copied in at the next call; one that keeps a state array must copy it.
        self.ref_angle = np.empty((2, n))
        self.state = {"ref": self.ref_angle[0], "angle": self.ref_angle[1],
                      **{name: np.empty(n) for name in ("speed", "ref_vel", "drive", "demand", "current_sq_sum")}}
        self.buf.i2_step, self.buf.step_angle = np.empty(n), np.empty(n)
        # Fixed points found by a check after a step (see __call__); they hold while the plan (this
        # object) lives and nobody rebinds the state arrays they depend on.
        self.ref_resting = self.at_rest = self.cruising = False
        #: Cruising applies when the speed update depends on the speed alone: all in wheel mode
        #: (no position controller), no arm (gravity depends on the angle), no blocked shaft.
        self.can_cruise = plan.any_wheel and not plan.any_arm and not plan.any_blocked
        self.check_in = 0
        #: Steps taken by each shortcut (for tests and benchmarks: that they run at all).
        self.rest_steps = self.cruise_steps = 0

    def __call__(self, s: SimpleNamespace, count: int) -> None:
        sub, add, mul, absolute, sqrt, rint, exp, cos = np.subtract, np.add, np.multiply, np.abs, np.sqrt, np.rint, np.exp, np.cos
        minimum, maximum, copysign, sign, heaviside = np.minimum, np.maximum, np.copysign, np.sign, np.heaviside
        c, p, bf = self.c, self.plan, self.buf
        e, d, t, u, err, cur, applied, dirn, fric, held = bf.e, bf.d, bf.t, bf.u, bf.err, bf.cur, bf.applied, bf.dirn, bf.fric, bf.held
        speed_products, in_units = bf.speed_products, bf.in_units
        speed_big, speed_k_r, speed_b = speed_products
        goal, max_speed, margin, gain, punch, limit, volts_r, en = (p.goal_rad, p.max_speed, p.ccw_margin, p.ccw_gain, p.punch,
                                                                    p.limit, p.volts_r, p.en)
        disabled, ext, neg_weight, free, viscous, wheel = self.disabled, self.ext, self.neg_weight, self.free, c.viscous, self.wheel
        state = self.state
        for name, own in state.items():
            current = getattr(s, name)
            if current is not own:  # rebound since the last call: take the new values in
                np.copyto(own, current)
                setattr(s, name, own)
                if name in ("ref", "ref_vel", "angle"):
                    self.ref_resting = self.at_rest = False
                elif name == "speed":
                    self.ref_resting = self.at_rest = self.cruising = False
        ref_angle = self.ref_angle
        ref, angle, speed, vel, drive, demand, i2_sum = (state["ref"], state["angle"], state["speed"], state["ref_vel"],
                                                         state["drive"], state["demand"], state["current_sq_sum"])
        i2_step, step_angle = bf.i2_step, bf.step_angle
        # Fixed points, checked after a step rather than assumed (every CHECK_EVERY steps while
        # none is found): a step that leaves the reference (and its speed) bit for bit unchanged
        # leaves it so for good; one that leaves the whole state unchanged (reference, angle,
        # speed: a servo holding still) repeats itself exactly, so later steps only heat; and in
        # wheel mode, where the speed update depends on the speed alone, one that leaves the
        # speed unchanged is cruising: later steps only turn the shaft by the same angle and heat.
        ref_resting = self.ref_resting
        step = 0
        while step < count:
            if self.at_rest:
                self.rest_steps += count - step
                for _ in range(count - step):
                    add(i2_sum, i2_step, i2_sum)
                break
            if self.cruising:
                self.cruise_steps += count - step
                for _ in range(count - step):
                    add(angle, step_angle, angle)
                    add(i2_sum, i2_step, i2_sum)
                break
            before = None
            if self.check_in <= 0:
                before = (ref.tobytes(), vel.tobytes(), angle.tobytes(), speed.tobytes())
            else:
                self.check_in -= 1
            step += 1
            if wheel:  # the generic loop's speed loop with feed-forward
                sub(p.wheel_ref, speed, t)
                mul(c.kv, t, t)
                add(p.wheel_ff, t, t)
                maximum(t, self.neg_limit, out=drive)
                minimum(drive, limit, out=drive)
                absolute(t, demand)
            else:
                if not ref_resting:  # setpoint.setpoint_step
                    sub(goal, ref, e)
                    absolute(e, d)
                    mul(d, c.two_a, t)
                    add(t, c.q, t)
                    sqrt(t, t)
                    sub(t, c.half_adt, t)
                    mul(d, c.inv_dt, u)
                    minimum(t, u, out=t)
                    minimum(max_speed, t, out=t)
                    copysign(t, e, t)
                    sub(t, vel, t)
                    maximum(t, c.neg_adt, out=t)
                    minimum(t, c.adt, out=t)
                    add(vel, t, vel)
                    mul(vel, c.dt, t)
                    add(ref, t, ref)
                if disabled is not None:
                    np.copyto(ref, angle, where=disabled)
                    mul(vel, en, vel)
                # controller.symmetric_compliance_drive, on the error in units
                mul(ref_angle, c.inv_unit2, in_units)
                rint(in_units[1], t)
                sub(in_units[0], t, err)
                absolute(err, d)
                sub(d, margin, d)
                mul(d, gain, demand)
                add(punch, demand, demand)
                heaviside(d, c.zero, t)  # (d > 0) as 0.0 / 1.0
                mul(demand, t, demand)
                minimum(demand, limit, out=drive)
                copysign(drive, err, drive)
            # motor current; an open bridge (torque off) carries none
            if disabled is not None:
                mul(drive, en, drive)
            mul(speed, c.by_speed, speed_products)
            mul(drive, volts_r, cur)
            sub(cur, speed_k_r, cur)
            if disabled is not None:
                mul(cur, en, cur)
            mul(c.eta_k, cur, applied)
            if ext is not None:
                add(applied, ext, applied)
            if neg_weight is not None:  # motor.arm_gravity_torque_nm
                sub(angle, c.arm_at, t)
                cos(t, t)
                mul(neg_weight, t, t)
                add(applied, t, applied)
            # motor.mechanics_step
            add(speed_big, applied, t)
            sign(t, dirn)
            mul(speed, speed, t)
            mul(t, c.strib, t)
            exp(t, t)
            mul(c.dts, t, t)
            add(c.tc, t, t)
            mul(dirn, t, fric)
            if viscous:
                add(fric, speed_b, fric)
            sub(applied, fric, t)
            mul(t, c.dt_j, t)
            if free is not None:
                held[:] = angle
            add(speed, t, speed)
            mul(speed, dirn, t)
            maximum(t, c.zero, out=t)
            mul(t, dirn, speed)
            mul(speed, c.dt, step_angle)
            add(angle, step_angle, angle)
            if free is not None:  # a held shaft keeps its angle
                sub(angle, held, t)
                mul(t, free, t)
                add(held, t, angle)
                mul(speed, free, speed)
            mul(cur, cur, i2_step)
            add(i2_sum, i2_step, i2_sum)
            if before is not None:
                same_ref = ref.tobytes() == before[0] and vel.tobytes() == before[1]
                same_speed = speed.tobytes() == before[3]
                self.at_rest = same_ref and same_speed and angle.tobytes() == before[2]
                self.cruising = same_speed and self.can_cruise
                ref_resting = self.ref_resting = same_ref and disabled is None  # else it follows a free shaft
                self.check_in = 0 if self.at_rest or self.cruising else CHECK_EVERY - 1
