r"""Discovery on dwell-grid data (DISCOVERY.md §2.2 a): the catalogue as regressor columns.

Each window of a dwell run (static or constant rate, constant temperature) gives a measured
pattern rate $y = \dot\theta_{\rm meas} = -k_{e,\rm nom}\,\Omega_{\rm meas}$ [rad/s]. Around the
nominal model every catalogue term is linear in its parameters at the window's covariates
(mean wave angle, table rate, temperature, …), so a model is a design matrix and the fit is
weighted least squares; the score test of a candidate is then exact (DISCOVERY.md §2.4 S3):

$$S_c = r^\top\tilde G_c(\tilde G_c^\top\tilde G_c)^{-1}\tilde G_c^\top r,\qquad
\tilde G_c = (I-P)\,G_c,\quad P = J(J^\top J)^{-1}J^\top,$$

in whitened units, χ²_q under the null. A readout term g(θ) enters through
$\dot\theta_{\rm meas} = (1+\partial g/\partial\theta)\,\dot\theta$ (for the gain mismatch
$1+\varepsilon_1\cos2\theta-\varepsilon_2\sin2\theta$), linearised at the nominal rate −k_e,nom Ω; a window in which the pattern sweeps an arc x
sees every 2θ harmonic times [`window_gain`][hrgjax.discovery.effects.window_gain](x); `angular_gain_temperature` and
`rate_scale_factor` likewise at k_e,nom. Nonregular time constants are held at their typical
size here.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaincc

from ..calibration.reduce import RateWindows
from ..units import DEG
from .effects import CATALOGUE, Covariates, window_rate


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
    """Regressor columns (W, q) of effect `name`: ∂(window rate)/∂p at the null
    ([`Effect.window_rate`][hrgjax.discovery.effects.Effect.window_rate])."""
    effect = CATALOGUE[name]
    p0 = jnp.asarray([0.0 if p.regular else p.scale for p in effect.params])
    regular = np.asarray([p.regular for p in effect.params])
    jac = np.asarray(jax.jacfwd(lambda p: effect.window_rate(p, c, k_e))(p0))
    return jac[:, regular]


def design(names, c: Covariates, k_e: float) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """Stacked columns of several effects and the (effect, column) labels."""
    blocks, labels = [], []
    for n in names:
        g = columns(n, c, k_e)
        blocks.append(g)
        labels += [(n, j) for j in range(g.shape[1])]
    return np.concatenate(blocks, axis=1), labels


def _split(names, beta):
    """{effect: full parameter vector} from the regular parameters `beta` in `design` order
    (nonregular ones at their typical size)."""
    out, i = {}, 0
    for n in names:
        full = []
        for p in CATALOGUE[n].params:
            if p.regular:
                full.append(beta[i])
                i += 1
            else:
                full.append(jnp.asarray(p.scale, dtype=float))
        out[n] = jnp.stack(full)
    return out


def model_rate(names, beta, c: Covariates, k_e: float):
    """A window's measured pattern rate [rad/s] under the model `names` at parameters
    `beta` (the order of `design`), to all orders in the readout terms
    ([`window_rate`][hrgjax.discovery.effects.window_rate]; the terms that scale the angular
    gain read the nominal `k_e`, as in `design`, which is this function's Jacobian at the
    null)."""
    return window_rate(_split(names, beta), c, k_e)


@functools.lru_cache(maxsize=64)
def _model_and_jacobian(names: tuple):
    f = lambda beta, c, k_e: model_rate(names, beta, c, k_e)
    return jax.jit(lambda beta, c, k_e: (f(beta, c, k_e), jax.jacfwd(f)(beta, c, k_e)))


def refine(names, beta, c: Covariates, y, sigma, train, k_e: float, iterations: int = 3):
    """Gauss–Newton steps from the linear fit `beta` on the exact
    [`model_rate`][hrgjax.discovery.dwell.model_rate] (weighted, training rows `train`):
    the readout terms' second-order part (ε²/2 of the rate for a gain mismatch ε: 2·10⁻⁴ at
    a 2 % mismatch) is systematic, and a ripple of 1 % makes it visible at 5 °/s.

    **Returns:** `(beta, model rate, Jacobian)` at the refined parameters."""
    fn = _model_and_jacobian(tuple(names))
    c = jax.tree.map(jnp.asarray, c)
    beta = jnp.asarray(beta)
    for _ in range(iterations):
        f, jac = fn(beta, c, k_e)
        f, jac = np.asarray(f), np.asarray(jac)
        jw = jac[train] / sigma[train][:, None]
        rw = (y[train] - f[train]) / sigma[train]
        step, *_ = np.linalg.lstsq(jw, rw, rcond=None)
        beta = beta + step
    f, jac = fn(beta, c, k_e)
    return np.asarray(beta), np.asarray(f), np.asarray(jac)


def target(w: RateWindows, k_e: float) -> np.ndarray:
    """Measured pattern rate of each window [rad/s]."""
    return -k_e * w.rate_dps * DEG


def wls(g: np.ndarray, y: np.ndarray, sigma: np.ndarray):
    """Weighted least squares: `(beta, residual (whitened), covariance)`."""
    gw, yw = g / sigma[:, None], y / sigma
    beta, *_ = np.linalg.lstsq(gw, yw, rcond=None)
    return beta, yw - gw @ beta, covariance(gw)


def covariance(gw: np.ndarray) -> np.ndarray:
    """(GᵀG)⁻¹ of whitened columns `gw`, with the columns scaled to unit norm first: the
    catalogue's columns differ by ten orders of magnitude (q/a ~ 10⁻⁴ beside Ω), and an
    unscaled pseudo-inverse would cut the small ones' variance to zero. A column the data
    never excite (k_e on static runs alone) gets an infinite variance."""
    norm = np.linalg.norm(gw, axis=0)
    d = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
    gs = gw * d
    cov = d[:, None] * np.linalg.pinv(gs.T @ gs, hermitian=True) * d[None, :]
    idx = np.arange(cov.shape[0])
    cov[idx, idx] = np.maximum(cov[idx, idx], 0.0)  # round-off below zero
    cov[norm == 0, norm == 0] = np.inf  # a column the data never excite: undetermined
    return cov


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
