"""Physical parameters of one AX-12+, in SI units, with their sources; TOML load and save.

Why it exists: every number the physical model uses lives here, as data, so
a fitted set can be saved, handed to ``ax12emu serve --params FILE`` and
checked.  Names carry their units.

Derivation of the motor constants (everything referred to the output shaft)
---------------------------------------------------------------------------
Model (see :mod:`firmware_model.motor`): ``i = (u V - k w) / R``, output
torque ``eta k i``, so at full drive ``T(w) = c V - c k w`` with
``c = eta k / R``.  Three data-sheet / report figures fix three numbers:

1. Holding torque fixes ``c``.  A powered, stalled servo resists an external
   torque with its stall torque ``c V`` plus static friction ``t_s`` (the
   gears must be made to slip too).  Data sheet: 1.18 N m at 7 V, 1.62 N m at
   10 V.  Least squares of ``H - t_s = c V`` through the origin over both
   points: ``c = (7 * 1.05 + 10 * 1.49) / (49 + 100) = 0.1493 N m/V``; the
   fit then gives 1.175 and 1.623 N m (-0.4 %, +0.2 %).  Stall current at
   9.6 V is ``V / R = 1.52 A``.
2. Peak acceleration fixes the inertia.  The report measured about
   200 rad/s**2 with its camera (figure 2.13; supply taken as the
   recommended 9.6 V).  Full drive from rest would give it with ``J = (c V -
   t_s) / a = (0.1493 * 9.6 - 0.13) / 200 = 6.5e-3 kg m**2``, but the
   controller reaches full drive only once the shaft already turns (the error
   must exceed the compliance slope) and back-EMF has taken its share, so
   that is an upper bound.  Simulating the 60-degree move at 9.6 V, the peak
   acceleration is 200 rad/s**2 at ``J = 3.4e-3 kg m**2``; less the camera's
   1.35e-4 the reflected rotor inertia is ``3.27e-3 kg m**2``, i.e.
   ``5.1e-8 kg m**2`` (0.5 g cm**2) at the motor through 254**2, typical of a
   small DC motor.  That figure is a Fourier fit to 100 Hz samples (report
   2.3.4), good to some 15 %, and it leaves out the gears (report 3.3).  Real
   AX-12A step responses ask for more: with the bridge coasting (see
   :mod:`firmware_model.motor`), the overshoot of a full-speed step and how
   it grows with a bar of known inertia on the horn fit a rotor-and-gear
   inertia of 1.8 times 3.27e-3 at 9.0 V (``tools/real_ax12a.py``).  The
   default takes 1.3 times (4.24e-3 kg m**2, total 4.38e-3): the most the
   report's 200 rad/s**2 allows within its 15 % (the simulated peak is then
   180 rad/s**2), and enough for the real servo's overshoot at 9.6 V.
3. The 60-degree time fixes the speed-voltage line, hence ``k`` and ``eta``.
   With full drive the top speed is ``w(V) = (c V - t_c) / D``, ``D = c k +
   b``.  The data sheet's "sec/60 deg" (0.269 s at 7 V, 0.196 s at 10 V) is
   read as the time of a full-speed 60-degree move, start to arrival.  First
   guess from a trapezoid (``theta / w + w / a``): ``w`` = 4.2 and 6.4 rad/s,
   so ``D = 3 c / 2.2 = 0.21``.  The controller's approach adds time, so the
   simulated move is fitted instead, with ``t_c = 0.10 N m``: ``D = 0.185``
   gives 0.268 s and 0.192 s (-0.4 %, -2 %).  With ``b = 0`` (see below)
   ``k = D / c = 1.239 N m/A`` at the output (4.88 mN m/A at the motor) and
   ``eta = c R / k = 0.76`` (0.95 per stage over five stages).  Top speed at
   full drive: 5.11 rad/s at 7 V, 7.21 at 9.6 V, 7.53 at 10 V, 9.15 at 12 V;
   the frictionless no-load speed ``V / k`` is 5.65, 7.75, 8.07, 9.69 rad/s.

Why not the report's "torque constant 6.6 N/A" (section 2.3.3): it is the
slope of output torque against the *supply-line* current, measured through
the PWM driver and the electronics (37 mA at rest).  A switching bridge
draws from the supply about ``u`` times the winding current (``u`` the duty
the controller happens to use), so that ratio is not the motor constant, and
the report itself found the relation not linear (section 5).
Taken literally as ``k`` at the output, with R = 6.3 ohm, it predicts a
no-load speed of ``9.6 / 6.6 = 1.5 rad/s`` and a stall torque of ``6.6 *
9.6 / 6.3 = 10 N m``, against 5-6 rad/s and 1.4 N m in the data sheet.

Why the viscous coefficient is not the report's 0.15 N m s/rad (section
2.3.2): that was measured back-driving the unpowered servo over a narrow,
slow range, with a negative intercept the report itself doubts.  Inside the
powered model it cannot coexist with the data sheet: the speed gained from 7
to 10 V needs ``D`` near 0.2 (0.185 fitted); with ``b = 0.15`` that leaves
``c k = 0.035``, i.e. ``eta = c**2 R / 0.035 = 4``, an efficiency above one.
So the powered model's ``b`` is the residual of the fit, zero, and the
report's value is kept as :data:`REPORT_VISCOUS_NM_S_RAD` for reference.  A
fitted parameter set may set ``viscous_friction_nm_s_rad`` (then ``k`` must
shrink to keep ``D``).

The report's 9.12 rad/s "at setting 785" (section 4.2) is a slope read off a
position plot; 785 is that speed expressed in register units (9.12 / 11.9 *
1023), not a value written to the servo.  It is above the naive data-sheet
speed (60 deg / 0.196 s = 5.3 rad/s at 10 V) because that figure includes
acceleration and the approach, not because the report is wrong.  In this
model Moving Speed N asks for ``N * 0.111 rpm`` and the servo delivers that
or its top speed at the present supply, whichever is lower; 9.12 rad/s is the
top speed at 12 V (9.15 rad/s, a common bench supply; the report does not
state its supply), and at the recommended 9.6 V the servo tops out at 7.2.
The register's full scale, 114 rpm (11.9 rad/s), is reachable at no valid
supply.
"""

