"""Which servo model each ID is, as users write it: "xl430-w250" or "1-5:xm430-w350,6:xl330-m077".

Why one parser: a bus of X-series servos may mix models, and the command line (``--servo``) and
any harness must read the same text the same way, with a clear message for every mistake.

Forms:

* ``MODEL``: every ID of ``--ids`` is that model;
* ``IDS:MODEL[,IDS:MODEL...]``: per-ID models (with ``also``, models of the other protocol too,
  for a wire that mixes them), where ``IDS`` is an ID list as ``--ids`` takes it
  (``1-5``, ``1,2,5``); a comma-separated ID list runs up to the colon, so ``1,2:xl430-w250,6:xm430-w350``
  gives IDs 1 and 2 one model and ID 6 another.
"""

from __future__ import annotations

from .ids import parse_ids
from .packets2 import MAX_ID2
from .servo_models import model, model_names

__all__ = ["parse_servo_spec"]


def _model_key(text: str, protocol: str, also: tuple[str, ...]) -> str:
    key = text.strip().lower()
    if key not in model_names():
        raise ValueError(f"unknown servo model {text.strip()!r}; choose one of: {', '.join(model_names())}")
    spec = model(key)
    if protocol not in spec.protocols and key not in also:
        serving = [k for k in model_names() if protocol in model(k).protocols]
        raise ValueError(f"{key} speaks Protocol {'/'.join(spec.protocols)}, not {protocol}; "
                         f"Protocol {protocol} models: {', '.join(serving)}" + (f" (and beside them: {', '.join(also)})" if also else ""))
    return key


def parse_servo_spec(text: str, ids: list[int] | None = None, *, protocol: str = "2.0",
                     also: tuple[str, ...] = ()) -> list[tuple[int, str]]:
    """(ID, model key) per servo, in the order written; ``ValueError`` naming the mistake.

    ``ids``: the IDs a bare ``MODEL`` applies to (``--ids``); with the per-ID form it must be None.
    ``also``: models of another protocol accepted beside ``protocol``'s (a bus mixing protocols).
    An ID may be given twice only to models of different protocols (each protocol has its own IDs).
    """
    text = text.strip()
    if not text:
        raise ValueError("empty servo list; write MODEL or IDS:MODEL[,IDS:MODEL...], e.g. 1-5:xm430-w350,6:xl330-m077")
    if ":" not in text:
        if ids is None:
            raise ValueError(f"{text!r} names no IDs: give --ids, or write IDS:MODEL")
        key = _model_key(text, protocol, also)
        out = [(servo_id, key) for servo_id in ids]
    else:
        if ids is not None:
            raise ValueError("--ids and a per-ID --servo list both name the IDs; give one of them")
        out = []
        pending: list[str] = []
        for part in text.split(","):
            if ":" not in part:
                pending.append(part)
                continue
            id_text, _, model_text = part.partition(":")
            if not model_text.strip():
                raise ValueError(f"{part!r} names no model after the colon")
            key = _model_key(model_text, protocol, also)
            for servo_id in parse_ids(",".join(pending + [id_text])):
                out.append((servo_id, key))
            pending = []
        if pending:
            raise ValueError(f"IDs {','.join(pending)!r} at the end have no model; write IDS:MODEL")
    seen: set[tuple[int, bool]] = set()
    for servo_id, key in out:
        native = protocol in model(key).protocols
        if (servo_id, native) in seen:
            raise ValueError(f"ID {servo_id} is given two models")
        if native and not 0 <= servo_id <= MAX_ID2:
            raise ValueError(f"ID {servo_id} is outside 0..{MAX_ID2} (Protocol 2.0)")
        seen.add((servo_id, native))
    return out
