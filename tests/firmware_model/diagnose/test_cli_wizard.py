"""The command line on Wizard 2 graph exports: detected, assumptions printed and overridable, bad options refused."""

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from firmware_model.diagnose.cli import main

ROOT = Path(__file__).resolve().parents[3]
REAL = ROOT / ".." / "shared" / "reference" / "real-ax12a"


def _cli(*argv) -> subprocess.CompletedProcess:
    """The CLI in its own process (plotting keeps matplotlib's font files open for the life of a process)."""
    return subprocess.run([sys.executable, "-m", "firmware_model.diagnose", *map(str, argv)],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)


def _wizard_file(path: Path, onset_s: float = 1.2347, seed: int = 5) -> Path:
    """A Wizard-format export of the model's own step response (goal 1 -> 500 at ``onset_s``), with flawed rows."""
    from test_nuisance import _step_response  # the same model-made recording the onset tests use

    _, pos, t = _step_response(onset_s, seed)
    lines = ["DYNAMIXEL Graph,2", "AX-12A,12", "ItemCount,1", "Present Position,#ffff00,0,1,0",
             "Time[ms],Present Position"]
    for i, (ti, p) in enumerate(zip(t, pos)):
        lines.append(f"{int(round(ti * 1000))},{p}")
        if i == 120:
            lines += [f"{int(round(ti * 1000)) % 10},{p}", str(p)]  # a lost digit of the time, a lost field
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


@pytest.fixture(autouse=True)
def _importable(monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).parent))


def test_wizard_export_end_to_end(tmp_path):
    """Detected without a flag; skipped rows counted; the goal write located; assumptions in stdout, report, JSON."""
    f = _wizard_file(tmp_path / "w.csv")
    r = _cli(f, "--out", tmp_path / "o", "--json", "-q")
    assert r.returncode == 0, r.stderr
    verdict = json.loads(r.stdout)
    facts = verdict["input"]
    assert facts["format"] == "wizard" and facts["skipped"] == {"garbled": 1, "repeated_time": 0, "time_back": 1}
    assert facts["goal"] == 500 and facts["moving_speed"] == 0 and facts["voltage_v"] == 12.0
    assert facts["onset_source"] == "estimated" and abs(facts["onset_s"] - 1.234) <= 0.002
    assert verdict["named"] == []  # the model's own response: nothing to name
    assert verdict["recording"]["not_offered"].keys() == {"delay"}
    report = (tmp_path / "o" / "report.md").read_text()
    assert "## Input and assumptions" in report and "assumed: goal 500 written once" in report
    assert "12.0 V — override with --goal" in report and "1 garbled, 1 time back" in report
    assert "pinned" not in report  # the model's own response: the write needs no pinning before the movement


def test_the_params_file_serves_the_twin_at_the_supply_it_was_fitted_at(tmp_path):
    """--voltage 9 (or the trace's voltage column) is what the fit simulated: params.toml carries it, so the served
    twin reads and moves as fitted (it was written at the default 9.6 V whatever the fit ran at)."""
    from firmware_model.params import ServoParams

    f = _wizard_file(tmp_path / "w.csv")
    r = _cli(f, "--out", tmp_path / "o", "-q", "--voltage", "9")
    assert r.returncode == 0, r.stderr
    params = ServoParams.from_toml(tmp_path / "o" / "params.toml")
    assert params.supply_voltage_v == 9.0
    assert "# supply_voltage_v: the supply given (--voltage), 9 V" in (tmp_path / "o" / "params.toml").read_text()


def test_overrides_are_used_and_reported(tmp_path):
    """--goal, --onset, --moving-speed and --voltage replace the defaults; a given onset is known, so delay is offered."""
    f = _wizard_file(tmp_path / "w.csv")
    r = _cli(f, "--out", tmp_path / "o", "-q", "--goal", "500", "--onset", "1.2347", "--moving-speed", "0",
             "--voltage", "12", "--effects", "delay,coulomb_friction")
    assert r.returncode == 0, r.stderr
    out = r.stdout
    assert "written at 1.235 s (given, so known)" in out and "not offered" not in out


