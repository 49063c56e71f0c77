"""An X-series trace replayed through the X-series firmware model over its physics: the search's simulator for X servos.

Why it exists: the discrepancy workflow compares a measured trace with the model; for an X-series
servo (Protocol 2.0) the model is :func:`firmware_model.xseries.firmware.build_x_servo`'s firmware over
:class:`~firmware_model.xseries.physics.XPhysics`, built from the data sheet the trace's metadata
carries (:data:`.trace.X_META`).  The trace's writes and reads go through the same closed loop as the
BAM log replay (:func:`firmware_model.xseries.closed_loop.run_closed_loop`): each command change is
written at its ``command_t`` (or its row's ``t``), the registers are read at each row's ``t``.

Knobs (what the effect library, :data:`.effects.X_LIBRARY`, changes): :data:`SIM_KNOBS` need a new
replay (physics parameters, the load on the horn, a PWM ceiling, a reading latency: the firmware is
read ``delay_s`` earlier, between two steps by linear interpolation); :data:`SENSING_KNOBS` change only
the position read (an offset and a gain about the middle of the turn), applied afterwards.

:class:`XEvaluator` answers the search's questions (:class:`.evaluate.Evaluator`'s interface): one
replay per distinct set of simulation knobs, remembered, so a profile over sensing knobs costs nothing.
A replay is scalar Python, about 5 us per 1 ms step while the shaft moves: a 3 s trace is ~20 ms.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..params import ServoParams
from ..units import RAD_PER_POSITION_UNIT
from ..xseries.closed_loop import Write, run_closed_loop
from ..xseries.firmware import PULSE_RAD, PULSES_PER_REV, XFirmware
from ..xseries.interface import OperatingMode, XCommands
from ..xseries.physics import XPhysics, XPhysicsParams
from ..xseries.profile import VELOCITY_UNIT_PULSES_S
from .evaluate import Evaluator
from .metrics import CHANNELS
from .phases import classify
from .schedule import Schedule, Segment
from .trace import Trace, TraceFormatError, x_meta_error

__all__ = ["physics_with", "XSetup", "SIM_KNOBS", "SENSING_KNOBS", "x_null_knobs", "replay_x", "simulate_x", "XEvaluator", "MIDDLE_PULSES"]

#: Sensor gain acts about the middle of the turn (Present Position 2048).
MIDDLE_PULSES = PULSES_PER_REV // 2
#: Registers a trace's metadata may set, with the values used when it does not (the XL330's factory gains,
#: e-manual XL330-M288 control table; Goal PWM at PWM Limit and Goal Current at Current Limit, as at power-on).
REGISTER_DEFAULTS = dict(operating_mode=OperatingMode.POSITION, drive_mode=0, position_p_gain=400, position_i_gain=0,
                         position_d_gain=0, feedforward_1st_gain=0, feedforward_2nd_gain=0, pwm_limit=885,
                         current_limit=1750, velocity_limit=445)
#: Knobs that need a new replay, with their null values (None: from the physics parameters).
SIM_KNOBS = {"gearbox_efficiency": None, "coulomb_friction_nm": None, "stribeck_friction_nm": None,
             "stribeck_velocity_rad_s": None, "load_friction_motor": None, "load_friction_external": None,
             "extra_inertia_kg_m2": 0.0, "arm_weight_nm": 0.0, "drive_ceiling": 1.0,
             "delay_s": 0.0}
#: Knobs that change only the position read.
SENSING_KNOBS = {"position_offset_units": 0.0, "position_gain": 1.0}
_X_CHANNELS = ("present_position", "present_velocity", "present_current", "present_pwm")


@dataclasses.dataclass(frozen=True)
class XSetup:
    """What the trace's metadata says about the servo and its set-up."""

    physics: XPhysicsParams
    current_unit_a: float | None
    position_output_scale: float
    registers: dict
    supply_v: float
    load_inertia_kg_m2: float
    gravity_moment_nm: float
    gravity_zero_pulses: float
    model: str

    @classmethod
    def from_trace(cls, trace: Trace, physics: XPhysicsParams | None = None) -> XSetup:
        """From ``trace.meta`` (``physics``: start from these instead of the data sheet's); ``TraceFormatError`` if it
        lacks one, or a key or value :data:`.trace.X_META` refuses (a trace read from a file was checked as read,
        at its line; one made in memory is checked here)."""
        meta = trace.meta
        if trace.servo != "x":
            raise TraceFormatError("not an X-series trace (#@ servo = \"x\")")
        bad = x_meta_error(meta)
        if bad is not None:
            raise TraceFormatError(bad[1])
        if physics is None:
            for key in ("gear_ratio", "ratings"):
                if key not in meta:
                    raise TraceFormatError(f"an X-series trace needs #@ {key} (the data sheet the model is built from)")
            try:
                physics = XPhysicsParams.from_datasheet(gear_ratio=float(meta["gear_ratio"]),
                                                        ratings=[tuple(r) for r in meta["ratings"]])
            except (TypeError, ValueError) as exc:
                raise TraceFormatError(f"bad data sheet in the metadata: {exc}") from None
        registers = {k: int(meta.get(k, v)) for k, v in REGISTER_DEFAULTS.items()}
        ratings = meta.get("ratings") or [[12.0]]
        supply = float(meta.get("supply_v", ratings[0][0]))
        unit = meta.get("current_unit_a", 0.001)
        return cls(physics, None if unit is None else float(unit), float(meta.get("position_output_scale", 1.0)),
                   registers, supply, float(meta.get("load_inertia_kg_m2", 0.0)),
                   float(meta.get("gravity_moment_nm", 0.0)), float(meta.get("gravity_zero_pulses", MIDDLE_PULSES)),
                   str(meta.get("model", "X-series")))


