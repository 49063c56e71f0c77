"""Motion phases: which part of a move each sample belongs to, so a gap can be located.

Why it exists: "the model is off by 3 units" helps nobody; "it is off while
braking and under load" points at inertia or a weak drive.  Phases are read
off the *commanded* motion (the setpoint generator run on the trace's
commands, :func:`firmware_model.setpoint.setpoint_step`), not off the
measurement, so they are the same for every candidate model and for the
measurement.  Precedence: under external load, reversing, then the
reference's own state.
"""

from __future__ import annotations

import numpy as np

from ..backend import SCALAR
from ..params import ServoParams
from ..setpoint import apply_dead_zone, setpoint_step
from ..units import RAD_PER_POSITION_UNIT
from .schedule import Schedule

__all__ = ["PHASES", "classify"]

#: Phase names, in report order.
PHASES = ("at_rest", "accelerating", "cruising", "braking", "settling", "reversing", "under_load")
#: After the reference stops, this long counts as settling.
SETTLE_S = 0.4
#: After the reference's direction flips, this long counts as reversing.
REVERSE_S = 0.3


def classify(schedule: Schedule, params: ServoParams = ServoParams()) -> np.ndarray:
    """Phase index (into :data:`PHASES`) of each row, shape (n,)."""
    dt, a = schedule.step_s, params.max_acceleration_rad_s2
    n = schedule.n_steps
    vel = np.zeros(n + 1)
    ext = np.zeros(n + 1)
    ref = schedule.initial_position_raw * float(RAD_PER_POSITION_UNIT)
    rv = 0.0
    for seg in schedule.segments:
        if seg.replan:
            ref = float(apply_dead_zone(ref, rv, seg.goal_rad, params.setpoint_eps_rad))
        for step in range(seg.first + 1, seg.last + 1):
            ref, rv = setpoint_step(SCALAR, ref, rv, seg.goal_rad, seg.max_speed_rad_s, a, dt)
            vel[step] = rv
        ext[seg.first + 1: seg.last + 1] = seg.external_torque_nm
    speed = np.abs(vel)
    dspeed = np.diff(speed, prepend=0.0)
    moving = speed > 1e-9
    code = np.where(dspeed > 1e-12, 1, np.where(dspeed < -1e-12, 3, 2))
    code = np.where(moving, code, 0)
    # settling: within SETTLE_S after the reference stopped
    last_moving = np.maximum.accumulate(np.where(moving, np.arange(n + 1), -10**9))
    code = np.where(~moving & (np.arange(n + 1) - last_moving <= SETTLE_S / dt), 4, code)
    # reversing: within REVERSE_S after the reference velocity changed sign
    sign = np.sign(vel)
    flips = np.zeros(n + 1, dtype=bool)
    nz = np.flatnonzero(sign != 0)
    if len(nz) > 1:
        flips[nz[1:][sign[nz[1:]] != sign[nz[:-1]]]] = True
    last_flip = np.maximum.accumulate(np.where(flips, np.arange(n + 1), -10**9))
    code = np.where(np.arange(n + 1) - last_flip <= REVERSE_S / dt, 5, code)
    code = np.where(ext != 0, 6, code)
    return code[schedule.sample_steps]
