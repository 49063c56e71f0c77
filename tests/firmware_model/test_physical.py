"""PhysicalModel as a ServoModel: modes, determinism, vectorisation, run-time inputs."""

import dataclasses

import numpy as np
import pytest

from firmware_model.interface import ServoModel
from firmware_model.params import ServoParams
from firmware_model.physical import RAD_S_PER_SPEED_UNIT, PhysicalModel


def test_is_a_servo_model():
    """It provides what the bus needs."""
    model: ServoModel = PhysicalModel(3)
    assert model.n == 3 and model.time_s == 0.0
    assert model.sense().present_position.tolist() == [512, 512, 512]


def test_wheel_mode_turns_endlessly_and_wraps(commands):
    """Both angle limits 0: Moving Speed 400 CCW drives at 400/1023 of full output (the e-manual's wheel mode:
    output control, not speed), so the shaft settles where that share of the supply holds it against its
    friction, and the position wraps 1023 -> 0."""
    model = PhysicalModel(1)
    p = model.params
    cmds = commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=400)
    positions = [model.advance(i * 0.005, cmds).present_position[0] for i in range(1, 601)]
    assert model.drive[0] == pytest.approx(400 / 1023)
    assert model.speed_rad_s[0] == pytest.approx(p.top_speed_rad_s(400 / 1023 * p.supply_voltage_v), rel=0.02)
    wraps = sum(1 for a, b in zip(positions, positions[1:]) if b < a - 500)
    assert wraps >= 1  # 2.5 rad/s for 3 s is 1.2 turns
    # Present Speed reads the output in wheel mode, as Present Load does (the e-manual's 0.1 % a unit)
    sensed = model.sense()
    assert sensed.present_speed[0] == sensed.present_load[0] == 400


def test_wheel_mode_direction_bit_turns_cw(commands):
    """Bit 10 of Moving Speed turns CW: Present Speed and Load carry the CW bit."""
    model = PhysicalModel(1)
    sensed = model.advance(0.5, commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=1024 | 600))
    assert model.drive[0] == pytest.approx(-600 / 1023)
    assert model.speed_rad_s[0] < -1.0
    assert sensed.present_speed[0] == sensed.present_load[0] == 1024 | 600


def test_a_load_slows_a_wheel_and_torque_limit_caps_its_output(commands):
    """No speed loop holds a wheel's speed: a torque against it slows it at the same output, and Torque Limit
    below the asked output caps the output."""
    free, loaded = PhysicalModel(1), PhysicalModel(1)
    loaded.set_external_torque(np.array([-0.3]))
    cmds = commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=800)
    for model in (free, loaded):
        model.advance(1.0, cmds)
        assert model.drive[0] == pytest.approx(800 / 1023)
    assert loaded.speed_rad_s[0] < 0.8 * free.speed_rad_s[0]
    capped = PhysicalModel(1)
    capped.advance(1.0, commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=800, torque_limit=400))
    assert capped.drive[0] == pytest.approx(400 / 1023)
    assert capped.speed_rad_s[0] < free.speed_rad_s[0]


def test_a_wheel_a_load_pushes_past_its_top_speed_settles_there(commands):
    """A wheel at a fifth of the output with a torque turning it the same way, well above its friction: the
    coasting bridge passes no braking current, but past the supply the diodes do, so the wheel settles a little
    above its top speed instead of running away."""
    model = PhysicalModel(1)
    p = model.params
    model.set_external_torque(np.array([0.5]))
    cmds = commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=200)
    model.advance(3.0, cmds)
    settled = float(model.speed_rad_s[0])
    model.advance(4.0, cmds)
    top = p.supply_voltage_v / p.torque_constant_nm_a
    assert float(model.speed_rad_s[0]) == pytest.approx(settled, rel=1e-3)
    assert top < settled < 1.5 * top


def test_same_result_whatever_the_advance_chunks(commands):
    """Deterministic fixed step: 1 ms, 7 ms or one 0.5 s advance give identical states."""
    cmds = commands(goal_position=800)
    results = []
    for chunk in (0.001, 0.007, 0.5):
        model = PhysicalModel(1)
        t = 0.0
        while t < 0.5 - 1e-12:
            t = min(0.5, t + chunk)
            model.advance(t, cmds)
        results.append((model.angle_rad[0], model.speed_rad_s[0], model.temperature_c[0]))
    assert results[0] == results[1] == results[2]


