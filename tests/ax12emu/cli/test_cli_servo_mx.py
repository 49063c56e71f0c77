"""``serve --servo mx-28`` (MX-64, MX-106): the MX series' Protocol 1.0 firmware from the command line, alone or on a mixed wire."""

from __future__ import annotations

import subprocess
import sys

import pytest

from ax12emu.cli.main import parse_args


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ax12emu", *args], capture_output=True, text=True, timeout=30)


def test_the_spec_takes_the_mx_series_alone_and_beside_other_models():
    assert parse_args(["serve", "--servo", "mx-28", "--ids", "1-4"]).servo_models == [(i, "mx-28") for i in range(1, 5)]
    assert parse_args(["serve", "--servo", "1-2:ax-12a,3:mx-64,4:xl430-w250"]).servo_models == [
        (1, "ax-12a"), (2, "ax-12a"), (3, "mx-64"), (4, "xl430-w250")]
    # IDs are per protocol: an MX (1.0) and an XL430 (2.0) may both be ID 1, two 1.0 models may not.
    assert parse_args(["serve", "--servo", "1:mx-106,1:xl430-w250"]).servo_models == [(1, "mx-106"), (1, "xl430-w250")]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--servo", "1:ax-12a,1:mx-28"], "ID 1"),
        (["--servo", "mx-64", "--voltage", "7"], "MX-64 runs on 10..14.8 V, not 7 V"),
        # an X-series Hardware Error Status name the Protocol 1.0 status packet has no bit for
        (["--servo", "mx-28", "--alarm", "1:electrical_shock"], "unknown alarm 'electrical_shock'"),
    ],
)
def test_mistakes_are_one_line(args, message):
    result = run("serve", *args)
    assert result.returncode != 0, result
    assert "Traceback" not in result.stderr
    assert message in result.stderr, result.stderr


def test_models_lists_the_mx_series_on_protocol_1():
    out = run("models").stdout
    rows = {line.split()[0]: line for line in out.splitlines()[1:]}
    for key in ("mx-28", "mx-64", "mx-106"):
        assert " 1.0 " in rows[key] and rows[key].endswith("x-series")
    assert rows["ax-12a"].endswith("ax-12") and rows["xl430-w250"].endswith("x-series")


def _wire(*flags: str):
    """The wire ``serve`` would serve for these flags, built in-process on a virtual clock (nothing is served)."""
    from ax12emu.bus.clock import VirtualClock
    from ax12emu.cli.main import build_serve_wire

    return build_serve_wire(parse_args(["serve", *flags]), VirtualClock())


def test_baud_takes_each_servos_own_rates():
    """--baud 3000000: an MX runs at Baud Rate 252 (MX-106 e-manual: "7,834 [bps] ~ 3 [Mbps]"), an XL430 at its
    table's 3 Mbps value; the AX-12A's 2,000,000 / (value + 1) is not asked of them."""
    bus = _wire("--servo", "1:mx-106,2:mx-28,1:xl430-w250", "--baud", "3000000")
    try:
        assert bus.servo(1, 1.0).table.get("baud_rate") == 252
        assert bus.servo(2, 1.0).table.get("baud_rate") == 252
        assert bus.servo(1, 2.0).table.get("baud_rate") == 5  # XL430: 0..7 are 9600 .. 4.5M, 5 is 3M
        assert bus.servo(1, 1.0).baud_bps == 3_000_000
    finally:
        bus.close()


def test_baud_one_servo_cannot_take_names_it():
    result = run("serve", "--servo", "1:ax-12a,2:mx-106", "--baud", "3000000")
    assert result.returncode == 2, result
    assert "Traceback" not in result.stderr
    assert "ID 1 (AX-12A) cannot run at 3000000 bps" in result.stderr, result.stderr


def test_serve_builds_the_harness_wire():
    """The same flags give the same wire as VirtualBus's builder: an AX-12A inside the MXs' bus, beside the X series."""
    from ax12emu.bus.clock import VirtualClock
    from ax12emu.bus.wire import build_wire, servo_list

    flags = "1:ax-12a,2:mx-64,1-2:xl430-w250"
    served, built = _wire("--servo", flags), build_wire(flags, clock=VirtualClock())
    try:
        assert type(served) is type(built) and servo_list(served) == servo_list(built)
        assert type(served.holder(served.servo(1, 1.0))) is type(built.holder(built.servo(1, 1.0)))
    finally:
        served.close()
        built.close()
