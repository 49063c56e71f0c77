"""The web server's log lines: a client's faults bounded in number, and none written from its event loop.

Why it exists: every malformed request, refused page or bad control is one INFO line, and a client can
send thousands a second.  Unbounded, they fill the terminal a ``--monitor`` draws on or, with stderr a
pipe nobody reads (``subprocess.Popen(stderr=PIPE)`` and only stdout read), fill the pipe: the event
loop then blocks in ``write`` and the page stops answering, Ctrl-C included, until someone reads.  So a
:class:`ClientFaultBudget` lets a burst of such lines through and then one a second, each saying how many
it stands for; and :class:`OffLoop` hands the loop's records to a thread of their own through a bounded
queue, so a stalled stderr holds that thread up, never the loop (records past the queue are dropped and
counted).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections.abc import Callable, Sequence

__all__ = ["ClientFaultBudget", "OffLoop", "off_loop", "release", "CLIENT_FAULT_BURST", "CLIENT_FAULT_LINES_PER_S", "QUEUED_RECORDS"]

#: Client-fault lines let through back to back (a user's handful of mistakes are each shown).
CLIENT_FAULT_BURST = 20
#: Past the burst, client-fault lines a second (each then says how many were held back since the last).
CLIENT_FAULT_LINES_PER_S = 1.0
#: Records waiting for the log's thread; a stderr stalled this long drops the rest.
QUEUED_RECORDS = 1000
#: How long closing waits for the log's thread to write what is queued (a stalled stderr may never take it).
DRAIN_TIMEOUT_S = 1.0


class ClientFaultBudget:
    """A token bucket of log lines: ``burst`` at once, then ``per_s`` a second."""

    def __init__(self, burst: int = CLIENT_FAULT_BURST, per_s: float = CLIENT_FAULT_LINES_PER_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.burst, self.per_s, self._clock = burst, per_s, clock
        self._tokens = float(burst)
        self._at_s = clock()
        self._lock = threading.Lock()
        #: Lines held back since the last one let through.
        self.held = 0

    def take(self) -> int | None:
        """None: hold this line back; else let it through, and how many were held back before it."""
        with self._lock:
            now = self._clock()
            self._tokens = min(float(self.burst), self._tokens + (now - self._at_s) * self.per_s)
            self._at_s = now
            if self._tokens < 1.0:
                self.held += 1
                return None
            self._tokens -= 1.0
            held, self.held = self.held, 0
            return held

    def admit(self, record: logging.LogRecord) -> bool:
        """Whether ``record`` (a client's fault) is logged; the first after a hold says how many it stands for."""
        held = self.take()
        if held is None:
            return False
        if held:
            record.msg, record.args = f"{record.getMessage()} (and {held} more client faults not shown)", None
        return True


class OffLoop(logging.Filter):
    """While open, the named loggers' records are handed to their handlers from a thread of their own.

    A filter on each logger, after its others (:meth:`open` puts it last), takes the record off the thread that
    logged it into a bounded queue (a full one drops it, counted in ``dropped``); the thread hands it to the
    handlers the logger would have (its own and its ancestors', as propagation does).  Closing gives the thread
    :data:`DRAIN_TIMEOUT_S` to write what is queued.  One per process (:func:`off_loop`): two would hand every
    record on twice.
    """

    def __init__(self, names: Sequence[str]) -> None:
        super().__init__()
        self._records: queue.Queue = queue.Queue(QUEUED_RECORDS)
        self._loggers = [logging.getLogger(name) for name in names]
        self._thread: threading.Thread | None = None
        self.dropped = 0

    def filter(self, record: logging.LogRecord) -> bool:
        # The message fixed now (its arguments may change meanwhile); the traceback kept for the handlers.
        record.msg, record.args = record.getMessage(), None
        try:
            self._records.put_nowait(record)
        except queue.Full:
            self.dropped += 1
        return False

    def _forward(self) -> None:
        while (record := self._records.get()) is not None:
            logging.getLogger(record.name).callHandlers(record)

    def open(self) -> "OffLoop":
        if self._thread is None:
            self._thread = threading.Thread(target=self._forward, name="ax12emu-live-log", daemon=True)
            self._thread.start()
        for logger in self._loggers:  # last: the loggers' own filters (a budget) decide first
            logger.removeFilter(self)
            logger.addFilter(self)
        return self

    def close(self) -> None:
        for logger in self._loggers:
            logger.removeFilter(self)
        if self._thread is None:
            return
        try:
            self._records.put(None, timeout=DRAIN_TIMEOUT_S)
            self._thread.join(DRAIN_TIMEOUT_S)
        except queue.Full:  # a stalled stderr: the (daemon) thread is left to it, the close goes on
            pass
        self._thread = None


_users = 0
_shared: OffLoop | None = None
_shared_lock = threading.Lock()


def off_loop(names: Sequence[str]) -> OffLoop:
    """The process's :class:`OffLoop` of ``names``, opened by the first user and put after the filters added since by
    each; each user calls :func:`release`."""
    global _users, _shared
    with _shared_lock:
        if _shared is None:
            _shared = OffLoop(names)
        _users += 1
        return _shared.open()


def release() -> None:
    """One user of :func:`off_loop` is done; the last closes it."""
    global _users, _shared
    with _shared_lock:
        _users -= 1
        if _users == 0 and _shared is not None:
            _shared.close()
            _shared = None
