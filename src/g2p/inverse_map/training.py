"""Training of the inverse map's network in torch: Levenberg-Marquardt, L-BFGS, Adam, early stopping.

`g2p.inverse_map` imports this module only when it trains, so that importing the map (its configuration,
prediction and files) does not import torch (about a second).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np
import torch
from numpy.typing import NDArray

from g2p.inverse_map.config import N_INPUTS, N_OUTPUTS, FitCancelled, InverseMapConfig, Optimizer, StopReason

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class TrainResult:
    """What `train` returns.

    Attributes:
        params: the kept weights [w_hidden (H, 6), b_hidden (H,), w_out (3, H), b_out (3,)].
        iterations: iterations run (see `Optimizer` for what one is).
        best_iteration: iteration whose weights were kept (0: the starting weights).
        stop_reason: why training stopped.
        train_rmse: RMS error on the training split with the kept weights (activation units, unclipped).
        validation_rmse: the same on the validation split.
    """

    params: list[FloatArray]
    iterations: int
    best_iteration: int
    stop_reason: StopReason
    train_rmse: float
    validation_rmse: float


def train(
    params: list[FloatArray],
    x_train: FloatArray,
    y_train: FloatArray,
    x_val: FloatArray,
    y_val: FloatArray,
    y_scale: FloatArray,
    cfg: InverseMapConfig,
    max_iterations: int,
    rng: np.random.Generator,
    cancel: threading.Event | None = None,
) -> TrainResult:
    """Train from `params` on normalized data, keeping the weights of the best validation error.

    Args:
        params: starting weights [w_hidden (H, 6), b_hidden (H,), w_out (3, H), b_out (3,)].
        x_train: normalized training inputs (n, 6).
        y_train: their normalized targets (n, 3).
        x_val: normalized held-out inputs (m, 6).
        y_val: their normalized targets (m, 3).
        y_scale: each output's normalization scale (3,), to report errors in activation units.
        cfg: optimizer, patience and threads.
        max_iterations: iteration budget.
        rng: source of minibatch order (Adam).
        cancel: when set, training stops at the next iteration with FitCancelled.

    Raises:
        FitCancelled: `cancel` was set.
    """
    split = _Split(*(torch.from_numpy(a) for a in (x_train, y_train, x_val, y_val)))
    trainer = {Optimizer.LM: _train_lm, Optimizer.LBFGS: _train_lbfgs, Optimizer.ADAM: _train_adam}
    with _threads(cfg.num_threads):
        theta, iterations, best_iteration, reason = trainer[cfg.optimizer](
            _flatten([torch.from_numpy(p) for p in params]), split, cfg, max_iterations, rng, cancel
        )
    out_scale = torch.from_numpy(y_scale)
    with torch.no_grad():
        rmse = [
            float(torch.sqrt(torch.mean(((_forward(theta, cfg.n_hidden, xx) - yy) * out_scale) ** 2)))
            for xx, yy in ((split.x_train, split.y_train), (split.x_val, split.y_val))
        ]
    params_out = [p.numpy() for p in _unflatten(theta, cfg.n_hidden)]
    return TrainResult(params_out, iterations, best_iteration, reason, rmse[0], rmse[1])


def _flatten(params: list[torch.Tensor]) -> torch.Tensor:
    """Parameter vector: [w_hidden | b_hidden] (H, 7) row-major, then [w_out | b_out] (3, H + 1) row-major."""
    w1, b1, w2, b2 = (p.detach().to(torch.float64) for p in params)
    hidden, out = torch.cat([w1, b1[:, None]], 1), torch.cat([w2, b2[:, None]], 1)
    return torch.cat([hidden.reshape(-1), out.reshape(-1)])


def _split_theta(theta: torch.Tensor, n_hidden: int) -> tuple[torch.Tensor, ...]:
    """Views (w_hidden, b_hidden, w_out, b_out) into a parameter vector."""
    h = n_hidden
    hidden = theta[: h * (N_INPUTS + 1)].reshape(h, N_INPUTS + 1)
    out = theta[h * (N_INPUTS + 1) :].reshape(N_OUTPUTS, h + 1)
    return hidden[:, :N_INPUTS], hidden[:, N_INPUTS], out[:, :h], out[:, h]


def _unflatten(theta: torch.Tensor, n_hidden: int) -> list[torch.Tensor]:
    return [p.clone() for p in _split_theta(theta.detach(), n_hidden)]


def _forward(theta: torch.Tensor, n_hidden: int, x: torch.Tensor) -> torch.Tensor:
    w1, b1, w2, b2 = _split_theta(theta, n_hidden)
    return torch.addmm(b2, torch.tanh(torch.addmm(b1, x, w1.T)), w2.T)


@contextmanager
def _threads(n: int) -> Iterator[None]:
    """Set torch's intra-op threads for the duration (n = 0: leave as is)."""
    if n == 0:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@dataclass(frozen=True)
