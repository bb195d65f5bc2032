"""An adversary against the rig's safety envelope: searched sequences and plain square waves, on many legs.

For each objective (`--objectives`: slack = cable paid into a slack tendon, impact = the fastest entry
into a joint's stop, tension = a tendon's peak) and each space (`--spaces`: periodic patterns, free step
sequences), a black-box search (g2p.adversary.search: CMA-ES with restarts, `--evaluations` sequences
each played for `--seconds` through the in-process rig with the envelope) looks for the most harm on leg
seed 0; its best sequence is then replayed on `--leg-seeds` leg seeds through `PlantRig` and as episodes
of the Gymnasium environment `g2p/Treadmill-v0` run as the RL baselines run it. Beside them, the known
attacks: the 0.97 Hz two-phase square wave and the 4 Hz square wave of M0 against M1, each as a stair
step and with its rises spread to 0.2 a tick. `--calibration paper` attacks `sim_paper`. Prints JSON:
per attack, path and leg seed, the harm (g2p.adversary.harm.Harm), a summary, and the episodes played.

    python benchmarks/bench_adversary.py [--objectives slack,impact,tension] [--spaces periodic,steps]
        [--evaluations 60] [--seconds 20] [--leg-seeds 10] [--calibration paper]
        [--set envelope.FIELD=VALUE ...] [--out F.json]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict
from typing import Any

import numpy as np
from setups import parse_override

from g2p.adversary.harm import Harm
from g2p.adversary.patterns import SPACES, known_attacks
from g2p.adversary.search import OBJECTIVES, replay, search
from g2p.plant import NOMINAL_TICK_HZ
from g2p.rig.envelope import EnvelopeConfig


def fixed_attacks(seconds: float) -> dict[str, np.ndarray]:
    """The plain attacks (g2p.adversary.patterns.known_attacks) for `seconds`, shape (N, 3) each."""
    return {name: p.activations(seconds, NOMINAL_TICK_HZ) for name, p in known_attacks().items()}


def summary(harms: list[Harm]) -> dict[str, Any]:
    """Over leg seeds: faults, trips, the worst entry, tension and payout, the median p95 entry."""
    return {
        "faults": sum(bool(h.fault) for h in harms),
        "fault_reasons": sorted({h.fault for h in harms if h.fault}),
        "envelope_trips": sum(bool(h.trip) and not h.fault for h in harms),
        "entry_max_rad_s": [round(max(h.entry_speed_rad_s[j] for h in harms), 1) for j in range(2)],
        "entry_p95_median_rad_s": [
            round(float(np.median([h.entry_p95_rad_s[j] for h in harms])), 1) for j in range(2)
        ],
        "peak_tension_max_n": round(max(max(h.peak_tension_n) for h in harms), 1),
        "ticks_over_rated_median": float(np.median([sum(h.ticks_over_rated) for h in harms])),
        "slack_payout_max_mm": round(1000 * max(max(h.max_slack_payout_m) for h in harms), 1),
    }


def main() -> None:
    """Run the attacks and print their figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--objectives", default=",".join(OBJECTIVES))
    parser.add_argument("--spaces", default=",".join(SPACES))
    parser.add_argument("--evaluations", type=int, default=60, help="sequences played per search")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--leg-seeds", type=int, default=10)
    parser.add_argument("--search-seed", type=int, default=0)
    parser.add_argument("--calibration", default="", help='the simulated rig: "" (default) or "paper"')
    parser.add_argument("--set", action="append", default=[], type=parse_override, dest="overrides")
    parser.add_argument("--out", default="", help="also write the JSON here")
    args = parser.parse_args()
    fields = {name: value for section, name, value in args.overrides if section == "envelope"}
    envelope = EnvelopeConfig(**fields)
    seeds = range(args.leg_seeds)
    out: dict[str, Any] = {
        "envelope": fields,
        "calibration": args.calibration,
        "seconds": args.seconds,
        "episodes": 0,
        "attacks": {},
    }

    def record(name: str, activations: np.ndarray, extra: dict[str, Any]) -> None:
        entry: dict[str, Any] = dict(extra)
        for path, through_env in (("rig", False), ("env", True)):
            harms = replay(activations, envelope, seeds, args.calibration, through_env)
            out["episodes"] += len(harms)
            entry[path] = {"summary": summary(harms), "per_seed": [asdict(h) for h in harms]}
        out["attacks"][name] = entry
        print(json.dumps({name: {p: entry[p]["summary"] for p in ("rig", "env")}}), flush=True)
        if args.out:
            with open(args.out, "w") as f:
                json.dump(out, f, indent=1)

    for name, activations in fixed_attacks(args.seconds).items():
        record(name, activations, {})
    for space in [s for s in args.spaces.split(",") if s]:
        for objective in [o for o in args.objectives.split(",") if o]:
            t0 = time.perf_counter()
            attack = search(
                envelope,
                objective,
                space,
                seed=args.search_seed,
                seconds=args.seconds,
                evaluations=args.evaluations,
                calibration=args.calibration,
            )
            out["episodes"] += attack.evaluations
            extra = {
                "sequence": attack.sequence.describe(),
                "evaluations": attack.evaluations,
                "restarts": attack.restarts,
                "search_s": round(time.perf_counter() - t0),
            }
            record(
                f"searched_{space}_{objective}",
                attack.sequence.activations(args.seconds, NOMINAL_TICK_HZ),
                extra,
            )


if __name__ == "__main__":
    main()
