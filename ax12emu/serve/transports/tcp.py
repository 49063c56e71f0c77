"""TCP transport: the same raw byte stream as the pty, on a socket.

URL format: ``tcp://HOST:PORT`` (PORT 0 picks a free port).

pyserial's ``socket://HOST:PORT`` is a ready client.  One host at a time, as
on a real bus with one master: while a client is connected, a second one is
accepted and closed at once (it sees EOF, whatever it sent first), so bytes of two hosts never
interleave, unless the first one turns out to have just hung up (its EOF
may land up to HANGUP_GRACE_S after the new connection).  A client that
disconnects, even mid-packet, leaves the bus serving; its partial packet is
dropped by the framer's silence timeout.  A client that half-closes (``shutdown(SHUT_WR)``,
``nc -N``: "nothing more to send", RFC 9293 section 3.6) still gets the replies to what it sent:
its end is kept for writing until the server has sent what it owes (:meth:`TcpTransport.replies_sent`),
a new client comes or a write fails, HALF_CLOSE_LINGER_S at most.
TCP carries no line speed, so every servo hears whatever its baud setting.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import select
import socket
import time

from .base import Transport

__all__ = ["TcpTransport", "parse_host_port", "address_error"]

log = logging.getLogger(__name__)

#: TCP keepalive of the connected client: probed after KEEPALIVE_IDLE_S of silence, every KEEPALIVE_INTERVAL_S,
#: given up after KEEPALIVE_PROBES unanswered. A client whose host vanished (a Wi-Fi drop, a laptop asleep, a
#: pulled cable) sends no FIN; without probes the server never learns and refuses every later client for good.
#: A live client's idle connection answers the probes in its kernel and stays.
KEEPALIVE_IDLE_S, KEEPALIVE_INTERVAL_S, KEEPALIVE_PROBES = 5, 1, 3
#: How long a reply may stay unacknowledged before the connection is given up (ms): as long as the probes take.
UNACKNOWLEDGED_LIMIT_MS = 1000 * (KEEPALIVE_IDLE_S + KEEPALIVE_INTERVAL_S * KEEPALIVE_PROBES)


def _keep_alive(conn: socket.socket) -> None:
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    # Keepalive probes only an idle connection: with a reply unacknowledged, retransmission rules instead, for up
    # to 15 minutes (Linux's tcp_retries2). TCP_USER_TIMEOUT (RFC 5482) bounds that wait the same way.
    for option, value in (("TCP_KEEPIDLE", KEEPALIVE_IDLE_S), ("TCP_KEEPINTVL", KEEPALIVE_INTERVAL_S),
                          ("TCP_KEEPCNT", KEEPALIVE_PROBES), ("TCP_USER_TIMEOUT", UNACKNOWLEDGED_LIMIT_MS)):
        if hasattr(socket, option):  # Linux; other systems keep their defaults (hours) and SO_KEEPALIVE alone
            conn.setsockopt(socket.IPPROTO_TCP, getattr(socket, option), value)

#: How long a new client waits for the connected one's hang-up to land before it is refused: a
#: client that hangs up and reconnects at once can have its FIN trail the new handshake (on
#: loopback the two may be queued on different CPUs); seen once in 200 reconnections on CI.
#: The wait is the serving loop's passes, never a blocking call.
HANGUP_GRACE_S = 0.002
#: How long a client that has half-closed is kept for the replies it is owed: a servo answers within
#: its Return Delay Time (at most 508 us), an injected ``--delay`` within its own bound.
HALF_CLOSE_LINGER_S = 1.0


def address_error(what: str, address: tuple, exc: OSError) -> OSError:
    """``exc`` naming what asked for the address it could not bind (a flag, an argument: ``--tcp`` and ``--web``
    each bind one, so the bare "Address already in use" left the user to guess which), errno kept."""
    host, port = address
    return OSError(exc.errno, f"{what} {host}:{port}: {exc.strerror or exc}")


def is_loopback(host: str) -> bool:
    """True for "localhost" and loopback addresses (127.0.0.0/8, ::1); binding anything else needs consent."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def parse_host_port(text: str) -> tuple[str, int]:
    """"HOST:PORT", "[v6]:PORT" or ":PORT" (loopback) to a pair, with clear errors."""
    host, sep, port_text = text.rpartition(":")
    if not sep:
        raise ValueError(f"expected HOST:PORT, got {text!r}")
    host = host.strip("[]") or "127.0.0.1"
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f"port must be a number, got {port_text!r}") from None
    if not 0 <= port <= 65535:
        raise ValueError(f"port must be 0..65535, got {port}")
    return host, port


