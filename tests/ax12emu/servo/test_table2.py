"""The Protocol 2.0 control table: every write check with its error number, reads, indirect addresses."""

from __future__ import annotations

import pytest

from ax12emu.protocol.packets2 import ErrorNumber
from ax12emu.protocol.servo_models import model
from ax12emu.servo.table2 import Table2


@pytest.fixture
def table() -> Table2:
    return Table2(model("xm430-w350").layout())


def u32(value: int) -> bytes:
    return (value & 0xFFFFFFFF).to_bytes(4, "little")


def test_defaults_and_reads_by_name(table):
    assert table.get("model_number") == 1020
    assert table.get("velocity_limit") == 200
    data, error = table.read(0, 2)
    assert (data, error) == ((1020).to_bytes(2, "little"), ErrorNumber.NONE)


def test_a_write_inside_the_rules_is_applied_whole(table):
    check = table.check_write(116, u32(1000))
    assert check.error == ErrorNumber.NONE
    assert [e.name for e in check.entries] == ["goal_position"]
    table.apply(check)
    assert table.get("goal_position") == 1000


def test_signed_registers_take_negative_values(table):
    check = table.check_write(104, u32(-150))
    assert check.error == ErrorNumber.NONE
    table.apply(check)
    assert table.get("goal_velocity") == -150


@pytest.mark.parametrize(
    ("address", "data", "error"),
    [
        (0, b"\x01\x00", ErrorNumber.ACCESS),  # Model Number is read-only
        (14, b"\x00", ErrorNumber.ACCESS),  # 14 is not defined
        (661, b"\x00\x00", ErrorNumber.ACCESS),  # runs past the table
        (116, b"\x00\x02", ErrorNumber.DATA_LENGTH),  # 2 bytes of the 4-byte Goal Position
        (118, b"\x00\x00", ErrorNumber.DATA_LENGTH),  # its upper half
        (116, u32(4096), ErrorNumber.DATA_RANGE),  # beyond 0..4095
        (64, b"\x02", ErrorNumber.DATA_RANGE),  # Torque Enable is 0 or 1
        (104, u32(201), ErrorNumber.DATA_LIMIT),  # within +-1023 but beyond Velocity Limit 200
        (104, u32(-201), ErrorNumber.DATA_LIMIT),  # "-velocity_limit" bounds it below
        (102, (1194).to_bytes(2, "little"), ErrorNumber.DATA_RANGE),
    ],
)
def test_each_check_names_its_error_and_writes_nothing(table, address, data, error):
    before = bytes(table.row)
    check = table.check_write(address, data)
    assert check.error == error
    assert bytes(table.row) == before


def test_limits_are_judged_on_the_table_after_the_write(table):
    """Max Position Limit lowered and Goal Position above it in one write: Data Limit; within it: accepted."""
    table.apply(table.check_write(48, u32(2000)))
    assert table.check_write(116, u32(2001)).error == ErrorNumber.DATA_LIMIT
    assert table.check_write(116, u32(2000)).error == ErrorNumber.NONE


def test_eeprom_is_locked_while_the_torque_is_on(table):
    table.apply(table.check_write(64, b"\x01"))
    assert table.check_write(11, b"\x01").error == ErrorNumber.ACCESS
    assert table.check_write(65, b"\x01").error == ErrorNumber.NONE  # RAM stays writable
    table.apply(table.check_write(64, b"\x00"))
    assert table.check_write(11, b"\x01").error == ErrorNumber.NONE


def test_access_comes_before_length_range_and_limit(table):
    """A write spanning a read-only byte and a half register: Access Error first."""
    assert table.check_write(122, b"\x00\x00\x00\x00").error == ErrorNumber.ACCESS


def test_refused_registers_answer_data_range(table):
    assert table.check_write(116, u32(100), refused=frozenset({"goal_position"})).error == ErrorNumber.DATA_RANGE
    assert table.check_write(65, b"\x01", refused=frozenset({"goal_position"})).error == ErrorNumber.NONE


