"""Array namespaces the step functions run on: numpy for many servos, plain floats for one.

Why it exists: a numpy call costs about a microsecond whatever the array
size, so one servo stepped through numpy is limited by call overhead, not
arithmetic.  The step functions in this package are written once against a
small namespace ``xp`` (``where``, ``minimum``, ``maximum``, ``abs``, ``sign``,
``sqrt``, ``exp``, ``cos``, ``copysign``); :data:`NUMPY` runs them on arrays of N servos and
:data:`SCALAR` on Python floats, several times faster for N = 1.  Both give
the same numbers (tests compare them).  Rules for step code: no ``~``, ``and``,
``or``, ``not`` or ``if`` on values; combine masks with ``&`` and ``|``.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

__all__ = ["NUMPY", "SCALAR"]


def _where(cond, a, b):
    return a if cond else b


def _sign(x):
    return float((x > 0) - (x < 0))


#: numpy itself: step functions act on arrays of shape (N,).
NUMPY = SimpleNamespace(
    name="numpy",
    where=np.where,
    minimum=np.minimum,
    maximum=np.maximum,
    abs=np.abs,
    sign=np.sign,
    sqrt=np.sqrt,
    exp=np.exp,
    cos=np.cos,
    rint=np.rint,
    floor=np.floor,
    copysign=np.copysign,
)

#: The same operations on Python floats and bools, for a single servo.
SCALAR = SimpleNamespace(
    name="scalar",
    where=_where,
    minimum=min,
    maximum=max,
    abs=abs,
    sign=_sign,
    sqrt=math.sqrt,
    exp=math.exp,
    cos=math.cos,
    rint=lambda x: float(round(x)),
    floor=lambda x: float(math.floor(x)),
    copysign=math.copysign,
)
