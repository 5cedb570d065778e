r"""The error model's covariance step: $(\Phi, Q_d)$ of $\dot x = Fx + w$ over one GNSS
interval by Taylor series and Gauss–Legendre quadrature, squared where a Gauss–Markov state
decays fast (no matrix exponential: no LAPACK kernel in a batched flight). The
loosely-coupled filter ([`hrgjax.ins.ekf`][hrgjax.ins.ekf]) calls it once per interval;
`hrgjax.ins.ekf.discretise` is this function."""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_finite_host, check_numbers, concrete_value, finite_number
from .._compiled import fused, tracing_callback_free


def _powers(F, order=8):
    """I, F, F², …, F^order stacked: (order + 1, n, n)."""
    out = [jnp.eye(F.shape[-1], dtype=F.dtype)]
    for _ in range(order):
        out.append(out[-1] @ F)
    return jnp.stack(out)


def _taylor(powers, s: float):
    """Σ_k F^k s^k / k! from the stacked powers of F."""
    s = jnp.asarray(s, float)
    c = jnp.stack([s**k / math.factorial(k) for k in range(powers.shape[0])])
    return jnp.einsum("k,kij->ij", c, powers)


MAX_SQUARINGS = 63
"""The most squarings [`discretise`][hrgjax.ins.discretisation.discretise] takes (6 binary digits):
enough for T·`fastest` up to 1e18 (τ down to 1e-17 s over a 10-s step); beyond, the
series' step is longer than 1/(8·`fastest`) and Φ, $Q_d$ are wrong, then NaN (from ≈ 4e19)."""


def _decay_rate(fastest) -> bool:
    """Whether `fastest` asks for the Gauss–Markov path (> 0, or traced); a one-line error for
    anything but a finite real number ≥ 0."""
    check_numbers("discretise: fastest", fastest, "a decay rate >= 0 [1/s]", shape=())
    value = concrete_value(fastest)
    if value is None:
        return True
    if not (np.isfinite(value) and value >= 0):
        raise ValueError(f"discretise: fastest must be a decay rate >= 0 [1/s]; got {float(value)}")
    return bool(value > 0)


def _square(_, pq):
    r"""One squaring: ($\phi \leftarrow \phi^2$, $Q \leftarrow \phi Q\phi^\top + Q$)."""
    p, qq = pq
    qq = p @ qq @ p.T + qq
    return p @ p, 0.5 * (qq + qq.T)


def _unchanged(pq):
    return pq


_DIGITS = tuple(
    functools.partial(jax.lax.fori_loop, 0, 2**b, _square)
    for b in range(MAX_SQUARINGS.bit_length())
)
"""Binary digit b's branch: 2^b squarings (module-level, so each `lax.cond` meets the same
functions on every trace)."""


def _squared(phi, qd, j):
    r"""(Φ, Q) squared `j` times ($\phi \leftarrow \phi^2$, $Q \leftarrow \phi Q\phi^\top + Q$),
    `j` an int array in [0, `MAX_SQUARINGS`]: binary digit b runs 2^b squarings under a
    `lax.cond` (one fixed-length loop each: reverse-differentiable, one program for any j)."""
    for b, run in enumerate(_DIGITS):
        phi, qd = jax.lax.cond(((j >> b) & 1) == 1, run, _unchanged, (phi, qd))
    return phi, qd


def _rate_estimate(powers):
    """max over k = 5…8 of |tr F^k|^(1/k) [1/s]: F's largest |eigenvalue| to within a factor
    n^(1/k) either way (units of the states drop out of a trace; four powers, so that one
    pair's λ^k do not cancel in all), without an eigen-decomposition in a trace."""
    p = jax.lax.stop_gradient(powers)
    return jnp.max(jnp.stack([jnp.abs(jnp.trace(p[k])) ** (1.0 / k) for k in range(5, 9)]))


@fused(static_argnames=("k", "gm"))
def _discretised(F, q, T, fastest, *, k: int, gm: bool):
    """`discretise`'s arithmetic, its arguments checked: one compiled program called eagerly
    (each operation its own program otherwise, and the squarings' conds traced anew), inlined
    in a caller's trace. `k` steps of h = T/k; `gm`: the Gauss–Markov path. Also returns the
    series' step × `_rate_estimate` (`discretise` checks it for a traced F)."""
    h = T / k
    if gm:  # j = ⌈log2(8·h·fastest)⌉ ≥ 0, and the series over h/2^j
        j = jnp.clip(jnp.ceil(jnp.log2(8.0 * h * jnp.maximum(fastest, 1e-300))), 0,
                     MAX_SQUARINGS).astype(int)  # fmt: skip
        h = h / jnp.exp2(j.astype(float))
    x, w = np.polynomial.legendre.leggauss(5 if gm else 3)
    powers = _powers(F)
    size = jax.lax.stop_gradient(h) * _rate_estimate(powers)
    qd = 0.0
    for xi, wi in zip(x, w, strict=True):
        p = _taylor(powers, 0.5 * h * (1.0 + xi))
        qd = qd + (0.5 * h * wi) * (p @ q @ p.T)
    phi, qd = _taylor(powers, h), 0.5 * (qd + qd.T)
    if gm:
        phi, qd = _squared(phi, qd, j)
    if k == 1:
        return phi, qd, size

    def compose(_, pq):
        p, qq = pq
        qq = phi @ qq @ phi.T + qd
        return phi @ p, 0.5 * (qq + qq.T)

    return (*jax.lax.fori_loop(1, k, compose, (phi, qd)), size)


