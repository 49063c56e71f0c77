"""The command line: bad input gives one line and a non-zero exit, never a traceback."""

from __future__ import annotations

import io
import socket
import subprocess
import sys
import time

import pytest

from ax12emu.bus.clock import WallClock
from ax12emu.cli.main import parse_args


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ax12emu", *args], capture_output=True, text=True, timeout=30)


@pytest.mark.parametrize(
    "args, message",
    [
        (["serve", "--ids", "1-x"], "not an ID"),
        (["serve", "--tcp", "localhost"], "HOST:PORT"),
        (["serve", "--tcp", "0.0.0.0:0"], "--allow-remote"),
        (["serve", "--time-scale", "-2"], "positive"),
        (["serve", "--profile", "ax18"], "invalid choice"),
        (["serve", "--goal-torque", "maybe"], "invalid choice"),
        (["serve", "--eeprom-busy-ms", "-1"], "0..1000 ms"),
        (["serve", "--eeprom-busy-ms", "nan"], "finite"),
        (["serve", "--link", "/tmp/x", "--tcp", "127.0.0.1:0"], "not allowed with|not to --tcp"),
        (["bogus"], "invalid choice"),
        (["serve", "--params", ""], "names no file"),
        (["serve", "--vanish", "1:inf:1"], "--vanish: expected finite seconds"),  # gone for 1 s, then never  # was refused as "Is a directory" (the working folder)
        (["conformance", "/dev/null", "--baud", "0"], "must be >= 1"),  # a division by the rate, after the checks began
    ],
)
def test_bad_flags_exit_2_with_usage(args, message):
    """argparse rejects bad flags with exit 2 and one line naming the problem (not the 17-line usage block)."""
    result = run(*args)
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert any(part in result.stderr for part in message.split("|")), result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "--help" in result.stderr, result.stderr


@pytest.mark.parametrize("url", ["socket://127.0.0.1", "socket://localhost:abc"])
def test_conformance_on_a_socket_url_without_its_port_is_one_line_naming_the_form(url):
    """pyserial's parser said "'<=' not supported between instances of 'int' and 'NoneType'" or only
    "'debug|info|warning|error'", as serve --tcp names HOST:PORT for the same mistake."""
    result = run("conformance", url, "--ids", "1")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == [f"ax12emu: expected socket://HOST:PORT[?logging=debug|info|warning|error] "
                                                  f"(PORT 1..65535), got {url!r}"], result.stderr


def test_corrupt_state_file_is_one_line(tmp_path):
    """A corrupt state file stops start-up with one line naming the file."""
    (tmp_path / "servo-001.json").write_text("garbage")
    result = run("serve", "--state-dir", str(tmp_path))
    assert result.returncode == 2
    assert "servo-001.json" in result.stderr and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_link_over_a_regular_file_is_refused(tmp_path):
    """--link never replaces a file that is not a symlink."""
    target = tmp_path / "precious"
    target.write_text("keep me")
    result = run("serve", "--link", str(target))
    assert result.returncode == 2 and "not a symlink" in result.stderr
    assert target.read_text() == "keep me"


def test_a_second_server_on_a_link_warns_and_the_first_leaves_it_alone(tmp_path, emulator):
    """Server B took a running server A's --link without a word, and A's exit then removed B's link."""
    import os
    import signal

    link = tmp_path / "ax12"
    first = emulator("--link", str(link))
    second = emulator("--link", str(link))
    assert os.readlink(link) == second.port
    assert first.stop(signal.SIGTERM) == 0
    assert link.is_symlink() and os.readlink(link) == second.port
    assert second.stop(signal.SIGTERM) == 0 and not link.is_symlink()
    said = second.process.stderr.read()
    assert "pointed at" in (said.decode() if isinstance(said, bytes) else said)


def test_a_hangup_stops_the_server_cleanly(tmp_path, emulator):
    """SIGHUP (the terminal or ssh session closing) killed it at once, leaving its --link at a freed pty number."""
    import signal

    link = tmp_path / "ax12"
    before = signal.signal(signal.SIGHUP, signal.SIG_DFL)  # a run under nohup would start it ignoring hangups
    try:
        served = emulator("--link", str(link))
    finally:
        signal.signal(signal.SIGHUP, before)
    assert served.stop(signal.SIGHUP) == 0
    assert not link.exists() and not link.is_symlink()


