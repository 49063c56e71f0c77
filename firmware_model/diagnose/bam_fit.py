"""Fit an X-series servo's physics to real BAM pendulum logs, and measure the fit on logs it has not seen.

Why it exists: a friction model earns its terms by predicting what it was not fitted on.  Rhoban's BAM
(github.com/Rhoban/bam; Duclusaud, Passault et al., "Extended Friction Models for the Physics
Simulation of Servo Actuators", ICRA 2025) fits each model on pendulum logs at some Position P Gains and
scores it by the mean absolute position error (MAE) of a closed-loop rollout on logs at a gain held out
(``bam/fit.py``: ``compute_score``, ``--validation_kp``).  This module does the same with this project's
own firmware model and physics: the log's goals go through the firmware (:mod:`firmware_model.xseries
.bam_replay`), the physics parameters are fitted by least squares on position, and the MAE is measured
per log.

Two parameter sets are fitted the same way (same logs, same motor parameters, same optimiser), differing
only in friction:

* :data:`BASELINE`: Coulomb + viscous (BAM's M1, the friction of common simulators);
* :data:`MODEL`: the same plus gear friction that grows with the torque the gears carry, from the motor
  side and from the load side, ``|mu_e tau_e - mu_m tau_m| + q_m tau_m**2`` (BAM's load-dependent
  directional friction and a quadratic motor-side term: the sliding parts of its M5 and M6).  Why the
  quadratic term: on the kp = 100 logs the equation-error residual of the linear terms grows with the
  motor torque (the shaft accelerates more than they predict at 0.03..0.2 N m and less at 0.3..0.4);
  with it the fit's position MAE on those logs drops from 25 to 18 mrad.

Both fit the back-EMF constant, the gearbox's efficiency ``k_t / k_e`` (at most 1), the reflected inertia,
the Coulomb and viscous terms and the pendulum's hanging angle (BAM's ``q_offset``); the winding
resistance stays at the data sheet's (the positions depend on ``k_t / R`` and ``k_t k_e / R`` only, so
it cannot be fitted with the others).  Two fits: :func:`initial_values`, least squares on the torque
balance of the moving shaft driven by the logged Present PWM (equation error), and :func:`fit`, least
squares on the closed-loop positions (simulation error) started from it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from firmware_model.xseries.bam_log import PWM_FULL_SCALE, PendulumLog
from firmware_model.xseries.bam_replay import replay_positions
from firmware_model.xseries.interface import XServoModel
from firmware_model.xseries.physics import GRAVITY_M_S2, XPhysics, XPhysicsParams

__all__ = ["FitParameter", "FitResult", "BASELINE", "MODEL", "MIN_SPEED_RAD_S", "physics_from", "initial_values", "fit", "position_mae"]

MakeModel = Callable[[XPhysics], XServoModel]


@dataclass(frozen=True)
class FitParameter:
    """One fitted number: an :class:`XPhysicsParams` field, ``efficiency`` (``k_t = efficiency k_e``) or ``gravity_zero_rad``."""

    name: str
    initial: float
    low: float
    high: float


_COMMON = (
    FitParameter("back_emf_v_s_rad", 0.41, 0.1, 1.5),
    FitParameter("inertia_kg_m2", 0.0019, 1e-4, 0.01),
    FitParameter("coulomb_friction_nm", 0.012, 0.0, 0.2),
    FitParameter("viscous_friction_nm_s_rad", 0.004, 0.0, 0.1),
    FitParameter("gravity_zero_rad", 0.0, -0.1, 0.1),
)
#: Coulomb + viscous friction, a constant gearbox efficiency (BAM's M1).
BASELINE = (FitParameter("efficiency", 0.85, 0.3, 1.0), *_COMMON)
#: The baseline plus gear friction growing with the torque the gears carry, from the motor side and from the
#: load side, and with the square of the motor's (the sliding parts of BAM's M5 and M6).
MODEL = (
    *BASELINE,
    FitParameter("load_friction_motor", 0.3, 0.0, 0.9),
    FitParameter("load_friction_external", 0.1, 0.0, 0.9),
    FitParameter("load_friction_motor_quadratic_per_nm", 0.3, 0.0, 3.0),
)


def physics_from(base: XPhysicsParams, values: dict[str, float]) -> tuple[XPhysicsParams, float]:
    """``base`` with the fitted ``values`` put in; returns the parameters and the pendulum's hanging angle."""
    values = dict(values)
    zero = values.pop("gravity_zero_rad", 0.0)
    efficiency = values.pop("efficiency", 1.0)
    back_emf = values.get("back_emf_v_s_rad", base.back_emf_v_s_rad)
    values["torque_constant_nm_a"] = efficiency * back_emf
    return dataclasses.replace(base, **values), zero


@dataclass(frozen=True)
class FitResult:
    values: dict[str, float]
    params: XPhysicsParams
    gravity_zero_rad: float
    #: Root mean square of the position residuals over the fitted logs, rad.
    rms_rad: float
    evaluations: int


#: Samples slower than this (rad/s) are left out of the equation-error fit: its dry friction there is
#: anything within the band, so the equation says nothing about it.
MIN_SPEED_RAD_S = 0.1
#: The equation-error fit's uniform resampling step and Savitzky-Golay windows (samples) for speed and acceleration.
_RESAMPLE_S = 0.005
_SPEED_WINDOW = 15
_ACCEL_WINDOW = 21


