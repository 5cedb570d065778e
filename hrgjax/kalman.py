r"""Kalman-filter building blocks shared by alignment, the INS error models and fault diagnosis.

- [`van_loan`][hrgjax.kalman.van_loan]: exact discretisation of $\dot x = Fx + w$,
  $E[w(t)w(s)^\top] = Q\,\delta(t-s)$, over a step `dt`: $\Phi = e^{F\,dt}$,
  $Q_d = \int_0^{dt} e^{Fs}Qe^{F^\top s}ds$ (Van Loan 1978).
- [`predict`][hrgjax.kalman.predict] / [`update`][hrgjax.kalman.update]: the filter step in
  a numerically safe form — Joseph-form covariance update, the innovation covariance solved
  by Cholesky (never inverted), the covariance re-symmetrised — returning the innovation's
  Gaussian log-likelihood (what a multiple-model filter bank needs).
- [`kalman_filter`][hrgjax.kalman.kalman_filter]: the whole pass as one `lax.scan`, control
  input honoured; [`rts_smoother`][hrgjax.kalman.rts_smoother]: every state given all the
  measurements.
- [`extended_kalman_filter`][hrgjax.kalman.extended_kalman_filter] (Jacobians by
  `jax.jacfwd`) and [`unscented_kalman_filter`][hrgjax.kalman.unscented_kalman_filter]
  for nonlinear models, with the same log-likelihood convention.
- [`steady_state`][hrgjax.kalman.steady_state]: the converged gain of a time-invariant
  model (the Riccati equation by doubling), for filters that must run at millions of steps
  per second.

All functions are pure `jax.numpy`: jit, vmap (over Monte Carlo runs or a bank of models)
and grad work. A missing measurement is a step with `mask=False`.
"""

from __future__ import annotations

import types

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.linalg import expm

from . import _kalman_checks as _kc
from . import _riccati
from ._compiled import fused
from ._linalg import cho_logdet, cho_solve, cholesky, whiten
from ._x64 import require_x64

LOG_2PI = 1.8378770664093453


def _floats(a):
    """`a` with integer or boolean entries (a tracer, an array, a list) as floats (float64 under
    x64; `jnp.array([0, 0])` is a zero state, a scan carry must be float); a NumPy array as a
    read-only copy (not a view of the caller's buffer); anything else as is (shapes checked)."""
    if isinstance(a, list | tuple):
        try:
            host = np.asarray(a)
        except ValueError:  # ragged: the shape checks name it
            return a
        return np.asarray(host, float) if host.dtype.kind in "biuf" else a
    if isinstance(a, jax.Array) and a.dtype.kind in "biu":
        return a.astype(jax.dtypes.canonicalize_dtype(np.float64))
    if isinstance(a, np.ndarray | np.generic):  # a copy: a later edit of `a` changes nothing here
        a = np.array(a, float if a.dtype.kind in "biu" else None)
        a.flags.writeable = False
    return a


class Gaussian(eqx.Module):
    """A state estimate: mean `x` (n,) and covariance `P` (n, n). Integer or boolean entries
    (`jnp.array([0, 0])`, a list) become floats; a NumPy array is kept as a read-only copy."""

    x: jax.Array = eqx.field(converter=_floats)
    P: jax.Array = eqx.field(converter=_floats)


def van_loan(F, Q, dt):
    r"""Exact discretisation $(\Phi, Q_d)$ of $\dot x = Fx + w$ with white-noise spectral
    density `Q` [state²/s] over a step `dt` [s] (`F` [1/s]): the exponential
    $\exp(\begin{bmatrix}-F & Q\\ 0 & F^\top\end{bmatrix}h) = \begin{bmatrix}\cdot &
    \Phi_h^{-1}Q_{d,h}\\ 0 & \Phi_h^\top\end{bmatrix}$ over $h = dt/2^k$, then k doublings
    $Q_d \leftarrow \Phi Q_d \Phi^\top + Q_d$, $\Phi \leftarrow \Phi^2$; k the least with
    $\|F\|_1 h < 1$ (≤ `VAN_LOAN_MAX_HALVINGS`; 0 for a slow F: one exponential, bit for bit
    as before). Over the whole step, $\Phi^{-1}$ grows as $e^{|\lambda| dt}$ and $Q_d$ lost
    that factor of precision: a Gauss–Markov rate's 8e-4 off its closed form at dt/τ = 30,
    50 % at 40, indefinite at 60, NaN from ≈ 700; now ≤ 2e-15 from dt/τ = 1 to 1e4
    (benchmarks/precision.py). k is traced (masked doublings): `jit`, `vmap` over `dt` and
    `grad` work, one program serves every `dt`; under `vmap` all doublings run (strapdown's
    1-h flight at 1 s: 0.56 → 0.77 s CPU). $FQ_d + Q_dF^\top + Q - \Phi Q\Phi^\top = 0$
    (PHYSICS.md §12). Refused in one line: a host `dt` that is not one finite number >= 0,
    `F` and `Q` not square (n, n); a concrete non-finite `F`, a `Q` not symmetric PSD."""
    F, Q = _floats(F), _floats(Q)
    _kc.check_discretise(F, Q, dt)
    return _van_loan(F, Q, dt)


