"""A live view of the virtual servos: a local web page and a terminal monitor.

Layered above :mod:`ax12emu.serve` and below the harness and the command
line: :class:`LiveView` samples a served bus through its ``call`` at a
bounded rate (:mod:`.sampler`, :mod:`.snapshot`), taps its bytes for the
packet log (:mod:`.tap`), serves the page, the JSON snapshot and the
controls (:mod:`.web`, :mod:`.controls`, assets in ``assets/``) and draws
the terminal view (:mod:`.monitor`).  Buses of either protocol and wires of
both are shown alike (:mod:`.buses`): each servo by its own table's register
names and in its model file's units.  The web part needs the ``web`` extra
(aiohttp); the monitor needs rich.
"""

from .controls import ACTIONS, ControlError, ServedControls, apply
from .sampler import Sampler
from .snapshot import take
from .tap import ByteTap
from .view import LiveView

__all__ = ["LiveView", "Sampler", "ByteTap", "ServedControls", "ACTIONS", "ControlError", "apply", "take"]
