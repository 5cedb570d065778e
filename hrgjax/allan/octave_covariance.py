r"""Each noise term's Allan variance for sampled data and the exact Gaussian covariance of the
overlapping Allan variance at octave scales — the moments
[`identify_noise`][hrgjax.allan.identify_noise] fits.

The terms, for rate samples $y_k$ every $\tau_0$ (their Allan variances exact for sampled
data, not the continuous-time approximations). By default (`sampling="interval"`) a sample
is the mean of the continuous rate over its interval, y_k = (θ(kτ₀) − θ((k−1)τ₀))/τ₀ — what
a rate-integrating gyro's angle output differenced gives (an HRG's wave angle, any Δθ/Δt),
what `hrgjax.simulate` and [`Noise`][hrgjax.Noise] produce (the Gauss–Markov rate integrated
exactly over each interval) and what IEEE 952's continuous-time terms describe.
`sampling="point"` takes instead instantaneous samples of a discrete rate process (a
sampled-rate sensor without integration): it changes only the rate random walk and the
Gauss–Markov terms.

| term | coefficient | Allan variance at τ = mτ₀ |
|---|---|---|
| `quantization` | Q [unit·s] (white angle noise, σ per sample) | 3Q²/τ² |
| `angle_random_walk` | N [unit·√s] (white rate noise, N²/τ₀ per sample) | N²/τ |
| `rate_random_walk` | K [unit/√s] (a continuous random walk; point: rate steps of variance K²τ₀) | K²τ/3 (point: + K²τ₀/(6m)) |
| `rate_ramp` | R [unit/s] (a drift y = R·t) | R²τ²/2 |
| `gauss_markov` (up to two) | σ [unit], T [s] (a first-order rate of variance σ², ε = τ₀/T; point: y_{k+1} = φy_k + …, φ = e^{−ε}) | (4D(m) − D(2m))/(2m²) |

with D(t) the structure function of the angle X = Σy [rate unit × samples] at a lag of t
samples: for interval means D(t) = σ²(2/ε)[t − (1 − e^{−εt})/ε] (the continuous process's,
so the Allan variance is IEEE 952 Annex C's (2σ²T/τ)[1 − T/(2τ)(3 − 4e^{−τ/T} +
e^{−2τ/T})]); for point samples D(t) = σ²[t + 2φ(t(1 − φ) − (1 − φᵗ))/(1 − φ)²]. For T = 10τ₀
the point samples' Allan variance is 1.54× the interval means' at τ₀ and 1.14× at 2τ₀: a model
of the wrong kind biases T and σ and is rejected on long records.

Each octave's estimate σ̂²(m) = Σᵢ aᵢ²/(2m²M) is a quadratic
form of the second differences aᵢ of the angle; for Gaussian noise
Cov(σ̂²_a, σ̂²_b) = Σ_ℓ n_ab(ℓ)·[2c_ab(ℓ)² + 4μ_aμ_b c_ab(ℓ)]/(4m_a²m_b²M_aM_b), where c_ab(ℓ)
is the covariance of aᵢ and b_{i+ℓ} (a sum of nine values of each term's generalised
covariance), n_ab(ℓ) the number of pairs at lag ℓ and μ the drift's mean difference. It is
exact for the model (finite record, overlapping estimates, neighbouring octaves correlated);
the sum over ℓ runs piecewise (Gauss–Legendre on each smooth piece, the end corrections of
Euler–Maclaurin; its error ≈ 1e-5 of each entry, below 4e-5 for a Gauss–Markov T of three
samples), so it costs the same for 10³ or 10⁷ samples.

A term enters through its *generalised covariance* G of the angle X = Σy (rate units ×
samples): white rate −|t|/2, random-walk rate |t|³/12 (point: (|t|³ − |t|)/12), a first-order
Gauss–Markov rate −D(t)/2; c_ab(ℓ) is [`second_difference_cov`][hrgjax.allan.octave_covariance.second_difference_cov].
On a piece between kinks the nine arguments of G keep their signs, so c_ab is a cubic plus
two exponentials per Gauss–Markov term there, and is evaluated so: exact zeros beyond the
kinks (where the nine cubics, summed pointwise at t ≈ 10⁵, cancel only to round-off).
"""

from __future__ import annotations

import functools
import math

