"""What a design assumes the calibration fits: the physical grey box or a linear surrogate
of an empirical compensator, each as a measured pattern rate of its parameters; and the
noise on the measured pattern angle."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_number, concrete_value, describe, is_concrete
from ..gyro import Gyro
from ..pattern_noise import NoiseModel
from ..profiles import Profile
from ..units import DEG_PER_H, K_E_NOMINAL
from ._plan import float64_setting, settings_hash, settings_repr


def _coefficients(x):
    """(p0, p1, p2, lam) of a TemperatureLaw, or (x, 0, 0, 0) of a constant."""
    from ..resonator.params import TemperatureLaw

    if isinstance(x, TemperatureLaw):
        return tuple(float(v) for v in (x.p0, x.p1, x.p2, x.lam))
    return float(x), 0.0, 0.0, 0.0


def nominal_values(gyro: Gyro | None = None) -> jax.Array:
    """The physical grey box's parameter vector (order of
    [`physical.PARAMETERS`][hrgjax.calibration.physical.PARAMETERS], SI) read from `gyro`'s
    laws (default: `presets.tvg3_like()`): the point the design linearises about. Law terms
    outside the grey box's family (a curvature of k_e, …) are left out."""
    g = _default_gyro() if gyro is None else gyro
    res, ro = g.resonator, g.readout
    ke = _coefficients(res.k_e)
    bias = _coefficients(g.rate_bias)
    dit = _coefficients(res.delta_inv_tau)
    tht = _coefficients(res.theta_tau)
    gm = _coefficients(ro.gain_mismatch)
    ct = _coefficients(ro.cross_talk)
    return jnp.asarray(
        [ke[0], ke[1] / ke[0], bias[0], bias[1], bias[2], dit[0], dit[3], tht[0], tht[1],
         gm[0], gm[1], ct[0]],
        dtype=float,
    )  # fmt: skip


def _default_gyro() -> Gyro:
    """`presets.tvg3_like()`, its numbers on the host even inside a trace (`jax.jit` of a
    criterion with the default values and noise: they are constants of the program)."""
    from ..presets import tvg3_like

    with jax.ensure_compile_time_eval():
        return tvg3_like()


def _noisy(gyro: Gyro | None) -> tuple[Gyro, float]:
    """`gyro` (default `presets.tvg3_like()`), checked to have noise, and its k_e."""
    g = _default_gyro() if gyro is None else gyro
    if g.noise is None:
        raise ValueError("the design needs a gyro with noise (its Noise model)")
    return g, float(_coefficients(g.resonator.k_e)[0])


def pattern_noise_model(gyro: Gyro | None = None) -> NoiseModel:
    """The noise on `gyro`'s measured pattern angle (default `presets.tvg3_like()`): its
    [`NoiseModel.from_gyro`][hrgjax.pattern_noise.NoiseModel.from_gyro] with the k_e of its
    law at the reference temperature — the model the discovery uses for a known gyro."""
    g, k_e = _noisy(gyro)
    return NoiseModel.from_gyro(g.noise, k_e)


def pattern_arw(gyro: Gyro | None = None) -> float:
    """Angle random walk of the measured pattern angle [rad/√s]: k_e × the gyro's ARW
    (`pattern_noise_model(gyro).angle_random_walk`; default gyro: 0.554 × 0.002 °/√h)."""
    return pattern_noise_model(gyro).angle_random_walk


def pattern_gauss_markov(gyro: Gyro | None = None) -> tuple[float, float]:
    """The gyro's Gauss–Markov rate (bias instability) on the measured pattern angle:
    (σ [rad/s] = k_e × `noise.bias_instability`, correlation time [s]) —
    `pattern_noise_model(gyro)`'s (`gm_sigma`, `gm_time`); default gyro: 0.554 × 0.003 °/h,
    600 s."""
    model = pattern_noise_model(gyro)
    return model.gm_sigma, model.gm_time


