"""The X-series motor model: data-sheet figures reproduced when measured as a dynamometer would, and the step's behaviour.

Stall torque: the smallest opposing torque under which a shaft at full duty makes no forward progress in
0.5 s (bisection to 0.1 %).  No-load speed: the speed after 1.5 s at full duty, unloaded (some 15
mechanical time constants).  One parameter set per model, fitted to all its ratings at once; 7 %
tolerance as in ``tests/firmware_model/test_datasheets_all_models.py`` (the sheets' two-digit rounding
at two voltages plus the linear motor's own error).  Where the sheet's figures are not on one motor's
line, the miss is a strict xfail with the measured figure.
"""

from __future__ import annotations

import math

import pytest

from ax12emu.protocol.servo_models import model
from firmware_model.xseries.physics import GRAVITY_M_S2, XPhysics, XPhysicsParams

X_MODELS = ("xl330-m077", "xl330-m288", "xc330-m288", "xl430-w250", "xm430-w350")
TOLERANCE = 0.07
DT_S = 1e-3


def _params(key: str) -> XPhysicsParams:
    physical = model(key).physical
    ratings = [(r.voltage_v, r.stall_torque_nm, r.stall_current_a, r.no_load_speed_rpm) for r in physical.ratings]
    return XPhysicsParams.from_datasheet(gear_ratio=physical.gear_ratio, ratings=ratings)


def measured_stall_torque_nm(params: XPhysicsParams, volts: float) -> float:
    """Bisection on the opposing torque: below it a fully driven shaft creeps forward, above it does not."""
    low, high = 0.0, 3.0 * params.torque_constant_nm_a * volts / params.resistance_ohm
    while high - low > 1e-3 * high:
        load = 0.5 * (low + high)
        shaft = XPhysics(params, supply_v=volts)
        shaft.set_external_torque(-load)
        for _ in range(500):
            shaft.step(1.0, DT_S)
        if shaft.angle_rad > 0.0:
            low = load
        else:
            high = load
    return 0.5 * (low + high)


def measured_no_load(params: XPhysicsParams, volts: float) -> tuple[float, float]:
    """Settled speed (rpm) and current (A) at full duty, unloaded."""
    shaft = XPhysics(params, supply_v=volts)
    for _ in range(1500):
        shaft.step(1.0, DT_S)
    return shaft.velocity_rad_s * 60.0 / (2.0 * math.pi), shaft.current_a


#: Ratings whose stall torque one linear motor cannot follow across the sheet's voltages (measured figure).
STALL_NOT_LINEAR = {
    ("xl330-m077", 3.7): "0.155 N m against 0.180 (-14 %): the sheet's stall torque grows slower than the supply",
    ("xl330-m077", 6.0): "0.255 N m against 0.228 (+12 %): the sheet's stall torque grows slower than the supply",
    ("xl330-m288", 3.7): "0.387 N m against 0.42 (-8 %)",
    ("xl430-w250", 9.0): "1.076 N m against 1.0 (+7.6 %)",
}
#: The XL330-M077's sheet puts its stall torque per stall current above its back-EMF constant (efficiency
#: 1.3): the derivation keeps torque and speed and drops the current (module docstring).
STALL_CURRENT_DROPPED = {
    ("xl330-m077", 3.7): "1.43 A against 1.11 (+29 %)",
    ("xl330-m077", 5.0): "1.93 A against 1.47 (+32 %)",
    ("xl330-m077", 6.0): "2.32 A against 1.74 (+33 %)",
}
CASES = [(key, r.voltage_v) for key in X_MODELS for r in model(key).physical.ratings]
IDS = [f"{k}@{v}V" for k, v in CASES]


def _marked(table: dict) -> list:
    return [pytest.param(k, v, marks=pytest.mark.xfail(reason=table[(k, v)], strict=True)) if (k, v) in table else (k, v)
            for k, v in CASES]


@pytest.mark.parametrize(("key", "volts"), _marked(STALL_NOT_LINEAR), ids=IDS)
def test_stall_torque_matches_the_data_sheet(key, volts):
    """Measured stall torque at each rated voltage within 7 % of the sheet, one parameter set per model."""
    params = _params(key)
    stall = measured_stall_torque_nm(params, volts)
    assert stall == pytest.approx(params.stall_torque_nm(volts), rel=0.01)  # the simulated shaft does what the closed form says
    assert stall == pytest.approx(model(key).physical.rating_at(volts).stall_torque_nm, rel=TOLERANCE)


