"""`hrgjax._stepped`: derivatives of a fixed-step recurrence from its stored states (batched
Jacobians and input tangents, then a d × d recurrence) equal those of the plain `lax.scan`
that JAX differentiates itself — forward mode, reverse mode, under `vmap`, with integer
per-step inputs — and the carrier path that uses it equals its own finite differences
(tests/test_carrier.py)."""

import jax
import jax.numpy as jnp
import numpy as np

from hrgjax._stepped import stepped


def _step(y, x, theta):
    """Midpoint step of a driven damped pendulum; `x` = (t, h, step index)."""
    t, h, k = x
    a, b = theta
    f = lambda y: jnp.stack(
        [y[1], -a * jnp.sin(y[0]) - b * y[1] + jnp.cos(t) + 0.0 * k.astype(t.dtype)]
    )  # noqa: E731
    return y + h * f(y + 0.5 * h * f(y))


def _plain(step, y0, xs, theta):
    body = lambda y, x: (step(y, x, theta),) * 2  # noqa: E731
    return jnp.concatenate([y0[None], jax.lax.scan(body, y0, xs)[1]])


N = 300
T = jnp.linspace(0.0, 6.0, N)
K = jnp.arange(N)


def _loss(solver, y0, t, h, theta):
    ys = solver(_step, y0, (t, h, K), theta)
    return jnp.sum(ys[::7, 0] ** 2) + ys[-1, 1]


def test_derivatives_equal_the_plain_scans():
    args = (jnp.array([0.5, 0.0]), T, jnp.full(N, 0.02), (jnp.asarray(2.0), jnp.asarray(0.3)))
    ours = lambda *a: _loss(lambda s, y, x, th: stepped(s, y, x, th, batch=128), *a)  # noqa: E731
    plain = lambda *a: _loss(_plain, *a)  # noqa: E731
    assert float(ours(*args)) == float(plain(*args))
    g_ours = jax.jit(jax.grad(ours, argnums=(0, 1, 2, 3)))(*args)
    g_plain = jax.jit(jax.grad(plain, argnums=(0, 1, 2, 3)))(*args)
    for a, b in zip(jax.tree_util.tree_leaves(g_ours), jax.tree_util.tree_leaves(g_plain),
                    strict=True):  # fmt: skip
        np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-12 * float(jnp.max(jnp.abs(b))))
    tangents = (jnp.array([1.0, -1.0]), 0.1 * jnp.ones(N), jnp.zeros(N),
                (jnp.asarray(1.0), jnp.asarray(0.5)))  # fmt: skip
    jvp = lambda fn: jax.jit(lambda a, t: jax.jvp(fn, a, t)[1])(args, tangents)  # noqa: E731
    np.testing.assert_allclose(jvp(ours), jvp(plain), rtol=1e-11)
    # under vmap (a batch of damping values), reverse mode per member
    bs = jnp.array([0.1, 0.3, 0.9])

    def per_member(fn):
        return jax.jit(jax.vmap(jax.grad(lambda b: fn(*args[:3], (args[3][0], b)))))(bs)

    np.testing.assert_allclose(per_member(ours), per_member(plain), rtol=1e-11)