def pattern_angle_white(gyro: Gyro | None = None) -> float:
    """White readout noise on the measured pattern angle [rad per sample]: the gyro's
    `noise.angle_white` (`pattern_noise_model(gyro).angle_white`; default gyro: 1″)."""
    return pattern_noise_model(gyro).angle_white


def noise_vector(arw, gauss_markov, angle_white=None) -> jax.Array:
    """The design's noise vector [N, σ, τ, σ_a]: pattern ARW [rad/√s], Gauss–Markov σ
    [rad/s] and correlation time [s], white angle noise [rad per sample] — the fields of a
    [`NoiseModel`][hrgjax.pattern_noise.NoiseModel] as (possibly traced) numbers (defaults:
    the default gyro's, `pattern_noise_model()`).

    **Raises:** `ValueError` (`TypeError` for a non-number) in one line naming the field,
    for a concrete value (traced ones pass: the design differentiates with respect to
    them) that is not one finite real number, an `arw` or τ ≤ 0, a σ or `angle_white` < 0,
    or one beyond its range in [`hrgjax.plausible.RANGES`][hrgjax.plausible.RANGES] (the
    `hrgjax.Noise` ones, `NOISE_FIELDS`: a datasheet's °/√h, °/h or arc-seconds typed as
    SI), or a `gauss_markov` that is not a pair (σ, τ)."""
    if arw is None or gauss_markov is None or angle_white is None:
        default = pattern_noise_model()
        arw = default.angle_random_walk if arw is None else arw
        if gauss_markov is None:
            gauss_markov = (default.gm_sigma, default.gm_time)
        angle_white = default.angle_white if angle_white is None else angle_white
    try:
        sigma, tau = gauss_markov
    except (TypeError, ValueError):
        raise ValueError("gauss_markov must be a pair (σ [rad/s], τ [s]) or None; got "
                         f"{describe(gauss_markov)}") from None  # fmt: skip
    for name, x in (("arw", arw), ("gauss_markov σ", sigma), ("gauss_markov τ", tau),
                    ("angle_white", angle_white)):  # fmt: skip
        if is_concrete(x):
            _check_noise_number(name, x)
    return jnp.asarray([arw, sigma, tau, angle_white], dtype=float)


NOISE_FIELDS = {
    "arw": ("> 0", "rad/√s", "noise_arw"),
    "gauss_markov σ": ("≥ 0", "rad/s", "noise_bias_instability"),
    "gauss_markov τ": ("> 0", "s", None),
    "angle_white": ("≥ 0", "rad per sample", "noise_angle_white"),
}
"""Each noise argument of the design: its sign, unit and range in
[`hrgjax.plausible.RANGES`][hrgjax.plausible.RANGES] (`hrgjax.Noise`'s: the pattern's ARW
and σ are k_e × the gyro's, inside the gyro's range)."""


def _check_noise_number(name: str, x) -> None:
    """Refuse the concrete noise argument `name` (`NOISE_FIELDS`) in one line."""
    sign, unit, quantity = NOISE_FIELDS[name]
    check_number(name, x, unit)
    value = float(np.asarray(x))
    ok = value > 0 if sign == "> 0" else value >= 0
    if not (np.isfinite(value) and ok):
        raise ValueError(f"{name} must be a finite number {sign} [{unit}]; got {value:g}")
    if quantity is not None:
        plausible.check(name, value, quantity)


def measured_rate(values, theta, temperature_c, rate, temperature_rate):
    """Rate of the measured pattern angle [rad/s] of the grey box `values` at true pattern
    angle `theta` [rad], temperature [°C], table rate `rate` [rad/s] and temperature rate
    [°C/s]: dθ̂/dθ · θ̇ + ∂θ̂/∂T · Ṫ (ideal loops, PHYSICS.md §10; the averaged field and
    the readout map of `physical.model_gyro`)."""
    from ..resonator.averaged import averaged_vector_field
    from ._physical_model import model_gyro, readout_angle

    gyro = model_gyro(values)
    g = gyro.at(temperature_c)
    one = jnp.ones_like(theta)
    slope = jax.jvp(lambda th: readout_angle(g, th), (theta,), (one,))[1]
    rest = Profile.static(1.0)
    prof = eqx.tree_at(
        lambda p: (p.rate, p.temperature),
        rest,
        (jnp.broadcast_to(rate, (2,)), jnp.broadcast_to(temperature_c, (2,))),
    )
    theta_dot = averaged_vector_field(0.0, theta[None], (gyro, prof))[0]
    d_temp = jax.jvp(lambda temp: readout_angle(gyro.at(temp), theta), (temperature_c,), (one,))[1]
    return slope * theta_dot + d_temp * temperature_rate