@pytest.mark.parametrize(("key", "volts"), CASES, ids=IDS)
def test_no_load_speed_matches_the_data_sheet(key, volts):
    """Measured no-load speed at each rated voltage within 7 % of the sheet (all within 2 %)."""
    speed_rpm, _ = measured_no_load(_params(key), volts)
    assert speed_rpm == pytest.approx(model(key).physical.rating_at(volts).no_load_speed_rpm, rel=TOLERANCE)


@pytest.mark.parametrize(("key", "volts"), _marked(STALL_CURRENT_DROPPED), ids=IDS)
def test_stall_current_matches_the_data_sheet(key, volts):
    """Winding current of a held shaft at full duty within 7 % of the sheet's stall current."""
    params = _params(key)
    shaft = XPhysics(params, supply_v=volts)
    shaft.set_external_torque(-2.0 * params.stall_torque_nm(volts))
    shaft.step(1.0, DT_S)  # one step: the shaft has barely moved
    assert shaft.current_a == pytest.approx(model(key).physical.rating_at(volts).stall_current_a, rel=TOLERANCE)


def test_derived_constants_are_physical():
    """Every model: efficiency at most one, a mechanical time constant of tens of ms (well above a 1 ms step)."""
    for key in X_MODELS:
        p = _params(key)
        assert 0.5 < p.gearbox_efficiency <= 1.0, key
        assert 0.02 < p.inertia_kg_m2 / p.back_emf_damping_nm_s_rad < 0.3, key
        assert 0 < p.coulomb_friction_nm < 0.05 * p.stall_torque_nm(5.0 if "330" in key else 12.0), key


def test_xl330_m288_inertia_is_bams_fitted_armature():
    """The inertia reference: the XL330-M288 gets BAM's fitted armature (bam/params/xl330/m1.json) exactly."""
    assert _params("xl330-m288").inertia_kg_m2 == pytest.approx(0.0018141672784458866, rel=1e-9)


def test_from_datasheet_refuses_impossible_ratings():
    with pytest.raises(ValueError, match="at least one rating"):
        XPhysicsParams.from_datasheet(gear_ratio=100.0, ratings=[])
    with pytest.raises(ValueError, match="all positive"):
        XPhysicsParams.from_datasheet(gear_ratio=100.0, ratings=[(5.0, 0.0, 1.0, 100.0)])
    with pytest.raises(ValueError, match="gear_ratio"):
        XPhysicsParams.from_datasheet(gear_ratio=0.0, ratings=[(5.0, 0.5, 1.0, 100.0)])
    with pytest.raises(ValueError, match="resistance_ohm"):
        XPhysicsParams(gear_ratio=1, resistance_ohm=-1, torque_constant_nm_a=1, back_emf_v_s_rad=1, inertia_kg_m2=1,
                       coulomb_friction_nm=0, viscous_friction_nm_s_rad=0)


def test_one_rating_is_met_exactly():
    p = XPhysicsParams.from_datasheet(gear_ratio=288.4, ratings=[(5.0, 0.52, 1.47, 103.0)])
    assert p.stall_torque_nm(5.0) == pytest.approx(0.52)
    assert p.stall_current_a(5.0) == pytest.approx(1.47)
    assert p.no_load_speed_rad_s(5.0) * 60 / (2 * math.pi) == pytest.approx(103.0)


def _pendulum(dt_s: float, duration_s: float, *, driven: bool, duty: float = 0.0, params: XPhysicsParams | None = None):
    params = params or _params("xl330-m288")
    shaft = XPhysics(params, supply_v=7.4, angle_rad=1.0)
    shaft.set_load(inertia_kg_m2=0.49 * 0.1**2, gravity_torque_nm=0.49 * GRAVITY_M_S2 * 0.1)
    trace = []
    for _ in range(round(duration_s / dt_s)):
        shaft.step(duty, dt_s, driven=driven)
        trace.append(shaft.angle_rad)
    return shaft, trace


