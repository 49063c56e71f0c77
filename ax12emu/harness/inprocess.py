"""An in-process link to a bus: no pty, no socket, no thread.

Why it exists: Windows has no pty, and a test wants servos without a second
process.  A host's ``write`` runs the bus at once under a lock; the replies
wait in a timed queue and a ``read`` returns them only once their Return
Delay Time (plus any injected delay) has passed, blocking up to its timeout
like a real port.  Replies of several servos are laid on the line as the
server does (:func:`ax12emu.serve.server.merge_replies`), so duplicate IDs
collide the same way; a Protocol 2.0 bus's replies, timed one after another
(broadcast Ping slots, Sync Read answers in list order), are released each at its own time.  The host's baud rate is passed to the bus, so a
servo at another baud is deaf, as on a pty.  A trace records each reply at its due time,
before the host's next bytes and at close, read or not, as a pty's trace has it.

Not modelled: wire time of the bytes (replies arrive whole), the
adapter's echo.  Physics advances when a packet arrives (the bus brings the
model up to date before it answers), on :meth:`InProcessLink.advance`, and
before a :meth:`InProcessLink.call` that asks (a wall-clock VirtualBus's).

Links are found by name from a URL (``ax12emu://NAME``): pyserial builds
a port from a string, so a small registry of weak references is the only
way to reach a bus created elsewhere in the process.  A name must come back
out of that URL as it went in (:func:`check_name`).
"""

from __future__ import annotations

import heapq
import threading
import time
import urllib.parse
import weakref
from collections.abc import Callable
from typing import Any

from ax12emu.bus.bus import Bus
from ax12emu.bus.bus2 import Bus2
from ax12emu.bus.reply import merge_replies
from ax12emu.tracing.trace import IN, OUT, TraceWriter

__all__ = ["InProcessLink", "register", "lookup", "check_name", "is_registered", "NameTaken", "LinkBusy", "LinkClosed",
           "LinkDetached"]

_REGISTRY: "weakref.WeakValueDictionary[str, InProcessLink]" = weakref.WeakValueDictionary()
_REGISTRY_LOCK = threading.Lock()


#: Characters a URL reads as its own parts: "/" (a path; "ax12emu:///" is a private bus), "?" (the options),
#: "#" (a fragment) and brackets (an IPv6 host): a name holding one is not the name its port finds.
_URL_PARTS = "/?#[]"


#: The longest a read waits before it looks again whether its bus was closed.
CLOSED_POLL_S = 0.1


class NameTaken(ValueError):
    """Another in-process bus holds the name."""


class LinkBusy(RuntimeError):
    """A second host tried to attach: one host at a time, as on a bus with one master."""


class LinkClosed(RuntimeError):
    """The bus behind the link was closed: its port is gone, as an unplugged adapter's."""


class LinkDetached(RuntimeError):
    """A host wrote in a session that has ended: its port was closed (another may be open on the bus now)."""


