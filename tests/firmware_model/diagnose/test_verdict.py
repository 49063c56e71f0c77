"""The verdict's rules on fits made of numbers: what passes, what is rejected and why, what is tentative.

The workflow's own tests (test_search.py) show the rules working on whole
traces; these pin each rule at its edge, without a simulation.
"""

import numpy as np
import pytest

from firmware_model.diagnose.effects import LIBRARY
from firmware_model.diagnose.phases import PHASES
from firmware_model.diagnose.selection import Fit, Linearisation, Score
from firmware_model.diagnose.verdict import (
    BIC_MARGIN,
    MIN_SHARE,
    POT_NOISE_MAX_RAD,
    STRUCTURE_FLOOR_UNITS,
    TENTATIVE_SHARE,
    UNEXPLAINED_RMS,
    Candidate,
    confidence,
    delta_bic,
    grid_profile,
    judge,
    rejections,
    residual_verdict,
    wald,
)
from firmware_model.units import RAD_PER_POSITION_UNIT

BACKLASH = LIBRARY["backlash"]  # one parameter, null 0
SAMPLE_HOLD = LIBRARY["sample_hold"]  # grid only, null 0.1 s


def _candidate(**changes) -> Candidate:
    """A candidate that passes every test (against a current held-out cost of 100), with ``changes``."""
    fields = dict(effect="backlash", values={"backlash_rad": 0.05}, base={}, uncertainty={}, cost_train=50.0,
                  cost_held=60.0, delta_bic=BIC_MARGIN + 20.0, n_eff=200.0, null_excluded=True, share=0.5)
    fields.update(changes)
    return Candidate(**fields)


def test_a_candidate_passing_every_test_has_no_reasons():
    assert rejections(_candidate(), current_held=100.0) == []


@pytest.mark.parametrize("changes, current_held, word", [
    ({"delta_bic": BIC_MARGIN}, 100.0, "BIC"),  # the margin must be exceeded, not met
    ({"delta_bic": -3.0}, 100.0, "BIC"),
    ({"share": MIN_SHARE - 0.001}, 100.0, "removes only"),
    ({"cost_held": 100.0}, 100.0, "held-out"),  # equal is not a fall
    ({"cost_held": 60.0}, 59.0, "held-out"),
    ({"null_excluded": False}, 100.0, "includes the null"),
    ({"cost_train": 0.0}, 100.0, "fits every reading exactly"),  # three rows: dBIC infinite, no spread at all
])
def test_each_failed_test_is_one_reason(changes, current_held, word):
    reasons = rejections(_candidate(**changes), current_held)
    assert len(reasons) == 1 and word in reasons[0], reasons


def test_every_failed_test_is_reported_not_only_the_first():
    c = _candidate(delta_bic=1.0, share=0.0, cost_held=120.0, null_excluded=False)
    assert len(rejections(c, current_held=100.0)) == 4


def test_delta_bic_counts_parameters_against_the_effective_sample_size():
    # the same fall in cost is worth less with more parameters and with fewer independent rows
    assert delta_bic(1, 100.0, 80.0, 200.0) == pytest.approx(200 * np.log(100 / 80) - np.log(200))
    assert delta_bic(2, 100.0, 80.0, 200.0) < delta_bic(1, 100.0, 80.0, 200.0)
    assert delta_bic(1, 100.0, 80.0, 50.0) < delta_bic(1, 100.0, 80.0, 200.0)
    assert delta_bic(1, 100.0, 0.0, 200.0) == np.inf  # a perfect fit, not a division error


def _grid_fit(cost_train: float, cost_held: float, n_eff: float) -> Fit:
    """A grid-only sample_hold fit at 0.15 s whose null (0.1 s) costs 40 % more than the optimum."""
    grid = [({"hold_s": 0.1}, 1.4 * cost_train), ({"hold_s": 0.15}, cost_train), ({"hold_s": 0.2}, 1.4 * cost_train)]
    return Fit("sample_hold", {"hold_s": 0.15}, {"gearbox_efficiency": 0.76}, {"sample_hold": {"hold_s": 0.15}},
               Score(cost_train, cost_held, n_eff), np.zeros((4, 1)), grid=grid)


