"""The one params.toml the diagnosis writes serves the fitted twin: base parameters and every named effect."""

import numpy as np
import pytest

from firmware_model.diagnose.batch import null_knobs
from firmware_model.diagnose.effects import LIBRARY, apply_effects
from firmware_model.diagnose.output import BASE_FIELD_EFFECTS, EFFECT_FIELDS, fitted_effects, write_outputs
from firmware_model.diagnose.replay import replay
from firmware_model.diagnose.search import diagnose
from firmware_model.diagnose.synthetic import make_trace
from firmware_model.params import ServoEffects, ServoParams


def test_every_library_effect_has_a_place_in_the_params_file():
    assert set(EFFECT_FIELDS) | set(BASE_FIELD_EFFECTS) == set(LIBRARY)
    assert not set(EFFECT_FIELDS) & set(BASE_FIELD_EFFECTS)


@pytest.mark.parametrize("effect", sorted(EFFECT_FIELDS))
def test_fitted_effects_carry_the_fitted_values(effect):
    values = {p.name: p.hidden[1] for p in LIBRARY[effect].params}
    if effect == "sensor_offset_gain":  # its hidden range is the gain's distance from 1
        values["position_gain"] = 1.0 + values["position_gain"]
    knobs = apply_effects(null_knobs(ServoParams()), {effect: values})
    effects, notes = fitted_effects([effect], knobs)
    assert effects.present() == {field: knobs[knob] for field, knob in EFFECT_FIELDS[effect].items()} and not notes
    assert fitted_effects([], knobs)[0] == ServoEffects()  # only named effects go in


def test_a_twins_effects_are_kept_and_a_refit_one_is_written_as_its_total():
    """Diagnosing from a twin's params.toml: its [effects] stay in the new file; more play adds to its play."""
    start = ServoEffects(backlash_rad=0.02, arm_weight_moment_nm=0.2)
    twin = ServoParams(effects=start)
    assert fitted_effects([], null_knobs(twin), start)[0] == start
    knobs = apply_effects(null_knobs(twin), {"backlash": {"backlash_rad": 0.01}})
    effects, _ = fitted_effects(["backlash"], knobs, start)
    assert effects.present() == pytest.approx({"backlash_rad": 0.03, "arm_weight_moment_nm": 0.2})


def test_a_value_that_cannot_be_served_is_pinned_with_a_note():
    """A negative delay (the reading ahead of the shaft) is served as none, and the note says so."""
    knobs = apply_effects(null_knobs(ServoParams()), {"delay": {"delay_s": -0.004}})
    effects, notes = fitted_effects(["delay"], knobs)
    assert effects == ServoEffects() and "sensing_delay_s" in notes[0] and "served as 0" in notes[0]


@pytest.fixture(scope="module")
def fonts_loaded():
    """Matplotlib keeps the font files it loads open for the life of the process (a cache, not a leak): load them
    before the per-test leak check looks (module scope is set up first)."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="x")
    ax.legend()
    fig.savefig(io.BytesIO(), format="png")
    plt.close(fig)


@pytest.fixture(scope="module")
def written(tmp_path_factory, fonts_loaded):
    """A trace with two hidden effects, diagnosed, its outputs written: (trace, diagnosis, folder)."""
    hidden = {"torque_saturation": {"drive_ceiling": 0.5}, "sensor_offset_gain": {"position_offset_units": 6.0,
                                                                                   "position_gain": 1.0}}
    trace, _ = make_trace(hidden, seed=5, duration_s=8.0)
    d = diagnose(trace, effects=["torque_saturation", "sensor_offset_gain", "compliance_deadband"])
    assert set(d.named) == set(hidden)
    out = tmp_path_factory.mktemp("outputs")
    write_outputs(trace, d, out, source="synthetic")
    return trace, d, out


def test_params_file_serves_the_fitted_twin(written):
    """Diagnose a trace with hidden effects, write the outputs, load params.toml into the physical model:
    it reads exactly what the diagnosis's fitted model read, every register, every row."""
    trace, d, tmp_path = written
    assert not (tmp_path / "effects.toml").exists()
    twin = ServoParams.from_toml(tmp_path / "params.toml")
    assert set(twin.effects.present()) == {"drive_ceiling_fraction", "position_offset_units", "position_gain"}
    served = replay(trace, twin)
    for ch in ("present_position", "present_speed", "present_load"):
        np.testing.assert_array_equal(served[ch], d.sim_after[ch], err_msg=ch)
    plain_gap = np.sqrt(np.mean((replay(trace)["present_position"] - trace["present_position"]) ** 2.0))
    twin_gap = np.sqrt(np.mean((served["present_position"] - trace["present_position"]) ** 2.0))
    assert twin_gap < 0.1 * plain_gap


