"""The Protocol 2.0 CRC-16: the e-manual's table and worked examples, and dynamixel-sdk's implementation."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from protocol2_vectors import EMANUAL_ERRATA, EMANUAL_PACKETS

from ax12emu.protocol.crc16 import CRC16_TABLE, crc16

sdk = pytest.importorskip("dynamixel_sdk.protocol2_packet_handler")

@pytest.mark.parametrize("name", EMANUAL_PACKETS)
def test_emanual_examples(name):
    """The CRC of each printed packet's bytes is the CRC printed after them, low byte first."""
    packet = bytes.fromhex(EMANUAL_PACKETS[name])
    assert crc16(packet[:-2]).to_bytes(2, "little") == packet[-2:]


@pytest.mark.parametrize("name", EMANUAL_ERRATA)
def test_emanual_errata(name):
    """Where the e-manual's printed CRC is wrong, the SDK computes what this module computes."""
    text, printed, computed = EMANUAL_ERRATA[name]
    body = bytes.fromhex(text)
    assert crc16(body) == computed != printed
    assert sdk.Protocol2PacketHandler().updateCRC(0, list(body), len(body)) == computed


def test_check_value_and_table():
    """CRC-16/BUYPASS's catalogue check value, and the table entry for entry against dynamixel-sdk's."""
    assert crc16(b"123456789") == 0xFEE8
    assert CRC16_TABLE[:4] == (0x0000, 0x8005, 0x800F, 0x000A)
    # updateCRC of one byte from 0 is that byte's table entry.
    handler = sdk.Protocol2PacketHandler()
    assert [handler.updateCRC(0, [i], 1) for i in range(256)] == list(CRC16_TABLE)


@settings(max_examples=300, deadline=None)
@given(data=st.binary(max_size=300), seed=st.integers(0, 0xFFFF), cut=st.integers(0, 300))
def test_matches_sdk_and_continues(data, seed, cut):
    """Same value as dynamixel-sdk from any start, and computing in two pieces equals one pass."""
    assert crc16(data, seed) == sdk.Protocol2PacketHandler().updateCRC(seed, list(data), len(data))
    assert crc16(data[cut:], crc16(data[:cut], seed)) == crc16(data, seed)
