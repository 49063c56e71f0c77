"""The fused step kernels against the generic loop: the same numbers, bit for bit.

Each scenario runs twice, fused and generic (``PhysicalModel(fused=False)``),
through goal changes, torque off, other compliance settings and the run-time
loads, and every state and register must be equal at every advance: the
same bytes, but for the sign of a zero (``-0.0 == 0.0``; nothing downstream
can tell them apart, and the fused kernels' ``copysign`` may flip it).
"""

import dataclasses

import numpy as np
import pytest

from firmware_model import stepping
from firmware_model.params import ServoEffects, ServoParams
from firmware_model.physical import PhysicalModel
from firmware_model.stepping import FusedNumpySteps, fused_scalar_steps, generic_steps

LOADS = {
    "none": lambda m: None,
    "external torque": lambda m: m.set_external_torque([0.1, -0.3, 0.0][: m.n]),
    "arm": lambda m: m.set_arm([0.1, 0.2, 0.05][: m.n], [0.1, 0.1, 0.2][: m.n]),
    "blocked": lambda m: m.set_blocked([True, False, True][: m.n]),
}


def _scenario(n: int, make_commands, wheel: bool) -> list[tuple[float, object]]:
    pick = lambda values: values[:n]  # noqa: E731
    if wheel:  # both angle limits 0; Moving Speed sets the output, its bit 10 turns CW
        spin = dict(cw_angle_limit=0, ccw_angle_limit=0)
        return [
            # long enough for an open-loop wheel to settle to the bit (about 0.8 s): the kernels' cruise shortcut
            (1.2, make_commands(n, moving_speed=pick([300, 1024 + 200, 0]), **spin)),
            (0.2, make_commands(n, moving_speed=pick([1024 + 500, 100, 700]), torque_enable=pick([0, 1, 0]), **spin)),
            # the first turning CW against its load, so that with no output it stops and holds (0.1 < 0.13 N m static)
            (0.3, make_commands(n, moving_speed=pick([1024 + 1023, 0, 50]), torque_limit=pick([300, 1023, 600]), **spin)),
            (0.6, make_commands(n, moving_speed=0, **spin)),  # long enough to stop
        ]
    return [
        (0.3, make_commands(n, goal_position=pick([300, 700, 100]), moving_speed=pick([0, 200, 50]))),
        (0.2, make_commands(n, goal_position=pick([800, 200, 900]), torque_enable=pick([0, 1, 0]))),
        (0.3, make_commands(n, goal_position=512, punch=pick([0, 100, 32]), cw_compliance_margin=5,
                            ccw_compliance_margin=5, torque_limit=pick([300, 1023, 600]))),
        (0.6, make_commands(n, goal_position=pick([520, 500, 530]))),  # long enough to come to rest and hold
    ]


#: The data-sheet parameters have no viscous friction; a fitted set may (the kernels have a branch for it).  A
#: fitted twin's drive ceiling, wider dead band, arm and sensor offset are plan data the fused kernels take.
PARAMS = {"data sheet": ServoParams(), "viscous": dataclasses.replace(ServoParams(), viscous_friction_nm_s_rad=0.02),
          "plan-data effects": dataclasses.replace(ServoParams(), effects=ServoEffects(  # an arm light enough to hold
              drive_ceiling_fraction=0.6, extra_compliance_margin_units=2.0, arm_weight_moment_nm=0.02,
              position_offset_units=-3.0, position_gain=1.02)),
          # The H-bridge: the default coasts against the drive; one that shorts the winding, and a blend.
          "braking bridge": dataclasses.replace(ServoParams(), bridge_braking_fraction=1.0),
          "half-braking bridge": dataclasses.replace(ServoParams(), bridge_braking_fraction=0.5)}


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind == "f":
        a, b = a + 0.0, b + 0.0  # -0.0 becomes 0.0
    return a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _trajectory(n: int, backend: str, fused: bool, load, make_commands, wheel: bool = False,
                params: ServoParams = ServoParams(), every_s: float = 0.007) -> list[tuple]:
    model = PhysicalModel(n, params=params, backend=backend, fused=fused)
    load(model)
    states, t = [], 0.0
    for duration_s, cmds in _scenario(n, make_commands, wheel):
        end = t + duration_s
        while t < end - 1e-12:
            t += every_s  # 7 ms: not a multiple of the thermal or sample period
            sensed = model.advance(t, cmds)
            states.append((model.angle_rad, model.speed_rad_s, model.reference_rad, model.drive, model.temperature_c,
                           np.array(model._s.current_sq_sum),  # the heating's running sum, not only its rounding
                           *(getattr(sensed, name) for name in type(sensed).field_names())))
    held = (model.speed_rad_s == 0) & (wheel or model.reference_rad == model._cached_plan(cmds).step.goal_rad)
    assert held.any(), "the scenario should end with a servo holding still (the kernels' fixed-point shortcut)"
    return states