VAN_LOAN_MAX_HALVINGS = 24
r"""Most halvings of the step in `van_loan`: ‖F‖₁h < 1 up to ‖F‖₁dt = 2²⁴ ≈ 1.7e7 (a 1-ms
Gauss–Markov state over 4 h); beyond, Qd's error grows (Gauss–Markov: 4e-9 at 1e8)."""


@fused
def _van_loan(F, Q, dt):
    """`van_loan` without the check of `dt` (fused: one compiled program)."""
    F, Q = jnp.asarray(F), jnp.asarray(Q)
    n, dt = F.shape[-1], jnp.asarray(dt, F.dtype)
    size = jax.lax.stop_gradient(jnp.max(jnp.sum(jnp.abs(F), axis=0)) * jnp.abs(dt))
    _, exponent = jnp.frexp(jnp.where(jnp.isfinite(size), size, 0.0))  # size < 2**exponent
    k = jnp.clip(exponent, 0, VAN_LOAN_MAX_HALVINGS)
    e = expm(jnp.block([[-F, Q], [jnp.zeros_like(F), F.T]]) * jnp.ldexp(dt, -k))
    phi = e[n:, n:].T  # Φ_h; e[:n, n:] = Φ_h⁻¹ Q_d,h

    def double(i, pq):
        p, q = pq[0], 0.5 * (pq[1] + pq[1].T)
        return jax.lax.cond(i < k, lambda: (p @ p, p @ q @ p.T + q), lambda: (p, q))

    phi, qd = jax.lax.fori_loop(0, VAN_LOAN_MAX_HALVINGS, double, (phi, phi @ e[:n, n:]))
    return phi, 0.5 * (qd + qd.T)


def discretise_input(F, B, dt):
    r"""Zero-order-hold input matrix $\Gamma = \int_0^{dt} e^{Fs}ds\,B$ (with $\Phi$), from the
    exponential of $\begin{bmatrix}F & B\\ 0 & 0\end{bmatrix}dt$: an input held constant over
    the step moves the state by $\Gamma u$ exactly. Refused in one line: a host `dt` that
    is not one finite number >= 0, `F` not (n, n), `B` not (n, m), a concrete NaN or inf."""
    F, B = _floats(F), _floats(B)
    _kc.check_dt("dt", dt)
    n = _kc.square("F", F)
    if len(np.shape(B)) != 2 or np.shape(B)[0] != n:
        raise ValueError(f"B must be (n, m) = ({n}, m) (n = rows of F); got {np.shape(B)}")
    for name, a in (("F", F), ("B", B)):
        _kc.check_finite_host(name, a)
    return _discretise_input(F, B, dt)


@fused
def _discretise_input(F, B, dt):
    """`discretise_input` without the check of `dt` (fused: one compiled program)."""
    F, B = jnp.asarray(F), jnp.asarray(B)
    n, m = B.shape
    top = jnp.concatenate([F, B], axis=1)
    big = jnp.concatenate([top, jnp.zeros((m, n + m))], axis=0) * dt
    e = expm(big)
    return e[:n, :n], e[:n, n:]


