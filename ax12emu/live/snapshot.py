"""What the live view shows of a bus, read in one go on the thread that serves it.

Why it exists: the bus is not thread-safe, so the live view never reads a
register from its own thread; :func:`take` runs through the serving
thread's ``call`` between packets and returns plain data (numbers, strings,
lists) that the web page, the JSON snapshot and the terminal monitor share.

Every servo is shown the same way whatever it is (an AX-12A on Protocol 1.0, an X-series
servo on 2.0, both on one wire): its registers by the names its own table has (no raw
addresses, no list per model), and ``readings``, the quantities a user of either looks for
(position, goal, velocity, current or load, PWM, voltage, temperature) each with the register
it came from, the raw value and the value in its unit.  The units are data: those the model
file states (``[physical]``: ``resolution_deg`` for positions, ``current_unit_ma`` for
currents) and, per register name, those the e-manual gives every model with that register
(:data:`REGISTER_UNITS`).  A new model file is shown with no code here.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from ax12emu.faults.injection import ALARM_NAMES, HW_ERROR_NAMES
from ax12emu.protocol.packets import StatusError
from ax12emu.protocol.servo_models import ServoModel, model, model_names
from ax12emu.servo.classic import CURRENT_ZERO

from .buses import AnyBus, parts, protocol_name

__all__ = ["take", "range_counts", "REGISTERS", "ERROR_BITS", "HW_ERROR_BITS", "READINGS", "REGISTER_UNITS", "MODES", "model_of"]

#: Registers shown per servo, by control-table name, where the servo's table has them (the
#: page and the JSON snapshot use these names).  The union of the AX-12's and the X series'
#: (and the XL-320's) names for what a user watches; a table without one simply lacks it.
REGISTERS = (
    "model_number",
    "firmware_version",
    "baud_rate",
    "return_delay_time",
    "operating_mode",
    "control_mode",
    "drive_mode",
    "cw_angle_limit",
    "ccw_angle_limit",
    "multi_turn_offset",
    "resolution_divider",
    "min_position_limit",
    "max_position_limit",
    "velocity_limit",
    "current_limit",
    "pwm_limit",
    "temperature_limit",
    "shutdown",
    "torque_enable",
    "led",
    "hardware_error_status",
    "bus_watchdog",
    "goal_pwm",
    "goal_current",
    "goal_velocity",
    "goal_position",
    "moving_speed",
    "torque_limit",
    "moving",
    "moving_status",
    "alarm_led",
    "present_pwm",
    "present_current",
    "current",
    "present_load",
    "present_velocity",
    "present_speed",
    "present_position",
    "present_input_voltage",
    "present_voltage",
    "present_temperature",
)

#: Status-packet error bits by name, lowest bit first (Protocol 1.0: the alarms of every status packet).
ERROR_BITS: Mapping[str, int] = {bit.name.lower(): int(bit) for bit in StatusError if bit}
#: Hardware Error Status bits by name (Protocol 2.0, e-manual X series "Hardware Error Status(70)"),
#: without the aliases ``alarm`` accepts.
HW_ERROR_BITS: Mapping[str, int] = {name: bit for bit, name in sorted({bit: name for name, bit in reversed(list(HW_ERROR_NAMES.items()))}.items())}
#: What ``alarm`` takes per protocol (the page offers these), without aliases, highest bit first: Overload,
#: which every default Shutdown selects, before the errors an X-series Shutdown may not select.
ALARM_CHOICES: Mapping[float, tuple[str, ...]] = {
    1.0: tuple(name for _, name in sorted({bit: name for name, bit in reversed(list(ALARM_NAMES.items()))}.items(), reverse=True)),
    2.0: tuple(reversed(HW_ERROR_BITS)),
}


@dataclass(frozen=True)
class Unit:
    """A register's unit: the model file's field that gives its size per count where the file has it, else ``per_raw``."""

    unit: str
    per_raw: float | None = None
    #: "section.field" of the model file (``[physical]``, ``[classic]``) giving the units per count.
    model_field: str | None = None
    #: An unsigned register whose direction is a bit (bit 10, or the model file's ``[classic]`` ``direction_bit``)
    #: above the magnitude (AX-12, XL-320, MX series); signed registers (X series) need no such reading.
    direction_bit: bool = False
    #: In wheel mode where the wheel output is a share of the output (the AX-12A; ``[classic]``
    #: ``wheel_output = "pwm"``): this unit and its size per count instead.
    wheel: tuple[str, float] | None = None
    #: The raw value that reads zero (the MX series' Current(68): 2048).
    zero: int = 0


#: The position readings' scale: degrees per count from the model file's range and the table (:func:`_model_field`).
POSITION_SCALE = "position_range_deg/goal_span"

#: Units by register name.  Sources (ROBOTIS e-manual): AX-12A "Present Speed(38)": about 0.111 rpm in
#: joint mode, about 0.1 % of the output in wheel mode, bit 10 the direction; "Present Load(40)": 0.1 %
#: of the maximum torque, bit 10 the direction; "Present Voltage(42)": 10 times the volts; the XL-320
#: and the MX series the same, their speed units in their model files' ``[classic]`` (0.111, 0.114 rpm);
#: X series "Present Velocity(128)": 0.229 rpm, "Present Load(126)": 0.1 %, "Present PWM(124)": 0.113 %
#: ("PWM Limit(36)": 885 = 100 %), "Present Input Voltage(144)": 0.1 V, "Present Temperature(146)": 1 °C.
#: MX-64/MX-106 "Current(68)": "I = ( 4.5mA ) * (CURRENT - 2048)", the unit the model file's ``current_unit_ma``
#: and the zero the firmware model's (:data:`~ax12emu.servo.classic.CURRENT_ZERO`, so view and servo agree).
#: Positions and currents (1 mA, 2.69 mA) differ per model: each model file states them.  A position count is
#: the file's position range over the counts it spans (:func:`range_counts`: 300 deg over 0..1023 on the AX-12A,
#: 1023 at 300 deg; a whole turn of 4096 counts on the X and MX series, 0.088 deg a count), as the dial draws it;
#: the data sheets' rounded resolution (0.29 deg) put 1023 at 296.7 deg on a 300 deg dial.
REGISTER_UNITS: Mapping[str, Unit] = {
    "present_position": Unit("deg", model_field=POSITION_SCALE),
    "goal_position": Unit("deg", model_field=POSITION_SCALE),
    "present_velocity": Unit("rpm", 0.229),
    "goal_velocity": Unit("rpm", 0.229),
    "present_speed": Unit("rpm", 0.111, model_field="classic.speed_unit_rpm", direction_bit=True, wheel=("%", 0.1)),
    "moving_speed": Unit("rpm", 0.111, model_field="classic.speed_unit_rpm", direction_bit=True, wheel=("%", 0.1)),
    "present_current": Unit("mA", model_field="physical.current_unit_ma"),
    "goal_current": Unit("mA", model_field="physical.current_unit_ma"),
    "current": Unit("mA", model_field="physical.current_unit_ma", zero=CURRENT_ZERO),
    "present_load": Unit("%", 0.1, direction_bit=True),
    "present_pwm": Unit("%", 0.113),
    "goal_pwm": Unit("%", 0.113),
    "present_input_voltage": Unit("V", 0.1),
    "present_voltage": Unit("V", 0.1),
    "present_temperature": Unit("°C", 1.0),
}
#: The direction bit where the model file does not name one (e-manual AX-12A: "bit 10").
DIRECTION_BIT = 10

#: What the page and the monitor show for every servo: (reading, registers that give it, the first the table has).
READINGS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("position", ("present_position",)),
    ("goal", ("goal_position",)),
    ("velocity", ("present_velocity", "present_speed")),
    ("current", ("present_current", "current")),
    ("load", ("present_load",)),
    ("pwm", ("present_pwm",)),
    ("voltage", ("present_input_voltage", "present_voltage")),
    ("temperature", ("present_temperature",)),
)

#: Operating Mode(11) values (e-manual X series): (name, whether the goal is a position).  Whether the
#: position limits bound that goal is the table's own rule (the goal register's ``ranges_when``: unused in
#: Extended and Current-based Position Control Mode), so the view says what the servo checks.
#: Tables without it (AX-12, XL-320, MX series) are in joint or wheel mode (and the MX series in
#: multi-turn mode) as their angle limits and the model file's ``[classic]`` mode register say.
MODES: Mapping[str, Mapping[int, tuple[str, bool]]] = {
    "operating_mode": {
        0: ("current", False),
        1: ("velocity", False),
        3: ("position", True),
        4: ("extended position", True),
        5: ("current-based position", True),
        16: ("PWM", False),
    },
}
#: The position-limit register pairs, the first pair the table has.
LIMITS = (("cw_angle_limit", "ccw_angle_limit"), ("min_position_limit", "max_position_limit"))


@functools.cache
def _models_by_number(protocol: str) -> Mapping[int, ServoModel]:
    return {spec.model_number: spec for spec in map(model, model_names()) if protocol in spec.protocols}


def model_of(servo: Any, protocol: float) -> ServoModel | None:
    """The model file of a servo: a Protocol 2.0 servo carries it; a 1.0 servo is found by its Model Number."""
    spec = getattr(servo, "spec", None)
    if spec is not None:
        return spec
    return _models_by_number(protocol_name(protocol)).get(servo.table.get("model_number"))


#: A position range of this many degrees closes the circle: its last count is one short of the first again.
FULL_TURN_DEG = 360.0


def range_counts(range_deg: float, maximum: int) -> int:
    """How many counts the goal register's span ``0..maximum`` puts over ``range_deg``.

    A range short of a turn has two ends, 0 and ``maximum`` (e-manual AX-12A Goal Position: 0..1023 over
    300 deg); a whole turn has none: count ``maximum + 1`` is count 0 again (e-manual X series Goal Position:
    0.088 deg a count, 0..4095 a turn, extended -1,048,575..1,048,575 for -256..256 turns: 4096 a turn).
    """
    return maximum + 1 if range_deg >= FULL_TURN_DEG else maximum


def _model_field(spec: ServoModel | None, field: str, layout: Any = None) -> Any:
    """``"section.name"`` of a model file (``physical.current_unit_ma``), None where the file has no such number;
    :data:`POSITION_SCALE`: degrees per position count, the position range over the counts it spans."""
    if field == POSITION_SCALE:
        range_deg = getattr(getattr(spec, "physical", None), "position_range_deg", None)
        goal = layout.by_name.get("goal_position") if layout is not None else None
        return None if range_deg is None or goal is None or not goal.maximum else range_deg / range_counts(range_deg, goal.maximum)
    section, name = field.split(".")
    return getattr(getattr(spec, section, None), name, None)


@dataclass(frozen=True)
class _Reading:
    name: str
    register: str
    unit: str
    #: Units per count (None: unknown, the raw value alone is shown).
    per_raw: float | None
    #: The direction bit's value, 0 where the register is signed or has none.
    direction_mask: int
    #: (unit, per count) in wheel mode, where it differs.
    wheel: tuple[str, float] | None
    #: The raw value that reads zero.
    zero: int = 0
    #: A position the table holds as two's complement in multi-turn mode (``[classic]`` ``multi_turn_limit``:
    #: the MX series' Goal Position takes -28,672..28,672 there): the register's width in bits, else 0.
    multi_turn_bits: int = 0


@dataclass(frozen=True)
class _Plan:
    """What to read from one kind of servo (a layout and a model file), worked out once: every frame reads it."""

    registers: tuple[tuple[str, Any], ...]
    readings: tuple[_Reading, ...]
    #: Hardware Error Status or status-packet error bits by name, lowest first.
    error_bits: Mapping[str, int]


#: Plans by (id of the layout, model key); the layout is kept in the value so its id stays its own.
_PLANS: dict[tuple[int, str | None], tuple[Any, _Plan]] = {}


def _plan(layout: Any, spec: ServoModel | None) -> _Plan:
    key = (id(layout), spec.key if spec is not None else None)
    found = _PLANS.get(key)
    if found is not None and found[0] is layout:
        return found[1]
    by_name = layout.by_name
    classic = getattr(spec, "classic", None)
    readings = []
    for name, candidates in READINGS:
        register = next((r for r in candidates if r in by_name), None)
        if register is None:
            continue
        unit = REGISTER_UNITS.get(register)
        if unit is None:
            readings.append(_Reading(name, register, "", None, 0, None))
            continue
        from_file = _model_field(spec, unit.model_field, layout) if unit.model_field else None
        per_raw = from_file if from_file is not None else unit.per_raw
        direction = (classic.direction_bit if classic is not None else DIRECTION_BIT) if unit.direction_bit and not by_name[register].signed else None
        # Wheel-mode speed is a share of the output unless the model file says it is a speed (the MX series).
        wheel = unit.wheel if classic is None or classic.wheel_output == "pwm" else None
        multi_turn = unit.model_field == POSITION_SCALE and getattr(classic, "multi_turn_limit", None) is not None
        bits = 8 * by_name[register].size if multi_turn and not by_name[register].signed else 0
        readings.append(_Reading(name, register, unit.unit if per_raw is not None else "", per_raw, 0 if direction is None else 1 << direction,
                                 wheel, unit.zero, bits))
    if "hardware_error_status" in by_name:  # Protocol 2.0: the latched errors (the classic tables' own bits in their file)
        errors = dict(sorted(((n, b) for n, b in classic.errors), key=lambda item: item[1])) if classic is not None and classic.errors else HW_ERROR_BITS
    else:
        errors = ERROR_BITS
    plan = _Plan(tuple((name, by_name[name]) for name in REGISTERS if name in by_name), tuple(readings), errors)
    _PLANS[key] = (layout, plan)
    return plan


def _readings(plan: _Plan, registers: Mapping[str, int], mode: str) -> list[dict[str, Any]]:
    out = []
    wheel, multi_turn = mode == "wheel", mode == "multi-turn"
    # Multi-turn mode: "Present position = (Real Position / Resolution Divider) + Multi-turn Offset" (the MX
    # pages' Resolution Divider(22)), so a count is the divider's number of the file's position units.
    divider = max(1, registers.get("resolution_divider", 1)) if multi_turn else 1
    for reading in plan.readings:
        # "raw" is the count with its sign, as the plots draw it: a direction bit read as a sign, a zero offset
        # taken off (the register itself is in ``registers``).
        raw = registers[reading.register] - reading.zero
        mask = reading.direction_mask
        if mask:
            raw = -(raw & (mask - 1)) if raw & mask else raw & (mask - 1)
        bits = reading.multi_turn_bits
        if multi_turn and bits:
            raw = raw - (1 << bits) if raw & (1 << (bits - 1)) else raw
        unit, per_raw = reading.wheel if wheel and reading.wheel is not None else (reading.unit, reading.per_raw)
        if bits:
            per_raw = None if per_raw is None else per_raw * divider
        value = None if per_raw is None else round(raw * per_raw, 3)
        out.append({"name": reading.name, "register": reading.register, "raw": raw, "value": value, "unit": unit})
    return out


def _table_limits(layout: Any, row: Any) -> bool:
    """Whether the table's own limits (Goal Position's ``min_from``/``max_from``) bound the goal now: not where
    its ``ranges_when`` selects a range without them (as :meth:`~ax12emu.servo.table2.Table2.range_of`)."""
    goal = layout.by_name.get("goal_position")
    for mode in goal.mode_ranges if goal is not None else ():
        if layout.by_name[mode.register].value_in(row) in mode.values:
            return mode.limits
    return True


def _mode(registers: Mapping[str, int], spec: ServoModel | None, layout: Any, row: Any) -> tuple[str, bool]:
    """The mode's name and whether the position limits bound the goal in it."""
    for register, names in MODES.items():
        if register in registers:
            value = registers[register]
            name, position = names.get(value, (f"mode {value}", True))
            return name, position and _table_limits(layout, row)
    classic = getattr(spec, "classic", None)
    cw, ccw = LIMITS[0]
    limits = (registers.get(cw), registers.get(ccw))
    # e-manual AX-12A "CW/CCW Angle Limit": both 0 is wheel mode; the classic tables add a mode register
    # (XL-320 Control Mode) and the MX series multi-turn at both 4095 (their model files' [classic]).
    mode_register = classic.mode_register if classic is not None else None
    if limits == (0, 0) or (mode_register in registers and registers[mode_register] in classic.wheel_modes):  # type: ignore[union-attr]
        return "wheel", False
    if classic is not None and classic.multi_turn_limit is not None and limits == (classic.multi_turn_limit,) * 2:
        return "multi-turn", False
    return "joint", True