#: The kernels and the ways the settings above reach them: servo count with backend, run mode.
KERNELS, MODES = [(1, "scalar"), (1, "numpy"), (3, "numpy")], ["joint", "wheel"]


def _pairwise_cases() -> list[tuple[int, str, str, str, str]]:
    """Every parameter set with every load, the kernel and mode turning with their sum (k = p + q).

    Every pair of settings meets in some case (each kernel with each load, parameter set and mode; each
    load with each mode and parameter set): k mod 3 and k mod 2 take all six joint values over k = 0..5,
    and k covers them for every fixed p or q.  20 cases instead of the 120 of the whole cross product,
    which the kernels do not need: they branch on each setting by itself (arm, load, bridge, viscous, wheel).
    """
    return [(*KERNELS[(p + q) % 3], load, MODES[(p + q) % 2], params)
            for p, params in enumerate(sorted(PARAMS)) for q, load in enumerate(sorted(LOADS))]


def test_pairwise_cases_cover_every_pair_of_settings():
    cases = _pairwise_cases()
    factors = [sorted(set(KERNELS)), sorted(LOADS), MODES, sorted(PARAMS)]
    rows = [((n, backend), load, mode, params) for n, backend, load, mode, params in cases]
    for i in range(4):
        for j in range(i + 1, 4):
            assert {(r[i], r[j]) for r in rows} == {(a, b) for a in factors[i] for b in factors[j]}, (i, j)


@pytest.mark.parametrize("n, backend, load, mode, params", _pairwise_cases())
def test_fused_kernels_equal_the_generic_loop(n, backend, load, mode, params, commands):
    fused, generic = (_trajectory(n, backend, flag, LOADS[load], commands, mode == "wheel", PARAMS[params])
                      for flag in (True, False))
    assert len(fused) == len(generic) > 100
    for step, (a, b) in enumerate(zip(fused, generic)):
        assert all(_same_bits(x, y) for x, y in zip(a, b)), f"differs at advance {step}"


@pytest.mark.parametrize("mode", ["joint", "wheel"])
@pytest.mark.parametrize("load", ["none", "external torque"])
def test_fused_kernel_equals_the_generic_loop_one_step_per_call(load, mode, commands):
    """The serving loop's cadence, one step per advance: fixed points found carry over between calls."""
    fused, generic = (_trajectory(3, "numpy", flag, LOADS[load], commands, mode == "wheel", every_s=0.001)
                      for flag in (True, False))
    assert len(fused) == len(generic) > 1000
    for step, (a, b) in enumerate(zip(fused, generic)):
        assert all(_same_bits(x, y) for x, y in zip(a, b)), f"differs at advance {step}"


@pytest.mark.parametrize("mode", ["joint", "wheel"])
def test_fused_kernel_without_the_clip_ufunc_equals_the_generic_loop(mode, commands, monkeypatch):
    """A numpy without the clip ufunc gets maximum-then-minimum: the same numbers, bit for bit."""
    monkeypatch.setattr(stepping, "_clip", stepping._min_max_clip)
    fused, generic = (_trajectory(3, "numpy", flag, LOADS["external torque"], commands, mode == "wheel")
                      for flag in (True, False))
    assert len(fused) == len(generic) > 100
    for step, (a, b) in enumerate(zip(fused, generic)):
        assert all(_same_bits(x, y) for x, y in zip(a, b)), f"differs at advance {step}"


