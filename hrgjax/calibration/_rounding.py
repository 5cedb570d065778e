"""A plan as a bench can run it: every number rounded to the bench's resolution."""

from __future__ import annotations

import math
from decimal import Decimal

import numpy as np

from .._checks import is_concrete
from ._plan import BenchModel, BenchPlan

TEMPERATURE_STEP_C = 0.1
"""Default resolution of a bench plan's temperatures [°C] (`round_plan`): a chamber's
set-point step."""
ANGLE_STEP_DEG = 0.1
"""Default resolution of its wave angles [° electrical] (`round_plan`)."""
TIME_STEP_S = 1.0
"""Default resolution of its durations [s] (`round_plan`): whole seconds, which
`simulate_plan`'s default output intervals (1 s, 0.5 s) divide."""
RATE_STEP_DPS = 0.01
"""Default resolution of its table rates [°/s] (`round_plan`): a rate table's set-point
step (a designed plan's rotations run at ±5 °/s, on it)."""

RESOLUTION_KEYS = {"temperature_step": "temperature_c", "angle_step": "wave_angle_deg",
                   "time_step": "duration_s", "rate_step": "rate_dps"}  # fmt: skip
"""`round_plan`'s step arguments and the plan-file key each one quantises (the unit is in the
key: °C, ° electrical, s, °/s) — the keys of a plan file's `"resolution"` block."""


def _decimals(step: float) -> int:
    """Decimal places of `step` as written (0.1 → 1, 0.25 → 2, 5.0 → 0)."""
    exponent = Decimal(repr(float(step))).normalize().as_tuple().exponent
    return max(0, -int(exponent))


def quantise(values, step: float, direction: str = "nearest") -> np.ndarray:
    """`values` on the grid of `step` (same unit), rounded `direction` (`"nearest"`,
    `"down"` or `"up"`; a value on the grid — to 1e-9 of a step — stays there), and written
    with the step's decimals, so that the floats print as a bench sheet would (−39.4, not
    −39.400000000000006). Idempotent. Host arrays (numpy)."""
    if not (isinstance(step, (int, float)) and math.isfinite(step) and step > 0):
        raise ValueError(f"step must be a finite number > 0; got {step!r}")
    k = np.asarray(values, dtype=float) / step
    if direction == "nearest":
        k = np.round(k)
    elif direction == "down":
        k = np.floor(k + 1e-9)
    elif direction == "up":
        k = np.ceil(k - 1e-9)
    else:
        raise ValueError(f"direction must be 'nearest', 'down' or 'up'; got {direction!r}")
    return np.round(k * step, _decimals(step)) + 0.0  # + 0.0: no −0.0 in a plan file


def wrap_wave_angle(angle_deg):
    """Electrical wave angles [°] wrapped to (−90°, 90°]: the same standing wave (θ and
    θ + 180° electrical differ by the amplitude's sign, which the phase absorbs) and the
    same drift, every modelled defect being a harmonic of 2θ (PHYSICS.md §1, "Angle
    periodicities"). Host arrays (numpy)."""
    a = np.asarray(angle_deg, dtype=float)
    return 90.0 - np.mod(90.0 - a, 180.0)


def _wave_angle_grid(angle_deg, step: float) -> np.ndarray:
    """The point of the grid k·`step` inside (−90°, 90°] nearest to each angle [°
    electrical] modulo 180° (the same wave): −89.97° → +90.0° at 0.1° steps, −167.2° →
    12.8°; a step that does not divide 180° has no point on one of the edges and takes the
    nearest one inside."""
    a = wrap_wave_angle(angle_deg)
    k_min = math.floor(-90.0 / step + 1e-9) + 1
    k_max = math.floor(90.0 / step + 1e-9)
    below = np.clip(np.floor(a / step), k_min, k_max)
    candidates = np.stack([below, np.clip(below + 1, k_min, k_max), np.full_like(a, k_min),
                           np.full_like(a, k_max)])  # fmt: skip
    distance = np.abs(np.mod(candidates * step - a + 90.0, 180.0) - 90.0)  # modulo 180°
    best = np.take_along_axis(candidates, np.argmin(distance, axis=0)[None], axis=0)[0]
    return quantise(best * step, step)


