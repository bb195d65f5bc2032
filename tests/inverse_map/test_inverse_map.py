"""Inverse map: recovery of a known map, warm-start refinement, seeding, persistence, validation."""

from __future__ import annotations

import threading
import time
import zipfile
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from g2p import inverse_map as im
from g2p.inverse_map import (
    FORMAT_VERSION,
    InverseMap,
    InverseMapConfig,
    InverseMapError,
    InverseMapFormatError,
    Optimizer,
    StopReason,
)
from g2p.inverse_map import training as imt
from g2p.validation import ConfigError

# Kinematics-like input scales: angles ~1 rad, velocities ~5-10 rad/s, accelerations ~50-100 rad/s^2.
SCALE = np.array([1.0, 1.5, 5.0, 10.0, 50.0, 100.0])
CFG = InverseMapConfig(max_iterations_fit=300)


def known_map(x: np.ndarray) -> np.ndarray:
    """A smooth nonlinear 6 -> 3 map with outputs in [0.25, 0.85], coupling several inputs per output."""
    u = x / SCALE
    return np.stack(
        [
            0.55 + 0.3 * np.tanh(u[:, 0] + 0.5 * u[:, 4] - 0.3 * u[:, 1]),
            0.55 + 0.25 * np.sin(u[:, 1] + 0.5 * u[:, 2]) * np.cos(0.5 * u[:, 0]),
            0.55 + 0.2 * np.tanh(u[:, 3] - u[:, 5] + 0.5 * u[:, 0] * u[:, 1]),
        ],
        axis=1,
    )


def sample(rng: np.random.Generator, n: int, side: int = 0) -> np.ndarray:
    """Inputs uniform in the box; side = -1 / +1 keeps only x0 <= 0 / >= 0."""
    x = rng.uniform(-1.0, 1.0, (n, 6))
    if side:
        x[:, 0] = side * np.abs(x[:, 0])
    return x * SCALE


def rmse(net: InverseMap, x: np.ndarray) -> float:
    return float(np.sqrt(np.mean((net.predict(x) - known_map(x)) ** 2)))


@pytest.fixture(scope="module")
def fitted() -> InverseMap:
    x = sample(np.random.default_rng(0), 2000)
    net = InverseMap(CFG)
    net.fit(x, known_map(x), np.random.default_rng(1))
    return net


def test_recovers_a_known_map(fitted: InverseMap) -> None:
    # Held-out RMSE below 0.005 (activation units) on a map whose outputs swing by +-0.3: under 2 %.
    assert rmse(fitted, sample(np.random.default_rng(2), 2000)) < 0.005
    report = fitted.last_report
    assert report is not None
    assert report.n_train + report.n_validation == 2000
    assert report.n_validation == 300
    assert report.validation_rmse < 0.005
    assert report.stop_reason in (StopReason.VALIDATION, StopReason.MAX_ITERATIONS)


def test_refinement_learns_new_region_without_forgetting() -> None:
    rng = np.random.default_rng(3)
    old, new = sample(rng, 2000, side=-1), sample(rng, 500, side=+1)
    old_test, new_test = sample(rng, 2000, side=-1), sample(rng, 2000, side=+1)
    net = InverseMap(CFG)
    net.fit(old, known_map(old), np.random.default_rng(4))
    old_before, new_before = rmse(net, old_test), rmse(net, new_test)
    assert new_before > 0.004  # the new region is really unknown to the initial map
    x_all = np.vstack([old, new])
    report = net.refine(x_all, known_map(x_all), np.random.default_rng(5))
    assert report.iterations <= CFG.max_iterations_refine
    # The new region's error falls to under 40 % of what it was; the old region's stays below 2.5e-3 (it
    # was ~5e-4: refinement on all data costs a little of the old fit, not all of it).
    assert rmse(net, new_test) < 0.4 * new_before
    assert rmse(net, old_test) < 2.5e-3
    assert old_before < 2.5e-3


