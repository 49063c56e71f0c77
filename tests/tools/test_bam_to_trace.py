"""tools/bam_to_trace.py: a BAM pendulum log becomes an X-series trace in the servo's units, with its model file's data sheet."""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path

import numpy as np
import pytest

from firmware_model.diagnose.trace import read_trace
from firmware_model.diagnose.xreplay import replay_x
from firmware_model.xseries.bam_replay import GOAL_LEAD_S, READ_LEAD_S

_SPEC = importlib.util.spec_from_file_location("bam_to_trace", Path(__file__).resolve().parents[2] / "tools" / "bam_to_trace.py")
bam_to_trace = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bam_to_trace)


def _log(tmp_path: Path) -> Path:
    pulse = 2 * math.pi / 4096
    entries = [dict(timestamp=0.004 * k, position=(k // 10) * pulse, goal_position=0.2 if k >= 5 else 0.0,
                    speed=0.1 * k, load=65535 if k == 3 else k, input_volts=7.3, temp=30, torque_enable=k < 40)
               for k in range(50)]
    path = tmp_path / "log.json"
    path.write_text(json.dumps(dict(mass=0.49, length=0.1, kp=400, vin=7.4, motor="xl330", trajectory="t", entries=entries)))
    return path


def test_a_log_converts_to_a_trace_the_diagnosis_replays(tmp_path):
    out = tmp_path / "trace.csv"
    assert bam_to_trace.main([str(_log(tmp_path)), str(out)]) == 0
    tr = read_trace(out)
    assert tr.servo == "x" and tr.meta["model"] == "XL330-M288" and tr.meta["gear_ratio"] == 288.4
    assert tr.meta["position_p_gain"] == 400 and tr.meta["supply_v"] == 7.4 and tr.meta["position_output_scale"] == 0.5
    assert tr.meta["gravity_moment_nm"] == pytest.approx(0.49 * 9.80665 * 0.1)
    stamps = 0.004 * np.arange(50)
    np.testing.assert_allclose(tr["t"], stamps - READ_LEAD_S, atol=1e-6)
    rows = tr.change_rows()
    np.testing.assert_allclose(tr["command_t"][rows[1:]], stamps[rows[1:]] - GOAL_LEAD_S, atol=1e-9)
    assert tr["goal_position"][4] == 2048 and tr["goal_position"][5] == 2048 + round(0.2 / (2 * math.pi / 4096))
    assert tr["present_position"][25] == 2050 and tr["present_pwm"][3] == -1
    assert tr["present_velocity"][10] == round(1.0 / (0.229 * 2 * math.pi / 60))
    assert tr["torque_enable"][39] == 1 and tr["torque_enable"][40] == 0
    sim = replay_x(tr)  # the replay runs it: the goal pulls the shaft up
    assert sim["present_position"][39] > 2060


def test_an_unknown_model_is_refused(tmp_path, capsys):
    assert bam_to_trace.main([str(_log(tmp_path)), str(tmp_path / "x.csv"), "--model", "no-such-servo"]) == 2
    assert "error" in capsys.readouterr().err
