"""The suite's host link: silence is listened to for its own window, and a reply after that window still fails.

The device here is this test, on the other end of a real pty: it answers a packet only after the link has
judged the packet silent, which is what a late reply is.
"""

from __future__ import annotations

import os
import re
import select
import time

import pytest

from ax12emu.conformance import FAIL, PASS, Check
from ax12emu.conformance import _run_one as run_one
from ax12emu.conformance.checks import Context, expect
from ax12emu.conformance.link import Link, open_port
from ax12emu.protocol.packets import Instruction, encode_instruction, encode_status

SILENCE_S, TIMEOUT_S = 0.02, 2.0


@pytest.fixture
def wire():
    """(device end of a pty, a Link on the host end with a short silence window)."""
    device, host = os.openpty()
    link = Link(open_port(os.ttyname(host), 1_000_000), timeout_s=TIMEOUT_S, silence_s=SILENCE_S)
    try:
        yield device, link
    finally:
        link.close()
        os.close(host)
        os.close(device)


def test_silence_is_listened_to_for_its_window_not_the_reply_timeout(wire):
    """A packet that must get no reply costs the silence window (default: the reply timeout)."""
    device, link = wire
    ctx = Context(link, [1])
    start = time.perf_counter()
    assert ctx.silent(encode_instruction(7, Instruction.PING))
    assert SILENCE_S <= time.perf_counter() - start < TIMEOUT_S
    assert os.read(device, 64) == encode_instruction(7, Instruction.PING)
    assert Link(link.port, timeout_s=TIMEOUT_S).silence_s == TIMEOUT_S


def test_a_check_fails_when_a_reply_comes_after_the_silence_window(wire):
    """The device answers a Ping to an absent ID only once the window has passed: the check that heard
    silence passes by itself, and fails once its next packet finds the late reply waiting."""
    device, link = wire
    ctx = Context(link, [1])

    def answered_late(ctx: Context) -> str:
        expect(ctx.silent(encode_instruction(7, Instruction.PING)), "ID 7 answered")
        os.write(device, encode_status(7, 0))  # the device's reply, later than the window
        # a pty hands bytes over through a kernel worker, which a loaded machine may delay: the reply has
        # come before the next packet once the host end can read it
        assert select.select([ctx.link.port.fileno()], [], [], 10.0)[0], "the late reply never reached the host"
        ctx.link.send(encode_instruction(1, Instruction.ACTION))
        return "silent"

    result = run_one(Check("absent ID is silent", answered_late), ctx)
    assert result.outcome == FAIL and "after the 20 ms silence window" in result.figure, result
    assert "ff ff 07 02 00 f6" in result.figure  # the late status packet, as received

    def quiet(ctx: Context) -> str:
        expect(ctx.silent(encode_instruction(7, Instruction.PING)), "ID 7 answered")
        time.sleep(0.05)
        ctx.link.send(encode_instruction(1, Instruction.ACTION))
        return "silent"

    assert run_one(Check("absent ID is silent", quiet), ctx).outcome == PASS


@pytest.mark.parametrize("url", ["socket://127.0.0.1", "socket://localhost:abc", "socket://localhost:70000",
                                 "socket://localhost:0", "socket://[::1]", "socket://localhost:7777?nodelay=1",
                                 "socket://localhost:7777?logging=verbose"])
def test_a_socket_url_pyserial_cannot_read_names_the_host_port_form(url):
    """pyserial's parser said "'<=' not supported between instances of 'int' and 'NoneType'" (no port), or only
    "'debug|info|warning|error'" (a port that is no number, an unknown option), or a bare KeyError (a level)."""
    form = "socket://HOST:PORT[?logging=debug|info|warning|error] (PORT 1..65535)"
    with pytest.raises(ValueError, match=f"^{re.escape(f'expected {form}, got {url!r}')}$"):
        open_port(url, 1_000_000)


def test_a_socket_url_with_its_port_and_option_opens():
    """The check lets through what pyserial opens: a port, and its one option."""
    import socket

    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        link = open_port(f"socket://127.0.0.1:{server.getsockname()[1]}?logging=warning", 1_000_000)
        link.close()