@pytest.mark.parametrize("argv, words", [
    (["--goal", "2000"], "--goal must be 0..1023"),
    (["--moving-speed", "-1"], "--moving-speed must be 0..1023"),
])
def test_bad_option_values(tmp_path, argv, words, capsys):
    """Out-of-range raw values are refused by the parser (exit 2) with the option named."""
    with pytest.raises(SystemExit) as info:
        main([str(tmp_path / "w.csv"), "--out", str(tmp_path / "o"), *argv])
    assert info.value.code == 2 and words in capsys.readouterr().err


def test_wizard_options_refused_for_a_trace_and_bad_voltage(tmp_path, capsys):
    """A trace CSV records its commands, so Wizard options are an error; a voltage out of range too."""
    tr = tmp_path / "t.csv"
    tr.write_text("t,goal_position,moving_speed,present_position\n0,512,0,512\n0.01,512,0,512\n")
    assert main([str(tr), "--out", str(tmp_path / "o"), "--goal", "500"]) == 2
    assert "--goal applies only to Wizard 2 graph exports" in capsys.readouterr().err
    assert main([str(tmp_path / "absent.csv"), "--out", str(tmp_path / "o"), "--goal", "500"]) == 2
    err = capsys.readouterr().err
    assert "No such file" in err and "trace CSV" not in err, err
    tr.write_text("t,goal_position,moving_speed,present_position,voltage\n0,512,0,512,50\n0.01,512,0,512,50\n")
    assert main([str(tr), "--out", str(tmp_path / "o")]) == 2  # 5.0 V: simulated, naming a negative friction
    assert "the voltage column's 5.0 V is outside" in capsys.readouterr().err
    f = _wizard_file(tmp_path / "w.csv")
    assert main([str(f), "--out", str(tmp_path / "o"), "--voltage", "30"]) == 2
    assert "--voltage 30.0 V is outside" in capsys.readouterr().err
    for onset in ("1e9", "-1e4"):  # a write outside the recording: it was fitted, meaninglessly
        assert main([str(f), "--out", str(tmp_path / "o"), f"--onset={onset}"]) == 2
        assert "the goal must be written within the recording" in capsys.readouterr().err


def test_a_flag_for_a_plotted_item_is_refused_and_a_recorded_supply_is_checked(tmp_path, capsys):
    """--goal with Goal Position plotted was ignored while the report still offered it; a plotted Present Voltage
    outside the model's range was simulated.  --voltage takes a recorded supply's place (a servo runs past the
    model's range: an AX-12A alarms only at 14 V), and the refusal says so; it was refused, a dead end."""
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.params import ServoParams

    lines = ["DYNAMIXEL Graph,2", "AX-12A,12", "ItemCount,3", "Present Position,#ffff00,0,1,0",
             "Goal Position,#00ff00,0,1,0", "Present Voltage,#0000ff,0,1,0",
             "Time[ms],Present Position,Goal Position,Present Voltage"]
    lines += [f"{16 * i},{min(1 + 20 * max(i - 5, 0), 500)},{1 if i < 5 else 500},{{volts}}" for i in range(60)]
    f = tmp_path / "w.csv"
    f.write_text("\n".join(lines).replace("{volts}", "120") + "\n")
    for flag in (["--goal", "300"], ["--onset", "0.05"]):
        assert main([str(f), "--out", str(tmp_path / "o"), *flag]) == 2
        assert "the export records" in capsys.readouterr().err
    f.write_text("\n".join(lines).replace("{volts}", "135") + "\n")  # 13.5 V: outside the AX-12A's 7..12 V
    assert main([str(f), "--out", str(tmp_path / "o")]) == 2
    assert ("the recorded Present Voltage (median) 13.5 V is outside the valid 7.0-12.0 V: give the supply to fit at "
            "with --voltage") in capsys.readouterr().err
    given = load_input(parse_args([str(f), "--out", str(tmp_path / "o"), "--voltage", "12"]), ServoParams())
    assert given.supply == "given" and set(given.trace["voltage"].tolist()) == {120}
    assert "--voltage 12 V in place of the recorded 13.5 V (median)" in given.notes


