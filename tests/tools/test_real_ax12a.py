"""tools/real_ax12a.py: the model against real AX-12A step responses (Wizard 2 exports in ../shared/reference).

The goals: a twin fitted on the unloaded step replays it (overshoot +-4, dip
+-3, RMS at the best command onset under 5 units) and, with only each bar's
inertia added, predicts the loaded steps' overshoot within 4; the default
model, unfitted, is already within 4 of the unloaded overshoot.
"""

import pytest
from emu_testkit import load_tool

tool = load_tool("real_ax12a")
DATA = tool.DEFAULT_DATA

pytestmark = pytest.mark.skipif(not (DATA / tool.FIT_ON).exists(),
                                reason=f"real AX-12A recordings not found in {DATA} (kept outside the repository)")


@pytest.fixture(scope="module")
def twin(real_ax12a_twin):
    """fit_twin(ServoParams(), the unloaded step, 500), made once per process (tests/tools/conftest.py)."""
    params, volts, scale, result = real_ax12a_twin
    return params, result


def _real(name):
    return tool.real_features(tool.load(DATA / name))


def test_twin_replays_the_unloaded_step(twin):
    params, result = twin
    real = _real(tool.FIT_ON)
    assert abs(result["overshoot"] - real["overshoot"]) <= 4, (result["overshoot"], real)
    assert abs(result["dip"] - real["dip"]) <= 3, (result["dip"], real)
    assert result["rms"] < 5.0


@pytest.mark.parametrize("rec", [r for r in tool.RECORDINGS if r.servo == "AX-12A" and r.file != tool.FIT_ON],
                         ids=lambda r: r.file)
def test_twin_predicts_every_other_step_with_only_the_bar_inertia(twin, rec):
    """Every AX-12A step the README lists but the one the twin was fitted on: the loaded ones with their bar's J
    added, repeats of the unloaded one as they are."""
    params, _ = twin
    if not (DATA / rec.file).exists():
        pytest.skip(f"{rec.file} not found in {DATA}")
    loaded = tool.dataclasses.replace(params, load_inertia_kg_m2=params.load_inertia_kg_m2 + rec.load_kg_m2)
    result = tool.evaluate(loaded, tool.load(DATA / rec.file), 500)
    real = _real(rec.file)
    assert abs(result["overshoot"] - real["overshoot"]) <= 4, (result["overshoot"], real)
    assert result["rms"] < 5.0


#: What the diagnosis names first on each loaded step from the closed twin, where it misses (measured 2026-11-24).
#: Why, measured by tools/real_ax12a_inertia.py: recordings the twin made itself with each bar (read at the same
#: rows, 0.5 units of noise) name extra_inertia first on 5 of 6, the bar inside every interval (``--synthetic``), so
#: the workflow resolves a bar of this size on one step read every 20 ms.  On the real steps it fits 2.8-3.6 times
#: the bar, and the held-out rows (the peak and the return from it) get worse: the model's overshoot grows by about
#: 2 units per 1e-3 kg m^2 where the real servo's grows by 4-5, and the real servo returns from a loaded peak faster
#: (512 -> 500 units in 28.0 and 23.2 ms, the twin with the bar in 34.0 and 32.0).  The miss is the model's response
#: to inertia at the end of a move, and the twin itself: fitted the same way on servos unlike the default, whose
#: answer is known, the workflow names the bar first with its interval holding it on 16 of 36 synthetic steps
#: (tools/bench_twin.py), one unloaded step leaving the twin's inertia off by as much as a bar.
#: The held-out rows alone cost least within a grid step of each bar, the training rows at 2.5-3e-3 with the
#: gearbox efficiency and the write time traded for it (tools/real_ax12a_inertia.py --split).
NAMED_FROM_TWIN_MISSES = {
    "AX12A_LOAD3_1.csv": "names nothing from the twin: extra_inertia fits 2.6e-3 +- 6.0e-3 kg m^2 (3.6 x the bar; dBIC "
                         "19.8, 46 % of the cost) but the held-out rows of the move get worse (cost 116 vs 42)",
    "AX12A_LOAD2_1.csv": "names nothing from the twin: extra_inertia fits 2.8e-3 +- 1.8e-3 kg m^2 (2.8 x the bar, "
                         "outside the interval; dBIC 16.4, 41 % of the cost) but the held-out rows get worse (217 vs 184)",
}


