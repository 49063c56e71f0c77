"""Fuzzing the Protocol 2.0 bus and a mixed 1.0 + 2.0 wire against an oracle (tools/fuzz2.py), in short runs."""

from __future__ import annotations

import pytest
from emu_testkit import load_tool
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ax12emu.protocol import packets2
from ax12emu.protocol.packets2 import ErrorNumber, Instruction2
from ax12emu.servo import request_handler2

fuzz2 = load_tool("fuzz2")


def test_a_few_thousand_inputs_on_both_buses_find_nothing():
    """3,000 PRNG-expanded inputs, on the 2.0 bus and the mixed wire: every invariant holds after every packet."""
    stats = fuzz2.fuzz(3000, seed=20261123)
    assert stats.failure is None, f"{stats.failure}\nreproducer: {stats.reproducer}"
    assert stats.inputs >= 3000
    assert stats.by_bus.get("2.0", 0) > 0 and stats.by_bus.get("mixed", 0) > 0


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.data())
def test_hypothesis_drawn_cases_hold_every_invariant(data):
    """The same grammar drawn through hypothesis (so a failure shrinks to a small case)."""
    case = fuzz2.generate_case(fuzz2.fuzz1.DataChooser(data), data.draw(st.integers(1, 10)))
    fuzz2.run_case(case)


def test_the_oracle_decodes_what_the_emulator_encodes():
    """The oracle's own CRC and stuffing agree with the e-manual's example (Ping to ID 1) and with the package."""
    assert fuzz2.frame(1, b"\x01") == bytes.fromhex("ff ff fd 00 01 03 00 01 19 4e")
    payload = bytes((0x55, 0)) + b"\xff\xff\xfd\x01"
    status = packets2.encode_status2(1, 0, payload[2:])
    assert fuzz2.parse_status(status, "test") == (1, 0, payload[2:])
    broken = bytearray(status)
    del broken[broken.index(b"\xff\xff\xfd\xfd") + 3]  # the stuffing byte dropped, LENGTH and CRC made right again
    broken[5] -= 1
    broken[-2:] = fuzz2.crc(bytes(broken[:-2])).to_bytes(2, "little")
    with pytest.raises(fuzz2.FuzzFailure, match="stuffing"):
        fuzz2.parse_status(bytes(broken), "test")


def _finds(monkeypatch, patch, seconds: float = 10.0):
    """Run the fuzzer with ``patch`` applied; it must fail with a minimised reproducer that passes once undone."""
    patch()
    stats = fuzz2.fuzz(10**9, seconds=seconds, seed=7)
    assert stats.failure is not None and "FuzzFailure" in stats.failure, stats.failure
    case = fuzz2.Case2.from_json(stats.reproducer)
    assert len(case.inputs) <= 4, "the failure is minimised"
    with pytest.raises(fuzz2.FuzzFailure):
        fuzz2.run_case(case)
    monkeypatch.undo()
    fuzz2.run_case(case)  # the real code passes the reproducer
    return stats


def test_fuzzer_catches_a_write_that_ignores_the_eeprom_lock(monkeypatch):
    """WRITE storing any bytes in the table (no Access, Length, Range checks) is found and shrunk."""

    def careless_write(servo, params):
        end = params.address + len(params.data)
        if params.data and end <= servo.table.size:
            servo.table.row[params.address:end] = params.data
        return ErrorNumber.NONE, b""

    _finds(monkeypatch, lambda: monkeypatch.setitem(request_handler2.HANDLERS, Instruction2.WRITE, careless_write))


def test_fuzzer_catches_a_framer_that_forgets_to_unstuff(monkeypatch):
    """Parameters handed on still stuffed (FF FF FD FD) are found: they are not what was sent."""
    _finds(monkeypatch, lambda: monkeypatch.setattr(packets2, "unstuff", bytes))


def test_fuzzer_catches_a_status_packet_with_a_wrong_crc(monkeypatch):
    """A reply whose CRC is off by one is found by the oracle's own CRC."""
    real = request_handler2.encode_status2

    def off_by_one(packet_id, error, params=b""):
        data = bytearray(real(packet_id, error, params))
        data[-1] ^= 1
        return bytes(data)

    _finds(monkeypatch, lambda: monkeypatch.setattr(request_handler2, "encode_status2", off_by_one))


def test_tool_main_prints_figures(capsys, tmp_path):
    """tools/fuzz2.py main: count, rate, what the oracle checked, and no failure for a small budget."""
    failure_file = str(tmp_path / "failure.json")  # written only on a failure, never into the working tree
    assert fuzz2.main(["--inputs", "300", "--no-coverage", "--seed", "1", "--bus", "mixed",
                       "--failure-file", failure_file]) == 0
    out = capsys.readouterr().out
    assert "inputs/s" in out and "2.0 packets checked" in out and "failures: 0" in out


def test_a_fast_sync_read_listing_an_id_two_servos_share_then_one_id_three_times():
    """Found by ``--seed 7``: an XL330-M077 moved to ID 2 beside the XM430-W350 there, then a Fast Sync Read of
    Present Input Voltage listing IDs 2, 1, 1, 1.  Both ID 2 servos send the header (announcing all four
    shares) and their share at once, AND-ed on the wire; ID 1 sends a share in each of its three turns, its
    CRC run on over the collided bytes.  The oracle predicts that packet byte for byte."""
    case = fuzz2.Case2(bus="2.0", reply_on_crc_error=False, inputs=[
        (bytes.fromhex("ffff0207027ed484861d7beafffffd00030600030700029ee1"), 0.0, 0.0),
        (bytes.fromhex("ffff"), 0.0, 0.0),
        (bytes.fromhex("fd00fe0b008a90000200020101016a6d"), 0.0, 0.0)])
    assert fuzz2.run_case(case) == 4
    assert fuzz2.CHECKED[("0x8a", "combined status")] >= 1