class _Split:
    x_train: torch.Tensor
    y_train: torch.Tensor
    x_val: torch.Tensor
    y_val: torch.Tensor


class _EarlyStopping:
    """Keeps the parameters of the best validation error; says when `patience` checks brought none better."""

    def __init__(
        self,
        theta: torch.Tensor,
        split: _Split,
        n_hidden: int,
        patience: int,
        cancel: threading.Event | None = None,
    ) -> None:
        self.split, self.n_hidden, self.patience, self.cancel = split, n_hidden, patience, cancel
        self.best_theta = theta.detach().clone()
        self.best_error = self.error(theta)
        self.best_iteration = 0
        self.fails = 0

    def error(self, theta: torch.Tensor) -> float:
        with torch.no_grad():
            out = _forward(theta, self.n_hidden, self.split.x_val)
            return float(torch.mean((out - self.split.y_val) ** 2))

    def should_stop(self, theta: torch.Tensor, iteration: int) -> bool:
        """After each iteration: whether to stop early; FitCancelled when a cancel was requested."""
        if self.cancel is not None and self.cancel.is_set():
            raise FitCancelled(f"fit cancelled after {iteration} iterations")
        err = self.error(theta)
        if err < self.best_error:
            self.best_theta, self.best_error = theta.detach().clone(), err
            self.best_iteration, self.fails = iteration, 0
            return False
        self.fails += 1
        return self.fails >= self.patience


def _train_lm(
    theta: torch.Tensor,
    split: _Split,
    cfg: InverseMapConfig,
    max_iterations: int,
    rng: np.random.Generator,
    cancel: threading.Event | None = None,
) -> tuple[torch.Tensor, int, int, StopReason]:
    """Levenberg-Marquardt with MATLAB trainlm's damping schedule and an analytic Gauss-Newton matrix."""
    del rng  # full batch, deterministic
    h, x, y = cfg.n_hidden, split.x_train, split.y_train
    stopper = _EarlyStopping(theta, split, h, cfg.patience, cancel)
    mu = cfg.lm_mu
    eye = torch.eye(theta.numel(), dtype=torch.float64)
    hid, res = _hidden_and_residual(theta, h, x, y)
    sse = float(torch.sum(res * res))
    for it in range(1, max_iterations + 1):
        jtj, grad = _gauss_newton(theta, h, x, hid, res)
        while True:  # raise the damping until a step lowers the training error
            candidate = theta - torch.linalg.solve(jtj + mu * eye, grad)
            hid_c, res_c = _hidden_and_residual(candidate, h, x, y)
            sse_c = float(torch.sum(res_c * res_c))
            if sse_c < sse:
                theta, hid, res, sse = candidate, hid_c, res_c, sse_c
                mu = max(mu * cfg.lm_mu_decrease, 1e-20)
                break
            mu *= cfg.lm_mu_increase
            if mu > cfg.lm_mu_max:
                return stopper.best_theta, it - 1, stopper.best_iteration, StopReason.CONVERGED
        if stopper.should_stop(theta, it):
            return stopper.best_theta, it, stopper.best_iteration, StopReason.VALIDATION
    return stopper.best_theta, max_iterations, stopper.best_iteration, StopReason.MAX_ITERATIONS


