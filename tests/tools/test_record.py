"""tools/record.py, the recorder users point at real servos: a port it cannot open is one line, not a traceback."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

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
