"""Datasets with a hidden effect, in the data contract, built on `simulate` (DISCOVERY.md §3.1).

The base gyro is the default one reduced to the nominal model's physics:
`presets.tvg3_like(temperature_laws=False)` (every law frozen at +20 °C) with a perfect readout
and ideal loops, so its drift is bias + damping anisotropy, with the preset's noise. (With the
preset's real loops the base is not null: at 5 °/s the closed loops add a 2θ ripple of 3·10⁻⁵
to the true rate — the catalogue's `loop_ripple`, which at one rate reads as
`readout_gain_mismatch`.) One effect is then
put back through the gyro's own parameters, at a chosen size, by its catalogue entry's
`inject` ([`Effect`][hrgjax.discovery.effects.Effect]: adding a generated effect is that one
entry):

| effect | size means | how it is injected |
|---|---|---|
| `damping_anisotropy_temperature` | λ [1/°C] | Δ(1/τ)(T) = Δ₂₀ e^{λΔT} |
| `bias_temperature` | slope [°/h/°C] | rate bias + slope·ΔT |
| `angular_gain_temperature` | κ_T [1/°C] | k_e(T) = k_e(1 + κ_T ΔT) |
| `readout_gain_mismatch` | g [–] | pickoff gain mismatch g |
| `thermal_rate` | c [°/h per °C/min] | `DriftTerms.temperature_rate` |
| `thermal_lag` | b_L [°/h/°C], τ_th = 600 s | `DriftTerms.lag`, `lag_time` |
| `warmup_transient` | b_w [°/h], τ_w = 600 s | `DriftTerms.warmup`, `warmup_time` |
| `rate_scale_factor` | relative scale-factor change at 100 °/s | `DriftTerms.rate_cubic` |
| `loop_ripple` | frequency split Δω [rad/s] | the preset's closed loops, Δω at θ_ω = 10° el. |

The four drift terms change the gyro's equivalent input rate (the catalogue term is −k_e times it).
Dwell grids ([`hidden_effect_dataset`][hrgjax.discovery.generate.hidden_effect_dataset]) cannot
show the thermal and warm-up effects — their temperature is constant and they share one
switch-on — so those come as continuous records
([`continuous_dataset`][hrgjax.discovery.generate.continuous_dataset]): temperature ramps up and
down at two speeds, static and slowly turning, each run its own switch-on. The quadrature
effects need a quadrature set-point offset and `acceleration_sensitivity` needs ±g
orientations; neither is generated yet.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _checks
from ..calibration.experiment import rotation_plan, run_plan, static_plan
from ..data import MeasuredData, concat
from ..gyro import DriftTerms, Gyro
from ..presets import tvg3_like
from ..profiles import Profile
from ..resonator.control import Control
from ..resonator.readout import Readout
from ..simulate import simulate
from .effects import CATALOGUE
from .effects import LAG_TIME_S as LAG_TIME_S

GENERATED = tuple(n for n, e in CATALOGUE.items() if e.inject is not None)
"""Effects the generator can hide (those whose catalogue entry has an `inject`)."""
DWELL_EFFECTS = tuple(n for n in GENERATED if CATALOGUE[n].on_dwell)
"""Effects a dwell grid shows (`rate_scale_factor` and `loop_ripple` need `rates_dps` with two
rates: at one rate the ripple reads as `readout_gain_mismatch`)."""
CONTINUOUS_EFFECTS = tuple(n for n in GENERATED if n not in ("rate_scale_factor", "loop_ripple"))
"""Effects the continuous records show (the ramps turn at one rate: not the two that need a
second one)."""

TEMPERATURES = (-40.0, -15.0, 10.0, 35.0, 60.0)
ANGLES = tuple(float(a) for a in range(-90, 90, 20))


def base_gyro(noise: bool = True) -> Gyro:
    """The default gyro with only the nominal model's physics (module docstring)."""
    g = tvg3_like(temperature_laws=False, noise=noise)
    return eqx.tree_at(lambda g: (g.readout, g.control), g, (Readout(), Control(ideal=True)))


