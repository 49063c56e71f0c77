"""The Protocol 2.0 conformance checks (X series), one small function each, in a table.

Why it exists: as :mod:`.checks` does for Protocol 1.0, one suite judges the
emulator and a real X-series servo alike.  Every check states, in its
docstring, what the ROBOTIS e-manual says and where; the check measures what
the device did.  The sources, by the shorthand the docstrings use:

* [P2] "DYNAMIXEL Protocol 2.0", https://emanual.robotis.com/docs/en/dxl/protocol2/
  (github ROBOTIS-GIT/emanual docs/en/dxl/protocol2.md @ 01179568a085cfc99bdad6e880e43fa871bd318a):
  packet layout, the error numbers ("Status Packet > Error"), each instruction's parameters and
  examples, and the NOTE under "Packet ID": a broadcast READ or WRITE gets no status packet.
* [CT] the X-series control table pages, e.g. https://emanual.robotis.com/docs/en/dxl/x/xl430-w250/
  and the texts they include (ROBOTIS-GIT/emanual ``_includes/en/dxl/x/``): "Area (EEPROM, RAM)"
  ("Data in the EEPROM Area can only be modified if Torque Enable(64) is set to '0'",
  control_table.md @ add0d1dabec2202f8ae9848b7eda8e98f9a44b0f), Status Return Level
  (status_return_level.md @ 048ec0de57bc856b9f127ef854243fb44c86d428), Return Delay Time
  (return_delay_time.md @ 827c5753c0247ee10a3aacee0497d2c89f1f9e7c), Registered Instruction
  (registered_instruction.md @ b1b86dc0c7cfe4d798f319538556c5b793d3dc32), Min/Max Position Limit
  (position_limit.md @ f9dea50c62a09efd77bc81a90fb8646f3a0c4596).

The motion checks (``Check.motion``, run only when asked: ``--motion``) turn the shaft and rest on
[CT] "What is the Profile" (``_includes/en/dxl/profile_description.md`` @
07d929f298ddcec4c3d4d9683afe21a667a466b2: t1 = 64 * Profile Velocity / Profile Acceleration, the
trajectory registers; the travel time t3 = t1 + 64 * dPos / Profile Velocity is on the older pages,
e.g. the XM430-W210 page of 2018), Profile Velocity/Acceleration (``x/profile_velocity.md`` @
048ec0de57bc856b9f127ef854243fb44c86d428, ``x/profile_acceleration.md`` @
53247968642942cbbdb3fb52e47d5aef4269267a), Goal Velocity (``x/goal_velocity.md`` @
9d6b128d8a83a030ec6e602b120fc143ae12b241), Velocity Trajectory (``x/velocity_trajectory.md`` @
d45c8b26749e6d7ac870734a9c85bb5a8f35497d), Moving Status (``x/moving_status.md`` @
53247968642942cbbdb3fb52e47d5aef4269267a), Goal Current (``control_table_goal_current.md`` @
0bb26122f28260b4e8cf9a35cb86bae3d45a2415) and Operating Mode (``x/operating_mode_xl.md`` @
27b439141aeeb8f0adae5240c95030e0231fac47: a mode change resets the gains, the profile and Goal PWM).
Their tolerances are meant for a real servo on a USB adapter: each READ's time is bounded by when it
was sent and answered rather than taken as a point, so latency widens a window instead of failing.

The device's control table comes from the model file whose model number its
Ping reports (``ax12emu/protocol/models/*.toml``), so the suite knows each
register's address, size, range and area without being told the model.

"Byte-exact": a status packet is accepted only if its CRC matches the bytes
received and its ID, error byte and parameters are the expected ones.  The
framer cuts the frame by its LENGTH field and the CRC covers the header,
LENGTH and every byte after, so these together fix every byte of the reply;
the figure shows the bytes.  The Alert bit (bit 7 of the error byte, a latched
hardware error) is reported, never judged: a warm or loaded servo may set it.

No waits after EEPROM writes: the e-manual gives X-series servos no busy time,
and lerobot writes Homing Offset, Min and Max Position Limit to real XL430 and
XL330 servos back to back, each answered (lerobot
src/lerobot/motors/dynamixel/dynamixel.py, ``write_calibration``).

Every check restores what it wrote (in ``finally``); the suite reads each
table before the first check and after the last and reports any writable
register that changed.  Checks that need torque off (EEPROM writes) skip
when torque is on rather than turn it off under a load.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from ax12emu.protocol.describe2 import describe_error2
from ax12emu.protocol.packets2 import (
    ALERT_BIT,
    BROADCAST_ID,
    ERROR_NUMBER_MASK,
    MAX_ID2,
    ErrorNumber,
    Instruction2,
    StatusPacket2,
    encode_instruction2,
    encode_status2,
)
from ax12emu.protocol.params2 import BACKUP_KEY
from ax12emu.protocol.registers import Access, Area, Entry, Layout
from ax12emu.protocol.servo_models import ServoModel, model, model_names

from .checks import Check, Failed, Note, Skipped, Transactions, expect, put_all, return_delay_figure
from .link import Link2

__all__ = ["CHECKS2", "Context2", "model_for_number", "table_differences2"]

#: [CT] Operating Mode(11): 3 is Position Control Mode, the only mode where the position limits apply.
POSITION_MODE = 3
#: [CT] Operating Modes in which torque on holds a position (position, extended, current-based position):
#: the EEPROM-lock check turns torque on only in these, with Goal Position at the present position.
HOLDING_MODES = frozenset({3, 4, 5})
#: dynamixel-sdk's Protocol 2.0 broadcastPing waits (14 * 253 bytes of air time) + 3 ms * 253 + 16 ms
#: (protocol2_packet_handler.py, ``broadcastPing``): the longest a full bus takes to answer in turn.
BROADCAST_PING_SLOT_S = 0.003
#: An instruction the e-manual's table does not define ([P2] "Instruction"): none is 0x50.
UNDEFINED_INSTRUCTION = 0x50
#: The largest READ the suite sends while reading a table (a run of adjacent registers).
_TABLE_READ_MAX = 128
#: The register choosing the mode, and its modes in which torque on holds a position: the X series' Operating
#: Mode, or the XL-320's classic Control Mode(11) ("1 Wheel Mode, 2 Joint Mode", e-manual XL-320 page).
HOLDING_MODE_REGISTERS = {"operating_mode": HOLDING_MODES, "control_mode": frozenset({2})}
#: Registers the firmware sets at power-up rather than to their table's initial value: the Goal registers
#: (Goal PWM/Current take PWM/Current Limit, Goal Position the present position) and, on the XL-320's
#: classic table, Torque Limit(35), "reset to the value of Max Torque(15)" (_includes/en/dxl/control_table_torque_limit.md).
SET_AT_POWER_UP = frozenset({"goal_position", "goal_velocity", "goal_pwm", "goal_current", "torque_limit"})


def model_for_number(number: int) -> ServoModel | None:
    """The shipped Protocol 2.0 model file whose model number is ``number``."""
    for key in model_names():
        candidate = model(key)
        if candidate.model_number == number and "2.0" in candidate.protocols:
            return candidate
    return None


def _reads_back(entry: Entry) -> bool:
    """Registers the suite compares before and after: all but what the firmware changes by itself."""
    return not (entry.area is Area.RAM and entry.access is Access.R)


def table_differences2(before: bytes, after: bytes, layout: Layout) -> list[str]:
    """Host-writable and identity registers that differ between two table images, as "name a->b"."""
    out = []
    for entry in layout.entries:
        if not _reads_back(entry):
            continue
        a, b = entry.value_in(before), entry.value_in(after)
        if a != b:
            out.append(f"{entry.name} {a}->{b}")
    return out


def _runs(layout: Layout) -> list[tuple[int, int]]:
    """(address, length) of READs covering every register, never crossing an undefined address."""
    runs: list[tuple[int, int]] = []
    for entry in layout.entries:
        if runs and runs[-1][0] + runs[-1][1] == entry.address and runs[-1][1] + entry.size <= _TABLE_READ_MAX:
            runs[-1] = (runs[-1][0], runs[-1][1] + entry.size)
        else:
            runs.append((entry.address, entry.size))
    return runs


def _hex(data: bytes) -> str:
    return data.hex(" ")


def _ms(seconds: float) -> str:
    return f"{seconds * 1e3:.2f} ms"


@dataclass
class Context2(Transactions):
    """What the checks share: the link, the IDs, each ID's model (from its Ping) and first table image.

    Its transactions (status, silent, ping_rtts) are :class:`~.checks.Transactions`' with Protocol 2.0's packets.
    """

    encode_packet = staticmethod(encode_instruction2)
    instructions = Instruction2
    check_ok = ("crc_ok", "CRC")
    ping_exchange_bytes = 24  # a Ping (10) and its status (14)

    link: Link2
    ids: list[int]
    destructive: bool = False
    #: Model file of each ID, found from the model number its Ping reported.
    models: dict[int, ServoModel] = field(default_factory=dict)
    #: Table image of each ID read before the first check.
    before: dict[int, bytes] = field(default_factory=dict)
    #: Status Return Level of each ID that had it below 2, raised to 2 for the run (``raise_levels``).
    raised: dict[int, int] = field(default_factory=dict)
    #: IDs that answered the broadcast Ping :meth:`identify` sends (servos under test or not).
    bus_ids: list[int] = field(default_factory=list)
    #: Each servo on the bus whose Secondary ID(12) is active (0 ~ 252; 255, the factory value, is none): that ID.
    secondary: dict[int, int] = field(default_factory=dict)

    @property
    def target(self) -> int:
        """The servo most checks work on."""
        return self.ids[0]

    def free_id(self) -> int:
        """An ID nobody answers to (counting down from 252): no servo under test or found on the bus has it as its ID or
        as its Secondary ID (a packet to that ID would reach the servo, silently)."""
        taken = {*self.ids, *self.bus_ids, *self.secondary.values()}
        free = next((i for i in range(MAX_ID2, -1, -1) if i not in taken), None)
        if free is None:
            raise Skipped(f"no free ID: every ID 0..{MAX_ID2} answers (as its ID or a Secondary ID)")
        return free

    def shadowed_ids(self) -> dict[int, list[int]]:
        """Each ID under test that other servos on the bus have as their Secondary ID: those servos."""
        shadows = {i: [s for s, second in self.secondary.items() if second == i and s != i] for i in self.ids}
        return {i: found for i, found in shadows.items() if found}

    def refusal(self, check: Check) -> str | None:
        """A check that writes is skipped where another servo shadows an ID under test by its Secondary ID(12).

        [CT] Secondary ID(12): an Instruction Packet to a Secondary ID reaches every servo that has it, which executes
        it (the RAM area only) and sends no Status Packet.  A check's writes to that ID (torque on and a Goal
        Position to hold, LED, Indirect Address ...) would reach that servo too, unseen: it moved and kept a stale goal.
        """
        shadows = self.shadowed_ids()
        if check.reads_only or not shadows:
            return None
        said = "; ".join(f"ID {i} is the Secondary ID(12) of servo{'s' if len(by) > 1 else ''} {', '.join(map(str, by))}"
                         for i, by in shadows.items())
        return (f"{said}: this check writes, and a write to that ID reaches {'them' if sum(map(len, shadows.values())) > 1 else 'it'} "
                "too, executed silently (e-manual, Secondary ID); set it to 255 there, or test other IDs")

    def address_bytes(self, address: int) -> bytes:
        """A register address as Protocol 2.0's READ and WRITE carry it (2 bytes, little-endian)."""
        return _u16(address)

    def layout(self, servo_id: int) -> Layout:
        """The control table of ``servo_id``'s model."""
        return self.models[servo_id].layout()

    def entry(self, servo_id: int, name: str) -> Entry:
        """A register of ``servo_id``'s table; skips the check where the model has none."""
        entry = self.layout(servo_id).by_name.get(name)
        if entry is None:
            raise Skipped(f"{self.models[servo_id].name} has no {name}")
        return entry

    # -- setup -----------------------------------------------------------------------------
    def identify(self) -> None:
        """Ping every ID and load the model file its model number names (:class:`Failed` if none fits); find the
        servos on the bus and their Secondary IDs (:meth:`scan_bus`); raise a Status Return Level below 2 for the run.

        A servo that answers Ping but not READ is at Status Return Level 0: the suite cannot read its table.
        """
        for servo_id in self.ids:
            status = self.status(servo_id, Instruction2.PING)
            expect(len(status.params) == 3, f"Ping id={servo_id} carried {len(status.params)} parameter bytes, not 3")
            number = int.from_bytes(status.params[:2], "little")
            found = model_for_number(number)
            expect(found is not None, f"ID {servo_id}: model number {number} has no Protocol 2.0 model file")
            assert found is not None
            self.models[servo_id] = found
        for servo_id in self.ids:
            entry = self.entry(servo_id, "status_return_level")
            if self.transact(encode_instruction2(servo_id, Instruction2.READ, _u16(entry.address) + _u16(1))).status is None:
                raise Failed(f"ID {servo_id} answers Ping but not READ: Status Return Level 0? (the suite reads every "
                             "table; set it to 1 or 2)")
        self.scan_bus()
        self.raise_levels()

    def scan_bus(self) -> None:
        """Broadcast Ping: every servo on the bus answers, under test or not ([P2] "Ping"); then read the Secondary
        ID(12) of each one whose model file has it (a servo that does not answer the READ is taken to have none).

        Listened to for dynamixel-sdk's budget for a full bus (a 14-byte status and 3 ms for each of 253 IDs, the
        adapter's 16 ms) plus the reply timeout: a servo with a high ID answers late.
        """
        byte_s = 10.0 / self.link.baud
        ping = encode_instruction2(BROADCAST_ID, Instruction2.PING)
        wait_s = (len(ping) * byte_s + (MAX_ID2 + 1) * (SDK_PING_STATUS_BYTES * byte_s + SDK_PING_SLOT_S)
                  + SDK_PING_LATENCY_S + self.link.timeout_s)
        start = time.perf_counter()
        self.link.send(ping)
        found: dict[int, int] = {}
        while True:
            status = self.link.receive(wait_s, start=start).status
            if status is None:
                break
            if status.crc_ok and len(status.params) == 3:
                found.setdefault(status.id, int.from_bytes(status.params[:2], "little"))
        self.bus_ids = sorted(found)
        for servo_id, number in found.items():
            spec = model_for_number(number)
            entry = None if spec is None else spec.layout().by_name.get("secondary_id")
            if entry is None:
                continue
            reply = self.transact(encode_instruction2(servo_id, Instruction2.READ, _u16(entry.address) + _u16(entry.size))).status
            if reply is None or not reply.crc_ok or reply.id != servo_id or reply.error & ERROR_NUMBER_MASK or len(reply.params) != 1:
                continue
            if reply.params[0] <= MAX_ID2:
                self.secondary[servo_id] = reply.params[0]

    def table(self, servo_id: int) -> bytes:
        """The whole control table, read register run by register run (undefined addresses left 0)."""
        layout = self.layout(servo_id)
        image = bytearray(layout.table_size)
        for address, length in _runs(layout):
            image[address : address + length] = self.read(servo_id, address, length)
        return bytes(image)

    # -- transactions (transact, status, silent, ping_rtts: Transactions') ----------------------
    def read(self, servo_id: int, address: int, length: int) -> bytes:
        """READ that must succeed: no error number, exactly ``length`` bytes."""
        status = self.status(servo_id, Instruction2.READ, _u16(address) + _u16(length))
        expect(not status.error & ERROR_NUMBER_MASK, f"READ {address}+{length} id={servo_id}: {describe_error2(status.error)}")
        expect(len(status.params) == length, f"READ {address}+{length} id={servo_id} returned {len(status.params)} bytes")
        return bytes(status.params)

    def get(self, servo_id: int, name: str) -> int:
        """A register by name (signed where the table says so)."""
        entry = self.entry(servo_id, name)
        return entry.value_in(bytes(entry.address) + self.read(servo_id, entry.address, entry.size))

    def write(self, servo_id: int, address: int, data: bytes) -> StatusPacket2:
        """WRITE ``data`` at ``address``; the status packet, whatever its error."""
        return self.status(servo_id, Instruction2.WRITE, _u16(address) + data)

    def put(self, servo_id: int, name: str, value: int) -> int:
        """WRITE a register by name; returns the reply's error number (Alert masked)."""
        entry = self.entry(servo_id, name)
        return self.write(servo_id, entry.address, entry.to_bytes(value)).error & ERROR_NUMBER_MASK

    def must_put(self, servo_id: int, name: str, value: int) -> None:
        """WRITE that must succeed."""
        error = self.put(servo_id, name, value)
        expect(not error, f"WRITE {name}={value} id={servo_id}: {describe_error2(error)}")

    def torque_on(self, servo_id: int) -> bool:
        """Torque Enable(64) is 1."""
        return bool(self.get(servo_id, "torque_enable"))

    def turn_torque_on(self, servo_id: int) -> None:
        """Torque Enable 1, for a check that needs the torque on; skipped while a hardware error is latched.

        [CT] Hardware Error Status(70) / Shutdown(63): a detected error turns the torque off and keeps it off until
        REBOOT, so such a servo cannot take the check (it failed the check's own figures instead, though it did
        what the e-manual says).  A servo that accepts the write and leaves the torque off otherwise fails.
        """
        hardware = self.get(servo_id, "hardware_error_status")
        if hardware:
            raise Skipped(f"ID {servo_id}'s Hardware Error Status is {hardware:#04x}: its torque stays off until "
                          "REBOOT, and this check needs it on")
        self.must_put(servo_id, "torque_enable", 1)
        expect(self.torque_on(servo_id), f"ID {servo_id}: Torque Enable 1 written and answered, but it reads 0")


