"""Servo families the workflow diagnoses: each one's simulator, effect library and shared base parameters.

Why it exists: the search (:mod:`.search`), the selection (:mod:`.selection`) and the verdict
(:mod:`.verdict`) never look at what servo a trace is from; they ask a simulator what candidate models
would read and choose among a library's effects.  Which simulator and which library is this table,
keyed by the trace's ``servo`` metadata (:attr:`.trace.Trace.servo`): the AX-12's batched compliance
model (:mod:`.batch`) or the X-series firmware over its physics (:mod:`.xreplay`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..params import ServoParams
from ..units import RAD_PER_POSITION_UNIT
from ..xseries.firmware import PULSE_RAD
from .effects import BASE_PARAMS, LIBRARY, X_BASE_PARAMS, X_LIBRARY, Effect, Param
from .evaluate import Evaluator
from .trace import Trace
from .xreplay import XEvaluator

__all__ = ["Family", "FAMILIES", "family_of"]


@dataclass(frozen=True)
class Family:
    """What the workflow needs to diagnose one servo family."""

    name: str
    library: dict[str, Effect]
    #: Re-fitted with every candidate; each one's null is the starting parameters' attribute of that name.
    base_params: tuple[Param, ...]
    #: (trace, starting parameters) -> an :class:`.evaluate.Evaluator` (or one with its interface).
    evaluator: Callable[[Trace, object], Evaluator]
    #: The starting parameters when none are given (None: the evaluator builds them from the trace).
    default_params: Callable[[], object]
    #: One unit of the trace's ``present_position``, rad.
    position_unit_rad: float = float(RAD_PER_POSITION_UNIT)


FAMILIES = {
    "ax": Family("ax", LIBRARY, BASE_PARAMS, Evaluator, ServoParams),
    "x": Family("x", X_LIBRARY, X_BASE_PARAMS, XEvaluator, lambda: None, float(PULSE_RAD)),
}


def family_of(trace: Trace) -> Family:
    """The family of ``trace`` (its ``servo`` metadata; the AX-12 when absent)."""
    return FAMILIES[trace.servo]