@pytest.fixture
def kernels(monkeypatch) -> list:
    """Every FusedNumpySteps built during the test, to read their shortcut counters."""
    built = []
    build = FusedNumpySteps.__init__

    def _collect(self, *args):
        build(self, *args)
        built.append(self)

    monkeypatch.setattr(FusedNumpySteps, "__init__", _collect)
    return built


def test_fixed_point_shortcuts_run_in_the_scenarios_above(commands, kernels):
    """Guards the comparisons: servos holding still, references cruising and wheels cruising take the shortcuts there."""
    _trajectory(3, "numpy", True, LOADS["none"], commands, wheel=False)
    assert sum(k.rest_steps for k in kernels) > 100
    assert sum(k.ref_cruise_steps for k in kernels) > 100
    kernels.clear()
    _trajectory(3, "numpy", True, LOADS["external torque"], commands, wheel=True, every_s=0.001)
    assert sum(k.cruise_steps for k in kernels) > 100


def test_fused_kernel_equals_the_generic_loop_through_wraps_while_cruising(commands, kernels):
    """Wheels cruising turn after turn: each wrap (the thermal event rebinds the angle) lands mid-cruise."""
    spin = commands(3, cw_angle_limit=0, ccw_angle_limit=0, moving_speed=[1023, 1024 + 1000, 950])
    models = [PhysicalModel(3, fused=flag) for flag in (True, False)]
    turned_rad = np.zeros(3)
    for i in range(1, 2501):
        readings = [model.advance(i * 0.001, spin) for model in models]
        states = [(model.angle_rad, model.speed_rad_s, model.temperature_c, r.present_position, r.present_speed)
                  for model, r in zip(models, readings)]
        assert all(_same_bits(x, y) for x, y in zip(*states)), f"differs at step {i}"
        turned_rad += np.abs(models[0].speed_rad_s) * 0.001
    assert (turned_rad > 2 * 2 * np.pi).all()  # two turns or more each, so wraps came while cruising
    assert sum(k.cruise_steps for k in kernels) > 1500


def test_cruise_safe_distance_keeps_every_speed_limit_exactly():
    """From the safe distance on, the setpoint's own arithmetic asks for exactly the limit, for every Moving Speed."""
    from firmware_model.controller import PidGains
    from firmware_model.stepping import StepConstants, _cruise_safe_distance
    from firmware_model.units import RAD_S_PER_SPEED_UNIT

    n = 1023
    k = StepConstants.from_params(ServoParams(), 1e-3, "compliance", PidGains())
    adt = k.accel_rad_s2 * k.step_s
    limit = np.arange(1, n + 1) * RAD_S_PER_SPEED_UNIT
    safe = _cruise_safe_distance(k, limit)
    for scale in (1.0, 1.0 + 1e-12, 1.37, 1e3):
        d = safe * scale  # the setpoint's braking curve, written out from a and dt (setpoint.braking_speed)
        curve = np.sqrt(d * (2.0 * k.accel_rad_s2) + 0.25 * adt * adt) - 0.5 * adt
        assert (np.minimum(limit, np.minimum(curve, d * (1.0 / k.step_s))) == limit).all()
    # and not far beyond what the braking curve needs, (v**2 + v a dt) / 2a, or one step at v
    needed = np.maximum((limit**2 + limit * adt) / (2 * k.accel_rad_s2), limit * k.step_s)
    assert (safe < needed * (1 + 1e-6) + 1e-9).all()


@pytest.mark.parametrize("every_s", [0.001, 0.01])
def test_fused_kernel_equals_the_generic_loop_through_slow_cruises(commands, kernels, every_s):
    """Moving Speed 1 to 7 (0.7 to 5 degrees a second): long cruises at the slowest references, bit for bit."""
    n = 4
    legs = [(2.5, commands(n, goal_position=[600, 400, 530, 500], moving_speed=[1, 3, 7, 2]))]
    _compare_fused_and_generic(n, legs, every_s)
    assert sum(k.ref_cruise_steps for k in kernels) > 1000


