"""The CLI end to end, tools/make_dataset.py, and tools/record.py against the emulator."""

import json
import subprocess
import sys
from pathlib import Path

from firmware_model.diagnose.trace import read_trace
from firmware_model.params import ServoParams

ROOT = Path(__file__).resolve().parents[3]


def test_make_dataset_and_cli(tmp_path):
    """make_dataset writes trace + key; the CLI names the effect, prints JSON, writes report, plots, loadable TOML."""
    csv, key = tmp_path / "m.csv", tmp_path / "key.json"
    subprocess.run([sys.executable, str(ROOT / "tools/make_dataset.py"), str(csv), "--key", str(key),
                    "--effects", "gravity_load", "--seed", "3", "--duration", "8"], check=True, capture_output=True)
    assert json.loads(key.read_text())["effects"].keys() == {"gravity_load"}
    out = subprocess.run([sys.executable, "-m", "firmware_model.diagnose", str(csv), "--out", str(tmp_path / "o"),
                          "--json", "--effects", "gravity_load,coulomb_friction,delay"],
                         check=True, capture_output=True, text=True)
    verdict = json.loads(out.stdout)
    assert [e["effect"] for e in verdict["named"]] == ["gravity_load"]
    assert verdict["gap_rms_after"]["present_position"] < verdict["gap_rms_before"]["present_position"]
    assert "round 1" in out.stderr  # progress
    for f in ("report.md", "measured_vs_model.png", "residual_by_phase.png", "params.toml"):
        assert (tmp_path / "o" / f).stat().st_size > 0
    assert not (tmp_path / "o" / "effects.toml").exists()  # one file holds the whole twin
    fitted = ServoParams.from_toml(tmp_path / "o" / "params.toml")
    assert fitted.effects.present().keys() == {"arm_weight_moment_nm"}


def test_cli_reports_malformed_trace(tmp_path):
    """A malformed trace exits 2 with line and column, no traceback."""
    bad = tmp_path / "bad.csv"
    bad.write_text("t,goal_position,moving_speed,present_position\n0,512,0,512\n0.1,512,0,abc\n")
    r = subprocess.run([sys.executable, "-m", "firmware_model.diagnose", str(bad), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and ":3: column 'present_position'" in r.stderr and "Traceback" not in r.stderr


def test_record_against_emulator(emulator, tmp_path):
    """tools/record.py drives the emulated servo through the excitation and writes a valid, moving trace."""
    served = emulator("--ids", "1")
    out = tmp_path / "rec.csv"
    subprocess.run([sys.executable, str(ROOT / "tools/record.py"), served.port, str(out), "--duration", "3",
                    "--rate", "50"], check=True, capture_output=True, timeout=60)
    tr = read_trace(out)
    assert len(tr) > 50
    assert abs(int(tr["present_position"][-1]) - 512) > 20 or tr["present_position"].max() - tr["present_position"].min() > 20
