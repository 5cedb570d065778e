"""Small dense solves in plain XLA operations, for code that runs under `vmap`.

`jnp.linalg.solve` lowers to LAPACK's LU, a custom call that jaxlib 0.10 splits over XLA's
CPU thread pool when batched; two such calls on a two-thread pool can wait for each other
for ever (`hrgjax/_threads.py`). The loops' slow manifold (`resonator.slow`) solves a 6×6
Newton system per angle and one 54×54 system per point, batched by the grey box's
`scale_factor_at`: here they are Gauss–Jordan elimination with partial pivoting in a
`fori_loop`, which XLA runs like any other loop, at any batch size, differentiable in both
modes. It costs about twice the LAPACK call there (the slow-manifold rate on 64 angles:
15.7 ms against 7.8–9.3 ms, `benchmarks/thread_pool.py` on 2 cores), a few ms of a
grey-box fit that takes tens of seconds.
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
