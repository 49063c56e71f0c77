"""``serve --servo xl-320``: XL-320s on Protocol 2.0 from the command line, alone or beside X-series servos."""

from __future__ import annotations

from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, PacketHandler

from ax12emu.cli.main import parse_args

XL320, XL430 = 350, 1060
HARDWARE_ERROR_STATUS = 50  # the XL-320's (70 on the X series)


def test_the_spec_takes_xl320_alone_and_per_id():
    assert parse_args(["serve", "--servo", "xl-320", "--ids", "1-3"]).servo_models == [(1, "xl-320"), (2, "xl-320"), (3, "xl-320")]
    assert parse_args(["serve", "--servo", "1-2:xl430-w250,3:xl-320"]).servo_models == [
        (1, "xl430-w250"), (2, "xl430-w250"), (3, "xl-320")]


def test_dynamixel_sdk_pings_xl320s_at_their_factory_baud_and_an_alarm_reads_in_their_bits(emulator):
    """The XL-320's factory Baud Rate is 3 (1 Mbps); --alarm 2:overload latches Overload, which the XL-320's
    Hardware Error Status(50) shows as bit 0 (its Shutdown(18) bits), with the Alert bit."""
    from emu_testkit import PatientPortHandler

    port = PatientPortHandler(emulator("--servo", "xl-320", "--ids", "1-3", "--alarm", "2:overload").port)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        ph = PacketHandler(2.0)
        assert [ph.ping(port, i)[:2] for i in (1, 2, 3)] == [(XL320, COMM_SUCCESS)] * 3
        assert ph.read1ByteTxRx(port, 2, HARDWARE_ERROR_STATUS) == (0x01, COMM_SUCCESS, 0x80)
        assert ph.read1ByteTxRx(port, 1, HARDWARE_ERROR_STATUS) == (0, COMM_SUCCESS, 0)
        assert ph.ping(port, 4)[1] == COMM_RX_TIMEOUT
    finally:
        port.closePort()


def test_xl320_beside_xl430s(emulator):
    from emu_testkit import PatientPortHandler

    port = PatientPortHandler(emulator("--servo", "1-2:xl430-w250,3:xl-320", "--baud", "1000000").port)
    assert port.openPort() and port.setBaudRate(1_000_000)
    try:
        ph = PacketHandler(2.0)
        assert [ph.ping(port, i)[0] for i in (1, 2, 3)] == [XL430, XL430, XL320]
    finally:
        port.closePort()


def test_models_lists_the_xl320_on_protocol_2_run_by_the_x_series_firmware():
    from ax12emu.cli.models import models_table

    row = next(line for line in models_table().splitlines() if line.startswith("xl-320 "))
    assert row.split()[1:4] == ["XL-320", "2.0", "350"]
    assert "0.39 N m @ 7.4 V" in row and "114 rpm @ 7.4 V" in row and row.split()[-1] == "x-series"
