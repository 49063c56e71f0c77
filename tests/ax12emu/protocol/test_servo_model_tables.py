"""The shipped model tables against rows quoted again from their e-manual pages, and their invariants.

Each file was written from its page (cited in the file); these rows are a second reading of the same
pages, of the registers most easily mistyped (defaults that differ between models of one family, odd
addresses, the ends of the indirect runs).  ``None`` as a default: the page prints "-".
"""

from __future__ import annotations

import pytest

from ax12emu.protocol.registers import Access
from ax12emu.protocol.servo_models import model, model_names

#: model -> (address, size, name, access, initial value or None, (min, max) or None for "not checked")
QUOTED = {
    "ax-18a": [(0, 2, "model_number", "R", 18, None), (11, 1, "temperature_limit", "RW", 75, None),
               (14, 2, "max_torque", "RW", 983, (0, 1023)), (26, 1, "cw_compliance_margin", "RW", 1, (0, 255)),
               (48, 2, "punch", "RW", 32, (32, 1023))],
    "mx-28": [(4, 1, "baud_rate", "RW", 34, None), (8, 2, "ccw_angle_limit", "RW", 4095, (0, 4095)),
              (11, 1, "temperature_limit", "RW", 80, (0, 100)), (13, 1, "max_voltage_limit", "RW", 160, (50, 160)),
              (20, 2, "multi_turn_offset", "RW", 0, (-24576, 24576)), (22, 1, "resolution_divider", "RW", 1, (1, 4)),
              (28, 1, "p_gain", "RW", 32, (0, 254)), (50, 2, "realtime_tick", "R", 0, None),
              (73, 1, "goal_acceleration", "RW", 0, (0, 254))],
    "mx-64": [(0, 2, "model_number", "R", 310, None), (13, 1, "max_voltage_limit", "RW", 240, None),
              (68, 2, "current", "RW", 0, None), (70, 1, "torque_ctrl_mode_enable", "RW", 0, (0, 1)),
              (71, 2, "goal_torque", "RW", 0, (0, 2047))],
    "mx-106": [(0, 2, "model_number", "R", 320, None), (10, 1, "drive_mode", "RW", 0, None),
               (13, 1, "max_voltage_limit", "RW", 160, None), (71, 2, "goal_torque", "RW", 0, (0, 2047))],
    "xl-320": [(0, 2, "model_number", "R", 350, None), (4, 1, "baud_rate", "RW", 3, (0, 3)),
               (11, 1, "control_mode", "RW", 2, (1, 2)), (14, 1, "max_voltage_limit", "RW", 90, (50, 250)),
               (18, 1, "shutdown", "RW", 3, (0, 7)), (25, 1, "led", "RW", 0, (0, 7)),
               (35, 2, "torque_limit", "RW", None, (0, 1023)), (50, 1, "hardware_error_status", "R", 0, None),
               (51, 2, "punch", "RW", 32, (0, 1023))],
    "xl430-w250": [(8, 1, "baud_rate", "RW", 1, (0, 7)), (24, 4, "moving_threshold", "RW", 10, (0, 1023)),
                   (44, 4, "velocity_limit", "RW", 265, (0, 1023)), (63, 1, "shutdown", "RW", 52, None),
                   (84, 2, "position_p_gain", "RW", 640, (0, 16383)), (126, 2, "present_load", "R", None, None),
                   (147, 1, "backup_ready", "R", None, None), (578, 2, "indirect_address_29", "RW", 634, (64, 661)),
                   (661, 1, "indirect_data_56", "RW", 0, (0, 255))],
    # The page prints ID 0 ~ 253; the file keeps 0 ~ 252, as Protocol 2.0 never uses 253 (0xFD) as an ID.
    "xm430-w350": [(7, 1, "id", "RW", 1, (0, 252)), (8, 1, "baud_rate", "RW", 1, (0, 7)),
                   (38, 2, "current_limit", "RW", 1193, (0, 1193)), (44, 4, "velocity_limit", "RW", 200, (0, 1023)),
                   (76, 2, "velocity_i_gain", "RW", 1920, None), (84, 2, "position_p_gain", "RW", 800, None),
                   (102, 2, "goal_current", "RW", None, (-1193, 1193)), (222, 2, "indirect_address_28", "RW", 251, None)],
    "xl330-m288": [(8, 1, "baud_rate", "RW", 1, (0, 6)), (38, 2, "current_limit", "RW", 1750, (0, 1750)),
                   (44, 4, "velocity_limit", "RW", 445, (0, 2047)), (62, 1, "pwm_slope", "RW", 140, (1, 255)),
                   (63, 1, "shutdown", "RW", 53, None), (76, 2, "velocity_i_gain", "RW", 1600, None),
                   (78, 2, "velocity_p_gain", "RW", 180, None), (206, 2, "indirect_address_20", "RW", 227, (64, 227)),
                   (227, 1, "indirect_data_20", "RW", 0, (0, 255))],
    "xl330-m077": [(0, 2, "model_number", "R", 1190, None), (44, 4, "velocity_limit", "RW", 1620, None),
                   (76, 2, "velocity_i_gain", "RW", 400, None), (78, 2, "velocity_p_gain", "RW", 40, None),
                   (82, 2, "position_i_gain", "RW", 400, None), (84, 2, "position_p_gain", "RW", 400, None)],
    "xc330-m288": [(0, 2, "model_number", "R", 1240, None), (38, 2, "current_limit", "RW", 2352, (0, 2352)),
                   (44, 4, "velocity_limit", "RW", 350, None), (63, 1, "shutdown", "RW", 52, None),
                   (78, 2, "velocity_p_gain", "RW", 50, None), (80, 2, "position_d_gain", "RW", 500, None),
                   (84, 2, "position_p_gain", "RW", 1100, None)],
}


