"""The AX-12 control table as data: addresses 0..49, sizes, access, defaults, ranges.

Why it exists: every register rule (what is writable, what is in range, what
is EEPROM and persists, what RESET restores, what Lock protects) is read from
the entries and profiles below, never from if-chains elsewhere.  Two profiles
exist because the sources differ: ``ax12a`` follows the current ROBOTIS
e-manual for the AX-12/AX-12+/AX-12A (the project follows the e-manual for
protocol and control table), ``ax12-2006`` the original 2006 AX-12 User's
Manual.  Where the e-manual gives no range the 2006 manual's table of write
ranges fills in.

The table's bytes live in one row of a ``numpy`` array owned by the bus (one
row per servo), so the physics adapter reads commands and writes sensed
values for all servos at once; :class:`ControlTable` is one row plus rules.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

from .packets import StatusError

__all__ = [
    "Access",
    "Area",
    "Entry",
    "ENTRIES",
    "TABLE_SIZE",
    "EEPROM_END",
    "Profile",
    "PROFILES",
    "DEFAULT_PROFILE",
    "Layout",
    "layout",
    "ControlTable",
]

TABLE_SIZE = 50
#: EEPROM occupies addresses 0..23, RAM 24..49 (e-manual, "Control Table").
EEPROM_END = 24


class Access(enum.Enum):
    """Who may change a register through the bus."""

    R = "R"
    RW = "RW"


class Area(enum.Enum):
    """EEPROM registers persist over power cycles; RAM ones return to defaults."""

    EEPROM = "EEPROM"
    RAM = "RAM"


@dataclass(frozen=True)
class Entry:
    """One control-table item (e-manual, "Control Table")."""

    #: First byte address.
    address: int
    #: 1 or 2 bytes, little-endian.
    size: int
    #: The e-manual's name, snake_case.
    name: str
    access: Access
    #: Value at power-up and after RESET.
    default: int
    #: Valid values for a write, inclusive (read-only entries keep their full span).
    minimum: int
    maximum: int

    @property
    def area(self) -> Area:
        """EEPROM below address 24, RAM from there on."""
        return Area.EEPROM if self.address < EEPROM_END else Area.RAM

    @property
    def end(self) -> int:
        """One past the last byte."""
        return self.address + self.size

    def value_in(self, image: np.ndarray | bytes) -> int:
        """This entry's value in a table image (a row, a candidate row or saved bytes), little-endian."""
        value = int(image[self.address])
        if self.size == 2:
            value |= int(image[self.address + 1]) << 8
        return value


R, RW = Access.R, Access.RW