import jax.numpy as jnp
import numpy as np

from .._checks import is_concrete

_GL_X, _GL_W = np.polynomial.legendre.leggauss(16)
SLOW = 1e-6
"""ε³·min(ma, mb)²·max(ma, mb) below which a Gauss–Markov term's c is evaluated pointwise on
the pair's pieces: its closed form's exponential part is ≈ σ²/ε² while c itself is
≈ σ²·ε·ma²·mb, so the closed form keeps ≈ 1e-16/(ε³ma²mb) of c (here ≤ 1e-10; for ma ≈ mb
this is 2ε(ma + mb) ≲ 0.04, the old rule; a pair of very different octaves needs more)."""
SAMPLINGS = ("interval", "point")
"""What a rate sample is: `"interval"` the mean of the continuous rate over its interval
(the default: angle-derived rates), `"point"` an instantaneous sample of a discrete process."""
_CP = np.array([1.0, -2.0, 1.0])
_P, _Q = np.divmod(np.arange(9), 3)
_W = _CP[_P] * _CP[_Q]  # c_p·c_q of the nine values of G in a second-difference covariance


# -- each term's generalised covariance of the angle X = Σy (rate units × samples) ------------


def _g_white(t):
    return -0.5 * np.abs(t)


def _g_walk(t, sampling="interval"):
    """G of a rate random walk with unit steps per sample: |t|³/12 for interval means of a
    continuous walk, (|t|³ − |t|)/12 for point samples of a discrete one."""
    t = np.abs(t)
    return t**3 / 12.0 if sampling == "interval" else (t**3 - t) / 12.0


def _gm_structure(t, eps, sampling="interval"):
    """D(t)/σ² of a unit-variance first-order Gauss–Markov rate (ε = τ₀/T) summed over t
    samples [samples²]: interval means (2/ε)[t − (1 − e^{−εt})/ε] (a series where εt < 0.1),
    point samples (φ = e^{−ε}) t + 2φ(t(1 − φ) − (1 − φᵗ))/(1 − φ)² (a series where
    εt < 1e-4). `t` and `eps` broadcast (several terms' ε in one call)."""
    if sampling == "point":
        return _gm_structure_point(t, eps)
    t = np.abs(np.asarray(t, dtype=float))
    eps = np.asarray(eps, dtype=float)
    u = eps * t
    with np.errstate(divide="ignore", invalid="ignore"):
        out = 2.0 * (u + np.expm1(-u)) / (eps * eps)  # (2/ε²)(u − 1 + e^{−u})
    small = u < 0.1
    if small.any():  # t²·2Σ(−u)ᵏ/(k + 2)!, to u⁹ (its remainder < 1e-17 relative)
        us = np.broadcast_to(u, out.shape)[small]
        ts = np.broadcast_to(t, out.shape)[small]
        acc = np.zeros_like(us)
        for k in range(9, -1, -1):
            acc = acc * (-us) + 2.0 / math.factorial(k + 2)
        out = np.array(out, dtype=float, copy=True)
        out[small] = ts * ts * acc
    return out


def _gm_structure_point(t, eps):
    t = np.abs(np.asarray(t, dtype=float))
    eps = np.asarray(eps, dtype=float)
    u = eps * t
    one_m_phi = -np.expm1(-eps)
    bracket = t * one_m_phi + np.expm1(-u)  # t(1 − φ) − (1 − φᵗ)
    small = u < 1e-4
    if small.any():
        e, ts = (eps, t[small]) if eps.ndim == 0 else (np.broadcast_to(eps, u.shape)[small],
                                                       np.broadcast_to(t, u.shape)[small])  # fmt: skip
        t2 = ts * ts  # (powers by products: np.power is ten times slower)
        bracket[small] = ((e * e / 2) * (t2 - ts) - (e * e * e / 6) * (t2 * ts - ts)
                          + (e * e * e * e / 24) * (t2 * t2 - ts))  # fmt: skip
    return t + 2 * np.exp(-eps) * bracket / one_m_phi**2


def _g_gm(t, eps, sampling="interval"):
    return -0.5 * _gm_structure(t, eps, sampling)


def _check_sampling(sampling):
    """`sampling`, checked to be one of [`SAMPLINGS`][hrgjax.allan.octave_covariance.SAMPLINGS]."""
    if not isinstance(sampling, str) or sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {list(SAMPLINGS)}; got {sampling!r}")
    return sampling


