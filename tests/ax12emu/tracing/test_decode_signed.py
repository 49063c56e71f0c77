"""Signed registers read as signed: Goal Velocity -10 is -10, not 4294967286."""

from __future__ import annotations

from ax12emu.protocol.packets import encode_instruction, encode_status
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2, encode_status2
from ax12emu.tracing.decoder import decode, register_names
from ax12emu.tracing.trace import IN, OUT, Chunk


def _i32(value: int) -> bytes:
    return (value & 0xFFFFFFFF).to_bytes(4, "little")


def test_2_0_signed_registers_in_writes_sync_writes_and_read_answers():
    write = encode_instruction2(1, Instruction2.WRITE, bytes([104, 0]) + _i32(-10))
    sync = encode_instruction2(254, Instruction2.SYNC_WRITE, bytes([104, 0, 4, 0, 1]) + _i32(-10) + bytes([2]) + _i32(10))
    read = encode_instruction2(1, Instruction2.READ, bytes([128, 0, 4, 0]))
    chunks = [Chunk(0.0, IN, write), Chunk(0.001, IN, sync), Chunk(0.002, IN, read), Chunk(0.003, OUT, encode_status2(1, 0, _i32(-3)))]
    texts = [d.text for d in decode(chunks, servos="1-2:xl430-w250")]
    assert texts == [
        "WRITE id=1 goal_velocity=-10 (4 bytes)",
        "SYNC_WRITE id=254 [id=1 goal_velocity=-10 (4 bytes)] [id=2 goal_velocity=10 (4 bytes)]",
        "READ id=1 present_velocity length=4",
        "STATUS id=1 ok present_velocity=-3",
    ]


def test_unsigned_registers_and_partial_writes_stay_unsigned():
    names = register_names("1:xl430-w250")[1]
    assert names[104] == "goal_velocity" and names[104].signed and not getattr(names[112], "signed", False)
    partial = encode_instruction2(1, Instruction2.WRITE, bytes([104, 0, 0xFF, 0xFF]))  # 2 bytes of a 4-byte register
    profile = encode_instruction2(1, Instruction2.WRITE, bytes([112, 0]) + _i32(-1))  # Profile Velocity: unsigned
    texts = [d.text for d in decode([Chunk(0.0, IN, partial), Chunk(0.001, IN, profile)], servos="1:xl430-w250")]
    assert texts == ["WRITE id=1 goal_velocity=65535 (2 bytes)", f"WRITE id=1 profile_velocity={0xFFFFFFFF} (4 bytes)"]


def test_1_0_signed_register_of_an_mx():
    """An MX's Multi Turn Offset (20, 2 bytes) is signed."""
    write = encode_instruction(1, 0x03, bytes([20]) + (-100 & 0xFFFF).to_bytes(2, "little"))
    read = encode_instruction(1, 0x02, bytes([20, 2]))
    chunks = [Chunk(0.0, IN, write), Chunk(0.001, IN, read), Chunk(0.002, OUT, encode_status(1, 0, (-5 & 0xFFFF).to_bytes(2, "little")))]
    texts = [d.text for d in decode(chunks, servos="1:mx-28")]
    assert texts[0] == "WRITE id=1 multi_turn_offset=-100"
    assert texts[2] == "STATUS id=1 ok multi_turn_offset=-5"
