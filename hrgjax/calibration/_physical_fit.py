"""The physical fit's least squares: the model's window rates simulated and reduced as the
measured ones (`simulated_rates`), the weighted residuals and their Jacobian, the PI loops'
pull (`loop_pull`), Levenberg–Marquardt finished by reweighted Gauss–Newton (`fit_values`)
and the residual scatter of each kind of window (`scatter_per_dof`)."""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._compiled import Check, device, first_failure, program
from .._least_squares import least_squares_with_jacobian
from .._progress import bar
from ..profiles import Profile
from ..simulate import simulate
from ._physical_groups import Group, many_groups_note, masked_slopes, window_weights
from ._physical_model import NAMES, SCALE, model_gyro, true_angle


def simulated_rates(group: Group, values, k_e: float, plant=None):
    """Simulated window rates (static (Rs,), moving (Rm, Wm), ramp (Rr, Wr)) [rad/s] of one
    group, reduced as the measured ones; ideal loops, or the `plant`'s PI loops."""
    gyro = model_gyro(values, plant=plant)

    def one(t, theta0, t_knots, rate, temp, acc):
        theta_start = true_angle(gyro.at(temp[0]), theta0)
        prof = Profile(t=t_knots, rate=rate, temperature=temp, accel=acc,
                       wave_angle0=theta_start)  # fmt: skip
        rec = simulate(gyro, prof, ts=t, adjoint=diffrax.ForwardMode(), rtol=1e-9, atol=1e-12)
        return rec.wave_angle

    theta = jax.vmap(one)(group.t, group.theta0, group.t_knots, group.rate, group.temperature,
                          group.accel)  # fmt: skip
    length = group.t.shape[1]

    def slopes(idx, mask, n, partial=False):
        idx = np.asarray(idx, int)
        return -masked_slopes(jnp, group.t[idx], theta[idx], mask, n, partial) / k_e

    static = slopes(group.static_idx, group.static_mask, length)[:, 0]
    moving_mask = jnp.ones((len(group.moving_idx), length))
    moving = slopes(group.moving_idx, moving_mask, group.n_move) * group.moving_valid
    ramp = slopes(group.ramp_idx, group.ramp_mask, group.n_ramp, True)
    return static, moving, ramp


def window_residuals(groups, values, k_e):
    """The fit's residuals at `values`: {True: at-rest residuals (static and ramp windows,
    each × √(length / 60 s)), False: moving residuals} [rad/s], measured − simulated; 0
    where there is no window."""
    sims = [simulated_rates(g, values, k_e) for g in groups]
    rest, moving = [], []
    for g, (s, mv, r) in zip(groups, sims, strict=True):
        rest += [(g.measured_static - s) * g.static_weight]
        rest += [((g.measured_ramp - r) * g.ramp_weight).ravel()]
        moving += [(g.measured_moving - mv).ravel()]
    return {True: jnp.concatenate(rest), False: jnp.concatenate(moving)}


LOOP_PASSES = 2
"""Times a fit with a plant computes the loops' pull (`loop_pull`) and fits: at the starting
values, then at the first fit's values (the pull is ≈ 3e-5 of the rate and changes with the
fitted values at that order: a second pass leaves nothing the data can see)."""


@program(check=Check("PhysicalCompensator.fit (the PI loops' pull)"))
def loop_pull(groups, values, k_e, plant):
    """What the plant's PI loops add to every window rate (static, moving, ramp) [rad/s]
    beyond the ideal-loop model at `values`: the same runs simulated both ways. Subtracted
    from the measured rates, it lets the fit run the ideal-loop model (cheap: the PI loops
    take ≈ 20× the ideal loops' time per run, `benchmarks/physical_plant.py`) and still fit the
    physical parameters."""
    out = []
    for g in groups:
        pi = simulated_rates(g, values, k_e, plant)
        ideal = simulated_rates(g, values, k_e)
        out.append(tuple(a - b for a, b in zip(pi, ideal, strict=True)))
    return out


def less_pull(groups, pull):
    """The groups with the loops' pull taken off their measured window rates, as host-made
    (uncommitted) device arrays like the groups': the pull's arrays come committed to the
    device of their program, and the fit's compiled runner keys on that — it compiled the
    residuals and Jacobian a second time (≈ 10 s, a quarter of a plant fit's time)."""
    out = []
    for g, (s, mv, r) in zip(groups, pull, strict=True):
        out.append(eqx.tree_at(
            lambda x: (x.measured_static, x.measured_moving, x.measured_ramp), g,
            tuple(device(np.asarray(a)) for a in (
                g.measured_static - s, g.measured_moving - mv * g.moving_valid,
                g.measured_ramp - jnp.where(g.ramp_weight > 0, r, 0.0))),
        ))  # fmt: skip
    return out


