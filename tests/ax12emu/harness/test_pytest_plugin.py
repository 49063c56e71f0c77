"""The pytest plugin: the ax12_bus fixture, its markers, and teardown when a test fails."""

from __future__ import annotations

import threading

import pytest
import serial

from ax12emu.protocol.packets import encode_instruction, encode_status

pytest_plugins = ["pytester"]


@pytest.mark.ax12_ids(4, 5)
def test_marker_chooses_ids(ax12_bus):
    """@pytest.mark.ax12_ids(4, 5) gives a running bus with exactly those IDs."""
    assert ax12_bus.running and ax12_bus.bus.ids == [4, 5]
    with serial.Serial(ax12_bus.port, 1_000_000, timeout=0.5) as link:
        link.write(encode_instruction(5, 0x01))
        assert link.read(6) == encode_status(5, 0)


@pytest.mark.parametrize("ax12_bus", [[7], [8, 9]], indirect=True)
def test_indirect_parametrization(ax12_bus):
    """Indirect parametrization of ax12_bus sets the IDs."""
    assert ax12_bus.bus.ids in ([7], [8, 9])


@pytest.mark.ax12_bus_options(transport="inprocess", virtual_time=True)
def test_options_marker(ax12_bus):
    """ax12_bus_options passes keyword arguments to VirtualBus."""
    assert ax12_bus.port.startswith("ax12emu://") and ax12_bus.virtual_time


@pytest.mark.parametrize(("marker", "says"), [
    ('ax12_servo(servo="xl430-w250")', "ax12_servo takes positional arguments"),  # served an AX-12A
    ("ax12_servo()", "ax12_servo takes one servo text"),
    ('ax12_bus_options({"virtual_time": True})', "ax12_bus_options takes keywords"),  # dropped
    ('ax12_ids("1,2")', "ax12_ids takes integer IDs, got '1,2'"),  # an error deep inside
])
def test_a_marker_written_the_other_way_round_is_a_usage_error_naming_how(pytester, marker, says):
    pytester.makepyfile(
        f"""
        import pytest

        @pytest.mark.{marker}
        def test_it(ax12_bus):
            pass
        """
    )
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines([f"*{says}*"])


@pytest.mark.ax12_ids(range(1, 4))
def test_a_range_of_ids(ax12_bus):
    assert ax12_bus.bus.ids == [1, 2, 3]


def test_failing_test_still_tears_down(pytester):
    """A test that fails inside the fixture leaves no serving thread behind, and the marker is registered."""
    pytester.makepyfile(
        """
        import pytest

        @pytest.mark.ax12_ids(1, 2)
        def test_fails(ax12_bus):
            assert ax12_bus.running
            assert False, "boom"
        """
    )
    result = pytester.runpytest_inprocess("--strict-markers", "-p", "no:cacheprovider")
    result.assert_outcomes(failed=1)
    assert not [t for t in threading.enumerate() if t.name.startswith("ax12emu-")]


def test_ax12_web_shows_a_bus_of_ax12_servo_models(tmp_path):
    """``pytest --ax12-web`` with an ``ax12_servo`` marker: the page shows the MX and the X series servo the marker
    names, with the test's last write, until Ctrl-C (the process is ended by its own handle)."""
    import json
    import os
    import signal
    import subprocess
    import sys
    import textwrap
    import time
    import urllib.request

    pytest.importorskip("aiohttp")
    (tmp_path / "test_watch.py").write_text(textwrap.dedent(
        """
        import pytest

        @pytest.mark.ax12_servo("1:mx-28,1:xl430-w250")
        def test_arm(ax12_bus):
            ax12_bus.write(1, "goal_position", 600, protocol=1.0)
        """
    ))
    # Ctrl-C ends the wait: a run started from a script's background job has SIGINT ignored, and a child
    # started so would ignore it too (no KeyboardInterrupt); with a handler here it starts with the default.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--ax12-web", "test_watch.py"],
            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
        )
    finally:
        signal.signal(signal.SIGINT, previous)
    try:
        lines: list[str] = []
        while not any("press Ctrl-C" in line for line in lines):
            line = process.stdout.readline()
            assert line, "pytest ended before the page was up: " + "".join(lines)
            lines.append(line)
        url = lines[-1].split(" still at ")[1].split()[0]
        deadline = time.monotonic() + 2.0
        shown: dict = {}
        while time.monotonic() < deadline:  # the page is at most a frame (40 ms) behind the bus
            with urllib.request.urlopen(url + "api/servos", timeout=5) as answer:
                shown = {(s["protocol"], s["id"]): s for s in json.loads(answer.read())["servos"]}
            if shown.get(("1.0", 1), {}).get("registers", {}).get("goal_position") == 600:
                break
        assert shown[("1.0", 1)]["model"] == "MX-28" and shown[("2.0", 1)]["model"] == "XL430-W250"
        assert shown[("1.0", 1)]["registers"]["goal_position"] == 600
        process.send_signal(signal.SIGINT)
        out, _ = process.communicate(timeout=20)
        assert process.returncode == 0, out
        assert "1 passed" in out
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()


