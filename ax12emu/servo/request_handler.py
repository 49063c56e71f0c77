"""What a servo does with one instruction packet, and whether it answers.

Why it exists: the policy of Protocol 1.0 (who answers, with which error
bits, what is written) lives here in one place, with one small handler per
instruction in a table keyed by instruction code, not an if-chain.  Wire
errors are values (:class:`StatusError`); nothing here raises on bad input.

Policy, with sources (ROBOTIS e-manual "Protocol 1.0", "Status Return Level";
the 2006 AX-12 User's Manual):

* the error byte of every status packet is the servo's present alarm bits
  OR'd with the errors of this instruction; bit 7 is never set;
* Status Return Level 0 answers PING only, 1 answers PING and READ, 2 all;
* the broadcast ID is executed by every servo and answered by none, except
  PING (see :class:`ServoOptions`);
* an undefined instruction, BULK_READ included (the AX-12 lacks it), and
  ACTION with nothing registered: Instruction Error;
* a write out of range, to a read-only or unused byte, past the table, or
  outside the Lock's window: Range Error, and nothing is written;
* Goal Position outside CW..CCW Angle Limit in joint mode: Angle Limit Error,
  nothing written;
* the status packet is built before the write takes effect on ID, baud and
  return delay (reverse-engineered AX-12 timing notes, xevelabs: "sent after
  everything has been checked but applied after"), so a servo whose ID is
  changed answers from its old ID and then answers to the new one;
* a write touching Goal Position turns the torque on, and a write into the
  EEPROM area leaves the servo deaf for a while after its answer (both
  optional, with their sources: :class:`ServoOptions`; the deafness is the
  bus's to keep, against its clock);
* an instruction's own error that Alarm Shutdown(18) selects (Range, Checksum,
  Instruction, besides Angle Limit) takes the output to 0 as every Alarm
  Shutdown does (:func:`cuts_output`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from ax12emu.protocol.control_table import EEPROM_END
from ax12emu.protocol.packets import BROADCAST_ID, Instruction, InstructionPacket, StatusError, encode_status

from .virtual_servo import VirtualServo

__all__ = ["INSTRUCTION_SHUTDOWN_BITS", "MAX_READ_BYTES", "Outcome", "answers", "cuts_output", "handle", "HANDLERS", "ping",
           "silent_read_length", "write_handlers"]

#: The largest READ reply that fits in one status packet (LENGTH is one byte).
MAX_READ_BYTES = 253
#: An instruction's own error bits that Alarm Shutdown(18) may select, besides Angle Limit (which a refused write
#: checks itself): "Bit 6 Instruction Error ... Bit 4 CheckSum Error ... Bit 3 Range Error", and "If errors occur,
#: ... in case of Alarm Shutdown, the motor output becomes 0 % by resetting the value of Torque Limit(34) to 0"
#: (e-manual, github ROBOTIS-GIT/emanual _includes/en/dxl/control_table_alarm_shutdown.md
#: @ 24e68fc8978bfd135701b94cf4ead644c40fd20b, the AX-12A's and the MX series' Protocol 1.0 pages alike).
INSTRUCTION_SHUTDOWN_BITS = StatusError.RANGE | StatusError.CHECKSUM | StatusError.INSTRUCTION


def cuts_output(servo, packet: InstructionPacket, error: int) -> bool:
    """Whether this instruction's ``error`` takes the output to 0: a bit Alarm Shutdown(18) selects among
    :data:`INSTRUCTION_SHUTDOWN_BITS`.

    A packet with a bad checksum counts when the servo acts on it: the bus hands it to the servo its ID byte names
    (or every servo, broadcast), and the e-manual's Checksum Error, a status packet bit and an Alarm Shutdown bit,
    is the firmware saying it took such a packet as its own; a servo set to stay silent on one
    (``reply_on_checksum_error`` False, "as some firmware is reported to do") is taken as one that drops it unheard.
    """
    bits = int(error) & servo.table.get("shutdown") & INSTRUCTION_SHUTDOWN_BITS
    return bool(bits) and (packet.checksum_ok or servo.options.reply_on_checksum_error)


class Outcome(NamedTuple):
    """What one servo does in answer to one packet (a NamedTuple: built per request)."""

    #: Encoded status packet, or None for silence.
    reply: bytes | None
    #: ID the reply carries (the ID at reception unless a policy says otherwise).
    reply_id: int
    #: Return delay to apply before the reply, seconds (the value at reception).
    delay_s: float
    #: Error bits of this instruction (also in the reply, when there is one).
    error: StatusError = StatusError.NONE


# A handler returns the instruction's error bits and the reply's data bytes.
Handler = Callable[[VirtualServo, InstructionPacket], tuple[StatusError, bytes]]


def ping(servo: object, packet: InstructionPacket) -> tuple[StatusError, bytes]:
    return StatusError.NONE, b""


def _read(servo: VirtualServo, packet: InstructionPacket) -> tuple[StatusError, bytes]:
    if len(packet.params) != 2:
        return StatusError.RANGE, b""
    address, length = packet.params
    data, error = servo.table.read(address, min(length, MAX_READ_BYTES))
    if length > MAX_READ_BYTES:
        error |= StatusError.RANGE
    return error, data


def _angle_error(servo: VirtualServo, candidate: np.ndarray) -> StatusError:
    """Angle Limit Error if the resulting Goal Position lies outside the limits in joint mode."""
    by_name = servo.table.layout.by_name
    cw = by_name["cw_angle_limit"].value_in(candidate)
    ccw = by_name["ccw_angle_limit"].value_in(candidate)
    goal = by_name["goal_position"].value_in(candidate)
    if (cw or ccw) and not cw <= goal <= ccw:
        return StatusError.ANGLE_LIMIT
    return StatusError.NONE


def _judge_write(servo: VirtualServo, address: int, data: bytes) -> tuple[np.ndarray | None, StatusError]:
    """The table after one write, or None and the error bits: what a WRITE and a REG_WRITE alike are checked by
    (a Reg Write is "similar to Write Instruction", e-manual Protocol 1.0, so a goal past the Angle Limits is
    refused when it is registered, as on the MX, not left to fail silently at a broadcast Action)."""
    table = servo.table
    candidate, error = table.check_write(address, data)
    if candidate is None:
        return None, error
    lock = table.layout.by_name["lock"]
    if lock.value_in(table.row) and not lock.value_in(candidate):
        return None, StatusError.RANGE  # Lock is released only by power-off (e-manual, Lock)
    if address <= 31 and address + len(data) > 30:
        error |= _angle_error(servo, candidate)
        if error:
            return None, error
    return candidate, StatusError.NONE


#: Registers whose write turns an AX's torque on (``ServoOptions.goal_position_enables_torque`` says why each).
TORQUE_ON_REGISTERS = ("goal_position", "moving_speed")


def _torque_on_entries(layout):
    return [layout.by_name[name] for name in TORQUE_ON_REGISTERS]


def _apply_write(servo: VirtualServo, address: int, data: bytes) -> StatusError:
    """Validate and commit one write, all-or-nothing, with the firmware's side effects."""
    table = servo.table
    candidate, error = _judge_write(servo, address, data)
    if candidate is None:
        if error & StatusError.ANGLE_LIMIT and table.get("shutdown") & StatusError.ANGLE_LIMIT:
            # "providing that Angle Limit Error Bit(0x01) in the Alarm LED/Shutdown is set, the Alarm LED will start
            # blinking and the motor's output will be 0 [%]" (e-manual, AX-12A, Goal Position; the bit is the
            # status packet's, 0x02); output 0 as every Alarm Shutdown makes it in this table's edition: through
            # Torque Limit (the e-manual), or Torque Enable (the 2006 manual: "torque will be turned off")
            table.set(table.profile.shutdown_clears or "torque_limit", 0)
        return error
    if address < EEPROM_END:
        servo.eeprom_dirty = True
        servo.eeprom_bytes_written += min(len(data), EEPROM_END - address)
    if servo.options.goal_position_enables_torque and any(
            address < entry.end and address + len(data) > entry.address for entry in _torque_on_entries(table.layout)):
        candidate[table.layout.by_name["torque_enable"].address] = 1
    table.row[:] = candidate
    return StatusError.NONE