def psd_factor(m):
    r"""A lower-triangular factor L with $LL^\top = M$ of a symmetric positive semi-definite M
    that may be singular: what samples $N(0, M) = L\,N(0, I)$ need where a plain Cholesky
    fails on a zero-variance state (a constant bias, an exactly known initial state).

    A Cholesky factorisation whose pivots are held at zero where they fall to round-off:
    the pivot of row k, the variance of state k not explained by states 0…k−1, is taken as 0
    (its column of L is 0) when it is at most $n\,\epsilon\,M_{kk}$ (ε the float's
    resolution). The test is relative to the state's own variance, so states in different
    units (radians of latitude beside metres per second) are factored alike: on the INS
    model's $Q_d$, $LL^\top$ meets M to 2e-16 of $\sqrt{M_{ii}M_{jj}}$, where an
    eigen-factor, whose clipping works at the largest eigenvalue's resolution, missed the
    latitude's variance by 10 %. On a rank-deficient M a round-off pivot just above the test
    can be kept: the error per pair of states then stays below ≈ 1e-9 (1200 random cases
    over 14 decades of units, a reviewer's check). Each entry of L is held within
    $\sqrt{\cdot}$ of its row's remaining variance (Cauchy–Schwarz, exact for a PSD M), so
    an M that is not PSD beyond round-off gives a bounded factor, not a large one.

    Unlike an eigen-decomposition, L is continuous in M (an eigenvector's sign or the basis
    of a repeated eigenvalue can flip under a change in the last bit, and with it every
    sample drawn from the same key) and its gradient is finite where eigenvalues repeat
    (several zero-variance states: NaN before). Where a pivot is held at zero the gradient
    through it is taken as 0 (the derivative of $\sqrt{v}$ at $v = 0$ is infinite); near a
    singular M it is large, as the factor's sensitivity is.

    `m`: (n, n) in any units; the result has the units of $\sqrt{M}$ (a concrete NaN or inf
    in `m` is refused in one line)."""
    _kc.square("m", m)
    _kc.check_finite_host("m", m)
    return _psd_factor(m)


@fused
def _psd_factor(m):
    """`psd_factor` without its checks (fused: one compiled program)."""
    m = jnp.asarray(m)
    m = 0.5 * (m + m.T)
    n = m.shape[-1]
    rows = jnp.arange(n)
    floor = n * jnp.finfo(m.dtype).eps * jnp.diagonal(m)

    def column(k, carry):
        a, factor = carry
        pivot = a[k, k]
        held = pivot > floor[k]
        root = jnp.sqrt(jnp.where(held, pivot, 1.0))
        col = jnp.where(held & (rows >= k), a[:, k] / root, 0.0)
        left = jnp.diagonal(a)  # |L_jk| ≤ √(a_jj) for a PSD a (a safe root: 0 where a_jj ≤ 0)
        bound = jnp.where(left > 0, jnp.sqrt(jnp.where(left > 0, left, 1.0)), 0.0)
        col = jnp.clip(col, -bound, bound)
        return a - jnp.outer(col, col), factor.at[:, k].set(col)

    return jax.lax.fori_loop(0, n, column, (m, jnp.zeros_like(m)))[1]


psd_factor.__wrapped__ = _psd_factor.__wrapped__