def gm_white_level(sigma, correlation_time, dt, sampling: str):
    """A first-order Gauss–Markov rate's white-noise level at long τ [unit²·s]: N² with which
    its Allan variance → N²/τ, for σ [unit], T = `correlation_time` [s] sampled every `dt`
    [s] as `sampling` — 2σ²T for interval means (the continuous rate's PSD at 0, whatever
    Δt), σ²Δt·(1 + φ)/(1 − φ) = σ²Δt·coth(Δt/2T) for point samples (φ = e^{−Δt/T}: the AR(1)
    samples' autocovariances summed, σ²Δt for T ≪ Δt, 2σ²T for T ≫ Δt). Python numbers
    give a `float` (Python's for interval means, NumPy's float64 — a `float` subclass — for
    point samples), NumPy arrays an array; traced values (`jit`, `vmap`, `grad` over σ, T or
    Δt) a JAX array, either sampling. Also importable from `hrgjax.allan.composite`.

    **Raises:** `ValueError` for a `sampling` not in
    [`SAMPLINGS`][hrgjax.allan.octave_covariance.SAMPLINGS] ("points" is not read as "point")."""
    if _check_sampling(sampling) == "interval":
        return 2.0 * sigma * sigma * correlation_time
    x = dt / (2.0 * correlation_time)
    return sigma * sigma * dt / (np.tanh(x) if is_concrete(x) else jnp.tanh(x))


def second_difference_cov(gfun, ell, ma, mb):
    """Covariance of the angle's second differences at lags ma (at i) and mb (at i + ℓ):
    Σ c_p c_q G(ℓ + u_q − t_p), c = (1, −2, 1), t = (0, ma, 2ma), u = (0, mb, 2mb)."""
    ell, ma, mb = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (ell, ma, mb)))
    axes = (9,) + (1,) * ell.ndim
    shift = _Q.reshape(axes) * mb - _P.reshape(axes) * ma
    return np.tensordot(_W, gfun(ell + shift), axes=1)  # the nine values in one call


# -- the model's Allan variance and the estimator's covariance -----------------------------


def unit_avar(term, m, tau0, eps=None, sampling="interval"):
    """Allan variance at factors `m` of one term with unit coefficient² (Q² = 1 [unit·s]²,
    …; Gauss–Markov: σ² = 1 [unit²] with ε = τ₀/T = `eps`; a 1-D `eps` gives one row per
    value) [unit²], for rate samples taken as `sampling` (one of
    [`SAMPLINGS`][hrgjax.allan.octave_covariance.SAMPLINGS])."""
    sampling = _check_sampling(sampling)
    m = np.asarray(m, dtype=float)
    if term == "rate_ramp":
        return (m * tau0) ** 2 / 2.0
    if term == "quantization":
        return 3.0 / (m * tau0) ** 2
    # second_difference_cov at ℓ = 0 (G(0) = 0, G even): (2G(2m) − 8G(m))/(2m²)
    if term == "gauss_markov":  # G at m and 2m in one evaluation
        if eps is None:
            raise ValueError("unit_avar: a gauss_markov term needs eps = τ₀/T")
        eps = np.asarray(eps, dtype=float)
        if eps.ndim == 1:  # a row per value
            eps = eps.reshape((eps.size,) + (1,) * (m.ndim + 1))
        g = _g_gm(np.stack([m, 2 * m], axis=-1), eps, sampling)
        return (2 * g[..., 1] - 8 * g[..., 0]) / (2 * m**2)
    g = term_g(term, tau0, sampling=sampling)
    return (2 * g(2 * m) - 8 * g(m)) / (2 * m**2)


def term_g(term, tau0, eps=None, sampling="interval"):
    """The generalised covariance of X = Σy for one term with unit coefficient², rate
    samples taken as `sampling` (as in [`unit_avar`][hrgjax.allan.octave_covariance.unit_avar])."""
    sampling = _check_sampling(sampling)
    if term == "angle_random_walk":  # σ² = N²/τ₀ per sample
        return lambda t: _g_white(t) / tau0
    if term == "rate_random_walk":  # steps of variance K²τ₀
        return lambda t: _g_walk(t, sampling) * tau0
    if term == "gauss_markov":
        return lambda t: _g_gm(t, eps, sampling)
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