def _reset(servo: VirtualServo, packet: InstructionPacket) -> tuple[StatusError, bytes]:
    if servo.table.get("lock"):
        # "1: EEPROM area cannot be modified"; "the power must be turned off and then turned on again to change
        # into 0" (e-manual, Lock): RESET rewrote the EEPROM and cleared Lock.  The e-manual does not say what a
        # locked servo answers to RESET: the Range Error its refused EEPROM writes get.
        return StatusError.RANGE, b""
    present = servo.table.get("present_position")
    servo.table.factory_reset()
    servo.table.set("present_position", present)
    servo.power_on()
    servo.eeprom_dirty = True
    return StatusError.NONE, b""


def write_handlers(apply_write: Callable[[Any, int, bytes], StatusError],
                   check_write: Callable[[Any, int, bytes], tuple[object | None, StatusError]]) -> dict[int, Handler]:
    """WRITE, REG_WRITE, ACTION and SYNC_WRITE as Protocol 1.0 defines them, over one servo kind's write.

    Why a factory: the AX-12 and the MX series on Protocol 1.0 parse these four alike (a write without
    address and data, or a Sync Write whose length does not divide, is a Range Error; Action with
    nothing registered an Instruction Error) and differ only in how one write is judged and committed.
    ``apply_write(servo, address, data)`` commits all-or-nothing and returns the error bits;
    ``check_write(servo, address, data)`` judges without writing: (anything, NONE) or (None, the bits).
    """

    def write(servo: Any, packet: InstructionPacket) -> tuple[StatusError, bytes]:
        if len(packet.params) < 2:
            return StatusError.RANGE, b""
        return apply_write(servo, packet.params[0], bytes(packet.params[1:])), b""

    def reg_write(servo: Any, packet: InstructionPacket) -> tuple[StatusError, bytes]:
        if len(packet.params) < 2:
            return StatusError.RANGE, b""
        address, data = packet.params[0], bytes(packet.params[1:])
        accepted, error = check_write(servo, address, data)
        if accepted is None:
            return error, b""
        servo.registered_write = (address, data)
        servo.table.set("registered", 1)
        return StatusError.NONE, b""

    def action(servo: Any, packet: InstructionPacket) -> tuple[StatusError, bytes]:
        if servo.registered_write is None:
            return StatusError.INSTRUCTION, b""
        address, data = servo.registered_write
        servo.registered_write = None
        servo.table.set("registered", 0)
        return apply_write(servo, address, data), b""

    def sync_write(servo: Any, packet: InstructionPacket) -> tuple[StatusError, bytes]:
        """SYNC_WRITE: start address, data length L, then (ID, L bytes) per servo."""
        params = packet.params
        if len(params) < 2 or params[1] == 0 or (len(params) - 2) % (params[1] + 1):
            return StatusError.RANGE, b""
        address, size = params[0], params[1]
        for start in range(2, len(params), size + 1):
            if params[start] == servo.id:
                return apply_write(servo, address, bytes(params[start + 1 : start + 1 + size])), b""
        return StatusError.NONE, b""

    return {
        Instruction.WRITE: write,
        Instruction.REG_WRITE: reg_write,
        Instruction.ACTION: action,
        Instruction.SYNC_WRITE: sync_write,
    }


