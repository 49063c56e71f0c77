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

All diagnoses are made once, in two fresh processes that also make
test_search_state.py's (see conftest.py: SEARCH_CASES, two_orders).
"""

import pytest

from firmware_model.diagnose.effects import LIBRARY
from firmware_model.diagnose.search import residual_structure
from firmware_model.diagnose.synthetic import COGGING_AMPLITUDE_NM

#: The diagnoses below are made once, in one fixture, two at a time (one per core); setup may take minutes.
pytestmark = pytest.mark.timeout(900)


@pytest.fixture(scope="module")
def results(two_orders):
    """conftest.py's two_orders: ``search_result(key)`` is a SEARCH_CASES key's (measured position, diagnosis)."""
    return two_orders


def _get(results, key):
    return results.search_result(key)


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