def _geometry(x, piece, lo, hi, ma, mb):
    """What [`_on_pieces`] needs of the pieces that no model changes: each argument's |t| at
    the end where φ^{|t|} is largest and the weights c_p c_q by its sign, the pieces' lengths,
    the nodes' offsets from either end, and at the nodes the two shapes a linear term's c
    takes — Σ c_p c_q |t| (white rate, and the linear part of a Gauss–Markov G) and
    Σ c_p c_q (|t|³ − |t|) (a random-walk rate), cubics in ℓ − lo from the signed moments
    Σ c_p c_q σ dʲ."""
    s = _Q[None, :] * mb[:, None] - _P[None, :] * ma[:, None]  # (pieces, 9)
    d, dh = lo[:, None] + s, hi[:, None] + s  # t at the piece's ends
    sig = np.where(d >= 0, 1.0, -1.0)
    sw, swd, swd2, swd3 = (np.stack([(_W * sig * d**j).sum(1) for j in range(4)], axis=1)).T
    plus = sig > 0
    xr = x - lo[piece]
    walk = np.stack([swd3 - swd, 3 * swd2 - sw, 3 * swd, sw], axis=1)[piece]
    # the exponentials' arguments take few distinct values (≈ 4·10³ of 1.7·10⁴ nodes, 5·10²
    # of 1.9·10⁴ piece ends on 10⁶ samples): each exp once, then spread by index
    dist_u, dist_i = np.unique(np.where(plus, d, -dh), return_inverse=True)
    xr_u, xr_i = np.unique(xr, return_inverse=True)
    rest_u, rest_i = np.unique((hi - lo)[piece] - xr, return_inverse=True)
    cube = (np.minimum(ma, mb) ** 2 * np.maximum(ma, mb))[piece]  # c ≈ σ²·ε·this (slow GM)
    nine = np.abs(x + s[piece].T)  # G's nine arguments at every node (9, nodes), few distinct
    args_u, args_i = np.unique(nine, return_inverse=True)
    return {"dist": (dist_u, dist_i.reshape(d.shape)),  # |t| at the end where φ^{|t|} is largest
            "w_plus": np.where(plus, _W, 0.0), "w_minus": np.where(plus, 0.0, _W),
            "xr": (xr_u, xr_i), "rest": (rest_u, rest_i),  # ℓ − lo and hi − ℓ at the nodes
            "cube": cube, "cube_min": float(cube.min(initial=np.inf)),
            "args": (args_u, args_i.reshape(nine.shape)),
            "abs_t": sw[piece] * xr + swd[piece],
            "cubic": ((walk[:, 3] * xr + walk[:, 2]) * xr + walk[:, 1]) * xr + walk[:, 0],
            "ma": ma, "mb": mb}  # fmt: skip


def _on_pieces(geo, x, piece, lin, gms, tau0, sampling):
    """Σ_terms coefficient²·[`second_difference_cov`][hrgjax.allan.octave_covariance.second_difference_cov]
    at the nodes `x` of pieces [lo, hi] between the kinks (pairs of factors ma, mb): on a
    piece every argument t = ℓ + q·mb − p·ma of G keeps its sign σ, so the white and
    random-walk parts are a cubic in ℓ − lo and a Gauss–Markov term's exponential part is
    P·φ^{ℓ−lo} + M·φ^{hi−ℓ} — nine values of G per node become one cubic and two exponentials
    per Gauss–Markov term (the cubics' two shapes are the layout's: a model only scales
    them). Where a Gauss–Markov term is near a random walk (ε³·min(ma, mb)²·max(ma, mb) <
    `SLOW`, its linear and exponential parts cancelling) it is evaluated pointwise."""
    f_abs = -0.5 * max(lin.get("angle_random_walk", 0.0), 0.0) / tau0
    c = f_abs * geo["abs_t"]
    if lin.get("rate_random_walk", 0.0) > 0:  # Σ c_p c_q |t|³ for interval means
        walk = geo["cubic"] + geo["abs_t"] if sampling == "interval" else geo["cubic"]
        c += (lin["rate_random_walk"] * tau0 / 12.0) * walk
    for s2, eps in gms:
        a, e = _gm_weights(s2, eps, sampling)
        ends = _exp(-eps, geo["dist"])
        pw = e * np.einsum("ij,ij->i", geo["w_plus"], ends)  # per piece
        mw = e * np.einsum("ij,ij->i", geo["w_minus"], ends)
        term = a * geo["abs_t"]
        term += pw[piece] * _exp(-eps, geo["xr"])  # P·φ^{ℓ−lo} + M·φ^{hi−ℓ}
        term += mw[piece] * _exp(-eps, geo["rest"])
        if geo["cube_min"] < SLOW / eps**3:
            slow = np.flatnonzero(geo["cube"] < SLOW / eps**3)  # linear and exponential parts
            args_u, args_i = geo["args"]  # cancel there: the pointwise value instead, G at
            if 9 * slow.size > args_u.size:  # every distinct argument once where that is fewer
                term[slow] = s2 * (_W @ _g_gm(args_u, eps, sampling)[args_i[:, slow]])
            else:
                ps = piece[slow]
                g = term_g("gauss_markov", tau0, eps, sampling)
                term[slow] = s2 * second_difference_cov(g, x[slow], geo["ma"][ps], geo["mb"][ps])
        c += term
    return c