from __future__ import annotations

import math
import sys
from dataclasses import asdict, dataclass, fields
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser, from PyPI
    import tomli as tomllib

__all__ = ["ServoParams", "ServoEffects", "EFFECT_RANGES", "EFFECT_NULLS", "DERIVED", "REPORT_VISCOUS_NM_S_RAD", "derive_holding_slope",
           "derive_total_inertia"]

#: The report's back-driven viscous coefficient (section 2.3.2), not used by the model (see module docstring).
REPORT_VISCOUS_NM_S_RAD = 0.15

#: Data-sheet points the derivation matches (data sheet p. 3; report table 1).
HOLDING_TORQUE_NM = {7.0: 1.18, 10.0: 1.62}
MOVE_60_DEG_S = {7.0: 0.269, 10.0: 0.196}


def derive_holding_slope(static_friction_nm: float) -> float:
    """``c = eta k / R`` from the holding torques (step 1 of the derivation)."""
    volts = list(HOLDING_TORQUE_NM)
    return sum(v * (HOLDING_TORQUE_NM[v] - static_friction_nm) for v in volts) / sum(v * v for v in volts)


def derive_total_inertia(slope_nm_v: float, static_friction_nm: float, accel_rad_s2: float, supply_v: float) -> float:
    """Total inertia at the output from the peak acceleration at full drive (step 2)."""
    return (slope_nm_v * supply_v - static_friction_nm) / accel_rad_s2


_C = derive_holding_slope(0.13)
#: Step 2's closed-form bound, kept to show the fit below it.
_J_BOUND = derive_total_inertia(_C, 0.13, 200.0, 9.6)
#: Total inertia fitted so the simulated peak acceleration at 9.6 V is 200 rad/s**2 (step 2).
_J = 3.4e-3
#: Rotor and gears over the fit above, from real AX-12A overshoots within the report's 15 % (step 2).
_GEARS_SCALE = 1.3
#: Damping ``c k + b`` at full drive, fitted to the simulated 60-degree move times (step 3).
_D = 0.185
_B = 0.0
_K = (_D - _B) / _C
#: The derived values, as stored (rounded) in the defaults below.
DERIVED = {
    "holding_slope_nm_v": _C,
    "total_inertia_bound_kg_m2": _J_BOUND,
    "total_inertia_kg_m2": _J,
    "damping_nm_s_rad": _D,
    "torque_constant_nm_a": _K,
    "gearbox_efficiency": _C * 6.3 / _K,
    "rotor_inertia_reflected_kg_m2": (_J - 1.35e-4) * _GEARS_SCALE,
}


