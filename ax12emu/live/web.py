"""The live view's web server: a page, a JSON snapshot, a WebSocket stream and the controls.

Why aiohttp: one well-kept package (the aio-libs project, released since 2014)
gives an HTTP server, WebSockets and their limits (request body size,
message size) on asyncio, with no other framework and no ASGI server to
pair it with, and it runs in a thread of its own, beside the serving
thread, with its own event loop.  Starlette with uvicorn would do the same
job as two packages.

Routes (all answers JSON except the page and its assets):

* ``GET /``: the page (``assets/index.html``; scripts and styles from ``/assets/``,
  nothing fetched from the internet).
* ``GET /api/servos``: a snapshot of every servo (registers by name, alarms,
  faults), the clock and the bus statistics, for scripts.
* ``GET /api/log?n=N``: the newest packet-log lines (``ax12emu decode``'s).
* ``GET /api/actions``: the controls and their parameters.
* ``POST /api/control``: one control, ``{"action": NAME, ...}`` as ``application/json``
  (see :mod:`ax12emu.live.controls`); also accepted as a WebSocket text message.
* ``GET /ws``: a WebSocket of frames at the sampler's rate.

Robustness: the bus never waits on this thread (frames come from the
:class:`~ax12emu.live.sampler.Sampler`, which reads the bus at a bounded
rate).  Request bodies over ``MAX_BODY_BYTES`` get 413, WebSocket messages
over ``MAX_MESSAGE_BYTES`` close the socket with 1009 (message too big),
malformed JSON or a bad control gets 400 with the reason, a body that stalls
after its headers 408 after ``BODY_TIMEOUT_S``; each WebSocket
client has a queue of ``QUEUE_FRAMES`` frames, and a client that falls that
far behind (one that never reads) is dropped; requests (and a socket's
controls) are answered at most ``REQUESTS_PER_S`` a second, the rest wait
their turn or, past ``MAX_REQUEST_WAIT_S``, get 503; a socket's messages of any kind (malformed or binary
or pings) each take a turn, and one whose turn is that far away gets the error reply, the socket staying
open; WebSocket upgrades are paced alike but by a turn of their own, so a flood of plain requests never keeps
the page from its stream; past ``max_connections`` open
connections a new one gets 503 and is closed; idle keep-alive connections
close after ``KEEPALIVE_S``.  A client's faults are logged in one short line each (what it sent cut to
``CLIENT_TEXT_CHARS``), a burst of them and then one a second for the whole process (:mod:`~ax12emu.live.logs`);
they are written as they happen, so a stderr pipe nobody reads will in the end block the server, as it would
any program.

Other web pages: the server answers only requests addressed to it (a ``Host`` of the bound address,
``localhost``, ``127.0.0.1`` or ``[::1]`` with its port; any IP address when bound to every interface),
so a page on a name that an attacker's DNS points at this machine (DNS rebinding) gets 403; a control
(a ``POST``, or the WebSocket its text messages are) from a page of another origin gets 403 (the
browser names the page's origin in ``Origin``); and ``/api/control`` takes ``Content-Type:
application/json`` alone (415 otherwise), a type no other page can send without the browser first
asking this server, which answers no such question.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import logging
import socket
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web
from aiohttp.http_exceptions import HttpProcessingError
from aiohttp.web_protocol import RequestPayloadError

from ax12emu.serve.transports.tcp import is_loopback

from . import logs
from .controls import ACTIONS, ControlError, Controls, apply
from .sampler import Frame, Sampler

__all__ = ["WebServer", "ASSETS", "MAX_BODY_BYTES", "MAX_MESSAGE_BYTES", "QUEUE_FRAMES"]

log = logging.getLogger(__name__)

#: The page's files, shipped as package data.
ASSETS = Path(__file__).resolve().parent / "assets"
#: Largest control request body; a control message is a few dozen bytes.
MAX_BODY_BYTES = 16 * 1024
#: Largest WebSocket message a client may send.
MAX_MESSAGE_BYTES = 4 * 1024
#: Frames queued per WebSocket client before it counts as not reading and is dropped.
QUEUE_FRAMES = 8
#: Kernel send buffer of a WebSocket connection (the system's default may grow to megabytes).
SEND_BUFFER_BYTES = 64 * 1024
#: Idle keep-alive connections close after this long.
KEEPALIVE_S = 15.0
#: How long ``/api/servos`` waits for the sampler's first frame before answering 503.
FIRST_FRAME_WAIT_S = 2.0
#: Newest log lines ``/api/log`` returns by default and at most.
LOG_LINES = 200
#: Requests the live view answers per second, all routes, WebSocket upgrades and every message a socket sends
#: together (only the frames it streams are not counted): a page needs a handful to load and one per control, a
#: script polling the snapshot 25 (the sampler's rate).  Past it requests wait their turn, so a flood of them
#: costs the bus (which shares this process) little more than the page does.
REQUESTS_PER_S = 100.0
#: A request whose turn is further away than this gets 503 at once instead of waiting.
MAX_REQUEST_WAIT_S = 2.0
#: How long a control's body may take to arrive once its headers have: a client that stalls mid-body would
#: otherwise hold its connection (and, many of them, every slot) for good; the keep-alive limit covers only
#: idle connections.
BODY_TIMEOUT_S = 5.0


#: Host names that always mean this machine (the loopback address by name and number).
LOOPBACK_NAMES = ("localhost", "127.0.0.1", "::1")
#: Addresses that bind every interface: requests to any of the machine's addresses reach the server.
_EVERY_INTERFACE = ("", "0.0.0.0", "::")
#: The one type ``/api/control`` takes: another origin's page can send a body as text/plain or a form without
#: asking the server first, but not as JSON.
CONTROL_TYPE = "application/json"


def _authority(text: str) -> tuple[str, int] | None:
    """``host[:port]`` (a Host header's, an Origin's after its scheme) as (lower-case host, port; 80 when absent),
    None when it does not parse."""
    try:
        parts = urlsplit("//" + text)
        host, port = parts.hostname, parts.port
    except ValueError:  # a port that is not a number, a bracket left open
        return None
    if not host or parts.path or parts.query or parts.fragment or parts.username is not None:
        return None
    return host.lower(), 80 if port is None else port


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host)
    except ValueError:
        return False
    return True


def _shown(value: Any, limit: int = 60) -> str:
    """A header's value for a log line: quoted, at most ``limit`` characters of it."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _error(status: int, text: str) -> web.Response:
    return web.json_response({"error": text}, status=status)