def _exp(rate, where):
    """e^{rate·v} at the values v = u[i] of `where` = (u, i): once per distinct value."""
    u, i = where
    return np.exp(rate * u)[i]


def _gm_weights(s2, eps, sampling):
    """G of a Gauss–Markov term (σ² = s2, φ = e^{−ε}) as a·|t| + e·φ^{|t|} + const: (a, e) —
    interval means −(s2/ε)|t| − (s2/ε²)φ^{|t|} + s2/ε², point samples
    −½s2(1 + 2φ/(1 − φ))|t| − s2·φ/(1 − φ)²·φ^{|t|} + const."""
    if sampling == "interval":
        return -s2 / eps, -s2 / eps**2
    r, phi = -math.expm1(-eps), math.exp(-eps)
    return -0.5 * s2 * (1 + 2 * phi / r), -0.5 * s2 * 2 * phi / r**2


def _tail_sum(rate, x_end):
    """Σ_{x=0}^{X} (X + 1 − x)·e^{−rate·x} for X = `x_end` (arrays): the count-weighted sum
    of an exponential over a tail, closed form, its cancellation avoided by a series where
    rate·(X + 1) < 1e-4."""
    x_end = np.maximum(x_end, -1.0)  # no tail: an empty sum
    big = x_end + 1.0
    u, v = -np.expm1(-rate), -np.expm1(-rate * big)
    with np.errstate(divide="ignore", invalid="ignore"):
        closed = (big * u - (1 - u) * v) / u**2
    series = big * (big + 1) / 2 - rate * x_end * (x_end + 1) * (x_end + 2) / 6
    return np.where(rate * big < 1e-4, series, closed)


