"""``ax12emu diagnose`` on a Wizard export of another AX model: the workflow starts from that servo's served model."""

from __future__ import annotations

import pytest

pytest.importorskip("scipy")

from ax12emu.cli.main import BASE_PARAMS_FILE, _from_the_served_servo  # noqa: E402
from ax12emu.protocol.servo_models import model  # noqa: E402
from ax12emu.servo.model_factory import datasheet_params  # noqa: E402
from firmware_model.diagnose.synthetic import wizard_step_export  # noqa: E402
from firmware_model.params import ServoParams  # noqa: E402


def _export(path, model_line: str):
    text = wizard_step_export(ServoParams(), 300.0, 2000.0).replace("AX-12A,12", model_line, 1)
    path.write_text(text, encoding="utf-8")
    return path


def test_an_ax18a_export_starts_from_the_served_ax18a(tmp_path, capsys):
    """Diagnosed against an AX-12A's motor, an AX-18A's step names the motor; the served AX-18A's parameters are
    written beside the report and given as --params, so the twin it writes serves as `--servo ax-18a --params`."""
    path = _export(tmp_path / "ax18.csv", "AX-18A,18")
    out = tmp_path / "report"
    args = _from_the_served_servo([str(path), "--out", str(out)])
    assert args == [str(path), "--out", str(out), "--params", str(out / BASE_PARAMS_FILE)]
    assert ServoParams.from_toml(out / BASE_PARAMS_FILE) == datasheet_params(model("ax-18a"))
    assert "starting from the served AX-18A's parameters" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [["--params", "mine.toml"], ["--bogus"]])
def test_given_parameters_an_ax12a_export_and_a_bad_command_line_are_left_as_they_are(tmp_path, extra):
    ax18 = [str(_export(tmp_path / "ax18.csv", "AX-18A,18")), "--out", str(tmp_path / "o"), *extra]
    assert _from_the_served_servo(ax18) == ax18
    ax12 = [str(_export(tmp_path / "ax12.csv", "AX-12A,12")), "--out", str(tmp_path / "o")]
    assert _from_the_served_servo(ax12) == ax12
    assert not (tmp_path / "o").exists()
    unknown = [str(_export(tmp_path / "ax99.csv", "AX-99,99")), "--out", str(tmp_path / "o")]
    assert _from_the_served_servo(unknown) == unknown


def test_the_model_comes_from_the_export_s_model_line_alone(tmp_path, monkeypatch):
    """Which servo's parameters to start from is read from the model line, not by parsing the export's rows, which
    the workflow then parses itself (a 120,000-row export was parsed twice before the row limit refused it)."""
    from firmware_model.diagnose import wizard

    def no_rows(*args, **kwargs):
        raise AssertionError("the export's rows were parsed")

    monkeypatch.setattr(wizard, "parse_wizard", no_rows)
    path = _export(tmp_path / "ax18.csv", "AX-18A,18")
    out = tmp_path / "report"
    assert _from_the_served_servo([str(path), "--out", str(out)])[-2:] == ["--params", str(out / BASE_PARAMS_FILE)]
