"""The control table as data: layout, profiles, all-or-nothing validated writes."""

from __future__ import annotations

import pytest

from ax12emu.protocol.control_table import EEPROM_END, PROFILES, TABLE_SIZE, ControlTable, layout
from ax12emu.protocol.packets import StatusError


def test_layout_covers_the_ax12_table():
    """Addresses 0..49; unused bytes are exactly 10, 19..23 and 45 (e-manual AX-12A)."""
    lay = layout("ax12a")
    unused = [a for a in range(TABLE_SIZE) if lay.owner[a] < 0]
    assert unused == [10, 19, 20, 21, 22, 23, 45]
    assert lay.by_name["model_number"].default == 12
    assert lay.by_name["return_delay_time"].default == 250


def test_profiles_differ_as_their_sources_say():
    """The 2006 manual's defaults: 85 C, 19.0 V, alarm bits 4, margins 0; calibration bytes present."""
    new, old = ControlTable(profile="ax12a"), ControlTable(profile="ax12-2006")
    assert (new.get("temperature_limit"), old.get("temperature_limit")) == (70, 85)
    assert (new.get("max_voltage_limit"), old.get("max_voltage_limit")) == (140, 190)
    assert (new.get("alarm_led"), old.get("alarm_led")) == (36, 4)
    assert (new.get("cw_compliance_margin"), old.get("cw_compliance_margin")) == (1, 0)
    assert "down_calibration" in layout("ax12-2006").by_name and "down_calibration" not in layout().by_name
    assert set(PROFILES) == {"ax12a", "ax12-2006"}
    with pytest.raises(ValueError, match="unknown profile"):
        ControlTable(profile="ax18")


@pytest.mark.parametrize(
    "address, data, error",
    [
        (24, b"\x01", StatusError.NONE),
        (24, b"\x02", StatusError.RANGE),  # Torque Enable is 0..1
        (30, b"\x00\x04", StatusError.RANGE),  # Goal 1024
        (36, b"\x00", StatusError.RANGE),  # read-only
        (10, b"\x00", StatusError.RANGE),  # unused byte
        (49, b"\x00\x00", StatusError.RANGE),  # past the table
        (48, b"\x10\x00", StatusError.RANGE),  # Punch below 0x20 (e-manual)
        (3, b"\xfe", StatusError.RANGE),  # ID 254 is the broadcast ID
    ],
)
def test_check_write(address, data, error):
    """Each rule of a WRITE gives its error bit, and an invalid write yields no new row."""
    table = ControlTable()
    candidate, got = table.check_write(address, data)
    assert got == error
    assert (candidate is None) == bool(error)


def test_invalid_byte_rejects_whole_write():
    """One bad value in a multi-register write leaves every register unchanged."""
    table = ControlTable()
    before = table.row.copy()
    candidate, error = table.check_write(24, b"\x01\x01\x05\x05\x20\x20\x00\x04")  # goal 1024 at the end
    assert candidate is None and error == StatusError.RANGE
    assert (table.row == before).all()


def test_two_byte_register_written_byte_by_byte():
    """The low byte alone is checked with the high byte as it stands."""
    table = ControlTable()
    table.set("goal_position", 0x300)
    candidate, error = table.check_write(30, b"\xff")
    assert error == StatusError.NONE and candidate[30] == 0xFF and candidate[31] == 3
    table.set("goal_position", 0x3FF)
    _, error = table.check_write(31, b"\x04")
    assert error == StatusError.RANGE


def test_lock_windows_per_profile():
    """Lock: the e-manual freezes the EEPROM; the 2006 manual also refuses Punch (its Example 20)."""
    for profile, punch_error in (("ax12a", StatusError.NONE), ("ax12-2006", StatusError.RANGE)):
        table = ControlTable(profile=profile)
        table.set("lock", 1)
        assert table.check_write(5, b"\x00")[1] == StatusError.RANGE
        assert table.check_write(30, b"\x00\x02")[1] == StatusError.NONE
        assert table.check_write(48, b"\x40\x00")[1] == punch_error


def test_read_past_table_pads_and_flags_range():
    """READ beyond address 49 returns the asked length (zeros past the end) with RANGE."""
    data, error = ControlTable().read(48, 4)
    assert data == b"\x20\x00\x00\x00" and error == StatusError.RANGE


def test_eeprom_round_trip_and_validation():
    """An EEPROM image loads back; an out-of-range one is refused with the register's name."""
    table = ControlTable()
    table.set("id", 9)
    image = table.eeprom_bytes()
    assert len(image) == EEPROM_END
    fresh = ControlTable()
    fresh.load_eeprom(image)
    assert fresh.get("id") == 9
    bad = bytearray(image)
    bad[16] = 7
    with pytest.raises(ValueError, match="status_return_level"):
        fresh.load_eeprom(bytes(bad))
