"""Motor, friction and stick-slip, on the bare shaft step (motor.shaft_speed_step)."""

import numpy as np
import pytest

from firmware_model.backend import NUMPY, SCALAR
from firmware_model.motor import (
    ARM_HORIZONTAL_RAD,
    DryFriction,
    arm_gravity_torque_nm,
    bridge_current_a,
    motor_current_a,
    rail_current_a,
    shaft_speed_step,
)
from firmware_model.params import ServoParams

P = ServoParams()
DT = 1e-3


DT_J = DT / P.total_inertia_kg_m2


def _step(angle, speed, applied, viscous_nm_s_rad=P.viscous_friction_nm_s_rad):
    """One step under ``applied`` N m; the angle moves with the speed the step starts from, as in the step loop."""
    friction = DryFriction.per_step(P.static_friction_nm, P.coulomb_friction_nm, P.stribeck_velocity_rad_s, DT_J)
    keep = 1.0 - viscous_nm_s_rad * DT_J if viscous_nm_s_rad else None
    return angle + speed * DT, shaft_speed_step(NUMPY, speed, applied * DT_J, friction, keep)


def test_sliding_to_rest_sticks_without_chatter():
    """A sliding shaft under a torque below static friction stops at exactly 0 and never flips sign."""
    angle, speed = np.zeros(1), np.array([2.0])
    speeds = []
    for _ in range(2000):
        angle, speed = _step(angle, speed, np.array([0.05]))  # helps the motion, but less than friction
        speeds.append(speed[0])
    speeds = np.array(speeds)
    stop = np.argmax(speeds == 0.0)
    assert stop > 0 and np.all(speeds[stop:] == 0.0) and np.all(speeds[:stop] > 0)


def test_breakaway_above_static_and_slip_at_coulomb():
    """From rest: 0.129 N m leaves it stuck, 0.131 N m starts it; once fast, friction falls toward Coulomb (Stribeck)."""
    for torque, moves in ((0.129, False), (0.131, True)):
        angle, speed = np.zeros(1), np.zeros(1)
        angle, speed = _step(angle, speed, np.array([torque]))
        assert (speed[0] > 0) == moves
    angle, speed = np.zeros(1), np.array([5.0])
    _, slower = _step(angle, speed, np.array([0.0]))
    decel = (5.0 - slower[0]) / DT * P.total_inertia_kg_m2
    assert decel == pytest.approx(P.coulomb_friction_nm + P.viscous_friction_nm_s_rad * 5.0, rel=0.01)
    _, slower = _step(angle, speed, np.array([0.0]), viscous_nm_s_rad=0.01)  # viscous friction adds b w
    decel = (5.0 - slower[0]) / DT * P.total_inertia_kg_m2
    assert decel == pytest.approx(P.coulomb_friction_nm + 0.01 * 5.0, rel=0.01)


def test_friction_never_turns_a_motion_round():
    """A sliding shaft pushed hard the other way stops at zero or reverses with the push, never past what the push gives."""
    _, fast_back = _step(np.zeros(1), np.array([0.01]), np.array([-0.05]))  # push below static: stops at exactly 0
    assert fast_back[0] == 0.0
    _, reversed_ = _step(np.zeros(1), np.array([0.01]), np.array([-2.0]))  # push far beyond friction: reverses
    free = 0.01 - 2.0 * DT_J
    assert free < reversed_[0] < 0.0


def test_motor_current_back_emf():
    """At the no-load speed the back-EMF cancels the supply: no current; at stall the current is V / R."""
    assert motor_current_a(1.0, 9.6, 9.6 / P.torque_constant_nm_a, P.torque_constant_nm_a, 6.3) == pytest.approx(0.0)
    assert motor_current_a(1.0, 9.6, 0.0, P.torque_constant_nm_a, 6.3) == pytest.approx(9.6 / 6.3)


