#!/usr/bin/env python3
"""The X-series physics against real XL330 pendulum logs: fit at one Position P Gain, predict the others.

Why it exists: the X-series motor and friction model (``firmware_model.xseries.physics``) is built from
data sheets; Rhoban's BAM logs of a real XL330 swinging a pendulum (``../shared/reference/real-xl330/``,
see its README) are what it can be held to.  Following BAM (github.com/Rhoban/bam, ``bam/fit.py`` with
``--validation_kp``; Duclusaud, Passault et al., ICRA 2025), the physics is fitted on the logs at one gain
(``--fit-kp``, 100) and scored on the logs at every other gain in the folder, which it has not seen, by
the mean absolute error of Present Position in a closed-loop replay: each log's goals go through this
project's X-series firmware model (``firmware_model.xseries.firmware``) with the log's Position P Gain,
torque off where the log has it off, the pendulum's mass and length and the log's supply.

Two friction models, fitted the same way (``firmware_model.diagnose.bam_fit``: an equation-error least
squares on the logs' Present PWM for a start, then least squares on position through the replay):
the baseline Coulomb + viscous (BAM's M1) and the model, whose gear friction grows with the torque the
gears carry and is larger at rest (BAM's M5).  The goal: the model's MAE on the logs it was not fitted
on at most half the baseline's.  The table also shows the start (the equation-error fit alone), which is
not fitted on positions at all.

Usage::

    python tools/xl330_fit.py [--data DIR] [--fit-kp 100] [--max-evaluations 400] [--plot tools/figures/xl330_fit.png]

``--plot`` writes a figure of the predictions (the logs at the other gains): per log, the measured
Present Position, the model's and the baseline's closed-loop replays (position fits), each fit's MAE in
the legend, torque-off stretches shaded (matplotlib, Agg; no display needed).

Exit status 2 with a message if the data folder or its logs at the fitting gain are missing.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from ax12emu.cli.arg_types import OneLineParser, nonnegative_int, positive_int  # noqa: E402
from ax12emu.protocol.servo_models import model as servo_model  # noqa: E402
from firmware_model.diagnose.bam_fit import BASELINE, MODEL, fit, initial_values, physics_from, position_mae  # noqa: E402
from firmware_model.xseries.bam_log import PendulumLog, read_bam_log  # noqa: E402
from firmware_model.xseries.bam_replay import replay_positions  # noqa: E402
from firmware_model.xseries.firmware import XFirmware  # noqa: E402
from firmware_model.xseries.physics import XPhysics, XPhysicsParams  # noqa: E402

#: Where the logs live, relative to the repository (never copied into it).
DEFAULT_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "reference" / "real-xl330"
#: BAM's XL330 is the XL330-M288-T (its README's list of identified servos).
MODEL_KEY = "xl330-m288"
#: The XL330's position controller output is half the e-manual's P/128 conversion (measured on these logs;
#: ``XFirmware``'s ``position_output_scale``); Present Current in 1 mA.
POSITION_OUTPUT_SCALE = 0.5
CURRENT_UNIT_A = 0.001
GOAL_RATIO = 0.5


def datasheet_params() -> XPhysicsParams:
    """The XL330-M288's physics from its e-manual ratings (the project's default, before any fit)."""
    physical = servo_model(MODEL_KEY).physical
    ratings = [(r.voltage_v, r.stall_torque_nm, r.stall_current_a, r.no_load_speed_rpm) for r in physical.ratings]
    return XPhysicsParams.from_datasheet(gear_ratio=physical.gear_ratio, ratings=ratings)


def make_firmware(physics: XPhysics) -> XFirmware:
    """The X-series firmware model as an XL330 over ``physics``."""
    return XFirmware(physics, current_unit_a=CURRENT_UNIT_A, position_output_scale=POSITION_OUTPUT_SCALE)


def read_logs(folder: Path) -> dict[int, list[PendulumLog]]:
    """Every ``xl330_kp*_*.json`` in ``folder``, by Position P Gain, each gain's logs in name order."""
    by_kp: dict[int, list[PendulumLog]] = {}
    for path in sorted(folder.glob("xl330_kp*_*.json")):
        log = read_bam_log(path)
        by_kp.setdefault(log.kp, []).append(log)
    return by_kp


def _row(name: str, base: float, model: float) -> str:
    return f"{name:<40} {1e3 * base:>9.1f} {1e3 * model:>9.1f} {model / base:>7.2f}"


