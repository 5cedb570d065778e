r"""The statistics every data shape of the search shares: weighted least squares, a covariance
that survives columns ten orders of magnitude apart, the score test (DISCOVERY.md §2.4 S3)
and the χ² and F tail probabilities.

The score statistic of a candidate with whitened columns $G_c$, given a fit's whitened
residual $r$ and Jacobian $J$:

$$S_c = r^\top\tilde G_c(\tilde G_c^\top\tilde G_c)^{-1}\tilde G_c^\top r,\qquad
\tilde G_c = (I-P)\,G_c,\quad P = J(J^\top J)^{-1}J^\top,$$

χ²_q under the null (q the candidate's columns). The dwell search
([`DwellProblem`][hrgjax.discovery.dwell.DwellProblem]), the continuous records
([`ContinuousProblem`][hrgjax.discovery.continuous.ContinuousProblem]), the leftover shapes
([`leftover`][hrgjax.discovery.leftover]) and the error bars
([`honest`][hrgjax.discovery.trust.honest]) all read them from here.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax.scipy.special import betainc, gammaincc


def wls(g: np.ndarray, y: np.ndarray, sigma: np.ndarray):
    """Weighted least squares of `y` on the columns `g` with standard errors `sigma`:
    `(beta, residual (whitened), covariance)`."""
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


def score(r: np.ndarray, j: np.ndarray, g: np.ndarray, q_j: np.ndarray | None = None):
    """Score statistic S, aliasing index A and one-step estimate of a candidate with
    whitened columns `g`, given the whitened residual `r` and fitted whitened Jacobian `j`
    (`q_j`: its orthonormal basis, when several candidates share it)."""
    if q_j is None:
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


def f_sf(f: float, d1: int, d2: int) -> float:
    """Upper tail probability of the F(d1, d2) distribution at `f`."""
    if not f > 0:
        return 1.0
    return float(betainc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f)))


def follows_covariate(means: np.ndarray, x: np.ndarray, alpha: float) -> tuple[np.ndarray, int]:
    """`means` less their mean and less the covariates (columns of `x`) that explain them
    significantly, chosen one at a time (F-test at `alpha`, Bonferroni over the covariates
    still tried); **returns** `(residual, columns fitted)` (the intercept counts)."""
    n = means.size
    cols = [np.ones(n)]
    cands = [x[:, i] for i in range(x.shape[1]) if np.ptp(x[:, i]) > 0]

    def rss(a):
        coef, *_ = np.linalg.lstsq(np.stack(a, axis=1), means, rcond=None)
        r = means - np.stack(a, axis=1) @ coef
        return float(r @ r), r

    base, resid = rss(cols)
    while cands and n - len(cols) - 1 > 1:
        trials = [(rss(cols + [c]), i) for i, c in enumerate(cands)]
        (new, r), i = min(trials, key=lambda t: t[0][0])
        dof = n - len(cols) - 1
        f = (base - new) / max(new / dof, 1e-300)
        if f_sf(f, 1, dof) >= alpha / len(cands):  # the best of them
            break
        cols.append(cands.pop(i))
        base, resid = new, r
    return resid, len(cols)
