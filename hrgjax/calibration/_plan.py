"""A bench plan as a differentiable pytree of segments, and the bench time it costs.

A [`BenchPlan`][hrgjax.calibration.BenchPlan] is a sequence of segments in bench order,
each of one kind:

- **static** — table at rest at one temperature and wave angle for a duration;
- **rotation** — the table turning at a constant rate, one temperature;
- **ramp** — the chamber moving the temperature linearly from T₀ to T₁ over the duration
  (the table at rest, or turning at `rate_dps`).

Every continuous quantity (temperatures, wave angles, rates, durations) is an array leaf, so
a plan can be differentiated, vmapped over and optimised; the kinds are static. A
[`BenchModel`][hrgjax.calibration.BenchModel] turns a plan into bench time: the measuring
time plus, between segments, the chamber's slew and soak and the table's re-positioning —
smoothly, so that the bench time has a gradient with respect to the plan.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import describe, is_concrete, is_finite_real, numeric_problem
from .._compiled import device, fused
from .experiment import QUICK_DURATION, QUICK_TEMPERATURES, SEED_ANGLES, SEED_TEMPERATURES

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
SEGMENT_UNITS = {
    "temperature_c": "°C",
    "temperature_start_c": "°C",
    "temperature_end_c": "°C",
    "wave_angle_deg": "° electrical",
    "rate_dps": "°/s",
    "duration_s": "s",
}
"""The unit of each segment key of a plan file (named in its error messages)."""


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

    Build one with [`BenchPlan.from_segments`][hrgjax.calibration.BenchPlan.from_segments]
    (the plan file's list of dicts), [`load_plan`][hrgjax.calibration.load_plan] or
    [`seed_bench_plan`][hrgjax.calibration.seed_bench_plan].
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

    @staticmethod
    def bench_or_default(bench: BenchModel | None = None) -> BenchModel:
        """`bench`, or `BenchModel()` where it is None: what a plan's figure and times take
        (`hrgjax.plots` draws a plan without importing `calibration`)."""
        return BenchModel() if bench is None else bench

    @classmethod
    def from_segments(cls, segments: Sequence[Mapping], where: str = "segments") -> BenchPlan:
        """A plan from the plan file's list of segment dicts (keys with units in their
        names, as in the module docstring). Every error names the segment and the key.

        The values stay float64 whatever JAX's mode: device arrays with float64 on, NumPy
        float64 arrays (host values, a pytree's leaves as well) with it off, where a device
        array would be float32 and round a temperature of −40.123456789012344 °C to
        −40.123455 without a word. A plan read with float64 off is written back bit for bit;
        what computes with it in float64 (`design`, `simulate_plan`) asks for the mode."""
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
                    allowed = ", ".join(f"'{a}' [{SEGMENT_UNITS[a]}]" for a in need + optional)
                    raise ValueError(f"{here} ({kind}): unknown key {k!r}; expected {allowed}")
            for k in need:
                if k not in seg:
                    raise ValueError(f"{here} ({kind}): missing {k!r} [{SEGMENT_UNITS[k]}]")
            val = {}
            for k in need + optional:
                if k not in seg:
                    continue
                val[k] = _segment_number(f"{here} ({kind}): {k!r}", seg[k], SEGMENT_UNITS[k])
            t0 = val.get("temperature_c", val.get("temperature_start_c"))
            cols["temperature_c"].append(t0)
            cols["temperature_end_c"].append(val.get("temperature_end_c", t0))
            cols["wave_angle_deg"].append(val["wave_angle_deg"])
            cols["rate_dps"].append(val.get("rate_dps", 0.0))
            cols["duration_s"].append(val["duration_s"])
            kinds.append(kind)
        try:
            return cls(tuple(kinds), **{k: _float64_leaf(v) for k, v in cols.items()})
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


def _segment_number(name: str, x, unit: str) -> float:
    """A segment's value as a float: one finite real number — Python, NumPy (np.int64,
    np.float32 …) or a 0-d array (NumPy, or JAX with a value) — or a one-line `ValueError`
    naming `name` and its `unit`; a traced one too (a plan is built from numbers on the
    host: jit, vmap or grad over a built `BenchPlan`'s leaves instead)."""
    if isinstance(x, jax.core.Tracer):
        raise ValueError(f"{name} must be a finite number [{unit}]; got a traced value (a plan "
                         "is built from numbers: trace the BenchPlan's leaves instead)")  # fmt: skip
    if not is_finite_real(x):
        raise ValueError(f"{name} must be a finite number [{unit}]; got {describe(x)}")
    return float(x)


def float64_setting(x):
    """A setting of a bench or a design model (`BenchModel`, `Empirical`) as a read-only
    NumPy float64 0-d array: a value of the compiled programs it enters, where
    `eqx.filter_jit` keeps a Python float static (each new value compiled `design`'s step
    again: 1 compile, ≈ 9 s). On the host it computes as the float did (NumPy float64, no
    XLA program; `float()` gives the number). A traced value, or one that is not real
    numbers (refused by the owner's checks, as before), is left as it is."""
    if isinstance(x, jax.core.Tracer) or numeric_problem(x, bools=True) is not None:
        return x
    out = np.array(x, dtype=np.float64)
    out.flags.writeable = False
    return out


def _settings(module):
    """`(name, value)` of each field, a `float64_setting` 0-d array as the number it holds."""
    for f in dataclasses.fields(module):
        v = getattr(module, f.name)
        yield f.name, float(v) if isinstance(v, np.ndarray) and v.shape == () else v


def settings_repr(module) -> str:
    """`Name(field=value, …)` with `float64_setting` fields shown as the numbers they hold
    (equinox shows a 0-d array as `f64[](numpy)`)."""
    fields = ", ".join(f"{name}={v!r}" for name, v in _settings(module))
    return f"{type(module).__name__}({fields})"


def settings_hash(module) -> int:
    """A hash of the numbers `float64_setting` holds (a NumPy array is unhashable: a bench or
    a design model as a dict key, in a set or `lru_cache` worked with the floats)."""
    return hash((type(module), *(v for _, v in _settings(module))))


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
    own rate inside their duration; one faster than the chamber takes the chamber's time,
    |T₁ − T₀|_δ/slew, and is charged it (`ramp_overrun_s`, counted as slewing) — `check`
    refuses it, as do `save_plan`, `plan_to_json` and `load_plan` for the bench they write
    or read.

    **Arguments:**

    - `slew_c_per_min`: the chamber's fastest temperature change [°C/min] (1 °C/min).
    - `settle_s`: soak after a temperature change, before measuring [s] (30 min).
    - `reposition_s`: between any two segments: set the wave angle, start or stop the table,
      check the loops [s] (1 min).
    - `start_temperature_c`: where the chamber starts [°C] (20 °C).
    - `settle_scale_c`: temperature change below which the soak shrinks [°C] (0.5 °C).

    Each is kept as a float64 0-d array (`float()` reads it): a value, not a constant, of
    the programs a bench enters, so a `design` for another bench compiles nothing.
    """

    slew_c_per_min: float = eqx.field(default=1.0, converter=float64_setting)
    settle_s: float = eqx.field(default=1800.0, converter=float64_setting)
    reposition_s: float = eqx.field(default=60.0, converter=float64_setting)
    start_temperature_c: float = eqx.field(default=20.0, converter=float64_setting)
    settle_scale_c: float = eqx.field(default=0.5, converter=float64_setting)

    __repr__ = settings_repr
    __hash__ = settings_hash

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
        return _transitions(self, plan.temperature_c, plan.temperature_end_c)

    def ramp_overrun_s(self, plan: BenchPlan) -> jax.Array:
        """Per segment, the time a ramp faster than the chamber takes beyond its duration
        [s], shape (S,): max(0, |T₁ − T₀|_δ/slew − duration) (0 for every other segment and
        every ramp the chamber can run) — a plan does not know its bench, so `bench_time_s`
        charges the chamber's time rather than the plan's (`check` refuses such a plan)."""
        return _overrun(self, plan.temperature_c, plan.temperature_end_c, plan.duration_s,
                        _ramps(plan))  # fmt: skip

    def bench_time_s(self, plan: BenchPlan) -> jax.Array:
        """Bench time of the whole plan [s]: measuring plus every transition, plus the
        chamber's time a ramp too fast for it overruns (`ramp_overrun_s`; differentiable
        with respect to the plan's arrays)."""
        return _bench_time(self, plan.temperature_c, plan.temperature_end_c, plan.duration_s,
                           _ramps(plan), 1.0)  # fmt: skip

    def breakdown_h(self, plan: BenchPlan) -> dict[str, float]:
        """Bench time split into measuring, slewing (a too-fast ramp's `ramp_overrun_s`
        included), settling and re-positioning [h]."""
        parts = {"measuring": plan.measuring_s}
        parts.update({k: jnp.sum(v) for k, v in self.transitions_s(plan).items()})
        parts["slew"] = parts["slew"] + jnp.sum(self.ramp_overrun_s(plan))
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


def _ramps(plan: BenchPlan) -> np.ndarray:
    """(S,) whether each segment is a ramp: a host array, an argument of `_bench_time`
    (from the static `kind` inside it, each order of kinds compiled a program of its own)."""
    return np.array([k == "ramp" for k in plan.kind], dtype=bool)


def _transitions(bench: BenchModel, t0, t1) -> dict[str, jax.Array]:
    """`BenchModel.transitions_s` from the plan's start and end temperatures (S,) [°C]."""
    prev_end = jnp.concatenate([jnp.reshape(jnp.asarray(bench.start_temperature_c, float), (1,)),
                                t1[:-1]])  # fmt: skip
    dt = t0 - prev_end
    delta = 0.05
    slew = dt * jnp.tanh(dt / delta) / bench.slew_c_per_min * 60.0
    settle = bench.settle_s * (1.0 - jnp.exp(-((dt / bench.settle_scale_c) ** 2)))
    repos = jnp.broadcast_to(jnp.asarray(bench.reposition_s, dtype=float), dt.shape)
    return {"slew": slew, "settle": settle, "reposition": repos}


def _overrun(bench: BenchModel, t0, t1, duration, ramp) -> jax.Array:
    """`BenchModel.ramp_overrun_s` from the plan's arrays and its ramp mask (S,)."""
    dtemp = t1 - t0
    slowest = dtemp * jnp.tanh(dtemp / 0.05) / bench.slew_c_per_min * 60.0
    over = slowest - duration  # where (not max): 0 with no slope at the limit
    return jnp.where(ramp & (over > 0.0), over, 0.0)


@fused
def _bench_time(bench: BenchModel, t0, t1, duration, ramp, unit_s) -> jax.Array:
    """`BenchModel.bench_time_s` in units of `unit_s` [s] (1: seconds, 3600: hours), one
    program per plan length (eagerly ≈ 20 operations, each compiled on a new length);
    inlined under the caller's `jit`, `grad` or `vmap`."""
    parts = _transitions(bench, t0, t1)
    total = (jnp.sum(duration) + sum(jnp.sum(p) for p in parts.values())
             + jnp.sum(_overrun(bench, t0, t1, duration, ramp)))  # fmt: skip
    return total / unit_s


def _float64_leaf(values) -> jax.Array | np.ndarray:
    """A plan's per-segment values (host floats) as a leaf that keeps them float64: a device
    array with JAX's float64 mode on, else the NumPy float64 array (float32 would round)."""
    x = np.array(values, dtype=np.float64)
    if jax.config.read("jax_enable_x64"):
        return device(x)
    x.flags.writeable = False  # as a device array's view is: the plan's checks hold
    return x


def bench_time_h(plan: BenchPlan, bench: BenchModel | None = None) -> jax.Array:
    """Bench time of `plan` [h] under `bench` (default `BenchModel()`)."""
    bench = BenchModel() if bench is None else bench
    return _bench_time(bench, plan.temperature_c, plan.temperature_end_c, plan.duration_s,
                       _ramps(plan), 3600.0)  # fmt: skip


def seed_bench_plan(
    quick: bool = False, rate_dps: float = 5.0, duration_s: float | None = None
) -> BenchPlan:
    """The seed's calibration plan as one bench session: at each temperature (−40 → +60 °C),
    3-min static dwells at each wave angle (−90…+90° in 10° steps), then 3-min rotations at
    `rate_dps` [°/s] from each angle. `quick`: −40, +20, +60 °C and 2-min runs (as
    `seed_plan(quick=True)`). `duration_s`: every run's length [s] instead (the same grid
    with shorter or longer dwells)."""
    temps, dur = (QUICK_TEMPERATURES, QUICK_DURATION) if quick else (SEED_TEMPERATURES, 180.0)
    if duration_s is not None:
        if not (is_finite_real(duration_s) and float(duration_s) > 0):
            raise ValueError(
                f"duration_s must be a positive run length [s]; got {describe(duration_s)}"
            )
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