def test_refine_keeps_normalization_and_split() -> None:
    rng = np.random.default_rng(6)
    x = sample(rng, 1000)
    net = InverseMap(InverseMapConfig(max_iterations_fit=20))
    net.fit(x, known_map(x), rng)
    before = net.to_arrays()
    split = net.validation_mask
    assert split is not None
    assert split.shape == (1000,)
    x2 = np.vstack([x, 3 * sample(rng, 200)])  # wider data must not move the normalization
    net.refine(x2, known_map(x2 / 3), rng)
    after = net.to_arrays()
    for key in ("x_offset", "x_scale", "y_offset", "y_scale"):
        np.testing.assert_array_equal(after[key], before[key])
    mask = net.validation_mask
    assert mask is not None
    np.testing.assert_array_equal(mask[:1000], split)
    assert mask.mean() == pytest.approx(0.15, abs=0.01)
    with pytest.raises(InverseMapError, match="all data so far"):
        net.refine(x[:500], known_map(x[:500]), rng)
    with pytest.raises(InverseMapError, match="rows"):
        net.refine(x2, known_map(x2 / 3), rng, rows=np.ones(1000, dtype=bool))


def test_a_refinement_on_some_rows_trains_and_validates_on_those_and_keeps_every_split() -> None:
    rng = np.random.default_rng(6)
    x = sample(rng, 1000)
    net = InverseMap(InverseMapConfig(max_iterations_fit=20, max_iterations_refine=5))
    net.fit(x, known_map(x), rng)
    x2 = np.vstack([x, sample(rng, 400)])
    rows = np.arange(1400) >= 600  # the last 400 of the fit's samples and the new ones
    report = net.refine(x2, known_map(x2), rng, rows=rows)
    mask = net.validation_mask
    assert mask is not None and mask.shape == (1400,)
    assert (report.n_train, report.n_validation) == (int((~mask & rows).sum()), int((mask & rows).sum()))


def test_same_seed_same_weights_other_seed_differs() -> None:
    x = sample(np.random.default_rng(7), 800)
    y = known_map(x)
    cfg = InverseMapConfig(max_iterations_fit=30)
    a, b, c = InverseMap(cfg), InverseMap(cfg), InverseMap(cfg)
    a.fit(x, y, np.random.default_rng(8))
    b.fit(x, y, np.random.default_rng(8))
    c.fit(x, y, np.random.default_rng(9))
    for key, value in a.to_arrays().items():
        np.testing.assert_array_equal(value, b.to_arrays()[key])
    assert not np.array_equal(a.to_arrays()["w_hidden"], c.to_arrays()["w_hidden"])
    a.refine(x, y, np.random.default_rng(10))
    b.refine(x, y, np.random.default_rng(10))
    np.testing.assert_array_equal(a.to_arrays()["w_out"], b.to_arrays()["w_out"])


@pytest.mark.parametrize("optimizer", [Optimizer.LBFGS, Optimizer.ADAM])
def test_other_optimizers_fit_too(optimizer: Optimizer) -> None:
    # Slower to converge than LM (see docs/ALGORITHM.md); within a small budget they still learn the map.
    rng = np.random.default_rng(11)
    x = sample(rng, 1500)
    net = InverseMap(InverseMapConfig(optimizer=optimizer, max_iterations_fit=100, patience=20))
    report = net.fit(x, known_map(x), rng)
    assert 0 < report.iterations <= 100
    assert rmse(net, sample(rng, 1000)) < 0.03  # the map's own spread is ~0.15


def test_gauss_newton_matches_autograd_jacobian() -> None:
    rng = np.random.default_rng(12)
    theta = imt._flatten([torch.from_numpy(p) for p in im._init_params(4, rng)]) + 0.1
    x = torch.tensor(rng.normal(size=(40, 6)))
    y = torch.tensor(rng.normal(size=(40, 3)))
    jac = torch.autograd.functional.jacobian(lambda t: (imt._forward(t, 4, x) - y).reshape(-1), theta)
    residual = (imt._forward(theta, 4, x) - y).reshape(-1)
    hid, res = imt._hidden_and_residual(theta, 4, x, y)
    jtj, grad = imt._gauss_newton(theta, 4, x, hid, res)
    exact = jac.T @ jac
    # The Gram matrix is accumulated in float32 (relative error ~1e-6); the gradient is float64.
    torch.testing.assert_close(jtj, exact, atol=1e-5 * float(exact.abs().max()), rtol=0)
    torch.testing.assert_close(grad, jac.T @ residual, atol=1e-12, rtol=0)


