"""ServoParams: derivation, validation and the TOML round trip."""

import dataclasses

import pytest

from firmware_model.params import DERIVED, ServoParams


def test_defaults_reproduce_the_holding_torques():
    """Step 1 of the derivation: c V + static friction gives 1.18 / 1.62 N m (data sheet) within 1 %."""
    p = ServoParams()
    assert p.holding_torque_nm(7.0) == pytest.approx(1.18, rel=0.01)
    assert p.holding_torque_nm(10.0) == pytest.approx(1.62, rel=0.01)


def test_derived_constants_are_physical():
    """Efficiency below 1, motor constant a few mN m/A at the motor, rotor ~0.5 g cm^2, top speed below no-load speed."""
    p = ServoParams()
    assert 0.5 < p.gearbox_efficiency < 0.95
    assert 2e-3 < p.torque_constant_nm_a / p.gear_ratio < 10e-3
    assert 1e-8 < p.rotor_inertia_reflected_kg_m2 / p.gear_ratio**2 < 2e-7
    assert p.top_speed_rad_s(9.6) < p.no_load_speed_rad_s(9.6)
    assert p.torque_constant_nm_a == pytest.approx(DERIVED["torque_constant_nm_a"], rel=1e-3)
    # The report's 6.6 "N/A" taken as k would give a 1.5 rad/s no-load speed: not this model.
    assert p.no_load_speed_rad_s(9.6) > 5 * 9.6 / 6.6


@pytest.mark.parametrize(
    ("change", "field"),
    [
        ({"coulomb_friction_nm": -0.1}, "coulomb_friction_nm"),
        ({"static_friction_nm": 0.05}, "static_friction_nm"),
        ({"load_inertia_kg_m2": -1e-4}, "load_inertia_kg_m2"),
        ({"rotor_inertia_reflected_kg_m2": 0.0}, "rotor_inertia_reflected_kg_m2"),
        ({"gearbox_efficiency": 1.2}, "gearbox_efficiency"),
        ({"winding_resistance_ohm": float("nan")}, "winding_resistance_ohm"),
        ({"supply_voltage_v": 14.0}, "supply_voltage_v"),
        ({"sample_hold_s": 0.0}, "sample_hold_s"),
        ({"bridge_braking_fraction": 1.5}, "bridge_braking_fraction"),
        ({"bridge_braking_fraction": -0.1}, "bridge_braking_fraction"),
        # what the registers can show (Present Voltage and Temperature are one byte each) and the ~10 Hz hold
        ({"supply_voltage_v": 30.0, "max_supply_voltage_v": 30.0}, "max_supply_voltage_v"),
        ({"ambient_temperature_c": -300.0}, "ambient_temperature_c"),
        ({"sample_hold_s": 1e300}, "sample_hold_s"),
    ],
)
def test_invalid_values_name_the_field(change, field):
    """Each physically impossible value raises ValueError naming its field."""
    with pytest.raises(ValueError, match=field):
        ServoParams(**change)


def test_toml_round_trip(tmp_path):
    """to_toml then from_toml gives equal parameters, including changed ones."""
    p = dataclasses.replace(ServoParams(), supply_voltage_v=11.5, coulomb_friction_nm=0.07, load_inertia_kg_m2=2.5e-4)
    path = tmp_path / "servo.toml"
    p.to_toml(path)
    assert ServoParams.from_toml(path) == p


def test_a_file_saved_with_a_byte_order_mark_is_read(tmp_path):
    """A params.toml saved by a Windows editor starts with a UTF-8 BOM; it was refused "Invalid statement (at line
    1, column 1)".  Read as the trace reader reads a CSV (utf-8-sig)."""
    p = dataclasses.replace(ServoParams(), supply_voltage_v=11.5)
    path = tmp_path / "servo.toml"
    p.to_toml(path)
    path.write_bytes(b"\xef\xbb\xbf" + path.read_bytes().replace(b"\n", b"\r\n"))
    assert ServoParams.from_toml(path) == p


def test_a_retired_key_of_an_older_file_is_read_and_ignored(tmp_path):
    """Files written before wheel mode lost its speed loop carry its gain: they still load, the key ignored."""
    path = tmp_path / "old.toml"
    path.write_text("supply_voltage_v = 11.0\nwheel_speed_gain_s_rad = 0.3\n", encoding="utf-8")
    assert ServoParams.from_toml(path) == ServoParams(supply_voltage_v=11.0)


