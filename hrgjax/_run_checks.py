"""The plausibility of a run's inputs, checked at `simulate`'s entry: the gyro's temperature
laws over the profile's temperatures (`check_laws`, on concrete values), and the same rules
with `Profile`'s own held at run time on traced values (`check_traced`: inside `jit`, `vmap`
or `hg.sweep`, where no value is known when the run is set up)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import plausible
from ._checks import RULES, is_concrete
from ._compiled import tracing_callback_free
from ._simulate_options import traced_grid_checks
from .gyro import DRIFT_PLAUSIBLE
from .gyro import PLAUSIBLE as GYRO_PLAUSIBLE
from .noise import NONNEGATIVE as NOISE_NONNEGATIVE
from .noise import PLAUSIBLE as NOISE_PLAUSIBLE
from .noise import UNITS as NOISE_UNITS
from .profiles import traced_checks as profile_checks
from .resonator.control import AVERAGED_BANDWIDTH, FTR_LIMITS
from .resonator.control import LIMITS as CONTROL_LIMITS
from .resonator.params import LIMITS as RESONATOR_LIMITS
from .resonator.params import TemperatureLaw, damping_problem, stiffness_problem
from .resonator.readout import LIMITS as READOUT_LIMITS

LAW_LIMITS = {  # (rule, unit) of the fields a temperature law must respect, by path
    **{f"resonator.{n}": rule for n, rule in RESONATOR_LIMITS.items()},
    "drift_terms.lag_time": ("> 0", "s"),
    "drift_terms.warmup_time": ("> 0", "s"),
    "noise.correlation_time": ("> 0", "s"),
    **{f"control.{n}": rule for n, rule in CONTROL_LIMITS.items()},
    **{f"readout.{n}": rule for n, rule in READOUT_LIMITS.items()},
    **{f"noise.{n}": (">= 0", NOISE_UNITS[n]) for n in NOISE_NONNEGATIVE},
}
"""(rule of `hrgjax._checks.RULES`, unit) of each gyro field a temperature law (or a value
put in with `eqx.tree_at`) must keep, by its path in the gyro; "finite" for any other."""


RANGED = {
    **GYRO_PLAUSIBLE,
    **{f"drift_terms.{n}": q for n, q in DRIFT_PLAUSIBLE.items()},
    **{f"noise.{n}": q for n, q in NOISE_PLAUSIBLE.items()},
}
"""The quantity of `hrgjax.plausible.RANGES` each gyro field must lie in, by its path: what
its module's `__check_init__` holds it to, held by `simulate` too where that did not run (a
value put in with `eqx.tree_at`, a traced one, a temperature law's over the run)."""


def _first_outside(values, quantity: str) -> int | None:
    """The index of the first finite value of `values` outside `RANGES[quantity]` (an
    `EXCLUSIVE` quantity's nonzero bounds outside too), or None."""
    low, high, _ = plausible.RANGES[quantity]
    v = np.ravel(np.asarray(values, dtype=float))
    ok = ~np.isfinite(v) | ((v >= low) & (v <= high))
    if quantity in plausible.EXCLUSIVE:
        ok &= ((v != low) | (low == 0.0)) & ((v != high) | (high == 0.0))
    bad = np.flatnonzero(~ok)
    return int(bad[0]) if bad.size else None


def law_limits(gyro) -> dict:
    """`LAW_LIMITS` with the narrower rules of the gyro's mode: in force-to-rebalance mode
    the rebalance loop closed (`hrgjax.resonator.control.FTR_LIMITS`)."""
    if gyro.control.mode != "ftr":
        return LAW_LIMITS
    return LAW_LIMITS | {f"control.{n}": rule for n, rule in FTR_LIMITS.items()}


LAW_GRID = 257
"""Points between the profile's lowest and highest temperature at which a law is evaluated
(with the knots' own temperatures)."""


def obeys(rule: str, value, xp=np):
    """Where `value` keeps `rule` of `LAW_LIMITS` ("finite" alone: everywhere)."""
    v = xp.asarray(value, dtype=float)
    return RULES[rule](v) if rule in RULES else xp.full(v.shape, True)