def resolution_step(name: str, value, unit: str) -> float:
    """A rounding step argument `name` [`unit`] as a float, checked to be finite and > 0."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not (math.isfinite(value) and value > 0):  # fmt: skip
        raise ValueError(f"{name} must be a finite number > 0 [{unit}]; got {value!r}")
    return float(value)


def round_plan(
    plan: BenchPlan,
    bench: BenchModel | None = None,
    *,
    temperature_step: float = TEMPERATURE_STEP_C,
    angle_step: float = ANGLE_STEP_DEG,
    time_step: float = TIME_STEP_S,
    rate_step: float = RATE_STEP_DPS,
    budget_h: float | None = None,
) -> BenchPlan:
    """`plan` as a bench can run it: every number on the bench's resolution.

    - **temperatures** (a static segment's or rotation's, a ramp's start and end) to the
      nearest `temperature_step` [°C] (0.1 °C) — equal temperatures stay equal, so a
      ramp still starts where its level is;
    - **wave angles** wrapped to (−90°, 90°] electrical (`wrap_wave_angle`: the same
      wave, the same drift) and to the nearest `angle_step` [° electrical] (0.1°) inside
      that range, modulo 180° (−89.97° → +90.0°);
    - **table rates** to the nearest `rate_step` [°/s] (0.01 °/s; a rotation keeps at
      least one step, in its own sense);
    - **durations** to `time_step` [s] (1 s): static segments and rotations down, ramps up
      and never shorter than the chamber (`bench`, default `BenchModel()`) needs for their
      rounded temperature change — so that a ramp never outruns it; a segment keeps at
      least one step;
    - with `budget_h` [h]: should the ramps' extra time (or the rounded temperatures'
      transitions) cross the budget, the longest static segment or rotation is shortened by
      whole steps until the bench time holds; `ValueError` if it cannot.

    Every value is written with its step's decimals (`quantise`: −39.4, not
    −39.400000000000006). Rounding is idempotent: a rounded plan rounds to itself. A
    `time_step` that is not a whole number of seconds gives durations `simulate_plan`'s
    default output intervals (1 s static and ramp, 0.5 s rotation) may not divide.

    **Returns:** a concrete, checked [`BenchPlan`][hrgjax.calibration.BenchPlan].

    **Raises:** `ValueError` naming a step that is not a finite number > 0, or the budget.
    """
    bench = BenchModel() if bench is None else bench
    temperature_step = resolution_step("temperature_step", temperature_step, "°C")
    angle_step = resolution_step("angle_step", angle_step, "° electrical")
    time_step = resolution_step("time_step", time_step, "s")
    rate_step = resolution_step("rate_step", rate_step, "°/s")
    if not all(is_concrete(x) for x in plan._fields().values()):
        raise ValueError("round_plan needs a concrete plan (host values), not a traced one")
    v = {k: np.asarray(x, dtype=float) for k, x in plan._fields().items()}
    kinds = np.array(plan.kind)
    ramp = kinds == "ramp"
    t0 = quantise(v["temperature_c"], temperature_step)
    t1 = quantise(v["temperature_end_c"], temperature_step)
    angle = _wave_angle_grid(v["wave_angle_deg"], angle_step)
    rate = quantise(v["rate_dps"], rate_step)
    turning = v["rate_dps"] != 0.0
    rate = np.where(turning & (rate == 0.0), np.sign(v["rate_dps"]) * rate_step, rate)
    rate = np.where(kinds == "static", 0.0, rate)
    chamber_s = np.abs(t1 - t0) / float(bench.slew_c_per_min) * 60.0
    dur = np.where(
        ramp,
        np.maximum(quantise(v["duration_s"], time_step, "up"),
                   quantise(chamber_s, time_step, "up")),
        quantise(v["duration_s"], time_step, "down"),
    )  # fmt: skip
    dur = np.maximum(dur, time_step)

    def build(durations):
        segs = []
        for i, k in enumerate(plan.kind):
            if k == "ramp":
                seg = {"kind": k, "temperature_start_c": float(t0[i]),
                       "temperature_end_c": float(t1[i])}  # fmt: skip
            else:
                seg = {"kind": k, "temperature_c": float(t0[i])}
            seg["wave_angle_deg"] = float(angle[i])
            if k == "rotation" or (k == "ramp" and rate[i] != 0.0):
                seg["rate_dps"] = float(rate[i])
            seg["duration_s"] = float(durations[i])
            segs.append(seg)
        return BenchPlan.from_segments(segs)

    out = build(dur)
    if budget_h is None:
        return out
    budget_s = float(budget_h) * 3600.0
    for _ in range(8 * plan.size):
        over = float(bench.bench_time_s(out)) - budget_s
        if over <= 0.0:
            return out
        longest = int(np.argmax(np.where(ramp, -np.inf, dur)))
        cut = max(time_step, float(quantise(over, time_step, "up")))
        if ramp[longest] or dur[longest] - cut < time_step:
            break
        dur[longest] = quantise(dur[longest] - cut, time_step)
        out = build(dur)
    raise ValueError(
        f"budget_h={float(budget_h):g}: the plan rounded to the bench's resolution takes "
        f"{float(bench.bench_time_s(out)) / 3600:.4f} h and its static segments and rotations "
        "cannot be shortened to fit; raise the budget or use a finer time_step"
    )
