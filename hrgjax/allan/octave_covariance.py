r"""Each noise term's Allan variance for sampled data and the exact Gaussian covariance of the
overlapping Allan variance at octave scales — the moments
[`identify_noise`][hrgjax.allan.identify_noise] fits.

The terms, for rate samples $y_k$ every $\tau_0$ (their Allan variances exact for sampled
data, not the continuous-time approximations):

| term | coefficient | Allan variance at τ = mτ₀ |
|---|---|---|
| `quantization` | Q [unit·s] (white angle noise, σ per sample) | 3Q²/τ² |
| `angle_random_walk` | N [unit·√s] (white rate noise, N²/τ₀ per sample) | N²/τ |
| `rate_random_walk` | K [unit/√s] (rate steps of variance K²τ₀) | K²τ/3 + K²τ₀/(6m) |
| `rate_ramp` | R [unit/s] (a drift y = R·t) | R²τ²/2 |
| `gauss_markov` (up to two) | σ [unit], T [s] (first order: y_{k+1} = φy_k + …, φ = e^{−τ₀/T}) | (4D(m) − D(2m))/(2τ²) |

with D(t) = σ²[t + 2φ(t(1 − φ) − (1 − φᵗ))/(1 − φ)²]τ₀² the structure function of the angle.

Each octave's estimate σ̂²(m) = Σᵢ aᵢ²/(2m²M) is a quadratic
form of the second differences aᵢ of the angle; for Gaussian noise
Cov(σ̂²_a, σ̂²_b) = Σ_ℓ n_ab(ℓ)·[2c_ab(ℓ)² + 4μ_aμ_b c_ab(ℓ)]/(4m_a²m_b²M_aM_b), where c_ab(ℓ)
is the covariance of aᵢ and b_{i+ℓ} (a sum of nine values of each term's generalised
covariance), n_ab(ℓ) the number of pairs at lag ℓ and μ the drift's mean difference. It is
exact for the model (finite record, overlapping estimates, neighbouring octaves correlated);
the sum over ℓ runs piecewise (Gauss–Legendre on each smooth piece, the end corrections of
Euler–Maclaurin), so it costs the same for 10³ or 10⁷ samples.

A term enters through its *generalised covariance* G of the angle X = Σy (rate units ×
samples): white rate −|t|/2, random-walk rate (|t|³ − |t|)/12, a first-order Gauss–Markov rate
−D(t)/2; c_ab(ℓ) is [`second_difference_cov`][hrgjax.allan.octave_covariance.second_difference_cov].
"""

from __future__ import annotations

import itertools
import math

import numpy as np

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)


# -- each term's generalised covariance of the angle X = Σy (rate units × samples) ------------


def _g_white(t):
    return -0.5 * np.abs(t)


def _g_walk(t):
    t = np.abs(t)
    return (t**3 - t) / 12.0


def _gm_structure(t, eps):
    """D(t)/σ² of a unit-variance AR(1) rate with φ = e^{−ε}, summed over t samples:
    t + 2φ(t(1 − φ) − (1 − φᵗ))/(1 − φ)², with the bracket's cancellation avoided (a
    series where εt < 1e-4)."""
    t = np.abs(np.asarray(t, dtype=float))
    u = eps * t
    one_m_phi = -math.expm1(-eps)
    bracket = t * one_m_phi + np.expm1(-u)  # t(1 − φ) − (1 − φᵗ)
    small = u < 1e-4
    ts = t[small]
    bracket[small] = ((eps**2 / 2) * (ts * ts - ts) - (eps**3 / 6) * (ts**3 - ts)
                      + (eps**4 / 24) * (ts**4 - ts))  # fmt: skip
    return t + 2 * math.exp(-eps) * bracket / one_m_phi**2


def _g_gm(t, eps):
    return -0.5 * _gm_structure(t, eps)


