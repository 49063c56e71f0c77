"""A BAM pendulum log (:mod:`firmware_model.xseries.bam_log`) as an X-series diagnosis trace.

Why it exists: the diagnosis reads one trace format (:mod:`.trace`); Rhoban's BAM logs of a real XL330
are the X-series recordings there are, so they are converted to it, in the servo's own units, with the
timing of BAM's recorder (:mod:`firmware_model.xseries.bam_replay`: each sample's goal written
:data:`~firmware_model.xseries.bam_replay.GOAL_LEAD_S` before its stamp, Present Position read
:data:`~firmware_model.xseries.bam_replay.READ_LEAD_S` before it), so the diagnosis replays a log as
the BAM replay does.  The data sheet is the caller's (the model files are the protocol side's, which
this package does not read): ``tools/bam_to_trace.py`` takes it from the servo's model file.

Columns: ``t`` (the Present Position read), ``goal_position`` and ``present_position`` (pulses, raw
2048 at the log's 0 rad), ``present_velocity`` (0.229 rpm), ``present_pwm`` (the log's ``load``),
``torque_enable`` and ``command_t``.  Metadata: the data sheet, Position P Gain = the log's ``kp``
(I and D 0, no profile: BAM's recorder), the supply (the log's ``vin``) and the pendulum (its inertia
and ``m g l``, hanging at raw 2048: the arm's own offset from there is BAM's ``q_offset``, which the
diagnosis sees as a sensor offset).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..xseries.bam_log import PendulumLog
from ..xseries.bam_replay import GOAL_LEAD_S, MIDDLE_PULSES, READ_LEAD_S
from ..xseries.firmware import PULSE_RAD
from ..xseries.physics import GRAVITY_M_S2
from ..xseries.profile import VELOCITY_UNIT_PULSES_S
from .trace import Trace

__all__ = ["bam_trace"]


def bam_trace(log: PendulumLog, *, model: str, gear_ratio: float, ratings: Sequence[Sequence[float]],
              current_unit_a: float | None, position_output_scale: float = 1.0) -> Trace:
    """``log`` as an X-series trace; the data sheet (``gear_ratio``, ``ratings`` as in the model files) is the caller's."""
    stamps = np.asarray(log.time_s, dtype=float)
    goal = MIDDLE_PULSES + np.rint(log.goal_position_rad / PULSE_RAD).astype(np.int64)
    position = MIDDLE_PULSES + np.rint(log.position_rad / PULSE_RAD).astype(np.int64)
    velocity = np.rint(log.speed_rad_s / (VELOCITY_UNIT_PULSES_S * PULSE_RAD)).astype(np.int64)
    meta = {
        "servo": "x", "model": model, "gear_ratio": float(gear_ratio), "ratings": [list(map(float, r)) for r in ratings],
        "current_unit_a": current_unit_a, "position_output_scale": float(position_output_scale),
        "operating_mode": 3, "position_p_gain": int(log.kp), "position_i_gain": 0, "position_d_gain": 0,
        "pwm_limit": 885, "current_limit": 1750, "velocity_limit": 445, "supply_v": float(log.supply_v),
        "load_inertia_kg_m2": float(log.inertia_kg_m2), "gravity_moment_nm": float(log.gravity_moment_nm(GRAVITY_M_S2)),
        "gravity_zero_pulses": MIDDLE_PULSES,
    }
    return Trace({"t": stamps - READ_LEAD_S, "goal_position": goal, "present_position": position,
                  "present_velocity": velocity, "present_pwm": np.asarray(log.present_pwm, dtype=np.int64),
                  "torque_enable": log.torque_enable.astype(np.int64), "command_t": stamps - GOAL_LEAD_S},
                 [f"BAM pendulum log {log.name} ({log.trajectory}, kp {log.kp}, {log.supply_v:g} V, "
                  f"{log.mass_kg:g} kg at {log.length_m:g} m)"], meta)
