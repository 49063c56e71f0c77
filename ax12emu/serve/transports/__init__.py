"""Transports by scheme name, imported lazily (as python-can's BACKENDS and pyserial's protocol_<scheme>)."""

from __future__ import annotations

import importlib

from .base import Transport

__all__ = ["Transport", "BACKENDS", "transport_class", "open_transport"]

#: scheme -> (module, class), as strings so an unused backend costs nothing.
BACKENDS: dict[str, tuple[str, str]] = {
    "pty": ("ax12emu.serve.transports.pty", "PtyTransport"),
    "tcp": ("ax12emu.serve.transports.tcp", "TcpTransport"),
}


def transport_class(scheme: str) -> type[Transport]:
    """The transport class registered for ``scheme``."""
    try:
        module_name, class_name = BACKENDS[scheme]
    except KeyError:
        raise ValueError(f"unknown transport {scheme!r}; known: {', '.join(BACKENDS)}") from None
    return getattr(importlib.import_module(module_name), class_name)


def open_transport(scheme: str, **options: object) -> Transport:
    """Open the transport registered for ``scheme`` (``pty``: ``link=``; ``tcp``: ``host=``, ``port=``).

    The one way the command line, :class:`~ax12emu.VirtualBus` and tools
    open a transport, so each sees the same set and the same errors.
    """
    return transport_class(scheme)(**options)
