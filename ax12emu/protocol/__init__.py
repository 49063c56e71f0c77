"""Protocol 1.0 as data: packets, framing, the control table, descriptions and ID lists.

The lowest layer: pure functions and tables, no I/O, no clock, no model.
Everything above may import it; it imports nothing of ax12emu's above it.
"""

from .control_table import DEFAULT_PROFILE, PROFILES, Access, Area, ControlTable, Layout, layout
from .framing import Framer
from .ids import parse_ids
from .packets import BROADCAST_ID, MAX_ID, Instruction, InstructionPacket, StatusError, StatusPacket

__all__ = [
    "Access", "Area", "BROADCAST_ID", "ControlTable", "DEFAULT_PROFILE", "Framer", "Instruction",
    "InstructionPacket", "Layout", "MAX_ID", "PROFILES", "StatusError", "StatusPacket", "layout", "parse_ids",
]
