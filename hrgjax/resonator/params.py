"""Resonator parameters and their temperature laws."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import (
    RULES,
    check_finite,
    check_numbers,
    check_positive,
    concrete_value,
    is_concrete,
    numeric_problem,
)
from ..units import T_REF_C, k_e_problem


def _as_float(x):
    # `jnp.array` copies: `jnp.asarray` shares a 64-byte-aligned NumPy buffer on CPU.
    return jnp.array(x, dtype=float)


PARAMETER_FORM = "a real number, an array of real numbers or a hrgjax.TemperatureLaw"
"""What a parameter field takes (`refuse_unconverted`'s default `form`)."""


class Unconverted:
    """What a parameter converter leaves in a field it cannot convert (a str, None, a dict,
    a bool, a complex or ragged value, a PRNG key): the value and why, for the module's
    `__check_init__` to refuse in one line naming the field (`refuse_unconverted`) — an
    `eqx.field` converter sees the value only, not the field's name."""

    __slots__ = ("value", "problem")

    def __init__(self, value, problem):
        self.value, self.problem = value, problem

    def __repr__(self):
        return f"Unconverted({self.problem})"


def _parameter_or_unconverted(x):
    problem = numeric_problem(x)
    return _as_float(x) if problem is None else Unconverted(x, problem)


def refuse_unconverted(module, form: str = PARAMETER_FORM) -> None:
    """Refuse, in one line naming `Owner.field`, the expected `form` and what was found, the
    first field of `module` its converter could not convert (an `Unconverted`): each
    module with parameter fields calls this first in its `__check_init__`."""
    for f in dataclasses.fields(module):
        value = getattr(module, f.name, None)
        if isinstance(value, Unconverted):
            raise TypeError(f"{type(module).__name__}.{f.name} must be {form}; got {value.problem}")


class TemperatureLaw(eqx.Module):
    r"""A parameter that depends on temperature.

    $$p(T) = (p_0 + p_1\,\Delta T + p_2\,\Delta T^2)\,e^{\lambda\,\Delta T},
    \qquad \Delta T = T - T_{\rm ref}$$

    Linear and quadratic laws set ``lam = 0``; an exponential law sets ``p1 = p2 = 0``.

    **Arguments:**

    - `p0`: value at the reference temperature (in the unit of the parameter it replaces).
    - `p1`, `p2`: linear [unit/°C] and quadratic [unit/°C²] coefficients.
    - `lam`: exponential rate [1/°C].
    - `t_ref`: reference temperature [°C] (20 °C by default).
    """

    p0: jax.Array = eqx.field(converter=_parameter_or_unconverted)
    p1: jax.Array = eqx.field(converter=_parameter_or_unconverted, default=0.0)
    p2: jax.Array = eqx.field(converter=_parameter_or_unconverted, default=0.0)
    lam: jax.Array = eqx.field(converter=_parameter_or_unconverted, default=0.0)
    t_ref: jax.Array = eqx.field(converter=_parameter_or_unconverted, default=T_REF_C)

    def __check_init__(self):
        refuse_unconverted(self, "a real number or an array of real numbers")
        for f in dataclasses.fields(self):  # a NaN coefficient made every value NaN
            if is_concrete(value := getattr(self, f.name)):
                check_finite(f"TemperatureLaw.{f.name}", value)

    def __call__(self, temperature_c, xp=jnp):
        """Evaluate the law at `temperature_c` [°C] (with `xp=np`, on the host: concrete
        coefficients, NumPy arrays out). A str, None, bool or complex is refused in one line
        (a str "20" was read as 20 °C); only the type is read (no check of a traced value)."""
        if (problem := numeric_problem(temperature_c)) is not None:
            raise TypeError(
                f"TemperatureLaw: temperature_c must be real numbers [°C]; got {problem}"
            )
        if xp is jnp:
            dt = jnp.asarray(temperature_c, dtype=float) - self.t_ref
            return (self.p0 + self.p1 * dt + self.p2 * dt**2) * jnp.exp(self.lam * dt)
        p0, p1, p2, lam, t_ref = (
            np.asarray(x, dtype=float) for x in (self.p0, self.p1, self.p2, self.lam, self.t_ref)
        )
        dt = np.asarray(temperature_c, dtype=float) - t_ref
        return (p0 + p1 * dt + p2 * dt**2) * np.exp(lam * dt)


def as_parameter(x):
    """A parameter field's value: a [`hrgjax.TemperatureLaw`][] as it is, real numbers as a
    float array (the converter of every parameter field that may follow a law); anything
    else (a str, None, a bool, a dict, a complex or ragged value, a PRNG key) is left as an
    `Unconverted` for the module's `__check_init__` to refuse naming the field
    (`refuse_unconverted`). A traced value is judged by its dtype only."""
    return x if isinstance(x, TemperatureLaw) else _parameter_or_unconverted(x)


def concrete_fields(module, names):
    """`(name, value)` for each field of `module` in `names` whose value can be checked now:
    not None, not a [`hrgjax.TemperatureLaw`][] (`simulate` checks a law over the run's
    temperatures) and not traced (checked inside the run)."""
    for name in names:
        value = getattr(module, name)
        if value is not None and not isinstance(value, TemperatureLaw) and is_concrete(value):
            yield name, value


def checked_temperature(temperature_c):
    """`temperature_c` [°C] if it is real numbers (traced or concrete), concrete ones finite
    and inside `plausible.RANGES["temperature_c"]`; else a one-line error naming it (what
    [`Resonator.at`][hrgjax.Resonator.at] and `Gyro.at` take from a user)."""
    check_numbers("temperature_c", temperature_c, "a temperature [°C]: a real number or array")
    if is_concrete(temperature_c):
        check_finite("temperature_c", temperature_c)
        plausible.check("temperature_c", temperature_c)
    return temperature_c


AXIS_ANGLE = ("in [-2π, 2π]", "rad (electrical; from degrees: × hrgjax.units.DEG)")
"""The range of the axes' angles θ_ω and θ_τ: they enter as 2θ (the axes repeat every π
electrical), so no radian value needs more than a turn either way, and 30 typed for 30° is
refused (a degree value of 6.28 or less cannot be told from radians)."""

LIMITS = {
    "omega": ("> 0", "rad/s"),
    "tau": ("> 0", "s"),
    "k_e": ("in (0, 1]", "(the electrical angular gain 2K, ≈ 0.554)"),
    "theta_omega": AXIS_ANGLE,
    "theta_tau": AXIS_ANGLE,
}
"""The range of each `Resonator` field a temperature law must keep (any other: finite); the
axes' angles' (`AXIS_ANGLE`) plain values too."""


def check_laws_at(owner: str, module, evaluated, temperature_c, limits) -> None:
    """Refuse, in one line naming `owner.field` and the temperature, a value a temperature
    law of `module` takes at `temperature_c` [°C] (in `evaluated`, `module` there) that is
    not finite or breaks its rule in `limits` ({field: (rule, unit)}): what `Resonator.at`
    and `Gyro.at` return must be a valid module (a τ law crossing 0 gave τ < 0). Concrete
    values only: under `jit` `simulate` holds laws to the same rules at run time."""
    for f in dataclasses.fields(module):
        if not isinstance(getattr(module, f.name), TemperatureLaw):
            continue
        v = concrete_value(getattr(evaluated, f.name))
        if v is None:
            continue
        rule, unit = limits.get(f.name, ("finite", ""))
        v = np.asarray(v, dtype=float)
        bad = ~(np.isfinite(v) & (RULES[rule](v) if rule in RULES else True))
        if not bad.any():
            continue
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        temps = np.asarray(concrete_value(temperature_c), dtype=float)
        at = temps[i[v.ndim - temps.ndim :]] if 0 < temps.ndim <= v.ndim else temps.ravel()[0]
        must = "finite" if rule == "finite" else f"finite and {rule}"
        raise ValueError(f"the temperature law of {owner}.{f.name} gives {v[i]:g} {unit} at "
                         f"{at:g} °C; it must be {must} there".replace("  ", " "))  # fmt: skip


def evaluate_at(tree, temperature_c):
    """Replace every `TemperatureLaw` leaf of a pytree by its value at `temperature_c` [°C]
    (unchecked: the library's own grids, e.g. the carrier step's temperature span, may lie
    outside a range the user narrowed; `Resonator.at` / `Gyro.at` check first)."""
    is_law = lambda x: isinstance(x, TemperatureLaw)
    return jax.tree_util.tree_map(
        lambda x: x(temperature_c) if is_law(x) else x, tree, is_leaf=is_law
    )


class Resonator(eqx.Module):
    r"""The n = 2 mode pair of a hemispherical resonator (PHYSICS.md §2).

    Equation of motion in the pendulum (electrical) plane, $\mathbf z = (x, y)$:

    $$\ddot{\mathbf z} + \mathbf D\dot{\mathbf z} + \mathbf K\mathbf z
    + 2k_e\Omega\,\mathbf J\dot{\mathbf z} + k_e\dot\Omega\,\mathbf J\mathbf z
    + \chi|\mathbf z|^2\mathbf z - \omega^2 h\cos(2\psi_r+2\gamma)\mathbf z = \mathbf f$$

    with $\mathbf D = \tfrac2\tau\mathbf I + \Delta(1/\tau)\mathbf A(\theta_\tau)$ and
    $\mathbf K = \omega^2\mathbf I + \omega\Delta\omega\,\mathbf A(\theta_\omega)$. All angles
    are **electrical** ($\theta = 2\theta_m$).

    Any field may be a [`hrgjax.TemperatureLaw`][]; [`Resonator.at`][hrgjax.Resonator.at]
    evaluates them at a temperature.

    **Arguments:**

    - `omega`: mean natural angular frequency ω [rad/s] (> 0).
    - `tau`: mean amplitude decay time τ [s], $2/\tau = 1/\tau_1 + 1/\tau_2$ (> 0).
    - `k_e`: electrical angular gain $k_e = 2K$ (Bryan factor K ≈ 0.277 → 0.554).
    - `delta_omega`: frequency split Δω [rad/s], $\omega_1^2-\omega_2^2 = 2\omega\Delta\omega$.
    - `theta_omega`: electrical angle of the ω₁ axis [rad], within ±2π (`AXIS_ANGLE`:
      degrees typed for radians are refused; × `hrgjax.units.DEG` converts them).
    - `delta_inv_tau`: damping anisotropy $\Delta(1/\tau) = 1/\tau_1 - 1/\tau_2$ [1/s].
    - `theta_tau`: electrical angle of the τ₁ (more damped if Δ(1/τ) > 0) axis [rad],
      within ±2π as `theta_omega`.
    - `chi`: isotropic cubic stiffness χ [rad²/s² per (readout unit)²].
    """

    omega: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter)
    tau: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter)
    k_e: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.554)
    delta_omega: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    theta_omega: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    delta_inv_tau: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    theta_tau: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    chi: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)

    def __check_init__(self):
        refuse_unconverted(self)
        for name, value in concrete_fields(self, ("omega", "tau")):
            check_positive(f"Resonator.{name}", value, "[rad/s]" if name == "omega" else "[s]")
        finite = ("k_e", "delta_omega", "theta_omega", "delta_inv_tau", "theta_tau", "chi")
        for name, value in concrete_fields(self, finite):
            check_finite(f"Resonator.{name}", value)
        for name, value in concrete_fields(self, ("theta_omega", "theta_tau")):
            v = np.asarray(value, dtype=float)
            if (bad := ~RULES[AXIS_ANGLE[0]](v)).any():
                got = v[tuple(np.argwhere(bad)[0])]
                raise ValueError(f"Resonator.{name} must be finite and {' '.join(AXIS_ANGLE)}; "
                                 f"got {got:g}")  # fmt: skip
        for _, k_e in concrete_fields(self, ("k_e",)):
            for value in np.ravel(np.asarray(k_e, dtype=float)):
                problem = k_e_problem(float(value))
                if problem:
                    raise ValueError(f"Resonator.k_e must be {problem}")
        problem = damping_problem(self) or stiffness_problem(self)
        if problem:
            raise ValueError(problem)

    def at(self, temperature_c) -> Resonator:
        """This resonator with every temperature law evaluated at `temperature_c` [°C].

        Traceable: `jax.vmap(res.at)(temperatures)` gives a batch of resonators.
        """
        temperature = checked_temperature(temperature_c)
        problem = damping_problem(self, temperature) or stiffness_problem(self, temperature)
        if problem:
            raise ValueError(problem)
        out = evaluate_at(self, temperature_c)
        check_laws_at("Resonator", self, out, temperature_c, LIMITS)
        return out

    @property
    def damping_matrix(self):
        r"""$\mathbf D = \tfrac2\tau\mathbf I + \Delta(1/\tau)\mathbf A(\theta_\tau)$ [1/s]."""
        return 2.0 / self.tau * jnp.eye(2) + self.delta_inv_tau * _a_matrix(self.theta_tau)

    @property
    def stiffness_matrix(self):
        r"""$\mathbf K = \omega^2\mathbf I + \omega\Delta\omega\,\mathbf A(\theta_\omega)$ [1/s²]."""
        return self.omega**2 * jnp.eye(2) + self.omega * self.delta_omega * _a_matrix(
            self.theta_omega
        )


