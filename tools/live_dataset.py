#!/usr/bin/env python3
"""Record a trace LIVE from ``ax12emu serve`` through dynamixel-sdk, with one effect hidden by a public knob.

Why it exists: traces from the project's own simulator (tools/make_dataset.py)
share its clock, its sampling and its idea of when a command took effect; a
live recording does not.  It carries what a user's recording carries: real-
time jitter, a reply's own time, an unknown phase of the 10 Hz speed/load
hold, commands that go out a few ms after their row.  The diagnosis is only
shown to work on real data once it names the right effect on recordings made
this way, and names nothing on a clean servo.

Each knob hides one library effect (firmware_model.diagnose.effects) the way
a user's setup would, through public means only: the server's options
(``--arm``, ``--voltage``), register writes through the SDK before the run
(Torque Limit, Compliance Margin), a parameter file (``--params``: base
fields, and the ``[effects]`` table where the served model has the field),
or a transform of the recording afterwards (a reading latency by shifting
the readings' times, a sensor offset/gain).  :data:`KNOBS` maps each knob to
the effect it should make the diagnosis name first, with magnitudes drawn
from the effect's ``hidden`` range (a signature well above the sensor; see
effects.py).  Every recording also draws the unit-to-unit spread of the
motor's strength (``gearbox_efficiency`` 0.74-0.78), as the synthetic maker
does.

The answer key goes to a JSON sidecar the workflow never reads.  Draws are
seeded (``--seed``); the recording itself is as reproducible as real time
allows (jitter and the hold phase differ run to run).  One recording costs
its duration plus about a second to start the server; record one at a time
(two at once on a 2-core machine disturb each other's timing).

Usage: ``python tools/live_dataset.py OUT.csv --key KEY.json [--knob none|arm|...] [--seed N]
[--duration 10] [--rate 100]``; ``--list`` prints the knobs.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
sys.path.insert(0, str(ROOT))

from record import record  # noqa: E402

from ax12emu.cli.arg_types import OneLineParser, nonnegative_int, output_file, positive_float  # noqa: E402
from ax12emu.harness.served import start_served  # noqa: E402
from firmware_model.diagnose.effects import LIBRARY  # noqa: E402
from firmware_model.diagnose.trace import Trace, write_trace  # noqa: E402
from firmware_model.params import ServoParams  # noqa: E402

__all__ = ["Setup", "Knob", "KNOBS", "record_live", "shift_readings", "offset_gain"]

GRAVITY_M_S2 = 9.80665
#: Arm length used for the gravity knob (short, so the arm's own inertia, m L**2, stays small).
ARM_LENGTH_M = 0.05
#: Seconds of :data:`firmware_model.diagnose.excitation.BREAKAWAY` that Stribeck friction needs (see effects.py).
STRIBECK_BREAKAWAY_S = 6.0
#: A started server gets this long to print its port.
SERVE_START_S = 20.0
#: How the server and the recorder are scheduled while they record.  A servo's controller is never descheduled;
#: on a shared 2-core machine (load average 7-10 while other work runs) a process at the default priority is, for
#: 10 ms and more at a time, even at niceness -10, and a command then takes effect that long after it was sent,
#: which the diagnosis rightly calls a latency.  So the server runs round-robin real-time at the lowest priority
#: for the recording's seconds (it sleeps between packets and physics steps, about a tenth of a core; the kernel
#: keeps 5 % of each core for ordinary tasks whatever happens), and the recorder at niceness -10 (not real-time:
#: dynamixel-sdk busy-waits for each reply, which at real-time priority would starve the server).  Where that is
#: not permitted, niceness -10, else the default; the key records which.
RECORDING_PRIORITY = ("SCHED_RR 1", "nice -10", "default")


@dataclass(frozen=True)
class Setup:
    """How one recording hides its effect, and what the library effect's values should come out as."""

    #: Extra ``ax12emu serve`` options.
    serve_args: tuple[str, ...] = ()
    #: ServoParams base fields written to the ``--params`` file.
    params: dict[str, float] = field(default_factory=dict)
    #: ServoEffects fields written to its ``[effects]`` table.
    effects: dict[str, float] = field(default_factory=dict)
    #: Registers written through the SDK before the run (e-manual names).
    writes: dict[str, int] = field(default_factory=dict)
    #: Readings stamped this much later than they were taken (a reading latency), applied afterwards.
    shift_s: float = 0.0
    #: Present Position reported as ``gain (x - 511.5) + 511.5 + offset`` (speed times ``gain``), afterwards.
    offset_units: float = 0.0
    gain: float = 1.0
    #: Present Voltage left out of the recording, afterwards: a logger that does not read the supply (record.py
    #: reads it), so the workflow runs at the supply it assumes.
    supply_unrecorded: bool = False
    #: Seconds of the breakaway block at the end of the excitation.
    breakaway_s: float = 0.0
    #: The library effect's parameter values this setup amounts to (for the key).
    truth: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Knob:
    """A public way to hide an effect: the effect it should make the diagnosis name first, and a seeded draw."""

    effect: str | None
    how: str
    draw: Callable[[np.random.Generator], Setup]