def _u16(value: int) -> bytes:
    return value.to_bytes(2, "little")


def exact(status: StatusPacket2, servo_id: int, number: int, params: bytes = b"") -> str:
    """Check a status packet byte for byte against ``number`` and ``params``; its bytes as the figure."""
    expected = encode_status2(servo_id, number | (status.error & ALERT_BIT), params)
    got = status.encode()
    expect(
        status.crc_ok and got == expected,
        f"expected {_hex(expected)} ({describe_error2(number)}), got {_hex(got)} ({describe_error2(status.error)})",
    )
    return _hex(got)


def error_reply(ctx: Context2, servo_id: int, instruction: int, params: bytes, number: ErrorNumber, what: str) -> str:
    """Send one instruction that must be answered with error ``number``; byte-exact for a write (no parameters).

    The data an erroring READ carries is not judged: the e-manual does not say, and dynamixel-sdk's
    ``read1ByteTxRx`` indexes the data of whatever reply comes, so a device may pad it.
    """
    status = ctx.status(servo_id, instruction, params)
    expect(status.error & ERROR_NUMBER_MASK == number,
           f"{what}: {describe_error2(status.error)}, expected {number.name}")
    if instruction == Instruction2.READ:
        return f"{what}: {number.name} ({len(status.params)} data bytes)"
    exact(status, servo_id, number)
    return f"{what}: {number.name}"


# -- identity and framing -------------------------------------------------------------------
def check_ping(ctx: Context2) -> str:
    """[P2] "Ping": every ID answers with Model Number (LSB, MSB) and Firmware Version, error 0,
    the same Model Number and Firmware Version its control table holds (addresses 0 and 6)."""
    figures = []
    for servo_id in ctx.ids:
        status = ctx.status(servo_id, Instruction2.PING)
        number = int.from_bytes(status.params[:2], "little")
        exact(status, servo_id, ErrorNumber.NONE, status.params)
        at = ctx.entry(servo_id, "firmware_version").address  # 6 on the X series, 2 on the XL-320
        table = ctx.read(servo_id, 0, at + 1)
        expect(int.from_bytes(table[:2], "little") == number, f"ID {servo_id}: Model Number {table[:2].hex()} in the table, {number} in Ping")
        expect(table[at] == status.params[2], f"ID {servo_id}: Firmware Version {table[at]} in the table, {status.params[2]} in Ping")
        figures.append(f"{servo_id}: {ctx.models[servo_id].name} ({number}) fw {status.params[2]}")
    rtts = ctx.ping_rtts(ctx.target, 5)
    return "; ".join(figures) + f"; median {_ms(statistics.median(rtts))}"


def check_absent_id(ctx: Context2) -> str:
    """[P2] "Packet ID": only the addressed device processes a packet; an ID nobody has gets silence."""
    free = ctx.free_id()
    expect(ctx.silent(encode_instruction2(free, Instruction2.PING)), f"ID {free} answered")
    return f"ID {free} silent for {_ms(ctx.link.silence_s)}"


def check_split_packet(ctx: Context2) -> str:
    """[P2] "Processing Order of Reception": a packet is found by its header and LENGTH, however the
    bytes arrive; a Ping sent one byte at a time, 0.5 ms apart, is answered."""
    packet = encode_instruction2(ctx.target, Instruction2.PING)
    start = time.perf_counter()
    ctx.link.flush_input()
    for byte in packet[:-1]:
        ctx.link.write_raw(bytes((byte,)))
        time.sleep(0.0005)
    ctx.link.sent.append(packet)
    ctx.link.write_raw(packet[-1:])
    response = ctx.link.receive(start=time.perf_counter())
    expect(response.status is not None and response.status.id == ctx.target, "no reply to a Ping sent byte by byte")
    return f"{len(packet)} bytes over {_ms(time.perf_counter() - start)}"


def check_resync(ctx: Context2) -> str:
    """[P2] "Processing Order of Reception": the receiver searches for the header FF FF FD (ignoring
    stuffed FF FF FD FD); garbage, a truncated packet and then a pause do not stop the next Ping."""
    ctx.link.write_raw(bytes(range(0, 0xFE, 7)) + b"\xff\xff\xfd\xfd\xff\xff\xfd\x00" + bytes((ctx.target,)) + b"\x07\x00\x02")
    time.sleep(0.1)
    ctx.status(ctx.target, Instruction2.PING)
    return "Ping answered after garbage + a truncated READ (100 ms pause)"


#: Where the stuffing check writes FF FF FD 00: 4 bytes whose first register cannot hold what it gets.
#: The X series: Profile Acceleration(108, 0 ~ 32,767) takes 16,646,143; a classic table (the XL-320):
#: Goal Position(30, 0 ~ 1,023) takes 65,535 and Moving Speed(32) the rest.
STUFFING_TARGETS = (("profile_acceleration",), ("goal_position", "moving_speed"))


def _stuffing_target(ctx: Context2, servo: int) -> tuple[Entry, ...]:
    """The first of :data:`STUFFING_TARGETS` the table has as 4 adjacent bytes; skips the check if none."""
    by_name = ctx.layout(servo).by_name
    for names in STUFFING_TARGETS:
        entries = tuple(by_name.get(name) for name in names)
        if all(entries) and sum(e.size for e in entries) == 4 and all(
                a.end == b.address for a, b in zip(entries, entries[1:])):
            return entries
    raise Skipped(f"{ctx.models[servo].name} has none of {', '.join('+'.join(n) for n in STUFFING_TARGETS)} as 4 adjacent bytes")