def x_null_knobs(physics: XPhysicsParams) -> dict[str, float]:
    """Every knob at the value that reproduces ``physics`` exactly."""
    out = {k: float(getattr(physics, k) if v is None else v) for k, v in SIM_KNOBS.items()}
    out.update(SENSING_KNOBS)
    return out


def physics_with(p: XPhysicsParams, knobs: dict[str, float]) -> XPhysicsParams:
    """``p`` with the knobs that are physics parameters applied (the fitted physics of a diagnosis's final knobs)."""
    return dataclasses.replace(
        p, torque_constant_nm_a=knobs["gearbox_efficiency"] * p.back_emf_v_s_rad,
        coulomb_friction_nm=max(knobs["coulomb_friction_nm"], 0.0),
        stribeck_friction_nm=max(knobs["stribeck_friction_nm"], 0.0),
        stribeck_velocity_rad_s=max(knobs["stribeck_velocity_rad_s"], 1e-3),
        load_friction_motor=max(knobs["load_friction_motor"], 0.0),
        load_friction_external=max(knobs["load_friction_external"], 0.0),
        inertia_kg_m2=max(p.inertia_kg_m2 + knobs["extra_inertia_kg_m2"], 1e-7))


def _commands(trace: Trace, setup: XSetup, i: int, ceiling: float) -> XCommands:
    regs = setup.registers
    pwm_limit = int(round(min(regs["pwm_limit"], 885) * min(max(ceiling, 0.0), 1.0)))
    row = {name: int(trace[name][i]) for name in ("profile_velocity", "profile_acceleration") if trace.has(name)}
    return XCommands(
        torque_enable=int(trace["torque_enable"][i]) if trace.has("torque_enable") else 1,
        operating_mode=regs["operating_mode"], drive_mode=regs["drive_mode"], goal_position=int(trace["goal_position"][i]),
        position_p_gain=regs["position_p_gain"], position_i_gain=regs["position_i_gain"],
        position_d_gain=regs["position_d_gain"], feedforward_1st_gain=regs["feedforward_1st_gain"],
        feedforward_2nd_gain=regs["feedforward_2nd_gain"], goal_pwm=pwm_limit, pwm_limit=pwm_limit,
        goal_current=regs["current_limit"], current_limit=regs["current_limit"], velocity_limit=regs["velocity_limit"],
        min_position_limit=0, max_position_limit=PULSES_PER_REV - 1, max_voltage_limit=255, min_voltage_limit=0,
        temperature_limit=100, **row)