def _hidden_and_residual(
    theta: torch.Tensor, n_hidden: int, x: torch.Tensor, y: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Hidden activations (n, H) and residuals net(x) - y (n, 3)."""
    w1, b1, w2, b2 = _split_theta(theta, n_hidden)
    hid = torch.tanh(torch.addmm(b1, x, w1.T))
    return hid, torch.addmm(b2, hid, w2.T) - y


def _gauss_newton(
    theta: torch.Tensor, n_hidden: int, x: torch.Tensor, hid: torch.Tensor, res: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """J^T J and J^T r of the residuals r = net(x) - y over all outputs, without forming J.

    With d = 1 - h^2, xa = [x, 1] and ha = [h, 1] per sample, output k's Jacobian row is
    [(w_out[k] * d) (x) xa, e_k (x) ha]. Hence the hidden block of J^T J is (P^T P) * kron(w_out^T w_out, 1)
    with P = d (x) xa (one product for the three outputs), the output block is kron(I_3, ha^T ha), and the
    cross block of output k is (P^T ha) * w_out[k] per hidden unit. The products with P are computed in
    float32 (they only shape the step; every step is accepted on the float64 error); the gradient is float64.

    Args:
        theta: parameters (see `_flatten`).
        n_hidden: hidden units H.
        x: inputs (n, 6).
        hid: hidden activations at theta (n, H).
        res: residuals at theta (n, 3).
    """
    h_units, n = n_hidden, len(x)
    _, _, w2, _ = _split_theta(theta, h_units)
    d = 1.0 - hid * hid
    ones = torch.ones(n, 1, dtype=x.dtype)
    xa, ha = torch.cat([x, ones], 1), torch.cat([hid, ones], 1)  # (n, 7), (n, H + 1)
    grad = torch.cat([((d * (res @ w2)).T @ xa).reshape(-1), (res.T @ ha).reshape(-1)])
    p = (d.float()[:, :, None] * xa.float()[:, None, :]).reshape(n, -1)  # (n, 7H)
    p_p, p_ha = (p.T @ p).double(), (p.T @ ha.float()).double()
    w_rep = w2.repeat_interleave(N_INPUTS + 1, dim=1)  # (3, 7H): w_out[k, j] for each hidden parameter
    hidden = p_p * torch.kron(w2.T @ w2, torch.ones(N_INPUTS + 1, N_INPUTS + 1, dtype=x.dtype))
    cross = torch.cat([p_ha * w_rep[k][:, None] for k in range(N_OUTPUTS)], 1)
    out = torch.kron(torch.eye(N_OUTPUTS, dtype=x.dtype), ha.T @ ha)
    jtj = torch.cat([torch.cat([hidden, cross], 1), torch.cat([cross.T, out], 1)], 0)
    return jtj, grad


def _train_lbfgs(
    theta: torch.Tensor,
    split: _Split,
    cfg: InverseMapConfig,
    max_iterations: int,
    rng: np.random.Generator,
    cancel: threading.Event | None = None,
) -> tuple[torch.Tensor, int, int, StopReason]:
    """Full-batch L-BFGS, one iteration per validation check."""
    del rng  # full batch, deterministic
    h = cfg.n_hidden
    stopper = _EarlyStopping(theta, split, h, cfg.patience, cancel)
    param = theta.detach().clone().requires_grad_(True)
    opt = torch.optim.LBFGS(
        [param],
        lr=1.0,
        max_iter=1,
        max_eval=25,
        history_size=cfg.lbfgs_history,
        line_search_fn="strong_wolfe",
        tolerance_grad=1e-12,
        tolerance_change=1e-15,
    )

    def closure() -> torch.Tensor:
        opt.zero_grad()
        loss = torch.mean((_forward(param, h, split.x_train) - split.y_train) ** 2)
        loss.backward()  # type: ignore[no-untyped-call]
        return loss

    previous = param.detach().clone()
    for it in range(1, max_iterations + 1):
        opt.step(closure)  # type: ignore[no-untyped-call]
        current = param.detach()
        if torch.equal(current, previous):
            return stopper.best_theta, it, stopper.best_iteration, StopReason.CONVERGED
        previous = current.clone()
        if stopper.should_stop(current, it):
            return stopper.best_theta, it, stopper.best_iteration, StopReason.VALIDATION
    return stopper.best_theta, max_iterations, stopper.best_iteration, StopReason.MAX_ITERATIONS


def _train_adam(
    theta: torch.Tensor,
    split: _Split,
    cfg: InverseMapConfig,
    max_iterations: int,
    rng: np.random.Generator,
    cancel: threading.Event | None = None,
) -> tuple[torch.Tensor, int, int, StopReason]:
    """Adam on minibatches shuffled by `rng`, one epoch per validation check."""
    h = cfg.n_hidden
    stopper = _EarlyStopping(theta, split, h, cfg.patience, cancel)
    param = theta.detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([param], lr=cfg.adam_learning_rate)
    n, bs = len(split.x_train), cfg.adam_batch_size
    for it in range(1, max_iterations + 1):
        order = torch.from_numpy(rng.permutation(n))
        for start in range(0, n, bs):
            batch = order[start : start + bs]
            opt.zero_grad()
            loss = torch.mean((_forward(param, h, split.x_train[batch]) - split.y_train[batch]) ** 2)
            loss.backward()  # type: ignore[no-untyped-call]
            opt.step()
        if stopper.should_stop(param.detach(), it):
            return stopper.best_theta, it, stopper.best_iteration, StopReason.VALIDATION
    return stopper.best_theta, max_iterations, stopper.best_iteration, StopReason.MAX_ITERATIONS