def _servo(protocol: float, servo: Any, slot: int, faults_active: Callable[[int], list[str]]) -> dict[str, Any]:
    table = servo.table
    by_name = table.layout.by_name
    spec = model_of(servo, protocol)
    plan = _plan(table.layout, spec)
    row = table.row
    registers = {name: entry.value_in(row) for name, entry in plan.registers}
    mode, limits_apply = _mode(registers, spec, table.layout, row)
    readings = _readings(plan, registers, mode)
    limits = next(([registers[lo], registers[hi]] for lo, hi in LIMITS if lo in registers and hi in registers), None)
    # Protocol 2.0: Hardware Error Status, latched, shown by the Alert bit; 1.0: the status packet's error bits.
    alarms = registers["hardware_error_status"] if "hardware_error_status" in registers else getattr(servo, "alarms", 0)
    goal = by_name.get("goal_position")
    physical = spec.physical if spec is not None else None
    return {
        "id": servo.id,
        "slot": slot,
        "protocol": protocol_name(protocol),
        "model": spec.name if spec is not None else f"model {registers.get('model_number')}",
        "profile": table.profile.name,
        "registers": registers,
        "readings": readings,
        "mode": mode,
        "limits": limits if limits_apply else None,
        # Dial: the goal register's span covers the model's position range (0..1023 over 300 deg, 0..4095 over 360),
        # ``counts`` of them over ``range_deg`` (:func:`range_counts`).
        "dial": None if goal is None or physical is None or physical.position_range_deg is None
        else {"max": goal.maximum, "range_deg": physical.position_range_deg,
              "counts": range_counts(physical.position_range_deg, goal.maximum)},
        # The rate the servo listens at now (its Baud Rate register by its own table of rates): a host still at the
        # old rate after a Baud Rate write hears nothing, and this says why.
        "baud_bps": getattr(servo, "baud_bps", None),
        "alarms": alarms,
        "alarm_names": [name for name, bit in plan.error_bits.items() if alarms & bit],
        "alarm_bits": list(plan.error_bits),
        "wheel_mode": not limits_apply,
        "faults": faults_active(slot),
    }


