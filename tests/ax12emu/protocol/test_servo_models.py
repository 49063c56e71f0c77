"""Servo models as data: the AX-12A file against the e-manual's printed table, and the loader's errors."""

from __future__ import annotations

import textwrap

import pytest

from ax12emu.protocol.control_table import EEPROM_END, TABLE_SIZE, ControlTable, layout
from ax12emu.protocol.registers import Access, Area
from ax12emu.protocol.servo_models import load_model_file, model, model_names, parse_model

#: The e-manual's AX-12A control table as printed (ROBOTIS-GIT/emanual docs/en/dxl/ax/ax-12a.md
#: @ 07fe860b): address, size, name, access, initial value ("-" where it prints none).
AX12A_EMANUAL = [
    (0, 2, "Model Number", "R", "12"), (2, 1, "Firmware Version", "R", "-"), (3, 1, "ID", "RW", "1"),
    (4, 1, "Baud Rate", "RW", "1"), (5, 1, "Return Delay Time", "RW", "250"), (6, 2, "CW Angle Limit", "RW", "0"),
    (8, 2, "CCW Angle Limit", "RW", "1023"), (11, 1, "Temperature Limit", "RW", "70"),
    (12, 1, "Min Voltage Limit", "RW", "60"), (13, 1, "Max Voltage Limit", "RW", "140"),
    (14, 2, "Max Torque", "RW", "1023"), (16, 1, "Status Return Level", "RW", "2"), (17, 1, "Alarm LED", "RW", "36"),
    (18, 1, "Shutdown", "RW", "36"),
    (24, 1, "Torque Enable", "RW", "0"), (25, 1, "LED", "RW", "0"), (26, 1, "CW Compliance Margin", "RW", "1"),
    (27, 1, "CCW Compliance Margin", "RW", "1"), (28, 1, "CW Compliance Slope", "RW", "32"),
    (29, 1, "CCW Compliance Slope", "RW", "32"), (30, 2, "Goal Position", "RW", "-"), (32, 2, "Moving Speed", "RW", "-"),
    (34, 2, "Torque Limit", "RW", "ADD 14&15"), (36, 2, "Present Position", "R", "-"), (38, 2, "Present Speed", "R", "-"),
    (40, 2, "Present Load", "R", "-"), (42, 1, "Present Voltage", "R", "-"), (43, 1, "Present Temperature", "R", "-"),
    (44, 1, "Registered", "R", "0"), (46, 1, "Moving", "R", "0"), (47, 1, "Lock", "RW", "0"), (48, 2, "Punch", "RW", "32"),
]
#: Write ranges from the e-manual's texts (ax12a profile) and the 2006 manual where the e-manual gives none.
AX12A_RANGES = {
    "id": (0, 253), "baud_rate": (0, 254), "return_delay_time": (0, 254), "cw_angle_limit": (0, 1023),
    "ccw_angle_limit": (0, 1023), "temperature_limit": (0, 100), "min_voltage_limit": (50, 160),
    "max_voltage_limit": (50, 160), "max_torque": (0, 1023), "status_return_level": (0, 2), "alarm_led": (0, 127),
    "shutdown": (0, 127), "torque_enable": (0, 1), "led": (0, 1), "cw_compliance_margin": (0, 254),
    "ccw_compliance_margin": (0, 254), "cw_compliance_slope": (0, 254), "ccw_compliance_slope": (0, 254),
    "goal_position": (0, 1023), "moving_speed": (0, 2047), "torque_limit": (0, 1023), "lock": (0, 1),
    "punch": (0x20, 0x3FF),
}
#: What the emulator puts where the e-manual prints "-": the model overwrites the Present* values before
#: any read; Goal Position = Present Position (512) and Torque Limit = Max Torque (1023) at power-up.
PLACEHOLDERS = {"firmware_version": 24, "goal_position": 512, "moving_speed": 0, "torque_limit": 1023,
                "present_position": 512, "present_speed": 0, "present_load": 0, "present_voltage": 96,
                "present_temperature": 30}


def _snake(name: str) -> str:
    return name.lower().replace(" ", "_")


