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

**σ_b's own uncertainty.** Six runs less the fixed effects the run means carry leave REML
about four degrees of freedom for σ_b (n_runs − Σ cos² of X's angles to the runs' span:
4.4 on `continuous_dataset`'s six ramps), so σ̂_b scatters by ×10 between seeds of one
design (0.036–0.39 °/h over 100 seeds, truth 0.2). A parameter the run means pin — the
angular gain, fixed by the turning runs' mean rate against the static ones' — has a σ
proportional to σ_b, and with σ̂_b plugged in as known its error over σ is Student's t on
those four degrees of freedom, not a normal: k_e's z-RMS was 1.34 over the 100 seeds
(audit 2026-11-30; one seed at −6.6σ where σ̂_b read 0.036 °/h), while the thermal rate,
pinned inside the runs, was unaffected (1.13). [`spread_factors`][hrgjax.discovery.run_bias.spread_factors]
carries σ_b's uncertainty into every parameter's variance: σ_b is integrated over its
posterior — the REML likelihood above times the Jeffreys prior of that likelihood,
$\pi(\sigma_b^2) \propto \sqrt{\tfrac12\operatorname{tr}(U^\top PU)^2}$ (∝ 1/σ_b² where
σ_b dominates a run mean, flat where the within-run noise does: proper at σ_b = 0) — and
each parameter's variance becomes $\mathrm E[C_{ii}(\sigma_b) + (\hat\theta_i(\sigma_b) -
\hat\theta_i)^2]$, the generalised-least-squares covariance and shift of the fit at each
σ_b (Woodbury again). For a parameter that only the run means pin this is the variance of
Student's t, ν/(ν − 2) × the plug-in one, whose z has unit variance whatever σ̂_b reads —
where σ_b dominates a run mean's noise. Where it does not, the factor over-covers (toy of
tests/test_discovery_run_bias.py, six runs, review of 31987e6: z-RMS 0.62 at σ_b = 0, 0.72
at 0.5×, 0.92 at 3× a run mean's noise). With ν ≤ 2 (3–4 runs) E[σ_b²] is infinite and
`spread` gives no σ ("σ_b not pinned by N runs") to a parameter whose variance keeps growing
with σ_b (∝ σ_b²: only the run means pin it); one the runs' own records also pin levels off
and keeps its integrated σ (the 3-run continuous design: k_e ×15, the bias ×14, the damping
anisotropy ×1.06 — review of 4c90143).
"""

from __future__ import annotations

import math

import numpy as np

from .records import rate_columns
from .stats import orthonormal_span

POSTERIOR_POINTS = 121
"""Values of σ_b the posterior is evaluated at (`posterior`: 20 a decade over six decades)."""
EDGE_SHARE = 0.1
"""Share of a parameter's σ_b-integrated variance from the posterior grid's top decade above
which `spread` gives it no σ (σ_b not pinned: 0.35–0.6 with ν = 2, 0.9 with ν = 1, ≤ 0.03
with ν = 4 on the toy of tests/test_discovery_run_bias.py)."""


def run_columns(groups) -> tuple[np.ndarray, list[int]]:
    """Whitened columns (rows of `groups` in residual order, runs) of each continuous run's
    constant rate of 1 rad/s: a run bias b adds b times its column to the whitened residual.
    Window rows (a mixed log's dwell runs: their session bias is profiled out) are zero.
    **Returns** `(U, run ids)` ([`rate_columns`][hrgjax.discovery.records.rate_columns])."""
    return rate_columns(groups)


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


def _scaled(r, x, u):
    """`_products` with the runs' columns in units of a run mean's spread under the
    whitening (`scale` [rad/s]): `(products, scale)`."""
    u = np.asarray(u, float)
    norms = np.linalg.norm(u, axis=0)
    scale = float(np.median(1.0 / norms[norms > 0]))  # a run mean's spread [rad/s]
    return _products(np.asarray(r, float), orthonormal_span(np.asarray(x, float)), u * scale), scale


def reml_run_bias(r, x, u, sigma_now: float) -> float:
    """σ_b [rad/s] that maximises the REML likelihood (module docstring) of the whitened
    residual `r` (whitened with σ_b = `sigma_now` [rad/s]), fixed-effect columns `x` and the
    runs' columns `u` ([`run_columns`][hrgjax.discovery.run_bias.run_columns]). Searched
    over 10⁻² … 10³ × the spread of a run mean under the whitening, and 0."""
    if np.shape(u)[1] == 0:
        return sigma_now
    products, scale = _scaled(r, x, u)

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


def _batched(products, delta):
    """`_loglik` and the REML Fisher information on σ_b² (½ tr((UᵀPU)²), in the units of
    `_scaled`) at every δ of the 1-D array `delta` at once (Woodbury, as `_loglik`)."""
    a, b, ur, xr, rr = products
    eye = np.eye(a.shape[0])
    m = eye + delta[:, None, None] * a
    sign, logdet_v = np.linalg.slogdet(m)
    g = delta[:, None, None] * np.linalg.inv(m)
    uvu = a - a @ g @ a  # UᵀV⁻¹U, then (with fixed effects) less its part along X
    rvr = rr - np.einsum("i,kij,j->k", ur, g, ur)
    logdet_x = np.zeros(delta.size)
    if b.shape[0]:
        xvx = np.eye(b.shape[0]) - b @ g @ b.T
        xvr = xr - np.einsum("ij,kjl,l->ki", b, g, ur)
        xvu = b - b @ g @ a
        sign_x, logdet_x = np.linalg.slogdet(xvx)
        sign = np.minimum(sign, sign_x)
        rvr = rvr - np.einsum("ki,ki->k", xvr, np.linalg.solve(xvx, xvr[..., None])[..., 0])
        uvu = uvu - np.swapaxes(xvu, 1, 2) @ np.linalg.solve(xvx, xvu)
    loglik = np.where(sign > 0, -0.5 * (logdet_v + logdet_x + rvr), -np.inf)
    return loglik, 0.5 * np.einsum("kij,kji->k", uvu, uvu)


def posterior(r, x, u, sigma_now: float, points: int = POSTERIOR_POINTS):
    """σ_b's posterior (module docstring: REML likelihood × its Jeffreys prior) from the
    arguments of [`reml_run_bias`][hrgjax.discovery.run_bias.reml_run_bias], on `points`
    values of σ_b spaced evenly in log σ_b over 10⁻³ … 10³ × a run mean's spread under the
    whitening: `(sigma_b [rad/s], weights summing to 1)`."""
    products, scale = _scaled(r, x, u)
    sigma = scale * np.logspace(-3.0, 3.0, points)
    loglik, info = _batched(products, (sigma**2 - sigma_now**2) / scale**2)
    # prior density in σ_b² times dσ_b²/dlog σ_b = 2σ_b²: the grid is even in log σ_b
    log_w = loglik + 0.5 * np.log(np.maximum(info, 1e-300)) + 2.0 * np.log(sigma / scale)
    w = np.exp(log_w - np.max(log_w))
    return sigma, w / w.sum()


def _contributions(j, r, u, sigma_now, sigma, weights):
    """`spread_factors`' sum term by term: `(w_k (C_ii + δθ_i²) at each kept σ_b_k (K, p),
    those σ_b_k, C_ii(σ_now))`, or None where the runs carry no bias column."""
    j, r, u = (np.asarray(a, float) for a in (j, r, u))
    u = u[:, np.linalg.norm(u, axis=0) > 0]
    norm = np.linalg.norm(j, axis=0)
    js = j / np.where(norm > 0, norm, 1.0)  # unit columns: they differ by 10¹⁰
    if u.shape[1] == 0 or j.shape[1] == 0:
        return None
    jj, ju, uu, ur, jr = js.T @ js, js.T @ u, u.T @ u, u.T @ r, js.T @ r
    keep = np.asarray(weights) > 1e-12
    s = np.r_[sigma_now, np.asarray(sigma, float)[keep]]
    delta = (s * s - sigma_now**2)[:, None, None]
    g = delta * np.linalg.inv(np.eye(uu.shape[0]) + delta * uu)
    c = np.linalg.pinv(jj - ju @ g @ ju.T, hermitian=True)
    shift = np.einsum("kij,kj->ki", c, jr - np.einsum("ij,kjl,l->ki", ju, g, ur))
    var = np.diagonal(c, axis1=1, axis2=2)
    terms = np.asarray(weights)[keep][:, None] * (var[1:] + (shift[1:] - shift[0]) ** 2)
    return terms, s[1:], var[0]


def spread_factors(j, r, u, sigma_now: float, sigma, weights) -> np.ndarray:
    """Each fitted parameter's variance with σ_b integrated over `(sigma, weights)`
    ([`posterior`][hrgjax.discovery.run_bias.posterior]) over its variance at
    `sigma_now` [rad/s], the σ_b the fit's whitened Jacobian `j` (N, p) and residual `r` are
    whitened with; `u` (N, R): the training runs' columns. Per σ_b the generalised least
    squares covariance C and shift δθ of the fit (one Gauss–Newton step: exact for a model
    linear near the fit) under the whitened covariance I + (σ_b² − σ_now²)UUᵀ; **returns**
    E[C_ii + δθ_i²] / C_ii(σ_now), shape (p,) (1 where the runs carry no bias column)."""
    return _factors(_contributions(j, r, u, sigma_now, sigma, weights), np.shape(j)[1])


def _factors(out, p: int) -> np.ndarray:
    """`spread_factors` from `_contributions`' output."""
    if out is None:
        return np.ones(p)
    terms, _, var0 = out
    mse = terms.sum(axis=0)
    return np.where(var0 > 0, mse / np.where(var0 > 0, var0, 1.0), 1.0)


def edge_share(j, r, u, sigma_now: float, sigma, weights) -> np.ndarray:
    """Each parameter's share of its σ_b-integrated variance
    ([`spread_factors`][hrgjax.discovery.run_bias.spread_factors], same arguments) that
    comes from σ_b in the top decade of `sigma`, shape (p,): near 0 where the variance
    settles inside the grid, a visible share where it grows with σ_b as fast as σ_b's
    posterior falls (a parameter only the run means pin, ν ≤ 2: E[σ_b²] diverges and
    the grid's top sets the value). 0 where the runs carry no bias column."""
    out = _contributions(j, r, u, sigma_now, sigma, weights)
    return _share(out, np.shape(j)[1], float(np.max(np.asarray(sigma, float))))


def _share(out, p: int, top: float) -> np.ndarray:
    """`edge_share` from `_contributions`' output, `top` the grid's largest σ_b."""
    if out is None:
        return np.zeros(p)
    terms, s, _ = out
    total = terms.sum(axis=0)
    upper = terms[s >= top / 10.0].sum(axis=0)
    return np.where(total > 0, upper / np.where(total > 0, total, 1.0), 0.0)


def dof(x, u) -> float:
    """Degrees of freedom the run means leave σ_b: the runs (columns of `u` that are not
    zero) less Σ cos² of the principal angles between the fixed effects `x` and the runs'
    span (a fixed effect inside the span spends one; one across it, part of one)."""
    u = np.asarray(u, float)
    q = orthonormal_span(u[:, np.linalg.norm(u, axis=0) > 0])
    xo = orthonormal_span(np.asarray(x, float))
    return float(q.shape[1] - np.sum(np.linalg.svd(q.T @ xo, compute_uv=False) ** 2))


def spread(fit, r, x, u, sigma_now: float, per_dph: float):
    """σ_b's uncertainty in a continuous fit's parameters (module docstring): `fit` (its
    whitened `r`, `j` on the training rows, whitened with σ_b = `sigma_now` [rad/s]), `(r, x,
    u)` from [`reml_inputs`][hrgjax.discovery.run_bias.reml_inputs] at it, `per_dph` the
    pattern rate [rad/s] of 1 °/h of input rate. **Returns** `(factors, info)`: each regular
    parameter's variance factor ([`spread_factors`][hrgjax.discovery.run_bias.spread_factors]),
    ∞ for a parameter σ_b is not pinned for: with ν ≤ 2 degrees of freedom (3–4 runs;
    E[σ_b²] is then infinite) every parameter whose variance still grows with σ_b at the
    grid's top (over twice its value a decade below: those only the run means pin, whose
    result would rest on the prior's tail and the grid's range; one the runs' own records
    also pin levels off there and keeps its integrated σ), and at any ν one with over `EDGE_SHARE` of its variance from
    the grid's top decade ([`edge_share`][hrgjax.discovery.run_bias.edge_share]) and over
    twice that decade's posterior weight; and `{"runs", "dof": dof(x, u),
    "sigma_b_dph": [16 %, 50 %, 84 % points of σ_b's posterior], "not_pinned": [indices of
    the ∞ factors], "basis": words}`."""
    sigma, w = posterior(r, x, u, sigma_now)
    n = np.asarray(fit.r).size
    args = (fit.j, fit.r, np.asarray(u)[:n], sigma_now, sigma, w)
    p, out = np.shape(fit.j)[1], _contributions(*args)  # the grid's solves, once
    factors, share = _factors(out, p), _share(out, p, float(np.max(sigma)))
    top = float(np.sum(w[sigma >= np.max(sigma) / 10.0]))
    nu, runs = dof(x, u), int(np.shape(u)[1])
    # a parameter only the run means pin: its variance still growing with σ_b at the grid's
    # top (∝ σ_b², 100× over the top decade; one the runs pin from inside levels off, ≈ 1×)
    ends = _contributions(*args[:4], [np.max(sigma) / 10.0, np.max(sigma)], [1.0, 1.0])
    grows = np.zeros(p, bool) if ends is None else ends[0][1] > 2.0 * ends[0][0]
    loose = ((share > EDGE_SHARE) & (share > 2.0 * top)) | ((nu <= 2.0 + 1e-6) & grows)
    factors = np.where(loose, np.inf, factors)
    q = np.interp([0.16, 0.5, 0.84], np.cumsum(w) - 0.5 * w, sigma) / per_dph
    words = (f"σ_b's uncertainty carried in (REML on {runs} runs, {nu:.1f} "
             f"degrees of freedom: {q[0]:.2g}–{q[2]:.2g} °/h)")  # fmt: skip
    if loose.any():
        words += (f"; σ_b not pinned by {runs} runs: no σ for the parameters the run means "
                  "pin (no_sigma)")  # fmt: skip
    info = {"runs": runs, "dof": nu, "sigma_b_dph": q.tolist(),
            "not_pinned": np.flatnonzero(loose).tolist(), "basis": words}  # fmt: skip
    return factors, info


def reml_inputs(fit, held, train_groups, held_groups, covariates):
    """What [`reml_run_bias`][hrgjax.discovery.run_bias.reml_run_bias] reads at a continuous
    problem's fit (arguments of [`reml_at_fit`][hrgjax.discovery.run_bias.reml_at_fit]):
    `(r, x, u)` on the training rows then the held-out rows, the training runs' columns
    first."""
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
    return r, np.concatenate([j, u @ cov], axis=1), u


def reml_at_fit(fit, held, train_groups, held_groups, covariates, sigma_now: float) -> float:
    """[`reml_run_bias`][hrgjax.discovery.run_bias.reml_run_bias] at a continuous problem's
    fit: `fit.r`, `fit.j` on the training rows of `train_groups`; `held`, the whitened
    residual and Jacobian (the fit's parameters) on the rows of `held_groups` (None without
    them: not fitted, but moved by the parameters the training runs fix); as further fixed
    effects each run covariate of `covariates` (`{run: values}`, those the run means follow)
    times the runs' columns. σ_b [rad/s]."""
    return reml_run_bias(*reml_inputs(fit, held, train_groups, held_groups, covariates),
                         sigma_now)  # fmt: skip
