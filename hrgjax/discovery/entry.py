r"""What a catalogue entry is: an [`Effect`][hrgjax.discovery.effects.Effect], its
[`Param`][hrgjax.discovery.effects.Param]s and the
[`Covariates`][hrgjax.discovery.effects.Covariates] its term reads, with the geometry the
terms share: a dwell window's gain on a 2θ harmonic
([`window_gain`][hrgjax.discovery.effects.window_gain]) and the angle a pickoff mismatch
reads ([`pickoff_angle`][hrgjax.discovery.effects.pickoff_angle]).

The entries themselves, and the model they add up to, are the catalogue:
`hrgjax.discovery.effects` (where every name here is importable too).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._compiled import fused
from ..units import T_REF_C


@dataclasses.dataclass(frozen=True)
class Param:
    """One parameter of an effect: `name`, model `unit`, a typical size `scale` (so
    optimisers see O(1) numbers), whether it is `regular` (defined under the null), and how
    a user reads it: `user_unit`, `user_factor` and `input_rate`. A pattern-rate parameter
    (`input_rate=True`) is reported as the input rate it imitates: θ̇ = −k_e·Ω, so a term f
    of the pattern rate reads as −f/k_e of input rate (°/h where f is in rad/s)."""

    name: str
    unit: str
    scale: float
    regular: bool = True
    user_unit: str = ""
    user_factor: float = 1.0
    input_rate: bool = False

    def user_scale(self, k_e: float) -> float:
        """Factor from the model unit to `user_unit` at angular gain `k_e`."""
        return self.user_factor * (-1.0 / k_e if self.input_rate else 1.0)


@dataclasses.dataclass(frozen=True)
class Effect:
    """A catalogue entry (DISCOVERY.md §2.3).

    - `name`: contract name; `title`: words; `where`: `"rate"` (adds to θ̇) or `"readout"`
      (adds to the measured angle).
    - `params`: its [`Param`][hrgjax.discovery.effects.Param]s (null = all zero, except
      nonregular ones, which only matter when the regular ones are non-zero).
    - `needs`: covariates the term reads; `signature`, `aliases`, `discriminate`: how it shows,
      what it is confused with, and the experiment that separates them.
    - `formula`: the term in user units, as the apparent input rate it adds (a readout term:
      the angle it adds), with `{param}` where each parameter's value goes (ΔT = T − 20 °C).
    - `term`: the term itself: `term(p, c, k_e)` → pattern rate [rad/s] for a rate term,
      `term(p, c)` → the pickoff mismatch pair (ε₁, ε₂) it adds for a readout term (the
      pairs of several readout terms add, then
      [`pickoff_angle`][hrgjax.discovery.effects.pickoff_angle] gives the angle) (p in the order of `params`,
      c the [`Covariates`][hrgjax.discovery.effects.Covariates]); `scales_gain`: the term
      changes the angular gain (reads k_e); `on_dwell`: a dwell grid (constant temperature
      per run, one switch-on) can reveal it; `shapes`: the generic shapes of
      [`leftover.SHAPES`][hrgjax.discovery.leftover.SHAPES] the term is (on dwell windows),
      so that a candidate is not taken for an uncovered shape it only partly imitates.
    - `record`: what the term reads of a whole continuous record before it is solved
      (None: nothing beyond the samples): `record(p, t, samples)` → `{covariate: (n,)
      samples}` replacing the record's own (`thermal_lag`: the temperature through its
      first-order lag of τ_th), with `t` the record's times [s] and `samples` its sampled
      covariates by [`Covariates`][hrgjax.discovery.effects.Covariates] name.
    - `inject`: how the synthetic data put it into a gyro (None: not generated yet):
      `inject(gyro, size)` → the [`hrgjax.Gyro`][] with the effect at `size`
      ([`generate.inject`][hrgjax.discovery.generate.inject], whose docstring says what
      `size` means for each effect).

    Adding an effect is one entry in `CATALOGUE`: the dwell regression
    ([`columns`][hrgjax.discovery.effects.Effect.columns]), the continuous simulation, the
    screening, the report and the synthetic data all read it from here.
    """

    name: str
    title: str
    where: str
    params: tuple[Param, ...]
    needs: tuple[str, ...]
    signature: str
    aliases: tuple[str, ...] = ()
    discriminate: str = ""
    formula: str = ""
    term: Callable | None = dataclasses.field(default=None, repr=False, compare=False)
    scales_gain: bool = False
    on_dwell: bool = True
    shapes: tuple[str, ...] = ()
    record: Callable | None = dataclasses.field(default=None, repr=False, compare=False)
    inject: Callable | None = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def size(self) -> int:
        """Number of parameters."""
        return len(self.params)

    @property
    def null(self):
        """Parameters at the null: regular ones 0, nonregular ones (time constants) at their
        typical size, where they have no effect."""
        return jnp.asarray([0.0 if p.regular else p.scale for p in self.params])

    @property
    def regular_names(self) -> tuple[str, ...]:
        """Names of the regular parameters (the fitted ones), in the order of `params`."""
        return tuple(p.name for p in self.params if p.regular)

    @property
    def nonregular_name(self) -> str | None:
        """Name of the nonregular parameter (a scanned time constant or bandwidth), or None."""
        return next((p.name for p in self.params if not p.regular), None)

    def rate(self, p, c: Covariates, k_e):
        """Pattern-rate contribution [rad/s] at parameters `p` (shape (q,), order of
        `params`), covariates `c` and angular gain `k_e` (read only by the terms that scale
        it: `scales_gain`)."""
        if self.where != "rate":
            raise ValueError(f"{self.name!r} is not a rate term")
        return self.term(p, c, k_e) + 0.0 * c.theta

    def readout(self, p, c: Covariates):
        """Measured-angle offset [rad] of a readout term at parameters `p` and covariates
        `c` (θ the true electrical angle), to all orders
        ([`pickoff_angle`][hrgjax.discovery.effects.pickoff_angle])."""
        if self.where != "readout":
            raise ValueError(f"{self.name!r} is not a readout term")
        return pickoff_angle(*self.term(p, c), c.theta)

    def window_rate(self, p, c: Covariates, k_e):
        """What the term adds to a dwell window's measured pattern rate [rad/s]: a rate
        term itself; a readout term g(θ) through θ̇_meas = (1 + ∂g/∂θ)·θ̇, linearised at the
        nominal rate −k_e·Ω and averaged over the window's arc (`c.harmonic_gain`)."""
        if self.where == "rate":
            return self.rate(p, c, k_e)
        f = lambda th: self.readout(p, eqx.tree_at(lambda x: x.theta, c, th))
        theta = jnp.asarray(c.theta, dtype=float)
        slope = jax.jvp(f, (theta,), (jnp.ones_like(theta),))[1]  # ∂g/∂θ
        return -k_e * c.rate * c.harmonic_gain * slope

    def columns(self, c: Covariates, k_e) -> np.ndarray:
        """The term's regressor columns (W, q) in the dwell regression: ∂(window rate)/∂p of
        its regular parameters at the null
        ([`window_rate`][hrgjax.discovery.effects.Effect.window_rate]) at the windows'
        covariates `c`."""
        return np.asarray(self._columns_program(c, k_e))

    @functools.cached_property
    def _columns_program(self):
        """[`columns`][hrgjax.discovery.effects.Effect.columns] as one compiled program per
        data shape: an eager `jacfwd` dispatched every operation of the term on its own,
        ≈ 0.2 s a call in the screening's refits."""
        regular = np.asarray([p.regular for p in self.params])

        def jac(c, k_e):
            return jax.jacfwd(lambda p: self.window_rate(p, c, k_e))(self.null)[:, regular]

        return jax.jit(jac)