def check_byte_stuffing(ctx: Context2) -> str:
    """[P2] "Processing Order of Transmission/Reception": parameters holding FF FF FD are sent stuffed
    (FF FF FD FD) and unstuffed by the receiver.  A WRITE of FF FF FD 00 to Profile Acceleration(108,
    4 bytes, 0 ~ 32,767) is 16,646,143 once unstuffed, out of range (on a classic table, Goal Position
    65,535 of 0 ~ 1,023: :data:`STUFFING_TARGETS`): the reply is Data Range, which shows the packet was
    unstuffed and understood rather than dropped; nothing changes."""
    entries = _stuffing_target(ctx, ctx.target)
    names = [entry.name for entry in entries]
    before = [ctx.get(ctx.target, name) for name in names]
    packet = encode_instruction2(ctx.target, Instruction2.WRITE, _u16(entries[0].address) + b"\xff\xff\xfd\x00")
    expect(b"\xff\xff\xfd\xfd" in packet, "the encoder did not stuff")
    response = ctx.transact(packet)
    expect(response.status is not None, "no reply to a stuffed WRITE")
    status = response.status
    assert status is not None
    expect(status.error & ERROR_NUMBER_MASK == ErrorNumber.DATA_RANGE,
           f"stuffed WRITE of FF FF FD 00 to {'+'.join(names)}: {describe_error2(status.error)}, expected DATA_RANGE")
    expect([ctx.get(ctx.target, name) for name in names] == before, f"the rejected write changed {'+'.join(names)}")
    return f"stuffed WRITE to {'+'.join(names)} answered DATA_RANGE, nothing changed"


def check_crc(ctx: Context2) -> "str | Note":
    """[P2] "Processing Order of Reception": the CRC is checked before anything else, so a packet whose
    CRC does not match is not executed; the error table defines CRC Error (3) for it.  Silence is
    a Note: the e-manual does not say a corrupt packet is answered."""
    led = ctx.get(ctx.target, "led")
    entry = ctx.entry(ctx.target, "led")
    bad = bytearray(encode_instruction2(ctx.target, Instruction2.WRITE, _u16(entry.address) + bytes((1 - led,))))
    bad[-1] ^= 0xFF
    response = ctx.link.transact(bytes(bad))
    try:
        expect(ctx.get(ctx.target, "led") == led, "a WRITE with a bad CRC was executed")
    finally:
        ctx.put(ctx.target, "led", led)
    if response.status is None:
        return Note("not executed; no reply")
    status = response.status
    expect(status.error & ERROR_NUMBER_MASK == ErrorNumber.CRC, f"reply to a bad CRC: {describe_error2(status.error)}")
    return "not executed; " + exact(status, ctx.target, ErrorNumber.CRC) + " (CRC)"


# -- read and write -------------------------------------------------------------------------
def check_read_sizes(ctx: Context2) -> str:
    """[P2] "Read": the status carries exactly the bytes asked for, LENGTH = 4 + X.  1 byte: ID(7) is
    the servo's ID; 2 bytes: Model Number(0) is the Ping's; 4 bytes: Max Position Limit(48) (a table
    without 4-byte registers, the XL-320's "1 ~ 2" bytes, is read in the sizes it has)."""
    figures = []
    for servo_id in ctx.ids:
        names = ["id", "model_number"] + (["max_position_limit"] if "max_position_limit" in ctx.layout(servo_id).by_name else [])
        for name in names:
            entry = ctx.entry(servo_id, name)
            status = ctx.status(servo_id, Instruction2.READ, _u16(entry.address) + _u16(entry.size))
            expect(len(status.params) == entry.size, f"READ {name} id={servo_id}: {len(status.params)} bytes, not {entry.size}")
            exact(status, servo_id, ErrorNumber.NONE, status.params)
        expect(ctx.get(servo_id, "id") == servo_id, f"ID {servo_id}: ID register reads {ctx.get(servo_id, 'id')}")
        expect(ctx.get(servo_id, "model_number") == ctx.models[servo_id].model_number, f"ID {servo_id}: Model Number differs")
        figures.append(f"{servo_id} ({', '.join(str(ctx.entry(servo_id, n).size) for n in names)} bytes)")
    return f"IDs {'; '.join(figures)}"


#: Registers the write-size check writes, by size, the first the table has: none moves the servo.
#: A classic table (the XL-320) has Punch(51) for 2 bytes and no 4-byte register.
WRITE_SIZE_REGISTERS = {1: ("led",), 2: ("indirect_address_1", "punch"), 4: ("profile_acceleration",)}


def check_write_sizes(ctx: Context2) -> str:
    """[P2] "Write": the status is FF FF FD 00 ID 04 00 55 00 CRC (the example's, for ID 1: ... A1 0C)
    and the value reads back.  1 byte: LED(65); 2 bytes: Indirect Address 1(168); 4 bytes: Profile
    Acceleration(108) (or the table's own, :data:`WRITE_SIZE_REGISTERS`; a size it lacks is left out).
    None moves the servo; all restored."""
    servo = ctx.target
    by_name = ctx.layout(servo).by_name
    chosen = [next(n for n in names if n in by_name) for names in WRITE_SIZE_REGISTERS.values() if any(n in by_name for n in names)]
    saved = {name: ctx.get(servo, name) for name in chosen}
    new = {name: value + 1 if value < by_name[name].maximum else by_name[name].minimum for name, value in saved.items()}
    figure = ""
    try:
        for name, value in new.items():
            entry = ctx.entry(servo, name)
            figure = exact(ctx.write(servo, entry.address, entry.to_bytes(value)), servo, ErrorNumber.NONE)
            expect(ctx.get(servo, name) == value, f"{name} reads {ctx.get(servo, name)} after writing {value}")
    finally:
        put_all(ctx, [(servo, name, value) for name, value in saved.items()])
    return f"{', '.join(chosen)} written and read back; status {figure}"


def check_data_length(ctx: Context2) -> str:
    """[P2] error 0x05 Data Length: "Attempt to write Data that is shorter than the data length of the
    corresponding Address (ex: ... only use 2 bytes of a item that has been defined as 4 bytes)".
    2 bytes to Profile Acceleration(108, 4 bytes), or on a table without it 1 byte to Punch(51, 2 bytes,
    the XL-320's); nothing changes."""
    by_name = ctx.layout(ctx.target).by_name
    name = "profile_acceleration" if "profile_acceleration" in by_name else "punch"
    entry = ctx.entry(ctx.target, name)
    before = ctx.get(ctx.target, name)
    short = entry.size // 2
    data = ((before + 1) & ((1 << (8 * short)) - 1)).to_bytes(short, "little")
    figure = error_reply(ctx, ctx.target, Instruction2.WRITE, _u16(entry.address) + data,
                         ErrorNumber.DATA_LENGTH, f"{short} byte(s) to the {entry.size}-byte {name}")
    expect(ctx.get(ctx.target, name) == before, f"the rejected write changed {name}")
    return figure


def check_data_range(ctx: Context2) -> str:
    """[P2] error 0x04 Data Range: "Data to be written ... is outside the range of the minimum/maximum
    value".  [CT] ranges: LED(65) 0 ~ 1, Indirect Address 1(168) 64 ~ 661 (the table's last address).
    LED = 2 and Indirect Address 1 = 63 (each one past the model file's range: the XL-320's LED(25) takes
    0 ~ 7, its colours, and it has no indirect addresses); nothing changes."""
    servo = ctx.target
    figures = []
    by_name = ctx.layout(servo).by_name
    bad_values = [("led", ctx.entry(servo, "led").maximum + 1)]
    if "indirect_address_1" in by_name:
        bad_values.append(("indirect_address_1", by_name["indirect_address_1"].minimum - 1))
    for name, bad in bad_values:
        entry = ctx.entry(servo, name)
        before = ctx.get(servo, name)
        figures.append(error_reply(ctx, servo, Instruction2.WRITE, _u16(entry.address) + entry.to_bytes(bad),
                                   ErrorNumber.DATA_RANGE, f"{name}={bad}"))
        expect(ctx.get(servo, name) == before, f"the rejected write changed {name}")
    return "; ".join(figures)


def check_access(ctx: Context2) -> str:
    """[P2] error 0x07 Access: "Attempt to write a value in an Address that is Read Only or has not been
    defined; attempt to read a value in an Address that ... has not been defined".  A WRITE to Model
    Number(0, R), a WRITE to the first undefined address, a READ past the table's last address."""
    servo = ctx.target
    layout = ctx.layout(servo)
    figures = [error_reply(ctx, servo, Instruction2.WRITE, _u16(0) + _u16(ctx.models[servo].model_number + 1),
                           ErrorNumber.ACCESS, "write Model Number")]
    gap = next(a for a in range(layout.table_size) if layout.owner[a] < 0)
    figures.append(error_reply(ctx, servo, Instruction2.WRITE, _u16(gap) + b"\x00", ErrorNumber.ACCESS, f"write undefined @{gap}"))
    figures.append(error_reply(ctx, servo, Instruction2.READ, _u16(layout.table_size) + _u16(1), ErrorNumber.ACCESS,
                               f"read @{layout.table_size} (past the table)"))
    expect(ctx.get(servo, "model_number") == ctx.models[servo].model_number, "the rejected write changed Model Number")
    return "; ".join(figures)


def check_read_undefined(ctx: Context2) -> Note:
    """[P2] error 0x07 Access lists "Attempt to read a value in an Address that is Write Only or has not
    been defined"; yet tools read whole runs of the table, gaps included.  A READ of the first undefined
    address alone: the figure says whether this device answers Access or data (a note either way)."""
    layout = ctx.layout(ctx.target)
    gap = next(a for a in range(layout.table_size) if layout.owner[a] < 0)
    status = ctx.status(ctx.target, Instruction2.READ, _u16(gap) + _u16(1))
    return Note(f"READ @{gap}+1: {describe_error2(status.error)}, {len(status.params)} data byte(s) {_hex(status.params)}")


@contextmanager
def _torque_held(ctx: Context2, servo: int) -> Iterator[bool]:
    """Torque on for the duration, holding the present position; yields whether it was on already.

    If torque is off it is turned on only in a holding mode ([CT] Operating Mode 3, 4, 5), after
    Goal Position is set to Present Position (no movement); both are put back afterwards.
    """
    was_on = ctx.torque_on(servo)
    goal = None
    try:
        if not was_on:
            by_name = ctx.layout(servo).by_name
            register = next((name for name in HOLDING_MODE_REGISTERS if name in by_name), None)
            if register is None:
                raise Skipped(f"{ctx.models[servo].name} has none of {', '.join(HOLDING_MODE_REGISTERS)}")
            mode = ctx.get(servo, register)
            if mode not in HOLDING_MODE_REGISTERS[register]:
                raise Skipped(f"torque off in {register} {mode}: turning it on could move the servo")
            goal = ctx.get(servo, "goal_position")
            present = ctx.get(servo, "present_position")
            if ctx.put(servo, "goal_position", present):
                raise Skipped(f"Present Position {present} is not a valid Goal Position here")
            ctx.turn_torque_on(servo)
        yield was_on
    finally:
        if not was_on and goal is not None:
            put_all(ctx, [(servo, "torque_enable", 0), (servo, "goal_position", goal)])


def check_eeprom_locked(ctx: Context2) -> str:
    """[P2] error 0x07 Access: "Attempt to write a value in the ROM domain while in a state of Torque
    Enable (ROM Lock)"; [CT] Torque Enable(64): "Setting [it] to '1' will enable output Torque and all
    Data in the EEPROM area will be locked".  With torque on, a WRITE of Return Delay Time(9) with its
    own value is refused with Access (torque turned on for the check as :func:`_torque_held` says)."""
    servo = ctx.target
    with _torque_held(ctx, servo) as was_on:
        delay = ctx.get(servo, "return_delay_time")
        entry = ctx.entry(servo, "return_delay_time")
        figure = error_reply(ctx, servo, Instruction2.WRITE, _u16(entry.address) + bytes((delay,)), ErrorNumber.ACCESS,
                             "EEPROM write with torque on")
    return figure + ("" if was_on else " (torque turned on holding the present position, then off)")


#: [P2] "Control Table Backup (0x20)": "Supported DYNAMIXELs: X430/540 Series (Fw v45 or above), X330 Series
#: (Fw v46 or above)" (https://emanual.robotis.com/docs/en/dxl/protocol2/#control-table-backup-0x20).
BACKUP_FIRMWARE = {"330": 46, "430": 45, "540": 45}