def _faults_figures(bus: AnyBus) -> dict[str, Any]:
    """The wire's reply faults (set on both protocols at once on a mixed wire) and what they did so far."""
    every = [sub.faults for _, sub in parts(bus) if sub.faults is not None]
    first = every[0] if every else None
    return {
        "drop": getattr(first, "drop", 0.0),
        "corrupt": getattr(first, "corrupt", 0.0),
        "delay": getattr(first, "delay", 0.0),
        "dropped": sum(getattr(f, "dropped", 0) for f in every),
        "corrupted": sum(getattr(f, "corrupted", 0) for f in every),
        "delayed": sum(getattr(f, "delayed", 0) for f in every),
    }


def take(bus: AnyBus, counters: Mapping[str, int] | None = None) -> dict[str, Any]:
    """All servos, the clock and the bus's counters, as plain data (call it on the serving thread)."""
    servos = []
    for protocol, sub in parts(bus):
        faults = sub.faults
        active: Callable[[int], list[str]] = faults.active if faults is not None and hasattr(faults, "active") else (lambda slot: [])
        servos.extend(_servo(protocol, servo, slot, active) for slot, servo in zip(sub.slots, sub.servos))
    clock = bus.clock
    return {
        "sim_time_s": clock.now_s(),
        "paused": bool(getattr(clock, "paused", False)) or not hasattr(clock, "time_scale"),
        "virtual_time": not hasattr(clock, "time_scale"),
        "protocols": [protocol_name(protocol) for protocol, _ in parts(bus)],
        # Per protocol: the alarm names the ``alarm`` control takes (the faults' names, per protocol).
        "alarm_choices": {protocol_name(p): list(ALARM_CHOICES[p]) for p, _ in parts(bus)},
        "servos": servos,
        "counters": dict(counters or {}),
        "faults": _faults_figures(bus),
    }
