r"""In-run bias drift in a Ferraris session's statistics: the covariance a random walk of
each channel's bias adds to the section sums, and its intensity estimated from the
session's own redundancy.

**Model.** Each of the six channels (gyro x, y, z; accelerometer x, y, z) reads its signal
plus white noise plus a bias that wanders as a random walk $\beta(t)$ from zero at the
session's start $t_0$ (the first row of its earliest section): $\mathrm{Cov}(\beta(s),
\beta(t)) = q^2 \min(s - t_0, t - t_0)$, q [unit/√s] one intensity for the gyros and one
for the accelerometers. A section statistic is a weighted sum of one channel's samples,
$S = \sum_k w_k x_k$ (a face mean: $w_k = 1/n$; a turn's sum: $w_k = \Delta t_k$), so that

$$\mathrm{Cov}(S_i, S_j) \mathrel{+}= q^2 \sum_k\sum_l w_{ik} w_{jl} \min(t_k - t_0, t_l - t_0)
  = q^2 \int_0^\infty W_i(u)\,W_j(u)\,du,$$

$W_i(u) = \sum_{t_k - t_0 > u} w_{ik}$ the weight of the samples after u (piecewise
constant between samples: the integral is an exact finite sum).

**Estimate of q².** Twelve combinations of the face means vanish for any calibration: for
each channel, the three ± pair sums ($u^+_i + u^-_i = 2 b_a$, $w^+_i + w^-_i = 2 b_g$ for
i = x, y, z) are equal — two contrasts per channel, six per sensor. Their covariance is
$A + q^2 B$ (A from the white noise, B from the kernel above); their restricted likelihood
(the contrasts are free of the parameters) gives q². Six contrasts pin q² down poorly:
its maximum-likelihood value (what the σ used before) is exactly 0 in about 6 % of sessions
that do drift, and the σ built on it then miss the gyro biases by up to 11σ (audit of
2026-11-30). The σ therefore use q's posterior mean (`walk_posterior_mean`, Jeffreys
prior), which holds what the contrasts allow of q and is never 0 on noisy data.

**The gyros on a bench that turns with the Earth.** A face's gyro mean holds the Earth's
horizontal rate at that face's heading, which the procedure leaves free: the pair sums
hold (h⁺ + h⁻)/2 of it, up to Ω cos φ, which q read as drift (the audit of 2026-12-01:
`bias_walk` 1.2e-5 rad/s/√s, ~150× its truth, on a tactical IMU that did not drift, and
σ(b_g) 10 °/h). The gyros' q therefore also uses the eighteen within-face contrasts
(`half_difference`: each face's first-half mean minus its second-half mean, per
channel), which the Earth's rate cannot reach, and the pair contrasts carry the Earth's
horizontal rate in their covariance (`hrgjax.imu._earth`): where it dwarfs the noise
they no longer inform q, and q comes from within the faces."""

from __future__ import annotations

import numpy as np


def walk_kernel(time: np.ndarray, items: list[list[tuple[int, int, np.ndarray, float]]],
                origin: int = 0) -> np.ndarray:  # fmt: skip
    """$\\sum_k\\sum_l w_{ik} w_{jl}\\min(t_k - t_0, t_l - t_0)$ for every pair of
    statistics of one channel, $t_0$ the time of row `origin` (no piece starts before it).

    **Arguments:** `time` (N,) [s]; `items`: per statistic, its pieces `(start, end, w,
    factor)` — rows [start, end) with weights `w` (end − start,) times `factor` (a key's
    repeats are pieces of one statistic).

    **Returns:** the (m, m) kernel [weight² · s]."""
    tau = np.asarray(time, float) - float(time[origin])
    m = len(items)
    out = np.zeros((m, m))
    for i in range(m):
        for j in range(i, m):
            out[i, j] = out[j, i] = sum(
                fi * fj * _pair(tau, si, ei, wi, sj, ej, wj)
                for si, ei, wi, fi in items[i]
                for sj, ej, wj, fj in items[j]
            )
    return out


