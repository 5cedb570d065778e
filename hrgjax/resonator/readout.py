r"""Demodulation and readout errors (PHYSICS.md §3.3, §4.7, §5).

The pickoffs read $\mathbf z_m = (\mathbf I + \mathbf E)\mathbf z$. Each channel is
demodulated against the reference phase $\psi_r$ into in-phase/quadrature components
$x = C_x\cos\psi_r + S_x\sin\psi_r$ (likewise y), from which

$$E = C_x^2+S_x^2+C_y^2+S_y^2,\quad Q = 2(C_xS_y - C_yS_x),\quad
R = C_x^2+S_x^2-C_y^2-S_y^2,\quad S = 2(C_xC_y + S_xS_y)$$

and the whole-angle estimates $\hat\theta = \tfrac12\operatorname{atan2}(S, R)$,
$\hat a = \tfrac12(\sqrt{E+Q}+\sqrt{E-Q})$, $\hat q = \tfrac12(\sqrt{E+Q}-\sqrt{E-Q})$.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import RULES
from .params import TemperatureLaw, as_parameter, concrete_fields, refuse_unconverted

LIMITS = {  # field: (rule of `hrgjax._checks.RULES`, unit); why: `Readout`'s docstring
    "gain_mismatch": ("in (-0.5, 0.5)", "(a fraction, not percent)"),
    "cross_talk": ("in (-0.5, 0.5)", "(a fraction, not percent)"),
    "misalignment": ("in (-π/4, π/4)", "rad (mechanical)"),
}
"""The range of each `Readout` field; `simulate` holds temperature laws and traced values to
them too (`hrgjax.simulate._LAW_LIMITS`)."""


def check_limits(owner: str, module, limits) -> None:
    """Refuse a concrete field of `module` that is not finite or breaks its rule in `limits`
    ({field: (rule, unit)}) in one line naming `owner.field`, the range and the unit. A
    temperature law or a traced value passes here: `simulate` checks laws over the run's
    temperatures and traced values inside the run (`check_finite_leaves`)."""
    for name, value in concrete_fields(module, limits):
        rule, unit = limits[name]
        v = np.asarray(value, dtype=float)
        bad = ~(np.isfinite(v) & RULES[rule](v))
        if bad.any():
            got = v[tuple(np.argwhere(bad)[0])]
            raise ValueError(f"{owner}.{name} must be finite and {rule} {unit}; got {got:g}")


class Readout(eqx.Module):
    r"""Pickoff (readout) errors: the matrix $\mathbf E$ in $\mathbf z_m = (\mathbf I+\mathbf E)\mathbf z$.

    $$\mathbf E = \begin{pmatrix} g & c \\ c - 2\varepsilon_m & -g\end{pmatrix}$$

    To first order (PHYSICS.md §4.7) the estimated angle is
    $\hat\theta - \theta = -g\sin2\theta + (c-\varepsilon_m)\cos2\theta - \varepsilon_m$
    and the scale factor $\mathrm{SF}(\theta) = 1 - 2g\cos2\theta - 2(c - \varepsilon_m)\sin2\theta$:
    period 180° of electrical wave angle. The loops are steered by $\hat\theta$, so the same
    errors also act on the drive (PHYSICS.md §4.4).

    **Arguments:**

    - `gain_mismatch`: g, relative gain difference of the x (0°) and y (45°) pickoffs.
    - `cross_talk`: c, symmetric cross-coupling between the channels.
    - `misalignment`: $\varepsilon_m$ [rad, mechanical], misplacement of the 45° pickoff.

    Each must lie in its range (`LIMITS`), or is refused in one line: |g|, |c| < 0.5, as
    fractions, not percent (at g = ±1 a channel reads nothing, and the first-order
    formulas above hold only for errors of a few percent), and |ε_m| < π/4 (at π/4 the
    45° pickoff would sit on the 90° axis, electrically opposite the 0° one: no y channel).
    """

    gain_mismatch: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    cross_talk: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    misalignment: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        refuse_unconverted(self)
        check_limits("Readout", self, LIMITS)

    def matrix(self):
        """The pickoff matrix $\\mathbf I + \\mathbf E$ (evaluate temperature laws first)."""
        g, c, m = self.gain_mismatch, self.cross_talk, self.misalignment
        return jnp.stack([jnp.stack([1.0 + g, c]), jnp.stack([c - 2.0 * m, 1.0 - g])])

    def angle_slope(self, theta):
        r"""$d\hat\theta/d\theta$ at the (electrical) wave angle `theta` [rad] of a standing
        wave (q = 0), exactly: the pickoffs read $(\mathbf I + \mathbf E)(\cos\theta,
        \sin\theta)$ and $\hat\theta$ is its direction, so a small motion δ of the wave
        reads as slope·δ: $\det(\mathbf I + \mathbf E)/|(\mathbf I + \mathbf E)(\cos\theta,
        \sin\theta)|^2$, to first order the class docstring's
        $\mathrm{SF}(\theta) = 1 - 2g\cos2\theta - 2(c - \varepsilon_m)\sin2\theta$.
        `simulate` moves its rate noise's angle through it. Evaluate temperature laws first."""
        (a, b), (c, d) = self.matrix()
        x, y = jnp.cos(theta), jnp.sin(theta)
        u, v = a * x + b * y, c * x + d * y  # what the pickoffs read
        return (a * d - b * c) / (u * u + v * v)  # d atan2(v, u)/dθ