@functools.lru_cache(maxsize=8)
def _layout(ms: tuple, n: int) -> dict:
    """The pairs of octaves, the pieces of the kinks' region −2mb < ℓ < 2ma (cut where a
    generalised covariance turns, ℓ = p·ma − q·mb, and where the count bends or reaches 0) and their
    nodes and weights (× the count of pairs at each lag; nodes where it is 0 left out) — the
    same for every model of one record."""
    ms = np.asarray(ms, dtype=np.int64)
    ia, ib = np.triu_indices(ms.size)  # the pairs a ≤ b
    ma, mb = ms[ia], ms[ib]
    na, nb = n + 1 - 2 * ma, n + 1 - 2 * mb
    kinks = _P[None, :] * ma[:, None] - _Q[None, :] * mb[:, None]  # (pairs, 9)
    first, end = -2 * mb + 1, 2 * ma  # the region's first lag, one past its last
    cuts = np.stack([first, np.zeros_like(ma), nb - na, nb, 1 - na, *kinks.T, end], axis=1)
    cuts = np.clip(cuts, first[:, None], end[:, None])
    cuts.sort(axis=1)  # repeated cuts make empty pieces, which the sum skips
    los, his = cuts[:, :-1].ravel(), (cuts[:, 1:] - 1).ravel()
    owner = np.repeat(np.arange(ma.size), cuts.shape[1] - 1)
    x, w, piece = _sum_rules(los, his)
    ma, mb, na, nb = (v.astype(float) for v in (ma, mb, na, nb))

    def count(ell, k):  # pairs (i, i + ℓ) of second differences at lag ℓ
        return np.maximum(np.minimum(na[k], nb[k] - ell) - np.maximum(0.0, -ell), 0.0)

    wc = w * count(x, owner[piece])
    keep = wc != 0
    x, wc, piece = x[keep], wc[keep], piece[keep]
    # white angle noise: c is non-zero only at the nine lags ℓ = t_p − u_q of each pair
    key, where = np.unique(np.stack([np.repeat(np.arange(ma.size), 9), kinks.ravel()]),
                           axis=1, return_inverse=True)  # fmt: skip
    q_k, q_x = key[0], key[1].astype(float)
    q_t = q_x + _Q[:, None] * mb[q_k] - _P[:, None] * ma[q_k]  # G's nine arguments there
    q_tu, q_ti = np.unique(np.abs(q_t), return_inverse=True)  # few distinct (G is even)
    lay = {"ia": ia, "ib": ib, "x": x, "wc": wc, "piece": piece, "k": owner[piece],
           "ma": ma, "mb": mb, "na": na, "nb": nb, "q_k": q_k, "q_x": q_x,
           "q_args": (q_tu, q_ti.reshape(q_t.shape)), "q_count": count(q_x, q_k),
           "q_unit": np.bincount(where.ravel(), weights=np.tile(_W, ma.size)),
           "geo": _geometry(x, piece, los.astype(float), his.astype(float), ma[owner],
                            mb[owner])}  # fmt: skip
    for a in (*lay.values(), *lay["geo"].values()):
        for v in a if isinstance(a, tuple) else (a,):
            if isinstance(v, np.ndarray):
                v.flags.writeable = False  # cached: shared by every call for this record
    return lay


def covariance(
    coef: dict, gm: list, ms, n: int, tau0: float, sampling: str = "interval"
) -> np.ndarray:
    """Cov(σ̂²(m_a), σ̂²(m_b)) of the overlapping Allan variance at factors `ms` of `n` rate
    samples for the model `coef` ({term: coefficient²} of [`LINEAR`][hrgjax.allan.composite.LINEAR])
    plus Gauss–Markov terms `gm` [(σ², T [s])] (module docstring), the samples taken as
    `sampling` (as in [`unit_avar`][hrgjax.allan.octave_covariance.unit_avar]). [unit⁴]

    Between the kinks the sum over ℓ runs piecewise by quadrature; beyond them only the
    Gauss–Markov terms' exponentials are left (c = Σ_g K_g φ_g^x, x lags past the last kink,
    the count linear in x), and both tails are summed in closed form."""
    sampling = _check_sampling(sampling)
    return _covariance(_layout(tuple(int(m) for m in ms), int(n)), coef, gm, ms, tau0, sampling)