def inject(gyro: Gyro, effect, size: float = 0.0) -> Gyro:
    """`gyro` with `effect` put in at `size` (table in the module docstring).

    `effect` is a name, `None` (the null: `gyro` unchanged) or a mapping `{name: size}` to
    hide several effects at once (a pair, say); `size` is then ignored."""
    if not isinstance(gyro, Gyro):
        raise TypeError(f"inject: gyro must be an hrgjax.Gyro (e.g. base_gyro()); got "
                        f"{type(gyro).__name__}")  # fmt: skip
    if effect is None:
        return gyro
    if not isinstance(effect, str):
        try:  # a mapping, or (name, size) pairs
            effects = None if isinstance(effect, bytes) else dict(effect)
        except (TypeError, ValueError):
            effects = None
        if effects is None:
            raise TypeError(f"inject: effect must be an effect name, None or a mapping "
                            f"{{name: size}}; got {_checks.describe(effect)}")  # fmt: skip
        for name, value in effects.items():
            gyro = inject(gyro, name, value)
        return gyro
    if effect not in GENERATED:
        raise ValueError(f"cannot generate {effect!r} yet; choose from {GENERATED} or None")
    where = f"inject: size of {effect!r}"  # a NaN failed in the gyro's checks, a str in `*`
    _checks.check_number(where, size)
    _checks.check_values(where, size, np.isfinite, "a finite real number (generate.inject)")
    return CATALOGUE[effect].inject(gyro, size)


def _settings(owner: str, key, **durations) -> None:
    """Refuse a generator's `key` (one JAX PRNG key) or `durations` (finite numbers > 0
    [s]) in one line naming `owner`, before any simulation."""
    _checks.check_key(f"{owner}: key", key)
    for name, value in durations.items():
        _checks.check_number(f"{owner}: {name}", value, "s")
        _checks.check_values(f"{owner}: {name}", value, _checks.FINITE_POSITIVE,
                             "a finite number > 0 [s]")  # fmt: skip


HOLD_S = 600.0
"""The hold at each continuous run's start temperature before its ramp [s]."""
_RAMP_FORM = "rows (start °C, end °C, ramp length s, table rate °/s, initial angle °), shape (R, 5)"


def _check_ramps(owner: str, duration_s, ramps) -> None:
    """Refuse `ramps` that are not rows of five finite numbers with a ramp length > 0, or a
    `duration_s` [s] that does not hold the hold and the longest ramp, in one line."""
    _checks.check_numbers(f"{owner}: ramps", ramps, _RAMP_FORM, shape=(None, 5))
    rows = np.asarray(ramps, float)
    if rows.shape[0] == 0:
        raise ValueError(f"{owner}: ramps must be {_RAMP_FORM}; got none")
    _checks.check_finite_host(f"{owner}: ramps", rows)
    if not np.all(rows[:, 2] > 0):
        raise ValueError(f"{owner}: each ramp's length (column 2) must be > 0 s; got "
                         f"{rows[:, 2][~(rows[:, 2] > 0)][0]:g}")  # fmt: skip
    _checks.check_number(f"{owner}: duration_s", duration_s, "s")
    if not HOLD_S + rows[:, 2].max() < duration_s:
        raise ValueError(f"{owner}: duration_s must exceed {HOLD_S + rows[:, 2].max():g} s "
                         f"(the {HOLD_S:g}-s hold and the longest ramp); got "
                         f"{_checks.describe(duration_s)}")  # fmt: skip


DRIFT_FIELDS = tuple(f.name for f in dataclasses.fields(DriftTerms))


def hidden_effect_dataset(
    effect,
    size: float = 0.0,
    *,
    key: jax.Array,
    duration_s: float = 60.0,
    temperatures_c=TEMPERATURES,
    angles_deg=ANGLES,
    rates_dps=(5.0,),
) -> MeasuredData:
    """A dwell-grid bench session (static runs and runs at each of `rates_dps` at every
    temperature × angle, one switch-on) of the base gyro with `effect` hidden at `size`
    (`effect` as in [`inject`][hrgjax.discovery.generate.inject]: a name, `None` or a
    mapping `{name: size}`)."""
    _settings("hidden_effect_dataset", key, duration_s=duration_s)
    _checks.check_numbers("hidden_effect_dataset: rates_dps", rates_dps,
                          "table rates [°/s], shape (n,)", shape=(None,))  # fmt: skip
    gyro = inject(base_gyro(), effect, size)
    k_static, k_rot, k_bias = jax.random.split(key, 3)
    static = static_plan(temperatures_c, angles_deg, duration_s=duration_s, dt_out=0.5)
    rotations = [  # every plan checked before the first simulation
        rotation_plan(temperatures_c, angles_deg, rate, duration_s=duration_s) for rate in rates_dps
    ]
    parts = [run_plan(gyro, static, key=k_static, bias_key=k_bias)]
    first = static.size
    for rotation, k in zip(rotations, jax.random.split(k_rot, len(rates_dps)), strict=True):
        parts.append(run_plan(gyro, rotation, key=k, bias_key=k_bias, first_run=first))
        first += rotation.size
    return concat(parts)


RAMPS = (
    # (start °C, end °C, ramp length s, table rate °/s, initial wave angle °)
    (-20.0, 40.0, 2400.0, 0.0, 0.0),
    (40.0, -20.0, 2400.0, 2.0, 0.0),
    (-20.0, 40.0, 600.0, 0.0, 45.0),
    (40.0, -20.0, 600.0, 2.0, 30.0),
    (0.0, 60.0, 1200.0, 0.0, -30.0),
    (60.0, 0.0, 1200.0, 2.0, 60.0),
)
"""The continuous runs: a 600-s hold, a ramp, a hold to the end; static or turning."""


