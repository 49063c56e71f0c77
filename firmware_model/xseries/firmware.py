"""The firmware of one ROBOTIS X-series servo: operating modes, profile, PID, protection, over its physics.

Why this shape: the protocol side hands over raw register values (:class:`.interface.XCommands`) and
reads raw registers back (:class:`.interface.XSensed`); everything the real firmware does between
them lives here, in the e-manual's own units, so a register written on the bus means what it means
on a real servo.  The motor, gearbox and load are :mod:`.physics`; this module decides the PWM duty
at each 1 ms control step and watches the protections.

Sources (ROBOTIS e-manual, X-series control tables, https://emanual.robotis.com/docs/en/dxl/x/xm430-w350/,
.../xl430-w250/, .../xl330-m288/; texts in github.com/ROBOTIS-GIT/emanual, _includes/dxl and _includes/en/dxl):

* "Position PID Gain(80, 82, 84), Feedforward 1st/2nd Gains(88, 90)": KPP = P/128, KPI = I/65536,
  KPD = D/16, KFF1 = FF1/4, KFF2 = FF2/4, "the constant in each equation includes sampling time";
  PID and feed-forward act on Position Trajectory and Velocity Trajectory and give the PWM, limited
  by Goal PWM(100).  The e-manual gives no internal units: we take the error in pulses, its sum and
  difference per 1 ms sample, and the feed-forward on the trajectory's pulses per sample (and per
  sample squared), which make the default gains a stiff, damped servo.
* "Velocity PI Gain(76, 78)": KVP = P/128, KVI = I/65536 on the velocity error in 0.229 rpm units,
  output PWM limited by Goal PWM; "Ka is an anti-windup gain": we stop integrating while saturated.
* Current-based Position Control Mode: the same PID gives a target current, limited by Goal
  Current(102); a current controller turns it into PWM.  The e-manual gives no current-loop gains;
  ours integrates the current error into the duty at half the winding's V/R, settling in a few samples.
* "Goal PWM(100)": in PWM mode it drives the motor directly; in the other modes it limits the PWM;
  it cannot exceed PWM Limit(36).  A real servo sets Goal PWM to PWM Limit (and Goal Current to
  Current Limit) at boot: the control table side hands those values in.  Both bound the output from
  the moment they are written, and Torque Enable 0 lets go of it at once (Present PWM and Present
  Current 0): what follows from the commands alone is not left for the next 1 ms step, which a host
  writing twice within one period would otherwise read around.
* "Drive Mode(10)": bit 0 reverse, bit 2 time-based profile, bit 3 torque on by goal update ("If the
  value of Torque Enable(64) is '0' and the command is given, the Torque Enable(64) switches to '1'
  and perform the command"; XL330/XC330 from firmware V46, X430 from V45).  The e-manual says reverse
  inverts Goal and Present Position on the X430/X330 and also velocity, current and PWM on others;
  here it mirrors the whole shaft frame, so every signed register of a reversed servo agrees.
  "the sign of Homing Offset value will not be reversed".
* "Homing Offset(20)": Present Position = Actual Position + Homing Offset; in Position Control Mode
  values outside -1024..1024 are ignored.
* "Present Position(132)": a continuous 4-byte count, reset to within one turn (0..4095, plus Homing
  Offset) when the mode changes to Position Control Mode, when torque is turned on in it, on reboot.
* "Min/Max Position Limit(48, 52)": used in Position Control Mode only; the goal is held inside them.
* "Profile Velocity(112)": cannot exceed Velocity Limit(44); "Goal Velocity(104)": within +-Velocity Limit.
* "Moving(122)": 1 while |Present Velocity| > Moving Threshold(24), and always while a profile runs
  after a Goal Position write.  "Moving Status(123)": 0x01 in position, 0x02 profile ongoing, 0x08
  following error, 0x30 profile type; in-position and following error only in the position modes.
  In-Position: "Whether or not the DYNAMIXEL has arrived to the desired Goal Position(116)", set "when
  the positional deviation is smaller than a predefined value" (_includes/en/dxl/x/moving_status.md):
  a window on Goal - Present Position, here once the profile has ended.  The e-manual gives no value
  for it nor for the following error: ours are :data:`IN_POSITION_PULSES` and :data:`FOLLOWING_ERROR_PULSES`.
* "Shutdown(63)" / "Hardware Error Status(70)": an error selected by Shutdown clears Torque Enable
  (output 0 %), and only REBOOT lets torque on again.  Shutdown selects what is detected ("when
  0x05 is defined as Shutdown, DYNAMIXEL can detect both Input Voltage Error and Overheating
  Error"), so an error not selected is not reported.  Overload "detects persistent load that exceeds
  maximum output"; the e-manual gives no current and no time.  ROBOTIS staff describe it as a
  current held over time ("When a high current flows for a few seconds, an overload occurs",
  DynamixelSDK's issue tracker, for an XM430 held at about 0.94 A for about 5 s in Position mode), and
  XM430s in Current-based Position mode with Goal Current 400 (1.08 A) are reported to trip: it
  watches the winding's current whatever limits it, not whether the output is at its limit.  Ours
  is that, the same in every mode: :data:`OVERLOAD_CURRENT_SHARE` and ``overload_time_s``.
  Overheating: a first-order thermal model heated by the winding's I^2 R (:class:`ThermalParams`).

Units in names: ``_pulses`` (0.088 deg), ``_pulses_s``, ``_a``, ``_v``, ``_s``, ``_c``; raw register
values are plain ints named after their register.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

from ..interface import STEP_SLACK
from .interface import (
    HW_ERROR_INPUT_VOLTAGE,
    HW_ERROR_OVERHEATING,
    HW_ERROR_OVERLOAD,
    POSITION_MODES,
    OperatingMode,
    XCommands,
    XSensed,
)
from .physics import XPhysics, XPhysicsParams
from .profile import (
    ACCEL_UNIT_PULSES_S2,
    PROFILE_STEP,
    PROFILE_TRAPEZOIDAL,
    VELOCITY_UNIT_PULSES_S,
    Profile,
    plan_time_based,
    plan_velocity_based,
)

__all__ = [
    "PWM_FULL_SCALE",
    "PULSES_PER_REV",
    "IN_POSITION_PULSES",
    "FOLLOWING_ERROR_PULSES",
    "OVERLOAD_CURRENT_SHARE",
    "ThermalParams",
    "XFirmware",
    "build_x_servo",
]

#: Goal/Present PWM at 100 % duty (e-manual "PWM Limit(36)": 885 = 100 %, 0.113 % per unit).
PWM_FULL_SCALE = 885
#: Encoder pulses per output turn (e-manual: 0.088 deg per unit, 0..4095 per turn).
PULSES_PER_REV = 4096
PULSE_RAD = 2.0 * math.pi / PULSES_PER_REV
#: Moving Status reports In-Position once the profile ended and Present Position is less than this from the goal
#: (ours: the e-manual's "predefined value" is not given).  Why 20 (1.8 deg): a factory-default servo on a free
#: shaft must get it, as a real one does, and a proportional-only loop (every X model's factory Position I Gain but
#: the XL330-M077's 400 is 0) stops wherever its output no longer beats the servo's own friction: at the factory gains that dead band is
#: up to 12 pulses on the XL330s at 5 V (16.5 at their lowest 3.7 V; 2 to 6 on the XC330, XL430 and XM430), so the
#: former 10 left most XL330 moves without it.  20 is also the window `ax12emu conformance` holds real servos to.
IN_POSITION_PULSES = 20
#: Distance from Position Trajectory beyond which Moving Status reports a following error (ours: 1/8 turn).
FOLLOWING_ERROR_PULSES = 512
#: Overload (ours: the e-manual gives neither a current nor a time): the winding current, whatever limits it, is
#: accounted over time against this share of the stall current at the present supply (``V / R``).  Above it the
#: account grows by ``dt (|I| - s I_stall) / (I_stall - s I_stall)``, at most ``dt`` (so a full stall trips in
#: ``overload_time_s``, 1 s); below it the account drains by the same formula (at zero current in 3 s from full);
#: Overload when it reaches ``overload_time_s``.  Why a quarter: the e-manual's design rule ("Stable motions are
#: possible with robots designed for loads with 1/5 or less of the stall torque") must never trip, and an XM430
#: holding 0.94 A (0.42 of its 2.25 A stall at 12 V) must trip in "a few seconds" (ROBOTIS staff; the reporter
#: saw about 5 s): 0.25 gives 4.4 s there, 3.3 s at Goal Current 400 in Current-based Position, and never at 0.2.
OVERLOAD_CURRENT_SHARE = 0.25
#: Extended and current-based position modes' Goal Position range (e-manual "Goal Position(116)": +-256 rev).
EXTENDED_GOAL_LIMIT = 1_048_575
#: Position Control Mode accepts Homing Offset only within this range (e-manual "Homing Offset(20)").
POSITION_MODE_HOMING_LIMIT = 1024

_RAD_S_TO_VELOCITY_UNITS = 1.0 / (PULSE_RAD * VELOCITY_UNIT_PULSES_S)
_INT32_MIN = -(2**31)
_INT32_SPAN = 2**32


def _int32(value: float) -> int:
    """A register value as the 4-byte signed integer the control table holds (wraps like the firmware's counter)."""
    return (int(round(value)) - _INT32_MIN) % _INT32_SPAN + _INT32_MIN


@dataclass(frozen=True)
class ThermalParams:
    """A first-order thermal model of the servo: ``C dT/dt = I^2 R - (T - T_ambient) / R_th``, ``C = tau / R_th``.

    Why first order: the firmware only compares Present Temperature with Temperature Limit; one time
    constant reproduces "holding a stall for tens of seconds overheats" without claiming more.  The
    defaults are our estimates (ROBOTIS publishes no thermal data): 20 K/W to ambient and a 300 s
    time constant, so a stall at 12 V (about 27 W in an XM430) reaches 80 C in about half a minute.
    Holding current heats as its square times the winding's resistance: 0.5 A settles some 27 K above
    ambient in an XM430 (5.3 ohm, 1.3 W) and 44 K in an XL430 (8.7 ohm, 2.2 W: 69 C from a 25 C room,
    close to its 72 C limit), nearly two thirds of that within the first 5 minutes.  (0.5 A is 0.39 of the
    XL430's stall current at 11.1 V, above :data:`OVERLOAD_CURRENT_SHARE`: unless Shutdown leaves Overload
    out, Overload stops it within seconds, long before it gets that warm.)
    """

    ambient_c: float = 25.0
    thermal_resistance_k_w: float = 20.0
    time_constant_s: float = 300.0


class XFirmware:
    """One X-series servo's firmware over its :class:`.physics.XPhysics`; implements :class:`.interface.XServoModel`.

    ``current_unit_a`` is Goal/Present Current's unit (1 mA on the XL330/XC330, 2.69 mA on the XM430)
    or ``None`` for a model without current sensing (the XL430), which reports Present Load (0.1 % of
    ``load_full_scale_a``) in Present Current's place and has no current modes.

    ``position_output_scale`` multiplies the position controller's output (PID and feed-forward)
    after the e-manual's gain conversion.  1 is the e-manual read as PWM units per pulse (KPP =
    P/128).  A real XL330 reads half of that: in Rhoban's eight BAM pendulum logs
    (../shared/reference/real-xl330, kp 100 and 400, 5.8..8.3 V) Present PWM is (P/128) x error x
    0.50 (correlation 1.000, the same at every voltage) until it saturates at 885; so 0.5 for the
    XL330.  No such data for the other models: they keep the e-manual's 1.
    """

    def __init__(
        self,
        physics: XPhysics,
        *,
        current_unit_a: float | None,
        load_full_scale_a: float = 1.0,
        step_s: float = 0.001,
        thermal: ThermalParams | None = None,
        overload_time_s: float = 1.0,
        position_output_scale: float = 1.0,
        shutdown_cuts_output: bool = False,
        single_turn_position: bool = False,
        overload_by_current: bool = True,
    ) -> None:
        self.physics = physics
        #: How Overload is judged: True, the X series' (the winding current accounted over time in every mode,
        #: :data:`OVERLOAD_CURRENT_SHARE`); False, Protocol 1.0's ("When the current load cannot be controlled by
        #: the set Torque", e-manual, Protocol 1.0, Status Packet: the output held at its limit while a load, not
        #: speed, keeps it there): the MX series on Protocol 1.0, for which the current-time evidence (X-series
        #: servos) says nothing, and which holds a third of its stall torque for minutes.
        self.overload_by_current = overload_by_current
        #: Position Control Mode on a single-turn count (the MX series' joint mode on Protocol 1.0: Goal and Present
        #: Position 0..4095, "Multi-turn mode allows joint mode control over multiple rotations", which joint mode
        #: therefore does not): a shaft pushed across 0/4095 with the torque on is counted within the turn again,
        #: so it is driven back the direct way within the range, not round the turns it was pushed through.
        self.single_turn_position = single_turn_position
        #: What an error Shutdown selects does: False, the X series' (latched in Hardware Error Status, torque off
        #: until REBOOT); True, the Protocol 1.0 MX firmware's (the output cut to 0 % until :meth:`restore_output`,
        #: nothing latched: its status packets report the conditions present, :attr:`present_errors`).
        self.shutdown_cuts_output = shutdown_cuts_output
        self.position_output_scale = position_output_scale
        self.step_s = step_s
        #: Control steps run since power-up: ``time_s`` is their count times ``step_s``, never a running sum.
        self._steps = 0
        self.resistance_ohm = physics.params.resistance_ohm
        self.current_unit_a = current_unit_a
        self.load_full_scale_a = load_full_scale_a
        self.thermal = thermal or ThermalParams()
        self.overload_time_s = overload_time_s
        self.temperature_c = self.thermal.ambient_c
        self._thermal_capacity_j_k = self.thermal.time_constant_s / self.thermal.thermal_resistance_k_w
        self._cmd = XCommands()
        #: Sensed registers pinned by a stuck sensor (:meth:`hold_reading`): the world's fault, so a reboot keeps them.
        self._held_readings: dict[str, int] = {}
        #: Error conditions a fault injection holds present (:meth:`hold_errors`): detected at every step until lifted.
        self._held_errors = 0
        #: Counts every change that may alter a sensed value other than :data:`.interface.TRAJECTORY_SENSED` (a step, a
        #: reboot, the world, a command that moves the frame or the torque): while it stands still, ``sense()``
        #: gives the same values for every other field.  A serving bus uses it to leave the copy of a
        #: command's effects for after a reply that reads none of them (``ax12emu.servo.plant2``).
        self.sensing_epoch = 0
        self._reset_firmware()

    # ------------------------------------------------------------------ state

    def _reset_firmware(self) -> None:
        """Power-on / REBOOT state: torque off, errors cleared, position counted within one turn."""
        self._torque_on = False
        self._last_torque_cmd = 0
        self._hw_error = 0
        #: Errors that cut the output (``shutdown_cuts_output``), kept until :meth:`restore_output`.
        self._cut_errors = 0
        #: The firmware's own Overload detection cut the output (reported until :meth:`restore_output`).
        self._overload_cut = False
        self._fixed = False
        self.sensing_epoch += 1
        self._overload_elapsed_s = 0.0
        self._duty = 0.0
        self._reset_control()
        self._turn_base_pulses = 0.0
        self._reset_turns()
        self._hold_here()

    def _reset_control(self) -> None:
        self._integral = 0.0
        self._prev_error = 0.0
        #: The current loop held its duty at the PWM bound last step (Goal PWM in current-based position): the
        #: position integral, whose output it could not deliver, stops growing as it does at the current bound.
        self._drive_at_pwm_bound = False
        self._velocity_integral = 0.0
        self._current_correction = 0.0

    def _sign(self) -> float:
        """Drive Mode bit 0: the reverse mode mirrors the shaft frame."""
        return -1.0 if self._cmd.drive_mode & 0x01 else 1.0

    def _homing_offset(self) -> int:
        offset = self._cmd.homing_offset
        if self._cmd.operating_mode == OperatingMode.POSITION and abs(offset) > POSITION_MODE_HOMING_LIMIT:
            return 0
        return offset

    def _present_pulses(self) -> float:
        """Present Position before rounding: the shaft in the firmware's frame, less the whole turns dropped, plus Homing Offset."""
        return self._sign() * self.physics.angle_rad / PULSE_RAD - self._turn_base_pulses + self._homing_offset()

    def _counted_pulses(self) -> float:
        """Present Position as the firmware counts it: whole encoder pulses, the register's value.

        Why the trajectory starts here and not at the shaft's exact angle: the firmware knows the shaft only
        through its encoder's count, so a goal written as the Present Position just read is where the
        trajectory already stands, and no profile runs.  From the exact angle, a fraction of a pulse away,
        that goal started a profile of that fraction, still accelerating when the next goal came a few
        milliseconds later; the next profile then started with its speed, ahead of one planned from rest.
        """
        return float(round(self._present_pulses()))

    def _reset_turns(self) -> None:
        """Present Position reset to within one turn (e-manual "Present Position(132)" note)."""
        shaft = self._sign() * self.physics.angle_rad / PULSE_RAD
        self._turn_base_pulses = math.floor(shaft / PULSES_PER_REV) * PULSES_PER_REV

    def _keep_within_one_turn(self) -> None:
        """``single_turn_position``: the count back within 0..4095 once the shaft has crossed 0/4095 (the trajectory, a
        goal within the range, stays: the error is taken the direct way, as an absolute encoder's reading gives it)."""
        present = self._present_pulses() - self._homing_offset()
        if -0.5 <= present < PULSES_PER_REV - 0.5:
            return
        self._reset_turns()
        self._prev_error = self._traj_pulses - self._present_pulses()  # no derivative kick from the count's jump

    def _hold_here(self) -> None:
        """No profile: the trajectory at the present position, at rest."""
        self._profile: Profile | None = None
        self._profile_start_s = self.time_s
        self._profile_kind = PROFILE_STEP
        self._planned_from: tuple[float, float, float] | None = None
        self._traj_pulses = self._counted_pulses()
        self._traj_velocity_pulses_s = 0.0
        self._traj_accel_pulses_s2 = 0.0
        self._goal_velocity_pulses_s = 0.0
        self._velocity_accel_pulses_s2 = math.inf

    def _profile_running(self) -> bool:
        return self._profile is not None and self.time_s - self._profile_start_s < self._profile.end_s

    # ------------------------------------------------------------------ commands

    def command(self, commands: XCommands, *, goal_written: bool = False) -> None:
        """Take the registers as they now are; mode, torque and goal changes take effect at ``time_s``.

        Torque Enable acts on its changes (0 -> 1 turns torque on unless a Shutdown error is latched),
        so a register the protocol side has not yet brought in line after a shutdown or a torque-on
        by goal update does not undo them; :attr:`.XSensed.torque_enable` is the firmware's value.
        """
        old = self._cmd
        # Our own copy: a caller may reuse and mutate its object.  A shallow copy of the instance dict, not
        # dataclasses.replace: every Sync Write commands each servo it reaches, and replace() re-runs
        # __init__ with every field by keyword (about ten times the cost).
        own = object.__new__(type(commands))
        own.__dict__.update(commands.__dict__)
        commands = own
        if not self.keeps_sensing(commands, goal_written=goal_written):
            self.sensing_epoch += 1
        self._cmd = commands
        self._fixed = False
        torque_cmd = 1 if commands.torque_enable else 0
        if (commands.drive_mode ^ old.drive_mode) & 0x01:
            self._reset_turns()  # a mirrored frame counts its turns afresh
            self._hold_here()
        if commands.operating_mode != old.operating_mode:
            if commands.operating_mode == OperatingMode.POSITION:
                self._reset_turns()
            self._reset_control()
            self._hold_here()
        elif commands.homing_offset != old.homing_offset and not self._profile_running():
            self._hold_here()
        if torque_cmd != self._last_torque_cmd:
            self._last_torque_cmd = torque_cmd
            if torque_cmd:
                self._torque_on_now()
                return
            if self._torque_on:
                self._open_bridge()
            self._torque_on = False
        self._clamp_duty()
        if goal_written:
            if self._torque_on:
                self._start_profile()
            elif commands.drive_mode & 0x08:
                # Drive Mode bit 3, torque on by goal update: "Torque Enable(64) will be updated to '1'", so it
                # is as if Torque Enable were written 1: a later 0 turns the torque off, a later 1 is no change.
                self._torque_on_now()
                if self._torque_on:
                    self._last_torque_cmd = 1

    def keeps_sensing(self, commands: XCommands, *, goal_written: bool = False) -> bool:
        """Whether :meth:`command` with these now would leave every sensed value but the trajectory ones
        (``TRAJECTORY_SENSED``) as it is, and so :attr:`sensing_epoch` too.

        What sense() reads besides the trajectory moves only with the frame (the reverse bit, the mode and
        Homing Offset: Present Position and the signs), the torque (turns counted afresh, the output) or a step.
        """
        old = self._cmd
        torque_cmd = 1 if commands.torque_enable else 0
        return not ((commands.drive_mode ^ old.drive_mode) & 0x01 or commands.operating_mode != old.operating_mode
                    or commands.homing_offset != old.homing_offset or torque_cmd != self._last_torque_cmd
                    or (goal_written and not self._torque_on and commands.drive_mode & 0x08)
                    or abs(self._duty) * PWM_FULL_SCALE > self._pwm_bound(commands) + 1e-6)

    def _pwm_bound(self, cmd: XCommands) -> float:
        """The largest |PWM| the commands allow a control step (as :meth:`_step_once` bounds it): PWM Limit, and Goal
        PWM but in PWM Control Mode (where Goal PWM is the command itself); 0 while an Alarm Shutdown cuts the output."""
        if self._cut_errors:
            return 0.0
        bound = min(cmd.pwm_limit, PWM_FULL_SCALE)
        if cmd.operating_mode != OperatingMode.PWM:
            bound = min(abs(cmd.goal_pwm), bound)
        return float(max(bound, 0))

    def _open_bridge(self) -> None:
        """Torque off: the output stage lets go now, not at the next control step, so Present PWM and Present
        Current (Present Load) read 0 beside Torque Enable 0 even for a host that reads within the same 1 ms (the
        winding's current dies within microseconds with the bridge open; a step with the torque off gives the same)."""
        self._duty = 0.0
        physics = self.physics
        physics.current_a = 0.0
        physics.motor_torque_nm = 0.0
        physics.bus_voltage_v = physics.supply_v

    def _clamp_duty(self) -> None:
        """A lowered PWM bound (Goal PWM, PWM Limit; on the MX, Torque Limit) bounds the output at once: Present PWM
        (the MX's Present Load) never reads above the bound just written; the next control step recomputes it anyway."""
        bound = self._pwm_bound(self._cmd)
        if abs(self._duty) * PWM_FULL_SCALE > bound + 1e-6:  # (a step's own duty, pwm / 885, is within it but for rounding)
            self._duty = math.copysign(bound / PWM_FULL_SCALE, self._duty)

    def _torque_on_now(self) -> None:
        if self._hw_error:
            return  # after a Shutdown only REBOOT lets torque on again
        self._torque_on = True
        if self._cmd.operating_mode == OperatingMode.POSITION:
            self._reset_turns()
        self._reset_control()
        self._hold_here()
        self._start_profile()

    def _goal_pulses(self) -> float:
        cmd = self._cmd
        goal = cmd.goal_position
        if cmd.operating_mode == OperatingMode.POSITION:
            return float(min(max(goal, cmd.min_position_limit), cmd.max_position_limit))
        return float(min(max(goal, -EXTENDED_GOAL_LIMIT), EXTENDED_GOAL_LIMIT))

    def _start_profile(self) -> None:
        """A goal was written (or torque came on): plan from the trajectory's present state (velocity override)."""
        cmd = self._cmd
        time_based = bool(cmd.drive_mode & 0x04)
        if cmd.operating_mode == OperatingMode.VELOCITY:
            self._start_velocity_ramp(time_based)
            return
        if cmd.operating_mode not in POSITION_MODES:
            return
        planned = self._planned_from
        if planned is not None and planned[0] == self.time_s:
            # A goal written again before the control loop ran (a host faster than 1 kHz): the loop plans
            # once, from the trajectory's state at its tick, so the profile the first goal started leaves
            # no trace; planning from that profile's own start would differ when it has no length
            # (not running, so the present position would stand in for the trajectory's).
            _, start, v0 = planned
        elif self._profile_running():
            start, v0 = self._traj_pulses, self._traj_velocity_pulses_s
        else:
            start, v0 = self._counted_pulses(), 0.0
        self._planned_from = (self.time_s, start, v0)
        goal = self._goal_pulses()
        if time_based:
            profile = plan_time_based(start, v0, goal, cmd.profile_velocity, cmd.profile_acceleration)
        else:
            velocity = cmd.profile_velocity
            if 0 < cmd.velocity_limit < velocity:
                velocity = cmd.velocity_limit  # "Profile Velocity(112) cannot exceed Velocity Limit(44)"
            profile = plan_velocity_based(start, v0, goal, velocity, cmd.profile_acceleration)
        self._profile = profile
        self._profile_start_s = self.time_s
        self._profile_kind = profile.kind
        self._traj_pulses, self._traj_velocity_pulses_s, self._traj_accel_pulses_s2 = profile.at(0.0)

    def _start_velocity_ramp(self, time_based: bool) -> None:
        """Velocity mode: Velocity Trajectory ramps to Goal Velocity at Profile Acceleration.

        e-manual "What is the Profile": velocity mode uses only Profile Acceleration; velocity-based
        t1 = 64 * Goal Velocity / Profile Acceleration (ms), time-based t1 = Profile Acceleration (ms).
        """
        cmd = self._cmd
        goal = cmd.goal_velocity
        if cmd.velocity_limit > 0:
            goal = min(max(goal, -cmd.velocity_limit), cmd.velocity_limit)
        self._goal_velocity_pulses_s = goal * VELOCITY_UNIT_PULSES_S
        if cmd.profile_acceleration <= 0:
            self._velocity_accel_pulses_s2 = math.inf
            self._profile_kind = PROFILE_STEP
        elif time_based:
            change = abs(self._goal_velocity_pulses_s - self._traj_velocity_pulses_s)
            self._velocity_accel_pulses_s2 = max(change, 1e-9) / (cmd.profile_acceleration / 1000.0)
            self._profile_kind = PROFILE_TRAPEZOIDAL
        else:
            self._velocity_accel_pulses_s2 = cmd.profile_acceleration * ACCEL_UNIT_PULSES_S2
            self._profile_kind = PROFILE_TRAPEZOIDAL

    # ------------------------------------------------------------------ stepping

    @property
    def time_s(self) -> float:
        """The model's time: its steps times ``step_s`` (a product, so it never drifts from the clock's grid)."""
        return self._steps * self.step_s

    def step_to(self, to_time_s: float) -> None:
        """Run whole control steps up to ``to_time_s``; a servo provably at rest skips its physics steps."""
        step_s = self.step_s
        # A step due within STEP_SLACK (a millionth of a step, 1 ns at 1 kHz) is taken: the caller's clock sums its
        # own floats, so after a long run it parts from the grid by more than a float's last digit; a caller that
        # finds a step due by the same slack then gets it (else a write's earned step was dropped: the caller judged
        # it due, and nothing ran).
        n = int((to_time_s - self.time_s) / step_s + STEP_SLACK)
        if n <= 0:
            return
        self.sensing_epoch += 1
        if self._fixed or self._at_rest():
            # Nothing but the temperature would change: heat or cool in closed form, unless that
            # would cross Temperature Limit on the way (then step, so the error comes on time).
            power_w = self.physics.current_a ** 2 * self.resistance_ohm
            settles_c = self.thermal.ambient_c + power_w * self.thermal.thermal_resistance_k_w
            # (nor when already past it: a servo rebooted hot detects Overheating again at its first step)
            limit_c = self._cmd.temperature_limit
            if max(settles_c, self.temperature_c) <= limit_c or not self._cmd.shutdown & HW_ERROR_OVERHEATING:
                self._relax_temperature(settles_c, n * step_s)
                self._steps += n
                self._check_readings()
                return
        for _ in range(n):
            self._step_once()

    def _at_rest(self) -> bool:
        """Torque off, shaft still, nothing pushing it, current zero, the overload account drained: a step would change
        nothing but the temperature."""
        physics = self.physics
        return (
            not self._torque_on
            and self._overload_elapsed_s == 0.0
            and physics.velocity_rad_s == 0.0
            and physics.current_a == 0.0
            and physics.external_torque_nm() == 0.0
        )

    def _relax_temperature(self, settles_c: float, dt_s: float) -> None:
        """The first-order thermal model over ``dt_s`` at constant power: exponential approach to ``settles_c``."""
        self.temperature_c = settles_c + (self.temperature_c - settles_c) * math.exp(-dt_s / self.thermal.time_constant_s)

    def _state(self) -> tuple[bool | float, ...]:
        """Everything a control step reads that a step can change (the fixed-point check compares it across a step)."""
        return (
            self._torque_on,
            self.physics.angle_rad,
            self.physics.velocity_rad_s,
            self._duty,
            self._integral,
            self._velocity_integral,
            self._current_correction,
            self._traj_pulses,
            self._traj_velocity_pulses_s,
        )

    def _step_once(self) -> None:
        """One control step; it also notes whether it was a fixed point (the next would repeat it exactly)."""
        cmd = self._cmd
        physics = self.physics
        step_s = self.step_s
        before = self._state()
        self._steps += 1
        saturated = False
        if self._torque_on:
            sign = self._sign()
            mode = cmd.operating_mode
            pwm_limit = min(cmd.pwm_limit, PWM_FULL_SCALE) if not self._cut_errors else 0
            if mode != OperatingMode.PWM:
                pwm_limit = min(abs(cmd.goal_pwm), pwm_limit)  # "Goal PWM ... is used to limit PWM value"
            if mode in POSITION_MODES:
                if self.single_turn_position and mode == OperatingMode.POSITION:
                    self._keep_within_one_turn()
                if self._profile is not None:
                    self._traj_pulses, self._traj_velocity_pulses_s, self._traj_accel_pulses_s2 = self._profile.at(
                        self.time_s - self._profile_start_s
                    )
                if mode == OperatingMode.CURRENT_BASED_POSITION:
                    limit_units = min(abs(cmd.goal_current), cmd.current_limit)
                    demand = self._position_pid(limit_units, held=self._drive_at_pwm_bound)
                    pwm, saturated = self._current_loop(min(max(demand, -limit_units), limit_units), pwm_limit, sign)
                    self._drive_at_pwm_bound = saturated
                else:
                    demand = self._position_pid(pwm_limit)
                    saturated = abs(demand) >= pwm_limit
                    pwm = min(max(demand, -pwm_limit), pwm_limit)
            elif mode == OperatingMode.VELOCITY:
                pwm, saturated = self._velocity_pi(pwm_limit, sign)
            elif mode == OperatingMode.CURRENT:
                limit_units = cmd.current_limit
                pwm, saturated = self._current_loop(min(max(cmd.goal_current, -limit_units), limit_units), pwm_limit, sign)
            else:  # PWM mode: Goal PWM straight to the inverter, within PWM Limit
                pwm = float(min(max(cmd.goal_pwm, -pwm_limit), pwm_limit))
                saturated = abs(pwm) >= PWM_FULL_SCALE
            self._duty = pwm / PWM_FULL_SCALE
            physics.step(sign * self._duty, step_s, driven=True)
        else:
            self._duty = 0.0
            physics.step(0.0, step_s, driven=False)
            self._traj_pulses = self._counted_pulses()
            self._traj_velocity_pulses_s = 0.0
        self._protect(saturated, step_s)
        # A held servo at rest repeats its step exactly: same angle and speed (a creep too slow to move
        # the angle's last bit counts as rest), duty, integrators and trajectory, no profile left to
        # run, nothing saturated, an empty overload account (a current above its threshold, or one
        # draining, changes it).  The inputs that could change it (commands, torque, load, supply) clear the flag.
        self._fixed = (
            not saturated
            and self._overload_elapsed_s == 0.0
            and not self._profile_running()
            and self._traj_velocity_pulses_s == self._goal_velocity_pulses_s
            and self._state() == before
        )

    def _position_pid(self, limit: float, held: bool = False) -> float:
        """PID plus feed-forward on the trajectory: PWM units (or current units in current-based position), unclipped.

        ``limit``: what the output is clipped to (Goal PWM within PWM Limit; Goal Current within Current Limit in
        current-based position), where the integral stops growing: held to full scale instead, it wound up behind
        a lowered Goal PWM or Goal Current while a load held the shaft back, and overshot when the load let go.
        ``held``: the stage after it held its output at a bound of its own last step (the current loop at Goal PWM).
        """
        cmd = self._cmd
        error = self._traj_pulses - self._present_pulses()
        difference = error - self._prev_error
        self._prev_error = error
        step_s = self.step_s
        scale = self.position_output_scale
        output = scale * (cmd.position_p_gain / 128.0 * error + cmd.position_d_gain / 16.0 * difference)
        if cmd.feedforward_1st_gain:
            output += scale * cmd.feedforward_1st_gain / 4.0 * self._traj_velocity_pulses_s * step_s
        if cmd.feedforward_2nd_gain:
            output += scale * cmd.feedforward_2nd_gain / 4.0 * self._traj_accel_pulses_s2 * step_s * step_s
        if cmd.position_i_gain:
            ki = scale * cmd.position_i_gain / 65536.0
            integral = self._integral + error
            if (abs(output + ki * integral) < max(limit, 1) and not held) or integral * error < 0:
                self._integral = integral  # anti-windup: no further integration while saturated
            output += ki * self._integral
        return output

    def _velocity_pi(self, pwm_limit: float, sign: float) -> tuple[float, bool]:
        """Velocity mode: ramp Velocity Trajectory toward the goal, then PI on the velocity error in 0.229 rpm units."""
        cmd = self._cmd
        goal = self._goal_velocity_pulses_s
        v = self._traj_velocity_pulses_s
        max_change = self._velocity_accel_pulses_s2 * self.step_s
        if abs(goal - v) <= max_change:
            v = goal
        else:
            v += max_change if goal > v else -max_change
        self._traj_velocity_pulses_s = v
        self._traj_pulses += v * self.step_s
        error_units = v / VELOCITY_UNIT_PULSES_S - sign * self.physics.velocity_rad_s * _RAD_S_TO_VELOCITY_UNITS
        kp = cmd.velocity_p_gain / 128.0
        ki = cmd.velocity_i_gain / 65536.0
        integral = self._velocity_integral + error_units
        demand = kp * error_units + ki * integral
        saturated = abs(demand) >= pwm_limit
        if not saturated or demand * error_units < 0:
            self._velocity_integral = integral  # anti-windup: no further integration into the limit
        return min(max(demand, -pwm_limit), pwm_limit), saturated

    def _current_loop(self, target_units: float, pwm_limit: float, sign: float) -> tuple[float, bool]:
        """Current controller: the duty that drives the target current through the winding, corrected by an integral.

        The winding's current follows the duty within a step (``i = (duty V - k_e w) / R``), so the
        duty is fed forward from the target and the back-EMF, and the integral (half the winding's
        V/R per sample, halving the error every millisecond without overshoot) takes up the rest.
        """
        physics = self.physics
        target_a = target_units * (self.current_unit_a or 0.0)
        supply_v = max(physics.supply_v, 0.1)
        per_amp = self.resistance_ohm / supply_v
        step = 0.5 * (target_a - sign * physics.current_a) * per_amp
        correction = self._current_correction + step
        back_emf_v = sign * physics.velocity_rad_s * physics.params.back_emf_v_s_rad
        duty = target_a * per_amp + back_emf_v / supply_v + correction
        limit = pwm_limit / PWM_FULL_SCALE
        saturated = abs(duty) >= limit
        # Anti-windup as the velocity PI's: at the limit the correction moves only back toward it.  Held there
        # whatever the error, a correction wound up while the shaft was driven backwards froze with the duty at
        # its limit, and Goal Torque/Current 0 (or Torque Limit 0) no longer stopped the motor.
        if not saturated or step * duty < 0:
            self._current_correction = correction
        return min(max(duty, -limit), limit) * PWM_FULL_SCALE, saturated

    # ------------------------------------------------------------------ protection

    def _protect(self, saturated: bool, dt_s: float) -> None:
        physics = self.physics
        current_a = physics.current_a
        thermal = self.thermal
        power_w = current_a * current_a * self.resistance_ohm
        self.temperature_c += (
            dt_s * (power_w - (self.temperature_c - thermal.ambient_c) / thermal.thermal_resistance_k_w) / self._thermal_capacity_j_k
        )
        detected = 0
        if self._held_readings.get("present_temperature", self.temperature_c) > self._cmd.temperature_limit:
            detected |= HW_ERROR_OVERHEATING
        if not self.overload_by_current:
            # Protocol 1.0's Overload: the output held at its limit while the motor draws at least half of what
            # that duty would draw at stall, i.e. a load, not speed, keeps it at the limit.
            at_duty_a = abs(self._duty) * physics.supply_v / self.resistance_ohm
            if saturated and at_duty_a > 0.0 and abs(current_a) >= 0.5 * at_duty_a:
                self._overload_elapsed_s += dt_s
                if self._overload_elapsed_s >= self.overload_time_s:
                    detected |= HW_ERROR_OVERLOAD
            else:
                self._overload_elapsed_s = 0.0
            if detected:
                self._latch(detected)
            self._check_readings()
            return
        # Overload: the current accounted over time, in every mode alike (OVERLOAD_CURRENT_SHARE).
        stall_a = physics.supply_v / self.resistance_ohm
        if stall_a > 0.0 or self._overload_elapsed_s:
            threshold_a = OVERLOAD_CURRENT_SHARE * stall_a
            rate = (abs(current_a) - threshold_a) / (stall_a - threshold_a) if stall_a > 0.0 else -1.0
            account = self._overload_elapsed_s + dt_s * min(rate, 1.0)
            self._overload_elapsed_s = min(max(account, 0.0), self.overload_time_s)
            if self._overload_elapsed_s >= self.overload_time_s:
                detected |= HW_ERROR_OVERLOAD
        if detected:
            self._latch(detected)
        self._check_readings()

    @property
    def present_errors(self) -> int:
        """The Hardware Error Status bits whose condition holds now, whether or not Shutdown(63) selects them.

        What a firmware that reports conditions rather than latched errors shows (the MX series' Protocol 1.0
        status packets, ``ax12emu.servo.plant1x``): the temperature reading above Temperature Limit, the
        supply outside the voltage limits, the overload account full (:data:`OVERLOAD_CURRENT_SHARE`), the conditions a fault
        injection holds.  An Overload that cut the output stays until :meth:`restore_output`: with no output
        the firmware cannot judge the load again.
        """
        cmd = self._cmd
        held = self._held_readings
        bits = self._held_errors | (HW_ERROR_OVERLOAD if self._overload_cut else 0)
        if held.get("present_temperature", self.temperature_c) > cmd.temperature_limit:
            bits |= HW_ERROR_OVERHEATING
        tenths_v = held.get("present_input_voltage", round(self.physics.supply_v * 10.0))
        if tenths_v < cmd.min_voltage_limit or tenths_v > cmd.max_voltage_limit:
            bits |= HW_ERROR_INPUT_VOLTAGE
        if self._overload_elapsed_s >= self.overload_time_s:
            bits |= HW_ERROR_OVERLOAD
        return bits

    def _check_readings(self) -> None:
        """Input voltage against its limits every step; a pinned temperature too (a real one is checked as it changes);
        the conditions a fault injection holds."""
        if self._held_errors:
            self._latch(self._held_errors, own=False)
        cmd = self._cmd
        held = self._held_readings
        if held and held.get("present_temperature", -1e9) > cmd.temperature_limit:
            self._latch(HW_ERROR_OVERHEATING)
        tenths_v = held.get("present_input_voltage", round(self.physics.supply_v * 10.0))
        if tenths_v < cmd.min_voltage_limit or tenths_v > cmd.max_voltage_limit:
            self._latch(HW_ERROR_INPUT_VOLTAGE)

    def _latch(self, detected: int, *, own: bool = True) -> None:
        """Act on errors detected now as Shutdown(63) selects; ``own``: the firmware's protections found them
        (not conditions a fault injection holds, which are reported for as long as they are held)."""
        detected &= self._cmd.shutdown
        if not detected:
            return
        if own and detected & HW_ERROR_OVERLOAD:
            self._overload_elapsed_s = 0.0  # acted on: the output is off, the account starts afresh
        if self.shutdown_cuts_output:
            self._cut_errors |= detected
            self._overload_cut = self._overload_cut or (own and bool(detected & HW_ERROR_OVERLOAD))
        else:
            self._hw_error |= detected
            self._torque_on = False

    @property
    def cut_errors(self) -> int:
        """The errors that have cut the output (``shutdown_cuts_output``) since the last :meth:`restore_output`."""
        return self._cut_errors

    def restore_output(self) -> None:
        """The host lets the motor run again after a cut (Protocol 1.0: Torque Limit written non-zero).

        An error still present is detected again at the next step and cuts the output again.
        """
        if self._cut_errors:
            self._cut_errors = 0
            self._overload_cut = False
            self._fixed = False
            self.sensing_epoch += 1

    def hold_errors(self, bits: int) -> None:
        """Hold the Hardware Error Status ``bits``' conditions present (fault injection) until called with 0.

        Detected now and at every step, as a real condition would be: latched or cutting the output as
        Shutdown(63) selects, and in :attr:`present_errors` while held.
        """
        self._fixed = False
        self.sensing_epoch += 1
        self._held_errors = int(bits)
        if bits:
            self._latch(bits, own=False)

    # ------------------------------------------------------------------ sensing

    def sense(self) -> XSensed:
        """The registers the firmware writes back, in register units, at ``time_s``."""
        cmd = self._cmd
        sign = self._sign()
        physics = self.physics
        present = sign * physics.angle_rad / PULSE_RAD - self._turn_base_pulses + self._homing_offset()  # _present_pulses()
        present_velocity = int(round(sign * physics.velocity_rad_s * _RAD_S_TO_VELOCITY_UNITS))
        current_a = sign * physics.current_a
        if self.current_unit_a:
            present_current = int(round(current_a / self.current_unit_a))
        else:
            present_current = min(max(int(round(1000.0 * current_a / self.load_full_scale_a)), -1000), 1000)
        position_mode = cmd.operating_mode in POSITION_MODES
        profile_on = self._torque_on and position_mode and self._profile_running()
        status = self._profile_kind
        if profile_on:
            status |= 0x02
        if position_mode and self._torque_on:
            if not profile_on and abs(self._goal_pulses() - present) < IN_POSITION_PULSES:
                status |= 0x01
            if abs(self._traj_pulses - present) > FOLLOWING_ERROR_PULSES:
                status |= 0x08
        # By position, in XSensed's field order (by keyword costs a dict per call, every step of every servo):
        # present_position, present_velocity, present_current, present_pwm, velocity_trajectory,
        # position_trajectory, moving, moving_status, present_input_voltage, present_temperature,
        # hardware_error_status, torque_enable.
        sensed = XSensed(
            _int32(present),
            present_velocity,
            present_current,
            int(round(self._duty * PWM_FULL_SCALE)),
            int(round(self._traj_velocity_pulses_s / VELOCITY_UNIT_PULSES_S)),
            _int32(self._traj_pulses),
            1 if profile_on or abs(present_velocity) > cmd.moving_threshold else 0,
            status,
            int(round(physics.supply_v * 10.0)),
            int(round(self.temperature_c)),
            self._hw_error,
            1 if self._torque_on else 0,
        )
        if self._held_readings:
            sensed = dataclasses.replace(sensed, **self._held_readings)
        return sensed

    # ------------------------------------------------------------------ instructions and the world

    def reboot(self) -> None:
        """REBOOT: errors cleared, torque off, Present Position within one turn again; the shaft and its heat stay."""
        self._reset_firmware()

    def clear_multi_turn(self) -> None:
        """CLEAR 0x01: drop Present Position's whole turns, keeping the angle within one turn.

        The trajectory moves by the same turns and a running profile ends, so a holding servo keeps
        the same shaft angle instead of driving back over the cleared turns.
        """
        self._fixed = False
        self.sensing_epoch += 1
        before = self._turn_base_pulses
        self._reset_turns()
        self._traj_pulses -= self._turn_base_pulses - before
        self._profile = None
        self._planned_from = None
        self._traj_velocity_pulses_s = 0.0
        self._traj_accel_pulses_s2 = 0.0

    def raise_error(self, bits: int) -> int:
        """The protections detect the Hardware Error Status ``bits`` now (fault injection); returns those latched.

        As with an error the firmware finds itself, only the bits Shutdown(63) selects are reported
        and turn the torque off, and only REBOOT clears them.
        """
        self._fixed = False
        self.sensing_epoch += 1
        latched = bits & self._cmd.shutdown
        self._latch(bits)
        return latched

    def set_blocked(self, blocked: bool) -> None:
        """Hold the output shaft still (or free it): the motor keeps driving into the block, so the current rises
        to what the drive gives at stall, and the overload protection follows if that is high enough (:meth:`_protect`)."""
        self._fixed = False
        self.sensing_epoch += 1
        self.physics.blocked = bool(blocked)

    def hold_reading(self, name: str, value: int | None) -> None:
        """Pin a sensed register at ``value`` (register units), as a stuck sensor would; None frees it.

        Present Temperature and Present Input Voltage pinned outside their limits raise Overheating
        and Input Voltage errors as real readings do (each if Shutdown selects it).
        """
        if name not in XSensed.field_names():
            raise ValueError(f"{name!r} is not a sensed register; the firmware senses {', '.join(XSensed.field_names())}")
        self._fixed = False
        self.sensing_epoch += 1
        if value is None:
            self._held_readings.pop(name, None)
        else:
            self._held_readings[name] = int(value)
            self._check_readings()

    def set_external_torque(self, torque_nm: float) -> None:
        """A torque on the output shaft (N·m, positive = counter-clockwise), passed to the physics."""
        self._fixed = False
        self.sensing_epoch += 1
        self.physics.set_external_torque(torque_nm)

    def set_supply_v(self, supply_v: float) -> None:
        """The bus supply voltage (V): the motor's drive and Present Input Voltage follow it."""
        self._fixed = False
        self.sensing_epoch += 1
        self.physics.supply_v = float(supply_v)

    def set_load(self, *, inertia_kg_m2: float = 0.0, gravity_torque_nm: float = 0.0, gravity_zero_rad: float = 0.0) -> None:
        """What is on the horn (an inertia, a pendulum), passed to the physics."""
        self._fixed = False
        self.sensing_epoch += 1
        self.physics.set_load(inertia_kg_m2=inertia_kg_m2, gravity_torque_nm=gravity_torque_nm, gravity_zero_rad=gravity_zero_rad)


def build_x_servo(
    *,
    gear_ratio: float,
    ratings: Sequence[tuple[float, float, float, float]],
    current_unit_a: float | None,
    supply_v: float = 12.0,
    angle_rad: float = 0.0,
    step_s: float = 0.001,
    thermal: ThermalParams | None = None,
    overload_time_s: float = 1.0,
    position_output_scale: float = 1.0,
    motor: str = "cored",
    rotor_inertia_at_motor_kg_m2: float | None = None,
) -> XFirmware:
    """One X-series servo from its data-sheet numbers: :class:`XFirmware` over :class:`.physics.XPhysics`.

    ``ratings``: the data sheet's ``(voltage_v, stall_torque_nm, stall_current_a, no_load_speed_rpm)``
    rows (as in the model files); ``current_unit_a``: Goal/Present Current's unit in amperes (0.001
    on the XL330/XC330, 0.00269 on the XM430) or ``None`` on a model without current sensing (the
    XL430: Present Load in 0.1 % of the sheet's stall current at the rating nearest ``supply_v``);
    ``position_output_scale``: see :class:`XFirmware` (0.5 measured on the XL330, else 1); ``motor`` (the
    e-manual's "Motor" row, "cored" or "coreless") and ``rotor_inertia_at_motor_kg_m2`` (where a source gives
    it): the rotor, see :meth:`.physics.XPhysicsParams.from_datasheet`.
    """
    params = XPhysicsParams.from_datasheet(gear_ratio=gear_ratio, ratings=ratings, motor=motor,
                                           rotor_inertia_at_motor_kg_m2=rotor_inertia_at_motor_kg_m2)
    physics = XPhysics(params, supply_v=supply_v, angle_rad=angle_rad)
    nearest = min(ratings, key=lambda rating: abs(rating[0] - supply_v))
    return XFirmware(
        physics,
        current_unit_a=current_unit_a,
        load_full_scale_a=nearest[2],
        step_s=step_s,
        thermal=thermal,
        overload_time_s=overload_time_s,
        position_output_scale=position_output_scale,
    )
