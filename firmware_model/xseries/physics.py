"""Motor, gearbox, friction and load of one X-series servo: the firmware's PWM duty in, the shaft's motion out.

Why it exists: the X-series firmware (:mod:`.firmware`) ends in a PWM duty, as the real one does (Goal PWM,
PWM Limit and Present PWM are duty registers); everything from there to the shaft is physics, owned here,
so the firmware model steers a motor rather than a shaft, and a fitted motor can be checked against real
recordings without touching the control law.

Model (everything referred to the output shaft, ``G`` the gear ratio):

* Motor: the H-bridge applies ``duty * V`` across the winding (averaged PWM).  Current
  ``i = (duty V - k_e w) / R``, output torque ``k_t i``, where ``k_e = G k_motor`` (back-EMF) and
  ``k_t = eta G k_motor`` (the gearbox's forward efficiency ``eta`` folded in: the data sheet's stall
  torque is measured at the horn, through the gears).  The winding inductance is neglected: ROBOTIS
  gives none, and a small DC motor's ``L / R`` (a fraction of a millisecond) is below the firmware's
  1 ms step, so the current settles within one step.  The bridge is synchronous: the current flows
  both ways (zero duty brakes with ``k_t k_e / R``); with torque off (``driven=False``) it is open and
  no current flows.  This is the motor of Rhoban's BAM (``bam/actuator.py``, ``VoltageControlledActuator
  .compute_torque``: ``tau = kt V / R - kt**2 dq / R``), with ``k_t`` and ``k_e`` kept apart.
* Friction, a budget that dry friction may spend each step (BAM's, ``bam/model.py``,
  ``Model.compute_frictions``): Coulomb ``t_c``, plus a Stribeck term ``t_s exp(-|w / w_s|**alpha)``
  that is there only near rest, plus gear friction that grows with the torque the gears carry:
  ``|mu_e tau_ext - mu_m tau_motor|`` (BAM's "load-dependent directional" models M5, M6: a gear pair
  driven from the motor side loses a share of the motor's torque, one back-driven by the load a share
  of the load's), with its own Stribeck part at rest (the same fading), a part growing with the square
  of the motor's torque (BAM's M6 has quadratic terms), and a viscous ``b w``.  All the extra terms
  default to zero: the plain model.
* Load: the reflected rotor and gear inertia, plus what :meth:`XPhysics.set_load` puts on the horn
  (an inertia and a pendulum), plus an external torque.
* Supply: a stiff source by default; with ``supply_resistance_ohm`` the bridge's input current
  ``duty i`` sags the servo's input (``bus_voltage_v``), which weakens the drive as ``R + duty**2 R_s``.
  On the real XL330 logs (a bench supply at 7.4 V) the servo's own Present Input Voltage sags by 0.13 V
  on average at duties above 0.8, some 0.07 ohm: the default is the right one there.

Integration (one step of ``dt``), semi-implicit so that a 1 ms step is stable for any of these motors
and no substeps are needed: the speed-proportional torques (back-EMF braking ``k_t k_e / R`` and
viscous ``b``) are taken at the new speed (backward Euler, unconditionally stable), the others at the
old state; dry friction is then applied as a proximal step, as in :mod:`firmware_model.motor`: it
removes up to its whole impulse ``F dt`` but never turns the motion round, so a shaft held within its
friction stays at exactly zero speed (BAM's "stopping torque" clip, ``bam/simulate.py``, in implicit
form).  The angle then moves by the new speed (symplectic Euler, which keeps a free pendulum's energy
bounded).  About 1-2 microseconds per step in CPython: cheap enough for the serving loop.

Data-sheet derivation (:meth:`XPhysicsParams.from_datasheet`): ROBOTIS gives, at each rated voltage
``V``, the stall torque ``S``, the stall current ``I`` and the no-load speed ``N``
(``ax12emu/protocol/models/*.toml``, from the e-manual).  Read as a dynamometer reads them at full
duty, against the servo's own friction: ``I = V / R``, ``S = c V - t_c`` with ``c = k_t / R``, and
``N = (c V - t_c) / (c k_e + b)``.  Three least squares over the ratings (relative errors) give
``R``, ``c`` and ``k_e``, hence ``k_t = c R``.  Friction is not on the data sheet; it is taken as the
share of the motor's figures that BAM fitted on a real XL330 (``bam/params/xl330/m1.json``:
``friction_base`` 0.0128 N m against a stall torque ``kt vin / R`` of 0.712 N m at 7.4 V, 1.8 %;
``friction_viscous`` 0.00366 N m s/rad against the back-EMF damping ``kt**2 / R`` of 0.0372, 9.8 %).
The rotor inertia is not on the data sheet either.  Where a model file gives it (``rotor_inertia_at_motor_kg_m2``,
e.g. BAM's fit of that very servo) it is used as given.  Otherwise it is scaled as geometrically similar
motors scale (torque as the cube of the size, inertia as its fifth power: ``J = k torque**(5/3)``, the
torque being the sheet's stall torque at its highest rated voltage, at the motor), with the constant ``k``
of the motor's kind, the e-manual's "Motor" row, because a coreless rotor (a self-supporting copper
winding, no iron) has several times less inertia than a cored one of the same torque:

* cored: BAM's fitted XL330 ``armature`` 0.00181 kg m**2 (``bam/params/xl330/m1.json``), 2.2e-8 kg m**2
  at the motor through 288.4**2, for 0.60 / 288.4 N m.  The XL-320's own BAM fit (``bam/params/xl320/m1.json``,
  0.00112 kg m**2 at the output) is 1.35 times what this gives it: the rule carries across cored motors.
* coreless: BAM's fits of two real Maxon-coreless servos, the MX-64 (``bam/params/mx64/m1.json``
  ``armature`` 0.01195 kg m**2, 2.99e-7 at the motor through 200**2, for 7.3 / 200 N m) and the MX-106
  (``bam/params/mx106/m1.json`` 0.02661, 5.26e-7 through 225**2, for 10.0 / 225 N m).  ``k`` is their
  geometric mean: it gives each of them within 13 % (1.13 and 0.89 times its fit), and it is 7.7 times
  below the cored ``k``.  How uncertain: the two points span only 1.2x in torque, too little to fix the
  exponent (through both exactly it would be 2.9, not 5/3); the coreless models the emulator scales
  with it (MX-28, XM430, XC330) lie 2.3 to 10 times below them in motor torque, where the 5/3 and the
  2.9 laws part by 3x (MX-28), 4x (XM430) and 17x (XC330).  The 5/3 law is kept because it is the one that
  holds for the cored motors; its figures for those models are estimates good to a factor of a few,
  the XC330's ("Coreless DC", maker not given) the least certain.  The MX-64 and MX-106 files give
  their BAM fits directly.

Where the sheet's three figures cannot come from one motor with
an efficiency at most one (the XL330-M077: its stall torque per stall current is above its back-EMF
constant), the stall current is the figure dropped: ``k_t = k_e`` and ``R = k_t / c``, so stall
torque and no-load speed still hold and the stall current comes out higher than the sheet's.

Against a real XL330 (``tools/xl330_fit.py``, Rhoban's BAM pendulum logs): fitted at Position P Gain
100 and replayed at 400 through the X-series firmware model, Coulomb + viscous friction leaves 103 mrad
of mean position error and the load-dependent gear friction above (motor-side 0.17, load-side 0.18,
quadratic 0.41 per N m, Coulomb 0.004 N m, an ideal motor with ``k_e`` 0.407 V s/rad, near the data
sheet's 0.413) 47 mrad; the data-sheet default, unfitted, 110 mrad.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields

__all__ = ["GRAVITY_M_S2", "XL330_ROTOR_INERTIA_AT_MOTOR_KG_M2", "XL330_MOTOR_STALL_TORQUE_NM", "MOTOR_KINDS",
           "ROTOR_INERTIA_PER_TORQUE_5_3", "COULOMB_SHARE", "VISCOUS_SHARE", "XPhysicsParams", "XPhysics"]

#: Standard gravity, m/s**2.
GRAVITY_M_S2 = 9.80665
#: Rotor inertia at the motor of the XL330 family: BAM's fitted XL330 armature (bam/params/xl330/m1.json,
#: 0.00181 kg m**2 at the output) over the XL330-M288's 288.4**2.
XL330_ROTOR_INERTIA_AT_MOTOR_KG_M2 = 0.0018141672784458866 / 288.4**2
#: Stall torque at the motor of that same motor, N m: the XL330-M288 sheet at its highest rated voltage
#: (0.60 N m at 6.0 V) over 288.4, the reference for scaling the rotor inertia to other motors.
XL330_MOTOR_STALL_TORQUE_NM = 0.60 / 288.4
#: BAM's fitted ``armature`` (kg m**2 at the output, ``bam/params/<servo>/m1.json``), gear ratio and the sheet's
#: stall torque at its highest rated voltage of the two Maxon-coreless servos BAM identified: the coreless reference.
_BAM_CORELESS_FITS = ((0.011951238325312509, 200.0, 7.3),     # MX-64, bam/params/mx64/m1.json
                      (0.026609234235148084, 225.0, 10.0))    # MX-106, bam/params/mx106/m1.json
#: The e-manual's "Motor" kinds the rotor scaling knows (its specifications table: "Cored", "Coreless(Maxon)",
#: "Coreless", "Coreless DC"; the coreless ones all "coreless" here).
MOTOR_KINDS = ("cored", "coreless")
#: ``k`` of ``J_rotor = k * motor_stall_torque**(5/3)`` (SI, at the motor) per motor kind: the cored one from BAM's
#: XL330, the coreless one the geometric mean over BAM's MX-64 and MX-106 (module docstring: how uncertain).
ROTOR_INERTIA_PER_TORQUE_5_3 = {
    "cored": XL330_ROTOR_INERTIA_AT_MOTOR_KG_M2 / XL330_MOTOR_STALL_TORQUE_NM ** (5.0 / 3.0),
    "coreless": math.exp(sum(math.log(armature / gear**2 / (stall / gear) ** (5.0 / 3.0))
                             for armature, gear, stall in _BAM_CORELESS_FITS) / len(_BAM_CORELESS_FITS)),
}
#: Coulomb friction as a share of the stall drive ``k_t V / R`` (BAM's XL330 M1 fit, see the module docstring).
COULOMB_SHARE = 0.01283272036582759 / (0.3866957639281311 * 7.4 / 4.017129222290597)
#: Viscous friction as a share of the back-EMF damping ``k_t k_e / R`` (same source).
VISCOUS_SHARE = 0.003661672282824312 / (0.3866957639281311**2 / 4.017129222290597)

_RPM = 2.0 * math.pi / 60.0


@dataclass(frozen=True)
class XPhysicsParams:
    """Motor, gearbox and friction constants of one X-series servo, SI units, at the output shaft."""

    gear_ratio: float
    #: Motor winding resistance, ohm.
    resistance_ohm: float
    #: Output torque per winding ampere: the motor's constant times the gear ratio times the gearbox's efficiency.
    torque_constant_nm_a: float
    #: Back-EMF per output rad/s: the motor's constant times the gear ratio (no efficiency: it is kinematic).
    back_emf_v_s_rad: float
    #: Rotor and gears reflected to the output, kg m**2 (the load on the horn comes from XPhysics.set_load).
    inertia_kg_m2: float
    #: Dry friction while sliding, N m.
    coulomb_friction_nm: float
    #: Viscous friction, N m s/rad.
    viscous_friction_nm_s_rad: float
    #: Extra dry friction at rest, fading with speed as ``exp(-|w / stribeck_velocity_rad_s| ** stribeck_exponent)``.
    stribeck_friction_nm: float = 0.0
    stribeck_velocity_rad_s: float = 1.0
    stribeck_exponent: float = 2.0
    #: Gear friction per N m of motor torque the gears carry (driving from the motor side), dimensionless.
    load_friction_motor: float = 0.0
    #: Gear friction per N m of external torque the gears carry (back-driven by the load), dimensionless.
    load_friction_external: float = 0.0
    #: Extra gear friction at rest per N m carried from the motor side and from the load side, fading with speed
    #: as the Stribeck term does (BAM's ``load_friction_motor_stribeck`` and ``load_friction_external_stribeck``).
    load_stribeck_motor: float = 0.0
    load_stribeck_external: float = 0.0
    #: Gear friction growing with the square of the motor torque the gears carry, per N m (BAM's M6 has such
    #: quadratic terms; its XL330 fit, ``load_friction_motor_quad``, uses it).
    load_friction_motor_quadratic_per_nm: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"XPhysicsParams.{f.name} must be a finite number, got {value!r}")
        for name in ("gear_ratio", "resistance_ohm", "torque_constant_nm_a", "back_emf_v_s_rad", "inertia_kg_m2",
                     "stribeck_velocity_rad_s", "stribeck_exponent"):
            if getattr(self, name) <= 0:
                raise ValueError(f"XPhysicsParams.{name} must be positive, got {getattr(self, name)!r}")
        for name in ("coulomb_friction_nm", "viscous_friction_nm_s_rad", "stribeck_friction_nm", "load_friction_motor",
                     "load_friction_external", "load_stribeck_motor", "load_stribeck_external",
                     "load_friction_motor_quadratic_per_nm"):
            if getattr(self, name) < 0:
                raise ValueError(f"XPhysicsParams.{name} must be >= 0, got {getattr(self, name)!r}")

    # ------------------------------------------------------------------ derived figures
    @property
    def gearbox_efficiency(self) -> float:
        """``k_t / k_e``: the forward efficiency the torque constant folds in."""
        return self.torque_constant_nm_a / self.back_emf_v_s_rad

    @property
    def back_emf_damping_nm_s_rad(self) -> float:
        """Braking torque per rad/s of the driven (shorted-through-the-bridge) motor, ``k_t k_e / R``."""
        return self.torque_constant_nm_a * self.back_emf_v_s_rad / self.resistance_ohm

    def stall_torque_nm(self, supply_v: float) -> float:
        """The opposing torque a fully driven shaft holds at rest: drive less Coulomb friction (as the sheet measures it)."""
        return self.torque_constant_nm_a * supply_v / self.resistance_ohm - self.coulomb_friction_nm

    def stall_current_a(self, supply_v: float) -> float:
        """Winding current at full duty and zero speed."""
        return supply_v / self.resistance_ohm

    def no_load_speed_rad_s(self, supply_v: float) -> float:
        """Settled speed at full duty against the servo's own friction (the Stribeck part gone at speed)."""
        drive = self.torque_constant_nm_a * supply_v / self.resistance_ohm
        return max(drive - self.coulomb_friction_nm, 0.0) / (self.back_emf_damping_nm_s_rad + self.viscous_friction_nm_s_rad)

    # ------------------------------------------------------------------ from a data sheet
    @classmethod
    def from_datasheet(cls, *, gear_ratio: float, ratings: Sequence[tuple[float, float, float, float]],
                       motor: str = "cored", rotor_inertia_at_motor_kg_m2: float | None = None) -> XPhysicsParams:
        """Constants from the e-manual's ratings ``(voltage_v, stall_torque_nm, stall_current_a, no_load_speed_rpm)``.

        Derivation in the module docstring: least squares (relative) of ``I = V / R``, ``S = c V - t_c`` and
        ``N = (c V - t_c) / (c k_e (1 + VISCOUS_SHARE))`` over the ratings, friction as BAM's XL330 shares, the
        rotor ``rotor_inertia_at_motor_kg_m2`` where a source gives it, else scaled from BAM's fits of the
        ``motor`` kind (:data:`MOTOR_KINDS`).  With one rating the figures are met exactly.  A rating that no
        motor could give (non-positive figures) raises ``ValueError``.
        """
        if gear_ratio <= 0:
            raise ValueError(f"gear_ratio must be positive, got {gear_ratio!r}")
        if motor not in ROTOR_INERTIA_PER_TORQUE_5_3:
            raise ValueError(f"motor must be one of {', '.join(MOTOR_KINDS)}, got {motor!r}")
        if rotor_inertia_at_motor_kg_m2 is not None and not (math.isfinite(rotor_inertia_at_motor_kg_m2)
                                                              and rotor_inertia_at_motor_kg_m2 > 0):
            raise ValueError(f"rotor_inertia_at_motor_kg_m2 must be positive, got {rotor_inertia_at_motor_kg_m2!r}")
        rows = [tuple(float(x) for x in r) for r in ratings]
        if not rows:
            raise ValueError("from_datasheet needs at least one rating")
        for row in rows:
            if len(row) != 4 or min(row) <= 0:
                raise ValueError(f"a rating is (voltage_v, stall_torque_nm, stall_current_a, no_load_speed_rpm), all positive; got {row!r}")
        volts = [r[0] for r in rows]
        # I = g V (g = 1 / R), relative least squares: minimise sum (g V / I - 1)**2.
        u = [v / i for v, _, i, _ in rows]
        resistance = sum(x * x for x in u) / sum(u)
        # S = c (V - COULOMB_SHARE V_max): Coulomb friction a share of the drive at the highest rated voltage.
        v_ref = max(volts)
        x = [(v - COULOMB_SHARE * v_ref) / s for v, s, _, _ in rows]
        c = sum(x) / sum(xi * xi for xi in x)
        coulomb = COULOMB_SHARE * c * v_ref
        # N = a / k_e with a = (c V - t_c) / (c (1 + VISCOUS_SHARE)): 1 / k_e by relative least squares.
        y = [(c * v - coulomb) / (c * (1.0 + VISCOUS_SHARE)) / (n * _RPM) for v, _, _, n in rows]
        back_emf = sum(yi * yi for yi in y) / sum(y)
        torque_constant = c * resistance
        if torque_constant > back_emf:
            # Efficiency above one: the sheet's stall current is not the winding's at its stall torque.
            # Keep torque and speed (what the servo does), drop the current: eta = 1.
            torque_constant = back_emf
            resistance = torque_constant / c
        if rotor_inertia_at_motor_kg_m2 is not None:
            rotor = float(rotor_inertia_at_motor_kg_m2)
        else:
            motor_stall_nm = max(rows)[1] / gear_ratio  # the sheet's stall torque at its highest voltage, at the motor
            rotor = ROTOR_INERTIA_PER_TORQUE_5_3[motor] * motor_stall_nm ** (5.0 / 3.0)
        return cls(
            gear_ratio=float(gear_ratio),
            resistance_ohm=resistance,
            torque_constant_nm_a=torque_constant,
            back_emf_v_s_rad=back_emf,
            inertia_kg_m2=rotor * gear_ratio**2,
            coulomb_friction_nm=coulomb,
            viscous_friction_nm_s_rad=VISCOUS_SHARE * c * back_emf,
        )