def test_judge_names_a_fit_whose_bic_gain_clears_the_margin_and_not_one_just_below():
    n_eff, current = 200.0, Score(100.0, 100.0, 200.0)
    # the cost at which the BIC gain is exactly the margin, for one parameter (a 7 % fall: above MIN_SHARE)
    edge = 100.0 / np.exp((BIC_MARGIN + np.log(n_eff)) / n_eff)
    above = judge(SAMPLE_HOLD, _grid_fit(edge * 0.999, 90.0, n_eff), current)
    below = judge(SAMPLE_HOLD, _grid_fit(edge * 1.001, 90.0, n_eff), current)
    assert above.passed(), above.reasons
    assert above.delta_bic > BIC_MARGIN > below.delta_bic
    assert not below.passed() and len(below.reasons) == 1 and "BIC" in below.reasons[0]


def test_judge_records_the_share_and_the_refitted_model():
    c = judge(SAMPLE_HOLD, _grid_fit(70.0, 90.0, 400.0), Score(100.0, 100.0, 400.0))
    assert c.share == pytest.approx(0.3)
    assert c.values == {"hold_s": 0.15} and c.base == {"gearbox_efficiency": 0.76}
    assert c.refitted == {"sample_hold": {"hold_s": 0.15}}
    assert (c.cost_train, c.cost_held, c.n_eff) == (70.0, 90.0, 400.0)


def test_judge_rejects_a_fit_that_worsens_the_held_out_blocks():
    c = judge(SAMPLE_HOLD, _grid_fit(70.0, 101.0, 400.0), Score(100.0, 100.0, 400.0))
    assert c.delta_bic > BIC_MARGIN and not c.passed()
    assert c.reasons == ["held-out cost does not fall (101.0 vs 100.0)"]


def _linear(estimate_sd: float, n: int = 2000, n_eff: float = 2000.0):
    """A one-parameter least-squares fit (plus a base column) whose backlash estimate lies ``estimate_sd`` sd from 0.

    Residuals are white with sd 1 (inside the soft-L1 scale, so the robust
    weights are near 1), each row's derivative is 1, so the estimate's sd is
    about ``sqrt(n / n_eff) / sqrt(n)``.
    """
    rng = np.random.default_rng(3)
    r0 = rng.standard_normal(n)
    r0 *= 1.0 / r0.std()
    jac = np.stack([np.ones(n), np.linspace(-1.0, 1.0, n)], axis=1)
    sd = np.sqrt(n / n_eff) / np.sqrt(n)
    values = {"backlash_rad": estimate_sd * sd, "gearbox_efficiency": 0.76}
    return values, Linearisation(["backlash_rad", "gearbox_efficiency"], r0, jac), sd


@pytest.mark.parametrize("estimate_sd, excluded", [(4.0, True), (2.5, True), (1.5, False), (0.3, False)])
def test_wald_excludes_the_null_only_beyond_the_95_percent_region(estimate_sd, excluded):
    values, linear, sd = _linear(estimate_sd)
    unc, out = wald(BACKLASH, values, linear, n_eff=2000.0)
    assert out is excluded
    assert unc["backlash_rad"] == pytest.approx(1.96 * sd, rel=0.05)


@pytest.mark.parametrize("estimate_sd, excluded", [(2.1, True), (1.6, False)])
def test_wald_tests_a_two_parameter_effect_jointly(estimate_sd, excluded):
    """sensor_offset_gain tests two parameters: its null is excluded beyond the joint 95 % region, chi-squared with
    two degrees of freedom (5.99). Both estimates 1.6 sd off (a statistic of about 5.1) lie inside it, though
    each alone, or a one-degree test (3.84), would exclude the null."""
    effect = LIBRARY["sensor_offset_gain"]
    assert len(effect.tested) == 2
    n = 2000
    rng = np.random.default_rng(3)
    r0 = rng.standard_normal(n)
    r0 /= r0.std()
    rows = np.arange(n)
    jac = np.stack([(rows % 2 == 0).astype(float), (rows % 2 == 1).astype(float), np.linspace(-1.0, 1.0, n)], axis=1)
    names = [*effect.tested, "gearbox_efficiency"]
    sd = 1.0 / np.sqrt(n / 2)  # each tested column covers half the rows
    values = {name: effect.param(name).null + estimate_sd * sd for name in effect.tested}
    _, out = wald(effect, {**values, "gearbox_efficiency": 0.76}, Linearisation(names, r0, jac), n_eff=float(n))
    assert out is excluded


def test_wald_widens_the_interval_for_autocorrelated_residuals():
    # 2000 rows worth 20 independent ones: the same estimate is no longer told from the null
    values, linear, _ = _linear(4.0, n_eff=2000.0)
    unc_white, excluded_white = wald(BACKLASH, values, linear, n_eff=2000.0)
    unc_corr, excluded_corr = wald(BACKLASH, values, linear, n_eff=20.0)
    assert excluded_white and not excluded_corr
    assert unc_corr["backlash_rad"] == pytest.approx(10.0 * unc_white["backlash_rad"], rel=1e-6)


