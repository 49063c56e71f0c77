"""A single step recorded like a Wizard export: its arbitrary rests and its unrecorded write time are not evidence.

The recordings are made here by the model (a bar's inertia added to the "servo"), read every 20 ms and stamped
on the Wizard's 16 ms tick, the way the real AX-12A exports are (firmware_model.diagnose.wizard), with flat
stretches before and after the step as long as a user happened to wait.
"""

import dataclasses

import numpy as np
import pytest

from firmware_model.diagnose.cli import load_input, parse_args
from firmware_model.diagnose.evaluate import REST_COUNTS_S, Evaluator, rest_weights
from firmware_model.diagnose.search import _ranking_bic, diagnose
from firmware_model.diagnose.selection import WRITE_SHIFT, Selection
from firmware_model.diagnose.synthetic import make_trace
from firmware_model.diagnose.verdict import Candidate
from firmware_model.interface import Commands
from firmware_model.params import ServoParams
from firmware_model.physical import PhysicalModel

HEADER = ["DYNAMIXEL Graph,2", "AX-12A,12", "ItemCount,1", "Present Position,#ffff00,0,1,0", "Time[ms],Present Position"]


def _step(params: ServoParams, duration_ms: int) -> np.ndarray:
    """Present Position every ms after Goal Position 500 is written (index 0) to a servo holding 1, full speed."""
    full = lambda v: np.full(1, v, dtype=np.int64)  # noqa: E731
    cmds = Commands(torque_enable=full(1), goal_position=full(500), moving_speed=full(0), torque_limit=full(1023),
                    cw_angle_limit=full(0), ccw_angle_limit=full(1023), cw_compliance_margin=full(1),
                    ccw_compliance_margin=full(1), cw_compliance_slope=full(32), ccw_compliance_slope=full(32),
                    punch=full(32), temperature_limit=full(70), min_voltage_limit=full(60), max_voltage_limit=full(140))
    model = PhysicalModel(1, params=params, initial_position_raw=1)
    return np.array([1.0] + [model.advance(i * 1e-3, cmds).present_position[0] for i in range(1, duration_ms + 1)])


def _wizard_export(path, params: ServoParams, head_ms: float, tail_ms: float, phase_ms: float = 7.3, seed: int = 0):
    """The step read every 20 ms and stamped on the first 16 ms tick after each reading (the newest one wins), the
    pot's noise (0.25 units) added before the reading is rounded."""
    sim = _step(params, int(tail_ms) + 900)
    rng = np.random.default_rng(seed)
    rows = {}
    for read_ms in np.arange(phase_ms, head_ms + len(sim) - 1, 20.0):
        k = int(read_ms - head_ms)
        rows[int(np.ceil(read_ms / 16.0) * 16)] = int(round((1 if k < 0 else sim[min(k, len(sim) - 1)])
                                                             + rng.normal(0.0, 0.25)))
    path.write_text("\n".join(HEADER + [f"{t},{v}" for t, v in sorted(rows.items())]) + "\n", encoding="utf-8")
    return path


def _trace(path, params: ServoParams):
    args = parse_args([str(path), "--out", "unused", "--goal", "500", "--voltage", str(params.supply_voltage_v)])
    return load_input(args, params).trace


@pytest.fixture(scope="module")
def start():
    return ServoParams()


def test_rests_of_a_wizard_export_count_the_same_however_long_they_last(tmp_path, start):
    """Each arbitrary rest weighs REST_COUNTS_S of readings; the move's rows weigh one each; a 1-unit settled
    error costs the same after 2 s of waiting as after 6 s."""
    costs = []
    for tail_ms in (2000.0, 6000.0):
        trace = _trace(_wizard_export(tmp_path / f"tail{tail_ms:.0f}.csv", start, 1500.0, tail_ms), start)
        w = rest_weights(trace)
        pos = trace["present_position"]
        moving = (np.abs(pos - pos[0]) >= 2) & (np.abs(pos - pos[-1]) > 1)
        assert np.all(w[moving] == 1.0)
        spacing_s = float(np.median(np.diff(trace.t)))
        head = np.arange(len(pos)) < np.argmax(np.abs(pos - pos[0]) >= 2) - 1
        assert w[head].sum() * spacing_s == pytest.approx(REST_COUNTS_S)
        ev = Evaluator(trace, start)
        settled = w < 1.0
        settled[head] = False
        z = np.zeros((len(pos), 1))
        z[settled, 0] = 1.0 / ev.sd[0]  # one unit off while settled
        costs.append(sum(ev.costs(z)))
    assert costs[0] == pytest.approx(costs[1], rel=0.1), costs
    # a trace of a designed excitation has no arbitrary rests
    assert np.all(rest_weights(make_trace({}, 1, 4.0, 100.0)[0]) == 1.0)


def test_the_write_shift_is_a_base_parameter_only_of_a_single_unrecorded_step(tmp_path, start):
    wizard = Selection(_trace(_wizard_export(tmp_path / "w.csv", start, 1200.0, 2500.0), start), start, print)
    assert wizard.shifts_write and WRITE_SHIFT.name in wizard.base
    assert "delay_s" not in wizard.base  # reported as the write's, not as a reading latency
    for live in (False, True):
        sel = Selection(make_trace({}, 1, 4.0, 100.0, live=live)[0], start, print)
        assert not sel.shifts_write and WRITE_SHIFT.name not in sel.base


@pytest.mark.parametrize("bar_kg_m2", [0.0, 3e-3])
def test_a_bar_on_a_wizard_step_is_named_as_inertia_and_nothing_without_one(tmp_path, start, bar_kg_m2):
    """A bar of half the model's inertia, recorded like a Wizard export with a long wait after the step: named
    extra_inertia first with the bar inside its 95 % interval (before the rests were weighed and the write time
    re-fitted with each candidate, nothing was named); without a bar nothing is named."""
    servo = dataclasses.replace(start, load_inertia_kg_m2=start.load_inertia_kg_m2 + bar_kg_m2)
    d = diagnose(_trace(_wizard_export(tmp_path / "bar.csv", servo, 1400.0, 4000.0), start))
    if not bar_kg_m2:
        assert d.named == [], d.named
        return
    assert d.named[:1] == ["extra_inertia"], d.named
    j, half = d.accepted[0].values["extra_inertia_kg_m2"], d.accepted[0].uncertainty["extra_inertia_kg_m2"]
    assert abs(j - bar_kg_m2) <= half, (j, half)


def test_passing_candidates_are_ranked_on_one_sample_count():
    """A fit that removes more of the cost ranks first even when its own, smoother residual counts fewer
    independent samples (its own BIC gain, on its own count, is the smaller)."""
    from firmware_model.diagnose.effects import LIBRARY

    class _Sel:
        library = LIBRARY

    def cand(effect, cost, n_eff):
        return Candidate(effect, {}, {}, {}, cost, cost, 0.0, n_eff, True)

    inertia, play = cand("extra_inertia", 243.0, 13.0), cand("backlash", 461.0, 47.0)
    assert _ranking_bic(_Sel, inertia, 1350.0, 20.0) > _ranking_bic(_Sel, play, 1350.0, 20.0)