def _plot(held: list[PendulumLog], fits: dict, out: Path):
    """The held-out logs, measured against each fit's replay (``fits``: label to its ``FitResult``); returns the figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    styles = {"model": dict(color="tab:blue", lw=1.3), "baseline": dict(color="tab:red", lw=1.0, ls="--")}
    names = {"model": "model (load-dependent friction)", "baseline": "baseline (Coulomb + viscous)"}
    fig, axes = plt.subplots(len(held), 1, figsize=(9, 2.7 * len(held)), squeeze=False, sharex=True)
    for ax, log in zip(axes[:, 0], held):
        t = log.time_s - log.time_s[0]
        off = ~log.torque_enable.astype(bool)
        if off.any():
            ax.fill_between(t, 0, 1, where=off, color="0.9", transform=ax.get_xaxis_transform(), label="torque off")
        ax.plot(t, log.goal_position_rad, color="0.6", lw=0.8, ls=":", label="goal")
        ax.plot(t, log.position_rad, "k", lw=1.6, label="real XL330 (measured)")
        for label, result in fits.items():
            replayed = replay_positions(log, result.params, make_firmware, gravity_zero_rad=result.gravity_zero_rad)
            mae_mrad = 1e3 * float(np.mean(np.abs(replayed - log.position_rad)))
            ax.plot(t, replayed, **styles[label], label=f"{names[label]}: MAE {mae_mrad:.0f} mrad")
        ax.set_title(f"{log.trajectory}, kp = {log.kp} (predicted: fitted at another gain)", fontsize=9)
        ax.set_ylabel("position, rad")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    axes[-1, 0].set_xlabel("s")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return fig


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of BAM XL330 logs")
    parser.add_argument("--fit-kp", type=nonnegative_int, default=100, help="fit on the logs at this Position P Gain")
    parser.add_argument("--max-evaluations", type=positive_int, default=400,
                        help="cap on replays of the fitting set per model")
    parser.add_argument("--plot", type=Path, default=None, help="write a figure of the predicted logs (needs matplotlib)")
    args = parser.parse_args(argv)
    if not args.data.is_dir():
        print(f"no XL330 logs: {args.data} is not a folder (see ../shared/reference/real-xl330/README.md)", file=sys.stderr)
        return 2
    try:
        by_kp = read_logs(args.data)
    except (ValueError, OSError) as exc:  # a log in the folder that is no BAM log (or unreadable): name it, no traceback
        print(f"xl330_fit.py: error: {exc}", file=sys.stderr)
        return 2
    if args.fit_kp not in by_kp:
        print(f"no logs at kp = {args.fit_kp} in {args.data} (gains there: {sorted(by_kp)})", file=sys.stderr)
        return 2
    train = by_kp[args.fit_kp]
    held = [log for kp in sorted(by_kp) if kp != args.fit_kp for log in by_kp[kp]]
    base = datasheet_params()
    results = {}
    for label, spec in (("baseline", BASELINE), ("model", MODEL)):
        t0 = time.perf_counter()
        start = initial_values(train, spec, base=base)
        result = fit(train, spec, make_firmware, base=base, start=start, max_evaluations=args.max_evaluations)
        start_params, start_zero = physics_from(base, start)
        results[label] = dict(
            result=result,
            start=start,
            fitted_mae=position_mae(train, result.params, result.gravity_zero_rad, make_firmware),
            held_mae=position_mae(held, result.params, result.gravity_zero_rad, make_firmware),
            start_held_mae=position_mae(held, start_params, start_zero, make_firmware),
            start_fitted_mae=position_mae(train, start_params, start_zero, make_firmware),
            seconds=time.perf_counter() - t0,
        )
    default_mae = position_mae(held, base, 0.0, make_firmware)
    b, m = results["baseline"], results["model"]
    print(f"XL330 ({MODEL_KEY}) physics fitted on the {len(train)} logs at kp = {args.fit_kp}, predicting {len(held)} at "
          f"kp = {', '.join(str(kp) for kp in sorted(by_kp) if kp != args.fit_kp)}")
    print("Position MAE, mrad, closed-loop replay through the X-series firmware model")
    print(f"{'log (position fit)':<40} {'baseline':>9} {'model':>9} {'ratio':>7}")
    for k, log in enumerate(train):
        print(_row(f"{log.name} (fitted)", b["fitted_mae"][k], m["fitted_mae"][k]))
    print(_row(f"mean, kp = {args.fit_kp} (fitted)", float(np.mean(b["fitted_mae"])), float(np.mean(m["fitted_mae"]))))
    for k, log in enumerate(held):
        print(_row(f"{log.name} (predicted)", b["held_mae"][k], m["held_mae"][k]))
    held_base, held_model = float(np.mean(b["held_mae"])), float(np.mean(m["held_mae"]))
    print(_row("mean, predicted", held_base, held_model))
    print(_row("equation-error fit alone, fitted", float(np.mean(b["start_fitted_mae"])), float(np.mean(m["start_fitted_mae"]))))
    eq_base, eq_model = float(np.mean(b["start_held_mae"])), float(np.mean(m["start_held_mae"]))
    print(_row("equation-error fit alone, predicted", eq_base, eq_model))
    for label, ratio in (("position fit", held_model / held_base), ("equation-error fit", eq_model / eq_base)):
        print(f"goal, {label}: predicted ratio <= {GOAL_RATIO}: {'met' if ratio <= GOAL_RATIO else 'MISSED'} ({ratio:.2f})")
    print(f"data-sheet default (no fit), predicted: {1e3 * float(np.mean(default_mae)):.1f} mrad")
    for label in ("baseline", "model"):
        r = results[label]["result"]
        values = ", ".join(f"{k} {v:.4g}" for k, v in r.values.items())
        print(f"{label}: {values}; k_t {r.params.torque_constant_nm_a:.4g} N m/A, R {r.params.resistance_ohm:.4g} ohm "
              f"(data sheet); {r.evaluations} evaluations, {results[label]['seconds']:.0f} s")
    if args.plot is not None:
        _plot(held, {label: results[label]["result"] for label in ("model", "baseline")}, args.plot)
        print(f"wrote {args.plot}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