def test_predict_clips_and_accepts_one_row(fitted: InverseMap) -> None:
    far = sample(np.random.default_rng(13), 500) * 20  # extrapolation drives the raw output off the range
    out = fitted.predict(far)
    assert out.shape == (500, 3)
    assert out.min() >= 0.15
    assert out.max() <= 1.0
    assert np.any(out == 0.15) or np.any(out == 1.0)
    one = fitted.predict(far[0])
    assert one.shape == (3,)
    np.testing.assert_allclose(one, out[0], rtol=1e-12)  # one row may take another BLAS path


def test_save_load_round_trip(fitted: InverseMap, tmp_path: Path) -> None:
    x = sample(np.random.default_rng(14), 300)
    path = tmp_path / "map.npz"
    fitted.save(path)
    loaded = InverseMap.load(path)
    np.testing.assert_array_equal(loaded.predict(x), fitted.predict(x))
    # Read back with numpy alone: the format is plain named arrays.
    with np.load(path, allow_pickle=False) as data:
        assert int(data["format_version"][0]) == FORMAT_VERSION
        assert data["w_hidden"].shape == (15, 6)
    # Loaded maps refine (with a fresh split).
    loaded.refine(x, known_map(x), np.random.default_rng(15))


def test_arrays_round_trip(fitted: InverseMap) -> None:
    arrays = fitted.to_arrays()
    assert set(arrays) == {
        "format_version",
        "w_hidden",
        "b_hidden",
        "w_out",
        "b_out",
        "x_offset",
        "x_scale",
        "y_offset",
        "y_scale",
        "activation_range",
    }
    assert all(a.dtype == np.float64 for a in arrays.values())
    x = sample(np.random.default_rng(16), 100)
    np.testing.assert_array_equal(InverseMap.from_arrays(arrays).predict(x), fitted.predict(x))
    # The arrays are copies: changing them does not change the map.
    arrays["w_out"][:] = 0.0
    assert np.any(fitted.to_arrays()["w_out"] != 0.0)


def test_save_appends_npz_suffix(fitted: InverseMap, tmp_path: Path) -> None:
    fitted.save(tmp_path / "weights")
    assert (tmp_path / "weights.npz").is_file()
    assert not list(tmp_path.glob("*.tmp*"))


def test_wrong_version_names_the_file(fitted: InverseMap, tmp_path: Path) -> None:
    path = tmp_path / "v2.npz"
    arrays = fitted.to_arrays()
    arrays["format_version"] = np.array([2.0])
    np.savez(path, kind=np.array("g2p.inverse_map"), **arrays)  # type: ignore[arg-type]
    with pytest.raises(InverseMapFormatError, match=r"v2\.npz: format_version \[2\.0\] is not supported"):
        InverseMap.load(path)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "not_a_map", "missing", "shape", "nan"])
def test_corrupt_file_raises_a_clear_error(fitted: InverseMap, tmp_path: Path, damage: str) -> None:
    path = tmp_path / "bad.npz"
    arrays = fitted.to_arrays()
    kind = "g2p.inverse_map"
    if damage == "missing":
        del arrays["b_out"]
    elif damage == "shape":
        arrays["x_scale"] = np.ones(5)
    elif damage == "nan":
        arrays["w_out"][0, 0] = np.nan
    elif damage == "not_a_map":
        kind = "something.else"
    np.savez(path, kind=np.array(kind), **arrays)  # type: ignore[arg-type]
    if damage == "truncate":
        path.write_bytes(path.read_bytes()[:200])
    elif damage == "garbage":
        path.write_bytes(b"definitely not a zip file")
    with pytest.raises(InverseMapFormatError, match=r"bad\.npz: "):
        InverseMap.load(path)


def test_missing_file_raises_format_error(tmp_path: Path) -> None:
    with pytest.raises(InverseMapFormatError, match=r"nope\.npz"):
        InverseMap.load(tmp_path / "nope.npz")


def test_pickled_npz_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "pickled.npz"
    np.savez(path, kind=np.array({"evil": 1}, dtype=object))
    with pytest.raises(InverseMapFormatError, match=r"pickled\.npz"):
        InverseMap.load(path)
    assert zipfile.is_zipfile(path)