def _covariance(lay, coef, gm, ms, tau0, sampling):
    """[`covariance`][hrgjax.allan.octave_covariance.covariance] on the record's layout `lay`."""
    ma, mb, na, nb = lay["ma"], lay["mb"], lay["na"], lay["nb"]
    lin = {t: c for t, c in coef.items() if t in ("angle_random_walk", "rate_random_walk")}
    gms = [(s2, tau0 / tt) for s2, tt in gm if s2 > 0]
    q2 = coef.get("quantization", 0.0) / tau0**2  # white angle noise in X units
    mu2 = coef.get("rate_ramp", 0.0) * tau0**2 * ma**2 * mb**2  # μ_a·μ_b of the drift

    c = _on_pieces(lay["geo"], lay["x"], lay["piece"], lin, gms, tau0, sampling)
    terms = 2 * c * c
    if mu2.any():
        terms = terms + 4 * mu2[lay["k"]] * c
    total = np.bincount(lay["k"], weights=lay["wc"] * terms, minlength=ma.size)
    # the tails ℓ ≥ 2ma (count nb − ℓ) and ℓ ≤ −2mb (count na + ℓ): c = Σ_g K_g φ_g^x with
    # K_g = e_g·(1 − φ^{ma})²(1 − φ^{mb})² (the nine exponentials factor)
    if gms:
        eps = np.array([e for _, e in gms])[:, None]  # (G, 1)
        amp = np.stack([_gm_weights(s2, e, sampling)[1] * np.expm1(-e * ma) ** 2 * np.expm1(-e * mb) ** 2
                        for s2, e in gms])  # fmt: skip
        ends = np.stack([nb - 1 - 2 * ma, na - 1 - 2 * mb])  # both tails (2, pairs) at once
        if mu2.any():
            total += 4 * mu2 * (amp[:, None] * _tail_sum(eps[:, None], ends)).sum((0, 1))
        pairs = _tail_sum((eps[:, None] + eps[None, :])[..., None], ends)  # (G, G, 2, pairs)
        total += 2 * (amp[:, None, None] * amp[None, :, None] * pairs).sum((0, 1, 2))
    if q2 > 0:  # white angle noise: c is q2·Σ c_p c_q at the lags ℓ = t_p − u_q only
        k, (tu, ti) = lay["q_k"], lay["q_args"]
        cq = q2 * lay["q_unit"]
        g = np.zeros(tu.size)  # the other terms' G at the distinct |t|, then their c there
        for t, wt in lin.items():
            if wt > 0:
                g += wt * term_g(t, tau0, sampling=sampling)(tu)
        for s2, e in gms:
            g += s2 * _g_gm(tu, e, sampling)
        cs = _W @ g[ti]
        total += np.bincount(k, weights=lay["q_count"] * (2 * ((cs + cq) ** 2 - cs**2)
                                                          + 4 * mu2[k] * cq), minlength=ma.size)  # fmt: skip
    out = np.zeros((len(ms), len(ms)))
    out[lay["ia"], lay["ib"]] = total / (4.0 * ma**2 * mb**2 * na * nb)
    out[lay["ib"], lay["ia"]] = out[lay["ia"], lay["ib"]]
    return out


