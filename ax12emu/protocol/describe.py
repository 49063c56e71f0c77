"""Human-readable one-line descriptions of packets, for logs and decoders.

Why it exists: ``-v`` logging (and later trace decoding) should say
"WRITE id=1 goal_position=512" rather than a hex dump, and the control table
is the one place that knows register names.
"""

from __future__ import annotations

from collections.abc import Mapping

from .control_table import DEFAULT_PROFILE, Layout, layout
from .packets import Instruction, InstructionPacket, StatusError, parse_bulk_read

__all__ = ["describe_instruction", "describe_error", "describe_status"]


def describe_error(error: int) -> str:
    """Error byte as names, e.g. "RANGE|OVERLOAD", or "ok"."""
    if not error:
        return "ok"
    names = [flag.name for flag in StatusError if flag and error & flag and flag.name]
    if error & 0x80:
        names.append("BIT7")
    return "|".join(names)


def _table(profile: str | Layout) -> Layout:
    """A profile's AX-12 table by name, or a model's own table (an AX-18A's, an MX's) as given."""
    return layout(profile) if isinstance(profile, str) else profile


def _registers(address: int, data: bytes, profile: str | Layout) -> str:
    lay = _table(profile)
    parts = []
    offset = 0
    while offset < len(data):
        at = address + offset
        index = int(lay.owner[at]) if 0 <= at < len(lay.owner) else -1
        if index < 0:
            parts.append(f"[{at}]={data[offset]}")
            offset += 1
            continue
        entry = lay.entries[index]
        start = at - entry.address
        chunk = data[offset : offset + entry.size - start]
        whole = start == 0 and len(chunk) == entry.size
        value = int.from_bytes(chunk, "little", signed=entry.signed and whole)  # an MX's Multi Turn Offset: signed
        suffix = "" if whole else f"(byte{start}+{len(chunk)})"
        parts.append(f"{entry.name}{suffix}={value}")
        offset += len(chunk)
    return " ".join(parts)


def _span(address: int, length: int, profile: str | Layout) -> str:
    """What a read of ``length`` bytes from ``address`` asks for, in register names."""
    lay = _table(profile)
    entries = lay.owner[address : address + length]
    names = sorted({lay.entries[i].name for i in entries if i >= 0}, key=str)
    return f"address={address} length={length} ({', '.join(names) or 'unused'})"


def describe_instruction(packet: InstructionPacket, profile: str | Layout = DEFAULT_PROFILE,
                         tables: Mapping[int, Layout] | None = None) -> str:
    """One line: instruction, ID and what it asks, in register names.

    ``profile``: the table every ID has (an AX-12 profile's name, or a Layout); ``tables``: an ID's own
    table where the wire mixes models (a SYNC WRITE names each block's registers by its ID's).
    """
    tables = tables or {}
    table = tables.get(packet.id, profile)
    try:
        name = Instruction(packet.instruction).name
    except ValueError:
        name = f"INSTR_{packet.instruction:#04x}"
    head = f"{name} id={packet.id}"
    if not packet.checksum_ok:
        head += " BAD-CHECKSUM"
    params = packet.params
    if packet.instruction == Instruction.READ and len(params) == 2:
        return f"{head} {_span(params[0], params[1], table)}"
    blocks = parse_bulk_read(bytes(params)) if packet.instruction == Instruction.BULK_READ else None
    if blocks:
        spans = (f"[id={b.servo_id} {_span(b.address, b.length, tables.get(b.servo_id, profile))}]" for b in blocks)
        return f"{head} " + " ".join(spans)
    if packet.instruction in (Instruction.WRITE, Instruction.REG_WRITE) and len(params) >= 2:
        return f"{head} {_registers(params[0], bytes(params[1:]), table)}"
    if packet.instruction == Instruction.SYNC_WRITE and len(params) >= 2 and params[1]:
        size = params[1]
        blocks = [
            f"[id={params[i]} {_registers(params[0], bytes(params[i + 1 : i + 1 + size]), tables.get(params[i], profile))}]"
            for i in range(2, len(params) - size, size + 1)
        ]
        return f"{head} " + " ".join(blocks)
    return f"{head} params={params.hex(' ')}" if params else head


def describe_status(
    packet_id: int,
    error: int,
    params: bytes,
    request: InstructionPacket | None = None,
    profile: str | Layout = DEFAULT_PROFILE,
    checksum_ok: bool = True,
) -> str:
    """One line for a status packet; a READ's data is named from its ``request`` (by the table ``profile`` gives:
    a profile's name, or the answering servo's own Layout)."""
    head = f"STATUS id={packet_id} {describe_error(error)}"
    if not checksum_ok:
        head += " BAD-CHECKSUM"
    if not params:
        return head
    if request is not None and request.instruction == Instruction.READ and len(request.params) == 2:
        return f"{head} {_registers(request.params[0], bytes(params), profile)}"
    if request is not None and request.instruction == Instruction.BULK_READ:
        # A Bulk Read is answered by every listed servo in turn, each with its own block's data.
        block = next((b for b in parse_bulk_read(bytes(request.params)) or () if b.servo_id == packet_id), None)
        if block is not None:
            return f"{head} {_registers(block.address, bytes(params), profile)}"
    return f"{head} params={bytes(params).hex(' ')}"
