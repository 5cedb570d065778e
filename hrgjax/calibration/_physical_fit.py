"""The physical fit's least squares: the model's window rates simulated and reduced as the
measured ones (`simulated_rates`), the weighted residuals and their Jacobian, the PI loops'
pull (`loop_pull`), Levenberg–Marquardt (`fit_values`) and the residual scatter of each kind
of window (`scatter_per_dof`)."""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._compiled import Check, device, first_failure, program
from .._least_squares import least_squares_with_jacobian
from ..profiles import Profile
from ..simulate import simulate
from ._physical_groups import Group, masked_slopes, window_weights
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
    """The groups with the loops' pull taken off their measured window rates."""
    out = []
    for g, (s, mv, r) in zip(groups, pull, strict=True):
        out.append(eqx.tree_at(
            lambda x: (x.measured_static, x.measured_moving, x.measured_ramp), g,
            (g.measured_static - s, g.measured_moving - mv * g.moving_valid,
             g.measured_ramp - jnp.where(g.ramp_weight > 0, r, 0.0)),
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


def fit_values(groups, x0, k_e, max_steps):
    """The fit of the parameters from `x0` over `groups`: weights, Levenberg–Marquardt (one
    compiled step at a time, with a progress bar), final residuals and Jacobian; returns
    (values, steps, residuals, σ of each kind, σ-weighted Jacobian in the parameters).

    Weights: the residual scatter of each kind of window (at rest, moving) at the starting
    values (robust: median absolute deviation; the harmonic start is close), re-estimated
    after the fit for the covariance. The solver is optimistix's Levenberg–Marquardt, fed
    the residuals and Jacobian of `residuals_jacobian` at each point it evaluates
    (`least_squares_with_jacobian`), so the simulator is compiled once per fit, not twice."""
    weights = window_weights(groups)
    x0 = np.asarray(x0)
    at = {}  # host copies of the last evaluation: {True/False: residuals}, Jacobians

    def weighted(x):
        # Host arithmetic between the compiled programs (eager jnp would compile each op).
        r, jac = residuals_jacobian(groups, device(x0 + np.asarray(x) * SCALE), k_e)
        at["r"], at["jac"] = {k: np.asarray(v) for k, v in r.items()}, jac
        if "sigma" not in at:  # the first call: at the starting values
            at["sigma"] = robust_scatter(at["r"], weights)
        sigma = at["sigma"]
        kinds = (True, False)
        r_w = np.concatenate([at["r"][k] / sigma[k] for k in kinds])
        jac_w = np.concatenate([np.asarray(jac[k]) / sigma[k] for k in kinds])
        return device(r_w), device(jac_w)

    # The problem is scaled so that one unit of x is about one standard error: stopping at
    # 1e-4 of that is far below anything the data can tell. Absolute only: a tolerance
    # relative to x stops a fit that started far (|x| in the hundreds) a fraction of a
    # standard error short of the optimum.
    x, steps, result, _ = least_squares_with_jacobian(
        weighted,
        optx.LevenbergMarquardt(rtol=0.0, atol=1e-4),
        device(np.zeros(len(NAMES))),
        max_steps=max_steps,
        desc="physical fit (Levenberg–Marquardt)",
    )
    message = first_failure(result, optx.RESULTS)
    if message is not None:
        raise RuntimeError(f"PhysicalCompensator.fit: Levenberg–Marquardt failed: {message}")
    values = x0 + np.asarray(x) * SCALE
    # `least_squares_with_jacobian` evaluated last at the solution: `at` holds it, unweighted.
    r1, jac1 = at["r"], at["jac"]
    sigma1 = scatter_per_dof(r1, {k: np.asarray(v) for k, v in jac1.items()}, weights)
    jac = np.concatenate(
        [np.asarray(jac1[True]) / sigma1[True], np.asarray(jac1[False]) / sigma1[False]]
    )
    return values, steps, r1, sigma1, jac / np.asarray(SCALE)[None, :]
