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
    process = subprocess.Popen(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--ax12-web", "test_watch.py"],
        cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
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