def _uniform(rng: np.random.Generator, effect: str, param: str) -> float:
    return float(rng.uniform(*LIBRARY[effect].param(param).hidden))


def _arm(rng):
    moment = _uniform(rng, "gravity_load", "arm_weight_nm")
    mass = moment / (GRAVITY_M_S2 * ARM_LENGTH_M)
    return Setup(serve_args=("--arm", f"{mass:.6f},{ARM_LENGTH_M}"), truth={"arm_weight_nm": moment})


def _torque_limit(rng):
    ceiling = _uniform(rng, "torque_saturation", "drive_ceiling")
    value = int(round(1023 * ceiling))
    return Setup(writes={"torque_limit": value}, truth={"drive_ceiling": value / 1023})


def _voltage(rng):
    # A weak supply caps the drive as a lower PWM ceiling would (torque and top speed both scale with volts):
    # the model assumes 9.6 V, so 7.0-7.3 V reads as a ceiling of 0.73-0.76.  Hidden only from a recording that
    # does not hold the supply: with record.py's voltage column the workflow simply runs at the recorded one.
    volts = float(rng.uniform(7.0, 7.3))
    return Setup(serve_args=("--voltage", f"{volts:.2f}"), supply_unrecorded=True,
                 truth={"drive_ceiling": volts / ServoParams().supply_voltage_v})


def _margin(rng):
    extra = int(rng.integers(3, 9))
    default = 1
    return Setup(writes={"cw_compliance_margin": default + extra, "ccw_compliance_margin": default + extra},
                 truth={"extra_margin_units": float(extra)})


def _delay(rng):
    shift = _uniform(rng, "delay", "delay_s")
    return Setup(shift_s=shift, truth={"delay_s": shift})


def _sensor(rng):
    e = LIBRARY["sensor_offset_gain"]
    offset = float(rng.choice([-1, 1]) * rng.uniform(*e.param("position_offset_units").hidden))
    gain = float(1.0 + rng.choice([-1, 1]) * rng.uniform(*e.param("position_gain").hidden))
    return Setup(offset_units=offset, gain=gain, truth={"position_offset_units": offset, "position_gain": gain})


def _coulomb(rng):
    extra = _uniform(rng, "coulomb_friction", "extra_coulomb_nm")
    base = ServoParams()
    return Setup(params={"coulomb_friction_nm": base.coulomb_friction_nm + extra,
                         "static_friction_nm": base.static_friction_nm + extra},
                 truth={"extra_coulomb_nm": extra})


def _stribeck(rng):
    extra = _uniform(rng, "stribeck_friction", "extra_static_nm")
    velocity = _uniform(rng, "stribeck_friction", "stribeck_velocity_rad_s")
    return Setup(params={"static_friction_nm": ServoParams().static_friction_nm + extra,
                         "stribeck_velocity_rad_s": velocity},
                 breakaway_s=STRIBECK_BREAKAWAY_S, truth={"extra_static_nm": extra, "stribeck_velocity_rad_s": velocity})


def _inertia(rng):
    extra = _uniform(rng, "extra_inertia", "extra_inertia_kg_m2")
    return Setup(params={"load_inertia_kg_m2": ServoParams().load_inertia_kg_m2 + extra},
                 truth={"extra_inertia_kg_m2": extra})


def _hold(rng):
    hold = float(rng.choice([h for h in np.round(np.arange(0.05, 0.21, 0.01), 2) if abs(h - 0.1) > 1e-9]))
    return Setup(params={"sample_hold_s": hold}, truth={"hold_s": hold})


def _served_delay(rng):
    latency = _uniform(rng, "delay", "delay_s")
    return Setup(effects={"sensing_delay_s": latency}, truth={"delay_s": latency})


def _backlash(rng):
    play = _uniform(rng, "backlash", "backlash_rad")
    return Setup(effects={"backlash_rad": play}, truth={"backlash_rad": play})