def _check_write(servo: VirtualServo, address: int, data: bytes) -> tuple[np.ndarray | None, StatusError]:
    return _judge_write(servo, address, data)


HANDLERS: dict[int, Handler] = {
    Instruction.PING: ping,
    Instruction.READ: _read,
    Instruction.RESET: _reset,
    **write_handlers(_apply_write, _check_write),
}


def answers(servo, packet: InstructionPacket, reads: tuple[int, ...] = (Instruction.READ,)) -> bool:
    """Whether a Protocol 1.0 servo sends a status packet for this packet (before errors): PING always (to the
    broadcast ID only as its options say), else as Status Return Level says, level 1 answering ``reads`` (the
    instructions that read: an MX's Bulk Read too)."""
    instruction = packet.instruction
    if packet.id == BROADCAST_ID:
        return instruction == Instruction.PING and servo.options.reply_to_broadcast_ping
    if instruction == Instruction.PING:
        return True
    level = servo.status_return_level
    return level >= 2 or (level == 1 and instruction in reads)


def silent_read_length(packet: InstructionPacket) -> int:
    """Bytes a READ asked for, so an erroring reply still carries them (dynamixel-sdk indexes them)."""
    if packet.instruction == Instruction.READ and len(packet.params) == 2:
        return min(packet.params[1], MAX_READ_BYTES)
    return 0


def handle(servo: VirtualServo, packet: InstructionPacket) -> Outcome:
    """Execute ``packet`` on ``servo`` (already known to be addressed to it) and build its answer."""
    reply_id = servo.id
    delay_s = servo.return_delay_s
    talks = answers(servo, packet)
    if not packet.checksum_ok:
        error = StatusError.CHECKSUM
        data = bytes(silent_read_length(packet))
        talks = talks and servo.options.reply_on_checksum_error
    else:
        handler = HANDLERS.get(packet.instruction)
        if handler is None:
            error, data = StatusError.INSTRUCTION, bytes(silent_read_length(packet))
        else:
            error, data = handler(servo, packet)
            if packet.instruction == Instruction.RESET and servo.options.reset_reply_from_new_id:
                reply_id = servo.id
        if error and packet.instruction == Instruction.READ:
            data = data.ljust(silent_read_length(packet), b"\x00")
    if cuts_output(servo, packet, error):
        # output 0 as the table's edition makes it (as for Angle Limit Error in _apply_write)
        servo.table.set(servo.table.profile.shutdown_clears or "torque_limit", 0)
    if not talks:
        return Outcome(None, reply_id, delay_s, error)
    status = (int(error) | servo.alarms) & 0x7F
    return Outcome(encode_status(reply_id, status, data), reply_id, delay_s, error)