def _a_matrix(beta):
    c, s = jnp.cos(2 * beta), jnp.sin(2 * beta)
    return jnp.stack([jnp.stack([c, s]), jnp.stack([s, -c])])


def _pair(resonator, names, temperature_c):
    """The two fields `names` of `resonator` as broadcast float arrays (laws evaluated at
    `temperature_c`), or None where one is traced, a law is not judged there (`temperature_c`
    None or traced, a batch of laws) or the shapes differ (judged where evaluated)."""
    values = []
    for name in names:
        x = getattr(resonator, name)
        if isinstance(x, TemperatureLaw):
            leaves = jax.tree_util.tree_leaves(x)
            if temperature_c is None or not all(is_concrete(v) for v in leaves):
                return None
            if any(np.ndim(v) for v in leaves):  # a batch of laws: judged where evaluated
                return None
            if not is_concrete(temperature_c):
                return None
            with np.errstate(over="ignore", invalid="ignore"):
                x = x(np.ravel(np.asarray(temperature_c, dtype=float)), xp=np)
        elif not is_concrete(x):
            return None
        values.append(np.asarray(x, dtype=float))
    try:
        return np.broadcast_arrays(*values)
    except ValueError:  # batches of different shapes: judged where evaluated
        return None


def _first_bad(resonator, names, temperature_c, bad):
    """(index, " at T °C" or "") of the first True of `bad` (over `_pair`'s arrays)."""
    i = tuple(int(k) for k in np.argwhere(bad)[0])
    at = ""
    if temperature_c is not None and any(
        isinstance(getattr(resonator, n), TemperatureLaw) for n in names
    ):
        temps = np.ravel(np.asarray(temperature_c, dtype=float))
        if bad.ndim and bad.shape[-1] == temps.size:
            at = f" at {temps[i[-1]]:g} °C"
    return i, at