def test_params_with_an_effect_the_fit_cannot_simulate_exit_2(tmp_path, capsys):
    """A command delay in [effects] cannot be simulated by the fit (it would be diagnosed as if absent): refused."""
    params = tmp_path / "p.toml"
    params.write_text("[effects]\ncommand_delay_s = 0.01\n", encoding="utf-8")
    f = _wizard_file(tmp_path / "w.csv")
    assert main([str(f), "--out", str(tmp_path / "o"), "--params", str(params)]) == 2
    assert "command_delay_s cannot be simulated" in capsys.readouterr().err


def test_malformed_wizard_export_exits_2(tmp_path):
    """A broken header is reported with file and line, no traceback."""
    bad = tmp_path / "bad.csv"
    bad.write_text("DYNAMIXEL Graph,2\nAX-12A,12\nItemCount,x\n")
    r = _cli(bad, "--out", tmp_path / "o")
    assert r.returncode == 2 and "bad.csv:3: expected 'ItemCount,<n>'" in r.stderr and "Traceback" not in r.stderr


def test_real_export_runs(tmp_path):
    """A shared real export goes through: rows counted, assumptions stated, a verdict (whatever it is) printed."""
    if not REAL.is_dir():
        pytest.skip(f"real AX-12A exports not present at {REAL.resolve()}")
    r = _cli(REAL / "AX12A_NOLOAD_1.csv", "--out", tmp_path / "o", "--json", "-q", "--goal", "500")
    assert r.returncode == 0, r.stderr
    v = json.loads(r.stdout)
    assert v["input"]["rows_read"] == 205 and v["input"]["onset_source"] == "estimated"
    # stamped 1.936 s after the first row; read on the Wizard's ~20 ms clock, 1.942 s after the first reading
    assert v["input"]["reading_period_s"] == pytest.approx(0.020, abs=5e-4)
    assert v["input"]["first_movement_s"] == pytest.approx(1.942, abs=0.002)
    assert 1.85 < v["input"]["onset_s"] < v["input"]["first_movement_s"]  # before the first reading that moved
    assert np.isfinite(v["gap_rms_after"]["present_position"])


@pytest.mark.parametrize(("moving_speed", "supply_v", "words"), [
    (300, 9.6, r"a Moving Speed of about (29\d|30\d) "),  # speed-limited: 300 x 0.111 rpm, slower than at any supply
    (0, 9.6, r"a lower supply, about 9\.[5-7] V \(--voltage\)"),  # full speed at 9.6 V, assumed 12 V
])
def test_a_step_slower_than_the_model_says_which_command_would_explain_it(tmp_path, moving_speed, supply_v, words):
    """An export does not record Moving Speed or the supply: a step that cruised well below the model's top speed
    at the assumed 12 V gets a note saying what would explain it, and the assumption stays the user's to change."""
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.diagnose.synthetic import wizard_step_export
    from firmware_model.params import ServoParams

    params = ServoParams(supply_voltage_v=supply_v)
    path = tmp_path / "w.csv"
    path.write_text(wizard_step_export(params, 300.0, 5000.0, moving_speed=moving_speed), encoding="utf-8")
    notes = load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams()).notes
    assert any(re.search(words, note) for note in notes), notes
    given = load_input(parse_args([str(path), "--out", str(tmp_path / "o"), "--moving-speed", str(moving_speed),
                                   "--voltage", str(supply_v)]), ServoParams()).notes
    assert not any("cruises" in note for note in given), given


def test_a_full_speed_step_at_the_assumed_supply_gets_no_cruise_note(tmp_path):
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.diagnose.synthetic import wizard_step_export
    from firmware_model.params import ServoParams

    path = tmp_path / "w.csv"
    path.write_text(wizard_step_export(ServoParams(supply_voltage_v=12.0), 300.0, 5000.0), encoding="utf-8")
    assert not any("cruises" in n for n in load_input(parse_args([str(path), "--out", str(tmp_path)]), ServoParams()).notes)


