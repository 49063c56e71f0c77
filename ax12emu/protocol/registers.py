"""Control-table entries, profiles and compiled layouts: the types every servo model's table is made of.

Why it exists: a servo model's control table is data (``ax12emu/protocol/models/*.toml``, read by
:mod:`ax12emu.protocol.servo_models`); this module holds what that data becomes, and compiles a
profile into the per-address lookups the bus uses.  It knows no model in particular: the AX-12A's
table is one file among others.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

import numpy as np

__all__ = ["Access", "Area", "Entry", "ModeRange", "Profile", "Layout", "compile_layout", "MAX_ENTRY_SIZE"]

#: The widest register any table has: the X series' 4-byte positions and velocities.
MAX_ENTRY_SIZE = 4


class Access(enum.Enum):
    """Who may change a register through the bus."""

    R = "R"
    RW = "RW"


class Area(enum.Enum):
    """EEPROM registers persist over power cycles; RAM ones return to defaults."""

    EEPROM = "EEPROM"
    RAM = "RAM"


@dataclass(frozen=True)
class ModeRange:
    """A register's range while another register holds one of some values (X series: Goal Position in
    Extended Position Control Mode takes -1,048,575..1,048,575 and ignores the position limits)."""

    #: The register that selects this range (``operating_mode``).
    register: str
    values: tuple[int, ...]
    minimum: int
    maximum: int
    #: Whether ``minimum_from``/``maximum_from`` still bound the value.
    limits: bool = True


@dataclass(frozen=True)
class Entry:
    """One control-table item (e-manual, "Control Table")."""

    #: First byte address.
    address: int
    #: 1, 2 or 4 bytes, little-endian.
    size: int
    #: The e-manual's name, snake_case.
    name: str
    access: Access
    #: Value at power-up and after RESET.
    default: int
    #: Valid values for a write, inclusive (read-only entries keep their full span).
    minimum: int
    maximum: int
    #: EEPROM (persists) or RAM.
    area: Area
    #: Two's complement (the X series' Homing Offset, Goal Velocity, Present Current ...).
    signed: bool = False
    #: Register whose value bounds this one at run time (X series: Goal Position within the position
    #: limits, Goal PWM within +-PWM Limit); a leading "-" negates it.  ``minimum``/``maximum`` are the
    #: widest values those registers allow.  Not enforced by :class:`~ax12emu.protocol.control_table.ControlTable`.
    minimum_from: str | None = None
    maximum_from: str | None = None
    #: Ranges that replace ``minimum``/``maximum`` while another register selects them (first match wins).
    mode_ranges: tuple[ModeRange, ...] = ()
    #: The only values a write may give, where the source lists them (Operating Mode: 0, 1, 3, 4, 5, 16); None: any in range.
    allowed: tuple[int, ...] | None = None

    @property
    def end(self) -> int:
        """One past the last byte."""
        return self.address + self.size

    def value_in(self, image: np.ndarray | bytes) -> int:
        """This entry's value in a table image (a row, a candidate row or saved bytes), little-endian."""
        # One C call (a NumPy row slice is a buffer too): the Protocol 2.0 write path reads dozens of registers a packet.
        return int.from_bytes(image[self.address : self.address + self.size], "little", signed=self.signed)

    @property
    def byte_range(self) -> tuple[int, int]:
        """The values this entry's bytes can hold at all (two's complement when signed), inclusive; the e-manual's
        range (``minimum``/``maximum``) is a separate, narrower matter."""
        bits = 8 * self.size
        return (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if self.signed else (0, (1 << bits) - 1)

    def to_bytes(self, value: int) -> bytes:
        """``value`` as this entry's bytes (two's complement when signed, any int masked to the size)."""
        return (value & ((1 << (8 * self.size)) - 1)).to_bytes(self.size, "little")


@dataclass(frozen=True)
class Profile:
    """A firmware generation's differences from its model's base table, as data."""

    name: str
    #: Where the differences come from.
    source: str
    #: Per-entry replacements of ``default`` / ``minimum`` / ``maximum``.
    overrides: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    #: Entries only this profile has.
    extra_entries: tuple[Entry, ...] = ()
    #: Addresses a WRITE may touch while Lock is 1; any other gives a RANGE error (None: no Lock register).
    lock_writable: range | None = None
    #: What Alarm Shutdown clears: "torque_limit" (set to 0) or "torque_enable"; None where the file's
    #: sources do not say.
    shutdown_clears: str | None = None


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
    #: Bytes in the table (addresses 0 .. table_size - 1).
    table_size: int
    #: EEPROM occupies addresses 0 .. eeprom_end - 1, RAM the rest.
    eeprom_end: int


def compile_layout(profile: Profile, base: tuple[Entry, ...], table_size: int) -> Layout:
    """Apply ``profile`` to ``base`` and compile it; ``ValueError`` on overlaps, bad sizes, defaults out of range."""
    unknown = set(profile.overrides) - {e.name for e in base}
    if unknown:
        raise ValueError(f"profile {profile.name} overrides unknown entries {sorted(unknown)}")
    entries = tuple(
        sorted(
            (dataclasses.replace(e, **profile.overrides.get(e.name, {})) for e in base + profile.extra_entries),
            key=lambda e: e.address,
        )
    )
    owner = np.full(table_size, -1, dtype=np.int64)
    writable = np.zeros(table_size, dtype=bool)
    raw = bytearray(table_size)
    for index, entry in enumerate(entries):
        if entry.size not in (1, 2, MAX_ENTRY_SIZE) or entry.address < 0 or entry.end > table_size:
            raise ValueError(f"profile {profile.name}: entry {entry.name} at {entry.address} (size {entry.size}) "
                             f"does not fit a table of {table_size} bytes in 1, 2 or 4 bytes")
        if np.any(owner[entry.address : entry.end] >= 0):
            other = entries[int(owner[entry.address : entry.end].max())]
            raise ValueError(f"profile {profile.name}: entry {entry.name} at {entry.address} overlaps "
                             f"{other.name} at {other.address}")
        if not entry.minimum <= entry.default <= entry.maximum:
            raise ValueError(f"profile {profile.name}: default {entry.default} of {entry.name} is outside "
                             f"{entry.minimum}..{entry.maximum}")
        owner[entry.address : entry.end] = index
        writable[entry.address : entry.end] = entry.access is Access.RW
        raw[entry.address : entry.end] = entry.to_bytes(entry.default)
    ram = [e.address for e in entries if e.area is Area.RAM]
    eeprom_end = min(ram) if ram else table_size
    late = [e.name for e in entries if e.area is Area.EEPROM and e.address >= eeprom_end]
    if late:
        raise ValueError(f"profile {profile.name}: EEPROM entries {late} lie after the first RAM entry (address "
                         f"{eeprom_end}); the EEPROM area must come first")
    owner.flags.writeable = False
    writable.flags.writeable = False
    return Layout(profile, entries, MappingProxyType({e.name: e for e in entries}), owner, writable, bytes(raw),
                  table_size, eeprom_end)