def _diagnoser(params, tmp_path_factory):
    """file -> the diagnosis of that recording from ``params``, each run once."""
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.diagnose.search import diagnose

    done = {}

    def run(name):
        if name not in done:
            if not (DATA / name).exists():
                pytest.skip(f"{name} not found in {DATA}")
            args = parse_args([str(DATA / name), "--out", str(tmp_path_factory.mktemp("diagnosis")), "--goal", "500",
                               "--voltage", str(params.supply_voltage_v)])
            done[name] = diagnose(load_input(args, params).trace, params)
        return done[name]

    return run


@pytest.fixture(scope="module")
def from_twin(twin, tmp_path_factory):
    """The diagnosis of a recording from the twin as fitted (file -> Diagnosis), each run once."""
    return _diagnoser(twin[0], tmp_path_factory)


@pytest.fixture(scope="module")
def closed(twin):
    """The twin with what the workflow names on its own fit recording added (tool.close_twin), and that diagnosis."""
    return tool.close_twin(twin[0], DATA / tool.FIT_ON, 500)


@pytest.fixture(scope="module")
def from_closed_twin(closed, tmp_path_factory):
    """The diagnosis of a recording from the closed twin (file -> Diagnosis), each run once."""
    return _diagnoser(closed[0], tmp_path_factory)


@pytest.mark.parametrize("rec", [pytest.param(r, marks=pytest.mark.xfail(r.file in NAMED_FROM_TWIN_MISSES, strict=True,
                                                                        reason=NAMED_FROM_TWIN_MISSES.get(r.file, "")))
                                 for r in tool.RECORDINGS if r.servo == "AX-12A" and r.load_kg_m2 > 0],
                         ids=lambda r: r.file)
def test_diagnosis_from_the_twin_names_the_bar_inertia(from_closed_twin, rec):
    """From the twin (closed with what the unloaded step names), the workflow on a loaded step names extra_inertia
    first, its 95 % interval holding the bar's J."""
    d = from_closed_twin(rec.file)
    assert d.named and d.named[0] == "extra_inertia", d.named
    first = d.accepted[0]
    j, half = first.values["extra_inertia_kg_m2"], first.uncertainty["extra_inertia_kg_m2"]
    assert abs(j - rec.load_kg_m2) <= half, (j, half, rec.load_kg_m2)


def test_the_twin_leaves_nothing_to_name_on_its_own_step_and_names_no_play_anywhere(twin, from_twin, closed):
    """The twin leaves nothing to name on the recording it was fitted on, so the closed twin is the twin, and no gear
    play is named on any step.  (With the model's reading rounded, and every reading at rest counted as one, the same
    twin named 0.0097 rad of play on its own step: its settled level half a unit off a whole reading.)"""
    own = from_twin(tool.FIT_ON)
    assert own.named == [], own.named
    assert own.gaps_after["present_position"]["rms"] < 1.2, own.gaps_after["present_position"]
    params, closing = closed
    assert closing.named == [] and params == twin[0]
    for rec in (r for r in tool.RECORDINGS if r.servo == "AX-12A" and r.load_kg_m2 > 0):
        assert "backlash" not in from_twin(rec.file).named, rec.file


def test_default_model_overshoots_like_the_real_servo():
    """No fit: the default model at its 9.6 V; the model before the coasting bridge missed by 17 units."""
    rec = tool.load(DATA / tool.FIT_ON)
    real = tool.real_features(rec)
    assert abs(tool.evaluate(tool.ServoParams(), rec, 500)["overshoot"] - real["overshoot"]) <= 4
    assert real["overshoot"] - tool.evaluate(tool.BEFORE, rec, 500)["overshoot"] > 10


def test_missing_data_folder_is_a_clear_error(tmp_path, capsys):
    assert tool.main(["--data", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err