class GreyBox(eqx.Module):
    """The physical grey box as the design sees it: parameters
    [`physical.PARAMETERS`][hrgjax.calibration.physical.PARAMETERS] (SI), the measured rate
    [`measured_rate`][hrgjax.calibration.design.measured_rate], k_e = `values[0]`, each
    parameter's typical uncertainty `physical.PARAMETERS`' scale."""

    name: str = eqx.field(static=True, default="physical")

    def rate(self, values, theta, temperature_c, rate, temperature_rate):
        """Rate of the measured pattern angle [rad/s] (`measured_rate`)."""
        return measured_rate(values, theta, temperature_c, rate, temperature_rate)

    def gain(self, values):
        """k_e of `values` (the pattern turns at −k_e Ω)."""
        return values[0]

    def scale(self) -> jax.Array:
        """Typical uncertainty of each parameter (SI): the prior is `prior_scale` × this."""
        from ._physical_model import PARAMETERS

        return jnp.asarray(np.array([p[2] for p in PARAMETERS]))

    def nominal(self) -> jax.Array:
        """The linearisation point: `nominal_values()`."""
        return nominal_values()


class Empirical(eqx.Module):
    r"""A linear surrogate of an *empirical* compensator (an MLP, a Fourier fit): what it
    must learn from the bench, with no physics to carry it between points. The drift
    D(θ, T) [rad/s], the scale factor's departure SF − 1 and the readout's temperature
    sensitivity s_T(θ, T) [rad/°C] are each a sum of the products of
    $1, \cos 2n\theta, \sin 2n\theta$ (n ≤ `harmonics`) and Legendre polynomials of
    (T − 10 °C)/50 °C up to `degree`, and the measured pattern rate is
    $-k_e(\mathrm{SF}\,\Omega + D) + s_T\dot T$ (k_e = `k_e`). Its coefficients have a
    Gaussian prior of magnitude `drift_dph` [°/h], `scale_factor` and `st_rad_per_c`
    [rad/°C] — the size of the default gyro's laws —, which is what keeps points the plan
    does not visit uncertain: a design for this model must cover the temperatures and
    angles the gyro will meet, and ramp at the angles where s_T shows. (`scale()` is 1/100
    of these magnitudes, so that the criteria's default `prior_scale = 100` puts the prior
    at them.) Linear: the linearisation point does not matter (`nominal()` is zero).
    The four magnitudes are float64 0-d arrays (`float()` reads one): values of the
    criteria's and `design`'s programs, so another magnitude compiles nothing (as static
    fields each new one compiled four programs again, ≈ 5 s)."""

    harmonics: int = eqx.field(static=True, default=2)
    degree: int = eqx.field(static=True, default=5)
    drift_dph: float = eqx.field(default=0.5, converter=float64_setting)
    scale_factor: float = eqx.field(default=0.01, converter=float64_setting)
    st_rad_per_c: float = eqx.field(default=1e-4, converter=float64_setting)
    k_e: float = eqx.field(default=K_E_NOMINAL, converter=float64_setting)
    name: str = eqx.field(static=True, default="empirical")
    __repr__ = settings_repr
    __hash__ = settings_hash

    def __check_init__(self):
        if self.harmonics < 0 or self.degree < 0:
            raise ValueError(
                f"Empirical: harmonics and degree must be ≥ 0; got {self.harmonics}, {self.degree}"
            )

    @property
    def terms(self) -> int:
        """Basis functions per law: (1 + 2 harmonics) × (degree + 1)."""
        return (1 + 2 * self.harmonics) * (self.degree + 1)

    def basis(self, theta, temperature_c):
        """The `terms` basis functions at one (θ [rad], T [°C])."""
        angle = [jnp.ones_like(theta)]
        for n in range(1, self.harmonics + 1):
            angle += [jnp.cos(2 * n * theta), jnp.sin(2 * n * theta)]
        x = (temperature_c - 10.0) / 50.0
        legendre = [jnp.ones_like(x), x]
        for k in range(1, self.degree):  # Bonnet: (k+1)P_{k+1} = (2k+1)x P_k − k P_{k−1}
            legendre.append(((2 * k + 1) * x * legendre[k] - k * legendre[k - 1]) / (k + 1))
        return jnp.stack([a * p for a in angle for p in legendre[: self.degree + 1]])

    def rate(self, values, theta, temperature_c, rate, temperature_rate):
        """Rate of the measured pattern angle [rad/s]: −k_e(SF Ω + D) + s_T Ṫ."""
        b = self.basis(theta, temperature_c)
        n = self.terms
        drift, sf, s_t = b @ values[:n], 1.0 + b @ values[n : 2 * n], b @ values[2 * n :]
        return -self.k_e * (sf * rate + drift) + s_t * temperature_rate

    def gain(self, values):
        """The nominal k_e (the surrogate does not fit it)."""
        return self.k_e

    def scale(self) -> jax.Array:
        """1/100 of each coefficient's prior magnitude: drift [rad/s], SF − 1, s_T [rad/°C]."""
        n = self.terms
        mags = (self.drift_dph * DEG_PER_H, self.scale_factor, self.st_rad_per_c)
        return jnp.concatenate([jnp.full(n, m / 100.0) for m in mags])

    def nominal(self) -> jax.Array:
        """Zeros (a linear model)."""
        return jnp.zeros(3 * self.terms)


