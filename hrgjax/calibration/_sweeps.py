"""Virtual-precession sweeps as `PrecessionCompensator.fit` reads them: grouped by
temperature, each run's samples after the settling, and the checks that the sweeps at each
temperature determine the drift (samples left, both directions, the angle covered); the
least squares' design, and the standard errors of the sweeps' fit and of mode reversal's
hold means from the data's own noise (`noise_components`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..data import MeasuredData
from ..units import DEG, DEG_PER_S, EARTH_RATE, STILL_RATE_DPS

EARTH_RATE_DPS = EARTH_RATE / DEG_PER_S
"""Largest constant case rate mode reversal and the sweeps take [°/s] (0.00418: Earth's
rate, the most of it a bench's sensitive axis sees; `hrgjax.units.STILL_RATE_DPS`, 1e-3 °/s,
is below its vertical share Ω_E sin φ above 14° latitude)."""
CONSTANT_RATE_DPS = 1e-6 * EARTH_RATE_DPS
"""The most a rate beyond `STILL_RATE_DPS` may vary over a run (mode reversal, a sweep) and
count as constant [°/s]: half a change between mode reversal's holds would go into the
anisotropy whole."""


def at_rest(rate_dps) -> bool:
    """Whether a run's case rates `rate_dps` [°/s] (a profile's knots or a run's samples) are
    rest: within `STILL_RATE_DPS` (a rate table's readback jitter), or constant to
    `CONSTANT_RATE_DPS` and no larger than Earth's (`EARTH_RATE_DPS`: a bench on the Earth,
    whose rate then enters the drift's constant term, as in a static run on that bench)."""
    rate_dps = np.asarray(rate_dps, dtype=float)
    peak, spread = float(np.max(np.abs(rate_dps))), float(np.ptp(rate_dps))
    return peak <= STILL_RATE_DPS or (peak <= EARTH_RATE_DPS and spread <= CONSTANT_RATE_DPS)


MIN_SWEEP_SAMPLES = 20
"""Fewest samples a sweep must keep after `settle_s`."""

MIN_COVERAGE_DEG = 120.0
"""Least arc of wave angle (electrical, mod 180°) the sweeps turning each way must cover at
a temperature after `settle_s` [°]: the 2nθ harmonics are determined only over most of a
period — the 2θ and 4θ basis has condition number 1 over 180°, 1.3 over 165° (a plan's
sweeps read with a longer settle_s), 5 over 120°, 20 over 90° and 2900 over 30° (a 30° arc
put the drift 100× off)."""


def sweeps_by_temperature(data: MeasuredData, bin_c: float, settle_s: float):
    """[(temperature [°C], [(t, θ, ρ, used) per run])] sorted by temperature, each with runs
    turning both ways. **Raises:** `ValueError` for a turning table (not `at_rest`: beyond
    [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS], readback jitter, unless constant and no
    larger than Earth's rate), a
    sweep that pauses, no sweeps, a sweep left with fewer than `MIN_SWEEP_SAMPLES` after
    `settle_s` [s] (checked before the directions: a settling longer than the sweeps leaves
    none), sweeps in one direction only, or covering less than `MIN_COVERAGE_DEG`."""
    by_temp: dict[float, list] = {}
    for idx in data.run_indices():
        t = data["time_s"][idx]
        rho = data["precession_dps"][idx] * DEG_PER_S
        if np.all(rho == 0):
            continue  # a static run: nothing to sweep
        run = int(data["run"][idx[0]])
        table = data["table_rate_dps"][idx]
        if not at_rest(table):  # jitter within STILL_RATE_DPS, or Earth's constant rate: rest
            raise ValueError(f"run {run}: the table turns (|table_rate_dps| up to "
                             f"{float(np.max(np.abs(table))):.3g} °/s, varying by "
                             f"{float(np.ptp(table)):.3g}); virtual-precession sweeps are taken "
                             f"with the case at rest (|table_rate_dps| ≤ STILL_RATE_DPS = "
                             f"{STILL_RATE_DPS:g} °/s, or constant and no larger than Earth's "
                             f"{EARTH_RATE_DPS:.4g} °/s)")  # fmt: skip
        temp = float(np.round(np.mean(data["temperature_c"][idx]) / bin_c) * bin_c)
        used = t - t[0] >= settle_s
        if np.any(rho[used] == 0):
            first = float(t[used][rho[used] == 0][0])
            raise ValueError(f"run {run}: the sweep pauses (precession_dps 0) at t = {first:g} s "
                             "after settling; give each sweep its own run")  # fmt: skip
        by_temp.setdefault(temp, []).append((t, data["wave_angle_deg"][idx] * DEG, rho, used))
    if not by_temp:
        raise ValueError("no virtual-precession sweeps in the data (every precession_dps is 0)")
    out = []
    for temp in sorted(by_temp):
        runs = by_temp[temp]
        short = min(runs, key=lambda r: int(r[3].sum()))
        if (kept := int(short[3].sum())) < MIN_SWEEP_SAMPLES:
            raise ValueError(
                f"at {temp:g} °C a sweep of {short[0][-1] - short[0][0]:g} s keeps {kept} samples "
                f"after settle_s = {settle_s:g} s, fewer than {MIN_SWEEP_SAMPLES}: give a "
                "settle_s shorter than the sweeps (or longer sweeps)"
            )
        signs = {float(np.sign(np.median(r[2][r[3]]))) for r in runs}
        if signs != {1.0, -1.0}:
            raise ValueError(
                f"at {temp:g} °C the sweeps turn one way only; the drift and the forcers' gain "
                "separate only with sweeps in both directions (precession_plan runs ±ρ)"
            )
        for sign, way in ((1.0, "+ρ"), (-1.0, "−ρ")):
            arcs = [r[1][r[3]] / DEG for r in runs if np.median(r[2][r[3]]) * sign > 0]
            covered = coverage_deg(arcs)
            if covered < MIN_COVERAGE_DEG:
                raise ValueError(
                    f"at {temp:g} °C the sweeps turning {way} cover {covered:.0f}° of the 180° "
                    f"(electrical) of wave angle the 2nθ harmonics need (≥ {MIN_COVERAGE_DEG:g}° "
                    "after settle_s): sweep over a half turn (180° electrical) in each direction "
                    "(precession_plan does)"
                )
        out.append((temp, runs))
    return out


def coverage_deg(arcs) -> float:
    """Degrees of the 180° (electrical) period visited by the wave angles [°] of `arcs` (each
    a run's samples, the path between them counted), in 1° bins."""
    seen = np.zeros(180, bool)
    for a in arcs:
        lo, hi = float(np.min(a)), float(np.max(a))
        if hi - lo >= 180.0:
            return 180.0
        start = int(np.floor(lo))
        bins = np.arange(start, start + int(np.ceil(hi - start)))
        seen[bins % 180] = True
    return float(seen.sum())


def sweep_design(t, wave_angle, precession, weight, harmonics: int):
    """`(a, y, J)`: the weighted design (R·n, 2J + R) and data (R·n,) of `fit_sweeps`' least
    squares (columns ∫ρb, ∫b over the basis of J functions, one offset per run) from `t` [s],
    `wave_angle` [rad], `precession` [rad/s] and `weight` (R, n); differentiable (jax)."""
    # Each interval's mean of b along a wave turning uniformly from θ_i to θ_{i+1} — exact
    # for that path: cos/sin 2kθ_m · sinc(kΔθ) (a trapezoid would err by (2kΔθ)²/12).
    mid = 0.5 * (wave_angle[:, 1:] + wave_angle[:, :-1])
    half = 0.5 * jnp.diff(wave_angle, axis=-1)
    cols = [jnp.ones_like(mid)]
    for k in range(1, harmonics + 1):
        damp = jnp.sinc(2 * k * half / jnp.pi)
        cols += [jnp.cos(2 * k * mid) * damp, jnp.sin(2 * k * mid) * damp]
    mean_b = jnp.stack(cols, axis=-1)  # (R, n − 1, J)
    dt = jnp.diff(t, axis=-1)[..., None]
    used = (weight[:, :-1] * weight[:, 1:])[..., None]  # intervals between two used samples
    mean_rho = 0.5 * (precession[:, 1:] + precession[:, :-1])[..., None]

    def cumulative(inc):  # ∫ dt from the run's first used sample
        inc = inc * dt * used
        return jnp.concatenate([jnp.zeros_like(inc[:, :1]), jnp.cumsum(inc, axis=1)], axis=1)

    r = t.shape[0]
    offsets = jnp.broadcast_to(jnp.eye(r)[:, None, :], (r, t.shape[1], r))
    design = jnp.concatenate([cumulative(mean_rho * mean_b), cumulative(mean_b), offsets], -1)
    w = weight.reshape(-1)[:, None]
    return design.reshape(-1, design.shape[-1]) * w, wave_angle.reshape(-1) * w[:, 0], len(cols)


MIN_NOISE_BLOCKS = 8
"""Fewest blocks of `noise_components`' length per series (a hold, a sweep) for a standard
error: fewer, and the random walk's share is read from too few block means (σ is NaN)."""


def noise_components(e, mask, xp=np, moments=None):
    """`(s, q)`: the variance s of white noise per sample and the increment variance q per
    sample of a random walk in the series `e` (…, K, N) (angle-like: a residual angle, or the
    running sum of a rate), read on the samples where `mask` is 1 (one contiguous stretch per
    series), pooled over the K series, in e's unit squared. Method of moments at two scales
    (`scales`): lag-1 differences, E = 2s + q, and differences of adjacent means over
    m samples, E = 2s/m + q(2m² + 1)/(3m), where the random walk outweighs the white noise;
    `moments` ((2, 2): each scale's E per unit s and q) replaces these for a fit's
    residuals (`sweep_std`). q ≥ 0 and s ≥ 0. `xp`: numpy, or jax.numpy."""
    mask = xp.asarray(mask, dtype=float)
    e = xp.asarray(e) * mask
    (lag1, ok1), (block, okb), m = scales(mask, xp)
    d1 = xp.sum(ok1 * lag1(e) ** 2, axis=(-2, -1)) / xp.sum(ok1, axis=(-2, -1))
    db = xp.sum(okb * block(e) ** 2, axis=(-2, -1)) / xp.sum(okb, axis=(-2, -1))
    return solve_moments(d1, db, raw_moments(m) if moments is None else moments, xp)


def solve_moments(d1, db, moments, xp=np):
    """`(s, q)` ≥ 0 from the two scales' observed moments and their expectations per unit s
    and q (`moments`, ((a, b), (c, d))); q < 0 read as 0 (s from the lag-1 moment alone)."""
    (a, b), (c, d) = moments
    q = (a * db - c * d1) / (a * d - b * c)
    s = xp.where(q > 0, (d1 - b * q) / a, d1 / a)
    return xp.maximum(s, 0.0), xp.maximum(q, 0.0)


def scales(mask, xp=np, m: int | None = None):
    """`((lag1, ok1), (block, okb), m)`: `noise_components`' two difference operators on series
    (…, N) masked by `mask` (…, K, N), each with where it is valid; m = N_min // 8 samples (the
    shortest series; N // K when traced) unless given."""
    if m is None:
        kept = concrete_count(mask)
        kept = np.shape(mask)[-1] // np.shape(mask)[-2] if kept is None else kept
        m = int(max(2, kept // MIN_NOISE_BLOCKS))

    def lag1(x):
        return x[..., 1:] - x[..., :-1]

    def block(x):  # adjacent means of samples i … i + m − 1 and i + m … i + 2m − 1
        c = xp.cumsum(x, axis=-1)
        c = xp.concatenate([xp.zeros_like(c[..., :1]), c], axis=-1)
        b = (c[..., m:] - c[..., :-m]) / m
        return b[..., m:] - b[..., :-m]

    ok = mask[..., m - 1 :] * mask[..., : 1 - m]  # a block's first and last samples kept
    return (lag1, mask[..., 1:] * mask[..., :-1]), (block, ok[..., m:] * ok[..., :-m]), m


def concrete_count(mask):
    """The fewest samples a series of `mask` (…, N) keeps (an int), or None when traced."""
    try:
        return int(np.min(np.sum(np.asarray(mask), axis=-1)))
    except Exception:  # a jax tracer: not concrete
        return None


def raw_moments(m: int):
    """E of the two scales' moments of a raw series per unit s and q: ((2, 1), (2/m, …))."""
    return ((2.0, 1.0), (2.0 / m, (2.0 * m * m + 1.0) / (3.0 * m)))


MIN_POOLED_SWEEPS = 6
"""Fewest sweeps (3 temperatures' ±ρ pairs) whose residuals `sweep_std` reads the noise from:
the fit takes out the slow part of the angle random walk that makes its error, so one pair's
residuals put q anywhere from 0 to 4.6× the truth (5–95 %, 100 seeds at 1 °/s): NaN below."""


def sweep_std(groups, harmonics: int, noise=None):
    """`[(s_std, d_std)]` per temperature: standard errors of `fit_sweeps`' coefficients
    (`groups`: its arguments t, wave_angle, precession, weight at each temperature, R runs × n
    samples; the same units, rad/s), from the fit's residuals: white angle noise s and an
    angle random walk q per sample, one pair for all the sweeps (one gyro), by moments at two
    scales (`scales`) whose expectations count what the fit takes out of the residuals
    (raw minus 2 tr(AHΣ) plus tr(AHΣH), H the fit's hat matrix), carried through the least
    squares: Var = s·LLᵀ + q·Σ UUᵀ (L the fit's pseudo-inverse, U its sums from each
    increment to the run's end). NaN where a run keeps fewer than 2·`MIN_NOISE_BLOCKS`
    samples, or fewer than `MIN_POOLED_SWEEPS` sweeps in all. `noise` (a
    `hrgjax.pattern_noise.NoiseModel`, pattern angle: σ_w, N) gives s = σ_w², q = N²·dt
    instead, whatever the number of sweeps. A rate wander slower than the sweeps (a
    Gauss–Markov bias) reads as drift and is not in σ."""
    from ..pattern_noise import NoiseModel

    if noise is not None and not isinstance(noise, NoiseModel):  # a Noise's N is input rate
        raise TypeError(
            f"noise must be an hrgjax.pattern_noise.NoiseModel (pattern angle: "
            f"NoiseModel.from_gyro(gyro.noise, k_e)); got {type(noise).__name__}"
        )
    ws = [np.asarray(g[3], dtype=float) for g in groups]
    m = max(2, int(min(np.min(np.sum(w, -1)) for w in ws)) // MIN_NOISE_BLOCKS)
    obs, exp, covs = np.zeros(2), np.zeros((2, 2)), []
    for (t, theta, rho, _), w in zip(groups, ws, strict=True):
        a, y, j = sweep_design(t, theta, rho, w, harmonics)
        a, y = np.asarray(a), np.asarray(y)
        scale = np.sqrt(np.sum(a * a, axis=0)) + 1e-300
        pinv = np.linalg.pinv(a / scale) / scale[:, None]  # (P, R·n)
        p = pinv.shape[0]
        lr = pinv.reshape(p, *w.shape) * w  # (P, R, n)
        tail = np.flip(np.cumsum(np.flip(lr, -1), -1), -1)[..., 1:]  # Σ_{i ≥ k} L_i, k ≥ 1
        u = tail * (w[:, 1:] * w[:, :-1])[None]  # increments between two used samples
        cov_s, cov_q = pinv @ pinv.T, np.einsum("prk,qrk->pq", u, u)  # Σ = I, Σ = K
        covs.append((np.diag(cov_s)[: 2 * j], np.diag(cov_q)[: 2 * j]))
        if noise is not None:  # s and q given: no moments to read
            continue
        walk = np.concatenate([np.zeros_like(u[..., :1]), np.cumsum(u, -1)], -1)  # K Lᵀ
        x = a.reshape(*w.shape, p).transpose(2, 0, 1)
        resid = (y - a @ (pinv @ y)).reshape(w.shape)
        (*ops, _), raw = scales(w, m=m), raw_moments(m)
        for k, (op, ok) in enumerate(ops):  # E per unit s, q: raw minus the fit's share
            gx = op(x) * ok
            proj = np.einsum("prk,qrk->pq", gx, gx)
            for i, (sig, cov) in enumerate(((lr, cov_s), (walk, cov_q))):
                exp[k, i] += raw[k][i] * np.sum(ok) - 2 * np.sum(op(sig) * gx) + np.sum(cov * proj)
            obs[k] += np.sum(ok * op(resid) ** 2)
    short = min(np.min(np.sum(w, -1)) for w in ws) < 2 * MIN_NOISE_BLOCKS
    if noise is not None:  # the sample interval of the first run's used samples
        dt = float(np.median(np.diff(np.asarray(groups[0][0])[0][ws[0][0] > 0])))
        s, q = noise.angle_white**2, noise.angle_random_walk**2 * dt
    else:
        s, q = solve_moments(obs[0], obs[1], exp)
        short = short or sum(len(w) for w in ws) < MIN_POOLED_SWEEPS
    out = [np.full(2 * j, np.nan) if short else np.sqrt(s * cs + q * cq) for cs, cq in covs]
    return [(std[:j], std[j:]) for std in out]


def hold_var(r, masks, means, xp):
    """Variance of each hold's mean rate (…, 2) [r's unit²]: `r` (…, N) the output, `masks`
    (…, 2, N) the holds' samples, `means` (…, 2) their means. The running sum of r − mean over
    a hold is an angle: white readout noise s per sample (in a mean of n rates only its two
    ends are left) and a random walk q per sample (white rate noise), read pooled over both
    holds (`noise_components`): (n q + 2s)/n². NaN for a hold of fewer than 16 samples."""
    e = xp.cumsum(masks * (r[..., None, :] - means[..., None]), axis=-1)
    s, q = noise_components(e, masks, xp)
    n = xp.sum(masks, axis=-1)
    var = (n * q[..., None] + 2.0 * s[..., None]) / n**2
    return xp.where(n >= 2 * MIN_NOISE_BLOCKS, var, xp.nan)
