"""A diagnosis is a function of its trace: the same one, made first in a fresh process and again after others.

Why: the search keeps work across calls within a process (the setpoint paths
of :mod:`firmware_model.diagnose.batch`; the X-series and fit caches live
per evaluator) and runs its fits in threads that pool their simulations.  If
any of that carried a result from one diagnosis into the next, a trace's
verdict would depend on what the process had diagnosed before it: the test
suite's worker processes, a batch run over many recordings and a single CLI
call could name different effects for the same data.

The diagnoses run in two child processes, so nothing the test session did
before (other tests' simulations in this process) counts as "before": one
makes three diagnoses in a row, the other the same three in the opposite order,
and each diagnosis must come out the same in both.  The three: the suite's
``extra_inertia`` trace (seed 7; with nothing before it in one process and
after the two others in the other), a compliance dead band, and an inertia trace
recorded live (command times not recorded: the search fits them) by a servo
with a higher acceleration limit (other setpoint paths), searched over part
of the library with that limit.  Every output is compared exactly: names,
fitted values, BIC gains, base parameters, recording traits, gaps and the
simulated registers.  Three, not more, because each diagnosis here is made
twice in the suite's time; a path cache keyed without the acceleration limit
(a leak of the kind meant) already shows on the first of them.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

#: Several diagnoses in a row in a child process; its stdout is one JSON list, one summary per diagnosis.
CHILD = r"""
import hashlib, json, sys
from dataclasses import replace
import numpy as np
from firmware_model.diagnose.search import diagnose
from firmware_model.diagnose.synthetic import draw_effect, make_trace
from firmware_model.params import ServoParams

def summary(hidden_names, seed, duration_s, breakaway_s, live, effects, accel_scale):
    rng = np.random.default_rng(seed + 100_000)
    hidden = {n: draw_effect(n, rng) for n in hidden_names}
    base = ServoParams()
    params = replace(base, max_acceleration_rad_s2=base.max_acceleration_rad_s2 * accel_scale)
    trace, _ = make_trace(hidden, seed, duration_s, params=params, breakaway_s=breakaway_s, live=live)
    d = diagnose(trace, None if accel_scale == 1.0 else params, progress=lambda m: None, effects=effects)
    onsets = d.nuisance.onsets
    return {
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

print(json.dumps([summary(*case) for case in json.loads(sys.argv[1])]))
"""

#: (hidden effects, seed, duration s, breakaway block s, live recording, effects searched (None: all),
#: acceleration scale of the servo that made the trace and of the model it is diagnosed with).
CASES = [
    (["extra_inertia"], 7, 10.0, 0.0, False, None, 1.0),
    (["compliance_deadband"], 7, 10.0, 0.0, False, None, 1.0),
    (["extra_inertia"], 7, 10.0, 0.0, True, ["extra_inertia", "coulomb_friction", "backlash"], 1.5),
]


def _diagnose_in_order(cases: list) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", CHILD, json.dumps(cases)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.timeout(900)
def test_diagnosis_does_not_depend_on_earlier_ones():
    """Each diagnosis is the same whichever ran before it in its process (two processes, opposite orders).

    The first of each order is made with nothing before it; it is made last
    in the other, after the two others.  Whichever way a kept result could
    travel (from an earlier diagnosis into a later one), some case sees it in
    one order and not in the other.
    """
    procs = [_diagnose_in_order(CASES), _diagnose_in_order(CASES[::-1])]
    try:
        runs = [p.communicate(timeout=840) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:  # a timed-out or failed comparison: end our own children, close their pipes
                p.kill()
                p.communicate()
    for p, (_, err) in zip(procs, runs):
        assert p.returncode == 0, err[-3000:]
    forward, backward = json.loads(runs[0][0]), json.loads(runs[1][0])[::-1]
    assert forward[0]["named"], forward[0]  # the inertia trace names something: values and rounds to compare
    for case, a, b in zip(CASES, forward, backward):
        for key in a:  # compared as JSON text: a NaN (a phase with no rows) equals itself there
            assert json.dumps(a[key], sort_keys=True) == json.dumps(b[key], sort_keys=True), (case, key, a[key], b[key])
