"""tools/bench_protocol.py: the parts that decide what a run counts, without timing anything."""

from dynamixel_sdk import COMM_RX_CORRUPT, COMM_SUCCESS
from emu_testkit import load_tool

tool = load_tool("bench_protocol")


class _Handler:
    """A PacketHandler stand-in replaying result codes, or raising as dynamixel-sdk does on a short reply."""

    def __init__(self, outcomes):
        self.outcomes = list(outcomes)
        self.calls = []

    def read2ByteTxRx(self, port, servo_id, address):
        self.calls.append((servo_id, address))
        outcome = self.outcomes.pop(0)
        if outcome is IndexError:
            raise IndexError("list index out of range")
        return 512, outcome, 0


def test_a_short_reply_counts_as_a_failed_read_and_the_run_goes_on():
    handler = _Handler([COMM_SUCCESS, IndexError, COMM_SUCCESS])
    once = tool.read_present_position(object(), handler)
    assert [once(), once(), once()] == [COMM_SUCCESS, COMM_RX_CORRUPT, COMM_SUCCESS]
    assert handler.calls == [(1, 36)] * 3
