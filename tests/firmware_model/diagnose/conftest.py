"""The synthetic diagnoses test_search.py and test_search_state.py look at, made once for both.

Both files need the same two diagnoses (the ``extra_inertia`` and the
``compliance_deadband`` trace, seed 7), and test_search_state.py needs each of
its three made in two fresh processes in opposite orders.  So two child
processes make everything: each starts with the three order cases (one in the
order listed, the other reversed), then diagnoses its half of test_search.py's
other cases.  test_search.py reads its diagnoses from them and
test_search_state.py compares the two orders; the parallel pass runs the two
files in one worker (tests/conftest.py, SCHEDULED_TOGETHER), which makes this
fixture once.
"""

from __future__ import annotations

import json
import pickle
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from firmware_model.diagnose.effects import LIBRARY

ROOT = Path(__file__).resolve().parents[3]

#: test_search.py's traces are 10 s of the reference excitation; Stribeck friction's 14 s, the last 6 s the
#: breakaway block (total seconds, of which breakaway block).
SEARCH_DURATION_S = 10.0
BREAKAWAY_S = {"stribeck_friction": (14.0, 6.0)}

#: Every diagnosis test_search.py looks at: key -> (hidden effects, seed); the slowest first, to balance the
#: two processes.
SEARCH_CASES = {
    "delay+extra_inertia": (("delay", "extra_inertia"), 2),
    **{name: ((name,), 7) for name in ("compliance_deadband", "stribeck_friction", "extra_inertia")},
    **{name: ((name,), 7) for name in LIBRARY},
    "cogging": (("cogging",), 5),
    "clean": ((), 12),
}

def search_case(hidden_names: tuple[str, ...], seed: int) -> tuple:
    """A SEARCH_CASES case in ORDER_CASES' form: a clean recording, the whole library, the default servo."""
    single = len(hidden_names) == 1
    duration_s, block_s = BREAKAWAY_S.get(hidden_names[0], (SEARCH_DURATION_S, 0.0)) if single else (SEARCH_DURATION_S, 0.0)
    return list(hidden_names), seed, duration_s, block_s, False, None, 1.0


#: test_search_state.py's three, made in both orders: key -> (hidden effects, seed, duration s, breakaway block s,
#: live recording, effects searched (None: all), acceleration scale of the servo that made the trace and of the
#: model it is diagnosed with).  The first two are test_search.py's cases of the same key, made once for both.
ORDER_CASES = {
    "extra_inertia": search_case(*SEARCH_CASES["extra_inertia"]),
    "compliance_deadband": search_case(*SEARCH_CASES["compliance_deadband"]),
    "live extra_inertia, faster servo": (["extra_inertia"], 7, 10.0, 0.0, True,
                                         ["extra_inertia", "coulomb_friction", "backlash"], 1.5),
}


#: Diagnoses cases in the order given (argv[1], JSON [[key, case], ...]); pickles [(key, result), ...] to argv[2],
#: a result being (summary, measured position, Diagnosis) or the exception the case raised.
CHILD = r"""
import hashlib, json, pickle, sys
from dataclasses import replace
import numpy as np
from firmware_model.diagnose.search import diagnose
from firmware_model.diagnose.synthetic import draw_effect, make_trace
from firmware_model.params import ServoParams

def run(hidden_names, seed, duration_s, breakaway_s, live, effects, accel_scale):
    rng = np.random.default_rng(seed + 100_000)
    hidden = {n: draw_effect(n, rng) for n in hidden_names}
    base = ServoParams()
    params = replace(base, max_acceleration_rad_s2=base.max_acceleration_rad_s2 * accel_scale)
    trace, _ = make_trace(hidden, seed, duration_s, params=params, breakaway_s=breakaway_s, live=live)
    d = diagnose(trace, None if accel_scale == 1.0 else params, progress=lambda m: None, effects=effects)
    onsets = d.nuisance.onsets
    summary = {
        "named": d.named,
        "values": [c.values for c in d.accepted],
        "delta_bic": [c.delta_bic for c in d.accepted],
        "confidence": [c.confidence for c in d.accepted],
        "round_bics": [[(c.effect, c.delta_bic) for c in r] for r in d.rounds],
        "base": d.base,
        "hold_phase_s": d.nuisance.hold_phase_s,
        "onsets": None if onsets is None else np.asarray(onsets).tolist(),
        "gaps_before": d.gaps_before,
        "gaps_after": d.gaps_after,
        "unexplained": d.unexplained,
        "sim_after_sha256": {ch: hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()
                             for ch, v in d.sim_after.items()},
    }
    return json.loads(json.dumps(summary)), trace["present_position"], d

out = []
for key, case in json.loads(sys.argv[1]):
    try:
        out.append((key, run(*case)))
    except Exception as exc:  # reported by the test that needs this case
        out.append((key, exc))
with open(sys.argv[2], "wb") as f:
    pickle.dump(out, f)
"""


@dataclass
class TwoOrders:
    """What the two child processes made."""

    #: ORDER_CASES as made: key -> case.
    order_cases: dict
    #: Each process's results in the order it made them: [(key, (summary, position, Diagnosis) or exception)].
    forward: list
    backward: list
    #: Each process's exit status and the end of its stderr.
    statuses: list[tuple[int, str]]

    def search_result(self, key: str):
        """test_search.py's (measured position, Diagnosis) of ``key``; a case's exception is raised here."""
        for made_key, result in self.forward + self.backward:
            if made_key == key:
                if isinstance(result, Exception):
                    raise result
                return result[1], result[2]
        status = "; ".join(f"exit {code}: {err}" for code, err in self.statuses)
        raise AssertionError(f"{key} was not diagnosed ({status})")


@pytest.fixture(scope="session")
def two_orders(tmp_path_factory) -> TwoOrders:
    """ORDER_CASES in two fresh processes in opposite orders, each then making half the remaining SEARCH_CASES."""
    rest = [(key, search_case(*case)) for key, case in SEARCH_CASES.items() if key not in ORDER_CASES]
    orders = [list(ORDER_CASES.items()) + rest[0::2], list(ORDER_CASES.items())[::-1] + rest[1::2]]
    folder = tmp_path_factory.mktemp("diagnoses")
    outputs = [folder / f"order{i}.pickle" for i in range(2)]
    procs = [subprocess.Popen([sys.executable, "-c", CHILD, json.dumps(order), str(out)], cwd=ROOT,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
             for order, out in zip(orders, outputs)]
    try:
        errors = [p.communicate(timeout=840)[1] for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:  # timed out: end our own children, close their pipes
                p.kill()
                p.communicate()
    made = []
    for out in outputs:
        try:
            with out.open("rb") as f:
                made.append(pickle.load(f))
        except OSError:
            made.append([])
    return TwoOrders(dict(ORDER_CASES), made[0], made[1], [(p.returncode, err[-3000:]) for p, err in zip(procs, errors)])