def test_wald_on_an_exact_fit_excludes_a_null_the_fit_left():
    """A fit that leaves no residual at all (a noise-free recording) has no spread to scale: the null is excluded
    where the estimate is off it, and not where it is on it (a zero spread once read as "includes the null")."""
    values, linear, _ = _linear(4.0)
    exact = Linearisation(linear.names, np.zeros_like(linear.residual), linear.jacobian)
    assert wald(BACKLASH, values, exact, n_eff=2000.0)[1]
    assert not wald(BACKLASH, {**values, "backlash_rad": 0.0}, exact, n_eff=2000.0)[1]


def test_judge_uses_the_wald_test_for_least_squares_fits():
    values, linear, _ = _linear(0.3)
    fit = Fit("backlash", {"backlash_rad": values["backlash_rad"]}, {"gearbox_efficiency": 0.76},
              {"backlash": {"backlash_rad": values["backlash_rad"]}}, Score(50.0, 60.0, 2000.0), np.zeros((4, 1)),
              linear=linear)
    c = judge(BACKLASH, fit, Score(100.0, 100.0, 2000.0))
    assert not c.null_excluded and c.reasons == ["confidence region includes the null"]


def test_grid_profile_excludes_a_null_that_costs_clearly_more():
    grid = [({"hold_s": 0.1}, 110.0), ({"hold_s": 0.15}, 100.0), ({"hold_s": 0.2}, 100.5)]
    # chi2 scale n_eff / cost = 1: the null is 10 worse (> 3.84), 0.2 s only 0.5 (inside the 95 % band)
    unc, excluded = grid_profile(SAMPLE_HOLD, {"hold_s": 0.15}, grid, 100.0, 100.0, current_cost=120.0)
    assert excluded
    assert unc["hold_s"] == pytest.approx(0.025)  # 0.15-0.2 inside, 0.1 not


def test_grid_profile_keeps_a_null_within_the_noise():
    grid = [({"hold_s": 0.1}, 102.0), ({"hold_s": 0.15}, 100.0)]
    _, excluded = grid_profile(SAMPLE_HOLD, {"hold_s": 0.15}, grid, 100.0, 100.0, current_cost=120.0)
    assert not excluded


def test_grid_profile_without_the_null_on_the_grid_compares_with_the_current_model():
    grid = [({"hold_s": 0.15}, 100.0), ({"hold_s": 0.2}, 101.0)]
    assert grid_profile(SAMPLE_HOLD, {"hold_s": 0.15}, grid, 100.0, 100.0, current_cost=110.0)[1]
    assert not grid_profile(SAMPLE_HOLD, {"hold_s": 0.15}, grid, 100.0, 100.0, current_cost=102.0)[1]


