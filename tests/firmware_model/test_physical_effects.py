"""The served model's effects (ServoParams.effects) against the diagnosis's batched simulator.

The diagnosis fits each library effect on :mod:`firmware_model.diagnose.batch`;
a twin served from its params.toml must read what the fit saw.  On the same
command sequence every register of PhysicalModel equals the batch's, row by
row (measured: no difference at all for every library effect; the command
delay, which the library does not have, equals the sensing delay exactly at
whole-step delays and within a unit between them).  At its null value an
effect changes nothing, bit for bit, and the usual configuration keeps its
fused kernel.
"""

import dataclasses

import numpy as np
import pytest

from firmware_model.diagnose.batch import null_knobs, sample, simulate
from firmware_model.diagnose.effects import LIBRARY, apply_effects
from firmware_model.diagnose.excitation import commands_at, program
from firmware_model.diagnose.replay import replay
from firmware_model.diagnose.schedule import compile_schedule
from firmware_model.diagnose.trace import Trace
from firmware_model.params import EFFECT_NULLS, ServoEffects, ServoParams
from firmware_model.physical import PhysicalModel
from firmware_model.stepping import generic_steps

CHANNELS = ("present_position", "present_speed", "present_load")

#: Library effect -> (its parameter values, the same as ServoEffects fields); values inside the "hidden" ranges.
CASES = {
    "backlash": ({"backlash_rad": 0.06}, {"backlash_rad": 0.06}),
    "delay": ({"delay_s": 0.0317}, {"sensing_delay_s": 0.0317}),
    "torque_saturation": ({"drive_ceiling": 0.45}, {"drive_ceiling_fraction": 0.45}),
    "gravity_load": ({"arm_weight_nm": 0.4}, {"arm_weight_moment_nm": 0.4}),
    "negative gravity_load": ({"arm_weight_nm": -0.25}, {"arm_weight_moment_nm": -0.25}),
    "compliance_deadband": ({"extra_margin_units": 5.0}, {"extra_compliance_margin_units": 5.0}),
    "sensor_offset_gain": ({"position_offset_units": -6.5, "position_gain": 1.03},
                           {"position_offset_units": -6.5, "position_gain": 1.03}),
}


def _trace(duration_s: float = 8.0, external_load: bool = True) -> Trace:
    """The diagnosis's excitation (moves, speeds, small steps), sampled irregularly at about 100 Hz."""
    rng = np.random.default_rng(4)
    t = np.arange(0, duration_s, 0.01) + rng.uniform(0, 0.004, int(duration_s * 100))
    c = commands_at(t, program(duration_s, 2.0))
    if not external_load:
        c.pop("external_torque_nm", None)
    return Trace(dict(t=t, present_position=np.full(len(t), 512), **c))


def _batch(trace: Trace, effect: str, values: dict) -> dict[str, np.ndarray]:
    p = ServoParams()
    schedule = compile_schedule(trace)
    knobs = apply_effects(null_knobs(p), {effect: {**LIBRARY[effect].null_values(), **values}})
    k1 = {k: np.array([v]) for k, v in knobs.items()}
    out = sample(schedule, simulate(schedule, p, k1, 1), p, k1)
    return {ch: out[ch][:, 0] for ch in CHANNELS}


def _served(trace: Trace, **effects) -> Trace:
    return replay(trace, dataclasses.replace(ServoParams(), effects=ServoEffects(**effects)))


@pytest.mark.parametrize("case", sorted(CASES))
def test_served_effect_reads_as_the_batch_simulator(case):
    """Every register of the served model equals the batched simulator's, row by row, and the effect is visible."""
    library_values, fields = CASES[case]
    effect = case.split()[-1]
    tr = _trace()
    batch, served = _batch(tr, effect, library_values), _served(tr, **fields)
    for ch in CHANNELS:
        np.testing.assert_array_equal(served[ch], batch[ch], err_msg=ch)
    plain = replay(tr)
    gap = np.sqrt(np.mean((served["present_position"] - plain["present_position"]) ** 2.0))
    assert gap > 2.0, f"{case} should move the position by more than the pot's noise, got {gap:.2f} units RMS"


