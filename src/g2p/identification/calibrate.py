"""`g2p-calibrate bags/<run> --out calib.yaml`: identify the simulated rig from a recorded run.

Fits the simulated rig's physical parameters (g2p.sim.calibration) so that, replaying the run's recorded
activations, it reads the recorded joint angles, motor currents and belt travel (g2p.identification.fit);
writes the calibration file the simulator loads (`ros2 run g2p_sim sim --ros-args -p
leg.calibration:=calib.yaml`, or `bringup --set rig.leg.calibration=calib.yaml`) and a report beside it:
the estimates with their 95 % intervals, the parameters the data did not determine, recorded vs simulated
angles before and after, and the joint-angle error on what the fit did not see (the run's attempts, or
the last fifth of its babbling when it has none).

Exit status: 0 written; 1 the fit did not converge (nothing written); 2 bad input (the message names the
file and what is missing).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from g2p.files import write_atomically, write_text_atomically
from g2p.identification.fit import (
    DEFAULT_PARAMETERS,
    Estimate,
    FitConfig,
    FitError,
    FitResult,
    angle_errors_rad,
    fit,
    rmse_rad,
)
from g2p.identification.segments import CalibrationInputError, RecordedRun, Segment, load_recorded_run
from g2p.plant import NOMINAL_TICK_HZ, FloatArray
from g2p.sim.calibration import PARAMETERS, LegCalibration
from g2p.validation import ConfigError

_BELT_PARAMETERS = ("belt_drag_n", "belt_damping_ns_per_m")
# The belt counts as moved when its speed exceeded this at some tick (mm/s).
_BELT_MOVED_MM_S = 1.0
# Without attempts, this share of the babbling is held out.
_HELD_OUT_SHARE = 0.2


@dataclass(frozen=True)
class Calibration:
    """A calibration and how well it replays the recorded run.

    Attributes:
        result: the fit.
        calibration: the calibration file's content.
        rmse_fit_rad: open-loop joint-angle RMSE on the fitted ticks, (model, calibrated) (rad).
        rmse_held_out_rad: the same on the held-out ticks (rad).
        held_out: what was held out.
        errors_before: per-segment angle errors of the model on the held-out ticks, shape (N, 2) each.
        errors_after: the same for the calibrated rig.
        recorded: the held-out recorded angles, shape (N, 2) each.
    """

    result: FitResult
    calibration: LegCalibration
    rmse_fit_rad: tuple[float, float]
    rmse_held_out_rad: tuple[float, float]
    held_out: str
    errors_before: list[FloatArray]
    errors_after: list[FloatArray]
    recorded: list[FloatArray]


def _split(run: RecordedRun, babbling_s: float | None) -> tuple[list[Segment], list[Segment], int, str]:
    """Fitted segments, held-out segments, ticks of the held-out tail of the last fitted one, and a label."""
    babbling = run.babbling
    if babbling_s is not None:
        babbling = [
            s.head(int(np.searchsorted(np.cumsum(s.period_s), babbling_s, side="right"))) for s in babbling
        ]
        babbling = [s for s in babbling if len(s)]
    if run.attempts:
        return babbling, run.attempts, 0, f"{len(run.attempts)} attempts"
    tail = int(len(babbling[-1]) * _HELD_OUT_SHARE)
    return babbling, [], tail, f"the last {tail} babbling ticks"


def calibrate(run: RecordedRun, config: FitConfig, babbling_s: float | None = None) -> Calibration:
    """Fit the simulated rig to a recorded run and measure the result on what the fit did not see.

    Raises:
        FitError: the fit did not converge.
    """
    fitted, held_out, tail, label = _split(run, babbling_s)
    to_fit = fitted if not tail else [*fitted[:-1], fitted[-1].head(len(fitted[-1]) - tail)]
    belt_moved = any(np.any(np.abs(s.belt_velocity_mm_s) > _BELT_MOVED_MM_S) for s in to_fit)
    names = tuple(p for p in config.parameters if belt_moved or p not in _BELT_PARAMETERS)
    result = fit(to_fit, run.leg_config, replace(config, parameters=names))
    skipped = tuple(p for p in config.parameters if p not in names)
    calibration = replace(
        result.calibration,
        undetermined=(*result.calibration.undetermined, *skipped),
        intervals={**result.calibration.intervals, **{p: float("inf") for p in skipped}},
    )
    model = LegCalibration({})
    before = angle_errors_rad(to_fit, run.leg_config, model)
    after = angle_errors_rad(to_fit, run.leg_config, calibration)
    rmse_fit = (rmse_rad(before), rmse_rad(after))
    if tail:  # replay the whole babbling, score its tail
        full = fitted[-1]
        errors = [angle_errors_rad([full], run.leg_config, c)[0][-tail:] for c in (model, calibration)]
        held_before, held_after, recorded = [errors[0]], [errors[1]], [full.position_rad[-tail:]]
    else:
        held_before = angle_errors_rad(held_out, run.leg_config, model)
        held_after = angle_errors_rad(held_out, run.leg_config, calibration)
        recorded = [s.position_rad for s in held_out]
    rmse_held = (rmse_rad(held_before), rmse_rad(held_after))
    calibration = replace(
        calibration,
        fit={
            "bag": str(run.bag),
            "fitted": f"{sum(len(s) for s in to_fit)} babbling ticks",
            "held_out": label,
            "joint_angle_rmse_rad": {
                "fitted": {"model": rmse_fit[0], "calibrated": rmse_fit[1]},
                "held_out": {"model": rmse_held[0], "calibrated": rmse_held[1]},
            },
            "evaluations": result.evaluations,
            "seconds": round(result.seconds, 1),
            "workers": result.workers,
            "interval_blocks": result.blocks,
            "optimizer": result.message,
            "not_fitted_belt_still": list(skipped),
        },
    )
    return Calibration(result, calibration, rmse_fit, rmse_held, label, held_before, held_after, recorded)


def _determined(e: Estimate) -> str:
    """Whether the data determine an estimate, and why not."""
    if e.determined:
        return "yes"
    if not math.isfinite(e.jacobian_interval):
        return "no: nothing recorded moves with it"
    return "no: its interval is wider than half its unit"


def report_markdown(cal: Calibration) -> str:
    """The report's table: estimates with intervals, errors before and after."""
    result = cal.result
    how = (
        f"each the larger of the spread of the same fit on {result.blocks} consecutive stretches of the "
        f"fitted ticks ({result.blocks_converged} of {result.blocks} converged), Student's t times their "
        "standard deviation, and the Jacobian's interval"
        if result.blocks
        else "from the Jacobian at the optimum alone (it assumes independent residuals: too narrow)"
    )
    lines = [
        "# Calibration",
        "",
        f"Fitted on {cal.calibration.fit.get('fitted')}; held out: {cal.held_out}. "
        f"The fit took {result.seconds:.0f} s with {result.workers} worker processes. 95 % intervals: {how}.",
        "",
        "| joint-angle RMSE (deg) | model | calibrated |",
        "| --- | --- | --- |",
        "| fitted | {:.2f} | {:.2f} |".format(*np.degrees(cal.rmse_fit_rad)),
        "| held out | {:.2f} | {:.2f} |".format(*np.degrees(cal.rmse_held_out_rad)),
        "",
        "| parameter | model | estimate | 95 % interval | determined by the data |",
        "| --- | --- | --- | --- | --- |",
    ]
    for e in cal.result.estimates:
        lines.append(
            f"| {e.name} | {e.model_value:.5g} | {e.value:.5g} | +- {e.interval:.2g} | {_determined(e)} |"
        )
    fitted = {e.name for e in cal.result.estimates}
    for name in cal.calibration.undetermined:
        if name not in fitted:
            lines.append(f"| {name} | | not fitted: the belt never moved | | no |")
    return "\n".join(lines) + "\n"