def damping_problem(resonator, temperature_c=None) -> str | None:
    r"""One line naming `Resonator.delta_inv_tau` if it gives an axis negative damping:
    $1/\tau_{1,2} = 1/\tau \pm \Delta(1/\tau)/2$ are both > 0 only while
    $|\Delta(1/\tau)| < 2/\tau$ (else the less damped axis grows, $e^{+t/|\tau_2|}$, and the
    averaged, full and slow models integrate an unstable mode). `None` when it holds, or when
    τ or Δ(1/τ) is traced (`simulate` judges it at run time: `hrgjax._run_checks`).

    **Arguments:** `resonator`, a [`hrgjax.Resonator`][]; `temperature_c` [°C], where to
    evaluate its [`TemperatureLaw`][hrgjax.TemperatureLaw]s (`None`: a law is not judged,
    only plain values)."""
    return _axis_problem(
        resonator, ("tau", "delta_inv_tau"), temperature_c,
        lambda tau, dit: np.abs(dit) * tau < 2.0,
        lambda t, d, at: (
            f"Resonator.delta_inv_tau = {d:.6g} 1/s with Resonator.tau = {t:.6g} s{at} gives "
            f"one axis negative damping (1/τ₂ = 1/τ − |Δ(1/τ)|/2 = {1 / t - abs(d) / 2:.3g} "
            f"1/s): |Δ(1/τ)| must be < 2/τ = {2 / t:.6g} 1/s"),
    )  # fmt: skip