@program(check=Check("PhysicalCompensator.fit (residuals and Jacobian)"))
def residuals_jacobian(groups, values, k_e):
    """Residuals {True: static, False: moving} [rad/s] at `values` and their Jacobians with
    respect to the scaled parameters x (values + x·scale). The fit's one simulator program:
    it serves the weights, every Levenberg–Marquardt step and the covariance."""
    fn = lambda x: window_residuals(groups, values + x * SCALE, k_e)
    return fn(jnp.zeros(len(NAMES))), jax.jacfwd(fn)(jnp.zeros(len(NAMES)))


def robust_scatter(residuals, weights) -> dict:
    """Robust scatter (1.4826 × median absolute deviation) of each kind of residual, over
    the real windows (`window_weights` > 0)."""
    out = {}
    for kind, r in residuals.items():
        r = np.asarray(r)[weights[kind] > 0]
        out[kind] = float(1.4826 * np.median(np.abs(r - np.median(r))))
    return out


def scatter_per_dof(residuals, jac, weights, iterations: int = 4) -> dict:
    """Residual scatter of each kind of window (at rest, moving) at the solution, each kind
    with its own degrees of freedom: σ_k² = Σ r_k² / (n_k − p_k), where p_k is the sum of
    the leverages (the hat matrix's diagonal of the σ-weighted Jacobian) over kind k's rows
    (Σ_k p_k = the number of parameters). A plain RMS would take σ of a kind whose few
    windows carry most of the parameters (the at-rest windows of a small plan) too small,
    and every error bar with it. The leverages depend on the σ's: a few fixed-point
    iterations from the RMS."""
    kinds = (True, False)
    real = {k: weights[k] > 0 for k in kinds}
    r = {k: np.asarray(residuals[k])[real[k]] for k in kinds}
    j = {k: np.asarray(jac[k])[real[k]] for k in kinds}
    n = {k: r[k].size for k in kinds}
    sigma = {k: np.sqrt(np.mean(r[k] ** 2)) for k in kinds}
    if not all(np.isfinite(s) and s > 0 for s in sigma.values()):
        return sigma  # noise-free (or degenerate) data: nothing to correct
    for _ in range(iterations):
        q, _ = np.linalg.qr(np.concatenate([j[k] / sigma[k] for k in kinds]))
        leverage = np.sum(q**2, axis=1)
        p = {True: leverage[: n[True]].sum(), False: leverage[n[True] :].sum()}
        sigma = {k: np.sqrt(np.sum(r[k] ** 2) / max(n[k] - p[k], 1.0)) for k in kinds}
    return sigma


MIN_DOF = 3.0
"""Fewest degrees of freedom `t_factors` takes a parameter's σ to rest on: a Student t with
ν ≤ 2 has no variance (its σ would be inflated without bound)."""


