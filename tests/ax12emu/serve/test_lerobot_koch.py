"""lerobot's Koch follower arm, call for call, through unmodified dynamixel-sdk against a served six-servo bus.

Why it exists: lerobot (huggingface/lerobot) drives the Koch arm with dynamixel-sdk's
Protocol 2.0 handler and checks what the servos answer (model numbers, errors,
sync reads).  Installing lerobot would pull torch, so this replays the calls its
``DynamixelMotorsBus`` makes, in the order its ``KochFollower`` makes them, with the
same SDK objects (``PortHandler``, ``PacketHandler(2.0)``, ``GroupSyncRead``,
``GroupSyncWrite``).  Every method below names the lerobot function it mirrors, in
huggingface/lerobot @ 7427f31801f944f5ec9ce53cda02862ce7d1638b:

* ``src/lerobot/robots/koch_follower/koch_follower.py``: the arm is IDs 1-2 XL430-W250
  (shoulder_pan, shoulder_lift) and IDs 3-6 XL330-M288 (elbow_flex, wrist_flex,
  wrist_roll, gripper); ``calibrate``, ``configure``, ``get_observation``,
  ``send_action``, ``disconnect``;
* ``src/lerobot/motors/dynamixel/dynamixel.py`` and ``src/lerobot/motors/motors_bus.py``:
  ``setup_motor``, ``_find_single_motor``, ``broadcast_ping``, ``_assert_motors_exist``,
  ``read_calibration``, ``write_calibration``, ``set_half_turn_homings``,
  ``configure_motors``, ``sync_read``/``sync_write``, ``_encode_sign``/``_decode_sign``,
  ``_normalize``/``_unnormalize``;
* ``src/lerobot/motors/dynamixel/tables.py``: addresses, model numbers 1060 and 1200,
  the X-series baud table (57,600 -> 1, 1,000,000 -> 3), two's complement registers.

Where lerobot waits for a person (moving the arm by hand during calibration), the
test says what it uses instead.  lerobot pins dynamixel-sdk >=3.7.31,<3.9.0; the
Protocol 2.0 handler calls used here are the same in the 4.x installed.
"""

from __future__ import annotations

import time

import pytest
from dynamixel_sdk import (
    COMM_SUCCESS,
    DXL_HIBYTE,
    DXL_HIWORD,
    DXL_LOBYTE,
    DXL_LOWORD,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
)
from emu_testkit import PatientPortHandler

#: The wall-clock tier (real time, margins meant for one test at a time; CI runs it on its own) takes the
#: scenario whose outcome hangs on how soon something happens: a teleoperation loop at 30 Hz for 2 s.
#: The handshake, the calibration file and the broadcast Pings time nothing (each reply, and each
#: broadcast Ping's replies, wait lerobot's 1,000 ms; see LerobotPort), so they run in parallel with
#: the other tests.
wallclock = pytest.mark.wallclock

#: How ``ax12emu serve`` is asked for the Koch follower's six servos.
KOCH_SERVE_ARGS = ("--servo", "1-2:xl430-w250,3-6:xl330-m288")

# -- lerobot's tables (tables.py) ----------------------------------------------------------
CONTROL_TABLE = {
    "ID": (7, 1), "Baud_Rate": (8, 1), "Return_Delay_Time": (9, 1), "Drive_Mode": (10, 1), "Operating_Mode": (11, 1),
    "Homing_Offset": (20, 4), "Max_Position_Limit": (48, 4), "Min_Position_Limit": (52, 4), "Torque_Enable": (64, 1),
    "Position_D_Gain": (80, 2), "Position_I_Gain": (82, 2), "Position_P_Gain": (84, 2), "Goal_Position": (116, 4),
    "Present_Position": (132, 4),
}
MODEL_NUMBER = {"xl430-w250": 1060, "xl330-m288": 1200}
BAUD_VALUE = {9_600: 0, 57_600: 1, 115_200: 2, 1_000_000: 3, 2_000_000: 4, 3_000_000: 5, 4_000_000: 6}
SIGNED = {"Homing_Offset", "Goal_Position", "Present_Position"}
RESOLUTION = 4096
DEFAULT_BAUD = 1_000_000
#: X-series factory Baud Rate(8) = 1: 57,600 bps (e-manual, XL430-W250 and XL330-M288 "Baud Rate(8)").
FACTORY_BAUD = 57_600
#: KochFollower.__init__: name -> (id, model, norm mode).
KOCH = {
    "shoulder_pan": (1, "xl430-w250", "m100_100"),
    "shoulder_lift": (2, "xl430-w250", "m100_100"),
    "elbow_flex": (3, "xl330-m288", "m100_100"),
    "wrist_flex": (4, "xl330-m288", "m100_100"),
    "wrist_roll": (5, "xl330-m288", "m100_100"),
    "gripper": (6, "xl330-m288", "0_100"),
}
#: How far from its goal a joint may stop (ticks): an XL330 at Position P Gain 400 within its friction band.
HOLD_BAND_TICKS = 16
#: dynamixel.py OperatingMode.
EXTENDED_POSITION, CURRENT_POSITION = 4, 5


