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
def twin():
    params, volts, scale, result = tool.fit_twin(tool.ServoParams(), tool.load(DATA / tool.FIT_ON), 500)
    return params, result


def _real(name):
    return tool.real_features(tool.load(DATA / name))


def test_twin_replays_the_unloaded_step(twin):
    params, result = twin
    real = _real(tool.FIT_ON)
    assert abs(result["overshoot"] - real["overshoot"]) <= 4, (result["overshoot"], real)
    assert abs(result["dip"] - real["dip"]) <= 3, (result["dip"], real)
    assert result["rms"] < 5.0


@pytest.mark.parametrize("rec", [r for r in tool.RECORDINGS if r.servo == "AX-12A" and r.load_kg_m2 > 0],
                         ids=lambda r: r.file)
def test_twin_predicts_the_loaded_steps_with_only_the_bar_inertia(twin, rec):
    params, _ = twin
    if not (DATA / rec.file).exists():
        pytest.skip(f"{rec.file} not found in {DATA}")
    loaded = tool.dataclasses.replace(params, load_inertia_kg_m2=params.load_inertia_kg_m2 + rec.load_kg_m2)
    result = tool.evaluate(loaded, tool.load(DATA / rec.file), 500)
    real = _real(rec.file)
    assert abs(result["overshoot"] - real["overshoot"]) <= 4, (result["overshoot"], real)
    assert result["rms"] < 5.0


def test_default_model_overshoots_like_the_real_servo():
    """No fit: the default model at its 9.6 V; the model before the coasting bridge missed by 17 units."""
    rec = tool.load(DATA / tool.FIT_ON)
    real = tool.real_features(rec)
    assert abs(tool.evaluate(tool.ServoParams(), rec, 500)["overshoot"] - real["overshoot"]) <= 4
    assert real["overshoot"] - tool.evaluate(tool.BEFORE, rec, 500)["overshoot"] > 10


def test_missing_data_folder_is_a_clear_error(tmp_path, capsys):
    assert tool.main(["--data", str(tmp_path)]) == 2
    assert "not found" in capsys.readouterr().err