def t_factors(jac, weights, sigma) -> tuple[np.ndarray, dict]:
    """The factor on each parameter's σ that makes it cover as a normal σ should, and each
    kind's degrees of freedom: ((p,) factors √(ν/(ν − 2)), {True: ν at rest, False: ν
    moving}).

    Each kind's σ is estimated from its own residuals (`scatter_per_dof`, ν_k = n_k − p_k,
    p_k its rows' leverages): a parameter's error over that σ is a Student t, not a normal,
    and a plan of few at-rest windows (18 static runs carrying 7 parameters: ν ≈ 11) covers
    66 % at ±1σ, 93 % at ±2σ, with z-RMS √(ν/(ν − 2)) = 1.10. A parameter's ν pools the
    kinds by the share each has in its variance (Satterthwaite, as
    `discovery.stats.effective_dof`): c_ik = Σ over kind k's rows of ((JᵀJ)⁻¹Jᵀ)_ir²,
    ν_i = (Σ_k c_ik)² / Σ_k c_ik²/ν_k (at least `MIN_DOF`). `jac`: the σ-weighted Jacobian,
    at-rest rows first (`_weigh`), in any parameter scaling (the factors do not depend on
    it); `weights` (`window_weights`): which rows are real windows; `sigma`: the kinds' σ
    (a noise-free fit, σ 0, gets factors 1)."""
    kinds = (True, False)
    jac = np.asarray(jac)
    n_rest = np.asarray(weights[True]).size
    real = np.concatenate([np.asarray(weights[k]) > 0 for k in kinds])
    rows = {True: np.arange(jac.shape[0]) < n_rest, False: np.arange(jac.shape[0]) >= n_rest}
    norm = np.linalg.norm(jac, axis=0)
    u, s, vt = np.linalg.svd(jac / norm, full_matrices=False)
    a = (vt.T / s) @ u.T  # (p, N): the scaled parameters' (JᵀJ)⁻¹Jᵀ
    leverage = np.sum(u**2, axis=1)
    nu = {k: max(float(np.sum(real & rows[k]) - leverage[real & rows[k]].sum()), 1.0)
          for k in kinds}  # fmt: skip
    c = {k: np.sum(a[:, rows[k]] ** 2, axis=1) for k in kinds}
    total = c[True] + c[False]
    pooled = total**2 / (c[True] ** 2 / nu[True] + c[False] ** 2 / nu[False])
    pooled = np.maximum(pooled, MIN_DOF)
    if not all(np.isfinite(sigma[k]) and sigma[k] > 0 for k in kinds):
        return np.ones(jac.shape[1]), nu  # noise-free: no σ estimated, nothing to widen
    return np.sqrt(pooled / (pooled - 2.0)), nu


POLISH_STEPS = 8
"""Most simulator evaluations of the reweighted Gauss–Newton after Levenberg–Marquardt
(`fit_values`); step halvings count."""
POLISH_TOL = 0.01
"""The reweighted Gauss–Newton stops when no parameter's step exceeds this fraction of its
own standard error (from the same Jacobian)."""


def gauss_newton_step(r_w, jac_w):
    """The Gauss–Newton step dx minimising ‖r_w + J_w dx‖ and the standard error of each x
    from the same Jacobian (√diag (JᵀJ)⁻¹), by the SVD of the σ-weighted Jacobian; (None,
    None) when J_w is rank-deficient (the covariance then names the parameters the data
    leave unidentified)."""
    u, s, vt = np.linalg.svd(np.asarray(jac_w), full_matrices=False)
    if not (s.size and np.all(np.isfinite(s)) and s[-1] > s[0] * 1e-13):
        return None, None
    dx = -vt.T @ ((u.T @ np.asarray(r_w)) / s)
    return dx, np.sqrt(np.sum((vt.T / s) ** 2, axis=1))


def _weigh(r, jac, sigma):
    """Residuals and Jacobians of both kinds divided by their kind's σ, stacked (at rest
    first)."""
    kinds = (True, False)
    return (
        np.concatenate([np.asarray(r[k]) / sigma[k] for k in kinds]),
        np.concatenate([np.asarray(jac[k]) / sigma[k] for k in kinds]),
    )