def write_times(trace: Trace) -> tuple[np.ndarray, np.ndarray]:
    """(rows whose commands change, when each is written, s after the first row): ``command_t`` or the row's ``t``."""
    rows = trace.change_rows()
    rows = rows[rows < len(trace) - 1]
    at = trace.t[rows].copy()
    if trace.records_command_times:
        at = np.clip(trace["command_t"][rows] - trace["t"][0], 0.0, None)
    at[0] = 0.0
    return rows, at


def simulate_x(trace: Trace, setup: XSetup, knobs: dict[str, float], write_s: np.ndarray | None = None,
               step_s: float = 1e-3) -> dict[str, np.ndarray]:
    """The registers read at each row under ``knobs`` (all of :data:`SIM_KNOBS`), shape (n,) per channel.

    ``write_s``: when each command change is written (default :func:`write_times`).
    """
    rows, at = write_times(trace)
    if write_s is not None:
        at = np.asarray(write_s, dtype=float)
    ceiling = knobs["drive_ceiling"]
    physics = XPhysics(physics_with(setup.physics, knobs), supply_v=setup.supply_v,
                       angle_rad=float(trace["present_position"][0]) * PULSE_RAD)
    physics.set_load(inertia_kg_m2=setup.load_inertia_kg_m2, gravity_torque_nm=setup.gravity_moment_nm + knobs["arm_weight_nm"],
                     gravity_zero_rad=setup.gravity_zero_pulses * PULSE_RAD)
    model = XFirmware(physics, current_unit_a=setup.current_unit_a, step_s=step_s,
                      position_output_scale=setup.position_output_scale)

    def world(i: int):
        def apply(m: XFirmware) -> None:
            if trace.has("voltage"):
                m.set_supply_v(float(trace["voltage"][i]) / 10.0)
            if trace.has("external_torque_nm"):
                m.set_external_torque(float(trace["external_torque_nm"][i]))
        return apply

    writes = [Write(float(a) + 1e-9, _commands(trace, setup, int(i), ceiling), goal_written=True, world=world(int(i)))
              for i, a in zip(rows, at)]
    order = np.argsort(at, kind="stable")
    writes = [writes[j] for j in order]
    t = trace.t
    delay = knobs["delay_s"]
    if delay == 0.0:
        sensed = run_closed_loop(model, writes, [float(x) + 1e-9 for x in t])
        return {ch: np.array([getattr(s, ch) for s in sensed], dtype=float) for ch in _X_CHANNELS}
    # A latency between the shaft and the reading: the registers of ``delay`` ago, between two steps linearly.
    where = np.maximum(t - delay, 0.0) / step_s
    lo = np.floor(where + 1e-9)
    frac = where - lo
    reads = np.ravel(np.stack([lo, lo + 1], axis=1)) * step_s + 1e-9
    sensed = run_closed_loop(model, writes, list(reads))
    out = {}
    for ch in _X_CHANNELS:
        v = np.array([getattr(s, ch) for s in sensed], dtype=float).reshape(-1, 2)
        out[ch] = v[:, 0] + (v[:, 1] - v[:, 0]) * frac
    return out


def _sense(sim: dict[str, np.ndarray], knobs: dict[str, float], channels: list[str]) -> np.ndarray:
    pos = sim["present_position"]
    g, off = knobs["position_gain"], knobs["position_offset_units"]
    if g != 1.0 or off != 0.0:
        pos = MIDDLE_PULSES + (pos - MIDDLE_PULSES) * g + off
    cols = {**sim, "present_position": pos}
    return np.stack([np.rint(cols[ch]) for ch in channels], axis=1)


def replay_x(trace: Trace, physics: XPhysicsParams | None = None, knobs: dict[str, float] | None = None) -> Trace:
    """The simulated trace: ``trace`` with its sensed columns replaced by the model's (``knobs``: effects applied)."""
    setup = XSetup.from_trace(trace, physics)
    k = {**x_null_knobs(setup.physics), **(knobs or {})}
    sim = simulate_x(trace, setup, k)
    channels = [ch for ch in _X_CHANNELS if trace.has(ch)]
    z = _sense(sim, k, channels)
    return trace.with_columns(**{ch: z[:, i].astype(np.int64) for i, ch in enumerate(channels)})