def test_ax12a_layout_matches_the_emanual_entry_by_entry():
    """Every e-manual row has its entry (address, size, access, area, default), and no entry is extra."""
    lay = layout("ax12a")
    assert [e.name for e in lay.entries] == [_snake(row[2]) for row in AX12A_EMANUAL]
    for address, size, name, access, initial in AX12A_EMANUAL:
        entry = lay.by_name[_snake(name)]
        assert (entry.address, entry.size, entry.access) == (address, size, Access(access)), name
        assert entry.area is (Area.EEPROM if address < 24 else Area.RAM), name
        want = PLACEHOLDERS[entry.name] if initial in ("-", "ADD 14&15") else int(initial)
        assert entry.default == want, name
        if entry.access is Access.RW:
            assert (entry.minimum, entry.maximum) == AX12A_RANGES[entry.name], name
    assert (TABLE_SIZE, EEPROM_END) == (50, 24)
    assert lay.defaults == ControlTable().row.tobytes()


def test_ax12a_2006_profile_adds_calibration_and_changes_defaults():
    """The 2006 profile: Down/Up Calibration read-only at 20..23, reserved 19, Lock window 0x18..0x23."""
    lay = layout("ax12-2006")
    assert [(e.address, e.size, e.access) for e in lay.entries if 19 <= e.address < 24] == [
        (19, 1, Access.RW), (20, 2, Access.R), (22, 2, Access.R)]
    assert lay.profile.lock_writable == range(0x18, 0x24) and lay.profile.shutdown_clears == "torque_enable"
    assert layout("ax12a").profile.lock_writable == range(24, 50)
    assert lay.eeprom_end == 24


def test_every_shipped_model_loads_and_names_its_source():
    """Each file under models/ loads, compiles every profile and cites the emanual repository commit."""
    assert "ax-12a" in model_names()
    for key in model_names():
        servo = model(key)
        assert "ROBOTIS-GIT/emanual" in servo.source and "ROBOTIS-GIT/emanual" in servo.physical.source, key
        for profile in servo.profiles:
            lay = servo.layout(profile)
            assert lay.by_name["model_number"].default == servo.model_number
        assert servo.physical.ratings


def test_entry_value_in_reads_four_bytes_little_endian_and_signed():
    """Sizes up to 4, little-endian; signed entries decode two's complement."""
    servo = parse_model(_minimal(extra='''
      { address = 4, size = 4, name = "goal_position", access = "RW", area = "RAM", min = 0, max = 4095 },
      { address = 8, size = 4, name = "homing_offset", access = "RW", area = "RAM", min = -1044479, max = 1044479, signed = true, default = -5 },
    '''), "t", "t.toml")
    lay = servo.layout()
    row = bytearray(lay.defaults)
    assert lay.by_name["homing_offset"].value_in(row) == -5
    row[4:8] = (0x0A0B0C0D).to_bytes(4, "little")
    assert lay.by_name["goal_position"].value_in(row) == 0x0A0B0C0D
    assert lay.by_name["homing_offset"].to_bytes(-1) == b"\xff\xff\xff\xff"


def test_runs_expand_with_counted_names_and_stepped_defaults():
    """An indirect-address run: count copies, {n} from first, default stepping."""
    servo = parse_model(_minimal(extra='''
      { address = 10, size = 2, count = 3, first = 29, name = "indirect_address_{n}", access = "RW", area = "RAM", default = 634, default_step = 1, min = 64, max = 661 },
    '''), "t", "t.toml")
    got = [(e.name, e.address, e.default) for e in servo.entries if e.name.startswith("indirect")]
    assert got == [("indirect_address_29", 10, 634), ("indirect_address_30", 12, 635), ("indirect_address_31", 14, 636)]