def discretise(F, q, T: float, fastest=0.0):
    r"""$(\Phi, Q_d)$ of $\dot x = Fx + w$, $E[ww^\top] = q\,\delta$, over a GNSS interval
    `T` [s]: $\Phi(s)$ by its Taylor series to eighth order, and
    $Q_d = \int_0^T\Phi(s)\,q\,\Phi(s)^\top ds$ by three-point Gauss–Legendre (exact for the
    integrand's polynomial of degree ≤ 5). The error model's F is a slow, nearly nilpotent
    chain (attitude → velocity → position, rates ≲ 1e-3 s⁻¹), so for T ≤ 10 s both agree with
    the exact Van Loan exponential ([`hrgjax.kalman.van_loan`][hrgjax.kalman.van_loan]):
    Φ to 1e-14, $Q_d$ in units of the states' σ to 3e-11 at 1 s and 4e-8 at 10 s
    (tests/test_navigation_filter.py), at a fraction of its cost batched over flights
    (benchmarks/navigation.py). A longer interval is k = ⌈T / 10 s⌉ such steps of h = T/k
    composed ($\Phi = \phi_h^k$, $Q_d$ by $Q \leftarrow \phi_h Q \phi_h^\top + Q_h$; 6e-10 at
    30 s): no matrix exponential, so no LAPACK kernel in a batched flight
    (hrgjax/_threads.py).

    `fastest` [1/s] (≥ 0; a number, or a traced scalar): the largest decay rate in F (1/τ of
    a Gauss–Markov state), or the largest |λ| of F's eigenvalues (a fast oscillation off its
    diagonal: [[−0.01, 5], [−5, −0.01]] needs `fastest=5` over 1 s). Given (> 0, or traced),
    $Q_h$ takes five-point Gauss–Legendre (the Gauss–Markov drive reaches the position
    through four integrations), and where
    h·`fastest` > 1/8 each step is the series over $h/2^j$, j the least with
    $h\cdot$`fastest`$/2^j \le 1/8$, squared j times
    ($\phi \leftarrow \phi^2$, $Q \leftarrow \phi Q \phi^\top + Q$): Φ and $Q_d$ within
    1e-11 of `van_loan` in units of the states' σ, T/τ from 1e-3 to 1e3, T = 1–30 s
    (tests/test_navigation_gauss_markov.py; the series alone had e^(−T/τ) 0.8 off at
    T/τ = 3). Not exact at any T/τ: the j squarings' rounding, in Φ's navigation block,
    grows ∝ T/τ — 1e-11 at T/τ = 1e4 (17 squarings), 1.2e-10 at 1e5, 7.5e-9 at 1e8, 1e-5 at
    1e12, where `van_loan` itself returns NaN ($Q_d$ within 2e-14); and each squaring costs
    a few matrix products (2× the batched fold's time at T/τ = 1e4). j is a value, not a
    shape: it is taken as its binary digits, each a `lax.cond` over 2^b squarings (up to
    `MAX_SQUARINGS`), so a new τ compiles nothing, and `grad` reaches τ through the series;
    where `vmap` batches τ itself each cond runs both branches (all `MAX_SQUARINGS`).

    **Raises:** `TypeError` for a `fastest` that is not one real number, `ValueError` for one
    that is not finite and ≥ 0 (a traced one is not checked here: the filter holds its
    model's τ, [`ImuModel.checked`][hrgjax.ins.sensors.ImuModel.checked]; past
    `MAX_SQUARINGS`, T·`fastest` > 1e18, Φ and $Q_d$ are NaN: the filter takes τ no shorter
    than T·1e-15, where e^(−T/τ) is 0 either way); `ValueError` for a concrete F with a
    decay rate |F_ii| or an eigenvalue |λ| beyond `SERIES_LIMIT` over the series' step that
    `fastest` does not cover (the series alone read e^(−10) as 1343, and the rotation above as
    a growing Φ: the message names the `fastest` to pass), and for a concrete q that is not
    symmetric positive semi-definite; for a traced F (or `fastest`), an `eqx.error_if` when
    the step × |λ| estimated from tr F^k exceeds `TRACED_LIMIT` (gross errors only; not
    inside hrgjax's own callback-free programs, the filter's, whose F is its INS model).

    Called outside a trace it runs as one compiled program per (n, k, path): a second call
    compiles nothing."""
    gm = _decay_rate(fastest)
    if not finite_number("discretise: T", T, "s") > 0:
        raise ValueError(f"discretise: T must be the interval > 0 [s]; got {T!r}")
    n = np.shape(F)[0] if len(np.shape(F)) == 2 else -1
    if np.shape(F) != (n, n) or np.shape(q) != (n, n):
        raise ValueError(f"discretise: F and q must both be square (n, n); got {np.shape(F)} "
                         f"and {np.shape(q)}")  # fmt: skip
    check_finite_host("discretise: F", F)
    check_finite_host("discretise: q", q)
    k = max(1, math.ceil(T / 10.0 - 1e-12))
    checked = _check_model(F, q, T / k, fastest, gm)
    F, q = jnp.asarray(F), jnp.asarray(q)
    phi, qd, size = _discretised(F, q, float(T), fastest if gm else 0.0, k=k, gm=gm)
    if checked or tracing_callback_free():  # the filter's own program: F is its INS model
        return phi, qd
    # outside the fused program: equinox reads its error mode while tracing (_compiled.fused)
    return eqx.error_if((phi, qd), size > TRACED_LIMIT, _TRACED_MESSAGE)


