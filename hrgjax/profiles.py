"""Rate, temperature and acceleration profiles (piecewise-linear in time)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import plausible
from ._checks import (
    FINITE_POSITIVE,
    check_finite,
    check_finite_host,
    check_number,
    check_numbers,
    check_values,
    concrete_value,
    finite_number,
    is_concrete,
    numeric_problem,
)
from ._compiled import device, fused
from .resonator.params import Unconverted, refuse_unconverted
from .units import DEG, DEG_PER_S


def _f(x):
    if isinstance(x, jax.Array) or (  # a jax value or a tracer, or a list holding one
        isinstance(x, list | tuple) and any(isinstance(v, jax.Array) for v in jax.tree.leaves(x))
    ):
        return jnp.asarray(x, dtype=float)
    # Host values: a copy, not `jnp.asarray`'s small compiled program per new shape; concrete
    # even inside `jax.jit` (knot times must stay concrete there, see `_eager`).
    with jax.ensure_compile_time_eval():
        return device(x, float)


def _field(x, bools=False):
    """A field's converter: `_f`, or an `Unconverted` (a str, None, a bool, a complex or
    ragged value, a PRNG key) that `Profile.__check_init__` refuses naming the field."""
    problem = numeric_problem(x, bools)
    return _f(x) if problem is None else Unconverted(x, problem)


def _optional(x):
    return x if x is None else _field(x)


def _schedule(x):
    return x if x is None else _field(x, bools=True)


def _finite(name, x):
    """Refuse a NaN or inf in `x` in one line: a known one (concrete, or an eager `grad`'s)
    now, with its index as plain ints; a traced one where the transformation runs eagerly
    (`check_finite`: an eager `vmap`), its banner dropped; under `jit`, `simulate`'s."""
    if (value := concrete_value(x)) is not None:
        check_finite_host(name, value)
        return
    try:
        check_finite(name, x)
    except eqx.EquinoxRuntimeError:  # equinox's banner and JAX's callback trace: one line
        raise ValueError(f"{name} must be finite (found NaN or inf)") from None


def _eager(fn, *args):
    """`fn(*args)`, computed eagerly when every argument is concrete: knot times built from
    Python numbers stay concrete inside `jax.jit` (and `hg.sweep`, which jits), so the
    output grid `simulate` derives from them can be built there."""
    if all(is_concrete(a) for a in args):
        with jax.ensure_compile_time_eval():
            return fn(*args)
    return fn(*args)


_UNITS = {"rate_dps": "°/s", "duration_s": "s", "temperature_c": "°C",
          "wave_angle0_deg": "° electrical", "precession_dps": "°/s electrical", "dwell_s": "s",
          "slew_s": "s"}  # fmt: skip
"""Units of the builders' scalar arguments, for their errors."""


def _scalars(builder: str, **args) -> None:
    """Refuse any of `args` that is not one real number (a bool, str, None, an array…) in one
    line naming `Profile.builder: argument` (a traced scalar passes: sweeps build profiles
    from traced scalars)."""
    for name, x in args.items():
        check_number(f"Profile.{builder}: {name}", x, _UNITS.get(name, ""))


def _duration(builder: str, duration_s) -> None:
    """Refuse a concrete `duration_s` that is not > 0 (a traced one passes: the knot times'
    own check holds it under `jit`), naming the builder's argument, not the knots it makes."""
    v = concrete_value(duration_s)
    if v is not None and not float(v) > 0:
        raise ValueError(f"Profile.{builder}: duration_s must be > 0 [s]; got {float(v):g}")


def _slew_fits(steps_deg: np.ndarray, slew_s: float) -> None:
    """`Profile.held_angles`'s `slew_s` [s] refused where its pulse (peak step/(¾·slew_s))
    would command a precession beyond the plausible range, naming `slew_s` and its least."""
    low, high, unit = plausible.RANGES["precession_dps"]
    peak = steps_deg / (0.75 * slew_s)
    if (bad := (peak < low) | (peak > high)).any():
        least = float(np.max(steps_deg[bad] / (0.75 * np.where(peak[bad] > 0, high, low))))
        raise ValueError(f"Profile.held_angles: slew_s = {slew_s:g} s moves the wave "
                         f"{steps_deg[bad][0]:g}° at a peak of {peak[bad][0]:.6g} {unit}, beyond "
                         f"the plausible {low:g} … {high:g}: give slew_s ≥ {least:.3g} s (or "
                         "widen it: hrgjax.plausible.relaxed(precession_dps=…))")  # fmt: skip


def _accel(builder: str, accel_g) -> None:
    check_numbers(f"Profile.{builder}: accel_g", accel_g,
                  "3 values (specific force along case x, y, z) [g], shape (3,)", (3,))  # fmt: skip


@fused
def lag_at_knots(t, values, tau):
    r"""First-order lag $\dot y = (x - y)/\tau$ of a piecewise-linear signal x (`values` at
    strictly increasing knots `t`), starting at $y(t_0) = x(t_0)$: y at every knot (exact).
    On a segment of slope s, $y_{k+1} = x_{k+1} - s\tau + (y_k - x_k + s\tau)e^{-h_k/\tau}$."""
    h = jnp.diff(t)
    slope = jnp.diff(values) / h

    def step(y, k):
        decay = jnp.exp(-h[k] / tau)
        nxt = values[k + 1] - slope[k] * tau + (y - values[k] + slope[k] * tau) * decay
        return nxt, nxt

    _, rest = jax.lax.scan(step, values[0], jnp.arange(h.shape[0]))
    return jnp.concatenate([values[:1], rest])


def _at_times(method: str):
    """`Profile.<method>(t)`'s check (`fused`'s `prepare`): `t` [s] finite real numbers."""
    form, name = "finite real numbers (times [s])", f"Profile.{method}: t"
    return lambda profile, t: (profile, check_values(name, t, np.isfinite, form))


def _lagged_args(profile, t, tau):
    """`Profile.lagged_temperature_at`'s check: `t` as `_at_times`, `tau` [s] finite, > 0."""
    name, form = "Profile.lagged_temperature_at: tau", "a finite number > 0 [s]"
    prepared = _at_times("lagged_temperature_at")(profile, t)
    return (*prepared, check_values(name, tau, FINITE_POSITIVE, form))


class Profile(eqx.Module):
    """What the bench does to the gyro: one run (one segment of a plan).

    Rate, temperature and specific force are piecewise-linear between the knots `t`.

    **Arguments:**

    - `t`: knot times [s], shape (N,), N ≥ 2, strictly increasing.
    - `rate`: inertial rate of the case about the sensitive axis [rad/s], shape (N,).
    - `temperature`: resonator temperature [°C], shape (N,).
    - `accel`: specific force along case axes x, y, z [g], shape (N, 3).
    - `wave_angle0`: initial electrical wave angle [rad].
    - `precession`: commanded precession rate of the wave at the knots [rad/s, electrical],
      shape (N,), or `None` (none). Whole-angle mode turns the wave at this rate with the
      case at rest (virtual precession); force-to-rebalance mode holds the wave at the
      commanded angle, `wave_angle0` + ∫ρ dt, so a pulse of ρ moves the held angle (angle
      switching, mode reversal). See [`Profile.held_angles`][hrgjax.Profile.held_angles]
      and [`Profile.virtual_precession`][hrgjax.Profile.virtual_precession].
    - `rebalance`: force-to-rebalance schedule at the knots, shape (N,), or `None`: 1 where
      the rebalance loop holds the wave over the segment that starts at that knot, 0 where
      the gyro runs whole-angle (the loop off, its integrator held). Switching to 1 captures
      the wave where the electronics read it then; switching to 0 lets it go. Needs a gyro
      in force-to-rebalance mode (`Control(mode="ftr")`) with its PI loops.
    """

    t: jax.Array = eqx.field(converter=_field)
    rate: jax.Array = eqx.field(converter=_field)
    temperature: jax.Array = eqx.field(converter=_field)
    accel: jax.Array = eqx.field(converter=_field)
    wave_angle0: jax.Array = eqx.field(converter=_field, default=0.0)
    precession: jax.Array | None = eqx.field(converter=_optional, default=None)
    rebalance: jax.Array | None = eqx.field(converter=_schedule, default=None)

    def __check_init__(self):
        refuse_unconverted(self, "real numbers (an array; precession and rebalance may be None)")
        n = self.t.shape[-1] if self.t.ndim else 0
        if self.t.ndim != 1 or n < 2:
            raise ValueError(f"Profile.t must have shape (N,) with N >= 2 knots; got "
                             f"{self.t.shape}")  # fmt: skip
        for name in ("rate", "temperature"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"Profile.{name} must have the shape of Profile.t, ({n},); "
                                 f"got {getattr(self, name).shape}")  # fmt: skip
        if self.accel.shape != (n, 3):
            raise ValueError(f"Profile.accel must have shape ({n}, 3) [g]; got {self.accel.shape}")
        if self.wave_angle0.shape != ():
            raise ValueError(f"Profile.wave_angle0 must be a scalar [rad]; got "
                             f"{self.wave_angle0.shape}")  # fmt: skip
        if self.precession is not None and self.precession.shape != (n,):
            raise ValueError(f"Profile.precession must have the shape of Profile.t, ({n},) "
                             f"[rad/s], or be None; got {self.precession.shape}")  # fmt: skip
        for name in ("t", "rate", "temperature", "accel", "wave_angle0"):
            _finite(f"Profile.{name}", getattr(self, name))
        if self.precession is not None:
            _finite("Profile.precession", self.precession)
        if self.rebalance is not None:
            if self.rebalance.shape != (n,):
                raise ValueError(
                    f"Profile.rebalance must have the shape of Profile.t, ({n},), or be None; "
                    f"got {self.rebalance.shape}"
                )
            if is_concrete(self.rebalance):
                bad = np.flatnonzero(~np.isin(np.asarray(self.rebalance), (0.0, 1.0)))
                if bad.size:
                    raise ValueError(
                        f"Profile.rebalance[{bad[0]}] is {float(self.rebalance[bad[0]])}; give 1 "
                        "(force-to-rebalance over the segment) or 0 (whole-angle)"
                    )
        plausible.check("Profile.temperature", self.temperature, "temperature_c")
        if is_concrete(self.rate):  # in the data's units: °/s, ° electrical, s
            plausible.check("Profile.rate [°/s]", np.degrees(np.asarray(self.rate)),
                            "table_rate_dps")  # fmt: skip
        if self.precession is not None and is_concrete(self.precession):
            plausible.check("Profile.precession [°/s, electrical]",
                            np.degrees(np.asarray(self.precession)), "precession_dps")  # fmt: skip
        if is_concrete(self.accel):  # each axis within ±20 g, and not 1 g in m/s² or mg
            axes = [
                f"Profile.accel[:, {j}] (specific force along {a}) [g]" for j, a in enumerate("xyz")
            ]
            plausible.check_specific_force("Profile.accel (specific force along case x, y, z) "
                                           "[g]", axes, np.asarray(self.accel))  # fmt: skip
        if is_concrete(self.wave_angle0):
            plausible.check("Profile.wave_angle0 [°]", np.degrees(np.asarray(self.wave_angle0)),
                            "wave_angle_deg")  # fmt: skip
        if is_concrete(self.t):
            plausible.check("Profile's length [s]", float(np.ptp(np.asarray(self.t))),
                            "duration_s")  # fmt: skip
            t = np.asarray(self.t)
            bad = np.nonzero(np.diff(t) <= 0)[0]
            if bad.size:
                i = int(bad[0]) + 1
                raise ValueError(
                    f"Profile.t must be strictly increasing; t[{i}] = {t[i]} follows "
                    f"t[{i - 1}] = {t[i - 1]} (unsorted or duplicate time)"
                )

    @classmethod
    def constant_rate(
        cls,
        rate_dps: float,
        duration_s: float,
        temperature_c: float = 20.0,
        wave_angle0_deg: float = 0.0,
        accel_g=(0.0, 0.0, 0.0),
    ) -> Profile:
        """A run at constant rate `rate_dps` [°/s] for `duration_s` [s] at `temperature_c` [°C],
        starting at electrical wave angle `wave_angle0_deg` [°], under specific force
        `accel_g` [g] (case axes x, y, z).

        Each argument but `accel_g` is one real number (bools, strings, None and arrays are
        refused in one line naming it); `accel_g` is three."""
        _scalars("constant_rate", rate_dps=rate_dps, duration_s=duration_s,
                 temperature_c=temperature_c, wave_angle0_deg=wave_angle0_deg)  # fmt: skip
        _duration("constant_rate", duration_s)
        _accel("constant_rate", accel_g)
        args = (rate_dps, duration_s, temperature_c, wave_angle0_deg, accel_g)
        if not any(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(args)):
            # Python / NumPy numbers: build on the host (no eager device programs).
            one, h = np.ones(2), lambda x: np.asarray(x, dtype=float)
            return cls(
                t=np.array([0.0, 1.0]) * h(duration_s),
                rate=one * h(rate_dps) * DEG_PER_S,
                temperature=one * h(temperature_c),
                accel=np.ones((2, 1)) * h(accel_g)[None, :],
                wave_angle0=h(wave_angle0_deg) * DEG,
            )
        t = _eager(lambda d: jnp.array([0.0, 1.0]) * _f(d), duration_s)
        one = jnp.ones(2)
        return cls(
            t=t,
            rate=one * _f(rate_dps) * DEG_PER_S,
            temperature=one * _f(temperature_c),
            accel=jnp.ones((2, 1)) * _f(accel_g)[None, :],
            wave_angle0=_f(wave_angle0_deg) * DEG,
        )

    @classmethod
    def static(
        cls,
        duration_s: float,
        temperature_c: float = 20.0,
        wave_angle0_deg: float = 0.0,
        accel_g=(0.0, 0.0, 0.0),
    ) -> Profile:
        """A static run (zero rate); arguments as [`Profile.constant_rate`][hrgjax.Profile.constant_rate]."""
        _scalars("static", duration_s=duration_s, temperature_c=temperature_c,
                 wave_angle0_deg=wave_angle0_deg)  # fmt: skip
        _duration("static", duration_s)
        _accel("static", accel_g)
        return cls.constant_rate(0.0, duration_s, temperature_c, wave_angle0_deg, accel_g)

    @classmethod
    def piecewise(
        cls,
        t_s,
        rate_dps,
        temperature_c,
        accel_g=None,
        wave_angle0_deg: float = 0.0,
        precession_dps=None,
        rebalance=None,
    ) -> Profile:
        """A profile from knot arrays in bench units: times [s], rates [°/s],
        temperatures [°C] and optionally specific force [g], shape (N, 3), a commanded
        precession [°/s, electrical] and a force-to-rebalance schedule (1 on, 0 whole-angle
        over the segment from each knot; see the class's arguments)."""
        for name, x in (("t_s", t_s), ("rate_dps", rate_dps), ("temperature_c", temperature_c),
                        ("accel_g", accel_g), ("precession_dps", precession_dps)):  # fmt: skip
            if x is not None or name in ("t_s", "rate_dps", "temperature_c"):
                check_numbers(f"Profile.piecewise: {name}", x, "real numbers")
        if rebalance is not None:
            check_numbers("Profile.piecewise: rebalance", rebalance, "1 or 0 per knot", bools=True)
        _scalars("piecewise", wave_angle0_deg=wave_angle0_deg)
        args = (t_s, rate_dps, temperature_c, accel_g, wave_angle0_deg, precession_dps, rebalance)
        knots = np.shape(t_s)
        for name, x in (("rate_dps", rate_dps), ("temperature_c", temperature_c),
                        ("precession_dps", precession_dps), ("rebalance", rebalance)):  # fmt: skip
            if x is not None and np.shape(x) not in ((), knots):
                raise ValueError(f"Profile.piecewise: {name} must be one value or one per knot "
                                 f"of t_s, shape {knots}; got shape {np.shape(x)}")  # fmt: skip
        if not any(isinstance(x, jax.Array) for x in jax.tree_util.tree_leaves(args)):
            t = np.asarray(t_s, dtype=float)  # host values: built on the host
            return cls(
                t=t,
                rate=np.broadcast_to(np.asarray(rate_dps, dtype=float), t.shape) * DEG_PER_S,
                temperature=np.broadcast_to(np.asarray(temperature_c, dtype=float), t.shape),
                accel=np.zeros(t.shape + (3,)) if accel_g is None else accel_g,
                wave_angle0=np.asarray(wave_angle0_deg, dtype=float) * DEG,
                precession=None if precession_dps is None else
                np.broadcast_to(np.asarray(precession_dps, dtype=float), t.shape) * DEG_PER_S,
                rebalance=None if rebalance is None else
                np.broadcast_to(np.asarray(rebalance, dtype=float), t.shape),
            )  # fmt: skip
        t = _eager(_f, t_s)
        rate = jnp.broadcast_to(_f(rate_dps), t.shape) * DEG_PER_S
        temp = jnp.broadcast_to(_f(temperature_c), t.shape)
        acc = jnp.zeros(t.shape + (3,)) if accel_g is None else _f(accel_g)
        extra = {}
        if precession_dps is not None:
            extra["precession"] = jnp.broadcast_to(_f(precession_dps), t.shape) * DEG_PER_S
        if rebalance is not None:
            extra["rebalance"] = jnp.broadcast_to(_f(rebalance), t.shape)
        return cls(
            t=t, rate=rate, temperature=temp, accel=acc, wave_angle0=_f(wave_angle0_deg) * DEG,
            **extra,
        )  # fmt: skip

    @classmethod
    def virtual_precession(
        cls,
        precession_dps: float,
        duration_s: float,
        temperature_c: float = 20.0,
        wave_angle0_deg: float = 0.0,
        **case,
    ) -> Profile:
        """A run whose wave is turned at `precession_dps` [°/s, electrical] by a commanded node
        force for `duration_s` [s] at `temperature_c` [°C] from `wave_angle0_deg` [° electrical],
        the case at rest unless `case` gives [`constant_rate`][hrgjax.Profile.constant_rate]'s
        `rate_dps` [°/s] or `accel_g` [g]. In whole-angle mode the wave then visits every
        angle: what the drift's θ-dependence needs, without a table."""
        _scalars("virtual_precession", precession_dps=precession_dps, duration_s=duration_s,
                 temperature_c=temperature_c, wave_angle0_deg=wave_angle0_deg,
                 **{k: v for k, v in case.items() if k == "rate_dps"})  # fmt: skip
        _duration("virtual_precession", duration_s)
        if "accel_g" in case:
            _accel("virtual_precession", case["accel_g"])
        rate_dps = case.pop("rate_dps", 0.0)
        p = cls.constant_rate(rate_dps, duration_s, temperature_c, wave_angle0_deg, **case)
        # built again (not `eqx.tree_at`) so that the precession is checked as any field is
        return cls(t=p.t, rate=p.rate, temperature=p.temperature, accel=p.accel,
                   wave_angle0=p.wave_angle0,
                   precession=jnp.ones(2) * _f(precession_dps) * DEG_PER_S)  # fmt: skip

    @classmethod
    def held_angles(
        cls,
        angles_deg,
        dwell_s: float,
        slew_s: float = 10.0,
        temperature_c: float = 20.0,
        rate_dps: float = 0.0,
    ) -> Profile:
        """A force-to-rebalance schedule: the wave held at each of `angles_deg` [° electrical]
        in turn for `dwell_s` [s], moved between them by a commanded precession pulse of
        `slew_s` [s] (a trapezoid: ramps of `slew_s`/4), the case at `rate_dps` [°/s] and
        `temperature_c` [°C]. Mode reversal is `angles_deg=(θ, θ + 90)`: the damping
        anisotropy's drift ½Δ(1/τ)·sin 2(θ − θ_τ) changes sign, the rate does not. Traced
        angles, times or temperature (vmap, grad, hg.sweep) give the same knots, with jnp."""
        check_numbers("Profile.held_angles: angles_deg", angles_deg,
                      "one or more finite angles [° electrical]")  # fmt: skip
        _scalars("held_angles", dwell_s=dwell_s, slew_s=slew_s, temperature_c=temperature_c,
                 rate_dps=rate_dps)  # fmt: skip
        array = lambda x: (np if is_concrete(x) else jnp).asarray(x, dtype=float)
        finite = concrete_value(ang := array(angles_deg))  # traced (vmap, grad, jit): jnp
        if ang.ndim > 1 or ang.size < 1 or (finite is not None and not np.isfinite(finite).all()):
            raise ValueError(f"Profile.held_angles: angles_deg must be one or more finite angles "
                             f"[° electrical], shape (n,); got shape {ang.shape}"
                             + ("" if ang.ndim > 1 or not ang.size else " with NaN or inf"))  # fmt: skip
        for name, v in (("dwell_s", dwell_s), ("slew_s", slew_s)):
            if (c := concrete_value(v)) is not None and not (np.isfinite(c) and c > 0):
                raise ValueError(f"Profile.held_angles: {name} must be a positive number of "
                                 f"seconds; got {v!r}")  # fmt: skip
        if finite is not None and finite.size > 1 and (slew := concrete_value(slew_s)) is not None:
            _slew_fits(np.diff(finite.reshape(-1)), float(slew))
        ang, ramp = ang.reshape(-1), slew_s / 4.0
        t, rho = [0.0, dwell_s], [0.0, 0.0]
        for k in range(1, ang.size):
            peak = (ang[k] - ang[k - 1]) / (slew_s - ramp)  # ∫ over the trapezoid = the step
            start = t[-1]
            t += [start + ramp, start + slew_s - ramp, start + slew_s, start + slew_s + dwell_s]
            rho += [peak, peak, 0.0, 0.0]
        t, one = array(t), np.ones(len(t))  # knot times stay NumPy (concrete) unless traced
        return cls(t=t, rate=one * rate_dps * DEG_PER_S, temperature=one * temperature_c,
                   accel=np.zeros((t.size, 3)), wave_angle0=ang[0] * DEG,
                   precession=array(rho) * DEG_PER_S)  # fmt: skip

    def hold_windows(self, settle_s: float = 0.0) -> list[tuple[float, float]]:
        """(start, end) [s] of each hold — a maximal stretch of knots between which the
        commanded precession is zero (the wave held still) — its start moved on by `settle_s`
        [s] (a finite number ≥ 0); holds no longer than `settle_s` are left out."""
        settle_s = finite_number("Profile.hold_windows: settle_s", settle_s, "s")
        if settle_s < 0:
            raise ValueError(f"Profile.hold_windows: settle_s must be >= 0 [s]; got {settle_s:g}")
        t = np.asarray(self.t)
        rho = np.zeros(t.size) if self.precession is None else np.asarray(self.precession)
        still = np.concatenate([[0], (rho[:-1] == 0) & (rho[1:] == 0), [0]]).astype(int)
        edges = np.flatnonzero(np.diff(still))  # runs of still segments a … b − 1: t[a] to t[b]
        return [(float(t[a]) + settle_s, float(t[b])) for a, b in zip(edges[::2], edges[1::2],
                strict=True) if t[b] - t[a] > settle_s]  # fmt: skip

    @property
    def duration(self):
        """Run length [s]."""
        return self.t[-1] - self.t[0]

    def _segment(self, t):
        """Index i of the segment [t_i, t_{i+1}] holding t and the fraction along it.

        Two-knot profiles (constant rate, static, one ramp) need no search."""
        n = self.t.shape[0]
        if n == 2:
            i = 0
        else:
            i = jnp.clip(jnp.searchsorted(self.t, t, side="right") - 1, 0, n - 2)
        t0, t1 = self.t[i], self.t[i + 1]
        return i, t0, t1 - t0

    @fused(prepare=_at_times("sample"))
    def sample(self, t):
        """Rate [rad/s], its derivative [rad/s²], temperature [°C] and specific force [g]
        at time t [s], with one segment look-up (clamped outside the knots)."""
        i, t0, length = self._segment(t)
        frac = jnp.clip((t - t0) / length, 0.0, 1.0)
        lerp = lambda v: v[i] + (v[i + 1] - v[i]) * frac
        rate_dot = (self.rate[i + 1] - self.rate[i]) / length
        return lerp(self.rate), rate_dot, lerp(self.temperature), lerp(self.accel)

    def _interp(self, t, values):
        i, t0, length = self._segment(t)
        frac = jnp.clip((t - t0) / length, 0.0, 1.0)
        return values[i] + (values[i + 1] - values[i]) * frac

    @fused(prepare=_at_times("rate_at"))
    def rate_at(self, t):
        """Rate [rad/s] at time t [s]."""
        return self._interp(t, self.rate)

    @fused(prepare=_at_times("temperature_at"))
    def temperature_at(self, t):
        """Temperature [°C] at time t [s]."""
        return self._interp(t, self.temperature)

    @fused(prepare=_at_times("accel_at"))
    def accel_at(self, t):
        """Specific force [g], shape (3,), at time t [s]."""
        return self._interp(t, self.accel)

    @fused(prepare=_at_times("rate_derivative_at"))
    def rate_derivative_at(self, t):
        """Angular acceleration [rad/s²] at time t [s] (slope of the current segment)."""
        i, _, length = self._segment(t)
        return (self.rate[i + 1] - self.rate[i]) / length

    @fused(prepare=_at_times("temperature_rate_at"))
    def temperature_rate_at(self, t):
        """Temperature rate dT/dt [°C/s] at time t [s] (slope of the current segment)."""
        i, _, length = self._segment(t)
        return (self.temperature[i + 1] - self.temperature[i]) / length

    @fused(prepare=_lagged_args)
    def lagged_temperature_at(self, t, tau):
        r"""First-order lagged temperature $T_i(t)$ [°C], $\dot T_i = (T - T_i)/\tau$,
        starting in equilibrium, $T_i(t_0) = T(t_0)$; `tau` [s] > 0 (a concrete one ≤ 0: refused).

        Exact for the piecewise-linear temperature: on a segment of slope s,
        $T_i(t) = T(t) - s\tau + (T_i(t_k) - T(t_k) + s\tau)\,e^{-(t-t_k)/\tau}$."""
        temp = self.temperature
        slope = jnp.diff(temp) / jnp.diff(self.t)
        at_knots = lag_at_knots(self.t, temp, tau)
        i, t0, _ = self._segment(t)
        dt = jnp.clip(t - t0, 0.0, None)
        s = slope[i]
        return temp[i] + s * dt - s * tau + (at_knots[i] - temp[i] + s * tau) * jnp.exp(-dt / tau)

    @fused(prepare=_at_times("kinematics_at"))
    def kinematics_at(self, t):
        """Table angle since the first knot [rad], rate [rad/s] and specific force [g] (3,)
        at time t [s], with one segment look-up (what a fixed step needs at its end)."""
        seg = 0.5 * (self.rate[1:] + self.rate[:-1]) * jnp.diff(self.t)
        cum = jnp.concatenate([jnp.zeros(1), jnp.cumsum(seg)])
        i, t0, length = self._segment(t)
        dt = t - t0
        slope = (self.rate[i + 1] - self.rate[i]) / length
        frac = jnp.clip(dt / length, 0.0, 1.0)
        accel = self.accel[i] + (self.accel[i + 1] - self.accel[i]) * frac
        return cum[i] + self.rate[i] * dt + 0.5 * slope * dt**2, self.rate[i] + slope * dt, accel

    @fused(prepare=_at_times("precession_at"))
    def precession_at(self, t):
        """Commanded precession rate [rad/s, electrical] at time t [s] (0 without one)."""
        if self.precession is None:
            return 0.0 * t
        return self._interp(t, self.precession)

    @fused(prepare=_at_times("commanded_angle_at"))
    def commanded_angle_at(self, t):
        """Commanded wave angle `wave_angle0` + ∫ρ dt [rad, electrical] at time t [s] (exact for
        the piecewise-linear ρ): the angle force-to-rebalance holds."""
        if self.precession is None:
            return self.wave_angle0 + 0.0 * t
        rho = self.precession
        seg = 0.5 * (rho[1:] + rho[:-1]) * jnp.diff(self.t)
        cum = jnp.concatenate([jnp.zeros(1), jnp.cumsum(seg)])
        i, t0, length = self._segment(t)
        dt = jnp.clip(t - t0, 0.0, length)
        slope = (rho[i + 1] - rho[i]) / length
        return self.wave_angle0 + cum[i] + rho[i] * dt + 0.5 * slope * dt**2

    @fused(prepare=_at_times("rebalance_at"))
    def rebalance_at(self, t):
        """1 where the rebalance loop holds the wave at time t [s], 0 where the gyro runs
        whole-angle (the `rebalance` schedule's value at the segment's start; 1 without one)."""
        if self.rebalance is None:
            return 1.0 + 0.0 * t
        i, _, _ = self._segment(t)
        return self.rebalance[i]

    @fused(prepare=_at_times("command_at"))
    def command_at(self, t):
        """(commanded angle [rad], commanded precession [rad/s], rebalance on 1 / off 0) at
        time t [s]: what the loops are told ([`hrgjax.resonator.control.loop_outputs`][]; in
        force-to-rebalance mode the models hold the angle in their state, so that a switch
        captures the wave where it is read)."""
        return self.commanded_angle_at(t), self.precession_at(t), self.rebalance_at(t)

    @fused(prepare=_at_times("table_angle_at"))
    def table_angle_at(self, t):
        """Table angle ∫Ω dt since the first knot [rad] (exact for the piecewise-linear rate)."""
        return self.kinematics_at(t)[0]


def traced_checks(profile: Profile) -> list:
    """The run-time twins of `Profile`'s own plausibility checks for its traced fields
    (inside `jit`, `vmap` or `hg.sweep` a module's `__check_init__` sees no values):
    `[(bad, message), …]`, `bad` a traced boolean, `message` the eager one line without the
    value, in the order `__check_init__` checks them; concrete fields were checked where the
    profile was built. `simulate` raises the first that holds (`eqx.branched_error_if`)."""
    traced = lambda x: x is not None and not is_concrete(x)  # noqa: E731
    checks = []
    if traced(profile.rebalance):
        off = jnp.any((profile.rebalance != 0.0) & (profile.rebalance != 1.0))
        checks.append((off, "Profile.rebalance is neither 1 nor 0 at one or more knots; give 1 "
                            "(force-to-rebalance over the segment) or 0 (whole-angle)"))  # fmt: skip
    fields = [("Profile.temperature", profile.temperature, "temperature_c", False),
              ("Profile.rate [°/s]", profile.rate, "table_rate_dps", True),
              ("Profile.precession [°/s, electrical]", profile.precession, "precession_dps",
               True)]  # fmt: skip
    if traced(profile.accel):
        fields += [(f"Profile.accel[:, {j}] (specific force along {axis}) [g]",
                    profile.accel[:, j], "specific_force_g", False)
                   for j, axis in enumerate("xyz")]  # fmt: skip
    fields.append(("Profile.wave_angle0 [°]", profile.wave_angle0, "wave_angle_deg", True))
    for name, value, quantity, in_degrees in fields:  # in the data's units, as eagerly
        if traced(value):
            value = jnp.degrees(value) if in_degrees else value
            checks += plausible.traced_violations(name, value, quantity)
    if traced(profile.t):
        length = jnp.max(profile.t) - jnp.min(profile.t)
        checks += plausible.traced_violations("Profile's length [s]", length, "duration_s")
        checks.append((jnp.any(jnp.diff(profile.t) <= 0), "Profile.t must be strictly "
                       "increasing at one or more knots (unsorted or duplicate time)"))  # fmt: skip
    return checks