def _minimal(extra: str = "", size: int = 20, header: str = "", physical: str | None = None) -> str:
    physical = physical if physical is not None else '''
        [physical]
        source = "ROBOTIS-GIT/emanual test"
        gear_ratio = 100
        operating_voltage_v = [6.0, 12.0]
        ratings = [ { voltage_v = 12.0, stall_torque_nm = 1.0, no_load_speed_rpm = 60 } ]
    '''
    return textwrap.dedent(f'''
        [model]
        name = "T"
        model_number = 7
        protocols = ["2.0"]
        source = "ROBOTIS-GIT/emanual test"
        {header}
        [table]
        size = {size}
        entries = [
          {{ address = 0, size = 2, name = "model_number", access = "R", area = "EEPROM", default = 7 }},
    ''') + textwrap.dedent(extra) + "]\n" + textwrap.dedent(physical)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        ('{ address = 1, size = 1, name = "id", access = "RW", area = "EEPROM" },', r"id.*overlaps model_number"),
        ('{ address = 4, size = 1, name = "id", access = "RW", area = "EEPROM", default = 300 },', r"outside|does not fit"),
        ('{ address = 4, size = 1, name = "id", access = "RW", area = "EEPROM", min = 0, max = 9, default = 10 },',
         r"table.entries\[1\] \(id\).default: default 10 is outside 0..9"),
        ('{ address = 4, size = 1, name = "id", access = "RW", area = "EEPROM", colour = 1 },', r"unknown key.*colour"),
        ('{ address = 4, size = 1, name = "id", access = "W", area = "EEPROM" },', r"\(id\).access: must be one of 'R', 'RW'"),
        ('{ address = 4, size = 1, name = "id", access = "RW", area = "ROM" },', r"\(id\).area: must be one of"),
        ('{ address = 4, size = 3, name = "id", access = "RW", area = "RAM" },', r"size must be 1, 2 or 4"),
        ('{ address = 19, size = 2, name = "id", access = "RW", area = "RAM" },', r"does not fit a table of 20"),
        ('{ address = 4, size = 1, name = "a", access = "RW", area = "RAM" }, { address = 5, size = 1, name = "b", '
         'access = "RW", area = "EEPROM" },', r"EEPROM entries \['b'\] lie after the first RAM entry"),
        ('{ address = 4, size = 1, name = "model_number", access = "RW", area = "RAM" },', r"used twice"),
        ('{ address = 4, size = 2, name = "goal", access = "RW", area = "RAM", max_from = "nothing" },', r"'nothing' is not in the table"),
        ('{ address = 4, size = 1, count = 2, name = "x", access = "RW", area = "RAM" },', r"needs \{n\}"),
    ],
)
def test_bad_entries_are_refused_naming_file_and_field(extra, message):
    with pytest.raises(ValueError, match=message) as info:
        parse_model(_minimal(extra=extra), "t", "bad.toml")
    assert str(info.value).startswith("bad.toml")


@pytest.mark.parametrize(
    ("header", "physical", "message"),
    [
        ('colour = "red"', None, r"model: unknown key"),
        ("", '[physical]\nsource = "s"\ngear_ratio = 1\noperating_voltage_v = [6.0, 12.0]\nratings = []', r"physical.ratings: must be a non-empty"),
        ("", '[physical]\nsource = "s"\ngear_ratio = 1\noperating_voltage_v = [6.0, 12.0]\n'
             'ratings = [ { voltage_v = 24.0, stall_torque_nm = 1.0, no_load_speed_rpm = 1 } ]', r"outside the operating range"),
        ("", '[physical]\nsource = "s"\ngear_ratio = -3\noperating_voltage_v = [6.0, 12.0]\n'
             'ratings = [ { voltage_v = 12.0, stall_torque_nm = 1.0, no_load_speed_rpm = 1 } ]', r"physical.gear_ratio: must be positive"),
        ("", '[physical]\nsource = "s"\ngear_ratio = 3\noperating_voltage_v = [6.0, 12.0]\nrotor_inertia_at_motor_kg_m2 = 0\n'
             'ratings = [ { voltage_v = 12.0, stall_torque_nm = 1.0, no_load_speed_rpm = 1 } ]',
         r"physical.rotor_inertia_at_motor_kg_m2: must be positive"),
        ("", '[physical]\nsource = "s"\ngear_ratio = 3\noperating_voltage_v = [6.0, 12.0]\nmotor = "brushless"\n'
             'ratings = [ { voltage_v = 12.0, stall_torque_nm = 1.0, no_load_speed_rpm = 1 } ]',
         r"physical.motor: must be one of 'cored', 'coreless'"),
    ],
)
def test_bad_model_or_physical_sections_are_refused(header, physical, message):
    with pytest.raises(ValueError, match=message):
        parse_model(_minimal(header=header, physical=physical), "t", "bad.toml")