#: lerobot's reply timeout (dynamixel.py DEFAULT_TIMEOUT_MS, set at connect).
LEROBOT_TIMEOUT_MS = 1000.0


class LerobotPort(PatientPortHandler):
    """dynamixel-sdk's PortHandler waiting lerobot's own timeout, 1000 ms, for each reply.

    At least that long for a reply to an instruction, rather than the SDK's few milliseconds: the tests
    run on a shared, loaded machine, where a reply can come late for reasons of the host.  At most that
    long for a broadcast Ping's replies: the SDK's Protocol 2.0 ``broadcastPing`` sets its window with
    ``setPacketTimeoutMillis((14 * 253 * tx_time_per_byte) + 3.0 * 253 + 16.0)``, the time all 253 IDs'
    replies would take at the line rate, and waits it out whoever answers (4.5 s at 9,600 bps, 1.4 s at
    57,600; dynamixel-sdk 4.1.0 protocol2_packet_handler.py).  The buses here hold one to six servos,
    whose replies come within milliseconds, so a second is the same test: a servo that answers is found
    and one that cannot hear the rate is silence.
    """

    def setPacketTimeout(self, packet_length):  # noqa: N802 (the SDK's name)
        super().setPacketTimeout(packet_length)
        self.packet_timeout = max(self.packet_timeout, LEROBOT_TIMEOUT_MS)

    def setPacketTimeoutMillis(self, msec):  # noqa: N802 (the SDK's name)
        super().setPacketTimeoutMillis(min(msec, LEROBOT_TIMEOUT_MS))


class LerobotError(Exception):
    """What lerobot raises (ConnectionError / RuntimeError) where the SDK reports a failure or a status error."""