@pytest.mark.parametrize("delay_s", [0.005, 0.03, 0.08])
def test_command_delay_reads_as_the_sensing_delay_at_whole_steps(delay_s):
    """Commands acted on ``d`` late: the position reads as the library's delay (the shaft read ``d`` late), exactly.

    Without an external load (a load is not a command, so only the sensing delay shifts it).
    """
    tr = _trace(external_load=False)
    batch, served = _batch(tr, "delay", {"delay_s": delay_s}), _served(tr, command_delay_s=delay_s)
    np.testing.assert_array_equal(served["present_position"], batch["present_position"])


def test_command_delay_between_steps_is_within_a_unit_of_the_sensing_delay():
    """Half a step: the command waits a whole number of steps, the reading interpolates (measured 0.49 RMS)."""
    tr = _trace(external_load=False)
    batch, served = _batch(tr, "delay", {"delay_s": 0.0125}), _served(tr, command_delay_s=0.0125)
    diff = served["present_position"] - batch["present_position"]
    assert np.abs(diff).max() <= 1 and np.sqrt(np.mean(diff**2.0)) < 0.6


def test_command_delay_leaves_the_servo_inert_until_the_first_command_acts(commands):
    model = PhysicalModel(1, dataclasses.replace(ServoParams(), effects=ServoEffects(command_delay_s=0.05)))
    go = commands(goal_position=800)
    model.advance(0.049, go)
    assert model.speed_rad_s[0] == 0.0 and model.sense().present_position[0] == 512
    model.advance(0.2, go)
    assert model.sense().present_position[0] > 530


_NULLS = {name: EFFECT_NULLS[name] for name in EFFECT_NULLS}


@pytest.mark.parametrize("name", sorted(_NULLS))
@pytest.mark.parametrize("n, backend", [(1, "scalar"), (3, "numpy")])
def test_null_value_changes_nothing_bit_for_bit(name, n, backend, commands):
    """An effect set to its null value gives the plain model's every register and state, with the same kernel."""
    runs = []
    for effects in (ServoEffects(), ServoEffects(**{name: _NULLS[name]})):
        model = PhysicalModel(n, dataclasses.replace(ServoParams(), effects=effects), backend=backend)
        states, t = [], 0.0
        for goal in ([700, 300, 600][:n], [300, 800, 512][:n]):
            cmds = commands(n, goal_position=goal)
            for _ in range(90):
                t += 0.007
                sensed = model.advance(t, cmds)
                states.append(b"".join(np.asarray(getattr(sensed, f)).tobytes() for f in type(sensed).field_names())
                              + np.asarray(model.angle_rad).tobytes() + np.asarray(model.speed_rad_s).tobytes())
        runs.append((states, type(model._cached_plan(cmds).kernel)))
    assert runs[0][0] == runs[1][0]
    assert runs[0][1] is runs[1][1]


ALL_EFFECTS = ServoEffects(backlash_rad=0.05, sensing_delay_s=0.0237, command_delay_s=0.012, drive_ceiling_fraction=0.7,
                           arm_weight_moment_nm=0.3, extra_compliance_margin_units=2.0, position_offset_units=3.0,
                           position_gain=0.98)


def _run(n, backend, every_s, commands, effects=ALL_EFFECTS, wheel=False):
    model = PhysicalModel(n, dataclasses.replace(ServoParams(), effects=effects), backend=backend)
    spin = dict(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=[300, 1024 + 500, 100][:n]) if wheel else {}
    plan = [(0.35, commands(n, goal_position=[800, 200, 600][:n], **spin)),
            (0.35, commands(n, goal_position=[300, 700, 512][:n], torque_enable=[1, 0, 1][:n], **spin)),
            (0.63, commands(n, goal_position=[520, 505, 515][:n], torque_limit=[1023, 400, 800][:n], **spin))]
    out, t = {}, 0.0
    for duration, cmds in plan:
        end = t + duration
        while t < end - 1e-9:
            t = round(t + every_s, 9)
            sensed = model.advance(t, cmds)
            out[round(t, 6)] = (sensed.present_position.copy(), sensed.present_speed.copy(),
                                sensed.present_load.copy(), model.angle_rad)
    return out, model


