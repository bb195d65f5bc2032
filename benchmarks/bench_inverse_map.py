"""Measure the inverse map: optimizers' fit time and accuracy, refinement time and effect, preprocessing.

Data come from a small MuJoCo leg built from the facts in G2P_FACTS.md (two hinges: hip +-60 deg, knee
[-90, 0] deg, damping 1, frictionloss 3; links 0.5 m / 3.9 kg and 0.48 m / 3.7 kg; three fixed tendons with
moment arms hip (-0.1, +0.1, -0.1) m and knee (+0.1, 0, -0.1) m; activations filtered with 40 ms, 300 N per
tendon), hanging in the air, ticked at 78 Hz with the tick length drawn from N(78, 5) Hz on a 1 ms physics
step. Babbling is 5 min of `g2p.learning.babbling`; pairs come from `g2p.learning.kinematics.training_pairs`
with the defaults.
Attempts play 20 random in-air cycles (features in [0.2, 0.8]) of BENCH_CYCLES through the current map.

Sections:
    fit:        each optimizer x torch threads x seed: seconds, iterations, validation RMSE, and RMSE on a
                second, independent babbling session (activation units).
    refine:     per torch thread count: LM fit, then attempts, each appended (first quarter dropped) and the
                map refined on all data so far: data size, refine seconds, RMSE on the new attempt before and
                after, RMSE on the independent babbling session (forgetting), tracking MSE.
    tracking:   one cycle per seed, run and refined 6 times (the paper's Fig. 5a): tracking MSE per attempt.
    preprocess: the same babbling processed by several resampling / differentiator choices; LM fits; RMSE on
                the independent session processed the same way, and tracking of 10 cycles by each map.
Tracking MSE: joint angles, second half of the attempt, deg^2 per joint summed over both (as in the paper).

Run:  PYTHONPATH=src python benchmarks/bench_inverse_map.py [--section fit|refine|tracking|preprocess|all]
      [--seeds 3] [--threads 1,2] [--optimizers lm,lbfgs,adam] [--attempts 20]
"""

from __future__ import annotations

import argparse
import math
import time

import mujoco
import numpy as np
from numpy.typing import NDArray

from g2p.inverse_map import InverseMap, InverseMapConfig, Optimizer
from g2p.learning.babbling import babbling_activations
from g2p.learning.kinematics import (
    Differentiator,
    PreprocessConfig,
    Resampling,
    TrainingPairs,
    training_pairs,
)
from g2p.learning.limit_cycle import LimitCycleConfig, attempt_kinematics
from g2p.plant import NOMINAL_TICK_HZ

FloatArray = NDArray[np.float64]

LEG_XML = """
<mujoco model="g2p-bench-leg">
  <option timestep="0.001" gravity="0 0 -9.81"/>
  <default><joint damping="1" frictionloss="3" limited="true"/></default>
  <worldbody>
    <body name="thigh" pos="0 0 1.2">
      <joint name="hip" type="hinge" axis="0 1 0" range="-60 60"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.03" mass="3.9"/>
      <body name="shank" pos="0 0 -0.5">
        <joint name="knee" type="hinge" axis="0 1 0" range="-90 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.48" size="0.03" mass="3.7"/>
      </body>
    </body>
  </worldbody>
  <tendon>
    <fixed name="t0"><joint joint="hip" coef="-0.10"/><joint joint="knee" coef="0.10"/></fixed>
    <fixed name="t1"><joint joint="hip" coef="0.10"/></fixed>
    <fixed name="t2"><joint joint="hip" coef="-0.10"/><joint joint="knee" coef="-0.10"/></fixed>
  </tendon>
  <actuator>
    <general tendon="t0" dyntype="filter" dynprm="0.04" gainprm="-300" ctrlrange="0 1" ctrllimited="true"/>
    <general tendon="t1" dyntype="filter" dynprm="0.04" gainprm="-300" ctrlrange="0 1" ctrllimited="true"/>
    <general tendon="t2" dyntype="filter" dynprm="0.04" gainprm="-300" ctrlrange="0 1" ctrllimited="true"/>
  </actuator>
</mujoco>
"""
RATE_HZ, RATE_SD_HZ = NOMINAL_TICK_HZ, 5.0
# The benchmark leg pulls at most 30 N m per tendon, less than the rig: the paper's cycles (65 / 47.5 deg
# spokes, ~1 s) are beyond it and no map tracks them. Half the radius and twice the period keep them feasible.
BENCH_CYCLES = LimitCycleConfig.in_air(
    radius_rad=(math.radians(32.5), math.radians(23.75)), samples_per_segment=16
)


