"""Identify the simulated rig's physical parameters from recorded segments, with MuJoCo's sysid toolbox.

The parameters (g2p.sim.calibration.PARAMETERS) are `mujoco.sysid.Parameter`s in a `ParameterDict` with
their bounds; `mujoco.sysid.optimize` minimises the residual (scipy's trust-region least squares with
MuJoCo's finite-difference Jacobian). The 95 % intervals come from the same fit on consecutive stretches
of the recording (`fit`): the Jacobian's own (`mujoco.sysid.calculate_intervals`) assume independent
residuals, and hold the truth for 9 % of parameters (docs/RESULTS.md, "Calibration intervals").

The residual is the plant itself replaying each segment: a `MujocoLeg` built with the candidate values
starts at its own resting posture and plays the recorded activations, each tick for its recorded duration
(sysid's own rollout steps a model at a fixed time step from a full recorded state, which the rig's
jittered ticks, its rest posture and its encoders' offset and delay do not fit). Per tick it compares
the two joint angles, the three motor currents and powers and the belt velocity with the recording, each
divided by a measurement scale (FitConfig), and a broad Gaussian prior (one row per parameter, its
value's departure from the model's in units of `prior_scale`) keeps the directions the data leave free
at the model's values.

Each parameter is searched in relative units, x = (value - model value) / scale, where scale is the
model value (the sensors' offsets and delay, 0 in the model, have a fixed scale): the finite-difference
step and the prior are then alike for a 25 mm moment arm and a 4000 N/m stiffness.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import os
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from g2p.identification.segments import Segment
from g2p.plant import FloatArray
from g2p.sim.calibration import PARAMETERS, LegCalibration, model_values
from g2p.sim.config import MujocoLegConfig
from g2p.sim.leg import MujocoLeg
from g2p.validation import ConfigError, require, require_positive

# The parameters a calibration fits unless told otherwise: the leg, its motors and their supply, the belt
# and the sensors (the belt span and the foot's friction act only in stance and are left to the model;
# the windings' thermal parameters and cut-out, and the tendons' strength, act on nothing a recording
# measures: docs/SIMULATOR.md, "Calibration").
DEFAULT_PARAMETERS = (
    "proximal_damping_nms",
    "distal_damping_nms",
    "proximal_friction_nm",
    "distal_friction_nm",
    "tendon_stiffness_n_per_m",
    "m0_proximal_arm_m",
    "m0_distal_arm_m",
    "m1_proximal_arm_m",
    "m2_proximal_arm_m",
    "m2_distal_arm_m",
    "motor_lag_s",
    "motor_max_current_a",
    "motor_kt_nm_per_a",
    "motor_resistance_ohm",
    "supply_voltage_v",
    "belt_drag_n",
    "belt_damping_ns_per_m",
    "proximal_encoder_offset_rad",
    "distal_encoder_offset_rad",
    "encoder_delay_s",
)
# Scale of the parameters whose model value is 0 (the sensors'): rad for offsets, s for the delay.
_ZERO_SCALES = {
    "proximal_encoder_offset_rad": 0.02,
    "distal_encoder_offset_rad": 0.02,
    "encoder_delay_s": 0.01,
}
# scipy.optimize.least_squares' status: > 0 converged, 0 evaluation budget spent, -1 failed.
_CONVERGED_STATUS = (1, 2, 3, 4)

_log = logging.getLogger(__name__)


class FitError(RuntimeError):
    """The fit did not converge; nothing should be written."""


@dataclass(frozen=True)
class FitConfig:
    """How the calibration fits.

    Attributes:
        parameters: names of the parameters to fit (g2p.sim.calibration.PARAMETERS); the others keep the
            model's values.
        angle_scale_rad: joint-angle error worth one unit of residual (rad).
        current_scale_a: motor-current error worth one unit of residual (A).
        belt_scale_mm_s: belt-velocity error worth one unit of residual (mm/s).
        power_scale_w: motor-power error worth one unit of residual (W).
        prior_scale: width of each parameter's Gaussian prior, in units of its scale (1 = the model's value
            +- 100 %).
        undetermined_share: a parameter whose 95 % interval is wider than this share of its scale is
            reported as not determined by the data.
        max_evaluations: the optimizer's budget of residual evaluations per round (not counting the
            Jacobian's); a round that spends it has not converged.
        cost_tolerance: a round has converged when a step lowers the cost by less than this share of it
            (scipy's ftol; the replays' roughness leaves no use for the default 1e-8).
        diff_step: finite-difference step, in units of each parameter's scale.
        workers: processes replaying segments in parallel (each Jacobian column is one replay); 0 = all
            CPUs.
        window_ticks: multiple shooting (see `replay`): the horizon of each prediction (ticks); 0 = open
            loop from rest. Short horizons keep the residual smooth in the parameters: the rig's contacts,
            stops and Coulomb friction make long replays part from the recording at moments that jump
            with the parameters (docs/SIMULATOR.md, "Calibration").
        rounds: the optimizer is started again from where it stopped, up to this many times, while a
            round lowers the cost by more than 1 % (a restart resets its trust region, which the
            residual's remaining roughness tends to shrink early).
        loss: scipy's loss on the residual ("linear", "soft_l1", "huber", "cauchy", "arctan").
        interval_blocks: the intervals come from the same fit repeated on this many consecutive
            stretches of the recording (`fit`); 0 gives the Jacobian's intervals alone.
        settle_ticks: a stretch that begins mid-recording is replayed from this many ticks earlier,
            which are not compared: the replay's motor currents and velocities catch up with the rig's.
    """

    parameters: tuple[str, ...] = DEFAULT_PARAMETERS
    angle_scale_rad: float = 0.005
    current_scale_a: float = 0.05
    belt_scale_mm_s: float = 5.0
    power_scale_w: float = 0.5
    prior_scale: float = 1.0
    undetermined_share: float = 0.5
    max_evaluations: int = 60
    cost_tolerance: float = 1e-3
    diff_step: float = 3e-3
    workers: int = 0
    window_ticks: int = 16
    rounds: int = 3
    loss: str = "linear"
    interval_blocks: int = 4
    settle_ticks: int = 32

    def __post_init__(self) -> None:
        unknown = [p for p in self.parameters if p not in PARAMETERS]
        require(not unknown, "parameters", f"unknown {unknown}; known: {', '.join(PARAMETERS)}")
        require(len(self.parameters) > 0, "parameters", "name at least one")
        require(len(set(self.parameters)) == len(self.parameters), "parameters", "each at most once")
        for name in (
            "angle_scale_rad",
            "current_scale_a",
            "belt_scale_mm_s",
            "power_scale_w",
            "prior_scale",
            "diff_step",
            "cost_tolerance",
            "undetermined_share",
        ):
            require_positive(getattr(self, name), name)
        require(self.max_evaluations >= 1, "max_evaluations", f"must be >= 1, got {self.max_evaluations}")
        require(self.workers >= 0, "workers", f"must be >= 0, got {self.workers}")
        require(
            self.interval_blocks == 0 or self.interval_blocks >= 2,
            "interval_blocks",
            f"must be 0 or >= 2, got {self.interval_blocks}",
        )
        require(self.settle_ticks >= 0, "settle_ticks", f"must be >= 0, got {self.settle_ticks}")


@dataclass(frozen=True)
class Replay:
    """What the simulated rig read replaying a segment.

    Attributes:
        position_rad: joint angles (encoder readings, unquantized), shape (N, 2) (rad).
        current_a: mean motor currents, shape (N, 3) (A).
        belt_velocity_mm_s: mean belt velocity over each tick, shape (N,) (mm/s).
        power_w: mean electrical power of each motor over each tick, shape (N, 3) (W).
    """

    position_rad: FloatArray
    current_a: FloatArray
    belt_velocity_mm_s: FloatArray
    power_w: FloatArray


def replay_config(leg_config: MujocoLegConfig) -> MujocoLegConfig:
    """The rig a fit replays on: `leg_config` with encoders fine enough to be smooth in the parameters.

    Quantized readings are flat between counts, which would give the finite differences nothing.
    """
    return replace(leg_config, encoder_bits=32, calibration="")


def replay(
    segments: Sequence[Segment],
    leg_config: MujocoLegConfig,
    calibration: LegCalibration,
    window_ticks: int = 0,
) -> list[Replay]:
    """Replay each segment from the resting posture on the simulated rig with `calibration`.

    Args:
        segments: the recorded segments.
        leg_config: the simulated rig.
        calibration: its calibration.
        window_ticks: multiple shooting: every this many ticks the joints are put back on the recorded
            angles (the encoder readings less the calibration's offsets, `encoder_delay_s` later: the
            angles at the tick's end; the velocities are the replay's own, which replay the recording
            better than its finite differences) and the replay predicts the next window from there; 0
            replays each segment open loop from rest.
    """
    plant = MujocoLeg(leg_config, calibration=calibration)
    offset, delay = calibration.encoder_offset_rad, calibration.encoder_delay_s
    out = []
    for seg in segments:
        start = plant.reset()
        if seg.start_position_rad is not None:  # a stretch from the middle of a recording
            plant.set_joint_state(seg.start_position_rad - offset)
        n = len(seg)
        true_rad = _true_angles(seg, delay) - offset if window_ticks else seg.position_rad
        position, current, belt, power = np.empty((n, 2)), np.empty((n, 3)), np.empty(n), np.empty((n, 3))
        for k in range(n):
            if window_ticks and k and k % window_ticks == 0:
                plant.set_joint_state(true_rad[k - 1])
            s = plant.step(seg.activation[k], period_s=float(seg.period_s[k]))
            position[k], current[k], belt[k], power[k] = s.position_rad, s.current_a, s.belt_mm, s.power_w
        velocity = np.diff(belt, prepend=belt[0] if n else start.belt_mm) / seg.period_s
        out.append(Replay(position, current, velocity, power))
    plant.close()
    return out


def _true_angles(seg: Segment, delay_s: float) -> FloatArray:
    """The joint angles at the end of each tick, read from the recording (encoder offsets included).

    An encoder with a delay reads the angle `delay_s` before the tick's end, so the angle at a tick's end
    is what the encoders read `delay_s` later (interpolated between ticks; the last ticks hold the last
    reading). Shape (N, 2) (rad).
    """
    if delay_s <= 0.0 or len(seg) < 2:
        return seg.position_rad
    t = np.cumsum(seg.period_s)
    return np.stack([np.interp(t + delay_s, t, seg.position_rad[:, j]) for j in range(2)], axis=1)


@dataclass(frozen=True)
class _Problem:
    """The fit's fixed parts: what a residual evaluation needs besides x (sent once to each worker)."""

    segments: tuple[Segment, ...]
    leg_config: MujocoLegConfig
    names: tuple[str, ...]
    nominal: FloatArray  # model values of `names`
    scale: FloatArray
    config: FitConfig

    def calibration(self, x: FloatArray) -> LegCalibration:
        values = self.nominal + self.scale * np.asarray(x, dtype=np.float64)
        clipped = {
            n: float(np.clip(v, PARAMETERS[n].low, PARAMETERS[n].high))
            for n, v in zip(self.names, values, strict=True)
        }
        return LegCalibration(clipped)

    def data_residual(self, x: FloatArray) -> FloatArray:
        """The per-tick errors of every segment, scaled, one flat vector."""
        cfg = self.config
        parts = []
        reps = replay(self.segments, self.leg_config, self.calibration(x), cfg.window_ticks)
        for seg, rep in zip(self.segments, reps, strict=True):
            k = seg.scored_from
            parts.append(((rep.position_rad[k:] - seg.position_rad[k:]) / cfg.angle_scale_rad).ravel())
            parts.append(((rep.current_a[k:] - seg.current_a[k:]) / cfg.current_scale_a).ravel())
            parts.append((rep.belt_velocity_mm_s[k:] - seg.belt_velocity_mm_s[k:]) / cfg.belt_scale_mm_s)
            parts.append(((rep.power_w[k:] - seg.power_w[k:]) / cfg.power_scale_w).ravel())
        return np.concatenate(parts)

    def residual(self, x: FloatArray) -> FloatArray:
        """Data rows, then one prior row per parameter."""
        return np.concatenate([self.data_residual(x), np.asarray(x) / self.config.prior_scale])


_PROBLEM: _Problem | None = None  # a worker's copy


def _init_worker(problem: _Problem) -> None:
    global _PROBLEM
    _PROBLEM = problem


def _worker_residual(x: FloatArray) -> FloatArray:
    assert _PROBLEM is not None
    return _PROBLEM.residual(x)


@dataclass(frozen=True)
class Estimate:
    """One fitted parameter.

    Attributes:
        name: the parameter.
        model_value: its value in the model the fit started from.
        value: the estimate.
        interval: 95 % confidence half-width (inf when the data do not constrain it): the larger of the
            spread of the block refits (`FitConfig.interval_blocks`) and the Jacobian's interval.
        determined: whether the data determine it (interval within `undetermined_share` of its scale).
        block_values: the estimates of the same fit on each block of the recording, shape (B,) (empty
            without blocks).
        jacobian_interval: the half-width from the Jacobian at the optimum alone, which assumes
            independent residuals (the sysid toolbox's `calculate_intervals`).
    """

    name: str
    model_value: float
    value: float
    interval: float
    determined: bool
    block_values: tuple[float, ...] = ()
    jacobian_interval: float = math.inf


@dataclass(frozen=True)
class FitResult:
    """The outcome of a fit.

    Attributes:
        estimates: one per fitted parameter, in the order fitted.
        calibration: the estimates as a calibration (undetermined ones included, at their estimate).
        cost_before: half the sum of squared scaled data residuals at the model's values.
        cost_after: the same at the estimates.
        evaluations: residual evaluations the optimizer made, the block refits' included.
        message: the optimizer's account of why it stopped.
        blocks: block refits made for the intervals (`FitConfig.interval_blocks`; 0: none).
        blocks_converged: how many of them converged.
        seconds: wall time of the fit, the block refits' included (s).
        workers: processes that replayed.
    """

    estimates: list[Estimate]
    calibration: LegCalibration
    cost_before: float
    cost_after: float
    evaluations: int
    message: str
    blocks: int = 0
    blocks_converged: int = 0
    seconds: float = 0.0
    workers: int = 1


@dataclass(frozen=True)
class _Solution:
    x: FloatArray  # the estimate, relative units
    r0: FloatArray  # residual at the model's values (data rows, then the prior's)
    fun: FloatArray  # residual at the estimate
    jac: FloatArray  # its Jacobian
    evaluations: int
    message: str
    converged: bool


def _solve(problem: _Problem, workers: int) -> _Solution:
    """Minimise the problem's residual from the model's values (x = 0) with the sysid toolbox."""
    from mujoco import sysid  # the toolbox of the mujoco[sysid] extra

    config, names = problem.config, problem.names
    params = sysid.ParameterDict()
    for name, v0, s in zip(names, problem.nominal, problem.scale, strict=True):
        spec = PARAMETERS[name]
        params.add(sysid.Parameter(name, 0.0, (spec.low - v0) / s, (spec.high - v0) / s))
    params.move_off_bounds()  # a delay or offset that starts on its bound would stall there

    cache: dict[bytes, FloatArray] = {}
    context = multiprocessing.get_context("fork")
    with ProcessPoolExecutor(
        workers, mp_context=context, initializer=_init_worker, initargs=(problem,)
    ) as pool:

        def residual_fn(x: FloatArray, _params: Any) -> tuple[list[FloatArray], list[Any], list[Any]]:
            columns = np.asarray(x, dtype=np.float64).reshape(len(names), -1)
            keys = [c.tobytes() for c in columns.T]
            todo = [i for i, k in enumerate(keys) if k not in cache]
            for i, r in zip(todo, pool.map(_worker_residual, [columns[:, i] for i in todo]), strict=True):
                cache[keys[i]] = r
            out = np.stack([cache[k] for k in keys], axis=1)
            if len(cache) > 4 * len(names):  # keep the last Jacobian's columns, not every one
                for k in list(cache)[: -2 * len(names)]:
                    del cache[k]
            return [out if np.ndim(x) > 1 else out[:, 0]], [], []

        r0 = residual_fn(np.zeros(len(names)), params)[0][0]
        opt_params, evaluations, cost, converged = params, 0, math.inf, True
        for _round in range(config.rounds):
            opt_params, result = sysid.optimize(
                opt_params,
                residual_fn,
                optimizer="scipy_parallel_fd",
                verbose=False,
                max_iters=config.max_evaluations,
                diff_step=config.diff_step,
                x_scale="jac",  # the parameters' sensitivities differ by orders of magnitude
                loss=config.loss,
                ftol=config.cost_tolerance,
            )
            evaluations += int(result.nfev)
            if int(result.status) not in _CONVERGED_STATUS:
                converged = False
                break
            improved = float(result.cost) < 0.99 * cost
            cost = float(result.cost)
            if not improved:
                break
    return _Solution(
        opt_params.as_vector(),
        r0,
        np.asarray(result.fun),
        np.asarray(result.jac),
        evaluations,
        str(result.message),
        converged,
    )


def block_half_width(block_x: FloatArray) -> FloatArray:
    """The 95 % half-width of a fit's error from its estimates on B stretches, shape (B, P) -> (P,).

    Student's t at B - 1 degrees of freedom times the stretches' standard deviation: the whole fit's
    error is taken to be distributed as one stretch's. Where the optimizer stops on the residual's
    roughness, not the recording's noise, sets the error, and it does not shrink with B times the data:
    the method of batch means (the same divided by sqrt(B)) held the truth for 83 % of parameters, this for
    94 % (docs/RESULTS.md, "Calibration intervals").
    """
    from scipy import stats

    spread: FloatArray = np.std(block_x, axis=0, ddof=1)
    return float(stats.t.ppf(0.975, block_x.shape[0] - 1)) * spread


def split_blocks(segments: Sequence[Segment], n_blocks: int, settle_ticks: int) -> list[list[Segment]]:
    """The segments' ticks cut into `n_blocks` consecutive stretches of equal length (to a tick).

    A stretch that begins inside a segment starts `settle_ticks` earlier (`Segment.block`).
    """
    total = sum(len(s) for s in segments)
    bounds = np.linspace(0, total, n_blocks + 1).round().astype(int)
    out: list[list[Segment]] = [[] for _ in range(n_blocks)]
    first = 0  # index of the segment's first tick among all
    for seg in segments:
        for b in range(n_blocks):
            lo, hi = max(bounds[b], first) - first, min(bounds[b + 1], first + len(seg)) - first
            if hi > lo:
                out[b].append(seg.block(lo, hi, settle_ticks))
        first += len(seg)
    return out


def fit(
    segments: Sequence[Segment], leg_config: MujocoLegConfig, config: FitConfig = FitConfig()
) -> FitResult:
    """Fit `config.parameters` so that the simulated rig replays `segments` as recorded.

    Then, for the intervals, the same fit on each of `config.interval_blocks` consecutive stretches of
    the segments: the residuals of a replay are neither independent nor noise (the multiple-shooting
    windows carry velocities, the contacts and the Coulomb friction make the cost rough, the optimizer
    stops on a relative decrease), so the Jacobian's interval is far too narrow; the spread of
    independent refits measures what a different recording would have given.

    Args:
        segments: recorded segments, each from the resting posture.
        leg_config: the simulated rig (carriage height, tick rate, sub-steps); its calibration is ignored:
            the fit starts from the model's values.
        config: what to fit and how.

    Raises:
        FitError: the optimizer stopped without converging.
        ConfigError: invalid settings.
    """
    from mujoco import sysid  # the toolbox of the mujoco[sysid] extra

    if not segments:
        raise ConfigError("segments: need at least one recorded segment")
    t0 = time.perf_counter()
    base = replay_config(leg_config)
    model = MujocoLeg(base).model
    values = model_values(model)
    names = tuple(config.parameters)
    nominal = np.array([values[n] for n in names])
    scale = np.array(
        [abs(v) if v != 0.0 else _ZERO_SCALES.get(n, 1.0) for n, v in zip(names, nominal, strict=True)]
    )
    problem = _Problem(tuple(segments), base, names, nominal, scale, config)
    workers = config.workers or os.cpu_count() or 1
    main = _solve(problem, workers)
    if not main.converged:
        raise FitError(f"the fit did not converge after {main.evaluations} evaluations: {main.message}")
    evaluations = main.evaluations
    n_data = main.r0.size - len(names)
    r_star = main.fun[:n_data]
    _cov, jacobian_hw = sysid.calculate_intervals([r_star], main.jac[:n_data])
    blocks = []
    if config.interval_blocks >= 2:
        for part in split_blocks(segments, config.interval_blocks, config.settle_ticks):
            solved = _solve(replace(problem, segments=tuple(part)), workers)
            evaluations += solved.evaluations
            blocks.append(solved)
    block_x = np.array([b.x for b in blocks]).reshape(len(blocks), len(names))
    spread_hw = block_half_width(block_x) if len(blocks) >= 2 else np.zeros(len(names))
    estimates, fitted, intervals, undetermined = [], {}, {}, []
    for i, name in enumerate(names):
        value = float(np.clip(nominal[i] + scale[i] * main.x[i], PARAMETERS[name].low, PARAMETERS[name].high))
        jac_width = float(scale[i] * jacobian_hw[i])
        width = max(jac_width, float(scale[i] * spread_hw[i]))
        determined = bool(math.isfinite(width) and width <= config.undetermined_share * scale[i])
        block_values = tuple(float(nominal[i] + scale[i] * x) for x in block_x[:, i])
        estimates.append(Estimate(name, float(nominal[i]), value, width, determined, block_values, jac_width))
        fitted[name], intervals[name] = value, width
        if not determined:
            undetermined.append(name)
    calibration = LegCalibration(fitted, intervals=intervals, undetermined=tuple(undetermined))
    return FitResult(
        estimates=estimates,
        calibration=calibration,
        cost_before=0.5 * float(np.sum(main.r0[:n_data] ** 2)),
        cost_after=0.5 * float(np.sum(r_star**2)),
        evaluations=evaluations,
        message=main.message,
        blocks=len(blocks),
        blocks_converged=sum(b.converged for b in blocks),
        seconds=time.perf_counter() - t0,
        workers=workers,
    )


def angle_errors_rad(
    segments: Sequence[Segment], leg_config: MujocoLegConfig, calibration: LegCalibration
) -> list[FloatArray]:
    """Simulated minus recorded joint angles, each segment replayed open loop from rest, shape (N, 2) each."""
    reps = replay(segments, replay_config(leg_config), calibration)
    return [r.position_rad - s.position_rad for r, s in zip(reps, segments, strict=True)]


def rmse_rad(errors: Sequence[FloatArray]) -> float:
    """Root mean square of angle errors over every tick and both joints (rad)."""
    return float(np.sqrt(np.mean(np.concatenate([e.ravel() for e in errors]) ** 2)))


__all__ = [
    "DEFAULT_PARAMETERS",
    "Estimate",
    "FitConfig",
    "FitError",
    "FitResult",
    "Replay",
    "angle_errors_rad",
    "fit",
    "replay",
    "replay_config",
    "rmse_rad",
]