def check_result_fail(ctx: Context2) -> "str | Note":
    """[P2] error 0x01 Result Fail, "Failed to process the sent Instruction Packet"; [P2] "Control Table
    Backup (0x20)": "If the Torque Enable is set as '1' (Torque On), Status Packet with Result Fail will
    be returned".  A backup store (0x01 "CTRL") with torque on (:func:`_torque_held`) is refused with
    Result Fail and stores nothing.  A firmware older than the page's v45 (X430/540) or v46 (X330)
    has no such instruction: Instruction Error from it is a Note."""
    servo = ctx.target
    firmware = ctx.read(servo, ctx.entry(servo, "firmware_version").address, 1)[0]
    series = next((s for s in BACKUP_FIRMWARE if s in ctx.models[servo].name), None)
    if series is None and ctx.models[servo].classic is not None:
        raise Skipped(f"{ctx.models[servo].name}: the e-manual gives Control Table Backup to the X430/540 and X330 only")
    with _torque_held(ctx, servo):
        status = ctx.status(servo, Instruction2.CONTROL_TABLE_BACKUP, b"\x01" + BACKUP_KEY)
    number = status.error & ERROR_NUMBER_MASK
    if number == ErrorNumber.INSTRUCTION and series is not None and firmware < BACKUP_FIRMWARE[series]:
        return Note(f"firmware {firmware}: no Control Table Backup (INSTRUCTION)")
    expect(number == ErrorNumber.RESULT_FAIL, f"backup store with torque on: {describe_error2(status.error)} (firmware {firmware})")
    exact(status, servo, ErrorNumber.RESULT_FAIL)
    return f"backup store with torque on: RESULT_FAIL (firmware {firmware})"


#: The mode register and its values in which Goal Position's limits apply: the X series' Position Control Mode, the
#: XL-320's joint mode (Control Mode 2; its CW/CCW Angle Limit bound Goal Position, wheel mode uses no goal).
LIMIT_MODES = {"operating_mode": frozenset({POSITION_MODE}), "control_mode": frozenset({2})}


def check_data_limit(ctx: Context2) -> "str | Note":
    """[P2] error 0x06 Data Limit: "Data to be written ... is outside of the Limit value"; [CT] Goal
    Position(116) ranges "Min Position Limit(52) ~ Max Position Limit(48)" in Position Control Mode
    (position_limit.md).  Goal Position = Max Position Limit + 1 (the limit lowered by one for the
    check if it is at its maximum, an EEPROM write: torque must be off) is refused and not taken.  Data
    Range instead is a Note: the page prints the limits in its Range column.  The limit is the register
    the model file bounds Goal Position by (``max_from``): CCW Angle Limit(8) on the XL-320, in joint mode."""
    servo = ctx.target
    by_name = ctx.layout(servo).by_name
    target = ctx.entry(servo, "goal_position")
    limit_name = target.maximum_from
    register = next((name for name in LIMIT_MODES if name in by_name), None)
    if limit_name is None or register is None:
        raise Skipped(f"{ctx.models[servo].name}: no register bounds Goal Position, or no mode register says where one applies")
    if ctx.get(servo, register) not in LIMIT_MODES[register]:
        raise Skipped(f"{register} {ctx.get(servo, register)}: not the mode where the limits apply")
    label = limit_name.replace("_", " ").title().replace("Ccw", "CCW")
    limit = ctx.get(servo, limit_name)
    lowered = limit >= min(ctx.entry(servo, limit_name).maximum, target.maximum)
    if lowered and ctx.torque_on(servo):
        raise Skipped(f"torque is on and {label} is at its maximum: lowering it is an EEPROM write")
    goal = ctx.get(servo, "goal_position")
    try:
        if lowered:
            ctx.must_put(servo, limit_name, limit - 1)
        beyond = (limit - 1 if lowered else limit) + 1
        status = ctx.write(servo, target.address, target.to_bytes(beyond))
        number = status.error & ERROR_NUMBER_MASK
        expect(ctx.get(servo, "goal_position") == goal, f"Goal Position {beyond} beyond the limit was taken ({describe_error2(number)})")
    finally:
        if lowered:
            ctx.put(servo, limit_name, limit)
    if number == ErrorNumber.DATA_RANGE:
        return Note(f"goal {beyond} > {label} {beyond - 1}: DATA_RANGE, not taken")
    expect(number == ErrorNumber.DATA_LIMIT, f"goal {beyond} > {label} {beyond - 1}: {describe_error2(number)}")
    exact(status, servo, ErrorNumber.DATA_LIMIT)
    return f"goal {beyond} > {label} {beyond - 1}: DATA_LIMIT, not taken"


def check_instruction_error(ctx: Context2) -> str:
    """[P2] error 0x02 Instruction: "Undefined Instruction has been used; Action has been used without
    Reg Write".  Instruction 0x50 (not in the table), then ACTION with Registered Instruction(69) 0."""
    servo = ctx.target
    figures = [error_reply(ctx, servo, UNDEFINED_INSTRUCTION, b"", ErrorNumber.INSTRUCTION, f"instruction {UNDEFINED_INSTRUCTION:#04x}")]
    if ctx.get(servo, "registered_instruction"):
        raise Skipped("a Reg Write is pending on the device")
    figures.append(error_reply(ctx, servo, Instruction2.ACTION, b"", ErrorNumber.INSTRUCTION, "bare ACTION"))
    return "; ".join(figures)


def check_reg_write_action(ctx: Context2) -> str:
    """[P2] "Reg Write": registers the write and sets Registered Instruction(69) to 1; "Action": executes
    it and sets Registered Instruction to 0 ([CT] registered_instruction.md).  Both answered with the
    example's empty status."""
    servo = ctx.target
    led = ctx.get(servo, "led")
    entry = ctx.entry(servo, "led")
    try:
        exact(ctx.status(servo, Instruction2.REG_WRITE, _u16(entry.address) + bytes((1 - led,))), servo, ErrorNumber.NONE)
        expect(ctx.get(servo, "registered_instruction") == 1, "Registered Instruction is not 1 after REG_WRITE")
        expect(ctx.get(servo, "led") == led, "REG_WRITE took effect before ACTION")
        exact(ctx.status(servo, Instruction2.ACTION), servo, ErrorNumber.NONE)
        expect(ctx.get(servo, "led") == 1 - led, "ACTION did not apply the registered write")
        expect(ctx.get(servo, "registered_instruction") == 0, "Registered Instruction still 1 after ACTION")
    finally:
        ctx.put(servo, "led", led)
    return "registered 0->1->0, LED applied on ACTION"


# -- several servos ---------------------------------------------------------------------------
def _replies(ctx: Context2, count: int, timeout_s: float | None = None) -> list[StatusPacket2]:
    out = []
    for _ in range(count):
        response = ctx.link.receive(timeout_s)
        if response.status is None:
            break
        out.append(response.status)
    return out


def _sharing(ctx: Context2, name: str) -> tuple[list[int], list[int]]:
    """The IDs whose ``name`` register sits where the target's does (one Sync instruction reaches them all), and the others.

    Why: a Sync Read or Write names one address for every listed servo, and a bus may mix tables (the
    XL-320's ID is at 3, the X series' at 7); a servo of another table is left out, and the figure says so.
    """
    entry = ctx.entry(ctx.target, name)
    same, other = [], []
    for servo_id in ctx.ids:
        mine = ctx.layout(servo_id).by_name.get(name)
        (same if mine is not None and (mine.address, mine.size) == (entry.address, entry.size) else other).append(servo_id)
    return same, other


def _left_out(other: list[int]) -> str:
    return f" (IDs {','.join(map(str, other))} left out: another table)" if other else ""


def check_sync_read(ctx: Context2) -> str:
    """[P2] "Sync Read" (0x82, ID 0xFE): each listed device answers with its own status packet; the
    example's two answer in the listed order.  IDs listed in reverse; each answers with its ID(7)
    byte, byte-exact, in that order."""
    same, other = _sharing(ctx, "id")
    order = list(reversed(same))
    entry = ctx.entry(ctx.target, "id")
    ctx.link.send(encode_instruction2(BROADCAST_ID, Instruction2.SYNC_READ, _u16(entry.address) + _u16(1) + bytes(order)))
    replies = _replies(ctx, len(order))
    expect([r.id for r in replies] == order, f"answers from {[r.id for r in replies]}, listed {order}")
    for reply in replies:
        exact(reply, reply.id, ErrorNumber.NONE, bytes((reply.id,)))
    return f"listed {order}, answered in that order" + _left_out(other)


def check_sync_write(ctx: Context2) -> str:
    """[P2] "Sync Write" (0x83, ID 0xFE): writes each listed device; nobody answers (a broadcast WRITE)."""
    same, other = _sharing(ctx, "led")
    entry = ctx.entry(ctx.target, "led")
    leds = {i: ctx.get(i, "led") for i in same}
    body = _u16(entry.address) + _u16(1) + b"".join(bytes((i, 1 - leds[i])) for i in same)
    try:
        expect(ctx.silent(encode_instruction2(BROADCAST_ID, Instruction2.SYNC_WRITE, body)), "SYNC_WRITE was answered")
        for servo_id in same:
            expect(ctx.get(servo_id, "led") == 1 - leds[servo_id], f"ID {servo_id} not written")
    finally:
        put_all(ctx, [(servo_id, "led", led) for servo_id, led in leds.items()])
    return f"{len(same)} servo(s) written, silent" + _left_out(other)


_BULK_REGISTERS = ("id", "model_number", "max_position_limit")


def _bulk_register(ctx: Context2, servo_id: int, turn: int) -> Entry:
    """The ``turn``-th of :data:`_BULK_REGISTERS` (cyclically), or the next one ``servo_id``'s table has: a mixed bus
    (an XL-320 has no Max Position Limit) is read in the registers each table has, whatever the IDs' order."""
    by_name = ctx.layout(servo_id).by_name
    names = [_BULK_REGISTERS[(turn + k) % len(_BULK_REGISTERS)] for k in range(len(_BULK_REGISTERS))]
    return next(by_name[name] for name in names if name in by_name)


def check_bulk_read(ctx: Context2) -> str:
    """[P2] "Bulk Read" (0x92, ID 0xFE): different address and length per device, each answers with its
    own status packet; the page's later revisions say "[Status Packet] will be returned in order,
    according to input ID in the [Instruction Packet]" (https://emanual.robotis.com/docs/en/dxl/protocol2/#bulk-read-0x92).  ID(7, 1 byte), Model
    Number(0, 2) and Max Position Limit(48, 4) in turn, IDs listed in reverse; a table without the register of its
    turn (the XL-320 has no Max Position Limit) is read in the next one it has."""
    order = list(reversed(ctx.ids))
    asked = {i: _bulk_register(ctx, i, n) for n, i in enumerate(order)}
    expected = {i: ctx.read(i, e.address, e.size) for i, e in asked.items()}
    body = b"".join(bytes((i,)) + _u16(e.address) + _u16(e.size) for i, e in asked.items())
    ctx.link.send(encode_instruction2(BROADCAST_ID, Instruction2.BULK_READ, body))
    replies = _replies(ctx, len(order))
    expect([r.id for r in replies] == order, f"answers from {[r.id for r in replies]}, listed {order}")
    for reply in replies:
        exact(reply, reply.id, ErrorNumber.NONE, expected[reply.id])
    return ", ".join(f"{i}: {asked[i].name}" for i in order) + ", in order"


