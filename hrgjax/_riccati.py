r"""The discrete Riccati equation's limit for `hrgjax.kalman.steady_state`: the states that
neither the process noise nor the initial covariance reach (known exactly), a diagonal
balancing of the rest, and the structure-preserving doubling on the balanced, reduced model.

Everything here is plain `jax.numpy` with no Python control flow on values: jit, vmap and
grad work, and the exactly-known states and the balancing are found the same way whether
the matrices are concrete or traced.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from ._linalg import cho_solve, cholesky, solve

STEADY_TOL = 1e-12
r"""`steady_state` has converged when a doubling changes no entry of P by more than this
share of $\sqrt{P_{ii}P_{jj}}$ (an exactly known state: not at all)."""


def sym(a):
    """The symmetric part of `a`."""
    return 0.5 * (a + a.T)


def reached_states(phi, x0):
    r"""Boolean (n,): the states whose variance can ever be > 0 — the closure of the first
    prior's support (`x0` = $\Phi p_0\Phi^\top + Q_d$, a variance > 0) under $\Phi$ (state i
    is reached when $\Phi_{ij} \ne 0$ for a reached j), as `diagnosis.complex.relevant_states`
    closes the states a measurement reads. n − 1 steps reach the closure. The rest have no
    noise and no initial uncertainty, and no reached state drives them: known exactly, their
    variance is 0 at every step. A pattern of values, so a mask under tracing; on NumPy
    arrays (`_kalman_checks.check_detectable`'s host check) a NumPy loop, no program (an
    eager `fori_loop` took 0.2–0.8 s a call)."""
    moves = phi != 0.0

    def grow(_, reach):
        return reach | (moves & reach[None, :]).any(axis=1)

    reach = x0.diagonal() > 0.0
    if isinstance(moves, np.ndarray) and isinstance(reach, np.ndarray):
        for i in range(phi.shape[0] - 1):
            reach = grow(i, reach)
        return reach
    return jax.lax.fori_loop(0, phi.shape[0] - 1, grow, reach)


def balancing(phi, qd, x0, reach):
    r"""Powers of 2, (n,): each reached state's standard deviation after n − 1 predictions
    from `x0` (no measurement: $M \leftarrow \Phi M\Phi^\top + Q_d$; `limit` passes $Q_d$:
    the sizes the noise gives the limit — from a first prior that `p0` dominates they were
    1e14× off, and a gain 8e-2 off at q₂ = 1e-28 in `steady_state`'s example), rounded
    down to a power of 2 so that scaling by them is exact; 1 for a state not reached, or
    whose prediction is 0 or not finite. Every reached state has a variance > 0 by then
    (the closure takes at most n − 1 steps), including one with no noise of its own that
    another state drives (a position under a velocity's noise), which the first prior's
    diagonal alone leaves at 0. It estimates the states' sizes, not the limit's: the
    doubling then runs on states of comparable size, its round-off relative to each. No
    gradient flows through it (the limit does not depend on the scaling)."""

    def predict(_, m):
        return sym(phi @ m @ phi.T + qd)

    m = jax.lax.fori_loop(0, phi.shape[0] - 1, predict, x0)
    d = jnp.sqrt(jnp.clip(jnp.diagonal(m), 0.0))
    ok = reach & (d > 0.0) & jnp.isfinite(d)
    _, e = jnp.frexp(jnp.where(ok, d, 1.0))
    return jax.lax.stop_gradient(jnp.ldexp(jnp.ones_like(d), e - 1))


STEIN_DOUBLINGS = 64
r"""Doublings of the Stein sum $\sum_k \Phi_c^k C\,\Phi_c^{\top k}$ in `limit`'s derivative:
$2^{64}$ closed-loop steps (a pole 1 − 1e-12 is summed to its end)."""


def steady(phi, qd, h, r, p0, n_iter: int):
    r"""`(P_prior, K, S, converged)` of `steady_state`: P by `limit`, then
    $S = HPH^\top + R$, $K = PH^\top S^{-1}$."""
    pp, done = limit(phi, qd, h, r, p0, n_iter)
    s = sym(h @ pp @ h.T + r)
    return pp, cho_solve(cholesky(s), h @ pp).T, s, done > 0.5


@functools.partial(jax.custom_jvp, nondiff_argnums=(5,))
def limit(phi, qd, h, r, p0, n_iter: int):
    r"""`(P_prior, converged)`, `converged` 1.0 or 0.0: the doubling of `steady_state`'s
    docstring on the balanced model $D^{-1}\Phi D$, $D^{-1}Q_dD^{-1}$, $HD$, $D^{-1}p_0D^{-1}$
    restricted to the reached states (the rows and columns of the others exactly 0), then
    $P = D\tilde PD$. Its derivative is the implicit one (`_limit_jvp`), not the doubling's:
    the mask and the scaling are values, and a derivative through them would hold a known
    state known (0 where a coupling or a noise at 0 makes it uncertain)."""
    sym0 = sym(phi @ p0 @ phi.T + qd)
    keep = reached_states(phi, sym0)
    d = balancing(phi, qd, sym(qd), keep)
    both = keep[:, None] & keep[None, :]
    scale = jnp.outer(d, d)
    phi = jnp.where(both, phi * (d[None, :] / d[:, None]), 0.0)
    qd, x0 = (jnp.where(both, a / scale, 0.0) for a in (qd, sym0))  # x0: the first prior
    h = jnp.where(keep[None, :], h * d[None, :], 0.0)
    eye = jnp.eye(phi.shape[0], dtype=phi.dtype)
    g0 = sym(h.T @ cho_solve(cholesky(sym(r)), h))  # Hᵀ R⁻¹ H

    def cover(a, g, hk):  # the prior after the 2^k steps (a, g, hk) cover, from x0
        return sym(hk + a.T @ x0 @ solve(eye + g @ x0, a))

    def double(_, carry):
        def step():
            a, g, hk, p, _ = carry
            n = eye.shape[0]
            w = solve(eye + g @ hk, jnp.concatenate([a, g], axis=1))  # (I + GH)⁻¹ [A, G]
            a, g, hk = a @ w[:, :n], sym(g + a @ w[:, n:] @ a.T), sym(hk + a.T @ hk @ w[:, :n])
            new = cover(a, g, hk)
            sd = jnp.sqrt(jnp.clip(jnp.diagonal(new), 0.0))
            done = jnp.all(jnp.abs(new - p) <= STEADY_TOL * jnp.outer(sd, sd)) & jnp.all(
                jnp.isfinite(new)
            )
            return a, g, hk, new, done

        return jax.lax.cond(carry[-1], lambda: carry, step)

    a0 = phi.T
    start = (a0, g0, qd, cover(a0, g0, qd), jnp.asarray(False))
    *_, pp, done = jax.lax.fori_loop(0, n_iter, double, start)
    done = done & jnp.all(jnp.diagonal(pp) >= -STEADY_TOL)  # a negative variance: round-off
    return pp * scale, done.astype(pp.dtype)


@limit.defjvp
def _limit_jvp(n_iter, primals, tangents):
    r"""The derivative of the Riccati equation's fixed point
    $P = \Phi P^+\Phi^\top + Q_d$, $P^+ = P - KHP$, $K = PH^\top S^{-1}$, by the implicit
    function theorem: $dP - \Phi_c\,dP\,\Phi_c^\top = C$ with $\Phi_c = \Phi(I - KH)$ and
    $C = d\Phi P^+\Phi^\top + \Phi P^+ d\Phi^\top + dQ_d
    + \Phi(K\,dR\,K^\top - P^+dH^\top K^\top - K\,dH\,P^+)\Phi^\top$, summed
    ($dP = \sum_k \Phi_c^kC\,\Phi_c^{\top k}$) by `STEIN_DOUBLINGS` doublings. It does not
    depend on $p_0$. A state known exactly whose coupling or noise is at 0 gets the
    derivative of the model that makes it uncertain (finite where its own Φ is stable;
    not finite where a noise would make it a random walk: no steady state there)."""
    phi, qd, h, r, p0 = primals
    dphi, dqd, dh, dr, _ = tangents
    pp, done = limit(phi, qd, h, r, p0, n_iter)
    eye = jnp.eye(phi.shape[0], dtype=phi.dtype)
    s = sym(h @ pp @ h.T + r)
    k = cho_solve(cholesky(s), h @ pp).T
    post = sym(pp - k @ h @ pp)
    ab = dphi @ post @ phi.T
    c = ab + ab.T + dqd + phi @ (k @ dr @ k.T - post @ dh.T @ k.T - k @ dh @ post) @ phi.T

    def double(_, carry):
        a, x = carry
        return a @ a, x + a @ x @ a.T

    _, dp = jax.lax.fori_loop(0, STEIN_DOUBLINGS, double, (phi @ (eye - k @ h), sym(c)))
    return (pp, done), (sym(dp), jnp.zeros_like(done))
