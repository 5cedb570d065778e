"""What a plan teaches: the Fisher information of a bench plan about a model's parameters,
and the posterior it leaves."""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import concrete_value, is_concrete
from .._compiled import device
from .._x64 import require_x64
from ..pattern_noise import gauss_markov_mean_factor, slope_variance
from ..units import DEG, DEG_PER_S
from ._models import GREY_BOX, as_model, model_values, noise_vector
from ._plan import DT_OUT, BenchPlan

NODES = 64
"""Quadrature points per rotation and ramp (a turning ramp's: per panel) of `information`."""


def window_density(arw, angle_white, samples, dt, length_s):
    """Effective white rate-noise density [rad/√s] of the physical fit's window slopes: a
    window of n = `samples` samples spaced Δt = `dt` [s] has least-squares slope variance
    6(n² + 1)/(5n(n² − 1)) · N²/Δt (random walk of density N = `arw` [rad/√s]; → 6/5 of a
    mean rate's N²/(nΔt) for long windows) + 12 σ_a²/(Δt² n(n² − 1)) (white angle noise
    σ_a = `angle_white` [rad per sample]), both exact — the pattern noise model's
    [`slope_variance`][hrgjax.pattern_noise.slope_variance] —; × the length of segment the
    window stands for (`length_s` [s]: nΔt for consecutive windows, the duration for a
    static segment's one window), the density a continuous observation of the rate with the
    same information would have."""
    return jnp.sqrt(slope_variance(angle_white, arw, samples, dt) * length_s)


def gauss_markov_discount(duration_s, arw, sigma, tau):
    """Share of a segment's white-noise information left by a Gauss–Markov rate:
    (N²/D) / (N²/D + V(D)), with V(D) = 2σ²τ/D · (1 − (τ/D)(1 − e^(−D/τ))) the variance of
    the GM rate's mean over the segment's duration D [s] (N [rad/√s], σ [rad/s], τ [s]) —
    the pattern noise model's
    [`gauss_markov_mean_variance`][hrgjax.pattern_noise.gauss_markov_mean_variance].
    Exact for the mean rate of a static segment; for a rotation it treats the GM rate as an
    extra error of each parameter's segment-average, which is what a slow bias is."""
    # D·V/N² = 2σ²τ/N² · (1 − (1 − e^−x)/x), x = D/τ (`gauss_markov_mean_factor`: expm1)
    excess = 2.0 * sigma**2 * tau / arw**2 * gauss_markov_mean_factor(duration_s / tau)
    return 1.0 / (1.0 + excess)


LEAST_SAMPLES = 6.0
"""Fewest samples of a window `reduce` (and so the physical fit) accepts: its standard error
takes at least 3 batches of 2 samples (`reduce`: `min(batches, n // 2) ≥ 3`); a segment
with fewer teaches `information` nothing."""


def _segment_windows(dt, t0, t1, rate_dps, duration):
    """(samples, sample interval [s], length [s], windows) of the windows the physical fit
    (and `reduce`) cuts a segment into (see `window_density`), sampled at `DT_OUT` of its
    kind: N = duration/Δt + 1 samples (whole for every plan `simulate_plan` runs: it
    refuses a duration that is not a whole number of Δt). Moving — windows of n =
    max(round(`PhysicalCompensator.window_s`/Δt), 4) samples, (N − 1)/n of them (at least
    one), or one window of all N samples where N < n (`reduce` and the fit keep a run
    shorter than a window whole); a ramp at rest — ≈ `RAMP_WINDOW_S` (300 s) windows tiling
    it; static — one window of all N. A segment of fewer than `LEAST_SAMPLES` (6) forms
    none: windows 0. `length` is the stretch of segment each window stands for
    (duration / windows).

    The moving count is the continuous extension of the ⌊N/n⌋ whole windows the reduction
    forms (the samples past the last are not used): equal to it where the duration is a
    whole number of windows (the seed's 180-s rotations: 18), within one window elsewhere
    (a 72-s rotation: 7.2 for 7) — a whole count would be a staircase in the duration, on
    whose steps every whole-second duration sits, and the design search and the
    criterion's gradient need one that moves with it."""
    from .physical import RAMP_WINDOW_S, PhysicalCompensator

    moving = rate_dps != 0.0
    ramp = t1 != t0
    total = duration / dt + 1.0  # N
    enough = total >= LEAST_SAMPLES
    per_window = jnp.maximum(jnp.round(PhysicalCompensator.window_s / dt), 4.0)
    long = total >= per_window
    moving_windows = jnp.where(long, jnp.maximum((total - 1.0) / per_window, 1.0), 1.0)
    ramp_windows = jnp.maximum(jnp.round(duration / RAMP_WINDOW_S), 1.0)  # tiling
    windows = jnp.where(moving, moving_windows, jnp.where(ramp, ramp_windows, 1.0))
    windows = jnp.where(enough, windows, 0.0)
    samples = jnp.where(moving, jnp.where(long, per_window, total),
                        jnp.where(ramp, duration / ramp_windows / dt, total))  # fmt: skip
    samples = jnp.where(enough, samples, LEAST_SAMPLES)  # (not used: no window)
    length = duration / jnp.maximum(windows, 1.0)
    return samples, dt, length, windows