class Demodulated(eqx.Module):
    """Demodulated in-phase (C) and quadrature (S) components of the x and y pickoffs."""

    cx: jax.Array
    sx: jax.Array
    cy: jax.Array
    sy: jax.Array

    def transform(self, matrix) -> Demodulated:
        """Apply a 2×2 pickoff matrix to the (x, y) channels."""
        # elementwise, not `matrix @ …`: a 2 × 2 dot is a kernel of its own on XLA:CPU,
        # which does not fuse with the scalar arithmetic around it (the carrier-resolving
        # model evaluates this at every stage)
        m00, m01, m10, m11 = matrix[0, 0], matrix[0, 1], matrix[1, 0], matrix[1, 1]
        return Demodulated(
            cx=m00 * self.cx + m01 * self.cy,
            sx=m00 * self.sx + m01 * self.sy,
            cy=m10 * self.cx + m11 * self.cy,
            sy=m10 * self.sx + m11 * self.sy,
        )

    def eqrs(self):
        """Lynch's (E, Q, R, S) (PHYSICS.md §3.3)."""
        cx, sx, cy, sy = self.cx, self.sx, self.cy, self.sy
        e = cx**2 + sx**2 + cy**2 + sy**2
        q = 2.0 * (cx * sy - cy * sx)
        r = cx**2 + sx**2 - cy**2 - sy**2
        s = 2.0 * (cx * cy + sx * sy)
        return e, q, r, s


def from_pendulum(a, q, theta, phi) -> Demodulated:
    r"""Demodulated components of $x = a\cos\theta\cos\psi - q\sin\theta\sin\psi$,
    $y = a\sin\theta\cos\psi + q\cos\theta\sin\psi$ against $\psi_r = \psi - \varphi$."""
    ct, st, cp, sp = jnp.cos(theta), jnp.sin(theta), jnp.cos(phi), jnp.sin(phi)
    return Demodulated(
        cx=a * ct * cp - q * st * sp,
        sx=-a * ct * sp - q * st * cp,
        cy=a * st * cp + q * ct * sp,
        sy=-a * st * sp + q * ct * cp,
    )


def from_signals(z, zdot, psi_r, omega) -> Demodulated:
    r"""Instantaneous (ideal quadrature) demodulation of displacement and velocity:
    $C = x\cos\psi_r - (\dot x/\omega)\sin\psi_r$, $S = x\sin\psi_r + (\dot x/\omega)\cos\psi_r$."""
    c, s = jnp.cos(psi_r), jnp.sin(psi_r)
    v = zdot / omega
    return Demodulated(
        cx=z[0] * c - v[0] * s,
        sx=z[0] * s + v[0] * c,
        cy=z[1] * c - v[1] * s,
        sy=z[1] * s + v[1] * c,
    )


class Estimates(eqx.Module):
    """What the electronics know: estimated angle, amplitude, quadrature, phase error."""

    theta: jax.Array
    """Estimated electrical wave angle [rad] (branch chosen by the caller)."""
    amplitude: jax.Array
    quadrature: jax.Array
    phase: jax.Array
    """Phase of the antinode oscillation relative to the reference [rad]."""
    energy: jax.Array


def wrap_half_pi(x):
    """Wrap an angle [rad] to [-π/2, π/2) (θ and θ + π are the same standing wave)."""
    return (x + jnp.pi / 2) % jnp.pi - jnp.pi / 2


def continue_angle(theta, near, expected):
    """Samples `theta` (n,) of an angle known modulo π [rad] made continuous: from one sample to
    the next the angle turns by `expected` (n − 1,) [rad] plus the difference from it wrapped
    to ±π/2, and the first sample lies within π/2 of `near` — right while the true turn over
    each interval is within π/2 of the expected one (an unwrap that takes the turn nearest
    zero aliases once the wave turns over π/2 a sample). Adds whole multiples of π: the
    gradient is `theta`'s."""
    steps = jnp.round((expected - jnp.diff(theta)) / jnp.pi)
    first = jnp.round((near - theta[0]) / jnp.pi)
    return theta + jnp.pi * jnp.concatenate([first[None], first + jnp.cumsum(steps)])


def estimate(demod: Demodulated, theta_branch=None) -> Estimates:
    r"""Whole-angle estimates from measured demodulated components.

    $\tfrac12\operatorname{atan2}(S, R)$ fixes the angle only modulo π. With `theta_branch`
    (a continuous angle near the truth, e.g. the averaged model's state) the estimate is
    unwrapped next to it; without it the branch is chosen so that the antinode in-phase
    component is positive, which keeps the drive in phase with the velocity as the pattern
    passes ±90°.
    """
    e, q, r, s = demod.eqrs()
    raw = 0.5 * jnp.arctan2(s, r)
    if theta_branch is None:
        c_a = jnp.cos(raw) * demod.cx + jnp.sin(raw) * demod.cy
        theta = raw + jnp.where(c_a < 0, jnp.pi, 0.0)
    else:
        theta = theta_branch + wrap_half_pi(raw - theta_branch)
    ct, st = jnp.cos(theta), jnp.sin(theta)
    c_a = ct * demod.cx + st * demod.cy
    s_a = ct * demod.sx + st * demod.sy
    root_p = jnp.sqrt(jnp.maximum(e + q, 0.0))
    root_m = jnp.sqrt(jnp.maximum(e - q, 0.0))
    return Estimates(
        theta=theta,
        amplitude=0.5 * (root_p + root_m),
        quadrature=0.5 * (root_p - root_m),
        phase=jnp.arctan2(-s_a, c_a),
        energy=e,
    )