def fit_values(groups, x0, k_e, max_steps):
    """The fit of the parameters from `x0` over `groups`: weights, Levenberg–Marquardt (one
    compiled step at a time, with a progress bar), Gauss–Newton with the weights re-estimated
    at the solution, final residuals and Jacobian; returns (values, steps, residuals, σ of
    each kind, σ-weighted Jacobian in the parameters), the residuals, σ's and Jacobian those
    at the returned values; `steps` counts Levenberg–Marquardt's steps and Gauss–Newton's
    evaluations.

    Levenberg–Marquardt weighs each kind of window (at rest, moving) by its residual scatter
    at the starting values (robust: median absolute deviation, which a far start's few bad
    windows do not inflate). The solver is optimistix's Levenberg–Marquardt, fed the
    residuals and Jacobian of `residuals_jacobian` at each point it evaluates
    (`least_squares_with_jacobian`), so the simulator is compiled once per fit, not twice.

    Those weights can be far off: the harmonic start fits the moving windows much worse than
    the solution does (10× their noise on a plan with temperature ramps), so the moving
    windows weigh ~100× too little, the fit lands many of its reported σ's from the
    optimum of the weights it reports (gain_mismatch1 by 7 σ), a fit restarted from its
    result moves, and the scatter over seeds exceeds the σ's. So Gauss–Newton steps follow
    (`_reweighted_gauss_newton`): each kind's σ re-estimated at the current point as the
    covariance's (`scatter_per_dof`), then a step on the weighted residuals from the
    residuals and Jacobian `residuals_jacobian` gives there (host linear algebra, no new
    program), until no parameter's step exceeds `POLISH_TOL` of its standard error (at most
    `POLISH_STEPS` evaluations; a step halved while it raises the cost). The returned values
    are then the weighted least squares whose weights and covariance the fit reports."""
    weights = window_weights(groups)
    x0 = np.asarray(x0)
    k_e = device(k_e, float)  # a value of the program, not a constant: a new k_e compiles nothing
    at = {}  # host copies of the last evaluation: {True/False: residuals}, Jacobians

    def evaluate(x):
        # Host arithmetic between the compiled programs (eager jnp would compile each op).
        r, jac = residuals_jacobian(groups, device(x0 + np.asarray(x) * SCALE), k_e)
        return {k: np.asarray(v) for k, v in r.items()}, {k: np.asarray(v) for k, v in jac.items()}

    def weighted(x):
        at["r"], at["jac"] = evaluate(x)
        if "sigma" not in at:  # the first call: at the starting values
            at["sigma"] = robust_scatter(at["r"], weights)
        return tuple(device(a) for a in _weigh(at["r"], at["jac"], at["sigma"]))

    note = many_groups_note(groups)  # each group compiles: say so where there are many
    # The problem is scaled so that one unit of x is about one standard error: stopping at
    # 1e-4 of that is far below anything the data can tell. Absolute only: a tolerance
    # relative to x stops a fit that started far (|x| in the hundreds) a fraction of a
    # standard error short of the optimum.
    x, steps, result, _ = least_squares_with_jacobian(
        weighted,
        optx.LevenbergMarquardt(rtol=0.0, atol=1e-4),
        device(np.zeros(len(NAMES))),
        max_steps=max_steps,
        desc=f"physical fit (Levenberg–Marquardt{'; ' * bool(note)}{note})",
    )
    message = first_failure(result, optx.RESULTS)
    if message is not None and int(steps) >= max_steps:  # optimistix's words name its own API
        raise RuntimeError(
            f"PhysicalCompensator.fit: Levenberg–Marquardt did not converge in max_steps = "
            f"{max_steps} steps; give PhysicalCompensator(max_steps=…) more (e.g. "
            f"{4 * max_steps}), or a bench whose runs pin the parameters better"
        )
    if message is not None:
        raise RuntimeError(f"PhysicalCompensator.fit: Levenberg–Marquardt failed: {message}")
    # `least_squares_with_jacobian` evaluated last at the solution: `at` holds it, unweighted.
    x, r1, jac1, sigma1, evaluations = _reweighted_gauss_newton(
        evaluate, weights, np.asarray(x), at["r"], at["jac"]
    )
    _, jac = _weigh(r1, jac1, sigma1)
    return x0 + x * SCALE, steps + evaluations, r1, sigma1, jac / np.asarray(SCALE)[None, :]


def _reweighted_gauss_newton(evaluate, weights, x, r, jac):
    """Gauss–Newton from `x` (residuals `r`, Jacobians `jac` there, unweighted) with each
    kind's σ re-estimated at every point (`fit_values`): (x, r, jac, σ's, evaluations)."""
    evaluations = 0
    with bar(None, "physical fit (Gauss–Newton, reweighted)") as progress:
        while True:
            sigma = scatter_per_dof(r, jac, weights)
            if not all(np.isfinite(s) and s > 0 for s in sigma.values()):
                break  # noise-free (or degenerate) data: no weights to re-estimate
            r_w, jac_w = _weigh(r, jac, sigma)
            dx, err = gauss_newton_step(r_w, jac_w)
            if dx is None or np.max(np.abs(dx) / err) <= POLISH_TOL:
                break
            cost = 0.5 * float(r_w @ r_w)
            while evaluations < POLISH_STEPS:
                r_new, jac_new = evaluate(x + dx)
                evaluations += 1
                r_w, _ = _weigh(r_new, jac_new, sigma)
                new_cost = 0.5 * float(r_w @ r_w)
                progress.update(1)
                progress.set_postfix_str(f"χ²/2 {new_cost:.6g}")
                if np.isfinite(new_cost) and new_cost <= cost:
                    x, r, jac = x + dx, r_new, jac_new
                    break
                dx = dx / 2
            else:
                break  # out of evaluations, the last step not taken: x is the last point
    return x, r, jac, sigma, evaluations
