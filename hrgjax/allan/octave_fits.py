r"""Fitting composite noise models to the octaves' Allan variances — the two fits
[`identify_noise`][hrgjax.allan.identify_noise] selects with:

- **GLS over subsets** (`best_fit`): the coefficients² of the linear terms and of up to two
  first-order Gauss–Markov terms by generalised least squares under a covariance Ω of the
  octave estimates, each Gauss–Markov correlation time profiled on a log grid and refined by
  a parabola in log T; every subset of the candidates screened from the Gram matrix of the
  whitened columns.
- **The refit on log σ̂²** (`log_fit`): one model fitted by Newton on the squares weighted
  by its own relative covariance D⁻¹ΩD⁻¹ (D the model), the covariance re-evaluated at the
  fit in rounds.

A fit is a dict: `names` (linear terms), `gm` (correlation times [s]), `c` (coefficients²,
the linear terms' then the Gauss–Markov terms' σ²) and `J` (the whitened misfit). Every
function that evaluates a term takes the rate samples' `sampling` (one of
[`SAMPLINGS`][hrgjax.allan.octave_covariance.SAMPLINGS]) as a required keyword, passed on
to [`unit_avar`][hrgjax.allan.octave_covariance.unit_avar] and
[`covariance`][hrgjax.allan.octave_covariance.covariance]. `upper_bounds`: the bounds on the
candidate terms a selected model left out; `octave_rows`: the octaves of a deviation the
caller has already, checked to be the record's.
"""

from __future__ import annotations

import functools
import itertools
import math
from statistics import NormalDist

import numpy as np

from .octave_covariance import covariance, unit_avar
from .uncertainty import chi2_sf


def model_avar(fit, ms, tau0, *, sampling):
    """The Allan variance [unit²] of a fit at the averaging factors `ms`, samples every
    `tau0` [s] taken as `sampling`."""
    out = sum(c * unit_avar(t, ms, tau0, sampling=sampling)
              for t, c in zip(fit["names"], fit["c"], strict=False))  # fmt: skip
    for c, t in zip(fit["c"][len(fit["names"]) :], fit["gm"], strict=True):
        out = out + c * unit_avar("gauss_markov", ms, tau0, tau0 / t, sampling)
    return out


def model_covariance(fit, ms, n, tau0, avar, *, sampling):
    """Ω [unit⁴]: the covariance of the octave estimates at factors `ms` of `n` samples under
    the fit ([`covariance`][hrgjax.allan.octave_covariance.covariance]), each variance
    floored at 1e-6 of the estimates' own (`avar` [unit²]) so that Ω stays invertible;
    samples taken as `sampling`."""
    coef = dict(zip(fit["names"], fit["c"][: len(fit["names"])], strict=True))
    gm = [(s2, tt) for s2, tt in zip(fit["c"][len(fit["names"]) :], fit["gm"], strict=True)]
    om = covariance(coef, gm, ms, n, tau0, sampling)
    # a floor of 1e-6 of each octave's own variance keeps Ω invertible where the model is 0
    return om + np.diag(1e-6 * np.maximum(np.diag(om), 2 * avar**2 / max(n, 1)))


def gls(avar, chol_inv, basis):
    """Coefficients² by GLS of the octaves' `avar` (S,) [unit²] on a batch of bases
    (C, S, p) of unit Allan variances (or one, (S, p)), `chol_inv` the inverse Cholesky
    factor of Ω: `(c (C, p), J (C,))`, J = inf where a coefficient is negative (that subset
    is not admissible)."""
    one = basis.ndim == 2
    basis = basis[None] if one else basis
    c, j = whitened_ls(chol_inv @ basis, chol_inv @ avar)
    return (c[0], j[0]) if one else (c, j)


def gram_ls(gram, h, bb, idx):
    """`gls` from the whitened columns' Gram matrix `gram`, their products `h` with the
    whitened data and its square `bb`, for the bases whose columns are the rows of `idx`
    (C, p): J = bb − c·(Aᵀb) at the solution (to ≈ 1e-16·bb, for ranking the bases)."""
    d = np.sqrt(gram.diagonal())[idx]  # the columns span decades
    ata = gram[idx[:, :, None], idx[:, None, :]] / (d[:, :, None] * d[:, None, :])
    atb = h[idx] / d
    try:
        c = np.linalg.solve(ata, atb[..., None])[..., 0]
    except np.linalg.LinAlgError:
        c = np.stack([np.linalg.lstsq(m, v, rcond=None)[0] for m, v in zip(ata, atb, strict=True)])
    j = bb - (c * atb).sum(1)
    c = c / d
    j = np.where(np.all(c >= 0, axis=1) & np.isfinite(j), np.maximum(j, 0.0), np.inf)
    return c, j


