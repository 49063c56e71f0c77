"""The X-series profile planner: every plan is continuous, bounded by its registers and ends at rest on the goal."""

from __future__ import annotations

import random

import pytest

from firmware_model.xseries.profile import (
    ACCEL_UNIT_PULSES_S2,
    PROFILE_RECTANGULAR,
    PROFILE_STEP,
    PROFILE_TRAPEZOIDAL,
    PROFILE_TRIANGULAR,
    VELOCITY_UNIT_PULSES_S,
    plan_time_based,
    plan_velocity_based,
)


def _sample(profile, dt_s=0.0005):
    t = 0.0
    out = []
    while t <= profile.end_s + 2 * dt_s:
        out.append(profile.at(t))
        t += dt_s
    return out


@pytest.mark.parametrize("seed", range(40))
def test_velocity_based_plans_from_any_start_are_continuous_bounded_and_end_on_the_goal(seed):
    rng = random.Random(seed)
    v_reg, a_reg = rng.randint(1, 400), rng.randint(1, 200)
    v_max, a_max = v_reg * VELOCITY_UNIT_PULSES_S, a_reg * ACCEL_UNIT_PULSES_S2
    start, goal = rng.uniform(-5000, 5000), rng.uniform(-5000, 5000)
    v0 = rng.uniform(-1.5, 1.5) * v_max  # an override may start faster than the new Profile Velocity, or backwards
    profile = plan_velocity_based(start, v0, goal, v_reg, a_reg)
    samples = _sample(profile)
    assert samples[0][0] == pytest.approx(start) and samples[0][1] == pytest.approx(v0)
    assert samples[-1][:2] == (goal, 0.0)
    dt = 0.0005
    for (p1, v1, _), (p2, v2, _) in zip(samples, samples[1:]):
        assert abs(v2 - v1) <= a_max * dt * 1.0001 + 1e-9  # velocity continuous, acceleration bounded
        assert abs(p2 - p1) <= (max(abs(v1), abs(v2)) + a_max * dt) * dt + 1e-6  # a peak may fall between samples
        assert abs(v2) <= max(v_max, abs(v0)) * 1.0001
    assert profile.kind in (PROFILE_TRIANGULAR, PROFILE_TRAPEZOIDAL)


def test_profile_kinds_follow_the_emanual_conditions():
    assert plan_velocity_based(0.0, 0.0, 1000.0, 0, 50).kind == PROFILE_STEP  # Profile Velocity 0: no profile
    assert plan_velocity_based(0.0, 0.0, 1000.0, 100, 0).kind == PROFILE_RECTANGULAR
    # V_PRFL_TRI = sqrt(A * dPos) in register units: 100 for A = 10, dPos = 1000
    assert plan_velocity_based(0.0, 0.0, 1000.0, 120, 10).kind == PROFILE_TRIANGULAR
    assert plan_velocity_based(0.0, 0.0, 1000.0, 80, 10).kind == PROFILE_TRAPEZOIDAL


@pytest.mark.parametrize(("t3_ms", "t1_ms", "v0"), [(1000, 200, 0.0), (600, 500, 0.0), (800, 0, 0.0), (1200, 300, 900.0)])
def test_time_based_plans_last_profile_velocity_ms_and_accelerate_for_profile_acceleration_ms(t3_ms, t1_ms, v0):
    profile = plan_time_based(100.0, v0, 2100.0, t3_ms, t1_ms)
    assert profile.end_s == pytest.approx(t3_ms / 1000)
    accel_s = min(t1_ms, t3_ms // 2) / 1000  # at most half the travel time (e-manual)
    if accel_s:
        assert profile.segments[0][0] == pytest.approx(accel_s)
    assert profile.at(profile.end_s) == (2100.0, 0.0, 0.0)
    # just before the end the trajectory is still short of the goal and slowing to rest
    p, v, _ = profile.at(profile.end_s - 0.001)
    assert p < 2100.0 and (v > 0 if accel_s else True)
