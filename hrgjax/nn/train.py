"""Full-batch training loops in one `lax.scan` (no Python loop over steps)."""

from __future__ import annotations

import equinox as eqx
import jax
import optax


def rprop(loss, params, steps: int, learning_rate: float = 1e-3):
    """`steps` full-batch resilient-backpropagation updates (`optax.rprop`) of the pytree
    `params` on the scalar `loss(params)`, in one `lax.scan`. **Returns** the parameters."""
    opt = optax.rprop(learning_rate)

    def step(carry, _):
        p, state = carry
        updates, state = opt.update(jax.grad(loss)(p), state, p)
        return (optax.apply_updates(p, updates), state), None

    (params, _), _ = jax.lax.scan(step, (params, opt.init(params)), None, length=steps)
    return params


def train_module(module, loss, steps: int, learning_rate: float = 1e-3):
    """Rprop on the inexact-array leaves of an equinox `module`; `loss(module)` → scalar."""
    params, static = eqx.partition(module, eqx.is_inexact_array)
    trained = rprop(lambda p: loss(eqx.combine(p, static)), params, steps, learning_rate)
    return eqx.combine(trained, static)
