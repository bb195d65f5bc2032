"""The inverse map: a 6 -> 15 -> 3 MLP from kinematics to motor activations, fitted and refined in torch.

Inputs are kinematics rows [q_prox, q_dist, dq_prox, dq_dist, ddq_prox, ddq_dist] (rad, rad/s, rad/s^2);
outputs are activations of M0..M2 in [low, high] = [0.15, 1]. Inputs and targets are normalized column-wise
(the authors' MATLAB mapminmax: min -> -1, max -> +1) with constants fixed at the initial fit and kept for
every refinement, so warm-started weights keep their meaning. The hidden layer is tanh; the output layer is
linear on the normalized targets and `predict` clips to [low, high] (see docs/ALGORITHM.md: targets sit at
the bounds, where a tanh output would need infinite pre-activations).

Training minimizes the mean squared error on a random training split with early stopping on a held-out
validation split (the weights of the best validation error are kept); each sample keeps its side of the split
across refinements. The default optimizer is
Levenberg-Marquardt, as the authors' MATLAB trainlm; full-batch L-BFGS and minibatch Adam are selectable.
The training runs in torch (`g2p.inverse_map.training`), imported by the first fit: torch takes about a second
to import, and the map's configuration, prediction and files need none of it.

May import: nothing of g2p beyond the top-level modules.
"""

from __future__ import annotations

import math
import os
import threading
import time
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from g2p.inverse_map.config import (
    N_INPUTS,
    N_OUTPUTS,
    FitCancelled,
    InverseMapConfig,
    Normalization,
    Optimizer,
    StopReason,
)
from g2p.validation import ConfigError

FloatArray = NDArray[np.float64]

__all__ = [
    "FORMAT_VERSION",
    "N_INPUTS",
    "N_OUTPUTS",
    "FitCancelled",
    "FitReport",
    "FloatArray",
    "InverseMap",
    "InverseMapConfig",
    "InverseMapError",
    "InverseMapFormatError",
    "Normalization",
    "Optimizer",
    "StopReason",
    "random_map",
]

FORMAT_VERSION = 1
"""Version of the `to_arrays` / `save` format; bump on any change of names, shapes or meaning."""
_KIND = "g2p.inverse_map"
_ARRAY_SHAPES = {  # name -> shape, with H = hidden units
    "w_hidden": ("H", N_INPUTS),
    "b_hidden": ("H",),
    "w_out": (N_OUTPUTS, "H"),
    "b_out": (N_OUTPUTS,),
    "x_offset": (N_INPUTS,),
    "x_scale": (N_INPUTS,),
    "y_offset": (N_OUTPUTS,),
    "y_scale": (N_OUTPUTS,),
    "activation_range": (2,),
}


class InverseMapError(ValueError):
    """The inverse map cannot do what was asked (not fitted, wrong data shape)."""


class InverseMapFormatError(InverseMapError):
    """Stored weights are corrupt, incomplete or of another format version."""


@dataclass(frozen=True)
class FitReport:
    """What one fit or refinement did.

    Attributes:
        n_train: training samples.
        n_validation: validation samples.
        iterations: iterations run (see `Optimizer` for what one is).
        best_iteration: iteration whose weights were kept (0: the starting weights).
        train_rmse: RMS error on the training split with the kept weights (activation units, unclipped).
        validation_rmse: the same on the validation split.
        seconds: wall-clock time (s).
        stop_reason: why training stopped.
    """

    n_train: int
    n_validation: int
    iterations: int
    best_iteration: int
    train_rmse: float
    validation_rmse: float
    seconds: float
    stop_reason: StopReason


@dataclass(frozen=True)
class _Scaling:
    """x_normalized = (x - offset) / scale, column-wise."""

    offset: FloatArray
    scale: FloatArray

    @classmethod
    def of(cls, data: FloatArray, kind: Normalization) -> _Scaling:
        if kind is Normalization.MINMAX:
            lo, hi = data.min(axis=0), data.max(axis=0)
            offset, scale = (hi + lo) / 2.0, (hi - lo) / 2.0
        else:
            offset, scale = data.mean(axis=0), data.std(axis=0)
        # A constant column carries no information; a unit scale keeps it harmless instead of dividing by 0.
        return cls(offset, np.where(scale > 1e-12 * np.maximum(1.0, np.abs(offset)), scale, 1.0))

    def forward(self, data: FloatArray) -> FloatArray:
        return (data - self.offset) / self.scale

    def inverse(self, data: FloatArray) -> FloatArray:
        return data * self.scale + self.offset