def _parse_json(data: bytes | str) -> Any:
    """A control message (JSON is UTF-8, RFC 8259, whatever charset a request names); ValueError with the reason,
    nesting too deep to parse included."""
    try:
        return json.loads(data)
    except RecursionError:
        raise ValueError("nested too deeply") from None


class _ClientFaults(logging.Filter):
    """A client's own faults in one INFO line each, and only so many of them (:class:`~ax12emu.live.logs.ClientFaultBudget`).

    aiohttp logs a client's faults (a connection dropped mid-request, a malformed request it has already answered
    with 400) as errors with a traceback, tens of lines each: one INFO line instead.  Those and this server's own
    INFO lines (refusals, bad controls, dropped sockets) are what a careless or hostile client makes happen: past a
    burst, one a second gets through (one budget for every live view in the process: they share its log), so such
    a client cannot fill the log or the terminal a ``--monitor`` draws on; what it sent is quoted cut short.
    """

    def filter(self, record: logging.LogRecord) -> bool:
        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, (ConnectionError, HttpProcessingError, RequestPayloadError)):
            said = " ".join(str(exc).split())  # aiohttp's messages quote the request over several lines
            record.msg, record.args = "live view: a client's request ended: %s: %s", (type(exc).__name__, said)
            record.exc_info = record.exc_text = None
            record.levelno, record.levelname = logging.INFO, "INFO"
        record.args = _bounded_args(record.args)
        return record.levelno > logging.INFO or logs.BUDGET.admit(record)


def _bounded_args(args: Any) -> Any:
    """A record's arguments with each text (a client's request, header or control, quoted) cut short; numbers kept,
    for the ``%d`` that shows them."""
    if not isinstance(args, tuple):
        return args
    return tuple(arg if isinstance(arg, (int, float)) or len(text := str(arg)) <= logs.CLIENT_TEXT_CHARS
                 else logs.bounded(text) for arg in args)