class KochBus:
    """The calls ``DynamixelMotorsBus`` makes, on stock dynamixel-sdk objects."""

    def __init__(self, port: str) -> None:
        # dynamixel.py DynamixelMotorsBus.__init__ (the port only raises the SDK's reply timeout floor).
        self.port_handler = LerobotPort(port)
        self.packet_handler = PacketHandler(2.0)
        self.sync_reader = GroupSyncRead(self.port_handler, self.packet_handler, 0, 0)
        self.sync_writer = GroupSyncWrite(self.port_handler, self.packet_handler, 0, 0)
        self.calibration: dict[str, dict[str, int]] = {}
        self.sent: list[str] = []

    # -- motors_bus.py ---------------------------------------------------------------------
    def open(self) -> None:
        """``_connect(handshake=False)``: openPort (dynamixel-sdk opens at 1,000,000 bps)."""
        if not self.port_handler.openPort():
            raise LerobotError("Failed to open port")

    def connect(self) -> None:
        """``connect``: open, ``_handshake`` -> ``_assert_motors_exist`` (ping each ID, compare model numbers), ``set_timeout``."""
        self.open()
        found = {}
        for name, (motor_id, model, _) in KOCH.items():
            model_number = self.ping(motor_id)
            if model_number != MODEL_NUMBER[model]:
                raise LerobotError(f"{name} (ID {motor_id}): expected model {MODEL_NUMBER[model]}, found {model_number}")
            found[motor_id] = model_number
        self.port_handler.setPacketTimeoutMillis(LEROBOT_TIMEOUT_MS)

    def close(self) -> None:
        self.port_handler.closePort()

    def set_baudrate(self, baudrate: int) -> None:
        """``set_baudrate``."""
        if self.port_handler.getBaudRate() != baudrate:
            self.port_handler.setBaudRate(baudrate)
            if self.port_handler.getBaudRate() != baudrate:
                raise LerobotError("Failed to write bus baud rate.")

    def ping(self, motor_id: int) -> int | None:
        """``ping``: the model number, None on a failed or erroring exchange."""
        model_number, comm, error = self.packet_handler.ping(self.port_handler, motor_id)
        if comm != COMM_SUCCESS or error != 0:
            return None
        return model_number

    def broadcast_ping(self) -> dict[int, int] | None:
        """dynamixel.py ``broadcast_ping``: {id: model number}."""
        data_list, comm = self.packet_handler.broadcastPing(self.port_handler)
        if comm != COMM_SUCCESS:
            return None
        return {id_: data[0] for id_, data in data_list.items()}

    def find_single_motor(self, model: str) -> tuple[int, int]:
        """dynamixel.py ``_find_single_motor``: broadcast ping at each baud rate of the model's table."""
        for baudrate in BAUD_VALUE:
            self.set_baudrate(baudrate)
            id_model = self.broadcast_ping()
            if id_model:
                found_id, found_model = next(iter(id_model.items()))
                if found_model != MODEL_NUMBER[model]:
                    raise LerobotError(f"model {found_model} found, {MODEL_NUMBER[model]} expected")
                return baudrate, found_id
        raise LerobotError(f"model {model} was not found")

    def setup_motor(self, name: str, initial_baudrate: int | None = None, initial_id: int | None = None) -> None:
        """``setup_motor``: find it, torque off, write ID, write Baud Rate for 1 Mbps, follow at 1 Mbps."""
        motor_id, model, _ = KOCH[name]
        if initial_baudrate is None:
            initial_baudrate, initial_id = self.find_single_motor(model)
        assert initial_id is not None
        self.set_baudrate(initial_baudrate)
        self._write("Torque_Enable", initial_id, 0)
        self._write("ID", initial_id, motor_id)
        self._write("Baud_Rate", motor_id, BAUD_VALUE[DEFAULT_BAUD])
        self.set_baudrate(DEFAULT_BAUD)

    def _serialize(self, value: int, length: int) -> list[int]:
        """``_serialize_data`` + dynamixel.py ``_split_into_byte_chunks`` (negative values refused)."""
        if value < 0:
            raise ValueError(f"Negative values are not allowed: {value}")
        if length == 1:
            return [value]
        if length == 2:
            return [DXL_LOBYTE(value), DXL_HIBYTE(value)]
        return [DXL_LOBYTE(DXL_LOWORD(value)), DXL_HIBYTE(DXL_LOWORD(value)), DXL_LOBYTE(DXL_HIWORD(value)), DXL_HIBYTE(DXL_HIWORD(value))]

    @staticmethod
    def _encode(data_name: str, value: int) -> int:
        """dynamixel.py ``_encode_sign`` (encoding_utils.encode_twos_complement)."""
        n_bytes = CONTROL_TABLE[data_name][1]
        return value + (1 << (8 * n_bytes)) if data_name in SIGNED and value < 0 else value

    @staticmethod
    def _decode(data_name: str, value: int) -> int:
        """dynamixel.py ``_decode_sign``."""
        n_bytes = CONTROL_TABLE[data_name][1]
        return value - (1 << (8 * n_bytes)) if data_name in SIGNED and value & (1 << (8 * n_bytes - 1)) else value

    def _write(self, data_name: str, motor_id: int, value: int) -> None:
        """``_write``: writeTxRx, raise on a failed exchange or a status error."""
        addr, length = CONTROL_TABLE[data_name]
        comm, error = self.packet_handler.writeTxRx(self.port_handler, motor_id, addr, length, self._serialize(value, length))
        self.sent.append(f"write {data_name} id={motor_id} {value}")
        if comm != COMM_SUCCESS:
            raise LerobotError(f"write {data_name} id={motor_id}: {self.packet_handler.getTxRxResult(comm)}")
        if error != 0:
            raise LerobotError(f"write {data_name}={value} id={motor_id}: {self.packet_handler.getRxPacketError(error)}")

    def write(self, data_name: str, motor: str, value: float, *, normalize: bool = True) -> None:
        """``write``: unnormalize Goal/Present Position, encode the sign, ``_write``."""
        motor_id = KOCH[motor][0]
        int_value = int(value)
        if normalize and data_name in ("Goal_Position", "Present_Position"):
            int_value = self._unnormalize({motor: value})[motor]
        self._write(data_name, motor_id, self._encode(data_name, int_value))

    def read(self, data_name: str, motor: str) -> int:
        """``read`` -> ``_read``: read{1,2,4}ByteTxRx."""
        addr, length = CONTROL_TABLE[data_name]
        read_fn = {1: self.packet_handler.read1ByteTxRx, 2: self.packet_handler.read2ByteTxRx,
                   4: self.packet_handler.read4ByteTxRx}[length]
        value, comm, error = read_fn(self.port_handler, KOCH[motor][0], addr)
        if comm != COMM_SUCCESS or error != 0:
            raise LerobotError(f"read {data_name} {motor}: comm {comm}, error {error}")
        return self._decode(data_name, value)

    def sync_read(self, data_name: str, motors: list[str] | None = None, *, normalize: bool = True) -> dict[str, float]:
        """``sync_read`` -> ``_sync_read``: one GroupSyncRead, getData per ID without isAvailable, decode, normalize."""
        names = list(KOCH) if motors is None else motors
        addr, length = CONTROL_TABLE[data_name]
        self.sync_reader.clearParam()
        self.sync_reader.start_address = addr
        self.sync_reader.data_length = length
        for name in names:
            self.sync_reader.addParam(KOCH[name][0])
        comm = self.sync_reader.txRxPacket()
        if comm != COMM_SUCCESS:
            raise LerobotError(f"sync read {data_name}: {self.packet_handler.getTxRxResult(comm)}")
        raw = {name: self._decode(data_name, self.sync_reader.getData(KOCH[name][0], addr, length)) for name in names}
        if normalize and data_name in ("Goal_Position", "Present_Position"):
            return self._normalize(raw)
        return raw

    def sync_write(self, data_name: str, values: dict[str, float]) -> None:
        """``sync_write`` -> ``_sync_write``: unnormalize, encode the sign, one GroupSyncWrite txPacket."""
        addr, length = CONTROL_TABLE[data_name]
        ints = self._unnormalize(values) if data_name in ("Goal_Position", "Present_Position") else {m: int(v) for m, v in values.items()}
        self.sync_writer.clearParam()
        self.sync_writer.start_address = addr
        self.sync_writer.data_length = length
        for name, value in ints.items():
            self.sync_writer.addParam(KOCH[name][0], self._serialize(self._encode(data_name, value), length))
        comm = self.sync_writer.txPacket()
        if comm != COMM_SUCCESS:
            raise LerobotError(f"sync write {data_name}: {self.packet_handler.getTxRxResult(comm)}")

    def _normalize(self, raw: dict[str, int]) -> dict[str, float]:
        """``_normalize`` (no drive mode: dynamixel.py sets apply_drive_mode = False)."""
        out = {}
        for name, val in raw.items():
            lo, hi = self.calibration[name]["range_min"], self.calibration[name]["range_max"]
            bounded = min(hi, max(lo, val))
            if KOCH[name][2] == "m100_100":
                out[name] = ((bounded - lo) / (hi - lo)) * 200 - 100
            else:
                out[name] = ((bounded - lo) / (hi - lo)) * 100
        return out

    def _unnormalize(self, values: dict[str, float]) -> dict[str, int]:
        """``_unnormalize``."""
        out = {}
        for name, val in values.items():
            lo, hi = self.calibration[name]["range_min"], self.calibration[name]["range_max"]
            if KOCH[name][2] == "m100_100":
                bounded = min(100.0, max(-100.0, val))
                out[name] = int(((bounded + 100) / 200) * (hi - lo) + lo)
            else:
                bounded = min(100.0, max(0.0, val))
                out[name] = int((bounded / 100) * (hi - lo) + lo)
        return out

    # -- dynamixel.py ----------------------------------------------------------------------
    def disable_torque(self) -> None:
        for motor in KOCH:
            self.write("Torque_Enable", motor, 0)

    def enable_torque(self) -> None:
        for motor in KOCH:
            self.write("Torque_Enable", motor, 1)

    def read_calibration(self) -> dict[str, dict[str, int]]:
        """``read_calibration``: four sync reads."""
        offsets = self.sync_read("Homing_Offset", normalize=False)
        mins = self.sync_read("Min_Position_Limit", normalize=False)
        maxes = self.sync_read("Max_Position_Limit", normalize=False)
        drive_modes = self.sync_read("Drive_Mode", normalize=False)
        return {m: {"drive_mode": int(drive_modes[m]), "homing_offset": int(offsets[m]), "range_min": int(mins[m]),
                    "range_max": int(maxes[m])} for m in KOCH}

    def write_calibration(self, calibration: dict[str, dict[str, int]]) -> None:
        """``write_calibration``: three writes per motor, back to back."""
        for motor, cal in calibration.items():
            self.write("Homing_Offset", motor, cal["homing_offset"])
            self.write("Min_Position_Limit", motor, cal["range_min"])
            self.write("Max_Position_Limit", motor, cal["range_max"])
        self.calibration = calibration

    def set_half_turn_homings(self) -> dict[str, int]:
        """``set_half_turn_homings``: ``reset_calibration``, read positions, Homing Offset = 2047 - position."""
        for motor in KOCH:
            self.write("Homing_Offset", motor, 0, normalize=False)
            self.write("Min_Position_Limit", motor, 0, normalize=False)
            self.write("Max_Position_Limit", motor, RESOLUTION - 1, normalize=False)
        self.calibration = {}
        positions = self.sync_read("Present_Position", normalize=False)
        offsets = {motor: int((RESOLUTION - 1) / 2) - int(pos) for motor, pos in positions.items()}
        for motor, offset in offsets.items():
            self.write("Homing_Offset", motor, offset)
        return offsets

    def configure_motors(self) -> None:
        """``configure_motors``: Return Delay Time 0 on every motor."""
        for motor in KOCH:
            self.write("Return_Delay_Time", motor, 0)