class InverseMap:
    """Kinematics (N, 6) -> activations (N, 3), fitted on babbling and refined on every attempt.

    Args:
        config: network and training parameters; the defaults when None.
    """

    def __init__(self, config: InverseMapConfig | None = None) -> None:
        self.config = config or InverseMapConfig()
        # w_hidden (H, 6), b_hidden (H,), w_out (3, H), b_out (3,)
        self._params: list[FloatArray] | None = None
        self._x: _Scaling | None = None
        self._y: _Scaling | None = None
        self._is_validation: NDArray[np.bool_] | None = None  # the split of every sample seen so far
        self.last_report: FitReport | None = None
        """Report of the latest fit or refinement (None before the first)."""

    @property
    def is_fitted(self) -> bool:
        """Whether weights and normalization exist (after `fit` or loading)."""
        return self._params is not None

    @property
    def validation_mask(self) -> NDArray[np.bool_] | None:
        """Which of the samples trained on so far are held out, shape (N,) (a copy); None before training."""
        return None if self._is_validation is None else self._is_validation.copy()

    def fit(
        self, x: ArrayLike, y: ArrayLike, rng: np.random.Generator, cancel: threading.Event | None = None
    ) -> FitReport:
        """Initial fit from fresh random weights; fixes the normalization for all later refinements.

        Args:
            x: kinematics, shape (N, 6) (rad, rad/s, rad/s^2), finite.
            y: activations that produced them, shape (N, 3), finite.
            rng: source of the weight initialization, the validation split and minibatch order.
            cancel: when set, the fit stops with FitCancelled and the map is left as it was.

        Returns:
            What the fit did (also kept in `last_report`).

        Raises:
            InverseMapError: wrong shapes, non-finite values or too few samples.
            FitCancelled: `cancel` was set.
        """
        xa, ya = _check_data(x, y, self.config)
        before = (self._params, self._x, self._y, self._is_validation)
        self._x = _Scaling.of(xa, self.config.normalization)
        self._y = _Scaling.of(ya, self.config.normalization)
        self._params = _init_params(self.config.n_hidden, rng)
        self._is_validation = None
        try:
            return self._train(xa, ya, rng, self.config.max_iterations_fit, cancel)
        except FitCancelled:
            self._params, self._x, self._y, self._is_validation = before
            raise

    def refine(
        self,
        x_all: ArrayLike,
        y_all: ArrayLike,
        rng: np.random.Generator,
        cancel: threading.Event | None = None,
        rows: NDArray[np.bool_] | None = None,
    ) -> FitReport:
        """Continue training from the current weights on all data so far (babbling + every attempt).

        The normalization of the initial fit is kept, and so is each sample's side of the train/validation
        split: the first rows are expected to be the data of the previous fit or refinement (data only grow),
        only the new rows are split at random. The starting weights then never saw the validation samples,
        so early stopping measures progress honestly (re-splitting would put samples already trained on into
        the validation set and often stop before the first step).

        Args:
            x_all: kinematics, shape (N, 6), finite; N at least the number of samples of the previous call.
            y_all: activations, shape (N, 3), finite.
            rng: source of the validation split and minibatch order.
            cancel: when set, the refinement stops with FitCancelled and the map is left as it was.
            rows: the samples this refinement trains and validates on, shape (N,) bool; None: all. Every
                sample still gets its side of the split, so a later refinement on other rows keeps it.

        Returns:
            What the refinement did (also kept in `last_report`).

        Raises:
            InverseMapError: not fitted yet, wrong shapes, non-finite values, or fewer samples than before.
            FitCancelled: `cancel` was set.
        """
        self._require_fitted()
        xa, ya = _check_data(x_all, y_all, self.config)
        if rows is not None and (np.shape(rows) != (len(xa),) or np.asarray(rows).dtype != np.bool_):
            raise InverseMapError(f"rows: expected a bool array of shape ({len(xa)},), got {np.shape(rows)}")
        if self._is_validation is not None and len(xa) < len(self._is_validation):
            raise InverseMapError(
                f"x_all: refine needs all data so far, got {len(xa)} samples after {len(self._is_validation)}"
            )
        before = self._is_validation
        try:
            return self._train(xa, ya, rng, self.config.max_iterations_refine, cancel, rows)
        except FitCancelled:
            self._is_validation = before
            raise

    def predict(self, x: ArrayLike) -> FloatArray:
        """Activations for kinematics, clipped to [activation_low, activation_high].

        Args:
            x: kinematics, shape (N, 6) or (6,) (rad, rad/s, rad/s^2).

        Returns:
            Activations, shape (N, 3) (or (3,) for a single row); each row's is the same, bit for bit,
            whatever batch it is predicted in.

        Raises:
            InverseMapError: not fitted, wrong shape or non-finite input.
        """
        params, xs, ys = self._require_fitted()
        xa = np.asarray(x, dtype=np.float64)
        single = xa.ndim == 1
        xa = np.atleast_2d(xa)
        if xa.ndim != 2 or xa.shape[1] != N_INPUTS:
            raise InverseMapError(f"x: expected shape (N, {N_INPUTS}), got {np.shape(x)}")
        if not np.all(np.isfinite(xa)):
            raise InverseMapError("x: non-finite values")
        w1, b1, w2, b2 = params
        # Products summed row by row rather than a BLAS matrix product, whose summation order depends on
        # the batch: a rig evaluating the map one tick at a time (g2p.rig.closed_loop) then gets exactly the
        # activations a whole sequence gets.
        hidden = np.tanh((xs.forward(xa)[:, np.newaxis, :] * w1).sum(axis=2) + b1)
        out = ys.inverse((hidden[:, np.newaxis, :] * w2).sum(axis=2) + b2)
        out = np.clip(out, self.config.activation_low, self.config.activation_high)
        return out[0] if single else out

    def to_arrays(self) -> dict[str, FloatArray]:
        """Weights, normalization and activation range as named float64 arrays, plus `format_version`.

        Returns:
            {'format_version': [1], 'w_hidden': (H, 6), 'b_hidden': (H,), 'w_out': (3, H), 'b_out': (3,),
            'x_offset': (6,), 'x_scale': (6,), 'y_offset': (3,), 'y_scale': (3,), 'activation_range': (2,)};
            a model's input is normalized as (x - x_offset) / x_scale and its output denormalized as
            y * y_scale + y_offset.
        """
        params, xs, ys = self._require_fitted()
        w1, b1, w2, b2 = (p.copy() for p in params)
        return {
            "format_version": np.array([float(FORMAT_VERSION)]),
            "w_hidden": w1,
            "b_hidden": b1,
            "w_out": w2,
            "b_out": b2,
            "x_offset": xs.offset.copy(),
            "x_scale": xs.scale.copy(),
            "y_offset": ys.offset.copy(),
            "y_scale": ys.scale.copy(),
            "activation_range": np.array([self.config.activation_low, self.config.activation_high]),
        }

    @classmethod
    def from_arrays(
        cls,
        arrays: Mapping[str, ArrayLike],
        config: InverseMapConfig | None = None,
        source: str = "arrays",
        validation_mask: ArrayLike | None = None,
    ) -> InverseMap:
        """Rebuild a map from `to_arrays` output.

        Args:
            arrays: the named arrays.
            config: training parameters for later refinements; n_hidden and the activation range come from
                the arrays.
            source: what the arrays came from, for error messages (e.g. a file name).
            validation_mask: the saved map's `validation_mask`, shape (N,) bool, so that the next refinement
                keeps each of the first N samples on its side of the split, as the saved map would; None:
                the next refinement splits all samples afresh.

        Raises:
            InverseMapFormatError: missing or extra names, wrong version, shapes or non-finite values, or a
                validation mask that is not a 1-D boolean array with samples on both sides.
        """
        version = np.asarray(arrays.get("format_version", np.array([])), dtype=np.float64).ravel()
        if version.shape != (1,) or version[0] != FORMAT_VERSION:
            raise InverseMapFormatError(
                f"{source}: format_version {version.tolist()} is not supported (expected [{FORMAT_VERSION}])"
            )
        names = set(arrays) - {"format_version", "kind"}
        if names != set(_ARRAY_SHAPES):
            raise InverseMapFormatError(
                f"{source}: missing {sorted(set(_ARRAY_SHAPES) - names)}, "
                f"unexpected {sorted(names - set(_ARRAY_SHAPES))}"
            )
        a = {k: np.asarray(arrays[k], dtype=np.float64) for k in _ARRAY_SHAPES}
        hidden = a["w_hidden"].shape[0] if a["w_hidden"].ndim == 2 else -1
        for name, shape in _ARRAY_SHAPES.items():
            expected = tuple(hidden if d == "H" else d for d in shape)
            if a[name].shape != expected:
                raise InverseMapFormatError(
                    f"{source}: {name} has shape {a[name].shape}, expected {expected}"
                )
            if not np.all(np.isfinite(a[name])):
                raise InverseMapFormatError(f"{source}: {name} has non-finite values")
        if np.any(a["x_scale"] <= 0) or np.any(a["y_scale"] <= 0):
            raise InverseMapFormatError(f"{source}: x_scale and y_scale must be > 0")
        base = config or InverseMapConfig()
        try:
            cfg = InverseMapConfig(
                **{
                    **base.__dict__,
                    "n_hidden": hidden,
                    "activation_low": float(a["activation_range"][0]),
                    "activation_high": float(a["activation_range"][1]),
                }
            )
        except ConfigError as err:
            raise InverseMapFormatError(f"{source}: {err}") from err
        net = cls(cfg)
        net._params = [a[k].copy() for k in ("w_hidden", "b_hidden", "w_out", "b_out")]
        net._x = _Scaling(a["x_offset"], a["x_scale"])
        net._y = _Scaling(a["y_offset"], a["y_scale"])
        if validation_mask is not None:
            mask = np.asarray(validation_mask)
            if mask.dtype != np.bool_ or mask.ndim != 1 or mask.all() or not mask.any():
                raise InverseMapFormatError(
                    f"{source}: validation_mask must be a 1-D boolean array with samples on both sides, "
                    f"got dtype {mask.dtype}, shape {mask.shape}"
                )
            net._is_validation = mask.copy()
        return net

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write `to_arrays` to an uncompressed .npz file (written to a temporary name, then renamed).

        Args:
            path: destination; numpy appends '.npz' when the name has no such suffix.
        """
        target = Path(path)
        if target.suffix != ".npz":
            target = target.with_name(target.name + ".npz")
        tmp = target.with_name(target.name + ".tmp.npz")
        np.savez(tmp, kind=np.array(_KIND), **self.to_arrays())  # type: ignore[arg-type]
        os.replace(tmp, target)

    @classmethod
    def load(cls, path: str | os.PathLike[str], config: InverseMapConfig | None = None) -> InverseMap:
        """Read a map written by `save`.

        Args:
            path: the .npz file.
            config: training parameters for later refinements (see `from_arrays`).

        Raises:
            InverseMapFormatError: the file is unreadable, not an inverse map, or of another format version;
                the message names the file.
        """
        try:
            with np.load(path, allow_pickle=False) as data:
                arrays = {k: data[k] for k in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as err:
            raise InverseMapFormatError(f"{os.fspath(path)}: not a readable .npz file: {err}") from err
        kind = str(arrays.pop("kind", ""))
        if kind != _KIND:
            raise InverseMapFormatError(
                f"{os.fspath(path)}: not an inverse map (kind {kind!r}, expected {_KIND!r})"
            )
        return cls.from_arrays(arrays, config, source=os.fspath(path))

    def _require_fitted(self) -> tuple[list[FloatArray], _Scaling, _Scaling]:
        if self._params is None or self._x is None or self._y is None:
            raise InverseMapError("the inverse map is not fitted: call fit() or load() first")
        return self._params, self._x, self._y

    def _train(
        self,
        x: FloatArray,
        y: FloatArray,
        rng: np.random.Generator,
        max_iterations: int,
        cancel: threading.Event | None,
        rows: NDArray[np.bool_] | None = None,
    ) -> FitReport:
        from g2p.inverse_map.training import train  # torch: see the module docstring

        params, xs, ys = self._require_fitted()
        cfg = self.config
        self._is_validation = _extend_split(self._is_validation, len(x), cfg.validation_fraction, rng)
        used = np.ones(len(x), dtype=bool) if rows is None else rows
        val = np.flatnonzero(self._is_validation & used)
        train_rows = np.flatnonzero(~self._is_validation & used)
        xn, yn = xs.forward(x), ys.forward(y)
        start = time.perf_counter()
        result = train(
            params,
            xn[train_rows],
            yn[train_rows],
            xn[val],
            yn[val],
            ys.scale,
            cfg,
            max_iterations,
            rng,
            cancel,
        )
        self._params = result.params
        self.last_report = FitReport(
            len(train_rows),
            len(val),
            result.iterations,
            result.best_iteration,
            result.train_rmse,
            result.validation_rmse,
            time.perf_counter() - start,
            result.stop_reason,
        )
        return self.last_report


def random_map(rng: np.random.Generator, n_hidden: int = InverseMapConfig.n_hidden) -> InverseMap:
    """A map ready to predict without training: random weights, normalized for the limit cycles' workspace.

    For tests and benchmarks of what runs a map rather than of what it predicts (the rig's per-tick cost,
    a trajectory goal's plumbing); the same generator state gives the same map. Weights: hidden (H, 6) from
    N(0, 1), hidden biases (H,) from N(0, 0.5), outputs (3, H) from N(0, 0.7), output biases 0, drawn in
    that order. Inputs are scaled from angles of 0 and -0.6 rad +- 0.6 rad, velocities of +- 5 rad/s and
    accelerations of +- 50 rad/s^2; outputs onto the default activation range.

    Args:
        rng: source of the weights.
        n_hidden: hidden tanh units (H).
    """
    low, high = InverseMapConfig.activation_low, InverseMapConfig.activation_high
    return InverseMap.from_arrays(
        {
            "format_version": np.array([float(FORMAT_VERSION)]),
            "w_hidden": rng.normal(0.0, 1.0, (n_hidden, N_INPUTS)),
            "b_hidden": rng.normal(0.0, 0.5, n_hidden),
            "w_out": rng.normal(0.0, 0.7, (N_OUTPUTS, n_hidden)),
            "b_out": np.zeros(N_OUTPUTS),
            "x_offset": np.array([0.0, -0.6, 0.0, 0.0, 0.0, 0.0]),
            "x_scale": np.array([0.6, 0.6, 5.0, 5.0, 50.0, 50.0]),
            "y_offset": np.full(N_OUTPUTS, (high + low) / 2.0),
            "y_scale": np.full(N_OUTPUTS, (high - low) / 2.0),
            "activation_range": np.array([low, high]),
        },
        source="random map",
    )


def _check_data(x: ArrayLike, y: ArrayLike, config: InverseMapConfig) -> tuple[FloatArray, FloatArray]:
    xa, ya = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    if xa.ndim != 2 or xa.shape[1] != N_INPUTS:
        raise InverseMapError(f"x: expected shape (N, {N_INPUTS}), got {xa.shape}")
    if ya.shape != (len(xa), N_OUTPUTS):
        raise InverseMapError(f"y: expected shape ({len(xa)}, {N_OUTPUTS}), got {ya.shape}")
    if not (np.all(np.isfinite(xa)) and np.all(np.isfinite(ya))):
        raise InverseMapError("x, y: non-finite values")
    n_min = math.ceil(2.0 / config.validation_fraction)
    if len(xa) < n_min:
        raise InverseMapError(f"x, y: need at least {n_min} samples to hold some out, got {len(xa)}")
    return xa, ya


def _extend_split(
    is_validation: NDArray[np.bool_] | None, n: int, fraction: float, rng: np.random.Generator
) -> NDArray[np.bool_]:
    """Keep the split of the first rows; send new rows to validation so that about `fraction` of all are."""
    old = np.zeros(0, dtype=bool) if is_validation is None else is_validation
    n_new = n - len(old)
    n_val_new = min(n_new, max(0, round(fraction * n) - int(old.sum())))
    new = np.zeros(n_new, dtype=bool)
    new[rng.permutation(n_new)[:n_val_new]] = True
    out = np.concatenate([old, new])
    if out.all() or not out.any():
        raise InverseMapError(f"cannot split {n} samples into training and validation")
    return out


def _init_params(n_hidden: int, rng: np.random.Generator) -> list[FloatArray]:
    """Nguyen-Widrow hidden layer (MATLAB's initnw): units spread so their active regions tile [-1, 1]^6."""
    beta = 0.7 * n_hidden ** (1.0 / N_INPUTS)
    w1 = rng.uniform(-1.0, 1.0, size=(n_hidden, N_INPUTS))
    w1 *= beta / np.linalg.norm(w1, axis=1, keepdims=True)
    b1 = beta * np.linspace(-1.0, 1.0, n_hidden) * np.sign(w1[:, 0]) if n_hidden > 1 else np.zeros(1)
    w2 = rng.uniform(-1.0, 1.0, size=(N_OUTPUTS, n_hidden)) / math.sqrt(n_hidden)
    b2 = np.zeros(N_OUTPUTS)
    return [w1, b1, w2, b2]
