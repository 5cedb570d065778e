r"""The continuous fits' Levenberg–Marquardt, finished where optimistix's own stalls.

[`records.lm`][hrgjax.discovery.records.lm] is `optimistix.LevenbergMarquardt`, whose
trust region (`optimistix.ClassicalTrustRegion`'s defaults, cutoffs 0.01 and 0.99) accepts
every step that gains 1 % of the predicted decrease *without shrinking the region*. On a
model that misses a large effect (the base model of records with a hidden bias-temperature
slope: χ²/dof ≈ 120) the residual's own curvature, $\sum_i r_i\nabla^2 r_i$, is about that
of the Gauss–Newton model, so each step is about twice too long: the iterates two-cycle
across the valley of bias and angular gain (which trade off on the turning runs, −k_e Ω),
the cycle shrinking by only ≈ 3 % a step, and 256 steps run out long before the
convergence test holds. [`converged_lm`][hrgjax.discovery._continuous_fit.converged_lm]
keeps `records.lm`'s answer wherever it converged (bit for bit) and otherwise goes on from
where it stopped with the classical trust-region cutoffs (0.25, 0.75): a step that gains
less than a quarter of its prediction is refused and the damping raised, which damps the
cycle in a few tens of steps, to the minimum `scipy.optimize.least_squares` finds.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._least_squares import least_squares_with_jacobian
from .records import lm, residual_and_jacobian

STRICT_STEPS = 256
"""Steps of the strict trust region after `records.lm` ran out (it needs a few tens)."""


def strict_solver(rtol: float = 1e-8, atol: float = 1e-8) -> optx.LevenbergMarquardt:
    """`optimistix.LevenbergMarquardt` (the tolerances of `records.lm`) whose trust region
    refuses a step gaining less than 25 % of its predicted decrease and widens only above
    75 % (the classical cutoffs; optimistix's defaults are 1 % and 99 %)."""
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol)
    region = optx.ClassicalTrustRegion(low_cutoff=0.25, high_cutoff=0.75)
    return eqx.tree_at(lambda s: s.search, solver, region)


def strict_least_squares(residuals_jacobian, y0, max_steps: int = STRICT_STEPS):
    """Minimise ½‖r(y)‖² from `y0` with
    [`strict_solver`][hrgjax.discovery._continuous_fit.strict_solver], where
    `residuals_jacobian(y) -> (r, J)`: `(y, converged)`."""
    y, _, result, _ = least_squares_with_jacobian(
        residuals_jacobian, strict_solver(), y0, max_steps=max_steps, desc="refining the fit"
    )
    return np.asarray(y), bool(result == optx.RESULTS.successful)


def converged_lm(layout, basis, z0, groups):
    """[`records.lm`][hrgjax.discovery.records.lm] over the parameters `basis` (P, m) picks,
    from `z0`; where it does not converge, on from where it stopped (from `z0` if that is
    not finite) with [`strict_least_squares`][hrgjax.discovery._continuous_fit.strict_least_squares]
    (module docstring): `(z, converged)`."""
    z, ok = lm(layout, basis, jnp.asarray(z0), groups)
    if bool(ok):
        return z, ok
    start = np.asarray(z) if np.all(np.isfinite(np.asarray(z))) else np.asarray(z0)
    basis = np.asarray(basis)

    def residuals_jacobian(u):
        z = jnp.asarray(start + basis @ np.asarray(u))
        return residual_and_jacobian(layout, z, basis, groups)

    u, ok = strict_least_squares(residuals_jacobian, np.zeros(basis.shape[1]))
    return jnp.asarray(start + basis @ u), jnp.asarray(ok)
