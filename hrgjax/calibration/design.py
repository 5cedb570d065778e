"""Bench plans as differentiable pytrees: segments, the bench-time model, plan files, and
simulating a plan as one switch-on.

A [`BenchPlan`][hrgjax.calibration.design.BenchPlan] is a sequence of segments in bench
order, each of one kind:

- **static** — table at rest at one temperature and wave angle for a duration;
- **rotation** — the table turning at a constant rate, one temperature;
- **ramp** — the chamber moving the temperature linearly from T₀ to T₁ over the duration
  (the table at rest, or turning at `rate_dps`).

Every continuous quantity (temperatures, wave angles, rates, durations) is an array leaf, so
a plan can be differentiated, vmapped over and optimised; the kinds are static. A
[`BenchModel`][hrgjax.calibration.design.BenchModel] turns a plan into bench time: the
measuring time plus, between segments, the chamber's slew and soak and the table's
re-positioning — smoothly, so that the bench time has a gradient with respect to the plan.

Plan files (DESIGN.md's contract) are JSON::

    {"segments": [
       {"kind": "static", "temperature_c": -40.0, "wave_angle_deg": 0.0, "duration_s": 180.0},
       {"kind": "rotation", "temperature_c": -40.0, "wave_angle_deg": 0.0, "rate_dps": 5.0,
        "duration_s": 72.0},
       {"kind": "ramp", "temperature_start_c": -40.0, "temperature_end_c": 60.0,
        "wave_angle_deg": 30.0, "duration_s": 6000.0}],
     "bench_time_h": 2.61,
     "bench": {"slew_c_per_min": 1.0, "settle_s": 1800.0, "reposition_s": 60.0,
               "start_temperature_c": 20.0}}

`bench_time_h` (and the `bench` block it was computed with) is written for the reader; on
loading, the bench time is computed again from the segments.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from decimal import Decimal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import concrete_value, is_concrete
from .._compiled import device
from .._io import read_json
from .._progress import bar
from .._x64 import require_x64
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..units import DEG, DEG_PER_H, DEG_PER_S, K_E_NOMINAL
from .experiment import CHUNK, SEED_ANGLES, SEED_TEMPERATURES, _simulate_chunk, failed_member
from .ins_impact import FLIGHTS, Flight

KINDS = ("static", "rotation", "ramp")
"""The segment kinds."""

DT_OUT = {"static": 1.0, "rotation": 0.5, "ramp": 1.0}
"""Default output interval of each kind [s] (the seed's: static 1 s, rotation 0.5 s)."""

_KEYS = {
    "static": (("temperature_c", "wave_angle_deg", "duration_s"), ()),
    "rotation": (("temperature_c", "wave_angle_deg", "rate_dps", "duration_s"), ()),
    "ramp": (
        ("temperature_start_c", "temperature_end_c", "wave_angle_deg", "duration_s"),
        ("rate_dps",),
    ),
}
_UNITS = {
    "temperature_c": "°C",
    "temperature_start_c": "°C",
    "temperature_end_c": "°C",
    "wave_angle_deg": "° electrical",
    "rate_dps": "°/s",
    "duration_s": "s",
}


class BenchPlan(eqx.Module):
    """A bench session as a sequence of segments (static, rotation, ramp), in bench order.

    **Arguments** (arrays of shape (S,), one entry per segment):

    - `kind`: tuple of S names from `KINDS` (static: not differentiated).
    - `temperature_c`: temperature at the segment's start [°C].
    - `temperature_end_c`: temperature at its end [°C] (equal to `temperature_c` except for
      ramps).
    - `wave_angle_deg`: electrical wave angle at the segment's start [°].
    - `rate_dps`: table rate [°/s] (0 for static segments; a ramp may turn).
    - `duration_s`: length of the segment [s] (a ramp's rate of change is
      (T₁ − T₀)/duration).

    Build one with [`BenchPlan.from_segments`][hrgjax.calibration.design.BenchPlan.from_segments]
    (the plan file's list of dicts), [`load_plan`][hrgjax.calibration.design.load_plan] or
    [`seed_bench_plan`][hrgjax.calibration.design.seed_bench_plan].
    """

    kind: tuple[str, ...] = eqx.field(static=True)
    temperature_c: jax.Array
    temperature_end_c: jax.Array
    wave_angle_deg: jax.Array
    rate_dps: jax.Array
    duration_s: jax.Array

    def __check_init__(self):
        if not isinstance(self.kind, tuple) or any(k not in KINDS for k in self.kind):
            bad = (
                [k for k in self.kind if k not in KINDS]
                if isinstance(self.kind, tuple)
                else [self.kind]
            )
            raise ValueError(f"BenchPlan.kind must be a tuple of {KINDS}; got {bad[:3]}")
        n = len(self.kind)
        if n == 0:
            raise ValueError("BenchPlan needs at least one segment")
        fields = self._fields()
        for name, x in fields.items():
            if getattr(x, "shape", None) != (n,):
                raise ValueError(
                    f"BenchPlan.{name} must have shape ({n},) (one value per segment); "
                    f"got {getattr(x, 'shape', type(x).__name__)}"
                )
        if not all(is_concrete(x) for x in fields.values()):
            return  # traced (under jit, grad, vmap): checked where it was built
        v = {k: np.asarray(x, dtype=float) for k, x in fields.items()}
        for name, x in v.items():
            bad = np.flatnonzero(~np.isfinite(x))
            if bad.size:
                raise ValueError(f"BenchPlan.{name}[{bad[0]}] is {x[bad[0]]}; give a finite value")
        bad = np.flatnonzero(v["duration_s"] <= 0)
        if bad.size:
            i = bad[0]
            raise ValueError(f"segment {i} ({self.kind[i]}): duration_s must be > 0 [s]")
        for name, quantity in (("temperature_c", "temperature_c"),
                               ("temperature_end_c", "temperature_c"),
                               ("wave_angle_deg", "wave_angle_deg"),
                               ("rate_dps", "table_rate_dps"),
                               ("duration_s", "duration_s")):  # fmt: skip
            plausible.check(f"BenchPlan.{name}", v[name], quantity)
        for i, k in enumerate(self.kind):
            if k != "ramp" and v["temperature_end_c"][i] != v["temperature_c"][i]:
                raise ValueError(
                    f"segment {i} ({k}): temperature_end_c must equal temperature_c "
                    "(only a ramp changes the temperature)"
                )
            if k == "static" and v["rate_dps"][i] != 0.0:
                raise ValueError(f"segment {i} (static): rate_dps must be 0; use a rotation")
            if k == "rotation" and v["rate_dps"][i] == 0.0:
                raise ValueError(f"segment {i} (rotation): rate_dps must be non-zero [°/s]")

    def _fields(self) -> dict[str, jax.Array]:
        return {
            "temperature_c": self.temperature_c,
            "temperature_end_c": self.temperature_end_c,
            "wave_angle_deg": self.wave_angle_deg,
            "rate_dps": self.rate_dps,
            "duration_s": self.duration_s,
        }

    @property
    def size(self) -> int:
        """Number of segments."""
        return len(self.kind)

    @property
    def measuring_s(self) -> jax.Array:
        """Total time of the segments themselves [s] (transitions excluded)."""
        return jnp.sum(self.duration_s)

    @classmethod
    def from_segments(cls, segments: Sequence[Mapping], where: str = "segments") -> BenchPlan:
        """A plan from the plan file's list of segment dicts (keys with units in their
        names, as in the module docstring). Every error names the segment and the key."""
        if isinstance(segments, (str, bytes)) or not isinstance(segments, Sequence):
            raise ValueError(f"{where} must be a list of segment objects; got {type(segments)}")
        if not segments:
            raise ValueError(f"{where} is empty; give at least one segment")
        cols: dict[str, list[float]] = {k: [] for k in cls._FIELDS}
        kinds = []
        for i, seg in enumerate(segments):
            here = f"{where}[{i}]"
            if not isinstance(seg, Mapping):
                raise ValueError(f"{here} must be an object with a 'kind'; got {seg!r}")
            kind = seg.get("kind")
            if kind not in KINDS:
                raise ValueError(f"{here}: 'kind' must be one of {KINDS}; got {kind!r}")
            need, optional = _KEYS[kind]
            for k in seg:
                if k != "kind" and k not in need + optional:
                    allowed = ", ".join(f"'{a}' [{_UNITS[a]}]" for a in need + optional)
                    raise ValueError(f"{here} ({kind}): unknown key {k!r}; expected {allowed}")
            for k in need:
                if k not in seg:
                    raise ValueError(f"{here} ({kind}): missing {k!r} [{_UNITS[k]}]")
            val = {}
            for k in need + optional:
                if k not in seg:
                    continue
                x = seg[k]
                if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
                    raise ValueError(f"{here} ({kind}): {k!r} must be a finite number "
                                     f"[{_UNITS[k]}]; got {x!r}")  # fmt: skip
                val[k] = float(x)
            t0 = val.get("temperature_c", val.get("temperature_start_c"))
            cols["temperature_c"].append(t0)
            cols["temperature_end_c"].append(val.get("temperature_end_c", t0))
            cols["wave_angle_deg"].append(val["wave_angle_deg"])
            cols["rate_dps"].append(val.get("rate_dps", 0.0))
            cols["duration_s"].append(val["duration_s"])
            kinds.append(kind)
        try:
            return cls(tuple(kinds), **{k: device(np.asarray(v)) for k, v in cols.items()})
        except ValueError as err:
            raise ValueError(f"{where}: {err}") from None

    _FIELDS = ("temperature_c", "temperature_end_c", "wave_angle_deg", "rate_dps", "duration_s")

    def segments(self) -> list[dict]:
        """The plan file's list of segment dicts (host floats; keys with units)."""
        v = {k: np.asarray(x, dtype=float) for k, x in self._fields().items()}
        out = []
        for i, k in enumerate(self.kind):
            if k == "ramp":
                seg = {"kind": k, "temperature_start_c": float(v["temperature_c"][i]),
                       "temperature_end_c": float(v["temperature_end_c"][i])}  # fmt: skip
            else:
                seg = {"kind": k, "temperature_c": float(v["temperature_c"][i])}
            seg["wave_angle_deg"] = float(v["wave_angle_deg"][i])
            if k == "rotation" or (k == "ramp" and v["rate_dps"][i] != 0.0):
                seg["rate_dps"] = float(v["rate_dps"][i])
            seg["duration_s"] = float(v["duration_s"][i])
            out.append(seg)
        return out


class BenchModel(eqx.Module):
    """What a bench session costs besides measuring: the thermal chamber and the rate table.

    Between consecutive segments (and before the first, from `start_temperature_c`) a
    temperature change ΔT = T_start(next) − T_end(previous) costs

    $$t(\\Delta T) = \\frac{|\\Delta T|_\\delta}{\\text{slew}}
      + t_\\text{settle}\\,\\bigl(1 - e^{-(\\Delta T/T_s)^2}\\bigr) + t_\\text{reposition},$$

    with |x|_δ = x·tanh(x/δ) (δ = 0.05 °C: |x| to 1e-15 beyond 2 °C, 0 at 0) and
    T_s = `settle_scale_c`: a smooth
    version of "slew at the chamber's rate, then soak until the gyro is at temperature", so
    that the bench time has a gradient with respect to every temperature. Ramps run at their
    own rate inside their duration (`check` refuses one faster than the chamber).

    **Arguments:**

    - `slew_c_per_min`: the chamber's fastest temperature change [°C/min] (1 °C/min).
    - `settle_s`: soak after a temperature change, before measuring [s] (30 min).
    - `reposition_s`: between any two segments: set the wave angle, start or stop the table,
      check the loops [s] (1 min).
    - `start_temperature_c`: where the chamber starts [°C] (20 °C).
    - `settle_scale_c`: temperature change below which the soak shrinks [°C] (0.5 °C).
    """

    slew_c_per_min: float = 1.0
    settle_s: float = 1800.0
    reposition_s: float = 60.0
    start_temperature_c: float = 20.0
    settle_scale_c: float = 0.5

    def __check_init__(self):
        for name in ("slew_c_per_min", "settle_scale_c"):
            x = getattr(self, name)
            if is_concrete(x) and not float(x) > 0:
                raise ValueError(f"BenchModel.{name} must be > 0; got {x}")
        for name in ("settle_s", "reposition_s"):
            x = getattr(self, name)
            if is_concrete(x) and not float(x) >= 0:
                raise ValueError(f"BenchModel.{name} must be ≥ 0 [s]; got {x}")
        x = self.start_temperature_c
        if is_concrete(x):
            if not math.isfinite(float(x)):
                raise ValueError(f"BenchModel.start_temperature_c must be finite [°C]; got {x}")
            plausible.check("BenchModel.start_temperature_c", x, "temperature_c")

    def transitions_s(self, plan: BenchPlan) -> dict[str, jax.Array]:
        """Per-segment costs before each segment [s], shape (S,) each: `slew`, `settle`,
        `reposition`."""
        prev_end = jnp.concatenate(
            [jnp.reshape(jnp.asarray(self.start_temperature_c, float), (1,)),
             plan.temperature_end_c[:-1]]
        )  # fmt: skip
        dt = plan.temperature_c - prev_end
        delta = 0.05
        slew = dt * jnp.tanh(dt / delta) / self.slew_c_per_min * 60.0
        settle = self.settle_s * (1.0 - jnp.exp(-((dt / self.settle_scale_c) ** 2)))
        repos = jnp.broadcast_to(jnp.asarray(self.reposition_s, dtype=float), dt.shape)
        return {"slew": slew, "settle": settle, "reposition": repos}

    def bench_time_s(self, plan: BenchPlan) -> jax.Array:
        """Bench time of the whole plan [s]: measuring plus every transition (differentiable
        with respect to the plan's arrays)."""
        parts = self.transitions_s(plan)
        return plan.measuring_s + sum(jnp.sum(p) for p in parts.values())

    def breakdown_h(self, plan: BenchPlan) -> dict[str, float]:
        """Bench time split into measuring, slewing, settling and re-positioning [h]."""
        parts = {"measuring": plan.measuring_s}
        parts.update({k: jnp.sum(v) for k, v in self.transitions_s(plan).items()})
        out = {k: float(v) / 3600.0 for k, v in parts.items()}
        out["total"] = sum(out.values())
        return out

    def check(self, plan: BenchPlan) -> None:
        """Raise `ValueError` naming the first ramp faster than the chamber can slew."""
        rate = (
            np.abs(np.asarray(plan.temperature_end_c) - np.asarray(plan.temperature_c))
            / np.asarray(plan.duration_s)
            * 60.0
        )
        for i, k in enumerate(plan.kind):
            if k == "ramp" and rate[i] > float(self.slew_c_per_min) * (1 + 1e-12):
                raise ValueError(
                    f"segment {i} (ramp): {rate[i]:.3g} °C/min is faster than the chamber's "
                    f"slew_c_per_min={float(self.slew_c_per_min):g}; lengthen duration_s"
                )

    def to_json(self) -> dict[str, float]:
        return {
            "slew_c_per_min": float(self.slew_c_per_min),
            "settle_s": float(self.settle_s),
            "reposition_s": float(self.reposition_s),
            "start_temperature_c": float(self.start_temperature_c),
            "settle_scale_c": float(self.settle_scale_c),
        }


def bench_time_h(plan: BenchPlan, bench: BenchModel | None = None) -> jax.Array:
    """Bench time of `plan` [h] under `bench` (default `BenchModel()`)."""
    return (BenchModel() if bench is None else bench).bench_time_s(plan) / 3600.0


def seed_bench_plan(
    quick: bool = False, rate_dps: float = 5.0, duration_s: float | None = None
) -> BenchPlan:
    """The seed's calibration plan as one bench session: at each temperature (−40 → +60 °C),
    3-min static dwells at each wave angle (−90…+90° in 10° steps), then 3-min rotations at
    `rate_dps` [°/s] from each angle. `quick`: −40, +20, +60 °C and 2-min runs (as
    `seed_plan(quick=True)`). `duration_s`: every run's length [s] instead (the same grid
    with shorter or longer dwells)."""
    from .experiment import QUICK_DURATION, QUICK_TEMPERATURES

    temps, dur = (QUICK_TEMPERATURES, QUICK_DURATION) if quick else (SEED_TEMPERATURES, 180.0)
    if duration_s is not None:
        if not (np.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"duration_s must be a positive run length [s]; got {duration_s}")
        dur = float(duration_s)
    segs = []
    for t in temps:
        for kind in ("static", "rotation"):
            for a in SEED_ANGLES:
                seg = {"kind": kind, "temperature_c": t, "wave_angle_deg": a, "duration_s": dur}
                if kind == "rotation":
                    seg["rate_dps"] = rate_dps
                segs.append(seg)
    return BenchPlan.from_segments(segs)


_CRITERION_KEYS = ("kind", "model", "unit", "optimised", "rounded")


def plan_to_json(plan: BenchPlan, bench: BenchModel | None = None, *,
                 criterion: Mapping | None = None, resolution: Mapping | None = None) -> dict:  # fmt: skip
    """The plan file's content: segments, `bench_time_h` (computed from `plan`, as it is)
    and the `bench` model used; with `criterion` (a designed plan's: `kind`, `model`,
    `unit`, `optimised` — the search's plan — and `rounded` — this one; as
    `Design.criterion_json`) and `resolution` (the steps the plan was rounded to, by
    segment key: `temperature_c` [°C], `wave_angle_deg` [° electrical], `duration_s` [s],
    `rate_dps` [°/s]), those blocks too."""
    bench = BenchModel() if bench is None else bench
    doc = {
        "segments": plan.segments(),
        "bench_time_h": float(bench_time_h(plan, bench)),
        "bench": bench.to_json(),
    }
    if criterion is not None:
        doc["criterion"] = _criterion_block(criterion, "criterion")
    if resolution is not None:
        doc["resolution"] = _resolution_block(resolution, "resolution")
    return doc


def _criterion_block(block, where: str) -> dict:
    """A plan file's `"criterion"` block, checked: `kind` (`CRITERIA`), `model`, `unit`
    (strings), `optimised` and `rounded` (finite numbers)."""
    if not isinstance(block, Mapping) or set(block) != set(_CRITERION_KEYS):
        raise ValueError(f"{where} must be an object with keys {list(_CRITERION_KEYS)}")
    if block["kind"] not in CRITERIA:
        raise ValueError(f"{where}: 'kind' must be one of {CRITERIA}; got {block['kind']!r}")
    for k in ("model", "unit"):
        if not isinstance(block[k], str):
            raise ValueError(f"{where}: {k!r} must be a string; got {block[k]!r}")
    for k in ("optimised", "rounded"):
        x = block[k]
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise ValueError(f"{where}: {k!r} must be a finite number; got {x!r}")
    return {k: block[k] if k in ("kind", "model", "unit") else float(block[k])
            for k in _CRITERION_KEYS}  # fmt: skip


def _resolution_block(block, where: str) -> dict:
    """A plan file's `"resolution"` block, checked: steps > 0 by segment key."""
    keys = tuple(RESOLUTION_KEYS.values())
    if not isinstance(block, Mapping) or not block or set(block) - set(keys):
        raise ValueError(f"{where} must be an object with keys from {list(keys)}")
    out = {}
    for k in keys:
        if k in block:
            x = block[k]
            if (
                isinstance(x, bool)
                or not isinstance(x, (int, float))
                or not (math.isfinite(x) and x > 0)
            ):
                raise ValueError(f"{where}: {k!r} must be a step > 0 [{_UNITS[k]}]; got {x!r}")
            out[k] = float(x)
    return out


def save_plan(plan: BenchPlan, path: str | os.PathLike, bench: BenchModel | None = None, *,
              criterion: Mapping | None = None, resolution: Mapping | None = None):  # fmt: skip
    """Write `plan` as a JSON plan file (atomically; `criterion`, `resolution`: the blocks
    of `plan_to_json`); returns the path."""
    from .._io import atomic_write

    doc = plan_to_json(plan, bench, criterion=criterion, resolution=resolution)
    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(json.dumps(doc, indent=1, ensure_ascii=False) + "\n")
    return os.fspath(path)


def load_plan(path: str | os.PathLike) -> tuple[BenchPlan, BenchModel]:
    """Read a JSON plan file: `(plan, bench)` — `bench` from its `"bench"` block where it
    has one, else `BenchModel()`. A designed plan's `"criterion"` and `"resolution"` blocks
    (`plan_to_json`) are checked and otherwise left to the reader; files without them load
    as before. Errors name the file, the segment and the key."""
    doc = read_json(path)
    where = f"{os.fspath(path)}"
    if not isinstance(doc, dict) or "segments" not in doc:
        raise ValueError(f"{where}: a plan file is an object with a 'segments' list")
    unknown = set(doc) - {"segments", "bench_time_h", "bench", "criterion", "resolution"}
    if unknown:
        raise ValueError(
            f"{where}: unknown key(s) {sorted(unknown)}; expected 'segments', "
            "'bench_time_h', 'bench', 'criterion', 'resolution'"
        )
    if "criterion" in doc:
        _criterion_block(doc["criterion"], f"{where}: 'criterion'")
    if "resolution" in doc:
        _resolution_block(doc["resolution"], f"{where}: 'resolution'")
    plan = BenchPlan.from_segments(doc["segments"], where=f"{where}: segments")
    bench = BenchModel()
    if "bench" in doc:
        b = doc["bench"]
        fields = set(BenchModel().to_json())
        if not isinstance(b, dict) or set(b) - fields:
            raise ValueError(f"{where}: 'bench' must be an object with keys from {sorted(fields)}")
        for k, v in b.items():  # numbers only: float() would read "inf", "1e3" or true
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"{where}: 'bench': {k!r} must be a finite number; got {v!r}")
        try:
            bench = BenchModel(**{k: float(v) for k, v in b.items()})
        except (TypeError, ValueError) as err:
            raise ValueError(f"{where}: 'bench': {err}") from None
    return plan, bench


