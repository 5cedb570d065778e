"""The design search: the bench plan that minimises a criterion within a bench-time budget,
by Adam over each structure's continuous quantities."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_key, describe, is_finite_real, whole_number
from .._compiled import device
from .._progress import bar
from .._x64 import require_x64
from ._criteria import CRITERIA, CRITERION_UNITS, evaluate_criterion, flight_nodes
from ._information import information_source, prior_scale_array
from ._models import Empirical, as_model, model_values, noise_vector
from ._plan import BenchModel, BenchPlan
from ._plan_file import plan_to_json, save_plan
from ._rounding import (
    ANGLE_STEP_DEG,
    RATE_STEP_DPS,
    RESOLUTION_KEYS,
    TEMPERATURE_STEP_C,
    TIME_STEP_S,
    resolution_step,
    round_plan,
)
from .ins_impact import Flight

CHAMBER_RANGE_C = (-40.0, 60.0)
"""Temperatures a designed plan may use [°C] (the seed's operating range)."""
ANGLE_UNIT_DEG = 20.0
"""Unit of the wave angles in `design`'s optimiser [°]: Adam moves a parameter by about its
learning rate per step, so in these units a wave angle can travel across its whole 180°
period within a search (in degrees it could move ≈ 15°)."""

DEFAULT_LEVELS = {"physical": (2, 3, 4, 5), "empirical": (4, 5, 6, 7)}
"""Numbers of temperature levels `design` tries by default, per model."""

MIN_STATIC_S = 60.0
"""Shortest static segment a design makes [s] (one drift window)."""

DEFAULT_LEARNING_RATE = 0.3
"""Adam's default learning rate in `design` (on log(criterion), level temperatures in logits,
angles in units of `ANGLE_UNIT_DEG`, log durations). Was 0.05 up to 2026-11-25: 300 steps
were then not enough — the empirical surrogate's `ins` design at 36 h reached 28 km where 0.3
reaches 11 km (6 and 7 levels: 28/47 → 18/11 km), and the grey box's 12-h `drift+warmup`
design 0.00255 → 0.00247 ° (`benchmarks/README.md`, design section)."""
MIN_ROTATION_S = 72.0
"""Shortest rotation [s] (one full turn at 5 °/s)."""
DESIGN_RATE_DPS = 5.0
"""Table rate of designed rotations [°/s] (the seed's; alternating in sign by level)."""


class Design(eqx.Module):
    """The result of [`design`][hrgjax.calibration.design.design].

    - `plan`: the designed [`BenchPlan`][hrgjax.calibration.BenchPlan], within budget
      and rounded to the bench's resolution (`round_plan`): what the bench runs.
    - `bench`: the [`BenchModel`][hrgjax.calibration.BenchModel] it was priced with.
    - `criterion`, `value`: the criterion's name and its value for `plan`, as rounded (unit:
      `CRITERION_UNITS`).
    - `optimised_plan`, `optimised_value`: the plan as the search left it (within budget,
      before rounding) and its criterion — what the rounding cost is `value` −
      `optimised_value`.
    - `resolution`: the steps `plan` was rounded to, by plan-file key (`RESOLUTION_KEYS`:
      `temperature_c` [°C], `wave_angle_deg` [° electrical], `duration_s` [s], `rate_dps`
      [°/s]).
    - `bench_time_h`: `plan`'s bench time [h]; `levels`: its number of temperature levels.
    - `search`: `{levels: value}` of every structure tried, as rounded (None: it cannot fit
      the budget even at its shortest segments); `history`: the loss per step of the chosen
      structure.
    - `model`: the name of the model the criterion was computed for (`MODELS`).
    """

    plan: BenchPlan
    bench: BenchModel
    criterion: str = eqx.field(static=True)
    value: float = eqx.field(static=True)
    bench_time_h: float = eqx.field(static=True)
    levels: int = eqx.field(static=True)
    search: dict = eqx.field(static=True)
    history: tuple = eqx.field(static=True)
    model: str = eqx.field(static=True, default="physical")
    optimised_plan: BenchPlan | None = None
    optimised_value: float = eqx.field(static=True, default=math.nan)
    resolution: dict = eqx.field(static=True, default_factory=dict)

    def criterion_json(self) -> dict:
        """The plan file's `"criterion"` block: `kind`, `model`, `unit`, `optimised` (the
        search's plan) and `rounded` (the plan written)."""
        return {"kind": self.criterion, "model": self.model,
                "unit": CRITERION_UNITS[self.criterion],
                "optimised": float(self.optimised_value), "rounded": float(self.value)}  # fmt: skip

    def to_json(self) -> dict:
        """The plan file's content: `plan_to_json` of `plan` with the `"criterion"` and
        `"resolution"` blocks."""
        return plan_to_json(self.plan, self.bench, criterion=self.criterion_json(),
                            resolution=self.resolution)  # fmt: skip

    def save(self, path: str | os.PathLike) -> str:
        """Write the rounded plan as a JSON plan file with its two criterion values and its
        resolution (atomically); returns the path. `load_plan` reads it."""
        return save_plan(self.plan, path, self.bench, criterion=self.criterion_json(),
                         resolution=self.resolution)  # fmt: skip


def _levels(levels) -> tuple[int, ...]:
    """`design`'s `levels` as a non-empty tuple of whole numbers ≥ 1, or a one-line
    `ValueError` (2.7 levels is refused, not read as 2)."""
    what = "a non-empty sequence of whole numbers ≥ 1 (temperature levels to try)"
    try:
        given = tuple(levels)
    except TypeError:
        raise ValueError(f"levels must be {what}; got {describe(levels)}") from None
    if not given:
        raise ValueError(f"levels must be {what}; got ()")
    return tuple(whole_number("levels", k, what, 1) for k in given)


def _structure(levels: int, statics: int, rotations: int, ramps: bool) -> tuple[str, ...]:
    kinds = []
    for k in range(levels):
        kinds += ["static"] * statics + ["rotation"] * rotations
        if ramps and k < levels - 1:
            kinds.append("ramp")
    return tuple(kinds)


def _unpack(z, kinds, levels, statics, rotations, ramps, bench):
    """The plan of the unconstrained parameters `z` (a dict of arrays)."""
    lo, hi = CHAMBER_RANGE_C
    temps = lo + (hi - lo) * jax.nn.sigmoid(z["level"])  # (K,)
    per = statics + rotations
    t0, t1, ang, rate, dur = [], [], [], [], []
    for k in range(levels):
        for j in range(per):
            i = k * per + j
            t0.append(temps[k])
            t1.append(temps[k])
            ang.append(ANGLE_UNIT_DEG * z["angle"][i])
            is_rot = j >= statics
            sign = 1.0 if k % 2 == 0 else -1.0
            rate.append(jnp.asarray(sign * DESIGN_RATE_DPS if is_rot else 0.0))
            base = MIN_ROTATION_S if is_rot else MIN_STATIC_S
            dur.append(base + jnp.exp(z["log_dur"][i]))
        if ramps and k < levels - 1:
            dtemp = jnp.abs(temps[k + 1] - temps[k])
            slowest = dtemp / bench.slew_c_per_min * 60.0  # the chamber's fastest ramp [s]
            t0.append(temps[k])
            t1.append(temps[k + 1])
            ang.append(ANGLE_UNIT_DEG * z["ramp_angle"][k])
            rate.append(jnp.asarray(0.0))
            dur.append(jnp.maximum(slowest, 60.0) * (1.0 + jnp.exp(z["ramp_stretch"][k])))
    stack = lambda xs: jnp.stack([jnp.asarray(x, dtype=float) for x in xs])
    return BenchPlan(kinds, stack(t0), stack(t1), stack(ang), stack(rate), stack(dur))


def _within_budget(plan: BenchPlan, bench: BenchModel, budget_s: float) -> BenchPlan:
    """`plan` with its static and rotation durations shrunk (by one factor, not below the
    minimum lengths) until its bench time is within `budget_s`."""
    if float(bench.bench_time_s(plan)) <= budget_s:
        return plan
    kinds = np.array(plan.kind)
    base = np.where(kinds == "rotation", MIN_ROTATION_S, MIN_STATIC_S)
    dur = np.asarray(plan.duration_s, dtype=float)
    free = kinds != "ramp"

    def shrunk(s):
        d = np.where(free, base + s * (dur - base), dur)
        return eqx.tree_at(lambda p: p.duration_s, plan, device(d))

    lo, hi = 0.0, 1.0
    if float(bench.bench_time_s(shrunk(0.0))) > budget_s:
        raise ValueError(
            f"budget_h={budget_s / 3600:g} cannot hold this structure even at its shortest "
            f"segments ({float(bench.bench_time_s(shrunk(0.0))) / 3600:.2f} h); raise the "
            "budget or use fewer levels or segments"
        )
    for _ in range(60):
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if float(bench.bench_time_s(shrunk(mid))) <= budget_s else (lo, mid)
    return shrunk(lo)


def _design_loss(z, values, arw, budget_s, args, criterion, flight, model):
    plan = _unpack(z, *args)
    c = evaluate_criterion(plan, criterion, values, arw, 100.0, flight, model)
    c = jnp.log(c) if criterion != "d" else c
    over = jax.nn.relu(args[-1].bench_time_s(plan) / budget_s - 1.0)
    return c + 100.0 * over**2


@eqx.filter_jit
def _design_step(z, state, values, arw, budget_s, args, criterion, flight, model,
                 learning_rate):  # fmt: skip
    """One Adam step of `design` (compiled once per structure, criterion and model; the
    learning rate is a traced argument)."""
    import optax

    val, g = jax.value_and_grad(_design_loss)(
        z, values, arw, budget_s, args, criterion, flight, model
    )
    upd, state = optax.adam(learning_rate).update(g, state, z)
    return optax.apply_updates(z, upd), state, val


def design(
    budget_h: float,
    *,
    criterion: str = "drift+warmup",
    levels: Sequence[int] | None = None,
    statics: int = 6,
    rotations: int = 2,
    ramps: bool = True,
    bench: BenchModel | None = None,
    steps: int = 300,
    learning_rate: float = DEFAULT_LEARNING_RATE,
    values=None,
    arw: float | None = None,
    gauss_markov: tuple[float, float] | None = None,
    angle_white: float | None = None,
    flight: Flight | Sequence[Flight] | None = None,
    model: str | Empirical | None = None,
    key: jax.Array | None = None,
    temperature_step: float = TEMPERATURE_STEP_C,
    angle_step: float = ANGLE_STEP_DEG,
    time_step: float = TIME_STEP_S,
    rate_step: float = RATE_STEP_DPS,
) -> Design:
    """The bench plan that, within `budget_h` hours of bench time (transitions included,
    priced by `bench`), minimises `criterion` (`CRITERIA`; default `drift+warmup`).

    **How.** A plan is a number of temperature levels; at each, `statics` static segments
    and `rotations` rotations at ±5 °/s, and (with `ramps`) a ramp to the next level that
    measures while the chamber moves (no slew or soak between levels then). Continuous
    quantities — the level temperatures (within `CHAMBER_RANGE_C`), every wave angle and
    duration, how much slower than the chamber each ramp runs — are optimised by Adam
    (`steps`, `learning_rate`: default `DEFAULT_LEARNING_RATE`) on log(criterion) plus a
    quadratic penalty above the budget;
    the number of levels by trying each of `levels` (default `DEFAULT_LEVELS[model]`: 2–5
    levels for the grey box, 4–7 for the empirical surrogate, which must visit more
    temperatures; a small discrete search; a structure
    that cannot fit the budget is skipped, and `ValueError` says so when none fits). The
    `arw`, `gauss_markov`, `angle_white`: the noise the criterion assumes (as
    [`information`][hrgjax.calibration.design.information]; default the default gyro's);
    `flight`: the `ins` criterion's flight or flights (default `INS_FLIGHTS`); `model`: what
    the calibration will fit (`MODELS`: `physical`, the default, or `empirical` — a plan for
    an MLP or a Fourier fit, which have no physics to carry them between points). The
    result is brought within the budget by shrinking its durations, then rounded to the
    bench's resolution by [`round_plan`][hrgjax.calibration.round_plan] —
    temperatures to `temperature_step` [°C] (0.1 °C), wave angles wrapped to (−90°, 90°]
    electrical and to `angle_step` [° electrical] (0.1°), durations to `time_step` [s]
    (whole seconds: static and rotation durations down, ramps up), table rates to
    `rate_step` [°/s] (0.01 °/s) — within the budget still, so that a bench — and
    [`simulate_plan`][hrgjax.calibration.simulate_plan] — can run it as it is; the
    criterion is computed again for the rounded plan (`Design.value`, beside the search's
    `Design.optimised_value`), and the structures are compared as rounded.
    `key` jitters the start angles.

    **Returns:** a [`Design`][hrgjax.calibration.design.Design].
    """
    import optax

    require_x64("hrgjax.calibration.design.design")
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}; got {criterion!r}")
    if not (is_finite_real(budget_h) and float(budget_h) > 0):
        raise ValueError(f"budget_h must be a positive number of hours; got {describe(budget_h)}")
    budget_h = float(budget_h)
    plausible.check("budget_h (as seconds)", budget_h * 3600.0, "duration_s")
    model = as_model(model)
    levels = _levels(DEFAULT_LEVELS[model.name] if levels is None else levels)
    statics = whole_number("statics", statics, "a whole number ≥ 1 (static segments per level)", 1)
    rotations = whole_number("rotations", rotations, "a whole number ≥ 0 (rotations per level)", 0)
    if not (is_finite_real(learning_rate) and float(learning_rate) > 0):
        raise ValueError(f"learning_rate must be a positive number; got {describe(learning_rate)}")
    steps = whole_number("steps", steps, "a whole number ≥ 1 (Adam steps per structure)", 1)
    bench = BenchModel() if bench is None else bench
    if not isinstance(bench, BenchModel):
        raise TypeError(f"bench must be a calibration.BenchModel or None; got {describe(bench)}")
    if key is not None:
        check_key("design: key", key)
    steps_by_key = {"temperature_step": (temperature_step, "°C"),
                    "angle_step": (angle_step, "° electrical"), "time_step": (time_step, "s"),
                    "rate_step": (rate_step, "°/s")}  # fmt: skip
    rounding = {name: resolution_step(name, x, unit) for name, (x, unit) in steps_by_key.items()}
    values = model_values(values, model)
    arw_v = noise_vector(arw, gauss_markov, angle_white)
    flight = flight_nodes(flight)
    budget_s = float(budget_h) * 3600.0
    key = jax.random.key(0) if key is None else key
    per = statics + rotations
    best, search, too_big = None, {}, None

    def _value(plan):  # the criterion of a concrete plan (its information, chunked)
        source, panels = information_source(plan, values, arw_v, model)
        return float(
            evaluate_criterion(
                source, criterion, values, arw_v, prior_scale_array(100.0), flight, model, panels
            )
        )

    with bar(len(levels) * steps, f"designing a {budget_h:g}-h plan", unit="step",
             tick=True) as progress:  # fmt: skip
        for n_lev in levels:
            kinds = _structure(n_lev, statics, rotations, ramps)
            n_meas = n_lev * per
            # start: levels spread over the range, angles spread over 180°, durations
            # sharing what the transitions leave of the budget
            spread = (np.arange(n_lev) + 0.5) / n_lev
            trans = n_lev * (bench.settle_s + bench.reposition_s * per) + 6000.0
            share = max(budget_s - trans, 0.3 * budget_s) / n_meas
            angles = np.tile(np.linspace(-90.0, 90.0, per, endpoint=False), n_lev)
            angles = angles + np.asarray(jax.random.uniform(key, angles.shape, maxval=5.0))
            n_ramp = max(n_lev - 1, 1)
            ramp_angles = (np.arange(n_ramp) + 0.5) / n_ramp * 180.0 - 90.0  # spread too
            z = {
                "level": jnp.asarray(np.log(spread / (1 - spread))),
                "angle": jnp.asarray(angles / ANGLE_UNIT_DEG),
                # a strongly typed start (jnp.full of a Python float is weakly typed, Adam's
                # first update is not: the step would compile twice per structure)
                "log_dur": jnp.full(n_meas, np.log(max(share - MIN_STATIC_S, 10.0)), dtype=float),
                "ramp_angle": jnp.asarray(ramp_angles / ANGLE_UNIT_DEG),
                "ramp_stretch": jnp.zeros(max(n_lev - 1, 1)),
            }
            args = (kinds, n_lev, statics, rotations, ramps, bench)
            opt = optax.adam(learning_rate)
            rate = jnp.asarray(float(learning_rate))  # a value: a new rate compiles nothing
            history = []
            budget = jnp.asarray(budget_s)
            # optax's Adam bias correction mixes int and float: traced under standard
            # promotion whatever the caller's setting
            with jax.numpy_dtype_promotion("standard"):
                state = opt.init(z)
                for _ in range(steps):
                    z, state, val = _design_step(z, state, values, arw_v, budget, args,
                                                 criterion, flight, model, rate)  # fmt: skip
                    history.append(float(val))
                    progress.update(1)
            try:
                optimised = _within_budget(_unpack(z, *args), bench, budget_s)
                # concrete, checked, runnable: the bench's resolution, within the budget
                plan = round_plan(optimised, bench, budget_h=budget_s / 3600.0, **rounding)
            except ValueError as err:  # this structure cannot fit: try the others
                search[n_lev] = None
                too_big = err
                continue
            optimised_value, value = _value(optimised), _value(plan)
            search[n_lev] = value
            progress.set_postfix_str(f"{n_lev} levels: {value:.4g}")
            if best is None or value < best[1]:
                best = (plan, value, n_lev, tuple(history), optimised, optimised_value)
    if best is None:
        raise too_big
    plan, value, n_lev, history, optimised, optimised_value = best
    return Design(
        plan=plan,
        bench=bench,
        criterion=criterion,
        value=value,
        bench_time_h=float(bench.bench_time_s(plan)) / 3600.0,
        levels=n_lev,
        search=search,
        history=history,
        model=model.name,
        optimised_plan=optimised,
        optimised_value=optimised_value,
        resolution={RESOLUTION_KEYS[k]: v for k, v in rounding.items()},
    )
