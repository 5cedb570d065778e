r"""The continuous records' model (DISCOVERY.md §2.2 b): the superset parameter layout, runs
stacked by length, the model's wave angle simulated by a fixed-step Bogacki–Shampine solve,
the whitened increment residuals, and the compiled programs that fit them (residual and
Jacobian, Levenberg–Marquardt on all training runs or on each run alone).

[`ContinuousProblem`][hrgjax.discovery.continuous.ContinuousProblem] is the search's side of
them; everything here is a function of a [`Layout`][hrgjax.discovery.records.Layout], a scaled
parameter vector `z` and groups of [`Runs`][hrgjax.discovery.records.Runs] (and, in a mixed
log, [`Windows`][hrgjax.discovery.records.Windows]). What an effect adds to the simulated
rate, and what it reads of a whole record before the solve (`thermal_lag`'s lagged
temperature: [`Effect.record`][hrgjax.discovery.effects.Effect]), comes from its catalogue
entry.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .. import _checks
from .._compiled import Unchecked, program
from . import stats
from .effects import CATALOGUE, Covariates, check_names, pattern_rate, readout_angle, window_rate
from .noise import NoiseModel

STEP_S = 5.0
"""Solver step [s]: Bogacki–Shampine (3rd order) steps on the samples nearest every
`STEP_S`. The covariates are interpolated between samples, so their corners fall on step
ends; Bosh3's solution weights no stage at the step's end (FSAL), so a corner never leaks
into the step before it (Tsit5's sixth stage, at the end with weight 2.3, would)."""

GAP_BLOCKS = 3.0
"""A continuous run with an interval between samples of `GAP_BLOCKS` × its median block Δ
or longer (a logger stall) is refused (`check_no_stall`): its whitening takes every block
as the median Δ (the block across a 300-s stall, carrying the run bias × the whole gap, is
weighted as an ordinary one) and one solver step spans the gap (1.65e-4 rad of solver error
across a 291-s gap in a turning run, 34× the white σ). A null log with a 300-s stall in a
held-out run read `unexplained`: held-out χ² 14 386 against 525 under the exact covariance
of its uneven blocks (audit 2026-11-30, docs/discovery.md)."""


class Layout:
    """The superset parameter vector: every parameter of `names` in scaled units
    (value / scale), so optimisers see O(1) numbers."""

    def __init__(self, names):
        self.names = check_names("Layout", names)
        self.slices, self.scales, self.regular, start = {}, [], [], 0
        for n in self.names:
            effect = CATALOGUE[n]
            self.slices[n] = slice(start, start + effect.size)
            self.scales += [p.scale for p in effect.params]
            self.regular += [p.regular for p in effect.params]
            start += effect.size
        self.size = start
        self.scale = np.asarray(self.scales)

    def __repr__(self):  # also the static value's key in the exported programs
        return f"Layout({self.names!r})"

    def __hash__(self):
        return hash(self.names)

    def __eq__(self, other):
        return isinstance(other, Layout) and other.names == self.names

    def null(self, k_e):
        """Scaled vector at the null (nonregular parameters at their typical size), with
        the angular gain at `k_e`."""
        _checks.finite_number("Layout.null: k_e", k_e, "–, the angular gain")
        z = np.asarray([0.0 if r else 1.0 for r in self.regular])
        if "angular_gain" in self.slices:
            z[self.slices["angular_gain"].start] = k_e / self.scale[self.slices["angular_gain"]][0]
        return z

    def unpack(self, z):
        """{effect: physical parameters} from a scaled vector."""
        p = z * jnp.asarray(self.scale)
        return {n: p[s] for n, s in self.slices.items()}

    def index(self, name, which=None):
        """Positions of an effect's (regular, or all) parameters in the vector."""
        s = self.slices[name]
        idx = range(s.start, s.stop)
        return [i for i in idx if which is None or self.regular[i] == which]


class Runs(eqx.Module):
    """Runs of one length, stacked: samples, covariates and block boundaries."""

    t: jax.Array  # (R, n) time [s]
    theta: jax.Array  # (R, n) measured wave angle [rad]
    rate: jax.Array  # (R, n) table rate [rad/s]
    temp: jax.Array  # (R, n) temperature [°C]
    accel: jax.Array  # (R, n) specific force along the axis [g]
    amp: jax.Array
    quad: jax.Array
    bidx: jax.Array  # (K+1,) sample indices of the block boundaries
    steps: jax.Array  # sample indices of the solver's steps
    whiten: jax.Array  # (R, K, K) L⁻¹ of each run's increment covariance
    run: tuple = eqx.field(static=True)  # run ids


class Windows(eqx.Module):
    """The dwell runs of a mixed log (constant temperature and rate), as windows: measured
    pattern rate `y` [rad/s], its standard error `sigma` [rad/s] and the window covariates
    (as the dwell search has them), `arc` [rad] the arc the pattern sweeps in each window (the
    leftover shapes' window gain, as on dwell grids); `run`: each window's run id.
    `session`: the windows are one switch-on of their own beside continuous records, whose
    bias is a draw of the run-to-run spread like each record's, not their common `bias`: it
    is profiled out of their residual (`_window_residual`). `reference`: for held-out windows
    of that session, the training windows, whose offset they take (not their own mean: that
    would hide a held-out dwell run that is off)."""

    y: jax.Array
    sigma: jax.Array
    cov: Covariates
    arc: jax.Array
    run: tuple = eqx.field(static=True)
    session: bool = eqx.field(static=True, default=False)
    reference: Windows | None = None


def _window_rate(layout: Layout, z, c: Covariates):
    """Model pattern rate of each dwell window [rad/s]
    ([`window_rate`][hrgjax.discovery.effects.window_rate]: the readout terms to all
    orders, as the dwell search's refinement)."""
    return window_rate(layout.unpack(z), c)


def _window_residual(layout: Layout, z, g: Windows):
    """Measured less model pattern rate of each window of `g` [rad/s]; for a session of its
    own (`g.session`) less its σ-weighted mean — the least-squares value of a free offset
    (the session's switch-on bias less the records' mean bias), so that no effect is fitted
    to it: with the session tied to the records' `bias`, that offset (≈ σ_b) had only
    `rate_scale_factor` to go to (with k_e it moves the records turning at 2 °/s and not
    the ±5 °/s windows: 2.8 ± 0.44 ppm/(°/s)², 6σ, on a bench log with none)."""
    r = g.y - _window_rate(layout, z, g.cov)
    if g.session:
        ref = g if g.reference is None else g.reference
        rr = r if g.reference is None else ref.y - _window_rate(layout, z, ref.cov)
        w = 1.0 / ref.sigma**2
        r = r - jnp.sum(w * rr) / jnp.sum(w)
    return r


def _one_run(layout: Layout, z, t, theta, rate, temp, accel, amp, quad, bidx, steps):
    """Model wave angle (with readout terms) at the block boundaries of one run."""
    params = layout.unpack(z)
    rate_params = {n: p for n, p in params.items() if CATALOGUE[n].where == "rate"}
    # the record's covariates at its samples (interpolated between them in the solve); an
    # effect that reads the whole record first puts its own in (`Effect.record`)
    samples = {"rate": rate, "temperature": temp, "temperature_lagged": temp,
               "amplitude": amp, "quadrature": quad, "accel_z": accel}  # fmt: skip
    for name, p in params.items():
        if CATALOGUE[name].record is not None:
            samples = samples | CATALOGUE[name].record(p, t, samples)
    n = t.shape[0]

    def field(s, y, args):
        i = jnp.clip(jnp.searchsorted(t, s, side="right") - 1, 0, n - 2)
        h = t[i + 1] - t[i]
        f = jnp.clip((s - t[i]) / h, 0.0, 1.0)
        lerp = lambda v: v[i] + (v[i + 1] - v[i]) * f
        c = Covariates(
            theta=y,
            temperature_rate=(temp[i + 1] - temp[i]) / h,
            t_run=s - t[0],
            **{k: lerp(v) for k, v in samples.items()},
        )
        return pattern_rate(rate_params, c)

    out = bosh3_path(field, t[steps], theta[0], t[bidx])
    readouts = {n: p for n, p in params.items() if CATALOGUE[n].where == "readout"}
    if readouts:
        out = out + readout_angle(readouts, Covariates(theta=out, temperature=temp[bidx]))
    return out


def bosh3_path(field, steps, y0, save_t):
    """Bogacki–Shampine (3rd order) from `y0` over the fixed steps `steps` (their ends),
    the solution at `save_t` by each step's cubic Hermite interpolant — what
    `diffrax.diffeqsolve(ODETerm(field), Bosh3(), stepsize_controller=StepTo(steps),
    saveat=SaveAt(ts=save_t))` computes (the same tableau, FSAL last stage and dense output,
    a save time on a step's end taken from the step before; equal to round-off), as one
    `lax.scan`: a fit traces this solve several times per program (Levenberg–Marquardt,
    `jax.jacfwd`, `vmap` over runs); one run's model traced in 1.6 s through diffrax's
    general loop, 0.8 s as this scan, and runs faster (benchmarks/README.md, the bench log's
    `discover`)."""
    f0 = field(steps[0], y0, None)

    def step(carry, ends):
        y, k1 = carry
        t0, t1 = ends
        h = t1 - t0
        k2 = field(t0 + 0.5 * h, y + 0.5 * h * k1, None)
        k3 = field(t0 + 0.75 * h, y + 0.75 * h * k2, None)
        y1 = y + h * (2 / 9 * k1 + 1 / 3 * k2 + 4 / 9 * k3)
        k4 = field(t1, y1, None)  # FSAL: the next step's first stage
        return (y1, k4), (y, y1, h * k1, h * k4)

    _, (ya, yb, ka, kb) = jax.lax.scan(step, (y0, f0), (steps[:-1], steps[1:]))
    j = jnp.clip(jnp.searchsorted(steps, save_t, side="left") - 1, 0, steps.shape[0] - 2)
    s = (save_t - steps[j]) / (steps[j + 1] - steps[j])
    y0s, y1s, k0, k1 = ya[j], yb[j], ka[j], kb[j]
    a = k0 + k1 + 2 * y0s - 2 * y1s
    b = -2 * k0 - k1 - 3 * y0s + 3 * y1s
    return ((a * s + b) * s + k0) * s + y0s


def _increments(layout, z, g: Runs):
    model = jax.vmap(lambda *a: _one_run(layout, z, *a, g.bidx, g.steps))(
        g.t, g.theta, g.rate, g.temp, g.accel, g.amp, g.quad
    )
    return jnp.diff(model, axis=1)


def _measured(g: Runs):
    return jnp.diff(g.theta[:, g.bidx], axis=1)


def _whitened(layout, z, groups):
    """Whitened increment residuals of every run of every group, concatenated."""
    out = []
    for g in groups:
        if isinstance(g, Windows):
            out.append(_window_residual(layout, z, g) / g.sigma)
            continue
        r = _measured(g) - _increments(layout, z, g)
        out.append(jnp.einsum("rkl,rl->rk", g.whiten, r).ravel())
    return jnp.concatenate(out)


def _anonymous(groups):
    """`groups` without their run ids: the ids are static fields, and a compiled program
    keyed on them would be traced and compiled again for every run of the same length."""
    return [dataclasses.replace(g, run=()) if g.run else g for g in groups]


def _width(m: int) -> int:
    """Compiled basis width for m columns: 4, 8, then multiples of 8 (one and two columns,
    the common case, share the width-4 programs: a cold search compiles fewer of them)."""
    return 4 if m <= 4 else 8 if m <= 8 else -(-m // 8) * 8


def _padded(basis, minimum: int = 1):
    """`basis` (P, m) with zero columns up to `_width(m)`: every fit and Jacobian of the
    search then runs on a few compiled widths instead of one program per candidate's
    parameter count. A zero column moves nothing: its Jacobian column is zero and its
    Levenberg–Marquardt step is zero."""
    basis = np.asarray(basis, float)
    m = basis.shape[1]
    return jnp.asarray(np.pad(basis, ((0, 0), (0, _width(max(m, minimum)) - m)))), m


def residual_and_jacobian(layout, z, basis, groups):
    """Whitened residual at `z` and its forward-mode derivative along the columns of
    `basis` (P, m): the sensitivities to m chosen parameters."""
    padded, m = _padded(basis)
    r, j = _residual_and_jacobian_compiled(layout, jnp.asarray(z), padded, _anonymous(groups))
    return r, j[:, :m]


def raw_residuals(layout, z, groups):
    """Unwhitened increment residuals per group [rad], shape (R, K) each (window groups:
    pattern-rate residuals [rad/s], shape (W,))."""
    return _raw_residuals_compiled(layout, z, _anonymous(groups))


def lm(layout, basis, z0, groups):
    """Levenberg–Marquardt over the parameters picked by `basis` (P, m), from `z0`."""
    padded, _ = _padded(basis, minimum=8)  # the nominal model's 4 and a candidate's 5–6
    return _lm_compiled(layout, padded, jnp.asarray(z0), _anonymous(groups))


def fit_each_run(layout, basis, z0, group):
    """Levenberg–Marquardt over the parameters picked by `basis` (P, m) on each run of
    `group` alone, from `z0`: `(z (R, P), converged (R,), whitened Jacobian (R, n, m))`."""
    padded, m = _padded(basis)
    z, ok, j = _per_run_compiled(layout, padded, jnp.asarray(z0), _anonymous([group])[0])
    return z, ok, j[..., :m]


def per_run_fits(layout, basis, z, groups, idx):
    """Each training run's own fit of the parameters `basis` picks (indices `idx` of the
    scaled vector; the rest held at `z`), `fit_each_run`; a dwell run is one grid point:
    none. **Returns:** `(fits, unconverged)`: `fits`, `(run id, its values (len(idx),), its
    information JᵀJ in them)` for every run whose fit converged, in run order;
    `unconverged`, the sorted ids of the runs whose fit did not (not dropped silently:
    `ContinuousProblem.consistency` reports them)."""
    out, unconverged = [], []
    for g in groups:
        if not isinstance(g, Windows):
            zs, oks, js = (np.asarray(a) for a in fit_each_run(layout, basis, jnp.asarray(z), g))
            for i, run in enumerate(g.run):
                if bool(oks[i]):
                    out.append((int(run), zs[i][idx], js[i].T @ js[i]))
                else:
                    unconverged.append(int(run))
    return sorted(out, key=lambda f: f[0]), sorted(unconverged)


LEVEL_PARTS = 6
"""Consecutive parts of each run whose rates the per-run consistency's noise level is read
along (`run_level`)."""


def rate_columns(groups, parts: int = 1) -> tuple[np.ndarray, list[int]]:
    """Whitened columns (rows of `groups` in residual order) of each continuous run's
    constant rate of 1 rad/s — with `parts` > 1, over each of that many consecutive parts of
    its blocks (near equal counts), zero elsewhere. Window rows are zero. **Returns** `(U, the
    run id of each column)`."""
    stats.check_count("rate_columns", "parts", parts)
    rows, blocks, runs = 0, [], []
    for g in groups:
        if isinstance(g, Windows):
            rows += len(g.run)
            continue
        bidx, t, w = np.asarray(g.bidx), np.asarray(g.t), np.asarray(g.whiten)
        k = w.shape[-1]
        for i, run in enumerate(g.run):
            delta = float(np.median(np.diff(t[i, bidx])))  # as `stack_runs` whitens
            for part in np.array_split(np.arange(k), parts):
                blocks.append((rows, w[i][:, part] @ np.full(part.size, delta)))
                runs.append(int(run))
            rows += k
    u = np.zeros((rows, len(runs)))
    for c, (at, col) in enumerate(blocks):
        u[at : at + col.size, c] = col
    return u, runs


def run_level(r, j, own, groups, parts: int = LEVEL_PARTS) -> tuple[float, int]:
    r"""The noise level (variance over the noise model's) that a fit's whitened residual `r`
    on the training runs `groups` shows at the scale of a per-run refit: along the rates
    over `parts` consecutive parts of each run, beyond the span of the fit's Jacobian `j`,
    each run's constant and, run by run, the columns `own` of `j` (the refitted effect's:
    a real run-to-run change of it is what the consistency tests, not noise).
    ([`stats.level_beyond`][hrgjax.discovery.stats.level_beyond]: `(level, dof)`.) The
    per-run refits' information comes from the noise model, whose slow part (angle random
    walk, Gauss–Markov rate) is read from the still stretches alone: on six 25-min ramps it
    scattered ×4 between seeds (0.0007–0.0029 °/√h, truth 0.002), and the χ² of a true,
    exactly catalogued thermal rate fell below p = 0.01 in 9 of 100 seeds (audit
    2026-11-30); judged at this level, F-distributed (`repeats`)."""
    r, j = stats.rows_of("run_level", r, j=j)
    u, _ = rate_columns(groups)
    s, _ = rate_columns(groups, parts)
    if u.shape[0] != r.size or not all(0 <= c < j.shape[1] for c in own):
        raise ValueError(f"run_level: r {r.shape}, j {j.shape} and own {list(own)} do not fit groups of {u.shape[0]} rows")  # fmt: skip
    per_run = [j[:, c] * (u[:, i] != 0) for c in own for i in range(u.shape[1])]
    return stats.level_beyond(np.asarray(r, float), np.column_stack([j, u, *per_run]), s)


def _rank(info):
    return int(np.linalg.matrix_rank(info, tol=1e-9 * np.trace(info))) if info.any() else 0


def _pooled(members):
    """One unit of the agreement: `(run ids, estimate, information)` of consecutive runs
    pooled — information summed, estimate their information-weighted combination (the
    group's own refit to first order)."""
    if len(members) == 1:
        run, p, info = members[0]
        return (run,), p, info
    info = sum(c for _, _, c in members)
    p = np.linalg.pinv(info, rcond=1e-9, hermitian=True) @ sum(c @ q for _, q, c in members)
    return tuple(run for run, _, _ in members), p, info


def repeats(fits, pooled, resolves=1.0, level=None, windows=None):
    r"""Whether an effect's estimates repeat run by run (DISCOVERY.md §2.1, "evidence must
    repeat"), from `fits` (`per_run_fits`: each run's $p_i$ and information $C_i$, in run
    order) and the pooled estimate $\bar p$. The units compared are the runs that *resolve*
    it ($s_i = \bar p^\top C_i\bar p \ge$ `resolves`²) when at least two do; otherwise
    consecutive runs pooled into groups, each closed as soon as it resolves it ($\sum s_i$,
    cut greedily: the most groups a split into consecutive parts allows), a last part
    that falls short joining the group before it; a group's estimate is
    $C_g^{+}\sum_i C_ip_i$ with $C_g = \sum_i C_i$. Consecutive, not interleaved: an
    effect that changes sign over the campaign splits into groups that disagree. Over the
    units: the χ² $\sum_u (p_u-\bar p)^\top C_u(p_u-\bar p)$ on Σ rank C_u − q
    degrees of freedom, and the share pointing the same way ($p_u^\top C_u\bar p > 0$).
    With `level` = `(s², ν)` (`run_level`: the noise level the residual shows at the runs'
    scale, read from ν degrees of freedom) the p-value is the F(dof, ν) tail of χ²/dof/s²
    (the χ² tail without it). `windows`: the whitened Jacobian rows $J_w$ of a mixed log's
    training dwell windows in the effect's parameters (one session, not a run, of
    information $C_w = J_w^\top J_w$); when $\bar p^\top C_w\bar p$ exceeds the runs'
    $\sum_i s_i$ the evidence lies in the windows and the runs' signs do not test it (a
    readout mismatch the rotations see at 10⁶ and three ramps at ≈ 1, whose refits took
    what the missing temperature laws left: agreement 0, refused): the check is not made.

    **Returns:** `{"p_value", "dof", "agreement", "units": [[run, …], …], "reason",
    "noise_level": [s², ν] or None}`; with
    fewer than two units (no split of the runs into two parts each resolving it) the
    check cannot be made: `agreement` None and `reason` says why (else None)."""
    pooled = stats.real_array("repeats", "pooled", pooled, (None,), "the estimate, shape (q,)")
    _checks.check_number("repeats: resolves", resolves, "σ")
    _checks.check_values("repeats: resolves", resolves, _checks.FINITE_NONNEGATIVE, "a finite number >= 0 [σ]")  # fmt: skip
    level = level if level is None else stats.check_level("repeats", level)
    if any(np.shape(p) != pooled.shape or np.shape(c) != pooled.shape * 2 for _, p, c in fits):
        raise ValueError(f"repeats: each of fits must be (run, estimate {pooled.shape}, information {pooled.shape * 2}), as pooled")  # fmt: skip
    if windows is not None:
        stats.real_array("repeats", "windows", windows, (None, pooled.size), "rows, shape (W, q)")
    need = resolves**2
    strength = [float(pooled @ c @ pooled) for _, _, c in fits]
    strong = [f for f, s in zip(fits, strength, strict=True) if s >= need]
    in_windows = 0.0 if windows is None else float(np.sum((np.asarray(windows) @ pooled) ** 2))
    if in_windows > sum(strength):  # the windows carry it: no unit of the runs is asked
        units = []
    elif len(strong) >= 2:
        units = [_pooled([f]) for f in strong]
    else:
        groups, part, total = [], [], 0.0
        for f, s in zip(fits, strength, strict=True):
            part, total = part + [f], total + s
            if total >= need:
                groups, part, total = groups + [part], [], 0.0
        if part and groups:
            groups[-1] += part
        units = [_pooled(g) for g in groups]
    reason = None
    if len(units) < 2:
        reason = (
            f"the dwell windows carry it (p̄ᵀC p̄ = {in_windows:.3g} against the runs' "
            f"{sum(strength):.3g}): the runs' refits do not test it" if in_windows > sum(strength)
            else "no training run's refit converged" if not fits
            else f"the training runs together do not resolve it (Σ p̄ᵀC_i p̄ = {sum(strength):.3g})"
            if sum(strength) < need
            else "no two parts of the training runs each resolve it: one part carries it"
        )  # fmt: skip
        units = []
    stat = sum(float((p - pooled) @ c @ (p - pooled)) for _, p, c in units)
    dof = sum(_rank(c) for _, _, c in units) - pooled.size
    agree = sum(float(p @ c @ pooled) > 0 for _, p, c in units)
    p = stats.chi2_sf(stat, dof) if dof > 0 else None
    if p is not None and level is not None and level[1] > 0:  # s² ≤ 0 (round-off): no test
        p = stats.f_sf(stat / dof / level[0], dof, int(level[1])) if level[0] > 0 else 1.0
    return {
        "p_value": p,
        "noise_level": None if level is None else [float(level[0]), int(level[1])],
        "dof": max(dof, 0),
        "agreement": agree / len(units) if units else None,
        "units": [list(runs) for runs, _, _ in units],
        "reason": reason,
    }


@program(check=Unchecked())
def _per_run_compiled(layout, basis, z0, group):
    """`fit_each_run`: one program for every run of a group (`vmap` over the runs)."""
    per_run = ("t", "theta", "rate", "temp", "accel", "amp", "quad", "whiten")

    def one(*arrays):
        g = Runs(**{f: a[None] for f, a in zip(per_run, arrays, strict=True)},
                 bidx=group.bidx, steps=group.steps, run=())  # fmt: skip
        z, ok = _levenberg_marquardt(layout, basis, z0, [g])
        return z, ok, _jacobian(layout, z, basis, [g])[1]

    return jax.vmap(one)(*(getattr(group, f) for f in per_run))


def _jacobian(layout, z, basis, groups):
    """Whitened residual at `z` and its forward-mode derivative along the columns of
    `basis` (P, m) (traced; `residual_and_jacobian` is the compiled entry point)."""
    fn = lambda u: _whitened(layout, z + basis @ u, groups)
    u0 = jnp.zeros(basis.shape[1])
    return fn(u0), jax.jacfwd(fn)(u0)


def _levenberg_marquardt(layout, basis, z0, groups):
    """Levenberg–Marquardt over the parameters picked by `basis` (P, m), from `z0`:
    `(z, converged)` (traced; `lm` is the compiled entry point)."""
    fn = lambda u, _: _whitened(layout, z0 + basis @ u, groups)
    sol = optx.least_squares(
        fn,
        optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8),
        jnp.zeros(basis.shape[1]),
        max_steps=256,
        throw=False,
    )
    return z0 + basis @ sol.value, sol.result == optx.RESULTS.successful


@program(check=Unchecked())
def _residual_and_jacobian_compiled(layout, z, basis, groups):
    """Whitened residual at `z` and its forward-mode derivative along the columns of
    `basis` (P, m): the sensitivities to m chosen parameters."""
    return _jacobian(layout, z, basis, groups)


@program(check=Unchecked())
def _raw_residuals_compiled(layout, z, groups):
    """Unwhitened increment residuals per group [rad], shape (R, K) each."""
    return [
        _window_residual(layout, z, g)
        if isinstance(g, Windows)
        else _measured(g) - _increments(layout, z, g)
        for g in groups
    ]


@program(check=Unchecked())
def _lm_compiled(layout, basis, z0, groups):
    """Levenberg–Marquardt over the parameters picked by `basis` (P, m), from `z0`."""
    return _levenberg_marquardt(layout, basis, z0, groups)


def block_index(n: int, m: int) -> np.ndarray:
    """Sample indices every `m` of `n` samples, the last sample always included."""
    n, m = stats.check_count("block_index", "n", n), stats.check_count("block_index", "m", m)
    idx = np.arange(0, n, m)
    if idx[-1] != n - 1:
        idx = np.r_[idx, n - 1]
    return idx


def check_no_stall(t, bidx, run) -> None:
    """Refuse a continuous run `run` (times `t` [s], block boundaries `bidx`) with an
    interval between samples of `GAP_BLOCKS` × its
    median block Δ or longer (a logger stall): one-line `ValueError` with the gap's start,
    length and the median block, and what to do."""
    delta = float(np.median(np.diff(t[bidx])))
    dt = np.diff(t)
    j = int(np.argmax(dt))
    if dt[j] >= GAP_BLOCKS * delta:
        raise ValueError(
            f"run {run} has a {dt[j]:.6g}-s interval with no samples from t = {t[j]:.6g} s "
            f"(its median block is {delta:.6g} s; intervals under {GAP_BLOCKS:g} blocks are taken): "
            "discovery whitens a continuous record's blocks as equal and solves the model "
            "across the gap in one step, so the block across it would read as an effect; "
            "split the run at the gap (give the part after it its own run id)"
        )


def stack_runs(stack, mask, noise: NoiseModel, block_s: float) -> Runs:
    """The runs `mask` of a stack of one length and sample interval
    (`MeasuredData.stacked`) as [`Runs`][hrgjax.discovery.records.Runs]:
    blocks of `block_s` [s] and solver steps of `STEP_S` in samples of the stack's interval,
    each run's increments whitened under `noise`. **Raises** `ValueError` for a run with a
    stall (`check_no_stall`)."""
    n = stack.n_samples
    m = max(1, int(round(block_s / stack.dt)))
    bidx = block_index(n, m)
    steps = block_index(n, max(1, int(round(STEP_S / stack.dt))))
    t = stack.t[mask]
    for ti, run in zip(t, stack.run[mask], strict=True):
        check_no_stall(ti, bidx, int(run))
    whiten = []
    for ti in t:
        delta = float(np.median(np.diff(ti[bidx])))
        cov = noise.increment_covariance(delta, bidx.size - 1)
        whiten.append(np.linalg.inv(np.linalg.cholesky(cov)))
    return Runs(
        t=jnp.asarray(t),
        theta=jnp.asarray(stack.wave_angle[mask]),
        rate=jnp.asarray(stack.rate[mask]),
        temp=jnp.asarray(stack.temperature[mask]),
        accel=jnp.asarray(stack.accel[mask][..., 2]),
        amp=jnp.asarray(stack.amplitude[mask]),
        quad=jnp.asarray(stack.quadrature[mask]),
        bidx=jnp.asarray(bidx),
        steps=jnp.asarray(steps),
        whiten=jnp.asarray(np.stack(whiten)),
        run=tuple(int(r) for r in stack.run[mask]),
    )


def whiten(raw, groups) -> np.ndarray:
    """Whitened residuals (concatenated) from per-group raw increment residuals (window
    groups: divided by their σ)."""
    out = [
        np.asarray(r) / np.asarray(g.sigma)
        if isinstance(g, Windows)
        else np.einsum("rkl,rl->rk", np.asarray(g.whiten), r).ravel()
        for g, r in zip(groups, raw, strict=True)
    ]
    return np.concatenate(out) if out else np.zeros(0)


def run_covariates(groups) -> dict[int, np.ndarray]:
    """Per continuous run: its mean dT/dt [°C/s] (end − start over the span), mean table
    rate [rad/s] and mean specific force along the axis [g]."""
    out = {}
    for g in groups:
        t, temp = np.asarray(g.t), np.asarray(g.temp)
        rate, accel = np.asarray(g.rate), np.asarray(g.accel)
        b0, b1 = int(g.bidx[0]), int(g.bidx[-1])
        for i, run in enumerate(g.run):
            span = t[i, b1] - t[i, b0]
            t_dot = (temp[i, b1] - temp[i, b0]) / span if span > 0 else 0.0
            out[int(run)] = np.array(
                [t_dot, np.mean(rate[i, b0 : b1 + 1]), np.mean(accel[i, b0 : b1 + 1])]
            )
    return out
