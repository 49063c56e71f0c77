"""Fitting X-series physics to pendulum logs: the equation-error fit recovers known constants from a simulated log,
and the position fit does not make a fit worse on the logs it fits."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from firmware_model.diagnose.bam_fit import BASELINE, MODEL, fit, initial_values, physics_from, position_mae
from firmware_model.xseries.bam_log import PendulumLog
from firmware_model.xseries.bam_replay import replay
from firmware_model.xseries.firmware import XFirmware
from firmware_model.xseries.physics import XPhysicsParams

BASE = XPhysicsParams.from_datasheet(gear_ratio=288.4, ratings=[(3.7, 0.42, 1.11, 76), (5.0, 0.52, 1.47, 103), (6.0, 0.60, 1.74, 123)])
TRUTH = {"efficiency": 0.9, "back_emf_v_s_rad": 0.40, "inertia_kg_m2": 0.0021, "coulomb_friction_nm": 0.008,
         "viscous_friction_nm_s_rad": 0.004, "gravity_zero_rad": 0.02, "load_friction_motor": 0.25, "load_friction_external": 0.1}


def _firmware(physics):
    return XFirmware(physics, current_unit_a=0.001, position_output_scale=0.5)


def _simulated(params: XPhysicsParams, zero: float, kp: int, goal: np.ndarray, enable: np.ndarray, period_s=0.005) -> PendulumLog:
    """A log as the recorder would have written it of a servo with ``params``: positions and Present PWM replayed."""
    n = len(goal)
    zeros = np.zeros(n)
    log = PendulumLog(name=f"sim_kp{kp}", motor="xl330", trajectory="sim", kp=kp, supply_v=7.4, mass_kg=0.49, length_m=0.1,
                      arm_mass_kg=0.0, time_s=0.0035 + period_s * np.arange(n), position_rad=zeros, goal_position_rad=goal,
                      speed_rad_s=zeros, present_pwm=zeros.astype(np.int64), input_voltage_v=zeros + 7.4,
                      temperature_c=zeros + 29, torque_enable=enable)
    positions, pwm = replay(log, params, _firmware, gravity_zero_rad=zero)
    return dataclasses.replace(log, position_rad=positions, present_pwm=pwm)


def _logs(params, zero, kp=100):
    t = np.arange(1200) * 0.005
    swing = 1.2 * np.sin(2 * math.pi * t / 2.5) * np.sin(2 * math.pi * t / 6.0)
    chirp = 1.0 * np.sin(2 * math.pi * (0.3 + 0.15 * t) * t)
    lift = np.where(t < 2.0, -1.5 * np.sin(math.pi * t / 4.0), -1.5)
    return [_simulated(params, zero, kp, swing, np.ones(len(t), bool)), _simulated(params, zero, kp, chirp, np.ones(len(t), bool)),
            _simulated(params, zero, kp, lift, t < 2.0)]


def test_the_equation_error_fit_recovers_the_constants_of_a_simulated_servo():
    """From the logged positions and Present PWM alone: back-EMF and efficiency within 10 %, inertia within 15 %, the
    hanging angle within 5 mrad, the load-dependent friction shares within 0.05."""
    truth, zero = physics_from(BASE, TRUTH)
    found = initial_values(_logs(truth, zero), MODEL, base=BASE)
    assert found["back_emf_v_s_rad"] == pytest.approx(TRUTH["back_emf_v_s_rad"], rel=0.10)
    assert found["efficiency"] == pytest.approx(TRUTH["efficiency"], rel=0.10)
    assert found["inertia_kg_m2"] == pytest.approx(TRUTH["inertia_kg_m2"], rel=0.15)
    assert found["gravity_zero_rad"] == pytest.approx(zero, abs=5e-3)
    assert found["load_friction_motor"] == pytest.approx(TRUTH["load_friction_motor"], abs=0.05)
    assert found["load_friction_external"] == pytest.approx(TRUTH["load_friction_external"], abs=0.05)


def test_the_position_fit_starts_from_the_equation_error_fit_and_does_not_end_worse():
    """A short position fit (two trust-region steps) on one simulated log: values within their bounds, the replayed
    error no larger than at its start (the equation-error fit)."""
    truth, zero = physics_from(BASE, TRUTH)
    log = _logs(truth, zero)[0]
    log = dataclasses.replace(log, **{f: getattr(log, f)[:300] for f in ("time_s", "position_rad", "goal_position_rad",
                                                                        "speed_rad_s", "present_pwm", "input_voltage_v",
                                                                        "temperature_c", "torque_enable")})
    start = initial_values([log], BASELINE, base=BASE)
    result = fit([log], BASELINE, _firmware, base=BASE, start=start, max_evaluations=2)
    assert all(p.low <= result.values[p.name] <= p.high for p in BASELINE)
    start_params, start_zero = physics_from(BASE, start)
    before = position_mae([log], start_params, start_zero, _firmware)[0]
    after = position_mae([log], result.params, result.gravity_zero_rad, _firmware)[0]
    assert after <= before * 1.05
