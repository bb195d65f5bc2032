"""Whether the calibration's 95 % intervals hold the truth 95 % of the time, on rigs it was never told.

    scripts/with-env python benchmarks/bench_calibration_coverage.py --rigs 3 --workers 2 \
        --out docs/results/calibration_coverage

Each hidden rig is the model with every parameter the calibration fits in the air drawn at random (each
physical one x exp(U(-0.3, 0.3)), the encoders' offsets U(-0.02, 0.02) rad, their delay U(0, 0.01) s),
babbling `--babbling-s` in the air in process (the rig's jittered ticks and 14-bit encoders), and the
calibration run on the recording as `g2p-calibrate` runs it (`g2p.identification.fit`, default settings).
For every parameter-recording: the truth, the estimate, the stated interval (block refits), the Jacobian's
interval, whether each holds the truth. Prints the coverage of both, overall and per parameter; writes
results.json into --out (one rig at a time, so a stopped run keeps the rigs it finished).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from g2p.files import write_text_atomically
from g2p.identification.fit import DEFAULT_PARAMETERS, FitConfig, fit
from g2p.identification.known_answers import hidden_babbling
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from g2p.sim.calibration import PARAMETERS, LegCalibration, model_values

AIR = MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)
# In the air the belt never moves: its parameters are not fitted (g2p-calibrate skips them).
FITTED = tuple(p for p in DEFAULT_PARAMETERS if not p.startswith("belt_"))
# The sensors' parameters, 0 in the model, are drawn within these spans (rad, rad, s).
SENSOR_SPANS = {
    "proximal_encoder_offset_rad": 0.02,
    "distal_encoder_offset_rad": 0.02,
    "encoder_delay_s": 0.01,
}


def hidden_rig(rng: np.random.Generator, model: dict[str, float]) -> dict[str, float]:
    """A rig drawn at random around the model (see the module docstring)."""
    out = {}
    for name in FITTED:
        if name == "encoder_delay_s":
            value = rng.uniform(0.0, SENSOR_SPANS[name])
        elif name in SENSOR_SPANS:
            value = rng.uniform(-SENSOR_SPANS[name], SENSOR_SPANS[name])
        else:
            value = model[name] * math.exp(rng.uniform(-0.3, 0.3))
        out[name] = float(np.clip(value, PARAMETERS[name].low, PARAMETERS[name].high))
    return out


def summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Coverage of the stated and the Jacobian's intervals, overall and per parameter.

    Only finite intervals count: an infinite one (nothing recorded moves with the parameter) holds the
    truth by saying nothing.
    """

    def cover(key: str, subset: list[dict[str, Any]]) -> float:
        inside = [abs(r["estimate"] - r["truth"]) <= r[key] for r in subset]
        return float(np.mean(inside)) if inside else math.nan

    finite = [r for r in rows if math.isfinite(r["interval"])]
    names = sorted({r["name"] for r in finite}, key=FITTED.index)
    return {
        "parameter_recordings": len(finite),
        "infinite_intervals": len(rows) - len(finite),
        "coverage": cover("interval", finite),
        "coverage_jacobian": cover("jacobian_interval", finite),
        "determined": int(sum(r["determined"] for r in finite)),
        "coverage_determined": cover("interval", [r for r in finite if r["determined"]]),
        "per_parameter": {n: cover("interval", [r for r in finite if r["name"] == n]) for n in names},
    }


def main() -> int:
    """Draw rigs, record, calibrate, count."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/results/calibration_coverage"))
    parser.add_argument("--rigs", type=int, default=4)
    parser.add_argument("--first-rig", type=int, default=0, help="seed of the first rig (to add rigs)")
    parser.add_argument("--babbling-s", type=float, default=60.0)
    parser.add_argument("--workers", type=int, default=0)
    args = parser.parse_args()
    path = args.out / "results.json"
    done: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {"rigs": []}
    model = model_values(MujocoLeg(AIR).model)
    config = FitConfig(parameters=FITTED, workers=args.workers)
    for seed in range(args.first_rig, args.first_rig + args.rigs):
        if any(r["seed"] == seed for r in done["rigs"]):
            continue
        truth = hidden_rig(np.random.default_rng(1000 + seed), model)
        t0 = time.perf_counter()
        segment = hidden_babbling(AIR, LegCalibration(truth), args.babbling_s, seed)
        result = fit([segment], AIR, config)
        rows: list[dict[str, Any]] = [
            {
                "name": e.name,
                "model": e.model_value,
                "truth": truth[e.name],
                "estimate": e.value,
                "interval": e.interval,
                "jacobian_interval": e.jacobian_interval,
                "block_values": list(e.block_values),
                "determined": e.determined,
            }
            for e in result.estimates
        ]
        done["rigs"].append(
            {
                "seed": seed,
                "babbling_s": args.babbling_s,
                "fit_s": time.perf_counter() - t0,
                "workers": result.workers,
                "blocks_converged": result.blocks_converged,
                "rows": rows,
            }
        )
        done["summary"] = summary([r for rig in done["rigs"] for r in rig["rows"]])
        args.out.mkdir(parents=True, exist_ok=True)
        write_text_atomically(path, json.dumps(done, indent=1))
        inside = sum(abs(r["estimate"] - r["truth"]) <= r["interval"] for r in rows)
        print(f"rig {seed}: {inside}/{len(rows)} inside, fit {time.perf_counter() - t0:.0f} s", flush=True)
    s = done["summary"] = summary([r for rig in done["rigs"] for r in rig["rows"]])
    write_text_atomically(path, json.dumps(done, indent=1))
    print(
        f"\n{s['parameter_recordings']} parameter-recordings with a finite interval over {len(done['rigs'])} "
        f"rigs ({s['infinite_intervals']} infinite)"
    )
    print(f"stated 95 % intervals hold the truth: {100 * s['coverage']:.0f} %")
    print(f"the Jacobian's intervals: {100 * s['coverage_jacobian']:.0f} %")
    print(f"determined: {s['determined']}, of which inside: {100 * s['coverage_determined']:.0f} %")
    print("| parameter | coverage |\n| --- | --- |")
    for name, c in s["per_parameter"].items():
        print(f"| {name} | {100 * c:.0f} % |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