#: Valid range of each effect, inclusive ``(low, high)``; a bound of None is open (strictly above / below).
#: Wide enough for any servo the diagnosis could meet, narrow enough to catch a unit mix-up (degrees for
#: radians, milliseconds for seconds, a register value for a fraction).
EFFECT_RANGES: dict[str, tuple[float, float]] = {
    "backlash_rad": (0.0, 0.5),
    "sensing_delay_s": (0.0, 1.0),
    "command_delay_s": (0.0, 1.0),
    "drive_ceiling_fraction": (0.0, 1.0),
    "arm_weight_moment_nm": (-10.0, 10.0),
    "extra_compliance_margin_units": (0.0, 254.0),
    "position_offset_units": (-1023.0, 1023.0),
    "position_gain": (0.5, 1.5),
}
#: The value at which each effect does nothing (the same as absent).
EFFECT_NULLS: dict[str, float] = {name: 0.0 for name in EFFECT_RANGES} | {"drive_ceiling_fraction": 1.0, "position_gain": 1.0}
#: Effects whose low bound is excluded (a zero ceiling would be no drive at all).
_OPEN_LOW = ("drive_ceiling_fraction",)


@dataclass(frozen=True)
class ServoEffects:
    """Physical effects beyond the base model, as the diagnosis names them; None means "absent".

    Why it exists: ``python -m firmware_model.diagnose`` fits these (the effect
    library, :mod:`firmware_model.diagnose.effects`) and writes them into the
    one ``params.toml`` beside the base parameters (TOML table ``[effects]``),
    so the fitted twin is served as it was fitted.  Each field names the
    library effect it carries; :class:`~firmware_model.physical.PhysicalModel`
    reproduces it as the diagnosis's batched simulator defines it.  An absent
    effect leaves the model bit for bit as it is without this class.
    """

    #: Gear play between motor and output, where the pot sits (effect ``backlash``): the output follows
    #: the motor only once the slack is taken up, and the controller sees the output.
    backlash_rad: float | None = None
    #: Latency from the output shaft to Present Position / Speed / Load (effect ``delay``): each reads the
    #: shaft this long ago (position interpolated between steps, speed and load from the latch then).
    sensing_delay_s: float | None = None
    #: Latency from a register write to the firmware acting on it (the other reading of effect ``delay``;
    #: the diagnosis cannot tell them apart from a trace, and writes the sensing one).
    command_delay_s: float | None = None
    #: The drive tops out at this fraction of full whatever Torque Limit says (effect ``torque_saturation``:
    #: a weak supply or a current-limited driver); the firmware's overload check still uses the register.
    drive_ceiling_fraction: float | None = None
    #: Weight moment ``m g L`` of an arm on the horn (effect ``gravity_load``; convention in
    #: :mod:`firmware_model.motor`; negative: the arm points the other way).  ``set_arm`` replaces it.
    arm_weight_moment_nm: float | None = None
    #: Added to both Compliance Margin registers (effect ``compliance_deadband``).
    extra_compliance_margin_units: float | None = None
    #: Present Position reads ``gain (x - 511.5) + 511.5 + offset`` for the true ``x`` in units, and Present
    #: Speed ``gain`` times the true one (effect ``sensor_offset_gain``); the controller sees the true ``x``.
    position_offset_units: float | None = None
    position_gain: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is None:
                continue
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"ServoEffects.{f.name} must be a finite number or absent (None), got {value!r}")
            low, high = EFFECT_RANGES[f.name]
            below = value <= low if f.name in _OPEN_LOW else value < low
            if below or value > high:
                interval = f"{'(' if f.name in _OPEN_LOW else '['}{low:g}, {high:g}]"
                raise ValueError(f"ServoEffects.{f.name} must lie in {interval}, got {value!r}")

    def present(self) -> dict[str, float]:
        """The effects that are set, name -> value."""
        return {f.name: float(getattr(self, f.name)) for f in fields(self) if getattr(self, f.name) is not None}

    def value(self, name: str, null: float) -> float:
        """``name``'s value, or ``null`` when absent."""
        value = getattr(self, name)
        return null if value is None else float(value)

    @classmethod
    def from_table(cls, table: dict, where: str = "[effects]") -> "ServoEffects":
        """From a parsed TOML table; unknown keys and non-numbers raise ``ValueError`` naming ``where``."""
        known = {f.name for f in fields(cls)}
        for key, value in table.items():
            if key not in known:
                raise ValueError(f"{where}: unknown effect {key!r}; known: {', '.join(sorted(known))}")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{where}: effect {key!r} must be a number, got {type(value).__name__}")
        try:
            return cls(**{k: float(v) for k, v in table.items()})
        except OverflowError:  # an integer too large for a float
            raise ValueError(f"{where}: an effect's value is too large to be a number: "
                             f"{', '.join(k for k, v in table.items() if not _fits_float(v))}") from None
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from exc