def ramp_profiles(duration_s: float = 3600.0, ramps=RAMPS) -> Profile:
    """The continuous runs of [`RAMPS`][hrgjax.discovery.generate.RAMPS] as one batched
    [`hrgjax.Profile`][] (leading axis = run)."""
    _check_ramps("ramp_profiles", duration_s, ramps)
    hold = HOLD_S
    profs = []
    for t_a, t_b, ramp, rate, angle in ramps:
        t = [0.0, hold, hold + ramp, duration_s]
        profs.append(Profile.piecewise(t, [rate] * 4, [t_a, t_a, t_b, t_b], wave_angle0_deg=angle))
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *profs)


@eqx.filter_jit
def _simulate_runs(gyro, profiles, keys, ts):
    return jax.vmap(lambda p, k: simulate(gyro, p, key=k, ts=ts, rtol=1e-11, atol=1e-12))(
        profiles, keys
    )


def continuous_dataset(
    effect,
    size: float = 0.0,
    *,
    key: jax.Array,
    duration_s: float = 3600.0,
    dt_out: float = 1.0,
    ramps=RAMPS,
) -> MeasuredData:
    """Continuous records of the base gyro with `effect` hidden at `size`: one run per entry
    of `ramps` (temperature ramps up and down at two speeds, static or turning at 2 °/s),
    each its own switch-on. `effect` as in [`inject`][hrgjax.discovery.generate.inject]."""
    _settings("continuous_dataset", key, duration_s=duration_s, dt_out=dt_out)
    _check_ramps("continuous_dataset", duration_s, ramps)
    if dt_out > duration_s:
        raise ValueError(f"continuous_dataset: dt_out must be <= duration_s (two samples a "
                         f"run at least); got {dt_out:g} s > {duration_s:g} s")  # fmt: skip
    gyro = inject(base_gyro(), effect, size)
    profiles = ramp_profiles(duration_s, ramps)
    ts = jnp.asarray(np.arange(int(round(duration_s / dt_out)) + 1) * dt_out)
    keys = jax.random.split(key, len(ramps))
    return _simulate_runs(gyro, profiles, keys, ts).to_data()


BENCH_LOG_TEMPERATURES = (-40.0, -20.0, 0.0, 20.0, 40.0, 60.0)
"""Temperatures of [`bench_log`][hrgjax.discovery.generate.bench_log] [°C]."""
BENCH_LOG_ANGLES = (-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0)
"""Wave angles of its static dwells [° el.]."""
BENCH_LOG_RAMPS = RAMPS + ((-40.0, 60.0, 2400.0, 0.0, 15.0), (60.0, -40.0, 2400.0, 2.0, -15.0))
"""Its eight temperature ramps (as [`RAMPS`][hrgjax.discovery.generate.RAMPS], plus the full
range both ways)."""


def bench_log(effect=None, size: float = 0.0, *, key: jax.Array) -> MeasuredData:
    """One campaign's bench log of the base gyro with `effect` hidden at `size` (as in
    [`inject`][hrgjax.discovery.generate.inject]), 62 runs in one dataset: 6 temperatures ×
    7 wave angles of 180-s static dwells at 1 Hz (one switch-on), a +5 °/s and a −5 °/s
    rotation of 72 s (one turn) at 10 Hz at each temperature, and eight 1-h temperature
    ramps at 0.2 Hz, each its own switch-on — dwell runs and continuous records together."""
    _checks.check_key("bench_log: key", key)
    gyro = inject(base_gyro(), effect, size)
    k_static, k_rot, k_bias, k_ramp = jax.random.split(key, 4)
    temps, angles = BENCH_LOG_TEMPERATURES, BENCH_LOG_ANGLES
    static = static_plan(temps, angles, duration_s=180.0, dt_out=1.0)
    parts = [run_plan(gyro, static, key=k_static, bias_key=k_bias)]
    first = static.size
    for rate, k in zip((5.0, -5.0), jax.random.split(k_rot), strict=True):
        rotation = rotation_plan(temps, (0.0,), rate, duration_s=72.0, dt_out=0.1)
        parts.append(run_plan(gyro, rotation, key=k, bias_key=k_bias, first_run=first))
        first += rotation.size
    ramps = continuous_dataset(effect, size, key=k_ramp, dt_out=5.0, ramps=BENCH_LOG_RAMPS)
    parts.append(MeasuredData({**ramps.columns, "run": ramps.run + first}))
    return concat(parts)