class Covariates(eqx.Module):
    r"""What the terms may read, per sample (arrays of one shape, or scalars).

    - `theta`: electrical wave angle [rad]; `rate`: table rate about the sensitive axis [rad/s].
    - `temperature` [°C], `temperature_rate` [°C/s], `temperature_lagged`: the temperature
      after a first-order lag (for `thermal_lag`) [°C].
    - `amplitude`, `quadrature`: a and q [readout units] (0 when the data lack them).
    - `accel_z`: specific force along the sensitive axis [g]; `t_run`: time since the run
      started [s].
    - `harmonic_gain`: factor on every 2θ harmonic (1 for an instantaneous rate; the
      window average $3(\sin x - x\cos x)/x^3$ for a least-squares slope over a window in
      which θ sweeps ±x/2 around its mean, see [`window_gain`][hrgjax.discovery.effects.window_gain]).
    """

    theta: jax.Array
    rate: jax.Array = 0.0
    temperature: jax.Array = T_REF_C
    temperature_rate: jax.Array = 0.0
    temperature_lagged: jax.Array = T_REF_C
    amplitude: jax.Array = 1.0
    quadrature: jax.Array = 0.0
    accel_z: jax.Array = 0.0
    t_run: jax.Array = 0.0
    harmonic_gain: jax.Array = 1.0


@fused
def window_gain(x):
    r"""What a least-squares slope over a window sees of a 2θ harmonic when θ sweeps
    uniformly across the window by `x` [rad] (x = θ_end − θ_start):
    $F(x) = 3(\sin x - x\cos x)/x^3$ (F(0) = 1; the slope's parabolic weights averaged
    over the sweep). It applies alike to a rate term ∝ sin 2θ and to the slope of a readout
    offset ∝ sin 2θ."""
    x = jnp.abs(jnp.asarray(x, dtype=float))
    small = x < 1e-3
    xs = jnp.where(small, 1.0, x)
    exact = 3.0 * (jnp.sin(xs) - xs * jnp.cos(xs)) / xs**3
    return jnp.where(small, 1.0 - x**2 / 10.0, exact)


def pickoff_angle(eps_1, eps_2, theta):
    r"""θ_meas − θ [rad] of pickoffs with the mismatch pair (ε₁, ε₂) at the true electrical
    angle θ, exactly: the pickoff matrix I + E with E = ½[[−ε₁, ε₂], [ε₂, ε₁]] (a gain
    mismatch g = −ε₁/2, a cross-talk c = ε₂/2) reads
    $\Delta = \operatorname{atan2}(u,\ 1+v)$,
    $u = \tfrac12(\varepsilon_1\sin2\theta + \varepsilon_2\cos2\theta)$,
    $v = \tfrac12(\varepsilon_2\sin2\theta - \varepsilon_1\cos2\theta)$
    — to first order ½ε₁ sin 2θ + ½ε₂ cos 2θ, plus (ε₁² + ε₂²)/8-sized 4θ terms."""
    s2, c2 = jnp.sin(2 * theta), jnp.cos(2 * theta)
    u = 0.5 * (eps_1 * s2 + eps_2 * c2)
    v = 0.5 * (eps_2 * s2 - eps_1 * c2)
    return jnp.arctan2(u, 1.0 + v)