def test_under_nohup_a_hangup_leaves_the_server_serving(emulator):
    """``nohup ax12emu serve &`` then logging out: a hangup ignored when the server started stays ignored."""
    import signal

    import serial

    before = signal.signal(signal.SIGHUP, signal.SIG_IGN)  # what nohup does before it runs the command
    try:
        served = emulator("--tcp", "127.0.0.1:0")
    finally:
        signal.signal(signal.SIGHUP, before)
    served.process.send_signal(signal.SIGHUP)
    time.sleep(0.5)
    assert served.process.poll() is None
    with serial.serial_for_url(served.port, timeout=2.0) as link:
        link.write(bytes.fromhex("ffff010201fb"))
        assert link.read(6) == bytes.fromhex("ffff010200fc")
    assert served.stop(signal.SIGTERM) == 0


@pytest.mark.parametrize(("flag", "under"), [("--link", "ax12"), ("--state-dir", "state")])
def test_a_path_in_a_missing_folder_is_named_with_its_flag(tmp_path, flag, under):
    """The bare errno named the pty ("'/dev/pts/0' -> '/no/dir/ax12'": as if the pty were missing) or a lock file."""
    path = tmp_path / "no-such-folder" / "deeper" / under
    if flag == "--state-dir":  # a folder it may make; under a file it cannot
        (tmp_path / "no-such-folder").write_text("a file")
    result = run("serve", flag, str(path))
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert result.stderr.strip().startswith("ax12emu:") and f"{flag} {path}:" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_named_pipe_for_a_state_file_is_refused_not_waited_on(tmp_path):
    """open() of a FIFO blocked the start (no port printed) until something wrote to it."""
    import os

    os.mkfifo(tmp_path / "servo-001.json")
    result = run("serve", "--state-dir", str(tmp_path))
    assert result.returncode == 2 and "not a regular file" in result.stderr, result.stderr


@pytest.mark.parametrize("value", ["1e20", "-1e5"])
def test_an_external_torque_past_the_heaviest_arm_is_refused(value):
    """1e20 N m put NaN into the physics: Present Temperature read 0 with no alarm."""
    result = run("serve", f"--external-torque={value}")
    assert result.returncode == 2 and "--external-torque: must lie in" in result.stderr, result.stderr


@pytest.mark.parametrize("served", [["--ids", "1"], ["--servo", "1:ax-12a,3:xl430-w250", "--baud", "1000000"]])
def test_a_factory_reset_run_killed_at_once_leaves_the_factory_image(tmp_path, emulator, served):
    """``--factory-reset`` wrote the factory image only when the server exited: one killed before any write left the
    old state, and the next normal run served the ID 9 and Return Delay 10 the reset run never served."""
    import json
    import signal

    from ax12emu.bus.state_store import StateStore
    from ax12emu.bus.wire import build_wire_of, servo_models

    store = StateStore(tmp_path)
    bus = build_wire_of(servo_models("1:ax-12a", None, mixed=True), clock=WallClock(), state_store1=store)
    bus.servo(1).table.set("return_delay_time", 10)
    bus.servo(1).table.set("id", 9)
    bus.close()
    assert emulator("--state-dir", str(tmp_path), "--factory-reset", *served).stop(signal.SIGKILL) == -signal.SIGKILL
    saved = json.loads(store.path_for(1).read_text())["eeprom"]
    assert (saved["id"], saved["return_delay_time"]) == (1, 250)


@pytest.mark.parametrize("served", [["--ids", "1"], ["--servo", "1:ax-12a,3:xl430-w250", "--baud", "1000000"]])
def test_a_factory_reset_run_refused_at_start_leaves_the_state_alone(tmp_path, served):
    """Saved before the server's other checks, a reset run refused for a fault flag (or a port in use) wiped the saved
    state though it never served; it is saved once the server has started."""
    import json

    from ax12emu.bus.state_store import StateStore
    from ax12emu.bus.wire import build_wire_of, servo_models

    store = StateStore(tmp_path)
    bus = build_wire_of(servo_models("1:ax-12a", None, mixed=True), clock=WallClock(), state_store1=store)
    bus.servo(1).table.set("return_delay_time", 10)
    bus.close()
    result = run("serve", "--state-dir", str(tmp_path), "--factory-reset", "--delay-s", "0.5", *served)
    assert result.returncode == 2 and "delay_s" in result.stderr, result.stderr
    assert json.loads(store.path_for(1).read_text())["eeprom"]["return_delay_time"] == 10
    # Refused later, by a live view whose port is taken: the bus built and closed (on --servo it saved as it closed).
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        result = run("serve", "--state-dir", str(tmp_path), "--factory-reset", "--tcp", "127.0.0.1:0", "--web",
                     f"127.0.0.1:{port}", *served)
    assert result.returncode == 1 and "in use" in result.stderr, result.stderr
    assert json.loads(store.path_for(1).read_text())["eeprom"]["return_delay_time"] == 10