class XPhysics:
    """One X-series servo's shaft: motor, gears, friction and load, stepped by the firmware's PWM duty.

    ``angle_rad`` is the output shaft's angle, continuous (it counts turns); positive is counter-clockwise.
    """

    def __init__(self, params: XPhysicsParams, *, supply_v: float, angle_rad: float = 0.0,
                 supply_resistance_ohm: float = 0.0) -> None:
        if not isinstance(params, XPhysicsParams):
            raise TypeError(f"params must be XPhysicsParams, got {type(params).__name__}")
        if not (math.isfinite(supply_resistance_ohm) and supply_resistance_ohm >= 0):
            raise ValueError(f"supply_resistance_ohm must be >= 0, got {supply_resistance_ohm!r}")
        self.params = params
        #: Open-circuit voltage of the supply, V (settable).
        self.supply_v = float(supply_v)
        #: Resistance of the supply and its wires up to the servo's input, ohm (settable; 0: a stiff supply).
        self.supply_resistance_ohm = float(supply_resistance_ohm)
        #: Voltage at the servo's input over the last step (what Present Input Voltage reads): the supply less
        #: the drop the bridge's input current makes across ``supply_resistance_ohm``.
        self.bus_voltage_v = self.supply_v
        self.angle_rad = float(angle_rad)
        self.velocity_rad_s = 0.0
        self.current_a = 0.0
        #: Torque the motor put on the output shaft over the last step, N m (k_t i).
        self.motor_torque_nm = 0.0
        self._external_nm = 0.0
        self._load_inertia_kg_m2 = 0.0
        self._gravity_nm = 0.0
        self._gravity_zero_rad = 0.0
        #: The output shaft is held still (an obstacle, a hand): the motor drives into it at zero speed.
        self.blocked = False

    def set_external_torque(self, torque_nm: float) -> None:
        """A torque acting on the output shaft, N m, positive counter-clockwise; stays until changed."""
        self._external_nm = float(torque_nm)

    def set_load(self, *, inertia_kg_m2: float = 0.0, gravity_torque_nm: float = 0.0, gravity_zero_rad: float = 0.0) -> None:
        """What is on the horn: an extra inertia and a pendulum (``-gravity_torque_nm sin(angle - gravity_zero_rad)``).

        A point mass ``m`` at ``l`` hanging down at ``gravity_zero_rad`` is ``inertia_kg_m2 = m l**2`` and
        ``gravity_torque_nm = m g l``.
        """
        if inertia_kg_m2 < 0 or not math.isfinite(inertia_kg_m2):
            raise ValueError(f"load inertia must be >= 0, got {inertia_kg_m2!r}")
        if not (math.isfinite(gravity_torque_nm) and math.isfinite(gravity_zero_rad)):
            raise ValueError("gravity_torque_nm and gravity_zero_rad must be finite")
        self._load_inertia_kg_m2 = float(inertia_kg_m2)
        self._gravity_nm = float(gravity_torque_nm)
        self._gravity_zero_rad = float(gravity_zero_rad)

    @property
    def inertia_kg_m2(self) -> float:
        """Everything the output shaft accelerates: rotor and gears plus the load."""
        return self.params.inertia_kg_m2 + self._load_inertia_kg_m2

    def external_torque_nm(self) -> float:
        """The torque the load puts on the shaft now: the set external torque plus the pendulum's gravity."""
        gravity = -self._gravity_nm * math.sin(self.angle_rad - self._gravity_zero_rad) if self._gravity_nm else 0.0
        return self._external_nm + gravity

    def step(self, duty: float, dt_s: float, *, driven: bool = True) -> None:
        """Advance ``dt_s`` with ``duty`` (-1..1, clipped) of the supply across the motor; ``driven=False``: bridge open."""
        p = self.params
        w = self.velocity_rad_s
        inertia = p.inertia_kg_m2 + self._load_inertia_kg_m2
        external = self.external_torque_nm()
        if driven:
            duty = -1.0 if duty < -1.0 else (1.0 if duty > 1.0 else float(duty))
            # The bridge draws duty * i from the supply, which sags by R_s duty i, and applies duty times
            # that to the winding: i = (duty V - k_e w) / (R + duty**2 R_s).
            resistance = p.resistance_ohm + duty * duty * self.supply_resistance_ohm
            applied_v = duty * self.supply_v
            drive_nm = p.torque_constant_nm_a * applied_v / resistance
            motor_damping = p.torque_constant_nm_a * p.back_emf_v_s_rad / resistance
            damping = motor_damping + p.viscous_friction_nm_s_rad
        else:
            resistance = p.resistance_ohm
            applied_v = 0.0
            drive_nm = 0.0
            motor_damping = 0.0
            damping = p.viscous_friction_nm_s_rad
        # Speed-proportional torques at the new speed (backward Euler), the rest at the old state.
        scale = inertia + dt_s * damping
        free = (inertia * w + dt_s * (drive_nm + external)) / scale
        # Dry friction budget (BAM's), taken at the step's starting state.
        budget = p.coulomb_friction_nm
        motor_nm = drive_nm - motor_damping * w
        if p.load_friction_motor or p.load_friction_external:
            budget += abs(p.load_friction_external * external - p.load_friction_motor * motor_nm)
        if p.load_friction_motor_quadratic_per_nm:
            budget += p.load_friction_motor_quadratic_per_nm * motor_nm * motor_nm
        if p.stribeck_friction_nm or p.load_stribeck_motor or p.load_stribeck_external:
            at_rest = math.exp(-abs(w / p.stribeck_velocity_rad_s) ** p.stribeck_exponent)
            budget += at_rest * (p.stribeck_friction_nm + abs(p.load_stribeck_external * external - p.load_stribeck_motor * motor_nm))
        slip = dt_s * budget / scale
        if free > slip:
            w_new = free - slip
        elif free < -slip:
            w_new = free + slip
        else:
            w_new = 0.0
        if self.blocked:
            w_new = 0.0
        self.velocity_rad_s = w_new
        self.angle_rad += w_new * dt_s
        if driven:
            self.current_a = (applied_v - p.back_emf_v_s_rad * w_new) / resistance
            self.bus_voltage_v = self.supply_v - self.supply_resistance_ohm * duty * self.current_a
        else:
            self.current_a = 0.0
            self.bus_voltage_v = self.supply_v
        self.motor_torque_nm = p.torque_constant_nm_a * self.current_a
