"""Closed-loop replay of a BAM pendulum log: the logged goals through an X-series firmware model over its physics.

Why it exists: a motor and friction model is judged by what the real servo did under its own controller,
so the replay feeds the log's goals (and Torque Enable) to a firmware model exactly as the recorder sent
them to the real servo, as raw register writes at the times they were written, and reads Present Position
back when the recorder read it.  The firmware is a parameter (anything with the
:class:`.interface.XServoModel` methods, built over the :class:`.physics.XPhysics` handed to it), so the
control law lives in one place, the firmware model, and the replay only wires registers.

Set-up, as BAM's recorder left the servo (``bam/dynamixel/record.py``; Rhoban's ``Xl330PyController``):
Position Control Mode, Position P Gain = the log's ``kp``, the XL330's factory D and I gains (0, e-manual
XL330 control table "Position D Gain(80)" and "Position I Gain(82)" defaults) and no profile (Profile
Velocity 0), PWM Limit 885.  Positions in the log are radians about the middle of the encoder's turn
(raw 2048 reads 0 rad: a sample at rest reads -0.00307 rad, which is -2 pulses).  The pendulum hangs at
0 rad less an offset the fit finds (BAM's ``q_offset``: the arm is not mounted exactly at the encoder's
middle); its mass, length and arm mass come from the log (BAM's ``Pendulum``).

Timing, from the recorder's loop: it writes Goal Position (and Torque Enable when it changes), sleeps
1 ms, then reads Present Position, Velocity, PWM, Input Voltage and Temperature one after the other and
stamps the sample at the middle of the reads.  With torque off (no write, no sleep) the five reads take
the whole 3.5 ms period, so one read is about 0.7 ms: Present Position is read about 1.4 ms before the
stamp (:data:`READ_LEAD_S`) and the goal takes effect about 2.7 ms before it (:data:`GOAL_LEAD_S`: the
read's lead, the 1 ms sleep, half a write).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from .bam_log import PWM_FULL_SCALE, PendulumLog
from .closed_loop import Write, run_closed_loop
from .interface import OperatingMode, XCommands, XServoModel
from .physics import GRAVITY_M_S2, XPhysics, XPhysicsParams

__all__ = ["READ_LEAD_S", "GOAL_LEAD_S", "PULSES_PER_TURN", "MIDDLE_PULSES", "replay", "replay_positions", "recorder_commands"]

#: Present Position is read this long before the sample's stamp (see the module docstring).
READ_LEAD_S = 1.4e-3
#: A goal written for a sample takes effect this long before its stamp.
GOAL_LEAD_S = 2.7e-3
PULSES_PER_TURN = 4096
#: The raw position that reads 0 rad in the logs.
MIDDLE_PULSES = 2048
_RAD_PER_PULSE = 2.0 * math.pi / PULSES_PER_TURN


def recorder_commands(kp: int, goal_rad: float, torque_enable: bool) -> XCommands:
    """The registers as BAM's recorder leaves them for one sample (see the module docstring)."""
    return XCommands(
        torque_enable=int(torque_enable),
        operating_mode=OperatingMode.POSITION,
        goal_position=MIDDLE_PULSES + round(goal_rad / _RAD_PER_PULSE),
        position_p_gain=int(kp),
        position_i_gain=0,
        position_d_gain=0,
        goal_pwm=PWM_FULL_SCALE,
        pwm_limit=PWM_FULL_SCALE,
        profile_velocity=0,
        profile_acceleration=0,
        goal_current=1750,
        current_limit=1750,
        velocity_limit=445,
        min_position_limit=0,
        max_position_limit=PULSES_PER_TURN - 1,
        max_voltage_limit=140,
        min_voltage_limit=31,
        temperature_limit=70,
    )


def replay_positions(
    log: PendulumLog,
    params: XPhysicsParams,
    make_model: Callable[[XPhysics], XServoModel],
    *,
    gravity_zero_rad: float = 0.0,
    supply_resistance_ohm: float = 0.0,
) -> np.ndarray:
    """Present Position (rad, the log's frame) at each of the log's samples, replayed through ``make_model(physics)``.

    ``gravity_zero_rad``: where the pendulum hangs, in the log's frame.  The model starts at the log's
    first position, at rest, and is told each sample's goal and Torque Enable at the time the recorder
    wrote them.
    """
    return replay(log, params, make_model, gravity_zero_rad=gravity_zero_rad, supply_resistance_ohm=supply_resistance_ohm)[0]


def replay(
    log: PendulumLog,
    params: XPhysicsParams,
    make_model: Callable[[XPhysics], XServoModel],
    *,
    gravity_zero_rad: float = 0.0,
    supply_resistance_ohm: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """As :func:`replay_positions`, with Present PWM (register units) read at the same times."""
    start_rad = math.pi + float(log.position_rad[0])  # raw 2048 is half a turn from raw 0
    physics = XPhysics(params, supply_v=log.supply_v, angle_rad=start_rad, supply_resistance_ohm=supply_resistance_ohm)
    physics.set_load(inertia_kg_m2=log.inertia_kg_m2, gravity_torque_nm=log.gravity_moment_nm(GRAVITY_M_S2),
                     gravity_zero_rad=math.pi + gravity_zero_rad)
    model = make_model(physics)
    # The model's clock starts at 0; the log's first goal is written GOAL_LEAD_S before its first stamp.
    origin_s = float(log.time_s[0]) - GOAL_LEAD_S - model.step_s
    writes: list[Write] = []
    last: tuple[int, bool] | None = None
    for k, stamp in enumerate(log.time_s):
        enable = bool(log.torque_enable[k])
        commands = recorder_commands(log.kp, float(log.goal_position_rad[k]), enable)
        key = (commands.goal_position, enable)
        if key != last:
            # The recorder writes the goal only with torque on (and Torque Enable when it changes).
            writes.append(Write(stamp - GOAL_LEAD_S - origin_s, commands, goal_written=enable))
            last = key
    sensed = run_closed_loop(model, writes, [stamp - READ_LEAD_S - origin_s for stamp in log.time_s])
    out = np.array([(s.present_position - MIDDLE_PULSES) * _RAD_PER_PULSE for s in sensed])
    pwm = np.array([s.present_pwm for s in sensed], dtype=np.int64)
    return out, pwm
