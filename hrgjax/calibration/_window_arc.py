r"""What a window's rate says of a law in wave angle: the average over the arc it turns.

A window's rate ([`reduce`][hrgjax.calibration.reduce]) is the least-squares slope of the
wave angle over its samples, and the slope of θ is a weighted mean of θ̇ over the window,
$\int w(\tau)\,\dot\theta(\tau)\,d\tau$ with the parabolic weight
$w(\tau) = 6(T^2/4 - \tau^2)/T^3$ (τ from the window's middle, T its length). While the wave
turns at v = k_e·|rate| (rad/s, electrical), a term cos kθ (or sin kθ) of the rate enters the
window's rate as its value at the window's mean angle times

$$F(x) = \frac{3(\sin x - x\cos x)}{x^3},\qquad x = k\,v\,T/2$$

(1 at rest; 0.998 for the 2θ term of a 3-s window at 5 °/s, 0.805 at 50 °/s, 0.377 at
100 °/s, and 0 at 155 °/s). The windows' slope is over samples, so the fits use the sum it
really forms, with τᵢ the sample times about the window's middle:

$$G_k = \sum_i \tau_i^2\,\mathrm{sinc}(k v\tau_i)\Big/\sum_i\tau_i^2$$

(`harmonic_gain`; exact to first order in the ripple for evenly spaced samples — the windows
of `reduce`, which cuts runs at time gaps — and the same sum as the discovery's
`sampled_gain`). F(x) of the continuous window with the same second moment,
T = dt·√(n² − 7/3) (`window_arc`), is within 3·10⁻⁵ of it at 30 samples and 50 °/s (the
window's span (n − 1)·dt put it 1.4 % off). A law that is not a Fourier series (the MLP's
networks) is averaged by quadrature over that window's arc instead: `ARC_NODES` Gauss nodes
of the weight w(τ) (2θ: G to 3·10⁻⁵ at 50 °/s and 30 samples, 6·10⁻⁴ at 100 °/s).

Left out, second order in the ripple: the wave turning unevenly as the scale factor ripples,
and the mean angle off the middle one. One window's reading of a 1 % 2θ ripple is 0.4 % off
at 50 °/s for it, but over windows at every angle it averages out: on the closed-form session
(0/20/40 °C, 3-s windows at 10 Hz) the Fourier fit's ripple came out 1.0000 of the truth at
50 °/s and 0.99997 at 100 °/s, 11 and 79 ppm RMS of the scale factor left.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ..units import DEG, group_temperatures
from ._compensator import LEVEL_TOLERANCE_C
from .reduce import RateWindows

ARC_NODES = 5
"""Quadrature nodes of the parabolic window weight across a window's arc (the MLP): the 2θ
average of a 3-s window at 100 °/s to 7·10⁻⁶, the 4θ one to 4·10⁻³ (3 nodes: 7·10⁻³ and
0.25)."""
ARC_TOLERANCE_DEG = 2.0
"""Windows whose arcs [° electrical] lie within this of each other share a scale-factor
cell of the MLP's targets (`bin_windows`), averaged over their mean arc."""
SERIES_LIMIT = 1e-2
"""Below this phase k·v·n·dt/2 [rad] a window's gain is its series 1 − (k v dt)²(3n² − 7)/120
(error < 10⁻¹⁰): a static window of 10⁶ samples needs no sum over them."""


def window_sampling(w: RateWindows) -> tuple[np.ndarray, np.ndarray]:
    """`(n, dt)` of each window: its sample count `stop − start` and its sample step
    `duration / (n − 1)` [s]; dt = 0 where a window has under 2 samples or no duration (a
    hand-built window of point values: gain 1, no arc)."""
    n = np.maximum(np.asarray(w.stop, dtype=int) - np.asarray(w.start, dtype=int), 1)
    duration = np.asarray(w.duration, dtype=float)
    dt = np.where((n >= 2) & (duration > 0), duration / np.maximum(n - 1, 1), 0.0)
    return n, dt


def turning_rate(w: RateWindows) -> np.ndarray:
    """How fast the wave turns in each window [rad/s, electrical]: k_e·|rate_dps|, the
    magnitude of the window's own wave-angle slope."""
    return w.k_e * np.abs(np.asarray(w.rate_dps, dtype=float)) * DEG


def harmonic_gain(w: RateWindows, k: int) -> np.ndarray:
    """G_k of each window (module docstring): what its rate holds of a term cos kθ or sin kθ
    of the rate, relative to the term at its mean angle θ [electrical]; shape (W,)."""
    n, dt = window_sampling(w)
    phase = k * turning_rate(w) * dt  # per sample [rad]
    gain = 1.0 - phase**2 * (3.0 * n**2 - 7.0) / 120.0  # the series, for short arcs
    full = 0.5 * phase * n >= SERIES_LIMIT
    for size in np.unique(n[full]):
        at = np.flatnonzero(full & (n == size))
        m = np.arange(size) - 0.5 * (size - 1)  # τ / dt
        # τ sin(kvτ)/(kv) = τ² sinc(kvτ/π): 1 at v = 0
        gain[at] = np.sinc(phase[at, None] * m / np.pi) @ (m * m) / (m @ m)
    return gain


