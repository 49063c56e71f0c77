"""Servo ID lists as users write them: "1,2,5", "1-18" or a mix.

Why one parser: the command line (``--ids``, ``--fault-ids``, ``--vanish``),
the ``ax12emu://`` URL and the fault configuration all take ID lists, and a
list accepted in one place must be accepted in every other.
"""

from __future__ import annotations

from .packets import MAX_ID

__all__ = ["parse_ids"]


def parse_ids(text: str) -> list[int]:
    """Parse "1,2,5" or "1-18" (or a mix) into a list of distinct servo IDs 0..253."""
    ids: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            raise ValueError(f"empty item in ID list {text!r}")
        low, sep, high = part.partition("-")
        try:
            first, last = (int(low), int(high)) if sep else (int(part), int(part))
        except ValueError:
            raise ValueError(f"{part!r} is not an ID or range of IDs (e.g. 1,2,5 or 1-18)") from None
        if first > last:
            raise ValueError(f"range {part!r} runs backwards")
        for servo_id in range(first, last + 1):
            if not 0 <= servo_id <= MAX_ID:
                raise ValueError(f"ID {servo_id} is outside 0..{MAX_ID}")
            if servo_id in ids:
                raise ValueError(f"ID {servo_id} is listed twice")
            ids.append(servo_id)
    return ids