@pytest.mark.parametrize(("flags", "says"), [
    (["--delay-s", "0.5"], "ax12emu: delay_s: how late the delay option's replies leave (0.5 s), and delay is not given"),
    (["--duplicate", "1:1"], "ax12emu: duplicate: 1:1 gives servo 1 the ID it was launched as"),
    (["--duplicate", "2:1", "--duplicate", "2:3"], "ax12emu: duplicate: ID 2 named more than once"),
])
def test_fault_flags_that_would_do_nothing_are_refused_in_one_line(flags, says):
    """They were served without a word: a delay with nothing delayed, a servo duplicated as itself, the last of two
    duplicates of one servo."""
    result = run("serve", "--ids", "1,2", *flags)
    assert result.returncode == 2 and says in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_state_dir_that_is_a_file_and_a_taken_port_name_their_flag(tmp_path):
    """One line each, naming what is wrong: "[Errno 17] File exists" and a bare "Address already in use" (which of
    --tcp and --web?) did not."""
    afile = tmp_path / "afile"
    afile.write_text("")
    result = run("serve", "--tcp", "127.0.0.1:0", "--state-dir", str(afile))
    assert result.returncode == 2 and f"{afile}: exists and is not a folder" in result.stderr, result.stderr
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        for flags, says in ((["--tcp", f"127.0.0.1:{port}"], f"--tcp 127.0.0.1:{port}: "),
                            (["--servo", "xl430-w250", "--ids", "1", "--tcp", f"127.0.0.1:{port}"], f"--tcp 127.0.0.1:{port}: "),
                            (["--tcp", "127.0.0.1:0", "--web", f"127.0.0.1:{port}"], f"--web 127.0.0.1:{port}: ")):
            result = run("serve", *flags)
            assert result.returncode == 1 and says in result.stderr and "in use" in result.stderr, result.stderr
            assert len(result.stderr.strip().splitlines()) == 1


def test_parse_args_defaults():
    """Defaults: ID 1 on a pty, e-manual profile, real time."""
    args = parse_args(["serve"])
    assert args.ids == [1] and not args.tcp and args.profile == "ax12a" and args.time_scale == 1.0
    assert args.goal_torque == "on" and args.eeprom_busy_ms == 6.0


@pytest.mark.parametrize(
    "args, message",
    [
        (["serve", "--voltage", "20"], "supply"),
        (["serve", "--model", "kinematic", "--arm", "0.1,0.1"], "physical model"),
        (["serve", "--params", "/nonexistent/params.toml"], "params.toml"),
    ],
)
def test_model_errors_are_one_line(args, message):
    """Model configuration errors (voltage out of 7-12 V, flags the model lacks, a missing file) are one line."""
    result = run(*args)
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_arm_flag_is_validated():
    """--arm takes MASS_KG,LENGTH_M as two non-negative numbers."""
    result = run("serve", "--arm", "heavy")
    assert result.returncode == 2 and "MASS_KG,LENGTH_M" in result.stderr


def test_diagnose_alias_reaches_the_workflow(tmp_path):
    """`ax12emu diagnose` is the discrepancy workflow's CLI: its help, and its one-line error on a missing file."""
    assert "MEASURED.csv" in run("diagnose", "--help").stdout
    result = run("diagnose", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "out"))
    assert result.returncode == 2 and "missing.csv" in result.stderr and "Traceback" not in result.stderr


def test_diagnose_help_is_printed_once():
    """``ax12emu diagnose --help`` reads the command line to find the servo before the workflow prints its help."""
    result = run("diagnose", "--help")
    assert result.returncode == 0 and result.stdout.count("usage:") == 1


@pytest.mark.parametrize("flag", [["--web", "127.0.0.1:0"], ["--monitor"]])
def test_web_and_monitor_without_the_web_extra_are_one_line(flag):
    """aiohttp and rich load when the live view starts: their absence was an 18-line traceback (exit 1), past the
    one-line hint meant for it."""
    code = ("import sys; sys.modules['aiohttp'] = None; sys.modules['rich'] = None; "
            "from ax12emu.cli.main import main; sys.exit(main(sys.argv[1:]))")
    result = subprocess.run([sys.executable, "-c", code, "serve", "--tcp", "127.0.0.1:0", *flag],
                            capture_output=True, text=True, timeout=30)
    assert result.returncode == 2, result
    assert result.stderr.strip().count("\n") == 0 and "Traceback" not in result.stderr, result.stderr
    assert "pip install 'ax12emu[web]'" in result.stderr


