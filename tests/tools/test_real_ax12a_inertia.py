"""tools/real_ax12a_inertia.py: what the real AX-12A steps say about the bars' inertia through the twin.

The figures are the documented reason the diagnosis does not identify the bars
(docs/diagnosis.md, "Against a real AX-12A"); the recordings are read from
../shared/reference and the tests skip where they are absent.
"""

import numpy as np
import pytest
from emu_testkit import load_tool

tool = load_tool("real_ax12a_inertia")
real = tool.real_ax12a
DATA = real.DEFAULT_DATA

pytestmark = pytest.mark.skipif(not (DATA / real.FIT_ON).exists(),
                                reason=f"real AX-12A recordings not found in {DATA} (kept outside the repository)")


@pytest.fixture(scope="module")
def twin(real_ax12a_twin):
    """fit_twin(ServoParams(), the unloaded step, 500)'s parameters, made once per process (tests/tools/conftest.py)."""
    return real_ax12a_twin[0]


def test_the_twin_read_like_the_wizard_peaks_where_the_loaded_steps_peak(twin):
    """Read every reading period, the twin with each bar's J peaks where the real loaded step does (within a
    unit): the loaded overshoots are predicted, and only the unloaded peak is 1-2 units high."""
    for rec in (r for r in real.RECORDINGS if r.servo == "AX-12A" and r.load_kg_m2 > 0):
        if not (DATA / rec.file).exists():
            pytest.skip(f"{rec.file} not found in {DATA}")
        measured = real.load(DATA / rec.file)
        period_ms = 1000.0 * tool.read_wizard(DATA / rec.file).read_period_s
        _, lo, hi = tool.peaks(twin, measured, rec.load_kg_m2, period_ms, 500)
        assert lo - 1 <= measured.pos.max() <= hi + 1, (rec.file, measured.pos.max(), lo, hi)


@pytest.fixture(scope="module")
def load3(twin):
    """LOAD3_1's recording entry and tool.profile of it from the twin, made once."""
    rec = next(r for r in real.RECORDINGS if r.file == "AX12A_LOAD3_1.csv")
    if not (DATA / rec.file).exists():
        pytest.skip(f"{rec.file} not found in {DATA}")
    return rec, tool.profile(twin, DATA / rec.file, 500)


def test_refitting_the_goal_write_never_costs_more_than_holding_it(load3):
    """The write time is a nuisance: re-fitted at each inertia it can only lower the cost (a single change owns
    every row after its window), and it lowers it most where inertia delays the start."""
    rec, p = load3
    assert np.all(p["refit"] <= p["fixed"] + 1e-6), (p["refit"], p["fixed"])
    at_bar = int(np.argmin(np.abs(tool.EXTRA_GRID_KG_M2 - rec.load_kg_m2)))
    assert p["refit"][at_bar] < 0.8 * p["fixed"][at_bar]
    lo, hi = p["move_region"]
    assert lo <= p["move_best"] <= hi


def test_the_move_rows_alone_hold_the_bar_but_too_little_to_name_it(load3):
    """On LOAD3_1's move rows (first movement to 120 ms after the peak) the 95 % region of extra inertia holds the
    bar and excludes none, yet the best point's BIC gain over none (measured 1.2) is far below the margin the
    workflow names at: one step's move does not carry this bar's signature strongly enough to name it."""
    rec, p = load3
    lo, hi = p["move_region"]
    assert lo <= rec.load_kg_m2 <= hi and lo > 0.0, p["move_region"]
    assert p["move_dbic"] < tool.BIC_MARGIN, p["move_dbic"]


