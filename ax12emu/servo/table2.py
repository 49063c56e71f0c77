"""A Protocol 2.0 control table for any model's layout: reads, validated all-or-nothing writes, indirect addresses.

Why it exists: the X series' tables (``ax12emu/protocol/models/x*.toml``) differ from the AX-12's
in size (hundreds of bytes, 4-byte signed registers), in their error numbers (Protocol 2.0 names
*why* a write failed) and in two mechanisms: the EEPROM area is locked while the torque is on, and
Indirect Data n stands for the byte whose address Indirect Address n holds.  Every rule is read
from the layout's entries (access, area, size, range, ``min_from``/``max_from``); the only names
this module knows are the registers whose meaning the e-manual gives the firmware (Torque Enable,
the indirect pairs).  :class:`ax12emu.protocol.control_table.ControlTable` stays the AX-12's
(its numpy rows serve the 1.0 bus's batched physics).

Write checks, in order (e-manual, "DYNAMIXEL Protocol 2.0" > "Status Packet" > "Error"):

* Access Error (7): a byte past the table, an undefined address, a read-only register, or an
  EEPROM register while Torque Enable is 1 ("Attempt to write a value in the ROM domain while in
  a state of Torque Enable (ROM Lock)");
* Data Length Error (5): a register written in part ("when you attempt to only use 2 bytes of a
  item that has been defined as 4 bytes"); written through indirect data, the same rule holds for
  the bytes the indirect addresses reach;
* Data Range Error (4): a value outside the register's minimum/maximum, or the range its mode selects
  (``ranges_when``: Goal Position in Extended Position Control Mode), or not among the values the
  source lists (``values``: Operating Mode);
* Data Limit Error (6): a value outside the registers that bound it at run time (``min_from`` /
  ``max_from``: Goal Position within Min/Max Position Limit, Goal PWM within +-PWM Limit ...),
  judged on the table as it would be after the write, so limits and goal written together agree.

Reads: any address inside the table may be read (undefined bytes read 0, so a client can read a
block spanning gaps, as ROBOTIS' own tools read whole tables); a read reaching past the table is an
Access Error.  The e-manual's "Attempt to read a value in an Address that ... has not been
defined" is taken to mean addresses the table does not have at all.
"""

from __future__ import annotations

from ax12emu.protocol.packets2 import ErrorNumber
from ax12emu.protocol.registers import Access, Area, Entry, Layout

__all__ = ["Table2", "WriteCheck"]

_INDIRECT_DATA = "indirect_data_"
#: More distinct (address, length) writes than a client uses; past it the plans start over.
MAX_PLANS = 1024
_UNPLANNED = object()
_INDIRECT_ADDRESS = "indirect_address_"


class WriteCheck:
    """The outcome of checking a write: the bytes to store (by address) or the error number."""

    __slots__ = ("error", "changes", "entries")

    def __init__(self, error: int, changes: dict[int, int] | None = None, entries: tuple[Entry, ...] = ()) -> None:
        self.error = error
        #: Address -> byte for every byte the write stores (indirect data already resolved).
        self.changes = changes or {}
        #: The registers the write changes, in address order.
        self.entries = entries


