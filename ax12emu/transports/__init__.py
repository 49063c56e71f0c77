"""Transports by scheme name, imported lazily (as python-can's BACKENDS and pyserial's protocol_<scheme>)."""

from __future__ import annotations

import importlib

from .base import Transport

__all__ = ["Transport", "BACKENDS", "transport_class"]

#: scheme -> (module, class), as strings so an unused backend costs nothing.
BACKENDS: dict[str, tuple[str, str]] = {
    "pty": ("ax12emu.transports.pty", "PtyTransport"),
    "tcp": ("ax12emu.transports.tcp", "TcpTransport"),
}


def transport_class(scheme: str) -> type[Transport]:
    """The transport class registered for ``scheme``."""
    try:
        module_name, class_name = BACKENDS[scheme]
    except KeyError:
        raise ValueError(f"unknown transport {scheme!r}; known: {', '.join(BACKENDS)}") from None
    return getattr(importlib.import_module(module_name), class_name)