def second_difference_cov(gfun, ell, ma, mb):
    """Covariance of the angle's second differences at lags ma (at i) and mb (at i + ℓ):
    Σ c_p c_q G(ℓ + u_q − t_p), c = (1, −2, 1), t = (0, ma, 2ma), u = (0, mb, 2mb)."""
    cp = (1.0, -2.0, 1.0)
    out = 0.0
    for p in range(3):
        for q in range(3):
            out = out + cp[p] * cp[q] * gfun(ell + q * mb - p * ma)
    return out


# -- the model's Allan variance and the estimator's covariance -----------------------------


def unit_avar(term, m, tau0, eps=None):
    """Allan variance at factors `m` of one term with unit coefficient² (Q² = 1 [unit·s]²,
    …; Gauss–Markov: σ² = 1 [unit²] with φ = e^{−eps})."""
    m = np.asarray(m, dtype=float)
    if term == "rate_ramp":
        return (m * tau0) ** 2 / 2.0
    if term == "quantization":
        return 3.0 / (m * tau0) ** 2
    return second_difference_cov(term_g(term, tau0, eps), 0.0, m, m) / (2 * m**2)


def term_g(term, tau0, eps=None):
    """The generalised covariance of X = Σy for one term with unit coefficient²."""
    if term == "angle_random_walk":  # σ² = N²/τ₀ per sample
        return lambda t: _g_white(t) / tau0
    if term == "rate_random_walk":  # steps of variance K²τ₀
        return lambda t: _g_walk(t) * tau0
    if term == "gauss_markov":
        return lambda t: _g_gm(t, eps)
    raise ValueError(term)


def _sum_rules(lo, hi):
    """Points, weights and piece index with Σ_{ℓ=lo}^{hi} f(ℓ) ≈ Σ wᵢ f(xᵢ) for each piece
    [lo, hi] (integer arrays) on which f is smooth: every point below 48 of them, else
    Gauss–Legendre on [lo, hi] plus the trapezoid's end terms and the first Euler–Maclaurin
    correction (f′ by differences)."""
    lo, hi = np.asarray(lo, dtype=np.int64), np.asarray(hi, dtype=np.int64)
    keep = hi >= lo
    lo, hi, piece = lo[keep], hi[keep], np.flatnonzero(keep)
    short = hi - lo < 48
    length = (hi - lo + 1)[short]
    start = np.repeat(lo[short], length)
    offset = np.arange(length.sum()) - np.repeat(np.cumsum(length) - length, length)
    xs, ws, ps = [start + offset], [np.ones(offset.size)], [np.repeat(piece[short], length)]
    lo_l, hi_l, p_l = lo[~short].astype(float), hi[~short].astype(float), piece[~short]
    half = 0.5 * (hi_l - lo_l)[:, None]
    xs.append((lo_l[:, None] + half * (_GL_X + 1.0)).ravel())
    ws.append((half * _GL_W).ravel())
    ps.append(np.repeat(p_l, _GL_X.size))
    ends = np.stack([lo_l, lo_l + 1, hi_l - 1, hi_l], axis=1)
    xs.append(ends.ravel())
    ws.append(np.tile([0.5 + 1 / 12, -1 / 12, -1 / 12, 0.5 + 1 / 12], p_l.size))
    ps.append(np.repeat(p_l, 4))
    return np.concatenate(xs).astype(float), np.concatenate(ws), np.concatenate(ps)


