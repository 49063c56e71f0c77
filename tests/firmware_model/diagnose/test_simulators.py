"""The batched simulator reproduces PhysicalModel's replay exactly, and every effect's null value is the base model."""

import numpy as np
import pytest

from firmware_model.diagnose.batch import null_knobs, sample, simulate
from firmware_model.diagnose.effects import LIBRARY, apply_effects
from firmware_model.diagnose.excitation import commands_at, program
from firmware_model.diagnose.replay import replay
from firmware_model.diagnose.schedule import compile_schedule
from firmware_model.diagnose.trace import Trace
from firmware_model.params import ServoParams


def _trace(duration=6.0):
    rng = np.random.default_rng(4)
    t = np.arange(0, duration, 0.01) + rng.uniform(0, 0.004, int(duration * 100))
    c = commands_at(t, program(duration))
    return Trace(dict(t=t, present_position=np.full(len(t), 512), **c))


def test_batch_equals_physical_model_replay():
    """All registers from the batched simulator at null knobs equal PhysicalModel's, row by row."""
    tr = _trace()
    p = ServoParams()
    ref = replay(tr, p)
    s = compile_schedule(tr)
    out = sample(s, simulate(s, p, {}, 3), p, columns=[1])
    for ch in ("present_position", "present_speed", "present_load"):
        np.testing.assert_array_equal(out[ch][:, 0], ref[ch])
    assert np.ptp(ref["present_position"]) > 300  # the trace really moves


@pytest.mark.parametrize("name", list(LIBRARY))
def test_null_value_is_the_base_model(name):
    """Each effect at its null values maps onto exactly the base knobs."""
    base = null_knobs(ServoParams())
    assert apply_effects(base, {name: LIBRARY[name].null_values()}) == base


def test_effects_change_something():
    """Away from the null, every effect changes the knobs (so it can be seen at all)."""
    base = null_knobs(ServoParams())
    for name, e in LIBRARY.items():
        vals = {p.name: p.hidden[1] if p.name != "position_gain" else 1.03 for p in e.params}
        assert apply_effects(base, {name: vals}) != base, name


def test_batch_equals_replay_with_command_times():
    """Command changes sent between readings (``command_t``, before and after their rows) act alike in both."""
    tr = _trace(3.0)
    rows = tr.change_rows()[1:]
    t = tr["t"]
    sent = t.copy()
    sent[rows[::2]] += 0.6 * (t[rows[::2] + 1] - t[rows[::2]])   # after the row's reading
    sent[rows[1::2]] -= 0.4 * (t[rows[1::2]] - t[rows[1::2] - 1])  # before it
    tr = tr.with_columns(command_t=sent)
    p = ServoParams()
    ref = replay(tr, p)
    s = compile_schedule(tr)
    assert not np.array_equal(s.nominal_onsets()[1:], np.floor(t[rows] / 1e-3 + 1e-9))
    out = sample(s, simulate(s, p, {}, 1), p)
    for ch in ("present_position", "present_speed", "present_load"):
        np.testing.assert_array_equal(out[ch][:, 0], ref[ch])