def test_scalar_and_numpy_backends_agree(commands):
    """One servo on floats and on numpy give the same trajectory (to rounding)."""
    runs = []
    for backend in ("scalar", "numpy"):
        model = PhysicalModel(1, backend=backend)
        model.set_external_torque(0.2)
        model.advance(0.8, commands(goal_position=300, moving_speed=500))
        runs.append((model.angle_rad[0], model.speed_rad_s[0], model.sense().present_load[0]))
    assert runs[0][0] == pytest.approx(runs[1][0], abs=1e-9)
    assert runs[0][2] == runs[1][2]


def test_servos_are_independent(commands):
    """Three different servos in one model move as each would alone."""
    goals, speeds = [300, 700, 512], [0, 200, 0]
    together = PhysicalModel(3)
    together.set_external_torque([0.0, 0.3, 0.0])
    sensed = together.advance(0.7, commands(3, goal_position=goals, moving_speed=speeds))
    for i in range(3):
        alone = PhysicalModel(1, backend="numpy")
        alone.set_external_torque([0.0, 0.3, 0.0][i])
        assert alone.advance(0.7, commands(1, goal_position=goals[i], moving_speed=speeds[i])).present_position[0] == sensed.present_position[i]


def test_torque_off_servo_is_free_and_reference_follows(commands):
    """Torque off: no drive, the shaft coasts under a torque; re-enabling does not jump back to an old reference."""
    model = PhysicalModel(1)
    model.set_external_torque(0.2)
    sensed = model.advance(0.3, commands(torque_enable=0))
    assert sensed.present_load[0] == 0 and sensed.present_position[0] > 600
    model.set_external_torque(0.0)
    model.advance(2.0, commands(torque_enable=0))  # Coulomb friction stops it
    assert model.speed_rad_s[0] == 0.0
    pushed = model.sense().present_position[0]
    sensed = model.advance(2.5, commands(goal_position=pushed))
    assert abs(sensed.present_position[0] - pushed) <= 3


@pytest.mark.parametrize("backend", ["scalar", "numpy"])
def test_a_goal_at_the_read_position_with_torque_coming_on_moves_nothing(commands, backend):
    """A shaft left between two readings with torque off: Goal Position written as the Present Position just read,
    torque on, and Moving reads 0 from the first step (the reference starts from the reading, as the firmware's
    does); from the shaft's exact angle it travelled the fraction, Moving 1 for 7 ms with nothing moving."""
    unit_rad = 300.0 / 1023.0 * np.pi / 180.0
    model = PhysicalModel(1, backend=backend, initial_position_raw=500)
    model.advance(0.01, commands(torque_enable=0))
    model.set_angle(0, 500.44 * unit_rad)  # turned by hand to between two readings (beyond the setpoint's dead zone)
    sensed = model.advance(0.5, commands(torque_enable=0))
    assert model.speed_rad_s[0] == 0.0
    present = int(sensed.present_position[0])
    assert present == 500
    for k in range(1, 11):
        sensed = model.advance(0.5 + k * 1e-3, commands(goal_position=present))
        assert sensed.moving[0] == 0 and sensed.present_position[0] == present, k


def test_arm_gravity_sags_into_the_compliance_slope(commands):
    """A 0.3 kg arm at 0.1 m held horizontally (0.29 N m) sags CW by a few units, more with a softer slope."""
    sags = []
    for slope in (32, 128):
        model = PhysicalModel(1)
        model.set_arm(0.3, 0.1)
        sensed = model.advance(1.0, commands(cw_compliance_slope=slope, ccw_compliance_slope=slope))
        sags.append(512 - int(sensed.present_position[0]))
    assert 1 <= sags[0] < sags[1] <= 40


def test_pid_controller_reaches_goal_with_overshoot(commands):
    """The report's PID (selectable): overshoots a 60-degree step and settles within 2 units."""
    model = PhysicalModel(1, controller="pid")
    positions = [model.advance(i * 1e-3, commands(goal_position=717)).present_position[0] for i in range(1, 1201)]
    assert max(positions) > 717 and abs(positions[-1] - 717) <= 2