def plot_angles(cal: Calibration, path: Path) -> None:
    """Recorded vs simulated joint angles on the first held-out segment, before and after (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    recorded = cal.recorded[0]
    t = np.arange(len(recorded)) / NOMINAL_TICK_HZ
    fig, axes = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    for j, (ax, joint) in enumerate(zip(axes, ("proximal (hip)", "distal (knee)"), strict=True)):
        ax.plot(t, np.degrees(recorded[:, j]), color="k", lw=1.5, label="recorded")
        ax.plot(t, np.degrees(recorded[:, j] + cal.errors_before[0][:, j]), lw=1, label="model")
        ax.plot(t, np.degrees(recorded[:, j] + cal.errors_after[0][:, j]), lw=1, ls="--", label="calibrated")
        ax.set_ylabel(f"{joint} (deg)")
    axes[0].legend(loc="upper right", ncol=3, fontsize=8)
    axes[0].set_title(f"held out ({cal.held_out}): recorded vs simulated joint angles")
    axes[1].set_xlabel("time (s)")
    fig.tight_layout()
    write_atomically(path, lambda tmp: fig.savefig(tmp, format="png", dpi=90))
    plt.close(fig)


def _parameters(text: str) -> tuple[str, ...]:
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in PARAMETERS]
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown parameters {unknown}; known: {', '.join(PARAMETERS)}")
    return names


def main(argv: list[str] | None = None) -> int:
    """Entry point of `g2p-calibrate`."""
    parser = argparse.ArgumentParser(prog="g2p-calibrate", description=__doc__.splitlines()[0])
    parser.add_argument("bag", type=Path, help="the recorded run (a bag directory)")
    parser.add_argument("--out", type=Path, required=True, help="the calibration file to write (YAML)")
    parser.add_argument("--report", type=Path, default=None, help="report folder (default: <out>.report/)")
    parser.add_argument(
        "--params",
        type=_parameters,
        default=DEFAULT_PARAMETERS,
        help=f"comma-separated parameters to fit (default: {','.join(DEFAULT_PARAMETERS)})",
    )
    parser.add_argument(
        "--babbling-s", type=float, default=None, help="fit on only the first S s of babbling"
    )
    parser.add_argument("--max-evaluations", type=int, default=FitConfig.max_evaluations)
    parser.add_argument("--window-ticks", type=int, default=FitConfig.window_ticks)
    parser.add_argument("--workers", type=int, default=0, help="processes (default: all CPUs)")
    parser.add_argument(
        "--interval-blocks",
        type=int,
        default=FitConfig.interval_blocks,
        help="the intervals from refits on this many stretches of the recording (0: the Jacobian's alone)",
    )
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    try:
        config = FitConfig(
            parameters=args.params,
            max_evaluations=args.max_evaluations,
            window_ticks=args.window_ticks,
            workers=args.workers,
            interval_blocks=args.interval_blocks,
        )
        run = load_recorded_run(args.bag)
        print(
            f"calibrating on {args.bag}: {sum(len(s) for s in run.babbling)} babbling ticks, "
            f"{len(run.attempts)} attempts; fitting {len(config.parameters)} parameters",
            flush=True,
        )
        cal = calibrate(run, config, args.babbling_s)
    except (CalibrationInputError, ConfigError) as err:
        print(f"g2p-calibrate: {err}", file=sys.stderr)
        return 2
    except FitError as err:
        print(f"g2p-calibrate: {args.bag}: {err}; nothing written", file=sys.stderr)
        return 1
    report = args.report if args.report is not None else args.out.with_name(args.out.name + ".report")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomically(args.out, cal.calibration.to_yaml())
    write_text_atomically(report / "calibration.md", report_markdown(cal))
    plot_angles(cal, report / "angles_held_out.png")
    print(report_markdown(cal))
    print(f"calibration: {args.out}\nreport:      {report}/calibration.md, {report}/angles_held_out.png")
    print(f"({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
