"""VirtualBus: start/stop from code, state access, deterministic virtual time, clean shutdown."""

from __future__ import annotations

import os
import threading
import time

import pytest
import serial

import ax12emu
from ax12emu import VirtualBus
from ax12emu.protocol.packets import encode_instruction, encode_status


def _threads() -> set[str]:
    return {t.name for t in threading.enumerate() if t.name.startswith("ax12emu-")}


def test_with_block_serves_a_pty_and_cleans_up():
    """Inside the block a client talks over bus.port; after it the thread is joined and the pty closed."""
    with ax12emu.VirtualBus(ids=[1, 2]) as bus:
        with serial.Serial(bus.port, 1_000_000, timeout=0.5) as link:
            link.write(encode_instruction(2, 0x01))
            assert link.read(6) == encode_status(2, 0)
        assert bus.running and _threads()
        master = bus._transport._master
    assert not bus.running and not _threads()
    with pytest.raises(OSError):
        os.fstat(master)


def test_exception_in_block_still_shuts_down():
    """An exception in the with body propagates and the bus is torn down anyway."""
    with pytest.raises(ZeroDivisionError):
        with VirtualBus([1]) as bus:
            _ = 1 / 0
    assert not bus.running and not _threads()
    bus.close()  # a second close is harmless


def test_state_access_by_name():
    """Registers read and written by name; an ID write moves the servo; the table lists every register."""
    with VirtualBus([1, 2], transport="inprocess", model="kinematic") as bus:
        bus.write(1, "led", 1)
        assert bus.read(1, "led") == 1
        assert bus.table(2)["model_number"] == 12
        bus.write(2, "id", 7)
        assert bus.read(7, "id") == 7
        with pytest.raises(KeyError, match="no servo with ID 2"):
            bus.read(2, "led")


def test_slow_motion_answers_calls_and_stops_within_a_period():
    """At a thousandth of real time a physics tick is a second of wall time apart; state access
    and close still take about a millisecond, as at real time (wide margins: 0.2 s each)."""
    bus = VirtualBus([1], time_scale=0.001, model="kinematic").start()
    try:
        for _ in range(3):
            start = time.monotonic()
            bus.write(1, "led", 1)
            assert bus.read(1, "led") == 1
            assert time.monotonic() - start < 0.2
    finally:
        start = time.monotonic()
        bus.close()
    assert time.monotonic() - start < 0.2 and not _threads()


def test_virtual_time_steps_are_deterministic():
    """Two buses stepped the same way reach the same positions; without steps nothing moves."""

    def run() -> list[int]:
        with VirtualBus([1], virtual_time=True, model="kinematic", transport="inprocess") as bus:
            bus.write(1, "torque_enable", 1)
            bus.write(1, "moving_speed", 100)
            bus.write(1, "goal_position", 900)
            trail = [bus.read(1, "present_position")]
            for _ in range(5):
                bus.step(0.1)
                trail.append(bus.read(1, "present_position"))
            return trail

    first = run()
    assert first == run()
    assert first[0] == 512 and first[1] > 512 and first == sorted(first)


def test_step_needs_virtual_time():
    """step() on a wall-clock bus is a clear error."""
    with VirtualBus([1], transport="inprocess") as bus, pytest.raises(RuntimeError, match="virtual_time"):
        bus.step(0.1)


def test_angle_temperature_and_external_torque():
    """Angle set by hand shows in Present Position; temperature pins; external torque reaches the model."""
    with VirtualBus([1], transport="inprocess", model="kinematic") as bus:
        bus.set_angle_deg(1, 150.0)
        assert abs(bus.angle_deg(1) - 150.0) < 1e-9
        assert abs(bus.read(1, "present_position") - 512) <= 2
        bus.set_temperature(1, 60)
        assert bus.temperature_c(1) == 60
        bus.set_external_torque(1, 0.5)
        assert bus.bus.model.external_torque_nm[0] == 0.5


def test_unknown_transport_is_a_value_error():
    """A misspelt transport names the choices."""
    with pytest.raises(ValueError, match="pty, tcp, inprocess"):
        VirtualBus([1], transport="usb")