def test_reads_span_gaps_and_past_the_end_is_access_error(table):
    data, error = table.read(0, 148)
    assert error == ErrorNumber.NONE and len(data) == 148
    assert data[14] == 0
    data, error = table.read(660, 4)
    assert (data, error) == (bytes(4), ErrorNumber.ACCESS)


def test_indirect_data_reads_and_writes_the_byte_its_address_names(table):
    """Indirect Address 1..4 -> Goal Position (116..119): Indirect Data 1..4 stand for it."""
    for n in range(4):
        table.apply(table.check_write(168 + 2 * n, (116 + n).to_bytes(2, "little")))
    check = table.check_write(224, u32(1234))
    assert check.error == ErrorNumber.NONE
    table.apply(check)
    assert table.get("goal_position") == 1234
    assert table.read(224, 4) == (u32(1234), ErrorNumber.NONE)


def test_indirect_writes_keep_the_targets_rules(table):
    """Through indirect data, a partial register is Data Length, a read-only target Access."""
    for n in range(2):
        table.apply(table.check_write(168 + 2 * n, (116 + n).to_bytes(2, "little")))
    assert table.check_write(224, b"\x01\x02").error == ErrorNumber.DATA_LENGTH
    table.apply(table.check_write(168, (132).to_bytes(2, "little")))  # Present Position
    assert table.check_write(224, b"\x01").error == ErrorNumber.ACCESS


def test_factory_defaults_keep_what_is_asked(table):
    table.apply(table.check_write(7, b"\x05"))
    table.apply(table.check_write(8, b"\x03"))
    table.factory_defaults(keep=("id",))
    assert (table.get("id"), table.get("baud_rate")) == (5, 1)
    table.factory_defaults()
    assert table.get("id") == 1


def test_extended_position_mode_widens_goal_position_and_drops_the_limits(table):
    """e-manual, Goal Position(116): -1,048,575 ~ 1,048,575 in Extended Position Control Mode, limits unused."""
    assert table.check_write(116, u32(-5000)).error == ErrorNumber.DATA_RANGE
    table.apply(table.check_write(48, u32(3000)))  # Max Position Limit
    table.apply(table.check_write(11, b"\x04"))  # Extended Position Control Mode
    for value in (-5000, 1_048_575, 3001):
        assert table.check_write(116, u32(value)).error == ErrorNumber.NONE, value
    assert table.check_write(116, u32(1_048_576)).error == ErrorNumber.DATA_RANGE
    table.apply(table.check_write(11, b"\x03"))
    assert table.check_write(116, u32(3001)).error == ErrorNumber.DATA_LIMIT


def test_operating_mode_takes_only_the_modes_the_model_lists(table):
    """XM430-W350, Operating Mode(11): 0, 1, 3, 4, 5, 16; the XL430-W250 has no current modes."""
    assert [table.check_write(11, bytes((mode,))).error for mode in (0, 2, 5, 6, 15, 16)] == [
        ErrorNumber.NONE, ErrorNumber.DATA_RANGE, ErrorNumber.NONE, ErrorNumber.DATA_RANGE, ErrorNumber.DATA_RANGE,
        ErrorNumber.NONE]
    xl430 = Table2(model("xl430-w250").layout())
    assert xl430.check_write(11, b"\x05").error == ErrorNumber.DATA_RANGE


@pytest.mark.parametrize("key", ["xm430-w350", "xl430-w250", "xl330-m288"])
def test_writes_judged_from_the_layout_alone_agree_with_the_byte_by_byte_rules(key, monkeypatch):
    """check_write's short way (what the layout says of an address range, remembered) and its byte-by-byte
    way give the same outcome for random writes anywhere, with the torque on and off."""
    import random

    rng = random.Random(7)
    short, long = Table2(model(key).layout()), Table2(model(key).layout())
    monkeypatch.setattr(long, "_plan", lambda address, length: None)  # every write the byte-by-byte way
    outcomes = set()
    for _ in range(3000):
        torque = int(rng.random() < 0.3)
        for table in (short, long):
            table.row[table._torque_enable] = torque
        address = rng.choice([rng.randrange(short.size), 64, 65, 84, 104, 108, 112, 116, 116, 7, 11, 12, 48, 52])
        data = bytes(rng.randrange(256) if rng.random() < 0.5 else rng.choice((0, 1, 255))
                     for _ in range(rng.choice((1, 2, 4, rng.randrange(1, 12)))))
        a, b = short.check_write(address, data), long.check_write(address, data)
        assert (a.error, a.changes, a.entries) == (b.error, b.changes, b.entries), (address, data.hex())
        outcomes.add(a.error)
        if not a.error:
            short.apply(a)
            long.apply(b)
    assert {ErrorNumber.NONE, ErrorNumber.ACCESS, ErrorNumber.DATA_LENGTH, ErrorNumber.DATA_RANGE} <= outcomes