def _pair(tau, s1, e1, w1, s2, e2, w2) -> float:
    """∫ W₁ W₂ du for two weighted row ranges: W(u) on (τ_{m-1}, τ_m] is the weight of rows
    ≥ m; both are constant (their totals) up to the earlier start and W₁W₂ = 0 from the
    earlier end on."""
    if e1 <= s2 or e2 <= s1:  # one range before the other: min(τ_k, τ_l) is the earlier's τ
        (sa, ea, wa), wb = ((s1, e1, w1), w2) if e1 <= s2 else ((s2, e2, w2), w1)
        return float(wa @ tau[sa:ea]) * float(np.sum(wb))
    tail1 = np.cumsum(w1[::-1])[::-1]
    tail2 = np.cumsum(w2[::-1])[::-1]
    lo, hi = min(s1, s2), min(e1, e2)
    total = tail1[0] * tail2[0] * tau[lo]
    if hi > lo + 1:
        rows = np.arange(lo + 1, hi)
        step = tau[rows] - tau[rows - 1]
        t1 = np.where(rows <= s1, tail1[0], tail1[np.clip(rows - s1, 0, e1 - s1 - 1)])
        t2 = np.where(rows <= s2, tail2[0], tail2[np.clip(rows - s2, 0, e2 - s2 - 1)])
        t1 = np.where(rows < e1, t1, 0.0)
        t2 = np.where(rows < e2, t2, 0.0)
        total += float(np.sum(step * t1 * t2))
    return float(total)


def half_difference(start: int, end: int) -> list[tuple[int, int, np.ndarray, float]]:
    """`walk_kernel`'s pieces of a face's first-half mean minus its second-half mean over
    rows [start, end) (at least two): a contrast that nothing constant on the face (its
    calibration, the Earth's rate at its heading) reaches — white noise and drift only."""
    mid = start + (end - start) // 2
    return [(start, mid, np.full(mid - start, 1.0 / (mid - start)), 1.0),
            (mid, end, np.full(end - mid, 1.0 / (end - mid)), -1.0)]  # fmt: skip


WALK_GRID = np.logspace(-6, 6, 1201)
"""Where `walk_posterior_mean` integrates: q² λ_max (the drift's largest share of a
whitened contrast's variance) from 1e-6 to 1e6, and 0."""


def walk_posterior_mean(residual: np.ndarray, white: np.ndarray, walk: np.ndarray) -> float:
    """Posterior mean of q (not q²) given `residual` (r,) ~ N(0, `white` + q² `walk`) (both
    (r, r)), under the Jeffreys prior of the variance component q², p(q²) ∝ (½ Σ λᵢ² /
    (1 + q² λᵢ)²)^½ (λ: the eigenvalues of `walk` whitened by `white`), on q² λ_max ∈
    [0, 1e6] (`WALK_GRID`); 0 where the white part is singular (noise-free data).

    Unlike the maximum-likelihood q², which the σ used before, it is positive whenever the
    residual can hold any drift, also where the likelihood peaks at 0. Its square, not q²'s
    posterior mean, goes into the σ: with six contrasts q²'s posterior has a heavy tail,
    and its mean made the σ of white-noise-only sessions' gyro biases 2.8× too large (RMS
    of z 0.34–0.37, against 0.40–0.43 with E[q]²) and a drifting session's too large by 10 %
    (`benchmarks/coverage_ferraris.py`)."""
    try:
        chol = np.linalg.cholesky(white)
    except np.linalg.LinAlgError:
        return 0.0
    y = np.linalg.solve(chol, residual)
    b = np.linalg.solve(chol, np.linalg.solve(chol, walk).T)
    lam, vec = np.linalg.eigh((b + b.T) / 2)
    lam = np.clip(lam, 0.0, None)
    z2 = (vec.T @ y) ** 2
    if lam.max() <= 0 or not np.all(np.isfinite(z2)):
        return 0.0
    theta = np.concatenate([[0.0], WALK_GRID / lam.max()])  # q²
    v = 1.0 + theta[:, None] * lam[None, :]
    loglik = -0.5 * np.sum(np.log(v) + z2 / v, axis=1)
    prior = np.sqrt(0.5 * np.sum((lam / v) ** 2, axis=1))
    f = np.exp(loglik - loglik.max()) * prior
    step = np.diff(theta)  # trapezoid rule on the log grid (fine: 100 points a decade)
    mass = np.sum(step * (f[1:] + f[:-1])) / 2
    g = np.sqrt(theta) * f
    return float(np.sum(step * (g[1:] + g[:-1])) / 2 / mass)