def _phases(n: int) -> np.ndarray:
    """Rows alternating between at rest and cruising, in blocks of 50."""
    return np.where((np.arange(n) // 50) % 2 == 0, PHASES.index("at_rest"), PHASES.index("cruising"))


def test_white_noise_residual_is_explained():
    rng = np.random.default_rng(1)
    z = rng.standard_normal((2000, 2))
    v = residual_verdict(z, ["present_position", "present_speed"], np.array([0.5, 2.0]), _phases(2000))
    assert not v.unexplained and v.detail == ""
    assert set(v.rms_sd) == {"present_position", "present_speed"}


def test_a_smooth_position_residual_above_a_unit_is_unexplained_by_its_structure():
    n = 2000
    rng = np.random.default_rng(2)
    # 3 units of slow ripple on 0.3 units of white noise, whitened by a 1-unit sd: small by size, clear by structure
    raw = 3.0 * np.sin(np.linspace(0.0, 20.0 * np.pi, n)) + 0.3 * rng.standard_normal(n)
    z = (raw / 1.5)[:, None]
    v = residual_verdict(z, ["present_position"], np.array([1.5]), _phases(n))
    assert v.rms_sd["present_position"] < UNEXPLAINED_RMS
    assert v.unexplained and v.detail.startswith("present_position keeps a time-correlated residual")
    assert "no library effect explains it" in v.detail


def test_a_smooth_residual_below_one_unit_is_below_the_sensor_and_not_flagged():
    n = 2000
    raw = 0.8 * STRUCTURE_FLOOR_UNITS * np.sin(np.linspace(0.0, 20.0 * np.pi, n)) * np.sqrt(2.0)
    v = residual_verdict((raw / 0.5)[:, None], ["present_position"], np.array([0.5]), _phases(n))
    assert not v.unexplained


def test_a_large_white_residual_on_another_channel_is_unexplained_by_its_size():
    n = 2000
    rng = np.random.default_rng(4)
    z = rng.standard_normal((n, 2))
    z[:, 1] *= 4.0
    z[_phases(n) == PHASES.index("cruising"), 1] *= 1.5  # where it is largest is named
    v = residual_verdict(z, ["present_position", "present_load"], np.array([0.5, 10.0]), _phases(n))
    assert v.unexplained and v.detail.startswith("present_load residual is")
    assert "largest while cruising" in v.detail


@pytest.mark.parametrize("share, unexplained, expected", [
    (TENTATIVE_SHARE - 0.01, True, "tentative"),
    (TENTATIVE_SHARE + 0.01, True, "confident"),
    (0.1, False, "confident"),
])
def test_a_named_effect_is_tentative_only_if_it_explained_little_and_a_residual_remains(share, unexplained, expected):
    assert confidence(share, unexplained) == expected


def test_an_effect_refitted_with_a_later_one_shows_that_fits_interval_and_null_test():
    """Accepted first at 0.0146, re-fitted with a later effect to 0.0053: the report showed 0.0053 with the first
    fit's interval and "null excluded", where the joint fit's interval held the null."""
    from firmware_model.diagnose.search import _refitted

    coulomb = LIBRARY["coulomb_friction"]
    (tested,) = coulomb.tested
    first = _candidate(effect="coulomb_friction", values={tested: 0.0146}, uncertainty={tested: 0.004})
    later = _candidate(effect="stribeck_friction", uncertainty={tested: 0.0097})
    _refitted(first, {tested: 0.0053}, later, coulomb)
    assert first.values == {tested: 0.0053} and first.uncertainty == {tested: 0.0097}
    assert first.null_excluded is False


def test_a_position_residual_far_above_any_pot_noise_is_unexplained_though_the_rest_rows_spread_as_much():
    """The size test whitens position by the noise of the rows the model has at rest; where the servo moved in them
    (a trace logged a row in 20, its onsets a sample off) they spread 30 units, a 35-unit residual read as about
    1 sd and the trace was called explained.  The pot reads no noisier than POT_NOISE_MAX_RAD at rest."""
    n = 100
    rng = np.random.default_rng(5)
    raw = 35.0 * rng.standard_normal(n)  # rows 200 ms apart: no structure row to row
    sd = np.array([30.0])
    pot = POT_NOISE_MAX_RAD / float(RAD_PER_POSITION_UNIT)
    v = residual_verdict((raw / sd[0])[:, None], ["present_position"], sd, _phases(n), pot_noise_max=pot)
    assert v.unexplained and "most a position sensor reads at rest" in v.detail, v.detail
    assert not residual_verdict((raw / sd[0])[:, None], ["present_position"], sd, _phases(n)).unexplained
    # a residual at the pot's noise stays explained, and where the rest rows spread less than the bound nothing changes
    assert not residual_verdict((0.5 * raw / 35.0 / sd[0])[:, None], ["present_position"], sd, _phases(n),
                                pot_noise_max=pot).unexplained
    z = rng.standard_normal((2000, 1)) * 2.0
    assert residual_verdict(z, ["present_position"], np.array([0.8]), _phases(2000), pot_noise_max=pot) == \
        residual_verdict(z, ["present_position"], np.array([0.8]), _phases(2000))


def test_the_structure_message_s_figures_stay_in_sd_where_the_pot_noise_bound_binds():
    """The bound on the pot's noise whitens the size test only: the structure message (chosen when position keeps
    a time-correlated residual) reported its per-phase figure rescaled by sd / pot_noise_max, a different "sd" for
    the same residual with and without the bound."""
    n = 400
    rng = np.random.default_rng(0)
    raw = 1.6 * np.sin(np.arange(n) / 15.0) + rng.normal(0.0, 0.3, n)  # structured, small by size
    sd = np.array([3.0, 1.0])
    z = np.stack([raw / sd[0], rng.normal(0.0, 1.0, n)], axis=1)
    plain = residual_verdict(z, ["present_position", "present_speed"], sd, _phases(n))
    bound = residual_verdict(z, ["present_position", "present_speed"], sd, _phases(n), pot_noise_max=1.96)
    assert plain.detail.startswith("present_position keeps a time-correlated residual"), plain.detail
    assert bound.detail == plain.detail