def predict(g: Gaussian, phi, qd, u=None) -> Gaussian:
    r"""Time update $x \leftarrow \Phi x (+u)$, $P \leftarrow \Phi P \Phi^\top + Q_d$."""
    phi, qd, u = _floats(phi), _floats(qd), _floats(u)
    _kc.check_predict(g, phi, qd, u)
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
    prior is returned unchanged). Shapes are checked when traced; values (a NaN in `z`
    where `mask` is True, `R` not positive-definite, `g.P` not positive semi-definite) when
    they are concrete."""
    z, H, R = _floats(z), _floats(H), _floats(R)
    _kc.check_update(g, z, H, R, mask)
    return _update_innovation(g, z - H @ g.x, H, R, mask)


def _update_innovation(g: Gaussian, nu, H, R, mask=True):
    """`update` given the innovation ν (linear: z − Hx; EKF: z − h(x)) and H. Where `mask`
    is False ν is not used at all (a NaN there, a missing measurement, reaches neither the
    result nor its gradient)."""
    raw, nu = nu, jnp.where(mask, nu, 0.0)
    s = H @ g.P @ H.T + R
    s = 0.5 * (s + s.T)
    c = cholesky(s)
    k = cho_solve(c, H @ g.P).T  # K = P Hᵀ S⁻¹
    x = g.x + k @ nu
    ikh = jnp.eye(g.x.shape[0]) - k @ H
    p = ikh @ g.P @ ikh.T + k @ R @ k.T
    w = whiten(c, nu)  # ‖L⁻¹ν‖² = νᵀS⁻¹ν
    loglik = -0.5 * (w @ w + cho_logdet(c) + nu.shape[0] * LOG_2PI)
    post = Gaussian(jnp.where(mask, x, g.x), jnp.where(mask, 0.5 * (p + p.T), g.P))
    return post, raw, s, jnp.where(mask, loglik, 0.0)


def _steps(prior, phi, qd, zs, mask, us):
    k = zs.shape[0]
    n = prior.x.shape[0]
    phis = jnp.broadcast_to(phi, (k,) + phi.shape[-2:])
    qds = jnp.broadcast_to(qd, (k,) + qd.shape[-2:])
    mask = jnp.ones(k, bool) if mask is None else jnp.asarray(mask)
    us = jnp.zeros((k, n), prior.x.dtype) if us is None else jnp.broadcast_to(us, (k, n))
    return phis, qds, mask, us


def kalman_filter(prior: Gaussian, phi, qd, H, R, zs, mask=None, us=None):
    r"""Run predict → update over the measurements `zs` (K, m) with one `lax.scan`.

    `phi`, `qd` are (n, n) or per-step (K, n, n) (the transition into step k); `H` (m, n),
    `R` (m, m); `mask` (K,) marks steps that have a measurement; `us` (K, n): the control
    input added in each step's prediction, $x_k = \Phi_k x_{k-1} + u_k$ (discretised with
    [`discretise_input`][hrgjax.kalman.discretise_input]: u = Γ·input).

    Refused in one line (`ValueError`): shapes that do not fit (checked when traced too);
    when the values are concrete, a NaN or inf in `zs` at a step with a measurement, `R` not
    positive-definite, `qd` or `prior.P` not symmetric positive semi-definite (to round-off),
    non-finite `phi`, `H`, `prior.x` or `us`; after the pass, an estimate that is not finite
    (an unstable state the measurements do not see overflows), naming its first step. Under
    a caller's `jit` the values are not checked.

    **Returns:** `(means (K, n), covariances (K, n, n), total log-likelihood)`."""
    return _checked_linear("kalman_filter", _kalman_filter, prior, phi, qd, H, R, zs, mask, us)


def _checked_linear(name: str, run, prior, phi, qd, H, R, zs, mask, us):
    """The public linear pass `name` (`kalman_filter`, `rts_smoother`): x64 and the arguments
    checked, then `run` (its fused program), whose estimates are checked finite."""
    require_x64(f"hrgjax.kalman.{name}")
    phi, qd, H, R, zs, us = (_floats(a) for a in (phi, qd, H, R, zs, us))
    _kc.check_linear(prior, phi, qd, H, R, zs, mask, us)
    return _kc.check_run(name, *run(prior, phi, qd, H, R, zs, mask, us))


def _forward(prior: Gaussian, phi, qd, H, R, zs, mask, us):
    """The filter's pass: `(filtered means (K, n), covariances (K, n, n), predicted means,
    predicted covariances, each step's log-likelihood (K,), Φ per step (K, n, n))`. Compiled,
    the outputs a caller drops are removed (`_kalman_filter` stores no predictions)."""
    phis, qds, mask, us = _steps(prior, phi, qd, zs, mask, us)

    def step(g, inp):
        f, q, z, m, u = inp
        pred = predict(g, f, q, u)
        g, _, _, ll = update(pred, z, H, R, m)
        return g, (g.x, g.P, pred.x, pred.P, ll)

    _, out = jax.lax.scan(step, prior, (phis, qds, zs, mask, us))
    return (*out, phis)


@fused  # one program per shape: an eager call compiled its scan every time (≈ 1 s)
def _kalman_filter(prior: Gaussian, phi, qd, H, R, zs, mask=None, us=None):
    """`kalman_filter` without the argument checks (fused: one compiled program); the public
    wrapper has checked x64 and the arguments."""
    xs, ps, _, _, ll, _ = _forward(prior, phi, qd, H, R, zs, mask, us)
    return xs, ps, jnp.sum(ll)


def rts_smoother(prior: Gaussian, phi, qd, H, R, zs, mask=None, us=None):
    r"""Rauch–Tung–Striebel smoother: the filter of
    [`kalman_filter`][hrgjax.kalman.kalman_filter] forward, then backward
    $C_k = P_{k|k}\Phi_{k+1}^\top P_{k+1|k}^{-1}$ (a Cholesky solve; where $P_{k+1|k}$ is
    singular — a state known exactly, with no process noise — a generalised inverse, so that
    state keeps its value: a plain Cholesky gave NaN),
    $x_{k|K} = x_{k|k} + C_k(x_{k+1|K} - x_{k+1|k})$,
    $P_{k|K} = P_{k|k} + C_k(P_{k+1|K} - P_{k+1|k})C_k^\top$ — the posterior of every state
    given all the measurements. Same arguments (and checks) as the filter.

    **Returns:** `(smoothed means (K, n), covariances (K, n, n), the filter's total
    log-likelihood)`."""
    return _checked_linear("rts_smoother", _rts_smoother, prior, phi, qd, H, R, zs, mask, us)


@fused  # one program per shape: an eager call compiled its scan every time (≈ 1 s)
def _rts_smoother(prior: Gaussian, phi, qd, H, R, zs, mask=None, us=None):
    """`rts_smoother` without the argument checks (fused: one compiled program); the public
    wrapper has checked x64 and the arguments."""
    xf, pf, xp, pp, ll, phis = _forward(prior, phi, qd, H, R, zs, mask, us)

    def backward(nxt, inp):
        x, p, x_pred, p_pred, f = inp  # filtered at k; predicted and Φ of step k + 1
        c = _psd_solve(p_pred, f @ p).T  # P Φᵀ P_pred⁻ (a generalised inverse)
        xs = x + c @ (nxt.x - x_pred)
        ps = p + c @ (nxt.P - p_pred) @ c.T
        g = Gaussian(xs, 0.5 * (ps + ps.T))
        return g, (g.x, g.P)

    last = Gaussian(xf[-1], pf[-1])
    inputs = (xf[:-1], pf[:-1], xp[1:], pp[1:], phis[1:])
    _, (xs, ps) = jax.lax.scan(backward, last, inputs, reverse=True)
    return jnp.concatenate([xs, xf[-1:]]), jnp.concatenate([ps, pf[-1:]]), jnp.sum(ll)


def _psd_solve(p, b):
    r"""$G b$ with G a generalised inverse of the symmetric PSD `p` ($pGp = p$): the inverse of
    `p` on the states whose pivots [`psd_factor`][hrgjax.kalman.psd_factor] keeps, 0 on the
    rest (a state known exactly, or one that is a combination of those before it). Where
    `p` is positive definite, $p^{-1}b$. The smoother's gain $P\Phi^\top G$ is the same
    for every generalised inverse (its columns and the corrections it multiplies lie in
    the range of $P_{k+1|k}$)."""
    low = _psd_factor(p)
    kept = jnp.diagonal(low) > 0.0
    both = kept[:, None] & kept[None, :]
    low = jnp.where(both, low, jnp.eye(p.shape[-1], dtype=p.dtype))  # identity on the rest
    mask = kept.reshape(kept.shape + (1,) * (b.ndim - 1))
    return jnp.where(mask, cho_solve(low, jnp.where(mask, b, 0.0)), 0.0)


# the unchecked programs, as `fused` exposes them (`kalman_filter.__wrapped__(…)`: the plain
# function's values)
kalman_filter.__wrapped__ = _kalman_filter.__wrapped__
rts_smoother.__wrapped__ = _rts_smoother.__wrapped__


def _nonlinear_steps(prior, qd, zs, mask, us):
    """Per-step noise, measurement mask and inputs of the EKF/UKF (inputs (K, 0) when none)."""
    k = zs.shape[0]
    qds = jnp.broadcast_to(qd, (k,) + qd.shape[-2:])
    mask = jnp.ones(k, bool) if mask is None else jnp.asarray(mask)
    us = jnp.zeros((k, 0), prior.x.dtype) if us is None else jnp.asarray(us)
    return qds, mask, us


def extended_kalman_filter(prior: Gaussian, f, qd, h, R, zs, mask=None, us=None):
    """Extended Kalman filter: $x_k = f(x_{k-1}, u_k) + w$, $z_k = h(x_k) + v$, with the
    Jacobians of `f` and `h` by `jax.jacfwd` at the current estimate; the update and the
    log-likelihood as in [`update`][hrgjax.kalman.update] (innovation z − h(x̂)).

    `f(x, u) -> x` and `h(x) -> z` (pure JAX functions); `qd` (n, n) or (K, n, n); `R` (m, m);
    `us` (K, p) inputs passed to `f` (zeros (K, 0) when None). On a linear model it is the
    Kalman filter.

    One compiled program per shape and model where the model cannot go stale: `f` and `h`
    each a callable `eqx.Module` (or a Module's bound method: its arrays are inputs of the
    program, so new parameter values compile nothing) or a plain function (static, by
    identity: it must be pure — a function reading a global that changes afterwards keeps
    the value it was compiled with, as under `jax.jit`). Any other callable (a bound method
    of a plain object, a callable instance, `functools.partial`) may carry state the program
    cannot see: the filter is traced and compiled on every call, as a plain `lax.scan` is.

    **Returns:** `(means (K, n), covariances (K, n, n), total log-likelihood)`."""
    require_x64("hrgjax.kalman.extended_kalman_filter")
    qd, R, zs, us = (_floats(a) for a in (qd, R, zs, us))
    _kc.check_nonlinear(prior, f, qd, h, R, zs, mask, us)
    run = _extended_kalman_filter if _kept(f) and _kept(h) else _ekf
    return run(prior, f, qd, h, R, zs, mask, us)


def _kept(fn) -> bool:
    """Whether a compiled filter may be kept for the model function `fn`: an `eqx.Module`
    (its bound methods are Modules too), whose arrays are the program's inputs, or a plain
    function; not a callable that may hold state the program would not see change."""
    return isinstance(fn, (eqx.Module, types.FunctionType))


def _ekf(prior: Gaussian, f, qd, h, R, zs, mask=None, us=None):
    """`extended_kalman_filter`'s pass, plain (no checks, not compiled)."""
    qds, mask, us = _nonlinear_steps(prior, qd, zs, mask, us)

    def step(g, inp):
        q, z, m, u = inp
        fj = jax.jacfwd(f)(g.x, u)
        p = fj @ g.P @ fj.T + q
        pred = Gaussian(f(g.x, u), 0.5 * (p + p.T))
        hj = jax.jacfwd(h)(pred.x)
        g, _, _, ll = _update_innovation(pred, z - h(pred.x), hj, R, m)
        return g, (g.x, g.P, ll)

    _, (xs, ps, ll) = jax.lax.scan(step, prior, (qds, zs, mask, us))
    return xs, ps, jnp.sum(ll)