def _compare_fused_and_generic(n: int, legs, every_s: float) -> None:
    models = [PhysicalModel(n, fused=flag) for flag in (True, False)]
    t = 0.0
    for duration_s, cmds in legs:
        end = t + duration_s
        while t < end - 1e-12:
            t += every_s
            readings = [model.advance(t, cmds) for model in models]
            states = [(model.angle_rad, model.speed_rad_s, model.reference_rad, model.drive, model._s.current_sq_sum,
                       r.present_position, r.present_speed, r.moving) for model, r in zip(models, readings)]
            assert all(_same_bits(x, y) for x, y in zip(*states)), f"differs at {t:.3f} s"


@pytest.mark.parametrize("every_s", [0.001, 0.01])
def test_fused_kernel_equals_the_generic_loop_through_long_cruises(commands, kernels, every_s):
    """Servos told to go far at moderate speeds cruise together for hundreds of steps (the setpoint skipped),
    then brake one after the other and rest; a goal changed mid-cruise turns some round."""
    n = 5
    legs = [(1.5, commands(n, goal_position=[1000, 20, 900, 100, 512], moving_speed=[150, 150, 200, 90, 300])),
            (1.2, commands(n, goal_position=[600, 300, 900, 400, 700], moving_speed=[150, 400, 200, 90, 0]))]
    _compare_fused_and_generic(n, legs, every_s)
    assert sum(k.ref_cruise_steps for k in kernels) > 300


def test_usual_configuration_runs_fused_and_others_the_generic_loop(commands):
    """Guards the comparison above: it must really compare two different kernels."""

    def _kernel(model: PhysicalModel, **overrides):
        return model._cached_plan(commands(model.n, **overrides)).kernel

    assert _kernel(PhysicalModel(1)).func is fused_scalar_steps
    assert isinstance(_kernel(PhysicalModel(3)), FusedNumpySteps)
    assert _kernel(PhysicalModel(3, fused=False)).func is generic_steps
    assert _kernel(PhysicalModel(3, controller="pid")).func is generic_steps
    assert _kernel(PhysicalModel(3), ccw_compliance_margin=4).func is generic_steps  # asymmetric
    assert isinstance(_kernel(PhysicalModel(3), ccw_angle_limit=0), FusedNumpySteps)  # wheel mode
    assert _kernel(PhysicalModel(1), ccw_angle_limit=0).func is fused_scalar_steps
    assert _kernel(PhysicalModel(2), ccw_angle_limit=[0, 1023]).func is generic_steps  # wheel and joint mixed
    for state_effect in (ServoEffects(backlash_rad=0.03), ServoEffects(sensing_delay_s=0.02)):  # kept per step
        twin = dataclasses.replace(ServoParams(), effects=state_effect)
        assert _kernel(PhysicalModel(1, twin)).func is generic_steps
        assert _kernel(PhysicalModel(3, twin)).func is generic_steps


@pytest.mark.parametrize(("change", "words"), [
    ({"winding_resistance_ohm": 0.1}, "brakes the shaft"),
    ({"rotor_inertia_reflected_kg_m2": 1e-6}, "brakes the shaft"),
    ({"viscous_friction_nm_s_rad": 5.0}, "viscous friction"),
    ({"torque_constant_nm_a": 1e100}, "brakes the shaft"),
    # k ** 2 past 1e308: an OverflowError traceback from serve, diagnose, VirtualBus and the URL, not this line
    ({"torque_constant_nm_a": 1e160}, "brakes the shaft"),
    ({"torque_constant_nm_a": 1e300}, "brakes the shaft"),
])
def test_parameters_too_stiff_for_the_step_are_refused_by_name(change, words):
    """Losses are taken explicitly per 1 ms step: past one step's worth the shaft would reverse and the speed run away
    (R 0.01 ohm overflowed on the first goal; R 0.1 read a goal of 800 as 1023 then 633)."""
    from firmware_model.params import ServoParams
    from firmware_model.stepping import check_step

    check_step(ServoParams(), 1e-3)  # the AX-12's own: a few per cent of a step
    params = ServoParams(**change)
    with pytest.raises(ValueError, match=words):
        check_step(params, 1e-3)