def test_arm_gravity_convention():
    """Arm horizontal at raw 512 pulls CW with m g L; pointing straight up it pulls nothing."""
    moment = 0.1 * 9.80665 * 0.1
    assert arm_gravity_torque_nm(NUMPY, np.array([ARM_HORIZONTAL_RAD]), moment)[0] == pytest.approx(-moment)
    assert arm_gravity_torque_nm(NUMPY, np.array([ARM_HORIZONTAL_RAD + np.pi / 2]), moment)[0] == pytest.approx(0.0, abs=1e-12)


def test_bridge_passes_current_only_with_the_drive_when_coasting():
    """Fraction 0: current in the drive's direction flows, current against it (and any at zero drive) is blocked."""
    current = np.array([0.5, -0.5, -0.4, 0.3, -0.2])
    drive = np.array([0.8, -0.8, 0.1, -0.1, 0.0])
    assert np.array_equal(bridge_current_a(current, drive, 0.0), [0.5, -0.5, 0.0, 0.0, 0.0])
    assert [bridge_current_a(float(i), float(u), 0.0) for i, u in zip(current, drive)] == [0.5, -0.5, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("fraction", [1.0, 0.5])
def test_bridge_fraction_scales_only_the_braking_current(fraction):
    """Fraction 1 is a bridge that shorts the winding (everything flows); 0.5 passes half the braking current."""
    current, drive = np.array([0.5, -0.4, -0.2]), np.array([0.8, 0.1, 0.0])
    assert np.allclose(bridge_current_a(current, drive, fraction), [0.5, -0.4 * fraction, -0.2 * fraction])


def test_coasting_motor_keeps_its_speed_where_a_shorted_one_brakes():
    """At zero drive and 6 rad/s: the back-EMF current of a shorted winding stops the shaft within ~0.1 s; coasting,
    only dry friction slows it (about 0.1 N m over 4.4e-3 kg m^2: under 25 rad/s^2)."""
    k, r, eta = P.torque_constant_nm_a, P.winding_resistance_ohm, P.gearbox_efficiency
    finals = {}
    for fraction in (0.0, 1.0):
        angle, speed = np.zeros(1), np.array([6.0])
        for _ in range(100):
            current = bridge_current_a(motor_current_a(0.0, 9.6, speed, k, r), 0.0, fraction)
            angle, speed = _step(angle, speed, eta * k * current)
        finals[fraction] = speed[0]
    assert finals[1.0] < 0.5
    assert 6.0 - 0.1 * 25 < finals[0.0] < 6.0



def test_the_diodes_carry_current_only_past_the_rail():
    """Below the supply nothing flows back through the diodes; past it, the excess over the winding, against the
    motion (as currents: e / R and V / R)."""
    emf, supply = np.array([0.5, 1.2, -1.5, -0.9]), np.full(4, 1.0)
    assert np.allclose(rail_current_a(NUMPY, emf, supply), [0.0, -0.2, 0.5, 0.0])
    assert [rail_current_a(SCALAR, float(e), 1.0) for e in emf] == pytest.approx([0.0, -0.2, 0.5, 0.0])


@pytest.mark.parametrize("fraction", [0.0, 0.5])
def test_a_coasting_bridge_still_brakes_a_shaft_pushed_past_its_top_speed(fraction):
    """Driven forward while a load pushes it faster than the supply could (an overhauling load): the blocked share
    of the braking current returns through the diodes once the back-EMF passes the supply, so the shaft settles
    just above its top speed instead of running away."""
    k, r, eta = P.torque_constant_nm_a, P.winding_resistance_ohm, P.gearbox_efficiency
    volts, push_nm, drive = 9.6, 0.6, 0.5
    angle, speed = np.zeros(1), np.array([volts / k])  # at the rail
    for _ in range(3000):
        current = motor_current_a(drive, volts, speed, k, r)
        rail = rail_current_a(NUMPY, k * speed / r, np.full(1, volts / r))
        current = bridge_current_a(current, drive, fraction, rail)
        angle, speed = _step(angle, speed, eta * k * current + push_nm)
    assert volts / k < speed[0] < 1.5 * volts / k
