"""The workflow on synthetic traces: each effect named, nothing named on clean data, unknown effects flagged.

Traces are 10 s (the bench, tools/bench_diagnose.py, sweeps 20 s traces over
many seeds); seeds are fixed, not picked.  For ``sample_hold`` and the
sensing of speed, the position channel carries no signal, so the shrink is
checked on the speed channel instead.
"""

import numpy as np
import pytest

from firmware_model.diagnose.effects import LIBRARY
from firmware_model.diagnose.search import diagnose
from firmware_model.diagnose.synthetic import draw_effect, make_trace

DURATION_S = 10.0


def _run(hidden_names, seed):
    rng = np.random.default_rng(seed + 100_000)
    hidden = {n: draw_effect(n, rng) for n in hidden_names}
    trace, _ = make_trace(hidden, seed, DURATION_S)
    return diagnose(trace, progress=lambda m: None)


@pytest.mark.parametrize("name", list(LIBRARY))
def test_single_effect_is_named_and_gap_shrinks(name):
    """Only ``name`` hidden (random values): it is named first and the RMS gap shrinks by >= 70 %."""
    d = _run([name], seed=7)
    assert d.named and d.named[0] == name, d.named
    ch = "present_speed" if name == "sample_hold" else "present_position"
    assert d.gaps_after[ch]["rms"] <= 0.3 * d.gaps_before[ch]["rms"], (d.gaps_before[ch]["rms"], d.gaps_after[ch]["rms"])


@pytest.mark.parametrize("seed", [11, 12])
def test_negative_control_names_nothing(seed):
    """No hidden effect: nothing is named and nothing is unexplained."""
    d = _run([], seed)
    assert d.named == [] and not d.unexplained


def test_out_of_library_effect_is_reported_unexplained():
    """A cogging ripple (no library effect) leaves an unexplained residual and no confident name."""
    d = _run(["cogging"], seed=5)
    assert d.unexplained
    assert d.confident == []


def test_two_effects_named_over_two_rounds():
    """Delay and extra inertia hidden together: both are named, one per round."""
    d = _run(["delay", "extra_inertia"], seed=2)
    assert sorted(d.named) == ["delay", "extra_inertia"]
    assert len(d.rounds) >= 2