#: Marks that gave a wrong bus or a deep error, and the UsageError each gives now, in the plugin's terms.
MISUSED = {
    "float_param": (['parametrize("ax12_bus", [1.9], indirect=True)'],  # served ID 1
                    "an indirect ax12_bus parameter takes integer IDs, got 1.9"),
    "text_param": (['parametrize("ax12_bus", ["1,2"], indirect=True)'],  # int()'s ValueError
                   "an indirect ax12_bus parameter takes integer IDs, got '1,2'"),
    "ids_twice": (["ax12_ids(1, 2)", "ax12_bus_options(ids=[3])"],  # a TypeError "got multiple values for argument 'ids'"
                  "ax12_bus_options(ids=...) and ax12_ids both give the IDs; give them once"),
    "servo_twice": (['ax12_servo("1-2:xl430-w250")', 'ax12_bus_options(servo="mx-28")'],  # the options' servo won
                    "ax12_servo and ax12_bus_options(servo=...) both give the servos; give them once"),
    "ids_beside_per_id_servo": (['ax12_servo("1-2:xl430-w250")', "ax12_ids(3)"],  # "--ids and a per-ID --servo list"
                                "ax12_ids and the per-ID servo text '1-2:xl430-w250' of ax12_servo both name the IDs; "
                                "give one of them"),
    "text_id_in_options": (['ax12_bus_options(ids=["1"])'], "ax12_bus_options(ids=...) takes integer IDs, got '1'"),
}


def test_ids_and_servos_given_wrongly_or_twice_are_usage_errors_in_the_plugins_terms(pytester):
    source = "import pytest\n"
    for name, (marks, _) in MISUSED.items():
        decorators = "".join(f"@pytest.mark.{mark}\n" for mark in marks)
        source += f"\n\n{decorators}def test_{name}(ax12_bus):\n    pass\n"
    pytester.makepyfile(source)
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-rE")
    result.assert_outcomes(errors=len(MISUSED))
    out = result.stdout.str()
    for name, (_, says) in MISUSED.items():
        assert f"ERROR test_ids_and_servos_given_wrongly_or_twice_are_usage_errors_in_the_plugins_terms.py::test_{name}" in out
        assert f"UsageError: {says}" in out, (name, out)
    assert "--ids" not in out


@pytest.mark.parametrize("ax12_bus", [range(2, 4), 5], indirect=True)
def test_an_indirect_parameter_takes_a_range_or_one_id(ax12_bus):
    assert ax12_bus.bus.ids in ([2, 3], [5])


@pytest.mark.ax12_bus_options(ids=[4, 6], transport="inprocess")
def test_ids_among_the_options_are_the_ids(ax12_bus):
    assert ax12_bus.bus.ids == [4, 6]


@pytest.mark.ax12_bus_options(servo="xl430-w250", transport="inprocess")
def test_a_servo_among_the_options_is_the_servo(ax12_bus):
    assert ax12_bus.read(1, "model_number") == 1060