def _segment_weights(noise, dt, t0, t1, rate_dps, duration):
    """Per segment: 1/N_w² × the segment's `gauss_markov_discount` — the factor of its
    quadrature weights [s⁻¹ per (rad/s)²] (N_w the windows' `window_density` with N, σ_a =
    `noise[0]`, `noise[3]`; σ, τ = `noise[1:3]`); 0 for a segment too short for a window
    (`_segment_windows`)."""
    arw, sigma, tau, angle_white = noise[0], noise[1], noise[2], noise[3]
    samples, dt, length, windows = _segment_windows(dt, t0, t1, rate_dps, duration)
    density = window_density(arw, angle_white, samples, dt, length)
    weight = gauss_markov_discount(duration, density, sigma, tau) / density**2
    return jnp.where(windows > 0.0, weight, 0.0)


def segment_windows(plan: BenchPlan) -> list[tuple[float, float]]:
    """(samples per window, windows) of each segment of a concrete `plan` as `information`
    counts them (`_segment_windows`; (0, 0) for a segment too short for one) — what the
    reduction forms of the segment's data at `DT_OUT`."""
    dt = jnp.asarray([DT_OUT[k] for k in plan.kind], dtype=float)
    samples, _, _, windows = _segment_windows(dt, plan.temperature_c, plan.temperature_end_c,
                                              plan.rate_dps, plan.duration_s)  # fmt: skip
    return [(float(n) if w else 0.0, float(w))
            for n, w in zip(np.asarray(samples), np.asarray(windows), strict=True)]  # fmt: skip


# The kinds of quadrature point (`_quadrature_points`): along a static or ramp, over one
# period of a rotation, over its remainder, and a turning ramp's extra angles (`RAMP_GRID`).
_ALONG, _PERIOD, _REST, _EXTRA = 0, 1, 2, 3


SWEEP_PER_NODE_DEG = 5.0
"""Electrical angle a ramp that turns may sweep per Gauss–Legendre node [°]: a turning
ramp is cut into panels of `nodes` nodes, each sweeping at most `nodes` × this (320° at 64
nodes: the information to 1e-14; one 64-node panel along an hour at 5 °/s, −40 → +20 °C,
was 29 % off) — `ramp_panels`."""

RAMP_GRID = 8
"""Wave angles per node of a ramp that turns, π/8 apart over the period π (the node's own
and 7 more at its T, Ω, Ṫ), from which the node's window average is taken
(`window_transfer`): the measured rate's harmonics of 2θ fall off ≈ 200× per order on the
default gyro, so the 3 that this grid resolves carry all but ~1e-7 of it."""


