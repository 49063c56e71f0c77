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
and each diagnosis must come out the same in both.  The three (conftest.py's
ORDER_CASES): the suite's ``extra_inertia`` trace (seed 7; with nothing before
it in one process and after the two others in the other), a compliance dead
band, and an inertia trace recorded live (command times not recorded: the
search fits them) by a servo with a higher acceleration limit (other setpoint
paths), searched over part of the library with that limit.  Every output is
compared exactly: names, fitted values, BIC gains, base parameters, recording
traits, gaps and the simulated registers.  Three, not more: a path cache keyed
without the acceleration limit (a leak of the kind meant) already shows on the
first of them.  The same two processes then make test_search.py's other
diagnoses (the first two here are two of its cases), after these.
"""

import json

import pytest


@pytest.mark.timeout(900)
def test_diagnosis_does_not_depend_on_earlier_ones(two_orders):
    """Each diagnosis is the same whichever ran before it in its process (two processes, opposite orders).

    The first of each order is made with nothing before it; it is made last
    in the other, after the two others.  Whichever way a kept result could
    travel (from an earlier diagnosis into a later one), some case sees it in
    one order and not in the other.
    """
    for code, err in two_orders.statuses:
        assert code == 0, err
    n = len(two_orders.order_cases)
    forward, backward = two_orders.forward[:n], two_orders.backward[:n][::-1]
    assert [key for key, _ in forward] == [key for key, _ in backward] == list(two_orders.order_cases)
    for _, result in forward + backward:
        if isinstance(result, Exception):
            raise result
    assert forward[0][1][0]["named"], forward[0]  # the inertia trace names something: values and rounds to compare
    for (key, (a, _, _)), (_, (b, _, _)) in zip(forward, backward):
        for field in a:  # compared as JSON text: a NaN (a phase with no rows) equals itself there
            assert json.dumps(a[field], sort_keys=True) == json.dumps(b[field], sort_keys=True), \
                (two_orders.order_cases[key], field, a[field], b[field])
