r"""Discovery on dwell-grid data (DISCOVERY.md §2.2 a): the catalogue as regressor columns.

Each window of a dwell run (static or constant rate, constant temperature) gives a measured
pattern rate $y = \dot\theta_{\rm meas} = -k_{e,\rm nom}\,\Omega_{\rm meas}$ [rad/s]. Around the
nominal model every catalogue term is linear in its parameters at the window's covariates
(mean wave angle, table rate, temperature, …), so a model is a design matrix and the fit is
weighted least squares; the score test of a candidate is then exact (DISCOVERY.md §2.4 S3):

$$S_c = r^\top\tilde G_c(\tilde G_c^\top\tilde G_c)^{-1}\tilde G_c^\top r,\qquad
\tilde G_c = (I-P)\,G_c,\quad P = J(J^\top J)^{-1}J^\top,$$

in whitened units, χ²_q under the null. The readout terms enter through
$\dot\theta_{\rm meas} = (1+\varepsilon_1\cos2\theta-\varepsilon_2\sin2\theta)\,\dot\theta$,
linearised at the nominal rate −k_e,nom Ω; a window in which the pattern sweeps an arc x
sees every 2θ harmonic times [`window_gain`][hrgjax.discovery.effects.window_gain](x); `angular_gain_temperature` and
`rate_scale_factor` likewise at k_e,nom. Nonregular time constants are held at their typical
size here.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaincc

from ..calibration.reduce import RateWindows
from ..units import DEG
from .effects import CATALOGUE, Covariates, rate_term, rate_term_with_gain


def covariates(w: RateWindows, extra: dict | None = None) -> Covariates:
    """Covariates of each window: mean angle [rad], table rate [rad/s], temperature [°C];
    `extra` may give `amplitude`, `quadrature`, `accel_z`, `t_run` and `harmonic_gain`
    (the window average of a 2θ harmonic) per window."""
    extra = extra or {}
    kw = {k: jnp.asarray(v) for k, v in extra.items()}
    return Covariates(
        theta=jnp.asarray(w.wave_angle_deg * DEG),
        rate=jnp.asarray(w.table_rate_dps * DEG),
        temperature=jnp.asarray(w.temperature_c),
        temperature_lagged=jnp.asarray(w.temperature_c),
        **kw,
    )


def columns(name: str, c: Covariates, k_e: float) -> np.ndarray:
    """Regressor columns (W, q) of effect `name`: ∂(pattern rate)/∂p at the null."""
    effect = CATALOGUE[name]
    p0 = jnp.asarray([0.0 if p.regular else p.scale for p in effect.params])
    regular = np.asarray([p.regular for p in effect.params])
    if effect.where == "readout":
        nominal = -k_e * c.rate

        def fn(p):
            harmonic = p[0] * jnp.cos(2 * c.theta) - p[1] * jnp.sin(2 * c.theta)
            return nominal * c.harmonic_gain * harmonic

    elif name in ("angular_gain_temperature", "rate_scale_factor"):

        def fn(p):
            return rate_term_with_gain(name, p, c, k_e)

    else:

        def fn(p):
            return rate_term(name, p, c)

    jac = np.asarray(jax.jacfwd(fn)(p0))
    return jac[:, regular]


def design(names, c: Covariates, k_e: float) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """Stacked columns of several effects and the (effect, column) labels."""
    blocks, labels = [], []
    for n in names:
        g = columns(n, c, k_e)
        blocks.append(g)
        labels += [(n, j) for j in range(g.shape[1])]
    return np.concatenate(blocks, axis=1), labels


def target(w: RateWindows, k_e: float) -> np.ndarray:
    """Measured pattern rate of each window [rad/s]."""
    return -k_e * w.rate_dps * DEG


def wls(g: np.ndarray, y: np.ndarray, sigma: np.ndarray):
    """Weighted least squares: `(beta, residual (whitened), covariance)`."""
    gw, yw = g / sigma[:, None], y / sigma
    beta, *_ = np.linalg.lstsq(gw, yw, rcond=None)
    cov = np.linalg.pinv(gw.T @ gw)
    return beta, yw - gw @ beta, cov


def score(r: np.ndarray, j: np.ndarray, g: np.ndarray):
    """Score statistic S, aliasing index A and one-step estimate of a candidate with
    whitened columns `g`, given the whitened residual `r` and fitted whitened Jacobian `j`."""
    q_j, _ = np.linalg.qr(j)
    g_t = g - q_j @ (q_j.T @ g)
    gram = g_t.T @ g_t
    alias = 1.0 - np.sum(g_t**2) / max(np.sum(g**2), 1e-300)
    if np.linalg.matrix_rank(gram, tol=1e-10 * max(np.trace(gram), 1e-300)) < g.shape[1]:
        return 0.0, 1.0, np.zeros(g.shape[1])
    step = np.linalg.solve(gram, g_t.T @ r)
    return float(r @ g_t @ step), float(alias), step


def chi2_sf(x: float, dof: int) -> float:
    """Upper tail probability of χ²_dof at x."""
    return float(gammaincc(dof / 2.0, jnp.asarray(max(x, 0.0) / 2.0)))
