r"""Elman recurrent network (Elman 1990): a tanh hidden layer whose context is its own previous
state,

$$h_t = \tanh(W_x x_t + W_h h_{t-1} + b), \qquad y_t = W_y h_t + c,$$

run over a sequence by one `lax.scan` (PHYSICS.md §12). With $W_h = 0$ it is a one-hidden-
layer MLP applied at each step; the context is what lets it model an error with memory."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._checks import check_key, whole_number
from .._compiled import fused


class Elman(eqx.Module):
    """An Elman network `in_size → hidden_size (tanh, with context) → out_size (linear)`.

    Call on a sequence `xs` (T, in_size) → `ys` (T, out_size); `h0` (hidden_size,) is the
    initial context (zeros by default). [`step`][hrgjax.nn.elman.Elman.step] advances one
    sample. Called eagerly the sequence runs as one compiled program per shape (a later call
    of the same shapes compiles nothing); inside a caller's `jit`/`vmap`/`grad` it is
    inlined."""

    w_x: eqx.nn.Linear
    w_h: eqx.nn.Linear
    w_y: eqx.nn.Linear
    hidden_size: int = eqx.field(static=True)

    def __init__(self, in_size: int, hidden_size: int, out_size: int, *, key: jax.Array):
        in_size, hidden_size, out_size = (
            whole_number(name, v, "a positive integer (units)")
            for name, v in (("in_size", in_size), ("hidden_size", hidden_size),
                            ("out_size", out_size))
        )  # fmt: skip
        if min(in_size, hidden_size, out_size) < 1:
            raise ValueError(
                f"sizes must be positive; got in={in_size}, hidden={hidden_size}, out={out_size}"
            )
        check_key("Elman: key (the PRNG key of the initial weights)", key)
        kx, kh, ky = jax.random.split(key, 3)
        self.w_x = eqx.nn.Linear(in_size, hidden_size, key=kx)
        self.w_h = eqx.nn.Linear(hidden_size, hidden_size, use_bias=False, key=kh)
        self.w_y = eqx.nn.Linear(hidden_size, out_size, key=ky)
        self.hidden_size = int(hidden_size)

    def step(self, h, x):
        """One sample: context `h` (hidden,), input `x` (in,) → `(h_new, y)`."""
        h = jnp.tanh(self.w_x(x) + self.w_h(h))
        return h, self.w_y(h)

    def __call__(self, xs, h0=None):
        xs = jnp.asarray(xs)
        n_in = self.w_x.in_features
        if xs.ndim != 2 or xs.shape[1] != n_in:
            raise ValueError(f"xs must have shape (T, in_size) = (T, {n_in}); got {xs.shape}")
        # the context in the dtype the step returns (float32 or integer samples beside float64
        # weights: the scan's carry changed type, a raw "carry input and carry output" error)
        with jax.numpy_dtype_promotion("standard"):  # whatever the caller's setting
            dtype = jnp.result_type(xs, self.w_x.weight, float)
        h0 = jnp.zeros(self.hidden_size, dtype) if h0 is None else jnp.asarray(h0)
        if h0.shape != (self.hidden_size,):
            raise ValueError(
                f"h0 must have shape (hidden_size,) = ({self.hidden_size},); got {h0.shape}"
            )
        with jax.numpy_dtype_promotion("standard"):
            dtype = jnp.result_type(dtype, h0)
        cast = lambda a: a if a.dtype == dtype else a.astype(dtype)  # noqa: E731
        return _run(self, cast(h0), cast(xs))


@fused
def _run(net: Elman, h0, xs):
    """`net` over `xs` (T, in) from context `h0` → ys (T, out): one compiled program per
    shape, kept by JAX's cache. A scan called eagerly traced its body afresh on every call
    (a new closure over the network each time) and compiled it again: 0.5–0.8 s per call of
    `fog.compensation.compensate` on a 2-core CPU (benchmarks/recompile_values.py --fog)."""
    _, ys = jax.lax.scan(lambda h, x: net.step(h, x), h0, xs)
    return ys