# one program per shape and model (a Module's arrays are inputs, a function is static): an
# eager call compiled its scan every time (`benchmarks/kalman_calls.py`)
_extended_kalman_filter = eqx.filter_jit(_ekf)


def sigma_points(g: Gaussian, alpha: float = 1.0, beta: float = 2.0, kappa: float = 0.0):
    """Scaled unscented sigma points (Van der Merwe): `(points (2n+1, n), mean weights,
    covariance weights)`; λ = α²(n + κ) − n, points x ± columns of L, LLᵀ = (n + λ)P
    ([`psd_factor`][hrgjax.kalman.psd_factor]: a P that its update left indefinite by
    round-off — a measurement 10¹⁶ more precise than the prior — gave a plain Cholesky's
    NaN, silently, from the first step on)."""
    n = _kc.check_prior(g, "g")
    _kc.check_unscented(n, alpha, beta, kappa)
    lam = alpha**2 * (n + kappa) - n
    root = psd_factor((n + lam) * g.P)
    pts = jnp.concatenate([g.x[None], g.x[None] + root.T, g.x[None] - root.T])
    wm = jnp.full(2 * n + 1, 0.5 / (n + lam)).at[0].set(lam / (n + lam))
    wc = wm.at[0].add(1 - alpha**2 + beta)
    return pts, wm, wc