#: Source: ROBOTIS e-manual, AX-12A "Control Table" (address, size, access,
#: initial value) and the 2006 manual's write ranges where the e-manual gives
#: none.  Present* defaults are placeholders the model overwrites before any
#: read; Goal Position is set to Present Position at power-up (2006 manual:
#: initial value "[Addr36] value") and Torque Limit to Max Torque (e-manual:
#: "ADD 14&15").  Moving Speed 0..2047: wheel mode uses bit 10 as direction.
ENTRIES: tuple[Entry, ...] = (
    Entry(0, 2, "model_number", R, 12, 0, 0xFFFF),
    Entry(2, 1, "firmware_version", R, 24, 0, 0xFF),
    Entry(3, 1, "id", RW, 1, 0, 253),
    Entry(4, 1, "baud_rate", RW, 1, 0, 254),
    Entry(5, 1, "return_delay_time", RW, 250, 0, 254),
    Entry(6, 2, "cw_angle_limit", RW, 0, 0, 1023),
    Entry(8, 2, "ccw_angle_limit", RW, 1023, 0, 1023),
    Entry(11, 1, "temperature_limit", RW, 70, 0, 150),
    Entry(12, 1, "min_voltage_limit", RW, 60, 50, 250),
    Entry(13, 1, "max_voltage_limit", RW, 140, 50, 250),
    Entry(14, 2, "max_torque", RW, 1023, 0, 1023),
    Entry(16, 1, "status_return_level", RW, 2, 0, 2),
    Entry(17, 1, "alarm_led", RW, 36, 0, 127),
    Entry(18, 1, "shutdown", RW, 36, 0, 127),
    Entry(24, 1, "torque_enable", RW, 0, 0, 1),
    Entry(25, 1, "led", RW, 0, 0, 1),
    Entry(26, 1, "cw_compliance_margin", RW, 1, 0, 254),
    Entry(27, 1, "ccw_compliance_margin", RW, 1, 0, 254),
    Entry(28, 1, "cw_compliance_slope", RW, 32, 0, 254),
    Entry(29, 1, "ccw_compliance_slope", RW, 32, 0, 254),
    Entry(30, 2, "goal_position", RW, 512, 0, 1023),
    Entry(32, 2, "moving_speed", RW, 0, 0, 2047),
    Entry(34, 2, "torque_limit", RW, 1023, 0, 1023),
    Entry(36, 2, "present_position", R, 512, 0, 1023),
    Entry(38, 2, "present_speed", R, 0, 0, 2047),
    Entry(40, 2, "present_load", R, 0, 0, 2047),
    Entry(42, 1, "present_voltage", R, 96, 0, 255),
    Entry(43, 1, "present_temperature", R, 30, 0, 255),
    Entry(44, 1, "registered", R, 0, 0, 1),
    Entry(46, 1, "moving", R, 0, 0, 1),
    Entry(47, 1, "lock", RW, 0, 0, 1),
    Entry(48, 2, "punch", RW, 32, 0, 1023),
)


@dataclass(frozen=True)
class Profile:
    """A firmware generation's differences from ENTRIES, as data."""

    name: str
    #: Where the differences come from.
    source: str
    #: Per-entry replacements of ``default`` / ``minimum`` / ``maximum``.
    overrides: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    #: Entries only this profile has.
    extra_entries: tuple[Entry, ...] = ()
    #: Addresses a WRITE may touch while Lock is 1; any other gives a RANGE error.
    lock_writable: range = range(EEPROM_END, TABLE_SIZE)
    #: What Alarm Shutdown clears: "torque_limit" (set to 0) or "torque_enable".
    shutdown_clears: str = "torque_limit"


PROFILES: Mapping[str, Profile] = MappingProxyType(
    {
        "ax12a": Profile(
            name="ax12a",
            source=(
                "ROBOTIS e-manual, AX-12A page and its shared control-table texts: temperature limit "
                "0..100, voltage limits 50..160, Punch 0x20..0x3FF; Lock makes the EEPROM area read-only "
                "until power-off; Shutdown sets Torque Limit to 0 until a non-zero value is written"
            ),
            overrides={
                "temperature_limit": {"maximum": 100},
                "min_voltage_limit": {"maximum": 160},
                "max_voltage_limit": {"maximum": 160},
                "punch": {"minimum": 32},
            },
        ),
        "ax12-2006": Profile(
            name="ax12-2006",
            source=(
                "AX-12 User's Manual (ROBOTIS, 2006): highest limit temperature 85 C, highest limit "
                "voltage 190, Alarm LED and Alarm Shutdown 4 (overheating only), compliance margins 0, "
                "slope 1..254; reserved byte 19 (0..1) and Down/Up Calibration at 20..23, read-only "
                "(per-unit values are not published: they read 0 here); with Lock set only 0x18..0x23 "
                "accept writes (its Example 20: writing Punch gives a Range Error); Shutdown turns "
                "torque off until Torque Enable is written 1"
            ),
            overrides={
                "temperature_limit": {"default": 85},
                "max_voltage_limit": {"default": 190},
                "alarm_led": {"default": 4},
                "shutdown": {"default": 4},
                "cw_compliance_margin": {"default": 0},
                "ccw_compliance_margin": {"default": 0},
                "cw_compliance_slope": {"minimum": 1},
                "ccw_compliance_slope": {"minimum": 1},
            },
            extra_entries=(
                Entry(19, 1, "reserved_19", RW, 0, 0, 1),
                Entry(20, 2, "down_calibration", R, 0, 0, 0xFFFF),
                Entry(22, 2, "up_calibration", R, 0, 0, 0xFFFF),
            ),
            lock_writable=range(0x18, 0x24),
            shutdown_clears="torque_enable",
        ),
    }
)
DEFAULT_PROFILE = "ax12a"