def test_missing_data_folder_is_a_clear_error(tmp_path, capsys):
    assert tool.main(["--data", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err


def test_the_return_from_the_peak_is_timed_between_its_levels():
    """A made-up step: up to 520 at row 10, then down one unit a ms; 512 to 500 is 12 ms however it is sampled."""
    t = np.arange(0.0, 60.0)
    pos = np.where(t <= 10, 500 + 2 * t, 530 - t)
    assert tool.return_ms(t, pos) == pytest.approx(12.0)
    assert tool.return_ms(t[::3], pos[::3]) == pytest.approx(12.0)
    with pytest.raises(ValueError, match="does not fall through 500"):
        tool.return_ms(t[:25], pos[:25])


#: The loaded steps whose return from the peak docs/diagnosis.md quotes (the figures of a known miss, not a goal).
RETURN_QUOTED = ("AX12A_LOAD3_1.csv", "AX12A_LOAD2_1.csv")


def test_the_real_servo_returns_from_a_bars_peak_faster_than_the_twin_with_the_bar(twin):
    """Why the held-out rows (the peak and the return) reject the bar from the twin: the real loaded steps fall
    from 512 to 500 units at least 4 ms sooner than the twin with the bar's J does (measured 28.0 vs 34.0 and
    23.2 vs 32.0 ms), where the unloaded step is within the readings' few ms (33.7 vs 37.0)."""
    for rec in (r for r in real.RECORDINGS if r.file in RETURN_QUOTED):
        if not (DATA / rec.file).exists():
            pytest.skip(f"{rec.file} not found in {DATA}")
        ex = tool.read_wizard(DATA / rec.file)
        measured = tool.return_ms(1000.0 * ex.times_s, ex.values["present_position"].astype(float))
        loaded = tool.dataclasses.replace(twin, load_inertia_kg_m2=twin.load_inertia_kg_m2 + rec.load_kg_m2)
        sim = real.simulate(loaded, int(ex.values["present_position"][0]), 500, 900)
        modelled = tool.return_ms(np.arange(len(sim), dtype=float), sim)
        assert measured <= modelled - 4.0, (rec.file, measured, modelled)


@pytest.fixture(scope="module")
def closed(twin):
    """The twin closed with what the workflow names on its own fit recording (real.close_twin)."""
    return real.close_twin(twin, DATA / real.FIT_ON, 500)[0]


@pytest.mark.parametrize("name", RETURN_QUOTED)
def test_the_workflow_names_a_bar_on_a_step_the_twin_recorded_with_it(closed, name):
    """The synthetic check: a loaded step re-made by the closed twin with the bar's J, read at the real rows with
    0.5 units of noise: on at least 2 of the 3 seeds the diagnosis names extra_inertia first with the bar inside
    its interval (measured 2 of 3 on LOAD3_1, 3 of 3 on LOAD2_1; with the model's reading rounded, 0 of 3 on each).
    So where it misses on the real steps, the model's response to inertia is what is missing, not the workflow's
    reach."""
    rec = next(r for r in real.RECORDINGS if r.file == name)
    if not (DATA / rec.file).exists():
        pytest.skip(f"{rec.file} not found in {DATA}")
    found = []
    for seed in range(tool.SYNTHETIC_SEEDS):
        d = tool.diagnose(tool.synthetic_trace(closed, DATA / rec.file, 500, rec.load_kg_m2, tool.SYNTHETIC_SIGMA_UNITS,
                                               seed), closed)
        first = d.accepted[0] if d.named[:1] == ["extra_inertia"] else None
        found.append(first is not None and abs(first.values["extra_inertia_kg_m2"] - rec.load_kg_m2)
                     <= first.uncertainty["extra_inertia_kg_m2"])
    assert sum(found) >= 2, found


@pytest.mark.parametrize("name", RETURN_QUOTED)
def test_the_held_out_rows_find_the_bar_where_the_training_rows_find_more_than_twice_it(closed, name):
    """From the closed twin, the base re-fitted at each extra inertia (tool.split_profile): the held-out rows of the
    step (its peak and the return from it) cost least within a grid step of the bar (measured 0.75e-3 for 0.727e-3,
    1.25e-3 for 1.019e-3), the training rows (the start, the approach, the rest) at 2.5-3e-3, the gearbox efficiency
    and the goal write's time traded for it.  Why the workflow fits 2.6-2.8e-3 and the held-out rows reject it:
    the model's start, approach and rest want more inertia than its peak does (docs/diagnosis.md)."""
    rec = next(r for r in real.RECORDINGS if r.file == name)
    if not (DATA / rec.file).exists():
        pytest.skip(f"{rec.file} not found in {DATA}")
    rows = tool.split_profile(closed, DATA / rec.file, 500)
    held = min(rows, key=lambda row: row["held"])["extra_kg_m2"]
    train = min(rows, key=lambda row: row["train"])["extra_kg_m2"]
    assert abs(held - rec.load_kg_m2) <= 0.25e-3 + 1e-9, (held, rec.load_kg_m2)
    assert train >= 2.0 * rec.load_kg_m2, (train, rec.load_kg_m2)