def test_the_report_gives_every_candidates_fit_accepted_or_not(written):
    """A candidate the verdict turned down still says what it fitted and how sure that was."""
    _, d, folder = written
    rows = (folder / "report.md").read_text(encoding="utf-8").splitlines()
    rejected = [c for r in d.rounds for c in r if not c.accepted]
    assert rejected  # a round ends when no candidate passes
    for no, cands in enumerate(d.rounds, 1):
        for c in cands:
            row = next(r for r in rows if r.startswith(f"| {no} | {c.effect} | "))
            for k, v in c.values.items():
                assert f"{k} {v:.4g} ± {c.uncertainty[k]:.2g}" in row, row


def test_a_supply_the_trace_does_not_hold_is_written_as_assumed(written):
    """A trace without a voltage column is fitted at the parameters' supply: params.toml called that "the
    recording's supply", which a reader then trusted over the servo's own."""
    trace, _, folder = written
    assert not trace.has("voltage")
    header = (folder / "params.toml").read_text(encoding="utf-8")
    assert "# supply_voltage_v: assumed 9.6 V: the recording does not hold its supply" in header, header
    assert "the recording's supply" not in header


def test_the_served_supply_is_the_recordings_with_a_note_where_it_cannot_be():
    """One supply for the served servo: the recording's median, said when it varied or lies outside the model's range."""
    from firmware_model.diagnose.output import fitted_supply_v
    from firmware_model.diagnose.trace import Trace

    def trace(volts):
        n = len(volts)
        return Trace({"t": np.arange(n) * 0.01, "present_position": np.full(n, 512), "goal_position": np.full(n, 512),
                      "moving_speed": np.zeros(n), "voltage": np.asarray(volts)})

    params = ServoParams()
    assert fitted_supply_v(trace([110] * 5), params) == (11.0, [])
    volts, notes = fitted_supply_v(trace([100, 110, 110, 120, 120]), params)
    assert volts == 11.0 and "varies (10.0-12.0 V)" in notes[0]
    volts, notes = fitted_supply_v(trace([130] * 5), params)
    assert volts == params.max_supply_voltage_v and "outside the model's" in notes[0]


@pytest.mark.parametrize("extra", [0.01, -1e-4, -0.0015])
def test_a_fitted_extra_inertia_is_served_whole_even_below_the_loads(extra):
    """A servo lighter than the model by more than the load's 1.35e-4 kg m^2: the load was pinned at 0 and the twin
    served heavier than fitted (7 position units off the fit's own simulation).  The rest comes off the reflected
    rotor inertia; the params file's header says so."""
    from types import SimpleNamespace

    from firmware_model.diagnose.batch import sample, simulate
    from firmware_model.diagnose.output import fitted_inertia, fitted_params
    from firmware_model.diagnose.schedule import compile_schedule

    p = ServoParams()
    knobs = apply_effects(null_knobs(p), {"extra_inertia": {"extra_inertia_kg_m2": extra}})
    twin = fitted_params(SimpleNamespace(knobs=knobs, named=["extra_inertia"]), p)
    assert twin.total_inertia_kg_m2 == pytest.approx(p.total_inertia_kg_m2 + extra, rel=1e-12)
    assert twin.load_inertia_kg_m2 >= 0.0 and twin.rotor_inertia_reflected_kg_m2 > 0.0
    notes = fitted_inertia(extra, p)[1]
    assert bool(notes) == (extra < -p.load_inertia_kg_m2) and all("rotor" in n for n in notes)
    trace, _ = make_trace({}, 3, 4.0, base_spread=False)
    k1 = {k: np.array([v]) for k, v in knobs.items()}
    sch = compile_schedule(trace)
    batch = sample(sch, simulate(sch, p, k1, 1), p, k1)
    served = replay(trace, twin)
    assert np.max(np.abs(served["present_position"] - batch["present_position"][:, 0])) <= 1
