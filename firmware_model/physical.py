"""The physical model of N AX-12+ servos behind the bus: firmware and physics stepped together.

Why it exists: it is the :class:`~firmware_model.interface.ServoModel` a
client should meet, with acceleration limits, overshoot, sag under load,
stalls, heating and the slow Present Speed / Load of the real servo.  It
wires the one-job modules together; each step is

    setpoint velocity (joint)  ->  reference and shaft move
    ->  controller drive (joint) or Moving Speed's output (wheel)
    ->  motor current and torque  ->  friction, stick-slip: the shaft's new speed

and every thermal period (10 ms) heating, the overload timer and Alarm
Shutdown, every sample period (``sample_hold_s``) the held Present Speed and
Load.

Alarm Shutdown (``Commands.shutdown``) acts at the thermal event an alarm it
selects is found, as the firmware's does at its control step (e-manual:
"the motor output becomes 0 % by resetting the value of Torque Limit(34) to
0"): the drive limit of that servo drops to 0 from the next step on, however
long the ``advance`` asked for, and ``Sensed.output_cut`` reports it until
that servo's Torque Limit, Torque Enable or Alarm Shutdown changes in the
commands (the bus writes the 0 it reports into them at once; a write to any
other register, or to another servo, leaves the cut as it is); a selected
alarm still there then cuts again at the next thermal event, as the firmware
cuts again a Torque Limit written while the alarm lasts.  The cut is Torque
Limit's (the bridge stays closed, and the overload timer runs on as it does
at a Torque Limit of 0); the 2006 manual's edition turns torque off instead
(built with ``shutdown_clears="torque_enable"``: the cut servo is driven as
with torque off), which the bus writes when it is shown the cut.

Integration is a fixed step (1 kHz by default), so results depend only on
the commands and the simulated times asked for, never on wall-clock speed.
``advance`` runs whole steps; the time asked for is rounded down to one.
Commands are decoded only when they change (the bus hands over the same
object until a register changes; otherwise their bytes are compared), and
the registers that change only at events are cached, so a call per step
stays cheap.  One servo runs on plain floats, more on numpy arrays
(:mod:`firmware_model.backend`); the numbers agree.  The step loop itself,
generic and fused for the usual configurations, is :mod:`firmware_model.stepping`.

Controllers: ``controller="compliance"`` (default, the e-manual's) or
``"pid"`` (the report's), see :mod:`firmware_model.controller`.

Joint mode: the controller sees the quantised position (``rint(angle /
unit)``, not pinned in the dead zone, where a driven servo never goes) and
the reference in units.  Goal Position is clamped to the angle limits (the firmware does not
move past them; the protocol side reports the Angle Limit error).  Moving
Speed 0 means the register's full scale, 114 rpm, which no supply reaches, so
the servo then runs at its top speed.  Wheel mode (both angle limits 0): the
lower ten bits of Moving Speed set the output, ``N / 1023`` of full drive
(the e-manual's 0.1 % a unit), bit 10 for CW, within Torque Limit; there is no
speed loop, so load slows the wheel.  The position wraps through the dead
zone.  With torque off the bridge is open and the reference follows the
shaft, so enabling torque never jumps.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, fields, replace

import numpy as np

from .backend import NUMPY, SCALAR
from .controller import PidGains, compliance_plan
from .interface import ALARM_INPUT_VOLTAGE, ALARM_OVERHEATING, ALARM_OVERLOAD, STEP_SLACK, Commands, Sensed
from .motor import GRAVITY_M_S2
from .params import ServoParams
from .protection import alarm_bits, overload_timer_step, thermal_step
from .sensors import DelayLine, LatchHistory, held_speed_rad_s, registers
from .setpoint import apply_dead_zone
from .stepping import Kernel, ModelState, PerServo, StepConstants, StepPlan, step_kernel
from .units import (
    DIRECTION_BIT,
    POSITION_MAX_RAW,
    POSITION_RANGE_RAD,
    RAD_PER_POSITION_UNIT,
    RAD_S_PER_SPEED_UNIT,
    position_rad_to_raw,
)

__all__ = ["PhysicalModel", "CONTROLLERS", "SHUTDOWN_CLEARS"]

#: Selectable position controllers.
CONTROLLERS = ("compliance", "pid")
#: Heating and the overload timer are updated this often.
THERMAL_PERIOD_S = 0.01
#: Moving Speed 0 in joint mode: the register's full scale, 114 rpm (e-manual).
FULL_SCALE_SPEED_RAD_S = float(1023 * RAD_S_PER_SPEED_UNIT)
_TWO_PI = 2.0 * math.pi
_COMMAND_FIELDS = Commands.field_names()
_RANGE_RAD, _UNIT_RAD = float(POSITION_RANGE_RAD), float(RAD_PER_POSITION_UNIT)
_STATE = tuple(f.name for f in fields(ModelState))
#: The alarm bits the model raises, the ones Alarm Shutdown can act on here.
_MODEL_ALARMS = ALARM_INPUT_VOLTAGE | ALARM_OVERHEATING | ALARM_OVERLOAD
#: The registers whose change ends a servo's Alarm Shutdown cut (module docstring).
_CUT_REGISTERS = ("torque_limit", "torque_enable", "shutdown")
#: What Alarm Shutdown's cut clears (PhysicalModel.shutdown_clears).
SHUTDOWN_CLEARS = ("torque_limit", "torque_enable")


@dataclass(frozen=True, slots=True, eq=False)
class _Sensing:
    """What :meth:`PhysicalModel.sense` and its alarms read of the commands, as numpy arrays of shape (N,)."""

    enabled: np.ndarray
    wheel: np.ndarray
    #: Wheel mode asked to turn (a speed other than 0).
    wheel_turning: np.ndarray
    goal_rad: np.ndarray
    temperature_limit: np.ndarray
    min_voltage_limit: np.ndarray
    max_voltage_limit: np.ndarray
    any_wheel: bool
    all_wheel: bool
    all_enabled: bool
    #: Moving as a read-only array of ones when it reads 1 whatever the shaft does (all driven wheels), else None.
    always_moving: np.ndarray | None


@dataclass(frozen=True, slots=True, eq=False)
class _Plan:
    """The commands decoded once per change: the step loop's plan and kernel, and what events and sense() read."""

    step: StepPlan
    kernel: Kernel
    sensing: _Sensing
    #: Drive at which the overload timer runs (the Torque Limit register, 0 where Alarm Shutdown cut it;
    #: infinite with torque off).
    overload_limit: PerServo
    #: The same from the registers alone, before any cut (a raised Torque Limit is judged against it; see _plan).
    register_limit: np.ndarray
    #: Per servo, the alarm bits that cut its output now (Alarm Shutdown's, where torque is on, Torque Limit
    #: above 0 and not cut yet); None where no servo has any (nothing to check at the events).
    shutdown_bits: np.ndarray | None