def whitened_ls(a, b):
    """`gls` on whitened columns a (C, S, p) and data b (S,)."""
    scale = np.sqrt(np.einsum("csp,csp->cp", a, a))[:, None, :]  # the columns span decades
    a = a / scale
    ata = a.transpose(0, 2, 1) @ a
    atb = b @ a
    try:
        c = np.linalg.solve(ata, atb[..., None])[..., 0]
    except np.linalg.LinAlgError:
        c = np.stack([np.linalg.lstsq(m, v, rcond=None)[0] for m, v in zip(ata, atb, strict=True)])
    r = (a @ c[..., None])[..., 0] - b
    j = (r * r).sum(1)
    c = c / scale[:, 0, :]
    j = np.where(np.all(c >= 0, axis=1) & np.isfinite(j), j, np.inf)
    return c, j


@functools.lru_cache(maxsize=8)
def combinations(n: int, k: int) -> np.ndarray:
    """The k-subsets of range(n) as rows (C, k)."""
    rows = list(itertools.combinations(range(n), k))
    out = np.asarray(rows, dtype=int).reshape(len(rows), k)
    out.flags.writeable = False
    return out


def best_fit(avar, omega, cols, gm_cols, names, g, g_exact, tau0, ms, *, sampling):
    """The best fit of the linear terms `names` plus g Gauss–Markov terms (correlation times
    profiled on the grid, then refined by a parabola in log T); with `g_exact` None, every
    admissible subset of them (NNLS), as the fullest model's fit. `cols` and `gm_cols`
    (the unit Allan variances) and `sampling` (for the refinement's) must agree."""
    chol_inv = np.linalg.inv(np.linalg.cholesky(omega))
    subsets = [names] if g_exact is not None else [
        list(s) for k in range(len(names) + 1) for s in itertools.combinations(names, k)]  # fmt: skip
    gms = [g] if g_exact is not None else list(range(g + 1))
    best = None
    grid = sorted(gm_cols)
    # every column whitened once, and their Gram matrix: each basis's normal equations are
    # a submatrix of it, each subset screened without forming its columns
    b = chol_inv @ avar
    lin = np.stack([cols[t] for t in names], axis=1) if names else np.zeros((len(ms), 0))
    w = chol_inv @ np.concatenate([lin, np.stack([gm_cols[t] for t in grid], axis=1)], axis=1)
    gram, h, bb = w.T @ w, w.T @ b, float(b @ b)
    for sub in subsets:
        li = np.asarray([names.index(t) for t in sub], dtype=int)
        for k in gms:
            if not sub and k == 0:
                continue
            combos = combinations(len(grid), k)
            idx = np.concatenate([np.broadcast_to(li, (len(combos), li.size)), len(names) + combos],
                                 axis=1)  # fmt: skip
            c, j = gram_ls(gram, h, bb, idx)
            i = int(np.argmin(j))
            if np.isfinite(j[i]) and (best is None or j[i] < best["J"]):
                best = {"names": list(sub), "gm": [grid[int(t)] for t in combos[i]], "c": c[i],
                        "J": float(j[i]), "idx": idx[i]}  # fmt: skip
    if best is None:
        return None
    # the winner's coefficients and J from its residual, as every other fit's
    c, j = whitened_ls(w[:, best.pop("idx")][None], b)
    if np.isfinite(j[0]):
        best["c"], best["J"] = c[0], float(j[0])
    if best["gm"]:
        best = refine(best, avar, chol_inv, cols, tau0, ms, grid, sampling=sampling)
    return best