def _laws(gyro):
    """(dotted path, leaf) of every leaf of `gyro`, a `TemperatureLaw` counting as one."""
    is_law = lambda x: isinstance(x, TemperatureLaw)  # noqa: E731
    flat, _ = jax.tree_util.tree_flatten_with_path(gyro, is_leaf=is_law)
    for path, law in flat:
        yield ".".join(str(getattr(p, "name", getattr(p, "key", p))) for p in path), law


def check_laws(gyro, profile) -> None:
    """Every temperature law of `gyro` finite over the profile's temperatures, and decay
    times, frequencies and noise levels of the right sign there, both axes damped
    (`resonator.params.damping_problem`) with stiffness (`stiffness_problem`); plain values put in with
    `eqx.tree_at` within their limits, and the fields of `RANGED` (values and laws) within
    their `plausible.RANGES` (concrete values only: `check_traced` holds traced ones to the
    same rules at run time)."""
    temps = np.asarray(profile.temperature, float).ravel() if is_concrete(
        profile.temperature) else None  # fmt: skip
    grid, limits = None, law_limits(gyro)
    for name, law in _laws(gyro):
        plain = not isinstance(law, TemperatureLaw) and is_concrete(law) and np.ndim(law) == 0
        if plain and np.asarray(law).dtype.kind in "fiu" and not isinstance(law, bool):
            # a plain value, checked here too: eqx.tree_at (as sweeps do) skips __init__
            value, (rule, unit) = float(np.asarray(law)), limits.get(name, ("finite", ""))
            if not (np.isfinite(value) and obeys(rule, value)):
                raise ValueError(f"gyro.{name} = {value:g} {unit}; it must be {rule}".replace(
                    "  ", " "))  # fmt: skip
        if name in RANGED and not isinstance(law, TemperatureLaw) and is_concrete(law):
            plausible.check(f"gyro.{name}", law, RANGED[name])  # g_sensitivity: 3 values
        if plain:
            continue
        if temps is None or not isinstance(law, TemperatureLaw):
            continue
        leaves = jax.tree_util.tree_leaves(law)
        if not all(is_concrete(x) for x in leaves) or any(np.ndim(x) for x in leaves):
            continue  # traced (`check_traced`), or a batch of laws: checked where evaluated
        lo, hi = float(temps.min()), float(temps.max())
        if grid is None:
            grid = np.unique(np.concatenate([temps, np.linspace(lo, hi, LAW_GRID)]))
        with np.errstate(over="ignore", invalid="ignore"):
            value = law(grid, xp=np)
        rule, unit = limits.get(name, ("finite", ""))
        bad = ~np.isfinite(value) | ~obeys(rule, value)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"the temperature law of gyro.{name} gives {value[i]:.6g} {unit} at "
                f"{grid[i]:.4g} °C, inside the profile's temperatures [{lo:.4g}, {hi:.4g}] °C; "
                f"it must be {rule} there".replace("  ", " ")
            )
        if name in RANGED and (i := _first_outside(value, RANGED[name])) is not None:
            plausible.check(f"the temperature law of gyro.{name} at {grid[i]:.4g} °C (inside "
                            f"the profile's temperatures [{lo:.4g}, {hi:.4g}] °C)", value[i],
                            RANGED[name])  # fmt: skip
    # both axes damped and stiff over the profile's temperatures (plain values too: eqx.tree_at)
    at = grid if grid is not None else temps
    if problem := damping_problem(gyro.resonator, at) or stiffness_problem(gyro.resonator, at):
        raise ValueError(f"gyro.resonator: {problem}")