class InProcessLink:
    """A host endpoint on ``bus``, safe to use from several threads."""

    def __init__(self, bus: Bus | Bus2, *, trace: TraceWriter | None = None) -> None:
        self.bus = bus
        self.trace = trace
        #: The bus timed its replies one after another (Protocol 2.0): each is released at its own time.
        self._in_sequence = bool(getattr(bus, "replies_in_sequence", False))
        self.lock = threading.RLock()
        self._cond = threading.Condition(self.lock)
        self._pending: list[tuple[float, int, bytes]] = []
        self._seq = 0
        self._rx = bytearray()
        self._attached = False
        #: Bumped by every attach and detach: a read begun in one host's session ends with it (a thread still
        #: reading on a closed port took the replies meant for the next port opened on the bus).
        self._session = 0
        #: The bus was closed (:meth:`close`): a host's reads and writes fail from then on.
        self.closed = False
        #: A host's read is to return at once with what has arrived (:meth:`cancel_read`), once.
        self._cancel_read = False
        #: Packets handled, for diagnostics.
        self.packets_in = 0

    # -- host side ---------------------------------------------------------------------
    def attach(self) -> int:
        """Claim the link for one host (a port being opened); returns the session its reads and writes name."""
        with self.lock:
            if self._attached:
                raise LinkBusy("another port is open on this in-process bus: one host at a time")
            self._attached = True
            self._session += 1
            self._rx.clear()
            return self._session

    def detach(self) -> None:
        """Release the link (the port closed); bytes in flight are lost, those already on the line are traced."""
        with self._cond:
            self._release(time.monotonic())
            self._attached = False
            self._session += 1
            self._cancel_read = False
            self._rx.clear()
            self._pending.clear()
            self._cond.notify_all()

    def close(self) -> None:
        """The bus is closed: a host still attached finds its port gone at its next read or write.

        Replies already due are traced first: they were on the line, read or not, as a pty's trace has them.
        """
        with self._cond:
            if not self.closed:
                self._release(time.monotonic())
            self.closed = True
            self._pending.clear()
            self._cond.notify_all()

    def cancel_read(self) -> None:
        """Make a read blocked in another thread (or the next read) return at once with what has arrived."""
        with self._cond:
            self._cancel_read = True
            self._cond.notify_all()

    def _check_open(self) -> None:
        if self.closed:
            raise LinkClosed("the in-process bus was closed")

    def write(self, data: bytes, line_bps: float | None = None, session: int | None = None) -> int:
        """The host sends ``data``; servos act at once and their replies are queued.  ``session`` (:meth:`attach`'s):
        :class:`LinkDetached` once it has ended, so a write racing its port's close never reaches the servos."""
        with self._cond:
            self._check_open()
            if session is not None and session != self._session:
                raise LinkDetached("the port was closed")
            now = time.monotonic()
            # Replies due by now went out before these bytes came in, read or not: traced (and received) first,
            # so the trace keeps time order as a pty's does.
            self._release(now)
            if self.trace is not None:
                self.trace.record(IN, data, now)
            for replies in self.bus.answer(data, now, line_bps=line_bps):  # with the reply cache, as the server
                self.packets_in += 1
                if replies:
                    for release_s, chunk in merge_replies(replies, now, per_byte=False, in_sequence=self._in_sequence):
                        self._seq += 1
                        heapq.heappush(self._pending, (release_s, self._seq, chunk))
            self._cond.notify_all()
        return len(data)

    def _release(self, now: float) -> None:
        """Move the replies due by ``now`` to the host's input, tracing each at its due time (in time order)."""
        pending = self._pending
        while pending and pending[0][0] <= now:
            release_s, _, chunk = heapq.heappop(pending)
            if self.trace is not None:
                self.trace.record(OUT, chunk, release_s)
            self._rx += chunk

    def in_waiting(self) -> int:
        """Bytes the host can read now."""
        with self.lock:
            self._release(time.monotonic())
            return len(self._rx)

    def read(self, size: int, timeout_s: float | None, session: int | None = None) -> bytes:
        """Up to ``size`` bytes; waits for them up to ``timeout_s`` (None: forever, 0: not at all).  ``session``
        (:meth:`attach`'s; None: the one under way): once it has ended, nothing more is read (b"")."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        with self._cond:
            if session is None:
                session = self._session
            while True:
                self._check_open()
                if self._session != session:  # its port closed meanwhile: what arrives now is the next host's
                    return b""
                now = time.monotonic()
                self._release(now)
                if self._cancel_read:
                    self._cancel_read = False
                    break
                if len(self._rx) >= size or not self._attached or (deadline is not None and now >= deadline):
                    break
                # Never longer than CLOSED_POLL_S: a bus dropped unclosed marks its link closed without the lock
                # (a collector may run anywhere), so no notify comes to a read waiting for ever.
                wait = CLOSED_POLL_S if deadline is None else min(deadline - now, CLOSED_POLL_S)
                if self._pending:
                    wait = min(wait, self._pending[0][0] - now)
                self._cond.wait(max(wait, 0.0))
            out = bytes(self._rx[:size])
            del self._rx[:size]
            return out

    def clear_input(self) -> None:
        """Drop bytes already received (not replies still to come, as on a real port)."""
        with self.lock:
            self._release(time.monotonic())
            self._rx.clear()

    # -- bus side ----------------------------------------------------------------------
    def call(self, fn: Callable[[Bus], Any], *, advance: bool = False) -> Any:
        """Run ``fn(bus)`` with the link locked, so no packet is handled meanwhile.

        ``advance``: bring the physics up to the clock's present time first.  Why: nothing steps an in-process
        bus between packets, so on the wall clock a caller would otherwise see the shaft where the last packet
        left it, where a served bus (whose loop steps every millisecond) shows where it is now.
        """
        with self.lock:
            if advance:
                self.bus.advance()
            return fn(self.bus)

    def advance(self) -> None:
        """Bring the physics up to the bus clock's present time."""
        with self.lock:
            self.bus.advance()


def check_name(name: str) -> str:
    """``name`` if ``ax12emu://NAME`` finds the bus named so; ValueError saying why not.

    A blank name makes ``ax12emu://`` a port of a private bus of its own, and the URL's own characters
    (:data:`_URL_PARTS`) or control characters (dropped by the URL parser) make it name another bus or none.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a text, got {type(name).__name__}")
    if not name.strip():
        raise ValueError(f"name {name!r} is blank: ax12emu:// without a name opens a private bus, not this one")
    used = sorted({c for c in name if c in _URL_PARTS or not c.isprintable()})
    if used:
        raise ValueError(f"name {name!r} cannot be part of its port ax12emu://{name}: "
                         f"{' '.join(map(repr, used))} {'is' if len(used) == 1 else 'are'} read as part of the URL")
    parts = urllib.parse.urlsplit(f"ax12emu://{name}")
    if (parts.netloc + parts.path).strip("/") != name:  # pragma: no cover - the rule above covers what urlsplit does
        raise ValueError(f"name {name!r} does not come back out of its port ax12emu://{name}")
    return name


def register(name: str, link: InProcessLink) -> None:
    """Make ``link`` reachable as ``ax12emu://NAME``; :class:`NameTaken` if another bus holds it."""
    check_name(name)
    with _REGISTRY_LOCK:
        held = _REGISTRY.get(name)
        if held is not None and not held.closed:  # a closed one (its bus dropped, a port still open on it) is gone
            raise NameTaken(f"an in-process bus named {name!r} already exists")
        _REGISTRY[name] = link


def is_registered(name: str) -> bool:
    """Whether a bus holds ``name`` now."""
    with _REGISTRY_LOCK:
        return name in _REGISTRY


def unregister(name: str, link: InProcessLink | None = None) -> None:
    """Forget a name (the bus closed); with ``link``, only while the name is still that link's (a dropped bus's
    late release must not take it from a new bus registered since)."""
    with _REGISTRY_LOCK:
        if link is None or _REGISTRY.get(name) is link:
            _REGISTRY.pop(name, None)


def lookup(name: str) -> InProcessLink:
    """The link registered as ``name``; KeyError lists the names there are."""
    with _REGISTRY_LOCK:
        try:
            return _REGISTRY[name]
        except KeyError:
            raise KeyError(f"no in-process bus named {name!r} (open: {sorted(_REGISTRY) or 'none'})") from None