def test_unfitted_map_refuses_to_predict_refine_or_save() -> None:
    net = InverseMap()
    assert not net.is_fitted
    with pytest.raises(InverseMapError, match="not fitted"):
        net.predict(np.zeros((1, 6)))
    with pytest.raises(InverseMapError, match="not fitted"):
        net.refine(np.zeros((100, 6)), np.zeros((100, 3)), np.random.default_rng(0))
    with pytest.raises(InverseMapError, match="not fitted"):
        net.to_arrays()


@pytest.mark.parametrize(
    ("x", "y", "match"),
    [
        (np.zeros((100, 5)), np.zeros((100, 3)), r"x: expected shape \(N, 6\)"),
        (np.zeros((100, 6)), np.zeros((99, 3)), r"y: expected shape \(100, 3\)"),
        (np.full((100, 6), np.nan), np.zeros((100, 3)), "non-finite"),
        (np.zeros((5, 6)), np.zeros((5, 3)), r"at least 14 samples"),
    ],
)
def test_bad_training_data_raise(x: np.ndarray, y: np.ndarray, match: str) -> None:
    with pytest.raises(InverseMapError, match=match):
        InverseMap().fit(x, y, np.random.default_rng(0))


@pytest.mark.parametrize(
    ("field", "kwargs"),
    [
        ("n_hidden", {"n_hidden": 0}),
        ("activation_low, activation_high", {"activation_low": 0.9, "activation_high": 0.5}),
        ("normalization", {"normalization": "robust"}),
        ("optimizer", {"optimizer": "sgd"}),
        ("validation_fraction", {"validation_fraction": 0.0}),
        ("max_iterations_fit", {"max_iterations_fit": 0}),
        ("max_iterations_refine", {"max_iterations_refine": 0}),
        ("patience", {"patience": 0}),
        ("lm_mu", {"lm_mu": -1.0}),
        ("lm_mu_decrease", {"lm_mu_decrease": 1.0}),
        ("lm_mu_increase", {"lm_mu_increase": 1.0}),
        ("lm_mu_max", {"lm_mu_max": 1e-5}),
        ("num_threads", {"num_threads": -1}),
    ],
)
def test_invalid_config_names_the_field(field: str, kwargs: dict[str, object]) -> None:
    with pytest.raises(ConfigError, match=f"^{field}:"):
        InverseMapConfig(**kwargs)  # type: ignore[arg-type]


def test_zscore_normalization_fits_too() -> None:
    rng = np.random.default_rng(17)
    x = sample(rng, 1500)
    net = InverseMap(InverseMapConfig(normalization="zscore", max_iterations_fit=200))  # type: ignore[arg-type]
    net.fit(x, known_map(x), rng)
    assert rmse(net, sample(rng, 1000)) < 0.005
    arrays = net.to_arrays()
    np.testing.assert_allclose(arrays["x_offset"], x.mean(axis=0))
    np.testing.assert_allclose(arrays["x_scale"], x.std(axis=0))


@pytest.mark.parametrize("optimizer", list(Optimizer))
def test_a_cancelled_fit_or_refinement_stops_at_once_and_leaves_the_map_as_it_was(
    optimizer: Optimizer,
) -> None:
    rng = np.random.default_rng(0)
    x = sample(rng, 4000)
    y = known_map(x)
    net = InverseMap(replace(CFG, optimizer=optimizer, max_iterations_fit=10**6, patience=10**6))
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(im.FitCancelled):
        net.fit(x, y, rng, cancel)
    assert not net.is_fitted  # as before the fit
    net = InverseMap(replace(CFG, optimizer=optimizer))
    net.fit(x, y, rng)
    before, mask = net.to_arrays(), net.validation_mask
    cancel = threading.Event()
    endless = replace(CFG, optimizer=optimizer, max_iterations_refine=10**6, patience=10**6)
    long_net = InverseMap.from_arrays(before, endless, validation_mask=mask)
    threading.Timer(0.3, cancel.set).start()
    start = time.monotonic()
    with pytest.raises(im.FitCancelled):
        long_net.refine(np.concatenate([x, x]), np.concatenate([y, y]), rng, cancel)
    assert time.monotonic() - start < 0.3 + 1.0  # within a second of the cancel
    for name, array in before.items():
        np.testing.assert_array_equal(long_net.to_arrays()[name], array)
    np.testing.assert_array_equal(long_net.validation_mask, mask)