def test_without_a_pty_the_example_suite_opens_its_port(tmp_path):
    """Where there is no pty (Windows) the fixture serves in process and its port is an ax12emu:// URL, which
    dynamixel-sdk's PortHandler (serial.Serial) cannot open: the example's robot code opens it through its
    UrlPortHandler.  Simulated here as the plugin detects it: no pty or termios module."""
    import shutil
    import subprocess
    import sys
    from pathlib import Path

    examples = Path(__file__).resolve().parents[3] / "tools" / "examples"
    for name in ("robot_arm.py", "test_robot_arm.py", "pytest.ini"):
        shutil.copy(examples / name, tmp_path / name)
    (tmp_path / "conftest.py").write_text(
        "import importlib.util\n\n"
        "_find_spec = importlib.util.find_spec\n"
        'importlib.util.find_spec = lambda name, *a, **k: None if name in ("pty", "termios") else _find_spec(name, *a, **k)\n\n\n'
        "def pytest_collection_modifyitems(items):\n"
        "    from ax12emu.harness.pytest_plugin import _default_transport\n\n"
        '    assert _default_transport() == "inprocess"\n'
    )
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert "5 passed" in result.stdout


def test_stacked_options_markers_add_up(pytester):
    """``ax12_bus_options`` on the module, the class and the test: each keyword reaches the bus (only the closest
    marker's did, the others' dropped without a word); one given twice alike is fine."""
    pytester.makepyfile(
        """
        import pytest
        from ax12emu import FaultConfig

        pytestmark = pytest.mark.ax12_bus_options(virtual_time=True)

        @pytest.mark.ax12_bus_options(transport="inprocess")
        def test_module_and_function(ax12_bus):
            assert (ax12_bus.virtual_time, ax12_bus.transport_name) == (True, "inprocess")

        class TestArm:
            pytestmark = pytest.mark.ax12_bus_options(transport="inprocess", virtual_time=True)

            @pytest.mark.ax12_bus_options(faults=FaultConfig(drop=0.5, seed=3))
            def test_class_and_method(self, ax12_bus):
                assert (ax12_bus.virtual_time, ax12_bus.transport_name) == (True, "inprocess")
                assert ax12_bus.faults.seed == 3

        @pytest.mark.ax12_bus_options(transport="inprocess")
        @pytest.mark.ax12_bus_options(ids=[2, 3])
        def test_two_on_one_function(ax12_bus):
            assert ax12_bus.transport_name == "inprocess" and ax12_bus.bus.ids == [2, 3]
        """
    )
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider")
    result.assert_outcomes(passed=3)


def test_where_two_options_markers_give_one_keyword_the_closest_wins(pytester):
    """A test's keyword over its module's, and a subclass's own over the one it inherits: a suite re-runs its base
    class's tests on another transport (refused as a keyword given twice, the subclass could not)."""
    pytester.makepyfile(
        """
        import pytest

        pytestmark = pytest.mark.ax12_bus_options(virtual_time=True, transport="pty")

        @pytest.mark.ax12_bus_options(virtual_time=False)
        def test_own(ax12_bus):
            assert not ax12_bus.virtual_time and not ax12_bus.port.startswith("ax12emu://")

        @pytest.mark.ax12_bus_options(transport="pty")
        class TestOnPty:
            def test_it(self, ax12_bus):
                assert ax12_bus.virtual_time
                assert ax12_bus.port.startswith("ax12emu://") == (type(self).__name__ == "TestInProcess")

        @pytest.mark.ax12_bus_options(transport="inprocess")
        class TestInProcess(TestOnPty):
            pass
        """
    )
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-rE")
    result.assert_outcomes(passed=3)


SUITE_AT_1_MBPS = """
    import pytest
    from dynamixel_sdk import COMM_SUCCESS, PacketHandler, PortHandler

    pytestmark = pytest.mark.ax12_bus_options(baud_bps=1_000_000)  # the suite's own rate, whatever the servos

    @pytest.mark.ax12_bus_options(transport="inprocess")
    def test_reads_a_position(ax12_bus):
        import serial

        class UrlPortHandler(PortHandler):
            def setupPort(self, cflag_baud):
                if self.is_open:
                    self.ser.baudrate = self.baudrate
                else:
                    self.ser = serial.serial_for_url(self.port_name, baudrate=self.baudrate, timeout=0)
                    self.is_open = True
                self.tx_time_per_byte = (1000.0 / self.baudrate) * 10.0
                return True

        port = UrlPortHandler(ax12_bus.port)
        assert port.openPort() and port.setBaudRate(1_000_000)
        try:
            _, comm, error = PacketHandler(1.0).read2ByteTxRx(port, 1, 36)
        finally:
            port.closePort()
        assert (comm, error) == (COMM_SUCCESS, 0)
"""


