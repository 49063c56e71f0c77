"""SIGKILL during bursts of EEPROM writes never leaves a corrupt, partial or stale state (tools/crash_state.py)."""

from __future__ import annotations

import numpy as np
from emu_testkit import load_tool

from ax12emu.bus.state_store import StateStore
from ax12emu.protocol.control_table import ControlTable

crash_state = load_tool("crash_state")


def test_sigkill_during_write_bursts_leaves_old_or_new_state(tmp_path):
    """15 kills at random moments: every restart loads one whole write, no older than the last acknowledged."""
    report = crash_state.run(15, seed=6, state_dir=tmp_path)
    assert report.failures == []
    assert report.iterations == 15
    assert report.kills_mid_burst >= 10, "most kills must land while writes are still being saved"


def test_leftover_temporary_files_are_removed_at_start(tmp_path):
    """A temporary file left by a kill between create and rename is removed when a server claims the store (the one
    process that owns the directory); the state stays."""
    store = StateStore(tmp_path)
    table = ControlTable(np.zeros(50, dtype=np.uint8))
    table.set("id", 7)
    store.save(1, table)
    (tmp_path / "servo-001.jsonab12cd.tmp").write_text('{"eeprom": {"id"')
    unrelated = tmp_path / "notes.tmp"
    unrelated.write_text("keep")
    claimed = StateStore(tmp_path)
    claimed.claim()
    claimed.release()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lock", "notes.tmp", "servo-001.json"]
    fresh = ControlTable(np.zeros(50, dtype=np.uint8))
    assert StateStore(tmp_path).load(1, fresh) and fresh.get("id") == 7
