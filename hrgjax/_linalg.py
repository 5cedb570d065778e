"""Small dense solves in plain XLA operations, for code that runs under `vmap`.

`jnp.linalg.solve`, `cholesky` and `jax.scipy.linalg.cho_factor`/`cho_solve` lower to LAPACK
(getrf, potrf, trsm): custom calls that jaxlib 0.10 splits over XLA's CPU thread pool when
batched. Two such calls running at once on a two-thread pool wait for each other for ever
(`hrgjax/_threads.py`): seen in the loops' slow manifold, and in twenty INS flights
(`ins.flights.fly(runs=20)`, the stacks in `lapack_dtrsm_ffi` → `ParallelBatchMap`).

Here the same factorisations are written in plain XLA operations, which XLA runs like any
other, at any batch size, differentiable in both modes:

- `solve`: Gauss–Jordan elimination with partial pivoting in a `fori_loop` (the slow
  manifold's 6×6 Newton and 54×54 harmonic-balance systems). About twice the LAPACK call
  there (64 angles: 15.7 ms against 7.8–9.3 ms, `benchmarks/thread_pool.py` on 2 cores).
- `cholesky`, `cho_solve`, `whiten`, `cho_logdet`: the Kalman filters' innovation and
  prediction covariances (`kalman`, `ins.ekf`, `diagnosis.filter_bank`), a column (a row of
  the substitutions) per iteration of a `fori_loop`; written out for n ≤ `UNROLLED`, where
  that is faster (the filter bank's 1–2 measurements). The filters' costs against LAPACK,
  side by side: `benchmarks/filter_linalg.py`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ._compiled import fused


@fused
def solve(a, b):
    """x with a·x = b, by Gauss–Jordan elimination with partial pivoting (no LAPACK call).

    **Arguments:** `a`, one square (n, n) matrix; `b`, (n,) or (n, k). Batch with `vmap`.

    **Returns:** x, shaped like `b`. A singular `a` gives non-finite values, as
    `jnp.linalg.solve` does.
    """
    n = a.shape[-1]
    vec = b.ndim == 1
    m = jnp.concatenate([a, b[:, None] if vec else b], axis=1)
    rows = jnp.arange(n)

    def eliminate(k, m):
        p = jnp.argmax(jnp.where(rows >= k, jnp.abs(m[:, k]), -1.0))  # the pivot row
        m = m.at[jnp.stack([k, p])].set(m[jnp.stack([p, k])])  # swap rows k and p
        pivot_row = m[k] / m[k, k]
        factors = jnp.where(rows == k, 0.0, m[:, k])
        m = m - factors[:, None] * pivot_row[None, :]
        return m.at[k].set(pivot_row)

    x = jax.lax.fori_loop(0, n, eliminate, m)[:, n:]
    return x[:, 0] if vec else x


UNROLLED = 3
"""Largest n for which the Cholesky factor and its triangular solves are written out (a
`fori_loop` above). Chosen from 0, 3 and 6 by `benchmarks/filter_linalg.py` (its figures
in benchmarks/README.md)."""


def _each(n: int, body, init):
    """`body(i, carry)` for i = 0 … n − 1: written out for n ≤ `UNROLLED`, else a
    `fori_loop`."""
    if n <= UNROLLED:
        for i in range(n):
            init = body(i, init)
        return init
    return jax.lax.fori_loop(0, n, body, init)


@fused
def cholesky(a):
    """Lower-triangular L with L·Lᵀ = a, column by column (the Cholesky–Crout order; no
    LAPACK call).

    **Arguments:** `a`, one symmetric positive-definite (n, n) matrix (its lower triangle is
    read). Batch with `vmap`.

    **Returns:** L (n, n), zero above the diagonal. A matrix that is not positive definite
    gives NaN from the first failing column on (`jnp.linalg.cholesky`: NaN on the whole lower
    triangle); a zero pivot (semidefinite) gives NaN below it, or, in the last column, a zero
    on the diagonal, where the solves give inf or NaN and `cho_logdet` −inf. Never a finite
    answer to an unsolvable system."""
    rows = jnp.arange(a.shape[-1])

    def column(j, lower):  # L[:, j] from the columns before it (zero from j on)
        v = a[:, j] - lower @ jnp.where(rows < j, lower[j], 0.0)
        d = jnp.sqrt(v[j])
        return lower.at[:, j].set(jnp.where(rows > j, v / d, jnp.where(rows == j, d, 0.0)))

    return _each(a.shape[-1], column, jnp.zeros_like(a))


def _forward(lower, b):
    """y with L·y = b (L lower triangular; b (n,) or (n, k)): row i from the rows before it
    (y is zero from i on)."""

    def row(i, y):
        return y.at[i].set((b[i] - lower[i] @ y) / lower[i, i])

    return _each(lower.shape[-1], row, jnp.zeros_like(b))


def _backward(lower, y):
    """x with Lᵀ·x = y: row n − 1 − k from the rows after it (x is zero up to it)."""
    n = lower.shape[-1]

    def row(k, x):
        i = n - 1 - k
        return x.at[i].set((y[i] - lower[:, i] @ x) / lower[i, i])

    return _each(n, row, jnp.zeros_like(y))


@fused
def cho_solve(lower, b):
    """x with (L·Lᵀ)·x = b, from L = `cholesky`(a): a forward and a backward substitution.

    **Arguments:** `lower` (n, n); `b`, (n,) or (n, k). Batch with `vmap`.

    **Returns:** x, shaped like `b`."""
    return _backward(lower, _forward(lower, b))


@fused
def whiten(lower, b):
    """L⁻¹·b: ‖L⁻¹ν‖² = νᵀ a⁻¹ ν (the Mahalanobis distance) with one substitution."""
    return _forward(lower, b)


@fused
def cho_logdet(lower):
    """log det a = 2 Σ log Lᵢᵢ from a's Cholesky factor L."""
    return 2.0 * jnp.sum(jnp.log(jnp.diagonal(lower)))
