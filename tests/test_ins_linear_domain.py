"""The linear strapdown error model's domain (hrgjax/ins/strapdown.py, docs/ins.md): initial
attitude errors (or σ) beyond `MAX_ANGLE` are refused, results whose error state leaves it
warn, and inside it the model agrees with the nonlinear mechanisation to the documented
≈ a/2 (`benchmarks/ins_linear_domain.py` has the full table)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import mechanise_ned

from hrgjax.ins import constants as C
from hrgjax.ins import ekf
from hrgjax.ins import strapdown as sd
from hrgjax.ins import trajectory as tr
from hrgjax.units import DEG_PER_H


@pytest.fixture(scope="module")
def hour():
    """1 h stationary at 45° (sphere): one compiled `propagate` for every test here."""
    return tr.stationary(45.0, duration_s=3600.0, dt=60.0, earth=C.SPHERE)


def test_initial_attitude_error_or_sigma_beyond_the_domain_is_refused(hour):
    """(Refused before anything compiles; the edge, 0.2 rad, runs in the last test.)"""
    assert sd.MAX_ANGLE == ekf.MAX_ATTITUDE_SIGMA == 0.2
    with pytest.raises(ValueError, match=r"^dx0\[6:9\] \(the initial attitude error φ.*0\.2 rad"):
        sd.propagate(hour, jnp.zeros(9).at[8].set(-0.3), altitude_aided=True)
    imu = sd.ImuErrors(gyro_bias=1e-8)
    p_bad = jnp.diag(jnp.zeros(9).at[6].set(0.25**2))
    with pytest.raises(ValueError, match=r"^√diag\(p0_nav\)\[6:9\] \(the initial attitude"):
        sd.initial_covariance(imu, p_bad)
    with pytest.raises(ValueError, match=r"p0_nav must be a \(9, 9\) covariance"):
        sd.initial_covariance(imu, jnp.eye(3))
    phi, qd = jnp.broadcast_to(jnp.eye(15), (4, 15, 15)), jnp.zeros((4, 15, 15))
    p0 = sd.initial_covariance(imu).at[6, 6].set(0.25**2)  # set by hand past the check
    with pytest.raises(ValueError, match=r"^√diag\(p0\)\[6:9\]"):
        sd.covariance(phi, qd, p0)
    with pytest.raises(ValueError, match=r"^√diag\(p0\)\[6:9\]"):
        sd.monte_carlo(phi, qd, p0, jax.random.key(0), 4)


def test_error_state_leaving_the_domain_warns_naming_when(hour):
    """100 °/h about the vertical: φ_D ≈ ε t passes 0.2 rad at 0.2/ε = 412 s (first sample
    past it 420 s). Covariance and Monte Carlo on a random walk of φ_D (variance 0.01 rad²
    a step, Φ = I): σ passes 0.2 rad after 4 steps, so the warning names step 5 (under
    `jit` nothing is checked: tests/test_ins_errors.py runs `propagate` jitted)."""
    eps = 100 * DEG_PER_H
    with pytest.warns(sd.LinearisationWarning, match=r"propagate: .* at t = 420 s and reach 1\.7"):
        dx = sd.propagate(hour, gyro_error=jnp.array([0.0, 0.0, eps]), altitude_aided=True)
    assert abs(float(dx[-1, 8])) == pytest.approx(eps * 3600, rel=0.02)  # (Earth rate: 1.4 %)
    phi = jnp.broadcast_to(jnp.eye(15), (8, 15, 15))
    qd = jnp.zeros((8, 15, 15)).at[:, 8, 8].set(0.01)
    p0 = jnp.zeros((15, 15))
    with pytest.warns(sd.LinearisationWarning, match=r"covariance: .*σ of the angles.* step 5 "):
        sd.covariance(phi, qd, p0)
    with pytest.warns(sd.LinearisationWarning, match=r"monte_carlo: .*RMS angles.* step [4-6] "):
        sd.monte_carlo(phi, qd, p0, jax.random.key(0), 400)


def _nonlinear(traj, dws, hours, c0s):
    """Nonlinear NED mechanisation, altitude held, driven by the ideal IMU output plus each
    constant body-frame gyro error of `dws` (K, 3) from each attitude of `c0s` (K, 3, 3)
    (`helpers.mechanise_ned`); (ts, (K, 61, 14))."""
    return mechanise_ned(traj, c0s, hours, dws, rtol=1e-10, atol=1e-12, max_steps=100_000)


def test_inside_the_domain_the_linear_model_is_within_half_the_angle(hour):
    """1 h stationary at 45°: a 0.2-rad heading error (exact rotation exp(−[φ×])) and a
    5 °/h north gyro bias; horizontal position of linear vs nonlinear within 0.55 a (measured
    ≤ 0.52 a over the benchmark's table), where a = max |φ_i|, |δφ| of the linear run
    (docs/ins.md: 9.7 % and 5.4 %, a = 0.2 and 0.105)."""
    traj = hour
    ct = traj.c_bn[0]
    p = 0.2  # exp(−[φ×]) for φ = (0, 0, p): a rotation of the NED frame about down
    rz = jnp.array([[np.cos(p), np.sin(p), 0], [-np.sin(p), np.cos(p), 0], [0, 0, 1.0]])
    eps = 5 * DEG_PER_H
    c0s = jnp.stack([ct, rz @ ct, ct])
    dws = jnp.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [eps, 0.0, 0.0]])
    ts, ys = _nonlinear(traj, dws, 1.0, c0s)
    idx = np.searchsorted(np.asarray(traj.t), np.asarray(ts))
    scale = np.array([C.SPHERE.radius, C.SPHERE.radius * np.cos(float(traj.lat[0]))])
    runs = [
        sd.propagate(traj, jnp.zeros(9).at[8].set(p), altitude_aided=True),
        sd.propagate(traj, gyro_error=dws[2], altitude_aided=True),
    ]
    for k, (dx, want) in enumerate(zip(runs, (0.097, 0.054), strict=True), start=1):
        dx = np.asarray(dx)[idx]
        a = np.abs(dx[:, [6, 7, 8, 0]]).max()
        lin, nl = dx[:, :2] * scale, np.asarray(ys[k] - ys[0])[:, :2] * scale
        rel = np.max(np.hypot(*(lin - nl).T)) / np.max(np.hypot(*nl.T))
        assert rel == pytest.approx(want, abs=0.003)  # the table's figure
        assert 0.2 * a < rel <= 0.55 * a and a <= sd.MAX_ANGLE + 1e-3