@pytest.mark.parametrize(
    ("header", "message"),
    [
        ('unsupported_instructions = "clear"', r"model.unsupported_instructions: must be a list"),
        ('unsupported_instructions = ["teleport"]', r"unknown instruction 'teleport'; choose from: .*fast_sync_read"),
        ('unsupported_instructions = ["ping"]', r"unknown instruction 'ping'"),  # every firmware knows PING
    ],
)
def test_unsupported_instructions_are_named_protocol_2_instructions(header, message):
    with pytest.raises(ValueError, match=message):
        parse_model(_minimal(header=header), "t", "bad.toml")
    one = _minimal(header='unsupported_instructions = ["clear"]').replace('protocols = ["2.0"]', 'protocols = ["1.0"]')
    with pytest.raises(ValueError, match=r"names Protocol 2.0 instructions of a model without it"):
        parse_model(one, "t", "bad.toml")
    assert parse_model(_minimal(header='unsupported_instructions = ["clear"]'), "t", "t.toml").unsupported_instructions == {0x10}
    assert model("xl430-w250").unsupported_instructions == frozenset()


def test_model_number_must_match_the_table_and_profiles_are_checked(tmp_path):
    """[model].model_number equals the table's default; a profile overriding a missing entry is refused."""
    text = _minimal().replace("model_number = 7\n", "model_number = 8\n", 1)
    with pytest.raises(ValueError, match=r"model.model_number: 8 must equal"):
        parse_model(text, "t", "bad.toml")
    text = _minimal() + '[profiles.p]\nsource = "s"\noverrides = { punch = { min = 1 } }\n'
    path = tmp_path / "p.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"p.toml: profiles.p.overrides.punch: no such entry"):
        load_model_file(path)
    path.write_text("[model\n")
    with pytest.raises(ValueError, match=r"p.toml: not valid TOML"):
        load_model_file(path)
    with pytest.raises(ValueError, match="unknown servo model"):
        model("ax-99")


def test_lock_window_and_shutdown_only_where_the_table_and_sources_have_them():
    """A Lock window needs a lock register; what Alarm Shutdown clears is None unless a profile states it."""
    servo = parse_model(_minimal(), "t", "t.toml")
    assert servo.layout().profile.lock_writable is None and servo.layout().profile.shutdown_clears is None
    with pytest.raises(ValueError, match=r"profiles.p.lock_writable: the table has no lock register"):
        parse_model(_minimal() + '[profiles.p]\nsource = "s"\nlock_writable = [4, 20]\n', "t", "bad.toml")
    with pytest.raises(ValueError, match=r"profiles.p.shutdown_clears: must be one of"):
        parse_model(_minimal() + '[profiles.p]\nsource = "s"\nshutdown_clears = "power"\n', "t", "bad.toml")
    assert model("xl430-w250").layout().profile.shutdown_clears == "torque_enable"
    assert model("ax-18a").layout().profile.shutdown_clears == "torque_limit"


@pytest.mark.parametrize(
    ("header", "message"),
    [
        ("baud_rates_bps = []", r"model.baud_rates_bps: must be a non-empty list"),
        ("baud_rates_bps = [9600, 0]", r"model.baud_rates_bps: bit rates must be positive"),
        ("baud_rates_bps = [9600, 57600]", r"2 rates, but baud_rate accepts values up to 3"),
    ],
)
def test_baud_rates_cover_every_baud_rate_value(header, message):
    extra = '{ address = 4, size = 1, name = "baud_rate", access = "RW", area = "EEPROM", min = 0, max = 3 },'
    with pytest.raises(ValueError, match=message):
        parse_model(_minimal(extra=extra, header=header), "t", "bad.toml")