def _dynamics_rows(log: PendulumLog) -> tuple[np.ndarray, ...]:
    """Per moving sample: applied volts (0 with torque off), speed, acceleration, angle, torque on (the log's frame)."""
    t = np.arange(log.time_s[0], log.time_s[-1], _RESAMPLE_S)
    q = np.interp(t, log.time_s, log.position_rad)
    w = savgol_filter(q, _SPEED_WINDOW, 3, deriv=1, delta=_RESAMPLE_S)
    a = savgol_filter(q, _ACCEL_WINDOW, 3, deriv=2, delta=_RESAMPLE_S)
    on = np.interp(t, log.time_s, log.torque_enable.astype(float)) > 0.5
    volts = np.interp(t, log.time_s, log.present_pwm) / PWM_FULL_SCALE * log.supply_v * on
    moving = np.abs(w) > MIN_SPEED_RAD_S
    return volts[moving], w[moving], a[moving], q[moving], on[moving].astype(float)


def _equation_residuals(rows: tuple[np.ndarray, ...], params: XPhysicsParams, zero: float) -> np.ndarray:
    """Torque balance of the moving shaft, N m: inertia times acceleration less every torque the physics puts on it."""
    volts, w, a, q, on, moment, load_inertia = rows
    motor_nm = params.torque_constant_nm_a * (volts - params.back_emf_v_s_rad * w * on) / params.resistance_ohm
    gravity_nm = -moment * np.sin(q - zero)
    # Sliding friction as XPhysics spends it (its at-rest part has faded at these speeds).
    budget = (params.coulomb_friction_nm + np.abs(params.load_friction_external * gravity_nm - params.load_friction_motor * motor_nm)
              + params.load_friction_motor_quadratic_per_nm * motor_nm**2)
    friction_nm = -np.sign(w) * budget - params.viscous_friction_nm_s_rad * w
    return (params.inertia_kg_m2 + load_inertia) * a - (motor_nm + gravity_nm + friction_nm)


def initial_values(logs: Sequence[PendulumLog], spec: Sequence[FitParameter], *, base: XPhysicsParams) -> dict[str, float]:
    """The equation-error fit, and the position fit's start: least squares on the torque balance of the moving shaft.

    The logs record the duty the firmware applied (Present PWM), so each moving sample (speed above
    :data:`MIN_SPEED_RAD_S`, from Savitzky-Golay derivatives of the positions resampled at 5 ms) gives one
    equation ``(J + J_load) a = tau_motor + tau_gravity + tau_friction`` with the physics' own terms (motor
    from the applied volts and the speed, friction as :class:`XPhysics` spends it while sliding).  This
    identifies the plant from its input and output, not through the closed loop, so no stop that the
    loop happens to make decides it.  Bounded least squares over the spec's parameters (the same bounds
    as the position fit); friction at rest is invisible to it and keeps its initial value.
    """
    rows = []
    for log in logs:
        volts, w, a, q, on = _dynamics_rows(log)
        rows.append((volts, w, a, q, on, np.full(len(w), log.gravity_moment_nm(GRAVITY_M_S2)), np.full(len(w), log.inertia_kg_m2)))
    stacked = tuple(np.concatenate(c) for c in zip(*rows))
    names = [p.name for p in spec]
    low = np.array([p.low for p in spec])
    high = np.array([p.high for p in spec])

    def residuals(x: np.ndarray) -> np.ndarray:
        params, zero = physics_from(base, dict(zip(names, x)))
        return _equation_residuals(stacked, params, zero)

    x0 = np.array([p.initial for p in spec])
    result = least_squares(residuals, x0, bounds=(low, high), x_scale=0.1 * (high - low))
    return {n: float(v) for n, v in zip(names, result.x)}


def _residuals(logs: Sequence[PendulumLog], params: XPhysicsParams, zero: float, make_model: MakeModel) -> np.ndarray:
    # Each log weighs the same whatever its sample count (BAM averages the per-log MAE).
    return np.concatenate([
        (replay_positions(log, params, make_model, gravity_zero_rad=zero) - log.position_rad) / np.sqrt(len(log.time_s))
        for log in logs
    ])


def fit(logs: Sequence[PendulumLog], spec: Sequence[FitParameter], make_model: MakeModel, *, base: XPhysicsParams,
        start: dict[str, float] | None = None, max_evaluations: int = 400) -> FitResult:
    """Least squares on position over ``logs`` (trust region within the bounds), from ``start`` (default: the
    equation-error fit, :func:`initial_values`).  ``max_evaluations`` caps the replays of the logs, not counting
    the finite-difference Jacobian's (one more replay per parameter and step)."""
    names = [p.name for p in spec]
    start = initial_values(logs, spec, base=base) if start is None else start
    x0 = np.array([start[name] for name in names])
    low = np.array([p.low for p in spec])
    high = np.array([p.high for p in spec])

    def residuals(x: np.ndarray) -> np.ndarray:
        params, zero = physics_from(base, dict(zip(names, x)))
        return _residuals(logs, params, zero, make_model)

    result = least_squares(residuals, x0, bounds=(low, high), x_scale=0.1 * (high - low), diff_step=1e-3,
                           max_nfev=max_evaluations)
    values = {n: float(v) for n, v in zip(names, result.x)}
    params, zero = physics_from(base, values)
    rms = float(np.sqrt(np.sum(result.fun**2) / len(logs)))
    return FitResult(values=values, params=params, gravity_zero_rad=zero, rms_rad=rms, evaluations=int(result.nfev))


def position_mae(logs: Sequence[PendulumLog], params: XPhysicsParams, gravity_zero_rad: float,
                 make_model: MakeModel) -> list[float]:
    """Mean absolute Present Position error (rad) of the closed-loop replay, per log (BAM's ``compute_score``)."""
    return [float(np.mean(np.abs(replay_positions(log, params, make_model, gravity_zero_rad=gravity_zero_rad)
                                 - log.position_rad))) for log in logs]
