"""pyserial URL handlers of ax12emu: ``ax12emu://`` (see :mod:`.protocol_ax12emu`).

``import ax12emu`` appends this package to ``serial.protocol_handler_packages``,
which is where :func:`serial.serial_for_url` looks for ``protocol_<scheme>``
modules; :func:`register` does it explicitly and is idempotent.
"""

from __future__ import annotations

__all__ = ["register", "PACKAGE"]

PACKAGE = __name__


def register() -> None:
    """Let ``serial.serial_for_url`` open ``ax12emu://`` URLs."""
    import serial

    if PACKAGE not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append(PACKAGE)
