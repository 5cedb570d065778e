r"""The loops on their slow manifold: the averaged model reduced to the wave angle alone.

With the PI loops closed, the fast states $\mathbf x = (a, q, \varphi, I_\varphi,
I_{\rm agc}, I_q)$ settle within ≈ 1/bandwidth onto a manifold $\mathbf x = \mathbf h(\theta)$
that the slow wave angle drags along; on it $\dot\theta = G(\mathbf h(\theta), \theta)$.
The manifold solves the invariance equation

$$\mathbf F(\mathbf h, \theta) = \frac{\partial\mathbf h}{\partial\theta}\,
G(\mathbf h, \theta)$$

($\mathbf F$, $G$: the averaged model's fast and slow right-hand sides,
`hrgjax.resonator.averaged`). Write $\mathbf h = \mathbf h_0 + \boldsymbol\delta$ with
$\mathbf h_0$ the loops at rest, $\mathbf F(\mathbf h_0, \theta) = 0$ (Newton from
`steady_integrators`; with a perfect readout, the ideal-loop model). The lag δ is small (≈
1e-4 of a₀), so linearised, $\dot\theta\,\partial_\theta\boldsymbol\delta = J(\theta)\,
\boldsymbol\delta - \dot\theta\,\partial_\theta\mathbf h_0$, $J = \partial\mathbf F/\partial
\mathbf x$ at $\mathbf h_0$: a linear equation periodic in θ (period π: every term is a 2θ
harmonic), solved by harmonic balance on `SAMPLES` angles θ + jπ/N with the spectral
derivative. That holds the loops' lag to all orders in θ̇/β (β: the loop bandwidths) for a
wave turning at the instant's rate: at 10 °/s on the default gyro, once the loops' transient
has passed, its θ̇ equals the PI loops' to within 1 % of what the ideal loops miss (the bound
`tests/test_loops_plant.py` asserts; the ideal loops miss ≈ 3e-5 of the rate).

What the lag is: a loop holds its error at zero only for a constant disturbance.
While the wave turns, the quadrature the frequency split Δω drives varies as
$\sin2(\theta-\theta_\omega)$ and the quadrature loop lags it,
$q \approx \dot d/\beta^2$; that q, through the nonlinearity ($-\chi aq/4\omega$), the split
and the excitation phase, gives a wave-angle rate ∝ $\dot\theta\cos2(\theta-\theta_\omega)$:
a 2θ scale-factor ripple the ideal-loop model lacks. On the default gyro (χ = 5000 rad²/s²,
Δω = 2π·0.5 mHz, 2 rad/s loops) it is ≈ 3e-5 of the rate — what an ideal-loop grey box reads
as readout gain mismatch (+1.5e-5) and cross-talk (+3.9e-6).

Not held: the loops' transients after a step in rate or temperature (they decay as
$e^{-\beta t}$) and terms in $\dot T$ and $\dot\Omega$ (the manifold is taken at the
instant's rate and temperature).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import is_concrete
from .._linalg import solve
from .averaged import loop_field
from .control import steady_integrators
from .params import TemperatureLaw

SAMPLES = 9
"""Angles over one period of 2θ on which the manifold is balanced (odd: no Nyquist term);
they resolve the 2θ…8θ harmonics, where the lag of a 2θ disturbance lives (4θ from products
of two defects)."""

NEWTON = 2
"""Newton iterations for the loops at rest, from the ideal steady state."""


def _derivative_matrix(n: int) -> np.ndarray:
    """Spectral derivative d/dθ on n (odd) equispaced samples of one period π."""
    k = np.fft.fftfreq(n, d=1.0 / n) * 2.0  # wavenumbers of a period-π function
    eye = np.eye(n)
    return np.real(np.fft.ifft(1j * k[:, None] * np.fft.fft(eye, axis=0), axis=0))


_D = _derivative_matrix(SAMPLES)


def _split(y):
    """Averaged state (a, q, θ, φ, I…) → (fast x = (a, q, φ, I…), θ)."""
    return jnp.concatenate([y[:2], y[3:]]), y[2]


def _join(x, theta):
    return jnp.concatenate([x[:2], theta[None], x[2:]])


def _fields(g, omega_in, x, theta):
    """(F, G): the fast states' and the wave angle's rates at (x, θ)."""
    dy = loop_field(g, omega_in, _join(x, theta))
    return _split(dy)


def _at_rest(g, omega_in, theta):
    """h₀(θ), J = ∂F/∂x there and G(h₀, θ)."""
    a0 = g.control.amplitude
    integ = steady_integrators(g.control, g.resonator, a0, theta)
    x = jnp.concatenate([jnp.stack([a0, 0.0 * a0, 0.0 * a0]), integ])
    fast = lambda x: _fields(g, omega_in, x, theta)[0]
    for _ in range(NEWTON):
        x = x - solve(jax.jacfwd(fast)(x), fast(x))  # no LAPACK call under vmap: _linalg
    return x, jax.jacfwd(fast)(x), _fields(g, omega_in, x, theta)[1]


LOOPS = ("pll", "agc", "quadrature")
"""The PI loops the slow manifold needs closed (bandwidth > 0)."""


def open_loop(control):
    """The first of `control`'s PI loops that is open — `"all"` for a free resonator, else
    `(name, bandwidth [rad/s])` for a concrete bandwidth ≤ 0 (a temperature law: at its
    reference temperature) — or `None`."""
    if not control.enabled:
        return "all"
    for name in LOOPS:
        bandwidth = getattr(control, f"{name}_bandwidth")
        if isinstance(bandwidth, TemperatureLaw):
            known = all(is_concrete(x) for x in jax.tree_util.tree_leaves(bandwidth))
            bandwidth = bandwidth(bandwidth.t_ref, xp=np) if known else 1.0
        if is_concrete(bandwidth) and np.any(np.asarray(bandwidth, dtype=float) <= 0):
            return name, float(np.min(np.asarray(bandwidth, dtype=float)))
    return None


def _closed(g, theta):
    """`theta`, once `g`'s loops are known closed: an open one is refused (concrete) or
    raises when the program runs (traced bandwidths) — its fast states have no rest point to
    settle on (the Newton step's Jacobian is singular: NaN)."""
    loop = open_loop(g.control)
    if loop == "all":
        raise ValueError("the slow manifold is the PI loops': a free resonator "
                         "(Control.free()) has none; simulate it with the averaged model")  # fmt: skip
    if loop is not None:
        raise ValueError(f"the slow manifold needs every PI loop closed; Control.{loop[0]}_"
                         f"bandwidth = {loop[1]:g} rad/s opens that loop: give it one > 0")  # fmt: skip
    widths = [getattr(g.control, f"{n}_bandwidth") for n in LOOPS]
    if all(is_concrete(w) for w in widths):
        return theta
    widths = jnp.stack([jnp.min(w) for w in widths])
    return eqx.error_if(theta, jnp.any(widths <= 0), "the slow manifold needs every PI loop "
                        "closed: a traced Control bandwidth is <= 0 rad/s (an open loop)")  # fmt: skip


def slow_manifold(g, omega_in, theta):
    """The loops' fast states $\\mathbf h(\\theta) = (a, q, \\varphi, I_\\varphi, I_{\\rm agc},
    I_q)$ on the slow manifold (module docstring).

    **Arguments:** `g`, a [`hrgjax.Gyro`][] at its temperature (`gyro.at(T)`) with closed
    loops; `omega_in`, the equivalent input rate [rad/s]; `theta`, the electrical wave angle
    [rad].

    **Raises:** `ValueError` for force-to-rebalance mode and for open loops (a free
    resonator, a bandwidth of 0: no rest point, NaN); a traced bandwidth ≤ 0 raises when
    the program runs.
    """
    if g.control.mode == "ftr":
        raise ValueError("the slow manifold is whole-angle mode's (the wave turns freely); "
                         "force-to-rebalance holds it — give a gyro with Control(mode='wa')")  # fmt: skip
    theta = _closed(g, jnp.asarray(theta, dtype=jnp.result_type(float)))
    n = SAMPLES
    thetas = theta + (jnp.pi / n) * jnp.arange(n, dtype=jnp.result_type(float))
    h0, jac, rate = jax.vmap(lambda th: _at_rest(g, omega_in, th))(thetas)
    m = h0.shape[1]
    d = jnp.asarray(_D, dtype=h0.dtype)
    big_d = jnp.kron(rate[:, None] * d, jnp.eye(m))  # θ̇_j Σ_k D_jk (per state)
    blocks = jax.scipy.linalg.block_diag(*[jac[j] for j in range(n)])
    delta = solve(big_d - blocks, -big_d @ h0.reshape(-1)).reshape(n, m)
    return h0[0] + delta[0]


def reduced_rate(g, omega_in, theta):
    """Wave-angle rate θ̇ [rad/s] with the loops on their slow manifold (`slow_manifold`)."""
    theta = jnp.asarray(theta, dtype=jnp.result_type(float))
    return _fields(g, omega_in, slow_manifold(g, omega_in, theta), theta)[1]
