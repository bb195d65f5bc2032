"""An adversary against the rig's safety envelope: searched patterns and plain square waves, on many legs.

For each objective (`--objectives`: slack = cable paid into a slack tendon, impact = the fastest entry
into a joint's stop, tension = a tendon's peak), a black-box search (g2p.adversary.search: scipy's
differential evolution over periodic patterns, each played for `--seconds` through the in-process rig
with the envelope) looks for the most harm on leg seed 0; its best pattern is then replayed on
`--leg-seeds` leg seeds. Beside them, the known attacks the search starts from: the 0.97 Hz two-phase
square wave and the 4 Hz square wave of M0 against M1, each as a stair step and with its rises spread to
0.2 a tick. Prints JSON: per attack and leg seed, the harm (g2p.adversary.harm.Harm), and a summary.

    python benchmarks/bench_adversary.py [--objectives slack,impact,tension] [--generations 8]
        [--population 5] [--seconds 20] [--leg-seeds 10] [--set envelope.FIELD=VALUE ...] [--out F.json]
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
from g2p.adversary.patterns import known_attacks
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
    parser.add_argument("--generations", type=int, default=8)
    parser.add_argument("--population", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--leg-seeds", type=int, default=10)
    parser.add_argument("--search-seed", type=int, default=0)
    parser.add_argument("--set", action="append", default=[], type=parse_override, dest="overrides")
    parser.add_argument("--out", default="", help="also write the JSON here")
    args = parser.parse_args()
    fields = {name: value for section, name, value in args.overrides if section == "envelope"}
    envelope = EnvelopeConfig(**fields)
    seeds = range(args.leg_seeds)
    out: dict[str, Any] = {"envelope": fields, "attacks": {}}

    def record(name: str, harms: list[Harm], extra: dict[str, Any]) -> None:
        out["attacks"][name] = {**extra, "summary": summary(harms), "per_seed": [asdict(h) for h in harms]}
        print(json.dumps({name: out["attacks"][name]["summary"]}), flush=True)
        if args.out:
            with open(args.out, "w") as f:
                json.dump(out, f, indent=1)

    for name, pattern in fixed_attacks(args.seconds).items():
        record(name, replay(pattern, envelope, seeds), {})
    for objective in [o for o in args.objectives.split(",") if o]:
        t0 = time.perf_counter()
        attack = search(
            envelope,
            objective,
            seed=args.search_seed,
            seconds=args.seconds,
            generations=args.generations,
            population=args.population,
        )
        pattern = attack.pattern.activations(args.seconds, NOMINAL_TICK_HZ)
        extra = {
            "pattern": attack.pattern.describe(),
            "evaluations": attack.evaluations,
            "search_s": round(time.perf_counter() - t0),
        }
        record(f"searched_{objective}", replay(pattern, envelope, seeds), extra)


if __name__ == "__main__":
    main()
