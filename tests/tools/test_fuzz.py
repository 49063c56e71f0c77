"""tools/fuzz.py beyond its oracle (tested in tests/ax12emu/test_fuzz.py; tools/fuzz2.py's in tests/tools/test_fuzz2.py):
the coverage figure's module names, the driver loop both fuzzers run (on a toy oracle here: it stops at the first
failing case and keeps that case's error and a minimised reproducer), and a replay of a file that holds no case."""

from __future__ import annotations

import json
from dataclasses import dataclass

import pytest
from emu_testkit import load_tool

fuzz = load_tool("fuzz")


@dataclass
class ToyCase:
    inputs: list[tuple[int, float, float]]

    def to_json(self) -> str:
        return json.dumps([value for value, _, _ in self.inputs])


def _make(case_seed: int, count: int) -> ToyCase:
    return ToyCase([((case_seed >> (4 * i)) % 40, 0.1, 0.001) for i in range(count)])


def _run(case: ToyCase) -> int:
    """The toy oracle: an input of 13 is a bug."""
    values = [value for value, _, _ in case.inputs]
    if 13 in values:
        raise AssertionError(f"13 fed as input {values.index(13)}")
    return len(values)


def test_drive_stops_at_the_first_failure_with_its_error_and_a_minimised_reproducer():
    tallies: list[int] = []
    stats = fuzz.drive(fuzz.Stats(), _make, _run, lambda case: fuzz.minimise(case, run=_run), 10**6,
                       round_seed=lambda k: 5 + k, pieces=12, batch=50, counted=lambda case, fed: tallies.append(fed))
    assert stats.failure.startswith("AssertionError: 13 fed as input "), stats.failure
    assert stats.failure.endswith("minimised (1 inputs): AssertionError: 13 fed as input 0")
    assert json.loads(stats.reproducer) == [13]
    assert sum(tallies) == stats.inputs and len(tallies) == stats.cases  # the passing cases, counted once each


def test_drive_spends_its_budget_and_repeats_with_its_seeds():
    def passing(case: ToyCase) -> int:
        return len(case.inputs)

    runs = [fuzz.drive(fuzz.Stats(), _make, passing, lambda case: case, 500, round_seed=lambda k: 9 + k, pieces=12,
                       batch=20) for _ in range(2)]
    assert runs[0].failure is None and runs[0].inputs >= 500
    assert (runs[0].inputs, runs[0].cases) == (runs[1].inputs, runs[1].cases)


