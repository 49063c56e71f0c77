"""The state store keys each EEPROM image to its model: another model on the same launch ID is refused with a message."""

from __future__ import annotations

import json

import pytest
from x2_testkit import recording_bus

from ax12emu.bus.bus import Bus
from ax12emu.bus.state_store import StateFileError, StateStore
from ax12emu.protocol.packets2 import Instruction2, encode_instruction2
from ax12emu.servo.virtual_servo import ServoOptions


def _write_return_delay(bus, servo_id: int, value: int) -> None:
    bus.receive(encode_instruction2(servo_id, Instruction2.WRITE, bytes((9, 0, value))))  # Return Delay Time(9): EEPROM


def test_an_image_returns_to_its_own_model(tmp_path):
    store = StateStore(tmp_path)
    bus, _ = recording_bus(ids=(1,), key="xl330-m077", state_store=store)
    _write_return_delay(bus, 1, 40)
    bus.close()
    document = json.loads((tmp_path / "servo-001.json").read_text())
    assert document["model_number"] == 1190 and document["profile"] == "xl330-m077"
    again, _ = recording_bus(ids=(1,), key="xl330-m077", state_store=store)
    assert again.servo(1).table.get("return_delay_time") == 40


def test_another_model_on_the_same_id_is_refused_by_name(tmp_path):
    """XL330-M077 and XL330-M288 share their table's layout; only the model number tells their images apart."""
    store = StateStore(tmp_path)
    bus, _ = recording_bus(ids=(1, 2), key="xl330-m077", state_store=store)
    _write_return_delay(bus, 1, 40)
    bus.close()
    with pytest.raises(StateFileError, match=r"servo-001.json: holds the EEPROM of another model \(xl330-m077, model number 1190\), "
                       r"not xl330-m288 \(model number 1200\); the servo launched with ID 1 is another model now"):
        recording_bus(ids=(1,), key="xl330-m288", state_store=store)
    again, _ = recording_bus(ids=(1,), key="xl330-m077", state_store=store)  # the file is untouched
    assert again.servo(1).table.get("return_delay_time") == 40


def test_a_file_without_a_model_number_loads_as_before(tmp_path):
    """Files written before the model number was kept still load (by register name)."""
    (tmp_path / "servo-003.json").write_text(json.dumps({"format": "ax12emu-eeprom/1", "profile": "xl430-w250",
                                                         "eeprom": {"return_delay_time": 17}}))
    bus, _ = recording_bus(ids=(3,), key="xl430-w250", state_store=StateStore(tmp_path))
    assert bus.servo(3).table.get("return_delay_time") == 17


def test_the_ax12_profiles_share_their_model_number(tmp_path):
    """An AX-12A's state saved under one table profile loads under the other: one model, model number 12."""
    store = StateStore(tmp_path)
    with Bus([1], options=ServoOptions(profile="ax12a"), state_store=store) as bus:
        bus.servo(1).table.set("return_delay_time", 50)
        bus.save_state()
    with Bus([1], options=ServoOptions(profile="ax12-2006"), state_store=store) as bus:
        assert bus.servo(1).table.get("return_delay_time") == 50


def test_another_models_file_with_a_backup_is_refused_as_another_model(tmp_path):
    """The backup's size (the XL430's table) must not speak first: the file is another model's."""
    store = StateStore(tmp_path)
    bus, _ = recording_bus(ids=(1,), key="xl430-w250", state_store=store)
    bus.receive(encode_instruction2(1, Instruction2.CONTROL_TABLE_BACKUP, b"\x01CTRL"))
    bus.close()
    assert "backup" in json.loads(store.path_for(1).read_text())
    with pytest.raises(StateFileError, match="holds the EEPROM of another model"):
        recording_bus(ids=(1,), key="xl-320", state_store=store)