def test_goal_clamped_to_angle_limits_and_moving_flag(commands):
    """Goal beyond CCW Angle Limit stops at the limit; Moving is 1 on the way and 0 at rest."""
    model = PhysicalModel(1)
    cmds = commands(goal_position=900, ccw_angle_limit=600)
    assert model.advance(0.05, cmds).moving[0] == 1
    sensed = model.advance(1.0, cmds)
    assert abs(sensed.present_position[0] - 600) <= 3 and sensed.moving[0] == 0


def test_supply_voltage_checked():
    """Supply outside the valid 7-12 V raises ValueError."""
    with pytest.raises(ValueError, match="outside"):
        PhysicalModel(1).set_supply_voltage(15.0)


def test_constructor_rejects_bad_arguments():
    """n, step, controller and backend are validated."""
    for kwargs in ({"n": 0}, {"n": 1, "step_s": 0.0}, {"n": 1, "controller": "bang"}, {"n": 2, "backend": "scalar"}):
        with pytest.raises(ValueError):
            PhysicalModel(**kwargs)


def test_viscous_friction_too_strong_for_the_step_is_refused():
    """b dt / J >= 1 would turn the shaft round each step; below it, a shorter step makes it usable."""
    strong = dataclasses.replace(ServoParams(), viscous_friction_nm_s_rad=5.0)  # J / dt is 4.379 at 1 ms
    with pytest.raises(ValueError, match="viscous friction 5.0 .* below inertia / step = 4.379"):
        PhysicalModel(1, params=strong)
    PhysicalModel(1, params=strong, step_s=0.5e-3)


def test_scalar_position_quantiser_matches_units():
    """The one-servo fast path of Present Position agrees with units.position_rad_to_raw everywhere, dead zone included."""
    from firmware_model.physical import _position_raw
    from firmware_model.units import position_rad_to_raw

    angles = np.linspace(-7.0, 13.0, 20011)
    assert [_position_raw(float(a)) for a in angles] == position_rad_to_raw(angles).tolist()


def test_numpy_position_quantiser_matches_units_at_the_track_ends(commands):
    """Many servos: Present Position agrees with units.position_rad_to_raw just inside, at and just past both ends."""
    from firmware_model.units import RAD_PER_POSITION_UNIT, position_rad_to_raw

    units = np.array([-0.7, -0.5, -0.49, -0.01, 0.0, 0.49, 0.51, 511.5, 1022.6, 1023.0, 1023.49, 1023.5, 1023.51, 1030.0])
    for chosen in ([0, 1, 2, 3, 4, 5, 6, 7], [7, 8, 9, 10, 11], [2, 3, 7, 9, 10], list(range(len(units)))):
        angles = units[chosen] * float(RAD_PER_POSITION_UNIT)
        model = PhysicalModel(len(chosen))
        for index, angle in enumerate(angles):
            model.set_angle(index, float(angle))
        model.advance(0.0, commands(len(chosen)))  # joint mode, no step: only the sensors
        assert model.sense().present_position.tolist() == position_rad_to_raw(angles).tolist(), units[chosen]


def test_sense_agrees_between_backends_while_moving(commands):
    """Sensed registers (position, moving, speed, load) are equal on the float and numpy paths mid-move."""
    outs = []
    for backend in ("scalar", "numpy"):
        model = PhysicalModel(1, backend=backend)
        model.advance(0.15, commands(goal_position=800))
        s = model.sense()
        outs.append([int(getattr(s, f)[0]) for f in s.field_names()])
    assert outs[0] == outs[1]


def test_leaving_wheel_mode_starts_from_the_shaft(commands):
    """After endless turning, joint mode moves from where the shaft is, at the setpoint's pace (no jump, no stale reference)."""
    model = PhysicalModel(1)
    model.advance(0.7, commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=300))
    model.advance(1.5, commands(cw_angle_limit=0, ccw_angle_limit=0, moving_speed=0))
    start = int(model.sense().present_position[0])
    goal = 300 if start > 600 else 800
    model.advance(1.501, commands(goal_position=goal))
    assert abs(model.reference_rad[0] - model.angle_rad[0]) < 0.01
    assert abs(model.advance(2.5, commands(goal_position=goal)).present_position[0] - goal) <= 3