class Leg:
    """The benchmark leg; `run` plays activations from the resting posture, one jittered tick per row."""

    def __init__(self) -> None:
        self.model = mujoco.MjModel.from_xml_string(LEG_XML)
        self.data = mujoco.MjData(self.model)

    def run(self, activations: FloatArray, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
        """Returns tick stamps (N,) (s) and joint angles (N, 2) (rad) at the end of each tick."""
        mujoco.mj_resetData(self.model, self.data)
        n = len(activations)
        steps = np.maximum(1, np.round(1000.0 / rng.normal(RATE_HZ, RATE_SD_HZ, n)).astype(int))
        t, q = np.empty(n), np.empty((n, 2))
        for i in range(n):
            self.data.ctrl[:] = activations[i]
            mujoco.mj_step(self.model, self.data, nstep=int(steps[i]))
            t[i], q[i] = self.data.time, self.data.qpos
        return t, q


def babble_raw(leg: Leg, seed: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Stamps (N,), angles (N, 2) and activations (N, 3) of a 5-min babbling session."""
    rng = np.random.default_rng(seed)
    act = babbling_activations(rng)
    t, q = leg.run(act, rng)
    return t, q, act


def babble_pairs(leg: Leg, seed: int, config: PreprocessConfig | None = None) -> TrainingPairs:
    """Pairs of a 5-min babbling session."""
    return training_pairs(*babble_raw(leg, seed), config)


def rmse(net: InverseMap, pairs: TrainingPairs) -> float:
    """RMS error of the clipped predictions (activation units)."""
    return float(np.sqrt(np.mean((net.predict(pairs.kinematics) - pairs.activation) ** 2)))


def bench_fit(args: argparse.Namespace, train: TrainingPairs, test: TrainingPairs) -> None:
    """Table of fit time and accuracy per optimizer, thread count and seed."""
    print(f"## fit on {len(train)} babbling samples; test: an independent session of {len(test)} samples")
    print("| optimizer | threads | seed | seconds | iterations | stop | val RMSE | test RMSE |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name in args.optimizers.split(","):
        for threads in (int(s) for s in args.threads.split(",")):
            for seed in range(args.seeds):
                # L-BFGS and Adam iterations are cheap and noisy: give them more patience than LM's 6.
                cfg = InverseMapConfig(
                    optimizer=Optimizer(name), num_threads=threads, patience=6 if name == "lm" else 20
                )
                net = InverseMap(cfg)
                rep = net.fit(train.kinematics, train.activation, np.random.default_rng(seed))
                print(
                    f"| {name} | {threads} | {seed} | {rep.seconds:.2f} | {rep.iterations} | "
                    f"{rep.stop_reason.value} | {rep.validation_rmse:.4f} | {rmse(net, test):.4f} |",
                    flush=True,
                )


def random_features(rng: np.random.Generator, cycles: LimitCycleConfig) -> FloatArray:
    """Features uniform within the cycle's bounds, shape (n_spokes,)."""
    return rng.uniform(cycles.feature_low, cycles.feature_high, cycles.n_spokes)


PREPROCESSING = {
    "linear five_point (authors)": PreprocessConfig(
        resampling=Resampling.LINEAR, differentiator=Differentiator.FIVE_POINT
    ),
    "cubic central": PreprocessConfig(differentiator=Differentiator.CENTRAL),
    "cubic savgol w=7 p=5": PreprocessConfig(savgol_window=7),
    "cubic savgol w=9 p=5 (default)": PreprocessConfig(),
    "cubic savgol w=11 p=5": PreprocessConfig(savgol_window=11),
    "linear savgol w=9 p=5": PreprocessConfig(resampling=Resampling.LINEAR),
}


def bench_preprocess(args: argparse.Namespace, leg: Leg) -> None:
    """End to end: activations predicted from each preprocessing's kinematics, and tracking with the map."""
    raw_train, raw_test = babble_raw(leg, 1), babble_raw(leg, 2)
    cycles = BENCH_CYCLES
    targets = [
        attempt_kinematics(random_features(np.random.default_rng(300 + k), cycles), cycles) for k in range(10)
    ]
    print(
        f"## preprocessing end to end: LM fits on babbling ({args.seeds} seeds); RMSE on an independent "
        "session; tracking MSE of 10 random cycles with each babbling map"
    )
    print("| preprocessing | val RMSE | test RMSE | tracking MSE median | tracking MSE mean |")
    print("| --- | --- | --- | --- | --- |")
    for name, pre in PREPROCESSING.items():
        train, test = training_pairs(*raw_train, pre), training_pairs(*raw_test, pre)
        val, tst, mse = [], [], []
        for seed in range(args.seeds):
            net = InverseMap(InverseMapConfig())
            rep = net.fit(train.kinematics, train.activation, np.random.default_rng(seed))
            val.append(rep.validation_rmse)
            tst.append(rmse(net, test))
            for k, target in enumerate(targets):
                _, q = leg.run(net.predict(target), np.random.default_rng(400 + k))
                mse.append(tracking_mse_deg2(target[:, :2], q))
        print(
            f"| {name} | {np.mean(val):.4f} +- {np.std(val):.4f} | {np.mean(tst):.4f} +- {np.std(tst):.4f} "
            f"| {np.median(mse):.0f} | {np.mean(mse):.0f} |",
            flush=True,
        )


def tracking_mse_deg2(target: FloatArray, q: FloatArray) -> float:
    """Joint-angle MSE over the second half (deg^2 per joint, summed over joints)."""
    half = len(q) // 2
    return float(np.sum(np.mean(np.degrees(q[half:] - target[half:]) ** 2, axis=0)))


def bench_refine(
    args: argparse.Namespace, leg: Leg, train: TrainingPairs, test: TrainingPairs, threads: int
) -> None:
    """Attempts of random cycles, refining after each on all data so far."""
    net = InverseMap(InverseMapConfig(num_threads=threads))
    rng = np.random.default_rng(100)
    rep = net.fit(train.kinematics, train.activation, rng)
    print(
        f"## refine (LM, {threads} threads); initial fit {rep.seconds:.2f} s, test RMSE {rmse(net, test):.4f}"
    )
    print(
        "| attempt | samples | refine s | iterations | new RMSE before | after | babble test RMSE | "
        "tracking MSE deg^2 |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    pre = PreprocessConfig()
    xs, ys = [train.kinematics], [train.activation]
    times = []
    for attempt in range(args.attempts):
        target = attempt_kinematics(random_features(rng, BENCH_CYCLES), BENCH_CYCLES)
        act = net.predict(target)
        t, q = leg.run(act, rng)
        new = training_pairs(t, q, act, pre, drop_fraction=pre.transition_fraction)
        before = rmse(net, new)
        xs.append(new.kinematics)
        ys.append(new.activation)
        rep = net.refine(np.vstack(xs), np.vstack(ys), rng)
        times.append(rep.seconds)
        print(
            f"| {attempt + 1} | {rep.n_train + rep.n_validation} | {rep.seconds:.2f} | {rep.iterations} | "
            f"{before:.4f} | {rmse(net, new):.4f} | {rmse(net, test):.4f} | "
            f"{tracking_mse_deg2(target[:, :2], q):.1f} |",
            flush=True,
        )
    print(f"refine seconds ({threads} threads): median {np.median(times):.2f}, max {np.max(times):.2f}")


def bench_tracking(args: argparse.Namespace, leg: Leg, train: TrainingPairs) -> None:
    """One in-air trajectory, run and refined 6 times (the paper's Fig. 5a): tracking MSE per attempt."""
    cycles = BENCH_CYCLES
    pre = PreprocessConfig()
    print(
        "## tracking: one in-air cycle, refined after each attempt; MSE deg^2 (both joints summed, 2nd half)"
    )
    for seed in range(args.seeds):
        rng = np.random.default_rng(200 + seed)
        net = InverseMap(InverseMapConfig())
        net.fit(train.kinematics, train.activation, rng)
        target = attempt_kinematics(random_features(rng, cycles), cycles)
        xs, ys, mses = [train.kinematics], [train.activation], []
        for _ in range(6):
            act = net.predict(target)
            t, q = leg.run(act, rng)
            mses.append(tracking_mse_deg2(target[:, :2], q))
            new = training_pairs(t, q, act, pre, drop_fraction=pre.transition_fraction)
            xs.append(new.kinematics)
            ys.append(new.activation)
            net.refine(np.vstack(xs), np.vstack(ys), rng)
        print(f"seed {seed}: " + " -> ".join(f"{m:.1f}" for m in mses), flush=True)


def main() -> None:
    """Run the selected sections and print markdown tables."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--section", default="all", choices=("fit", "refine", "tracking", "preprocess", "all")
    )
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--threads", default="1,2", help="torch thread counts for fit and refine")
    parser.add_argument("--optimizers", default="lm,lbfgs,adam")
    parser.add_argument("--attempts", type=int, default=20)
    args = parser.parse_args()
    leg = Leg()
    start = time.perf_counter()
    train, test = babble_pairs(leg, 1), babble_pairs(leg, 2)
    print(f"babbling sessions simulated and preprocessed in {time.perf_counter() - start:.1f} s")
    if args.section in ("fit", "all"):
        bench_fit(args, train, test)
    if args.section in ("refine", "all"):
        for threads in (int(n) for n in args.threads.split(",")):
            bench_refine(args, leg, train, test, threads)
    if args.section in ("tracking", "all"):
        bench_tracking(args, leg, train)
    if args.section in ("preprocess", "all"):
        bench_preprocess(args, leg)


if __name__ == "__main__":
    main()