def check_bulk_write(ctx: Context2) -> str:
    """[P2] "Bulk Write" (0x93, ID 0xFE): a different address and length per device; nobody answers.
    LED(65, 1 byte) and Indirect Address 1(168, 2 bytes) in turn (or the table's own 2-byte register of
    :data:`WRITE_SIZE_REGISTERS`: Punch(51) on the XL-320); restored."""
    plan = {}
    for n, servo_id in enumerate(ctx.ids):
        by_name = ctx.layout(servo_id).by_name
        name = "led" if n % 2 == 0 else next((n2 for n2 in WRITE_SIZE_REGISTERS[2] if n2 in by_name), "indirect_address_1")
        old = ctx.get(servo_id, name)
        entry = ctx.entry(servo_id, name)
        plan[servo_id] = (name, old, old + 1 if old < entry.maximum else entry.minimum)
    body = b"".join(
        bytes((i,)) + _u16(ctx.entry(i, name).address) + _u16(ctx.entry(i, name).size) + ctx.entry(i, name).to_bytes(new)
        for i, (name, _, new) in plan.items()
    )
    try:
        expect(ctx.silent(encode_instruction2(BROADCAST_ID, Instruction2.BULK_WRITE, body)), "BULK_WRITE was answered")
        for servo_id, (name, _, new) in plan.items():
            expect(ctx.get(servo_id, name) == new, f"ID {servo_id}: {name} not written")
    finally:
        put_all(ctx, [(servo_id, name, old) for servo_id, (name, old, _) in plan.items()])
    return ", ".join(f"{i}: {name}" for i, (name, _, _) in plan.items()) + ", silent"


def _expect_unique(seen: list[int]) -> None:
    """Fail naming every ID that answered one broadcast Ping more than once: two servos share it ([P2] "Packet ID":
    each device has its own ID), and every packet to it reaches both."""
    shared = sorted({i for i in seen if seen.count(i) > 1})
    expect(not shared, f"ID{'s' if len(shared) > 1 else ''} {', '.join(map(str, shared))} answered more than once "
                       f"(answers from {seen}): two servos share {'each' if len(shared) > 1 else 'it'}")


def check_broadcast_ping(ctx: Context2) -> str:
    """[P2] "Ping": "When the Packet ID field is 0xFE (Broadcast ID): All devices send their Status Packet
    according to their arranged order" (Example 2: ID 1, then ID 2); Ping is answered whatever the
    Status Return Level.  Every ID under test answers, byte-exact, in ascending ID order."""
    wait_s = ctx.link.timeout_s + BROADCAST_PING_SLOT_S * (max(ctx.ids) + 1)
    start = time.perf_counter()
    ctx.link.send(encode_instruction2(BROADCAST_ID, Instruction2.PING))
    replies: list[StatusPacket2] = []
    last_s = 0.0
    while True:
        # once every ID under test has answered, only the silence window is left for an answer too many
        response = ctx.link.receive(ctx.link.silence_s if set(ctx.ids) <= {r.id for r in replies} else wait_s)
        if response.status is None:
            break
        replies.append(response.status)
        last_s = time.perf_counter() - start
    seen = [r.id for r in replies]
    _expect_unique(seen)
    expect(set(ctx.ids) <= set(seen), f"answers from {seen}, expected {sorted(ctx.ids)}")
    expect(seen == sorted(seen), f"answers in the order {seen}, not ascending")
    for reply in replies:
        expect(reply.crc_ok, f"ID {reply.id}: bad CRC")
        if reply.id in ctx.models:
            expect(int.from_bytes(reply.params[:2], "little") == ctx.models[reply.id].model_number, f"ID {reply.id}: model number")
            exact(reply, reply.id, ErrorNumber.NONE, reply.params)
    return f"answers from {seen}, the last {_ms(last_s)} after the Ping"


#: dynamixel-sdk's Protocol 2.0 ``broadcastPing`` budget: a status packet of 14 bytes and 3 ms for every ID up to
#: the highest, plus 16 ms (the USB adapter's latency timer) (protocol2_packet_handler.py: ``STATUS_LENGTH = 14``,
#: ``setPacketTimeoutMillis((wait_length * tx_time_per_byte) + (3.0 * MAX_ID) + 16.0)``).
SDK_PING_STATUS_BYTES, SDK_PING_SLOT_S, SDK_PING_LATENCY_S = 14, 0.003, 0.016


def check_broadcast_ping_timing(ctx: Context2) -> str:
    """[P2] "Ping": to the Broadcast ID "all connected devices will respond with a status packet", and (Example 2)
    in ID order; the e-manual gives no time for a device's turn.  [CT] Return Delay Time(9) delays every status
    packet by 2 us a unit.  What clients rely on is dynamixel-sdk's budget: ID n answered within the instruction,
    Return Delay Time and n + 1 slots of a 14-byte status plus 3 ms, plus 16 ms of adapter latency; here each ID
    must answer within that budget plus the link's own overhead (the fastest unicast Ping's round trip less its
    wire time).  The figure gives each answer's arrival and the time per ID (a line through them): the turn a
    device waits is left open by the e-manual, so it is reported, not judged (a USB adapter delivers answers in
    batches, which hides the spacing)."""
    byte_s = 10.0 / ctx.link.baud
    delay_s = max(ctx.get(i, "return_delay_time") for i in ctx.ids) * 2e-6
    ping = encode_instruction2(BROADCAST_ID, Instruction2.PING)
    unicast = min(ctx.ping_rtts(ctx.target, 5))
    overhead_s = max(0.0, unicast - (len(ping) + SDK_PING_STATUS_BYTES) * byte_s - delay_s)
    budget = {i: len(ping) * byte_s + delay_s + (i + 1) * (SDK_PING_STATUS_BYTES * byte_s + SDK_PING_SLOT_S)
              + SDK_PING_LATENCY_S + overhead_s for i in ctx.ids}
    wait_s = max(budget.values()) + ctx.link.timeout_s
    start = time.perf_counter()
    ctx.link.send(ping)
    arrivals: list[tuple[int, float]] = []
    while True:
        if set(ctx.ids) <= {i for i, _ in arrivals}:  # every ID answered: the silence window for one too many
            response = ctx.link.receive(ctx.link.silence_s)
            response = response._replace(rtt_s=time.perf_counter() - start)
        else:
            response = ctx.link.receive(wait_s, start=start)
        if response.status is None:
            break
        arrivals.append((response.status.id, response.rtt_s))
    seen = [i for i, _ in arrivals]
    _expect_unique(seen)  # (and a line through the answers needs distinct IDs)
    expect(set(ctx.ids) <= set(seen) and seen == sorted(seen), f"answers from {seen}, expected {sorted(ctx.ids)} in order")
    late = [f"ID {i} at {_ms(t)} (budget {_ms(budget[i])})" for i, t in arrivals if i in budget and t > budget[i]]
    figure = ", ".join(f"{i}: {_ms(t)}" for i, t in arrivals)
    if len(arrivals) > 1:
        slope = statistics.linear_regression([i for i, _ in arrivals], [t for _, t in arrivals]).slope
        figure += f"; {slope * 1e3:.2f} ms per ID (a 14-byte status is {_ms(SDK_PING_STATUS_BYTES * byte_s)})"
    expect(not late, "late: " + "; ".join(late) + f" ({figure})")
    return figure + f"; link overhead {_ms(overhead_s)}"


def check_broadcast_read_write(ctx: Context2) -> str:
    """[P2] "Packet ID" NOTE: with the Broadcast ID "Status Packet will not be returned for READ and WRITE
    Instructions"; [P2] "Packet ID": 0xFE "makes all connected devices execute the Instruction
    Packet".  A broadcast WRITE of LED sets every servo, silently; a broadcast READ is not answered.  On a bus
    mixing tables, servos whose LED is elsewhere are judged unchanged, and the check is skipped where the
    byte would land on another table's 1-byte register (it would be written)."""
    same, other = _sharing(ctx, "led")
    entry = ctx.entry(ctx.target, "led")
    for servo_id in other:
        layout = ctx.layout(servo_id)
        owner = int(layout.owner[entry.address]) if entry.address < layout.table_size else -1
        if owner >= 0 and layout.entries[owner].size == 1:
            raise Skipped(f"ID {servo_id}'s table has {layout.entries[owner].name} at LED's address {entry.address}")
    leds = {i: ctx.get(i, "led") for i in same}
    images = {i: ctx.table(i) for i in other}
    try:
        expect(ctx.silent(encode_instruction2(BROADCAST_ID, Instruction2.WRITE, _u16(entry.address) + b"\x01")),
               "broadcast WRITE answered")
        for servo_id in same:
            expect(ctx.get(servo_id, "led") == 1, f"ID {servo_id} not written by the broadcast WRITE")
        for servo_id, image in images.items():
            changed = table_differences2(image, ctx.table(servo_id), ctx.layout(servo_id))
            expect(not changed, f"ID {servo_id} (another table): the broadcast WRITE changed {', '.join(changed)}")
    finally:
        put_all(ctx, [(servo_id, "led", led) for servo_id, led in leds.items()])
    expect(ctx.silent(encode_instruction2(BROADCAST_ID, Instruction2.READ, _u16(entry.address) + _u16(1))),
           "broadcast READ answered")
    return "WRITE executed by all, silent; READ silent" + ("" if not other else f" (IDs {','.join(map(str, other))}: another table, unchanged)")


def check_status_return_level(ctx: Context2) -> str:
    """[CT] Status Return Level(68): 0 answers PING only, 1 PING and READ, 2 all instructions.  At 1 a
    WRITE is executed but silent; at 0 a READ is silent too.  Restored with a WRITE that, at level 0,
    gets no reply, then read back."""
    servo = ctx.target
    level = ctx.get(servo, "status_return_level")
    srl = ctx.entry(servo, "status_return_level")
    led = ctx.entry(servo, "led")
    value = ctx.get(servo, "led")
    write_led = encode_instruction2(servo, Instruction2.WRITE, _u16(led.address) + bytes((value,)))
    read_led = encode_instruction2(servo, Instruction2.READ, _u16(led.address) + _u16(1))
    ping = encode_instruction2(servo, Instruction2.PING)
    try:
        ctx.link.transact(encode_instruction2(servo, Instruction2.WRITE, _u16(srl.address) + b"\x01"))
        expect(ctx.silent(write_led), "level 1 answered a WRITE")
        expect(ctx.answers(read_led), "level 1 did not answer a READ")
        expect(ctx.answers(ping), "level 1 did not answer PING")
        # at level 1 this WRITE gets no answer: listened to for the silence window, not the reply timeout
        ctx.link.transact(encode_instruction2(servo, Instruction2.WRITE, _u16(srl.address) + b"\x00"), timeout_s=ctx.link.silence_s)
        expect(ctx.silent(read_led), "level 0 answered a READ")
        expect(ctx.silent(write_led), "level 0 answered a WRITE")
        expect(ctx.answers(ping), "level 0 did not answer PING")
    finally:
        ctx.link.send(encode_instruction2(servo, Instruction2.WRITE, _u16(srl.address) + bytes((level,))))
        time.sleep(0.005)
    expect(ctx.get(servo, "status_return_level") == level, "Status Return Level not restored")
    return "0: PING only; 1: PING+READ; 2: all"


def check_return_delay(ctx: Context2) -> "str | Note":
    """[CT] Return Delay Time(9): the status packet is returned after the set time, 2 us per unit,
    0 ~ 254 (default 250 = 500 us).  The fastest Ping round trip at 250 minus the fastest at 0 is at
    least 0.6 x 500 us (a busy host only adds time).  An EEPROM register: skipped with torque on."""
    servo = ctx.target
    if ctx.torque_on(servo):
        raise Skipped("torque is on: Return Delay Time is in the EEPROM area")
    return return_delay_figure(ctx, servo)


def check_defaults(ctx: Context2) -> "str | Note":
    """[CT] "Initial Value" column: registers at the model file's factory defaults (ID and what the
    firmware or a user's configuration sets excepted); differences are a Note, not a failure."""
    servo = ctx.target
    layout = ctx.layout(servo)
    ignore = {"id", "firmware_version", "model_information"} | SET_AT_POWER_UP
    differ = [d for d in table_differences2(layout.defaults, ctx.before[servo], layout) if d.split()[0] not in ignore]
    if differ:
        return Note("differs: " + ", ".join(differ))
    return "all at defaults"


