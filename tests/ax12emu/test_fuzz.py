"""Fuzzing the framer and request handling against an oracle (tools/fuzz.py), in short runs."""

from __future__ import annotations

import numpy as np
import pytest
from emu_testkit import load_tool
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ax12emu.protocol.packets import Instruction, StatusError
from ax12emu.servo import request_handler

fuzz = load_tool("fuzz")


def test_short_fuzz_run_finds_nothing():
    """A few seconds of PRNG-expanded cases: every invariant holds after every input."""
    stats = fuzz.fuzz(10**9, seconds=4.0, seed=20240611)
    assert stats.failure is None, f"{stats.failure}\nreproducer: {stats.reproducer}"
    assert stats.inputs > 2000


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_hypothesis_drawn_cases_hold_every_invariant(data):
    """The same grammar drawn through hypothesis (so a failure shrinks to a small case)."""
    case = fuzz.generate_case(fuzz.DataChooser(data), data.draw(st.integers(1, 12)))
    fuzz.run_case(case)


def test_fuzzer_catches_a_planted_bug(monkeypatch, tmp_path):
    """With WRITE ignoring access and range rules the oracle fails within seconds, with a replayable case."""

    def careless_write(servo, packet):
        address, data = packet.params[0], bytes(packet.params[1:])
        if len(packet.params) >= 2 and address + len(data) <= 50:
            servo.table.row[address : address + len(data)] = np.frombuffer(data, dtype=np.uint8)
        return StatusError.NONE, b""

    monkeypatch.setitem(request_handler.HANDLERS, Instruction.WRITE, careless_write)
    stats = fuzz.fuzz(10**9, seconds=10.0, seed=7)
    assert stats.failure is not None and "FuzzFailure" in stats.failure
    case = fuzz.Case.from_json(stats.reproducer)
    assert len(case.inputs) <= 3, "the failure is minimised"
    with pytest.raises(fuzz.FuzzFailure):
        fuzz.run_case(case)
    monkeypatch.undo()
    fuzz.run_case(case)  # the fixed handler passes the reproducer


def test_tool_main_prints_figures(capsys):
    """tools/fuzz.py main: count, rate and no failure for a small budget."""
    assert fuzz.main(["--inputs", "500", "--no-coverage", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "inputs/s" in out and "failures: 0" in out


def test_a_read_after_an_alarm_shutdown_within_the_same_input():
    """Found by ``--seed 41``: a broadcast write of Temperature Limit 22 (below the servo's 30 C), then in one input
    a READ over Torque Limit: the control step that write earned, taken before the READ, raised Overheating and
    the Alarm Shutdown zeroed Torque Limit, so the READ shows 0 where the oracle's table (which learns of the
    shutdown after the input) holds 255."""
    case = fuzz.Case(model="physical", reset_reply_from_new_id=True, inputs=[
        (bytes.fromhex("ffff0306aa037f0106c3ffff84054c03116b293426fffffe04030b16d9"), 0.0001, 0.0),
        (bytes.fromhex("ffff01"), 0.0001, 0.0),
        (bytes.fromhex("04020d707bfffffe05040301fdf7"), 0.0, 0.0)])
    assert fuzz.run_case(case) == 4
