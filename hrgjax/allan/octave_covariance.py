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
On a piece between kinks the nine arguments of G keep their signs, so c_ab is a cubic plus
two exponentials per Gauss–Markov term there, and is evaluated so: exact zeros beyond the
kinks (where the nine cubics, summed pointwise at t ≈ 10⁵, cancel only to round-off).
"""

from __future__ import annotations

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
    g = term_g(term, tau0, eps)  # second_difference_cov at ℓ = 0 (G(0) = 0, G even)
    return (2 * g(2 * m) - 8 * g(m)) / (2 * m**2)


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


_CP = np.array([1.0, -2.0, 1.0])
_P, _Q = np.divmod(np.arange(9), 3)
_W = _CP[_P] * _CP[_Q]  # c_p·c_q of the nine values of G in a second-difference covariance


def _on_pieces(x, piece, lo, hi, ma, mb, lin, gms, tau0):
    """Σ_terms coefficient²·[`second_difference_cov`][hrgjax.allan.octave_covariance.second_difference_cov]
    at the nodes `x` of pieces [lo, hi] (pairs of factors ma, mb): on a piece every argument
    t = ℓ + q·mb − p·ma of G keeps its sign σ, so the white and random-walk parts are a cubic
    in ℓ − lo and a Gauss–Markov term's exponential part is P·φ^{ℓ−lo} + M·φ^{hi−ℓ} — nine
    values of G per node become one cubic and two exponentials per Gauss–Markov term. Where
    every σ agrees (beyond the kinks) the polynomial part vanishes exactly and P, M are
    products of expm1's; where a Gauss–Markov term is near a random walk (ε·(ma + mb) < 0.05,
    its linear and exponential parts cancelling), it is evaluated pointwise."""
    s = _Q[None, :] * mb[:, None] - _P[None, :] * ma[:, None]  # (pieces, 9)
    d, dh = lo[:, None] + s, hi[:, None] + s  # t at the piece's ends
    sig = np.where(d >= 0, 1.0, -1.0)
    inside = np.any(sig != sig[:, :1], axis=1)  # the kinks' region: mixed signs
    sw = np.where(inside, (_W * sig).sum(1), 0.0)
    swd = np.where(inside, (_W * sig * d).sum(1), 0.0)
    coef = np.zeros((lo.size, 4))  # cubic in x = ℓ − lo
    if lin.get("angle_random_walk", 0.0) > 0:
        f = -0.5 * lin["angle_random_walk"] / tau0
        coef[:, 1] += f * sw
        coef[:, 0] += f * swd
    if lin.get("rate_random_walk", 0.0) > 0:
        f = lin["rate_random_walk"] * tau0 / 12.0
        swd2 = np.where(inside, (_W * sig * d * d).sum(1), 0.0)
        swd3 = np.where(inside, (_W * sig * d**3).sum(1), 0.0)
        coef += f * np.stack([swd3 - swd, 3 * swd2 - sw, 3 * swd, sw], axis=1)
    xr = x - lo[piece]
    cp = coef[piece]
    c = ((cp[:, 3] * xr + cp[:, 2]) * xr + cp[:, 1]) * xr + cp[:, 0]
    for s2, eps in gms:
        r, phi = -math.expm1(-eps), math.exp(-eps)
        near_walk = inside & (eps * 2 * (ma + mb) < 0.05)
        a = -0.5 * s2 * (1 + 2 * phi / r)  # the linear part of −D/2 (its constant cancels)
        e = -0.5 * s2 * 2 * phi / r**2  # the exponential part's weight
        plus = sig > 0
        pw = np.where(plus, _W * np.exp(-eps * np.where(plus, d, 0.0)), 0.0).sum(1)
        mw = np.where(plus, 0.0, _W * np.exp(eps * np.where(plus, 0.0, dh))).sum(1)
        # beyond the kinks the nine exponentials factor: (1 − φ^{mb})²(1 − φ^{−ma})²·φ^{lo}
        both = (-np.expm1(-eps * ma)) ** 2 * (-np.expm1(-eps * mb)) ** 2
        right, left = ~inside & plus[:, 0], ~inside & ~plus[:, 0]
        pw[right] = np.exp(-eps * (lo - 2 * ma)[right]) * both[right]
        mw[left] = np.exp(eps * (hi + 2 * mb)[left]) * both[left]
        length = (hi - lo)[piece]
        part = a * (sw[piece] * xr + swd[piece])
        part += e * (pw[piece] * np.exp(-eps * xr) + mw[piece] * np.exp(-eps * (length - xr)))
        slow = near_walk[piece]
        if slow.any():
            g = term_g("gauss_markov", tau0, eps)
            part[slow] = s2 * second_difference_cov(g, x[slow], ma[piece][slow], mb[piece][slow])
        c = c + part
    return c


def covariance(coef: dict, gm: list, ms, n: int, tau0: float) -> np.ndarray:
    """Cov(σ̂²(m_a), σ̂²(m_b)) of the overlapping Allan variance at factors `ms` of `n` rate
    samples for the model `coef` ({term: coefficient²} of [`LINEAR`][hrgjax.allan.composite.LINEAR])
    plus Gauss–Markov terms `gm` [(σ², T [s])] (module docstring). [unit⁴]"""
    ms = np.asarray([int(m) for m in ms], dtype=np.int64)
    terms = [(term_g(t, tau0), c) for t, c in coef.items()
             if t in ("angle_random_walk", "rate_random_walk") and c > 0]  # fmt: skip
    terms += [(term_g("gauss_markov", tau0, tau0 / tt), s2) for s2, tt in gm if s2 > 0]
    q2 = coef.get("quantization", 0.0) / tau0**2  # white angle noise in X units
    drift = coef.get("rate_ramp", 0.0)
    tails = [tt / tau0 for s2, tt in gm if s2 > 0]
    ia, ib = np.triu_indices(ms.size)  # the pairs a ≤ b
    ma, mb = ms[ia], ms[ib]
    na, nb = n + 1 - 2 * ma, n + 1 - 2 * mb
    # breakpoints: where a generalised covariance turns (ℓ = t_p − u_q) and the count bends;
    # Gauss–Markov tails cut where they have died (φ^{2ℓ} < 1e-16)
    lo_all, hi_all = -(na - 1), nb - 1
    kinks = _P[None, :] * ma[:, None] - _Q[None, :] * mb[:, None]  # (pairs, 9)
    cuts = [np.zeros_like(ma), nb - na, *kinks.T]
    edge = 2 * np.maximum(ma, mb)
    for tt in tails:
        for j in (1, 2, 4, 8, 18):
            cuts += [edge + int(j * tt), -edge - int(j * tt)]
    if tails:
        reach = edge + int(18 * max(tails)) + 1
        lo_all, hi_all = np.maximum(lo_all, -reach), np.minimum(hi_all, reach)
    cuts = np.clip(np.stack([lo_all, *cuts, hi_all + 1], axis=1), lo_all[:, None],
                   (hi_all + 1)[:, None])  # fmt: skip
    cuts.sort(axis=1)  # repeated cuts make empty pieces, which the sum skips
    los, his = cuts[:, :-1].ravel(), (cuts[:, 1:] - 1).ravel()
    owner = np.repeat(np.arange(ma.size), cuts.shape[1] - 1)
    ma_of, mb_of, na_of, nb_of = (v.astype(float) for v in (ma, mb, na, nb))
    mu2 = drift * tau0**2 * ma_of**2 * mb_of**2  # μ_a·μ_b of the drift

    def count(ell, k):
        return np.maximum(np.minimum(na_of[k], nb_of[k] - ell) - np.maximum(0.0, -ell), 0.0)

    x, w, piece = _sum_rules(los, his)
    k = owner[piece]
    lin = {t: c for t, c in coef.items() if t in ("angle_random_walk", "rate_random_walk")}
    gms = [(s2, tau0 / tt) for s2, tt in gm if s2 > 0]
    c = _on_pieces(x, piece, los.astype(float), his.astype(float), ma_of[owner], mb_of[owner],
                   lin, gms, tau0)  # fmt: skip
    total = np.bincount(k, weights=w * count(x, k) * (2 * c * c + 4 * mu2[k] * c),
                        minlength=ma.size)  # fmt: skip
    if q2 > 0:  # white angle noise: c is q2·Σ c_p c_q at the lags ℓ = t_p − u_q only
        key, where = np.unique(np.stack([np.repeat(np.arange(ma.size), 9), kinks.ravel()]),
                               axis=1, return_inverse=True)  # fmt: skip
        cq = np.bincount(where.ravel(), weights=np.tile(_W * q2, ma.size))
        k, x = key[0], key[1].astype(float)
        cs = (sum(w * second_difference_cov(g, x, ma_of[k], mb_of[k]) for g, w in terms)
              if terms else np.zeros_like(x))  # fmt: skip
        total += np.bincount(k, weights=count(x, k) * (2 * ((cs + cq) ** 2 - cs**2)
                                                       + 4 * mu2[k] * cq), minlength=ma.size)  # fmt: skip
    out = np.zeros((ms.size, ms.size))
    out[ia, ib] = total / (4.0 * ma_of**2 * mb_of**2 * na_of * nb_of)
    out[ib, ia] = out[ia, ib]
    return out