def test_replay_of_a_file_that_holds_no_case_is_a_one_line_error(tmp_path, capsys):
    other = tmp_path / "fuzz2-failure.json"
    other.write_text('{"inputs": [], "bus": "2.0"}')
    assert fuzz.main(["--replay", str(other)]) == 2
    assert fuzz.main(["--replay", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("error: ") for line in err), err


def test_the_coverage_figure_names_modules_that_exist():
    """Both fuzzers' coverage is measured on the files named here (ax12emu/<path>.py): a stale name measures nothing."""
    from pathlib import Path

    fuzz2 = load_tool("fuzz2")
    package = Path(fuzz.__file__).resolve().parents[1] / "ax12emu"
    for tool in (fuzz, fuzz2):
        missing = [name for name in tool.TARGET_MODULES if not (package / f"{name}.py").is_file()]
        assert not missing, f"{tool.__name__}: {missing}"


def test_the_mx_wire_holds_every_invariant_and_both_wires_run():
    """A few thousand inputs on both wires: the MX wire (an MX-28, an MX-64 and an AX-12A) among them."""
    stats = fuzz.fuzz(4000, seed=20261123)
    assert stats.failure is None, f"{stats.failure}\nreproducer: {stats.reproducer}"
    assert stats.by_wire.get("mx", 0) > 0 and stats.by_wire.get("ax12", 0) > 0


def _refused_but_written(monkeypatch):
    from ax12emu.protocol.packets import Instruction
    from ax12emu.servo import request_handler1x

    original = request_handler1x.HANDLERS[Instruction.WRITE]

    def write(servo, packet):
        error, data = original(servo, packet)
        params = bytes(packet.params)
        if error and len(params) >= 2:  # the reply says refused, the table takes the bytes anyway
            for offset, byte in enumerate(params[1:][: max(0, servo.table.size - params[0])]):
                servo.table.row[params[0] + offset] = byte
        return error, data

    monkeypatch.setitem(request_handler1x.HANDLERS, Instruction.WRITE, write)


def _read_one_byte_off(monkeypatch):
    from ax12emu.servo import request_handler1x

    original = request_handler1x.listed_read

    def listed_read(servo, address, length):
        return original(servo, address + 1, length)

    monkeypatch.setattr(request_handler1x, "listed_read", listed_read)


def _reply_from_the_next_id(monkeypatch):
    from ax12emu.protocol.packets import encode_status
    from ax12emu.servo import request_handler1x

    original = request_handler1x.handle1x

    def handle1x(servo, packet):
        outcome = original(servo, packet)
        if outcome.reply is None:
            return outcome
        return outcome._replace(reply=encode_status((servo.id + 1) % 253, outcome.reply[4], outcome.reply[5:-1]))

    monkeypatch.setattr(request_handler1x, "handle1x", handle1x)
    monkeypatch.setattr("ax12emu.bus.bus1x.handle1x", handle1x)


@pytest.mark.parametrize("plant", [_refused_but_written, _read_one_byte_off, _reply_from_the_next_id])
def test_the_mx_checks_catch_a_planted_bug(monkeypatch, plant):
    """Each planted MX bug fails the MX wire's checks within seconds, with a minimised case the real code passes."""
    plant(monkeypatch)
    stats = fuzz.fuzz(10**9, seconds=15.0, seed=11, wire="mx")
    assert stats.failure is not None and "FuzzFailure" in stats.failure, stats.failure
    case = fuzz.Case.from_json(stats.reproducer)
    assert case.wire == "mx" and len(case.inputs) <= 4, "the failure is minimised"
    with pytest.raises(fuzz.FuzzFailure):
        fuzz.run_case(case)
    monkeypatch.undo()
    fuzz.run_case(case)


def _packet(servo_id: int, instruction: int, params: bytes, *, bad_checksum: bool = False) -> bytes:
    from ax12emu.protocol.packets import encode_instruction

    data = bytearray(encode_instruction(servo_id, instruction, params))
    if bad_checksum:
        data[-1] ^= 0xFF
    return bytes(data)


def _shutdown_case(wire: str, *, reply_on_checksum_error: bool = True):
    """Alarm Shutdown 0x7F on ID 1, then a Range, an Instruction and a Checksum Error sent to it, Torque Limit
    written back to 1023 before each (the oracles must expect Torque Limit 0 after each)."""
    restore = _packet(1, 0x03, bytes([34, 0xFF, 0x03]))
    inputs = [_packet(1, 0x03, bytes([18, 0x7F])), _packet(1, 0x03, bytes([36, 1])), restore, _packet(1, 0x07, b""),
              restore, _packet(1, 0x03, bytes([25, 1]), bad_checksum=True)]
    return fuzz.Case(wire=wire, reply_on_checksum_error=reply_on_checksum_error,
                     inputs=[(data, 0.03, 0.0) for data in inputs])


@pytest.mark.parametrize("wire", ["ax12", "mx"])
@pytest.mark.parametrize("reply_on_checksum_error", [True, False])
def test_the_oracles_expect_alarm_shutdown_of_an_instruction_error(monkeypatch, wire, reply_on_checksum_error):
    """Range, Checksum and Instruction Error, each selected by Alarm Shutdown, zero Torque Limit on the AX-12A and the
    MX (e-manual, control_table_alarm_shutdown.md); a servo silent on a bad checksum drops it, output kept.  A servo
    that ignores those bits fails the oracle."""
    from ax12emu.servo import request_handler, request_handler1x

    case = _shutdown_case(wire, reply_on_checksum_error=reply_on_checksum_error)
    fuzz.run_case(case)
    monkeypatch.setattr(request_handler, "cuts_output", lambda servo, packet, error: False)
    monkeypatch.setattr(request_handler1x, "cuts_output", lambda servo, packet, error: False)
    with pytest.raises(fuzz.FuzzFailure, match="Torque Limit|byte 34|is 255"):
        fuzz.run_case(case)
    if not reply_on_checksum_error:  # and one that cuts on a checksum it does not answer fails it too
        monkeypatch.setattr(request_handler, "cuts_output", lambda servo, packet, error: bool(error & servo.table.get("shutdown") & 0x58))
        monkeypatch.setattr(request_handler1x, "cuts_output", lambda servo, packet, error: bool(error & servo.table.get("shutdown") & 0x58))
        fuzz.run_case(_shutdown_case(wire, reply_on_checksum_error=True))
        with pytest.raises(fuzz.FuzzFailure):
            fuzz.run_case(case)