def gapped_covariance(
    coef: dict,
    gm: list,
    ms,
    segments,
    tau0: float,
    sampling: str = "interval",
    layouts: dict | None = None,
    progress=None,
) -> np.ndarray:
    """[`covariance`][hrgjax.allan.octave_covariance.covariance] for a rate record with gaps:
    `segments` the (start, length) of each gap-free run of rate samples, in order [samples]
    (`AllanResult.segments`); each estimate averages the second differences whose window of
    2m samples lies in one run (`hrgjax.allan.gaps`), M_a = Σᵣ max(Lᵣ + 1 − 2m_a, 0) of them. [unit⁴]

    Windows in different runs do not overlap, so a pair of them is correlated only through
    the Gauss–Markov terms' exponential tails: the sum over pairs is, per run, that of a
    gap-free record of its length (`covariance` × Nₐ⁽ʳ⁾N_b⁽ʳ⁾, once per distinct length),
    plus across runs r < s the tails' geometric sums Σ φ^x = Σ_{r<s} G(Nₐ⁽ʳ⁾)G(N_b⁽ˢ⁾)φ^{dᵣₛ}
    (G(N) = Σ_{k<N} φᵏ, dᵣₛ the samples between the runs; both orders of a and b), over
    MₐM_b. Exact for the model, as `covariance` is; the cost grows with the number of
    distinct run lengths (a `covariance` call each, on a layout built once per length and
    kept in `layouts`, a dict the caller passes to each call for one record: a fit's 6–7
    calls then build them once; None: a store for this call alone) and, with Gauss–Markov
    terms, of runs. The store holds at most `LAYOUT_STORE_BYTES` of layouts; the lengths
    past it are built again on each call (10⁶ samples with 0.1 % missing hold ~0.8 GB of
    them, 10⁷ with 0.1 % ~2.7 GB: docs/allan.md). `progress`: a bar (anything with
    `update(n)`) advanced by one per distinct run length done (`fit_noise` draws one over
    its calls)."""
    sampling = _check_sampling(sampling)
    segs = np.asarray(segments, dtype=np.int64).reshape(-1, 2)
    starts, lengths = segs[:, 0], segs[:, 1]
    ms = np.asarray(ms, dtype=np.int64)
    per_run = np.maximum(lengths[:, None] + 1 - 2 * ms[None, :], 0).astype(float)  # (R, S)
    total = np.zeros((ms.size, ms.size))
    layouts = {} if layouts is None else layouts
    held = sum(map(_nbytes, layouts.values()))
    for length, times in zip(*np.unique(lengths, return_counts=True), strict=True):
        k = np.flatnonzero(length + 1 - 2 * ms >= 1)
        if k.size:
            nk = (length + 1 - 2 * ms[k]).astype(float)
            key = (tuple(int(m) for m in ms[k]), int(length))
            lay = layouts.get(key)
            if lay is None:
                lay = _layout.__wrapped__(*key)
                size = _nbytes(lay)
                if held + size <= LAYOUT_STORE_BYTES:  # past the cap: built again next call
                    layouts[key], held = lay, held + size
            om = _covariance(lay, coef, gm, ms[k], tau0, sampling)
            total[np.ix_(k, k)] += times * om * np.outer(nk, nk)
        if progress is not None:
            progress.update(1)
    gms = [(s2, tau0 / tt) for s2, tt in gm if s2 > 0]
    if gms and lengths.size > 1:
        ia, ib = np.triu_indices(ms.size)
        ma, mb = ms[ia].astype(float), ms[ib].astype(float)
        eps = np.array([e for _, e in gms])
        amp = np.stack(
            [
                _gm_weights(s2, e, sampling)[1] * np.expm1(-e * ma) ** 2 * np.expm1(-e * mb) ** 2
                for s2, e in gms
            ]
        )  # (G, pairs) fmt: skip
        mu2 = coef.get("rate_ramp", 0.0) * tau0**2 * ma**2 * mb**2
        # rates ρ of the sums: φ_gφ_h for c², φ_g for the drift's 4μμc
        rates = np.concatenate([(eps[:, None] + eps[None, :]).ravel(), eps])  # (C,)
        weight = np.concatenate(
            [2 * (amp[:, None] * amp[None, :]).reshape(-1, ia.size), 4 * mu2 * amp]
        )  # (C, pairs) fmt: skip
        cross = _cross_runs(rates, per_run[:, ia], per_run[:, ib], starts, lengths)
        total[ia, ib] += np.sum(weight * cross, axis=0) / (4.0 * ma**2 * mb**2)
        total[ib, ia] = total[ia, ib]
    count = per_run.sum(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return total / np.outer(count, count)


LAYOUT_STORE_BYTES = 256 * 2**20
"""The most bytes of run layouts `gapped_covariance` keeps in a fit's store (256 MiB): a
layout is 0.1–3 MB (its τ count and length), a record of 10⁶ samples with 0.1 % missing at
random has ~800 distinct run lengths, 10⁷ samples ~2 400."""


def _nbytes(lay) -> int:
    """The bytes of a layout's arrays (nested dicts and tuples included)."""
    if isinstance(lay, np.ndarray):
        return lay.nbytes
    if isinstance(lay, dict):
        lay = lay.values()
    return sum(map(_nbytes, lay)) if isinstance(lay, (tuple, list, type({}.values()))) else 0


def _cross_runs(rates, na, nb, starts, lengths):
    """Σ over pairs of differences in different runs of e^{−rate·x}, x the tail's lag (the
    samples between the two windows): Σ_{r<s} [G(naᵣ)G(nb_s) + G(nbᵣ)G(na_s)]·e^{−rate·dᵣₛ},
    G(N) = Σ_{k<N} e^{−rate·k}, dᵣₛ = start_s − (startᵣ + Lᵣ); `na`, `nb` (runs, pairs) the
    differences each run holds at the pair's two factors. Returns (rates, pairs), by one pass
    over the runs."""
    r = np.asarray(rates, dtype=float)[:, None]
    den = -np.expm1(-r)

    def geo(n):  # Σ_{k<n} e^{−r k}
        return -np.expm1(-r * n) / den

    ca = np.zeros((r.size, na.shape[1]))  # Σ_{earlier runs} G(n)·e^{−r·(distance to here)}
    cb = np.zeros_like(ca)
    out = np.zeros_like(ca)
    for i in range(starts.size):
        if i:
            step = np.exp(-r * float(starts[i] - starts[i - 1]))
            ca *= step
            cb *= step
            back = np.exp(-r * float(starts[i] - starts[i - 1] - lengths[i - 1]))
            ca += geo(na[i - 1]) * back
            cb += geo(nb[i - 1]) * back
            out += ca * geo(nb[i]) + cb * geo(na[i])
    return out
