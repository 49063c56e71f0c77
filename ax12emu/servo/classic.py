"""A classic control table (XL-320, MX series: the AX series' registers) read as the X-series firmware's commands.

Why it exists: the XL-320 and the MX series are PID servos like the X series, but their tables keep the
AX series' registers (Goal Position, Moving Speed, Torque Limit, P/I/D Gain, Present Load ...) in each
family's own units.  Rather than a second firmware model, this translates: the registers' values in,
:class:`~firmware_model.xseries.interface.XCommands` out, and the firmware's
:class:`~firmware_model.xseries.interface.XSensed` back into the classic registers.  The numbers are
the model file's ``[classic]`` section (:class:`ax12emu.protocol.servo_models.Classic`), so one map
serves every such family; nothing here names a model.  It knows no table class: a caller hands it
register values by name (a Protocol 2.0 :class:`~ax12emu.servo.table2.Table2` or a Protocol 1.0 table).

The translation (X units: e-manual, X series control tables: 4096 pulses per turn with 2048 the
middle, velocity 0.229 rpm, PWM 885 = 100 %, "Position PID Gain(80, 82, 84)": KPP = P/128,
KPI = I/65536, KPD = D/16, the constants including the sampling time: github ROBOTIS-GIT/emanual
_includes/en/dxl/control_table_position_pid_gain.md @ 01a2df191e6a2ec17e8265a88bda43659f384e41; the
classic tables' "Kp : P Gain / 8, Ki : I Gain * 1,000 / 2,048, Kd : D Gain * 4 / 1,000":
_includes/en/dxl/control_table_mx_pid.md @ 0a1cc01d4c883a2a1276cee8f92ecb0e2abd504b, shared by the
MX and XL-320 pages):

* Goal/Present Position: ``position_units`` over ``position_span_deg`` with ``position_centre`` at
  the middle, to pulses with 2048 at the middle (XL-320: 1024 units over 300 deg, 3.33 pulses a unit);
  CW/CCW Angle Limit become Min/Max Position Limit, which the firmware holds the goal inside.
* Joint mode is Position Control Mode; Moving Speed (``speed_unit_rpm``) is Profile Velocity
  (0.229 rpm, at least 1 so a slow speed is not read as "no limit"), and Moving Speed 0, "the maximum rpm
  of the motor is used without controlling the speed. ... However, the rpm will not exceed the No Load
  Speed" (e-manual), a profile at the data sheet's no-load speed (``no_load_speed_rpm``): Moving, "Goal
  position command execution is in progress", is then the firmware's running profile from the first step.
* Wheel mode (``mode_register`` in ``wheel_modes``, or both angle limits 0) is PWM Control Mode where
  Moving Speed is a share of the output (``wheel_output = "pwm"``: the AX and XL-320 pages, "only the
  output control is possible, not speed"), Velocity Control Mode where it is a speed ("velocity");
  bit ``direction_bit`` set turns clockwise (negative in X terms).
* Torque Limit (``output_full_scale`` = 100 %) is Goal PWM in joint mode and PWM Limit in wheel mode:
  a PWM bound is a torque bound at rest, where the winding's current is duty x V / R.
* P/I/D Gain: the e-manual's controller gains (``p_gain_factor`` ..., e.g. the MX/XL-320 Kp = P/8,
  Ki = I x 1000/2048, Kd = D x 4/1000) act on the error in the table's position units and give an
  output in ``output_full_scale`` units; the X firmware's act on pulses and give PWM units (885).  So
  the X register is the gain x 128 (65536, 16) x (885 / output_full_scale) / (pulses per unit), with
  Ki read as per second and Kd as seconds (the e-manual's 1,000 and 1/1,000 are its 1 ms sample; ours
  is the firmware's ``step_s``): ours, the e-manual gives the classic controller's units nowhere.
* Present Speed and Present Load: magnitude with the direction bit (set: clockwise); Present Speed in
  ``speed_unit_rpm``, or in wheel mode with ``wheel_output = "pwm"`` the output share ("the unit is
  about 0.1%", e-manual XL-320 "Present Speed(39)"); Present Load the output (Present PWM) as a share of
  ``output_full_scale``: "Present load is an inferred value based on the internal output value"
  (control_table_present_load.md, the MX and XL-320 pages), as the AX-12A's, not the winding's current
  (a shaft pushed round with the output at 0 reads no load).
* Shutdown and Hardware Error Status: each family's bits (``errors``) for the firmware's protections.

What only the MX series has (e-manual, MX-28/64/106 Protocol 1.0 pages and their shared texts in
github ROBOTIS-GIT/emanual _includes/en/dxl/):

* multi-turn mode, both angle limits at ``multi_turn_limit`` ("Condition that Both CW and CCW are
  4095", control_table_mx_angle_limit.md): Extended Position Control Mode, Goal Position signed within
  +-``multi_turn_goal_limit``; "Present position = (Real Position / Resolution Divider) + Multi-turn
  Offset" (control_table_resolution_divider.md), "only available in multi-turn mode": the offset goes
  to the firmware as Homing Offset (times the divider, in its pulses) and the divider divides what it
  reports, so the goal is the register value times the divider;
* Goal Acceleration (``acceleration_unit_deg_s2``: "the unit is approximately 8.583 deg / sec^2 ...
  When it is set to 0, there is no control over acceleration", control_table_goal_acceleration.md) is
  Profile Acceleration (214.577 rev/min^2), planned with Moving Speed's profile speed (the no-load speed
  for Moving Speed 0, as above: the X series plans no acceleration without a Profile Velocity);
* Torque Control Mode Enable(70) = 1 (MX-64/106: "DYNAMIXEL is controlled by the Goal Torque value ...
  behaves as if it is in the wheel mode") is Current Control Mode, Goal Torque(71) the goal current in
  the model's current unit with the direction bit ("the unit is 4.5mA"), bounded by Torque Limit's share
  of the stall current ("Goal Torque cannot be bigger than Torque Limit"); Current(68) reads
  ``CURRENT_ZERO`` + the current in that unit ("I = (4.5mA) * (CURRENT - 2048)").
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from functools import reduce
from operator import or_

from ax12emu.protocol.servo_models import Classic, ServoModel
from firmware_model.xseries.firmware import PULSES_PER_REV, PWM_FULL_SCALE
from firmware_model.xseries.interface import (
    HW_ERROR_INPUT_VOLTAGE,
    HW_ERROR_OVERHEATING,
    HW_ERROR_OVERLOAD,
    OperatingMode,
    XCommands,
    XSensed,
)
from firmware_model.xseries.profile import ACCEL_UNIT_PULSES_S2

__all__ = ["ClassicMap", "COMMAND_REGISTERS", "SENSED_REGISTERS", "GOAL_REGISTERS", "X_CENTRE_PULSES",
           "X_VELOCITY_UNIT_RPM", "WHEEL_VELOCITY_GAINS"]

#: The X series' Present Position at the middle of the turn (the horn straight ahead).
X_CENTRE_PULSES = PULSES_PER_REV // 2
#: X series Goal/Present Velocity and Profile Velocity unit (e-manual: 0.229 rpm).
X_VELOCITY_UNIT_RPM = 0.229
#: X series Position P/I/D Gain divisors (e-manual "Position PID Gain(80, 82, 84)": KPP = P/128, KPI = I/65536, KPD = D/16).
X_POSITION_GAIN_DIVISORS = {"p": 128.0, "i": 65536.0, "d": 16.0}
#: Velocity P/I Gain for a wheel mode that runs Velocity Control Mode (the MX series': ``wheel_output = "velocity"``):
#: the same servo's under its Protocol 2.0 firmware (MX-106(2.0) page, "Velocity I Gain(76)" 1,920, "Velocity P
#: Gain(78)" 100, as the XM430's); the classic tables have no such gains.  (The XL430's 1,000 left an MX-106 5 %
#: short of a new wheel speed a second after it was written.)
WHEEL_VELOCITY_GAINS = (100, 1920)
#: The firmware's protection bits by the names the model files use (``[classic].errors``).
X_ERROR_BITS = {"input_voltage": HW_ERROR_INPUT_VOLTAGE, "overheating": HW_ERROR_OVERHEATING, "overload": HW_ERROR_OVERLOAD}

#: Classic registers that steer the servo (each read where the table has it).
COMMAND_REGISTERS = ("torque_enable", "goal_position", "moving_speed", "torque_limit", "cw_angle_limit", "ccw_angle_limit",
                     "p_gain", "i_gain", "d_gain", "temperature_limit", "min_voltage_limit", "max_voltage_limit", "shutdown",
                     "multi_turn_offset", "resolution_divider", "goal_acceleration", "torque_ctrl_mode_enable", "goal_torque",
                     "drive_mode")
#: Classic registers the firmware's readings go to (each written where the table has it).
SENSED_REGISTERS = ("present_position", "present_speed", "present_load", "present_voltage", "present_temperature",
                    "moving", "hardware_error_status", "torque_enable", "current")
#: Classic registers whose write starts a new move (a new profile in the firmware), besides the X series' Goal registers.
GOAL_REGISTERS = frozenset({"goal_position", "moving_speed", "goal_acceleration", "goal_torque", "torque_ctrl_mode_enable"})
#: Current(68) at zero current (MX-64/106: "At an idle state without current flow, this value is 2,048").
CURRENT_ZERO = 2048
#: X series Profile Acceleration unit in deg/s^2 (214.577 rev/min^2).
X_ACCELERATION_UNIT_DEG_S2 = ACCEL_UNIT_PULSES_S2 * 360.0 / PULSES_PER_REV

_WHEEL_X_MODES = (OperatingMode.PWM, OperatingMode.VELOCITY)


def _decode_signed(raw: int, bit: int) -> int:
    """A magnitude with a direction bit (set: clockwise) as a signed value (clockwise negative, as on the X series)."""
    magnitude = raw & ((1 << bit) - 1)
    return -magnitude if raw & (1 << bit) else magnitude


def _encode_signed(value: float, bit: int, full_scale: int) -> int:
    """A signed value as magnitude (at most ``full_scale``) with the direction bit set when clockwise (negative)."""
    magnitude = min(int(round(abs(value))), full_scale)
    return magnitude | (1 << bit) if value < 0 and magnitude else magnitude


class ClassicMap:
    """The translation between one classic table's registers and the X-series firmware's commands and readings."""

    def __init__(self, units: Classic, registers: Iterable[str], *,
                 step_s: float = 0.001, name: str = "", no_load_speed_rpm: float = 0.0,
                 current_limit_units: float = 0.0) -> None:
        """``registers``: the table's register names; ``step_s``: the firmware's control step;
        ``no_load_speed_rpm``: the profile speed of Moving Speed 0 (0: the X series' step); ``current_limit_units``:
        the current (in the model's current unit) at Torque Limit 100 %, for Goal Torque."""
        self.units = units
        self.no_load_speed_rpm = no_load_speed_rpm
        self.current_limit_units = current_limit_units
        names = set(registers)
        self.name = name
        #: The classic registers :meth:`commands` reads and :meth:`sensed_to_registers` writes, those the table has.
        self.command_registers = tuple(n for n in COMMAND_REGISTERS if n in names)
        if units.mode_register is not None and units.mode_register not in self.command_registers:
            self.command_registers += (units.mode_register,)
        self.sensed_registers = tuple(n for n in SENSED_REGISTERS if n in names)
        self.goal_registers = frozenset(n for n in GOAL_REGISTERS if n in names)
        missing = [n for n in ("goal_position", "torque_enable", "present_position") if n not in names]
        if missing:
            raise ValueError(f"{name or 'a classic table'}: the classic map needs {', '.join(missing)} in the table")
        #: X pulses per classic position unit.
        self.pulses_per_unit = PULSES_PER_REV / 360.0 * units.position_span_deg / units.position_units
        self.step_s = step_s
        output = PWM_FULL_SCALE / units.output_full_scale
        per_sample = {"p": units.p_gain_factor,
                      "i": None if units.i_gain_factor_s is None else units.i_gain_factor_s * step_s,
                      "d": None if units.d_gain_factor_s is None else units.d_gain_factor_s / step_s}
        for key in per_sample:
            if f"{key}_gain" in names and per_sample[key] is None:
                raise ValueError(f"{name or 'a classic table'}: {key}_gain needs [classic] {key}_gain_factor"
                                 f"{'' if key == 'p' else '_s'} (the e-manual's conversion)")
        #: X Position P/I/D Gain register units per classic gain register unit.
        self.x_gain_per_register = {key: (factor or 0.0) * X_POSITION_GAIN_DIVISORS[key] * output / self.pulses_per_unit
                                    for key, factor in per_sample.items()}
        self._x_bits = tuple((classic_bit, X_ERROR_BITS[name_]) for name_, classic_bit in units.errors)

    @classmethod
    def from_model(cls, spec: ServoModel, *, step_s: float = 0.001) -> ClassicMap:
        """The map of a model file with a ``[classic]`` section; ``ValueError`` naming the file when it has none."""
        if spec.classic is None:
            raise ValueError(f"{spec.path or spec.name}: no [classic] section (the table's units for the X-series firmware)")
        units = spec.classic
        physical = spec.physical
        rating = physical.rating_at()
        current_limit = 0.0
        if physical.current_unit_ma is not None and rating.stall_current_a is not None:
            current_limit = rating.stall_current_a / (physical.current_unit_ma * 1e-3)
        return cls(units, (entry.name for entry in spec.entries), step_s=step_s,
                   name=spec.path or spec.name, no_load_speed_rpm=rating.no_load_speed_rpm,
                   current_limit_units=current_limit)

    # -- units -----------------------------------------------------------------------------
    def position_to_pulses(self, value: float) -> float:
        """A classic position (table units) as X pulses."""
        return X_CENTRE_PULSES + (value - self.units.position_centre) * self.pulses_per_unit

    def pulses_to_position(self, pulses: float) -> int:
        """X pulses (any turn) as the classic position within the table's range (the dead zone reads its nearer end)."""
        units = self.units
        within_turn = pulses % PULSES_PER_REV
        value = int(round(units.position_centre + (within_turn - X_CENTRE_PULSES) / self.pulses_per_unit))
        return min(max(value, 0), units.position_units - 1)

    def speed_to_x_velocity(self, units_value: float) -> float:
        """A classic speed (``speed_unit_rpm`` units) in X velocity units (0.229 rpm)."""
        return units_value * self.units.speed_unit_rpm / X_VELOCITY_UNIT_RPM

    def is_wheel(self, values: Mapping[str, int]) -> bool:
        """Whether the registers select wheel mode (the mode register, or both angle limits 0)."""
        units = self.units
        if units.mode_register is not None:
            return values.get(units.mode_register) in units.wheel_modes
        return values.get("cw_angle_limit", 1) == 0 and values.get("ccw_angle_limit", 1) == 0

    def is_multi_turn(self, values: Mapping[str, int]) -> bool:
        """Whether the registers select multi-turn mode (both angle limits at ``multi_turn_limit``)."""
        limit = self.units.multi_turn_limit
        return limit is not None and values.get("cw_angle_limit") == limit and values.get("ccw_angle_limit") == limit

    def divider(self, values: Mapping[str, int]) -> int:
        """Resolution Divider as it applies (multi-turn mode only; 1 otherwise)."""
        return max(1, values.get("resolution_divider", 1)) if self.is_multi_turn(values) else 1

    def errors_to_classic(self, hardware_error_status: int) -> int:
        """The firmware's Hardware Error Status bits as the family's own error bits (``errors``)."""
        return reduce(or_, (classic_bit for classic_bit, x_bit in self._x_bits if hardware_error_status & x_bit), 0)

    def errors_to_x(self, classic_bits: int) -> int:
        """The family's own error bits (Shutdown, the status packet's alarms) as Hardware Error Status bits."""
        return reduce(or_, (x_bit for classic_bit, x_bit in self._x_bits if classic_bits & classic_bit), 0)

    # -- registers -> firmware ---------------------------------------------------------------
    def commands(self, values: Mapping[str, int]) -> XCommands:
        """The X commands the classic registers ``values`` (name -> value, as the table holds them) mean."""
        units = self.units
        full = units.output_full_scale
        torque_pwm = int(round(min(values.get("torque_limit", full), full) * PWM_FULL_SCALE / full))
        cmd = XCommands(torque_enable=values.get("torque_enable", 0), shutdown=self.errors_to_x(values.get("shutdown", 0)))
        for name in ("temperature_limit", "min_voltage_limit", "max_voltage_limit"):
            if name in values:
                setattr(cmd, name, values[name])  # same units on both (deg C, 0.1 V)
        speed_raw = values.get("moving_speed", 0)
        if values.get("torque_ctrl_mode_enable", 0) and "goal_torque" in values:
            cmd.operating_mode = OperatingMode.CURRENT
            cmd.goal_pwm = cmd.pwm_limit
            cmd.current_limit = int(round(min(values.get("torque_limit", full), full) / full * self.current_limit_units))
            cmd.goal_current = _decode_signed(values["goal_torque"], units.direction_bit)
            return cmd
        if self.is_wheel(values):
            signed = _decode_signed(speed_raw, units.direction_bit)
            cmd.pwm_limit = torque_pwm
            if units.wheel_output == "pwm":
                cmd.operating_mode = OperatingMode.PWM
                cmd.goal_pwm = int(round(max(min(signed, full), -full) * PWM_FULL_SCALE / full))
            else:
                cmd.operating_mode = OperatingMode.VELOCITY
                cmd.goal_pwm = torque_pwm
                cmd.goal_velocity = int(round(self.speed_to_x_velocity(signed)))
                cmd.velocity_p_gain, cmd.velocity_i_gain = WHEEL_VELOCITY_GAINS
                cmd.profile_acceleration = self._profile_acceleration(values)
            return cmd
        cmd.operating_mode = OperatingMode.POSITION
        # Drive Mode(10) bit 0 (the MX-106's): "rotational direction is inverted. Thus, Goal Position, Present Position
        # will have a inverted direction"; "Normal/Reverse Mode is activated under Joint Mode and Multi-turn Mode"
        # (control_table_drivemode.md), so not in wheel or torque control mode (returned above).  Bit 1 (dual joint
        # slave) needs a second servo on a sync cable: not modelled.
        cmd.drive_mode = values.get("drive_mode", 0) & 0x01
        cmd.goal_pwm = torque_pwm
        cmd.goal_position = int(round(self.position_to_pulses(values["goal_position"])))
        cmd.min_position_limit = int(round(self.position_to_pulses(values.get("cw_angle_limit", 0))))
        cmd.max_position_limit = int(round(self.position_to_pulses(values.get("ccw_angle_limit", units.position_units - 1))))
        speed = speed_raw & ((1 << units.direction_bit) - 1)
        # Any speed at least one X unit, so a slow one is never read as unlimited.  Moving Speed 0, "the maximum
        # rpm of the motor is used without controlling the speed. ... However, the rpm will not exceed the No Load
        # Speed" (MX-28 and XL-320 pages, "Moving Speed(32)"), is a profile at the data sheet's no-load speed
        # rather than the X series' step (Profile Velocity 0): the classic Moving reads "Goal position command
        # execution is in progress" (the pages' Moving(46)/(49)), which a step, over before the first control
        # step ends, would not show, and the X series plans no acceleration without a profile speed either.
        cmd.profile_velocity = max(1, int(round(self.speed_to_x_velocity(speed)))) if speed else self._full_speed()
        cmd.profile_acceleration = self._profile_acceleration(values)
        if self.is_multi_turn(values):
            divider = self.divider(values)
            goal = values["goal_position"]
            goal = goal - 0x10000 if goal & 0x8000 else goal  # two's complement in the 2-byte register
            limit = units.multi_turn_goal_limit
            cmd.operating_mode = OperatingMode.EXTENDED_POSITION
            cmd.homing_offset = values.get("multi_turn_offset", 0) * divider
            cmd.goal_position = max(-limit, min(limit, goal)) * divider
        gains = self.x_gain_per_register
        cmd.position_p_gain = int(round(values.get("p_gain", 0) * gains["p"]))
        cmd.position_i_gain = int(round(values.get("i_gain", 0) * gains["i"]))
        cmd.position_d_gain = int(round(values.get("d_gain", 0) * gains["d"]))
        return cmd

    def _full_speed(self) -> int:
        """Moving Speed 0's Profile Velocity: the no-load speed (0, the X series' step, on a map given none)."""
        return max(1, int(round(self.no_load_speed_rpm / X_VELOCITY_UNIT_RPM))) if self.no_load_speed_rpm > 0 else 0

    def _profile_acceleration(self, values: Mapping[str, int]) -> int:
        """Goal Acceleration as Profile Acceleration (at least 1 when set, so it is never read as "none")."""
        unit = self.units.acceleration_unit_deg_s2
        raw = values.get("goal_acceleration", 0)
        if unit is None or raw == 0:
            return 0
        return max(1, int(round(raw * unit / X_ACCELERATION_UNIT_DEG_S2)))

    def goal_changed(self, before: Mapping[str, int] | None, after: Mapping[str, int]) -> bool:
        """Whether a classic goal register (Goal Position, Moving Speed) differs between two sets of values, or the mode
        (wheel, joint, multi-turn: the angle limits or the mode register) changed.

        Why a change of mode counts as a goal write: the classic firmware's mode is read from the angle limits (the
        MX on Protocol 1.0 switches with the torque on, as pypot's ``set_wheel_mode`` does), and it then runs on the
        goal registers it holds: after CW = CCW = 0 the wheel turns at the Moving Speed already set, after a CCW
        limit back at its maximum the joint goes to the Goal Position already set (the AX-12A beside it on the wire
        does both).  The X firmware's mode change only holds where the shaft is (Operating Mode is written with the
        torque off there), so the new mode's goals are handed over as written.
        """
        if before is None:
            return False
        if self.is_wheel(before) != self.is_wheel(after) or self.is_multi_turn(before) != self.is_multi_turn(after):
            return True
        return any(before.get(name) != after.get(name) for name in self.goal_registers)

    # -- firmware -> registers ---------------------------------------------------------------
    def sensed_to_registers(self, sensed: XSensed, commands: XCommands,
                            values: Mapping[str, int] | None = None) -> dict[str, int]:
        """The classic registers (those the table has) for the firmware's readings; ``commands`` tell the mode,
        ``values`` (the command registers, as :meth:`commands` took them) the multi-turn frame."""
        units = self.units
        bit, full = units.direction_bit, units.output_full_scale
        wheel = commands.operating_mode in _WHEEL_X_MODES
        if wheel and units.wheel_output == "pwm":
            speed = sensed.present_pwm * full / PWM_FULL_SCALE
            speed_full = full
        else:
            speed = sensed.present_velocity * X_VELOCITY_UNIT_RPM / units.speed_unit_rpm
            speed_full = (1 << bit) - 1
        error = self.errors_to_classic(sensed.hardware_error_status)
        if commands.operating_mode == OperatingMode.EXTENDED_POSITION and values is not None:
            # Real Position / Resolution Divider, the offset (already in the firmware's count) divided with it
            position = (sensed.present_position // self.divider(values)) & 0xFFFF
        else:
            position = self.pulses_to_position(sensed.present_position)
        out = {
            "present_position": position,
            "present_speed": _encode_signed(speed, bit, speed_full),
            "present_load": _encode_signed(sensed.present_pwm * full / PWM_FULL_SCALE, bit, full),
            "present_voltage": sensed.present_input_voltage,
            "present_temperature": sensed.present_temperature,
            "moving": sensed.moving,
            "hardware_error_status": error,
            "torque_enable": sensed.torque_enable,
            "current": min(max(CURRENT_ZERO + sensed.present_current, 0), 0xFFFF),
        }
        return {name: out[name] for name in self.sensed_registers}
