"""tools/twin_check.py records at the priority tools/live_dataset.py records at (live_dataset.recording_priority).

Why: at the default priority on a shared 2-core machine the served emulator is descheduled for 10 ms and more, a
command then takes effect that late, and the diagnosis of twin_check's measurement rightly names a latency that is
no part of the hidden effect.  live_dataset raised the server's and the recorder's priority; twin_check did not.
"""

import sys
import types
from pathlib import Path

import numpy as np
from emu_testkit import load_tool

from firmware_model.diagnose.trace import Trace

TOOLS = Path(__file__).resolve().parents[2] / "tools"


def test_twin_check_records_with_the_server_and_itself_prioritised(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(TOOLS))
    calls, during = [], []

    def fake_record(port, servo_id, baud, duration_s, rate_hz, breakaway_s, writes):
        during.append(list(calls))
        t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
        n = len(t)
        return Trace({"t": t, "goal_position": np.full(n, 512), "moving_speed": np.zeros(n, dtype=np.int64),
                      "present_position": np.full(n, 512)})

    monkeypatch.setitem(sys.modules, "record", types.SimpleNamespace(record=fake_record))
    import live_dataset

    monkeypatch.setitem(sys.modules, "live_dataset", live_dataset)  # gone again after (it holds the fake record)
    monkeypatch.setattr(live_dataset, "_prioritise", lambda pid, realtime: calls.append((pid, realtime)) or 2)
    tool = load_tool("twin_check")

    class Served:
        port = "fake"
        process = types.SimpleNamespace(pid=4242, poll=lambda: None)

        def close(self):
            calls.append("closed")

    monkeypatch.setattr(tool, "start_served", lambda args, cwd: Served())
    tool.live_recorder(0.1, 100.0, 0.0)([], {}, tmp_path / "measured.csv")
    assert during == [[(4242, True), (0, False)]], during
    assert calls[-1] == "closed"
