"""Synthetic "measured" traces: a reference servo with hidden effects, read like real hardware.

Why it exists: the workflow can only be shown to work on data whose answer
is known.  The reference servo is the batched simulator (:mod:`.batch`, the
base model exactly when no effect is hidden) with some library effects (or
an out-of-library one) switched on at random values, a small unit-to-unit
spread of the motor's strength, and the imperfections of a real recording:
irregular sample times (timing jitter), small timestamp noise, noisy
potentiometer readings before quantisation, and the registers' quantisation;
with ``live=True`` also the traits of a real-time client's recording (see
:func:`make_trace`), which the workflow must fit without naming them.
The answer key is returned separately; the workflow never sees it.

Out-of-library effect available for negative tests: ``cogging`` (a torque
ripple ``A sin(n angle)`` on the shaft), which no library effect models.
"""

from __future__ import annotations

import numpy as np

from ..interface import Commands
from ..params import ServoParams
from ..physical import PhysicalModel
from .batch import null_knobs, sample, simulate
from .effects import BASE_PARAMS, LIBRARY, apply_effects
from .excitation import commands_at, program
from .schedule import compile_schedule
from .trace import Trace

__all__ = ["draw_effect", "make_trace", "OUT_OF_LIBRARY", "COGGING_AMPLITUDE_NM", "wizard_step_export", "WIZARD_TICK_MS",
           "step_response"]

#: Effects the library does not contain, for negative tests.
OUT_OF_LIBRARY = ("cogging",)
#: Cogging / gear-mesh ripple amplitude drawn for ``cogging``, N m at the output: 10-17 % of the ~1.5 N m stall
#: torque (a damaged gear tooth or a strongly cogging iron-core motor; the AX-12's motor is iron-cored).  It
#: moves the shaft 1.5-3 position units RMS: clearly visible, yet nothing in the library reproduces it.  At
#: 0.08-0.15 N m (tried first) it left about 1 unit, the size of the pot's own noise, on 10 s traces.
COGGING_AMPLITUDE_NM = (0.15, 0.25)


def draw_effect(name: str, rng: np.random.Generator) -> dict[str, float]:
    """Random values of a clearly present ``name`` effect (from each parameter's ``hidden`` range)."""
    if name == "cogging":
        return {"amplitude_nm": float(rng.uniform(*COGGING_AMPLITUDE_NM)),
                "periods_per_rad": float(rng.choice([20.0, 30.0]))}
    e = LIBRARY[name]
    if name == "sample_hold":
        return {"hold_s": float(rng.choice([h for h in np.round(np.arange(0.05, 0.21, 0.01), 2) if abs(h - 0.1) > 1e-9]))}
    if name == "sensor_offset_gain":
        lo, hi = e.param("position_offset_units").hidden
        glo, ghi = e.param("position_gain").hidden
        return {"position_offset_units": float(rng.choice([-1, 1]) * rng.uniform(lo, hi)),
                "position_gain": float(1.0 + rng.choice([-1, 1]) * rng.uniform(glo, ghi))}
    return {p.name: float(rng.uniform(*p.hidden)) for p in e.params}


def make_trace(hidden: dict[str, dict[str, float]], seed: int, duration_s: float = 20.0, rate_hz: float = 100.0,
               params: ServoParams = ServoParams(), base_spread: bool = True,
               breakaway_s: float = 0.0, live: bool = False) -> tuple[Trace, dict]:
    """A measured trace with ``hidden`` effects, and its answer key (effects, base values, noise).

    ``breakaway_s``: the last this many seconds run :data:`.excitation.BREAKAWAY` (see
    :func:`.excitation.program`).

    By default each command takes effect at its row's reading and the trace
    records it (``command_t``), and the speed/load hold starts with the
    trace.  ``live=True`` records like a real-time client through
    dynamixel-sdk instead: the hold's phase is random, each row is stamped
    after its read returns (0.5-2.5 ms late, varying row to row), each
    command goes out after that stamp (a further 0.3-4 ms, varying command to
    command) and the trace does not say when (no ``command_t``).
    """
    rng = np.random.default_rng(seed)
    period = 1.0 / rate_hz
    n = int(round(duration_s * rate_hz))
    t_true = np.arange(n) * period + np.concatenate([[0.0], rng.uniform(-0.3, 0.3, n - 1) * period])
    t_true = np.maximum.accumulate(t_true + np.arange(n) * 1e-9)
    cmd = commands_at(t_true, program(duration_s, breakaway_s))
    if live:  # stamps after the read returns; commands sent after the stamp, before the next read
        read_lag = rng.uniform(0.5e-3, 2.5e-3, n)
        sent = np.minimum(t_true + read_lag + rng.uniform(0.3e-3, 4e-3, n), np.append(t_true[1:], np.inf) - 1e-4)
    else:
        read_lag, sent = np.zeros(n), t_true
    trace = Trace({"t": t_true, "present_position": np.full(n, 512), "command_t": sent, **cmd})
    schedule = compile_schedule(trace, 1e-3, params.supply_voltage_v)
    knobs = null_knobs(params)
    base = {p.name: float(rng.uniform(*p.hidden)) if base_spread else getattr(params, p.name) for p in BASE_PARAMS}
    knobs.update(base)
    if live:
        knobs["hold_phase_s"] = float(rng.integers(0, int(round(params.sample_hold_s * 1000)))) / 1000.0
    library_part = {k: v for k, v in hidden.items() if k in LIBRARY}
    knobs = apply_effects(knobs, library_part)
    cog = hidden.get("cogging")
    if cog:
        record = _simulate_with_cogging(schedule, params, knobs, cog)
    else:
        record = simulate(schedule, params, {k: np.array([v]) for k, v in knobs.items()}, 1)
    # noisy pot: perturb the recorded angle before quantisation (the controller saw the clean one)
    noise_units = 0.25
    record.angle = record.angle + rng.normal(0.0, noise_units, record.angle.shape) * (np.pi * 300 / 180 / 1023)
    read = sample(schedule, record, params, {k: np.array([v]) for k, v in knobs.items()})
    t_logged = t_true + read_lag + rng.normal(0.0, 5e-5, n)
    t_logged[1:] = np.maximum(t_logged[1:], t_logged[:-1] + 1e-6)
    t_logged = np.round(t_logged, 6)
    recorded = {} if live else {"command_t": t_logged}
    measured = Trace({
        "t": t_logged, **cmd, **recorded,
        "present_position": read["present_position"][:, 0],
        "present_speed": read["present_speed"][:, 0],
        "present_load": read["present_load"][:, 0],
    }, comments=[f"synthetic trace, seed {seed}, firmware_model.diagnose.synthetic"])
    key = {"effects": hidden, "base": base, "seed": seed, "duration_s": duration_s, "rate_hz": rate_hz,
           "pot_noise_units": noise_units, "timestamp_noise_s": 5e-5, "breakaway_s": breakaway_s, "live": live,
           "hold_phase_s": knobs["hold_phase_s"], "command_sent_s": [float(x) for x in sent[trace.change_rows()]]}
    return measured, key


