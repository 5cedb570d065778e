"""`hrgjax._linalg`: Gauss–Jordan and Cholesky in plain XLA operations, equal to LAPACK's, with
no custom call for XLA:CPU's pool to wedge on (hrgjax/_threads.py)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import batched_lapack

from hrgjax import _linalg as L
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


def test_cholesky_and_its_solves_equal_lapacks_written_out_and_looped():
    """n ≤ UNROLLED is written out, larger n loops: both equal
    numpy's Cholesky, solve and log-determinant; a matrix that is not positive definite gives
    NaN, as `jnp.linalg.cholesky` does."""
    assert L.UNROLLED < 21
    for n in (1, L.UNROLLED, L.UNROLLED + 1, 21):  # 21: the INS filter with scale factors
        m = RNG.normal(size=(n, n))
        a = m @ m.T + n * np.eye(n)
        b = RNG.normal(size=(n, 2))
        c = L.cholesky(jnp.asarray(a))
        np.testing.assert_allclose(c, np.linalg.cholesky(a), rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(L.cho_solve(c, jnp.asarray(b)), np.linalg.solve(a, b),
                                   rtol=1e-11, atol=1e-13)  # fmt: skip
        w = L.whiten(c, jnp.asarray(b[:, 0]))
        assert float(w @ w) == pytest.approx(b[:, 0] @ np.linalg.solve(a, b[:, 0]), rel=1e-12)
        assert float(L.cho_logdet(c)) == pytest.approx(np.linalg.slogdet(a)[1], rel=1e-13)
    assert np.all(np.isnan(np.asarray(L.cholesky(-jnp.eye(3))).diagonal()))


def test_cholesky_batched_and_differentiated_like_jax_without_lapack():
    def ours(s, nu):  # the log-likelihood's pieces
        c = L.cholesky(s)
        return L.cho_logdet(c) + jnp.sum(L.whiten(c, nu) ** 2)

    def theirs(s, nu):
        return jnp.linalg.slogdet(s)[1] + nu @ jnp.linalg.solve(s, nu)

    @functools.partial(jax.jit, static_argnums=0)
    def both_modes(f, s, nu):
        g = lambda s: f(0.5 * (s + s.T), nu)  # noqa: E731 (tangents kept symmetric)
        return jax.grad(g)(s), jax.jacfwd(g)(s)

    for n in (L.UNROLLED, 9):  # written out, looped
        m = jnp.asarray(RNG.normal(size=(3, n, n)))
        a = m @ jnp.swapaxes(m, 1, 2) + n * jnp.eye(n)[None]
        np.testing.assert_allclose(jax.vmap(L.cholesky)(a), jnp.linalg.cholesky(a), rtol=1e-12)
        assert not batched_lapack(jax.vmap(lambda a: L.cho_solve(L.cholesky(a), a[0])), a)
        for x, y in zip(both_modes(ours, a[1], a[0, 0]), both_modes(theirs, a[1], a[0, 0]),
                        strict=True):  # fmt: skip
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-12)
