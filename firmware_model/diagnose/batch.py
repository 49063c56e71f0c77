"""Many parameter sets of one servo at once: the fast simulator the search runs on.

Why it exists: a fit needs hundreds of simulations of a 20 s trace (20,000
steps at 1 kHz), and a numpy call costs about a microsecond whatever the
array size.  So K parameter sets run as the K "servos" of one vectorised
loop, with *per-servo parameter arrays* (which
:class:`~firmware_model.physical.PhysicalModel` cannot take): one pass
simulates a whole grid, or a point and its finite-difference neighbours.

It is built from the model's own step functions
(:func:`~firmware_model.setpoint.setpoint_velocity`,
:func:`~firmware_model.controller.symmetric_compliance_drive`,
:func:`~firmware_model.motor.shaft_speed_step`, ...) in the same order as
:func:`~firmware_model.stepping.generic_steps`, so with every knob at its null value it gives the
same registers as :func:`.replay.replay` (a test checks it).  Scope: joint
mode, compliance control with symmetric registers, torque on: what a trace
records.

Dynamic knobs (change the motion, need a simulation): see :data:`DYNAMIC_KNOBS`.
Sensing knobs (change only what is read, applied afterwards by
:func:`sample`, so no re-simulation): see :data:`SENSING_KNOBS`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..controller import compliance_plan, symmetric_compliance_drive
from ..motor import DryFriction, arm_gravity_torque_nm, bridge_current_a, shaft_speed_step
from ..params import ServoParams
from ..setpoint import apply_dead_zone, setpoint_velocity
from ..units import RAD_PER_POSITION_UNIT, RAD_S_PER_SPEED_UNIT
from .replay import DEFAULT_REGISTERS
from .schedule import Schedule, Segment

__all__ = ["DYNAMIC_KNOBS", "SENSING_KNOBS", "EFFECT_FIELD_KNOBS", "Record", "simulate", "sample", "null_knobs",
           "THERMAL_PERIOD_STEPS"]

#: Knobs that change the motion, with their null values (or None: take it from ServoParams).
DYNAMIC_KNOBS = {
    "gearbox_efficiency": None,
    "coulomb_friction_nm": None,
    "static_friction_nm": None,
    "stribeck_velocity_rad_s": None,
    "extra_inertia_kg_m2": 0.0,
    "backlash_rad": 0.0,
    "drive_ceiling": 1.0,
    "arm_weight_nm": 0.0,
    "extra_margin_units": 0.0,
}
#: Knobs that change only the readings, with their null values (None: from ServoParams).
SENSING_KNOBS = {
    "delay_s": 0.0,
    "hold_s": None,
    "hold_phase_s": 0.0,
    "position_offset_units": 0.0,
    "position_gain": 1.0,
}
#: The model's held registers update only on a thermal period (10 ms at 1 kHz), see PhysicalModel._run.
THERMAL_PERIOD_STEPS = 10
_UNIT = float(RAD_PER_POSITION_UNIT)
_SPEED_UNIT = float(RAD_S_PER_SPEED_UNIT)


def load_dv(xp, angle_rad, weight_nm, step_over_inertia):
    """The arm's gravity as a speed change per step, in the model's form (``-(m g L dt / J) cos``).

    A seam: :mod:`.synthetic` adds an out-of-library torque here.
    """
    return arm_gravity_torque_nm(xp, angle_rad, weight_nm * step_over_inertia)


#: The knob that reproduces each :class:`~firmware_model.params.ServoEffects` field a params file may carry
#: (a twin written by the diagnosis, ``[effects]``), so a fit started from that file simulates it as it is served.
#: ``command_delay_s`` has none: the batch shifts readings, not commands (:func:`null_knobs` refuses it).
EFFECT_FIELD_KNOBS = {
    "backlash_rad": "backlash_rad",
    "sensing_delay_s": "delay_s",
    "drive_ceiling_fraction": "drive_ceiling",
    "arm_weight_moment_nm": "arm_weight_nm",
    "extra_compliance_margin_units": "extra_margin_units",
    "position_offset_units": "position_offset_units",
    "position_gain": "position_gain",
}


def null_knobs(params: ServoParams) -> dict[str, float]:
    """Every knob at the value that reproduces ``params`` exactly, its ``effects`` included.

    Raises ``ValueError`` for an effect the batch cannot reproduce (a command delay).
    """
    out = {}
    for name, null in {**DYNAMIC_KNOBS, **SENSING_KNOBS}.items():
        if null is None:
            null = params.sample_hold_s if name == "hold_s" else getattr(params, name)
        out[name] = float(null)
    for field_name, value in params.effects.present().items():
        if field_name not in EFFECT_FIELD_KNOBS:
            raise ValueError(f"[effects] {field_name} cannot be simulated by the diagnosis (it shifts when commands "
                             "act, which a trace cannot tell from a reading latency): use sensing_delay_s")
        out[EFFECT_FIELD_KNOBS[field_name]] = float(value)
    return out


@dataclass
class Record:
    """Per-step history of K simulations: the angle the sensor sees and the drive, shape (steps + 1, K)."""

    angle: np.ndarray
    drive: np.ndarray


def _knob(knobs: dict, name: str, k: int, default: float) -> np.ndarray:
    return np.broadcast_to(np.asarray(knobs.get(name, default), dtype=float), (k,)).copy()


def simulate(schedule: Schedule, params: ServoParams, knobs: dict[str, np.ndarray], k: int,
             onsets: np.ndarray | None = None) -> Record:
    """Run K parameter sets (``knobs``: name -> scalar or array (K,); missing = null) over ``schedule``.

    ``onsets``: the step after which each segment's commands start, shape
    (segments,) or (segments, K) (default: each segment's ``first``), for a
    recording that does not say when commands were sent (:mod:`.nuisance`).
    """
    p, dt = params, schedule.step_s
    null = null_knobs(p)
    kn = {name: _knob(knobs, name, k, null[name]) for name in DYNAMIC_KNOBS}
    regs = DEFAULT_REGISTERS
    comp = compliance_plan(np.array([regs["ccw_compliance_margin"]]), np.array([regs["ccw_compliance_margin"]]),
                           np.array([regs["ccw_compliance_slope"]]), np.array([regs["ccw_compliance_slope"]]),
                           np.array([regs["punch"]]), np.array([1023]))
    margin = float(comp.ccw_margin[0]) + kn["extra_margin_units"]
    gain, punch = float(comp.ccw_gain[0]), float(comp.punch[0])
    a, inv_unit = p.max_acceleration_rad_s2, 1.0 / _UNIT
    k_r = p.torque_constant_nm_a / p.winding_resistance_ohm
    eta_k = kn["gearbox_efficiency"] * p.torque_constant_nm_a
    if np.all(kn["gearbox_efficiency"] == p.gearbox_efficiency):
        eta_k = np.full(k, p.gearbox_efficiency * p.torque_constant_nm_a)
    ts, tc, vs = kn["static_friction_nm"], kn["coulomb_friction_nm"], kn["stribeck_velocity_rad_s"]
    b = p.viscous_friction_nm_s_rad
    inertia = p.total_inertia_kg_m2 + kn["extra_inertia_kg_m2"]
    dt_j = np.where(kn["extra_inertia_kg_m2"] == 0, dt / p.total_inertia_kg_m2, dt / inertia)
    eta_k_dv = eta_k * dt_j  # as StepConstants.eta_k_dv
    friction = DryFriction.per_step(ts, tc, vs, dt_j)
    keep = 1.0 - b * dt_j if b else None
    braking = p.bridge_braking_fraction
    half_play = kn["backlash_rad"] / 2.0
    any_play = bool(np.any(half_play != 0))
    weight = kn["arm_weight_nm"]
    any_arm = bool(np.any(weight != 0))
    ceiling = kn["drive_ceiling"]

    n = schedule.n_steps
    rec_angle = np.empty((n + 1, k))
    rec_drive = np.empty((n + 1, k))
    angle = np.full(k, schedule.initial_position_raw * _UNIT)
    out = angle.copy()
    speed, ref, ref_vel, drive = np.zeros(k), angle.copy(), np.zeros(k), np.zeros(k)
    rec_angle[0], rec_drive[0] = out, drive
    eps = p.setpoint_eps_rad
    segs = schedule.segments
    if onsets is None:
        on = np.broadcast_to(schedule.nominal_onsets()[:, None], (len(segs), k))
    else:
        on = np.broadcast_to(np.asarray(onsets, dtype=np.int64).reshape(len(segs), -1), (len(segs), k))
    # each segment's commands start after its onset step, per simulation (the same step for all but a fitted onset)
    events: dict[int, list[tuple[Segment, np.ndarray | None]]] = {}
    for j, seg in enumerate(segs):
        for at in np.unique(on[j]):
            mask = on[j] == at
            events.setdefault(int(at), []).append((seg, None if mask.all() else mask))
    goal, vmax, limit, volts_r, ext = (np.zeros(k) for _ in range(5))
    ext_dv, any_ext = None, False
    for step in range(1, n + 1):
        starting = events.get(step - 1)
        if starting:
            for seg, mask in starting:
                new = (seg.goal_rad, seg.max_speed_rad_s, seg.limit, seg.supply_v / p.winding_resistance_ohm,
                       seg.external_torque_nm)
                if mask is None:
                    goal, vmax, limit, volts_r, ext = (np.full(k, v) for v in new)
                    if seg.replan:
                        ref = apply_dead_zone(ref, ref_vel, goal, eps)
                else:
                    goal, vmax, limit, volts_r, ext = (np.where(mask, v, old) for v, old in
                                                       zip(new, (goal, vmax, limit, volts_r, ext)))
                    if seg.replan:
                        ref = np.where(mask, apply_dead_zone(ref, ref_vel, goal, eps), ref)
            limit = np.minimum(limit, ceiling)
            any_ext = bool(np.any(ext != 0))
            ext_dv = ext * dt_j if any_ext else None
        ref_vel = setpoint_velocity(np, ref, ref_vel, goal, vmax, a, dt)
        ref = ref + ref_vel * dt
        angle = angle + speed * dt
        out = np.minimum(np.maximum(out, angle - half_play), angle + half_play) if any_play else angle
        error = ref * inv_unit - np.rint(out * inv_unit)
        drive, _ = symmetric_compliance_drive(np, error, margin, gain, punch, limit)
        current = drive * volts_r - k_r * speed
        if braking != 1.0:  # as generic_steps: the H-bridge's share of braking current
            current = bridge_current_a(current, drive, braking)
        applied_dv = current * eta_k_dv
        if any_ext:
            applied_dv = applied_dv + ext_dv
        if any_arm:
            applied_dv = applied_dv + load_dv(np, angle, weight, dt_j)
        speed = shaft_speed_step(np, speed, applied_dv, friction, keep)
        rec_angle[step] = out
        rec_drive[step] = drive
    return Record(rec_angle, rec_drive)


def sample(schedule: Schedule, record: Record, params: ServoParams, sensing: dict | None = None,
           columns: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Registers read at each row: ``present_position``, signed ``present_speed`` and ``present_load``, shape (n, M).

    ``columns`` picks which of the record's K simulations to read (default
    all); each sensing knob is a scalar or an array (M,), one per column.
    """
    cols = np.arange(record.angle.shape[1]) if columns is None else np.asarray(columns)
    m = len(cols)
    null = null_knobs(params)
    sn = {name: _knob(sensing or {}, name, m, null[name]) for name in SENSING_KNOBS}
    dt = schedule.step_s
    steps = schedule.sample_steps
    n_rec = record.angle.shape[0]
    pos = np.empty((len(steps), m), dtype=np.int64)
    spd = np.empty((len(steps), m), dtype=np.int64)
    load = np.empty((len(steps), m), dtype=np.int64)
    for j, c in enumerate(cols):
        ang, drv = record.angle[:, c], record.drive[:, c]
        delay_steps = sn["delay_s"][j] / dt
        if delay_steps == 0:
            x = ang[steps] / _UNIT
            read = steps
        else:  # a latency between the shaft and the reading: the angle of ``delay`` ago, interpolated
            where = np.clip(steps - delay_steps, 0, n_rec - 1)
            lo = np.floor(where).astype(np.int64)
            hi = np.minimum(lo + 1, n_rec - 1)
            x = (ang[lo] + (ang[hi] - ang[lo]) * (where - lo)) / _UNIT
            read = lo
        g, off = sn["position_gain"][j], sn["position_offset_units"][j]
        if g != 1.0 or off != 0.0:
            x = x * g + (511.5 * (1.0 - g) + off)
        pos[:, j] = np.clip(np.rint(x), 0, 1023).astype(np.int64)
        hold = max(1, int(round(sn["hold_s"][j] / dt)))
        phase = int(round(sn["hold_phase_s"][j] / dt)) % hold
        # the latest latch at or before each read; latches at phase + i * hold (> 0).  The model latches
        # only on a thermal period, so ServoParams.sample_hold_s should be a multiple of 10 ms.
        last = read - ((read - phase) % hold)
        valid = last > 0
        last_c = np.where(valid, last, 0)
        prev = np.maximum(last_c - hold, 0)
        period = hold * dt
        held_speed = np.where(valid, (ang[last_c] - ang[prev]) / period, 0.0) * g
        held_drive = np.where(valid, drv[last_c], 0.0)
        spd_mag = np.minimum(np.rint(np.abs(held_speed) / _SPEED_UNIT), 1023).astype(np.int64)
        spd[:, j] = np.where(held_speed < 0, -spd_mag, spd_mag)
        load_mag = np.minimum(np.rint(np.abs(held_drive) * 1023.0), 1023).astype(np.int64)
        load[:, j] = np.where(held_drive < 0, -load_mag, load_mag)
    return {"present_position": pos, "present_speed": spd, "present_load": load}