SERIES_LIMIT = 0.125
"""The largest h·|decay rate| (h·|λ|, λ an eigenvalue of F) the eighth-order series takes in
one step of h (1/8: Φ's e^(−h/τ) to ≈ 1e-13); `fastest` squares a faster mode's steps down
to it."""

TRACED_LIMIT = 2 * SERIES_LIMIT
"""The largest series step × `_rate_estimate` `discretise` lets pass for a traced F (an
`eqx.error_if`): the estimate reads |λ| up to n^(1/5) high (6 Gauss–Markov states at 1/τ:
1.43×), so a traced check holds only the gross errors (the series alone read
[[−0.01, 5], [−5, −0.01]] over 1 s as a growing Φ, 2.6 for 0.28)."""

_TRACED_MESSAGE = (
    f"discretise: F (traced) has a mode too fast for the series over its step (step·|λ| > "
    f"{TRACED_LIMIT}, |λ| estimated from tr F^k): pass fastest= F's largest |eigenvalue| [1/s]"
)


def _check_model(F, q, h: float, fastest, gm: bool) -> bool:
    """Host checks of a concrete (F, q) for `discretise` over steps of `h` [s]: a decay rate
    |F_ii|, then an eigenvalue |λ| of F (a fast oscillation or coupling off the diagonal),
    the series cannot take over its step (h, or h/2^j with `fastest`) without a `fastest`
    that covers it, and a q that is not symmetric positive semi-definite, each a one-line
    `ValueError`. Returns whether F's rates were checked here (else `discretise` checks them
    in the trace)."""
    f, qv = concrete_value(F), concrete_value(q)
    given = concrete_value(fastest)
    checked = f is not None and (given is not None or not gm)
    if checked:
        f = np.asarray(f, float)
        covered = float(given) if gm else 0.0
        j = min(max(math.ceil(math.log2(8.0 * h * covered)), 0), MAX_SQUARINGS) if covered else 0
        step = h / 2.0**j  # the series' step, as _discretised takes it
        lam = float(np.max(np.abs(np.linalg.eigvals(f)))) if f.size else 0.0
        for rate, what, which in (
            (float(np.max(np.abs(np.diag(f)), initial=0.0)), "a decay rate |F_ii|", "1/τ in"),
            (lam, "an eigenvalue |λ|", "|λ| of"),
        ):
            if step * rate > SERIES_LIMIT * (1 + 1e-4):  # 1e-4: a fastest printed to 6 digits
                raise ValueError(
                    f"discretise: F has {what} = {rate:g} /s, too fast for the series over "
                    f"h = {h:g} s (h·rate > {SERIES_LIMIT}) with fastest = {covered:g}: "
                    f"pass fastest={rate:g} (the largest {which} F)"
                )
    if qv is not None:
        qv = np.asarray(qv, float)
        scale = max(float(np.max(np.abs(qv))), np.finfo(float).tiny)
        if np.max(np.abs(qv - qv.T)) > 1e-9 * scale:
            raise ValueError("discretise: q must be symmetric (a noise spectral density matrix)")
        low = float(np.min(np.linalg.eigvalsh(qv)))
        if low < -1e-9 * scale:
            raise ValueError(
                f"discretise: q must be positive semi-definite (a noise spectral density "
                f"matrix); its smallest eigenvalue is {low:g}"
            )
    return checked