#: The loggers a client's faults are logged on.
_CLIENT_FAULT_LOGGERS = ("aiohttp.server", __name__)
_CLIENT_FAULTS = _ClientFaults()
#: Live views running, which the filter is on the loggers for (the last to close takes it off).
_filtering = 0
_filtering_lock = threading.Lock()


def _filter_client_faults(on: bool) -> None:
    """One live view starts (``on``) or stops filtering its client faults: the first puts the one filter on, the
    last takes it off."""
    global _filtering
    with _filtering_lock:
        _filtering += 1 if on else -1
        if _filtering == (1 if on else 0):
            for logger in map(logging.getLogger, _CLIENT_FAULT_LOGGERS):
                if on:
                    logger.addFilter(_CLIENT_FAULTS)
                else:
                    logger.removeFilter(_CLIENT_FAULTS)


class _Refuse(asyncio.Protocol):
    """A connection past the limit: one 503 answer, then closed."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        body = b'{"error": "too many connections"}'
        transport.write(  # type: ignore[attr-defined]
            b"HTTP/1.1 503 Service Unavailable\r\nContent-Type: application/json\r\nConnection: close\r\n"
            + f"Content-Length: {len(body)}\r\n\r\n".encode()
            + body
        )
        transport.close()


class _Turns:
    """Turns of answering, ``REQUESTS_PER_S`` a second, one after another (event-loop time)."""

    def __init__(self) -> None:
        #: When the next one may be answered.
        self._next_slot_s = 0.0

    def turn(self) -> float | None:
        """Seconds until the next turn (0: now), taken; or None, none taken, when that is over ``MAX_REQUEST_WAIT_S``."""
        now = asyncio.get_running_loop().time()
        slot = max(now, self._next_slot_s)
        if slot - now > MAX_REQUEST_WAIT_S:
            return None
        self._next_slot_s = slot + 1.0 / REQUESTS_PER_S
        return slot - now


class WebServer:
    """Serves the live view of ``sampler``'s bus on ``host:port`` in its own thread."""

    def __init__(
        self,
        sampler: Sampler,
        controls: Controls | None,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        allow_remote: bool = False,
        max_connections: int = 256,
        max_clients: int = 32,
    ) -> None:
        if not is_loopback(host) and not allow_remote:
            raise ValueError(f"--web {host}: binding beyond loopback needs --allow-remote")
        self.sampler = sampler
        self.controls = controls
        self.host, self.port = host, port
        self.max_connections = max_connections
        self.max_clients = max_clients
        #: Each WebSocket client's frame queue and its connection (aborted when it is dropped).
        self._clients: dict[web.WebSocketResponse, tuple[asyncio.Queue[str], asyncio.BaseTransport | None]] = {}
        #: Clients dropped for not reading (diagnostics and tests).
        self.dropped_clients = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._failure: BaseException | None = None
        # Controls wait for the serving thread (about a millisecond): never on the event loop.
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="ax12emu-live-control")
        self._runner: web.AppRunner | None = None
        self._server: asyncio.base_events.Server | None = None
        #: Turns of requests (every route, a socket's messages) and, apart, of WebSocket upgrades: see :class:`_Turns`.
        self._requests, self._upgrades = _Turns(), _Turns()
        #: Whether this server has the client-fault filter on (from setup to teardown).
        self._filtering = False

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    # -- life cycle -------------------------------------------------------------------------
    def start(self) -> "WebServer":
        """Bind and serve; raises the bind error (a port in use) here, in the caller's thread."""
        self._thread = threading.Thread(target=self._run, name="ax12emu-live-web", daemon=True)
        self._thread.start()
        self._ready.wait(10.0)
        if self._failure is not None:
            self._thread.join(5.0)
            self._executor.shutdown(wait=True)
            raise self._failure
        self.sampler.subscribe(self._on_frame)
        return self

    def close(self) -> None:
        self.sampler.unsubscribe(self._on_frame)
        loop = self._loop
        if loop is not None and self._thread is not None and self._thread.is_alive():
            loop.call_soon_threadsafe(loop.stop)
            self._thread.join(10.0)
        self._executor.shutdown(wait=True)

    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._setup())
        except BaseException as exc:  # reported to start()
            self._failure = exc
            self._ready.set()
            loop.run_until_complete(self._teardown())
            loop.close()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(self._teardown())
            loop.close()

    async def _setup(self) -> None:
        _filter_client_faults(True)  # taken off in _teardown, which follows a failed setup too
        self._filtering = True
        app = web.Application(client_max_size=MAX_BODY_BYTES, middlewares=[self._paced, self._guarded])
        app.router.add_get("/", self._index)
        app.router.add_static("/assets/", ASSETS, show_index=False)
        app.router.add_get("/api/servos", self._servos)
        app.router.add_get("/api/log", self._log)
        app.router.add_get("/api/actions", self._actions)
        app.router.add_post("/api/control", self._control)
        app.router.add_get("/ws", self._ws)
        # lingering_time 0: a request answered before its body arrived (408, 413) is closed at once, not after
        # reading up to 10 s more of a body nobody will use.
        self._runner = web.AppRunner(app, access_log=None, keepalive_timeout=KEEPALIVE_S, shutdown_timeout=1.0,
                                     lingering_time=0.0)
        await self._runner.setup()
        family = socket.AF_INET6 if ":" in self.host else socket.AF_INET
        sock = socket.socket(family, socket.SOCK_STREAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            sock.bind((self.host, self.port))
            sock.listen(128)
            sock.setblocking(False)
        except OSError:
            sock.close()
            raise
        self.port = sock.getsockname()[1]
        handler = self._runner.server
        assert handler is not None

        def protocol() -> asyncio.Protocol:
            if len(handler.connections) >= self.max_connections:
                return _Refuse()
            return handler()

        self._server = await asyncio.get_running_loop().create_server(protocol, sock=sock)

    async def _teardown(self) -> None:
        for ws in list(self._clients):
            await self._drop(ws, "the live view is closing")
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
        if self._runner is not None:
            await self._runner.cleanup()
        if self._filtering:
            self._filtering = False
            _filter_client_faults(False)

    # -- frames -----------------------------------------------------------------------------
    def _on_frame(self, frame: Frame) -> None:
        """On the sampler thread: hand the frame to the loop (never blocks)."""
        loop = self._loop
        if loop is not None and self._clients:
            try:
                loop.call_soon_threadsafe(self._broadcast, frame)
            except RuntimeError:  # the loop closed meanwhile
                pass

    def _broadcast(self, frame: Frame) -> None:
        text = json.dumps({"type": "frame", **frame}, separators=(",", ":"))
        for ws, (queue, _) in list(self._clients.items()):
            try:
                queue.put_nowait(text)
            except asyncio.QueueFull:
                self.dropped_clients += 1
                self.sampler.note("dropped a live-view client that stopped reading")
                asyncio.ensure_future(self._drop(ws, "not reading"))

    async def _drop(self, ws: web.WebSocketResponse, why: str) -> None:
        client = self._clients.pop(ws, None)
        if client is None:
            return
        queue, transport = client
        if not queue.full():
            queue.put_nowait("")  # the writer ends
        if transport is not None:
            transport.abort()  # a client that does not read would hold a polite close up
        log.info("live view: dropped a WebSocket client (%s)", why)

    # -- pacing ------------------------------------------------------------------------------
    @web.middleware
    async def _paced(self, request: web.Request, handler: Any) -> web.StreamResponse:
        # Every request, a WebSocket upgrade too (each sends a hello with the log: opened and closed in a loop, they
        # cost as much as any request) but in turns of their own: a flood of plain requests must not keep the page
        # from its stream.  The frames are paced by the sampler, a socket's messages by _serve_messages.
        wait = (self._upgrades if request.path == "/ws" else self._requests).turn()
        if wait is None:
            return _error(503, f"the live view answers {REQUESTS_PER_S:g} requests a second and more are "
                               "waiting; frames stream on /ws")
        if wait:
            await asyncio.sleep(wait)
        return await handler(request)

    # -- other web pages ---------------------------------------------------------------------
    def _is_own_host(self, authority: tuple[str, int] | None) -> bool:
        """Whether ``authority`` names this server: its port, and the bound address or a loopback name (any IP
        address when bound to every interface: a page of another site can make the browser send an IP address
        only by being served from it, which DNS rebinding cannot do)."""
        if authority is None:
            return False
        host, port = authority
        if port != self.port:
            return False
        bound = self.host.strip("[]").lower()
        return host in LOOPBACK_NAMES or host == bound or (bound in _EVERY_INTERFACE and _is_ip(host))

    def _refusal(self, request: web.Request) -> str | None:
        """Why ``request`` comes from a page other than the live view's own (None: it does not)."""
        host = request.headers.get("Host")
        # Browsers always send Host; a client that sends none is a script, which no web page can make it do.
        if host is not None and not self._is_own_host(_authority(host)):
            return f"Host {_shown(host)} is not this server"
        if request.method in ("GET", "HEAD") and request.path != "/ws":
            return None  # reads: another origin's page cannot read the answer
        origin = request.headers.get("Origin")
        if origin is None:  # browsers name it on every POST and WebSocket: this client is a script (curl, urllib)
            return None
        scheme, _, rest = origin.partition("://")
        if scheme.lower() != "http" or not self._is_own_host(_authority(rest)):
            return f"Origin {_shown(origin)} is not this server's page"
        return None

    @web.middleware
    async def _guarded(self, request: web.Request, handler: Any) -> web.StreamResponse:
        """Another web page in the user's browser may neither drive the controls nor read the bus (see the module
        text); after the pacing, so refusals too are answered (and logged) at most ``REQUESTS_PER_S`` a second."""
        why = self._refusal(request)
        if why is not None:
            log.info("live view: refused %s %s: %s", request.method, _shown(request.path), why)
            return _error(403, f"refused: {why}")
        return await handler(request)

    # -- routes -----------------------------------------------------------------------------
    async def _index(self, request: web.Request) -> web.StreamResponse:
        return web.FileResponse(ASSETS / "index.html")

    def _snapshot(self) -> dict[str, Any] | None:
        frame = self.sampler.latest
        if frame is None:
            return None
        return {key: value for key, value in frame.items() if key != "log"}

    async def _servos(self, request: web.Request) -> web.Response:
        snapshot = self._snapshot()
        for _ in range(int(FIRST_FRAME_WAIT_S / 0.02)):  # just started: the first frame is a period away
            if snapshot is not None:
                break
            await asyncio.sleep(0.02)
            snapshot = self._snapshot()
        if snapshot is None:
            return _error(503, "no snapshot yet: the sampler has not read the bus")
        return web.json_response(snapshot)

    async def _log(self, request: web.Request) -> web.Response:
        try:
            count = int(request.query.get("n", LOG_LINES))
        except ValueError:
            return _error(400, f"n must be an integer, got {request.query.get('n')!r}")
        if not 0 < count <= LOG_LINES:
            return _error(400, f"n must be 1..{LOG_LINES}, got {count}")
        lines = list(self.sampler.log_lines)[-count:]
        return web.json_response({"lines": lines})

    async def _actions(self, request: web.Request) -> web.Response:
        return web.json_response({name: {"params": list(action.params), "defaults": dict(action.defaults or {})} for name, action in ACTIONS.items()})

    async def _apply(self, message: Any) -> tuple[int, dict[str, Any]]:
        if self.controls is None:
            return 403, {"error": "this live view is read-only"}
        loop = asyncio.get_running_loop()
        try:
            said = await loop.run_in_executor(self._executor, apply, self.controls, message)
        except ControlError as exc:  # the client's mistake: one line, as a client's other faults
            log.info("live view: refused a control: %s", exc)
            return 400, {"error": str(exc)}
        except TimeoutError:
            return 503, {"error": "the bus did not answer in time"}
        except Exception as exc:  # a fault in the emulator, not in the message: reported, and the page stays up
            log.exception("live view: the control %r failed", message)
            return 500, {"error": f"the control failed inside the emulator: {type(exc).__name__}: {exc}"}
        self.sampler.note(said, id=message.get("id", message.get("slot")))
        return 200, {"ok": True, "log": said}

    async def _control(self, request: web.Request) -> web.Response:
        if request.content_length is not None and request.content_length > MAX_BODY_BYTES:
            return _error(413, f"request body over {MAX_BODY_BYTES} bytes")
        if request.content_type != CONTROL_TYPE:  # before the body is read: it will not be used
            log.info("live view: refused a control sent as %s", _shown(request.headers.get("Content-Type")))
            return _error(415, f"send a control as Content-Type: {CONTROL_TYPE}")
        try:
            data = await asyncio.wait_for(request.read(), BODY_TIMEOUT_S)
        except web.HTTPRequestEntityTooLarge:
            return _error(413, f"request body over {MAX_BODY_BYTES} bytes")
        except asyncio.TimeoutError:  # (TimeoutError itself from Python 3.11 on; a class of its own on 3.10)
            late = _error(408, f"the body did not arrive within {BODY_TIMEOUT_S:g} s of its headers")
            late.force_close()  # the rest of the body may still come: the connection cannot carry another request
            return late
        except RequestPayloadError as exc:  # e.g. a body its Content-Encoding cannot decode
            return _error(400, f"the body could not be read: {exc}")
        try:
            message = _parse_json(data)
        except ValueError as exc:
            return _error(400, f"the body is not JSON: {exc}")
        status, body = await self._apply(message)
        return web.json_response(body, status=status)

    async def _ws(self, request: web.Request) -> web.StreamResponse:
        if len(self._clients) >= self.max_clients:
            return _error(503, f"at most {self.max_clients} live-view clients at once")
        # autoping off: a ping is a message as any other, answered in its turn (aiohttp would answer each at once).
        ws = web.WebSocketResponse(max_msg_size=MAX_MESSAGE_BYTES, heartbeat=None, autoping=False)
        await ws.prepare(request)
        sock = request.transport.get_extra_info("socket") if request.transport is not None else None
        if sock is not None:  # a client that stops reading fills this, then its queue, then is dropped
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        queue: asyncio.Queue[str] = asyncio.Queue(maxsize=QUEUE_FRAMES)
        self._clients[ws] = (queue, request.transport)
        hello = {"type": "hello", "log": list(self.sampler.log_lines)[-LOG_LINES:], "actions": list(ACTIONS)}
        await ws.send_str(json.dumps(hello, separators=(",", ":")))
        writer = asyncio.ensure_future(self._write(ws, queue))
        try:
            await self._serve_messages(ws)
        except ConnectionError:  # dropped (aborted) or gone
            pass
        finally:
            writer.cancel()
            self._clients.pop(ws, None)
        return ws

    async def _serve_messages(self, ws: web.WebSocketResponse) -> None:
        """Controls sent as WebSocket text messages, each answered with a reply or an error.

        Every message takes its turn before it is looked at (a malformed or binary one costs an answer as much as a
        control does), and the next is read once it is answered: one message, one turn.  Where the turn is over
        ``MAX_REQUEST_WAIT_S`` away (other clients' requests hold the turns), the message gets the error reply at
        once, as a request gets 503, and the socket stays open: with one turn waiting at most, a socket is never
        what floods.
        """
        async for message in ws:
            if message.type == WSMsgType.ERROR:
                return
            wait = self._requests.turn()
            if wait is None:
                if message.type != WSMsgType.PONG:  # (no ping of ours asked for it: nothing to answer)
                    await ws.send_str(json.dumps({"type": "error", "error": f"more than {REQUESTS_PER_S:g} requests a "
                                                  "second are waiting: control not taken"}))
                continue
            if wait:
                await asyncio.sleep(wait)
            await self._answer(ws, message)

    async def _answer(self, ws: web.WebSocketResponse, message: Any) -> None:
        if message.type == WSMsgType.PING:
            await ws.pong(message.data)
            return
        if message.type != WSMsgType.TEXT:  # binary; a pong, which no ping of ours asked for, needs no answer
            if message.type == WSMsgType.BINARY:
                await ws.send_str(json.dumps({"type": "error", "error": "send control messages as JSON text"}))
            return
        try:
            parsed = _parse_json(message.data)
        except ValueError as exc:
            await ws.send_str(json.dumps({"type": "error", "error": f"not JSON: {exc}"}))
            return
        status, body = await self._apply(parsed)
        await ws.send_str(json.dumps({"type": "reply", "status": status, **body}))

    async def _write(self, ws: web.WebSocketResponse, queue: asyncio.Queue[str]) -> None:
        try:
            while True:
                text = await queue.get()
                if not text or ws.closed:
                    return
                await ws.send_str(text)
        except (ConnectionError, RuntimeError):
            self._clients.pop(ws, None)
