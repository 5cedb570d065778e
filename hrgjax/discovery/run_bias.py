r"""The continuous records' run-to-run (switch-on) bias spread σ_b, by restricted maximum
likelihood (REML) at a fit.

Each continuous run is its own switch-on, whose constant bias is a random effect of spread
σ_b: $\sigma_b^2\Delta^2$ on every element of the run's increment covariance
([`increment_covariance`][hrgjax.pattern_noise.NoiseModel.increment_covariance]). The
information on σ_b is the scatter of the run means, and the fitted model takes part of it:
on the six ramps of `generate.continuous_dataset` the nominal `bias` and the two damping
anisotropy components set the three static runs' means and `angular_gain` the turning runs'.
The moment estimate it replaces — the run means' scatter at the fit with σ_b = 0, less what
the rest of the noise gives them — read the runs' biases after the fit had absorbed them:
0.04 °/h on the audit's null log (truth 0.2 °/h), whose whitening then pinned each run's mean
so hard that a shape with a nonzero run mean (a 2θ·Ω ripple over a run's incomplete turns)
took up the biases and the log read `unexplained` (audit 2026-11-30).

REML counts what the fit spends. With r the whitened residual at the current noise model
(training runs, then the held-out runs, which the training fit moves too), X the fit's
whitened Jacobian on both (plus any run covariate the run means follow, as fixed effects)
and U the whitened columns of each run's constant rate, a change δ of σ_b² makes the
whitened covariance V = I + δUUᵀ, and

$$\ell(\delta) = -\tfrac12\left[\log|I + \delta U^\top U| + \log|X^\top V^{-1}X| + r^\top P r\right],
\quad P = V^{-1} - V^{-1}X(X^\top V^{-1}X)^{-1}X^\top V^{-1},$$

all through the Woodbury identity on the runs' few columns (exact for a model linear in its
parameters at any δ: y − r lies in the span of X, so yᵀPy = rᵀPr). It is maximised over
σ_b ≥ 0 on a grid in log σ_b refined by golden section. The parameters are pinned by the
runs' whole records (the damping anisotropy by the turning runs' 2θ ripple), not only by
their means: the same REML on the six run means alone, X their Jacobian, still read 0.03 °/h
on the audit's log.
"""

from __future__ import annotations

import math

import numpy as np

from .records import Windows


