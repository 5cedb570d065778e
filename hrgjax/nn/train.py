"""Full-batch training loops in one `lax.scan` (no Python loop over steps)."""

from __future__ import annotations

import equinox as eqx
import jax
import optax


def rprop(loss, params, steps: int, learning_rate: float = 1e-3, max_step: float = 50.0):
    """`steps` full-batch resilient-backpropagation updates (`optax.rprop`) of the pytree
    `params` on the scalar `loss(params)`, in one `lax.scan`; `learning_rate` is the initial
    step size, `max_step` the largest one (a sigmoid/tanh network saturates, and stops
    learning, when a weight's step grows too large). **Returns** the parameters."""
    opt = optax.rprop(learning_rate, max_step_size=max_step)

    def step(carry, _):
        p, state = carry
        updates, state = opt.update(jax.grad(loss)(p), state, p)
        return (optax.apply_updates(p, updates), state), None

    (params, _), _ = jax.lax.scan(step, (params, opt.init(params)), None, length=steps)
    return params


def train_module(module, loss, steps: int, learning_rate: float = 1e-3, max_step: float = 50.0):
    """Rprop on the inexact-array leaves of an equinox `module`; `loss(module)` → scalar."""
    params, static = eqx.partition(module, eqx.is_inexact_array)
    trained = rprop(lambda p: loss(eqx.combine(p, static)), params, steps, learning_rate, max_step)
    return eqx.combine(trained, static)
