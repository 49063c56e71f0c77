"""``ax12emu serve --web/--monitor`` and ``pytest --ax12-web`` as users run them."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import textwrap
import time
import urllib.request

import pytest

pytest.importorskip("aiohttp")

from dynamixel_sdk import COMM_SUCCESS  # noqa: E402
from emu_testkit import sdk_port  # noqa: E402

from ax12emu.cli.main import parse_args  # noqa: E402


def read_line(stream) -> str:
    """The next line (the emulator prints its lines at once; pytest-timeout ends a hang)."""
    line = stream.readline()
    assert line, "the stream ended"
    return line.strip()


def test_serve_web_and_monitor_keep_the_port_on_the_first_stdout_line(emulator):
    served = emulator("--ids", "1,2", "--tcp", "127.0.0.1:0", "--web", "127.0.0.1:0", "--monitor")
    assert served.port.startswith("socket://127.0.0.1:")  # the first line, as without the live view
    url = read_line(served.process.stdout)
    assert url.startswith("http://127.0.0.1:") and url.endswith("/")
    with urllib.request.urlopen(url + "api/servos", timeout=5) as answer:
        assert [s["id"] for s in json.loads(answer.read())["servos"]] == [1, 2]
    with sdk_port(served.port) as (port, ph):
        assert ph.ping(port, 2)[1] == COMM_SUCCESS
    assert served.stop() == 0  # stderr is a pipe: the monitor prints its last picture on the way out
    rest_of_stdout = served.process.stdout.read()
    assert rest_of_stdout == ""  # the monitor draws on stderr only
    err = served.process.stderr.read()
    assert "packets/s" in err and "AX-12" in err and "position" in err


def test_monitor_alone_on_a_pty(emulator):
    served = emulator("--ids", "3", "--monitor")
    assert served.port.startswith("/dev/pts/")
    err = b""
    deadline = time.monotonic() + 10
    while b"AX-12" not in err and time.monotonic() < deadline:  # stderr is a pipe: the first picture is printed at once
        if select.select([served.process.stderr], [], [], 0.1)[0]:
            err += os.read(served.process.stderr.fileno(), 65536)
    assert served.stop() == 0
    assert b"AX-12A (P1.0)" in err and b"packets/s" in err


def test_serve_servo_takes_web_and_monitor(emulator):
    """An X-series bus with an AX-12A beside it: the page lists both, each by its protocol; the monitor draws them."""
    served = emulator("--servo", "1:ax-12a,1-2:xl430-w250", "--tcp", "127.0.0.1:0", "--web", "127.0.0.1:0", "--monitor")
    assert served.port.startswith("socket://127.0.0.1:")  # the port stays the first stdout line
    url = read_line(served.process.stdout)
    with urllib.request.urlopen(url + "api/servos", timeout=5) as answer:
        body = json.loads(answer.read())
    assert body["protocols"] == ["1.0", "2.0"]
    assert [(s["protocol"], s["id"], s["model"]) for s in body["servos"]] == [("1.0", 1, "AX-12A"), ("2.0", 1, "XL430-W250"), ("2.0", 2, "XL430-W250")]
    assert served.stop() == 0
    err = served.process.stderr.read()
    assert "XL430-W250 (P2.0)" in err and "AX-12A (P1.0)" in err


def test_servo_no_longer_refuses_the_live_view():
    args = parse_args(["serve", "--servo", "xl430-w250", "--web", "127.0.0.1:0", "--monitor"])
    assert args.web_address == ("127.0.0.1", 0) and args.monitor and args.servo_models == [(1, "xl430-w250")]


@pytest.mark.parametrize(
    "argv, says",
    [
        (["--web", "0.0.0.0:0"], "--web 0.0.0.0: binding beyond loopback needs --allow-remote"),
        (["--web", "192.0.2.1:8080"], "needs --allow-remote"),
        (["--web", "localhost:notaport"], "port must be a number"),
        (["--web", "nocolon"], "expected HOST:PORT"),
    ],
)
def test_bad_web_addresses_are_clear_usage_errors(argv, says, capsys):
    with pytest.raises(SystemExit) as exit_:
        parse_args(["serve", *argv])
    assert exit_.value.code == 2 and says in capsys.readouterr().err


def test_web_beyond_loopback_is_allowed_when_asked():
    args = parse_args(["serve", "--web", "0.0.0.0:0", "--allow-remote"])
    assert args.web_address == ("0.0.0.0", 0)


def test_pytest_ax12_web_keeps_the_page_up_until_ctrl_c(tmp_path):
    (tmp_path / "test_watch.py").write_text(
        textwrap.dedent(
            """
            import pytest

            @pytest.mark.ax12_ids(4, 5)
            def test_arm(ax12_bus):
                ax12_bus.write(4, "goal_position", 600)
            """
        )
    )
    # Ctrl-C ends the wait: a run started from a script's background job has SIGINT ignored, and a child
    # started so would ignore it too (no KeyboardInterrupt); with a handler here it starts with the default.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--ax12-web", "test_watch.py"],
            cwd=tmp_path,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        )
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        lines = []
        while not any("press Ctrl-C" in line for line in lines):
            lines.append(read_line(process.stdout))
        url = lines[-1].split(" still at ")[1].split()[0]
        deadline = time.monotonic() + 2.0
        goal = None
        while goal != 600 and time.monotonic() < deadline:  # the page is at most a frame (40 ms) behind the bus
            with urllib.request.urlopen(url + "api/servos", timeout=5) as answer:
                goal = {s["id"]: s for s in json.loads(answer.read())["servos"]}[4]["registers"]["goal_position"]
        assert goal == 600  # the test's last state, still there after it ended
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=20)
        assert process.returncode == 0, out
        assert "1 passed" in out
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
