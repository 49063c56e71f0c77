"""tools/record.py, the recorder users point at real servos: a port it cannot open is one line, not a traceback;
the trace says the supply the servo ran at."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from emu_testkit import load_tool

from firmware_model.diagnose.trace import read_trace

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("port", ["/dev/ax12emu-no-such-port", __file__])  # missing; a file that is no serial port
def test_a_port_that_cannot_be_opened_is_one_line(tmp_path, port):
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "record.py"), port, str(tmp_path / "out.csv")],
                            capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert result.returncode != 0 and "Traceback" not in result.stderr, result.stderr
    assert result.stderr.strip().startswith(f"cannot open {port}") and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize(("write", "says"), [("id=5", "another ID than --id"), ("baud_rate=34", "another rate"),
                                              ("status_return_level=1", "every write answered")])
def test_a_set_up_write_that_would_cut_the_recorder_off_is_refused_before_the_port_opens(tmp_path, write, says):
    """Such a write was sent: the servo moved, then the next write went unanswered (a servo now at ID 5)."""
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "record.py"), "/dev/ax12emu-no-such-port",
                             str(tmp_path / "out.csv"), "--write", write], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert result.returncode == 2 and says in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_the_trace_holds_the_supply_the_servo_reads(emulator, tmp_path):
    """A recording had no voltage column, so the diagnosis fitted a servo on 12 V at the model's 9.6 V and named
    the difference as friction; the recorder reads Present Voltage with the rest and writes it."""
    served = emulator("--ids", "1", "--voltage", "11.3")
    out = tmp_path / "rec.csv"
    subprocess.run([sys.executable, str(ROOT / "tools" / "record.py"), served.port, str(out), "--duration", "2",
                    "--rate", "50"], check=True, capture_output=True, timeout=60, cwd=ROOT)
    trace = read_trace(out)
    assert trace.has("voltage") and set(trace["voltage"].tolist()) == {113}


def test_a_wavering_supply_reading_is_one_value_with_a_comment():
    """Each change of a trace's voltage is a command the replay acts on: readings that waver with the motor's
    draw are written as their median, and the range they spanned is said."""
    record = load_tool("record")
    volts, notes = record.supply_column(np.array([120, 119, 120, 121, 120, 118]))
    assert volts.tolist() == [120] * 6 and notes == ["Present Voltage read 11.8-12.1 V; the voltage column is their "
                                                     "median, 12.0 V"]
    steady, notes = record.supply_column(np.array([96, 96]))
    assert steady.tolist() == [96, 96] and notes == []
