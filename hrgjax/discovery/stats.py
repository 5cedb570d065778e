r"""The statistics every data shape of the search shares: weighted least squares, a covariance
that survives columns ten orders of magnitude apart, the score test (DISCOVERY.md §2.4 S3)
the χ² and F tail probabilities, and the same test judged at the noise level the residual
shows ([`level_test`][hrgjax.discovery.stats.level_test]).

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

import math

import jax
import numpy as np
from jax.scipy.special import betainc, gammaincc

from .._checks import (
    ROUND_OFF,
    check_finite_host,
    check_flag,
    check_numbers,
    describe,
    is_finite_real,
    numeric_problem,
    whole_number,
)

# The tails as one compiled program each: the search and the error bars ask for thousands of
# scalar tails, and an eager call dispatches betainc's primitives one at a time (0.44 ms a
# call against 0.11 ms compiled; `trust.honest` 1.35× faster: benchmarks/discovery_stats.py).
_betainc = jax.jit(betainc)
_gammaincc = jax.jit(gammaincc)


def real_array(owner: str, name: str, x, shape, form: str) -> np.ndarray:
    """`x` as a float array, or one line naming `owner: name` and the expected `form`: a
    `TypeError` for anything but real numbers, a `ValueError` for another `shape` (a tuple,
    None entries any length) or a NaN or inf."""
    check_numbers(f"{owner}: {name}", x, form, shape=shape)
    v = np.asarray(x, float)
    check_finite_host(f"{owner}: {name}", v)
    return v


def rows_of(owner: str, r, **blocks) -> tuple:
    """`r` (a whitened residual, (N,)) and each of `blocks` (columns, (N, k)) as float arrays,
    or one line naming `owner`, the argument and its expected shape (`real_array`)."""
    r = real_array(owner, "r", r, (None,), "the whitened residual, shape (N,)")
    n = r.size
    out = [real_array(owner, k, v, (n, None), f"whitened columns, shape (N, k) with N = {n}")
           for k, v in blocks.items()]  # fmt: skip
    return r, *out


def check_classes(owner: str, classes, n: int):
    """`classes` (None, or an integer class per row: (N,)) as an array, or one line naming
    `owner`: the classes of the wrong type, length or a non-integer class."""
    if classes is None:
        return None
    if numeric_problem(classes, bools=True) is not None or np.ndim(classes) != 1:
        raise (TypeError if numeric_problem(classes, bools=True) else ValueError)(
            f"{owner}: classes must be None or an integer class per row, shape (N,) = ({n},); "
            f"got {describe(classes)}"
        )
    c = np.asarray(classes)
    c = c.astype(int) if c.dtype == bool else c  # two classes given as a mask
    if c.size != n:
        raise ValueError(f"{owner}: {c.size} row classes for {n} rows (classes: an integer "
                         "class per row, or None)")  # fmt: skip
    if c.dtype.kind not in "iu" and not np.all(np.isfinite(c) & (c == np.round(c))):
        raise ValueError(f"{owner}: classes must be whole numbers (an integer class per row); "
                         f"got {c[~(np.isfinite(c) & (c == np.round(c)))][0]}")  # fmt: skip
    return c


def check_count(owner: str, name: str, value) -> int:
    """`value` as an int when it is a whole number >= 1, else one line naming `owner: name`."""
    return whole_number(f"{owner}: {name}", value, "an integer >= 1", minimum=1)


def check_level(owner: str, level):
    """A noise level `(s², ν)` ([`level_beyond`][hrgjax.discovery.stats.level_beyond]): s²
    finite and >= 0 to round-off (`level_beyond` returns −1e-19 for a residual inside the
    columns' span), ν a whole number >= 0; else one line naming `owner`."""
    v = real_array(owner, "level", level, (2,), "(s², ν): a noise level >= 0 and its dof >= 0")
    if not (v[0] >= -ROUND_OFF and v[1] >= 0 and v[1] == round(v[1])):
        raise ValueError(f"{owner}: level must be (s², ν) with s² >= 0 and ν a whole number "
                         f">= 0; got ({v[0]:g}, {v[1]:g})")  # fmt: skip
    return level


def wls(g: np.ndarray, y: np.ndarray, sigma: np.ndarray):
    """Weighted least squares of `y` on the columns `g` with standard errors `sigma`:
    `(beta, residual (whitened), covariance)`. The whitened columns are scaled to unit norm
    before the solve (and β back), as in `covariance`: unscaled, `lstsq`'s cut-off at ε of
    the largest singular value took a column 1e12 smaller beside a near-parallel one as
    rank-deficient and set β 89 σ off (tests/test_precision.py). A column the columns before
    it already span (its part orthogonal to them ≤ n ε of its norm: a candidate aliased with
    the model, a column of zeros) gets β = 0, the others their fit without it — not the
    minimum-norm split, which depends on the columns' units (scaled, it halved the angular
    gain beside a candidate proportional to it)."""
    g = real_array("wls", "g", g, (None, None), "the columns, shape (N, p)")
    n = g.shape[0]
    y = real_array("wls", "y", y, (n,), f"the data, shape (N,) with N = {n} (g's rows)")
    sigma = real_array("wls", "sigma", sigma, (n,), f"standard errors > 0, shape ({n},)")
    if not np.all(sigma > 0):
        raise ValueError(f"wls: sigma must be standard errors > 0; got {sigma[~(sigma > 0)][0]}")
    gw, yw = g / sigma[:, None], y / sigma
    norm = np.linalg.norm(gw, axis=0)
    d = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
    gs = gw * d
    pivots = np.abs(np.diagonal(np.linalg.qr(gs, mode="r")))
    keep = np.zeros(gs.shape[1], bool)
    keep[: pivots.size] = pivots > max(gs.shape) * np.finfo(gs.dtype).eps
    beta = np.zeros(gs.shape[1])
    beta[keep] = np.linalg.lstsq(gs[:, keep], yw, rcond=None)[0] * d[keep]
    return beta, yw - gw @ beta, covariance(gw)


UNDETERMINED = 1e-10
"""A column whose unit vector puts more than this share of its weight on directions the
data leave undetermined (`gram_inverse`) has no finite variance."""


def gram_inverse(gw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(GᵀG)⁺ of whitened columns `gw` (the pseudo-inverse, columns scaled to unit norm
    first) and which columns it determines: a column whose parameter has a share of its
    unit vector on the directions the pseudo-inverse cuts (eigenvalues of the scaled GᵀG
    below 10⁻¹⁵ of the largest: a column of zeros, a column the others span) is not
    determined by the data — the pseudo-inverse's finite variance for it is that of the
    minimum-norm split, not of the parameter (one table rate and no static runs: k_e and
    the bias, each 0.67 °/h where neither is determined). **Returns:** `(cov, determined)`,
    `cov` finite throughout (for products: `trust`'s sandwich)."""
    norm = np.linalg.norm(gw, axis=0)
    d = np.where(norm > 0, 1.0 / np.where(norm > 0, norm, 1.0), 0.0)
    gs = gw * d
    p = gs.shape[1]
    if p == 0:
        return np.zeros((0, 0)), np.zeros(0, bool)
    val, vec = np.linalg.eigh(gs.T @ gs)
    cut = val <= 1e-15 * max(float(val[-1]), 0.0)  # numpy's pinv(hermitian=True) rcond
    live = vec[:, ~cut]
    cov = d[:, None] * ((live / val[~cut]) @ live.T) * d[None, :]
    determined = np.sum(vec[:, cut] ** 2, axis=1) <= UNDETERMINED
    return cov, determined & (norm > 0)


def covariance(gw: np.ndarray) -> np.ndarray:
    """(GᵀG)⁻¹ of whitened columns `gw`, with the columns scaled to unit norm first: the
    catalogue's columns differ by ten orders of magnitude (q/a ~ 10⁻⁴ beside Ω), and an
    unscaled pseudo-inverse would cut the small ones' variance to zero. A column the data
    do not determine ([`gram_inverse`][hrgjax.discovery.stats.gram_inverse]: never excited,
    as k_e on static runs alone, or spanned by the others, as k_e beside the bias at one
    table rate) gets an infinite variance."""
    cov, determined = gram_inverse(gw)
    idx = np.arange(cov.shape[0])
    cov[idx, idx] = np.maximum(cov[idx, idx], 0.0)  # round-off below zero
    cov[~determined, ~determined] = np.inf  # undetermined: no finite σ
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


MIN_ROWS = 30
"""Fewest rows of a class whose noise level `class_levels` reads from its residual as it is."""
SMALL_DOF = 4.0
"""A class below `MIN_ROWS` with at most this many degrees of freedom pools its noise level
with the other classes' (`class_levels`)."""


def leverage(a):
    """Diagonal of the hat matrix of the columns `a` (N, p): how much of each row's noise the
    fit takes (their sum is the rank); invariant to the columns' units."""
    norm = np.linalg.norm(a, axis=0)
    live = norm > 0
    if not live.any():
        return np.zeros(a.shape[0])
    u, sv, _ = np.linalg.svd(a[:, live] / norm[live], full_matrices=False)
    rank = int(np.sum(sv > sv[0] * max(a.shape) * np.finfo(float).eps))
    return np.sum(u[:, :rank] ** 2, axis=1)


def class_levels(r, a, classes, weights=None, h=None, allowance=True):
    """Per-row noise scale s (N,) from each class's residual mean square
    ([`honest`][hrgjax.discovery.trust.honest]: a class of `MIN_ROWS` or more rows reads its
    level as it is, a smaller one with the t allowance ν/(ν−2) and never below 1, or pooled
    with the others at `SMALL_DOF` or fewer; `allowance=False`: every class with degrees of
    freedom reads its level as it is — for a test whose F tail already carries the level's
    uncertainty, where the allowance counted it twice: a 25-row class's p < 0.05 held in
    2.4 % of nulls):
    `r` the residual of the fit on the whitened columns `a` weighted by 1/`weights` (the
    previous scale; None: 1), each class's degrees of freedom n_g − Σ_g h_ii (the leverage
    its rows carry: static windows fix most of a dwell model's parameters, so an even share
    p·n_g/n read their scale ≈ 15 % low on a small grid; `h`: those leverages, when known)."""
    r, a = rows_of("class_levels", r, a=a)
    n = r.size
    classes = check_classes("class_levels", classes, n)
    form = f"one value per row, shape ({n},)"
    if weights is not None:
        weights = real_array("class_levels", "weights", weights, (n,), f"{form}, each > 0")
        if not np.all(weights > 0):
            raise ValueError(f"class_levels: weights must be {form}, each > 0 (the previous "
                             f"noise scale); got {weights[~(weights > 0)][0]}")  # fmt: skip
    h = None if h is None else real_array("class_levels", "h", h, (n,), form)
    allowance = check_flag("class_levels: allowance", allowance)
    s = np.ones(n)
    if classes is None:
        classes = np.zeros(n, int)
    w = np.ones(n) if weights is None else np.asarray(weights, float)
    h = leverage(a / w[:, None]) if h is None else h
    rss, dof, small = {}, {}, []
    for c in np.unique(classes):
        m = classes == c
        rss[c], dof[c] = float(r[m] @ r[m]), float(m.sum() - h[m].sum())
        if not (math.isfinite(rss[c]) and rss[c] > 0 and dof[c] > 0):
            continue
        if m.sum() >= MIN_ROWS or not allowance:
            s[m] = math.sqrt(rss[c] / dof[c])
        else:
            small.append(c)
    for c in small:  # too few rows to read a level alone: never below the noise model's
        m = classes == c
        if dof[c] > SMALL_DOF:  # its own rows, with the t allowance ν/(ν−2) of a level read from ν
            level = rss[c] / (dof[c] - 2.0)
        else:  # pooled with the other classes
            good = [k for k in rss if math.isfinite(rss[k]) and dof[k] > 0]
            level = sum(rss[k] for k in good) / sum(dof[k] for k in good)
        s[m] = math.sqrt(max(level, 1.0))
    return s


def effective_dof(h, g_t, classes):
    """Degrees of freedom behind the noise level a shape is judged at: each class's
    n_g − Σ_g h_ii (`h`: the leverages of the fit with the shape), pooled with the weight the shape's
    (model-orthogonal, whitened) columns `g_t` put on the class, Satterthwaite's
    ν = (Σ w_g)² / Σ w_g²/ν_g: a shape seen on the few static windows rests on their ν, one
    seen on thousands of continuous blocks on theirs."""
    h = real_array("effective_dof", "h", h, (None,), "the leverages, shape (N,)")
    g_t = real_array("effective_dof", "g_t", g_t, (h.size, None),
                     f"whitened columns, shape (N, k) with N = {h.size}")  # fmt: skip
    classes = check_classes("effective_dof", classes, h.size)
    if classes is None:
        return max(float(h.size - h.sum()), 1.0)
    w, nu = [], []
    for c in np.unique(classes):
        m = classes == c
        w.append(float(np.sum(g_t[m] ** 2)))
        nu.append(max(float(m.sum() - h[m].sum()), 1.0))
    w = np.asarray(w)
    if not w.sum() > 0:
        return 1.0
    return max(float(w.sum() ** 2 / np.sum(w**2 / np.asarray(nu))), 1.0)


def level_test(r: np.ndarray, j: np.ndarray, g: np.ndarray, classes=None):
    r"""The score test of the columns `g` against the whitened residual `r` of a fit with
    whitened Jacobian `j`, judged at the noise level the residual itself shows once `g` is
    fitted (each row class's own, [`class_levels`][hrgjax.discovery.stats.class_levels];
    `classes`: an integer per row, None for one class) with the F(q, ν) tail of a level read
    from ν degrees of freedom ([`effective_dof`][hrgjax.discovery.stats.effective_dof]).

    `score` alone takes the whitening as exact (χ²_q); where the noise model behind it is
    estimated, the two part ways: on 60-s dwells the angle random walk is often estimated at
    0 and the static windows' whitened residual has mean square 2–6, so a χ²_q p-value on
    pure noise fell below 10⁻³ in 15 % of null grids (audit 2026-11-30). Read at the
    residual's level, the test is exact for a noise model right up to one scale per class,
    and a level the candidate's own signal would raise is read with it fitted (no effect
    hides itself).

    **Returns:** `(S, A, step, p, s)`: the score at that level, the aliasing index, the
    one-step estimate (in `g`'s units), the upper-tail p-value (1 where `g` adds nothing)
    and the level s per row (the factor on the whitening)."""
    r, j, g = rows_of("level_test", r, j=j, g=g)
    classes = check_classes("level_test", classes, r.size)
    a = np.concatenate([j, g], axis=1)
    norm = np.linalg.norm(a, axis=0)
    a_n = a / np.where(norm > 0, norm, 1.0)  # columns ten orders of magnitude apart
    coef, *_ = np.linalg.lstsq(a_n, r, rcond=None)
    h = leverage(a)
    s = class_levels(r - a_n @ coef, a, classes, None, h, allowance=False)
    j_s, g_s = j / s[:, None], g / s[:, None]
    q_j, _ = np.linalg.qr(j_s)
    sc, alias, step = score(r / s, j_s, g_s, q_j)
    if alias >= 0.999 or not sc > 0:
        return float(max(sc, 0.0)), alias, step, 1.0, s
    q = int(g.shape[1])
    g_t = g_s - q_j @ (q_j.T @ g_s)
    nu = effective_dof(h, g_t, classes)
    return sc, alias, step, f_sf(sc / q, q, max(int(math.floor(nu)), 1)), s


def orthonormal_span(a: np.ndarray) -> np.ndarray:
    """Orthonormal basis (N, k) of the span of `a`'s (N, p) columns, each scaled to unit norm
    first (numerical rank by SVD at 10⁻⁹ of the largest; zero columns dropped; (N, 0) for
    none). Dimensionless."""
    a = real_array("orthonormal_span", "a", a, (None, None), "columns, shape (N, p)")
    if a.size == 0 or a.shape[1] == 0:
        return np.zeros((a.shape[0], 0))
    norm = np.linalg.norm(a, axis=0)
    a = a[:, norm > 0] / norm[norm > 0]
    if a.shape[1] == 0:
        return np.zeros((a.shape[0], 0))
    q, s, _ = np.linalg.svd(a, full_matrices=False)
    return q[:, s > 1e-9 * s[0]]


def level_beyond(r: np.ndarray, a: np.ndarray, s: np.ndarray) -> tuple[float, int]:
    """The noise level a whitened residual `r` shows along the columns `s` beyond the span
    of `a` (a Birge ratio in that subspace: 1 when the whitening is right there):
    `(‖P_[a s] r‖² − ‖P_a r‖²) / ν, ν)`, ν the rank `s` adds to `a` ((1.0, 0) when none)."""
    r, a, s = rows_of("level_beyond", r, a=a, s=s)
    qa, qs = orthonormal_span(a), orthonormal_span(np.concatenate([a, s], axis=1))
    nu = qs.shape[1] - qa.shape[1]
    if nu <= 0:
        return 1.0, 0
    return float((np.sum((qs.T @ r) ** 2) - np.sum((qa.T @ r) ** 2)) / nu), int(nu)


def log_parabola_peak(taus, values) -> float | None:
    """The peak τ of the parabola through three (log τ, value) points, clipped to their τ
    range; None where the parabola has no maximum (it opens upward or is flat)."""
    x = np.log(np.asarray(taus, float))
    a, b, _ = np.polyfit(x, np.asarray(values, float), 2)
    return float(np.exp(np.clip(-b / (2 * a), x[0], x[2]))) if a < 0 else None


def chi2_sf(x: float, dof: int) -> float:
    """Upper tail probability of χ²_dof at x."""
    _tail_args("chi2_sf", x=x, dof=dof)
    return float(_gammaincc(np.float64(dof / 2.0), np.float64(max(x, 0.0) / 2.0)))


def f_sf(f: float, d1: int, d2: int) -> float:
    """Upper tail probability of the F(d1, d2) distribution at `f` (1 where `f` is not
    > 0, NaN too)."""
    _tail_args("f_sf", f=f, d1=d1, d2=d2)
    if not f > 0:
        return 1.0
    return float(
        _betainc(np.float64(0.5 * d2), np.float64(0.5 * d1), np.float64(d2 / (d2 + d1 * f)))
    )


def f_sf_many(f, d1, d2) -> np.ndarray:
    """[`f_sf`][hrgjax.discovery.stats.f_sf] of many statistics at once: upper tail
    probabilities of F(`d1`, `d2`) at `f`, element by element (`f`, `d1`, `d2`: finite real
    numbers or 1-D arrays of one length; 1 where `f` is not > 0), in one compiled call — the search
    and the leftover shapes ask for a tail per candidate, and one call each cost ≈ 0.3 ms
    where eighteen together cost ≈ 0.15 ms (benchmarks/discovery_stats.py). Lengths are
    padded to a power of two, so a search compiles a few sizes, not one per count."""
    f, d1, d2 = (real_array("f_sf_many", k, v, None, "real numbers or a 1-D array")
                 for k, v in (("f", f), ("d1", d1), ("d2", d2)))  # fmt: skip
    try:
        f, d1, d2 = (np.atleast_1d(v).astype(float) for v in np.broadcast_arrays(f, d1, d2))
    except ValueError:
        raise ValueError(f"f_sf_many: f, d1 and d2 must be of one length; got shapes "
                         f"{np.shape(f)}, {np.shape(d1)}, {np.shape(d2)}") from None  # fmt: skip
    if f.ndim != 1:
        raise ValueError(f"f_sf_many: f, d1 and d2 must be numbers or 1-D; got shape {f.shape}")
    if not (np.all(d1 > 0) and np.all(d2 > 0)):
        raise ValueError("f_sf_many: d1 and d2 must be > 0 (degrees of freedom); got "
                         f"{np.r_[d1, d2][~(np.r_[d1, d2] > 0)][0]:g}")  # fmt: skip
    n = f.size
    if n == 0:
        return np.zeros(0)
    size = 1 << max(3, (n - 1).bit_length())
    live = f > 0
    x = np.ones(size)
    x[:n] = np.where(live, d2 / (d2 + d1 * np.where(live, f, 1.0)), 1.0)
    a, b = np.ones(size), np.ones(size)
    a[:n], b[:n] = 0.5 * d2, 0.5 * d1
    out = np.asarray(_betainc(a, b, x))[:n]
    return np.where(live, out, 1.0)


def _tail_args(owner: str, **args) -> None:
    """Refuse a tail's argument in one line naming `owner`: the statistic (`x`, `f`) not a
    single real number, a degrees of freedom
    (`dof` >= 0, `d1`, `d2` > 0) not a finite number in range."""
    for name, v in args.items():
        if name in ("x", "f"):  # (NaN passes: its tail is NaN, or 1 for F, not significant)
            ok = numeric_problem(v) is None and np.ndim(v) == 0
            form = "a single real number"
        else:
            ok = is_finite_real(v) and (v >= 0 if name == "dof" else v > 0)
            form = f"a finite number {'>= 0' if name == 'dof' else '> 0'} (degrees of freedom)"
        if not ok:
            kind = TypeError if numeric_problem(v) is not None else ValueError
            raise kind(f"{owner}: {name} must be {form}; got {describe(v)}")


def _covariate_args(owner: str, means, x, alpha):
    """`follows_covariate`'s arguments as float arrays, or one line naming `owner`."""
    means = real_array(owner, "means", means, (None,), "the run means, shape (n,)")
    x = real_array(owner, "x", x, (means.size, None),
                   f"covariates, shape (n, k) with n = {means.size}")  # fmt: skip
    if not (is_finite_real(alpha) and 0 <= alpha <= 1):
        kind = TypeError if numeric_problem(alpha) is not None else ValueError
        raise kind(f"{owner}: alpha must be a significance level in [0, 1]; got "
                   f"{describe(alpha)}")  # fmt: skip
    return means, x


def follows_covariate(means: np.ndarray, x: np.ndarray, alpha: float) -> tuple[np.ndarray, int]:
    """`means` less their mean and less the covariates (columns of `x`) that explain them
    significantly, chosen one at a time (F-test at `alpha`, Bonferroni over the covariates
    still tried); **returns** `(residual, columns fitted)` (the intercept counts)."""
    means, x = _covariate_args("follows_covariate", means, x, alpha)
    resid, chosen = followed_covariates(means, x, alpha)
    return resid, 1 + len(chosen)


def followed_covariates(means: np.ndarray, x: np.ndarray, alpha: float):
    """[`follows_covariate`][hrgjax.discovery.stats.follows_covariate] with the chosen
    columns: **returns** `(residual, indices of the columns of x chosen)`."""
    means, x = _covariate_args("followed_covariates", means, x, alpha)
    n = means.size
    cols = [np.ones(n)]
    cands = [i for i in range(x.shape[1]) if np.ptp(x[:, i]) > 0]
    chosen = []

    def rss(a):
        coef, *_ = np.linalg.lstsq(np.stack(a, axis=1), means, rcond=None)
        r = means - np.stack(a, axis=1) @ coef
        return float(r @ r), r

    base, resid = rss(cols)
    while cands and n - len(cols) - 1 > 1:
        trials = [(rss(cols + [x[:, c]]), k) for k, c in enumerate(cands)]
        (new, r), k = min(trials, key=lambda t: t[0][0])
        dof = n - len(cols) - 1
        f = (base - new) / max(new / dof, 1e-300)
        if f_sf(f, 1, dof) >= alpha / len(cands):  # the best of them
            break
        chosen.append(cands.pop(k))
        cols.append(x[:, chosen[-1]])
        base, resid = new, r
    return resid, chosen