def _axis_problem(resonator, names, temperature_c, holds, say) -> str | None:
    """`say(base, delta, at)` for the first value (or law temperature) where the pair
    `names` (a positive base, its axes' difference) breaks `holds(base, delta)`; `None`
    where it holds or is traced. A base ≤ 0 or a non-finite value is `check_positive`'s /
    `check_finite`'s to refuse."""
    if (pair := _pair(resonator, names, temperature_c)) is None:
        return None
    base, delta = pair
    bad = np.isfinite(base) & (base > 0) & np.isfinite(delta) & ~holds(base, delta)
    if not bad.any():
        return None
    i, at = _first_bad(resonator, names, temperature_c, bad)
    return say(float(base[i]), float(delta[i]), at)


def stiffness_problem(resonator, temperature_c=None) -> str | None:
    r"""One line naming `Resonator.delta_omega` if it gives an axis no positive stiffness:
    the axes' stiffnesses $\omega^2 \pm \omega\Delta\omega$ (the eigenvalues of $\mathbf K$,
    PHYSICS.md §2) are both > 0 only while $|\Delta\omega| < \omega$ (else one axis has no
    restoring force and the full model's amplitude grows without bound: 4·10³⁷ after 0.5 s
    at Δω = 1.5 ω). `None` when it holds, or when ω or Δω is traced; laws as
    `damping_problem`."""
    return _axis_problem(
        resonator, ("omega", "delta_omega"), temperature_c,
        lambda omega, split: np.abs(split) < omega,
        lambda w, d, at: (
            f"Resonator.delta_omega = {d:.6g} rad/s with Resonator.omega = {w:.6g} rad/s{at} "
            f"gives one axis negative stiffness (ω² − ω|Δω| = {w * w - w * abs(d):.3g} "
            f"rad²/s²): |Δω| must be < ω"),
    )  # fmt: skip