def test_an_export_resting_far_from_the_default_goal_asks_for_it(tmp_path):
    """A step to 300 without --goal was fitted against 500 (gap 146.55 -> 143.60, a twin written, exit 0): the
    distance was read as physics.  A step that settles short of 500, as the real ones do, still runs."""
    from firmware_model.diagnose.cli import load_input, parse_args
    from firmware_model.diagnose.synthetic import wizard_step_export
    from firmware_model.params import ServoParams

    path = tmp_path / "w.csv"
    path.write_text(wizard_step_export(ServoParams(supply_voltage_v=12.0), 300.0, 2000.0, goal=300), encoding="utf-8")
    with pytest.raises(ValueError, match=r"comes to rest at 29\d, 20\d units from the default goal 500 .* with --goal$"):
        load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    given = load_input(parse_args([str(path), "--out", str(tmp_path / "o"), "--goal", "300"]), ServoParams())
    assert given.facts["goal"] == 300
    # resting 20 units off 500 is within what a servo (a loaded one, say) settles from its goal: taken as a step to 500
    path.write_text(wizard_step_export(ServoParams(supply_voltage_v=12.0), 300.0, 2000.0, goal=482), encoding="utf-8")
    assert load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams()).facts["goal"] == 500
    from firmware_model.diagnose.cli import SETTLES_WITHIN_UNITS

    assert SETTLES_WITHIN_UNITS == 33  # the e-manual's compliance margin 1 and slope 32
    # a rest read with a pot's noise (a spread of 4 units) is still a rest
    text = wizard_step_export(ServoParams(supply_voltage_v=12.0), 300.0, 2000.0, goal=800, noise_units=1.0,
                              seed=1).splitlines()
    path.write_text("\n".join(text) + "\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"comes to rest at 79\d, 29\d units from the default goal 500"):
        load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    # a rest whose last two readings alone seem to head for 500 (801 ... 796): the whole run of them says rest
    rows = [k for k, line in enumerate(text) if line[:1].isdigit()]
    for k, value in zip(rows[-5:], (801, 797, 798, 799, 796)):
        text[k] = f"{text[k].split(',')[0]},{value}"
    path.write_text("\n".join(text) + "\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"comes to rest at 79\d, 29\d units from the default goal 500"):
        load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    # cut off while still moving away from 500, past it: that was no step to 500
    text = wizard_step_export(ServoParams(supply_voltage_v=12.0), 300.0, 2000.0, goal=900).splitlines()
    cut = next(k for k, line in enumerate(text) if line[:1].isdigit() and int(line.split(",")[1]) > 700)
    path.write_text("\n".join(text[:cut + 1]) + "\n", encoding="utf-8")
    with pytest.raises(ValueError, match=r"ends moving away from the default goal 500, at 7\d\d"):
        load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    # an export that ends mid-move shows no rest at all, so nothing about its goal: taken as a step to 500, as before
    text = wizard_step_export(ServoParams(supply_voltage_v=12.0), 300.0, 2000.0, goal=500).splitlines()
    cut = next(k for k, line in enumerate(text) if line[:1].isdigit() and int(line.split(",")[1]) > 300)
    path.write_text("\n".join(text[:cut + 1]) + "\n", encoding="utf-8")  # the export stops at about 300 units
    moving = load_input(parse_args([str(path), "--out", str(tmp_path / "o")]), ServoParams())
    assert moving.facts["goal"] == 500 and 300 < moving.trace["present_position"][-1] < 460


def test_the_help_says_which_supply_another_ax_models_export_gets(capsys):
    """ax12emu diagnose gives an AX-18A's export the served AX-18A's parameters, so 11.1 V; --help said 12.0."""
    with pytest.raises(SystemExit):
        main(["--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert "another AX model's Wizard export (an AX-18A's) that model's served parameters as --params, so its served " \
           "supply" in help_text
    assert "in place of a recorded one" in help_text