def test_a_header_profile_that_is_not_a_text_is_one_line(tmp_path):
    """A trace's header is the file's word: a profile given as a list is refused as an unknown one is."""
    trace = tmp_path / "t.jsonl"
    trace.write_text('{"format": "ax12emu-trace/1", "profile": ["x"]}\n')
    result = run("decode", str(trace))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "profile ['x'] is none of" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_decode_into_a_reader_that_goes_away_stops_quietly(tmp_path):
    """``ax12emu decode big.jsonl | head -1``: the closed pipe ends the command without a word on stderr."""
    lines = ['{"format": "ax12emu-trace/1"}']
    lines += [f'{{"t": {k * 0.001:.3f}, "dir": "in", "data": "ff ff 01 02 01 fb"}}' for k in range(20_000)]
    trace = tmp_path / "big.jsonl"
    trace.write_text("\n".join(lines) + "\n")
    reader = subprocess.Popen(["head", "-1"], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        result = subprocess.run([sys.executable, "-m", "ax12emu", "decode", str(trace)], stdout=reader.stdin,
                                stderr=subprocess.PIPE, text=True, timeout=60)
        reader.stdin.close()
        first = reader.stdout.read().decode()
    finally:
        reader.kill()
        reader.wait()
    assert "PING id=1" in first
    assert result.stderr == "" and result.returncode == 1, result.stderr


def test_decoding_a_trace_with_no_packets_says_so(tmp_path):
    """A server stopped before any packet leaves the header alone: decode printed nothing at all."""
    trace = tmp_path / "t.jsonl"
    trace.write_text('{"format": "ax12emu-trace/1", "profile": "ax12a", "echo": false}\n')
    result = run("decode", str(trace))
    assert result.returncode == 0 and result.stdout == "" and "no bytes to decode" in result.stderr


@pytest.mark.parametrize("flag", ["--trace", "--state-dir"])
def test_an_empty_path_is_a_flag_error(capsys, flag):
    """``serve --trace ""`` served untraced, ``--state-dir ""`` kept nothing (an unset ``$DIR``), without a word."""
    with pytest.raises(SystemExit) as stop:
        parse_args(["serve", flag, ""])
    assert stop.value.code == 2
    assert f"argument {flag}: names no file" in capsys.readouterr().err


def test_decode_prints_each_line_before_the_trace_is_read_through(tmp_path, monkeypatch):
    """``ax12emu decode`` held every line of a trace before printing the first (a 20 MB trace: 11.6 s, 217 MB)."""
    from ax12emu.cli import hil
    from ax12emu.protocol.packets import encode_instruction, encode_status
    from ax12emu.tracing import trace as trace_module
    from ax12emu.tracing.decoder import decode, format_decoded

    path = tmp_path / "t.jsonl"
    with trace_module.TraceWriter(path) as trace:
        for k in range(50):
            trace.record(trace_module.IN, encode_instruction(1, 1), trace._start + k * 1e-3)
            trace.record(trace_module.OUT, encode_status(1, 0), trace._start + k * 1e-3 + 5e-4)
    out = io.StringIO()
    readings: list[list[int]] = []  # per reading of the file: the lines printed before each chunk was handed on
    read = trace_module.read_capture

    def reading(name):
        printed: list[int] = []
        readings.append(printed)
        for chunk in read(name):
            printed.append(out.getvalue().count("\n"))
            yield chunk

    monkeypatch.setattr(trace_module, "read_capture", reading)
    monkeypatch.setattr(sys, "stdout", out)
    assert hil.COMMANDS["decode"](parse_args(["decode", str(path)])) == 0
    decoding = readings[-1]
    assert len(decoding) == 100 and decoding[2] >= 2  # the PING and its answer printed before the next PING is read
    assert out.getvalue().splitlines() == [format_decoded(d) for d in decode(trace_module.read_trace(path))]


@pytest.mark.parametrize("protocol", ["auto", "1.0"])
def test_decode_prints_every_line_before_an_unreadable_one_whatever_the_protocol_choice(tmp_path, protocol):
    """A killed server's trace with a bad line: with the protocol chosen from the file, the first reading stopped at
    the bad line and nothing was printed, where ``--protocol 1.0`` printed the packets before it."""
    good = ['{"format": "ax12emu-trace/1", "profile": "ax12a", "echo": false}',
            '{"t": 0.001, "dir": "in", "data": "ff ff 01 02 01 fb"}',
            '{"t": 0.002, "dir": "out", "data": "ff ff 01 02 00 fc"}',
            '{"t": 0.003, "dir": "in", "data": "ff ff 01 02 01 fb"}']
    trace = tmp_path / "t.jsonl"
    trace.write_text("\n".join([*good, '{"t": 0.0005, "dir": "out", "data": "ff ff 01 02 00 fc"}']) + "\n")
    result = run("decode", str(trace), "--protocol", protocol)
    assert result.returncode == 2 and "t.jsonl:5: not a trace line" in result.stderr, result
    assert [line.split()[1] for line in result.stdout.splitlines()] == ["host", "servo", "host"], result.stdout
