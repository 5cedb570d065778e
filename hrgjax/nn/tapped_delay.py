"""Tapped-delay inputs: the last `taps` samples of a multichannel series as one vector."""

from __future__ import annotations

import jax.numpy as jnp

from .._checks import whole_number


def windows(x, taps: int):
    """Sliding windows of `x` (K, c) → (K − taps + 1, taps·c); row k holds samples
    k … k + taps − 1 (oldest first), i.e. the window that ends at sample k + taps − 1."""
    x = jnp.asarray(x)
    if x.ndim != 2:
        raise ValueError(f"x must have shape (K, channels); got {x.shape}")
    taps = whole_number("taps", taps, f"an integer in [1, {x.shape[0]}] (samples)")
    if not 1 <= taps <= x.shape[0]:
        raise ValueError(f"taps must be in [1, K = {x.shape[0]}] (K: the samples of x); got {taps}")
    idx = jnp.arange(x.shape[0] - taps + 1)[:, None] + jnp.arange(taps)[None, :]
    return x[idx].reshape(idx.shape[0], taps * x.shape[1])
