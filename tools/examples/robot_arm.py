"""A small "user's robot code": a two-joint arm driven through dynamixel-sdk.

It is what the pytest suite beside it tests against virtual servos (the
``ax12_bus`` fixture of ax12emu's pytest plugin), including the unhappy
paths: lost replies, an overheating joint, a blocked joint.
"""

from __future__ import annotations

import time

import serial
from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

TORQUE_ENABLE, GOAL_POSITION, MOVING_SPEED, PRESENT_POSITION, MOVING = 24, 30, 32, 36, 46
ALARMS = {0x01: "input voltage", 0x04: "overheating", 0x20: "overload"}


#: How close "arrived" is, in position units: with its default compliance (margin 1, slope 32) an
#: AX-12 stops a few units short of or past the goal against its own static friction.
POSITION_TOLERANCE = 4

class UrlPortHandler(PortHandler):
    """dynamixel-sdk's PortHandler, opening pyserial URLs as well as device paths.

    The SDK opens its port with ``serial.Serial(name)``, which knows device paths only; where there is no
    pty (Windows) the ``ax12_bus`` fixture's port is an ``ax12emu://`` URL, which ``serial_for_url`` opens
    (as it opens ``socket://`` and a plain device path).
    """

    def setupPort(self, cflag_baud):
        if self.is_open:  # setBaudRate: change the line speed; reopening would end a private ax12emu:// bus
            self.ser.baudrate = self.baudrate
        else:
            self.ser = serial.serial_for_url(self.port_name, baudrate=self.baudrate, timeout=0)
            self.is_open = True
        self.ser.reset_input_buffer()
        self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
        return True


class CommError(RuntimeError):
    """A servo did not answer after every retry."""


class Arm:
    """Joints on one Protocol 1.0 bus."""

    def __init__(self, port_name: str, joint_ids: list[int], *, baud: int = 1_000_000, retries: int = 5) -> None:
        self.port = UrlPortHandler(port_name)
        self.packets = PacketHandler(1.0)
        self.joint_ids = joint_ids
        self.retries = retries
        if not self.port.openPort() or not self.port.setBaudRate(baud):
            raise CommError(f"cannot open {port_name}")

    def close(self) -> None:
        self.port.closePort()

    def _retry(self, call):
        """Run an SDK call until it communicates; return (value, error byte)."""
        for _ in range(self.retries):
            result = call()
            comm = result[-2]
            if comm == COMM_SUCCESS:
                return (result[0] if len(result) == 3 else None), result[-1]
            time.sleep(0.002)  # let a late reply drain before trying again
        raise CommError(f"no answer after {self.retries} tries ({self.packets.getTxRxResult(comm)})")

    def read_position(self, joint: int) -> int:
        value, _ = self._retry(lambda: self.packets.read2ByteTxRx(self.port, joint, PRESENT_POSITION))
        return value

    def enable(self, speed: int = 300) -> None:
        for joint in self.joint_ids:
            self._retry(lambda joint=joint: self.packets.write2ByteTxRx(self.port, joint, MOVING_SPEED, speed))
            self._retry(lambda joint=joint: self.packets.write1ByteTxRx(self.port, joint, TORQUE_ENABLE, 1))

    def move_to(self, joint: int, position: int, timeout_s: float = 3.0) -> bool:
        """Command a position and wait until the joint stops; False if it never gets there."""
        self._retry(lambda: self.packets.write2ByteTxRx(self.port, joint, GOAL_POSITION, position))
        deadline = time.monotonic() + timeout_s
        time.sleep(0.005)  # Moving is updated by the servo's control loop, not by the write itself
        still = 0
        while time.monotonic() < deadline:
            moving, _ = self._retry(lambda: self.packets.read1ByteTxRx(self.port, joint, MOVING))
            # Two still readings in a row: an AX-12 that overshoots its goal turns round at zero
            # speed, and a poll landing on that instant reads Moving 0 a few units past the goal.
            still = 0 if moving else still + 1
            if still == 2:
                return abs(self.read_position(joint) - position) <= POSITION_TOLERANCE
            time.sleep(0.01)
        return False

    def health(self) -> dict[int, list[str]]:
        """Alarms each joint reports in its status byte."""
        report = {}
        for joint in self.joint_ids:
            _, error = self._retry(lambda joint=joint: self.packets.read1ByteTxRx(self.port, joint, MOVING))
            report[joint] = [name for bit, name in ALARMS.items() if error & bit]
        return report
