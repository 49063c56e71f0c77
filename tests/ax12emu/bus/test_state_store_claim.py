"""One server per state directory, and a server whose directory stops taking saves goes on serving."""

from __future__ import annotations

import logging
import os
import shutil
import subprocess
import sys

import pytest
from x2_testkit import recording_bus

from ax12emu.bus.bus import Bus
from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.state_store import StateFileError, StateStore
from ax12emu.protocol.packets import encode_instruction
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.servo.virtual_servo import ServoOptions


def test_a_second_claim_on_a_directory_names_the_holder_and_a_released_one_can_be_taken(tmp_path):
    first, second = StateStore(tmp_path), StateStore(tmp_path)
    first.claim()
    with pytest.raises(StateFileError, match=rf"in use by another server \(pid {os.getpid()}\)"):
        second.claim()
    first.release()
    second.claim()
    second.release()


def test_a_claim_clears_what_a_crash_left_mid_save_and_an_unclaimed_store_leaves_it(tmp_path):
    """The leftovers are cleared by the one process that owns the directory: a second server starting used to
    remove the first one's file mid-save, and the first died on the rename."""
    leftover = tmp_path / "servo-001.json8x2k.tmp"
    leftover.write_text("{")
    StateStore(tmp_path)
    assert leftover.exists()
    store = StateStore(tmp_path)
    store.claim()
    assert not leftover.exists()
    store.release()


def test_a_second_serve_on_the_same_state_dir_is_refused_in_one_line(tmp_path, emulator):
    emulator("--tcp", "127.0.0.1:0", "--state-dir", str(tmp_path))
    result = subprocess.run([sys.executable, "-m", "ax12emu", "serve", "--tcp", "127.0.0.1:0", "--state-dir", str(tmp_path)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and "in use by another server" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_an_ax12_bus_whose_directory_goes_serves_on_and_says_so_once(tmp_path, caplog):
    directory = tmp_path / "state"
    bus = Bus([1], clock=VirtualClock(), options=ServoOptions(eeprom_busy_s_per_byte=0.0), state_store=StateStore(directory))
    shutil.rmtree(directory)
    with caplog.at_level(logging.ERROR, logger="ax12emu.bus.state_store"):
        for delay in (10, 20):  # Return Delay Time: the EEPROM area
            replies = bus.receive(encode_instruction(1, 0x03, bytes([5, delay])))
            assert len(replies) == 1 and replies[0].data[4] == 0  # answered, no error
    assert bus.servo(1).table.get("return_delay_time") == 20
    bus.close()  # a server told to stop: it closes, saying nothing more (it raised, and serve exited 1)
    failures = [r for r in caplog.records if "could not keep the EEPROM" in r.getMessage()]
    assert len(failures) == 1, [r.getMessage() for r in caplog.records]


def test_a_protocol_2_bus_whose_directory_goes_serves_on(tmp_path, caplog):
    directory = tmp_path / "state"
    bus, _ = recording_bus(ids=(1,), key="xl430-w250", state_store=StateStore(directory))
    shutil.rmtree(directory)
    with caplog.at_level(logging.ERROR, logger="ax12emu.bus.state_store"):
        replies = bus.receive(encode_instruction2(1, Instruction2.WRITE, bytes((31, 0, 60))))  # Temperature Limit
    assert len(replies) == 1 and bus.servo(1).table.get("temperature_limit") == 60
    bus.close()
    assert any("could not keep the EEPROM" in r.getMessage() for r in caplog.records)
