"""The transport contract: a non-blocking byte pipe to one host, plus what it knows of the line.

Why it exists: the serving loop multiplexes whatever a transport exposes
(a pty master, a listening socket and its client) without knowing which it
is.  Reads and writes never block: a host that stops reading loses replies,
as it would on a real bus, but never stalls the servos.
"""

from __future__ import annotations

import abc

__all__ = ["Transport"]


class Transport(abc.ABC):
    """A byte stream to the host, served from one thread with select/poll."""

    #: Human-readable location printed at start-up (a device path, an address).
    name: str = ""
    #: Whether the serving loop should give up the CPU for a moment after a reply: the kernel
    #: may hand written bytes to the host through a worker thread that needs this CPU first.
    yield_after_reply: bool = False
    #: Hosts connected so far, for a transport that accepts several in turn (TCP); a new one is a new host.
    connections: int | None = None

    @property
    def url(self) -> str:
        """What a client opens to reach the bus: a device path, or a pyserial URL such as ``socket://HOST:PORT``.

        A transport no client opens by name (a test's pipe) may leave it as its ``name``.
        """
        return self.name

    @abc.abstractmethod
    def fds(self) -> list[int]:
        """File descriptors to watch for readability now."""

    @abc.abstractmethod
    def on_readable(self, fd: int) -> bytes:
        """Handle readability of ``fd``; return the bytes received (may be empty)."""

    @abc.abstractmethod
    def write(self, data: bytes) -> int:
        """Send what can be sent without blocking; return the count sent (0 if no host)."""

    def line_bps(self) -> float | None:
        """The host's bit rate if the transport can tell (a pty's termios), else None."""
        return None

    @abc.abstractmethod
    def close(self) -> None:
        """Release everything; safe to call more than once."""

    def __enter__(self) -> "Transport":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