def test_toml_partial_file_keeps_defaults(tmp_path):
    """A file with a few keys overrides only those."""
    path = tmp_path / "fit.toml"
    path.write_text("static_friction_nm = 0.2\nsample_hold_s = 0.13\n")
    p = ServoParams.from_toml(path)
    assert (p.static_friction_nm, p.sample_hold_s, p.gear_ratio) == (0.2, 0.13, 254.0)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("gear_ratio = 254\nmotor_colour = 3\n", "motor_colour"),
        ('gear_ratio = "254"\n', "gear_ratio"),
        ("gear_ratio = true\n", "gear_ratio"),
        ("[servo]\ngear_ratio = 254\n", "servo"),
        ("gear_ratio = = 1\n", "not valid TOML"),
        ("coulomb_friction_nm = 0.5\n", "static_friction_nm"),
        (f"gear_ratio = {'9' * 400}\n", "too large to be a number: gear_ratio"),
        (f"[effects]\nbacklash_rad = {'9' * 400}\n", "too large to be a number: backlash_rad"),
    ],
)
def test_toml_errors_name_file_and_key(tmp_path, text, message):
    """Unknown keys, wrong types, bad syntax and bad values raise ValueError naming the file and the key."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        ServoParams.from_toml(path)
    assert "bad.toml" in str(info.value)


def test_non_utf8_params_file_names_the_file(tmp_path):
    """A params file that is not UTF-8 text is refused with its path in the message."""
    from firmware_model.params import ServoParams

    bad = tmp_path / "latin1.toml"
    bad.write_bytes(b"gear_ratio = 254 # \xe9\n")
    with pytest.raises(ValueError, match="latin1.toml"):
        ServoParams.from_toml(bad)


# ---------------------------------------------------------------------- effects (one file holds the fitted twin)
from firmware_model.params import EFFECT_RANGES, ServoEffects  # noqa: E402

ALL_EFFECTS = ServoEffects(backlash_rad=0.05, sensing_delay_s=0.02, command_delay_s=0.01, drive_ceiling_fraction=0.6,
                           arm_weight_moment_nm=-0.3, extra_compliance_margin_units=3.5, position_offset_units=-4.0,
                           position_gain=1.02)


def test_every_effect_has_a_range_and_defaults_to_absent():
    assert set(EFFECT_RANGES) == {f.name for f in dataclasses.fields(ServoEffects)}
    assert ServoParams().effects.present() == {}


def test_toml_round_trip_with_effects(tmp_path):
    """Base fields and every effect survive to_toml / from_toml; absent effects are listed as comments."""
    p = dataclasses.replace(ServoParams(), coulomb_friction_nm=0.07, effects=ALL_EFFECTS)
    path = tmp_path / "twin.toml"
    p.to_toml(path, comments=("fitted from a test",))
    assert ServoParams.from_toml(path) == p
    some = dataclasses.replace(p, effects=ServoEffects(backlash_rad=0.05))
    some.to_toml(path)
    text = path.read_text()
    assert "[effects]" in text and "# sensing_delay_s: absent" in text
    assert ServoParams.from_toml(path) == some


def test_file_without_effects_reads_as_before(tmp_path):
    """A params.toml from before effects were served (a flat table) loads with every effect absent."""
    path = tmp_path / "old.toml"
    path.write_text("static_friction_nm = 0.2\nsample_hold_s = 0.13\n")
    assert ServoParams.from_toml(path).effects == ServoEffects()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[effects]\nbacklash_deg = 3\n", "unknown effect 'backlash_deg'"),
        ("[effects]\nbacklash_rad = 2.9\n", r"backlash_rad must lie in \[0, 0.5\]"),
        ("[effects]\nsensing_delay_s = -0.01\n", "sensing_delay_s"),
        ("[effects]\ndrive_ceiling_fraction = 0\n", r"drive_ceiling_fraction must lie in \(0, 1\]"),
        ("[effects]\ndrive_ceiling_fraction = 800\n", "drive_ceiling_fraction"),
        ("[effects]\nposition_gain = true\n", "position_gain"),
        ('[effects]\ncommand_delay_s = "5 ms"\n', "command_delay_s"),
        ("backlash_rad = 0.05\n", "is an effect: put it under \\[effects\\]"),
        ("effects = 3\n", "must be a table"),
    ],
)
def test_effect_errors_name_file_and_key(tmp_path, text, message):
    """Unknown effects, out-of-range values, wrong types and misplaced effects raise ValueError naming file and key."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message) as info:
        ServoParams.from_toml(path)
    assert "bad.toml" in str(info.value)


def test_effects_validate_in_python_too():
    with pytest.raises(ValueError, match="arm_weight_moment_nm"):
        ServoEffects(arm_weight_moment_nm=float("nan"))
    with pytest.raises(ValueError, match="ServoParams.effects"):
        ServoParams(effects={"backlash_rad": 0.1})


@pytest.mark.parametrize("volts", [7.0, 9.6, 12.0])
def test_the_supply_for_a_top_speed_is_the_top_speed_s_own_supply(volts):
    params = ServoParams(viscous_friction_nm_s_rad=0.01)
    assert params.supply_for_top_speed_v(params.top_speed_rad_s(volts)) == pytest.approx(volts)
