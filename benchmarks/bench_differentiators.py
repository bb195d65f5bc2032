"""Compare resampling methods and differentiators on realistic joint-angle signals with known derivatives.

Signals (per joint, 5 min each, like a babbling session):
    sines: sums of 5 sines, frequencies uniform in [0.2, 5] Hz, amplitudes proportional to 1/f, 0.5 rad RMS.
    steps: a second-order joint (natural frequency 1.5-4 Hz, damping 0.2-0.7) driven by stair steps with a
        mean dwell of 1 s and levels uniform in [-0.6, 0.6] rad, like a joint under motor babbling; its
        acceleration jumps at every step.
Sampling: stamps at 78 Hz with the rate drawn per interval from N(78, 5) Hz (clipped to [65, 91] Hz), angles
quantized to 2*pi/2^14 rad (14-bit encoders). "ideal" rows use uniform stamps and no quantization instead.
Errors are RMS over the interior of the uniform grid against the analytic values, in percent of the RMS of the
true signal (q: in microradians RMS). For "steps", a second error ("away") leaves out the grid samples within
0.13 s (10 samples) of a step, where no 78 Hz estimator can resolve the jump in acceleration.

Run:  PYTHONPATH=src python benchmarks/bench_differentiators.py [--seeds 5] [--duration 300]
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from g2p.learning.kinematics import (
    Differentiator,
    PreprocessConfig,
    Resampling,
    differentiate,
    resample,
    uniform_grid,
)
from g2p.plant import NOMINAL_TICK_HZ

FloatArray = NDArray[np.float64]
# Returns (q, dq, ddq) at the given stamps, each shape (N, 2).
Signal = Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]]

RATE_HZ = NOMINAL_TICK_HZ
RATE_SD_HZ = 5.0
LSB_RAD = 2 * np.pi / 2**14


def sines(rng: np.random.Generator, n_components: int = 5, rms_rad: float = 0.5) -> Signal:
    """A sum of sines per joint with 1/f amplitudes in the 0.2-5 Hz band."""
    f = rng.uniform(0.2, 5.0, size=(n_components, 2))
    amp = 1.0 / f
    amp *= rms_rad * np.sqrt(2.0 / np.sum(amp**2, axis=0))
    phase = rng.uniform(0, 2 * np.pi, size=(n_components, 2))
    w = 2 * np.pi * f

    def signal(t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        arg = w[None] * t[:, None, None] + phase[None]
        return (
            np.sum(amp * np.sin(arg), axis=1),
            np.sum(amp * w * np.cos(arg), axis=1),
            np.sum(-amp * w**2 * np.sin(arg), axis=1),
        )

    return signal


def stair_response(
    rng: np.random.Generator, duration_s: float, dwell_s: float = 1.0
) -> tuple[Signal, FloatArray]:
    """Exact response of x'' + 2 z w x' + w^2 x = w^2 u(t) to stair-step u, per joint, and the step times."""
    pairs = [_stair_joint(rng, duration_s, dwell_s) for _ in range(2)]
    joints = [p[0] for p in pairs]

    def signal(t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        parts = [j(t) for j in joints]
        return tuple(np.stack([p[k] for p in parts], axis=1) for k in range(3))  # type: ignore[return-value]

    return signal, np.sort(np.concatenate([p[1] for p in pairs]))


def _stair_joint(
    rng: np.random.Generator, duration_s: float, dwell_s: float
) -> tuple[Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]], FloatArray]:
    w = 2 * np.pi * rng.uniform(1.5, 4.0)
    z = rng.uniform(0.2, 0.7)
    sigma, wd = z * w, w * np.sqrt(1 - z**2)
    n_steps = int(3 * duration_s / dwell_s) + 10
    starts = np.concatenate([[-1e3], np.cumsum(rng.exponential(dwell_s, n_steps))])
    starts = starts[starts < duration_s + 10.0]
    u = rng.uniform(-0.6, 0.6, size=len(starts))
    x0 = np.empty(len(starts))
    v0 = np.empty(len(starts))
    x0[0], v0[0] = u[0], 0.0  # at rest on the first level long before t = 0

    def free(dx: FloatArray, dv: FloatArray, tau: FloatArray) -> tuple[FloatArray, FloatArray]:
        c1, c2 = dx, (dv + sigma * dx) / wd
        e, c, s = np.exp(-sigma * tau), np.cos(wd * tau), np.sin(wd * tau)
        return e * (c1 * c + c2 * s), e * ((-sigma * c1 + wd * c2) * c + (-sigma * c2 - wd * c1) * s)

    for i in range(1, len(starts)):
        tau = np.array(starts[i] - starts[i - 1])
        dx, dv = free(np.array(x0[i - 1] - u[i - 1]), np.array(v0[i - 1]), tau)
        x0[i], v0[i] = float(dx) + u[i - 1], float(dv)

    def joint(t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = np.searchsorted(starts, t, side="right") - 1
        dx, v = free(x0[k] - u[k], v0[k], t - starts[k])
        x = dx + u[k]
        return x, v, w**2 * (u[k] - x) - 2 * z * w * v

    return joint, starts[1:]


def stamps(rng: np.random.Generator, duration_s: float, jitter: bool) -> FloatArray:
    """Tick stamps over [0, duration_s]: uniform, or with the rate drawn per interval from N(78, 5) Hz."""
    n = int(duration_s * RATE_HZ * 1.2)
    if not jitter:
        t = np.arange(n) / RATE_HZ
    else:
        t = np.concatenate([[0.0], np.cumsum(1.0 / np.clip(rng.normal(RATE_HZ, RATE_SD_HZ, n - 1), 65, 91))])
    return t[t <= duration_s]


@dataclass(frozen=True)
class Errors:
    """RMS errors: q in microradians, dq and ddq in percent of the true signal's RMS (NaN: not measured)."""

    q_urad: float
    dq_pct: float
    ddq_pct: float
    dq_away_pct: float
    ddq_away_pct: float


def evaluate(
    signal: Signal,
    t_raw: FloatArray,
    config: PreprocessConfig,
    quantize: bool,
    steps_s: FloatArray | None = None,
) -> Errors:
    """Errors of the kinematics computed from samples of `signal` at `t_raw` with `config`.

    `steps_s`: times of input steps; the "away" errors leave out samples within 10 grid samples of them.
    """
    q_raw = signal(t_raw)[0]
    if quantize:
        q_raw = np.round(q_raw / LSB_RAD) * LSB_RAD
    grid = uniform_grid(t_raw, config.rate_hz)
    kin = differentiate(resample(t_raw, q_raw, grid, config.resampling), config)
    e = config.edge
    t = grid[e : len(grid) - e]
    q, dq, ddq = signal(t)

    def rms(x: FloatArray) -> float:
        return float(np.sqrt(np.mean(x**2)))

    away = np.full(len(t), np.nan)
    if steps_s is not None:
        i = np.clip(np.searchsorted(steps_s, t), 1, len(steps_s) - 1)
        far = np.minimum(np.abs(t - steps_s[i - 1]), np.abs(t - steps_s[i])) > 10.0 / config.rate_hz
        away = np.array(
            [
                100 * rms(kin[far, 2:4] - dq[far]) / rms(dq[far]),
                100 * rms(kin[far, 4:] - ddq[far]) / rms(ddq[far]),
            ]
        )
    return Errors(
        1e6 * rms(kin[:, :2] - q),
        100 * rms(kin[:, 2:4] - dq) / rms(dq),
        100 * rms(kin[:, 4:] - ddq) / rms(ddq),
        float(away[0]),
        float(away[1]),
    )


def candidates() -> list[tuple[str, PreprocessConfig]]:
    """Every resampling x differentiator combination compared (Savitzky-Golay over windows and orders)."""
    out = []
    for res in Resampling:
        out.append(
            (
                f"{res.value:6s} five_point",
                PreprocessConfig(resampling=res, differentiator=Differentiator.FIVE_POINT),
            )
        )
        out.append(
            (
                f"{res.value:6s} central",
                PreprocessConfig(resampling=res, differentiator=Differentiator.CENTRAL),
            )
        )
        for w, p in itertools.product((5, 7, 9, 11, 13, 15, 19), (3, 4, 5)):
            if p < w:
                cfg = PreprocessConfig(
                    resampling=res, differentiator=Differentiator.SAVGOL, savgol_window=w, savgol_polyorder=p
                )
                out.append((f"{res.value:6s} savgol w={w} p={p}", cfg))
    return out


def main() -> None:
    """Print a table of mean errors over seeds, per signal family and sampling condition."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--duration", type=float, default=300.0, help="signal length (s)")
    parser.add_argument("--top", type=int, default=0, help="show only the best N by mean ddq error (0: all)")
    args = parser.parse_args()
    conditions = {"realistic": (True, True), "ideal": (False, False)}
    rows: dict[str, dict[str, list[Errors]]] = {}
    for seed in range(args.seeds):
        for family in ("sines", "steps"):
            rng = np.random.default_rng([seed, family == "steps"])
            sig, steps_s = (sines(rng), None) if family == "sines" else stair_response(rng, args.duration)
            for cond, (jitter, quant) in conditions.items():
                t_raw = stamps(np.random.default_rng([seed, 7]), args.duration, jitter)
                for name, cfg in candidates():
                    if cond == "ideal" and cfg.resampling is Resampling.CUBIC:
                        continue  # on a uniform grid both resamplings are the identity
                    rows.setdefault(name, {}).setdefault(f"{family}/{cond}", []).append(
                        evaluate(sig, t_raw, cfg, quant, steps_s)
                    )
    keys = [f"{f}/{c}" for c in conditions for f in ("sines", "steps")]

    def mean(name: str, key: str, attr: str) -> float:
        return float(np.mean([getattr(e, attr) for e in rows[name].get(key, [])] or [np.nan]))

    # Rank by the realistic acceleration errors: sines, and steps away from the steps.
    order = sorted(
        rows, key=lambda n: mean(n, "sines/realistic", "ddq_pct") + mean(n, "steps/realistic", "ddq_away_pct")
    )
    if args.top:
        order = order[: args.top]
    print(
        f"mean over {args.seeds} seeds, {args.duration:.0f} s per signal; q: RMS error in urad; "
        "dq, ddq: RMS error in % of RMS; steps: all samples (away from steps)"
    )
    print(f"| method | {' | '.join(f'{k} q / dq / ddq' for k in keys)} |")
    print(f"| --- | {' | '.join('---' for _ in keys)} |")
    for name in order:
        cells = []
        for k in keys:
            if np.isnan(mean(name, k, "q_urad")):
                cells.append("-")
                continue
            cell = f"{mean(name, k, 'q_urad'):.0f} / {mean(name, k, 'dq_pct'):.2f}"
            if k.startswith("steps"):
                cell += f" ({mean(name, k, 'dq_away_pct'):.2f}) / {mean(name, k, 'ddq_pct'):.1f}"
                cell += f" ({mean(name, k, 'ddq_away_pct'):.2f})"
            else:
                cell += f" / {mean(name, k, 'ddq_pct'):.2f}"
            cells.append(cell)
        print(f"| {name} | {' | '.join(cells)} |")


if __name__ == "__main__":
    main()
