"""The batched simulator reproduces PhysicalModel's replay exactly, and every effect's null value is the base model."""

import dataclasses

import numpy as np
import pytest

from firmware_model.diagnose.batch import EFFECT_FIELD_KNOBS, null_knobs, sample, simulate
from firmware_model.diagnose.effects import LIBRARY, apply_effects
from firmware_model.diagnose.excitation import commands_at, program
from firmware_model.diagnose.replay import replay
from firmware_model.diagnose.schedule import compile_schedule
from firmware_model.diagnose.trace import Trace
from firmware_model.params import ServoEffects, ServoParams


def _trace(duration=6.0):
    rng = np.random.default_rng(4)
    t = np.arange(0, duration, 0.01) + rng.uniform(0, 0.004, int(duration * 100))
    c = commands_at(t, program(duration))
    return Trace(dict(t=t, present_position=np.full(len(t), 512), **c))


def test_batch_equals_physical_model_replay():
    """All registers from the batched simulator at null knobs equal PhysicalModel's, row by row."""
    tr = _trace()
    p = ServoParams()
    ref = replay(tr, p)
    s = compile_schedule(tr)
    out = sample(s, simulate(s, p, {}, 3), p, columns=[1])
    for ch in ("present_position", "present_speed", "present_load"):
        np.testing.assert_array_equal(out[ch][:, 0], ref[ch])
    assert np.ptp(ref["present_position"]) > 300  # the trace really moves


def test_an_unrounded_sample_is_the_rounded_one_before_its_rounding():
    """A prediction reads the registers unrounded (floats); rounded, they are the recording's whole units."""
    tr = _trace()
    p = ServoParams()
    s = compile_schedule(tr)
    rec = simulate(s, p, {}, 1)
    whole, exact = sample(s, rec, p), sample(s, rec, p, rounded=False)
    for ch, step in (("present_position", 1.0), ("present_speed", 1.0), ("present_load", 1.0)):
        assert whole[ch].dtype.kind == "i" and exact[ch].dtype.kind == "f"
        np.testing.assert_array_equal(np.rint(exact[ch]), whole[ch])
        assert np.abs(exact[ch] - whole[ch]).max() <= step / 2
    assert np.any(exact["present_position"] != whole["present_position"])


@pytest.mark.parametrize("name", list(LIBRARY))
def test_null_value_is_the_base_model(name):
    """Each effect at its null values maps onto exactly the base knobs."""
    base = null_knobs(ServoParams())
    assert apply_effects(base, {name: LIBRARY[name].null_values()}) == base


#: A twin carrying every effect the batch can simulate ([effects] in its params.toml).
TWIN_EFFECTS = ServoEffects(backlash_rad=0.02, sensing_delay_s=0.012, drive_ceiling_fraction=0.8,
                            arm_weight_moment_nm=0.2, extra_compliance_margin_units=2.0, position_offset_units=-3.0,
                            position_gain=1.02)


def test_a_twins_effects_are_its_null_knobs():
    """A fit started from a params file simulates its [effects] as served, and each library effect is added to them."""
    twin = dataclasses.replace(ServoParams(), effects=TWIN_EFFECTS)
    base = null_knobs(twin)
    for field_name, knob in EFFECT_FIELD_KNOBS.items():
        assert base[knob] == getattr(TWIN_EFFECTS, field_name), field_name
    for name in LIBRARY:
        assert apply_effects(base, {name: LIBRARY[name].null_values()}) == base, name
    more = apply_effects(base, {"backlash": {"backlash_rad": 0.01}, "delay": {"delay_s": 0.005}})
    assert more["backlash_rad"] == pytest.approx(0.03) and more["delay_s"] == pytest.approx(0.017)


def test_batch_with_a_twins_effects_equals_the_served_twin():
    """The fit's base model, started from a twin with effects, reads what ``serve --params`` of that twin reads."""
    twin = dataclasses.replace(ServoParams(), effects=TWIN_EFFECTS)
    tr = _trace(4.0)
    schedule = compile_schedule(tr, 1e-3, twin.supply_voltage_v)
    k1 = {k: np.array([v]) for k, v in null_knobs(twin).items()}
    out = sample(schedule, simulate(schedule, twin, k1, 1), twin, k1)
    served = replay(tr, twin)
    for ch in ("present_position", "present_speed", "present_load"):
        np.testing.assert_array_equal(out[ch][:, 0], served[ch], err_msg=ch)
    assert np.sqrt(np.mean((served["present_position"] - replay(tr)["present_position"]) ** 2.0)) > 2.0


def test_a_command_delay_cannot_be_simulated_and_says_so():
    with pytest.raises(ValueError, match="command_delay_s"):
        null_knobs(dataclasses.replace(ServoParams(), effects=ServoEffects(command_delay_s=0.01)))