def check_bandwidths(gyro, profile, model: str) -> None:
    """Refuse, for the averaged `model`, a rate that reaches `AVERAGED_BANDWIDTH` × the
    carrier ω at one of the profile's temperatures (`LAW_GRID` points between the lowest and
    the highest; laws evaluated there): a closed loop's bandwidth (a 5·10⁴ rad/s PLL on a
    3.1·10⁴ rad/s carrier ran without a word), the damping rate 1/τ or an axis's
    1/τ ± ½|Δ(1/τ)| (Q = 2.5: θ 0.05 rad off), or the split |Δω| (Δω = 0.2 ω: θ 0.25 rad
    off): the averaging holds only for rates far slower than the carrier. Concrete values
    only; ideal or absent loops are not read."""
    if model != "averaged" or not is_concrete(profile.temperature):
        return
    temps = np.asarray(profile.temperature, float).ravel()
    grid = np.linspace(temps.min(), temps.max(), LAW_GRID)

    def at(x):  # a value or a law over the grid; None where traced
        leaves = jax.tree_util.tree_leaves(x)
        if not all(is_concrete(v) for v in leaves) or any(np.ndim(v) for v in leaves):
            return None
        with np.errstate(over="ignore", invalid="ignore"):
            return (
                x(grid, xp=np) if isinstance(x, TemperatureLaw) else np.full(grid.shape, float(x))
            )

    res, ctl = gyro.resonator, gyro.control
    if (omega := at(res.omega)) is None:
        return
    rates = []  # (field, its value over the grid, its unit, the rate it sets, what that is)
    if (tau := at(res.tau)) is not None:
        rates.append(("resonator.tau", tau, "s", 1.0 / tau, "the damping rate 1/τ"))
        if (dit := at(res.delta_inv_tau)) is not None:
            rates.append(("resonator.delta_inv_tau", dit, "1/s", 1.0 / tau + np.abs(dit) / 2,
                          "an axis's damping rate 1/τ + ½|Δ(1/τ)|"))  # fmt: skip
    if (split := at(res.delta_omega)) is not None:
        rates.append(("resonator.delta_omega", split, "rad/s", np.abs(split), ""))
    if ctl.enabled and not ctl.ideal:
        loops = ("pll", "agc", "quadrature") + (("rebalance",) if ctl.mode == "ftr" else ())
        for loop in loops:
            if (beta := at(getattr(ctl, f"{loop}_bandwidth"))) is not None:
                rates.append((f"control.{loop}_bandwidth", beta, "rad/s", beta, ""))
    for name, value, unit, rate, what in rates:
        if not np.any(high := rate >= AVERAGED_BANDWIDTH * omega):
            continue
        i = int(np.flatnonzero(high)[0])
        of = f" ({what} = {rate[i]:g} 1/s)" if what else ""
        raise ValueError(
            f"gyro.{name} = {value[i]:g} {unit} at {grid[i]:.4g} °C{of} is at or above "
            f"{AVERAGED_BANDWIDTH:g} × the carrier ω = {omega[i]:g} rad/s: the averaged "
            "model holds for rates far slower than the carrier; lower it, or run "
            'model="full"'
        )


def law_checks(gyro, profile) -> list:
    """`check_laws`'s rule for every law it could not check (traced coefficients, or traced
    temperatures): `[(bad, message), …]`, `bad` a traced boolean, the message its one line
    without the value. A law is judged only where the temperatures and its coefficients are
    finite (a NaN is the finite check's)."""
    temps = jnp.ravel(jnp.asarray(profile.temperature, dtype=float))
    temps_traced = not is_concrete(profile.temperature)
    checks, grid, limits = [], None, law_limits(gyro)
    for name, law in _laws(gyro):
        if not isinstance(law, TemperatureLaw):
            if limits.get(name) != LAW_LIMITS.get(name) and not is_concrete(law):
                rule, unit = limits[name]  # a mode's rule, beyond `traceable`'s `LAW_LIMITS`
                checks.append((jnp.any(jnp.isfinite(law) & ~obeys(rule, law, jnp)),
                               f"gyro.{name} must be {rule} {unit}"))  # fmt: skip
            if name in RANGED and not is_concrete(law):
                checks += plausible.traced_violations(f"gyro.{name}", law, RANGED[name])
            continue
        leaves = jax.tree_util.tree_leaves(law)
        if any(np.ndim(x) for x in leaves):
            continue  # a batch of laws (as `check_laws`)
        if not temps_traced and all(is_concrete(x) for x in leaves):
            continue  # `check_laws` did it
        if grid is None:
            grid = jnp.concatenate([temps, jnp.linspace(temps.min(), temps.max(), LAW_GRID)])
        rule, unit = limits.get(name, ("finite", ""))
        value = law(grid)
        judged = jnp.all(jnp.isfinite(temps)) & jnp.all(
            jnp.stack([jnp.all(jnp.isfinite(x)) for x in leaves]))  # fmt: skip
        bad = judged & jnp.any(~jnp.isfinite(value) | ~obeys(rule, value, jnp))
        checks.append((bad, f"the temperature law of gyro.{name} leaves its range at one or "
                            "more points inside the profile's temperatures; it must be "
                            f"{rule} {unit} there".replace("  ", " ")))  # fmt: skip
        if name in RANGED:
            where = f"the temperature law of gyro.{name} over the profile's temperatures"
            checks += plausible.traced_violations(where, value, RANGED[name])
    checks += _damping_check(gyro.resonator, temps, temps_traced)
    return checks


