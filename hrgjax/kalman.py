r"""Kalman-filter building blocks shared by alignment, the INS error models and fault diagnosis.

- [`van_loan`][hrgjax.kalman.van_loan]: exact discretisation of $\dot x = Fx + w$,
  $E[w(t)w(s)^\top] = Q\,\delta(t-s)$, over a step `dt`: $\Phi = e^{F\,dt}$,
  $Q_d = \int_0^{dt} e^{Fs}Qe^{F^\top s}ds$ (Van Loan 1978).
- [`predict`][hrgjax.kalman.predict] / [`update`][hrgjax.kalman.update]: the filter step in
  a numerically safe form — Joseph-form covariance update, the innovation covariance solved
  by Cholesky (never inverted), the covariance re-symmetrised — returning the innovation's
  Gaussian log-likelihood (what a multiple-model filter bank needs).
- [`kalman_filter`][hrgjax.kalman.kalman_filter]: the whole pass as one `lax.scan`.
- [`steady_state`][hrgjax.kalman.steady_state]: the converged gain of a time-invariant
  model (Riccati iteration), for filters that must run at millions of steps per second.

All functions are pure `jax.numpy`: jit, vmap (over Monte Carlo runs or a bank of models)
and grad work. A missing measurement is a step with `mask=False`.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.linalg import cho_factor, cho_solve, expm

LOG_2PI = 1.8378770664093453


class Gaussian(eqx.Module):
    """A state estimate: mean `x` (n,) and covariance `P` (n, n)."""

    x: jax.Array
    P: jax.Array


def van_loan(F, Q, dt):
    r"""Exact discretisation $(\Phi, Q_d)$ of $\dot x = Fx + w$ with white-noise spectral
    density `Q` over a step `dt`, from one matrix exponential:

    $$\exp\!\left(\begin{bmatrix}-F & Q\\ 0 & F^\top\end{bmatrix}dt\right)
    = \begin{bmatrix}\cdot & \Phi^{-1}Q_d\\ 0 & \Phi^\top\end{bmatrix}.$$

    It satisfies $FQ_d + Q_dF^\top + Q - \Phi Q\Phi^\top = 0$ (PHYSICS.md §12)."""
    F, Q = jnp.asarray(F), jnp.asarray(Q)
    n = F.shape[-1]
    z = jnp.zeros_like(F)
    m = jnp.block([[-F, Q], [z, F.T]]) * dt
    e = expm(m)
    phi = e[n:, n:].T
    qd = phi @ e[:n, n:]
    return phi, 0.5 * (qd + qd.T)


def discretise_input(F, B, dt):
    r"""Zero-order-hold input matrix $\Gamma = \int_0^{dt} e^{Fs}ds\,B$ (with $\Phi$), from the
    exponential of $\begin{bmatrix}F & B\\ 0 & 0\end{bmatrix}dt$: an input held constant over
    the step moves the state by $\Gamma u$ exactly."""
    F, B = jnp.asarray(F), jnp.asarray(B)
    n, m = B.shape
    top = jnp.concatenate([F, B], axis=1)
    big = jnp.concatenate([top, jnp.zeros((m, n + m))], axis=0) * dt
    e = expm(big)
    return e[:n, :n], e[:n, n:]


def psd_factor(m):
    r"""A factor L with $LL^\top = M$ of a symmetric positive semi-definite M that may be
    singular (eigen-decomposition, negative round-off clipped): what samples
    $N(0, M) = L\,N(0, I)$ need where Cholesky would fail on a zero-variance state."""
    w, v = jnp.linalg.eigh(m)
    return v * jnp.sqrt(jnp.clip(w, 0.0))[None, :]


def predict(g: Gaussian, phi, qd, u=None) -> Gaussian:
    r"""Time update $x \leftarrow \Phi x (+u)$, $P \leftarrow \Phi P \Phi^\top + Q_d$."""
    x = phi @ g.x if u is None else phi @ g.x + u
    p = phi @ g.P @ phi.T + qd
    return Gaussian(x, 0.5 * (p + p.T))


def update(g: Gaussian, z, H, R, mask=True):
    r"""Measurement update with `z = H x + v`, `v ~ N(0, R)`.

    Joseph form $P \leftarrow (I-KH)P(I-KH)^\top + KRK^\top$ keeps P symmetric positive
    semi-definite under round-off; the gain comes from a Cholesky solve of the innovation
    covariance $S = HPH^\top + R$.

    **Returns:** `(posterior, innovation, S, loglik)` where `loglik` is
    $\log N(\nu; 0, S)$ of the innovation ν (0 when `mask` is False: no measurement, the
    prior is returned unchanged)."""
    nu = z - H @ g.x
    s = H @ g.P @ H.T + R
    s = 0.5 * (s + s.T)
    c = cho_factor(s, lower=True)
    k = cho_solve(c, H @ g.P).T  # K = P Hᵀ S⁻¹
    x = g.x + k @ nu
    ikh = jnp.eye(g.x.shape[0]) - k @ H
    p = ikh @ g.P @ ikh.T + k @ R @ k.T
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diag(c[0])))
    loglik = -0.5 * (nu @ cho_solve(c, nu) + logdet + nu.shape[0] * LOG_2PI)
    post = Gaussian(jnp.where(mask, x, g.x), jnp.where(mask, 0.5 * (p + p.T), g.P))
    return post, nu, s, jnp.where(mask, loglik, 0.0)


def kalman_filter(prior: Gaussian, phi, qd, H, R, zs, mask=None):
    """Run predict → update over the measurements `zs` (K, m) with one `lax.scan`.

    `phi`, `qd` are (n, n) or per-step (K, n, n) (the transition into step k); `H` (m, n),
    `R` (m, m); `mask` (K,) marks steps that have a measurement.

    **Returns:** `(means (K, n), covariances (K, n, n), total log-likelihood)`."""
    k = zs.shape[0]
    phis = jnp.broadcast_to(phi, (k,) + phi.shape[-2:])
    qds = jnp.broadcast_to(qd, (k,) + qd.shape[-2:])
    mask = jnp.ones(k, bool) if mask is None else jnp.asarray(mask)

    def step(g, inp):
        f, q, z, m = inp
        g, _, _, ll = update(predict(g, f, q), z, H, R, m)
        return g, (g.x, g.P, ll)

    _, (xs, ps, ll) = jax.lax.scan(step, prior, (phis, qds, zs, mask))
    return xs, ps, jnp.sum(ll)


def steady_state(phi, qd, h, r, p0, n_iter: int = 4000):
    r"""Converged prior covariance, gain and innovation covariance of a time-invariant model,
    by iterating the Riccati recursion (predict, then the Joseph update) `n_iter` times from
    `p0`. With them a filter step is $x \leftarrow \Phi x$, $x \leftarrow x + K(z - Hx)$,
    and the innovation log-likelihood uses the fixed $S$.

    **Returns:** `(P_prior (n, n), K (n, m), S (m, m))`."""
    eye = jnp.eye(phi.shape[0])

    def step(p, _):
        pp = phi @ p @ phi.T + qd
        s = h @ pp @ h.T + r
        k = cho_solve(cho_factor(0.5 * (s + s.T), lower=True), h @ pp).T
        ikh = eye - k @ h
        p = ikh @ pp @ ikh.T + k @ r @ k.T
        return 0.5 * (p + p.T), None

    p, _ = jax.lax.scan(step, jnp.asarray(p0), None, length=n_iter)
    pp = phi @ p @ phi.T + qd
    s = h @ pp @ h.T + r
    s = 0.5 * (s + s.T)
    k = cho_solve(cho_factor(s, lower=True), h @ pp).T
    return 0.5 * (pp + pp.T), k, s
