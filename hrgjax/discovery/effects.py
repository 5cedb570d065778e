r"""The effect catalogue of PHYSICS.md §10: named terms of the reduced wave-angle model.

$$\dot\theta = \sum_{\text{rate terms}} f_e(p_e;\,\mathbf c),\qquad
\theta_{\rm meas} = \theta + \sum_{\text{readout terms}} g_e(p_e;\,\theta) + \text{noise},$$

θ the electrical wave angle [rad], $\mathbf c$ the covariates
([`Covariates`][hrgjax.discovery.effects.Covariates]). Every term is exactly zero at its null
parameters (all zeros); magnitude/axis pairs are Cartesian so the null is a point, not a
circle. The names are the contract (DESIGN.md); each entry also records what it looks like,
what it is confused with and which experiment tells them apart (DISCOVERY.md §2.3).

What an entry is made of lives in `hrgjax.discovery.entry`, how the synthetic data inject it
in `hrgjax.discovery.injection`; their names are importable from here too.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .._checks import describe
from ..profiles import lag_at_knots
from ..resonator.params import TemperatureLaw
from ..resonator.readout import Readout
from ..units import DEG, DEG_PER_H, T_REF_C
from .entry import Covariates as Covariates
from .entry import Effect as Effect
from .entry import Param as Param
from .entry import pickoff_angle as pickoff_angle
from .entry import window_gain as window_gain
from .injection import LAG_TIME_S as LAG_TIME_S
from .injection import closed_loops, replace_leaf, set_drift_terms

NOMINAL = ("bias", "angular_gain", "damping_anisotropy")
"""The nominal model `base` (DESIGN.md)."""


_H = DEG_PER_H  # 1 °/h in rad/s: the natural size of a drift term


def _rate(name, unit, scale, user_unit, factor=1.0 / _H):
    """A pattern-rate parameter reported as input rate (°/h by default)."""
    return Param(name, unit, scale, True, user_unit, factor, True)


def _plain(name, unit, scale, user_unit=None, factor=1.0, regular=True):
    """A parameter reported in its own unit (times `factor`)."""
    return Param(name, unit, scale, regular, unit if user_unit is None else user_unit, factor)


def _e(
    name, title, where, params, needs, signature, aliases=(), discriminate="", formula="",
    *, term, scales_gain=False, on_dwell=True, shapes=(), record=None, inject=None,
):  # fmt: skip
    return Effect(
        name, title, where, tuple(params), tuple(needs), signature, tuple(aliases),
        discriminate, formula, term, scales_gain, on_dwell, tuple(shapes), record, inject,
    )  # fmt: skip


def _dt(c):
    return c.temperature - T_REF_C


def _s2(c):
    return c.harmonic_gain * jnp.sin(2 * c.theta)


def _c2(c):
    return c.harmonic_gain * jnp.cos(2 * c.theta)


def _q_over_a(c):
    return c.quadrature / c.amplitude


def _loop_ripple(p, c, k_e):
    r"""The closed loops' ripple on the true pattern rate (PHYSICS.md §4.7; measured on
    `presets.tvg3_like()`: 3.1·10⁻⁵ of the rate, axis 2θ_ω, lagging as 2k_eΩ nears the
    amplitude loop's 1 rad/s): $-k_e\Omega\,[r_c\cos(2\theta+\varphi) +
    r_s\sin(2\theta+\varphi)]$, $\varphi = \arctan(2k_e\Omega/B)$."""
    phi = jnp.arctan2(2.0 * k_e * c.rate, p[2])
    ripple = p[0] * jnp.cos(2 * c.theta + phi) + p[1] * jnp.sin(2 * c.theta + phi)
    return -k_e * c.rate * c.harmonic_gain * ripple


CATALOGUE: dict[str, Effect] = {
    e.name: e
    for e in (
        _e(
            "angular_gain",
            "angular gain k_e (nominal)",
            "rate",
            [_plain("k_e", "", 1e-3)],
            ["rate"],
            "wave angle turns at −k_e·Ω",
            formula="θ̇ = −{k_e}·Ω (the angular gain)",
            term=lambda p, c, k: -p[0] * c.rate,
            shapes=("Ω",),
        ),
        _e(
            "bias",
            "constant drift (nominal)",
            "rate",
            [_rate("b", "rad/s", _H, "°/h")],
            [],
            "constant pattern rate",
            formula="{b}",
            term=lambda p, c, k: p[0],
        ),
        _e(
            "damping_anisotropy",
            "damping anisotropy Δ(1/τ), axis θ_τ (nominal)",
            "rate",
            [_rate("d_c", "rad/s", _H, "°/h"), _rate("d_s", "rad/s", _H, "°/h")],
            ["theta"],
            "180°-periodic drift in θ, independent of q and Ω",
            ("drive_gain_mismatch", "readout_gain_mismatch"),
            "vary Ω: a rate term's angle error falls as 1/Ω, a readout error does not",
            formula="{d_c}·sin 2θ − {d_s}·cos 2θ",
            term=lambda p, c, k: p[0] * _s2(c) - p[1] * _c2(c),
            shapes=("2θ",),
        ),
        _e(
            "bias_temperature",
            "drift offset varying with T",
            "rate",
            [
                _rate("b1", "rad/s/°C", 0.01 * _H, "°/h/°C"),
                _rate("b2", "rad/s/°C²", 1e-4 * _H, "°/h/°C²"),
            ],
            ["temperature"],
            "offset tracking T, the same at every θ",
            ("thermal_lag", "warmup_transient"),
            "reversed temperature ramps; repeated runs",
            formula="{b1}·ΔT + {b2}·ΔT²",
            term=lambda p, c, k: p[0] * _dt(c) + p[1] * _dt(c) ** 2,
            shapes=("ΔT", "ΔT²"),
            inject=replace_leaf(
                lambda g: g.rate_bias, lambda g, s: TemperatureLaw(g.rate_bias, s * _H)
            ),
        ),
        _e(
            "angular_gain_temperature",
            "angular gain varying with T",
            "rate",
            [_plain("kappa_T", "1/°C", 1e-5, "ppm/°C", 1e6)],
            ["rate", "temperature"],
            "rate error ∝ Ω·(T − T₀)",
            ("rate_scale_factor",),
            "rotate at several T",
            formula="{kappa_T}·ΔT · Ω (ppm of the rate)",
            term=lambda p, c, k: -k * p[0] * _dt(c) * c.rate,
            scales_gain=True,
            shapes=("Ω·ΔT",),
            inject=replace_leaf(
                lambda g: g.resonator.k_e,
                lambda g, s: TemperatureLaw(g.resonator.k_e, g.resonator.k_e * s),
            ),
        ),
        _e(
            "rate_scale_factor",
            "scale factor varying with rate",
            "rate",
            [_plain("kappa_Omega", "s²", 1e-3, "ppm/(°/s)²", 1e6 * DEG**2)],
            ["rate"],
            "rate error ∝ Ω³",
            ("angular_gain_temperature",),
            "several rates at one temperature",
            formula="{kappa_Omega}·Ω² · Ω (Ω in °/s; ppm of the rate)",
            term=lambda p, c, k: -k * p[0] * c.rate**3,
            scales_gain=True,
            shapes=("Ω³",),
            inject=set_drift_terms(lambda s: {"rate_cubic": s / (100.0 * DEG) ** 2}),
        ),
        _e(
            "damping_anisotropy_temperature",
            "damping anisotropy varying with T",
            "rate",
            [
                _rate("d_c1", "rad/s/°C", 0.01 * _H, "°/h/°C"),
                _rate("d_s1", "rad/s/°C", 0.01 * _H, "°/h/°C"),
            ],
            ["theta", "temperature"],
            "180° drift pattern whose amplitude and phase change with T (seed: 3.5→0.7 °/h, 16°)",
            ("bias_temperature",),
            "several wave angles at each temperature",
            formula="({d_c1}·sin 2θ − {d_s1}·cos 2θ)·ΔT",
            term=lambda p, c, k: (p[0] * _s2(c) - p[1] * _c2(c)) * _dt(c),
            shapes=("2θ·ΔT",),
            inject=replace_leaf(
                lambda g: g.resonator.delta_inv_tau,
                lambda g, s: TemperatureLaw(g.resonator.delta_inv_tau, lam=s),
            ),
        ),
        _e(
            "frequency_split",
            "frequency split Δω, axis θ_ω, with residual quadrature",
            "rate",
            [
                _rate("f_c", "rad/s", 1e-3, "°/h per unit q/a"),
                _rate("f_s", "rad/s", 1e-3, "°/h per unit q/a"),
            ],
            ["theta", "amplitude", "quadrature"],
            "drift ∝ q/a with a 180° pattern",
            ("nonlinearity", "excitation_phase"),
            "offset the quadrature set-point",
            formula="−(q/a)·({f_c}·cos 2θ + {f_s}·sin 2θ)",
            term=lambda p, c, k: -_q_over_a(c) * (p[0] * _c2(c) + p[1] * _s2(c)),
        ),
        _e(
            "excitation_phase",
            "excitation phase error γ_e with quadrature",
            "rate",
            [_rate("p_gamma", "1/s", 1e-5, "°/h per unit q/a")],
            ["amplitude", "quadrature"],
            "drift ∝ q/a, independent of θ",
            ("frequency_split", "nonlinearity"),
            "change the drive level",
            formula="−{p_gamma}·(q/a)",
            term=lambda p, c, k: -_q_over_a(c) * p[0],
        ),
        _e(
            "nonlinearity",
            "Duffing nonlinearity with quadrature",
            "rate",
            [_rate("c_chi", "1/s per unit²", 1e-3, "°/h per unit a·q")],
            ["amplitude", "quadrature"],
            "drift ∝ a·q, independent of θ",
            ("excitation_phase", "frequency_split"),
            "change the amplitude set-point",
            formula="−{c_chi}·a·q",
            term=lambda p, c, k: -p[0] * c.amplitude * c.quadrature,
        ),
        _e(
            "drive_gain_mismatch",
            "drive (forcer) gain mismatch",
            "rate",
            [_rate("p_g", "rad/s", _H, "°/h")],
            ["theta"],
            "180° drift pattern with its axis at 0°/90°",
            ("damping_anisotropy",),
            "electrode swap / mode reversal",
            formula="−{p_g}·sin 2θ",
            term=lambda p, c, k: -p[0] * _s2(c),
            shapes=("2θ",),
        ),
        _e(
            "thermal_rate",
            "drift proportional to the temperature rate",
            "rate",
            [_rate("c_Tdot", "rad/s per °C/s", 10 * _H, "°/h per °C/min", 1 / (60 * _H))],
            ["temperature_rate"],
            "offset that flips sign with the ramp direction; beside `bias_temperature` (b₁) it "
            "is also what a thermometer lagging the gyro by τ gives: T_read = T − τṪ makes "
            "b₁·T_read + b₁τ·Ṫ, c = b₁τ exactly (c/b₁ a time constant of minutes, printed in "
            "s by `equations`)",
            ("thermal_lag",),
            "vary the ramp rate (against thermal_lag); a temperature sensor lag scales with Ṫ "
            "too: a second thermometer on the resonator, or the thermometer's own response to "
            "a temperature step",
            formula="{c_Tdot}·dT/dt",
            term=lambda p, c, k: p[0] * c.temperature_rate,
            on_dwell=False,
            shapes=("dT/dt",),
            inject=set_drift_terms(lambda s: {"temperature_rate": s * _H * 60.0}),
        ),
        _e(
            "thermal_lag",
            "drift following a lagged temperature",
            "rate",
            [
                _rate("b_L", "rad/s/°C", 0.01 * _H, "°/h/°C"),
                _plain("tau_th", "s", 300.0, regular=False),
            ],
            ["temperature_lagged"],
            "bias-vs-T loop (hysteresis) over a temperature cycle",
            ("bias_temperature", "thermal_rate"),
            "a fast temperature step",
            formula="{b_L}·(T_lag − 20 °C), T_lag: T through a first-order lag of {tau_th}",
            term=lambda p, c, k: p[0] * (c.temperature_lagged - T_REF_C),
            on_dwell=False,
            record=lambda p, t, samples: {
                "temperature_lagged": lag_at_knots(t, samples["temperature"], p[1])
            },
            inject=set_drift_terms(lambda s: {"lag": s * _H, "lag_time": LAG_TIME_S}),
        ),
        _e(
            "warmup_transient",
            "decaying drift after switch-on",
            "rate",
            [_rate("b_w", "rad/s", _H, "°/h"), _plain("tau_w", "s", 600.0, regular=False)],
            ["t_run"],
            "offset decaying from the start of each run",
            ("bias_temperature",),
            "several switch-ons at one temperature",
            formula="{b_w}·exp(−t_run/{tau_w})",
            term=lambda p, c, k: p[0] * jnp.exp(-c.t_run / p[1]),
            on_dwell=False,
            shapes=("t_run",),
            inject=set_drift_terms(lambda s: {"warmup": s * _H, "warmup_time": LAG_TIME_S}),
        ),
        _e(
            "acceleration_sensitivity",
            "drift ∝ specific force along the axis",
            "rate",
            [_rate("G", "rad/s per g", 0.01 * _H, "°/h/g")],
            ["accel_z"],
            "offset tracking a_z",
            (),
            "turn the gyro over (±g)",
            formula="{G}·a_z",
            term=lambda p, c, k: p[0] * c.accel_z,
            shapes=("a_z",),
        ),
        _e(
            "readout_gain_mismatch",
            "pickoff gain mismatch / cross-talk",
            "readout",
            [_plain("eps_1", "", 1e-3, "ppm", 1e6), _plain("eps_2", "", 1e-3, "ppm", 1e6)],
            ["theta"],
            "bounded 180° angle error; SF(θ) = 1 + ε₁cos2θ − ε₂sin2θ",
            ("damping_anisotropy",),
            "vary Ω: the angle error does not grow with time",
            formula="angle read out + ½·{eps_1}·sin 2θ + ½·{eps_2}·cos 2θ",
            term=lambda p, c: (p[0], p[1]),
            shapes=("2θ·Ω",),
            inject=replace_leaf(lambda g: g.readout, lambda g, s: Readout(gain_mismatch=s)),
        ),
        _e(
            "readout_gain_mismatch_temperature",
            "pickoff gain mismatch varying with T (scale-factor ripple ∝ T)",
            "readout",
            [
                _plain("eps_1T", "1/°C", 1e-4, "ppm/°C", 1e6),
                _plain("eps_2T", "1/°C", 1e-4, "ppm/°C", 1e6),
            ],
            ["theta", "temperature"],
            "scale-factor ripple ∝ cos 2θ whose size tracks T (seed: 1.3 % at 0 °C → 0.15 % at "
            "+60 °C); on a ramp an apparent rate ∝ Ṫ·sin 2θ",
            ("readout_gain_mismatch", "loop_ripple"),
            "rotations at several temperatures",
            formula="angle read out + ½·({eps_1T}·sin 2θ + {eps_2T}·cos 2θ)·ΔT",
            term=lambda p, c: (p[0] * _dt(c), p[1] * _dt(c)),
        ),
        _e(
            "loop_ripple",
            "closed-loop scale-factor ripple (frequency split through the control loops)",
            "rate",
            [
                _plain("r_c", "", 1e-5, "ppm", 1e6),
                _plain("r_s", "", 1e-5, "ppm", 1e6),
                _plain("loop_bw", "rad/s", 1.0, regular=False),
            ],
            ["theta", "rate", "rates"],
            "scale-factor ripple ∝ Ω·cos 2(θ − θ_ω) on the true pattern rate whose axis lags "
            "by atan(2k_eΩ/B) as the rate grows past the loops' bandwidth B; zero at rest",
            ("readout_gain_mismatch", "readout_gain_mismatch_temperature"),
            "rotate at rates below and above the loop bandwidth (the ripple's axis turns with Ω; "
            "a readout ripple's does not)",
            formula="({r_c}·cos(2θ+φ) + {r_s}·sin(2θ+φ))·Ω, φ = atan(2k_eΩ/{loop_bw}) "
            "(ppm of the rate)",
            term=_loop_ripple,
            scales_gain=True,
            shapes=("2θ·Ω", "2θ·Ω²"),
            inject=closed_loops,
        ),
    )
}
"""Every effect by contract name (PHYSICS.md §10)."""


def rate_term(name: str, p, c: Covariates):
    """Pattern-rate contribution [rad/s] of rate effect `name` with parameters `p` (shape
    (q,), order of its `params`) at covariates `c` (the terms that scale the angular gain:
    [`rate_term_with_gain`][hrgjax.discovery.effects.rate_term_with_gain])."""
    effect = _effect(name)
    if effect.scales_gain:
        raise ValueError(f"{name} scales the angular gain: use rate_term_with_gain")
    if effect.where != "rate":
        rates = sorted(n for n, e in CATALOGUE.items() if e.where == "rate" and not e.scales_gain)
        raise ValueError(f"{name!r} is not a rate term; rate terms: {rates}")
    return effect.rate(p, c, None)


def rate_term_with_gain(name: str, p, c: Covariates, k_e):
    """A term that scales the angular gain k_e [rad/s]: `angular_gain_temperature`
    (−k_e κ_T (T − T₀) Ω), `rate_scale_factor` (−k_e κ_Ω Ω³), `loop_ripple`."""
    effect = _effect(name)
    if not effect.scales_gain:
        raise ValueError(f"{name!r} does not scale the angular gain")
    return effect.rate(p, c, k_e)


def readout_term(name: str, p, c: Covariates):
    """Measured-angle offset [rad] of readout effect `name` (`readout_gain_mismatch`,
    `readout_gain_mismatch_temperature`) at covariates `c`."""
    effect = _effect(name)
    if effect.where != "readout":
        raise ValueError(f"{name!r} is not a readout term")
    return effect.readout(p, c)


def check_names(owner: str, names) -> tuple[str, ...]:
    """`names` (a list, tuple or any iterable of effect names, a generator too) as a tuple,
    or one line naming `owner`: `TypeError` for a str, None or a non-iterable, `ValueError`
    for a name not in `CATALOGUE`."""
    listed = not isinstance(names, str | bytes | None) and hasattr(names, "__iter__")
    names = tuple(names) if listed else names  # (a generator is read once, here)
    if not listed or any(not isinstance(n, str) or n not in CATALOGUE for n in names):
        kind = ValueError if listed else TypeError
        raise kind(f"{owner}: names must be a list of effect names; got {describe(names)} "
                   f"(catalogue: {sorted(CATALOGUE)})")  # fmt: skip
    return names


def _effect(name: str) -> Effect:
    if name not in CATALOGUE:
        raise ValueError(f"unknown effect {name!r}; the catalogue: {sorted(CATALOGUE)}")
    return CATALOGUE[name]


def pattern_rate(params: dict, c: Covariates, k_e=None):
    """θ̇ [rad/s] of the superset model: the sum of every rate term in `params`
    ({effect name: parameter array}; readout terms are skipped). The terms that scale the
    angular gain read `k_e` (default: the model's own `angular_gain`, which must then be
    present)."""
    if k_e is None:
        if "angular_gain" not in params:
            raise ValueError("params must contain 'angular_gain' (the k_e of −k_e·Ω)")
        k_e = params["angular_gain"][0]
    total = 0.0 * c.theta
    for name, p in params.items():
        effect = _effect(name)
        if effect.where == "rate":
            total = total + effect.rate(p, c, k_e)
    return total


def readout_angle(params: dict, c: Covariates):
    """θ_meas − θ [rad] of the readout terms in `params` (rate terms are skipped): their
    mismatch pairs add in the pickoff matrix, then
    [`pickoff_angle`][hrgjax.discovery.effects.pickoff_angle]."""
    e1, e2, any_ = 0.0, 0.0, False
    for name, p in params.items():
        effect = _effect(name)
        if effect.where == "readout":
            d1, d2 = effect.term(p, c)
            e1, e2, any_ = e1 + d1, e2 + d2, True
    return pickoff_angle(e1, e2, c.theta) if any_ else 0.0 * c.theta


def readout_slope(params: dict, c: Covariates):
    """∂(θ_meas − θ)/∂θ of the readout terms in `params` at covariates `c` [–]: the relative
    scale-factor change they put on a turning pattern."""
    f = lambda th: readout_angle(params, eqx.tree_at(lambda x: x.theta, c, th))
    theta = jnp.asarray(c.theta, dtype=float)
    return jax.jvp(f, (theta,), (jnp.ones_like(theta),))[1]


def window_rate(params: dict, c: Covariates, k_e=None):
    """A dwell window's measured pattern rate [rad/s] under the model `params` ({effect:
    full parameter array}), to all orders in the readout terms: the true angle solves
    θ + g(θ) = θ_meas (`c.theta`, fixed point), the rate terms read it, and the readout's
    slope scales the whole rate, θ̇_meas = (1 + ∂g/∂θ)·θ̇ (averaged over the window's arc:
    `c.harmonic_gain`). The terms that scale the angular gain read `k_e` (default: the
    model's own `angular_gain`). Its Jacobian at the null is the dwell regression's design
    ([`Effect.window_rate`][hrgjax.discovery.effects.Effect.window_rate])."""
    readouts = {n: p for n, p in params.items() if _effect(n).where == "readout"}
    theta = c.theta
    for _ in range(4 if readouts else 0):  # |∂g/∂θ| ≲ 0.03: ~1.5 digits a pass
        theta = c.theta - readout_angle(readouts, eqx.tree_at(lambda x: x.theta, c, theta))
    ct = eqx.tree_at(lambda x: x.theta, c, theta) if readouts else c
    total = pattern_rate(params, ct, k_e)
    if readouts:
        total = total * (1.0 + c.harmonic_gain * readout_slope(readouts, ct))
    return total


def null_params(names) -> dict:
    """{name: parameters at the null} for the given effects: regular parameters 0,
    nonregular ones (time constants) at their typical size, where they have no effect."""
    return {n: CATALOGUE[n].null for n in names}


def regular_parameters(names) -> list[tuple[str, str]]:
    """(effect, parameter) of each column of a fit's Jacobian: the regular parameters of the
    effects `names`, in that order (the order both data shapes build their Jacobian in)."""
    return [(n, p) for n in names for p in CATALOGUE[n].regular_names]
