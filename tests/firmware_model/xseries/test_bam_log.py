"""BAM pendulum logs: the real XL330 files read into arrays; malformed files refused with a ValueError that says why."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from firmware_model.xseries.bam_log import read_bam_log

REAL = Path(__file__).resolve().parents[3] / ".." / "shared" / "reference" / "real-xl330"


def _entry(t: float, **over) -> dict:
    entry = dict(position=0.0, speed=0.0, load=0, input_volts=7.3, temp=29, timestamp=t, goal_position=0.1, torque_enable=True)
    return entry | over


def _write(tmp_path: Path, data, name: str = "log.json") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data), encoding="utf-8")
    return path


def _log(entries=None, **over) -> dict:
    data = dict(mass=0.49, length=0.1, kp=100, vin=7.4, motor="xl330", trajectory="sin_sin",
                entries=entries if entries is not None else [_entry(0.0), _entry(0.005, load=65530), _entry(0.01, load=12)])
    return data | over


def test_a_written_log_reads_back_with_signed_pwm(tmp_path):
    log = read_bam_log(_write(tmp_path, _log()))
    assert log.kp == 100 and log.supply_v == 7.4 and log.mass_kg == 0.49 and log.length_m == 0.1 and log.arm_mass_kg == 0.0
    assert log.present_pwm.tolist() == [0, -6, 12]
    assert log.time_s.tolist() == [0.0, 0.005, 0.01] and log.torque_enable.all()
    assert log.inertia_kg_m2 == pytest.approx(0.49 * 0.01)
    assert log.gravity_moment_nm(9.81) == pytest.approx(0.49 * 9.81 * 0.1)


def test_arm_mass_under_either_key_and_the_later_duty_format(tmp_path):
    log = read_bam_log(_write(tmp_path, _log(**{"arm-mass": 0.03})))
    assert log.arm_mass_kg == 0.03 and log.inertia_kg_m2 == pytest.approx((0.49 + 0.01) * 0.01)
    entries = [_entry(0.0, load=0.5), _entry(0.005, load=-0.25)]
    assert read_bam_log(_write(tmp_path, _log(entries, arm_mass=0.02))).present_pwm.tolist() == [442, -221]


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ("{not json", "not a readable JSON log"),
        ("[1, 2]", "JSON object"),
        (_log(kp=None), "'kp' must be a finite number"),
        ({k: v for k, v in _log().items() if k != "vin"}, "missing 'vin'"),
        (_log(length=0.0), "length and vin > 0"),
        (_log(kp=12.5), "kp a register value"),
        (_log(entries=[_entry(0.0)]), "at least two samples"),
        (_log(entries=[_entry(0.0), {k: v for k, v in _entry(0.1).items() if k != "position"}]), "entry 1 has no 'position'"),
        (_log(entries=[_entry(0.0), _entry(0.1, speed="fast")]), "entry 1 'speed' must be a finite number"),
        (_log(entries=[_entry(0.0), _entry(0.1, torque_enable="yes")]), "'torque_enable' must be true/false"),
        (_log(entries=[_entry(0.1), _entry(0.1)]), "timestamps must increase"),
        (_log(entries=[_entry(0.0), _entry(0.1, load=70000)]), "0..65535"),
        (_log(entries=[_entry(0.0), _entry(0.1, load=900)]), "beyond full scale"),
        (_log(entries=[_entry(0.0), _entry(0.1, load=1.5)]), "duty and must lie in -1..1"),
        # numbers a float cannot hold, and a pendulum no horn carries (each overflowed with a traceback)
        (_log(kp=10**400), "'kp' is too large to be a number"),
        (_log(length=1e200), "length at most 10 m"),
        (_log(kp=1e9), "kp a Position P Gain"),
        (_log(vin=100.0), "vin at most 25.5 V"),
    ],
)
def test_malformed_logs_are_refused_saying_why(tmp_path, data, message):
    with pytest.raises(ValueError, match=message) as info:
        read_bam_log(_write(tmp_path, data))
    assert "log.json" in str(info.value)


def test_a_missing_file_is_a_value_error(tmp_path):
    with pytest.raises(ValueError, match="not a readable JSON log"):
        read_bam_log(tmp_path / "absent.json")


@pytest.mark.skipif(not REAL.is_dir(), reason=f"real XL330 logs not found in {REAL} (third-party data, not in the project)")
def test_the_real_xl330_logs_read_as_their_readme_says():
    """Eight logs, kp 100 and 400, mass 0.49 kg at 0.1 m, 7.4 V; lift_and_drop has its torque off for some 1,100 samples;
    Present PWM within full scale, and negative (wrapped in the file) wherever the shaft is held below the goal."""
    files = sorted(REAL.glob("xl330_kp*_*.json"))
    assert len(files) == 8
    for path in files:
        log = read_bam_log(path)
        assert log.kp in (100, 400) and f"kp{log.kp}_{log.trajectory}" in path.stem
        assert (log.mass_kg, log.length_m, log.supply_v) == (0.49, 0.1, 7.4)
        assert 5.9 < log.time_s[-1] - log.time_s[0] < 6.1
        off = int(np.count_nonzero(~log.torque_enable))
        assert (1000 < off < 1200) if log.trajectory == "lift_and_drop" else off == 0
        assert np.abs(log.present_pwm).max() <= 885
        below = log.torque_enable & (log.goal_position_rad < log.position_rad - 0.05)
        assert np.all(log.present_pwm[below] < 0)
