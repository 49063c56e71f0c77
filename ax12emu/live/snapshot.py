"""What the live view shows of a bus, read in one go on the thread that serves it.

Why it exists: the bus is not thread-safe, so the live view never reads a
register from its own thread; :func:`take` runs through the serving
thread's ``call`` between packets and returns plain data (numbers, strings,
lists) that the web page, the JSON snapshot and the terminal monitor share.
It reads registers by name from each servo's table (no raw addresses) and
costs tens of microseconds for a handful of servos, at the sampler's bounded
rate.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from ax12emu.bus import Bus
from ax12emu.protocol.packets import StatusError

__all__ = ["take", "REGISTERS", "ERROR_BITS", "MODEL_NAMES"]

#: Registers shown per servo, by control-table name (the page and the JSON snapshot use these names).
REGISTERS = (
    "present_position",
    "goal_position",
    "cw_angle_limit",
    "ccw_angle_limit",
    "moving_speed",
    "present_speed",
    "present_load",
    "present_voltage",
    "present_temperature",
    "temperature_limit",
    "torque_enable",
    "torque_limit",
    "led",
    "moving",
    "alarm_led",
    "shutdown",
    "model_number",
    "firmware_version",
    "return_delay_time",
)
#: Status-packet error bits by name, lowest bit first.
ERROR_BITS: Mapping[str, int] = {bit.name.lower(): int(bit) for bit in StatusError if bit}
#: Model Number register values to names.
MODEL_NAMES: Mapping[int, str] = {12: "AX-12"}


def _servo(bus: Bus, index: int, faults_active: Callable[[int], list[str]]) -> dict[str, Any]:
    servo = bus.servos[index]
    table = servo.table
    registers = {name: table.get(name) for name in REGISTERS}
    slot = bus.slots[index]
    return {
        "id": servo.id,
        "slot": slot,
        "protocol": "1.0",
        "model": MODEL_NAMES.get(registers["model_number"], f"model {registers['model_number']}"),
        "profile": table.profile.name,
        "registers": registers,
        "alarms": servo.alarms,
        "alarm_names": [name for name, bit in ERROR_BITS.items() if servo.alarms & bit],
        # Joint mode: both angle limits zero means wheel mode, where the dial shows no limits.
        "wheel_mode": registers["cw_angle_limit"] == 0 and registers["ccw_angle_limit"] == 0,
        "faults": faults_active(slot),
    }


def take(bus: Bus, counters: Mapping[str, int] | None = None) -> dict[str, Any]:
    """All servos, the clock and the bus's counters, as plain data (call it on the serving thread)."""
    faults = bus.faults
    faults_active: Callable[[int], list[str]] = faults.active if faults is not None and hasattr(faults, "active") else (lambda slot: [])
    clock = bus.clock
    return {
        "sim_time_s": clock.now_s(),
        "paused": bool(getattr(clock, "paused", False)) or not hasattr(clock, "time_scale"),
        "virtual_time": not hasattr(clock, "time_scale"),
        "servos": [_servo(bus, index, faults_active) for index in range(len(bus.servos))],
        "counters": dict(counters or {}),
        "faults": {
            "drop": getattr(faults, "drop", 0.0),
            "corrupt": getattr(faults, "corrupt", 0.0),
            "delay": getattr(faults, "delay", 0.0),
            "dropped": getattr(faults, "dropped", 0),
            "corrupted": getattr(faults, "corrupted", 0),
            "delayed": getattr(faults, "delayed", 0),
        },
    }
