"""What an MX-series servo on Protocol 1.0 does with one instruction, and what it answers.

Why it exists: the MX's Protocol 1.0 firmware follows the AX-12's policy (:mod:`.request_handler`:
who answers, the status byte, the reply built before an ID change takes effect) over a different
table and firmware (:mod:`.servo1x`), and adds Bulk Read (0x92), which the AX-12 lacks.  One small
handler per instruction, in a table keyed by instruction code; wire errors are values, nothing raises.

Policy, with sources (ROBOTIS e-manual, "Protocol 1.0", https://emanual.robotis.com/docs/en/dxl/protocol1/):

* the status error byte is this instruction's error bits OR'd with the servo's alarm bits (Input
  Voltage, Overheating, Overload: "Status Packet" > "Error"); bit 7 is never set;
* Status Return Level 0 answers PING only, 1 PING and READ (and Bulk Read: the reads), 2 everything;
  "Even if Status Return Level(16) is 0, Dynamixel returns Status Packet all the time for Ping";
* the broadcast ID is executed by every servo and answered by none ("Status Packet will not be
  returned if Broadcast ID(0xFE) is used"), except PING (``Servo1XOptions.reply_to_broadcast_ping``);
* an undefined instruction, or Action "without the reg_write instruction": Instruction Error;
* malformed parameters (a Read without its two bytes, a Sync Write whose length does not divide): Range Error;
* Bulk Read (0x92) is answered by the bus (the listed servos answer in list order, each after the one
  before it: "Bulk Read" > "ID 2 monitors the status packet being sent from ID 1"), from :func:`listed_read`;
* RESET (0x06, "Factory Reset"): answered from the ID the packet reached (the e-manual's example
  answers from ID 0), then the factory table; a broadcast one is not carried out ("Broadcast ID(0xFE)
  cannot be used for Reset instruction", for the MX from firmware V40);
* REBOOT (0x08, "Reboot", MX from firmware V40): answered, then the servo restarts as at power-up
  (RAM area back to its defaults, the EEPROM kept);
* an instruction's Range, Checksum or Instruction Error that Alarm Shutdown(18) selects takes the output to 0
  (Torque Limit 0: :func:`~.request_handler.cuts_output`, the AX-12's rule), a Bulk Read's listed read too.
"""

from __future__ import annotations

from collections.abc import Callable

from ax12emu.protocol.packets import (
    BROADCAST_ID,
    Instruction,
    InstructionPacket,
    StatusError,
    encode_status,
)

from .request_handler import MAX_READ_BYTES, Outcome, answers, cuts_output, ping, silent_read_length, write_handlers
from .servo1x import Servo1X

__all__ = ["HANDLERS", "Outcome1X", "handle1x", "listed_read", "status_byte"]

#: The AX-12's answer (:class:`~.request_handler.Outcome`): who replies, when, with which error bits.
Outcome1X = Outcome

Handler = Callable[[Servo1X, InstructionPacket], tuple[StatusError, bytes]]


def status_byte(servo: Servo1X, error: int) -> int:
    """The status packet's error byte: this instruction's bits and the servo's alarms (bit 7 clear)."""
    return (int(error) | servo.alarms) & 0x7F


def listed_read(servo: Servo1X, address: int, length: int) -> tuple[StatusError, bytes]:
    """A READ's data, always ``length`` bytes (dynamixel-sdk indexes the data of an erroring reply); past the table Range
    Error, which cuts the output when Alarm Shutdown selects it (a Bulk Read's, which the bus answers, as a READ's)."""
    table = servo.table
    length = min(length, MAX_READ_BYTES)
    if address + length > table.size:
        inside = bytes(table.row[address:table.size]) if address < table.size else b""
        servo.instruction_error(StatusError.RANGE)
        return StatusError.RANGE, inside.ljust(length, b"\x00")
    return StatusError.NONE, bytes(table.row[address : address + length])


def _read(servo: Servo1X, packet: InstructionPacket) -> tuple[StatusError, bytes]:
    if len(packet.params) != 2:
        return StatusError.RANGE, b""
    address, length = packet.params
    error, data = listed_read(servo, address, length)
    if length > MAX_READ_BYTES:
        error |= StatusError.RANGE
    return error, data


def _after_reply(servo: Servo1X, packet: InstructionPacket) -> tuple[StatusError, bytes]:
    return StatusError.NONE, b""  # REBOOT: done after the reply is built (handle1x)


def _reset(servo: Servo1X, packet: InstructionPacket) -> tuple[StatusError, bytes]:
    """Factory Reset, carried out after the reply; refused while Lock is 1, as the AX-12A refuses it (Lock: "EEPROM
    area cannot be modified", released only by a power cycle; the e-manual does not say what a locked servo answers:
    the Range Error its refused EEPROM writes get)."""
    return (StatusError.RANGE, b"") if servo.table.get("lock") else (StatusError.NONE, b"")


HANDLERS: dict[int, Handler] = {
    Instruction.PING: ping,
    Instruction.READ: _read,
    Instruction.RESET: _reset,
    Instruction.REBOOT: _after_reply,
    **write_handlers(Servo1X.write, Servo1X.check_write),
}


#: The instructions Status Return Level 1 answers besides PING: an MX's Bulk Read reads too.
READS = (Instruction.READ, Instruction.BULK_READ)


def handle1x(servo: Servo1X, packet: InstructionPacket) -> Outcome1X:
    """Execute ``packet`` on ``servo`` (addressed to it, or broadcast) and build its answer (Bulk Read is the bus's)."""
    reply_id = servo.id
    delay_s = servo.return_delay_s
    talks = answers(servo, packet, READS)
    if not packet.checksum_ok:
        error, data = StatusError.CHECKSUM, bytes(silent_read_length(packet))
        talks = talks and servo.options.reply_on_checksum_error
    else:
        handler = HANDLERS.get(packet.instruction)
        if handler is None:
            error, data = StatusError.INSTRUCTION, bytes(silent_read_length(packet))
        else:
            error, data = handler(servo, packet)
        if error and packet.instruction == Instruction.READ:
            data = data.ljust(silent_read_length(packet), b"\x00")
    if cuts_output(servo, packet, error):
        servo.instruction_error(error)
    reply = encode_status(reply_id, status_byte(servo, error), data) if talks else None
    if packet.checksum_ok and packet.instruction == Instruction.RESET and packet.id != BROADCAST_ID and not error:
        # "Broadcast ID(0xFE) cannot be used for Reset instruction. Applied Products: MX-12W(V41), MX-28(V40),
        # MX-64(V40), MX-106(V40)" (e-manual, Protocol 1.0, "Factory Reset"): every ID on the wire back to 1 otherwise.
        servo.reset()
    elif packet.checksum_ok and packet.instruction == Instruction.REBOOT:
        servo.reboot()
    return Outcome1X(reply, reply_id, delay_s, error)
