"""A servo whose firmware state is a :class:`~.table2.Table2` built from its model file.

Why a module of its own: the X series on Protocol 2.0 (:class:`~.servo2.Servo2`) and the MX series on
Protocol 1.0 (:class:`~.servo1x.Servo1X`) keep their state alike: a table of their model's layout,
the servo's model file and index on the bus, a Reg Write waiting for Action, an EEPROM area the bus
persists when a write changed it, and the registers the bus reads on every packet (ID, Return Delay
Time, Status Return Level) at addresses looked up once by name.  Each names its own protocol's rules
(baud rates, write errors, what power-up sets).  The AX-12's servos live in the bus's numpy rows
instead (:mod:`.virtual_servo`).
"""

from __future__ import annotations

from ax12emu.protocol.servo_models import ServoModel

from .table2 import Table2

__all__ = ["TableServo"]


class TableServo:
    """Firmware-side state every table-backed servo keeps, and the registers the bus reads per packet."""

    @staticmethod
    def require(spec: ServoModel, protocol: str) -> None:
        """ValueError unless ``spec``'s model file says it speaks ``protocol`` ("1.0", "2.0")."""
        if protocol not in spec.protocols:
            raise ValueError(f"{spec.name} speaks Protocol {'/'.join(spec.protocols)}, not {protocol}")

    def __init__(self, spec: ServoModel, table: Table2, *, servo_id: int, index: int, options) -> None:
        """``table``: the servo's own, of its model's layout (checked by :meth:`require` first)."""
        self.spec = spec
        self.options = options
        self.index = index
        self.table = table
        by_name = table.layout.by_name
        # Read on every packet (a Sync Read or Write of six servos reads each for every servo): looked up once.
        self._id_at = by_name["id"].address
        self._baud_at = by_name["baud_rate"].address
        self._return_delay_at = by_name["return_delay_time"].address
        self._level_at = by_name["status_return_level"].address
        table.set("id", servo_id)
        #: The REG_WRITE waiting for ACTION: (address, data), or None.
        self.registered_write: tuple[int, bytes] | None = None
        #: Set when a write changed the EEPROM area; the bus persists and clears it.
        self.eeprom_dirty = False
        #: The backup area of Control Table Backup (Protocol 2.0's 0x20): the table's bytes, or None; kept with
        #: the EEPROM, as the servo keeps it in its non-volatile memory.
        self.backup: bytes | None = None

    @property
    def id(self) -> int:
        return self.table.row[self._id_at]

    @property
    def return_delay_s(self) -> float:
        """Return Delay Time: 2 us per unit (e-manual, MX series' (5) and X series' (9) alike)."""
        return self.table.row[self._return_delay_at] * 2e-6

    @property
    def status_return_level(self) -> int:
        return self.table.row[self._level_at]