def harmonic_gains(w: RateWindows, harmonics: int) -> np.ndarray:
    """G of the harmonics 2θ, 4θ, …, 2·`harmonics`·θ of each window, shape (W, harmonics)."""
    return np.stack([harmonic_gain(w, 2 * n) for n in range(1, harmonics + 1)], axis=-1)


def window_arc(w: RateWindows) -> np.ndarray:
    """The arc [rad, electrical] of the continuous window matching each window's second
    moment: v·dt·√(n² − 7/3) (module docstring); 0 for point values."""
    n, dt = window_sampling(w)
    return turning_rate(w) * dt * np.sqrt(np.maximum(n**2 - 7.0 / 3.0, 0.0))


def arc_quadrature(nodes: int = ARC_NODES) -> tuple[np.ndarray, np.ndarray]:
    """Gauss nodes x ∈ (−1, 1) and weights (summing to 1) of the weight 1 − x²: the interior
    Gauss–Lobatto nodes (Gauss–Jacobi α = β = 1), exact for polynomials up to degree
    2·`nodes` − 1."""
    leg = np.polynomial.legendre
    c = np.zeros(nodes + 2)
    c[-1] = 1.0  # P_{nodes+1}
    x = np.sort(leg.legroots(leg.legder(c)))
    lobatto = 2.0 / ((nodes + 1) * (nodes + 2) * leg.legval(x, c) ** 2)
    weights = lobatto * (1.0 - x**2)
    return x, weights / weights.sum()


def arc_angles(theta, arc, nodes: int = ARC_NODES) -> tuple[np.ndarray, np.ndarray]:
    """`(angles, weights)`: each window's `ARC_NODES` quadrature angles θ + (arc/2)·x [rad],
    shape (W, nodes), and the weights (nodes,) that average a law over them."""
    x, weights = arc_quadrature(nodes)
    angles = np.asarray(theta, float)[..., None] + 0.5 * np.asarray(arc, float)[..., None] * x
    return angles, weights


def arc_rows(features, theta, temperature_c, arc, nodes: int = ARC_NODES):
    """`features(θ [rad], T [°C])` (NumPy rows (..., d)) at each window's quadrature angles:
    `(x, weights)`, x (W, nodes, d) and weights (nodes,) for `window_average`; without any
    arc (point values) `(features(θ, T), None)`, one row a window."""
    if not np.any(arc):
        return features(theta, temperature_c), None
    angles, weights = arc_angles(theta, arc, nodes)
    return features(
        angles, np.broadcast_to(np.asarray(temperature_c)[:, None], angles.shape)
    ), weights


def arc_mean(law, theta, temperature_c, arc, nodes: int = ARC_NODES) -> np.ndarray:
    """A host law `law(θ, T)` (NumPy, any shape) averaged over each window's arc (θ [rad] or
    [°], `arc` [rad], T [°C]: (W,) each) as its rate averages it; shape (W,)."""
    rows, weights = arc_rows(lambda a, t: law(a, t)[..., None], theta, temperature_c, arc, nodes)
    return rows[..., 0] if weights is None else rows[..., 0] @ weights


def window_average(model, x, weights):
    """A window's model of its rate: `model` (one row (d,) → scalar) averaged over each
    window's quadrature rows `x` (W, nodes, d) with `weights` (nodes,); `weights` None:
    `x` is (W, d), one point a window. Traceable (jit, vmap)."""
    if weights is None:
        return jax.vmap(model)(x)
    return jax.vmap(jax.vmap(model))(x) @ jnp.asarray(weights, x.dtype)


def bin_windows(theta, temperature_c, arc, value, bin_deg: float):
    """Average `value` in cells of one temperature level, `bin_deg` of wave angle (period
    180°) and one arc (arcs within `ARC_TOLERANCE_DEG`, grouped as temperatures are).
    Temperature levels are the windows' temperatures grouped within `LEVEL_TOLERANCE_C`
    ([`group_temperatures`][hrgjax.units.group_temperatures], as the fits count distinct
    temperatures), so a sensor's noise does not make each window its own cell.

    **Returns:** `(theta, temperature_c, arc, value)` per non-empty cell; θ [rad] is the
    circular mean (in 2θ) of the cell's angles, the temperature and arc [rad] the means of
    its windows'.
    """
    folded = (np.degrees(theta) + 90.0) % 180.0
    cell_angle = np.floor(folded / bin_deg).astype(int)
    levels = group_temperatures(np.asarray(temperature_c, dtype=float), LEVEL_TOLERANCE_C)
    arcs = group_temperatures(np.degrees(np.asarray(arc, dtype=float)), ARC_TOLERANCE_DEG)
    _, t_idx = np.unique(levels, return_inverse=True)
    _, a_idx = np.unique(arcs, return_inverse=True)
    per_level = int(np.ceil(180.0 / bin_deg)) + 1
    keys = (a_idx.ravel() * (t_idx.max() + 1) + t_idx.ravel()) * per_level + cell_angle
    _, inv = np.unique(keys, return_inverse=True)
    count = np.bincount(inv)
    mean = lambda x: np.bincount(inv, weights=x) / count  # noqa: E731
    th = 0.5 * np.arctan2(mean(np.sin(2 * theta)), mean(np.cos(2 * theta)))
    return th, mean(temperature_c), mean(np.asarray(arc, dtype=float)), mean(value)
