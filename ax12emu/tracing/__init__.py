"""Bus traces: recording every byte with its time, and decoding a trace like a logic analyser."""

from .trace import IN, OUT, Chunk, TraceWriter, read_capture, read_raw

__all__ = ["IN", "OUT", "Chunk", "TraceWriter", "read_capture", "read_raw"]