def check_alert(ctx: Context2) -> str:
    """[P2] "Status Packet > Error": bit 7 (Alert) is set "when there has been a problem in the Device"
    and Hardware Error Status(70) "can indicate the cause": each servo's Ping carries Alert exactly
    when its Hardware Error Status is non-zero."""
    figures = []
    for servo_id in ctx.ids:
        status = ctx.status(servo_id, Instruction2.PING)
        hardware = ctx.get(servo_id, "hardware_error_status")
        expect(status.alert == bool(hardware), f"ID {servo_id}: Alert {int(status.alert)} with Hardware Error Status {hardware:#04x}")
        figures.append(f"{servo_id}: {hardware:#04x}")
    return "Hardware Error Status " + ", ".join(figures) + "; Alert matches"


# -- destructive: all put back, but a failure halfway may leave the servo changed -------------------
#: How long a rebooting or reset servo may take before it answers a Ping again (the e-manual gives no time).
BOOT_WAIT_S = 2.0


def _wait_for(ctx: Context2, servo_id: int) -> float:
    """Ping ``servo_id`` until it answers (after Reboot or Factory Reset); the seconds it took."""
    start = time.perf_counter()
    packet = encode_instruction2(servo_id, Instruction2.PING)
    while time.perf_counter() - start < BOOT_WAIT_S:
        if ctx.link.transact(packet).status is not None:
            return time.perf_counter() - start
    raise Failed(f"ID {servo_id} silent for {BOOT_WAIT_S} s after the instruction")


def _write_back(ctx: Context2, servo_id: int, image: bytes) -> list[str]:
    """Write every register that differs from ``image`` back, EEPROM first (torque is off), Torque Enable last."""
    layout = ctx.layout(servo_id)
    now = ctx.table(servo_id)
    order = [e for e in layout.entries if e.access is Access.RW and e.name not in ("id", "baud_rate", "torque_enable")]
    order += [layout.by_name["torque_enable"]]
    refused = []
    for entry in order:  # every register tried: one unanswered write does not leave the rest unwritten
        value = entry.value_in(image)
        try:
            if entry.value_in(now) != value and ctx.put(servo_id, entry.name, value):
                refused.append(entry.name)
        except (Failed, OSError) as exc:
            refused.append(f"{entry.name} ({exc})")
    return refused


def check_reboot(ctx: Context2) -> str:
    """[P2] "Reboot": answered with an empty status (the example's), then the device restarts;
    [CT] "Area": the RAM area returns to its initial values, the EEPROM area is kept.  Torque
    Enable, LED and Registered Instruction read 0 afterwards; everything is written back."""
    servo = ctx.target
    before = ctx.table(servo)
    exact(ctx.status(servo, Instruction2.REBOOT), servo, ErrorNumber.NONE)
    took = _wait_for(ctx, servo)
    layout = ctx.layout(servo)
    after = ctx.table(servo)
    try:
        for name in ("torque_enable", "led", "registered_instruction"):
            expect(layout.by_name[name].value_in(after) == 0, f"{name} is {layout.by_name[name].value_in(after)} after Reboot")
        eeprom = [e for e in layout.entries if e.area is Area.EEPROM and e.value_in(before) != e.value_in(after)]
        expect(not eeprom, "Reboot changed the EEPROM area: " + ", ".join(e.name for e in eeprom))
    finally:
        refused = _write_back(ctx, servo, before)
    expect(not refused, "could not write back " + ", ".join(refused))
    return f"answered, back after {_ms(took)}; RAM at power-up values, EEPROM kept; written back"


def check_factory_reset(ctx: Context2) -> str:
    """[P2] "Factory Reset": option 0x02 "Reset all except ID and Baudrate", answered with an empty
    status; the table returns to its factory defaults ([CT] "Initial Value") but for ID and Baud Rate.
    Everything is written back (torque off first: the EEPROM area is locked while it is on)."""
    servo = ctx.target
    before = ctx.table(servo)
    layout = ctx.layout(servo)
    if ctx.torque_on(servo):
        ctx.must_put(servo, "torque_enable", 0)
    exact(ctx.status(servo, Instruction2.FACTORY_RESET, b"\x02"), servo, ErrorNumber.NONE)
    took = _wait_for(ctx, servo)
    try:
        after = ctx.table(servo)
        ignore = {"id", "baud_rate", "firmware_version", "model_information"} | SET_AT_POWER_UP
        differ = [d for d in table_differences2(layout.defaults, after, layout) if d.split()[0] not in ignore]
        expect(not differ, "after Factory Reset 0x02: " + ", ".join(differ))
        kept = layout.by_name["baud_rate"].value_in(after), layout.by_name["id"].value_in(after)
        expect(kept == (layout.by_name["baud_rate"].value_in(before), servo), f"baud and ID after the reset: {kept}")
    finally:
        refused = _write_back(ctx, servo, before)
    expect(not refused, "could not write back " + ", ".join(refused))
    return f"answered, back after {_ms(took)}; table at defaults but ID and baud; written back"


def check_id_change(ctx: Context2) -> str:
    """[CT] ID(7): 0 ~ 252, an EEPROM register.  After writing a free ID only the new ID answers; put back.
    Which ID the write's own status comes from the e-manual does not say; the figure shows it."""
    old, new = ctx.target, ctx.free_id()
    if ctx.torque_on(old):
        raise Skipped("torque is on: ID is in the EEPROM area")
    entry = ctx.entry(old, "id")
    # A servo already at the new ID (one not under test) would answer for the moved one and be written back to the
    # old ID with it: two servos renumbered, one ID for both.
    expect(ctx.silent(encode_instruction2(new, Instruction2.PING)), f"ID {new}, the free ID this check moves to, answers")
    response = ctx.transact(encode_instruction2(old, Instruction2.WRITE, _u16(entry.address) + bytes((new,))))
    try:
        ctx.status(new, Instruction2.PING)
        expect(ctx.silent(encode_instruction2(old, Instruction2.PING)), f"old ID {old} still answers")
    finally:
        ctx.transact(encode_instruction2(new, Instruction2.WRITE, _u16(entry.address) + bytes((old,))))
    ctx.status(old, Instruction2.PING)
    answered = "silent" if response.status is None else f"answered from ID {response.status.id}"
    return f"{old}->{new}->{old}; the write {answered}"


def check_baud_change(ctx: Context2) -> "str | Note":
    """[CT] Baud Rate(8): the register selects the bit rate (the model file's table of the page's
    values).  After writing another value the servo answers at that rate only; put back."""
    servo = ctx.target
    rates = ctx.models[servo].baud_rates_bps
    if not rates:
        raise Skipped(f"{ctx.models[servo].name}'s model file lists no baud rates")
    if ctx.torque_on(servo):
        raise Skipped("torque is on: Baud Rate is in the EEPROM area")
    original = ctx.get(servo, "baud_rate")
    host = ctx.link.baud
    value = next(v for v in (3, 1, 0) if v != original and v < len(rates))
    changed = False
    try:
        ctx.must_put(servo, "baud_rate", value)
        changed = True
        old_rate_silent = ctx.silent(encode_instruction2(servo, Instruction2.PING))
        ctx.link.baud = rates[value]
        rtt = statistics.median(ctx.ping_rtts(servo, 3))
    finally:
        if changed:
            ctx.link.baud = rates[value]
            ctx.put(servo, "baud_rate", original)
        ctx.link.baud = host
    ctx.status(servo, Instruction2.PING)
    figure = f"answers at {rates[value]} bps ({_ms(rtt)}); at {host} bps: {'silent' if old_rate_silent else 'still answered'}"
    return figure if old_rate_silent else Note(figure + " (the port carries no line rate?)")


# -- motion: the shaft turns (only with --motion) --------------------------------------------------
# Every motion check needs torque off to start (Operating Mode and Drive Mode are EEPROM registers),
# runs on the first ID of each model under test, writes its goal before turning torque on (a real
# servo boots with Goal Current at Current Limit and Goal PWM at PWM Limit), and puts back every
# register it or the mode change touched ([CT] Operating Mode(11) NOTE: a mode change resets the
# gains, "Profile Velocity(112) and Profile Acceleration(108) will be set to '0'", "Goal PWM(100) is
# reset to the value of PWM Limit(36)").  Speeds are a third of the data sheet's no-load speed at its
# lowest rated supply, so any supply the servo is rated for reaches them.

#: [CT] Operating Mode(11) values.
CURRENT_MODE, VELOCITY_MODE = 0, 1
#: [CT] Drive Mode(10) bit 2: "Time-based Profile" (0: Velocity-based Profile).
TIME_BASED_BIT = 0x04
#: [CT] Moving Status(123): bit 1 "Profile Ongoing", bits 4-5 the profile type (11: trapezoidal).
PROFILE_ONGOING, PROFILE_TYPE_MASK, TRAPEZOIDAL = 0x02, 0x30, 0x30
#: [CT] Goal/Present Velocity(104, 128) unit, rev/min; Present Position(132): 4096 pulses a turn.
RPM_PER_UNIT = 0.229
PULSES_PER_REV = 4096
#: The goal speeds, as a fraction of the data sheet's no-load speed at its lowest rated supply (ours).
SPEED_FRACTION = 0.3
#: The goal current, as a fraction of the data sheet's stall current at its lowest rated supply (ours): well
#: above what a free gearbox needs to turn, far below what heats the motor in half a second.
CURRENT_FRACTION = 0.15
#: How long a servo in Velocity Control Mode may take to come within tolerance of Goal Velocity (ours: the
#: e-manual gives no time; the default Velocity PI gains settle well within it), then how long it is measured.
VELOCITY_SETTLE_S, VELOCITY_WINDOW_S = 1.0, 0.25
#: Present Velocity within max(2 units, 10 %) of the goal: a real servo's reading jitters by a unit or two.
VELOCITY_TOLERANCE = 0.10
#: Each direction of the current-mode check, seconds; samples closer than this to a goal write are not judged
#: (the current loop and the sensor's filter settle).
CURRENT_PHASE_S, CURRENT_SETTLE_S = 0.3, 0.015
#: Present Current within max(20 mA, 15 %) of Goal Current while the current loop has voltage to spare.
CURRENT_TOLERANCE, CURRENT_TOLERANCE_MA = 0.15, 20.0
#: PWM at or above this fraction of Goal PWM: the drive is out of voltage (back-EMF), the current may fall short.
PWM_SATURATED = 0.9
#: The profile checks' travel, pulses, and the time-based profile's t3 and t1, ms.
PROFILE_TRAVEL_PULSES = 400
TIME_BASED_T3_MS, TIME_BASED_T1_MS = 500, 120
#: [CT] Profile Velocity(112): "Time-based Profiles are available from firmware V42" (not said of the X330).
TIME_BASED_FIRMWARE = 42
#: Velocity-based acceleration time t1 the check asks for (ours), ms.
VELOCITY_BASED_T1_MS = 150
#: Position Trajectory may be this late against the plan: [CT] "What is the Profile" NOTE (older pages):
#: "Dynamixel supports Jerk control ... actual travel time by the target trajectory of Profile could be
#: longer than t3", by how much not said (ours: 10 % of t3); early by no more than two control steps.
PROFILE_LATE_FRACTION, PROFILE_EARLY_MS = 0.10, 2.0
#: Position Trajectory within this many pulses of the plan (rounding of the register and of 64 vs 0.229 rpm).
PROFILE_PULSES_TOLERANCE = 2.0
#: After the profile ends, Present Position must come this close to the goal within the settle time (ours: the
#: In-Position window is "a predefined value" the e-manual does not give).
IN_POSITION_PULSES, POSITION_SETTLE_S = 20, 0.3

