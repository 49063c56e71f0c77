"""The conformance suite against the emulator: one scenario over pty, TCP and in process."""

from __future__ import annotations

import subprocess
import sys
import types

import pytest
from emu_testkit import CONFORMANCE_TIMEOUT_S, EMULATOR_SILENCE_S

from ax12emu import VirtualBus, conformance
from ax12emu.conformance import FAIL, PASS

#: Real time and real ports: the wall-clock tier (CI runs it too).
pytestmark = pytest.mark.wallclock

IDS = [1, 2]
TRANSPORTS = ["pty", "tcp", "inprocess"]


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_full_suite_passes(transport, emulator):
    """Every check, destructive ones included, passes and the tables end as they began.

    Over pty and TCP the emulator runs as its own process, as a user runs it: in a thread of
    this process it would share the interpreter lock with the client, and the round trips the
    return-delay check times would carry the lock's hand-overs.
    """
    if transport == "inprocess":
        with VirtualBus(IDS, transport=transport, model="kinematic") as bus:
            report = conformance.run(bus.port, IDS, destructive=True, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    else:
        where = ["--tcp", "127.0.0.1:0"] if transport == "tcp" else []
        served = emulator("--ids", ",".join(map(str, IDS)), "--model", "kinematic", *where)
        report = conformance.run(served.port, IDS, destructive=True, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    assert report.passed, report.table()
    for name in ("ID change", "RESET", "return delay", "status return levels", "resync after garbage", "table unchanged"):
        assert report.outcome(name) == PASS, report.table()


def _tables_over_the_port(port: str) -> dict[int, bytes]:
    """Every servo's whole table, read by a client of its own (raw READ packets, pty path or socket:// URL)."""
    import serial

    from ax12emu.protocol.packets import encode_instruction

    tables = {}
    with serial.serial_for_url(port, baudrate=1_000_000, timeout=1.0) as link:
        for servo_id in IDS:
            link.reset_input_buffer()
            link.write(encode_instruction(servo_id, 0x02, bytes([0, 50])))
            reply = link.read(6 + 50)
            assert len(reply) == 56 and reply[2] == servo_id and reply[4] == 0, reply.hex()
            tables[servo_id] = reply[5:55]
    return tables


@pytest.mark.parametrize("transport", TRANSPORTS)
def test_non_destructive_mode_changes_nothing(transport, emulator):
    """Without --destructive the device's table, read independently before and after, is unchanged.

    In process the tables are read through the API; over pty and TCP the emulator is a process
    of its own (see test_full_suite_passes) and a separate client reads all 50 bytes.
    """
    if transport == "inprocess":
        with VirtualBus(IDS, transport=transport, model="kinematic") as bus:
            before = {i: bus.table(i) for i in IDS}
            report = conformance.run(bus.port, IDS, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
            after = {i: bus.table(i) for i in IDS}
    else:
        where = ["--tcp", "127.0.0.1:0"] if transport == "tcp" else []
        served = emulator("--ids", ",".join(map(str, IDS)), "--model", "kinematic", *where)
        before = _tables_over_the_port(served.port)
        report = conformance.run(served.port, IDS, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
        after = _tables_over_the_port(served.port)
    assert report.passed, report.table()
    assert report.outcome("RESET") == "skip"
    assert before == after


def test_private_url_passes_like_the_pty():
    """serial_for_url("ax12emu://?ids=1,2"), with no VirtualBus at all, passes the same suite."""
    report = conformance.run("ax12emu://?ids=1,2", IDS, destructive=True, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    assert report.passed, report.table()


def test_a_misbehaving_device_fails_with_a_figure():
    """A servo that loses every reply fails the checks and the table says what was seen."""
    report = conformance.run("ax12emu://?ids=1&drop=1", [1], timeout_s=0.02)
    assert not report.passed
    assert report.results[0].outcome == FAIL and "no reply" in report.results[0].figure


def test_cli_conformance_against_served_tcp(emulator):
    """ax12emu conformance socket://... prints the table and exits 0; a broken device exits 1.

    Two checks (``--only``): the whole suite over a served TCP bus is test_full_suite_passes[tcp]'s;
    this one checks what the command adds (arguments, the table, the exit status).
    """
    served = emulator("--tcp", "127.0.0.1:0", "--ids", "1,2", "--model", "kinematic")
    result = subprocess.run(
        [sys.executable, "-m", "ax12emu", "conformance", served.port, "--ids", "1,2",
         "--timeout-ms", str(round(CONFORMANCE_TIMEOUT_S * 1e3)), "--silence-ms", str(round(EMULATOR_SILENCE_S * 1e3)),
         "--only", "ping", "--only", "return delay", "--only", "absent ID is silent"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "return delay" in result.stdout and "4 checks, 0 failed" in result.stdout  # the three and "table unchanged"
    assert f"silent for {round(EMULATOR_SILENCE_S * 1e3)}" in result.stdout
    bad = subprocess.run(
        [sys.executable, "-m", "ax12emu", "conformance", "ax12emu://?ids=1&corrupt=1", "--only", "ping"],
        capture_output=True, text=True, timeout=60,
    )
    assert bad.returncode == 1 and "FAIL" in bad.stdout


@pytest.mark.parametrize(("argv", "says"), [
    (["--only", "nosuch"], "no such check: nosuch; the Protocol 1.0 checks are: ping,"),
    (["--only", "read tables"], "no such check: read tables"),  # a row the report prints, not a check
    (["--protocol", "2.0", "--only", "ping", "--only", "moving"], "no such check: moving; the Protocol 2.0 checks"),
    (["--timeout-ms", "nan"], "--timeout-ms: must be a finite number"),  # it waited for good
    (["--timeout-ms", "0"], "--timeout-ms: must be a positive finite number"),  # it blamed the servo
    (["--silence-ms", "-5"], "--silence-ms: must be a positive finite number"),
])
def test_a_misspelt_check_or_a_bad_timeout_is_an_error_not_a_pass_or_a_hang(argv, says):
    """A check name no suite has ran nothing and reported a pass (rc 0); a NaN timeout hung."""
    result = subprocess.run([sys.executable, "-m", "ax12emu", "conformance", "ax12emu://?ids=1", *argv],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and says in result.stderr, (result.returncode, result.stdout, result.stderr)


def test_reset_leaves_a_servo_not_under_test_alone():
    """Testing ID 2 beside a servo at ID 1: the RESET check would put ID 2 on ID 1 and write its table back to both
    (servo 1 ended with servo 2's ID and table); it is skipped, and servo 1 is as it was."""
    with VirtualBus([1, 2], transport="inprocess", model="kinematic") as bus:
        bus.write(1, "ccw_angle_limit", 800)
        before = bus.table(1)
        report = conformance.run(bus.port, [2], destructive=True, only=["RESET"], timeout_s=CONFORMANCE_TIMEOUT_S,
                                 silence_s=EMULATOR_SILENCE_S)
        assert report.outcome("RESET") == "skip" and bus.table(1) == before and bus.read(2, "id") == 2


def test_the_broadcast_write_check_leaves_a_servo_not_under_test_dark():
    """A broadcast reaches every servo on the bus: one not under test kept its LED lit after the check."""
    with VirtualBus([1, 2, 3], transport="inprocess", model="kinematic") as bus:
        report = conformance.run(bus.port, [1, 2], only=["broadcast WRITE"], timeout_s=CONFORMANCE_TIMEOUT_S,
                                 silence_s=EMULATOR_SILENCE_S)
        assert report.outcome("broadcast WRITE") == "pass" and bus.read(3, "led") == 0


def test_a_destructive_check_that_fails_mid_way_still_puts_the_servo_back():
    """A RESET answered from the new ID (--reset-reply-id new) fails the check, and the servo gets its ID and table
    back (it was left at ID 1 with the factory table, and the report did not say)."""
    from ax12emu.servo.virtual_servo import ServoOptions

    with VirtualBus([2], transport="inprocess", model="kinematic", options=ServoOptions(reset_reply_from_new_id=True)) as bus:
        bus.write(2, "ccw_angle_limit", 800)
        report = conformance.run(bus.port, [2], destructive=True, only=["RESET"], timeout_s=CONFORMANCE_TIMEOUT_S,
                                 silence_s=EMULATOR_SILENCE_S)
        assert report.outcome("RESET") == FAIL and "came from id=1" in next(r.figure for r in report.results if r.name == "RESET")
        assert bus.bus.ids == [2] and bus.read(2, "ccw_angle_limit") == 800


def test_an_echoing_adapter_neither_fails_the_suite_nor_stands_in_for_a_servo(emulator):
    """A half-duplex adapter hands back every byte the host sends (--echo): the suite passes through it, its
    echoes (that of a packet with a wrong checksum too) never taken for replies; and an ID nobody has fails
    (the split-packet and back-to-back checks passed on the echo alone)."""
    served = emulator("--ids", "1,2", "--echo", "--tcp", "127.0.0.1:0")
    report = conformance.run(served.port, IDS, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    assert report.passed, report.table()
    from ax12emu.conformance.checks import Context, Failed, check_back_to_back, check_split_packet
    from ax12emu.conformance.link import Link, open_port

    link = Link(open_port(served.port, 1_000_000), timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    try:
        for check in (check_split_packet, check_back_to_back):
            with pytest.raises(Failed):
                check(Context(link, [7, 9]))  # nobody has IDs 7 and 9: only the echoes come back
    finally:
        link.close()


def test_alarms_a_servo_raises_are_said_not_passed_over():
    """Every other check looks past the alarm bits, so an overloaded servo passed unseen: the alarms check says it."""
    report = conformance.run("ax12emu://?ids=1,2&alarm=1:overload", IDS, only=["alarms"], timeout_s=CONFORMANCE_TIMEOUT_S,
                             silence_s=EMULATOR_SILENCE_S)
    assert report.outcome("alarms") == "note" and "ID 1 OVERLOAD" in report.table()
    clean = conformance.run("ax12emu://?ids=1,2", IDS, only=["alarms"], timeout_s=CONFORMANCE_TIMEOUT_S,
                            silence_s=EMULATOR_SILENCE_S)
    assert clean.outcome("alarms") == "pass"


@pytest.mark.parametrize(("servo", "ids", "baud"), [
    ("mx-28", [1], 57_600),  # the MX series' factory Baud Rate 34
    ("mx-64", [1], 57_600),
    ("mx-106", [1], 57_600),
    ("ax-18a", [1], 1_000_000),
    ("1:ax-12a,2:mx-28", [1, 2], 1_000_000),
    ("1:mx-28,2:ax-18a,3:mx-106", [3, 2, 1], 1_000_000),  # an MX the target, two of them for Bulk Read
])
def test_the_protocol1_suite_takes_each_servos_table_from_its_model_number(servo, ids, baud):
    """Every Protocol 1.0 model served passes the whole suite, destructive checks included: each servo is judged by
    its own model file's table (the suite took every servo for an AX-12: an MX-28's model number 29, its 74-byte
    table and its factory 57,600 bps after RESET failed, as did an AX-18A's defaults)."""
    url = f"ax12emu://?servo={servo}" + ("" if baud == 57_600 else f"&baud={baud}")
    report = conformance.run(url, ids, baud=baud, destructive=True, timeout_s=CONFORMANCE_TIMEOUT_S,
                             silence_s=EMULATOR_SILENCE_S)
    assert report.passed, report.table()
    for name in ("model number", "read whole table", "read past the table", "instruction error", "ID change",
                 "baud change", "RESET", "table unchanged"):
        assert report.outcome(name) == PASS, report.table()
    figures = {r.name: r.figure for r in report.results}
    if servo.startswith("mx"):  # a lone MX at its factory rate: its own defaults, its own 74 bytes
        assert report.outcome("defaults") == PASS and figures["read whole table"] == "74 bytes", report.table()
        assert figures["instruction error"].startswith("0x50: INSTRUCTION"), report.table()  # an MX knows Bulk Read
    if servo == "ax-18a":
        assert report.outcome("defaults") == PASS and figures["instruction error"].startswith("BULK_READ"), report.table()
    assert report.outcome("BULK_READ") == (PASS if servo.count("mx") >= 2 else "skip"), report.table()


def test_a_model_number_no_file_has_fails_that_check_and_the_rest_judge_by_the_ax12_table(monkeypatch):
    """A servo whose model number names no Protocol 1.0 model file (an RX-28, say) fails the model-number check, which
    says so; the checks that need its factory table skip, and the rest judge it by the AX-12A's table."""
    from ax12emu.conformance import checks

    known = checks.model_for_number1
    monkeypatch.setattr(checks, "model_for_number1", lambda number: None if number == 12 else known(number))
    report = conformance.run("ax12emu://?ids=1", [1], destructive=True, timeout_s=CONFORMANCE_TIMEOUT_S,
                             silence_s=EMULATOR_SILENCE_S, only=["model number", "defaults", "read past the table",
                                                                  "instruction error", "RESET"])
    figures = {r.name: r.figure for r in report.results}
    assert report.outcome("model number") == FAIL and "model number 12 names no Protocol 1.0 model file" in figures["model number"]
    assert report.outcome("defaults") == "skip" and report.outcome("RESET") == "skip", report.table()
    assert report.outcome("read past the table") == PASS and report.outcome("table unchanged") == PASS, report.table()
    assert figures["instruction error"].startswith("0x50: INSTRUCTION"), report.table()  # it may know Bulk Read


class _LaggyLink:
    """A servo's registers behind a link whose round trips are ``base_s`` whatever Return Delay Time says (an FTDI
    adapter's latency timer holding every short reply back), or that add it (``shows_delay``)."""

    ping_exchange_bytes = 24  # Protocol 2.0's

    def __init__(self, base_s: float, shows_delay: bool, baud: int = 1_000_000) -> None:
        self.base_s, self.shows_delay, self.rdt = base_s, shows_delay, 250
        self.link = types.SimpleNamespace(baud=baud)

    def get(self, servo, name):
        return self.rdt

    def must_put(self, servo, name, value):
        self.rdt = value

    put = must_put

    def ping_rtts(self, servo, count):
        return [self.base_s + (self.rdt * 2e-6 if self.shows_delay else 0.0)] * count


@pytest.mark.parametrize(("base_s", "shows_delay", "baud", "outcome"), [
    (0.016, False, 1_000_000, "note"),   # behind a 16 ms latency timer: the adapter decides, not the servo
    (0.0002, False, 1_000_000, "fail"),  # a quick link and no delay seen: the servo ignores Return Delay Time
    (0.016, True, 1_000_000, "pass"),
    (0.0042, False, 57_600, "fail"),     # 4.2 ms is a 2.0 Ping's and its status's time on the wire at 57,600 bps
])
def test_return_delay_is_not_failed_on_a_link_too_coarse_to_see_it(base_s, shows_delay, baud, outcome):
    from ax12emu.conformance.checks import Failed, Note, return_delay_figure

    link = _LaggyLink(base_s, shows_delay, baud)
    try:
        seen = "note" if isinstance(return_delay_figure(link, 1), Note) else "pass"
    except Failed:
        seen = "fail"
    assert seen == outcome
    assert link.rdt == 250  # put back


@pytest.mark.parametrize("waits", [{"timeout_s": float("nan")}, {"timeout_s": -1.0}, {"silence_s": 0.0},
                                   {"silence_s": float("inf")}])
def test_a_wait_that_cannot_be_kept_is_refused_before_the_port_opens(waits):
    """NaN waited for ever; 0 or less listened for nothing, passing an ID that answers as silent."""
    with pytest.raises(ValueError, match="must be a positive finite number of seconds"):
        conformance.run("ax12emu://?ids=1", [1], **waits)


def test_the_protocol_may_be_given_as_a_number_as_virtualbus_takes_it():
    report = conformance.run("ax12emu://?servo=xl430-w250", [1], baud=57_600, protocol=2.0, only=["ping"],
                             timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    assert report.outcome("ping") == PASS


def test_a_servo_at_status_return_level_1_is_raised_for_the_run_and_put_back():
    """Level 1 answers PING and READ only (a legitimate setting): 9 checks failed with "no reply to WRITE", and the run
    left a REG_WRITE registered. Raised to 2 for the run, the suite passes, every table ends as it began, and the
    last row says the level was put back."""
    with VirtualBus(IDS, transport="inprocess", model="kinematic") as bus:
        bus.write(1, "status_return_level", 1)
        before = {i: bus.table(i) for i in IDS}
        report = conformance.run(bus.port, IDS, timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
        after = {i: bus.table(i) for i in IDS}
    assert report.passed, report.table()
    assert report.results[-1].name == "Status Return Level put back" and report.results[-1].outcome == "note"
    assert "ID 1: 1 -> 2 for the run" in report.results[-1].figure
    sensed = {"present_position", "present_speed", "present_load", "present_voltage", "present_temperature", "moving"}
    assert {i: {k for k in before[i] if before[i][k] != after[i][k]} - sensed for i in IDS} == {1: set(), 2: set()}
    assert after[1]["status_return_level"] == 1 and after[1]["registered"] == 0


def test_a_restore_tries_every_servo_though_one_put_fails():
    """The restores in ``finally`` stopped at the first unanswered put, leaving the servos after it changed."""
    from ax12emu.conformance.checks import Failed, put_all

    tried = []

    class _Ctx:
        def put(self, servo, name, value):
            tried.append(servo)
            if servo == 1:
                raise Failed("no reply to WRITE id=1")
            return 0

    with pytest.raises(Failed, match="could not put back: no reply to WRITE id=1"):
        put_all(_Ctx(), [(1, "led", 0), (2, "led", 0), (3, "led", 0)])
    assert tried == [1, 2, 3]


def test_reset_write_back_leaves_the_torque_off_and_the_shaft_where_it_is(monkeypatch):
    """The RESET write-back wrote Goal Position and Moving Speed before Torque Enable: on an AX either turns the torque
    on, and a shaft turned by hand with the torque off was driven back to its stale goal. With the saved torque off
    they are written with Torque Limit 0 (torque on, no torque to give), then Torque Enable 0, then Torque Limit:
    every register comes back, Moving Speed's limit too, and the shaft stays where it is."""
    from ax12emu.conformance import checks

    with VirtualBus([1], transport="inprocess") as bus:
        bus.write(1, "moving_speed", 100)
        bus.set_angle_deg(1, 60.0)  # turned by hand, torque off: Present Position far from Goal Position
        driving = []
        put = checks.Context.put

        def watching(self, *args, **kwargs):
            error = put(self, *args, **kwargs)
            if 1 in bus.bus.ids and bus.read(1, "torque_enable") and bus.read(1, "torque_limit"):
                driving.append(args)
            return error

        monkeypatch.setattr(checks.Context, "put", watching)
        position = bus.read(1, "present_position")
        report = conformance.run(bus.port, [1], destructive=True, only=["RESET"], timeout_s=CONFORMANCE_TIMEOUT_S,
                                 silence_s=EMULATOR_SILENCE_S)
        assert report.passed, report.table()
        assert driving == []  # never torque on with torque to give
        assert abs(bus.read(1, "present_position") - position) <= 1 and bus.read(1, "torque_enable") == 0
        assert bus.read(1, "moving_speed") == 100 and bus.read(1, "torque_limit") == 1023


def test_two_packets_in_one_write_is_a_note_where_the_line_cannot_carry_both_replies(emulator):
    """At 57,600 bps the second packet's 8 bytes take 1.39 ms, longer than the first reply's Return Delay Time (0.5 ms):
    on a half-duplex line the reply overlaps the host's bytes (serve --pace keeps that wire time), so a real bus
    cannot pass; it failed. A note saying why."""
    served = emulator("--ids", "1", "--servo", "mx-28", "--pace", "--tcp", "127.0.0.1:0")
    report = conformance.run(served.port, [1], baud=57_600, only=["two packets in one write"],
                             timeout_s=CONFORMANCE_TIMEOUT_S, silence_s=EMULATOR_SILENCE_S)
    result = report.results[0]
    assert result.outcome == "note", report.table()
    assert "take 1.39 ms at 57600 bps, longer than ID 1's Return Delay Time (500 us)" in result.figure
