"""The AX-12 control table and its rules: reads, validated all-or-nothing writes, defaults.

Why it exists: every register rule (what is writable, what is in range, what
is EEPROM and persists, what RESET restores, what Lock protects) is read from
the table's entries and profiles, never from if-chains elsewhere.  The table
itself is data: ``models/ax-12a.toml`` (read by
:mod:`ax12emu.protocol.servo_models`), with two profiles because the sources
differ: ``ax12a`` follows the current ROBOTIS e-manual for the
AX-12/AX-12+/AX-12A (the project follows the e-manual for protocol and control
table), ``ax12-2006`` the original 2006 AX-12 User's Manual.  Where the
e-manual gives no range the 2006 manual's table of write ranges fills in.

The bus serves AX-12 tables: :data:`PROFILES` and :func:`layout` are the
AX-12A model's profiles (other models' tables are in
:func:`ax12emu.protocol.servo_models.model`); a table of the same shape from
another Protocol 1.0 model (the AX-18A, :data:`PROTOCOL1_MODELS`) is taken too.

The table's bytes live in one row of a ``numpy`` array owned by the bus (one
row per servo), so the physics adapter reads commands and writes sensed
values for all servos at once; :class:`ControlTable` is one row plus rules.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np

from .packets import StatusError
from .registers import Access, Area, Entry, Layout, Profile
from .servo_models import model

__all__ = [
    "Access",
    "Area",
    "Entry",
    "TABLE_SIZE",
    "EEPROM_END",
    "Profile",
    "PROFILES",
    "DEFAULT_PROFILE",
    "Layout",
    "layout",
    "ControlTable",
    "AX12_MODEL",
    "PROTOCOL1_MODELS",
]

#: The model whose tables the bus serves.
AX12_MODEL = "ax-12a"
#: The AX-12A's profiles: ``ax12a`` (e-manual) and ``ax12-2006`` (2006 User's Manual).
PROFILES: Mapping[str, Profile] = model(AX12_MODEL).profiles
DEFAULT_PROFILE = "ax12a"
#: Protocol 1.0 models the bus serves: tables laid out as the AX-12A's (same size, same EEPROM
#: area, same register names, so the plant and the request handler read them alike), with their
#: own model number and data-sheet physics.  The MX series' 1.0 tables differ (PID gains where the
#: compliance registers are, goal acceleration, multi-turn offset): their own bus serves them
#: (:mod:`ax12emu.bus.bus1x`, on the X-series firmware).
PROTOCOL1_MODELS = (AX12_MODEL, "ax-18a")


def layout(profile: str = DEFAULT_PROFILE) -> Layout:
    """The compiled AX-12 table of ``profile`` (checked for overlaps and defaults out of range on load)."""
    if profile not in PROFILES:
        raise ValueError(f"unknown profile {profile!r}; choose one of: {', '.join(PROFILES)}")
    return model(AX12_MODEL).layout(profile)


for _name in PROFILES:  # compile every profile at import
    layout(_name)

#: Addresses 0..49 (e-manual, "Control Table").
TABLE_SIZE = layout().table_size
#: EEPROM occupies addresses 0..23, RAM 24..49 (e-manual, "Control Table").
EEPROM_END = layout().eeprom_end


class ControlTable:
    """One servo's control table: reads, validated all-or-nothing writes, defaults.

    ``row`` is a writable uint8 array of TABLE_SIZE bytes (a row of the bus's
    shared array); a fresh one is made when none is given.
    """

    def __init__(self, row: np.ndarray | None = None, *, profile: str = DEFAULT_PROFILE,
                 table_layout: Layout | None = None) -> None:
        #: ``table_layout``: another Protocol 1.0 model's table (:data:`PROTOCOL1_MODELS`) instead of ``profile``'s.
        self.layout = layout(profile) if table_layout is None else table_layout
        if self.layout.table_size != TABLE_SIZE or self.layout.eeprom_end != EEPROM_END:
            raise ValueError(f"a Protocol 1.0 table here has {TABLE_SIZE} bytes with EEPROM below {EEPROM_END}; "
                             f"{self.layout.profile.name} has {self.layout.table_size} and {self.layout.eeprom_end}")
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
                value = entry.value_in(data)
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
        self.row[entry.address : entry.end] = np.frombuffer(entry.to_bytes(value), dtype=np.uint8)
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
