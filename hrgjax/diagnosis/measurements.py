r"""Diagnosis measurements of seed 002: pairwise differences between the INS of a complex.

For navigation parameters $z_i^k$ of INS i at step k (sampling step Δt):

- eq. (7), second differences over Δt² (gyro faults in ξ, ζ and the geographic-trihedron
  faults):
  $$\Delta z_{ij}^k = \frac{z_i^k - 2z_i^{k-1} + z_i^{k-2}}{\Delta t^2}
   - \frac{z_j^k - 2z_j^{k-1} + z_j^{k-2}}{\Delta t^2};$$
- eq. (8), differences of first differences over Δt² (η-axis faults, on the departure):
  $$\Delta\dot w_{ij}^k = \frac{(z_i^k - z_i^{k-1}) - (z_j^k - z_j^{k-1})}{\Delta t^2}.$$

The true motion is common to all INS and cancels; what is left are the INS errors.
"""

from __future__ import annotations

import itertools

import jax.numpy as jnp

from .._checks import describe, is_finite_real, numeric_problem, whole_number


def pairs(n_ins: int = 3) -> tuple[tuple[int, int], ...]:
    """Index pairs (i, j), i < j, of a complex of `n_ins` INS: (0,1), (0,2), (1,2) for three."""
    n_ins = whole_number("n_ins", n_ins, "an integer >= 2 (INS in the complex)")
    if n_ins < 2:
        raise ValueError(f"a complex needs at least 2 INS; got {n_ins}")
    return tuple(itertools.combinations(range(n_ins), 2))


def _check(z, dt, k_min):
    z = jnp.asarray(z)
    if z.ndim < 2:
        raise ValueError(
            f"z must have shape (..., n_ins, K) (INS axis second to last); got {z.shape}"
        )
    if z.shape[-1] < k_min:
        raise ValueError(f"z needs at least {k_min} time steps; got {z.shape[-1]}")
    if not (is_finite_real(dt) and dt > 0):
        kind = TypeError if numeric_problem(dt) is not None else ValueError
        raise kind(f"dt must be a finite number > 0 s; got {describe(dt)}")
    return z


def second_difference_pairs(z, dt: float, which=None):
    """Eq. (7) for every pair: `z` (..., n_ins, K) → (..., n_pairs, K − 2), pairs in the order
    of [`pairs`][hrgjax.diagnosis.measurements.pairs] (`which`: only these (i, j), in their
    order); step k of the output is step k + 2 of the input."""
    z = _check(z, dt, 3)
    return _differences((z[..., 2:] - 2.0 * z[..., 1:-1] + z[..., :-2]) / dt**2, which)


def first_difference_pairs(z, dt: float, which=None):
    """Eq. (8) for every pair (`which`: only these (i, j)): `z` (..., n_ins, K) →
    (..., n_pairs, K − 1); step k of the output is step k + 1 of the input."""
    z = _check(z, dt, 2)
    return _differences((z[..., 1:] - z[..., :-1]) / dt**2, which)


def _differences(d, which):
    """d_i − d_j of the INS axis (second to last) for the pairs `which` (default every pair):
    only those are formed (a (K, n_ins, 3) nav read as K INS had K²/2 pairs)."""
    which = pairs(d.shape[-2]) if which is None else which
    return jnp.stack([d[..., i, :] - d[..., j, :] for i, j in which], axis=-2)
