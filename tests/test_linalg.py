"""`hrgjax._linalg.solve`: Gauss–Jordan in plain XLA operations, equal to LAPACK's solve, with
no custom call for XLA:CPU's pool to wedge on (hrgjax/_threads.py)."""

import jax
import jax.numpy as jnp
import numpy as np

from hrgjax._linalg import solve

RNG = np.random.default_rng(0)


def test_equals_numpy_with_pivoting_one_and_many_right_hand_sides():
    for n in (1, 6, 54):  # the slow manifold's Newton and harmonic-balance sizes
        a = RNG.normal(size=(n, n)) + 3.0 * np.eye(n)
        b, bs = RNG.normal(size=n), RNG.normal(size=(n, 2))
        np.testing.assert_allclose(solve(jnp.asarray(a), jnp.asarray(b)),
                                   np.linalg.solve(a, b), rtol=1e-12, atol=1e-13)  # fmt: skip
        np.testing.assert_allclose(solve(jnp.asarray(a), jnp.asarray(bs)),
                                   np.linalg.solve(a, bs), rtol=1e-12, atol=1e-13)  # fmt: skip
    a = np.array(
        [[0.0, 1.0, 2.0], [1.0, 0.0, 3.0], [4.0, 5.0, 0.0]]
    )  # zero diagonal: needs rows swapped
    b = np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(solve(jnp.asarray(a), jnp.asarray(b)), np.linalg.solve(a, b),
                               rtol=1e-14, atol=1e-15)  # fmt: skip


def test_batched_and_differentiated_like_jnp_linalg_solve_without_a_custom_call():
    a = jnp.asarray(0.3 * RNG.normal(size=(5, 6, 6)) + 3.0 * np.eye(6))  # well conditioned
    b = jnp.asarray(RNG.normal(size=(5, 6)))
    batched = jax.jit(jax.vmap(solve))
    np.testing.assert_allclose(batched(a, b), jax.vmap(jnp.linalg.solve)(a, b), rtol=1e-12)
    hlo = batched.lower(a, b).as_text()
    assert "custom_call" not in hlo and "lapack" not in hlo.lower()
    ours = lambda m: jnp.sum(jnp.sin(solve(m, b[0])))
    theirs = lambda m: jnp.sum(jnp.sin(jnp.linalg.solve(m, b[0])))
    np.testing.assert_allclose(jax.grad(ours)(a[0]), jax.grad(theirs)(a[0]), rtol=1e-11, atol=1e-14)
    np.testing.assert_allclose(jax.jacfwd(ours)(a[0]), jax.jacfwd(theirs)(a[0]), rtol=1e-11,
                               atol=1e-14)  # fmt: skip