#: Registers the velocity-mode and profile checks need (the X series').
_X_MOTION_NEEDS = ("operating_mode", "drive_mode", "goal_velocity", "profile_velocity", "velocity_trajectory")
#: Registers a motion check or a mode change may alter, put back in this order (EEPROM first, torque last).
_MOTION_REGISTERS = ("operating_mode", "drive_mode", "velocity_i_gain", "velocity_p_gain", "position_d_gain",
                     "position_i_gain", "position_p_gain", "feedforward_2nd_gain", "feedforward_1st_gain",
                     "goal_pwm", "goal_current", "goal_velocity", "profile_acceleration", "profile_velocity",
                     "goal_position", "torque_enable")


@dataclass(frozen=True)
class _Sample:
    """One READ while the shaft turns: when it was sent and answered (s after the reference), the values."""

    sent_s: float
    answered_s: float
    values: dict[str, int]


def _one_per_model(ctx: Context2, wanted=lambda m: True) -> list[int]:
    """The first ID of each model under test that ``wanted`` accepts."""
    seen: dict[str, int] = {}
    for servo_id in ctx.ids:
        found = ctx.models[servo_id]
        if found.key not in seen and wanted(found):
            seen[found.key] = servo_id
    return list(seen.values())


def _x_series(ctx: Context2) -> list[int]:
    """:func:`_one_per_model` of the models with the X series' Operating Mode(11) and profiles (not the XL-320's
    classic table, whose Control Mode has no velocity mode or profile); skips the check if there are none."""
    servos = _one_per_model(ctx, lambda found: all(name in found.layout().by_name for name in _X_MOTION_NEEDS))
    if not servos:
        raise Skipped(f"no model under test has {', '.join(_X_MOTION_NEEDS)}: "
                      + ", ".join(sorted({m.name for m in ctx.models.values()})))
    return servos


def _lowest_rating(found: ServoModel):
    return min(found.physical.ratings, key=lambda r: r.voltage_v)


def _sampler(ctx: Context2, servo: int, names: tuple[str, ...]):
    """A function reading ``names`` (adjacent registers) in one READ, timed against a reference."""
    entries = [ctx.entry(servo, name) for name in names]
    start = min(e.address for e in entries)
    length = max(e.end for e in entries) - start

    def sample(reference_s: float) -> _Sample:
        sent = time.perf_counter()
        data = bytes(start) + ctx.read(servo, start, length)
        answered = time.perf_counter()
        return _Sample(sent - reference_s, answered - reference_s, {e.name: e.value_in(data) for e in entries})

    return sample


def _timed_put(ctx: Context2, servo: int, name: str, value: int) -> tuple[float, float]:
    """WRITE that must succeed; (sent, answered) perf_counter times: the servo took the value in between."""
    sent = time.perf_counter()
    ctx.must_put(servo, name, value)
    return sent, time.perf_counter()


def _in_motion(ctx: Context2, servos: list[int], setup: dict[str, int], body) -> list[str]:
    """Run ``body(servo)`` on each servo with the EEPROM ``setup`` written (torque off), then put everything back."""
    for servo in servos:
        if ctx.torque_on(servo):
            raise Skipped(f"ID {servo}: torque is on (the servo may be holding a load; the check changes EEPROM registers)")
    figures = []
    for servo in servos:
        names = [n for n in _MOTION_REGISTERS if n in ctx.layout(servo).by_name]
        saved = {name: ctx.get(servo, name) for name in names}
        refused: list[str] = []
        try:
            for name, value in setup.items():
                ctx.must_put(servo, name, value)
            figures.append(f"{servo} {ctx.models[servo].name}: " + body(servo))
        finally:
            try:
                ctx.put(servo, "torque_enable", 0)
            except (Failed, OSError) as exc:
                refused.append(f"torque_enable 0 ({exc})")
            for name in names:  # each tried, though one fails
                try:
                    if ctx.get(servo, name) != saved[name] and ctx.put(servo, name, saved[name]):
                        refused.append(name)
                except (Failed, OSError) as exc:
                    refused.append(f"{name} ({exc})")
        expect(not refused, f"ID {servo}: could not put back " + ", ".join(refused))
    return figures


def _velocity_body(ctx: Context2, servo: int) -> str:
    found = ctx.models[servo]
    rating = _lowest_rating(found)
    goal = round(SPEED_FRACTION * rating.no_load_speed_rpm / RPM_PER_UNIT)
    limit = ctx.get(servo, "velocity_limit")
    if 0 < limit < goal:
        goal = limit
    tolerance = max(2.0, VELOCITY_TOLERANCE * goal)
    sample = _sampler(ctx, servo, ("velocity_trajectory", "present_velocity", "present_position"))
    ctx.must_put(servo, "goal_velocity", 0)
    ctx.turn_torque_on(servo)
    start = time.perf_counter()
    _timed_put(ctx, servo, "goal_velocity", goal)
    close = 0
    reached_s = None
    while reached_s is None:
        row = sample(start)
        close = close + 1 if abs(row.values["present_velocity"] - goal) <= tolerance else 0
        if close >= 3:
            reached_s = row.answered_s
        elif row.sent_s > VELOCITY_SETTLE_S:
            raise Failed(f"ID {servo}: Present Velocity {row.values['present_velocity']} {_ms(row.sent_s)} after Goal "
                         f"Velocity {goal}, not within {tolerance:.0f}")
    window = [sample(start)]
    while window[-1].sent_s - window[0].answered_s < VELOCITY_WINDOW_S:
        window.append(sample(start))
    ctx.must_put(servo, "goal_velocity", 0)
    mean = statistics.fmean(r.values["present_velocity"] for r in window)
    trajectory = {r.values["velocity_trajectory"] for r in window}
    travelled = window[-1].values["present_position"] - window[0].values["present_position"]
    # The shaft's rate, bounded by when the first and last READs can have been served.
    low = travelled / (window[-1].answered_s - window[0].sent_s)
    high = travelled / (window[-1].sent_s - window[0].answered_s)
    goal_rate = goal * RPM_PER_UNIT * PULSES_PER_REV / 60.0
    figure = (f"goal {goal} ({goal * RPM_PER_UNIT:.1f} rpm, {SPEED_FRACTION:.0%} of {rating.no_load_speed_rpm:g} rpm at "
              f"{rating.voltage_v:g} V): within {tolerance:.0f} after {_ms(reached_s)}; Present Velocity {mean:.1f}, "
              f"Velocity Trajectory {sorted(trajectory)}, position {low:.0f}..{high:.0f} pulses/s (goal {goal_rate:.0f})")
    expect(trajectory == {goal}, f"ID {servo}: Velocity Trajectory not at Goal Velocity: {figure}")
    expect(abs(mean - goal) <= tolerance, f"ID {servo}: {figure}")
    expect(low * (1 - VELOCITY_TOLERANCE) <= goal_rate <= high * (1 + VELOCITY_TOLERANCE), f"ID {servo}: position rate: {figure}")
    return figure


def check_velocity_mode(ctx: Context2) -> str:
    """[CT] Goal Velocity(104): "used to set the target velocity when in the Velocity Control Mode", unit
    0.229 rpm; Velocity Trajectory(136): in Velocity Control Mode, "When the generated Profile reaches it's
    endpoint, [Velocity Trajectory(136)] becomes equal to [Goal Velocity(104)]"; Present Position(132)
    counts 4096 pulses a turn.  With Profile Acceleration 0 ("an infinite maximum acceleration") and a goal of
    a third of the data sheet's no-load speed, Present Velocity comes within max(2, 10 %) of the goal within
    1 s, Velocity Trajectory equals it, and over 0.25 s the position advances at that rate (within 10 %,
    bounded by when the READs were served)."""
    setup = {"operating_mode": VELOCITY_MODE, "profile_acceleration": 0}
    return "; ".join(_in_motion(ctx, _x_series(ctx), setup, lambda servo: _velocity_body(ctx, servo)))


def _has_current_mode(found: ServoModel) -> bool:
    entry = found.layout().by_name.get("operating_mode")
    return (entry is not None and "goal_current" in found.layout().by_name and found.physical.current_unit_ma is not None
            and (entry.allowed is None or CURRENT_MODE in entry.allowed))


def _current_body(ctx: Context2, servo: int) -> str:
    found = ctx.models[servo]
    rating = _lowest_rating(found)
    unit_ma = found.physical.current_unit_ma
    assert unit_ma is not None and rating.stall_current_a is not None
    goal = min(round(CURRENT_FRACTION * rating.stall_current_a * 1e3 / unit_ma), ctx.get(servo, "current_limit"))
    tolerance = max(CURRENT_TOLERANCE_MA / unit_ma, CURRENT_TOLERANCE * goal)
    pwm_limit = abs(ctx.get(servo, "goal_pwm"))
    sample = _sampler(ctx, servo, ("present_pwm", "present_current", "present_velocity", "present_position"))
    ctx.must_put(servo, "goal_current", 0)
    ctx.turn_torque_on(servo)
    figures = []
    for sign in (1, -1):
        target = sign * goal
        sent, _ = _timed_put(ctx, servo, "goal_current", target)
        rows = [sample(sent)]
        while rows[-1].sent_s < CURRENT_PHASE_S:
            rows.append(sample(sent))
        judged = [r for r in rows if r.sent_s >= CURRENT_SETTLE_S]
        tracking = saturated = 0
        for row in judged:
            current, pwm = row.values["present_current"], row.values["present_pwm"]
            if abs(current - target) <= tolerance:
                tracking += 1
            elif abs(pwm) >= PWM_SATURATED * pwm_limit and sign * current <= goal + tolerance:
                saturated += 1
            else:
                raise Failed(f"ID {servo}: Goal Current {target}: Present Current {current} at PWM {pwm} "
                             f"(Goal PWM {pwm_limit}) {_ms(row.sent_s)} after the write")
        half = [r for r in judged if r.sent_s >= CURRENT_PHASE_S / 2]
        moved = half[-1].values["present_position"] - half[0].values["present_position"]
        velocity = half[-1].values["present_velocity"]
        figure = (f"{target:+d} ({target * unit_ma:+.0f} mA): {tracking} of {len(judged)} READs within {tolerance:.0f}, "
                  f"{saturated} at the PWM limit; {moved:+d} pulses in the last {_ms(half[-1].sent_s - half[0].sent_s)}, "
                  f"Present Velocity {velocity:+d}")
        expect(tracking > 0, f"ID {servo}: Present Current never reached Goal Current: {figure}")
        expect(moved * sign > 0 and velocity * sign > 0, f"ID {servo}: the shaft did not turn the way of the current: {figure}")
        figures.append(figure)
    ctx.must_put(servo, "goal_current", 0)
    return "; ".join(figures)


def check_current_mode(ctx: Context2) -> str:
    """[CT] Goal Current(102): "In case of Torque Control Mode [Current Control Mode], Goal Current(102) can
    be used to set a desired current"; Present Current(126) reads it back in the model's unit (1 mA on the
    XL330/XC330, 2.69 mA on the XM430).  On a free shaft the servo accelerates until back-EMF takes the
    drive's voltage, then the current falls short of the goal at full PWM: so every READ (after 15 ms) has
    Present Current within max(20 mA, 15 %) of Goal Current, or Present PWM at 90 % of Goal PWM and the
    current no larger than the goal; at least one READ tracks, and the shaft turns the way of the current
    (+15 % of the stall current, then -15 %, 0.3 s each).  Models without Current Control Mode (the
    XL430-W250's Operating Mode takes 1, 3, 4, 16) are skipped."""
    servos = _one_per_model(ctx, _has_current_mode)
    if not servos:
        raise Skipped("no model under test has Current Control Mode: " + ", ".join(sorted({m.name for m in ctx.models.values()})))
    setup = {"operating_mode": CURRENT_MODE}
    return "; ".join(_in_motion(ctx, servos, setup, lambda servo: _current_body(ctx, servo)))