def _write(link, servo_id: int, address: int, *data: int) -> bytes:
    link.write(encode_instruction(servo_id, 0x03, [address, *data]))
    return link.read(6)


def test_in_process_on_the_wall_clock_the_state_methods_see_the_shaft_now():
    """Nothing steps an in-process bus between packets: a read a while after the last packet showed the shaft where
    that packet left it (Present Position 512), where a pty's serving loop shows it at its goal."""
    with VirtualBus([1], transport="inprocess") as bus:
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.1) as link:
            assert _write(link, 1, 30, 600 & 0xFF, 600 >> 8) == encode_status(1, 0)  # Goal Position 600 (torque on)
            time.sleep(0.3)  # about 0.15 s at full speed
            assert abs(bus.read(1, "present_position") - 600) <= 4
            assert abs(bus.table(1)["present_position"] - 600) <= 4
            assert bus.angle_deg(1) == pytest.approx(600 * 300 / 1023, abs=1.5)


@pytest.mark.parametrize("transport", ["inprocess", "pty"])
def test_in_virtual_time_a_servo_answers_right_after_an_eeprom_write(transport):
    """The default busy time (6 ms a byte) never ends while the clock stands still: the servo was deaf until
    bus.step(); none by default, as ax12emu://?virtual_time=1.  options= given keeps its own."""
    from ax12emu.servo.virtual_servo import ServoOptions

    with VirtualBus([1], transport=transport, virtual_time=True) as bus:
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.1) as link:
            assert _write(link, 1, 5, 10) == encode_status(1, 0)  # Return Delay Time: EEPROM
            link.write(encode_instruction(1, 0x01))
            assert link.read(6) == encode_status(1, 0)
    with VirtualBus([1], transport="inprocess", virtual_time=True, options=ServoOptions()) as bus:
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.05) as link:
            assert _write(link, 1, 5, 10) == encode_status(1, 0)
            link.write(encode_instruction(1, 0x01))
            assert link.read(6) == b""  # busy, as asked, until the clock moves
            bus.step(0.01)
            link.write(encode_instruction(1, 0x01))
            assert link.read(6) == encode_status(1, 0)


def test_in_virtual_time_the_ax_servos_of_a_servo_text_answer_after_an_eeprom_write():
    with VirtualBus(servo="1:ax-12a,2:xl430-w250", virtual_time=True, transport="inprocess", baud_bps=1_000_000) as bus:
        with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.1) as link:
            assert _write(link, 1, 5, 10) == encode_status(1, 0)
            link.write(encode_instruction(1, 0x01))
            assert link.read(6) == encode_status(1, 0)


@pytest.mark.parametrize(("kwargs", "says"), [
    ({"transport": "tcp", "tcp_address": "0.0.0.0:0"}, "tcp_address: 0.0.0.0 binds beyond loopback"),
    ({"transport": "tcp", "tcp_address": ("192.0.2.1", 0)}, "tcp_address: 192.0.2.1 binds beyond loopback"),
    ({"transport": "inprocess", "web": "0.0.0.0:0"}, "web: 0.0.0.0 binds beyond loopback"),
])
def test_binding_beyond_loopback_needs_allow_remote(kwargs, says):
    """As serve asks for --allow-remote: a tcp_address of 0.0.0.0 served every interface without a word, while web=
    on the same address was refused naming a flag the API has not."""
    with pytest.raises(ValueError, match=f"{says}.*pass allow_remote=True") as refused:
        VirtualBus([1], **kwargs)
    assert "--allow-remote" not in str(refused.value)


def test_allow_remote_serves_every_interface(caplog):
    with VirtualBus([1], transport="tcp", tcp_address="0.0.0.0:0", allow_remote=True) as bus:
        assert bus.port.startswith("socket://0.0.0.0:")
    assert "reachable from other machines" in caplog.text


def test_allow_remote_lets_the_live_page_bind_every_interface():
    pytest.importorskip("aiohttp")
    with VirtualBus([1], transport="inprocess", web="0.0.0.0:0", allow_remote=True) as bus:
        assert bus.web_url is not None