@dataclass(frozen=True)
class Layout:
    """A profile compiled into per-address lookups (as pymodbus compiles SimData into SimRuntime)."""

    profile: Profile
    entries: tuple[Entry, ...]
    by_name: Mapping[str, Entry]
    #: Index into ``entries`` of the entry owning each address, -1 where unused.
    owner: np.ndarray
    #: True where a WRITE may change the byte.
    writable: np.ndarray
    #: The table at factory defaults.
    defaults: bytes


@functools.cache
def layout(profile: str = DEFAULT_PROFILE) -> Layout:
    """Compile ``profile``, checking there are no overlaps and every default is in range."""
    try:
        prof = PROFILES[profile]
    except KeyError:
        raise ValueError(f"unknown profile {profile!r}; choose one of: {', '.join(PROFILES)}") from None
    unknown = set(prof.overrides) - {e.name for e in ENTRIES}
    if unknown:
        raise AssertionError(f"profile {profile} overrides unknown entries {sorted(unknown)}")
    entries = tuple(
        sorted(
            (dataclasses.replace(e, **prof.overrides.get(e.name, {})) for e in ENTRIES + prof.extra_entries),
            key=lambda e: e.address,
        )
    )
    owner = np.full(TABLE_SIZE, -1, dtype=np.int64)
    writable = np.zeros(TABLE_SIZE, dtype=bool)
    raw = bytearray(TABLE_SIZE)
    for index, entry in enumerate(entries):
        if entry.size not in (1, 2) or entry.end > TABLE_SIZE:
            raise AssertionError(f"bad control-table entry {entry}")
        if np.any(owner[entry.address : entry.end] >= 0):
            raise AssertionError(f"overlapping control-table entry {entry}")
        if not entry.minimum <= entry.default <= entry.maximum:
            raise AssertionError(f"default out of range in {entry}")
        owner[entry.address : entry.end] = index
        writable[entry.address : entry.end] = entry.access is Access.RW
        raw[entry.address : entry.end] = entry.default.to_bytes(entry.size, "little")
    owner.flags.writeable = False
    writable.flags.writeable = False
    return Layout(prof, entries, MappingProxyType({e.name: e for e in entries}), owner, writable, bytes(raw))


for _name in PROFILES:  # validate every profile at import
    layout(_name)