def _trapezoid_pulses(t_ms: float, t1_ms: float, t3_ms: float, travel: float) -> float:
    """Where the e-manual's trapezoid is ``t_ms`` after the goal: accelerate over t1, cruise, decelerate over t1, stop at t3."""
    if t_ms <= 0.0:
        return 0.0
    if t_ms >= t3_ms:
        return travel
    peak = travel / (t3_ms - t1_ms)  # per ms: the area under the trapezoid is the travel
    if t_ms < t1_ms:
        return peak * t_ms * t_ms / (2.0 * t1_ms)
    if t_ms <= t3_ms - t1_ms:
        return peak * (t_ms - t1_ms / 2.0)
    return travel - peak * (t3_ms - t_ms) ** 2 / (2.0 * t1_ms)


def _profile_body(ctx: Context2, servo: int, time_based: bool) -> str:
    found = ctx.models[servo]
    low, high = ctx.get(servo, "min_position_limit"), ctx.get(servo, "max_position_limit")
    if high - low < 2 * PROFILE_TRAVEL_PULSES:
        raise Skipped(f"ID {servo}: the position limits {low}..{high} leave no room for {PROFILE_TRAVEL_PULSES} pulses")
    if time_based:
        velocity, acceleration = TIME_BASED_T3_MS, TIME_BASED_T1_MS
        t1_ms, t3_ms = float(acceleration), float(velocity)
        peak_units = PROFILE_TRAVEL_PULSES / (t3_ms - t1_ms) * 60_000.0 / (RPM_PER_UNIT * PULSES_PER_REV)
    else:
        velocity = round(SPEED_FRACTION * _lowest_rating(found).no_load_speed_rpm / RPM_PER_UNIT)
        # A trapezoid, not a triangle, needs the deceleration to start after the acceleration ends: t2 >= t1,
        # i.e. 64 * travel / V >= t1.  Twice t1, so the cruise is as long as a ramp (a fast model, the
        # XL330-M077, would otherwise make a triangle).
        velocity = min(velocity, int(64 * PROFILE_TRAVEL_PULSES / (2 * VELOCITY_BASED_T1_MS)))
        acceleration = max(1, round(64 * velocity / VELOCITY_BASED_T1_MS))
        t1_ms = 64.0 * velocity / acceleration
        t3_ms = t1_ms + 64.0 * PROFILE_TRAVEL_PULSES / velocity
        peak_units = float(velocity)
    ctx.must_put(servo, "profile_velocity", velocity)
    ctx.must_put(servo, "profile_acceleration", acceleration)
    present = ctx.get(servo, "present_position")
    if not low <= present <= high:
        raise Skipped(f"ID {servo}: Present Position {present} is outside the position limits {low}..{high}")
    ctx.must_put(servo, "goal_position", present)
    ctx.turn_torque_on(servo)
    origin = ctx.get(servo, "present_position")  # "ΔPos, the distance ... between desired position and present position"
    sign = 1 if origin < (low + high) / 2 else -1
    goal = origin + sign * PROFILE_TRAVEL_PULSES
    sample = _sampler(ctx, servo, ("moving_status", "present_position", "velocity_trajectory", "position_trajectory"))
    sent, answered = _timed_put(ctx, servo, "goal_position", goal)
    late_ms = PROFILE_LATE_FRACTION * t3_ms
    rows = [sample(sent)]
    while rows[-1].values["moving_status"] & PROFILE_ONGOING or abs(rows[-1].values["present_position"] - goal) > IN_POSITION_PULSES:
        if rows[-1].sent_s * 1e3 > t3_ms + late_ms + POSITION_SETTLE_S * 1e3:
            break
        rows.append(sample(sent))
    lag_s = answered - sent  # a READ's times are from the write's sending; the servo took the goal up to lag_s later
    worst = 0.0
    for row in rows:
        earliest_ms, latest_ms = (row.sent_s - lag_s) * 1e3, row.answered_s * 1e3
        done = sign * (row.values["position_trajectory"] - origin)
        low_plan = _trapezoid_pulses(earliest_ms - late_ms, t1_ms, t3_ms, PROFILE_TRAVEL_PULSES) - PROFILE_PULSES_TOLERANCE
        high_plan = _trapezoid_pulses(latest_ms + PROFILE_EARLY_MS, t1_ms, t3_ms, PROFILE_TRAVEL_PULSES) + PROFILE_PULSES_TOLERANCE
        worst = max(worst, low_plan - done, done - high_plan)
        expect(low_plan <= done <= high_plan,
               f"ID {servo}: Position Trajectory {done:+.0f} pulses into the move {_ms(row.sent_s)} after the goal; the plan "
               f"(t1 {t1_ms:.0f} ms, t3 {t3_ms:.0f} ms) allows {low_plan:.0f}..{high_plan:.0f}")
    ongoing = [r for r in rows if r.values["moving_status"] & PROFILE_ONGOING]
    kinds = {r.values["moving_status"] & PROFILE_TYPE_MASK for r in ongoing}
    expect(kinds == {TRAPEZOIDAL}, f"ID {servo}: Moving Status profile type {sorted(hex(k) for k in kinds)} during the move, not 0x30")
    peak = max(sign * r.values["velocity_trajectory"] for r in rows)
    expect(abs(peak - peak_units) <= 2.0, f"ID {servo}: Velocity Trajectory peaks at {peak}, the plan's {peak_units:.1f}")
    finished = next((i for i, r in enumerate(rows) if not r.values["moving_status"] & PROFILE_ONGOING), None)
    expect(finished is not None and finished > 0, f"ID {servo}: Profile Ongoing never cleared ({_ms(rows[-1].sent_s)})")
    assert finished is not None
    end_low_ms = (rows[finished - 1].sent_s - lag_s) * 1e3
    end_high_ms = rows[finished].answered_s * 1e3
    expect(end_low_ms <= t3_ms + late_ms and end_high_ms >= t3_ms - PROFILE_EARLY_MS,
           f"ID {servo}: the profile ended {end_low_ms:.0f}..{end_high_ms:.0f} ms after the goal, t3 is {t3_ms:.0f} ms")
    settled = abs(rows[-1].values["present_position"] - goal)
    expect(settled <= IN_POSITION_PULSES, f"ID {servo}: Present Position {settled} pulses from the goal {_ms(rows[-1].sent_s)} after it")
    return (f"{PROFILE_TRAVEL_PULSES * sign:+d} pulses, Profile Velocity {velocity}, Acceleration {acceleration}: t1 {t1_ms:.0f} ms, "
            f"t3 {t3_ms:.0f} ms; ended {end_low_ms:.0f}..{end_high_ms:.0f} ms; Velocity Trajectory peak {peak} "
            f"(plan {peak_units:.1f}); Position Trajectory within the plan over {len(rows)} READs; "
            f"{settled} pulses from the goal after {_ms(rows[-1].sent_s)}")


def check_velocity_profile(ctx: Context2) -> str:
    """[CT] "What is the Profile": with a Velocity-based Profile (Drive Mode(10) bit 2 = 0), Profile Velocity(112)
    "sets the maximum velocity of the Profile" and Profile Acceleration(108) its acceleration; "Acceleration time
    (t1) ... t1 = 64 * {Profile Velocity(112) / Profile Acceleration(108)}" ms; the travel time (the older pages'
    step 7, https://emanual.robotis.com/docs/en/dxl/x/xm430-w210/#what-is-the-profile) "t3 = t1 + t2" with
    "t2 = 64 * ΔPos / Profile Velocity"; "The desired velocity trajectory and desired position trajectory from the
    Profile are stored at [Velocity Trajectory(136)] and [Position Trajectory(140)]"; Moving Status(123) bits
    4-5 = 11 for a trapezoid, bit 1 while the profile is in progress.  A 400-pulse move in Position Control
    Mode at a third of the no-load speed (at most 85, so the cruise lasts as long as a ramp), t1 ~150 ms: every Position Trajectory READ lies on the trapezoid
    (no more than 2 ms early, 10 % of t3 late: the e-manual's jerk control may lengthen it), Velocity
    Trajectory peaks at Profile Velocity, Profile Ongoing clears at t3, and the shaft comes within 20 pulses."""
    def body(servo: int) -> str:
        return _profile_body(ctx, servo, time_based=False)

    figures = []
    for servo in _x_series(ctx):
        drive = ctx.get(servo, "drive_mode") & ~TIME_BASED_BIT
        figures += _in_motion(ctx, [servo], {"operating_mode": POSITION_MODE, "drive_mode": drive}, body)
    return "; ".join(figures)


def check_time_profile(ctx: Context2) -> str:
    """[CT] Drive Mode(10) bit 2 = 1, Time-based Profile: "Profile Velocity(112) is used to set the time span of
    the Profile(t3), while Profile Acceleration(108) sets allowed accelerating time(t1) in millisecond[ms]" ("What
    is the Profile"; "Time-based Profiles are available from firmware V42" on the X430, always on the X330).
    A 400-pulse move with Profile Velocity 500 and Profile Acceleration 120: the trapezoid of t1 120 ms and
    t3 500 ms, judged as the velocity-based check judges its own."""
    def body(servo: int) -> str:
        return _profile_body(ctx, servo, time_based=True)

    figures = []
    for servo in _x_series(ctx):
        firmware = ctx.get(servo, "firmware_version")
        if "330" not in ctx.models[servo].name and firmware < TIME_BASED_FIRMWARE:
            raise Skipped(f"ID {servo}: firmware {firmware}; Time-based Profiles need V{TIME_BASED_FIRMWARE} on the X430")
        drive = ctx.get(servo, "drive_mode") | TIME_BASED_BIT
        figures += _in_motion(ctx, [servo], {"operating_mode": POSITION_MODE, "drive_mode": drive}, body)
    return "; ".join(figures)


CHECKS2: tuple[Check, ...] = (
    Check("ping", check_ping, reads_only=True),
    Check("absent ID is silent", check_absent_id, reads_only=True),
    Check("defaults", check_defaults, reads_only=True),
    Check("packet split into bytes", check_split_packet, reads_only=True),
    Check("resync after garbage", check_resync, reads_only=True),
    Check("byte stuffing", check_byte_stuffing),
    Check("bad CRC not executed", check_crc),
    Check("read 1, 2 and 4 bytes", check_read_sizes, reads_only=True),
    Check("write 1, 2 and 4 bytes", check_write_sizes),
    Check("data length error", check_data_length),
    Check("data range error", check_data_range),
    Check("access error", check_access),
    Check("read of an undefined address", check_read_undefined, reads_only=True),
    Check("EEPROM locked by torque", check_eeprom_locked),
    Check("data limit error", check_data_limit),
    Check("result fail", check_result_fail),
    Check("instruction error", check_instruction_error),
    Check("REG_WRITE + ACTION", check_reg_write_action),
    Check("SYNC_READ", check_sync_read, reads_only=True),
    Check("SYNC_WRITE", check_sync_write),
    Check("BULK_READ", check_bulk_read, reads_only=True),
    Check("BULK_WRITE", check_bulk_write),
    Check("broadcast PING", check_broadcast_ping, reads_only=True),
    Check("broadcast PING timing", check_broadcast_ping_timing, reads_only=True),
    Check("broadcast READ/WRITE", check_broadcast_read_write),
    Check("status return levels", check_status_return_level),
    Check("return delay", check_return_delay),
    Check("alert bit", check_alert, reads_only=True),
    Check("velocity mode", check_velocity_mode, motion=True),
    Check("current mode", check_current_mode, motion=True),
    Check("velocity-based profile", check_velocity_profile, motion=True),
    Check("time-based profile", check_time_profile, motion=True),
    Check("ID change", check_id_change, destructive=True),
    Check("baud change", check_baud_change, destructive=True),
    Check("REBOOT", check_reboot, destructive=True),
    Check("FACTORY_RESET keeping ID and baud", check_factory_reset, destructive=True),
)