@pytest.mark.parametrize("servo", [[], ["--ax12-servo", "mx-28"]], ids=["ax-12a", "mx-28"])
def test_a_suite_pins_its_rate_for_every_model(pytester, servo):
    """An AX-12 suite at 1 Mbps under ``--ax12-servo mx-28``: the MX starts at its factory 57,600 bps, and the
    marker that pins the rate was refused on the AX-12A bus, so the suite could run against one model only."""
    pytester.makepyfile(SUITE_AT_1_MBPS)
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", *servo)
    result.assert_outcomes(passed=1)


def test_ax12_web_under_xdist_is_a_usage_error_saying_why(pytester):
    """``pytest -n 2 --ax12-web``: the workers' URLs never reached the terminal and the run hung in their linger
    (--collect-only here: it starts no workers, so the check cannot hang the run it guards)."""
    pytest.importorskip("xdist")
    pytester.makepyfile("def test_it(ax12_bus):\n    pass\n")
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-n", "2", "--ax12-web", "--collect-only")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines(["*--ax12-web cannot run under pytest-xdist*run without -n (or -n 0)*"])


def test_an_xdist_worker_is_told_by_its_workerinput():
    """Not by PYTEST_XDIST_WORKER, which a pytest started from a worker's test inherits."""
    from types import SimpleNamespace

    from ax12emu.harness.pytest_plugin import _distributed

    assert _distributed(SimpleNamespace(workerinput={}, option=SimpleNamespace()))
    assert _distributed(SimpleNamespace(option=SimpleNamespace(dist="load", tx=["popen"] * 2)))
    assert not _distributed(SimpleNamespace(option=SimpleNamespace(dist="no", tx=[])))
    assert not _distributed(SimpleNamespace(option=SimpleNamespace()))  # pytest without xdist


def test_ax12_web_at_an_address_in_use_names_the_option_and_the_address(pytester):
    """It was a bare ``OSError: Address already in use``."""
    import errno
    import os
    import socket

    pytest.importorskip("aiohttp")
    pytester.makepyfile("def test_it(ax12_bus):\n    pass\n")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        address = f"127.0.0.1:{taken.getsockname()[1]}"
        result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "-rE", "--ax12-web", f"--ax12-web-at={address}")
    result.assert_outcomes(errors=1)
    # the address once: the bus's own error names it again, so only its errno's words are quoted
    in_use = os.strerror(errno.EADDRINUSE)
    result.stdout.fnmatch_lines([f"*UsageError: --ax12-web-at {address}: the live view cannot serve there ({in_use}); *"])


@pytest.mark.parametrize("text, says", [
    ("xl430", "unknown servo model 'xl430'; choose one of: *xl430-w250*"),
    ("1:xl430-w250,1:xm430-w350", "ID 1 is given two models"),
    ("", "empty servo list*"),
])
def test_an_ax12_servo_text_that_names_no_servos_is_one_usage_error_at_start(pytester, text, says):
    """``--ax12-servo xl430`` errored every test without an ax12_servo marker with a traceback, while the marked
    ones passed; the run is refused before it starts, naming the option, the text and the known models."""
    pytester.makepyfile(
        """
        import pytest

        @pytest.mark.ax12_servo("xl430-w250")
        def test_marked(ax12_bus):
            pass

        def test_unmarked(ax12_bus):
            pass
        """
    )
    result = pytester.runpytest_inprocess("-p", "no:cacheprovider", "--ax12-servo", text)
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    result.stderr.fnmatch_lines([f"ERROR: --ax12-servo {text!r}: {says}"])
    assert "Traceback" not in result.stdout.str() + result.stderr.str()