def _orthonormal(x: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the column span of `x` (numerical rank by SVD)."""
    if x.size == 0 or x.shape[1] == 0:
        return np.zeros((x.shape[0], 0))
    norm = np.linalg.norm(x, axis=0)
    x = x[:, norm > 0] / norm[norm > 0]
    if x.shape[1] == 0:
        return np.zeros((x.shape[0], 0))
    q, s, _ = np.linalg.svd(x, full_matrices=False)
    return q[:, s > 1e-9 * s[0]]


def run_columns(groups) -> tuple[np.ndarray, list[int]]:
    """Whitened columns (rows of `groups` in residual order, runs) of each continuous run's
    constant rate of 1 rad/s: a run bias b adds b times its column to the whitened residual.
    Window rows (a mixed log's dwell runs: their session bias is profiled out) are zero.
    **Returns** `(U, run ids)`."""
    rows, blocks, runs = 0, [], []
    for g in groups:
        if isinstance(g, Windows):
            rows += len(g.run)
            continue
        bidx, t, w = np.asarray(g.bidx), np.asarray(g.t), np.asarray(g.whiten)
        for i, run in enumerate(g.run):
            delta = float(np.median(np.diff(t[i, bidx])))  # as `stack_runs` whitens
            col = w[i] @ np.full(w.shape[-1], delta)
            blocks.append((rows, col))
            runs.append(int(run))
            rows += col.size
    u = np.zeros((rows, len(runs)))
    for k, (at, col) in enumerate(blocks):
        u[at : at + col.size, k] = col
    return u, runs


def reml_loglik(r: np.ndarray, x: np.ndarray, u: np.ndarray, delta) -> float:
    """REML log-likelihood (up to a constant) of whitened residual `r` with fixed-effect
    columns `x` (orthonormal) when the whitened covariance is I + δ·UUᵀ (module docstring);
    −∞ where that is not positive definite."""
    return _loglik(_products(r, x, u), delta)


def _products(r, x, u):
    """The small products the likelihood needs: UᵀU, XᵀU, Uᵀr, Xᵀr, rᵀr."""
    return u.T @ u, x.T @ u, u.T @ r, x.T @ r, float(r @ r)


def _loglik(products, delta) -> float:
    """`reml_loglik` from `_products` (Woodbury: V⁻¹ = I − U G Uᵀ, G = δ(I + δUᵀU)⁻¹)."""
    a, b, ur, xr, rr = products
    m = np.eye(a.shape[0]) + delta * a
    sign, logdet_v = np.linalg.slogdet(m)
    if sign <= 0:
        return -math.inf
    g = delta * np.linalg.inv(m)
    xvx = np.eye(b.shape[0]) - b @ g @ b.T
    xvr = xr - b @ g @ ur
    rvr = rr - ur @ g @ ur
    if b.shape[0]:
        sign_x, logdet_x = np.linalg.slogdet(xvx)
        if sign_x <= 0:
            return -math.inf
        quad = rvr - xvr @ np.linalg.solve(xvx, xvr)
    else:
        logdet_x, quad = 0.0, rvr
    return -0.5 * (logdet_v + logdet_x + quad)


def reml_run_bias(r, x, u, sigma_now: float) -> float:
    """σ_b [rad/s] that maximises the REML likelihood (module docstring) of the whitened
    residual `r` (whitened with σ_b = `sigma_now` [rad/s]), fixed-effect columns `x` and the
    runs' columns `u` ([`run_columns`][hrgjax.discovery.run_bias.run_columns]). Searched
    over 10⁻² … 10³ × the spread of a run mean under the whitening, and 0."""
    u = np.asarray(u, float)
    if u.shape[1] == 0:
        return sigma_now
    norms = np.linalg.norm(u, axis=0)
    scale = float(np.median(1.0 / norms[norms > 0]))  # a run mean's spread [rad/s]
    u = u * scale
    products = _products(np.asarray(r, float), _orthonormal(np.asarray(x, float)), u)

    def loglik(log_s):  # σ_b = e^log_s [rad/s] (None: 0); δ in units of scale²
        s = math.exp(log_s) if log_s is not None else 0.0
        return _loglik(products, (s * s - sigma_now**2) / scale**2)

    grid = np.log(scale) + np.log(10.0) * np.arange(-2.0, 3.0 + 1e-9, 0.25)
    values = [loglik(g) for g in grid]
    best = int(np.argmax(values))
    at_zero = loglik(None)
    if at_zero >= values[best] and best == 0:
        return 0.0
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - golden * (hi - lo), lo + golden * (hi - lo)
    fa, fb = loglik(a), loglik(b)
    for _ in range(25):  # golden section on log σ_b: to 10⁻⁵ of the bracket
        if fa > fb:
            hi, b, fb = b, a, fa
            a = hi - golden * (hi - lo)
            fa = loglik(a)
        else:
            lo, a, fa = a, b, fb
            b = lo + golden * (hi - lo)
            fb = loglik(b)
    mid = 0.5 * (lo + hi)
    return 0.0 if at_zero > loglik(mid) else math.exp(mid)


def reml_at_fit(fit, held, train_groups, held_groups, covariates, sigma_now: float) -> float:
    """[`reml_run_bias`][hrgjax.discovery.run_bias.reml_run_bias] at a continuous problem's
    fit: `fit.r`, `fit.j` on the training rows of `train_groups`; `held`, the whitened
    residual and Jacobian (the fit's parameters) on the rows of `held_groups` (None without
    them: not fitted, but moved by the parameters the training runs fix); as further fixed
    effects each run covariate of `covariates` (`{run: values}`, those the run means follow)
    times the runs' columns. σ_b [rad/s]."""
    (u_t, ids_t), (u_h, ids_h) = run_columns(train_groups), run_columns(held_groups)
    u = np.zeros((u_t.shape[0] + u_h.shape[0], len(ids_t) + len(ids_h)))
    u[: u_t.shape[0], : len(ids_t)] = u_t
    u[u_t.shape[0] :, len(ids_t) :] = u_h
    j, r = np.asarray(fit.j), np.asarray(fit.r)
    if held is not None:
        j = np.concatenate([j, np.asarray(held[1])])
        r = np.concatenate([r, np.asarray(held[0])])
    cov = np.asarray([covariates[run] for run in ids_t + ids_h]).reshape(
        len(ids_t) + len(ids_h), -1
    )
    return reml_run_bias(r, np.concatenate([j, u @ cov], axis=1), u, sigma_now)
