"""tools/live_dataset.py: live recordings through dynamixel-sdk from ``ax12emu serve``, diagnosed.

The end-to-end cases record one clean trace in real time (10 s) and hide a
reading latency in a copy afterwards, then diagnose both at once: the clean
servo must get no effect named, and the hidden latency must be named first,
which only works because the recorder says when each command was sent.
"""

import importlib.util
import json
import os
import subprocess
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from firmware_model.diagnose.search import diagnose
from firmware_model.diagnose.trace import Trace, command_time_errors, read_trace, write_trace

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "live_dataset.py"


def _tool():
    """The tool as a module (tools/ is not a package); dataclasses need it in sys.modules while it loads."""
    if "live_dataset" not in sys.modules:
        spec = importlib.util.spec_from_file_location("live_dataset", TOOL)
        module = importlib.util.module_from_spec(spec)
        sys.modules["live_dataset"] = module
        spec.loader.exec_module(module)
    return sys.modules["live_dataset"]


def _recorded_like() -> Trace:
    """A recorder's trace: rows every 10 ms, commands sent 0.5-3 ms after their row's reading."""
    rng = np.random.default_rng(5)
    t = np.arange(100) * 0.01 + rng.uniform(0, 0.002, 100)
    goal = np.where(t < 0.3, 512, np.where(t < 0.6, 600, 400))
    changed = np.flatnonzero(np.diff(goal)) + 1
    sent = t.copy()
    for i in changed:
        sent[i] = t[i] + rng.uniform(0.0005, 0.003)
    sent = sent[np.maximum.accumulate(np.where(np.isin(np.arange(100), changed), np.arange(100), 0))]
    return Trace({"t": t, "goal_position": goal, "moving_speed": np.zeros(100, int),
                  "present_position": np.arange(100) + 400, "present_speed": np.arange(100) - 50,
                  "command_t": sent})


def test_shift_readings_keeps_when_commands_were_sent():
    """Readings stamped later; each command keeps its send time and sits on a row the format accepts."""
    live = _tool()
    tr = _recorded_like()
    shifted = live.shift_readings(tr, 0.033)
    assert np.allclose(shifted["t"], tr["t"] + 0.033)
    assert len(command_time_errors(shifted)) == 0
    rows = shifted.change_rows()[1:]
    assert np.allclose(np.sort(shifted["command_t"][rows]), tr["command_t"][tr.change_rows()[1:]])
    # each row carries the last command sent before the next reading (applied at its send time)
    changes = tr.change_rows()
    following = np.append(shifted["t"][1:], np.inf)
    for i in range(len(tr)):
        last = changes[tr["command_t"][changes] < following[i]][-1]
        assert shifted["goal_position"][i] == tr["goal_position"][last], i
    assert np.array_equal(shifted["present_position"], tr["present_position"])


def test_offset_gain_scales_about_the_centre():
    """Position reads gain (x - 511.5) + 511.5 + offset, rounded and clipped; speed times gain; commands untouched."""
    live = _tool()
    tr = _recorded_like()
    out = live.offset_gain(tr, -6.0, 1.03)
    assert np.array_equal(out["present_position"], np.clip(np.round(1.03 * (tr["present_position"] - 511.5) + 505.5), 0, 1023))
    assert np.array_equal(out["present_speed"], np.round(1.03 * tr["present_speed"]))
    assert np.array_equal(out["goal_position"], tr["goal_position"])


def test_every_knob_names_a_library_effect_and_draws_reproducibly():
    """Each knob hides a library effect (or nothing), and a seed draws the same setup twice."""
    from firmware_model.diagnose.effects import LIBRARY

    live = _tool()
    for name, knob in live.KNOBS.items():
        assert knob.effect is None or knob.effect in LIBRARY, name
        a, b = (knob.draw(np.random.default_rng(7)) for _ in range(2))
        assert a == b, name
        assert set(a.truth) <= {p.name for p in LIBRARY[knob.effect].params} if knob.effect else not a.truth


def test_bad_knob_is_a_clear_error(tmp_path):
    r = subprocess.run([sys.executable, str(TOOL), str(tmp_path / "x.csv"), "--key", str(tmp_path / "k.json"),
                        "--knob", "gremlins"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "unknown knob 'gremlins'" in r.stderr and "Traceback" not in r.stderr


#: The live recording's seed and the seed of the reading latency hidden in it afterwards (fixed, not picked).
CLEAN_SEED, DELAY_SEED = 11, 12


def _diagnose(path: str):
    d = diagnose(read_trace(path), progress=lambda m: None)
    return d.named, {c.effect: c.values for c in d.accepted}


@pytest.fixture(scope="module")
def live_results(tmp_path_factory):
    """One clean recording made live (real time), a copy with the delay knob's latency hidden, both diagnosed at once.

    The delay knob hides its latency in the recording after it was made (record_live applies shift_readings,
    tested above), so the copy is the clean recording as ``--knob delay`` would have left it: the hidden latency
    is the only difference between the two traces.
    """
    folder = tmp_path_factory.mktemp("live")
    paths = {case: folder / f"{case}.csv" for case in ("clean", "delay")}
    subprocess.run([sys.executable, str(TOOL), str(paths["clean"]), "--key", str(folder / "clean.json"), "--knob", "none",
                    "--seed", str(CLEAN_SEED), "--duration", "10"], check=True, capture_output=True, timeout=120)
    setup = _tool().KNOBS["delay"].draw(np.random.default_rng(DELAY_SEED))
    write_trace(_tool().shift_readings(read_trace(paths["clean"]), setup.shift_s), paths["delay"])
    keys = {"clean": json.loads((folder / "clean.json").read_text()), "delay": {"effect": "delay", "truth": setup.truth}}
    with ProcessPoolExecutor(max(1, min(2, os.cpu_count() or 1))) as pool:
        futures = {case: pool.submit(_diagnose, str(path)) for case, path in paths.items()}
        results = {case: f.result() for case, f in futures.items()}
    return {case: (read_trace(paths[case]), keys[case], *results[case]) for case in paths}


@pytest.mark.wallclock
@pytest.mark.timeout(300)
def test_live_recording_says_when_commands_were_sent(live_results):
    """The recorder stamps each command change's send time between its row's reading and the next."""
    trace, key, _, _ = live_results["clean"]
    assert trace.records_command_times and len(command_time_errors(trace)) == 0
    assert len(trace.change_rows()) >= 10 and key["effect"] is None
    assert np.ptp(trace["present_position"]) > 300  # the servo really moved through the excitation


@pytest.mark.wallclock
@pytest.mark.timeout(300)
def test_clean_live_recording_names_nothing(live_results):
    """How the data was taken (jitter, hold phase, a command's own latency) is not named as physics."""
    _, _, named, values = live_results["clean"]
    assert named == [], values


@pytest.mark.wallclock
@pytest.mark.timeout(300)
def test_hidden_latency_named_first_on_live_recording(live_results):
    """Readings stamped 10-50 ms late after a live recording: ``delay`` is named first, near the hidden value."""
    _, key, named, values = live_results["delay"]
    assert named[:1] == ["delay"], values
    assert abs(values["delay"]["delay_s"] - key["truth"]["delay_s"]) < 0.008, (values, key["truth"])
