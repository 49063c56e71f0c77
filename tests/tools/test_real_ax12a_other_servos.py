"""tools/real_ax12a.py on a step of another servo (the README's AX-18A): replayed with that servo's served model.

No recording is needed: the steps here are the served model's own, read every 20 ms.
"""

import numpy as np
import pytest
from emu_testkit import load_tool

tool = load_tool("real_ax12a")


def _rows(params, moving_speed, every_ms=20.0, head_ms=100.0):
    """The served model's step from 0 to 500 as rows every ``every_ms`` (a Measured, like a Wizard export's)."""
    sim = tool.simulate(params, 0, 500, 1800, moving_speed)
    t_ms = np.arange(0.0, head_ms + len(sim) - 1, every_ms)
    pos = np.array([0.0 if t < head_ms else sim[int(t - head_ms)] for t in t_ms])
    return tool.Measured(t_ms, pos)


def test_only_protocol1_servos_other_than_the_ax12a_are_replayed_with_their_data_sheet_model():
    ax18 = tool.datasheet_servo("AX-18A")
    assert ax18 is not None and ax18.stall_torque_nm(12.0) > tool.ServoParams().stall_torque_nm(12.0)
    assert tool.datasheet_servo("AX-12A") is None  # the AX-12A has its own rows (default, twin)
    assert tool.datasheet_servo("XL-320") is None  # Protocol 2.0: not a Wizard step of this kind
    assert tool.datasheet_servo("AX-99") is None


@pytest.mark.parametrize("moving_speed", [250, 450])
def test_a_speed_limited_step_is_replayed_at_the_moving_speed_its_cruise_shows(moving_speed):
    """Moving Speed is not in the export: a step that cruised well below the motor's top speed was taken with one,
    and the cruise tells which (within a few per cent: the rows are 20 ms apart, rounded)."""
    params = tool.datasheet_servo("AX-18A")
    rows = tool.other_servo_rows(tool.Recording("x.csv", "AX-18A", 0.0, None, None), _rows(params, moving_speed), 500)
    speeds = [speed for _, speed in rows.values()]
    assert speeds[0] == 0 and len(speeds) == 2
    assert abs(speeds[1] - moving_speed) <= 0.04 * moving_speed, speeds


def test_a_full_speed_step_is_replayed_at_full_speed_only():
    params = tool.datasheet_servo("AX-18A")
    rows = tool.other_servo_rows(tool.Recording("x.csv", "AX-18A", 0.0, None, None), _rows(params, 0), 500)
    assert [speed for _, speed in rows.values()] == [0]


def test_a_step_without_a_middle_has_no_cruise():
    with pytest.raises(ValueError, match="cross the middle"):
        tool.cruise_units_s(tool.Measured(np.array([0.0, 20.0, 40.0, 1100.0, 1200.0]), np.array([0.0, 0.0, 500.0, 500.0, 500.0])))


OTHERS = [r for r in tool.RECORDINGS if r.servo != "AX-12A" and tool.datasheet_servo(r.servo) is not None]


@pytest.mark.parametrize("rec", OTHERS, ids=lambda r: r.file)
def test_the_served_servo_replays_a_real_step_of_its_model(rec):
    """A real speed-limited step of another AX servo (the README's AX-18A): the served model at the Moving Speed its
    cruise shows comes into the goal as the real one does, within 3 units of its overshoot and 5 RMS at the best onset."""
    path = tool.DEFAULT_DATA / rec.file
    if not path.exists():
        pytest.skip(f"{rec.file} not found in {tool.DEFAULT_DATA} (kept outside the repository)")
    measured = tool.load(path)
    real = tool.real_features(measured)
    params, speed = list(tool.other_servo_rows(rec, measured, 500).values())[-1]  # at the cruise's speed, if slower
    if speed == 0:
        pytest.skip(f"{rec.file} cruised at the served model's top speed: its supply, which the export does not "
                    "record, sets the move, and the data-sheet model's is not fitted")
    result = tool.evaluate(params, measured, 500, speed)
    assert abs(result["overshoot"] - real["overshoot"]) <= 3, (result["overshoot"], real)
    assert result["rms"] < 5.0


def test_a_bar_on_another_servo_is_replayed_with_the_bar():
    params = tool.datasheet_servo("AX-18A")
    rows = tool.other_servo_rows(tool.Recording("x.csv", "AX-18A", 2.0e-3, None, None), _rows(params, 0), 500)
    assert [p.load_inertia_kg_m2 for p, _ in rows.values()] == [params.load_inertia_kg_m2 + 2.0e-3]


def test_a_step_too_short_to_cruise_is_replayed_at_full_speed_only():
    short = tool.Measured(np.arange(0.0, 1500.0, 20.0), np.where(np.arange(0.0, 1500.0, 20.0) < 100.0, 0.0, 3.0))
    rows = tool.other_servo_rows(tool.Recording("x.csv", "AX-18A", 0.0, None, None), short, 3)
    assert [speed for _, speed in rows.values()] == [0]


def test_the_mx_series_is_not_replayed_with_the_ax_physics():
    """An MX serves on the X-series firmware model: the AX bus's data-sheet physics would not be what it serves."""
    assert tool.datasheet_servo("MX-28") is None