def _per_servo(values, n: int) -> np.ndarray:
    """``values`` as an array of shape (n,): as it is when it has that shape (the usual case, and
    ``broadcast_to`` costs about 10 us a call), else broadcast."""
    array = np.asarray(values)
    return array if array.shape == (n,) else np.broadcast_to(array, (n,))


def _wheel_speed_is_the_output(regs: dict[str, np.ndarray], sensing: _Sensing | None) -> None:
    """In wheel mode Present Speed reads the output, as Present Load does (e-manual, Present Speed: "Wheel Mode:
    The unit is about 0.1%. For example, if it is set to 512, it means that the torque is controlled by 50% of
    the maximum torque to the CCW direction"); in joint mode the shaft's speed.  ``regs`` is changed in place."""
    if sensing is not None and sensing.any_wheel:
        regs["present_speed"] = np.where(sensing.wheel, regs["present_load"], regs["present_speed"])


def _position_raw(angle_rad: float) -> int:
    """:func:`~firmware_model.units.position_rad_to_raw` for one float (tests check they agree)."""
    wrapped = angle_rad % _TWO_PI
    if wrapped > _RANGE_RAD:
        return POSITION_MAX_RAW if wrapped - _RANGE_RAD < _TWO_PI - wrapped else 0
    return min(max(round(wrapped / _UNIT_RAD), 0), POSITION_MAX_RAW)


