"""The web server's log lines about a client's faults: bounded in number and in length.

Why it exists: every malformed request, refused page or bad control is one INFO line, and a client can
send thousands a second, each quoting what it sent.  Unbounded, they fill the terminal a ``--monitor``
draws on or, with stderr a pipe nobody reads, fill the pipe sooner.  So a :class:`ClientFaultBudget`
lets a burst of such lines through and then one a second, each saying how many it stands for, and
:func:`bounded` cuts what a client sent, quoted in a line, to :data:`CLIENT_TEXT_CHARS`.  The lines are
written where they are logged, as any other (a handler, a filter or ``caplog`` sees them at once and in
order); a stderr pipe nobody reads will in the end block the server, as it would any program.

One budget per process (:data:`BUDGET`): the log and the terminal are the process's, whichever live view
the faults came to.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

__all__ = ["ClientFaultBudget", "BUDGET", "bounded", "CLIENT_FAULT_BURST", "CLIENT_FAULT_LINES_PER_S",
           "CLIENT_TEXT_CHARS"]

#: Client-fault lines let through back to back (a user's handful of mistakes are each shown).
CLIENT_FAULT_BURST = 20
#: Past the burst, client-fault lines a second (each then says how many were held back since the last).
CLIENT_FAULT_LINES_PER_S = 1.0
#: Characters of a client's text (a request line, a header, a control) quoted in one log line.
CLIENT_TEXT_CHARS = 200


def bounded(text: str, limit: int = CLIENT_TEXT_CHARS) -> str:
    """``text`` cut to ``limit`` characters, saying how many more there were."""
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text) - limit} more)"


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


#: The process's budget, shared by every live view in it.
BUDGET = ClientFaultBudget()