def _served_koch(emulator):
    """The Koch follower's bus, each servo at its factory settings (57,600 bps), on a pty."""
    return emulator(*KOCH_SERVE_ARGS)


def test_setup_motors_finds_a_lone_servo_by_broadcast_ping_and_moves_it_to_1_mbps(emulator):
    """``lerobot-setup-motors``: one XL330-M288 at the factory ID 1 and 57,600 bps, found by broadcast ping
    (9,600 bps first: silence), given the gripper's ID 6 and 1 Mbps, then answers there."""
    served = emulator("--servo", "xl330-m288", "--ids", "1")
    bus = KochBus(served.port)
    bus.open()
    try:
        assert bus.find_single_motor("xl330-m288") == (FACTORY_BAUD, 1)
        bus.setup_motor("gripper", FACTORY_BAUD, 1)
        assert bus.port_handler.getBaudRate() == DEFAULT_BAUD
        assert bus.ping(6) == MODEL_NUMBER["xl330-m288"]
        assert bus.ping(1) is None
    finally:
        bus.close()


@wallclock
def test_koch_follower_session(emulator):
    """Setup, connect, calibrate, configure, a teleoperation loop and disconnect, as KochFollower runs them."""
    served = _served_koch(emulator)
    bus = KochBus(served.port)
    bus.open()
    try:
        # lerobot-setup-motors, each motor already on the bus at its ID: setup_motor(motor, 57600, id).
        for motor in reversed(KOCH):
            bus.setup_motor(motor, FACTORY_BAUD, KOCH[motor][0])
        bus.close()

        # KochFollower.connect -> bus.connect: handshake pings, model numbers 1060 x2, 1200 x4.
        bus.connect()
        # is_calibrated: read_calibration vs. no calibration file.
        factory = bus.read_calibration()
        assert all(c == {"drive_mode": 0, "homing_offset": 0, "range_min": 0, "range_max": 4095} for c in factory.values()), factory

        # KochFollower.calibrate: torque off, Operating Mode 4, half-turn homings.
        bus.disable_torque()
        for motor in KOCH:
            bus.write("Operating_Mode", motor, EXTENDED_POSITION)
        offsets = bus.set_half_turn_homings()
        # "Present_Position = Actual_Position + Homing_Offset": each joint now reads 2047.
        centred = bus.sync_read("Present_Position", normalize=False)
        assert all(abs(pos - 2047) <= 2 for pos in centred.values()), (offsets, centred)
        # record_ranges_of_motion streams sync reads while a person moves each joint; nobody moves it here,
        # so the ranges recorded are taken as 2047 +- 600 (shoulder_pan and wrist_roll: 0..4095, as lerobot sets).
        for _ in range(5):
            bus.sync_read("Present_Position", [m for m in KOCH if m not in ("shoulder_pan", "wrist_roll")], normalize=False)
        calibration = {
            m: {"drive_mode": 0, "homing_offset": offsets[m],
                "range_min": 0 if m in ("shoulder_pan", "wrist_roll") else 2047 - 600,
                "range_max": 4095 if m in ("shoulder_pan", "wrist_roll") else 2047 + 600}
            for m in KOCH
        }
        bus.write_calibration(calibration)
        assert bus.read_calibration() == calibration  # is_calibrated

        # KochFollower.configure, inside torque_disabled().
        bus.disable_torque()
        bus.configure_motors()
        for motor in KOCH:
            if motor != "gripper":
                bus.write("Operating_Mode", motor, EXTENDED_POSITION)
        bus.write("Operating_Mode", "gripper", CURRENT_POSITION)
        bus.write("Position_P_Gain", "elbow_flex", 1500)
        bus.write("Position_I_Gain", "elbow_flex", 0)
        bus.write("Position_D_Gain", "elbow_flex", 600)
        bus.enable_torque()
        assert bus.read("Return_Delay_Time", "elbow_flex") == 0
        assert bus.read("Position_P_Gain", "elbow_flex") == 1500

        # Teleoperation: get_observation (sync read) and send_action (sync write), 30 Hz for 2 s.
        start = bus.sync_read("Present_Position")
        goal = {m: (start[m] + 10.0 if m != "gripper" else 60.0) for m in KOCH}
        deadline = time.monotonic() + 2.0
        observed = start
        while time.monotonic() < deadline:
            observed = bus.sync_read("Present_Position")
            bus.sync_write("Goal_Position", goal)
            time.sleep(1 / 30)
        observed = bus.sync_read("Present_Position")
        goal_raw = bus._unnormalize(goal)
        for motor in KOCH:
            assert bus.read("Goal_Position", motor) == goal_raw[motor]
        moved = {m: round(observed[m] - start[m], 1) for m in KOCH}
        off_ticks = {m: abs(int(v) - goal_raw[m]) for m, v in bus._unnormalize(observed).items()}
        # Every joint, the current-based gripper too, went the 10 units (60 to 240 ticks) and stopped within
        # its hold band: a few ticks, and up to about 12 on an XL330 left at its default Position P Gain
        # (its position loop drives half the e-manual's reading, measured; the model file's [controller]),
        # where gear friction outlasts the drive near the goal, as on a real one.
        assert all(off_ticks[m] <= HOLD_BAND_TICKS for m in KOCH), (start, goal, observed, moved, off_ticks)
        assert all(abs(moved[m]) > 5.0 for m in KOCH if m != "gripper"), moved

        # KochFollower.disconnect -> bus.disconnect(disable_torque=True): clearPort, torque off, closePort.
        bus.port_handler.clearPort()
        bus.port_handler.is_using = False
        bus.disable_torque()
    finally:
        bus.close()
    check = KochBus(served.port)
    check.connect()
    try:
        assert all(check.read("Torque_Enable", m) == 0 for m in KOCH)
    finally:
        check.close()