def ramp_panels(plan, nodes=NODES):
    """Gauss–Legendre panels per segment of `plan` (a tuple, static), or None where every
    segment takes one — or the plan's rates and durations are unknown on the host (traced by
    `jit`: then one panel each; `jax.grad` alone carries the values).
    A ramp that turns sweeps at most |Ω| D of electrical angle (k_e < 1): it gets
    ⌈|Ω| D / (`nodes` · `SWEEP_PER_NODE_DEG`)⌉ panels. Rotations need none (their rule is
    exact at any length), statics one node."""
    if "ramp" not in plan.kind:
        return None
    rate, duration = concrete_value(plan.rate_dps), concrete_value(plan.duration_s)
    if rate is None or duration is None:
        return None
    swept = np.abs(rate.astype(float)) * duration.astype(float)
    per_panel = nodes * SWEEP_PER_NODE_DEG
    panels = tuple(
        max(1, math.ceil(float(a) / per_panel)) if k == "ramp" else 1
        for k, a in zip(plan.kind, swept, strict=True)
    )
    return None if all(p == 1 for p in panels) else panels


def turning_ramps(plan):
    """Which segments of `plan` are ramps that turn (a tuple of bools, static), or None where
    none does — or the rates are unknown on the host (traced by `jit`: a ramp is then taken
    at rest, as the design search's are; `jax.grad` alone carries the values)."""
    if "ramp" not in plan.kind:
        return None
    rate = concrete_value(plan.rate_dps)
    if rate is None:
        return None
    turning = tuple(k == "ramp" and float(r) != 0.0 for k, r in zip(plan.kind, rate, strict=True))
    return turning if any(turning) else None


def plan_layout(plan, nodes=NODES):
    """The static shape of `plan`'s quadrature beyond its kinds: (`ramp_panels`,
    `turning_ramps`), or None where neither applies."""
    panels, turning = ramp_panels(plan, nodes), turning_ramps(plan)
    return None if panels is None and turning is None else (panels, turning)


def window_transfer(omega, samples, dt):
    """Gain of the physical fit's window slope on a rate oscillating at angular frequency
    `omega` [rad/s] (any shape): the least-squares slope of a window of `samples` (static)
    angle samples Δt = `dt` [s] apart of ∫ cos ωt dt, over the rate's value at the window's
    centre — Σ c_k sin(ω u_k)/ω, with u_k the samples' times from the centre and c_k =
    u_k / Σ u² the slope's weights: 1 at ω = 0, → 0 once a window spans several periods (a
    rotation's 10-s windows at 40 °/s sweep 222° electrical: the 2θ harmonic keeps 12 %).
    Real (the weights are odd about the centre), even in ω, and smooth (`jnp.sinc`)."""
    u = (np.arange(samples) - 0.5 * (samples - 1)) * dt
    omega = jnp.asarray(omega)
    u_ = u.reshape((1,) * omega.ndim + u.shape)  # explicit ranks (rank promotion: raise)
    weights = (u * u / np.sum(u * u)).reshape(u_.shape)
    return jnp.sum(weights * jnp.sinc(omega[..., None] * u_ / jnp.pi), axis=-1)


def _window_samples(kind):
    """Samples of the physical fit's moving window of a segment of `kind` (static):
    `PhysicalCompensator.window_s` over `DT_OUT` of the kind, at least 4 (`fit_groups`)."""
    from .physical import PhysicalCompensator

    return max(int(round(PhysicalCompensator.window_s / DT_OUT[kind])), 4)