def refine(fit, avar, chol_inv, cols, tau0, ms, grid, *, sampling):
    """Each correlation time moved to the vertex of a parabola in log T through its grid
    neighbours (the others held), when that lowers J."""
    step = math.log(grid[1] / grid[0])
    for i in range(len(fit["gm"])):

        def j_at(log_ts, fit=fit, i=i):  # J and (times, c) with T_i at each of `log_ts`
            times = np.repeat(np.asarray(fit["gm"], dtype=float)[None], len(log_ts), axis=0)
            times[:, i] = np.exp(log_ts)
            gm = unit_avar("gauss_markov", ms, tau0, tau0 / times.ravel(), sampling)
            gm = gm.reshape(*times.shape, len(ms)).transpose(0, 2, 1)  # (trials, S, k)
            lin = np.stack([cols[t] for t in fit["names"]], 1) if fit["names"] else gm[0, :, :0]
            basis = np.concatenate([np.broadcast_to(lin, (len(log_ts), *lin.shape)), gm], 2)
            c, j = gls(avar, chol_inv, basis)
            return [(np.inf, None) if not np.isfinite(jt) else (float(jt), (list(ts), ct))
                    for jt, ts, ct in zip(j, times, c, strict=True)]  # fmt: skip

        x0 = math.log(fit["gm"][i])
        (j_lo, _), (j_hi, _) = j_at([x0 - step, x0 + step])
        den = j_lo - 2 * fit["J"] + j_hi  # J at x0 is the fit's own
        if np.isfinite(den) and den > 0:
            x = x0 + 0.5 * step * (j_lo - j_hi) / den
            x = min(max(x, math.log(grid[0])), math.log(grid[-1]))
            ((jx, sol),) = j_at([x])
            if sol is not None and jx < fit["J"]:
                fit = {"names": fit["names"], "gm": sol[0], "c": sol[1], "J": jx}
    return fit


def log_parts(p, lin, k, ms, tau0, *, sampling):
    """Model Allan variance M, ∂(log M)/∂p, and a function giving ∂²(log M)/∂p² (S, P, P),
    at p = (log c² of the linear terms, whose unit Allan variances at `ms` are the columns
    of `lin` (S, q), and of the k Gauss–Markov terms, log T of each; samples taken as
    `sampling`)."""
    q = lin.shape[1]
    c = np.exp(p[: q + k])
    h = 1e-4  # ∂/∂ log T by central differences: each T and T·e^{±h} in one evaluation
    if k:
        logt = p[q + k :]
        times = np.exp(np.concatenate([logt, logt + h, logt - h]))
        gm = unit_avar("gauss_markov", ms, tau0, tau0 / times, sampling)
        amp = np.concatenate([lin, gm[:k].T], axis=1) * c  # ∂M/∂ log c² = c²·f
        slope = c[q:] * (gm[k : 2 * k] - gm[2 * k :]).T / (2 * h)  # ∂M/∂ log T
    else:
        amp, slope = lin * c, np.zeros((len(ms), 0))
    model = amp.sum(1)
    jac = np.concatenate([amp, slope], axis=1) / model[:, None]

    def curvature():  # ∂²M/M − ∇L∇Lᵀ, ∂²M nonzero on the diagonal and each (c_g², T_g) pair
        size = q + 2 * k
        second = np.zeros((len(ms), size, size))
        second[:, np.arange(q + k), np.arange(q + k)] = amp
        if k:
            g, t = np.arange(q, q + k), np.arange(q + k, size)
            second[:, g, t] = second[:, t, g] = slope
            second[:, t, t] = c[q:] * (gm[k : 2 * k] - 2 * gm[:k] + gm[2 * k :]).T / (h * h)
        return second / model[:, None, None] - jac[:, :, None] * jac[:, None, :]

    return model, jac, curvature


