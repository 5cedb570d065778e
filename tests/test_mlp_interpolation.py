"""The MLP compensator between sparse temperature levels (`MLPCompensator.drift_t_curvature`,
`sf_t_curvature`: the smoothness prior in T).

Oracle: exact reduced targets of known smooth laws at 0/20/40 °C; the networks are checked
against those laws at +10 and +30 °C, where they had no data. Without the prior the scale
factor's error there was 15–40× its error at the levels (200–390 ppm against 5–16 ppm).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.calibration import MLPCompensator, RateWindows
from hrgjax.calibration.mlp import curvature_points, t_curvature, train_rprop
from hrgjax.calibration.reduce import K_E_NOMINAL
from hrgjax.units import DEG, DEG_PER_H

LEVELS = (0.0, 20.0, 40.0)
BETWEEN = (10.0, 30.0)
THETA = np.linspace(-90.0, 90.0, 37)  # [° electrical]


def true_drift(theta, temp):
    """Drift [rad/s]: amplitude exponential in T, axis moving 0.16 °/°C (the tvg3-like laws)."""
    amp = 1.5 * DEG_PER_H * np.exp(-0.016 * (temp - 20.0))
    phase = (25.0 + 0.16 * (temp - 20.0)) * DEG
    return 0.3 * DEG_PER_H + 0.005 * DEG_PER_H * (temp - 20) - amp * np.sin(2 * (theta - phase))


def true_sf(theta, temp):
    """Scale factor: ripple 1 − 2g cos 2θ, g linear in T."""
    return 1.0 - 2 * (0.0046 - 9.6e-5 * (temp - 20.0)) * np.cos(2 * theta)


def level_windows():
    """Exact static and 5 °/s windows at `LEVELS`, wave angle every 10°."""
    tt, aa = np.meshgrid(LEVELS, np.arange(-90.0, 90.0, 10.0), indexing="ij")
    tt, aa, n = tt.ravel(), aa.ravel(), tt.size
    th = aa * DEG
    rate = np.r_[true_drift(th, tt), true_sf(th, tt) * 5.0 * DEG + true_drift(th, tt)] / DEG
    return RateWindows(
        run=np.arange(2 * n), start=np.zeros(2 * n, int), stop=np.full(2 * n, 10),
        t_mid=np.full(2 * n, 5.0), duration=np.zeros(2 * n),  # point values: no arc
        temperature_c=np.tile(tt, 2), table_rate_dps=np.r_[np.zeros(n), np.full(n, 5.0)],
        wave_angle_deg=np.tile(aa, 2), rate_dps=rate, stderr_dps=np.full(2 * n, 1e-6),
        k_e=K_E_NOMINAL,
    )  # fmt: skip


def errors(comp, temps):
    """RMS over `THETA` of the drift [°/h] and scale-factor errors at each of `temps`."""
    drift = [np.sqrt(np.mean((comp.drift_dph(THETA, t) - true_drift(THETA * DEG, t) / DEG_PER_H)
                             ** 2)) for t in temps]  # fmt: skip
    sf = [np.sqrt(np.mean((comp.scale_factor_at(THETA, t) - true_sf(THETA * DEG, t)) ** 2))
          for t in temps]  # fmt: skip
    return np.asarray(drift), np.asarray(sf)


@pytest.fixture(scope="module")
def fitted():
    return MLPCompensator(steps=1000).fit(level_windows(), key=jax.random.key(0))


def test_scale_factor_between_levels_is_near_its_error_at_the_levels(fitted):
    _, sf_at = errors(fitted, LEVELS)
    _, sf_between = errors(fitted, BETWEEN)
    # with the prior (keys 0–2): 8–21 ppm between, 5–31 at the levels; without: 200–390
    # between, 5–16 at the levels
    assert sf_between.max() < 3.0 * sf_at.max() and sf_between.max() < 50e-6, (sf_at, sf_between)


def test_drift_between_levels_is_bounded(fitted):
    drift_at, _ = errors(fitted, LEVELS)
    drift_between, _ = errors(fitted, BETWEEN)
    # the drift law curves in T (its prior's weight is small): the largest error between the
    # levels was 0.015–0.029 °/h over keys 0–2 (0.065–0.116 without the prior), < 2 % of the
    # law's 1.8 °/h peak-to-peak at 0 °C; at the levels 0.001–0.003 °/h
    assert drift_between.max() < 0.035 and drift_at.max() < 0.005, (drift_at, drift_between)


def test_t_curvature_is_the_second_derivative_in_normalised_temperature():
    """Against the closed form of one tanh hidden layer (weights W, b; output weights v):
    ∂²net/∂τ² = Σ_j v_j W_jτ² tanh''(z_j), tanh'' = −2 tanh (1 − tanh²)."""
    comp = MLPCompensator(drift_width=7).init(jax.random.key(1))
    th, temp = curvature_points(20.0, 20.0)
    assert th.shape == temp.shape == (64,) and 0.0 <= th.min() and th.max() < np.pi
    assert 0.0 <= temp.min() and temp.max() <= 40.0
    x = comp.features(th, temp, np)
    hidden, out = comp.drift_net.layers
    h = np.tanh(x @ np.asarray(hidden.weight).T + np.asarray(hidden.bias))
    second = (-2.0 * h * (1.0 - h**2) * np.asarray(hidden.weight)[:, -1] ** 2) @ out.weight[0]
    np.testing.assert_allclose(t_curvature(comp.drift_net, x), np.mean(second**2), rtol=1e-12)


DEEP = eqx.nn.MLP(3, "scalar", 6, 3, jnp.tanh, key=jax.random.key(2))  # three hidden layers
X = np.random.default_rng(0).uniform(-1.0, 1.0, (40, 3))


def test_t_curvature_of_a_deeper_net_matches_finite_differences():
    """Any depth (before: a net with more than one hidden layer failed to unpack): the
    central second difference along τ, step 10⁻³ (truncation ~10⁻⁷ relative)."""
    h, e = 1e-3, np.array([0.0, 0.0, 1.0])
    net = jax.vmap(DEEP)
    fd = (net(X + h * e) - 2.0 * net(X) + net(X - h * e)) / h**2
    np.testing.assert_allclose(t_curvature(DEEP, X), np.mean(fd**2), rtol=1e-5)
    with pytest.raises(ValueError, match=r"^t_curvature: needs .* to a scalar; got x \(40, 3\), "
                       r"net output \(2,\)$"):  # fmt: skip
        t_curvature(eqx.nn.MLP(3, 2, 4, 1, key=jax.random.key(0)), X)


def test_train_rprop_without_a_prior_trains_a_deeper_net():
    """The public `train_rprop` with `prior=None` never evaluates the curvature (before: it
    did, with weight 0, and a net of more than one hidden layer failed); a prior that is not
    a pair is refused in one line."""
    y = np.sin(2.0 * X[:, 2])
    loss = lambda n: float(np.mean((jax.vmap(n)(X) - y) ** 2))  # noqa: E731
    trained = train_rprop(DEEP, X, y, 40, desc="test")
    assert loss(trained) < 0.5 * loss(DEEP), (loss(DEEP), loss(trained))
    with pytest.raises(ValueError, match=r"^train_rprop: prior must be None or a pair"):
        train_rprop(DEEP, X, y, 2, prior=X)
    # a target column (n, 1) broadcast to an (n, n) residual and trained the net to the
    # mean (MSE 0.50 against 0.002); zero rows gave "training diverged"; a row of the wrong
    # width or a NaN target raised raw errors or "training diverged": each one line now
    for xx, yy, found in ((X, y[:, None], r"y must have shape \(40,\).*got \(40, 1\)"),
                          (X[:0], y[:0], r"x must be \(n, d\).*n >= 1"),
                          (X[:, :2], y, r"net does not take a row of x, shape \(2,\)"),
                          (X, np.where(np.arange(40) == 5, np.nan, y),
                           r"y \(training targets\) must be finite; it has nan at index \(5,\)")):  # fmt: skip
        with pytest.raises(ValueError, match=rf"^train_rprop: {found}"):
            train_rprop(DEEP, xx, yy, 2)


@pytest.mark.parametrize("field", ["drift_t_curvature", "sf_t_curvature"])
@pytest.mark.parametrize("value", [-1e-3, float("nan"), float("inf"), "0.1"])
def test_bad_prior_weight_is_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"MLPCompensator: {field} must be a finite number ≥ 0"):
        MLPCompensator(**{field: value})