def test_a_fast_sync_read_of_an_id_two_servos_share_last():
    """Found by ``--seed 7`` next: on the mixed wire an XL330-M077 reset to ID 1 beside the XL430-W250 there, both
    moved to ID 4, then a Fast Sync Read of ID 4 alone.  The packet's CRC is the two servos' CRCs AND-ed, not a
    CRC of the collided bytes; the oracle checks the bytes and does not demand a whole CRC of a collided end."""
    case = fuzz2.Case2(bus="mixed", reply_on_crc_error=False, inputs=[
        (bytes.fromhex("fffffd0003040006ff55e4"), 0.0, 0.0),
        (bytes.fromhex("fffffd0001060003070004a963"), 0.0, 0.0),
        (bytes.fromhex("fffffd00fe08008a2600020004623c"), 0.0, 0.0)])
    assert fuzz2.run_case(case) == 4


def test_a_fast_bulk_read_past_the_tables_of_two_servos_sharing_the_first_id():
    """Found by ``--seed 7`` next: an XL330-M077 (a 228-byte table) and an XL430-W250 (662 bytes) both on ID 1,
    then a Fast Bulk Read of 662 bytes from 64 on ID 1 and 4 bytes on ID 1 again.  Each reads zeros up to its
    own table's size, so each announces another LENGTH in the header they send at once (AND-ed)."""
    case = fuzz2.Case2(bus="2.0", inputs=[(bytes.fromhex(h), 0.0, 0.0) for h in (
        "fffffd0002070055009cea568b03fffffd00030700036400d6ff495bfffffd00040f264378030001190a"
        "fffffd00040900035e0200008b056c63fffffd",
        "0003040006ff55e4",
        "fffffd00040b0003e000fffffd5a16b4884bfffffd0004087399c275762dcfded23efffffd00fe0d009a01400096020174000400f36a")])
    assert fuzz2.run_case(case) == 4


def test_the_xl320_with_its_classic_table_is_fuzzed_beside_the_x_series():
    """The XL-320 is on both buses and the oracle checks its replies, a power-up's Torque Limit among them."""
    assert "xl-320" in dict(fuzz2.BUS2_SERVOS).values() and "xl-320" in dict(fuzz2.MIXED_SERVOS2).values()
    before = fuzz2.CHECKED_MODELS["XL-320"]
    stats = fuzz2.fuzz(3000, seed=20261124)
    assert stats.failure is None, f"{stats.failure}\nreproducer: {stats.reproducer}"
    assert fuzz2.CHECKED_MODELS["XL-320"] - before > 100
    # A reboot that left Torque Limit at its default instead of Max Torque is caught.
    rules = fuzz2.TableRules("xl-320")
    row = bytearray(rules.defaults)
    row[rules.address["max_torque"]:rules.address["max_torque"] + 2] = (500).to_bytes(2, "little")
    shadow = fuzz2.Shadow(rules, bytes(row))
    oracle = fuzz2.Oracle2.__new__(fuzz2.Oracle2)
    oracle.shadows = [shadow]
    _, _, image, mark = oracle.execute(shadow, bytes(row), fuzz2.REBOOT, b"", to_broadcast=False)
    assert mark == "boot"
    booted = bytearray(image)
    booted[rules.address["torque_limit"]:rules.address["torque_limit"] + 2] = (500).to_bytes(2, "little")
    fuzz2._compare(oracle, 0, image, bytes(booted), mark, "test")
    with pytest.raises(fuzz2.FuzzFailure, match="torque_limit"):
        fuzz2._compare(oracle, 0, image, image, mark, "test")


def test_a_reg_write_through_a_secondary_id_leaves_the_eeprom_out_of_reach():
    """Found by ``--seed 60417``: a broadcast Write of Secondary ID(12) = 1, then a Reg Write of Homing Offset(20)
    to ID 1. The servo refuses it (the EEPROM is out of reach through a Secondary ID, for a Reg Write as for a
    Write); the oracle registered it."""
    case = fuzz2.Case2(bus="2.0", reply_on_crc_error=False, line_bps=1_000_000.0, inputs=[
        (bytes.fromhex("fffffd00fe0600030c0001d813"), 0.0, 0.0),
        (bytes.fromhex("fffffd00010900041400a698f4ff2a47"), 0.0, 0.0)])
    assert fuzz2.run_case(case) == 3  # the inputs, and the full read after them


def test_an_indirect_address_naming_indirect_data_is_followed_on():
    """Found by ``--seed 60417`` next: Indirect Address 21 names Indirect Data 1, whose Indirect Address 1 then
    names Present Input Voltage's neighbour (117): the byte stands for where the chain ends, as the servo reads
    it; the oracle stopped after one step."""
    case = fuzz2.Case2(bus="mixed", reply_on_crc_error=True, inputs=[
        (bytes.fromhex("fffffd00fe070003d000e00051af"), 0.03, 0.0),
        (bytes.fromhex("fffffd00fe070003a80075004fb1"), 0.0001, 0.0)])
    assert fuzz2.run_case(case) == 3  # the inputs, and the full read after them
