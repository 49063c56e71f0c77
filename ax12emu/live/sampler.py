"""The live view's one reader of the bus: snapshots at a bounded rate, the packet log, statistics.

Why it exists: the web page, the JSON snapshot and the terminal monitor all
show the same picture, and the bus must never wait for any of them.  A
:class:`Sampler` thread asks the serving thread for a snapshot
(:func:`~ax12emu.live.snapshot.take`, through the bus's ``call``) ``rate_hz``
times a second, decodes what the :class:`~ax12emu.live.tap.ByteTap` saw since
the last frame with the ``ax12emu decode`` decoder, and hands each frame to
its subscribers.  Decoding is bounded per frame (``max_chunks``): a host
polling thousands of times a second gets a log line saying how many chunks
were not shown, rather than a live view that competes with the bus for the
interpreter.
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

from ax12emu.protocol.control_table import DEFAULT_PROFILE
from ax12emu.protocol.packets import Instruction
from ax12emu.protocol.packets2 import Instruction2, InstructionPacket2, StatusPacket2
from ax12emu.tracing.decoder import ECHO, GARBAGE, INSTRUCTION, STATUS, Decoded, Decoder

from .buses import AnyBus
from .snapshot import take
from .tap import ByteTap

__all__ = ["Sampler", "Frame"]

log = logging.getLogger(__name__)

Frame = dict[str, Any]
#: What a log line's ``who`` says, by decoded kind.
_WHO = {INSTRUCTION: "host", STATUS: "servo", ECHO: "echo", GARBAGE: "noise"}
_INSTRUCTION_NAMES = {int(code): code.name for code in Instruction}
_INSTRUCTION2_NAMES = {int(code): code.name for code in Instruction2}


class Sampler:
    """Samples a served bus at ``rate_hz`` on its own thread and publishes frames.

    ``call(fn)`` runs ``fn(bus)`` where the bus is served (``BusServer.call``,
    ``VirtualBus.call``); ``counters()`` is read there too (e.g. the server's
    ``packets_in``).
    """

    def __init__(
        self,
        call: Callable[[Callable[[AnyBus], Any]], Any],
        *,
        tap: ByteTap | None = None,
        counters: Callable[[], dict[str, int]] | None = None,
        rate_hz: float = 25.0,
        profile: str = DEFAULT_PROFILE,
        protocol: str = "1.0",
        servos: str | None = None,
        echo: bool | None = None,
        log_capacity: int = 500,
        max_chunks: int = 80,
    ) -> None:
        if not 0 < rate_hz <= 100:
            raise ValueError(f"rate_hz must be in (0, 100], got {rate_hz}")
        self._call = call
        self.tap = tap
        self._counters = counters or (lambda: {})
        self.period_s = 1.0 / rate_hz
        #: The decoder's options: the 1.0 profile, the protocol ("1.0", "2.0" or "both" on a mixed
        #: wire) and the 2.0 servos by launch ID and model file, so it names their registers; ``echo``, whether the
        #: wire echoes the host's bytes (False: a host's repeated poll is never taken for an echo; None: not known).
        self._decoding = {"profile": profile, "protocol": protocol, "servos": servos, "echo": echo}
        self._decoder = Decoder(**self._decoding)
        self._max_chunks = max_chunks
        #: The newest log lines, for a page that connects late (bounded).
        self.log_lines: collections.deque[dict[str, Any]] = collections.deque(maxlen=log_capacity)
        self._pending_notes: collections.deque[dict[str, Any]] = collections.deque(maxlen=log_capacity)
        self._subscribers: list[Callable[[Frame], None]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._t0 = time.monotonic()
        self._last_request: str | None = None
        self._rate_window: collections.deque[tuple[float, int]] = collections.deque(maxlen=32)
        #: The newest frame (None before the first).
        self.latest: Frame | None = None
        self.frames = 0
        self.stats = {"status_errors": 0, "checksum_errors": 0, "noise_bytes": 0, "log_chunks_skipped": 0, "sample_failures": 0}

    # -- life cycle -------------------------------------------------------------------------
    def start(self) -> "Sampler":
        self._thread = threading.Thread(target=self._run, name="ax12emu-live-sampler", daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None

    def subscribe(self, callback: Callable[[Frame], None]) -> None:
        """Call ``callback(frame)`` on the sampler thread for every frame (it must not block)."""
        with self._lock:
            self._subscribers.append(callback)

    def unsubscribe(self, callback: Callable[[Frame], None]) -> None:
        with self._lock:
            if callback in self._subscribers:
                self._subscribers.remove(callback)

    def note(self, text: str, **fields: Any) -> None:
        """Put a line in the packet log (a control used, a client dropped); safe from any thread."""
        self._pending_notes.append({"t": round(time.monotonic() - self._t0, 6), "who": "control", "id": fields.get("id"), "ins": None, "text": text})

    # -- sampling ---------------------------------------------------------------------------
    def _run(self) -> None:
        next_s = time.monotonic()
        while not self._stop.is_set():
            try:
                self.sample()
            except Exception:  # a bus closing under us, a slow serving thread: try again next period
                self.stats["sample_failures"] += 1
                log.debug("live sample failed", exc_info=True)
            next_s = max(next_s + self.period_s, time.monotonic())
            self._stop.wait(max(0.0, next_s - time.monotonic()))

    def sample(self) -> Frame:
        """Take one frame now and publish it (the thread does this every period)."""
        counters = self._counters
        snapshot = self._call(lambda bus: take(bus, counters()))
        now = time.monotonic()
        lines = self._decode_new()
        while self._pending_notes:
            lines.append(self._pending_notes.popleft())
        self.log_lines.extend(lines)
        frame: Frame = {
            "seq": self.frames,
            "wall_s": round(now - self._t0, 6),
            **snapshot,
            "stats": self._stats(snapshot["counters"], snapshot["faults"], now),
            "log": lines,
        }
        self.frames += 1
        self.latest = frame
        with self._lock:
            subscribers = list(self._subscribers)
        for callback in subscribers:
            try:
                callback(frame)
            except Exception:
                log.exception("a live-view subscriber failed")
        return frame

    def _stats(self, counters: dict[str, int], faults: dict[str, Any], now: float) -> dict[str, Any]:
        packets = counters.get("packets_in", 0)
        self._rate_window.append((now, packets))
        first_s, first_packets = self._rate_window[0]
        rate = (packets - first_packets) / (now - first_s) if now > first_s else 0.0
        return {
            "packets": packets,
            "packets_per_s": round(rate, 1),
            **self.stats,
            "timeouts_injected": faults.get("dropped", 0) + faults.get("delayed", 0),
            "corrupt_injected": faults.get("corrupted", 0),
            # Last: a counter the bus's server keeps over every packet (status errors) replaces the log's own count,
            # which misses what the log left out; checksum errors are the log's alone.
            **{k: v for k, v in counters.items() if k != "packets_in"},
        }

    def _decode_new(self) -> list[dict[str, Any]]:
        if self.tap is None:
            return []
        chunks, lost = self.tap.take()
        skipped = lost + max(0, len(chunks) - self._max_chunks)
        lines: list[dict[str, Any]] = []
        if skipped:
            # The framers were mid-stream: start afresh rather than call the cut packets noise.
            chunks = chunks[-self._max_chunks :]
            self._decoder = Decoder(**self._decoding)
            self.stats["log_chunks_skipped"] += skipped
            t = chunks[0].t - self._t0 if chunks else time.monotonic() - self._t0
            lines.append({"t": round(t, 6), "who": "skip", "id": None, "ins": None, "text": f"{skipped} chunk(s) on the line not shown (the log shows at most {self._max_chunks} per frame)"})
        decoded: list[Decoded] = []
        for chunk in chunks:
            self._decoder.feed(chunk, decoded)
        lines.extend(self._line(item) for item in decoded)
        return lines

    def _line(self, item: Decoded) -> dict[str, Any]:
        packet = item.packet
        if item.kind == GARBAGE:
            self.stats["noise_bytes"] += item.discarded
        elif item.kind == INSTRUCTION and packet is not None and not isinstance(packet, StatusPacket2):
            names = _INSTRUCTION2_NAMES if isinstance(packet, InstructionPacket2) else _INSTRUCTION_NAMES
            self._last_request = names.get(packet.instruction, f"0x{packet.instruction:02X}")
        elif item.kind == STATUS and packet is not None:
            # A 1.0 status packet is decoded as a packet whose instruction byte is the error; a 2.0
            # one has its own error field and a CRC instead of a checksum.
            two = isinstance(packet, StatusPacket2)
            if not (packet.crc_ok if two else packet.checksum_ok):
                self.stats["checksum_errors"] += 1
            elif packet.error if two else packet.instruction:
                self.stats["status_errors"] += 1
        ins = None if packet is None else (self._last_request if item.kind in (STATUS, INSTRUCTION, ECHO) else None)
        text = item.text if item.latency_s is None else f"{item.text}  (+{item.latency_s * 1e6:.0f} us)"
        return {
            "t": None if item.t is None else round(item.t - self._t0, 6),
            "who": _WHO[item.kind],
            "id": None if packet is None else packet.id,
            "ins": ins,
            "text": text,
        }
