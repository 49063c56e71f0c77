"""Servos on one wire: who hears a packet, their replies and reply cache, clocks and saved state.

Above :mod:`ax12emu.servo`; no I/O of its own (the serving loop above feeds it bytes).
"""

from .bus import BAUD_TOLERANCE, Bus
from .clock import VirtualClock, WallClock
from .reply import BITS_PER_BYTE, Reply, merge_replies
from .state_store import StateFileError, StateStore

__all__ = [
    "BAUD_TOLERANCE", "BITS_PER_BYTE", "Bus", "Reply", "StateFileError", "StateStore", "VirtualClock", "WallClock",
    "merge_replies",
]