def _damping_check(resonator, temps, temps_traced) -> list:
    """`damping_problem`'s rule (both axes damped: |Δ(1/τ)| < 2/τ) and `stiffness_problem`'s
    (both axes stiff: |Δω| < ω) where a value is traced (a sweep over `delta_inv_tau`, say):
    `[(bad, message), …]`, without a rule `check_laws` judged (all concrete) or for a batch
    of laws."""
    checks = []
    for names, message in (
        (("tau", "delta_inv_tau"), "gyro.resonator.delta_inv_tau gives one axis negative "
         "damping at one or more points (1/τ₂ = 1/τ − |Δ(1/τ)|/2 ≤ 0): |Δ(1/τ)| must be < 2/τ"),
        (("omega", "delta_omega"), "gyro.resonator.delta_omega gives one axis negative "
         "stiffness at one or more points (ω² − ω|Δω| ≤ 0): |Δω| must be < ω"),
    ):  # fmt: skip
        fields = [getattr(resonator, name) for name in names]
        leaves = jax.tree_util.tree_leaves(fields)
        if any(np.ndim(x) for x in leaves) or (not temps_traced and all(map(is_concrete, leaves))):
            continue
        grid = jnp.concatenate([temps, jnp.linspace(temps.min(), temps.max(), LAW_GRID)])
        scale, x = (
            f(grid) if isinstance(f, TemperatureLaw) else jnp.asarray(f, float) for f in fields
        )
        ok = jnp.abs(x) * scale < 2.0 if names[0] == "tau" else jnp.abs(x) < scale
        judged = jnp.isfinite(scale) & (scale > 0)
        judged &= jnp.isfinite(x) & jnp.all(jnp.isfinite(temps))
        checks.append((jnp.any(judged & ~ok), message))
    return checks


def check_traced(gyro, profile, ts, explicit: bool = True):
    """`(gyro, profile, ts)` with the plausibility rules of their traced values held at run
    time by one `eqx.branched_error_if` on every traced leaf of them (what the run computes
    from): `Profile`'s own ranges and knot order (`hrgjax.profiles.traced_checks`), the
    temperature laws' and the gyro's ranges (`law_checks`), then the order and span of the
    output times `ts` where they were given (`explicit`; `dt_out`'s lie within by
    construction: `_simulate_options.traced_grid_checks`). The
    first rule broken raises its one line, the eager message without the value (`hg.sweep`:
    "sweep: at one or more grid points, …"). Concrete inputs add nothing: they were checked
    eagerly.

    Nor does a run traced inside one of hrgjax's own compiled programs (`tracing_callback_free`):
    their profiles come from data and plans checked where they were loaded or built, and are
    padded on purpose (the physical fit continues a run's temperature linearly past its end to
    stack runs of several lengths), and there a failed check could only poison the values
    (equinox's NaN form) into a solver's "NaN or inf"."""
    if tracing_callback_free():
        return gyro, profile, ts
    checks = profile_checks(profile) + law_checks(gyro, profile)
    checks += traced_grid_checks(ts, profile) if explicit else []
    if not checks:
        return gyro, profile, ts
    bad = jnp.stack([jnp.asarray(b) for b, _ in checks])
    messages = [m for _, m in checks]
    flat, tree = jax.tree_util.tree_flatten((gyro, profile, ts))
    traced = [i for i, x in enumerate(flat)
              if isinstance(x, jax.Array) and not is_concrete(x)]  # fmt: skip
    checked = eqx.branched_error_if(
        [flat[i] for i in traced], jnp.any(bad), jnp.argmax(bad), messages
    )
    for i, x in zip(traced, checked, strict=True):
        flat[i] = x
    return jax.tree_util.tree_unflatten(tree, flat)