@pytest.mark.parametrize("wheel", [False, True])
def test_effects_give_the_same_numbers_on_both_backends_and_any_call_cadence(commands, wheel):
    """One servo on floats or numpy, one step a call or 7 ms a call: the same registers at the common instants."""
    one_step, model = _run(1, "scalar", 0.001, commands, wheel=wheel)
    assert _kernel_func(model) is generic_steps  # gear play and the sensing delay need the generic loop
    for backend, every_s in (("numpy", 0.001), ("scalar", 0.007), ("numpy", 0.007)):
        other, _ = _run(1, backend, every_s, commands, wheel=wheel)
        for t, values in other.items():
            assert all(np.array_equal(a, b) for a, b in zip(values, one_step[t])), (backend, every_s, t)


def test_effects_per_servo_of_three_agree_with_one_servo_runs(commands):
    """N servos on numpy with the effects: each reads what it would alone (where the commands coincide)."""
    three, _ = _run(3, "numpy", 0.007, commands)
    single, _ = _run(1, "scalar", 0.007, commands)
    for t, values in single.items():
        assert all(np.array_equal(a[:1], b) for a, b in zip(three[t], values)), t


def _kernel_func(model):
    kernel = model._plan_cache[1].kernel
    return getattr(kernel, "func", kernel)


def test_plan_data_effects_keep_the_fused_kernel(commands):
    """A drive ceiling, a wider dead band and an arm are plan data the fused kernels take (test_stepping checks the
    numbers); gear play and a sensing delay run the generic loop."""
    for effects, fused in ((ServoEffects(drive_ceiling_fraction=0.5, extra_compliance_margin_units=3.0,
                                         arm_weight_moment_nm=0.2, position_offset_units=2.0), True),
                           (ServoEffects(backlash_rad=0.02), False), (ServoEffects(sensing_delay_s=0.01), False)):
        model = PhysicalModel(3, dataclasses.replace(ServoParams(), effects=effects))
        model.advance(0.01, commands(3))
        assert (_kernel_func(model) is not generic_steps) == fused, effects


def test_gear_play_shows_as_a_lag_at_reversals_and_the_horn_reads_the_output(commands):
    """The output stays within half the play of the motor side; angle_rad is the output's (the horn)."""
    model = PhysicalModel(1, dataclasses.replace(ServoParams(), effects=ServoEffects(backlash_rad=0.08)))
    gaps, t = [], 0.0
    for goal in (800, 300):
        for _ in range(150):
            t += 0.004
            model.advance(t, commands(goal_position=goal))
            gaps.append(float(model._s.angle - model._s.out))
    assert max(abs(g) for g in gaps) <= 0.04 + 1e-12
    assert min(gaps) < -0.039 and max(gaps) > 0.039  # slack taken up on both sides
    assert model.angle_rad[0] == pytest.approx(model._s.out % (2 * np.pi))


def test_set_arm_replaces_the_parameters_arm(commands):
    model = PhysicalModel(1, dataclasses.replace(ServoParams(), effects=ServoEffects(arm_weight_moment_nm=0.5)))
    assert model._s.weight_nm == 0.5
    model.set_arm(0.0, 0.0)
    plain = PhysicalModel(1)
    for t in (0.2, 0.5):
        a, b = model.advance(t, commands(goal_position=700)), plain.advance(t, commands(goal_position=700))
        assert all(np.array_equal(getattr(a, f), getattr(b, f)) for f in type(a).field_names())