class PhysicalModel:
    """N servos with firmware and physics; implements :class:`~firmware_model.interface.ServoModel`."""

    def __init__(
        self,
        n: int,
        params: ServoParams = ServoParams(),
        step_s: float = 1e-3,
        initial_position_raw: int | np.ndarray = 512,
        *,
        controller: str = "compliance",
        pid_gains: PidGains = PidGains(),
        backend: str = "auto",
        fused: bool = True,
        shutdown_clears: str = "torque_limit",
    ) -> None:
        if n < 1:
            raise ValueError(f"need at least one servo, got n={n}")
        if not step_s > 0:
            raise ValueError(f"step_s must be positive, got {step_s}")
        if controller not in CONTROLLERS:
            raise ValueError(f"controller must be one of {CONTROLLERS}, got {controller!r}")
        if backend not in ("auto", "numpy", "scalar") or (backend == "scalar" and n != 1):
            raise ValueError(f"backend must be 'auto', 'numpy' or (for n=1) 'scalar', got {backend!r}")
        if shutdown_clears not in SHUTDOWN_CLEARS:
            raise ValueError(f"shutdown_clears must be one of {SHUTDOWN_CLEARS}, got {shutdown_clears!r}")
        self._shutdown_clears = shutdown_clears
        self.n = n
        self.params = params
        self.step_s = step_s
        self.controller = controller
        self.pid_gains = pid_gains
        #: Whether the usual configuration runs the fused kernels (False: always the generic loop, for comparison).
        self.fused = fused
        self._k = StepConstants.from_params(params, step_s, controller, pid_gains)
        self.time_s = 0.0
        self._steps = 0
        self._xp = SCALAR if (backend == "scalar" or (backend == "auto" and n == 1)) else NUMPY
        self._thermal_steps = max(1, round(THERMAL_PERIOD_S / step_s))
        self._thermal_period_s = self._thermal_steps * step_s
        self._thermal_decay = math.exp(-self._thermal_period_s / (params.thermal_resistance_k_w * params.heat_capacity_j_k))
        #: Steady-state rise per A**2 summed over a period's steps: R R_th / steps.
        self._rise_k_per_a2_sum = params.winding_resistance_ohm * params.thermal_resistance_k_w / self._thermal_steps
        self._hold_steps = max(1, round(params.sample_hold_s / step_s))
        self.supply_voltage_v = params.supply_voltage_v
        angle = np.broadcast_to(np.asarray(initial_position_raw, dtype=float) * RAD_PER_POSITION_UNIT, (n,)).copy()
        zeros = np.zeros(n)
        values = {name: zeros.copy() for name in _STATE}
        values.update(angle=angle, ref=angle.copy(), sample_angle=angle.copy(), out=angle.copy(),
                      temperature=np.full(n, params.ambient_temperature_c))
        fx = params.effects
        if fx.arm_weight_moment_nm:  # an arm on every shaft, until set_arm replaces it
            values["weight_nm"] = np.full(n, fx.arm_weight_moment_nm)
        self._s = ModelState(**{k: self._to_backend(v) for k, v in values.items()})
        self._init_effects(fx, angle)
        #: Decoded commands, keyed by the registers' bytes (and the object, for a quick check).
        self._plan_cache: tuple[bytes, _Plan] | None = None
        self._plan_commands: Commands | None = None
        #: Registers for sense() that change only at events (held speed/load, temperature, alarms).
        self._slow: dict[str, np.ndarray] | None = None
        #: Rounded temperatures and overload flags at the last thermal event (see _thermal_event).
        self._thermal_key: tuple[bytes, bytes] | None = None
        self._sensing: _Sensing | None = None
        #: The commands the present plan was decoded from (an Alarm Shutdown decodes them again).
        self._plan_source: Commands | None = None
        #: Servos whose output Alarm Shutdown cut, and their Torque Limit, Torque Enable and Alarm Shutdown
        #: then (rows, _CUT_REGISTERS): a cut holds until one of its servo's changes (module docstring).
        self._cut = np.zeros(n, dtype=bool)
        self._cut_registers = np.zeros((n, len(_CUT_REGISTERS)), dtype=np.int64)
        #: The overload timer's limit from the present plan's registers, before any cut (see _plan).
        self._overload_limit = np.full(n, np.inf)
        #: The plan whose alarms were last checked against Alarm Shutdown.
        self._shutdown_checked: _Plan | None = None

    def _init_effects(self, fx, angle: np.ndarray) -> None:
        """Constants and state of the effects in ``params.effects`` (None where absent: the plain model)."""
        play = fx.value("backlash_rad", 0.0)
        #: Half the gear play (the output sits within it of the motor side), or None.
        self._half_play_rad = play / 2.0 if play else None
        #: Drive ceiling (fraction of full) below any Torque Limit, or None.
        self._drive_ceiling = fx.drive_ceiling_fraction if fx.value("drive_ceiling_fraction", 1.0) < 1.0 else None
        self._extra_margin_units = fx.value("extra_compliance_margin_units", 0.0)
        offset, gain = fx.value("position_offset_units", 0.0), fx.value("position_gain", 1.0)
        #: Present Position's scale and offset, (gain, 511.5 (1 - gain) + offset), or None.
        self._position_map = (gain, 511.5 * (1.0 - gain) + offset) if (gain != 1.0 or offset != 0.0) else None
        self._speed_gain = gain if gain != 1.0 else None
        delay_steps = fx.value("sensing_delay_s", 0.0) / self.step_s
        self._delay_line = DelayLine(delay_steps, angle) if delay_steps > 0 else None
        self._latches = (LatchHistory(int(math.ceil(delay_steps / self._hold_steps)) + 2, self.n)
                         if self._delay_line is not None else None)
        #: Steps between a command reaching the model and the firmware acting on it (0: at once).
        self._command_delay_steps = round(fx.value("command_delay_s", 0.0) / self.step_s)
        #: Commands received but not yet acted on: (step they act from, key, commands), oldest first.
        self._pending: deque[tuple[int, bytes, Commands]] = deque()
        self._acting: Commands | None = None
        self._latest_key: bytes | None = None
        #: Whether sense() reads anything but the plain registers at the present step.
        self._effect_sense = (self._half_play_rad is not None or self._delay_line is not None
                              or self._position_map is not None)

    @property
    def shutdown_clears(self) -> str:
        """What Alarm Shutdown's cut is, as the table's edition says (module docstring): "torque_limit" (the
        e-manual: Torque Limit 0, torque stays on) or "torque_enable" (the 2006 manual: torque off).  Fixed when the
        model is built: a cut decoded under one edition and held under another would be neither's."""
        return self._shutdown_clears

    # ------------------------------------------------------------------ run-time inputs
    def set_supply_voltage(self, volts: float) -> None:
        """Change the supply (V); must lie in the parameters' valid range."""
        self.params.check_supply(float(volts))
        self.supply_voltage_v = float(volts)
        self._plan_cache = self._slow = None

    def set_external_torque(self, torque_nm: np.ndarray) -> None:
        """Set a constant torque on each output shaft (N m, positive = CCW), added to any arm's gravity."""
        self._s.ext_nm = self._to_backend(np.broadcast_to(np.asarray(torque_nm, dtype=float), (self.n,)))
        self._plan_cache = None

    @property
    def external_torque_nm(self) -> np.ndarray:
        """The torque :meth:`set_external_torque` put on each shaft (a copy), so a caller can change one servo's."""
        return np.asarray(self._array("ext_nm"), dtype=float)

    def set_arm(self, mass_kg, length_m) -> None:
        """Hang an arm (point mass at ``length_m``) on each shaft; convention in :mod:`firmware_model.motor`.

        It replaces any arm the parameters' effects hung (``arm_weight_moment_nm``).
        """
        moment = np.asarray(mass_kg, dtype=float) * GRAVITY_M_S2 * np.asarray(length_m, dtype=float)
        if np.any(moment < 0):
            raise ValueError("arm mass and length must be >= 0")
        self._s.weight_nm = self._to_backend(np.broadcast_to(moment, (self.n,)))
        self._plan_cache = None

    def set_blocked(self, blocked) -> None:
        """Block (True) or free each output shaft, as a hand or an obstacle holding the horn.

        A blocked shaft does not turn whatever the motor does, so the controller
        keeps driving, the drive saturates and the overload timer runs, as on a
        real servo pushing against a stop.
        """
        mask = np.broadcast_to(np.asarray(blocked, dtype=bool), (self.n,))
        self._s.blocked = self._to_backend(mask.astype(float))
        if mask.any():
            self._s.speed = self._to_backend(np.where(mask, 0.0, self._array("speed")))
        self._plan_cache = None

    def set_angle(self, index: int, angle_rad: float) -> None:
        """Put shaft ``index`` at ``angle_rad`` (by hand), at rest; the reference follows it, so nothing jumps."""
        values = {name: self._array(name) for name in ("angle", "speed", "ref", "ref_vel", "sample_angle", "out")}
        values["angle"][index] = values["ref"][index] = values["sample_angle"][index] = float(angle_rad)
        values["out"][index] = float(angle_rad)  # gear play taken up on neither side
        values["speed"][index] = values["ref_vel"][index] = 0.0
        for name, array in values.items():
            setattr(self._s, name, self._to_backend(array))
        self._slow = None
        self._plan_cache = None

    # ------------------------------------------------------------------ state views
    @property
    def angle_rad(self) -> np.ndarray:
        """Output shaft (horn) angles, radians from the CW end, wrapped to [0, 2 pi); with gear play, the
        output side's."""
        return np.mod(self._array("angle" if self._half_play_rad is None else "out"), _TWO_PI)

    @property
    def speed_rad_s(self) -> np.ndarray:
        """True shaft speeds (not the held register), rad/s, positive CCW."""
        return self._array("speed")

    @property
    def reference_rad(self) -> np.ndarray:
        """The setpoint generator's reference, radians."""
        return self._array("ref")

    @property
    def drive(self) -> np.ndarray:
        """Present controller output, duty in [-1, 1]."""
        return self._array("drive")

    @property
    def temperature_c(self) -> np.ndarray:
        """Thermal node temperature, degrees C (unrounded)."""
        return self._array("temperature")

    # ------------------------------------------------------------------ the seam
    def advance(self, to_time_s: float, commands: Commands) -> Sensed:
        """Step from ``time_s`` to ``to_time_s`` (whole steps) holding ``commands``; return the sensors."""
        self.step_to(to_time_s, commands)
        return self.sense()

    def step_to(self, to_time_s: float, commands: Commands) -> None:
        """:meth:`advance` without reading the sensors."""
        # A step due within a millionth of a step (1 ns at 1 kHz) is taken: a caller's clock sums its own floats, and
        # one that finds a step due by that slack (the bus's grid) must get it, or a write's earned step is lost.
        target = int(math.floor(to_time_s / self.step_s + STEP_SLACK))
        if self._command_delay_steps:
            self._step_delayed(target, commands)
            return
        plan = self._cached_plan(commands)
        if target > self._steps:
            self._run(plan, self._steps, target)
            self._steps = target
            self.time_s = self._steps * self.step_s

    def _step_delayed(self, target: int, commands: Commands) -> None:
        """:meth:`step_to` when the firmware acts on commands ``command_delay_s`` after they arrive.

        Until the first commands act the servo is inert (at rest, nothing driven).
        """
        key = self._commands_key(commands)
        if key != self._latest_key:  # a copy: the caller may change its arrays in place
            copy = Commands(**{name: np.array(getattr(commands, name)) for name in _COMMAND_FIELDS})
            self._pending.append((self._steps + self._command_delay_steps, key, copy))
            self._latest_key = key
        step = self._steps
        while step < target:
            while self._pending and self._pending[0][0] <= step:
                self._acting = self._pending.popleft()[2]
            stop = min(target, self._pending[0][0]) if self._pending else target
            if self._acting is None:
                if self._delay_line is not None:
                    self._delay_line.repeat(stop - step)
            else:
                self._run(self._cached_plan(self._acting), step, stop)
            step = stop
        if target > self._steps:
            self._steps = target
            self.time_s = self._steps * self.step_s
        if self._acting is not None:
            self._cached_plan(self._acting)  # sense() reads the acting plan's limits

    def sense(self) -> Sensed:
        """The registers at ``time_s`` without advancing."""
        if self._effect_sense:
            return self._sense_effects()
        return self._sense_plain()

    def _sense_effects(self) -> Sensed:
        """:meth:`sense` with gear play, a sensing delay or a position offset / gain.

        The same rules as the diagnosis's batched simulator
        (:func:`firmware_model.diagnose.batch.sample`): the delayed angle
        interpolated between steps, then ``gain x + offset`` in units, rounded and
        pinned to 0..1023; speed and load from the latch at or before the delayed step.
        """
        plain = self._sense_plain()
        seen = self._array("angle" if self._half_play_rad is None else "out")
        changes = {}
        if self._delay_line is not None:
            seen, step = self._delay_line.read()
            held_speed, held_drive = self._latches.at(step)
            regs = registers(held_speed, held_drive, self.supply_voltage_v, self._array("temperature"))
            _wheel_speed_is_the_output(regs, self._sensing)
            changes.update(present_speed=regs["present_speed"], present_load=regs["present_load"])
        x = seen / _UNIT_RAD
        c = self._sensing
        wheel = c.wheel if (c is not None and c.any_wheel) else None
        if wheel is not None:  # endless turns: through the dead zone as the plain reading does
            x = np.where(wheel, position_rad_to_raw(seen).astype(float), x)
        if self._position_map is not None:
            gain, shift = self._position_map
            x = x * gain + shift
        changes["present_position"] = np.clip(np.rint(x), 0, POSITION_MAX_RAW).astype(np.int64)
        return replace(plain, **changes)

    def _sense_plain(self) -> Sensed:
        """The registers at ``time_s``, with no effect on the readings."""
        if self._slow is None:
            self._slow = self._slow_registers()
        slow = self._slow  # read-only arrays, shared until the next event: no copy per call
        c = self._sensing
        if self._xp is SCALAR:  # one servo: plain Python is several times cheaper than numpy here
            st = self._s
            busy = ((c.wheel_turning[0] if c.wheel[0] else abs(st.ref_vel) > 1e-9 or abs(c.goal_rad[0] - st.ref) > 1e-9)
                    if c is not None else False)
            moving = int(c is not None and c.enabled[0] and (busy or abs(st.speed) > RAD_S_PER_SPEED_UNIT))
            return Sensed(present_position=np.array([_position_raw(st.angle)], dtype=np.int64),
                          moving=np.array([moving], dtype=np.int64), **slow)
        st = self._s
        if c is None:
            moving = np.zeros(self.n, dtype=np.int64)
        elif c.always_moving is not None:
            moving = c.always_moving
        else:
            # Joint mode: the reference still travelling, or not yet at the goal (reversing
            # toward a new goal, its velocity passes through 0 for a step mid-move).
            if not c.any_wheel:
                busy = (np.abs(st.ref_vel) > 1e-9) | (np.abs(c.goal_rad - st.ref) > 1e-9)
            elif c.all_wheel:
                busy = c.wheel_turning
            else:
                busy = np.where(c.wheel, c.wheel_turning, (np.abs(st.ref_vel) > 1e-9) | (np.abs(c.goal_rad - st.ref) > 1e-9))
            busy = busy | (np.abs(st.speed) > RAD_S_PER_SPEED_UNIT)
            moving = (busy if c.all_enabled else c.enabled & busy).astype(np.int64)
        if c is not None and c.any_wheel:  # endless turns: some shaft is usually in the gap
            return Sensed(present_position=position_rad_to_raw(st.angle), moving=moving, **slow)
        raw = np.rint(st.angle / _UNIT_RAD).astype(np.int64)
        # All round to 0..1023 (negatives wrap to huge as unsigned): on the track, or within half a
        # unit of an end, where the general conversion gives the same.
        if raw.view(np.uint64).max() <= POSITION_MAX_RAW:
            return Sensed(present_position=raw, moving=moving, **slow)
        return Sensed(present_position=position_rad_to_raw(st.angle), moving=moving, **slow)

    def _slow_registers(self) -> dict[str, np.ndarray]:
        """Present Speed / Load / Voltage / Temperature and the alarms, recomputed after an event."""
        regs = registers(self._array("held_speed"), self._array("held_drive"), self.supply_voltage_v,
                         self._array("temperature"))
        c = self._sensing
        _wheel_speed_is_the_output(regs, c)
        if c is None:
            regs["alarms"] = np.zeros(self.n, dtype=np.int64)
        else:
            regs["alarms"] = alarm_bits(regs["present_temperature"], c.temperature_limit, self._array("overload_timer"),
                                        self.params.overload_delay_s, self.supply_voltage_v,
                                        c.min_voltage_limit, c.max_voltage_limit)
        regs["output_cut"] = self._cut.astype(np.int64)
        for array in regs.values():
            array.flags.writeable = False  # handed to every sense() caller until the next event
        return regs

    # ------------------------------------------------------------------ internals
    def _to_backend(self, values: np.ndarray):
        return float(values[0]) if self._xp is SCALAR else np.array(values, dtype=float)

    def _array(self, name: str) -> np.ndarray:
        value = getattr(self._s, name)
        return np.array([value]) if self._xp is SCALAR else value.copy()

    @staticmethod
    def _commands_key(commands: Commands) -> bytes:
        """The command registers' bytes: equal keys, equal plans."""
        return b"".join([np.ascontiguousarray(getattr(commands, name), dtype=np.int64).tobytes() for name in _COMMAND_FIELDS])

    def _cached_plan(self, commands: Commands) -> _Plan:
        """The decoded plan, rebuilt only when a register, the supply or an external load changed."""
        if self._plan_cache is not None and commands is self._plan_commands:
            return self._plan_cache[1]  # the bus hands over the same object until a register changes
        key = self._commands_key(commands)
        if self._plan_cache is None or self._plan_cache[0] != key:
            if self._cut.any():  # a cut servo's own registers, written since, say what its output is
                held = (self._cut_registers_of(commands) == self._cut_registers).all(axis=1)
                self._cut = self._cut & held
            self._plan_source = commands
            self._plan_cache = (key, self._plan(commands))
            self._sensing, self._slow = self._plan_cache[1].sensing, None
        self._plan_commands = commands
        return self._plan_cache[1]

    def _plan(self, c: Commands) -> _Plan:
        """Decode the command registers into per-servo constants for the step loop (and restart references)."""
        plan = self._decode(c)
        self._restart_reference(plan)
        # A Torque Limit raised (written again after an Alarm Shutdown, say) is judged afresh: the overload
        # timer restarts, so the firmware drives for the overload delay before it finds the overload again.
        # Raised against the register's previous value, not against a cut's 0: a cut is no register write.
        limit = plan.register_limit
        raised = limit > self._overload_limit
        if raised.any():
            self._s.overload_timer = self._to_backend(np.where(raised, 0.0, self._array("overload_timer")))
        self._overload_limit = limit
        return plan

    def _cut_registers_of(self, c: Commands) -> np.ndarray:
        """Per servo, the registers whose change ends its cut (rows, _CUT_REGISTERS)."""
        return np.stack([_per_servo(getattr(c, name), self.n).astype(np.int64) for name in _CUT_REGISTERS], axis=1)

    def _decode(self, c: Commands) -> _Plan:
        """The command registers as per-servo constants for the step loop, under any Alarm Shutdown's cut."""
        p, n = self.params, self.n
        raw = {name: _per_servo(getattr(c, name), n) for name in _COMMAND_FIELDS}
        enabled = raw["torque_enable"] != 0
        cut = self._cut
        on_register = enabled  # Torque Enable as written (the overload limit a raise is judged against)
        if self._shutdown_clears == "torque_enable" and cut.any():  # the 2006 edition's cut: torque off
            enabled, cut = enabled & ~cut, np.zeros(n, dtype=bool)
        wheel = (raw["cw_angle_limit"] == 0) & (raw["ccw_angle_limit"] == 0)
        speed_raw = raw["moving_speed"].astype(np.int64)
        magnitude = (speed_raw & 0x3FF) * RAD_S_PER_SPEED_UNIT
        goal_raw = np.clip(raw["goal_position"], raw["cw_angle_limit"], np.maximum(raw["ccw_angle_limit"], raw["cw_angle_limit"]))
        comp = compliance_plan(raw["cw_compliance_margin"], raw["ccw_compliance_margin"], raw["cw_compliance_slope"],
                               raw["ccw_compliance_slope"], raw["punch"], raw["torque_limit"])
        uncut_limit = np.where(on_register, comp.limit, np.inf)
        if cut.any():  # Alarm Shutdown has set Torque Limit to 0 (the commands may not show it yet)
            comp.limit = np.where(cut, 0.0, comp.limit)
        register_limit = comp.limit  # the firmware's overload check compares with the register
        if self._extra_margin_units:  # a dead band wider than the registers say
            comp.cw_margin = comp.cw_margin + self._extra_margin_units
            comp.ccw_margin = comp.ccw_margin + self._extra_margin_units
        if self._drive_ceiling is not None:  # the drive tops out below full whatever Torque Limit says
            comp.limit = np.minimum(comp.limit, self._drive_ceiling)
        volts = self.supply_voltage_v
        # Wheel mode is output control, not speed (e-manual, Moving Speed: "In Wheel Mode, only the output control
        # is possible, not speed ... if it is set to 512, it means the output is controlled by 50% of the maximum
        # output"; the 2006-era RX-64 manual's Endless Turn: "no speed control function").  The 2008 report calls
        # the mode velocity controlled, which the e-manual, the authority on what a register means, contradicts.
        output = (speed_raw & 0x3FF) / 1023.0
        per_servo = dict(
            goal_rad=goal_raw * RAD_PER_POSITION_UNIT,
            max_speed_rad_s=np.where((speed_raw & 0x3FF) == 0, FULL_SCALE_SPEED_RAD_S, magnitude),
            wheel_output=np.where(speed_raw & DIRECTION_BIT, -output, output), cw_margin=comp.cw_margin, ccw_margin=comp.ccw_margin,
            cw_gain=comp.cw_gain, ccw_gain=comp.ccw_gain, punch=comp.punch, limit=comp.limit,
            en=enabled.astype(float), stall_current_a=np.where(enabled, volts / p.winding_resistance_ohm, 0.0),
        )
        wheel_turning = (speed_raw & 0x3FF) != 0
        all_wheel = bool(wheel.all())
        always_moving = None
        if all_wheel and bool((enabled & wheel_turning).all()):
            # Every servo driven at a speed in wheel mode: Moving is 1 whatever the shaft does, so
            # sense() hands over this one read-only array (the plant then need not rewrite it).
            always_moving = np.ones(n, dtype=np.int64)
            always_moving.flags.writeable = False
        sensing = _Sensing(
            enabled=enabled, wheel=wheel, wheel_turning=wheel_turning, goal_rad=goal_raw * RAD_PER_POSITION_UNIT,
            temperature_limit=raw["temperature_limit"].copy(), min_voltage_limit=raw["min_voltage_limit"].copy(),
            max_voltage_limit=raw["max_voltage_limit"].copy(), any_wheel=bool(wheel.any()), all_wheel=all_wheel,
            all_enabled=bool(enabled.all()), always_moving=always_moving,
        )
        step_plan = StepPlan(
            **{k: self._to_backend(v.astype(float)) for k, v in per_servo.items()},
            **(dict(enabled=bool(enabled[0]), wheel=bool(wheel[0])) if self._xp is SCALAR
               else dict(enabled=enabled, wheel=wheel)),
            any_wheel=sensing.any_wheel, any_joint=not all_wheel, any_disabled=bool((~enabled).any()),
            any_arm=bool(np.any(self._array("weight_nm") != 0)), any_ext=bool(np.any(self._array("ext_nm") != 0)),
            any_blocked=bool(np.any(self._array("blocked") != 0)),
            symmetric=bool(np.all(comp.cw_margin == comp.ccw_margin) and np.all(comp.cw_gain == comp.ccw_gain)),
            half_play_rad=self._half_play_rad, history=self._delay_line,
        )
        overload_limit = np.where(enabled, register_limit, np.inf)  # torque off cannot overload
        # Alarm Shutdown can cut a driven output not cut already (where Torque Limit is 0 there is nothing to cut).
        can_cut = enabled & (register_limit > 0.0)
        shutdown_bits = np.where(can_cut, raw["shutdown"].astype(np.int64) & _MODEL_ALARMS, 0)
        return _Plan(step=step_plan, kernel=step_kernel(self._xp, step_plan, self._k, self._s, self.fused),
                     sensing=sensing, overload_limit=self._to_backend(overload_limit.astype(float)),
                     register_limit=uncut_limit.astype(float), shutdown_bits=shutdown_bits if shutdown_bits.any() else None)

    def _restart_reference(self, plan: _Plan) -> None:
        """Where a new plan leaves wheel mode or torque off, the reference restarts at the shaft; a goal within
        ``setpoint_eps_rad`` of a resting reference is taken as reached."""
        n, p = self.n, self.params
        wheel, goal_rad = plan.sensing.wheel, plan.sensing.goal_rad
        # In wheel mode the reference is unused; entering or leaving it restarts the reference at the shaft.
        was_wheel = self._sensing.wheel if self._sensing is not None else np.zeros(n, dtype=bool)
        restart = wheel | was_wheel
        ref = np.where(restart, self._array("angle"), self._array("ref"))
        ref_vel = np.where(restart, 0.0, self._array("ref_vel"))
        # A reference that followed the shaft (torque off, or wheel mode) starts from the pot as the controller
        # reads it, in whole units: the shaft may sit between two readings, and a goal written as the Present
        # Position just read then sent the reference travelling that fraction (Moving 1 for some 7 ms with
        # nothing moving).  With torque on the reference is the setpoint's, and is left where it is.
        was_off = ~self._sensing.enabled if self._sensing is not None else np.zeros(n, dtype=bool)
        ref = np.where(restart | was_off, np.rint(ref / _UNIT_RAD) * _UNIT_RAD, ref)
        self._s.ref = self._to_backend(apply_dead_zone(ref, ref_vel, goal_rad, p.setpoint_eps_rad))
        self._s.ref_vel = self._to_backend(ref_vel)

    def _run(self, plan: _Plan, first: int, last: int) -> None:
        """Steps ``first + 1 .. last``: the plan's kernel between events, the periodic events at their steps."""
        thermal_steps, hold_steps = self._thermal_steps, self._hold_steps
        step = first
        while step < last:
            stop = min(last, (step // thermal_steps + 1) * thermal_steps)
            plan.kernel(self._s, stop - step)
            step = stop
            if step % thermal_steps == 0:
                slow_changed = self._thermal_event(plan)
                if plan.shutdown_bits is not None and (slow_changed or plan is not self._shutdown_checked):
                    plan = self._shutdown_event(plan)  # an alarm found now cuts the drive from the next step
                if step % hold_steps == 0:
                    self._sample_event(step)
                    slow_changed = True
                if slow_changed:
                    self._slow = None

    def _thermal_event(self, plan: _Plan) -> bool:
        """Heating, the overload timer and angle wrapping, once per thermal period.

        Returns whether a register it feeds (Present Temperature in whole degrees, the
        overload alarm) may have changed, so ``sense`` recomputes them only then.
        """
        xp, p, s = self._xp, self.params, self._s
        period = self._thermal_period_s
        s.temperature = thermal_step(xp, s.temperature, s.current_sq_sum * self._rise_k_per_a2_sum,
                                     p.ambient_temperature_c, self._thermal_decay)
        if xp is SCALAR:
            s.current_sq_sum = 0.0
        else:  # in place: the fused kernel owns this array and need not copy a new one in
            s.current_sq_sum.fill(0.0)
        s.overload_timer = overload_timer_step(xp, s.overload_timer, s.demand, plan.overload_limit, s.drive, s.speed,
                                               p.stall_speed_rad_s, period)
        # Only wheel mode turns endlessly; a joint-mode shaft keeps a continuous angle, so an
        # overshoot below 0 reads as a small negative error, not as a jump to the far end.
        if plan.step.any_wheel:
            turns = np.asarray(s.angle / _TWO_PI)
            if turns.min() < 0.0 or turns.max() >= 1.0:  # some shaft is a turn off (else all stay bound as they are)
                shift = xp.where(plan.step.wheel, xp.floor(turns if xp is NUMPY else float(turns)) * _TWO_PI, 0.0 * s.angle)
                s.angle, s.sample_angle, s.ref, s.out = s.angle - shift, s.sample_angle - shift, s.ref - shift, s.out - shift
                if self._delay_line is not None:
                    self._delay_line.shift(shift)
        key = (np.rint(s.temperature).tobytes(), np.asarray(s.overload_timer >= p.overload_delay_s - 1e-9).tobytes())
        changed = key != self._thermal_key
        self._thermal_key = key
        return changed

    def _shutdown_event(self, plan: _Plan) -> _Plan:
        """Alarm Shutdown at a thermal event: the plan to run on, with the drive limit cut to 0 where an alarm it
        selects is present now (the alarms ``sense`` would report at this step)."""
        self._shutdown_checked = plan
        c, s = plan.sensing, self._s
        present_c = np.clip(np.rint(np.asarray(s.temperature, dtype=float)), 0, 255)  # as sensors.registers
        bits = alarm_bits(present_c, c.temperature_limit, np.asarray(s.overload_timer, dtype=float),
                          self.params.overload_delay_s, self.supply_voltage_v, c.min_voltage_limit, c.max_voltage_limit)
        trips = (bits & plan.shutdown_bits) != 0
        if not trips.any():
            return plan
        source, cache = self._plan_source, self._plan_cache
        assert source is not None and cache is not None  # the plan running was decoded from them
        self._cut = self._cut | trips
        self._cut_registers[trips] = self._cut_registers_of(source)[trips]
        plan = self._decode(source)  # the same commands under the cut; the reference goes on as it was
        self._plan_cache = (cache[0], plan)
        self._sensing, self._slow = plan.sensing, None
        self._shutdown_checked = plan
        return plan

    def _sample_event(self, step: int) -> None:
        """Latch Present Speed and Present Load, once per sample period (``step``: the step it is taken at)."""
        s = self._s
        seen = s.angle if self._half_play_rad is None else s.out  # the pot sits on the output
        s.held_speed = held_speed_rad_s(seen, s.sample_angle, self._hold_steps * self.step_s)
        if self._speed_gain is not None:  # the position's scale error scales the speed computed from it
            s.held_speed = s.held_speed * self._speed_gain
        # Copies: the fused kernel updates the state arrays in place.
        s.held_drive = s.drive if self._xp is SCALAR else s.drive.copy()
        s.sample_angle = seen if self._xp is SCALAR else seen.copy()
        if self._latches is not None:
            self._latches.add(step, s.held_speed, s.held_drive)
