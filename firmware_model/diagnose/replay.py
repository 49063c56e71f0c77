"""Replay a trace's commands through the real :class:`~firmware_model.physical.PhysicalModel`.

Why it exists: it is the ground truth the fast batched simulator
(:mod:`.batch`) is checked against, and the simplest way for a user to see
"what would the emulator have done with these commands".  The model is
advanced to each row's ``t`` with the previous row's commands and read, so
the simulated trace is sampled exactly as the measurement was (a command
change acting from its ``command_t`` where the trace records one), including the
held Present Speed / Load (``ServoParams.sample_hold_s``, phase starting at
the first row).  Commands a trace does not carry keep the e-manual defaults
(compliance margin 1, slope 32, punch 32, joint mode over the full range).
"""

from __future__ import annotations

import numpy as np

from ..interface import Commands
from ..params import ServoParams
from ..physical import PhysicalModel
from ..units import signed_raw_to_value
from .trace import Trace

__all__ = ["replay", "commands_for_row"]


def commands_for_row(trace: Trace, i: int) -> Commands:
    """Commands for one servo from row ``i`` (the e-manual's power-up values for the registers the trace lacks)."""
    return Commands.power_up(**{name: int(trace[name][i]) for name in ("goal_position", "moving_speed", "torque_limit")
                                if trace.has(name)})


def replay(trace: Trace, params: ServoParams = ServoParams(), step_s: float = 1e-3, arm_weight_nm: float = 0.0) -> Trace:
    """The simulated trace: ``trace`` with its sensed columns replaced by the model's.

    ``arm_weight_nm`` hangs an arm of that weight moment (``m g L``) on the
    shaft (see :mod:`firmware_model.motor` for the convention).
    """
    model = PhysicalModel(1, params, step_s, initial_position_raw=int(trace["present_position"][0]))
    if arm_weight_nm:
        model.set_arm(arm_weight_nm / 9.80665, 1.0)
    t = trace.t
    n = len(trace)
    pos, spd, load = np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64)
    # where the trace records when a change was sent, it acts from then (before or after its row's reading)
    sent = trace["command_t"] - trace["t"][0] if trace.records_command_times else None
    changes = set(trace.change_rows().tolist()) - {0}
    state = {"ext": None, "volt": None}

    def take(i: int) -> Commands:
        """Row ``i``'s commands, with its external torque and supply applied to the model now."""
        if trace.has("external_torque_nm") and trace["external_torque_nm"][i] != state["ext"]:
            state["ext"] = float(trace["external_torque_nm"][i])
            model.set_external_torque(np.array([state["ext"]]))
        if trace.has("voltage") and trace["voltage"][i] != state["volt"]:
            state["volt"] = int(trace["voltage"][i])
            model.set_supply_voltage(state["volt"] / 10.0)
        return commands_for_row(trace, i)

    sensed = model.sense()
    cmds = None
    for i in range(n):
        early = sent is not None and i in changes and sent[i] < t[i]
        if i > 0:
            if early:
                model.step_to(float(sent[i]), cmds)
                cmds = take(i)
            sensed = model.advance(float(t[i]), cmds)
        pos[i] = sensed.present_position[0]
        spd[i] = signed_raw_to_value(sensed.present_speed)[0]
        load[i] = signed_raw_to_value(sensed.present_load)[0]
        if not early:
            if sent is not None and i in changes and sent[i] > t[i]:
                model.step_to(float(sent[i]), cmds)
            cmds = take(i)
    return trace.with_columns(present_position=pos, present_speed=spd, present_load=load)
