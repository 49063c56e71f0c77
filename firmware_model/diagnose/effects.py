"""The effect library: named, physical extensions of the base model, as data.

Why it exists: the search (:mod:`.search`) must choose among *explanations*,
not among free curve-fitting terms, so each candidate is a physical effect
with a one-line mechanism, the residual signature it leaves (so a report can
say why it was named), parameters with units, bounds and a null value, and a
mapping onto the batched simulator's knobs (:mod:`.batch`).  At its null
value every effect maps to the base knobs exactly, so "no effect" is the
base model bit for bit (a test checks each one).

``grid`` values seed the coarse screen and the multi-start for parameters the
residual is not smooth in (delay, hold period, play, dead band; ``starts``
fits from several grid points, for Stribeck friction, whose stick-slip makes
the cost surface rough);
``extra_inertia``'s grid starts at 0.0005 kg m**2, a tenth of the model's own, so that bars of 12-17 % of it
(the real AX-12A steps', 0.73e-3 and 1.0e-3 kg m**2) are screened.  It started at 0.002 while the model's
reading was compared rounded: the finer grid then named 3.3e-4 on a clean live recording, whose timing a small
inertia absorbed; compared unrounded, and the rests by the reading's unit (:mod:`.evaluate`), clean live
recordings name nothing from it (see the diagnosis page, "Against a real AX-12A").  It is fitted from its three
best grid points: on a single step its cost is rough (a fit of a bar of 3e-3 kg m**2 started at 0.002 once
stopped at 2.4e-3, at three times the cost of the one started at 0.003);
``fd_step`` is the finite-difference step of the fit (a position unit's worth
for the quantised ones).  ``tested`` names the parameters whose joint 95 %
confidence region must exclude the null for the effect to be accepted.
``sensing`` effects change only what is read, so they need no re-simulation.

Every value is *added to* what the starting parameters already have (a
twin's ``[effects]`` table, :data:`.batch.EFFECT_FIELD_KNOBS`; nothing by
default): a fit started from a twin with gear play looks for more play, or
for something else, not for the play it already simulates.

``hidden`` ranges (what :mod:`.synthetic` draws for "measured" data) are
effects a user would want found *and* that leave a signature above the
sensor: the pot reads whole units with about 0.25 units of noise, so even the
true model leaves a position gap of about 0.5 units RMS, and an effect must
open a gap of about 2 units RMS before a 70 % shrink is possible at all.
Two effects are nearly invisible to the position channel at small values,
so their ranges start where they are not (measured on 10 s traces, seeds
7-9, gap with the effect vs. the noise floor):

* ``backlash``: the pot sits on the output and the loop closes on it, so
  play shows only in transients (reversals, settling); 0.025 rad (1.4 deg)
  opens a 1.1-1.3 unit gap (floor 0.5-0.6: not separable to 70 %), 0.05
  rad 2.5 units.  Range 0.045-0.08 rad (2.6-4.6 deg): a worn plastic gear
  train or a loose horn spline, the play a user sees by hand.
* ``stribeck_friction``: breakaway shows when the shaft starts from rest
  and in where it stops short, so its tests add :data:`.excitation.BREAKAWAY`;
  with 6 s of those (14 s in all), 0.15 N m extra opens a 1.05-1.25 unit
  gap (ratio to the floor 0.4-0.6), 0.25 N m 1.9-2.1 (0.21-0.30), 0.35 N m
  2.9-3.1 (0.14-0.21).  Range 0.25-0.45 N m above the base 0.13 N m
  breakaway (a dry, dirty or over-tightened gear train: 3-4.5 x nominal,
  25-40 % of the stall torque); fitted to >= 74 % shrink on seeds 7-12.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Param", "Effect", "LIBRARY", "BASE_PARAMS", "apply_effects", "X_LIBRARY", "X_BASE_PARAMS"]


@dataclass(frozen=True)
class Param:
    """One parameter of an effect; the unit is in the name."""

    name: str
    null: float
    low: float
    high: float
    grid: tuple[float, ...]
    fd_step: float
    #: Range the dataset maker draws hidden values from (a clearly present effect).
    hidden: tuple[float, float]


@dataclass(frozen=True)
class Effect:
    """A named model extension."""

    name: str
    physics: str
    signature: str
    params: tuple[Param, ...]
    #: values -> {knob: new value}, given the knobs so far.
    knobs: Callable[[dict[str, float], dict[str, float]], dict[str, float]]
    tested: tuple[str, ...]
    sensing: bool = False
    #: Whether least squares refines the grid's best point (False: grid only, e.g. a hold period in 10 ms steps).
    smooth: bool = True
    #: Least-squares starts: from the best this many grid points, keeping the best fit (a rough cost surface).
    starts: int = 1
    #: Function evaluations of each fit, as a multiple of the search's default (a rough surface needs more).
    effort: int = 1
    #: Recording nuisances (:data:`.nuisance.PROFILERS`) whose best value depends on this effect's values: the
    #: search re-fits them at each of its grid points and holds them through the fit from that point (a hold
    #: period screened at the base fit's phase would look wrong only because the phase belongs to another
    #: period; a latency shifts the hold's latches, so the base fit's phase has absorbed it).
    nuisances: tuple[str, ...] = ()
    #: Only offered on traces that record when commands were sent (``command_t``): without them the effect is
    #: indistinguishable from when the commands took effect, which the base fit estimates (:mod:`.nuisance`).
    needs_command_times: bool = False

    def null_values(self) -> dict[str, float]:
        """The parameter values that reproduce the base model."""
        return {p.name: p.null for p in self.params}

    def param(self, name: str) -> Param:
        """The parameter called ``name``."""
        return next(p for p in self.params if p.name == name)


def _add(knob: str, value: float, base: dict[str, float]) -> float:
    return base[knob] + value if value else base[knob]


def _coulomb(v, k):
    return {"coulomb_friction_nm": _add("coulomb_friction_nm", v["extra_coulomb_nm"], k),
            "static_friction_nm": _add("static_friction_nm", v["extra_coulomb_nm"], k)}


def _stribeck(v, k):
    return {"static_friction_nm": _add("static_friction_nm", v["extra_static_nm"], k),
            "stribeck_velocity_rad_s": v["stribeck_velocity_rad_s"]}


_HOLD_GRID = tuple(round(0.02 + 0.01 * i, 2) for i in range(29))

#: The shared base parameters re-fitted with every candidate: unit-to-unit spread of the motor's strength.
BASE_PARAMS = (Param("gearbox_efficiency", 0.7594, 0.55, 0.95, (0.7594,), 0.01, (0.74, 0.78)),)

#: Effects by identifier.
LIBRARY: dict[str, Effect] = {e.name: e for e in (
    Effect(
        "coulomb_friction",
        "Extra sliding friction in the gear train (dry gears, a stiff horn bearing) adds a constant torque against motion.",
        "Slower cruising at full drive, late arrival, a larger steady offset after small steps; load higher while moving.",
        (Param("extra_coulomb_nm", 0.0, -0.08, 0.6, (-0.05, 0.05, 0.1, 0.2, 0.3, 0.45), 0.01, (0.08, 0.3)),),
        _coulomb, ("extra_coulomb_nm",)),
    Effect(
        "stribeck_friction",
        "Breakaway (static) friction above the sliding level, fading with speed over the Stribeck velocity.",
        "Stick-slip on small steps and slow moves, offsets at rest, a kick at start; little change at full speed.",
        (Param("extra_static_nm", 0.0, -0.03, 0.6, (0.05, 0.1, 0.15, 0.2, 0.27, 0.35, 0.45), 0.01, (0.25, 0.45)),
         Param("stribeck_velocity_rad_s", 1.025, 0.05, 3.0, (0.1, 0.2, 0.35, 0.5, 0.7, 1.0), 0.05, (0.1, 0.5))),
        _stribeck, ("extra_static_nm",), starts=5, effort=2),
    Effect(
        "backlash",
        "Gear play: the output (where the pot sits) follows the motor only once the slack is taken up.",
        "Position lags at every reversal by the play; hunting around the goal; load swings with no position change.",
        (Param("backlash_rad", 0.0, 0.0, 0.12, (0.005, 0.01, 0.02, 0.03, 0.045, 0.06, 0.08), 0.003, (0.045, 0.08)),),
        lambda v, k: {"backlash_rad": _add("backlash_rad", v["backlash_rad"], k)}, ("backlash_rad",)),
    Effect(
        "delay",
        "Latency between the shaft and the reading (or equivalently the command): ADC, firmware loop, bus.",
        "Residual proportional to speed, antisymmetric across each move, zero at rest; all channels shifted in time.",
        (Param("delay_s", 0.0, -0.01, 0.15, (0.005, 0.01, 0.02, 0.03, 0.05, 0.08), 0.002, (0.01, 0.05)),),
        lambda v, k: {"delay_s": _add("delay_s", v["delay_s"], k)}, ("delay_s",), sensing=True, needs_command_times=True,
        nuisances=("hold_phase",)),
    Effect(
        "sample_hold",
        "Present Speed / Load are latched at another period than the model's 0.1 s (the firmware's own timer).",
        "Position fits; speed and load residuals are staircases whose steps come at the wrong spacing.",
        (Param("hold_s", 0.1, 0.02, 0.3, _HOLD_GRID, 0.01, (0.05, 0.2)),),
        lambda v, k: {"hold_s": v["hold_s"]}, ("hold_s",), sensing=True, smooth=False, nuisances=("hold_phase",)),
    Effect(
        "torque_saturation",
        "The drive tops out below full (a lower torque limit, a weak supply or a current-limited driver).",
        "Acceleration and holding torque capped: slower starts, sag under external load, load pinned at a ceiling.",
        (Param("drive_ceiling", 1.0, 0.1, 1.0, (0.3, 0.4, 0.5, 0.6, 0.7, 0.85), 0.01, (0.3, 0.7)),),
        lambda v, k: {"drive_ceiling": min(v["drive_ceiling"], k["drive_ceiling"])}, ("drive_ceiling",)),
    Effect(
        "gravity_load",
        "An arm's weight on the horn: torque m g L cos(angle - horizontal at raw 512), pulling CW near the centre.",
        "Position-dependent sag at rest and asymmetric up/down moves; load offset that varies with position.",
        (Param("arm_weight_nm", 0.0, -0.3, 1.2, (0.1, 0.2, 0.35, 0.5, 0.7), 0.01, (0.15, 0.6)),),
        lambda v, k: {"arm_weight_nm": _add("arm_weight_nm", v["arm_weight_nm"], k)}, ("arm_weight_nm",)),
    Effect(
        "extra_inertia",
        "More mass on the shaft than the model has (a horn, a wheel, a link): slower to accelerate and brake.",
        "Lag while accelerating, overshoot when braking and settling; cruise speed unchanged.",
        (Param("extra_inertia_kg_m2", 0.0, -0.002, 0.06, (0.0005, 0.001, 0.002, 0.003, 0.005, 0.0075, 0.01, 0.015, 0.02, 0.035),
               0.0005, (0.004, 0.02)),),
        lambda v, k: {"extra_inertia_kg_m2": _add("extra_inertia_kg_m2", v["extra_inertia_kg_m2"], k)},
        ("extra_inertia_kg_m2",), starts=3),
    Effect(
        "compliance_deadband",
        "The firmware's dead band is wider than the Compliance Margin register says.",
        "Settles several units short of the goal (on the side it came from); zero load at those offsets.",
        (Param("extra_margin_units", 0.0, 0.0, 14.0, (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 11.0), 0.5, (2.0, 8.0)),),
        lambda v, k: {"extra_margin_units": _add("extra_margin_units", v["extra_margin_units"], k)},
        ("extra_margin_units",)),
    Effect(
        "sensor_offset_gain",
        "The reported position is offset/scaled against the one the controller settles on (a re-mounted or re-calibrated pot, an external encoder).",
        "Constant or position-proportional offset at every rest, in every phase; speed scaled by the gain.",
        (Param("position_offset_units", 0.0, -30.0, 30.0, (-8.0, -4.0, 0.0, 4.0, 8.0), 0.5, (3.0, 10.0)),
         Param("position_gain", 1.0, 0.85, 1.15, (0.97, 1.0, 1.03), 0.002, (0.01, 0.04))),
        lambda v, k: {"position_offset_units": _add("position_offset_units", v["position_offset_units"], k),
                      "position_gain": k["position_gain"] * v["position_gain"]},
        ("position_offset_units", "position_gain"), sensing=True),
)}


def apply_effects(knobs: dict[str, float], chosen: dict[str, dict[str, float]],
                  library: dict[str, Effect] | None = None) -> dict[str, float]:
    """``knobs`` with each chosen effect (identifier -> parameter values, of ``library``: default the AX-12's) applied in turn."""
    out = dict(knobs)
    for name, values in chosen.items():
        out.update((library or LIBRARY)[name].knobs(values, out))
    return out


# ---------------------------------------------------------------------------------------------------------------
# X-series servos (Protocol 2.0): the same effects where they map onto the X-series physics, as data.
#
# The simulator is the X-series firmware over its physics (:mod:`.xreplay`), whose knobs are physics
# parameters and set-up: each effect below says which.  Scales are an XL330's (stall torque about 0.5 N m,
# rotor and gears 1.8e-3 kg m**2 at the output, Coulomb friction 0.012 N m, 4096 pulses per turn).
#
# Effects of the AX-12 library not offered here, and why:
# * ``backlash``: the X-series physics has one rigid shaft (its encoder and motor see the same angle); play
#   needs a second body, which it does not have.
# * ``sample_hold``: an X-series servo reads every register fresh (no 10 Hz hold of velocity or load).
# * ``compliance_deadband``: the AX-12's compliance control; the X-series firmware is a PID.

def _x_add(knob: str, value: float, base: dict[str, float]) -> float:
    return base[knob] + value if value else base[knob]


#: The shared base parameter of X-series servos: the gearbox's efficiency k_t / k_e (unit-to-unit strength).
X_BASE_PARAMS = (Param("gearbox_efficiency", 0.884, 0.4, 1.0, (0.884,), 0.01, (0.85, 0.92)),)

#: X-series effects by identifier (the descriptions are the AX-12 library's where the mechanism is the same).
X_LIBRARY: dict[str, Effect] = {e.name: e for e in (
    Effect(
        "coulomb_friction", LIBRARY["coulomb_friction"].physics, LIBRARY["coulomb_friction"].signature,
        (Param("extra_coulomb_nm", 0.0, -0.011, 0.3, (0.005, 0.01, 0.02, 0.04, 0.08), 0.002, (0.02, 0.08)),),
        lambda v, k: {"coulomb_friction_nm": _x_add("coulomb_friction_nm", v["extra_coulomb_nm"], k)},
        ("extra_coulomb_nm",)),
    Effect(
        "stribeck_friction", LIBRARY["stribeck_friction"].physics, LIBRARY["stribeck_friction"].signature,
        (Param("extra_static_nm", 0.0, -0.005, 0.3, (0.01, 0.02, 0.04, 0.08), 0.002, (0.03, 0.1)),
         Param("stribeck_velocity_rad_s", 1.0, 0.05, 3.0, (0.1, 0.3, 1.0), 0.05, (0.1, 0.5))),
        lambda v, k: {"stribeck_friction_nm": _x_add("stribeck_friction_nm", v["extra_static_nm"], k),
                      "stribeck_velocity_rad_s": v["stribeck_velocity_rad_s"]},
        ("extra_static_nm",), starts=3, effort=2),
    Effect(
        "load_friction",
        "Gear friction growing with the torque the gears carry: a share of the motor's torque when it drives, of the "
        "load's when the load back-drives (BAM's load-dependent friction, XPhysicsParams.load_friction_motor/_external).",
        "A drive that looks weak only under load: slow, short moves against gravity or an inertia being accelerated, "
        "PWM high for the motion it makes; unloaded cruising nearly unchanged.",
        (Param("extra_motor_share", 0.0, -0.1, 0.9, (0.05, 0.1, 0.2, 0.4), 0.01, (0.1, 0.4)),
         Param("extra_external_share", 0.0, -0.1, 0.9, (0.0, 0.1, 0.3), 0.01, (0.05, 0.3))),
        lambda v, k: {"load_friction_motor": _x_add("load_friction_motor", v["extra_motor_share"], k),
                      "load_friction_external": _x_add("load_friction_external", v["extra_external_share"], k)},
        ("extra_motor_share", "extra_external_share")),
    Effect(
        "delay", LIBRARY["delay"].physics, LIBRARY["delay"].signature,
        (Param("delay_s", 0.0, -0.01, 0.15, (0.005, 0.01, 0.02, 0.04, 0.08), 0.002, (0.01, 0.05)),),
        lambda v, k: {"delay_s": _x_add("delay_s", v["delay_s"], k)}, ("delay_s",), needs_command_times=True),
    Effect(
        "torque_saturation",
        "The drive tops out below full: a lower PWM Limit than the metadata says, a weak supply or a current-limited driver.",
        LIBRARY["torque_saturation"].signature,
        (Param("drive_ceiling", 1.0, 0.1, 1.0, (0.3, 0.5, 0.7, 0.85), 0.01, (0.3, 0.7)),),
        lambda v, k: {"drive_ceiling": min(v["drive_ceiling"], k["drive_ceiling"])}, ("drive_ceiling",)),
    Effect(
        "gravity_load",
        "An arm's weight on the horn, hanging down at gravity_zero_pulses (default 2048): torque -m g L sin(angle - hanging).",
        "Position-dependent offset at rest growing with the distance from where the arm hangs; PWM / current offset "
        "that varies with position; asymmetric up and down moves.",
        (Param("arm_weight_nm", 0.0, -0.4, 0.6, (0.02, 0.05, 0.1, 0.2, 0.35), 0.005, (0.05, 0.25)),),
        lambda v, k: {"arm_weight_nm": _x_add("arm_weight_nm", v["arm_weight_nm"], k)}, ("arm_weight_nm",), effort=2),
    Effect(
        "extra_inertia", LIBRARY["extra_inertia"].physics, LIBRARY["extra_inertia"].signature,
        (Param("extra_inertia_kg_m2", 0.0, -0.0015, 0.05, (0.0005, 0.001, 0.002, 0.004, 0.008, 0.015), 0.0002,
               (0.002, 0.01)),),
        lambda v, k: {"extra_inertia_kg_m2": _x_add("extra_inertia_kg_m2", v["extra_inertia_kg_m2"], k)},
        ("extra_inertia_kg_m2",)),
    Effect(
        "sensor_offset_gain",
        "The reported position is offset/scaled against the shaft's (a horn mounted off its spline, an external encoder).",
        LIBRARY["sensor_offset_gain"].signature,
        (Param("position_offset_units", 0.0, -200.0, 200.0, (-20.0, -10.0, -5.0, 0.0, 5.0, 10.0, 20.0), 0.5, (5.0, 30.0)),
         Param("position_gain", 1.0, 0.85, 1.15, (0.97, 1.0, 1.03), 0.002, (0.01, 0.04))),
        lambda v, k: {"position_offset_units": _x_add("position_offset_units", v["position_offset_units"], k),
                      "position_gain": k["position_gain"] * v["position_gain"]},
        ("position_offset_units", "position_gain"), sensing=True),
)}
