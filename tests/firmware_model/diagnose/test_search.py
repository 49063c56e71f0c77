"""The workflow on synthetic traces: each effect named, nothing named on clean data, unknown effects flagged.

Traces are 10 s of the reference excitation, one fixed seed per case (seeds
are fixed, not picked); the sweep over many seeds and 20 s traces is the
bench, tools/bench_diagnose.py.  Hidden values are drawn from each effect's
``hidden`` range (see firmware_model/diagnose/effects.py for why backlash and
Stribeck friction start where they do: below that they leave about one
position unit against a noise floor of half a unit).  Stribeck friction shows
where the shaft starts from rest, so its trace is 14 s, the last 6 s small
steps and moderate-speed moves (excitation.BREAKAWAY).  For ``sample_hold``
the position channel carries no signal, so the shrink is checked on the
speed channel instead.

All diagnoses are made once by a module fixture, in two worker processes
(the machine has two cores; one diagnosis uses one).
"""

import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from firmware_model.diagnose.effects import LIBRARY
from firmware_model.diagnose.search import diagnose, residual_structure
from firmware_model.diagnose.synthetic import COGGING_AMPLITUDE_NM, draw_effect, make_trace

#: The diagnoses below are made once, in one fixture, two at a time (one per core); setup may take minutes.
pytestmark = pytest.mark.timeout(900)

DURATION_S = 10.0
#: Effects whose test trace needs the breakaway block: (total seconds, of which breakaway block).
BREAKAWAY_S = {"stribeck_friction": (14.0, 6.0)}
#: Every diagnosis the tests look at: key -> (hidden effects, seed); the slowest first, to balance the workers.
CASES = {
    "delay+extra_inertia": (("delay", "extra_inertia"), 2),
    **{name: ((name,), 7) for name in ("compliance_deadband", "stribeck_friction", "extra_inertia")},
    **{name: ((name,), 7) for name in LIBRARY},
    "cogging": (("cogging",), 5),
    "clean": ((), 12),
}


def _run(case):
    """(measured position, diagnosis) of one synthetic trace; runs in a worker process."""
    hidden_names, seed = case
    rng = np.random.default_rng(seed + 100_000)
    hidden = {n: draw_effect(n, rng) for n in hidden_names}
    single = len(hidden_names) == 1
    duration, block = BREAKAWAY_S.get(hidden_names[0], (DURATION_S, 0.0)) if single else (DURATION_S, 0.0)
    trace, _ = make_trace(hidden, seed, duration, breakaway_s=block)
    return trace["present_position"], diagnose(trace, progress=lambda m: None)


@pytest.fixture(scope="module")
def results():
    """All CASES diagnosed once, in parallel (an exception is kept and re-raised by the test that needs it)."""
    workers = max(1, min(2, os.cpu_count() or 1))
    with ProcessPoolExecutor(workers) as pool:
        futures = {key: pool.submit(_run, case) for key, case in CASES.items()}
        out = {}
        for key, fut in futures.items():
            try:
                out[key] = fut.result()
            except Exception as exc:  # noqa: BLE001 - reported by the test for this case
                out[key] = exc
    return out


def _get(results, key):
    r = results[key]
    if isinstance(r, Exception):
        raise r
    return r


@pytest.mark.parametrize("name", list(LIBRARY))
def test_single_effect_is_named_and_gap_shrinks(results, name):
    """Only ``name`` hidden (random values): it is named first and the RMS gap shrinks by >= 70 %."""
    _, d = _get(results, name)
    assert d.named and d.named[0] == name, d.named
    ch = "present_speed" if name == "sample_hold" else "present_position"
    assert d.gaps_after[ch]["rms"] <= 0.3 * d.gaps_before[ch]["rms"], (d.gaps_before[ch]["rms"], d.gaps_after[ch]["rms"])


def test_negative_control_names_nothing(results):
    """No hidden effect: nothing is named and nothing is unexplained (more seeds: the bench's 20 clean traces)."""
    _, d = _get(results, "clean")
    assert d.named == [] and not d.unexplained, (d.named, d.unexplained_detail)


def test_clean_residual_is_noise(results):
    """On a clean trace the base model's position residual is mostly row-to-row noise (structure < noise)."""
    position, d = _get(results, "clean")
    structured, white = residual_structure(d.sim_after["present_position"] - position)
    assert 0.2 < white < 0.8 and structured < white, (structured, white)


def test_out_of_library_effect_is_reported_unexplained(results):
    """A cogging ripple (no library effect, 10-17 % of stall torque) leaves an unexplained residual, no confident name."""
    _, d = _get(results, "cogging")
    assert d.gaps_before["present_position"]["rms"] > 1.5  # clearly visible in the data
    assert d.unexplained, (d.named, d.residual_rms_sd)
    assert d.confident == []
    assert "no library effect explains it" in d.unexplained_detail


def test_cogging_amplitude_is_plausible():
    """The out-of-library ripple stays a fraction of the AX-12's ~1.5 N m stall torque."""
    assert 0.0 < COGGING_AMPLITUDE_NM[0] < COGGING_AMPLITUDE_NM[1] <= 0.2 * 1.5


def test_two_effects_named_over_two_rounds(results):
    """Delay and extra inertia hidden together: both are named, one per round, before anything else.

    One more name may follow.  Over seeds 2-6 and 8 of this case, more than
    the two hidden effects were named in 3 of 6 traces with the present step
    loop (positions first, implicit dry friction) and in 2 of 6 with the
    Karnopp loop before it (whose seed 2 rejected a third name only on the
    held-out check), and in seed 8 neither put both hidden effects first.
    False positives on several-effect traces are a known limit of the search;
    the clean traces' false positives are the bench's concern.
    """
    _, d = _get(results, "delay+extra_inertia")
    assert sorted(d.named[:2]) == ["delay", "extra_inertia"], d.named
    assert len(d.named) <= 3, d.named
    assert len(d.rounds) >= 2
