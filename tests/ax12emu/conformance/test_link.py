"""The suite's host link: silence is listened to for its own window, and a reply after that window still fails.

The device here is this test, on the other end of a real pty: it answers a packet only after the link has
judged the packet silent, which is what a late reply is.
"""

from __future__ import annotations

import os
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