@pytest.mark.parametrize("key", sorted(QUOTED))
def test_quoted_rows(key):
    lay = model(key).layout()
    for address, size, name, access, initial, span in QUOTED[key]:
        entry = lay.by_name[name]
        assert (entry.address, entry.size, entry.access) == (address, size, Access(access)), name
        assert entry.default == (0 if initial is None else initial), name
        if span is not None:
            assert (entry.minimum, entry.maximum) == span, name


@pytest.mark.parametrize("key", model_names())
def test_eeprom_ends_where_torque_enable_starts(key):
    """Every table's RAM area begins with Torque Enable (24 on Protocol 1.0 tables and the XL-320, 64 on the X series)."""
    lay = model(key).layout()
    assert lay.eeprom_end == lay.by_name["torque_enable"].address == (64 if "2.0" in model(key).protocols and key != "xl-320" else 24)


@pytest.mark.parametrize("key", model_names())
def test_protocol_1_tables_use_one_and_two_byte_registers(key):
    """Protocol 1.0 tables (and the XL-320's) have no 4-byte entries; the X series' positions and velocities have."""
    lay = model(key).layout()
    sizes = {e.size for e in lay.entries}
    if "1.0" in model(key).protocols or key == "xl-320":
        assert sizes <= {1, 2}
    else:
        assert lay.by_name["goal_position"].size == lay.by_name["present_velocity"].size == 4


@pytest.mark.parametrize("key", [k for k in model_names() if "indirect_address_1" in model(k).layout().by_name])
def test_each_indirect_address_points_at_its_indirect_data(key):
    """At the factory, Indirect Address n holds the address of Indirect Data n (e-manual: 224, 225, ... / 208, ...)."""
    by_name = model(key).layout().by_name
    n = 1
    while f"indirect_address_{n}" in by_name:
        assert by_name[f"indirect_address_{n}"].default == by_name[f"indirect_data_{n}"].address, n
        n += 1
    assert n - 1 in (20, 56)


def _answers_backup(key: str) -> bool:
    from ax12emu.protocol.packets2 import Instruction2

    spec = model(key)
    return "2.0" in spec.protocols and Instruction2.CONTROL_TABLE_BACKUP not in spec.unsupported_instructions


@pytest.mark.parametrize("key", [k for k in model_names() if _answers_backup(k)])
def test_a_model_that_answers_control_table_backup_has_its_startup_and_ready_registers(key):
    """Control Table Backup stores the RAM too, which only Startup Configuration(60)'s RAM Restore brings back, and a
    client polls Backup Ready(147) after the store (e-manual, Protocol 2.0, Control Table Backup): an XM430-W350
    answered the store, then read Backup Ready 0 ("no backup") and refused the restore setting with Access Error."""
    names = model(key).layout().by_name
    assert names["startup_configuration"].address == 60 and names["backup_ready"].address == 147