# --- A plan as a bench can run it: rounded to the bench's resolution ----------------------

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


def _step(name: str, value, unit: str) -> float:
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

    **Returns:** a concrete, checked [`BenchPlan`][hrgjax.calibration.design.BenchPlan].

    **Raises:** `ValueError` naming a step that is not a finite number > 0, or the budget.
    """
    bench = BenchModel() if bench is None else bench
    temperature_step = _step("temperature_step", temperature_step, "°C")
    angle_step = _step("angle_step", angle_step, "° electrical")
    time_step = _step("time_step", time_step, "s")
    rate_step = _step("rate_step", rate_step, "°/s")
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


def _profiles(plan: BenchPlan, idx: np.ndarray, length_s: float | None = None) -> Profile:
    """The segments `idx` as one batch of two-knot profiles (host arrays); with `length_s`,
    each runs on to that time [s] (rate held, temperature continuing its ramp)."""
    v = {k: np.asarray(x, dtype=float)[idx] for k, x in plan._fields().items()}
    n = len(idx)
    if length_s is not None:
        stretch = length_s / v["duration_s"]
        v["temperature_end_c"] = v["temperature_c"] + stretch * (
            v["temperature_end_c"] - v["temperature_c"]
        )
        v["duration_s"] = np.full(n, float(length_s))
    t = np.stack([np.zeros(n), v["duration_s"]], axis=1)
    # One checked profile, its arrays replaced by the batch (as Plan.profiles: no eager vmap
    # of the constructor); the batch's values were checked by BenchPlan.
    return eqx.tree_at(
        lambda p: (p.t, p.rate, p.temperature, p.accel, p.wave_angle0),
        Profile.piecewise([0.0, 1.0], [0.0, 0.0], [0.0, 0.0]),
        (
            device(t),
            device(np.repeat(v["rate_dps"][:, None], 2, axis=1) * DEG_PER_S),
            device(np.stack([v["temperature_c"], v["temperature_end_c"]], axis=1)),
            device(np.zeros((n, 2, 3))),
            device(v["wave_angle_deg"] * DEG),
        ),
    )


SIMULATOR_COMPILE_S = 3.5
"""Seconds one batched simulator of `simulate_plan` takes to compile (averaged model, 2-core
CPU: `benchmarks/plan_first_calibration.py`'s first simulation of a 12-h plan in 7 groups
39.0 s, in 3 groups 17.6 s, ≈ 5 s a group with its first run) — what running two groups of
segment lengths as one saves, against the steps the shorter segments then run on for
(`_simulation_groups`; steps cost `hrgjax._cost.CPU_STEP_S`)."""

RUNS_PER_COMPILE = 4.0
"""How many times a plan is simulated per compile, as `_simulation_groups` weighs run time
against compile time (a study simulates a plan a few times; a Monte Carlo, many)."""

MERGED_STEPS_MAX = 2**13
"""Estimated solver steps beyond which `_simulation_groups` merges no further (the averaged
model's `max_steps` is 2¹⁶)."""


def _chunk(members: int) -> int:
    """Batch size for a group of `members` segments: a power of two up to `CHUNK`, so that
    groups of one length and different sizes share a compiled simulator."""
    from .physical import _ladder

    return min(CHUNK, _ladder(members))


def _simulation_groups(plan, n_out, dts, model) -> dict[tuple[int, float], list[int]]:
    """Segments grouped by output samples and interval: `{(samples, dt): [segment, …]}`.

    A length at least `physical.SHARED_LENGTH_RUNS` segments share is a group of its own; a
    rarer one is padded to the next power of two of samples. Then, per output interval,
    neighbouring groups (sorted by length) are merged where the estimated steps the shorter
    segments run on for cost less than compiling another simulator: a partition of the
    sorted groups by dynamic programming on compile (`SIMULATOR_COMPILE_S`) + run time
    (`_cost.CPU_STEP_S`, steps by `physical.steps_estimate` at the group's largest rate). Padded
    segments are run on (rate held, a ramp's temperature continuing) and cut back. A designed
    12-h plan: 7 groups → 3, its first `simulate_plan` in a fresh process 35–38 → 16 s, a
    later one 0.5–0.6 → 0.8–0.9 s (`benchmarks/plan_first_calibration.py`). The full
    model's steps are far dearer than a compile: its groups stay apart."""
    from .._cost import CPU_STEP_S
    from .physical import SHARED_LENGTH_RUNS, _ladder, _partition, steps_estimate

    exact: dict[tuple[int, float], int] = {}
    for i, k in enumerate(plan.kind):
        exact[(int(n_out[i]), dts[k])] = exact.get((int(n_out[i]), dts[k]), 0) + 1
    units: dict[tuple[int, float], list[int]] = {}
    for i, k in enumerate(plan.kind):
        n, dt = int(n_out[i]), dts[k]
        samples = n + 1 if exact[(n, dt)] >= SHARED_LENGTH_RUNS else _ladder(n + 1)
        units.setdefault((samples, dt), []).append(i)
    if model != "averaged":
        return units
    rate = np.abs(np.asarray(plan.rate_dps, dtype=float)) * DEG_PER_S
    groups: dict[tuple[int, float], list[int]] = {}
    for dt in sorted({dt for _, dt in units}):
        keys = sorted(u for u in units if u[1] == dt)

        def cost(i, j, keys=keys, dt=dt):  # units i..j−1 as one group, run to the longest
            members = [m for u in keys[i:j] for m in units[u]]
            steps = steps_estimate((keys[j - 1][0] - 1) * dt, float(np.max(rate[members])))
            if j - i > 1 and steps > MERGED_STEPS_MAX:
                return math.inf  # far from simulate's max_steps, whatever the estimate's error
            chunk = _chunk(len(members))
            run = -(-len(members) // chunk) * steps * (CPU_STEP_S[0] + chunk * CPU_STEP_S[1])
            return SIMULATOR_COMPILE_S + RUNS_PER_COMPILE * run

        for i, j in _partition(len(keys), cost):
            groups[keys[j - 1]] = [m for u in keys[i:j] for m in units[u]]
    return groups


def simulate_plan(
    gyro: Gyro,
    plan: BenchPlan,
    *,
    key: jax.Array | None = None,
    bias_key: jax.Array | None = None,
    model: str = "averaged",
    dt_out: Mapping[str, float] | None = None,
) -> MeasuredData:
    """Simulate every segment of `plan` on `gyro` as one bench session (one switch-on: the
    run-to-run bias drawn once from `bias_key`); segment i is run i of the data.

    Segments of equal length and output interval share one compiled simulator (vmapped in
    chunks of up to `CHUNK`, as `run_plan`); a length fewer than
    `physical.SHARED_LENGTH_RUNS` segments share is run on to the next power of two of
    samples (the rate held, a ramp's temperature continuing) and cut back, and neighbouring
    lengths are run as one where compiling another simulator would cost more than the
    extra steps, so a plan of many different durations compiles a few simulators.
    `dt_out`: output interval per kind [s] (default `DT_OUT`: static 1 s, rotation 0.5 s,
    ramp 1 s). Each segment gets its own noise key
    (`jax.random.split(key, S)[i]`), so a segment's data do not depend on the other
    segments' keys."""
    require_x64("hrgjax.calibration.simulate_plan")
    if not all(is_concrete(x) for x in plan._fields().values()):
        raise ValueError("simulate_plan needs a concrete plan (host values), not a traced one")
    dts = dict(DT_OUT)
    if dt_out is not None:
        unknown = set(dt_out) - set(KINDS)
        if unknown:
            raise ValueError(f"dt_out keys must be from {KINDS}; got {sorted(unknown)}")
        dts.update({k: float(v) for k, v in dt_out.items()})
        if not all(v > 0 for v in dts.values()):
            raise ValueError(f"dt_out values must be > 0 [s]; got {dts}")
    keys = None
    if gyro.noise is not None:
        if key is None:
            raise ValueError("this gyro has noise: pass key=jax.random.key(…)")
        k_seg, k_bias = jax.random.split(key)
        bias_key = k_bias if bias_key is None else bias_key
        keys = np.asarray(jax.random.key_data(jax.random.split(k_seg, plan.size)))
        impl = jax.random.key_impl(k_seg)

    durations = np.asarray(plan.duration_s, dtype=float)
    n_out = np.zeros(plan.size, dtype=int)
    for i, k in enumerate(plan.kind):
        dt = dts[k]
        n_out[i] = round(durations[i] / dt)
        if n_out[i] < 1 or abs(n_out[i] * dt - durations[i]) > 1e-9 * max(1.0, durations[i]):
            raise ValueError(
                f"segment {i} ({k}): duration_s={durations[i]:g} is not a whole number of "
                f"dt_out={dt:g} s output intervals"
            )
    plausible.check_size("simulate_plan", float(np.sum(n_out + 1)), plan.size)
    groups = _simulation_groups(plan, n_out, dts, model)
    per_segment: list[dict | None] = [None] * plan.size
    with bar(plan.size, f"simulating {plan.size} segments", unit="segment") as progress:
        for (samples, dt), members in groups.items():
            idx = np.asarray(members)
            ts = device(np.arange(samples) * dt)
            chunk = _chunk(len(idx))
            n_pad = -len(idx) % chunk
            padded = np.concatenate([idx, np.repeat(idx[-1:], n_pad)])
            for s in range(0, len(padded), chunk):
                take = padded[s : s + chunk]
                k = None
                if keys is not None:
                    k = jax.random.wrap_key_data(device(keys[take]), impl=impl)
                profiles = _profiles(plan, take, (samples - 1) * dt)
                try:
                    rec, _ = _simulate_chunk(gyro, profiles, k, bias_key, ts, model)
                except RuntimeError as err:
                    raise RuntimeError(_failed_segment(plan, take, str(err))) from None
                cols = rec.to_data().columns
                real = min(chunk, len(idx) - s)
                for j in range(real):
                    rows = np.flatnonzero(cols["run"] == j)[: n_out[take[j]] + 1]
                    seg = {c: v[rows] for c, v in cols.items()}
                    seg["run"] = np.full(rows.size, take[j], dtype=np.int64)
                    per_segment[take[j]] = seg
                progress.update(real)
    names = list(per_segment[0])
    return MeasuredData({c: np.concatenate([s[c] for s in per_segment]) for c in names})


def _failed_segment(plan: BenchPlan, take: np.ndarray, message: str) -> str:
    """A simulator failure inside a chunk of segments `take`, with the segment named (the
    simulator's message says which batch member failed)."""
    member, detail = failed_member(message)
    members = [int(take[member])] if member is not None else sorted(set(map(int, take)))
    i = members[0]
    what = (f"segment {i} ({plan.kind[i]}, {float(plan.temperature_c[i]):g} °C, "
            f"{float(plan.rate_dps[i]):g} °/s, {float(plan.duration_s[i]):g} s)")  # fmt: skip
    if member is None and len(members) > 1:
        what = f"one of segments {members[0]}…{members[-1]} (first: {what})"
    return f"simulate_plan: {what} failed: {detail}"


# --- What a plan teaches: Fisher information of the physical grey box ----------------------

CRITERIA = ("drift+warmup", "drift", "warmup", "ins", "d", "a")
"""Design criteria: `drift+warmup` (the default: the wave-angle error an hour of operation
leaves — the static drift's over the flight's length and the warm-up's own, in quadrature
[°]), `drift` (RMS of the compensated static drift's standard deviation over the operating
grid [°/h]), `warmup` (RMS wave-angle error at the end of the warm-up flights [°]), `ins`
(RMS horizontal position error after the warm-up flights [km]), `d` (log-determinant of the
scaled posterior covariance), `a` (trace of the scaled posterior covariance)."""

CRITERION_UNITS = {"drift+warmup": "°", "drift": "°/h", "warmup": "°", "ins": "km", "d": "",
                   "a": ""}  # fmt: skip
"""The unit each criterion is printed in."""

OPERATING_TEMPERATURES = tuple(float(t) for t in range(-40, 61, 5))
"""Temperatures of the `drift` criterion's operating grid [°C] (the seed's test range)."""
OPERATING_ANGLES = tuple(float(a) for a in range(-90, 91, 5))
"""Wave angles of its operating grid [° electrical] (the seed's 5° test steps)."""


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


def pattern_arw(gyro: Gyro | None = None) -> float:
    """Angle random walk of the measured pattern angle [rad/√s]: k_e × the gyro's ARW
    (default gyro: 0.554 × 0.002 °/√h)."""
    g, k_e = _noisy(gyro)
    return k_e * float(g.noise.angle_random_walk)


def pattern_gauss_markov(gyro: Gyro | None = None) -> tuple[float, float]:
    """The gyro's Gauss–Markov rate (bias instability) on the measured pattern angle:
    (σ [rad/s] = k_e × `noise.bias_instability`, correlation time [s]); default gyro:
    0.554 × 0.003 °/h, 600 s."""
    g, k_e = _noisy(gyro)
    return k_e * float(g.noise.bias_instability), float(g.noise.correlation_time)


def pattern_angle_white(gyro: Gyro | None = None) -> float:
    """White readout noise on the measured pattern angle [rad per sample]: the gyro's
    `noise.angle_white` (default gyro: 1″)."""
    g, _ = _noisy(gyro)
    return float(g.noise.angle_white)


def _noise(arw, gauss_markov, angle_white=None) -> jax.Array:
    """The design's noise vector [N, σ, τ, σ_a]: pattern ARW [rad/√s], Gauss–Markov σ
    [rad/s] and correlation time [s], white angle noise [rad per sample] (defaults: the
    default gyro's)."""
    arw = pattern_arw() if arw is None else arw
    sigma, tau = pattern_gauss_markov() if gauss_markov is None else gauss_markov
    angle_white = pattern_angle_white() if angle_white is None else angle_white
    concrete = all(is_concrete(x) for x in (arw, sigma, tau, angle_white))
    if concrete and not (
        float(arw) > 0 and float(sigma) >= 0 and float(tau) > 0 and float(angle_white) >= 0
    ):
        raise ValueError(
            f"arw must be > 0 [rad/√s], gauss_markov (σ ≥ 0 [rad/s], τ > 0 [s]) and "
            f"angle_white ≥ 0 [rad]; got arw={arw!r}, gauss_markov={(sigma, tau)!r}, "
            f"angle_white={angle_white!r}"
        )
    return jnp.asarray([arw, sigma, tau, angle_white], dtype=float)


def window_density(arw, angle_white, samples, dt, length_s):
    """Effective white rate-noise density [rad/√s] of the physical fit's window slopes: a
    window of n = `samples` samples spaced Δt = `dt` [s] has least-squares slope variance
    6(n² + 1)/(5n(n² − 1)) · N²/Δt (random walk of density N = `arw` [rad/√s]; → 6/5 of a
    mean rate's N²/(nΔt) for long windows) + 12 σ_a²/(Δt² n(n² − 1)) (white angle noise
    σ_a = `angle_white` [rad per sample]), both exact; × the length of segment the window
    stands for (`length_s` [s]: nΔt for consecutive windows, the duration for a static
    segment's one window), the density a continuous observation of the rate with the same
    information would have."""
    n = samples
    m = n * (n**2 - 1.0)
    var = 6.0 * (n**2 + 1.0) / (5.0 * m) * arw**2 / dt + 12.0 * angle_white**2 / (dt**2 * m)
    return jnp.sqrt(var * length_s)


def gauss_markov_discount(duration_s, arw, sigma, tau):
    """Share of a segment's white-noise information left by a Gauss–Markov rate:
    (N²/D) / (N²/D + V(D)), with V(D) = 2σ²τ/D · (1 − (τ/D)(1 − e^(−D/τ))) the variance of
    the GM rate's mean over the segment's duration D [s] (N [rad/√s], σ [rad/s], τ [s]).
    Exact for the mean rate of a static segment; for a rotation it treats the GM rate as an
    extra error of each parameter's segment-average, which is what a slow bias is."""
    x = duration_s / tau
    # D·V/N² = 2σ²τ/N² · (1 − (1 − e^−x)/x), written with expm1 for short segments
    excess = 2.0 * sigma**2 * tau / arw**2 * (1.0 + jnp.expm1(-x) / x)
    return 1.0 / (1.0 + excess)


def measured_rate(values, theta, temperature_c, rate, temperature_rate):
    """Rate of the measured pattern angle [rad/s] of the grey box `values` at true pattern
    angle `theta` [rad], temperature [°C], table rate `rate` [rad/s] and temperature rate
    [°C/s]: dθ̂/dθ · θ̇ + ∂θ̂/∂T · Ṫ (ideal loops, PHYSICS.md §10; the averaged field and
    the readout map of `physical.model_gyro`)."""
    from ..resonator.averaged import averaged_vector_field
    from .physical import _readout_angle, model_gyro

    gyro = model_gyro(values)
    g = gyro.at(temperature_c)
    one = jnp.ones_like(theta)
    slope = jax.jvp(lambda th: _readout_angle(g, th), (theta,), (one,))[1]
    rest = Profile.static(1.0)
    prof = eqx.tree_at(
        lambda p: (p.rate, p.temperature),
        rest,
        (jnp.broadcast_to(rate, (2,)), jnp.broadcast_to(temperature_c, (2,))),
    )
    theta_dot = averaged_vector_field(0.0, theta[None], (gyro, prof))[0]
    d_temp = jax.jvp(lambda temp: _readout_angle(gyro.at(temp), theta), (temperature_c,), (one,))[1]
    return slope * theta_dot + d_temp * temperature_rate


# --- What the calibration fits: the physical grey box, or a surrogate of an empirical model ---


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
        from .physical import _SCALE

        return jnp.asarray(_SCALE)

    def nominal(self) -> jax.Array:
        """The linearisation point: `nominal_values()`."""
        return nominal_values()


class Empirical(eqx.Module):
    r"""A linear surrogate of an *empirical* compensator (an MLP, a Fourier fit): what it
    must learn from the bench, with no physics to carry it between points. The drift
    D(θ, T) [rad/s], the scale factor's departure SF − 1 and the readout's temperature
    sensitivity s_T(θ, T) [rad/°C] are each a sum of the products of
    $1, \cos 2n	heta, \sin 2n	heta$ (n ≤ `harmonics`) and Legendre polynomials of
    (T − 10 °C)/50 °C up to `degree`, and the measured pattern rate is
    $-k_e(\mathrm{SF}\,\Omega + D) + s_T\dot T$ (k_e = `k_e`). Its coefficients have a
    Gaussian prior of magnitude `drift_dph` [°/h], `scale_factor` and `st_rad_per_c`
    [rad/°C] — the size of the default gyro's laws —, which is what keeps points the plan
    does not visit uncertain: a design for this model must cover the temperatures and
    angles the gyro will meet, and ramp at the angles where s_T shows. (`scale()` is 1/100
    of these magnitudes, so that the criteria's default `prior_scale = 100` puts the prior
    at them.) Linear: the linearisation point does not matter (`nominal()` is zero)."""

    harmonics: int = eqx.field(static=True, default=2)
    degree: int = eqx.field(static=True, default=5)
    drift_dph: float = eqx.field(static=True, default=0.5)
    scale_factor: float = eqx.field(static=True, default=0.01)
    st_rad_per_c: float = eqx.field(static=True, default=1e-4)
    k_e: float = eqx.field(static=True, default=K_E_NOMINAL)
    name: str = eqx.field(static=True, default="empirical")

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


def _model(model):
    """`model` (None, a name of `MODELS`, or a GreyBox / Empirical) as a model object."""
    if model is None or model == "physical":
        return GREY_BOX
    if model == "empirical":
        return Empirical()
    if isinstance(model, (GreyBox, Empirical)):
        return model
    raise ValueError(f"model must be one of {MODELS} or an Empirical(...); got {model!r}")


def _values(values, model):
    return model.nominal() if values is None else jnp.asarray(values, dtype=float)


_NODES = 64


def _segment_windows(dt, t0, t1, rate_dps, duration):
    """(samples, sample interval [s], length [s]) of the windows the physical fit reduces a
    segment with (see `window_density`): moving — `PhysicalCompensator.window_s` (10 s);
    a ramp at rest — ≈ `RAMP_WINDOW_S` (300 s) tiling it; static — the whole segment (one
    window of duration/Δt + 1 samples); sampled at `DT_OUT` of its kind."""
    from .physical import RAMP_WINDOW_S, PhysicalCompensator

    moving = rate_dps != 0.0
    ramp = t1 != t0
    ramp_window = duration / jnp.maximum(jnp.round(duration / RAMP_WINDOW_S), 1.0)  # tiling
    length = jnp.where(moving, PhysicalCompensator.window_s,
                       jnp.where(ramp, ramp_window, duration))  # fmt: skip
    samples = jnp.where(moving | ramp, length / dt, duration / dt + 1.0)
    return samples, dt, length


def _segment_weights(noise, dt, t0, t1, rate_dps, duration):
    """Per segment: 1/N_w² × the segment's `gauss_markov_discount` — the factor of its
    quadrature weights [s⁻¹ per (rad/s)²] (N_w the windows' `window_density` with N, σ_a =
    `noise[0]`, `noise[3]`; σ, τ = `noise[1:3]`)."""
    arw, sigma, tau, angle_white = noise[0], noise[1], noise[2], noise[3]
    density = window_density(arw, angle_white, *_segment_windows(dt, t0, t1, rate_dps,
                                                                 duration))  # fmt: skip
    return gauss_markov_discount(duration, density, sigma, tau) / density**2


# The kinds of quadrature point (`_quadrature_points`).
_ALONG, _PERIOD, _REST = 0, 1, 2


SWEEP_PER_NODE_DEG = 5.0
"""Electrical angle a ramp that turns may sweep per Gauss–Legendre node [°]: a turning
ramp is cut into panels of `nodes` nodes, each sweeping at most `nodes` × this (320° at 64
nodes: the information to 1e-14; one 64-node panel along an hour at 5 °/s, −40 → +20 °C,
was 29 % off) — `_ramp_panels`."""


def _ramp_panels(plan, nodes=_NODES):
    """Gauss–Legendre panels per segment of `plan` (a tuple, static), or None where every
    segment takes one — or the plan's rates and durations are unknown on the host (traced by
    `jit`: then one panel each; `jax.grad` alone carries the values).
    A ramp that turns sweeps at most |Ω| D of electrical angle (k_e < 1): it gets
    ⌈|Ω| D / (`nodes` · `SWEEP_PER_NODE_DEG`)⌉ panels. Rotations need none (their rule is
    exact at any length), statics one node."""
    if "ramp" not in plan.kind:
        return None
    rate, duration = concrete_value(plan.rate_dps), concrete_value(plan.duration_s)
    if rate is None or duration is None:
        return None
    swept = np.abs(rate.astype(float)) * duration.astype(float)
    per_panel = nodes * SWEEP_PER_NODE_DEG
    panels = tuple(
        max(1, math.ceil(float(a) / per_panel)) if k == "ramp" else 1
        for k, a in zip(plan.kind, swept, strict=True)
    )
    return None if all(p == 1 for p in panels) else panels


def _quadrature_points(kinds, nodes, panels=None):
    """(segment index, point kind, position s ∈ [0, 1], weight summing to 1 per part) of
    every quadrature point of a plan of `kinds` (`panels`: `_ramp_panels`).

    - static: one point (`_ALONG`) — its path is one point (θ and T constant, Ω = Ṫ = 0), so
      its integrand is constant and one node integrates it exactly, as it does its
      derivatives with respect to the plan (linear in the node's position; a one-point rule
      is exact to degree 1);
    - ramp: `nodes`-point Gauss–Legendre along the whole segment (`_ALONG`) — or, for a ramp
      that turns, along each of its `panels[i]` equal panels (its integrand oscillates with
      the wave angle while T moves: a node per `SWEEP_PER_NODE_DEG` of angle swept);
    - rotation: at constant T the integrand is periodic in time — the rate is π-periodic in
      the electrical wave angle (every law of both models is a function of 2θ), which turns
      by π in T_π = π / (k_e |Ω|) — so the segment is m = ⌊D / T_π⌋ whole periods, each the
      same integral, plus a remainder shorter than one: `nodes` / 2 points of the periodic
      trapezoid rule over one period (`_PERIOD`: exact for harmonics of 2θ below `nodes` / 2)
      and `nodes` / 2 Gauss–Legendre points over the remainder (`_REST`). Exact for any
      length: Gauss–Legendre along a long rotation would need a node per ~25° of electrical
      angle swept (64 nodes were off by 10 % at one hour at 5 °/s)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    half = max(nodes // 2, 1)
    xh, wh = np.polynomial.legendre.leggauss(half)
    seg, code, pos, wt = [], [], [], []

    def add(i, c, s, ws):
        seg.append(np.full(len(s), i))
        code.append(np.full(len(s), c))
        pos.append(np.asarray(s, float))
        wt.append(np.asarray(ws, float))

    for i, k in enumerate(kinds):
        if k == "static":
            add(i, _ALONG, [0.5], [1.0])
        elif k == "rotation":
            add(i, _PERIOD, (np.arange(half) + 0.5) / half, np.full(half, 1.0 / half))
            add(i, _REST, (xh + 1.0) / 2.0, wh / 2.0)
        else:
            p = 1 if panels is None else panels[i]
            for j in range(p):
                add(i, _ALONG, (j + (x + 1.0) / 2.0) / p, w / 2.0 / p)
    return tuple(np.concatenate(a) for a in (seg, code, pos, wt))


def information(plan: BenchPlan, values=None, arw: float | None = None, nodes: int = _NODES,
                gauss_markov: tuple[float, float] | None = None,
                angle_white: float | None = None, model=None):  # fmt: skip
    """Fisher information matrix (P × P, P = 12) of `plan` about the physical grey box's
    parameters ([`physical.PARAMETERS`][hrgjax.calibration.physical.PARAMETERS] order, SI)
    — or, with `model` (`MODELS`), about that model's — linearised at `values` (default
    the model's `nominal()`: `nominal_values()`), for white rate noise of density
    `arw` on the measured pattern angle [rad/√s] (default `pattern_arw()`) and a
    Gauss–Markov rate `gauss_markov` = (σ [rad/s], τ [s]) on it (default
    `pattern_gauss_markov()`; `(0.0, 1.0)` for white noise only) and white readout noise
    `angle_white` on each sample of it [rad] (default `pattern_angle_white()`; 0 for none).
    `nodes`: quadrature points per rotation and ramp (a static segment's path is one point,
    which one node integrates exactly; a rotation is whole periods of its π-periodic
    integrand plus a remainder, exact at any length; a ramp that turns takes panels of
    `nodes` points, each sweeping at most `nodes` × `SWEEP_PER_NODE_DEG` — counted from the
    plan's numbers (as `jax.grad` carries them), so under `jax.jit` with the plan traced a
    ramp takes one panel, accurate while it sweeps less than that — `_quadrature_points`).

    Each segment is observed through its measured pattern rate along its path: θ turning at
    −k_e Ω from its wave angle, T moving linearly from start to end (a ramp's Ṫ reaches the
    readout's temperature sensitivity ∂θ̂/∂T — what a static grid cannot see) — through the
    windows the physical fit reduces it with (a static segment whole, a rotation in 10-s
    windows, a ramp in 300-s windows; samples every `DT_OUT`), whose least-squares slopes
    have the noise density [`window_density`][hrgjax.calibration.design.window_density]:
    the random walk's 6/5 and, for short windows, the readout noise (1″ per 0.5-s sample is
    ≈ 14× the ARW's variance in a 10-s window). The
    Gauss–Markov rate discounts each segment's information by
    [`gauss_markov_discount`][hrgjax.calibration.design.gauss_markov_discount] (a long dwell
    averages white noise down, not a slow bias); the switch-on bias is left out (it is a
    constant of the session: the fitted bias absorbs it). Differentiable with respect to the
    plan's arrays (`jax.grad` of a criterion gives a plan-shaped gradient)."""
    require_x64("hrgjax.calibration.design.information")
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or nodes < 2:
        raise ValueError(f"nodes must be a whole number ≥ 2 (quadrature points); got {nodes!r}")
    model = _model(model)
    values = _values(values, model)
    noise = _noise(arw, gauss_markov, angle_white)
    source, panels = _source(plan, values, noise, model, nodes)
    if not isinstance(source, BenchPlan):
        return source
    return _information(plan, values, noise, nodes, model, panels)


@eqx.filter_jit
def _information(plan, values, noise, nodes, model=GREY_BOX, panels=None):
    """`information`, compiled once per plan length, kinds and model: each segment observed
    through its measured pattern rate, ∫ g gᵀ dt / N_w² with g = ∂(measured rate)/∂values
    along its path (θ turning at −k_e Ω, T linear) — every quadrature point of every
    segment (`_quadrature_points`) in one vmapped Jacobian, so that the program holds one
    copy of the rate's derivative."""
    weight, *path = _path_points(plan, values, noise, nodes, model, panels)
    return _weighted_information(values, model, weight, *path)


def _weighted_information(values, model, weight, thetas, temps, omega, temp_rate):
    """Σ wᵢ gᵢ gᵀᵢ over points (θ, T, Ω, Ṫ), g = ∂(measured rate)/∂values."""
    jac = jax.vmap(lambda th, T, om, tr: jax.jacfwd(model.rate)(values, th, T, om, tr))(
        thetas, temps, omega, temp_rate
    )  # (points, P)
    return jnp.einsum("n,np,nq->pq", weight, jac, jac)


INFORMATION_CHUNK = 1024
"""Quadrature points per call of the information's compiled Jacobian on a concrete plan
(`_information_chunked`): every plan, whatever its length and kinds, meets one program."""


_chunk_information = eqx.filter_jit(_weighted_information)


def _information_chunked(plan, values, noise, model=GREY_BOX, panels=None, nodes=_NODES):
    """`_information` of a concrete plan (values and noise concrete too): the
    points' weights and paths by a small program per plan structure, then their Jacobians
    `INFORMATION_CHUNK` points at a time (padded with weight 0) by one program for every
    plan — a criterion of a new plan then compiles nothing large (`hrgjax design` compares
    three plans of different structures; each cost ≈ 4 s of compiling before)."""
    points = [np.asarray(x) for x in _path_points_compiled(plan, values, noise, nodes, model,
                                                            panels)]  # fmt: skip
    n = points[0].shape[0]
    m = -(-n // INFORMATION_CHUNK) * INFORMATION_CHUNK
    points = [np.pad(x, (0, m - n)) for x in points]  # padding: weight 0, θ = T = Ω = 0
    total = None
    for i in range(0, m, INFORMATION_CHUNK):
        part = _chunk_information(values, model, *(device(x[i : i + INFORMATION_CHUNK])
                                                    for x in points))  # fmt: skip
        total = part if total is None else total + part
    return total


def _source(plan, values, noise, model=GREY_BOX, nodes=_NODES):
    """What the criteria read the plan through: its information matrix, chunked
    (`_information_chunked`), where the plan, values and noise are concrete; else the plan
    itself (traced: `jax.jit`, `jax.grad` with respect to it — `_information` inline)."""
    panels = _ramp_panels(plan, nodes)
    if all(is_concrete(x) for x in (*plan._fields().values(), values, noise)):
        return _information_chunked(plan, values, noise, model, panels, nodes), None
    return plan, panels


def _path_points(plan, values, noise, nodes, model=GREY_BOX, panels=None):
    """Every quadrature point of `plan` (`_quadrature_points`): its weight (quadrature
    weight × span × its segment's 1/N_w² and Gauss–Markov discount) and its path point
    (θ [rad], T [°C], Ω [rad/s], Ṫ [°C/s])."""
    dt = jnp.asarray([DT_OUT[k] for k in plan.kind], dtype=float)  # each kind's sampling
    t0, t1, angle, rate, duration = (plan.temperature_c, plan.temperature_end_c,
                                     plan.wave_angle_deg, plan.rate_dps, plan.duration_s)  # fmt: skip
    seg_w = _segment_weights(noise, dt, t0, t1, rate, duration)
    seg, code, pos, wt = _quadrature_points(plan.kind, nodes, panels)
    at = lambda x: x[seg]  # noqa: E731  (each point's segment's value)
    d, omega = at(duration), at(rate) * DEG_PER_S
    k_e = model.gain(values)
    # a rotation's period of the integrand, T_π = π / (k_e |Ω|), and its whole periods m
    # (computed with Ω = 1 for the other points, which do not use them: no division by 0)
    turning = jnp.asarray(code != _ALONG)
    period = jnp.pi / (k_e * jnp.abs(jnp.where(turning, omega, 1.0)))
    whole = jnp.floor(d / period)
    rest = d - whole * period
    pos, wt = jnp.asarray(pos), jnp.asarray(wt)
    is_period, is_rest = jnp.asarray(code == _PERIOD), jnp.asarray(code == _REST)
    t = jnp.where(is_period, pos * period, jnp.where(is_rest, whole * period + pos * rest, pos * d))
    span = jnp.where(is_period, whole * period, jnp.where(is_rest, rest, d))  # [s]
    temp_rate = (at(t1) - at(t0)) / d
    thetas = at(angle) * DEG - k_e * omega * t
    # a rotation holds its temperature (checked where the plan is built): at the mean of
    # its two, so that the path stays periodic in every direction a gradient takes (the
    # derivative splits equally between temperature_c and temperature_end_c, as a static's)
    temps = jnp.where(turning, 0.5 * (at(t0) + at(t1)), at(t0) + temp_rate * t)
    return wt * span * at(seg_w), thetas, temps, omega, temp_rate


_path_points_compiled = eqx.filter_jit(_path_points)


def _precision_factor(plan, values, noise, prior_scale, model=GREY_BOX, panels=None):
    """Cholesky factor of the posterior precision in units of each parameter's typical
    uncertainty, equilibrated to unit diagonal: `(L, d)` with A = diag(d) L Lᵀ diag(d)
    (forming (F + Λ)⁻¹ explicitly loses ~cond·ε; triangular solves keep the criteria and
    their gradients accurate). `plan`: a plan, or its information matrix (`_source`)."""
    scale = model.scale()
    if isinstance(plan, BenchPlan):
        a = _information(plan, values, noise, _NODES, model, panels)
    else:
        a = plan
    a = a * scale[:, None] * scale[None, :]
    a = a + jnp.eye(a.shape[0]) / prior_scale**2
    d = jnp.sqrt(jnp.diagonal(a))
    return jnp.linalg.cholesky(a / d[:, None] / d[None, :]), d


def _scaled_solve(factor, h):
    """Rows L⁻¹ diag(d)⁻¹ hᵢ for h (N, P) in scaled units: ‖row‖² = hᵢᵀ A⁻¹ hᵢ."""
    import jax.scipy.linalg as jsl

    chol, d = factor
    return jsl.solve_triangular(chol, (h / d[None, :]).T, lower=True).T


def posterior_covariance(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                         gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    """Linearised posterior covariance of the grey box's parameters after `plan` (P × P,
    SI): (F + Λ)⁻¹ with F = [`information`][hrgjax.calibration.design.information] and a
    weak Gaussian prior Λ of σ = `prior_scale` × each parameter's typical uncertainty
    (`physical.PARAMETERS`; `model` as [`information`][hrgjax.calibration.design.information],
    its `scale()`), which keeps directions a plan does not see finite."""
    model = _model(model)
    values = _values(values, model)
    noise = _noise(arw, gauss_markov, angle_white)
    source, panels = _source(plan, values, noise, model)
    factor = _precision_factor(source, values, noise, prior_scale, model, panels)
    scale = model.scale()
    w = _scaled_solve(factor, jnp.eye(scale.shape[0]))  # rows: L⁻¹ D⁻¹ e_i
    return (w @ w.T) * scale[:, None] * scale[None, :]


def drift_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                temperatures_c=OPERATING_TEMPERATURES, angles_deg=OPERATING_ANGLES,
                gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    """Predicted standard deviation of the compensated static drift [°/h of input rate],
    RMS over the operating grid (`temperatures_c` × `angles_deg`): √(mean hᵀ C h) with
    h = ∂(static drift)/∂values and C the posterior covariance (noise arguments and `model`
    as [`information`][hrgjax.calibration.design.information])."""
    model = _model(model)
    values = _values(values, model)
    source, panels = _source(plan, values, noise := _noise(arw, gauss_markov, angle_white), model)
    return _drift_error(source, values, noise, prior_scale, temperatures_c, angles_deg, model,
                        panels)  # fmt: skip


def _drift_error(plan, values, noise, prior_scale, temperatures_c=OPERATING_TEMPERATURES,
                 angles_deg=OPERATING_ANGLES, model=GREY_BOX, panels=None):  # fmt: skip
    factor = _precision_factor(plan, values, noise, prior_scale, model, panels)
    tt, aa = np.meshgrid(np.asarray(temperatures_c, float), np.asarray(angles_deg, float))

    def drift(v, theta, temp):  # input-rate units [rad/s], nominal gain
        return model.rate(v, theta, temp, 0.0, 0.0) / model.gain(values)

    h = jax.vmap(lambda th, T: jax.grad(drift)(values, th, T))(
        jnp.asarray(aa.ravel() * DEG), jnp.asarray(tt.ravel())
    )
    z = _scaled_solve(factor, h * model.scale()[None, :])
    return jnp.sqrt(jnp.mean(jnp.sum(z**2, axis=-1))) / DEG_PER_H


INS_FLIGHTS = FLIGHTS
"""The `ins` criterion's default flights: the three 1-h warm-up flights of
[`study.FLIGHTS`][hrgjax.calibration.study.FLIGHTS] (level at 200 m/s, the IMU warming from
−40 °C to +20 °C with a 20-min time constant; wave-angle pairs 30°/−55°, −20°/70°, 80°/5°),
so that a design does not specialise to one pair of wave angles."""


def _flights(flight) -> tuple[Flight, ...]:
    """`flight` (None, one `Flight` or a sequence of them) as a non-empty tuple of flights."""
    if flight is None:
        return INS_FLIGHTS
    flights = (flight,) if isinstance(flight, Flight) else flight
    try:
        flights = tuple(flights)
    except TypeError:
        flights = (flights,)
    if not flights or not all(isinstance(f, Flight) for f in flights):
        bad = next((type(f).__name__ for f in flights if not isinstance(f, Flight)), "empty")
        raise TypeError(
            f"flight must be an ins_impact.Flight or a non-empty sequence of them; got {bad}"
        )
    return flights


def ins_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
              flight=None, gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    r"""Predicted horizontal position error [km] at the end of `flight` (a
    [`Flight`][hrgjax.calibration.ins_impact.Flight] or a sequence of them: RMS over the
    flights; default `INS_FLIGHTS`, the three 1-h warm-up flights) from the calibration's
    uncertainty after `plan` (of the physical grey box unless `model` says otherwise): each level gyro's compensated rate error along the flight is
    ε(t) = h(t)ᵀ δv, with h = ∂(measured rate)/∂values at its wave angle, the flight's
    temperature T(t) *and its rate* Ṫ(t) (the readout's temperature sensitivity, which only a
    plan with ramps can calibrate); ε drives the classical Schuler channels (PHYSICS.md §12:
    a rate error at time s moves the position at the end T by R(1 − cos ω_s(T − s))), so the
    error is δp = M δv with M = R ∫ (1 − cos ω_s(T − s)) h(s)ᵀ ds per gyro, and its expected
    squared length is tr(M C Mᵀ), C the posterior covariance (heading drops out: the two
    gyros' errors rotate into north and east together). Gauss–Legendre quadrature over the
    flight; noise arguments and `model` as
    [`information`][hrgjax.calibration.design.information].

    What it leaves out, by design (none of it depends on the plan): the flight's own noise
    (ARW, Gauss–Markov rate), the Earth-rate coupling of the full strapdown model
    ([`ins_impact`][hrgjax.calibration.ins_impact.ins_impact] keeps both), and model error
    outside the grey box's family."""
    require_x64("hrgjax.calibration.design.ins_error")
    model = _model(model)
    values = _values(values, model)
    source, panels = _source(plan, values, noise := _noise(arw, gauss_markov, angle_white), model)
    return _ins_error(source, values, noise, float(prior_scale), _flights(flight), model, panels)


def ins_sensitivity(values=None, flight=None, nodes: int = _NODES, model=None) -> jax.Array:
    """M of [`ins_error`][hrgjax.calibration.design.ins_error] (2F × P for F flights, [m]
    per SI unit of each parameter): the end-of-flight position error of each flight's x and
    y gyros' channels per unit error of each grey-box parameter (classical Schuler response,
    input-rate units at nominal gain; `model` as
    [`information`][hrgjax.calibration.design.information])."""
    model = _model(model)
    return _ins_sensitivity(_values(values, model), _flights(flight), int(nodes), model)


@eqx.filter_jit
def _ins_sensitivity(values, flights, nodes=_NODES, model=GREY_BOX, schuler=True):
    """M of `ins_sensitivity` (`schuler`), or of `warmup_sensitivity` (the plain integral of
    the rate error over each flight: the end-of-flight wave-angle error per unit error of
    each parameter [rad per SI unit])."""
    from .ins_impact import EARTH_RADIUS, GRAVITY

    x, w = np.polynomial.legendre.leggauss(nodes)
    omega_s = math.sqrt(GRAVITY / EARTH_RADIUS)

    def rate(v, theta, t, t_rate):  # input-rate units [rad/s], nominal gain
        return model.rate(v, theta, t, 0.0, t_rate) / model.gain(values)

    # Every (flight, gyro, node) point in one vmapped gradient: one copy of the rate's
    # derivative in the compiled program however many flights (unrolled per flight and gyro,
    # six copies compiled in ~5 s; one in ~1 s), the sums per row in numpy-built weights.
    temps, temp_rates, thetas, weights = [], [], [], []
    for flight in flights:
        length = float(flight.duration_s)
        s = (x + 1.0) / 2.0 * length
        wt = w / 2.0 * length
        if schuler:
            wt = wt * EARTH_RADIUS * (1.0 - np.cos(omega_s * (length - s)))
        for angle in (flight.wave_angle_x_deg, flight.wave_angle_y_deg):
            temps.append(flight.temperature(s))
            temp_rates.append(flight.temperature_rate(s))
            thetas.append(np.full(nodes, angle * DEG))
            weights.append(wt)
    h = jax.vmap(jax.grad(rate), in_axes=(None, 0, 0, 0))(
        values,
        jnp.asarray(np.concatenate(thetas), dtype=float),
        jnp.asarray(np.concatenate(temps), dtype=float),
        jnp.asarray(np.concatenate(temp_rates), dtype=float),
    )  # (rows × nodes, P)
    return jnp.einsum(
        "rn,rnp->rp", jnp.asarray(np.stack(weights)), h.reshape(len(weights), nodes, -1)
    )


def warmup_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                 flight=None, gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    r"""Predicted wave-angle (heading) error [°] at the end of `flight` (default
    `INS_FLIGHTS`, the three 1-h warm-up flights; RMS over the flights and their x and y
    gyros) from the calibration's uncertainty after `plan`: the compensated rate error
    ε(t) = h(t)ᵀ δv of [`ins_error`][hrgjax.calibration.design.ins_error] — at the flight's
    temperature T(t) *and* its rate Ṫ(t) — integrated over the flight, m = ∫ h(s)ᵀ ds, with
    expected square mᵀ C m. What a gyro-compass or an attitude reference loses to the
    warm-up, before any Schuler dynamics. Noise arguments and `model` as
    [`information`][hrgjax.calibration.design.information]."""
    require_x64("hrgjax.calibration.design.warmup_error")
    model = _model(model)
    values = _values(values, model)
    source, panels = _source(plan, values, noise := _noise(arw, gauss_markov, angle_white), model)
    return _warmup_error(source, values, noise, float(prior_scale), _flights(flight), model,
                         panels)  # fmt: skip


def warmup_sensitivity(values=None, flight=None, nodes: int = _NODES, model=None) -> jax.Array:
    """m of [`warmup_error`][hrgjax.calibration.design.warmup_error] (2F × P for F flights,
    [rad] per SI unit of each parameter): the end-of-flight wave-angle error of each flight's
    x and y gyros per unit error of each parameter (input-rate units at nominal gain)."""
    model = _model(model)
    return _ins_sensitivity(_values(values, model), _flights(flight), int(nodes), model, False)


def _warmup_error(plan, values, noise, prior_scale, flights, model=GREY_BOX, panels=None):
    factor = _precision_factor(plan, values, noise, prior_scale, model, panels)
    m = _ins_sensitivity(values, flights, _NODES, model, False)
    z = _scaled_solve(factor, m * model.scale()[None, :])
    return jnp.sqrt(jnp.sum(z**2) / (2 * len(flights))) / DEG


def drift_warmup_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                       flight=None, gauss_markov=None, angle_white=None, model=None,
                       terms: bool = False):  # fmt: skip
    r"""The default design criterion [°]: the wave-angle error an hour of operation leaves,
    √((σ_drift · L)² + σ_warm-up²) — [`drift_error`][hrgjax.calibration.design.drift_error]
    (RMS over the operating grid, °/h) acting for the flights' mean length L [h], and
    [`warmup_error`][hrgjax.calibration.design.warmup_error] (°) after `flight` (default
    `INS_FLIGHTS`). The first rewards covering every temperature and angle, the second the
    temperatures and rates of change a warm-up passes through. Arguments as `ins_error`;
    `terms=True` returns `(total [°], drift [°/h], warm-up [°])` from one compiled program."""
    require_x64("hrgjax.calibration.design.drift_warmup_error")
    model = _model(model)
    values = _values(values, model)
    source, panels = _source(plan, values, noise := _noise(arw, gauss_markov, angle_white), model)
    out = _drift_warmup_terms(source, values, noise, float(prior_scale), _flights(flight), model,
                              panels)  # fmt: skip
    return out if terms else out[0]


def _drift_warmup_error(plan, values, noise, prior_scale, flights, model=GREY_BOX,
                        panels=None):  # fmt: skip
    hours = float(np.mean([f.duration_s for f in flights])) / 3600.0
    drift = _drift_error(plan, values, noise, prior_scale, model=model, panels=panels)
    warm = _warmup_error(plan, values, noise, prior_scale, flights, model, panels)
    return jnp.sqrt((drift * hours) ** 2 + warm**2), drift, warm


_drift_warmup_terms = eqx.filter_jit(_drift_warmup_error)


def _ins_error(plan, values, noise, prior_scale, flights, model=GREY_BOX, panels=None):
    factor = _precision_factor(plan, values, noise, prior_scale, model, panels)
    m = _ins_sensitivity(values, flights, _NODES, model)
    z = _scaled_solve(factor, m * model.scale()[None, :])
    return jnp.sqrt(jnp.sum(z**2) / len(flights)) / 1000.0


def criterion(plan: BenchPlan, kind: str = "drift+warmup", values=None, arw=None,
              prior_scale: float = 100.0, gauss_markov=None, angle_white=None,
              flight=None, model=None):  # fmt: skip
    """The design criterion of `plan` (smaller is better; differentiable with respect to the
    plan's arrays): `drift+warmup` (the default) —
    [`drift_warmup_error`][hrgjax.calibration.design.drift_warmup_error] [°];
    `drift` — [`drift_error`][hrgjax.calibration.design.drift_error] [°/h];
    `warmup` — [`warmup_error`][hrgjax.calibration.design.warmup_error] [°];
    `ins` — [`ins_error`][hrgjax.calibration.design.ins_error] after `flight` (one or a
    sequence of flights; default `INS_FLIGHTS`) [km];
    `d` — log det of the posterior covariance in units of each parameter's typical
    uncertainty (D-optimal); `a` — its trace (A-optimal). Noise arguments and `model` (what
    the calibration fits: `MODELS`) as [`information`][hrgjax.calibration.design.information]."""
    if kind not in CRITERIA:
        raise ValueError(f"criterion kind must be one of {CRITERIA}; got {kind!r}")
    model = _model(model)
    values = _values(values, model)
    noise = _noise(arw, gauss_markov, angle_white)
    source, panels = _source(plan, values, noise, model)
    return _criterion(source, kind, values, noise, float(prior_scale), _flights(flight), model,
                      panels)  # fmt: skip


@eqx.filter_jit
def _criterion(plan, kind, values, noise, prior_scale, flights=INS_FLIGHTS, model=GREY_BOX,
               panels=None):  # fmt: skip
    """`criterion`, compiled once per plan length, kind, model (and flights, for `ins`;
    `panels`: `_ramp_panels`, for a plan with ramps that turn)."""
    if kind == "drift+warmup":
        return _drift_warmup_error(plan, values, noise, prior_scale, flights, model, panels)[0]
    if kind == "drift":
        return _drift_error(plan, values, noise, prior_scale, model=model, panels=panels)
    if kind == "warmup":
        return _warmup_error(plan, values, noise, prior_scale, flights, model, panels)
    if kind == "ins":
        return _ins_error(plan, values, noise, prior_scale, flights, model, panels)
    chol, d = factor = _precision_factor(plan, values, noise, prior_scale, model, panels)
    if kind == "d":  # log det A⁻¹
        return -2.0 * (jnp.sum(jnp.log(jnp.diagonal(chol))) + jnp.sum(jnp.log(d)))
    w = _scaled_solve(factor, jnp.eye(d.shape[0]))
    return jnp.sum(w**2)


# --- Searching plans: gradient descent under a bench-time budget ---------------------------

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

    - `plan`: the designed [`BenchPlan`][hrgjax.calibration.design.BenchPlan], within budget
      and rounded to the bench's resolution (`round_plan`): what the bench runs.
    - `bench`: the [`BenchModel`][hrgjax.calibration.design.BenchModel] it was priced with.
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
    c = _criterion(plan, criterion, values, arw, 100.0, flight, model)
    c = jnp.log(c) if criterion != "d" else c
    over = jax.nn.relu(args[-1].bench_time_s(plan) / budget_s - 1.0)
    return c + 100.0 * over**2


@eqx.filter_jit
def _design_step(z, state, values, arw, budget_s, args, criterion, flight, model,
                 learning_rate):  # fmt: skip
    """One Adam step of `design` (compiled once per structure, criterion, model and rate)."""
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
    bench's resolution by [`round_plan`][hrgjax.calibration.design.round_plan] —
    temperatures to `temperature_step` [°C] (0.1 °C), wave angles wrapped to (−90°, 90°]
    electrical and to `angle_step` [° electrical] (0.1°), durations to `time_step` [s]
    (whole seconds: static and rotation durations down, ramps up), table rates to
    `rate_step` [°/s] (0.01 °/s) — within the budget still, so that a bench — and
    [`simulate_plan`][hrgjax.calibration.design.simulate_plan] — can run it as it is; the
    criterion is computed again for the rounded plan (`Design.value`, beside the search's
    `Design.optimised_value`), and the structures are compared as rounded.
    `key` jitters the start angles.

    **Returns:** a [`Design`][hrgjax.calibration.design.Design].
    """
    import optax

    require_x64("hrgjax.calibration.design.design")
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}; got {criterion!r}")
    if not (isinstance(budget_h, (int, float)) and math.isfinite(budget_h) and budget_h > 0):
        raise ValueError(f"budget_h must be a positive number of hours; got {budget_h!r}")
    plausible.check("budget_h (as seconds)", float(budget_h) * 3600.0, "duration_s")
    model = _model(model)
    levels = tuple(int(k) for k in (DEFAULT_LEVELS[model.name] if levels is None else levels))
    if not levels or min(levels) < 1:
        raise ValueError(f"levels must be positive integers; got {levels}")
    if statics < 1 or rotations < 0:
        raise ValueError("statics must be ≥ 1 and rotations ≥ 0 per level")
    if not (isinstance(learning_rate, (int, float)) and 0 < learning_rate < math.inf):
        raise ValueError(f"learning_rate must be a positive number; got {learning_rate!r}")
    if not (isinstance(steps, int) and steps >= 1):
        raise ValueError(f"steps must be a whole number ≥ 1; got {steps!r}")
    bench = BenchModel() if bench is None else bench
    steps_by_key = {"temperature_step": (temperature_step, "°C"),
                    "angle_step": (angle_step, "° electrical"), "time_step": (time_step, "s"),
                    "rate_step": (rate_step, "°/s")}  # fmt: skip
    rounding = {name: _step(name, x, unit) for name, (x, unit) in steps_by_key.items()}
    values = _values(values, model)
    arw_v = _noise(arw, gauss_markov, angle_white)
    flight = _flights(flight)
    budget_s = float(budget_h) * 3600.0
    key = jax.random.key(0) if key is None else key
    per = statics + rotations
    best, search, too_big = None, {}, None

    def _value(plan):  # the criterion of a concrete plan (its information, chunked)
        source, panels = _source(plan, values, arw_v, model)
        return float(_criterion(source, criterion, values, arw_v, 100.0, flight, model, panels))

    with bar(len(levels) * steps, f"designing a {budget_h:g}-h plan", unit="step") as progress:
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
            history = []
            budget = jnp.asarray(budget_s)
            # optax's Adam bias correction mixes int and float: traced under standard
            # promotion whatever the caller's setting
            with jax.numpy_dtype_promotion("standard"):
                state = opt.init(z)
                for _ in range(steps):
                    z, state, val = _design_step(z, state, values, arw_v, budget, args,
                                                 criterion, flight, model, learning_rate)  # fmt: skip
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
