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
`steady_integrators`; with a perfect readout, the ideal-loop model). Linearised in the lag
δ, $\dot\theta\,\partial_\theta\boldsymbol\delta = J(\theta)\,\boldsymbol\delta -
\dot\theta\,\partial_\theta\mathbf h_0$, $J = \partial\mathbf F/\partial\mathbf x$ at
$\mathbf h_0$: a linear equation periodic in θ (period π: every term is a 2θ harmonic),
solved by harmonic balance on `SAMPLES` angles θ + jπ/N with the spectral derivative. That
is the start: `BALANCE_NEWTON` Newton steps then solve the invariance equation itself on
those angles (the rate G taken on h, not on h₀: the lag's pull on θ̇ feeds back into it).
The linearised lag alone is wrong as the split grows against the quadrature loop's bandwidth
β_q, not as the lag q/a grows: at 10 °/s its mean defect drift is off by 0.03 % at Δω/β_q =
0.0016 (the default gyro), 1.8 % at 0.16, 31 % at 0.63 and 2.4× at 1.6 (the averaged PI-loop
runs' truth), where at 400 °/s and 0.16 a lag q/a = 0.019 is still right to 2e-5; with the
Newton steps it is right to ≤ 6e-6 up to Δω/β_q = 0.63. Above `MAX_SPLIT_RATIO` the balance
no longer converges (4 % off at 3.1, or diverging) and a split there is refused
(`split_problem`). That holds the loops' lag to all orders in θ̇/β (β: the loop
bandwidths) for a wave turning at the instant's rate: at 10 °/s on the default gyro, once
the loops' transient has passed, its θ̇ equals the PI loops' to within 1 % of what the
ideal loops miss (the bound `tests/test_loops_plant.py` asserts; the ideal loops miss ≈
3e-5 of the rate).

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

from .._checks import check_values, is_concrete
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

BALANCE_NEWTON = 3
"""Newton iterations on the nonlinear collocation equations, from the linearised lag (they
converge quadratically: at Δω/β_q = 0.63, 10 °/s, the mean drift's error goes 0.31 → 9e-4
→ 1e-7 → 4e-13 of it)."""

MAX_SPLIT_RATIO = 1.0
"""Largest frequency split the slow manifold takes, as |Δω|/β_q (β_q: the quadrature loop's
bandwidth [rad/s]). Measured against a converged balance (15 angles, 12 Newton steps, itself
within 6e-5 of the averaged PI-loop runs): the mean defect drift is right to ≤ 6e-6 of it
at |Δω|/β_q ≤ 0.63 (10 and 100 °/s), 1.4e-5…7.8e-3 at 1.57, and 4 % or diverged at 3.1 (the
balance's 9 angles and the Newton start then fail); `benchmarks/slow_manifold_domain.py`."""


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


def _linearised(g, omega_in, x, theta):
    """((F, G), (∂F/∂x, ∂G/∂x)) at (x, θ): the rates and their Jacobian, from one trace."""

    def both(x):
        rates = _fields(g, omega_in, x, theta)
        return rates, rates  # the second: jacfwd's aux, the primal values

    return jax.jacfwd(both, has_aux=True)(x)[::-1]


def _at_rest(g, omega_in, theta):
    """h₀(θ), J = ∂F/∂x there and G(h₀, θ): `NEWTON` steps from the ideal steady state, in a
    `fori_loop` (its body, one Jacobian, traced and compiled once; a fixed trip count, so
    reverse-differentiable), the last pass only evaluating."""
    a0 = g.control.amplitude
    integ = steady_integrators(g.control, g.resonator, a0, theta)
    x = jnp.concatenate([jnp.stack([a0, 0.0 * a0, 0.0 * a0]), integ])

    def step(i, carry):
        x = carry[0]
        (f, rate), (jac, _) = _linearised(g, omega_in, x, theta)
        last = i >= NEWTON  # the last pass only evaluates: its solve is on I, 0 (a singular
        # Jacobian at the rest point must not put 0·inf into the reverse pass)
        eye = jnp.eye(x.size, dtype=x.dtype)
        step_x = solve(jnp.where(last, eye, jac), jnp.where(last, 0.0, f))  # no LAPACK: _linalg
        return x - step_x, jac, rate

    # the carried Jacobian and rate are only written: any start value shaped like them, made
    # from x so that under vmap it is batched as they are (one batching pass over the body)
    start = (x, jnp.broadcast_to(x[0], (x.size, x.size)), x[0])
    return jax.lax.fori_loop(0, NEWTON + 1, step, start)


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


def split_problem(g, temperature_c=None, name: str = "gyro") -> str | None:
    """One line naming `{name}.resonator.delta_omega` if the split exceeds
    `MAX_SPLIT_RATIO` × the quadrature loop's bandwidth — where the slow manifold no longer
    holds — else `None` (also for traced values: `slow_manifold` holds those when it runs).

    **Arguments:** `g`, a [`hrgjax.Gyro`][]; `temperature_c` [°C], where to evaluate its
    [`TemperatureLaw`][hrgjax.TemperatureLaw]s (`None`: at their reference temperature);
    `name`, what the message calls the gyro."""
    values = []
    for x in (g.resonator.delta_omega, g.control.quadrature_bandwidth):
        if isinstance(x, TemperatureLaw):
            if not all(is_concrete(v) for v in jax.tree_util.tree_leaves(x)):
                return None
            temps = x.t_ref if temperature_c is None else temperature_c
            if not is_concrete(temps):
                return None
            x = x(np.ravel(np.asarray(temps, dtype=float)), xp=np)
        elif not is_concrete(x):
            return None
        values.append(np.ravel(np.asarray(x, dtype=float)))
    split, width = np.broadcast_arrays(*values)
    ratio = np.abs(split) / np.where(width > 0, width, np.inf)  # open loops: `_closed`'s
    bad = np.isfinite(ratio) & (ratio > MAX_SPLIT_RATIO)
    if not bad.any():
        return None
    i = int(np.flatnonzero(bad)[0])
    at = ""
    if temperature_c is not None and np.size(temperature_c) == split.size > 0:
        at = f" at {float(np.ravel(np.asarray(temperature_c, dtype=float))[i]):g} °C"
    return (
        f"{name}.resonator.delta_omega = {split[i]:.4g} rad/s ({split[i] / (2 * np.pi):.3g} "
        f"Hz){at} is {ratio[i]:.2f}× the quadrature loop's bandwidth ({name}.control."
        f"quadrature_bandwidth = {width[i]:.4g} rad/s): the slow manifold holds the loops' "
        f"lag for |Δω| ≤ {MAX_SPLIT_RATIO:g}× it only; trim the split or widen that loop"
    )


def _in_domain(g, theta):
    """`theta`, once `g`'s split is inside `MAX_SPLIT_RATIO` (`split_problem`): refused
    now when concrete, when the program runs when traced."""
    problem = split_problem(g)
    if problem:
        raise ValueError(problem)
    split, width = g.resonator.delta_omega, g.control.quadrature_bandwidth
    if is_concrete(split) and is_concrete(width):
        return theta
    bad = jnp.any(jnp.abs(split) > MAX_SPLIT_RATIO * width)
    return eqx.error_if(theta, bad, "the slow manifold holds the loops' lag only for |Δω| <= "
                        f"{MAX_SPLIT_RATIO:g}x the quadrature loop's bandwidth; a traced "
                        "gyro.resonator.delta_omega exceeds it")  # fmt: skip


def _block_diag(blocks):
    """(n, m, m) blocks → the (n·m, n·m) block-diagonal matrix."""
    return jax.scipy.linalg.block_diag(*[blocks[j] for j in range(blocks.shape[0])])


def _balanced(g, omega_in, thetas, h):
    """One Newton step on the collocation equations $\\mathbf F(\\mathbf h_j, \\theta_j) =
    G(\\mathbf h_j, \\theta_j)\\,(D\\mathbf h)_j$ at the samples `thetas`, from `h` (n, m)."""
    n, m = h.shape
    d = jnp.asarray(_D, dtype=h.dtype)
    (f, rate), (jac_f, jac_g) = jax.vmap(lambda x, th: _linearised(g, omega_in, x, th))(h, thetas)
    dh = d @ h  # ∂h/∂θ at the samples
    residual = (f - rate[:, None] * dh).reshape(-1)
    blocks = jac_f - dh[:, :, None] * jac_g[:, None, :]
    big = _block_diag(blocks) - jnp.kron(rate[:, None] * d, jnp.eye(m, dtype=h.dtype))
    return h - solve(big, residual).reshape(n, m)


def slow_manifold(g, omega_in, theta):
    """The loops' fast states $\\mathbf h(\\theta) = (a, q, \\varphi, I_\\varphi, I_{\\rm agc},
    I_q)$ on the slow manifold (module docstring).

    **Arguments:** `g`, a [`hrgjax.Gyro`][] at its temperature (`gyro.at(T)`) with closed
    loops; `omega_in`, the equivalent input rate [rad/s]; `theta`, the electrical wave angle
    [rad].

    **Raises:** `TypeError` for a `g` that is not a gyro or an `omega_in` or `theta` that is
    not real numbers; `ValueError` for one that is not one finite number (where its value is
    known on the host: a traced one passes; `jax.vmap` over many angles), for
    force-to-rebalance mode, for open loops (a free resonator, a bandwidth of 0: no rest
    point, NaN) and for a split |Δω| above `MAX_SPLIT_RATIO` × the quadrature loop's
    bandwidth (`split_problem`: the balance no longer converges); traced, a bandwidth ≤ 0 or
    such a split raises when the program runs.
    """
    omega_in, theta = _checked("slow_manifold", g, omega_in, theta)
    if g.control.mode == "ftr":
        raise ValueError("the slow manifold is whole-angle mode's (the wave turns freely); "
                         "force-to-rebalance holds it — give a gyro with Control(mode='wa')")  # fmt: skip
    theta = _closed(g, theta)
    theta = _in_domain(g, theta)
    n = SAMPLES
    thetas = theta + (jnp.pi / n) * jnp.arange(n, dtype=jnp.result_type(float))
    h0, jac, rate = jax.vmap(lambda th: _at_rest(g, omega_in, th))(thetas)
    m = h0.shape[1]
    d = jnp.asarray(_D, dtype=h0.dtype)
    big_d = jnp.kron(rate[:, None] * d, jnp.eye(m))  # θ̇_j Σ_k D_jk (per state)
    delta = solve(big_d - _block_diag(jac), -big_d @ h0.reshape(-1)).reshape(n, m)
    # the Newton steps in a fixed-trip `fori_loop`: one step traced and compiled, not
    # BALANCE_NEWTON of them (reverse-differentiable: it lowers to a scan)
    step = lambda _, h: _balanced(g, omega_in, thetas, h)
    return jax.lax.fori_loop(0, BALANCE_NEWTON, step, h0 + delta)[0]


def reduced_rate(g, omega_in, theta):
    """Wave-angle rate θ̇ [rad/s] with the loops on their slow manifold (`slow_manifold`).

    **Raises:** as [`slow_manifold`][hrgjax.resonator.slow.slow_manifold]."""
    omega_in, theta = _checked("reduced_rate", g, omega_in, theta)
    return _fields(g, omega_in, slow_manifold(g, omega_in, theta), theta)[1]


def _checked(owner: str, g, omega_in, theta):
    """(`omega_in`, `theta` as a float array) once `g` is a gyro and both are one real number
    each, finite where known on the host (a traced one passes), else a one-line error naming
    `owner` and the argument (a NaN gave NaN after seconds of eager work; an array of angles
    met the manifold's own samples in a broadcasting error)."""
    if not (hasattr(g, "control") and hasattr(g, "resonator")):
        raise TypeError(f"{owner}: g must be a hrgjax.Gyro at its temperature (gyro.at(T)); "
                        f"got {type(g).__name__}")  # fmt: skip
    out = []
    for name, x, what in (("omega_in", omega_in, "the input rate [rad/s]"),
                          ("theta", theta, "the electrical wave angle [rad]")):  # fmt: skip
        form = f"one finite real number ({what}; jax.vmap it over many)"
        x = check_values(f"{owner}: {name}", x, np.isfinite, form)
        if np.ndim(x) != 0:
            raise ValueError(f"{owner}: {name} must be {form}; got shape {np.shape(x)}")
        out.append(x)
    return out[0], jnp.asarray(out[1], dtype=jnp.result_type(float))