@functools.lru_cache(maxsize=32)
def _quadrature_points(kinds, nodes, layout=None):
    """(segment index, point kind, position s ∈ [0, 1], weight summing to 1 per part, wave
    angle offset [rad], grid of the point, grids' members (G, W), their mask, grid sizes
    (G,)) of every quadrature point of a plan of `kinds` (`layout`: `plan_layout`).

    - static: one point (`_ALONG`) — its path is one point (θ and T constant, Ω = Ṫ = 0), so
      its integrand is constant and one node integrates it exactly, as it does its
      derivatives with respect to the plan (linear in the node's position; a one-point rule
      is exact to degree 1);
    - ramp: `nodes`-point Gauss–Legendre along the whole segment (`_ALONG`) — or, for a ramp
      that turns, along each of its `panels[i]` equal panels (its integrand oscillates with
      the wave angle while T moves: a node per `SWEEP_PER_NODE_DEG` of angle swept), each
      node of a turning ramp with `RAMP_GRID` − 1 more wave angles π/`RAMP_GRID` apart
      (`_EXTRA`, weight 0) for its window average;
    - rotation: at constant T the integrand is periodic in time — the rate is π-periodic in
      the electrical wave angle (every law of both models is a function of 2θ), which turns
      by π in T_π = π / (k_e |Ω|) — so the segment is m = ⌊D / T_π⌋ whole periods, each the
      same integral, plus a remainder shorter than one: `nodes` / 2 points of the periodic
      trapezoid rule over one period (`_PERIOD`: exact for harmonics of 2θ below `nodes` / 2)
      and `nodes` / 2 Gauss–Legendre points over the remainder (`_REST`). Exact for any
      length: Gauss–Legendre along a long rotation would need a node per ~25° of electrical
      angle swept (64 nodes were off by 10 % at one hour at 5 °/s).

    A point's window average (`_window_average`) is read from its grid: N equally spaced
    wave angles over π at its T, Ω, Ṫ — a rotation's period points, or a turning ramp
    node's own `RAMP_GRID` (itself first). Grid 0 is empty (N = 0: the points at rest).
    Cached per (kinds, nodes, layout): read-only arrays."""
    panels, turning = (None, None) if layout is None else layout
    x, w = np.polynomial.legendre.leggauss(nodes)
    half = max(nodes // 2, 1)
    xh, wh = np.polynomial.legendre.leggauss(half)
    width = max(half, RAMP_GRID)
    seg, code, pos, wt, off, grid_of = [], [], [], [], [], []
    members, sizes = [np.zeros(width, int)], [0]  # grid 0: empty
    count = 0

    def add(i, c, s, ws, offsets=None, grids=None):
        nonlocal count
        n = len(s)
        seg.append(np.full(n, i))
        code.append(np.full(n, c))
        pos.append(np.asarray(s, float))
        wt.append(np.asarray(ws, float))
        off.append(np.zeros(n) if offsets is None else np.asarray(offsets, float))
        grid_of.append(np.zeros(n, int) if grids is None else np.asarray(grids, int))
        count += n
        return count - n + np.arange(n)

    def new_grid(index):
        members.append(np.pad(index, (0, width - len(index))))
        sizes.append(len(index))
        return len(sizes) - 1

    for i, k in enumerate(kinds):
        if k == "static":
            add(i, _ALONG, [0.5], [1.0])
        elif k == "rotation":
            g = new_grid(count + np.arange(half))
            add(i, _PERIOD, (np.arange(half) + 0.5) / half, np.full(half, 1.0 / half),
                grids=np.full(half, g))  # fmt: skip
            add(i, _REST, (xh + 1.0) / 2.0, wh / 2.0, grids=np.full(half, g))
        else:
            p = 1 if panels is None else panels[i]
            s = np.concatenate([(j + (x + 1.0) / 2.0) / p for j in range(p)])
            ws = np.tile(w / 2.0 / p, p)
            if turning is None or not turning[i]:
                add(i, _ALONG, s, ws)
                continue
            n, m = len(s), RAMP_GRID - 1
            own = count + np.arange(n)
            extra = (own[-1] + 1 + np.arange(n * m)).reshape(n, m)
            grids = [new_grid(np.r_[own[j], extra[j]]) for j in range(n)]
            add(i, _ALONG, s, ws, grids=grids)
            angles = np.arange(1, RAMP_GRID) * np.pi / RAMP_GRID
            add(i, _EXTRA, np.repeat(s, m), np.zeros(n * m), np.tile(angles, n),
                grids=np.repeat(grids, m))  # fmt: skip
    members = np.stack(members)
    mask = (np.arange(width)[None, :] < np.asarray(sizes)[:, None]).astype(float)
    out = (*(np.concatenate(a) for a in (seg, code, pos, wt, off, grid_of)), members, mask,
           np.asarray(sizes))  # fmt: skip
    for a in out:
        a.flags.writeable = False  # shared by every call (cached)
    return out


def information(plan: BenchPlan, values=None, arw: float | None = None, nodes: int = NODES,
                gauss_markov: tuple[float, float] | None = None,
                angle_white: float | None = None, model=None):  # fmt: skip
    """Fisher information matrix (P × P, P = 12) of `plan` about the physical grey box's
    parameters ([`physical.PARAMETERS`][hrgjax.calibration.physical.PARAMETERS] order, SI)
    — or, with `model` (`MODELS`), about that model's — linearised at `values` (default
    the model's `nominal()`: `nominal_values()`), for white rate noise of density
    `arw` on the measured pattern angle [rad/√s] (default `pattern_arw()`) and a
    Gauss–Markov rate `gauss_markov` = (σ [rad/s], τ [s]) on it (default
    `pattern_gauss_markov()`; `(0.0, 1.0)` for white noise only) and white readout noise
    `angle_white` on each sample of it [rad] (default `pattern_angle_white()`; 0 for none).
    `nodes`: quadrature points per rotation and ramp (a static segment's path is one point,
    which one node integrates exactly; a rotation is whole periods of its π-periodic
    integrand plus a remainder, exact at any length; a ramp that turns takes panels of
    `nodes` points, each sweeping at most `nodes` × `SWEEP_PER_NODE_DEG` — counted from the
    plan's numbers (as `jax.grad` carries them), so under `jax.jit` with the plan traced a
    ramp takes one panel, accurate while it sweeps less than that — `_quadrature_points`).

    Each segment is observed through its measured pattern rate along its path: θ turning at
    −k_e Ω from its wave angle, T moving linearly from start to end (a ramp's Ṫ reaches the
    readout's temperature sensitivity ∂θ̂/∂T — what a static grid cannot see) — through the
    windows the physical fit reduces it with (a static segment whole, a rotation in 10-s
    windows, a ramp in 300-s windows; samples every `DT_OUT`), whose least-squares slopes
    have the noise density [`window_density`][hrgjax.calibration.design.window_density]:
    the random walk's 6/5 and, for short windows, the readout noise (1″ per 0.5-s sample is
    ≈ 14× the ARW's variance in a 10-s window). A window's slope is the rate averaged with
    the least-squares slope's kernel: on a table that turns (a rotation, a ramp with a
    rate) each harmonic of 2θ of the rate's sensitivity is scaled by the kernel's gain
    `window_transfer` (at 40 °/s a 10-s window sweeps 222° electrical and the 2θ ripple all
    but averages out; counted pointwise it was over-counted 70–80×) — a rotation's from its
    period's points, a turning ramp's from `RAMP_GRID` wave angles per node (under
    `jax.jit` with the plan traced a ramp is taken at rest, as its panels are counted). The
    Gauss–Markov rate discounts each segment's information by
    [`gauss_markov_discount`][hrgjax.calibration.design.gauss_markov_discount] (a long dwell
    averages white noise down, not a slow bias); the switch-on bias is left out (it is a
    constant of the session: the fitted bias absorbs it, to 0.00 σ as a rate bias — a
    simulated `Noise.run_bias`, which does not move the wave, shifts θ_τ0 0.34 σ on 2400-s
    dwells; docs/design.md, "The switch-on bias in the simulated sessions"). Differentiable
    with respect to the plan's arrays (`jax.grad` of a criterion gives a plan-shaped
    gradient)."""
    require_x64("hrgjax.calibration.design.information")
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or nodes < 2:
        raise ValueError(f"nodes must be a whole number ≥ 2 (quadrature points); got {nodes!r}")
    model = as_model(model)
    values = model_values(values, model)
    noise = noise_vector(arw, gauss_markov, angle_white)
    source, layout = information_source(plan, values, noise, model, nodes)
    if not isinstance(source, BenchPlan):
        return source
    return _information(plan, values, noise, nodes, model, layout)


@eqx.filter_jit
def _information(plan, values, noise, nodes, model=GREY_BOX, layout=None):
    """`information`, compiled once per plan length, kinds and model: each segment observed
    through its window slopes, ∫ ḡ ḡᵀ dt / N_w² with ḡ the window average of g =
    ∂(measured rate)/∂values along its path (θ turning at −k_e Ω, T linear) — every
    quadrature point of every segment (`_quadrature_points`) in one vmapped Jacobian, so
    that the program holds one copy of the rate's derivative."""
    weight, gain, *path = _path_points(plan, values, noise, nodes, model, layout)
    grids = _quadrature_points(plan.kind, nodes, layout)[5:8]
    jac = _jacobians(values, model, *path)
    return _window_information(jnp, weight, gain, path[0], *grids, jac)


def _jacobians(values, model, thetas, temps, omega, temp_rate):
    """g = ∂(measured rate)/∂values at points (θ, T, Ω, Ṫ): (points, P)."""
    return jax.vmap(lambda th, T, om, tr: jax.jacfwd(model.rate)(values, th, T, om, tr))(
        thetas, temps, omega, temp_rate
    )


def _window_information(xp, weight, gain, thetas, grid_of, members, mask, jac):
    """Σ wᵢ ḡᵢ ḡᵀᵢ over points, ḡᵢ the window average of gᵢ (`_window_average`): gᵢ plus
    Σ_{1 ≤ n < N/2} (2/N)(H_n − 1)[cos 2nθᵢ · Cₙ + sin 2nθᵢ · Sₙ], where Cₙ, Sₙ = Σⱼ (cos,
    sin) 2nθⱼ · gⱼ over the N points θⱼ of the point's grid (`gain`: (points, harmonics) of
    (2/N)(H_n − 1), 0 where not resolved)."""
    n = xp.arange(1.0, gain.shape[1] + 1.0)
    angle = 2.0 * n[None, :] * thetas[:, None]  # (points, harmonics)
    cos, sin = xp.cos(angle), xp.sin(angle)
    at = lambda x: x[members] * mask[..., None]  # noqa: E731  (grids, W, …)
    # each grid's discrete Fourier coefficients of g: (grids, harmonics, P)
    c_hat = xp.einsum("gkh,gkp->ghp", at(cos), at(jac))
    s_hat = xp.einsum("gkh,gkp->ghp", at(sin), at(jac))
    mean = jac + xp.einsum("nh,nhp->np", gain * cos, c_hat[grid_of])
    mean = mean + xp.einsum("nh,nhp->np", gain * sin, s_hat[grid_of])
    return (mean * weight[:, None]).T @ mean


INFORMATION_CHUNK = 1024
"""Quadrature points per call of the information's compiled Jacobian on a concrete plan
(`_information_chunked`): every plan, whatever its length and kinds, meets one program."""


_chunk_jacobians = eqx.filter_jit(_jacobians)


def _information_chunked(plan, values, noise, model=GREY_BOX, layout=None, nodes=NODES):
    """`_information` of a concrete plan (values and noise concrete too): the
    points' weights, window corrections and paths by a small program per plan structure,
    then their Jacobians `INFORMATION_CHUNK` points at a time (padded with θ = T = Ω = 0) by
    one program for every plan — a criterion of a new plan then compiles nothing large
    (`hrgjax design` compares three plans of different structures; each cost ≈ 4 s of
    compiling before) — and the window averages and the sum on the host."""
    weight, gain, *path = (
        np.asarray(x) for x in _path_points_compiled(plan, values, noise, nodes, model, layout)
    )
    grids = _quadrature_points(plan.kind, nodes, layout)[5:8]
    n = weight.shape[0]
    m = -(-n // INFORMATION_CHUNK) * INFORMATION_CHUNK
    padded = [np.pad(x, (0, m - n)) for x in path]
    jac = np.concatenate([
        np.asarray(_chunk_jacobians(values, model, *(device(x[i : i + INFORMATION_CHUNK])
                                                     for x in padded)))
        for i in range(0, m, INFORMATION_CHUNK)
    ])[:n]  # fmt: skip
    thetas = path[0][:n]
    return jnp.asarray(_window_information(np, weight, gain, thetas, *grids, jac))


def information_source(plan, values, noise, model=GREY_BOX, nodes=NODES):
    """What the criteria read the plan through: its information matrix, chunked
    (`_information_chunked`), where the plan, values and noise are concrete; else the plan
    itself (traced: `jax.jit`, `jax.grad` with respect to it — `_information` inline); and
    its quadrature's `plan_layout`."""
    layout = plan_layout(plan, nodes)
    if all(is_concrete(x) for x in (*plan._fields().values(), values, noise)):
        return _information_chunked(plan, values, noise, model, layout, nodes), None
    return plan, layout


def _window_average(omega, k_e, kinds, seg, grid_of, sizes):
    """(2/N)(H_n − 1) per point and harmonic n = 1 … W/2 − 1 (0 where n ≥ N/2 of the
    point's grid, N = `sizes[grid_of]`): the physical fit sees a moving segment only
    through its windows' least-squares slopes, which average the rate with the slope's
    kernel — each harmonic e^{2inθ} of g (angular frequency 2n k_e Ω, Ω = `omega` per
    segment) scaled by `window_transfer`, H_n,
    with each kind's window (`_window_samples`; a static is at rest: H = 1).
    `_window_information` takes the grid's discrete Fourier series of (H − 1) g at the
    point's θ — exact for harmonics below N/2; the higher ones (≲ 1e-7 of g on the default
    gyro) are kept as they are."""
    size = sizes[grid_of]
    harmonic = np.arange(1, max(int(np.max(sizes)), 2) // 2)
    used = harmonic[None, :] < size[:, None] / 2.0  # (points, harmonics)
    kinds = np.asarray(kinds)
    frequency = 2.0 * harmonic[None, :] * k_e * omega[:, None]  # (segments, harmonics)
    gain = jnp.ones_like(frequency)
    for kind in sorted(set(kinds.tolist()) - {"static"}):
        here = jnp.asarray(kinds == kind)[:, None]
        gain = jnp.where(here, window_transfer(frequency, _window_samples(kind), DT_OUT[kind]),
                         gain)  # fmt: skip
    scale = np.where(used, 2.0 / np.maximum(size, 1)[:, None], 0.0)
    return jnp.asarray(scale) * (gain[seg] - 1.0)


def _path_points(plan, values, noise, nodes, model=GREY_BOX, layout=None):
    """Every quadrature point of `plan` (`_quadrature_points`): its weight (quadrature
    weight × span × its segment's 1/N_w² and Gauss–Markov discount), its window average's
    coefficients (`_window_average`) and its path point (θ [rad], T [°C], Ω [rad/s], Ṫ
    [°C/s])."""
    dt = jnp.asarray([DT_OUT[k] for k in plan.kind], dtype=float)  # each kind's sampling
    t0, t1, angle, rate, duration = (plan.temperature_c, plan.temperature_end_c,
                                     plan.wave_angle_deg, plan.rate_dps, plan.duration_s)  # fmt: skip
    seg_w = _segment_weights(noise, dt, t0, t1, rate, duration)
    seg, code, pos, wt, off, grid_of, _, _, sizes = _quadrature_points(plan.kind, nodes, layout)
    at = lambda x: x[seg]  # noqa: E731  (each point's segment's value)
    d, omega = at(duration), at(rate) * DEG_PER_S
    k_e = model.gain(values)
    # a rotation's period of the integrand, T_π = π / (k_e |Ω|), and its whole periods m
    # (computed with Ω = 1 for the other points, which do not use them: no division by 0)
    turning = jnp.asarray((code == _PERIOD) | (code == _REST))
    period = jnp.pi / (k_e * jnp.abs(jnp.where(turning, omega, 1.0)))
    whole = jnp.floor(d / period)
    rest = d - whole * period
    pos, wt = jnp.asarray(pos), jnp.asarray(wt)
    is_period, is_rest = jnp.asarray(code == _PERIOD), jnp.asarray(code == _REST)
    t = jnp.where(is_period, pos * period, jnp.where(is_rest, whole * period + pos * rest, pos * d))
    span = jnp.where(is_period, whole * period, jnp.where(is_rest, rest, d))  # [s]
    temp_rate = (at(t1) - at(t0)) / d
    thetas = at(angle) * DEG - k_e * omega * t + jnp.asarray(off)
    # a rotation holds its temperature (checked where the plan is built): at the mean of
    # its two, so that the path stays periodic in every direction a gradient takes (the
    # derivative splits equally between temperature_c and temperature_end_c, as a static's)
    temps = jnp.where(turning, 0.5 * (at(t0) + at(t1)), at(t0) + temp_rate * t)
    gain = _window_average(rate * DEG_PER_S, k_e, plan.kind, seg, grid_of, sizes)
    return wt * span * at(seg_w), gain, thetas, temps, omega, temp_rate


_path_points_compiled = eqx.filter_jit(_path_points)


PRECISION_FLOOR = 16.0 * float(np.finfo(np.float64).eps)
"""The weakest prior float64 resolves, relative to what a plan teaches: `precision_factor`
floors each parameter's prior precision at P × this (P parameters: 4.3·10⁻¹⁴ for the grey
box's 12) × the parameter's own information F_ii (in units of its typical uncertainty). F is
summed in float64, so a direction a plan does not see reads as ±P·ε of F's diagonal, not 0:
a prior weaker than that (`prior_scale` ≳ 10⁶ on a plan that leaves directions unseen) left
a posterior variance that was round-off, and at 10⁸ no Cholesky factor at all (NaN
criteria). Floored, such a prior reads as the floor and every criterion stays finite; where
the prior is stronger than the floor (the default `prior_scale` = 100 on any plan so far),
nothing changes, and a parameter the plan does not see at all keeps its prior."""


def prior_scale_array(prior_scale):
    """`prior_scale` as a float64 array — an argument of the criteria's compiled programs,
    not a constant baked into them, so a sweep over it compiles once — refused in one line
    when its value is known and is not a finite number > 0."""
    given = concrete_value(prior_scale)
    if given is not None and not (
        given.shape == () and np.isfinite(given) and given > 0 and given.dtype != bool
    ):
        raise ValueError(f"prior_scale must be a finite number > 0 (the prior's σ in units of "
                         f"each parameter's typical uncertainty); got {given}")  # fmt: skip
    return jnp.asarray(prior_scale, dtype=jnp.float64)


def precision_factor(plan, values, noise, prior_scale, model=GREY_BOX, panels=None):
    """Cholesky factor of the posterior precision in units of each parameter's typical
    uncertainty, equilibrated to unit diagonal: `(L, d)` with A = diag(d) L Lᵀ diag(d)
    (forming (F + Λ)⁻¹ explicitly loses ~cond·ε; triangular solves keep the criteria and
    their gradients accurate), the prior floored at float64's resolution (`PRECISION_FLOOR`).
    `plan`: a plan, or its information matrix (`information_source`); `prior_scale` > 0."""
    prior_scale = prior_scale_array(prior_scale)
    scale = model.scale()
    if isinstance(plan, BenchPlan):
        a = _information(plan, values, noise, NODES, model, panels)
    else:
        a = plan
    n = a.shape[0]
    a = a * scale[:, None] * scale[None, :]
    prior = jnp.maximum(1.0 / prior_scale**2, (n * PRECISION_FLOOR) * jnp.diagonal(a))
    a = a + jnp.diag(prior)
    d = jnp.sqrt(jnp.diagonal(a))
    return jnp.linalg.cholesky(a / d[:, None] / d[None, :]), d


def scaled_solve(factor, h):
    """Rows L⁻¹ diag(d)⁻¹ hᵢ for h (N, P) in scaled units: ‖row‖² = hᵢᵀ A⁻¹ hᵢ."""
    import jax.scipy.linalg as jsl

    chol, d = factor
    return jsl.solve_triangular(chol, (h / d[None, :]).T, lower=True).T


def posterior_covariance(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                         gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    """Linearised posterior covariance of the grey box's parameters after `plan` (P × P,
    SI): (F + Λ)⁻¹ with F = [`information`][hrgjax.calibration.design.information] and a
    weak Gaussian prior Λ of σ = `prior_scale` × each parameter's typical uncertainty
    (`physical.PARAMETERS`; `model` as [`information`][hrgjax.calibration.design.information],
    its `scale()`), which keeps directions a plan does not see finite (`prior_scale` > 0;
    beyond ≈ 10⁶ float64 cannot resolve it, and it reads as `PRECISION_FLOOR`)."""
    model = as_model(model)
    values = model_values(values, model)
    noise = noise_vector(arw, gauss_markov, angle_white)
    source, panels = information_source(plan, values, noise, model)
    factor = precision_factor(source, values, noise, prior_scale, model, panels)
    scale = model.scale()
    w = scaled_solve(factor, jnp.eye(scale.shape[0]))  # rows: L⁻¹ D⁻¹ e_i
    return (w @ w.T) * scale[:, None] * scale[None, :]