def test_a_1ms_step_follows_a_fine_step():
    """A driven (braking) and a coasting pendulum at 1 ms stay within 0.01 rad of the same at 0.05 ms (no substeps needed)."""
    for driven in (True, False):
        _, coarse = _pendulum(1e-3, 1.0, driven=driven)
        _, fine = _pendulum(5e-5, 1.0, driven=driven)
        worst = max(abs(a - b) for a, b in zip(coarse, fine[19::20]))
        assert worst < 0.01, (driven, worst)


def test_torque_off_coasts_with_no_current_and_friction_stops_it_at_rest():
    """Bridge open: no current; the pendulum swings, loses energy to friction only, and comes to rest hanging down."""
    shaft, trace = _pendulum(1e-3, 0.3, driven=False)
    assert shaft.current_a == 0.0 and shaft.motor_torque_nm == 0.0
    assert min(trace) < 0.0  # swung through the bottom
    shaft, trace = _pendulum(1e-3, 20.0, driven=False)
    assert shaft.velocity_rad_s == 0.0
    assert abs(math.sin(shaft.angle_rad)) * 0.49 * GRAVITY_M_S2 * 0.1 <= shaft.params.coulomb_friction_nm + 1e-12


def test_frictionless_coasting_pendulum_keeps_its_energy():
    """No friction, bridge open: the amplitude after 5 s of swinging is within 1 % of the start (symplectic step)."""
    p = _params("xl330-m288")
    frictionless = XPhysicsParams(**{**p.__dict__, "coulomb_friction_nm": 0.0, "viscous_friction_nm_s_rad": 0.0})
    _, trace = _pendulum(1e-3, 5.0, driven=False, params=frictionless)
    assert max(trace[-1500:]) == pytest.approx(1.0, rel=0.01)


def test_driven_at_zero_duty_brakes_harder_than_coasting():
    """Zero duty with the bridge driven shorts the winding: the back-EMF brakes the swing."""
    braked, _ = _pendulum(1e-3, 0.5, driven=True)
    coasted, _ = _pendulum(1e-3, 0.5, driven=False)
    assert abs(braked.angle_rad) + abs(braked.velocity_rad_s) < abs(coasted.angle_rad) + abs(coasted.velocity_rad_s)


def test_external_torque_sign_and_holding_within_friction():
    p = _params("xl330-m288")
    shaft = XPhysics(p, supply_v=5.0)
    shaft.set_external_torque(0.9 * p.coulomb_friction_nm)
    for _ in range(100):
        shaft.step(0.0, DT_S, driven=False)
    assert shaft.angle_rad == 0.0 and shaft.velocity_rad_s == 0.0  # held by friction
    shaft.set_external_torque(5.0 * p.coulomb_friction_nm)
    for _ in range(100):
        shaft.step(0.0, DT_S, driven=False)
    assert shaft.velocity_rad_s > 0.0  # counter-clockwise


def test_the_angle_counts_turns_and_duty_is_clipped():
    p = _params("xl330-m077")
    shaft = XPhysics(p, supply_v=5.0)
    for _ in range(3000):
        shaft.step(5.0, DT_S)  # clipped to full duty
    assert shaft.velocity_rad_s == pytest.approx(p.no_load_speed_rad_s(5.0), rel=0.01)
    assert shaft.angle_rad > 4 * math.pi  # more than two turns, not wrapped


def test_supply_is_settable_and_scales_the_drive():
    p = _params("xl330-m288")
    shaft = XPhysics(p, supply_v=5.0)
    for _ in range(1500):
        shaft.step(1.0, DT_S)
    at_5v = shaft.velocity_rad_s
    shaft.supply_v = 6.0
    for _ in range(1500):
        shaft.step(1.0, DT_S)
    assert shaft.velocity_rad_s == pytest.approx(p.no_load_speed_rad_s(6.0), rel=0.01) and shaft.velocity_rad_s > at_5v


