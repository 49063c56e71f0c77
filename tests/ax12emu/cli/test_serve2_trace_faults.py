"""``ax12emu serve --servo`` with ``--trace`` and the wire's fault flags, driven by dynamixel-sdk PacketHandler(2.0).

The trace's header names the servos, so ``ax12emu decode`` shows their registers by name; a
dropped status is a timeout for the client and is missing from the trace.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler
from emu_testkit import PatientPortHandler, ok

pytestmark = pytest.mark.wallclock

LED = 65


def test_trace_and_dropped_replies_of_a_served_2_0_bus(tmp_path, emulator):
    path = tmp_path / "bus.jsonl"
    served = emulator("--servo", "1:xl430-w250,2:xl330-m077", "--trace", str(path), "--drop", "1", "--fault-ids", "2")
    port = PatientPortHandler(served.port)
    assert port.openPort() and port.setBaudRate(57600)
    ph = PacketHandler(2.0)
    try:
        assert ph.write1ByteTxRx(port, 1, LED, 1) == (COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 2, LED, 1)[0] == COMM_RX_TIMEOUT
        assert ok(ph.read1ByteTxRx(port, 1, LED)) == 1
    finally:
        port.closePort()
    assert served.stop() == 0
    result = subprocess.run([sys.executable, "-m", "ax12emu", "decode", str(path)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    lines = [line.split(None, 2)[2] for line in result.stdout.splitlines()]
    assert [line.split("  (+")[0] for line in lines] == [
        "WRITE id=1 led=1 (1 byte)",
        "STATUS id=1 ok",
        "WRITE id=2 led=1 (1 byte)",  # its status was dropped
        "READ id=1 led length=1",
        "STATUS id=1 ok led=1",
    ]