def log_fit(
    fit, avar, ms, n, tau0, steps: int = 12, rounds: int = 3, cols=None, give_up=None, *, sampling
):
    """The selected model refitted on log σ̂² (Newton on the weighted squares, Gauss–Newton
    where its Hessian is not positive definite, step-halving): the relative covariance
    D⁻¹ΩD⁻¹ (D the model) hardly depends on the fitted level, so the weights do not follow
    the estimate as Ω's do on σ̂² itself, and the long octaves' skewed estimates weigh
    symmetrically. Samples taken as `sampling` (`cols`, where given, must agree). **Returns:** `(fit, Ω, covariance of p)`, p = (log c², log T)."""
    c = np.asarray(fit["c"], dtype=float)
    keep = c > 0  # a term at zero is absent: log c² has no place to start from
    q = len(fit["names"])
    names = [t for t, kept in zip(fit["names"], keep[:q], strict=True) if kept]
    gm = [t for t, kept in zip(fit["gm"], keep[q:], strict=True) if kept]
    k, c = len(gm), c[keep]
    p = np.concatenate([np.log(c), np.log(np.asarray(gm, dtype=float))])
    target = np.log(avar)
    lin = (np.stack([unit_avar(t, ms, tau0, sampling=sampling) if cols is None else cols[t]
                     for t in names], axis=1)
           if names else np.zeros((len(ms), 0)))  # fmt: skip

    def fitted(p):
        return {"names": names, "gm": list(np.exp(p[len(names) + k :])),
                "c": np.exp(p[: len(names) + k])}  # fmt: skip

    def whitened(parts, whiten):  # whitened residual and Jacobian, the log model's ∂², and
        model, jac, curvature = parts  # which parameters still move the model (a term whose
        # share of it has fallen below 1e-6 at every octave is absent: its log c² would fall
        # by ≈ 1 a step for as long as it is let, changing nothing)
        live = np.max(np.abs(jac), axis=0) >= 1e-6
        return whiten @ (target - np.log(model)), whiten @ jac, curvature, live

    def relative(p, model):  # the covariance of log σ̂² at p, D⁻¹ΩD⁻¹, and its inverse factor
        om = model_covariance(fitted(p), ms, n, tau0, avar, sampling=sampling)
        return om, np.linalg.inv(np.linalg.cholesky(om / np.outer(model, model)))

    def step_from(r, a, curv, whiten):
        # Newton: the squares' Hessian AᵀA − Σ (Wᵀr)_s ∂²L_s; where the residuals are
        # large against A's small singular values Gauss–Newton alone converges linearly
        hess = a.T @ a - np.einsum("s,sij->ij", whiten.T @ r, curv())
        try:
            np.linalg.cholesky(hess)
            return np.linalg.solve(hess, a.T @ r)
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(a, r, rcond=None)[0]

    dof = max(len(ms) - p.size, 1)
    for _ in range(rounds):  # Newton with the weights held, then the weights at its end
        parts = log_parts(p, lin, k, ms, tau0, sampling=sampling)
        om, chol = relative(p, parts[0])
        r, a, curv, live = whitened(parts, chol)
        cost = float(r @ r)
        for _ in range(steps):
            step = step_from(r, a, curv, chol)
            for scale in (1.0, 0.5, 0.25, 0.125):
                trial = p + scale * np.clip(step, -2.0, 2.0)
                got = whitened(log_parts(trial, lin, k, ms, tau0, sampling=sampling), chol)
                if float(got[0] @ got[0]) < cost:
                    p, (r, a, curv, live), cost = trial, got, float(got[0] @ got[0])
                    break
            else:
                break
            if np.max(np.abs(scale * step)[live], initial=0.0) < 1e-6:
                break
        if give_up is not None and chi2_sf(cost, dof) < give_up:  # rejected, whatever the
            break  # later rounds do
    parts = log_parts(p, lin, k, ms, tau0, sampling=sampling)
    om, chol = relative(p, parts[0])
    r, a, *_ = whitened(parts, chol)
    f = fitted(p)
    f["J"] = float(r @ r)
    return f, om, np.linalg.pinv(a.T @ a)


def upper_bounds(fit, avar, omega, cols, ms, n, tau0, terms, ci, sampling):
    """[`identify_noise`][hrgjax.allan.identify_noise]'s bounds: upper ends at level `ci` of
    the candidate linear terms not in `fit`, each forced in
    beside the selected model (its coefficient² free in sign, the others' held): √ of the
    largest b ≥ 0 with b ≤ ĉ² + zσ(b), ĉ² and σ by GLS under the octaves' covariance of the
    model with the term at b — the test of c² = b inverted (`largest_accepted`). Ω of the
    model without the term is too small at the octaves the term would lift (the bound fell
    below a true rate random walk in 16 % of records at 95 %); inf where no b is rejected
    (σ grows as fast as b) [coefficient unit]."""
    z = NormalDist().inv_cdf(0.5 + ci / 2)
    base = model_avar(fit, ms, tau0, sampling=sampling)
    k = len(fit["names"])
    out = {}
    for name in terms:
        if name in fit["names"]:
            continue

        def gls(om, name=name):  # ĉ² and its σ under Ω
            chol_inv = np.linalg.inv(np.linalg.cholesky(om))
            a = chol_inv @ cols[name]
            return float(a @ (chol_inv @ (avar - base)) / (a @ a)), 1 / math.sqrt(float(a @ a))

        def excess(b, name=name):  # b − (ĉ² + zσ) under Ω of the model with the term at b
            with_term = dict(fit, names=[*fit["names"], name],
                             c=np.concatenate([fit["c"][:k], [b], fit["c"][k:]]))  # fmt: skip
            c2, sigma = gls(model_covariance(with_term, ms, n, tau0, avar, sampling=sampling))
            return b - (c2 + z * sigma)

        c2, sigma = gls(omega)
        out[name] = math.sqrt(largest_accepted(excess, max(c2 + z * sigma, 0.0), z * sigma))
    return out


