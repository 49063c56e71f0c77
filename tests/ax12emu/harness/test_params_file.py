"""A fitted twin's params.toml (base parameters and effects) served through VirtualBus(params=) and ax12emu://?params=."""

from __future__ import annotations

import pytest
import serial

import ax12emu  # noqa: F401  (registers the handler)
from ax12emu import VirtualBus
from ax12emu.harness.urlhandler.protocol_ax12emu import UrlError
from ax12emu.protocol.packets import encode_instruction
from firmware_model.params import ServoEffects, ServoParams

#: Read Present Position (36, two bytes) of servo 1.
READ_POSITION = encode_instruction(1, 0x02, bytes([36, 2]))


def _position(link) -> int:
    link.write(READ_POSITION)
    reply = link.read(8)
    assert len(reply) == 8, reply
    return reply[5] | reply[6] << 8


@pytest.fixture
def offset_twin(tmp_path):
    """A twin whose pot reads 9 units high: at rest on 512 it reports 521."""
    path = tmp_path / "params.toml"
    ServoParams(effects=ServoEffects(position_offset_units=9.0)).to_toml(path)
    return path


def test_url_serves_the_params_file(offset_twin):
    with serial.serial_for_url(f"ax12emu://?params={offset_twin}&virtual_time=1", baudrate=1_000_000,
                               timeout=0.5) as link:
        assert _position(link) == 521
    with serial.serial_for_url("ax12emu://?virtual_time=1", baudrate=1_000_000, timeout=0.5) as link:
        assert _position(link) == 512


def test_url_with_a_missing_params_file_is_a_clear_error(tmp_path):
    with pytest.raises(UrlError, match="cannot read the parameter file"):
        serial.serial_for_url(f"ax12emu://?params={tmp_path / 'none.toml'}")


@pytest.mark.parametrize("as_object", [False, True])
def test_virtual_bus_serves_the_params_file(offset_twin, as_object):
    params = ServoParams.from_toml(offset_twin) if as_object else offset_twin
    with VirtualBus(transport="inprocess", virtual_time=True, params=params) as bus:
        assert bus.bus.model.params.effects.position_offset_units == 9.0
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5) as link:
            assert _position(link) == 521


def test_virtual_bus_refuses_params_with_a_model_object(offset_twin):
    from firmware_model import PhysicalModel

    with pytest.raises(ValueError, match="params= builds the physical model"):
        VirtualBus(transport="inprocess", params=offset_twin, model=PhysicalModel(1))