def test_joint_mode_overshoot_below_zero_does_not_wrap(commands):
    """A move to Goal Position 0 that overshoots below 0 comes back to 0 instead of wrapping to the far end.

    Regression: the angle used to wrap modulo 2 pi in joint mode too, so an overshoot at 0 read as
    position ~1228 and the servo drove the long way round.
    """
    cmds = commands(goal_position=0)
    for backend in ("scalar", "numpy"):
        model = PhysicalModel(1, backend=backend)
        positions = [int(model.advance(t / 100, cmds).present_position[0]) for t in range(1, 101)]
        assert max(positions[70:]) <= 5, (backend, positions)


@pytest.mark.parametrize("backend", ["scalar", "numpy"])
def test_blocked_shaft_and_set_angle(backend, commands):
    """A blocked shaft does not turn under full drive and overloads; set_angle moves it by hand without a jump."""
    from firmware_model.interface import ALARM_OVERLOAD

    model = PhysicalModel(1, backend=backend)
    commands = commands(goal_position=800)
    model.set_blocked(True)
    sensed = model.advance(1.0, commands)
    assert int(sensed.present_position[0]) == 512
    assert int(sensed.present_load[0]) & 0x3FF > 1000 and int(sensed.alarms[0]) & ALARM_OVERLOAD
    model.set_blocked(False)
    sensed = model.advance(2.0, commands)
    assert abs(int(sensed.present_position[0]) - 800) <= 4
    model.set_angle(0, 300 * 0.2929 * np.pi / 180)
    assert abs(int(model.sense().present_position[0]) - 300) <= 1


def test_moving_in_wheel_mode_is_one_shared_array_while_every_servo_is_driven(commands):
    """Every servo driven in wheel mode reads Moving 1, handed over as one read-only array (the plant
    then skips rewriting it); a servo told to stop, or with torque off, reads 0 once at rest."""
    model = PhysicalModel(3)
    turning = commands(3, cw_angle_limit=0, ccw_angle_limit=0, moving_speed=300)
    first = model.advance(0.05, turning).moving
    assert first.tolist() == [1, 1, 1] and not first.flags.writeable
    assert model.advance(0.06, turning).moving is first
    mixed = commands(3, cw_angle_limit=0, ccw_angle_limit=0, moving_speed=[300, 0, 300], torque_enable=[1, 1, 0])
    assert model.advance(1.5, mixed).moving.tolist() == [1, 0, 0]


@pytest.mark.parametrize("n", [1, 2], ids=["one-servo", "numpy-n2"])
def test_moving_stays_1_while_the_shaft_still_travels_at_moving_speed_0(commands, n):
    """Moving Speed 0 (no speed control) from 512 to 800: the setpoint reaches the goal ~100 ms before the shaft
    does.  Moving(46) is "1: Goal position command execution is in progress" (e-manual, AX-12A): it reads 1 at
    every step the shaft turns faster than one speed unit, and falls to 0 only once the shaft has reached the goal
    (the first 0 may come at the overshoot's turn, 16 units past it, where the shaft stands still for a step); at
    rest it reads 0 within a few units of the goal.  n=1 takes the float path, n=2 the numpy one."""
    model = PhysicalModel(n)
    cmds = commands(n, goal_position=800, moving_speed=0)
    first_zero = [None] * n
    for i in range(1, 1501):
        sensed = model.advance(i * 1e-3, cmds)
        for k in range(n):
            speed = abs(float(model.speed_rad_s[k]))
            moving, present = int(sensed.moving[k]), int(sensed.present_position[k])
            if speed > RAD_S_PER_SPEED_UNIT:
                assert moving == 1, (i, k, present, speed)
            if moving == 0 and first_zero[k] is None:
                first_zero[k] = (i, present, speed)
    for k in range(n):
        assert first_zero[k] is not None, k
        _, present, speed = first_zero[k]
        assert present >= 800 - 3 and speed <= RAD_S_PER_SPEED_UNIT, first_zero[k]
        assert sensed.moving[k] == 0 and abs(int(sensed.present_position[k]) - 800) <= 3
        assert model.speed_rad_s[k] == 0.0
