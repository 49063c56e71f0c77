"""The setpoint generator: the report's state machine (section 3.1), its limits and mid-move changes."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from firmware_model.backend import NUMPY, SCALAR
from firmware_model.setpoint import ACCEL_NEG, ACCEL_POS, CRUISE_POS, REST, apply_dead_zone, setpoint_step, state_code

A, DT = 200.0, 1e-3


def _run(ref, vel, goal, vmax, steps, xp=NUMPY):
    refs, vels = [ref], [vel]
    for _ in range(steps):
        ref, vel = setpoint_step(xp, ref, vel, goal, vmax, A, DT)
        refs.append(ref)
        vels.append(vel)
    return np.array(refs, dtype=float), np.array(vels, dtype=float)


segment = st.tuples(
    st.floats(0.0, 5.2),  # goal, rad
    st.floats(0.5, 12.0),  # max speed, rad/s
    st.integers(1, 400),  # steps before the next change
)


@settings(max_examples=120, deadline=None)
@given(start=st.floats(0.0, 5.2), segments=st.lists(segment, min_size=1, max_size=6))
def test_random_changes_respect_limits_and_end_at_goal(start, segments):
    """Hypothesis: any goal/speed changes keep |dv| <= a dt and |v| <= max(v_max, |v_prev|), and end at rest on the goal."""
    ref, vel = np.array([start]), np.array([0.0])
    for i, (goal, vmax, steps) in enumerate(segments):
        if i == len(segments) - 1:  # the last one runs long enough to finish
            steps = int(math.ceil((abs(goal - ref[0]) + 1.0) / vmax / DT + 2 * 12.0 / (A * DT))) + 200
        refs, vels = _run(float(ref[0]), float(vel[0]), goal, vmax, steps, xp=SCALAR)
        refs, vels = refs.reshape(-1, 1), vels.reshape(-1, 1)
        dv = np.abs(np.diff(vels[:, 0]))
        assert dv.max() <= A * DT * (1 + 1e-9)
        bound = np.maximum(vmax, np.abs(vels[:-1, 0]))
        assert np.all(np.abs(vels[1:, 0]) <= bound * (1 + 1e-9) + 1e-12)
        ref, vel = refs[-1], vels[-1]
    assert ref[0] == pytest.approx(segments[-1][0], abs=1e-9)
    assert abs(vel[0]) <= 1e-9


def test_trapezoid_profile_states():
    """A long move passes through the report's states 1 -> 2 -> 3 -> 4 -> 1 and lands exactly."""
    refs, vels = _run(np.array([0.0]), np.array([0.0]), 3.0, 5.0, 1000)
    codes = [int(state_code(vels[i + 1], vels[i], 5.0)[0]) for i in range(len(vels) - 1)]
    seen = [c for i, c in enumerate(codes) if i == 0 or c != codes[i - 1]]
    assert seen[:3] == [ACCEL_POS, CRUISE_POS, ACCEL_NEG] and seen[-1] == REST  # a last-step landing tweak may sit between
    assert refs[-1, 0] == pytest.approx(3.0, abs=1e-12)
    # Cruise time + accel time: 3/5 + 5/200 = 0.625 s, to within two steps.
    arrival = np.argmax(np.abs(refs[:, 0] - 3.0) < 1e-12) * DT
    assert arrival == pytest.approx(0.625, abs=2 * DT)


def test_reversal_mid_move_brakes_then_returns():
    """A goal behind the moving reference: it brakes at a (no jump), turns and settles on the new goal."""
    refs, vels = _run(np.array([0.0]), np.array([0.0]), 3.0, 5.0, 300)
    refs2, vels2 = _run(refs[-1], vels[-1], 0.5, 5.0, 1500)
    assert np.abs(np.diff(vels2[:, 0])).max() <= A * DT + 1e-12
    assert vels2[:, 0].min() < 0 < vels2[0, 0]
    assert refs2[-1, 0] == pytest.approx(0.5, abs=1e-12)


def test_lower_speed_mid_move_decelerates_to_it():
    """Moving Speed lowered while cruising: it decelerates at a to the new speed, then cruises there."""
    refs, vels = _run(np.array([0.0]), np.array([0.0]), 5.0, 5.0, 100)
    _, vels2 = _run(refs[-1], vels[-1], 5.0, 2.0, 100)
    assert np.all(np.diff(vels2[:16, 0]) == pytest.approx(-A * DT))
    assert vels2[-1, 0] == pytest.approx(2.0)


def test_goal_inside_braking_distance_overshoots_and_returns():
    """A goal closer than v^2/2a: braking at a overshoots it, then the reference comes back."""
    refs, vels = _run(np.array([0.0]), np.array([0.0]), 5.0, 5.0, 200)  # at 5 rad/s, braking distance 62 mm-rad
    goal = refs[-1, 0] + 0.02
    refs2, _ = _run(refs[-1], vels[-1], goal, 5.0, 600)
    assert refs2[:, 0].max() > goal + 0.02
    assert refs2[-1, 0] == pytest.approx(goal, abs=1e-12)


def test_dead_zone_takes_close_goal_as_reached():
    """Report's eps (0.001 rad): a goal within eps of a resting reference is reached at once; a moving one is not."""
    assert apply_dead_zone(np.array([1.0]), np.array([0.0]), np.array([1.0009]), 0.001)[0] == 1.0009
    assert apply_dead_zone(np.array([1.0]), np.array([0.0]), np.array([1.002]), 0.001)[0] == 1.0
    assert apply_dead_zone(np.array([1.0]), np.array([0.1]), np.array([1.0005]), 0.001)[0] == 1.0


def test_scalar_and_numpy_backends_agree():
    """The float path used for one servo gives the numpy path's numbers exactly."""
    refs_np, vels_np = _run(np.array([0.3]), np.array([0.0]), 2.0, 4.0, 700)
    refs_sc, vels_sc = _run(0.3, 0.0, 2.0, 4.0, 700, xp=SCALAR)
    np.testing.assert_allclose(refs_np[:, 0], refs_sc, rtol=0, atol=1e-12)
    np.testing.assert_allclose(vels_np[:, 0], vels_sc, rtol=0, atol=1e-12)