GREY_BOX = GreyBox()
"""The physical grey box (the default model of every criterion)."""

MODELS = ("physical", "empirical")
"""What the calibration fits, by name: `physical` ([`GreyBox`][hrgjax.calibration.design.GreyBox])
or `empirical` ([`Empirical`][hrgjax.calibration.design.Empirical]`()`); an `Empirical(...)`
instance may be passed as well."""


def as_model(model):
    """`model` (None, a name of `MODELS`, or a GreyBox / Empirical) as a model object."""
    if model is None or model == "physical":
        return GREY_BOX
    if model == "empirical":
        return Empirical()
    if isinstance(model, (GreyBox, Empirical)):
        return model
    raise ValueError(f"model must be one of {MODELS} or an Empirical(...); got {model!r}")


def model_values(values, model):
    """`values` as a float array, or `model`'s linearisation point (`nominal()`) for None.

    **Raises:** `ValueError` naming `values` when its shape is not `model`'s parameter
    vector's (`nominal()`: the grey box's 12, in
    [`physical.PARAMETERS`][hrgjax.calibration.physical.PARAMETERS] order), or — where its
    numbers are known on the host — one is not finite, or the grey box's k_e = `values[0]`
    is not > 0 (every criterion was NaN, or a broadcasting error, before)."""
    if values is None:
        return model.nominal()
    expected = model.scale().shape
    order = "physical.PARAMETERS" if isinstance(model, GreyBox) else f"the {model.name} model's"
    what = f"values must be {expected[0]} finite numbers in {order} order (the linearisation point)"
    shape = np.shape(values)
    if shape != expected:
        raise ValueError(f"{what}; got shape {shape}")
    given = concrete_value(values)
    if given is not None:
        given = np.asarray(given, dtype=float)
        bad = np.flatnonzero(~np.isfinite(given))
        if bad.size:
            raise ValueError(f"{what}; got {given[bad[0]]} at index {bad[0]}")
        if isinstance(model, GreyBox) and not given[0] > 0:
            raise ValueError(f"{what}, k_e = values[0] > 0; got k_e = {given[0]}")
    return jnp.asarray(values, dtype=float)
