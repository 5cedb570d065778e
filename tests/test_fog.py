"""Seed 003 building blocks: installation misalignment (map, inverse, calibration) and the
Elman network."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.fog import misalignment as mis
from hrgjax.nn.elman import Elman
from hrgjax.nn.mlp import MLP


def test_misalignment_map_and_first_order_inverse_round_trip_to_second_order():
    rng = np.random.default_rng(0)
    for scale in (1e-3, 1e-4):
        angles = jnp.asarray(rng.normal(size=6) * scale)
        e = mis.misalignment_matrix(angles)
        assert np.allclose(np.diag(e), 0.0)
        assert e[0, 1] == angles[0] and e[2, 1] == angles[5]  # xy and zy
        rt = mis.body_from_sensor(angles) @ mis.sensor_from_body(angles) - jnp.eye(3)
        # (I − E)(I + E) − I = −E²: second order, exactly
        np.testing.assert_allclose(rt, -(e @ e), atol=1e-18)
        assert np.abs(rt).max() <= 3 * scale**2 * 10
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        mis.misalignment_matrix(jnp.zeros(5))


def _positions():
    """Six ±axis positions plus eight tilted ones (unit vectors × 9.8 m/s²)."""
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    tilted = np.array([[1, 1, 1], [1, -1, 1], [-1, 1, 1], [-1, -1, 1],
                       [1, 1, -1], [1, -1, -1], [-1, 1, -1], [-1, -1, -1]]) / np.sqrt(3)  # fmt: skip
    return np.concatenate([axes, tilted]) * 9.80665


def test_calibration_recovers_injected_angles_within_their_uncertainties():
    truth = mis.TriadCalibration(
        angles=jnp.array([3e-4, -2e-4, 1e-4, 5e-4, -4e-4, 2.5e-4]),
        scale=jnp.array([2e-4, -1e-4, 3e-4]),
        bias=jnp.array([1e-3, -2e-3, 5e-4]),
        angles_std=jnp.zeros(6), scale_std=jnp.zeros(3), bias_std=jnp.zeros(3),
        residual_std=jnp.zeros(3),
    )  # fmt: skip
    b = _positions()
    noise = 5e-5 * 9.80665  # 50 µg per averaged position
    pulls = []
    for seed in range(20):
        s = np.asarray(truth.sensor(b)) + np.random.default_rng(seed).normal(size=b.shape) * noise
        fit = mis.calibrate(b, s)
        pulls.append(
            (np.asarray(fit.angles) - np.asarray(truth.angles)) / np.asarray(fit.angles_std)
        )
        np.testing.assert_allclose(fit.scale, truth.scale, atol=5 * float(fit.scale_std.max()))
        np.testing.assert_allclose(fit.bias, truth.bias, atol=5 * float(fit.bias_std.max()))
    pulls = np.array(pulls)
    assert np.all(np.abs(pulls) < 5.0)
    # the standard errors are honest: the pulls scatter like N(0, 1)
    assert 0.6 < pulls.std() < 1.5, pulls.std()
    # compensation undoes the model
    np.testing.assert_allclose(fit.body(truth.sensor(b)), b, atol=10 * noise)
    with pytest.raises(ValueError, match=">= 5 positions"):
        mis.calibrate(b[:4], b[:4])
    with pytest.raises(ValueError, match="shape"):
        mis.calibrate(b, b[:, :2])


@pytest.fixture(scope="module")
def elman():
    return Elman(2, 7, 1, key=jax.random.key(0))


def test_elman_without_recurrence_is_an_mlp(elman):
    flat = eqx.tree_at(lambda m: m.w_h.weight, elman, jnp.zeros((7, 7)))
    mlp = MLP((2, 7, 1), key=jax.random.key(1))
    mlp = eqx.tree_at(lambda m: (m.layers[0].weight, m.layers[0].bias, m.layers[1].weight,
                                 m.layers[1].bias),
                      mlp, (flat.w_x.weight, flat.w_x.bias, flat.w_y.weight, flat.w_y.bias))  # fmt: skip
    xs = jax.random.normal(jax.random.key(2), (50, 2))
    np.testing.assert_allclose(flat(xs), jax.vmap(mlp)(xs), rtol=1e-12, atol=1e-14)
    # with its recurrence it is not: the context carries the past
    assert not np.allclose(elman(xs), flat(xs))
    with pytest.raises(ValueError, match=r"\(T, in_size\)"):
        elman(jnp.zeros(3))


def test_gradients_through_the_scan_match_finite_differences(elman):
    xs = jax.random.normal(jax.random.key(3), (40, 2))
    target = jnp.sin(jnp.arange(40.0))[:, None]

    def loss(w_h):
        m = eqx.tree_at(lambda m: m.w_h.weight, elman, w_h)
        return jnp.mean((m(xs) - target) ** 2)

    w = elman.w_h.weight
    g = jax.grad(loss)(w)
    d = jax.random.normal(jax.random.key(4), w.shape)
    eps = 1e-6
    fd = (loss(w + eps * d) - loss(w - eps * d)) / (2 * eps)
    np.testing.assert_allclose(jnp.sum(g * d), fd, rtol=1e-7)


def test_psd_peak_finds_a_known_tone_and_matches_scipy():
    from scipy.signal import welch

    from hrgjax.fog import spectrum

    fs, t = 200.0, np.arange(0, 40.0, 1 / 200.0)
    rng = np.random.default_rng(0)
    for f0, amp in ((10.0, 0.5 * 9.80665), (37.3, 1.0 * 9.80665)):
        x = amp * np.sin(2 * np.pi * f0 * t + 0.3) + rng.normal(size=t.size) * 0.2
        f, p = spectrum.psd(jnp.asarray(x), fs, nperseg=1024)
        fr, pr = welch(x, fs, window="hann", nperseg=1024, detrend="constant")
        np.testing.assert_allclose(f, fr)
        np.testing.assert_allclose(p, pr, rtol=1e-10, atol=1e-12 * pr.max())
        freq, a = spectrum.tone(jnp.asarray(x), fs, nperseg=1024)
        assert abs(float(freq) - f0) < 0.05 * (fs / 1024)  # 5 % of a bin
        assert abs(float(a) / amp - 1.0) < 0.01
    # Parseval: white noise of variance σ² has ∫P df = σ²
    w = rng.normal(size=2**15) * 0.7
    f, p = spectrum.psd(jnp.asarray(w), fs, nperseg=512)
    assert abs(float(jnp.sum(p) * (f[1] - f[0])) / 0.49 - 1.0) < 0.03
    with pytest.raises(ValueError, match="fs must be > 0"):
        spectrum.psd(jnp.asarray(w), 0.0)
    with pytest.raises(ValueError, match="x must be finite"):
        spectrum.psd(jnp.asarray(w).at[3].set(jnp.nan), fs)