def test_a_write_that_also_sets_its_own_bounds_is_judged_on_them_as_written(monkeypatch):
    """A layout where the registers a goal's bounds come from sit beside it (no shipped model file has one,
    but a model is data): one write of mode, limit and goal is judged on the mode and limit it writes, the
    short way and the byte-by-byte way alike."""
    import itertools

    from ax12emu.protocol.registers import Access, Area, Entry, ModeRange, Profile, compile_layout

    rw = {"access": Access.RW, "area": Area.RAM}
    base = (
        Entry(0, 1, "torque_enable", default=0, minimum=0, maximum=1, **rw),
        Entry(1, 1, "operating_mode", default=3, minimum=0, maximum=4, allowed=(3, 4), **rw),
        Entry(2, 2, "limit", default=1000, minimum=0, maximum=4000, **rw),
        Entry(4, 2, "goal", default=0, minimum=0, maximum=4000, maximum_from="limit",
              mode_ranges=(ModeRange("operating_mode", (4,), 0, 5000, limits=False),), **rw),
    )
    layout = compile_layout(Profile("test", "a layout for this test"), base, 6)
    short, long = Table2(layout), Table2(layout)
    monkeypatch.setattr(long, "_plan", lambda address, length: None)
    outcomes = []
    for mode, limit, goal in itertools.product((3, 4), (500, 3000), (400, 2000, 4500)):
        data = bytes((mode,)) + limit.to_bytes(2, "little") + goal.to_bytes(2, "little")
        for _ in range(2):  # the second time from what was remembered of the first
            a, b = short.check_write(1, data), long.check_write(1, data)
            assert (a.error, a.changes, a.entries) == (b.error, b.changes, b.entries), (mode, limit, goal)
        outcomes.append(a.error)
    assert outcomes == [ErrorNumber.NONE, ErrorNumber.DATA_LIMIT, ErrorNumber.DATA_RANGE,
                        ErrorNumber.NONE, ErrorNumber.NONE, ErrorNumber.DATA_RANGE,
                        ErrorNumber.NONE, ErrorNumber.NONE, ErrorNumber.NONE,
                        ErrorNumber.NONE, ErrorNumber.NONE, ErrorNumber.NONE]


def test_indirect_data_pointing_at_indirect_data_follows_the_chain():
    """Indirect Address 1 -> Indirect Data 2, Indirect Address 2 -> LED: writing Indirect Data 1 sets the LED, as the
    data it stands for does (it was stored in Indirect Data 2's own byte: success, yet LED 0 and Data 2 reading 0);
    a chain closing on itself stands for the byte where it closes."""
    from ax12emu.protocol.servo_models import model
    from ax12emu.servo.table2 import Table2

    table = Table2(model("xl430-w250").layout())
    data1, data2 = table.layout.by_name["indirect_data_1"].address, table.layout.by_name["indirect_data_2"].address
    table.set("indirect_address_1", data2)
    table.set("indirect_address_2", table.layout.by_name["led"].address)
    check = table.check_write(data1, b"\x01")
    assert not check.error
    table.apply(check)
    assert table.get("led") == 1 and table.read(data2, 1) == (b"\x01", 0) and table.read(data1, 1) == (b"\x01", 0)
    table.set("indirect_address_2", data1)  # a loop: 1 -> 2 -> 1
    table.apply(table.check_write(data1, b"\x07"))
    assert table.read(data1, 1)[0] == b"\x07" and table.get("led") == 1