def covariance(coef: dict, gm: list, ms, n: int, tau0: float) -> np.ndarray:
    """Cov(σ̂²(m_a), σ̂²(m_b)) of the overlapping Allan variance at factors `ms` of `n` rate
    samples for the model `coef` ({term: coefficient²} of [`LINEAR`][hrgjax.allan.composite.LINEAR])
    plus Gauss–Markov terms `gm` [(σ², T [s])] (module docstring). [unit⁴]"""
    ms = [int(m) for m in ms]
    terms = [(term_g(t, tau0), c) for t, c in coef.items()
             if t in ("angle_random_walk", "rate_random_walk") and c > 0]  # fmt: skip
    terms += [(term_g("gauss_markov", tau0, tau0 / tt), s2) for s2, tt in gm if s2 > 0]
    q2 = coef.get("quantization", 0.0) / tau0**2  # white angle noise in X units
    drift = coef.get("rate_ramp", 0.0)
    tails = [tt / tau0 for s2, tt in gm if s2 > 0]
    count_m = [n + 1 - 2 * m for m in ms]
    pairs = list(itertools.combinations_with_replacement(range(len(ms)), 2))
    los, his, owner, qx, qc, qidx = [], [], [], [], [], []
    for k, (a, b) in enumerate(pairs):
        ma, mb, na, nb = ms[a], ms[b], count_m[a], count_m[b]
        # breakpoints: where a generalised covariance turns (ℓ = t_p − u_q) and the count
        # bends; Gauss–Markov tails cut where they have died (φ^{2ℓ} < 1e-16)
        lo_all, hi_all = -(na - 1), nb - 1
        cuts = {lo_all, hi_all + 1, 0, nb - na}
        cuts.update(p * ma - q * mb for p in range(3) for q in range(3))
        edge = 2 * max(ma, mb)
        for tt in tails:
            for j in (1, 2, 4, 8, 18):
                cuts.update((edge + int(j * tt), -edge - int(j * tt)))
        if tails:
            reach = edge + int(18 * max(tails)) + 1
            lo_all, hi_all = max(lo_all, -reach), min(hi_all, reach)
        pts = sorted(c for c in cuts if lo_all < c <= hi_all + 1)
        pts = [lo_all, *pts] if pts[-1] == hi_all + 1 else [lo_all, *pts, hi_all + 1]
        los += pts[:-1]
        his += [c - 1 for c in pts[1:]]
        owner += [k] * (len(pts) - 1)
        if q2 > 0:  # white angle noise: c is q2·Σ c_p c_q at ℓ = t_p − u_q only
            lags = {}
            for p, q in itertools.product(range(3), range(3)):
                ell = p * ma - q * mb
                lags[ell] = lags.get(ell, 0.0) + (1, -2, 1)[p] * (1, -2, 1)[q] * q2
            qx += list(lags)
            qc += list(lags.values())
            qidx += [k] * len(lags)
    ma_of = np.asarray([ms[a] for a, _ in pairs], dtype=float)
    mb_of = np.asarray([ms[b] for _, b in pairs], dtype=float)
    na_of = np.asarray([count_m[a] for a, _ in pairs], dtype=float)
    nb_of = np.asarray([count_m[b] for _, b in pairs], dtype=float)
    mu2 = drift * tau0**2 * ma_of**2 * mb_of**2  # μ_a·μ_b of the drift

    def c_smooth(ell, k):
        if not terms:
            return np.zeros_like(ell)
        return sum(w * second_difference_cov(g, ell, ma_of[k], mb_of[k]) for g, w in terms)

    def count(ell, k):
        return np.maximum(np.minimum(na_of[k], nb_of[k] - ell) - np.maximum(0.0, -ell), 0.0)

    x, w, piece = _sum_rules(los, his)
    k = np.asarray(owner)[piece]
    c = c_smooth(x, k)
    total = np.bincount(k, weights=w * count(x, k) * (2 * c * c + 4 * mu2[k] * c),
                        minlength=len(pairs))  # fmt: skip
    if qx:
        x, cq, k = np.asarray(qx, dtype=float), np.asarray(qc), np.asarray(qidx)
        cs = c_smooth(x, k)
        total += np.bincount(k, weights=count(x, k) * (2 * ((cs + cq) ** 2 - cs**2)
                                                       + 4 * mu2[k] * cq), minlength=len(pairs))  # fmt: skip
    out = np.zeros((len(ms), len(ms)))
    for k, (a, b) in enumerate(pairs):
        out[a, b] = out[b, a] = total[k] / (4.0 * ms[a] ** 2 * ms[b] ** 2 * na_of[k] * nb_of[k])
    return out