def test_effects_change_something():
    """Away from the null, every effect changes the knobs (so it can be seen at all)."""
    base = null_knobs(ServoParams())
    for name, e in LIBRARY.items():
        vals = {p.name: p.hidden[1] if p.name != "position_gain" else 1.03 for p in e.params}
        assert apply_effects(base, {name: vals}) != base, name


def test_batch_equals_replay_with_command_times():
    """Command changes sent between readings (``command_t``, before and after their rows) act alike in both."""
    tr = _trace(3.0)
    rows = tr.change_rows()[1:]
    t = tr["t"]
    sent = t.copy()
    sent[rows[::2]] += 0.6 * (t[rows[::2] + 1] - t[rows[::2]])   # after the row's reading
    sent[rows[1::2]] -= 0.4 * (t[rows[1::2]] - t[rows[1::2] - 1])  # before it
    tr = tr.with_columns(command_t=sent)
    p = ServoParams()
    ref = replay(tr, p)
    s = compile_schedule(tr)
    assert not np.array_equal(s.nominal_onsets()[1:], np.floor(t[rows] / 1e-3 + 1e-9))
    out = sample(s, simulate(s, p, {}, 1), p)
    for ch in ("present_position", "present_speed", "present_load"):
        np.testing.assert_array_equal(out[ch][:, 0], ref[ch])


def test_shortcuts_give_the_records_of_stepping_every_step(monkeypatch):
    """Copying runs of resting steps and reusing kept reference paths change no value.

    Varied knobs (play, an arm, friction, a drive ceiling) and per-column onsets, simulated with the
    shortcuts and then with every step stepped and every reference path stepped afresh: equal records.
    """
    from firmware_model.diagnose import batch

    tr = _trace(4.0)
    rows = tr.change_rows()
    tr = tr.with_columns(external_torque_nm=np.where(np.arange(len(tr)) > rows[5], 0.2, 0.0))
    s = compile_schedule(tr)
    p = ServoParams()
    k = 5
    knobs = {"backlash_rad": np.array([0.0, 0.01, 0.0, 0.02, 0.005]),
             "arm_weight_nm": np.array([0.0, 0.0, 0.2, 0.1, 0.0]),
             "coulomb_friction_nm": np.linspace(0.02, 0.08, k), "drive_ceiling": np.array([1.0, 0.6, 1.0, 1.0, 0.8])}
    onsets = s.nominal_onsets()[:, None] + np.array([0, 0, 3, 7, 3])
    onsets[0] = 0
    fast = [simulate(s, p, knobs, k, onsets=on) for on in (None, onsets, onsets)]  # the last reuses kept paths
    rests = np.all(fast[0].angle[1:] == fast[0].angle[:-1], axis=1)
    assert rests.sum() > 4 * batch.REST_CHECK_EVERY  # every shaft rests long enough for runs to be copied
    monkeypatch.setattr(batch, "REST_CHECK_EVERY", s.n_steps + 1)
    monkeypatch.setattr(batch, "_PATHS", {})
    monkeypatch.setattr(batch, "_PATHS_KEPT", 1)
    slow = [simulate(s, p, knobs, k, onsets=on) for on in (None, onsets)]
    for a, b in zip(fast, [slow[0], slow[1], slow[1]]):
        np.testing.assert_array_equal(a.angle, b.angle)
        np.testing.assert_array_equal(a.drive, b.drive)
    assert not np.array_equal(fast[0].angle, fast[1].angle)  # the onsets matter


def test_reference_paths_stepped_by_threads_at_once_are_those_stepped_alone(monkeypatch):
    """The kept reference paths are shared by every simulation in the process: diagnoses run in threads side by
    side extend one path at once.  Each path is stepped by one thread at a time, so the references are those of
    one thread alone (unguarded, threads switching every few steps raised IndexError and BufferError)."""
    import sys
    import threading

    from firmware_model.diagnose import batch

    s = compile_schedule(_trace(6.0))
    p = ServoParams()
    on = s.nominal_onsets()[:, None]
    monkeypatch.setattr(batch, "_PATHS", {})
    alone, _ = batch._reference_units(s, p, on)
    results = []

    def worker(starts):
        starts.wait()
        try:
            results.append(batch._reference_units(s, p, on)[0])
        except Exception as exc:  # noqa: BLE001 - reported by the assertion below
            results.append(exc)

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads switch every few steps of a path, not every 5 ms
    try:
        for _ in range(5):  # each round starts from no kept path, so the threads step the same paths together
            monkeypatch.setattr(batch, "_PATHS", {})
            starts = threading.Barrier(8)
            threads = [threading.Thread(target=worker, args=(starts,)) for _ in range(8)]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
    finally:
        sys.setswitchinterval(interval)
    assert len(results) == 40
    for table in results:
        assert isinstance(table, np.ndarray), table
        np.testing.assert_array_equal(table, alone)
