"""A write that changes Operating Mode(11) resets what the model's ``[mode_change]`` names (the e-manual's NOTE).

Servos stand on the recording firmware model (``x2_testkit``): what is checked is the control table.
"""

from __future__ import annotations

import pytest
from x2_testkit import recording_bus

from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.protocol.servo_models import model

GAINS = ("velocity_i_gain", "velocity_p_gain", "position_d_gain", "position_i_gain", "position_p_gain",
         "feedforward_2nd_gain", "feedforward_1st_gain")
#: Values none of the models has as a default (ours).
TUNED = {name: 1234 + i for i, name in enumerate(GAINS)} | {"profile_acceleration": 77, "profile_velocity": 99}


def u16(value: int) -> bytes:
    return (value & 0xFFFF).to_bytes(2, "little")


def write(bus, servo_id: int, name: str, value: int) -> None:
    entry = bus.servo(servo_id).table.layout.by_name[name]
    params = u16(entry.address) + (value & ((1 << 8 * entry.size) - 1)).to_bytes(entry.size, "little")
    bus.receive(encode_instruction2(servo_id, Instruction2.WRITE, params))


def tune(bus, servo_id: int = 1) -> None:
    """Gains and profile away from their defaults, Goal PWM/Current below their limits."""
    for name, value in TUNED.items():
        write(bus, servo_id, name, value)
    write(bus, servo_id, "goal_pwm", 100)
    if bus.servo(servo_id).table.has("goal_current"):
        write(bus, servo_id, "goal_current", 50)


def defaults(key: str) -> dict[str, int]:
    layout = model(key).layout()
    return {name: layout.by_name[name].value_in(layout.defaults) for name in TUNED}


@pytest.mark.parametrize("key", ["xl430-w250", "xm430-w350", "xl330-m077", "xl330-m288", "xc330-m288"])
def test_a_mode_change_by_write_resets_gains_profile_and_goal_limits(key):
    bus, _ = recording_bus(ids=[1], key=key)
    table = bus.servo(1).table
    tune(bus)
    assert {name: table.get(name) for name in TUNED} == TUNED
    write(bus, 1, "operating_mode", 1)
    assert table.get("operating_mode") == 1
    assert {name: table.get(name) for name in TUNED} == defaults(key)
    assert table.get("profile_acceleration") == 0 and table.get("profile_velocity") == 0
    assert table.get("goal_pwm") == table.get("pwm_limit")
    if table.has("goal_current"):
        assert table.get("goal_current") == table.get("current_limit")


def test_writing_the_mode_it_already_has_resets_nothing():
    bus, _ = recording_bus(ids=[1], key="xm430-w350")
    table = bus.servo(1).table
    tune(bus)
    write(bus, 1, "operating_mode", table.get("operating_mode"))
    assert {name: table.get(name) for name in TUNED} == TUNED
    assert table.get("goal_pwm") == 100


def test_a_refused_mode_write_resets_nothing():
    bus, _ = recording_bus(ids=[1], key="xl430-w250")
    table = bus.servo(1).table
    tune(bus)
    write(bus, 1, "operating_mode", 5)  # not among the XL430-W250's modes: Data Range Error
    assert table.get("operating_mode") == 3
    assert {name: table.get(name) for name in TUNED} == TUNED


def test_a_sync_write_and_an_action_change_the_mode_with_the_same_resets():
    bus, _ = recording_bus(ids=[1, 2], key="xm430-w350")
    for servo_id in (1, 2):
        tune(bus, servo_id)
    mode_at = bus.servo(1).table.layout.by_name["operating_mode"].address
    # SYNC_WRITE: start address, data length, then ID + data per servo (e-manual, Protocol 2.0).
    bus.receive(encode_instruction2(0xFE, Instruction2.SYNC_WRITE, u16(mode_at) + u16(1) + bytes([1, 16])))
    assert bus.servo(1).table.get("operating_mode") == 16
    assert bus.servo(1).table.get("position_p_gain") == defaults("xm430-w350")["position_p_gain"]
    assert bus.servo(2).table.get("position_p_gain") == TUNED["position_p_gain"]  # not addressed
    bus.receive(encode_instruction2(2, Instruction2.REG_WRITE, u16(mode_at) + bytes([4])))
    assert bus.servo(2).table.get("position_p_gain") == TUNED["position_p_gain"]  # registered, not yet done
    bus.receive(encode_instruction2(0xFE, Instruction2.ACTION))
    assert bus.servo(2).table.get("operating_mode") == 4
    assert bus.servo(2).table.get("profile_velocity") == 0
    assert bus.servo(2).table.get("goal_current") == bus.servo(2).table.get("current_limit")


def test_a_model_file_naming_an_unknown_register_is_refused():
    from ax12emu.protocol.servo_models import parse_model

    text = model("xl430-w250").path
    with open(text, encoding="utf-8") as handle:
        source = handle.read().replace('"velocity_i_gain", "velocity_p_gain"', '"velocity_i_gain", "no_such_gain"', 1)
    with pytest.raises(ValueError, match="mode_change.defaults.*no_such_gain"):
        parse_model(source, "xl430-w250", "x.toml")
