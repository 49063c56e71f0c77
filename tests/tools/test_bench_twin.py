"""tools/bench_twin.py: bars diagnosed from a twin fitted on the servo's unloaded step, the answer known."""

import pytest
from emu_testkit import load_tool

bench = load_tool("bench_twin")


def test_from_the_twin_of_a_weaker_servo_a_bar_is_named_first_its_interval_holding_it(capsys):
    """The twin puts the weaker gearbox into its supply and rotor inertia, and from it a bar of a third of the
    servo's own inertia is named first with its 95 % interval holding it; the table says so."""
    servo = "weaker gearbox (efficiency 0.68)"
    rows = bench.run(1, 1, servos=[servo], bars=(2.0e-3,))[servo]
    assert bench.summary(rows) == (1, 1, 1, 1), rows
    assert "named first 1/1, named first with the interval holding the bar 1/1" in capsys.readouterr().out


def test_the_twin_of_a_servo_with_more_friction_carries_less_inertia_than_the_servo():
    """Why a twin fitted on one unloaded step misjudges a bar: on that step more friction and less inertia look
    alike, so the twin of a servo with half again the friction takes less rotor inertia than the servo has, an
    error the size of the bars before any bar is put on."""
    servo = "more friction (x1.5)"
    twin, line = bench.twin_of(servo)
    assert twin.total_inertia_kg_m2 < bench.servo_params(servo).total_inertia_kg_m2 - 0.25e-3, line


def test_bad_counts_are_refused(capsys):
    with pytest.raises(SystemExit):
        bench.main(["--seeds", "0"])
    assert "must be >= 1" in capsys.readouterr().err