def test_protocol_2_models_give_baud_rates_and_current_units():
    """Every Protocol 2.0 X-series file maps each Baud Rate value to bits per second; current units where sensed."""
    xl430, xm430 = model("xl430-w250"), model("xm430-w350")
    assert xl430.baud_rates_bps[1] == 57600 and xl430.baud_rates_bps[3] == 1_000_000
    assert (xl430.physical.current_unit_ma, xm430.physical.current_unit_ma) == (None, 2.69)
    assert model("ax-12a").baud_rates_bps == ()


def test_ranges_when_and_values_are_read_and_checked():
    goal = model("xl430-w250").layout().by_name["goal_position"]
    assert [(m.register, m.values, m.minimum, m.maximum, m.limits) for m in goal.mode_ranges] == [
        ("operating_mode", (4,), -1048575, 1048575, False)]
    entry = '{ address = 4, size = 1, name = "x", access = "RW", area = "RAM", ranges_when = [ %s ] },'
    for spec, message in [
        ('{ register = "nothing", values = [1], min = 0, max = 1 }', r"'nothing' is not in the table"),
        ('{ register = "model_number", values = [], min = 0, max = 1 }', r"values: must be a non-empty list"),
        ('{ register = "model_number", values = [1], min = 0, max = 300 }', r"does not fit the entry"),
        ('{ register = "model_number", values = [1], min = 0, max = 1, limits = 2 }', r"limits: must be true or false"),
    ]:
        with pytest.raises(ValueError, match=message):
            parse_model(_minimal(extra=entry % spec), "t", "bad.toml")
    for values, message in [("[]", "must be a non-empty list"), ("[1, 300]", r"must lie in 0..255"), ("[1, 2]", "hold the default 0")]:
        bad = f'{{ address = 4, size = 1, name = "x", access = "RW", area = "RAM", values = {values} }},'
        with pytest.raises(ValueError, match=message):
            parse_model(_minimal(extra=bad), "t", "bad.toml")


@pytest.mark.parametrize(
    ("controller", "message"),
    [
        ('[controller]\nposition_output_scale = 0.5', r"controller: missing key 'source'|controller.*source"),
        ('[controller]\nsource = "s"\nposition_output_scale = 0', r"controller.position_output_scale: must be positive"),
        ('[controller]\nsource = "s"\ngain = 2', r"controller: unknown key"),
    ],
)
def test_bad_controller_sections_are_refused(controller, message):
    with pytest.raises(ValueError, match=message):
        parse_model(_minimal() + "\n" + controller + "\n", "t", "bad.toml")


def test_controller_departures_are_read_where_measured_and_absent_elsewhere():
    text = _minimal() + '\n[controller]\nsource = "a measurement"\nposition_output_scale = 0.5\n'
    assert parse_model(text, "t", "t.toml").controller.position_output_scale == 0.5
    assert parse_model(_minimal(), "t", "t.toml").controller.position_output_scale == 1.0
    assert model("xl330-m288").controller.position_output_scale == 0.5
    assert model("xl430-w250").controller.position_output_scale == 1.0


def test_every_model_file_names_its_motor_as_its_e_manual_page_does():
    """The e-manual's "Motor" row (specifications): the MX-28/64/106 "Coreless(Maxon)", the XM430 "Coreless", the
    XC330 "Coreless DC", the AX-18A "Coreless"; the XL330s, XL430, XL-320 and AX-12A "Cored"."""
    coreless = {"ax-18a", "mx-28", "mx-64", "mx-106", "xm430-w350", "xc330-m288"}
    assert {key: model(key).physical.motor for key in model_names()} == {
        key: "coreless" if key in coreless else "cored" for key in model_names()}


def test_the_motor_kinds_a_model_file_may_name_are_the_kinds_the_physics_builds():
    """The protocol layer may not import the physics, so the kinds are written in both: a kind added to one
    alone would be refused at load (or never built) while the other layer takes it."""
    from ax12emu.protocol.servo_models import MOTOR_KINDS as named
    from firmware_model.xseries.physics import MOTOR_KINDS as built

    assert named == built