def test_a_call_that_uses_the_buss_own_methods_runs_at_once_on_a_pty_too():
    """Served on a pty, fn ran on the serving thread and its own bus.read queued behind itself: 5 s, then TimeoutError."""
    import time

    with VirtualBus([1, 2]) as bus:
        start = time.monotonic()
        assert bus.call(lambda b: {i: bus.read(i, "present_position") for i in (1, 2)}) == {1: 512, 2: 512}
        assert time.monotonic() - start < 2.0


def test_step_and_the_clock_refuse_what_they_cannot_keep():
    import math

    from firmware_model import KinematicModel

    with VirtualBus([1], transport="pty", virtual_time=True) as bus:
        with pytest.raises(ValueError, match="finite step"):
            bus.step(math.inf)  # overflowed the serving thread's wait
    with pytest.raises(ValueError, match="time_scale applies to the wall clock"):
        VirtualBus([1], virtual_time=True, time_scale=50)  # was ignored
    with pytest.raises(ValueError, match="step_s must be positive"):
        KinematicModel(1, step_s=math.nan)


def test_the_ax12a_bus_starts_at_baud_bps():
    """``baud_bps=`` on the AX-12A bus sets each servo's Baud Rate (it was refused even at 1,000,000), so a suite
    pins its rate whatever model ``pytest --ax12-servo`` serves: a host at that rate is heard, one at 1 Mbps not."""
    with VirtualBus([1, 2], transport="inprocess", baud_bps=57_600) as bus:
        assert [bus.read(i, "baud_rate") for i in (1, 2)] == [34, 34]
        for host_bps, answer in ((57_600, encode_status(2, 0)), (1_000_000, b"")):
            with serial.serial_for_url(bus.port, baudrate=host_bps, timeout=0.05) as link:
                link.write(encode_instruction(2, 0x01))
                assert link.read(6) == answer


def _answered(bus: VirtualBus, packets: int = 40) -> str:
    """Which of ``packets`` PINGs got an answer, as 1s and 0s."""
    with serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.02) as link:
        seen = ""
        for _ in range(packets):
            link.write(encode_instruction(1, 0x01))
            seen += "1" if link.read(6) else "0"
        return seen


def test_seed_seeds_the_faults_a_fault_config_starts():
    """``VirtualBus(seed=N, faults=FaultConfig(...))``: the faults followed FaultConfig.seed (0) and ignored seed=."""
    from ax12emu import FaultConfig

    def pattern(**kwargs) -> str:
        with VirtualBus(transport="inprocess", **kwargs) as bus:
            return _answered(bus)

    by_seed = pattern(faults=FaultConfig(drop=0.5), seed=123)
    assert by_seed == pattern(faults=FaultConfig(drop=0.5, seed=123))
    assert by_seed != pattern(faults=FaultConfig(drop=0.5))
    with VirtualBus(transport="inprocess", faults=FaultConfig(seed=9)) as bus:  # no fault yet: those added later
        assert bus.faults.seed == 9
    with pytest.raises(ValueError, match=r"seed=1 and faults=FaultConfig\(seed=2\) give two seeds"):
        VirtualBus(seed=1, faults=FaultConfig(drop=0.5, seed=2))


def test_read_after_a_clients_write_shows_what_the_clients_next_read_would():
    """The AX-12 bus's advance takes only steps already due, so read and table lagged a client's write (Moving 0
    after a Goal Position write, where the client's own next read finds 1) until the next step."""
    with VirtualBus([1], transport="inprocess", virtual_time=True) as bus:
        port = serial.serial_for_url(bus.port, baudrate=1_000_000, timeout=0.5)
        try:
            port.write(encode_instruction(1, 0x03, bytes((30, 900 & 0xFF, 900 >> 8))))  # Goal Position 900
            assert port.read(6) == encode_status(1, 0)
            assert bus.read(1, "moving") == 1 and bus.table(1)["moving"] == 1
        finally:
            port.close()