def _fits_float(value: int | float) -> bool:
    """Whether a TOML number converts to a float (an integer of hundreds of digits does not)."""
    try:
        float(value)
    except OverflowError:
        return False
    return True


#: Keys older parameter files carry that no longer mean anything, read and ignored (key -> why).
RETIRED_KEYS = {
    "wheel_speed_gain_s_rad": "wheel mode has no speed loop: Moving Speed sets the output (e-manual)",
}


@dataclass(frozen=True)
class ServoParams:
    """One AX-12+ in SI units; every default names its source."""

    #: Gear ratio: data sheet 254:1; the report's tooth count gives 253.97 (table 2).
    gear_ratio: float = 254.0
    #: Winding resistance, ohm: report section 3.3 (figure 3.3 table).
    winding_resistance_ohm: float = 6.3
    #: Motor constant referred to the output (torque per amp = back-EMF per rad/s): derived, step 3.
    torque_constant_nm_a: float = round(DERIVED["torque_constant_nm_a"], 4)
    #: Forward efficiency of the gear train: derived, step 3 (eta = c R / k).
    gearbox_efficiency: float = round(DERIVED["gearbox_efficiency"], 4)
    #: Rotor and gear inertia reflected to the output (J_motor * 254**2 and the gears): derived, step 2.
    rotor_inertia_reflected_kg_m2: float = round(DERIVED["rotor_inertia_reflected_kg_m2"], 7)
    #: Load inertia: the report's camera, section 3.3.
    load_inertia_kg_m2: float = 1.35e-4
    #: Static (breakaway) friction at the output: report section 2.3.2, 2.4 N at 54 mm.
    static_friction_nm: float = 0.13
    #: Coulomb friction: the report's fit failed (negative); below static as physics needs, used in step 3.
    coulomb_friction_nm: float = 0.10
    #: Viscous friction of the powered drive: residual of step 3 (the report's 0.15 is discussed above).
    viscous_friction_nm_s_rad: float = _B
    #: Stribeck velocity: the report's Matlab fit, figure 2.7 (1.025 rad/s).
    stribeck_velocity_rad_s: float = 1.025
    #: Share of the against-the-drive (braking) winding current the H-bridge passes, 0..1: 0, the motor
    #: coasts until the drive reverses (freewheeling diodes), fitted to a real AX-12A's overshoot and dip;
    #: 1, a bridge that shorts the winding (see firmware_model.motor).
    bridge_braking_fraction: float = 0.0
    #: Setpoint generator's acceleration: report section 2.3.4, figure 2.13 (about 200 rad/s**2).
    max_acceleration_rad_s2: float = 200.0
    #: Setpoint generator's dead zone: report section 3.1 (eps = 0.001 rad).
    setpoint_eps_rad: float = 0.001
    #: Supply voltage, V: data sheet recommends 9.6 V (8 NiMH cells).
    supply_voltage_v: float = 9.6
    #: Supply range the constants are valid for: data sheet 7-10 V, AX-12A up to 12 V.
    min_supply_voltage_v: float = 7.0
    max_supply_voltage_v: float = 12.0
    #: Present Speed / Present Load update period: report figure 2.5 (9-10 samples at 100 Hz).
    sample_hold_s: float = 0.1
    #: Ambient temperature, degrees C: ours (a warm room; matches KinematicModel).
    ambient_temperature_c: float = 30.0
    #: Thermal resistance node to ambient, K/W: estimate for a small motor in a plastic case.
    thermal_resistance_k_w: float = 20.0
    #: Heat capacity of the node, J/K: estimate (motor and case, some tens of grams).
    heat_capacity_j_k: float = 15.0
    #: Overload must hold this long before the alarm: ours (e-manual gives none).
    overload_delay_s: float = 0.5
    #: Below this output speed a shaft counts as stalled for the overload alarm: ours.
    stall_speed_rad_s: float = 0.2
    #: Effects beyond the base model (backlash, delays, ...), all absent by default; see ServoEffects.
    effects: ServoEffects = ServoEffects()

    def __post_init__(self) -> None:
        if not isinstance(self.effects, ServoEffects):
            raise ValueError(f"ServoParams.effects must be a ServoEffects, got {type(self.effects).__name__}")
        for f in fields(self):
            if f.name == "effects":
                continue
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"ServoParams.{f.name} must be a finite number, got {value!r}")
        positive = (
            "gear_ratio", "winding_resistance_ohm", "torque_constant_nm_a", "gearbox_efficiency",
            "rotor_inertia_reflected_kg_m2", "stribeck_velocity_rad_s", "max_acceleration_rad_s2",
            "setpoint_eps_rad", "supply_voltage_v", "min_supply_voltage_v", "sample_hold_s",
            "thermal_resistance_k_w", "heat_capacity_j_k", "stall_speed_rad_s",
        )
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"ServoParams.{name} must be positive, got {getattr(self, name)!r}")
        for name in ("load_inertia_kg_m2", "coulomb_friction_nm", "viscous_friction_nm_s_rad", "overload_delay_s"):
            if getattr(self, name) < 0:
                raise ValueError(f"ServoParams.{name} must be >= 0, got {getattr(self, name)!r}")
        if self.static_friction_nm < self.coulomb_friction_nm:
            raise ValueError(
                f"ServoParams.static_friction_nm ({self.static_friction_nm}) must be >= "
                f"coulomb_friction_nm ({self.coulomb_friction_nm})"
            )
        if self.gearbox_efficiency > 1:
            raise ValueError(f"ServoParams.gearbox_efficiency must be <= 1, got {self.gearbox_efficiency!r}")
        if not 0.0 <= self.bridge_braking_fraction <= 1.0:
            raise ValueError(f"ServoParams.bridge_braking_fraction must lie in [0, 1], got {self.bridge_braking_fraction!r}")
        if self.max_supply_voltage_v < self.min_supply_voltage_v:
            raise ValueError("ServoParams.max_supply_voltage_v must be >= min_supply_voltage_v")
        # What the registers can show: Present Voltage is one byte of 0.1 V, Present Temperature one byte of
        # degrees C (a reading past them would wrap round); the speed/load hold is the firmware's ~10 Hz update,
        # a fraction of a second (the diagnosis tries every phase of it, millisecond by millisecond).
        bounds = {"max_supply_voltage_v": (0.0, 25.5), "ambient_temperature_c": (0.0, 150.0), "sample_hold_s": (0.0, 1.0)}
        for name, (low, high) in bounds.items():
            if not low <= getattr(self, name) <= high:
                raise ValueError(f"ServoParams.{name} must lie in [{low:g}, {high:g}], got {getattr(self, name)!r}")
        self.check_supply(self.supply_voltage_v, "supply_voltage_v")

    def check_supply(self, volts: float, name: str = "supply voltage") -> None:
        """Raise ``ValueError`` unless ``volts`` is within the range the constants are valid for."""
        if not (self.min_supply_voltage_v <= volts <= self.max_supply_voltage_v):
            raise ValueError(
                f"{name} {volts!r} V is outside the valid {self.min_supply_voltage_v}-{self.max_supply_voltage_v} V"
            )

    # ------------------------------------------------------------------ derived quantities
    @property
    def total_inertia_kg_m2(self) -> float:
        """Everything the output shaft accelerates."""
        return self.rotor_inertia_reflected_kg_m2 + self.load_inertia_kg_m2

    @property
    def holding_slope_nm_v(self) -> float:
        """Stall torque per supply volt, ``eta k / R``."""
        return self.gearbox_efficiency * self.torque_constant_nm_a / self.winding_resistance_ohm

    def stall_torque_nm(self, supply_v: float) -> float:
        """Motor torque at full drive and zero speed."""
        return self.holding_slope_nm_v * supply_v

    def holding_torque_nm(self, supply_v: float) -> float:
        """External torque a powered stalled servo resists: stall torque plus static friction."""
        return self.stall_torque_nm(supply_v) + self.static_friction_nm

    def top_speed_rad_s(self, supply_v: float) -> float:
        """Steady speed at full drive against the servo's own friction (Stribeck part neglected)."""
        c = self.holding_slope_nm_v
        return max(c * supply_v - self.coulomb_friction_nm, 0.0) / (
            c * self.torque_constant_nm_a + self.viscous_friction_nm_s_rad
        )

    def supply_for_top_speed_v(self, speed_rad_s: float) -> float:
        """The supply at which :meth:`top_speed_rad_s` is ``speed_rad_s`` (its inverse)."""
        c = self.holding_slope_nm_v
        return (speed_rad_s * (c * self.torque_constant_nm_a + self.viscous_friction_nm_s_rad) + self.coulomb_friction_nm) / c

    def no_load_speed_rad_s(self, supply_v: float) -> float:
        """Speed at which the back-EMF equals the supply (no friction at all)."""
        return supply_v / self.torque_constant_nm_a

    # ------------------------------------------------------------------ from a data sheet
    @classmethod
    def from_datasheet(
        cls,
        stall_torque_nm: float,
        no_load_speed_rad_s: float,
        voltage_v: float,
        *,
        gear_ratio: float,
        min_supply_voltage_v: float,
        max_supply_voltage_v: float,
        stall_current_a: float | None = None,
        gearbox_efficiency: float | None = None,
        static_friction_nm: float | None = None,
        coulomb_friction_nm: float | None = None,
        viscous_friction_nm_s_rad: float = 0.0,
        rotor_inertia_at_motor_kg_m2: float | None = None,
    ) -> "ServoParams":
        """Parameters for another servo model from its data sheet, derived as the AX-12 defaults are.

        The data sheet's stall torque ``S`` and no-load speed ``N`` at ``voltage_v`` are read as a
        dynamometer reads them at full drive: ``S`` where the loaded shaft comes to rest (motor torque
        less static friction, ``S = c V - t_s``), ``N`` where the unloaded shaft settles against its own
        friction (``N = (c V - t_c) / (c k + b)``, Stribeck part gone at speed; :meth:`top_speed_rad_s`).
        So ``c = (S + t_s) / V`` (step 1 of the module's derivation) and ``k = ((c V - t_c) / N - b) / c``
        (step 3).  The third number is the winding resistance, either from the data sheet's stall
        current (``R = V / I``: at stall the winding carries all of it; the electronics' tens of mA
        are neglected) with the efficiency following as ``eta = c R / k``, or, where that would put
        ``eta`` above one (a current-limited stall figure), from a given ``gearbox_efficiency``
        (``R = eta k / c``).  Exactly one of ``stall_current_a`` and ``gearbox_efficiency`` is given.

        What no data sheet gives is taken from the AX-12 defaults, scaled: friction as the same share
        of the stall torque as the AX-12's at its recommended supply (unless given), the rotor inertia
        as the AX-12's at the motor (unless given) times ``gear_ratio**2``; the firmware and thermal
        constants as they are.  A sheet whose figures cannot come from this model (efficiency above one, friction above
        the stall torque) gets a ``ValueError``.
        """
        base = cls()
        base_stall_nm = base.stall_torque_nm(base.supply_voltage_v) - base.static_friction_nm
        t_s = stall_torque_nm * base.static_friction_nm / base_stall_nm if static_friction_nm is None else static_friction_nm
        t_c = stall_torque_nm * base.coulomb_friction_nm / base_stall_nm if coulomb_friction_nm is None else coulomb_friction_nm
        if (stall_current_a is None) == (gearbox_efficiency is None):
            raise ValueError("from_datasheet needs exactly one of stall_current_a and gearbox_efficiency")
        c = (stall_torque_nm + t_s) / voltage_v
        if c * voltage_v <= t_c:
            raise ValueError(f"Coulomb friction {t_c} N m leaves no drive at {voltage_v} V")
        k = ((c * voltage_v - t_c) / no_load_speed_rad_s - viscous_friction_nm_s_rad) / c
        if k <= 0:
            raise ValueError(f"viscous friction {viscous_friction_nm_s_rad} N m s/rad alone exceeds the no-load damping")
        if stall_current_a is not None:
            resistance = voltage_v / stall_current_a
            efficiency = c * resistance / k
            if efficiency > 1:
                raise ValueError(
                    f"stall current {stall_current_a} A at {voltage_v} V with {stall_torque_nm} N m and "
                    f"{no_load_speed_rad_s:.3f} rad/s needs a gearbox efficiency of {efficiency:.2f} (> 1): the sheet's "
                    "stall current is not the winding's (current-limited); give gearbox_efficiency instead"
                )
        else:
            efficiency = float(gearbox_efficiency)
            resistance = efficiency * k / c
        rotor_at_motor = (base.rotor_inertia_reflected_kg_m2 / base.gear_ratio**2 if rotor_inertia_at_motor_kg_m2 is None
                          else rotor_inertia_at_motor_kg_m2)
        return cls(
            gear_ratio=gear_ratio,
            winding_resistance_ohm=resistance,
            torque_constant_nm_a=k,
            gearbox_efficiency=efficiency,
            rotor_inertia_reflected_kg_m2=rotor_at_motor * gear_ratio**2,
            load_inertia_kg_m2=0.0,
            static_friction_nm=t_s,
            coulomb_friction_nm=t_c,
            viscous_friction_nm_s_rad=viscous_friction_nm_s_rad,
            supply_voltage_v=voltage_v,
            min_supply_voltage_v=min_supply_voltage_v,
            max_supply_voltage_v=max_supply_voltage_v,
        )

    # ------------------------------------------------------------------ TOML
    def to_toml(self, path: str | Path, comments: tuple[str, ...] = ()) -> None:
        """Write the base fields as a flat table of numbers, then the present effects as ``[effects]``.

        TOML by hand (no writer dependency); absent effects are listed as comments, so a
        reader sees what could be set.  ``comments`` go at the top, one ``#`` line each.
        """
        lines = ["# ax12emu servo parameters, SI units (firmware_model.params.ServoParams)"]
        lines += [f"# {line}" for line in comments]
        lines += [f"{name} = {float(value)!r}" for name, value in asdict(self).items() if name != "effects"]
        lines += ["", "# Effects beyond the base model (firmware_model.params.ServoEffects); a missing key is absent.",
                  "[effects]"]
        present = self.effects.present()
        for f in fields(ServoEffects):
            lines.append(f"{f.name} = {present[f.name]!r}" if f.name in present else f"# {f.name}: absent")
        Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")

    @classmethod
    def from_toml(cls, path: str | Path) -> "ServoParams":
        """Read the base table and an optional ``[effects]`` table (older files have none).

        Missing keys keep their defaults (effects: absent); unknown, non-numeric or
        out-of-range keys raise ``ValueError`` naming the file and the key.
        """
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8-sig"))  # a BOM (Windows editors) is no statement
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"{path}: not valid TOML: {exc}") from exc
        except UnicodeDecodeError as exc:
            raise ValueError(f"{path}: not UTF-8 text: {exc}") from exc
        table = data.pop("effects", {})
        if not isinstance(table, dict):
            raise ValueError(f"{path}: 'effects' must be a table ([effects]), got {type(table).__name__}")
        effects = ServoEffects.from_table(table, f"{path}: [effects]")
        known = {f.name for f in fields(cls)} - {"effects"}
        effect_names = {f.name for f in fields(ServoEffects)}
        data = {k: v for k, v in data.items() if k not in RETIRED_KEYS}
        for key, value in data.items():
            if key in effect_names:
                raise ValueError(f"{path}: {key!r} is an effect: put it under [effects]")
            if key not in known:
                raise ValueError(f"{path}: unknown key {key!r}")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{path}: key {key!r} must be a number, got {type(value).__name__}")
        too_large = [k for k, v in data.items() if not _fits_float(v)]
        if too_large:
            raise ValueError(f"{path}: too large to be a number: {', '.join(too_large)}")
        try:
            return cls(**{k: float(v) for k, v in data.items()}, effects=effects)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from exc
