"""The one wire builder: each servo takes a bit rate as its own model's Baud Rate values give it."""

from __future__ import annotations

import pytest

from ax12emu.bus.clock import VirtualClock
from ax12emu.bus.wire import build_wire


@pytest.mark.parametrize(("bps", "value"), [(3_000_000, 252), (2_500_000, 251), (2_250_000, 250), (1_000_000, 1),
                                            (57_600, 34)])
def test_an_mx_takes_its_own_baud_values(bps, value):
    """MX series, Protocol 1.0: 2,000,000 / (value + 1) up to 249, then 2.25, 2.5 and 3 Mbps at 250..252."""
    bus = build_wire("mx-106", clock=VirtualClock(), baud_bps=bps)
    try:
        servo = bus.servo(1)
        assert servo.table.get("baud_rate") == value
        assert servo.baud_bps == pytest.approx(bps, rel=0.03)
    finally:
        bus.close()


def test_rates_come_from_each_servos_table_range():
    """Every value the Baud Rate register accepts (0..254 in the MX and AX-18A files) has a rate, and no other."""
    bus = build_wire("1:ax-18a,2:mx-28", clock=VirtualClock())
    try:
        ax, mx = bus.servo(1), bus.servo(2)
        assert sorted(ax.baud_rates_bps) == sorted(mx.baud_rates_bps) == list(range(255))
        assert max(ax.baud_rates_bps.values()) == 2_000_000 and max(mx.baud_rates_bps.values()) == 3_000_000
    finally:
        bus.close()


def test_a_rate_one_servo_cannot_run_names_it():
    with pytest.raises(ValueError, match=r"ID 1 \(AX-18A\) cannot run at 3000000 bps"):
        build_wire("1:ax-18a,2:mx-28", clock=VirtualClock(), baud_bps=3_000_000)


def test_a_servo_the_state_directory_kept_starts_at_its_kept_rate_not_at_baud(tmp_path):
    """A client set an XL430 to 57,600; the next start with --baud 1000000 put it back at 1 Mbps and overwrote the
    saved Baud Rate, where a real servo keeps it.  A servo with nothing kept starts at --baud."""
    from ax12emu.bus.state_store import StateStore
    from ax12emu.bus.wire import build_wire_of, servo_models

    def start(ids):
        return build_wire_of(servo_models(ids, None), clock=VirtualClock(), baud_bps=1_000_000,
                             state_store2=StateStore(tmp_path))

    bus = start("1:xl430-w250")
    bus.servo(1).table.set("baud_rate", 1)  # a client's 57,600
    bus.close()
    bus = start("1-2:xl430-w250")
    assert bus.servo(1).table.get("baud_rate") == 1 and bus.servo(2).table.get("baud_rate") == 3
    bus.close()


def test_a_state_not_loaded_is_replaced_on_disk_at_once(tmp_path):
    """``--factory-reset`` saved the factory image only at close: a server killed before then left the old files, and
    the next run brought back IDs the reset run never served.  save_wire_state writes every family's factory image
    (the AX-12As inside an MX bus too), before anything closes the wire."""
    import json

    from ax12emu.bus.state_store import StateStore
    from ax12emu.bus.wire import build_wire_of, save_wire_state, servo_models

    models = servo_models("1:ax-12a,2:mx-28,3:xl430-w250", None, mixed=True)
    store1, store2 = StateStore(tmp_path), StateStore(tmp_path / "2")

    def start(load_state):
        return build_wire_of(models, clock=VirtualClock(), state_store1=store1, state_store2=store2,
                             load_state=load_state)

    bus = start(True)
    for servo_id in (1, 2, 3):
        bus.servo(servo_id).table.set("return_delay_time", 10)
    bus.close()
    files = {1: store1.path_for(1), 2: store1.path_for(2), 3: store2.path_for(3)}
    assert all(json.loads(path.read_text())["eeprom"]["return_delay_time"] == 10 for path in files.values())
    bus = start(False)
    try:
        save_wire_state(bus)  # as serve --factory-reset does once it has started
        factory = {slot: bus.servo(slot).table.get("return_delay_time") for slot in files}
        saved = {slot: json.loads(path.read_text())["eeprom"]["return_delay_time"] for slot, path in files.items()}
        assert saved == factory and 10 not in factory.values()
    finally:
        bus.close()
