"""Exposure: loopback by default, explicit opt-in beyond it, no file access outside the state directory, one-line errors."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
import serial

from ax12emu.bus.state_store import StateFileError, StateStore
from ax12emu.protocol.control_table import ControlTable
from ax12emu.protocol.packets import encode_instruction, encode_status

#: Real processes and ports, but nothing here is timed (a reply gets a second, a refusal is an exit code): not the
#: wall-clock tier, so CI runs these in parallel with the other tests.


def run(*args: str, cwd=None, timeout_s: float = 30) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ax12emu", *args], capture_output=True, text=True,
                          timeout=timeout_s, cwd=cwd)


def listening_addresses(port: int) -> set[str]:
    """Local IPv4 addresses with a socket listening on ``port``, from /proc/net/tcp."""
    found = set()
    with open("/proc/net/tcp", encoding="ascii") as table:
        next(table)
        for line in table:
            local, state = line.split()[1], line.split()[3]
            address, port_hex = local.split(":")
            if state == "0A" and int(port_hex, 16) == port:
                found.add(socket.inet_ntoa(bytes.fromhex(address)[::-1]))
    return found


# -- binding ------------------------------------------------------------------------------
@pytest.mark.parametrize("where", [":0", "127.0.0.1:0", "localhost:0"])
def test_tcp_listens_on_loopback_only(emulator, where):
    """--tcp without a host, with 127.0.0.1 or with localhost: the kernel shows the listener on 127.0.0.1 only."""
    served = emulator("--tcp", where)
    port = int(served.port.rsplit(":", 1)[1])
    assert served.port == f"socket://127.0.0.1:{port}"
    assert listening_addresses(port) == {"127.0.0.1"}


def test_binding_beyond_loopback_needs_the_flag():
    """--tcp 0.0.0.0 (or any non-loopback host) without --allow-remote: exit 2 naming the flag, nothing listens."""
    for where in ("0.0.0.0:0", "192.0.2.1:0", "example.com:0"):
        result = run("serve", "--tcp", where)
        assert result.returncode == 2 and "Traceback" not in result.stderr
        assert "binding beyond loopback needs --allow-remote" in result.stderr.strip().splitlines()[-1], result.stderr
        assert result.stdout == ""


def test_allow_remote_binds_everywhere_with_a_warning(emulator):
    """--tcp 0.0.0.0:0 --allow-remote serves, listens on 0.0.0.0, and warns that it is reachable from other machines."""
    served = emulator("--tcp", "0.0.0.0:0", "--allow-remote")
    port = int(served.port.rsplit(":", 1)[1])
    assert listening_addresses(port) == {"0.0.0.0"}
    with serial.serial_for_url(f"socket://127.0.0.1:{port}", timeout=1.0) as link:
        link.write(encode_instruction(1, 0x01))
        assert link.read(6) == encode_status(1, 0)
    served.stop()
    warnings = [line for line in served.process.stderr.read().splitlines() if "WARNING" in line]
    assert len(warnings) == 1 and "reachable from other machines" in warnings[0]


# -- files --------------------------------------------------------------------------------
def test_state_file_names_stay_inside_the_directory(tmp_path):
    """Every slot maps to servo-NNN.json directly inside the directory; anything else is refused."""
    store = StateStore(tmp_path / "state")
    for slot in range(0, 254):
        path = store.path_for(slot)
        assert path.parent == store.directory and path.name == f"servo-{slot:03d}.json"
    for bad in (-1, 254, 10**6):
        with pytest.raises(ValueError):
            store.path_for(bad)
    with pytest.raises((ValueError, TypeError)):
        store.path_for("../../etc/passwd")


def test_symlinked_state_file_is_not_followed(tmp_path):
    """A state file that is a symlink to a file elsewhere is refused on load, and a save replaces the link, not its target."""
    outside = tmp_path / "outside.json"
    original = json.dumps({"eeprom": {"id": 9}})
    outside.write_text(original)
    state = tmp_path / "state"
    store = StateStore(state)
    (state / "servo-001.json").symlink_to(outside)
    table = ControlTable(np.zeros(50, dtype=np.uint8))
    with pytest.raises(StateFileError, match="servo-001.json"):
        store.load(1, table)
    store.save(1, table)
    assert outside.read_text() == original
    assert not (state / "servo-001.json").is_symlink()


def test_no_client_input_writes_outside_the_state_directory(emulator, tmp_path):
    """Client writes of every ID, baud and a RESET: only servo-001.json / servo-002.json appear, inside the directory."""
    state = tmp_path / "state"
    served = emulator("--state-dir", str(state), "--ids", "1,2", "--model", "kinematic")
    with serial.Serial(served.port, 1_000_000, timeout=0.3) as link:
        for new_id in (0, 253, 254, 47, 2):  # 254 is rejected (RANGE); 2 collides with the other servo
            link.write(encode_instruction(0xFE, 0x03, bytes([3, new_id])))
            time.sleep(0.01)
            link.write(encode_instruction(0xFE, 0x06))  # RESET: back to ID 1, EEPROM rewritten
            time.sleep(0.01)
        link.write(encode_instruction(0xFE, 0x83, bytes([3, 1, 1, 9, 2, 10])))  # SYNC_WRITE IDs
        time.sleep(0.05)
    assert served.stop() == 0
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == [
        "state", "state/lock", "state/servo-001.json", "state/servo-002.json"]  # lock: the serving process's claim


# -- one-line errors ----------------------------------------------------------------------
def _one_line_failure(result: subprocess.CompletedProcess, *needles: str) -> None:
    lines = result.stderr.strip().splitlines()
    assert result.returncode != 0, result
    assert "Traceback" not in result.stderr
    assert len(lines) == 1, result.stderr
    assert result.stdout == "", "no port may be printed before failing"
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.mark.parametrize(
    "content, needles",
    [
        ("bogus_key = 1\n", ("params.toml", "unknown key 'bogus_key'")),
        ("gear_ratio = \n", ("params.toml", "not valid TOML")),
        ("gear_ratio = 'high'\n", ("params.toml", "gear_ratio", "must be a number")),
        ("[section]\ngear_ratio = 1\n", ("params.toml", "unknown key 'section'")),
        ("gear_ratio = -5\n", ("params.toml",)),
    ],
)
def test_params_file_errors_are_one_line(tmp_path, content, needles):
    """serve --params FILE with an unknown key, bad TOML, a string or a bad value: one line naming the file, exit != 0."""
    params = tmp_path / "params.toml"
    params.write_text(content)
    _one_line_failure(run("serve", "--params", str(params)), *needles)


@pytest.mark.parametrize("make", ["directory", "binary"])
def test_unreadable_params_file_is_one_line(tmp_path, make):
    """A directory or a non-UTF-8 file given as --params: one line, exit != 0."""
    params = tmp_path / "params.toml"
    if make == "directory":
        params.mkdir()
    else:
        params.write_bytes(b"\xff\xfe\x00garbage")
    _one_line_failure(run("serve", "--params", str(params)))


def test_runtime_errors_are_one_line(tmp_path):
    """A state dir that is a file, a trace or link in a missing directory, a busy port: one line each, exit != 0."""
    afile = tmp_path / "afile"
    afile.write_text("")
    _one_line_failure(run("serve", "--state-dir", str(afile)), "afile")
    _one_line_failure(run("serve", "--trace", str(tmp_path / "missing" / "x.trace")), "missing")
    _one_line_failure(run("serve", "--link", str(tmp_path / "missing" / "link")), "missing")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        _one_line_failure(run("serve", "--tcp", f"127.0.0.1:{busy.getsockname()[1]}"), "in use")
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "servo-001.json").mkdir()
    _one_line_failure(run("serve", "--state-dir", str(tmp_path / "state")), "servo-001.json", "--factory-reset")


def test_argparse_errors_end_in_one_error_line():
    """Bad flags: exit 2, no traceback, and one line: the error and where the usage is (not argparse's usage block)."""
    for args in (["serve", "--ids", "300"], ["serve", "--voltage", "nan"], ["serve", "--tcp", "127.0.0.1:99999"]):
        result = run(*args)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and "Traceback" not in result.stderr
        assert len(lines) == 1 and "error:" in lines[0] and "--help" in lines[0], result.stderr


@pytest.mark.parametrize("value", ["nan", "inf"])
def test_non_finite_external_torque_is_a_usage_error(value):
    """--external-torque nan or inf is refused before serving, as a usage error."""
    result = run("serve", "--external-torque", value, timeout_s=10)
    assert result.returncode == 2 and result.stdout == "" and "finite" in result.stderr


def test_ipv6_loopback_url_is_usable(emulator):
    """--tcp [::1]:0 prints a socket:// URL that pyserial can open."""
    if not socket.has_ipv6:
        pytest.skip("no IPv6")
    try:
        served = emulator("--tcp", "[::1]:0")
    except RuntimeError as exc:
        pytest.skip(f"IPv6 loopback unavailable: {exc}")
    with serial.serial_for_url(served.port, timeout=1.0) as link:
        link.write(encode_instruction(1, 0x01))
        assert link.read(6) == encode_status(1, 0)
