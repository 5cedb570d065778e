"""`sweep`: a function over the Cartesian product of parameter grids, batched by vmap."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def sweep(fn, **grids):
    """Evaluate `fn(**point)` on the Cartesian product of 1-D grids.

    `hg.sweep(fn, temperature_c=jnp.linspace(-40, 60, 11), rate_dps=jnp.array([0.1, 5, 400]))`
    calls `fn(temperature_c=…, rate_dps=…)` for every pair in one `jax.vmap` and returns
    outputs with leading shape `(11, 3)` (keyword order). When several devices are visible
    the flattened batch is sharded over them (padded to a multiple of the device count).

    **Arguments:**

    - `fn`: a function of keyword arguments returning a pytree of arrays.
    - `**grids`: 1-D arrays, one per keyword.
    """
    if not grids:
        raise ValueError(
            "sweep needs at least one grid, e.g. temperature_c=jnp.linspace(-40, 60, 11)"
        )
    names = list(grids)
    arrays = []
    for name in names:
        g = jnp.asarray(grids[name])
        if g.ndim != 1 or g.shape[0] == 0:
            raise ValueError(
                f"sweep grid {name!r} must be a non-empty 1-D array; got shape {g.shape}"
            )
        arrays.append(g)
    shape = tuple(a.shape[0] for a in arrays)
    mesh = jnp.meshgrid(*arrays, indexing="ij")
    flat = {n: m.reshape(-1) for n, m in zip(names, mesh, strict=True)}
    total = int(np.prod(shape))
    devices = jax.devices()
    call = jax.vmap(lambda kw: fn(**kw))
    if len(devices) > 1:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        pad = (-total) % len(devices)
        flat = {n: jnp.concatenate([v, jnp.repeat(v[-1:], pad)]) for n, v in flat.items()}
        sharding = NamedSharding(Mesh(np.array(devices), ("batch",)), PartitionSpec("batch"))
        flat = jax.device_put(flat, sharding)
        # No outer jit: fn may build profiles from concrete constants (their output grid must
        # stay concrete); the compiled solves inside partition the sharded batch themselves.
        out = call(flat)
        return jax.tree_util.tree_map(lambda x: x[:total].reshape(shape + x.shape[1:]), out)
    out = call(flat)
    return jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), out)