class ControlTable:
    """One servo's control table: reads, validated all-or-nothing writes, defaults.

    ``row`` is a writable uint8 array of TABLE_SIZE bytes (a row of the bus's
    shared array); a fresh one is made when none is given.
    """

    def __init__(self, row: np.ndarray | None = None, *, profile: str = DEFAULT_PROFILE) -> None:
        self.layout = layout(profile)
        if row is None:
            row = np.zeros(TABLE_SIZE, dtype=np.uint8)
        if row.shape != (TABLE_SIZE,) or row.dtype != np.uint8:
            raise ValueError(f"control table row must be uint8[{TABLE_SIZE}]")
        self.row = row
        #: Called with the register's name after every :meth:`set` (see there); None: nobody listens.
        self.on_set: Callable[[str], None] | None = None
        self.factory_reset()

    @property
    def profile(self) -> Profile:
        """The profile this table follows."""
        return self.layout.profile

    # -- whole-table operations -------------------------------------------------------
    def factory_reset(self) -> None:
        """Every register back to its factory default (RESET, and power-up before EEPROM loads)."""
        self.row[:] = np.frombuffer(self.layout.defaults, dtype=np.uint8)

    def eeprom_bytes(self) -> bytes:
        """The EEPROM area, the part that persists."""
        return self.row[:EEPROM_END].tobytes()

    def load_eeprom(self, data: bytes) -> None:
        """Restore a persisted EEPROM area; every writable value must be in range.

        Read-only EEPROM values (model number, firmware version) always come
        from the profile, so a state file cannot turn the servo into another model.
        """
        if len(data) != EEPROM_END:
            raise ValueError(f"EEPROM image must be {EEPROM_END} bytes, got {len(data)}")
        for entry in self.layout.entries:
            if entry.area is Area.EEPROM and entry.access is Access.RW:
                value = int.from_bytes(data[entry.address : entry.end], "little")
                if not entry.minimum <= value <= entry.maximum:
                    raise ValueError(f"{entry.name} = {value} is outside {entry.minimum}..{entry.maximum}")
        for entry in self.layout.entries:
            if entry.area is Area.EEPROM and entry.access is Access.RW:
                self.row[entry.address : entry.end] = np.frombuffer(data[entry.address : entry.end], dtype=np.uint8)

    # -- registers by name (firmware side: no access or range checks) ----------------
    def get(self, name: str) -> int:
        """Value of the named register."""
        return self.layout.by_name[name].value_in(self.row)

    def set(self, name: str, value: int) -> None:
        """Set a register as the firmware does (no access or range check), and tell :attr:`on_set`.

        Whatever caches values derived from the table (the plant's decoded
        commands, the readings it last wrote) listens here, so a writer
        outside the packet path (faults, a test harness) cannot leave it stale.
        """
        entry = self.layout.by_name[name]
        self.row[entry.address] = value & 0xFF
        if entry.size == 2:
            self.row[entry.address + 1] = (value >> 8) & 0xFF
        if self.on_set is not None:
            self.on_set(name)

    # -- bus access -------------------------------------------------------------------
    def read(self, address: int, length: int) -> tuple[bytes, StatusError]:
        """Bytes for a READ; past the table the missing bytes read 0 and RANGE is set.

        Always ``length`` bytes: dynamixel-sdk indexes the data of an erroring
        reply, so a short reply would crash it.  Unused addresses read 0.
        """
        inside = self.row[address : min(address + length, TABLE_SIZE)].tobytes() if address < TABLE_SIZE else b""
        if len(inside) < length:
            return inside + bytes(length - len(inside)), StatusError.RANGE
        return inside, StatusError.NONE

    def check_write(self, address: int, data: bytes) -> tuple[np.ndarray | None, StatusError]:
        """Validate a WRITE without applying it: the new row, or None and the error bits.

        All-or-nothing: one invalid byte rejects the whole write.  Checks in
        order: inside the table; Lock (2006 manual, Example 20: RANGE); every
        byte writable (read-only or unused: RANGE, as "an instruction out of
        the range for use" — the sources are silent on this case); each
        touched entry's resulting value in range (RANGE).  A 2-byte entry
        written one byte at a time is checked with its other byte as it stands.
        """
        end = address + len(data)
        lay = self.layout
        if not data or end > TABLE_SIZE:
            return None, StatusError.RANGE
        if self.row[lay.by_name["lock"].address] and not (
            address in lay.profile.lock_writable and end - 1 in lay.profile.lock_writable
        ):
            return None, StatusError.RANGE
        if not lay.writable[address:end].all():
            return None, StatusError.RANGE
        candidate = self.row.copy()
        candidate[address:end] = np.frombuffer(bytes(data), dtype=np.uint8)
        for entry in self.entries_touched(address, len(data)):
            if not entry.minimum <= entry.value_in(candidate) <= entry.maximum:
                return None, StatusError.RANGE
        return candidate, StatusError.NONE

    def entries_touched(self, address: int, length: int) -> tuple[Entry, ...]:
        """Entries overlapping ``address .. address+length-1``, in address order."""
        seen: list[Entry] = []
        for index in self.layout.owner[address : min(address + length, TABLE_SIZE)]:
            if index >= 0 and (not seen or seen[-1] is not self.layout.entries[index]):
                seen.append(self.layout.entries[index])
        return tuple(seen)