#: Knob -> the effect it hides (None: a clean servo).  Order is the order the bench cycles through.
KNOBS: dict[str, Knob] = {
    "none": Knob(None, "nothing hidden", lambda rng: Setup()),
    "arm": Knob("gravity_load", "ax12emu serve --arm MASS,0.05 (weight moment 0.15-0.6 N m)", _arm),
    "torque_limit": Knob("torque_saturation", "Torque Limit written through the SDK (30-70 % of 1023)", _torque_limit),
    "voltage": Knob("torque_saturation", "ax12emu serve --voltage 7.0-7.3, the recording without its supply (the model "
                    "assumes 9.6 V)", _voltage),
    "compliance_margin": Knob("compliance_deadband", "CW/CCW Compliance Margin written through the SDK (4-9)",
                              _margin),
    "delay": Knob("delay", "readings stamped 10-50 ms late, afterwards (commands keep their send times)", _delay),
    "served_delay": Knob("delay", "--params [effects] sensing_delay_s 10-50 ms (the served model reads the shaft "
                         "that long ago)", _served_delay),
    "sensor": Knob("sensor_offset_gain", "Present Position offset 3-10 units and gain 1 +- 1-4 %, afterwards",
                   _sensor),
    "friction": Knob("coulomb_friction", "--params: sliding and breakaway friction 0.08-0.3 N m higher", _coulomb),
    "inertia": Knob("extra_inertia", "--params: load inertia 0.004-0.02 kg m2 higher", _inertia),
    "hold": Knob("sample_hold", "--params: speed/load hold period 0.05-0.2 s instead of 0.1", _hold),
    "stribeck": Knob("stribeck_friction", "--params: breakaway 0.25-0.45 N m higher, 6 s breakaway block",
                     _stribeck),
    "backlash": Knob("backlash", "--params [effects] backlash_rad 0.045-0.08", _backlash),
}


def servable(knob: str) -> bool:
    """Whether the served model can carry this knob (an ``[effects]`` field must exist in ServoEffects)."""
    from firmware_model import params

    effects_cls = getattr(params, "ServoEffects", None)
    names = {f.name for f in fields(effects_cls)} if effects_cls else set()
    setup = KNOBS[knob].draw(np.random.default_rng(0))
    return set(setup.effects) <= names


# ---------------------------------------------------------------------- post-recording transforms
def shift_readings(trace: Trace, shift_s: float) -> Trace:
    """The readings stamped ``shift_s`` later: each shows the shaft that long before its stamp.

    Commands keep the times they were sent (``command_t``), so each change is
    moved to the row after which it now falls (the format wants it between
    its row's neighbours); the first row carries whatever was sent before it.
    """
    t = trace["t"] + shift_s
    rows = trace.change_rows()
    sent = trace["command_t"][rows]
    at = np.maximum(np.searchsorted(t, sent, side="left") - 1, 0)
    owner = np.full(len(trace), -1)
    owner[at] = np.arange(len(rows))  # a later change on the same row wins
    owner = np.maximum.accumulate(owner)
    src = rows[owner]
    columns = {name: trace[name][src] for name in ("goal_position", "moving_speed")}
    columns["command_t"] = sent[owner]
    return Trace({**trace.columns, "t": t, **columns}, list(trace.comments))


def offset_gain(trace: Trace, offset_units: float, gain: float) -> Trace:
    """Present Position reported as ``gain (x - 511.5) + 511.5 + offset`` and Present Speed times ``gain``."""
    pos = np.clip(np.round(gain * (trace["present_position"] - 511.5) + 511.5 + offset_units), 0, 1023)
    out = {"present_position": pos}
    if trace.has("present_speed"):
        out["present_speed"] = np.clip(np.round(gain * trace["present_speed"]), -1023, 1023)
    return trace.with_columns(**out)


# ---------------------------------------------------------------------- serving and recording
def _prioritise(pid: int, realtime: bool) -> int:
    """Schedule ``pid`` (0: this process) as :data:`RECORDING_PRIORITY` says; the index of what was permitted."""
    try:
        if realtime:
            os.sched_setscheduler(pid, os.SCHED_RR, os.sched_param(1))
            return 0
    except (OSError, AttributeError):
        pass
    try:
        os.setpriority(os.PRIO_PROCESS, pid, -10)
        return 1
    except OSError:
        return 2


@contextmanager
def recording_priority(server_pid: int) -> Iterator[dict[str, str]]:
    """For a recording's seconds, the server ``server_pid`` and this process (the recorder) scheduled as
    :data:`RECORDING_PRIORITY` says, this process's niceness restored after; yields what was permitted
    (``{"server": ..., "recorder": ...}``).  tools/twin_check.py records through it too."""
    own = os.getpriority(os.PRIO_PROCESS, 0)
    try:
        yield {"server": RECORDING_PRIORITY[_prioritise(server_pid, True)],
               "recorder": RECORDING_PRIORITY[_prioritise(0, False)]}
    finally:
        os.setpriority(os.PRIO_PROCESS, 0, own)


