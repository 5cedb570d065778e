r"""Fixed-step recurrences whose derivatives are taken from the stored states, in batches.

`stepped(step, y0, xs, theta)` returns every state $Y_0 … Y_N$ of
$Y_{n+1} = \Phi(Y_n, x_n, \theta)$ for a small state vector (the carrier path's 8–10
numbers, discovery's 2). Differentiated the ordinary way, a `lax.scan` of such steps is
bound by its loop: each of thousands of iterations runs a few hundred tiny operations, and
the reverse pass (or, under `jax.checkpoint`, a recomputed forward pass and the reverse
pass) runs as many again, so a gradient cost 6–10× its forward pass on the carrier path
(benchmarks/gradient_scans.py). Here the derivative is a custom JVP built from the stored
states $Y_n$:

- the step's Jacobians $J_n = \partial\Phi/\partial Y$ at every stored state, and the
  tangents $u_n = \partial\Phi/\partial(x, \theta) \cdot (\dot x_n, \dot\theta)$, are
  computed for all steps at once (`vmap` over n, in batches of `batch` steps to bound
  memory) — wide array operations instead of a loop;
- the tangent recurrence $\dot Y_{n+1} = J_n \dot Y_n + u_n$ is the only loop left: a
  d × d matrix–vector product per step.

Forward mode (`jax.jvp`, `jax.jacfwd`) uses the rule as written; reverse mode
(`jax.grad`) is JAX's transpose of it: the recurrence runs backwards with $J_n^\top$ and the
tangent map $u$ transposes into one batched VJP of the step over all n. Nothing is
recomputed sequentially. Memory: the states, N × d, and the Jacobians, N × d × d numbers
(the caller bounds N; the carrier path falls back to checkpointing per chunk beyond
`carrier.STORE_STEPS`).

Every traced value `step` reads must come through `xs` (per step, leading axis N) or
`theta` (shared); `step` itself closes over static values only.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

BATCH = 4096
"""Steps whose Jacobians and tangents are computed together (bounds the memory of the
batched derivatives to about BATCH × the step's intermediates)."""


def stepped(step, y0, xs, theta, batch: int = BATCH):
    """All states (N + 1, d) of `y_{n+1} = step(y_n, xs[n], theta)` from `y0` (d,), with
    the derivative rule of the module docstring. `xs`: pytree of per-step inputs (leading
    axis N); `theta`: pytree of shared inputs; `batch`: steps linearised together."""
    return _stepped(step, batch, y0, xs, theta)


def scan_states(step, y0, xs, theta):
    """All states (N + 1, d) of the recurrence by a plain `lax.scan` (no derivative rule)."""

    def body(y, x):
        y1 = step(y, x, theta)
        return y1, y1

    _, ys = jax.lax.scan(body, y0, xs)
    return jnp.concatenate([y0[None], ys])


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _stepped(step, batch, y0, xs, theta):
    return scan_states(step, y0, xs, theta)


def _map(fn, args, batch):
    """`vmap(fn)` over the leading axis of `args`, `batch` at a time."""
    n = jax.tree_util.tree_leaves(args)[0].shape[0]
    return jax.lax.map(lambda a: fn(*a), args, batch_size=min(int(batch), max(n, 1)))


@_stepped.defjvp
def _stepped_jvp(step, batch, primals, tangents):
    y0, xs, theta = primals
    ys = _stepped(step, batch, y0, xs, theta)
    return ys, tangent_states(step, ys, xs, theta, *tangents, batch=batch)


def tangent_states(step, ys, xs, theta, dy0, dxs, dtheta, batch: int = BATCH):
    """The tangents (N + 1, d) of the states `ys` (N + 1, d) of `step` (as `stepped`) for
    tangents `dy0`, `dxs`, `dtheta` of its inputs: batched Jacobians and input tangents, then
    the recurrence (module docstring). For a caller that computes the states itself."""
    states = ys[:-1]
    eye = jnp.eye(ys.shape[1], dtype=ys.dtype)
    zero_theta = jax.tree_util.tree_map(_zero_tangent, theta)

    def linear(y, x, dx):  # J_n and ∂Φ/∂(x, θ)·(dx, dθ) from one linearisation at Y_n
        dx = jax.tree_util.tree_map(_zero_if_none, x, dx, is_leaf=lambda v: v is None)
        _, lin = jax.linearize(step, y, x, theta)
        zero_x = jax.tree_util.tree_map(_zero_tangent, x)
        jn = jax.vmap(lambda e: lin(e, zero_x, zero_theta), out_axes=1)(eye)
        return jn, lin(jnp.zeros_like(y), dx, dtheta)

    jacobians, inputs = _map(linear, (states, xs, _float_only(dxs)), batch)  # (N, d, d), (N, d)

    def carry(dy, jn_un):
        jn, un = jn_un
        dy1 = jn @ dy + un
        return dy1, dy1

    _, dys = jax.lax.scan(carry, dy0, (jacobians, inputs))
    return jnp.concatenate([dy0[None], dys])


def _float_only(tangents):
    """The tangents with `None` for integer inputs (float0 tangents cannot be mapped over)."""
    return jax.tree_util.tree_map(lambda t: None if t.dtype == jax.dtypes.float0 else t, tangents)


def _zero_tangent(x):
    """A zero tangent for `x` (float0 for an integer input)."""
    if jnp.issubdtype(jnp.result_type(x), jnp.inexact):
        return jnp.zeros_like(x)
    return np.zeros(np.shape(x), jax.dtypes.float0)


def _zero_if_none(x, dx):
    """The tangent of one input: float0 zeros for an integer input."""
    if x is None or dx is not None:
        return dx
    return _zero_tangent(x)
