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


def test_the_streamed_cycle_sends_new_goals_every_cycle_and_reads_every_servo():
    """The for-information loop of ``--protocol 2.0``: each cycle's Sync Write carries goals the last did not,
    and its Sync Read gets every servo's answer (run against the emulator in process, ``ax12emu://``)."""
    from dynamixel_sdk import PacketHandler
    from emu_testkit import UrlPortHandler

    port = UrlPortHandler("ax12emu://?servo=1-6:xl430-w250&baud=1000000")
    port.baudrate = 1_000_000
    assert port.openPort()
    try:
        ph = PacketHandler(2.0)
        sent = []
        write_port = port.writePort
        port.writePort = lambda packet: sent.append(bytes(packet)) or write_port(packet)
        cycle = tool.streamed_sync_cycle(port, ph)
        assert [cycle() for _ in range(3)] == [COMM_SUCCESS] * 3
        writes = [packet for packet in sent if packet[7] == 0x83]  # SYNC_WRITE
        assert len(writes) == 3 and len(set(writes)) == 3
    finally:
        port.closePort()