def test_handshake_refuses_a_bus_of_the_wrong_models(emulator):
    """``_assert_motors_exist``: six XL430-W250s ping 1060 where the Koch arm's ID 3 must ping 1200."""
    served = emulator("--servo", "xl430-w250", "--ids", "1-6")
    bus = KochBus(served.port)
    bus.open()
    try:
        for motor in reversed(KOCH):
            bus.setup_motor(motor, FACTORY_BAUD, KOCH[motor][0])
        bus.close()
        with pytest.raises(LerobotError, match=r"elbow_flex \(ID 3\): expected model 1200, found 1060"):
            bus.connect()
    finally:
        bus.close()


def test_the_docs_recipe_connects_without_setup_and_takes_its_calibration_file(emulator):
    """docs/lerobot.md: ``--baud 1000000`` serves the arm where lerobot connects, and the calibration file the page
    shows, written as ``KochFollower.calibrate`` writes a file, puts each joint at the middle of its range."""
    import json
    import re
    from pathlib import Path

    page = (Path(__file__).resolve().parents[3] / "docs" / "lerobot.md").read_text(encoding="utf-8")
    serve_line = re.search(r"ax12emu serve (--servo \S+ --baud \d+)", page).group(1).split()
    file_text = re.search(r"```json\n(.*?)\n\s*```", page, re.DOTALL).group(1)
    calibration = {m: {k: v for k, v in c.items() if k != "id"} for m, c in json.loads(file_text).items()}
    assert {m: c["id"] for m, c in json.loads(file_text).items()} == {m: KOCH[m][0] for m in KOCH}

    served = emulator(*serve_line)
    bus = KochBus(served.port)
    bus.connect()
    try:
        assert bus.read_calibration() != calibration  # is_calibrated is False: lerobot offers to write the file
        bus.disable_torque()
        bus.write_calibration(calibration)
        assert bus.read_calibration() == calibration
        observed = bus.sync_read("Present_Position")
        assert all(abs(observed[m] - (50.0 if m == "gripper" else 0.0)) < 1.0 for m in KOCH), observed
    finally:
        bus.close()
