"""One-line human descriptions of Protocol 2.0 packets, for logs and the trace decoder.

Why it exists: as ``describe.py`` does for Protocol 1.0, a trace should read
"WRITE id=1 @116=512 (4 bytes)" rather than a hex dump.  The X-series control
table is not in this project yet, so registers are named by address unless
the caller passes ``names`` (address to register name).
"""

from __future__ import annotations

from collections.abc import Mapping

from .packets2 import ALERT_BIT, ERROR_NUMBER_MASK, ErrorNumber, Instruction2, InstructionPacket2, Malformed, StatusPacket2
from .params2 import (
    BulkRead,
    BulkWrite,
    Clear,
    ControlTableBackup,
    FactoryReset,
    Read,
    SyncRead,
    SyncWrite,
    Write,
    parse_fast_status,
    parse_params,
    parse_ping_reply,
)

__all__ = ["RegisterName", "describe_error2", "describe_instruction2", "describe_status2"]


class RegisterName(str):
    """A register's name in ``names`` that says how its value reads: ``signed`` (two's complement, the X series'
    Goal Velocity, Present Current ...) when the data is the register's whole ``size``."""

    signed: bool
    size: int

    def __new__(cls, name: str, *, signed: bool = False, size: int = 0) -> "RegisterName":
        self = super().__new__(cls, name)
        self.signed, self.size = signed, size
        return self


def describe_error2(error: int) -> str:
    """Error byte as words, e.g. "ok", "DATA_RANGE", "ALERT|ACCESS", "ERROR_0x09"."""
    number = error & ERROR_NUMBER_MASK
    try:
        words = [] if number == ErrorNumber.NONE else [ErrorNumber(number).name]
    except ValueError:
        words = [f"ERROR_{number:#04x}"]
    if error & ALERT_BIT:
        words.insert(0, "ALERT")
    return "|".join(words) or "ok"


def _at(address: int, names: Mapping[int, str] | None) -> str:
    name = names.get(address) if names else None
    return name if name else f"@{address}"


def _value(data: bytes, name: str | None = None) -> str:
    """Registers are 1, 2 or 4 bytes little-endian (signed where ``name``, a :class:`RegisterName` of that size, says
    so); other sizes are shown as bytes."""
    if len(data) in (1, 2, 4):
        signed = getattr(name, "signed", False) and getattr(name, "size", 0) == len(data)
        return str(int.from_bytes(data, "little", signed=signed))
    return data.hex(" ") if data else "(none)"


def _write(address: int, data: bytes, names: Mapping[int, str] | None) -> str:
    name = names.get(address) if names else None
    return f"{_at(address, names)}={_value(data, name)} ({len(data)} byte{'' if len(data) == 1 else 's'})"


def _name(instruction: int) -> str:
    try:
        return Instruction2(instruction).name
    except ValueError:
        return f"INSTR_{instruction:#04x}"


def describe_instruction2(packet: InstructionPacket2, names: Mapping[int, str] | None = None,
                          names_by_id: Mapping[int, Mapping[int, str]] | None = None) -> str:
    """One line: instruction, ID and what it asks.

    ``names_by_id``: each servo's names, for the blocks of a Sync or Bulk packet (models on one wire need not share
    addresses: the XL-320's 32 is Moving Speed, the XL430's Max Voltage Limit); ``names`` where it has none.
    """
    head = f"{_name(packet.instruction)} id={packet.id}"

    def of(servo_id: int) -> Mapping[int, str] | None:
        return names_by_id.get(servo_id, names) if names_by_id else names

    if not packet.crc_ok:
        return f"{head} BAD-CRC"
    parsed = parse_params(packet.instruction, packet.params)
    if isinstance(parsed, Malformed):
        detail = f" params={packet.params.hex(' ')}" if packet.params else ""
        return f"{head} MALFORMED ({parsed.reason}){detail}"
    if isinstance(parsed, Read):
        return f"{head} {_at(parsed.address, names)} length={parsed.length}"
    if isinstance(parsed, Write):
        return f"{head} {_write(parsed.address, parsed.data, names)}"
    if isinstance(parsed, (FactoryReset, Clear, ControlTableBackup)):
        return f"{head} {parsed.option.name}"
    if isinstance(parsed, SyncRead):
        ids = ",".join(str(i) for i in parsed.ids)
        at = {_at(parsed.address, of(i)) for i in parsed.ids} or {_at(parsed.address, names)}
        where = at.pop() if len(at) == 1 else f"@{parsed.address}"  # named only where every listed servo agrees
        return f"{head} {where} length={parsed.length} ids={ids}"
    if isinstance(parsed, SyncWrite):
        blocks = " ".join(f"[id={i} {_write(parsed.address, data, of(i))}]" for i, data in parsed.writes)
        return f"{head} {blocks}" if blocks else head
    if isinstance(parsed, BulkRead):
        return head + "".join(f" [id={i} {_at(a, of(i))} length={n}]" for i, a, n in parsed.reads)
    if isinstance(parsed, BulkWrite):
        return head + "".join(f" [id={i} {_write(a, data, of(i))}]" for i, a, data in parsed.writes)
    return head


def _describe_fast(packet: StatusPacket2, parsed: object) -> str | None:
    """A combined Fast Sync/Bulk Read status, servo by servo; None if it does not fit its request."""
    if isinstance(parsed, SyncRead):
        lengths: int | dict[int, int] = parsed.length
    elif isinstance(parsed, BulkRead):
        lengths = {servo_id: length for servo_id, _, length in parsed.reads}
    else:
        return None
    entries = parse_fast_status(packet, lengths)
    if isinstance(entries, Malformed):
        return None
    return "FAST-STATUS " + " ".join(
        f"[id={e.id} {describe_error2(e.error)} {_value(e.data)}{'' if e.crc_ok else ' BAD-CRC'}]" for e in entries
    )


def describe_status2(
    packet: StatusPacket2, request: InstructionPacket2 | None = None, names: Mapping[int, str] | None = None
) -> str:
    """One line for a status packet; the ``request`` it answers lets READ data and Fast replies be named."""
    head = f"STATUS id={packet.id} {describe_error2(packet.error)}"
    if not packet.crc_ok:
        return f"{head} BAD-CRC"
    parsed = parse_params(request.instruction, request.params) if request is not None and request.crc_ok else None
    if request is not None and request.instruction in (Instruction2.FAST_SYNC_READ, Instruction2.FAST_BULK_READ):
        fast = _describe_fast(packet, parsed)
        if fast is not None:
            return fast
    if not packet.params:
        return head
    if request is not None and request.instruction == Instruction2.PING:
        reply = parse_ping_reply(packet.params)
        if not isinstance(reply, Malformed):
            return f"{head} model={reply.model_number} firmware={reply.firmware_version}"
    address = None
    if isinstance(parsed, (Read, SyncRead)):
        address = parsed.address
    elif isinstance(parsed, BulkRead):
        address = next((a for i, a, _ in parsed.reads if i == packet.id), None)
    if address is not None:
        return f"{head} {_at(address, names)}={_value(packet.params, names.get(address) if names else None)}"
    return f"{head} params={packet.params.hex(' ')}"