def _params_toml(setup: Setup, base: dict[str, float], path: Path) -> None:
    lines = ["# hidden by tools/live_dataset.py"]
    lines += [f"{k} = {float(v)!r}" for k, v in {**base, **setup.params}.items()]
    if setup.effects:
        lines += ["", "[effects]"] + [f"{k} = {float(v)!r}" for k, v in setup.effects.items()]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    ServoParams.from_toml(path)  # refuse a bad draw here, not in the server


def record_live(knob: str, seed: int, duration_s: float = 10.0, rate_hz: float = 100.0) -> tuple[Trace, dict]:
    """Start a server with ``knob``'s effect hidden, record the excitation live, transform; return (trace, key)."""
    if knob not in KNOBS:
        raise ValueError(f"unknown knob {knob!r}; known: {', '.join(KNOBS)}")
    spec = KNOBS[knob]
    rng = np.random.default_rng(seed)
    setup = spec.draw(rng)
    base = {"gearbox_efficiency": float(rng.uniform(0.74, 0.78))}
    duration = duration_s + setup.breakaway_s
    with tempfile.TemporaryDirectory(prefix="live_dataset_") as tmp:
        params_path = Path(tmp) / "params.toml"
        _params_toml(setup, base, params_path)
        # Served from this checkout (cwd), so the recording's model is the code the diagnosis runs.
        served = start_served(["--ids", "1", "--params", str(params_path), *setup.serve_args], cwd=ROOT,
                              timeout_s=SERVE_START_S)
        try:
            with recording_priority(served.process.pid) as priority:
                trace = record(served.port, 1, 1_000_000, duration, rate_hz, setup.breakaway_s, setup.writes)
        finally:
            served.close()
    if setup.supply_unrecorded:
        trace = Trace({k: v for k, v in trace.columns.items() if k != "voltage"}, list(trace.comments), dict(trace.meta))
    if setup.shift_s:
        trace = shift_readings(trace, setup.shift_s)
    if setup.offset_units or setup.gain != 1.0:
        trace = offset_gain(trace, setup.offset_units, setup.gain)
    trace.comments[:] = [f"live recording through dynamixel-sdk from ax12emu serve, seed {seed}, tools/live_dataset.py"]
    key = {"knob": knob, "effect": spec.effect, "how": spec.how, "truth": setup.truth, "seed": seed,
           "duration_s": duration, "rate_hz": rate_hz, "base": base, "setup": asdict(setup),
           "priority": priority}
    return trace, key


def main(argv: list[str] | None = None) -> int:
    """Record one live trace and its key."""
    p = OneLineParser(description=__doc__.splitlines()[0])
    p.add_argument("out", nargs="?", type=output_file, help="trace CSV to write")
    p.add_argument("--key", type=output_file, help="answer key JSON to write (keep it away from the workflow)")
    p.add_argument("--knob", default="none", help="what to hide (--list shows them; default none)")
    p.add_argument("--seed", type=nonnegative_int, default=0, help="seeds numpy's generator, which refuses < 0")
    p.add_argument("--duration", type=positive_float, default=10.0, help="seconds of the main excitation (default 10)")
    p.add_argument("--rate", type=positive_float, default=100.0, help="readings per second (default 100)")
    p.add_argument("--list", action="store_true", help="print the knobs and the effect each hides, and exit")
    args = p.parse_args(argv)
    if args.list:
        for name, k in KNOBS.items():
            print(f"{name:>18}  {k.effect or '-':<20} {k.how}{'' if servable(name) else '  (not servable yet)'}")
        return 0
    if not args.out or not args.key:
        p.error("OUT.csv and --key are required")
    if Path(args.key).resolve() == Path(args.out).resolve():  # the key would overwrite the recording
        p.error("--key must not be the trace file OUT")
    if args.knob not in KNOBS:
        p.error(f"unknown knob {args.knob!r}; known: {', '.join(KNOBS)}")
    if not servable(args.knob):
        p.error(f"knob {args.knob!r} needs an [effects] field the served model does not have yet")
    if not args.rate <= 1000:
        p.error("--rate must be in (0, 1000]")
    trace, key = record_live(args.knob, args.seed, args.duration, args.rate)
    write_trace(trace, args.out)
    Path(args.key).write_text(json.dumps(key, indent=2), encoding="utf-8")
    print(f"{args.out}: {len(trace)} rows over {trace.t[-1]:.2f} s, {args.knob} -> {key['effect'] or 'nothing'}; "
          f"key in {args.key}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