class XEvaluator(Evaluator):
    """:class:`.evaluate.Evaluator` for an X-series trace: the same questions, answered by :func:`simulate_x`."""

    def __init__(self, trace: Trace, params: XPhysicsParams | None = None, step_s: float = 1e-3) -> None:
        self.trace = trace
        self.setup = XSetup.from_trace(trace, params if isinstance(params, XPhysicsParams) else None)
        self.params = self.setup.physics
        self.schedule = _schedule(trace, self.setup, step_s)
        # phases from the goals through the AX-12's setpoint generator (where a gap lies, and the rows at rest whose
        # noise scales the channels): at the profile's speed, or the no-load speed where there is no profile (the
        # X-series trajectory then steps to the goal), with no acceleration limit
        self.phases = classify(self.schedule, ServoParams(max_acceleration_rad_s2=1e6))
        self._measure(trace, [ch for ch in CHANNELS if ch in _X_CHANNELS and trace.has(ch)])
        self.null = x_null_knobs(self.params)
        self.onsets = None
        self._sims: dict[tuple, dict[str, np.ndarray]] = {}
        self.simulations = 0
        self.columns = 0

    def run(self, requests: list[dict[str, float]], onsets: np.ndarray | None = None) -> np.ndarray:
        """Simulated channels for each knob set, shape (M, n, C) (see :meth:`.evaluate.Evaluator.run`)."""
        full = [{**self.null, **r} for r in requests]
        dt = self.schedule.step_s
        shared = self.onsets if onsets is None else onsets
        out = []
        for j, r in enumerate(full):
            on = None if shared is None else (np.asarray(shared)[:, j] if np.ndim(shared) == 2 else np.asarray(shared))
            key = tuple(r[k] for k in SIM_KNOBS) + (None if on is None else np.asarray(on, dtype=np.int64).tobytes(),)
            sim = self._sims.get(key)
            if sim is None:
                write_s = None if on is None else np.asarray(on, dtype=float) * dt
                sim = simulate_x(self.trace, self.setup, r, write_s, dt)
                if len(self._sims) > 512:
                    self._sims.clear()
                self._sims[key] = sim
                self.simulations += 1
                self.columns += 1
            out.append(_sense(sim, r, self.channels))
        return np.stack(out).astype(float)


def _schedule(trace: Trace, setup: XSetup, step_s: float) -> Schedule:
    """The trace's command changes as :class:`.schedule.Schedule` segments (for the phases and the onset fit)."""
    t = trace.t
    steps = np.floor(t / step_s + 1e-9).astype(np.int64)
    rows, at = write_times(trace)
    first = np.minimum(np.floor(at / step_s + 1e-9).astype(np.int64), steps[-1])
    first = np.maximum.accumulate(first)
    if trace.records_command_times:
        bounds = np.stack([first, first], axis=1)
    else:
        bounds = np.stack([first, steps[rows + 1]], axis=1)
        bounds[0] = first[0]
    no_load = setup.physics.no_load_speed_rad_s(setup.supply_v)
    p0 = int(trace["present_position"][0])
    segments = []
    for j, i in enumerate(rows):
        last = int(first[j + 1]) if j + 1 < len(rows) else int(steps[-1])
        pv = int(trace["profile_velocity"][i]) if trace.has("profile_velocity") else 0
        speed = min(pv * VELOCITY_UNIT_PULSES_S * PULSE_RAD, no_load) if pv > 0 else no_load
        ext = float(trace["external_torque_nm"][i]) if trace.has("external_torque_nm") else 0.0
        # the phases' setpoint starts from initial_position_raw in the AX-12's units: goals are put in that frame
        goal_rad = (float(trace["goal_position"][i]) - p0) * PULSE_RAD + p0 * float(RAD_PER_POSITION_UNIT)
        segments.append(Segment(int(first[j]), last, goal_rad, speed, 1.0, ext, setup.supply_v, replan=True))
    return Schedule(step_s, tuple(segments), steps, p0, bounds)

