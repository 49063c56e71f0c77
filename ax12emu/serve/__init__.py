"""Serving a bus on a transport: the serving loop and the transports (pty, TCP) behind one registry."""

from .server import BusServer
from .transports import BACKENDS, Transport, open_transport, transport_class

__all__ = ["BACKENDS", "BusServer", "Transport", "open_transport", "transport_class"]