class TcpTransport(Transport):
    """Listens on ``host:port`` and serves one client at a time."""

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind((host, port))
            self._listener.listen(4)
        except OSError:
            self._listener.close()
            raise
        self._listener.setblocking(False)
        self._client: socket.socket | None = None
        #: A client that came while one was connected: (socket, peer, until when it waits for that one's hang-up).
        self._pending: tuple[socket.socket, object, float] | None = None
        #: When the connected client half-closed (its EOF came), None while it may still send.
        self._eof_at: float | None = None
        self.host, self.port = self._listener.getsockname()[:2]
        self.name = f"tcp://{self.host}:{self.port}"
        #: Clients turned away because one was already connected.
        self.refused = 0
        #: Clients accepted so far (a change tells the server a new host began).
        self.connections = 0

    @property
    def url(self) -> str:
        """``socket://HOST:PORT`` for pyserial, an IPv6 host in brackets."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"socket://{host}:{self.port}"

    @property
    def connected(self) -> bool:
        """Whether a host is connected."""
        return self._client is not None

    def fds(self) -> list[int]:
        # The client first: when it hangs up and reconnects at once, select reports both,
        # and its EOF must be seen before the new connection, or that one is refused.
        if self._client is not None and self._eof_at is not None and time.monotonic() - self._eof_at > HALF_CLOSE_LINGER_S:
            self._drop_client()
        if self._pending is not None:
            self._settle_pending()
        if self._client is not None and self._eof_at is None:
            return [self._client.fileno(), self._listener.fileno()]
        return [self._listener.fileno()]

    def on_readable(self, fd: int) -> bytes:
        if fd == self._listener.fileno():
            self._accept()
            return b""
        if self._client is None:
            return b""
        # Read until the socket is empty, so an EOF right behind the last bytes (a client
        # that sends and hangs up) is seen now, before a reconnecting client is accepted.
        chunks: list[bytes] = []
        while len(chunks) < 16:
            try:
                data = self._client.recv(4096)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                log.info("client connection failed: %s", exc)
                data = b""
            if not data:
                # The client sends no more; it may still read the replies to what it sent (module docstring).
                self._eof_at = time.monotonic()
                break
            chunks.append(data)
        return b"".join(chunks)

    def _accept(self) -> None:
        try:
            conn, peer = self._listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        if self._client is not None and (self._eof_at is not None or self._hung_up()):
            self._drop_client()
        if self._client is None:
            self._take(conn, peer)
        elif self._pending is not None:  # one waits already: this one is turned away
            self._refuse(conn, peer)
        else:
            # The connected client may have hung up with its FIN still on the way: the new one waits up to
            # HANGUP_GRACE_S for it, settled by :meth:`fds` on the serving loop's next passes (waiting here, in
            # select, held the loop 2 ms for every refused client: a reconnecting one slowed the host 4x).
            conn.setblocking(False)
            self._pending = (conn, peer, time.monotonic() + HANGUP_GRACE_S)

    def _settle_pending(self) -> None:
        conn, peer, deadline = self._pending  # type: ignore[misc]
        if self._client is None or self._eof_at is not None or self._hung_up():
            self._pending = None
            self._drop_client()
            self._take(conn, peer)
        elif time.monotonic() >= deadline:
            self._pending = None
            self._refuse(conn, peer)

    def _take(self, conn: socket.socket, peer: object) -> None:
        conn.setblocking(False)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        _keep_alive(conn)
        self._client = conn
        self.connections += 1
        log.info("client connected from %s", peer)

    def _refuse(self, conn: socket.socket, peer: object) -> None:
        self.refused += 1
        log.warning("refused a second client from %s: one host at a time", peer)
        # A client sends its first packet as soon as it connects; closed with those bytes unread, the socket
        # answers with a reset ("connection reset by peer", a network fault to the client). Read them and end the
        # connection in order, so the client sees EOF.
        conn.setblocking(False)
        with contextlib.suppress(OSError):
            while conn.recv(4096):
                pass
        with contextlib.suppress(OSError):
            conn.shutdown(socket.SHUT_RDWR)
        conn.close()

    def _hung_up(self) -> bool:
        """Whether the connected client has hung up with nothing left unread (asked without waiting)."""
        client = self._client
        readable, _, _ = select.select([client], [], [], 0.0)
        if not readable:
            return False
        try:
            return client.recv(1, socket.MSG_PEEK) == b""
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:  # reset: gone too
            return True

    def replies_sent(self) -> None:
        """The server owes the host nothing more: a client that half-closed is closed now."""
        if self._eof_at is not None:
            self._drop_client()

    def _drop_client(self) -> None:
        if self._client is not None:
            log.info("client disconnected")
            self._client.close()
            self._client = None
        self._eof_at = None

    def write(self, data: bytes) -> int:
        if self._client is None:
            return 0
        try:
            return self._client.send(data)
        except (BlockingIOError, InterruptedError):
            return 0
        except OSError:
            self._drop_client()
            return 0

    def close(self) -> None:
        self._drop_client()
        if self._pending is not None:
            self._pending[0].close()
            self._pending = None
        self._listener.close()