def unscented_kalman_filter(
    prior: Gaussian, f, qd, h, R, zs, mask=None, us=None, alpha=1.0, beta=2.0, kappa=0.0
):
    """Unscented Kalman filter: the same model and returns as
    [`extended_kalman_filter`][hrgjax.kalman.extended_kalman_filter], moments propagated
    through `f` and `h` by [`sigma_points`][hrgjax.kalman.sigma_points] instead of Jacobians
    (exact for the mean of a quadratic). The log-likelihood is that of the innovation under
    its unscented covariance. Compiled once per shape and model, as the EKF (`alpha`,
    `beta`, `kappa` are inputs: new values compile nothing)."""
    require_x64("hrgjax.kalman.unscented_kalman_filter")
    qd, R, zs, us = (_floats(a) for a in (qd, R, zs, us))
    _kc.check_nonlinear(prior, f, qd, h, R, zs, mask, us)
    _kc.check_unscented(np.shape(prior.x)[0], alpha, beta, kappa)
    alpha, beta, kappa = (jnp.asarray(v, float) for v in (alpha, beta, kappa))
    run = _unscented_kalman_filter if _kept(f) and _kept(h) else _ukf
    return run(prior, f, qd, h, R, zs, mask, us, alpha, beta, kappa)


def _ukf(prior: Gaussian, f, qd, h, R, zs, mask=None, us=None, alpha=1.0, beta=2.0, kappa=0.0):
    """`unscented_kalman_filter`'s pass, plain (no checks, not compiled)."""
    qds, mask, us = _nonlinear_steps(prior, qd, zs, mask, us)

    def step(g, inp):
        q, z, m, u = inp
        pts, wm, wc = sigma_points(g, alpha, beta, kappa)
        fx = jax.vmap(lambda x: f(x, u))(pts)
        x = wm @ fx
        dx = fx - x[None]
        p = (wc[:, None] * dx).T @ dx + q
        pred = Gaussian(x, 0.5 * (p + p.T))
        pts, wm, wc = sigma_points(pred, alpha, beta, kappa)
        hz = jax.vmap(h)(pts)
        zhat = wm @ hz
        dz, dxp = hz - zhat[None], pts - pred.x[None]
        s = (wc[:, None] * dz).T @ dz + R
        s = 0.5 * (s + s.T)
        pxz = (wc[:, None] * dxp).T @ dz
        c = cholesky(s)
        gain = cho_solve(c, pxz.T).T
        nu = z - zhat
        xn = pred.x + gain @ nu
        pn = pred.P - gain @ s @ gain.T
        w = whiten(c, nu)
        ll = -0.5 * (w @ w + cho_logdet(c) + nu.shape[0] * LOG_2PI)
        g = Gaussian(jnp.where(m, xn, pred.x), jnp.where(m, 0.5 * (pn + pn.T), pred.P))
        return g, (g.x, g.P, jnp.where(m, ll, 0.0))

    _, (xs, ps, ll) = jax.lax.scan(step, prior, (qds, zs, mask, us))
    return xs, ps, jnp.sum(ll)