def largest_accepted(excess, start: float, scale: float) -> float:
    """The b ≥ 0 where `excess(b)` (≤ 0 at b = 0: accepted) turns positive for good, from
    `start` (the guess; `scale` > 0 where it is 0): bracketed by doubling, then Brent's root
    to 1e-6 relative; inf where it stays ≤ 0 up to 2⁶⁰ × the guess."""
    from scipy.optimize import brentq

    lo, hi = 0.0, start if start > 0 else scale
    if excess(hi) <= 0:
        for _ in range(60):
            lo, hi = hi, 2.0 * hi
            if excess(hi) > 0:
                break
        else:
            return math.inf
    if excess(lo) > 0:  # accepted at 0 by construction unless ĉ² < 0 there: then 0
        return 0.0
    return float(brentq(excess, lo, hi, xtol=1e-300, rtol=1e-6))


def octave_rows(result, y, rate_hz: float, octaves):
    """The rows of `result` (the overlapping Allan deviation of `y` at `rate_hz`, default
    noise rule) at the factors `octaves`, checked to be that: an `AllanResult` of kind oadev
    without gaps, its factors holding every octave, its counts those of `y`'s length, its τ
    `octaves / rate_hz`, and its value at the first, a middle and the last octave `y`'s own
    (recomputed here in NumPy from the phase, to 1e-8: a deviation of another record that
    agrees at m = 1 — the raw log's beside its detrended one — differs at long τ). Used by
    [`identify_noise`][hrgjax.allan.identify_noise]`(oadev=)`.

    **Raises:** `ValueError` naming `oadev` where any check fails."""
    import dataclasses

    from .result import AllanResult

    octaves = np.asarray(octaves)
    m = None if not isinstance(result, AllanResult) or result.m is None else np.asarray(result.m)
    pick = None if m is None else np.flatnonzero(np.isin(m, octaves))
    ok = (
        m is not None
        and result.kind == "oadev"
        and getattr(result, "segments", None) is None
        and pick.size == octaves.size
        and np.array_equal(np.asarray(result.n_terms)[pick], y.size + 1 - 2 * octaves)
        and np.allclose(result.taus[pick], octaves / rate_hz, rtol=1e-9, atol=0.0)
    )
    if ok:
        # the phase in units of τ₀, of the record less its mean (as `deviation` takes it: a
        # 1e4 °/h bias over 4e6 samples lost 1e-7 of the second differences' digits)
        x = np.concatenate([[0.0], np.cumsum(y - np.mean(y))])
        for i in sorted({0, pick.size // 2, pick.size - 1}):
            k = int(octaves[i])
            d2 = x[2 * k :] - 2.0 * x[k:-k] + x[: -2 * k]
            own = math.sqrt(0.5 * np.mean(d2 * d2)) / k
            ok = ok and math.isclose(result.dev[pick[i]], own, rel_tol=1e-8, abs_tol=0.0)
    if not ok:
        raise ValueError("oadev must be the AllanResult of deviation(y, rate_hz) (kind 'oadev', "
                         "octave τ, the default noise rule) for this y; or None to compute "
                         "it")  # fmt: skip
    return dataclasses.replace(
        result, taus=result.taus[pick], m=m[pick], dev=result.dev[pick],
        dev_low=result.dev_low[pick], dev_high=result.dev_high[pick], edf=result.edf[pick],
        n_terms=np.asarray(result.n_terms)[pick], alpha=np.asarray(result.alpha)[pick],
        bias_factor=None if result.bias_factor is None else np.asarray(result.bias_factor)[pick],
        mixture=None if result.mixture is None else np.asarray(result.mixture)[pick],
    )  # fmt: skip
