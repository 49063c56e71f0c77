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

import threading
from array import array
from dataclasses import dataclass

import numpy as np

from ..backend import SCALAR
from ..controller import compliance_plan
from ..interface import POWER_UP
from ..motor import DryFriction, arm_gravity_torque_nm, rail_current_a
from ..params import ServoParams
from ..setpoint import apply_dead_zone, setpoint_velocity
from ..stepping import _clip as clip
from ..units import RAD_PER_POSITION_UNIT, RAD_S_PER_SPEED_UNIT
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

    The reference (the setpoint generator's output) depends on the commands
    and their onsets alone, never on the shaft or a knob, so it is stepped
    apart, once per distinct onset column, and kept for the next call on the
    same schedule (:func:`_reference_units`).  Where every shaft rests and
    neither a command nor the reference changes, a step repeats the one
    before exactly, so such runs are copied rather than stepped (looked for
    every :data:`REST_CHECK_EVERY` steps; a fifth to a third of a diagnosis
    trace's steps).  The shaft's step then runs in
    place, as :class:`~firmware_model.stepping.FusedNumpySteps` does and for
    the same reason (a numpy call costs about a microsecond, twice that when
    it converts a Python float or allocates): every constant broadcast to
    shape (K,) once, every call writing into a preallocated buffer, the
    same arithmetic in the same order as the step functions, so the records
    are those of :func:`~firmware_model.stepping.generic_steps` to the bit
    (a test compares them with :func:`.replay.replay`).
    """
    p, dt = params, schedule.step_s
    null = null_knobs(p)
    kn = {name: _knob(knobs, name, k, null[name]) for name in DYNAMIC_KNOBS}
    regs = POWER_UP
    comp = compliance_plan(np.array([regs["ccw_compliance_margin"]]), np.array([regs["ccw_compliance_margin"]]),
                           np.array([regs["ccw_compliance_slope"]]), np.array([regs["ccw_compliance_slope"]]),
                           np.array([regs["punch"]]), np.array([1023]))
    full = lambda value: np.full(k, float(value))  # noqa: E731
    margin = float(comp.ccw_margin[0]) + kn["extra_margin_units"]
    gain, punch = full(comp.ccw_gain[0]), full(comp.punch[0])
    k_r = full(p.torque_constant_nm_a / p.winding_resistance_ohm)
    eta_k = kn["gearbox_efficiency"] * p.torque_constant_nm_a
    if np.all(kn["gearbox_efficiency"] == p.gearbox_efficiency):
        eta_k = np.full(k, p.gearbox_efficiency * p.torque_constant_nm_a)
    ts, tc, vs = kn["static_friction_nm"], kn["coulomb_friction_nm"], kn["stribeck_velocity_rad_s"]
    b = p.viscous_friction_nm_s_rad
    inertia = p.total_inertia_kg_m2 + kn["extra_inertia_kg_m2"]
    dt_j = np.where(kn["extra_inertia_kg_m2"] == 0, dt / p.total_inertia_kg_m2, dt / inertia)
    eta_k_dv = eta_k * dt_j  # as StepConstants.eta_k_dv
    friction = DryFriction.per_step(ts, tc, vs, dt_j)
    # motor.shaft_speed_step's constants: viscous keep, Stribeck coefficient and height, Coulomb
    keep = 1.0 - b * dt_j if b else None
    strib = np.broadcast_to(friction.stribeck_coef_s2_rad2, (k,)).copy()
    stribeck_dv = np.broadcast_to(friction.static_dv_rad_s - friction.coulomb_dv_rad_s, (k,)).copy()
    coulomb_dv = np.broadcast_to(friction.coulomb_dv_rad_s, (k,)).copy()
    braking = p.bridge_braking_fraction
    # motor.bridge_current_a: None passes all braking current, ``zero`` none, else the share (as _NumpyConstants)
    zero = full(0.0)
    bridge_share = None if braking == 1.0 else zero if braking == 0.0 else full(braking)
    bridge_against = full(1.0 - braking)
    half_play = kn["backlash_rad"] / 2.0
    any_play = bool(np.any(half_play != 0))
    weight = kn["arm_weight_nm"]
    any_arm = bool(np.any(weight != 0))
    ceiling = kn["drive_ceiling"]
    step, inv_unit = full(dt), full(1.0 / _UNIT)

    n = schedule.n_steps
    segs = schedule.segments
    if onsets is None:
        on = np.broadcast_to(schedule.nominal_onsets()[:, None], (len(segs), k))
    else:
        on = np.broadcast_to(np.asarray(onsets, dtype=np.int64).reshape(len(segs), -1), (len(segs), k))
    ref_units, next_change = _reference_units(schedule, p, on)
    rec_angle = np.empty((n + 1, k))
    rec_drive = np.empty((n + 1, k))
    angle = np.full(k, schedule.initial_position_raw * _UNIT)
    out = angle.copy() if any_play else angle
    speed, drive = np.zeros(k), np.zeros(k)
    rec_angle[0], rec_drive[0] = out, drive
    events = _events(segs, on)
    limit, volts_r, ext = (np.zeros(k) for _ in range(3))
    ext_dv = None
    rint, exp, sign, minimum, maximum, heaviside = np.rint, np.exp, np.sign, np.minimum, np.maximum, np.heaviside
    i, start_speed = 0, speed
    while i < n:
        i += 1
        if not i % REST_CHECK_EVERY and next_change[i - 1] > i and not start_speed.any() and not speed.any():
            # Step i - 1 started and ended with every shaft still, and nothing changes before step
            # next_change[i - 1] (no command starts, no reference moves): each step until then repeats
            # it exactly, its position, error, drive and zero speed, so it is copied, not stepped.
            stop = next_change[i - 1]
            rec_angle[i:stop] = out
            rec_drive[i:stop] = drive
            i = stop - 1
            continue
        start_speed = speed
        starting = events.get(i - 1)
        if starting:
            for seg, mask in starting:
                new = (seg.limit, seg.supply_v / p.winding_resistance_ohm, seg.external_torque_nm)
                if mask is None:
                    limit, volts_r, ext = (np.full(k, v) for v in new)
                else:
                    limit, volts_r, ext = (np.where(mask, v, old) for v, old in zip(new, (limit, volts_r, ext)))
            limit = np.minimum(limit, ceiling)
            ext_dv = ext * dt_j if np.any(ext != 0) else None
        angle = angle + speed * step
        if any_play:  # the sensor's side of the gear play
            out = minimum(maximum(out, angle - half_play), angle + half_play)
        else:
            out = angle
        # controller.symmetric_compliance_drive, on the error in units; (d > 0) as 0.0 / 1.0 by heaviside
        error = ref_units[i] - rint(out * inv_unit)
        beyond = abs(error) - margin
        drive = minimum((punch + beyond * gain) * heaviside(beyond, zero), limit) * sign(error)
        current = drive * volts_r - k_r * speed
        if bridge_share is not None:  # motor.bridge_current_a, as generic_steps: the H-bridge's share of braking
            passes = heaviside(current * drive, zero)
            if ext_dv is not None or any_arm:  # motor.rail_current_a, as generic_steps: with a load that can overhaul
                rail = rail_current_a(np, k_r * speed, volts_r)
                if bridge_share is zero:
                    current = current * passes + rail * (1.0 - passes)
                else:
                    current = current * (bridge_share + bridge_against * passes) + rail * (bridge_against * (1.0 - passes))
            else:
                current = current * (passes if bridge_share is zero else bridge_share + bridge_against * passes)
        applied_dv = current * eta_k_dv
        if ext_dv is not None:
            applied_dv = applied_dv + ext_dv
        if any_arm:
            applied_dv = applied_dv + load_dv(np, angle, weight, dt_j)
        # motor.shaft_speed_step: the free speed, then dry friction (at the starting speed);
        # copysign(minimum(|free|, dry), free) is clip(free, -dry, dry), the same values in fewer calls
        free = applied_dv + (speed if keep is None else speed * keep)
        dry = coulomb_dv + stribeck_dv * exp(speed * speed * strib)
        speed = free - clip(free, -dry, dry)
        rec_angle[i] = out
        rec_drive[i] = drive
    return Record(rec_angle, rec_drive)


def _events(segs: tuple[Segment, ...], on: np.ndarray) -> dict[int, list[tuple[Segment, np.ndarray | None]]]:
    """Step -> the segments whose commands start after it, each with the columns it starts in (None: all)."""
    events: dict[int, list[tuple[Segment, np.ndarray | None]]] = {}
    for j, seg in enumerate(segs):
        for at in np.unique(on[j]):
            mask = on[j] == at
            events.setdefault(int(at), []).append((seg, None if mask.all() else mask))
    return events


#: :func:`simulate` looks for a run of repeated resting steps after every this many steps (a check costs
#: about two numpy calls, a step about thirty).
REST_CHECK_EVERY = 8
#: The setpoint generator's path from each state it was started in (see :func:`_reference_path`), for the
#: next call: (accel, step, ref, ref_vel, goal, max_speed) -> [refs, ref_vels, whether it ends at a fixed point].
_PATHS: dict = {}
#: Past this many paths the store is emptied (a diagnosis needs a few hundred; each is at most a segment long).
_PATHS_KEPT = 2048
#: Guards :data:`_PATHS`: a path is looked up, extended and read by one thread at a time.  Within a diagnosis
#: one simulation runs at a time (:class:`.evaluate.Lockstep`), but diagnoses run in threads side by side share
#: the store, and two threads extending one path interleaved their steps (IndexError, BufferError).
_PATHS_LOCK = threading.Lock()


def _reference_units(schedule: Schedule, params: ServoParams, on: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """The reference after each step, in position units, shape (n + 1, K): one column per onset column of ``on``;
    and for each step the next one at which a command starts or any reference moves (n + 1: none).

    Each distinct column of ``on`` (segments, K) is stepped as ``generic_steps``
    steps it: at each onset the segments starting there set goal and speed in
    turn (re-planning through the dead zone), then
    :func:`~firmware_model.setpoint.setpoint_velocity` runs until the next
    onset.  It runs on plain floats (:data:`~firmware_model.backend.SCALAR`:
    the same values as numpy's, as IEEE sums, products and square roots round
    alike), from paths kept across calls: a fit varies the knobs and the
    onsets, seldom the state a segment starts from.
    """
    cols, inverse = np.unique(on, axis=1, return_inverse=True)
    inverse = np.asarray(inverse).reshape(-1)
    a, eps, dt = params.max_acceleration_rad_s2, params.setpoint_eps_rad, schedule.step_s
    n, segs = schedule.n_steps, schedule.segments
    table = np.empty((n + 1, cols.shape[1]))
    start = schedule.initial_position_raw * _UNIT
    for g in range(cols.shape[1]):
        column = table[:, g]
        column[0] = start
        ref, vel, goal, vmax, done = start, 0.0, 0.0, 0.0, 0
        for j in sorted(range(len(segs)), key=lambda j: cols[j, g]):  # a stable sort: onset, then segment
            at = int(cols[j, g])
            if at >= n:  # acts on no step
                break
            if at > done:
                ref, vel = _reference_path(column, done, at, ref, vel, goal, vmax, a, dt)
                done = at
            seg = segs[j]
            goal, vmax = seg.goal_rad, seg.max_speed_rad_s
            if seg.replan:
                ref = float(apply_dead_zone(ref, vel, goal, eps))
        _reference_path(column, done, n, ref, vel, goal, vmax, a, dt)
    table *= 1.0 / _UNIT
    changes = np.zeros(n + 2, dtype=bool)
    changes[1:n + 1] = np.any(table[1:] != table[:-1], axis=1)
    starts = np.unique(cols) + 1  # a command starting after step ``at`` acts from step ``at + 1``
    changes[starts[(starts >= 1) & (starts <= n)]] = True
    changes[n + 1] = True
    at = np.where(changes, np.arange(n + 2), n + 1)
    next_change = np.minimum.accumulate(at[::-1])[::-1][1:].tolist()  # [i]: the first change after step i
    expanded = np.broadcast_to(table, (n + 1, len(inverse))) if table.shape[1] == 1 else table[:, inverse]
    return expanded, next_change


def _reference_path(column: np.ndarray, done: int, stop: int, ref: float, vel: float, goal: float, vmax: float,
                    a: float, dt: float) -> tuple[float, float]:
    """Write the reference (rad) after steps ``done + 1 .. stop`` into ``column``; return the state after ``stop``.

    A path that reaches a fixed point (a step that changes neither reference
    nor velocity: it rests on its goal) is stepped no further, since every
    step after it repeats it.
    """
    with _PATHS_LOCK:
        return _kept_path(column, done, stop, ref, vel, goal, vmax, a, dt)


def _kept_path(column: np.ndarray, done: int, stop: int, ref: float, vel: float, goal: float, vmax: float,
               a: float, dt: float) -> tuple[float, float]:
    """:func:`_reference_path`'s work, with :data:`_PATHS_LOCK` held."""
    key = (a, dt, ref, vel, goal, vmax)
    path = _PATHS.get(key)
    if path is None:
        if len(_PATHS) >= _PATHS_KEPT:
            _PATHS.clear()
        path = _PATHS[key] = [array("d"), array("d"), False]
    refs, vels, fixed = path
    count = stop - done
    if len(refs) < count and not fixed:
        r, v = (refs[-1], vels[-1]) if refs else (ref, vel)
        while len(refs) < count:
            v_next = setpoint_velocity(SCALAR, r, v, goal, vmax, a, dt)
            r_next = r + v_next * dt
            if r_next == r and v_next == v:
                path[2] = fixed = True
                break
            r, v = r_next, v_next
            refs.append(r)
            vels.append(v)
    have = min(count, len(refs))
    column[done + 1:done + 1 + have] = np.frombuffer(refs, count=have)
    if have == count:
        return (refs[count - 1], vels[count - 1]) if count else (ref, vel)
    last = (refs[-1], vels[-1]) if refs else (ref, vel)
    column[done + 1 + have:stop + 1] = last[0]
    return last


def sample(schedule: Schedule, record: Record, params: ServoParams, sensing: dict | None = None,
           columns: np.ndarray | None = None, rounded: bool = True) -> dict[str, np.ndarray]:
    """Registers read at each row: ``present_position``, signed ``present_speed`` and ``present_load``, shape (n, M).

    ``columns`` picks which of the record's K simulations to read (default
    all); each sensing knob is a scalar or an array (M,), one per column.
    ``rounded``: whole register units, as the servo reports them (a recording); False gives what the
    registers would hold before the rounding, as floats (a prediction to compare a recording with: the
    recording's rounding is part of its noise, :func:`.metrics.channel_scales`, and a rounded prediction
    would count it twice and make the cost a staircase in every parameter).
    """
    cols = np.arange(record.angle.shape[1]) if columns is None else np.asarray(columns)
    m = len(cols)
    null = null_knobs(params)
    sn = {name: _knob(sensing or {}, name, m, null[name]) for name in SENSING_KNOBS}
    dt = schedule.step_s
    steps = schedule.sample_steps
    n_rec = record.angle.shape[0]
    kind = np.int64 if rounded else float
    whole = np.rint if rounded else (lambda v: v)
    pos = np.empty((len(steps), m), dtype=kind)
    spd = np.empty((len(steps), m), dtype=kind)
    load = np.empty((len(steps), m), dtype=kind)
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
        pos[:, j] = np.clip(whole(x), 0, 1023)
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
        spd_mag = np.minimum(whole(np.abs(held_speed) / _SPEED_UNIT), 1023)
        spd[:, j] = np.where(held_speed < 0, -spd_mag, spd_mag)
        load_mag = np.minimum(whole(np.abs(held_drive) * 1023.0), 1023)
        load[:, j] = np.where(held_drive < 0, -load_mag, load_mag)
    return {"present_position": pos, "present_speed": spd, "present_load": load}