def test_load_dependent_friction_holds_a_heavier_load_and_stribeck_sticks_more():
    """The extra terms: gear friction growing with the carried torque; Stribeck friction at rest only."""
    p = _params("xl330-m288")
    load = 3.0 * p.coulomb_friction_nm
    plain = XPhysics(p, supply_v=5.0)
    geared = XPhysics(XPhysicsParams(**{**p.__dict__, "load_friction_external": 0.8}), supply_v=5.0)
    sticky = XPhysics(XPhysicsParams(**{**p.__dict__, "stribeck_friction_nm": 3.0 * p.coulomb_friction_nm}), supply_v=5.0)
    for shaft in (plain, geared, sticky):
        shaft.set_external_torque(load)
        for _ in range(100):
            shaft.step(0.0, DT_S, driven=False)
    assert plain.velocity_rad_s > 0.0
    assert geared.velocity_rad_s == 0.0 and sticky.velocity_rad_s == 0.0
    spinning = XPhysics(XPhysicsParams(**{**p.__dict__, "stribeck_friction_nm": 0.1, "stribeck_velocity_rad_s": 0.5}),
                        supply_v=5.0)
    for _ in range(1500):
        spinning.step(1.0, DT_S)
    assert spinning.velocity_rad_s == pytest.approx(p.no_load_speed_rad_s(5.0), rel=1e-3)  # gone at speed


def test_a_soft_supply_sags_with_the_bridge_current_and_weakens_the_stall():
    """The bridge draws duty * i from a supply with resistance R_s: i = duty V / (R + duty**2 R_s) at rest."""
    p = _params("xl330-m288")
    for duty in (1.0, 0.5):
        shaft = XPhysics(p, supply_v=7.4, supply_resistance_ohm=1.0)
        shaft.set_external_torque(-5.0)  # held at rest (pushed back, but one step barely moves it)
        shaft.step(duty, 1e-6)
        assert shaft.current_a == pytest.approx(duty * 7.4 / (p.resistance_ohm + duty**2 * 1.0), rel=1e-3)
        assert shaft.bus_voltage_v == pytest.approx(7.4 - 1.0 * duty * shaft.current_a, rel=1e-6)
    stiff = XPhysics(p, supply_v=7.4)
    stiff.step(1.0, DT_S)
    assert stiff.bus_voltage_v == 7.4
    stiff.step(1.0, DT_S, driven=False)
    assert stiff.bus_voltage_v == 7.4 and stiff.current_a == 0.0
    with pytest.raises(ValueError, match="supply_resistance_ohm"):
        XPhysics(p, supply_v=7.4, supply_resistance_ohm=-1.0)


def test_load_dependent_friction_at_rest_holds_a_driven_shaft_that_sliding_friction_would_not():
    """Gear friction at rest growing with the motor's torque: a driven shaft against a load stays put; the same
    torques with the shaft already sliding keep it going (the at-rest part has faded)."""
    p = _params("xl330-m288")
    sticky = XPhysicsParams(**{**p.__dict__, "load_stribeck_motor": 0.6, "stribeck_velocity_rad_s": 0.05})
    load = 0.3
    duty = 0.7 * (load + p.coulomb_friction_nm) / p.stall_torque_nm(7.4) + 0.3  # drive above the load, below the held band
    held = XPhysics(sticky, supply_v=7.4)
    held.set_external_torque(-load)
    for _ in range(200):
        held.step(duty, DT_S)
    assert held.angle_rad == 0.0
    moving = XPhysics(sticky, supply_v=7.4)
    moving.set_external_torque(-load)
    moving.velocity_rad_s = 1.0
    for _ in range(200):
        moving.step(duty, DT_S)
    assert moving.velocity_rad_s > 0.5


def test_quadratic_gear_friction_costs_more_at_high_motor_torque():
    """The quadratic term: a driven shaft's steady speed falls by more at full duty than at half (friction ~ tau_m**2)."""
    p = _params("xl330-m288")
    quad = XPhysicsParams(**{**p.__dict__, "load_friction_motor_quadratic_per_nm": 1.0})
    losses = []
    for duty in (0.5, 1.0):
        speeds = []
        for params in (p, quad):
            shaft = XPhysics(params, supply_v=7.4)
            shaft.set_external_torque(-0.5 * duty * params.stall_torque_nm(7.4))  # a load, so the motor carries torque
            for _ in range(1500):
                shaft.step(duty, DT_S)
            speeds.append(shaft.velocity_rad_s)
        losses.append(speeds[0] - speeds[1])
    assert 0.0 < losses[0] and 2.0 * losses[0] < losses[1]