_unscented_kalman_filter = eqx.filter_jit(_ukf)  # one program per shape and model, as the EKF's


# the plain passes (`extended_kalman_filter.__wrapped__(…)`: as before, traced every call)
extended_kalman_filter.__wrapped__ = _ekf
unscented_kalman_filter.__wrapped__ = _ukf


STEADY_DOUBLINGS = 100
"""Default most doublings of `steady_state`: 2¹⁰⁰ Riccati steps."""
STEADY_TOL = _riccati.STEADY_TOL
r"""`steady_state` has converged when a doubling changes no entry of P by more than this
share of $\sqrt{P_{ii}P_{jj}}$ (an exactly known state: not at all)."""


def steady_state(phi, qd, h, r, p0=None, n_iter: int = STEADY_DOUBLINGS):
    r"""Converged prior covariance, gain and innovation covariance of a time-invariant model:
    the limit of the Riccati recursion (predict, then update) started from the posterior
    covariance `p0` (default 0: the stabilising solution of the discrete algebraic Riccati
    equation $P = \Phi P\Phi^\top - \Phi PH^\top(HPH^\top + R)^{-1}HP\Phi^\top + Q_d$ where
    the model is stabilisable and detectable; every `p0` then reaches it).

    By the structure-preserving doubling algorithm (Chu, Fan & Lin 2005): with
    $A_0 = \Phi^\top$, $G_0 = H^\top R^{-1}H$, $H_0 = Q_d$,
    $A_{k+1} = A_k(I + G_kH_k)^{-1}A_k$, $G_{k+1} = G_k + A_k(I + G_kH_k)^{-1}G_kA_k^\top$,
    $H_{k+1} = H_k + A_k^\top H_k(I + G_kH_k)^{-1}A_k$, the covariance after $2^k$ steps
    from a prior X is $H_k + A_k^\top X(I + G_kX)^{-1}A_k$: each doubling doubles the steps
    covered, and near the limit the error squares (a random walk at q/r = 1e-12, whose
    closed-loop pole is 1 − 1e-6, converges in ≈ 25 doublings; 4000 plain Riccati steps
    left its gain 250× too large). It stops when a doubling changes P by less than
    `STEADY_TOL`, within `n_iter` doublings (whole number >= 1). A model without a steady
    state is refused in one line: on concrete values (a `ValueError`) a mode the
    measurements never see, now or through Φ, that grows or is a random walk the noise
    drives (the PBH test on the unobservable subspace: two random walks that a measured
    state sees only through their sum "converged" to P = 913, or −6.9e13, by round-off),
    named by its states; on any values (under the caller's `jit` an `eqx.error_if`) a
    doubling that does not converge or ends on a negative variance, as does a state without
    process noise that the measurements see and `p0` holds uncertain (its variance falls as
    1/k for ever: no steady gain). Traced values skip the PBH test: call once eagerly.

    Exactly known states: those neither `qd` nor `p0` reaches (the closure of the first
    prior $\Phi p_0\Phi^\top + Q_d$'s support under Φ's nonzero pattern) have variance 0 at
    every step; their rows and columns of P and K are exactly 0 and the doubling runs on
    the rest (their eigenvalue of Φ, kept, amplified round-off without end: a constant
    with no noise and p0 = 0 driving a measured state was refused, or with n_iter = 200
    made its neighbour's variance 20× too large). The set is a mask of values, found
    alike under `jit` and `vmap`.

    Derivatives (`grad`, `jvp`) are the implicit ones of the fixed point: $dP$ solves the
    Stein equation $dP - \Phi_c\,dP\,\Phi_c^\top = C$ on the closed loop $\Phi_c$, so they
    do not depend on the doubling, the mask or `p0`; a coupling into a known state, or its
    noise, at 0 gets the derivative of the model it would become (a mask held fixed gave
    0: a parameter started at 0 never moved under gradient descent).

    Balancing: the doubling runs on $D^{-1}\Phi D$, $D^{-1}Q_dD^{-1}$, $HD$, $D^{-1}p_0D^{-1}$,
    then $P = D\tilde PD$, with D each state's standard deviation after n − 1 predictions
    from $Q_d$ (n states: every reached state, one driven without noise of its own
    included, has a variance by then; not from the first prior, which a large `p0` can
    dominate), rounded to a power of 2. The
    scaling is then exact and every product covariant: what it changes is the pivot order
    of the Gauss–Jordan solves of $I + G_kH_k$, which partial pivoting picks by size, in
    the model's units. Unbalanced, Φ = [[1, 9.8], [0, 0.9999]], Q_d = diag(1e-6, q₂),
    H = [1, 0], R = 1e-2 gave the small state's gain 5e-4 off at q₂ = 1e-24, 36× at 1e-28;
    now ≤ 3e-13 off an 80-digit solution from q₂ = 1e-12 to 1e-30, whatever `p0` (scipy's
    `solve_discrete_are`: 1.3e-9 at 1e-28). Accuracy otherwise: round-off grows as the
    closed-loop pole nears 1, ≈ ε/(1 − pole): the random walk's gain to 3e-11 at
    q/r = 1e-12, 4e-9 at 1e-16 (a diagonal scaling does not change a scalar model).

    With the results a filter step is $x \leftarrow \Phi x$, $x \leftarrow x + K(z - Hx)$,
    and the innovation log-likelihood uses the fixed $S$. `jit`, `vmap` and `grad` work.

    **Returns:** `(P_prior (n, n), K (n, m), S (m, m))`, in the units of the model."""
    phi, qd, h, r = (_floats(a) for a in (phi, qd, h, r))
    p0 = np.zeros(np.shape(phi)) if p0 is None else _floats(p0)
    n_iter = _kc.check_steady(phi, qd, h, r, p0, n_iter)
    _kc.check_detectable(phi, qd, h, p0)
    *out, ok = _steady_state(phi, qd, h, r, p0, n_iter)
    return (_kc.check_converged(ok, out[0], n_iter), *out[1:])


@fused(static_argnames="n_iter")  # one program per shape: an eager call compiled every time
def _steady_state(phi, qd, h, r, p0, n_iter: int = STEADY_DOUBLINGS):
    """`steady_state`'s balanced doubling with its matrices as floats (fused: one compiled
    program); returns `(P_prior, K, S, converged)`."""
    require_x64("hrgjax.kalman.steady_state")
    return _riccati.steady(phi, qd, h, r, p0, n_iter)


def _steady_plain(phi, qd, h, r, p0, n_iter: int = STEADY_DOUBLINGS):
    """`steady_state`'s values by the plain (not compiled) doubling, without its checks."""
    return _steady_state.__wrapped__(phi, qd, h, r, p0, n_iter)[:3]


steady_state.__wrapped__ = _steady_plain
