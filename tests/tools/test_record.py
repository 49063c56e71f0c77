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