def _simulate_with_cogging(schedule, params, knobs, cog):
    """The reference simulation plus a cogging torque (out of library), via the external-torque path."""
    from . import batch

    amp, per = cog["amplitude_nm"], cog["periods_per_rad"]
    original = batch.load_dv

    def ripple(xp, angle, weight, step_over_inertia):
        return original(xp, angle, weight, step_over_inertia) + (amp * xp.sin(per * angle)) * step_over_inertia

    batch.load_dv = ripple
    try:
        kn = {k: np.array([v]) for k, v in knobs.items()}
        kn["arm_weight_nm"] = np.array([knobs["arm_weight_nm"] or 1e-300])  # force the arm path on
        return simulate(schedule, params, kn, 1)
    finally:
        batch.load_dv = original


#: DYNAMIXEL Wizard 2's graph tick (ms): each row is stamped on the first tick after its reading.
WIZARD_TICK_MS = 16.0
_WIZARD_HEADER = ("DYNAMIXEL Graph,2", "AX-12A,12", "ItemCount,1", "Present Position,#ffff00,0,1,0",
                  "Time[ms],Present Position")


def step_response(params: ServoParams, start: int, goal: int, duration_ms: int, moving_speed: int = 0) -> np.ndarray:
    """Present Position every ms after ``goal`` is written (index 0) to a served servo holding ``start``, at
    ``moving_speed`` (0: full speed), the e-manual's default compliance (margin 1, slope 32, punch 32), at the
    params' supply."""
    cmds = Commands.power_up(goal_position=goal, moving_speed=moving_speed)
    model = PhysicalModel(1, params=params, initial_position_raw=start)
    return np.array([float(start)] + [model.advance(i * 1e-3, cmds).present_position[0] for i in range(1, duration_ms + 1)])


def wizard_step_export(params: ServoParams, head_ms: float, tail_ms: float, phase_ms: float = 7.3, seed: int = 0,
                       noise_units: float = 0.25, read_every_ms: float = 20.0, start: int = 1, goal: int = 500,
                       moving_speed: int = 0) -> str:
    """One step of Goal Position as DYNAMIXEL Wizard 2 exports it (:mod:`.wizard`), the answer known.

    The served model (:class:`~firmware_model.physical.PhysicalModel`, not the diagnosis's own simulator) steps
    from ``start`` to ``goal`` at ``moving_speed`` (0: full speed) written ``head_ms`` after the first reading and is read every ``read_every_ms``
    from ``phase_ms`` on until ``tail_ms`` after the write, the pot's noise (``noise_units`` SD) added before the
    reading is rounded; each row is stamped on the first :data:`WIZARD_TICK_MS` tick after its reading, the
    newest winning a tick, as the Wizard stamps them.  Returns the export's text.
    """
    sim = step_response(params, start, goal, int(tail_ms) + 900, moving_speed)
    rng = np.random.default_rng(seed)
    rows = {}
    for read_ms in np.arange(phase_ms, head_ms + len(sim) - 1, read_every_ms):
        k = int(read_ms - head_ms)
        value = start if k < 0 else sim[min(k, len(sim) - 1)]
        rows[int(np.ceil(read_ms / WIZARD_TICK_MS) * WIZARD_TICK_MS)] = int(round(value + rng.normal(0.0, noise_units)))
    return "\n".join([*_WIZARD_HEADER, *(f"{t},{v}" for t, v in sorted(rows.items()))]) + "\n"
