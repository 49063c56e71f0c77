"""Protocol 1.0 and 2.0 as data: packets, framing, the control table, descriptions and ID lists.

Protocol 2.0 (the X series) lives beside 1.0 in the modules ending in 2
(``packets2``, ``params2``, ``framing2``, ``describe2``) and ``crc16``.

The lowest layer: pure functions and tables, no I/O, no clock, no model.
Everything above may import it; it imports nothing of ax12emu's above it.
"""

from .control_table import DEFAULT_PROFILE, PROFILES, Access, Area, ControlTable, Layout, layout
from .framing import Framer
from .framing2 import Framer2
from .ids import parse_ids
from .packets import BROADCAST_ID, MAX_ID, Instruction, InstructionPacket, StatusError, StatusPacket
from .packets2 import MAX_ID2, ErrorNumber, Instruction2, InstructionPacket2, Malformed, StatusPacket2

__all__ = [
    "Access", "Area", "BROADCAST_ID", "ControlTable", "DEFAULT_PROFILE", "Framer", "Instruction",
    "InstructionPacket", "Layout", "MAX_ID", "PROFILES", "StatusError", "StatusPacket", "layout", "parse_ids",
    "ErrorNumber", "Framer2", "Instruction2", "InstructionPacket2", "MAX_ID2", "Malformed", "StatusPacket2",
]