class Table2:
    """One servo's Protocol 2.0 control table: ``row`` holds its bytes; rules come from ``layout``."""

    def __init__(self, layout: Layout) -> None:
        self.layout = layout
        self.row = bytearray(layout.defaults)
        self.size = layout.table_size
        by_name = layout.by_name
        self._torque_enable = by_name["torque_enable"].address
        #: Indirect Data byte address -> address of the Indirect Address register naming its target.
        self._indirect: dict[int, int] = {}
        for entry in layout.entries:
            if entry.name.startswith(_INDIRECT_DATA):
                partner = by_name.get(_INDIRECT_ADDRESS + entry.name[len(_INDIRECT_DATA):])
                if partner is None or entry.size != 1:
                    raise ValueError(f"{entry.name} needs a 1-byte register and an {_INDIRECT_ADDRESS}n partner")
                self._indirect[entry.address] = partner.address
        #: The span of Indirect Data bytes (empty when none): reads and writes clear of it take a short way.
        self._indirect_lo = min(self._indirect, default=0)
        self._indirect_hi = max(self._indirect, default=-1) + 1
        #: A ``minimum_from``/``maximum_from`` reference -> (the register it names, negated).
        self._bounds: dict[str, tuple[Entry, bool]] = {}
        #: (address, length) -> what :meth:`check_write` finds from the layout alone (see ``_plan``).
        self._plans: dict[tuple[int, int], tuple[int, bool, tuple[Entry, ...]] | None] = {}
        #: (address, end, refused) -> the spans of the registers a write's bounds come from, and whether it covers
        #: one of them (see :meth:`_judge_span`).
        self._judged_from: dict[tuple[int, int, frozenset[str]], tuple[tuple[tuple[int, int], ...], bool]] = {}
        #: (address, end, refused, those registers' bytes) -> the checks with every bound read (``_span_checks``).
        self._span_checks: dict[tuple, tuple[bool, tuple, tuple]] = {}

    # -- firmware side: by name, no checks -----------------------------------------------
    def get(self, name: str) -> int:
        """Value of the named register (signed where the entry is)."""
        return self.layout.by_name[name].value_in(self.row)

    def set(self, name: str, value: int) -> None:
        """Set a register as the firmware does (no access or range check)."""
        entry = self.layout.by_name[name]
        self.row[entry.address : entry.end] = entry.to_bytes(value)

    def has(self, name: str) -> bool:
        """Whether this model's table has the register."""
        return name in self.layout.by_name

    def factory_defaults(self, keep: tuple[str, ...] = ()) -> None:
        """Every register to its default, except those named in ``keep``."""
        kept = {name: self.get(name) for name in keep}
        self.row[:] = self.layout.defaults
        for name, value in kept.items():
            self.set(name, value)

    def ram_defaults(self) -> None:
        """The RAM area back to its defaults (a reboot: the EEPROM area stays)."""
        start = self.layout.eeprom_end
        self.row[start:] = self.layout.defaults[start:]

    @property
    def profile(self):
        """The model profile this table follows (its name goes into saved state)."""
        return self.layout.profile

    def eeprom_bytes(self) -> bytes:
        """The EEPROM area, the part that persists."""
        return bytes(self.row[: self.layout.eeprom_end])

    def load_eeprom(self, data: bytes) -> None:
        """Restore a persisted EEPROM area; every writable value must be in its range (read-only ones stay the model's)."""
        end = self.layout.eeprom_end
        if len(data) != end:
            raise ValueError(f"EEPROM image must be {end} bytes, got {len(data)}")
        writable = [e for e in self.layout.entries if e.area is Area.EEPROM and e.access is Access.RW]
        for entry in writable:
            if not entry.minimum <= entry.value_in(data) <= entry.maximum:
                raise ValueError(f"{entry.name} = {entry.value_in(data)} is outside {entry.minimum}..{entry.maximum}")
        for entry in writable:
            self.row[entry.address : entry.end] = data[entry.address : entry.end]

    @property
    def torque_on(self) -> bool:
        return bool(self.row[self._torque_enable])

    # -- bus side ---------------------------------------------------------------------------
    def _target(self, address: int) -> int:
        """The address a byte stands for: Indirect Data n's is Indirect Address n's value, followed on where that is
        Indirect Data too ("inherits features and properties of the Data from the specific Address", e-manual,
        Indirect Address); a chain that comes back on itself stands for the byte where it closes."""
        holder = self._indirect.get(address)
        if holder is None:
            return address
        seen = {address}
        row = self.row
        target = row[holder] | (row[holder + 1] << 8)
        while target in self._indirect and target not in seen:
            seen.add(target)
            holder = self._indirect[target]
            target = row[holder] | (row[holder + 1] << 8)
        return target

    def reads_indirect(self, address: int, length: int) -> bool:
        """Whether ``address``..``+length`` covers Indirect Data (bytes that stand for others)."""
        return not (address + length <= self._indirect_lo or address >= self._indirect_hi)

    def read(self, address: int, length: int) -> tuple[bytes, int]:
        """``length`` bytes from ``address`` and the error number; past the table, Access Error and zeros.

        ``length`` bytes (at most the table's size): dynamixel-sdk indexes the data of an
        erroring reply, so a short one would crash the client instead of reporting the error.
        """
        if address + length > self.size:
            return bytes(min(length, self.size)), ErrorNumber.ACCESS
        if address + length <= self._indirect_lo or address >= self._indirect_hi:
            return bytes(self.row[address : address + length]), ErrorNumber.NONE
        row = self.row
        out = bytearray(row[address : address + length])
        for offset in range(length):
            target = self._target(address + offset)
            if target != address + offset:
                out[offset] = row[target] if target < self.size else 0
        return bytes(out), ErrorNumber.NONE

    def check_write(self, address: int, data: bytes, *, refused: frozenset[str] = frozenset()) -> WriteCheck:
        """Judge a WRITE of ``data`` at ``address`` without applying it (see the module docstring).

        ``refused``: registers whose writes are refused with Data Range Error now (the
        Goal registers during a Bus Watchdog Error, the firmware's state, not the table's).
        """
        if not data or address + len(data) > self.size:
            return WriteCheck(ErrorNumber.ACCESS)
        key = (address, len(data))
        plan = self._plans.get(key, _UNPLANNED)
        if plan is _UNPLANNED:
            if len(self._plans) >= MAX_PLANS:
                self._plans.clear()
            plan = self._plans[key] = self._plan(address, len(data))
        if plan is not None:  # no Indirect Data among the bytes: the layout alone says which registers they are
            error, eeprom, touched = plan
            if error == ErrorNumber.DATA_LENGTH and eeprom and self.torque_on:
                return WriteCheck(ErrorNumber.ACCESS)  # Access Error comes first, as below
            if error:
                return WriteCheck(error)
            if eeprom and self.torque_on:
                return WriteCheck(ErrorNumber.ACCESS)
            return self._judge_span(address, data, touched, refused)
        layout, row = self.layout, self.row
        changes: dict[int, int] = {}
        for offset, byte in enumerate(data):
            changes[self._target(address + offset)] = byte
        touched: list[Entry] = []
        torque_on = self.torque_on
        for target in sorted(changes):
            index = int(layout.owner[target]) if target < self.size else -1
            if index < 0:
                return WriteCheck(ErrorNumber.ACCESS)
            entry = layout.entries[index]
            if entry.access is not Access.RW or (entry.area is Area.EEPROM and torque_on):
                return WriteCheck(ErrorNumber.ACCESS)
            if not touched or touched[-1] is not entry:
                touched.append(entry)
        for entry in touched:
            if any(a not in changes for a in range(entry.address, entry.end)):
                return WriteCheck(ErrorNumber.DATA_LENGTH)
        candidate = bytearray(row)
        for target, byte in changes.items():
            candidate[target] = byte
        return self._judge(changes, tuple(touched), candidate, refused)

    def registers_written(self, address: int, length: int) -> tuple[Entry, ...] | None:
        """The registers a write of ``length`` bytes at ``address`` covers, if the layout alone accepts it (no
        Indirect Data, no undefined, read-only or partly written register, no EEPROM one); else None."""
        if length <= 0 or address + length > self.size:
            return None
        key = (address, length)
        plan = self._plans.get(key, _UNPLANNED)
        if plan is _UNPLANNED:
            if len(self._plans) >= MAX_PLANS:
                self._plans.clear()
            plan = self._plans[key] = self._plan(address, length)
        if plan is None or plan[0] or plan[1]:
            return None
        return plan[2]

    def _plan(self, address: int, length: int) -> tuple[int, bool, tuple[Entry, ...]] | None:
        """What :meth:`check_write` finds of a write to ``address``..``+length`` from the layout alone.

        None if an Indirect Data byte is among them (its target depends on the table); else the
        error the layout gives (Access: undefined or read-only; Data Length: a register in part),
        whether an EEPROM register is among them (Access Error while the torque is on) and the
        registers touched, in address order.  Why: a robot writes the same registers every cycle.
        """
        if not (address + length <= self._indirect_lo or address >= self._indirect_hi):
            if any(target in self._indirect for target in range(address, address + length)):
                return None
        layout = self.layout
        touched: list[Entry] = []
        eeprom = False
        for target in range(address, address + length):
            index = int(layout.owner[target])
            if index < 0:
                return ErrorNumber.ACCESS, False, ()
            entry = layout.entries[index]
            if entry.access is not Access.RW:
                return ErrorNumber.ACCESS, False, ()
            eeprom = eeprom or entry.area is Area.EEPROM
            if not touched or touched[-1] is not entry:
                touched.append(entry)
        if touched[0].address < address or touched[-1].end > address + length:
            return ErrorNumber.DATA_LENGTH, eeprom, ()
        return ErrorNumber.NONE, eeprom, tuple(touched)

    def _judge(self, changes: dict[int, int], touched: tuple[Entry, ...], candidate: bytearray,
               refused: frozenset[str]) -> WriteCheck:
        """The value checks of :meth:`check_write` on the table as it would be after the write."""
        ranges = [self.range_of(entry, candidate) for entry in touched]
        for entry, (minimum, maximum, _) in zip(touched, ranges):
            if entry.name in refused:
                return WriteCheck(ErrorNumber.DATA_RANGE)
            value = entry.value_in(candidate)
            if not minimum <= value <= maximum or (entry.allowed is not None and value not in entry.allowed):
                return WriteCheck(ErrorNumber.DATA_RANGE)
        for entry, (_, _, limits) in zip(touched, ranges):
            if limits and not self._within_limits(entry, candidate):
                return WriteCheck(ErrorNumber.DATA_LIMIT)
        return WriteCheck(ErrorNumber.NONE, changes, touched)

    def _judge_span(self, address: int, data: bytes, touched: tuple[Entry, ...], refused: frozenset[str]) -> WriteCheck:
        """:meth:`_judge` of a write whose bytes are exactly the registers ``touched`` (no Indirect Data).

        The same checks in the same order: a register lies wholly inside the written bytes or wholly
        outside them (a write covering part of one is a Data Length Error before this).  The bounds come
        from a few registers (Operating Mode, the position limits): with their bytes, after the write, as
        they were last time, every bound is as it was, and only the written values are compared.  The
        table as it would be after the write is built only when the write covers one of those registers.
        Why: a robot's Sync Write judges every servo's goal every cycle.
        """
        end = address + len(data)
        key = (address, end, refused)
        known_spans = self._judged_from.get(key)
        if known_spans is None:
            if len(self._judged_from) >= MAX_PLANS:
                self._judged_from.clear()
            known_spans = self._judged_from[key] = self._bounds_read(address, end, touched)
        spans, written = known_spans
        image = self.row
        if written:
            image = bytearray(image)
            image[address:end] = data
        known_key = (key, b"".join([image[start:stop] for start, stop in spans]))
        known = self._span_checks.get(known_key)
        if known is None:
            if len(self._span_checks) >= MAX_PLANS:
                self._span_checks.clear()
            known = self._span_checks[known_key] = self._span_rules(address, touched, refused, image)
        refused_any, in_range, in_limits = known
        if refused_any:
            return WriteCheck(ErrorNumber.DATA_RANGE)
        for start, size, signed, minimum, maximum, allowed in in_range:
            value = int.from_bytes(data[start : start + size], "little", signed=signed)
            if not minimum <= value <= maximum or (allowed is not None and value not in allowed):
                return WriteCheck(ErrorNumber.DATA_RANGE)
        for start, size, signed, lowest, highest in in_limits:
            value = int.from_bytes(data[start : start + size], "little", signed=signed)
            if (lowest is not None and value < lowest) or (highest is not None and value > highest):
                return WriteCheck(ErrorNumber.DATA_LIMIT)
        return WriteCheck(ErrorNumber.NONE, dict(zip(range(address, end), data)), touched)

    def _bounds_read(self, address: int, end: int, touched: tuple[Entry, ...]) -> tuple[tuple[tuple[int, int], ...], bool]:
        """The byte spans of the registers :meth:`_judge_span`'s bounds come from (mode selectors, limit
        registers), and whether the write to ``address``..``end`` covers one of them."""
        by_name = self.layout.by_name
        names = {mode.register for entry in touched for mode in entry.mode_ranges}
        names |= {ref.lstrip("-") for entry in touched for ref in (entry.minimum_from, entry.maximum_from) if ref}
        spans = tuple((by_name[name].address, by_name[name].end) for name in sorted(names))
        return spans, any(start < end and address < stop for start, stop in spans)

    def _span_rules(self, address: int, touched: tuple[Entry, ...], refused: frozenset[str],
                    image: bytearray) -> tuple[bool, tuple, tuple]:
        """:meth:`_judge_span`'s checks with every bound read from ``image`` (the table after the write): whether a
        refused register is written, then (start in the data, size, signed, minimum, maximum, allowed values)
        per register, then (start, size, signed, lowest, highest) per register its limits bound."""
        in_range, in_limits = [], []
        for entry in touched:
            minimum, maximum, limits = self.range_of(entry, image)
            start = entry.address - address
            in_range.append((start, entry.size, entry.signed, minimum, maximum, entry.allowed))
            if limits and (entry.minimum_from is not None or entry.maximum_from is not None):
                lowest = self._bound(entry.minimum_from, image) if entry.minimum_from is not None else None
                highest = self._bound(entry.maximum_from, image) if entry.maximum_from is not None else None
                in_limits.append((start, entry.size, entry.signed, lowest, highest))
        return any(entry.name in refused for entry in touched), tuple(in_range), tuple(in_limits)

    def range_of(self, entry: Entry, image: bytearray | None = None) -> tuple[int, int, bool]:
        """The entry's (minimum, maximum, limits apply) in ``image`` (default: the table): a mode's range where one is selected."""
        image = self.row if image is None else image
        for mode in entry.mode_ranges:
            if self.layout.by_name[mode.register].value_in(image) in mode.values:
                return mode.minimum, mode.maximum, mode.limits
        return entry.minimum, entry.maximum, True

    def _bound(self, ref: str, image: bytearray) -> int:
        bound = self._bounds.get(ref)
        if bound is None:  # looked up once per reference: a robot's every goal write is judged against its limits
            bound = self._bounds[ref] = (self.layout.by_name[ref.lstrip("-")], ref.startswith("-"))
        entry, negate = bound
        value = entry.value_in(image)
        return -value if negate else value

    def _within_limits(self, entry: Entry, image: bytearray) -> bool:
        value = entry.value_in(image)
        if entry.minimum_from is not None and value < self._bound(entry.minimum_from, image):
            return False
        if entry.maximum_from is not None and value > self._bound(entry.maximum_from, image):
            return False
        return True

    def apply(self, check: WriteCheck) -> None:
        """Store a write :meth:`check_write` accepted."""
        row = self.row
        for target, byte in check.changes.items():
            row[target] = byte
