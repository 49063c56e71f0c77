"""One live view of one served bus: the sampler and, as asked, the web page and the terminal monitor.

Why it exists: ``ax12emu serve --web/--monitor``, ``VirtualBus(web=...)`` and
the pytest plugin all start the same three parts in the same order and stop
them in reverse; :class:`LiveView` does it once.  :meth:`LiveView.for_server`
puts a :class:`~ax12emu.live.tap.ByteTap` in the server's trace hook (keeping
a trace file, if any, behind it) and reads the server's counters.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import IO, Any

from ax12emu.serve.server import BusServer

from .buses import AnyBus, decoder_options
from .controls import Controls, ServedControls
from .sampler import Sampler
from .tap import ByteTap

__all__ = ["LiveView"]

#: How long a sample waits for the serving thread (which answers within about a physics period).
SAMPLE_TIMEOUT_S = 0.5
#: How long a control waits for it.
CONTROL_TIMEOUT_S = 2.0


class LiveView:
    """Samples a bus through ``call`` and shows it on the web (``web=(host, port)``) and/or the terminal."""

    def __init__(
        self,
        call: Callable[[Callable[[AnyBus], Any]], Any],
        *,
        controls: Controls | None = None,
        tap: ByteTap | None = None,
        counters: Callable[[], dict[str, int]] | None = None,
        web: tuple[str, int] | None = None,
        allow_remote: bool = False,
        monitor: bool = False,
        monitor_stream: IO[str] | None = None,
        rate_hz: float = 25.0,
        profile: str = "ax12a",
        protocol: str = "1.0",
        servos: str | None = None,
        echo: bool | None = None,
    ) -> None:
        self.sampler = Sampler(call, tap=tap, counters=counters, rate_hz=rate_hz, profile=profile, protocol=protocol, servos=servos,
                               echo=echo)
        self._web_address = web
        self._allow_remote = allow_remote
        self._controls = controls
        self._monitor_wanted = monitor
        self._monitor_stream = monitor_stream
        self.web: Any = None
        self.monitor: Any = None

    @classmethod
    def for_server(cls, server: BusServer, *, seed: int = 0, controls: Controls | None = None, **options: Any) -> "LiveView":
        """A live view of a BusServer's bus of either protocol, or both (call it before the server runs, or from its thread)."""
        tap = ByteTap(server.trace)
        server.trace = tap
        server.count_status_errors = True
        # The server's count of status packets with error bits stands in for the log's, which decodes at most
        # ``max_chunks`` chunks a frame (the sampler's stats take a counter of the same name over their own).
        counters = lambda: {"packets_in": server.packets_in, "bytes_dropped": server.bytes_dropped, "collisions": server.collisions,
                            "status_errors": server.status_errors}
        if controls is None:
            controls = ServedControls(lambda fn: server.call(fn, CONTROL_TIMEOUT_S), servos=len(server.bus.servos), seed=seed)
        # A short wait: once the server has stopped, a pending sample must not hold the close up.
        sample = lambda fn: server.call(fn, SAMPLE_TIMEOUT_S)
        return cls(sample, controls=controls, tap=tap, counters=counters,
                   **{**decoder_options(server.bus), "echo": server.echo, **options})

    @property
    def url(self) -> str | None:
        """The page's address, once started with ``web``."""
        return None if self.web is None else self.web.url

    def start(self) -> "LiveView":
        """Start sampling and the views; on failure (a port in use) everything started is stopped."""
        try:
            if self._web_address is not None:
                try:
                    from .web import WebServer
                except ImportError as exc:  # aiohttp: the web extra
                    raise ImportError(f"the live view needs the web extra: pip install 'ax12emu[web]' ({exc})") from exc

                host, port = self._web_address
                self.web = WebServer(self.sampler, self._controls, host=host, port=port, allow_remote=self._allow_remote).start()
            if self._monitor_wanted:
                try:
                    from .monitor import Monitor
                except ImportError as exc:  # rich: the web extra
                    raise ImportError(f"the live view needs the web extra: pip install 'ax12emu[web]' ({exc})") from exc

                self.monitor = Monitor(self.sampler, stream=self._monitor_stream).start()
            self.sampler.start()
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Stop the views and the sampler (safe to call more than once)."""
        self.sampler.close()
        if self.monitor is not None:
            self.monitor.close()
            self.monitor = None
        if self.web is not None:
            self.web.close()
            self.web = None

    def __enter__(self) -> "LiveView":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
