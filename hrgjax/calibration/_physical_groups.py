"""The bench runs as the physical fit sees them: stacked and padded into compiled groups
(`fit_groups`, `merge_buckets`), each with its measured window rates (static runs as one
window, rotations in `window_s` windows, ramps in `RAMP_WINDOW_S` windows) and their weights
(`window_weights`)."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import numpy as np

from .._compiled import device
from ..data import MeasuredData
from ..pattern_noise import TEMPERATURE_TOLERANCE_C
from ._grouping import ladder, partition
from .reduce import K_E_NOMINAL, RAMP_WINDOW_S, least_squares_slope

WEIGHT_WINDOW_S = 60.0
"""Window length [s] the at-rest residual scatter is referred to: an at-rest window of
length L is weighted by √(L / 60 s) / σ (white rate noise: variance ∝ 1/L)."""


SHARED_LENGTH_RUNS = 4
"""A run length shared by at least this many runs (of one sample interval) gets a compiled
group of its own; rarer lengths are padded up to the next power of two of samples and
share one — a plan of 44 different segment lengths compiles 5 groups, not 44. The padded
tail is simulated and masked out of every window: it costs run time (≤ 2×, on a simulator
that runs in seconds) and saves compiling (about 3–4 s per group for the simulator, more
for the fit's Jacobian program: a 12-h designed plan's first calibration 109–119 → 58–65 s;
`benchmarks/README.md`). Neighbouring lengths are then run as one group where that is
cheaper than compiling another (`merge_buckets`: 7 groups → 3, first fit 49.0 → 21.4 s)."""


FIT_COMPILE_S = 6.0
"""Seconds one group adds to compiling the fit's residual-and-Jacobian program (2-core CPU,
`benchmarks/fit_group_layouts.py`: a 12-h designed plan's 7, 3 and 2 groups 46.8, 22.4 and
16.1 s) — what running two groups of run lengths as one saves (`merge_buckets`)."""

MANY_GROUPS = 8
"""Compiled groups beyond which the fit's progress bar says how many it compiles and why
(`many_groups_note`): each costs about `FIT_COMPILE_S` of compiling, more than a whole fit's
evaluations on a plan of one sample interval."""


def many_groups_note(groups) -> str:
    """One line for the fit's progress bar when `groups` are more than `MANY_GROUPS`: how
    many compile (≈ `FIT_COMPILE_S` s each) and what splits runs into groups; else empty."""
    n = len(groups or ())  # (None: a test's stand-in for the residuals has no groups)
    if n <= MANY_GROUPS:
        return ""
    return (
        f"compiling {n} groups (≈ {FIT_COMPILE_S:.0f} s each): the runs differ in "
        "length or sample interval (intervals within 1e-6 or the runs' jitter count as one)"
    )


FIT_EVALUATIONS = 40.0
"""Residual-and-Jacobian evaluations per compile, as `merge_buckets` weighs them against
compiling: a fit makes ≈ 12 (its Levenberg–Marquardt steps, the weights, the covariance);
this counts three fits per session."""

FIT_MERGED_STEPS_MAX = 2**13
"""Estimated solver steps beyond which `merge_buckets` merges no further."""

FIT_STEP_S = (1e-6, 1.5e-6)
"""Seconds per solver step of one evaluation of a group's residuals and Jacobian, fixed + per
run (2-core CPU, fitted to a 12-h designed plan's layouts of 7 and 2 groups; measured by
`benchmarks/fit_group_layouts.py`: 80, 131 and 410 ms per evaluation for 7, 3 and 2)."""


def steps_estimate(seconds: float, rate_rad_s: float) -> float:
    """Accepted steps of the averaged model over `seconds` at a table rate [rad/s]
    (`hrgjax._cost.steps_per_s` at the nominal angular gain)."""
    from .._cost import steps_per_s

    return seconds * steps_per_s(abs(rate_rad_s) * K_E_NOMINAL)


def _extend(x: np.ndarray, length: int, linear: bool) -> np.ndarray:
    """(R, N, …) → (R, length, …): continued linearly from the last two samples (`linear`)
    or held at the last."""
    n = x.shape[1]
    if n == length:
        return x
    k = np.arange(1, length - n + 1, dtype=float).reshape((1, -1) + (1,) * (x.ndim - 2))
    step = x[:, -1:] - x[:, -2:-1] if linear else 0.0 * x[:, -1:]
    return np.concatenate([x, x[:, -1:] + k * step], axis=1)


def _knots(n: int, length: int, step: int, count: int) -> np.ndarray:
    """`count` knot indices of a run of `n` samples padded to `length`: every `step` samples
    and its last sample (so the profile on the run itself is the unpadded one), then as many
    more as `count` asks, in the padded tail first, else in the widest gaps."""
    knots = set(np.arange(0, n, step).tolist()) | {n - 1}
    if length > n:
        knots.add(length - 1)
    while len(knots) < count:
        k = np.array(sorted(knots))
        gaps = np.diff(k)
        tail = k[1:] > n - 1
        pick = np.where(tail & (gaps > 1), gaps, 0)
        if not pick.any():
            pick = np.where(gaps > 1, gaps, 0)
        i = int(np.argmax(pick))
        knots.add(int(k[i] + gaps[i] // 2))
    return np.array(sorted(knots))


class Group(eqx.Module):
    """Runs of one padded length and sample interval, stacked for one vmap of the
    simulator. Static runs are reduced as one window, moving runs as windows of `window_s`
    (`n_move` samples), ramps (at rest, the temperature moving) as windows of
    `RAMP_WINDOW_S` (`n_ramp` samples; the last may be partial); windows past a run's own
    end carry zero weight."""

    t: jax.Array  # (R, L) sample times [s], padded
    theta0: jax.Array  # (R,) measured initial angle [rad]
    t_knots: jax.Array  # (R, K) profile knots [s]
    rate: jax.Array  # (R, K) [rad/s]
    temperature: jax.Array  # (R, K) [°C]
    accel: jax.Array  # (R, K, 3) [g]
    measured_static: jax.Array  # (Rs,) window rates [rad/s]
    static_mask: jax.Array  # (Rs, L) 1 on the run's own samples
    static_weight: jax.Array  # (Rs,) √(window length / WEIGHT_WINDOW_S)
    measured_moving: jax.Array  # (Rm, Wm)
    moving_valid: jax.Array  # (Rm, Wm) 1 for whole windows inside the run
    measured_ramp: jax.Array  # (Rr, Wr)
    ramp_mask: jax.Array  # (Rr, L)
    ramp_weight: jax.Array  # (Rr, Wr) √(window length / 60 s), 0 for windows < 4 samples
    static_idx: tuple = eqx.field(static=True)
    moving_idx: tuple = eqx.field(static=True)
    ramp_idx: tuple = eqx.field(static=True)
    n_move: int = eqx.field(static=True)
    n_ramp: int = eqx.field(static=True)


def _windows(xp, a, n: int, partial: bool):
    """(R, L) → (R, W, n): consecutive windows of `n` samples; the samples past the last
    whole window dropped, or (`partial`) kept in one more window padded with zeros."""
    r, length = a.shape
    w = -(-length // n) if partial else length // n
    if w * n > length:
        a = xp.concatenate([a, xp.zeros((r, w * n - length), dtype=a.dtype)], axis=1)
    return a[:, : w * n].reshape(r, w, n)


def masked_slopes(xp, t, y, mask, n, partial=False):
    """Least-squares slopes of `y` over consecutive windows of `n` samples of (R, L) arrays
    (`_windows`), each over its samples with `mask` 1 (`reduce`'s slope); (R, W). Windows
    without 2 such samples give 0."""
    t, y, m = (_windows(xp, a, n, partial) for a in (t, y, mask))
    return least_squares_slope(xp, t, y, m)[0]


def fit_groups(data: MeasuredData, window_s: float, k_e: float) -> list[Group]:
    """The runs of `data` as the fit's compiled groups (`Group`): one per run length and
    sample interval that `SHARED_LENGTH_RUNS` runs share, rarer lengths padded to the next
    power of two, neighbouring lengths merged where cheaper (`merge_buckets`); rotations in
    `window_s` windows, rates over the nominal angular gain `k_e`.

    **Raises:** `ValueError` for a run of fewer than 4 samples."""
    stacks = data.stacked()
    for stack in stacks:
        if stack.n_samples < 4:
            raise ValueError(
                f"run {int(stack.run[0])} has {stack.n_samples} samples; reduction needs at "
                "least 4 per window"
            )
    buckets: dict[tuple[int, float], list] = {}
    short: set[tuple[int, float]] = set()
    for stack in stacks:
        n = stack.n_samples
        # runs shorter than a moving window keep their length (reduced as one window)
        is_short = n < max(int(round(window_s / stack.dt)), 4)
        length = n if is_short or len(stack) >= SHARED_LENGTH_RUNS else ladder(n)
        key = (length, stack.dt)  # one value per interval class (`MeasuredData.stacked`)
        buckets.setdefault(key, []).append(stack)
        if is_short:
            short.add(key)
    merged = merge_buckets(buckets, short)
    return [_group(stacks, length, window_s, k_e) for length, stacks in merged]


def merge_buckets(buckets, short) -> list[tuple[int, list]]:
    """The buckets `{(length, dt): [RunStack, …]}` as `[(padded length, stacks), …]`, one per
    compiled group. Buckets of one sample interval, sorted by length, run as one group
    (padded to the longest) where compiling another group's simulator and Jacobian
    (`FIT_COMPILE_S`) costs more than the steps the shorter runs are simulated on for over a
    fit's evaluations (`FIT_EVALUATIONS`, each with its tangents); runs shorter than a window
    stay apart (`short`: their keys)."""
    out = []
    for dt in sorted({dt for _, dt in buckets}):
        keys = sorted(k for k in buckets if k[1] == dt)

        def cost(i, j, keys=keys, dt=dt):
            if any(k in short for k in keys[i:j]) and j - i > 1:
                return math.inf
            stacks = [st for k in keys[i:j] for st in buckets[k]]
            rows = sum(len(st) for st in stacks)
            rate = max(float(np.max(np.abs(st.rate))) for st in stacks)
            steps = steps_estimate((keys[j - 1][0] - 1) * dt, rate)
            if j - i > 1 and steps > FIT_MERGED_STEPS_MAX:
                return math.inf
            run = steps * (FIT_STEP_S[0] + rows * FIT_STEP_S[1])
            return FIT_COMPILE_S + FIT_EVALUATIONS * run

        for i, j in partition(len(keys), cost):
            out.append((keys[j - 1][0], [st for k in keys[i:j] for st in buckets[k]]))
    return out


def _group(stacks, length: int, window_s: float, k_e: float) -> Group:
    """One `Group` of `stacks` (same sample interval) padded to `length` samples."""
    dt = stacks[0].dt
    n_move = min(max(int(round(window_s / dt)), 4), length)
    n_ramp = min(max(int(round(RAMP_WINDOW_S / dt)), 4), length)
    rows = []  # per run: (n, t, theta, rate, temperature, accel, kind)
    for st in stacks:
        # a ramp: at rest, the temperature moving by more than a thermometer's noise
        ramp = st.static & (np.ptp(st.temperature, axis=1) > TEMPERATURE_TOLERANCE_C)
        kind = np.where(~st.static, "moving", np.where(ramp, "ramp", "static"))
        ext = (
            _extend(st.t, length, True),
            _extend(st.wave_angle, length, False),
            _extend(st.rate, length, False),
            _extend(st.temperature, length, True),
            _extend(st.accel, length, False),
        )
        rows += [(st.n_samples, *(a[i] for a in ext), kind[i]) for i in range(len(st))]
    # knots: every window's start (the shortest window any run here is cut into) and the end
    kinds = {r[-1] for r in rows}
    step = min([length - 1] + [n_move] * ("moving" in kinds) + [n_ramp] * ("ramp" in kinds))
    count = max(_knots(r[0], length, step, 0).size for r in rows)
    knots = np.stack([_knots(r[0], length, step, count) for r in rows])
    t = np.stack([r[1] for r in rows])
    theta = np.stack([r[2] for r in rows])
    n_of = np.array([r[0] for r in rows])
    own = (np.arange(length)[None, :] < n_of[:, None]).astype(float)  # (R, L)
    pick = lambda a: np.stack([r[a][k] for r, k in zip(rows, knots, strict=True)])
    idx = {k: np.array([i for i, r in enumerate(rows) if r[-1] == k], int) for k in kinds}
    idx = {k: idx.get(k, np.zeros(0, int)) for k in ("static", "moving", "ramp")}
    s, m, r = idx["static"], idx["moving"], idx["ramp"]
    # moving: whole windows inside the run (as `reduce`); ramps: windows tiling the run,
    # the last partial one kept when it has ≥ 4 samples
    n_whole = n_of[m] // n_move
    moving_valid = (np.arange(length // n_move)[None, :] < n_whole[:, None]).astype(float)
    in_win = _windows(np, own[r], n_ramp, True).sum(axis=-1)
    ramp_weight = np.where(in_win >= 4, np.sqrt(np.maximum(in_win - 1, 0) * dt / WEIGHT_WINDOW_S),
                           0.0)  # fmt: skip
    slopes = lambda sel, mask, n, p=False: -masked_slopes(np, t[sel], theta[sel], mask, n, p) / k_e
    return Group(
        t=device(t),
        theta0=device(theta[:, 0]),
        t_knots=device(np.take_along_axis(t, knots, axis=1)),
        rate=device(pick(3)),
        temperature=device(pick(4)),
        accel=device(pick(5)),
        measured_static=device(slopes(s, own[s], length)[:, 0]),
        static_mask=device(own[s]),
        static_weight=device(np.sqrt((n_of[s] - 1) * dt / WEIGHT_WINDOW_S)),
        measured_moving=device(slopes(m, own[m], n_move) * moving_valid),
        moving_valid=device(moving_valid),
        measured_ramp=device(slopes(r, own[r], n_ramp, True) * (ramp_weight > 0)),
        ramp_mask=device(own[r]),
        ramp_weight=device(ramp_weight),
        static_idx=tuple(s.tolist()),
        moving_idx=tuple(m.tolist()),
        ramp_idx=tuple(r.tolist()),
        n_move=n_move,
        n_ramp=n_ramp,
    )


def window_weights(groups) -> dict:
    """The weights of the fit's windows, host arrays in the order of
    `_physical_fit.window_residuals`: {True: each at-rest residual's √(length / 60 s) (0: no
    window), False: 1 for a moving window inside its run, else 0}."""
    rest, moving = [], []
    for g in groups:
        rest += [np.asarray(g.static_weight), np.asarray(g.ramp_weight).ravel()]
        moving += [np.asarray(g.moving_valid).ravel()]
    return {True: np.concatenate(rest), False: np.concatenate(moving)}
