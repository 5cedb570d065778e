"""Physical plausibility: the one place for the ranges a number must lie in to be physical.

Numbers that parse but cannot be true — a temperature of −273 °C or one in kelvin, a wave
angle of 1e300°, a table turning at 1e6 °/s, a run of 1e9 s — are refused where data, plans
and profiles are built and where a computation starts, with the field, its range, its unit
and, where a column looks like another unit (kelvin, radians), a hint. The ranges are wide
enough for any bench or vehicle an HRG meets; `RANGES` lists them and [`relaxed`][
hrgjax.plausible.relaxed] widens one for a block of code (a thermal-vacuum test at −150 °C):

```python
import hrgjax as hg

with hg.plausible.relaxed(temperature_c=(-200.0, 200.0)):
    data = hg.load("cryo.csv")
```
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator, Mapping

import numpy as np

from ._plausible_ranges import DEFAULTS as _DEFAULTS
from ._plausible_ranges import EXCLUSIVE as EXCLUSIVE
from ._unit_hints import EARTH_HINTS as EARTH_HINTS
from ._unit_hints import GNSS_HINTS as GNSS_HINTS
from ._unit_hints import GYRO_HINTS as GYRO_HINTS
from ._unit_hints import IMU_HINTS as IMU_HINTS
from ._unit_hints import NOISE_HINTS as NOISE_HINTS
from ._unit_hints import TABLE_ANGLE_HINTS as TABLE_ANGLE_HINTS
from ._unit_hints import run_ends, run_turns, wave_ratio_looks

_OVERRIDES: contextvars.ContextVar[dict[str, tuple[float, float, str]] | None] = (
    contextvars.ContextVar("hrgjax_plausible_overrides", default=None)
)
"""The ranges a `relaxed` block set, per thread and per asyncio task: one thread's block
neither widens another thread's ranges nor outlives its own `with`."""


class _Ranges(Mapping):
    """A read-only view of the ranges in force in the calling thread/task: the defaults with
    this context's `relaxed` overrides on top (read as a dict: `RANGES[name]`, `.items()`)."""

    def __getitem__(self, name: str) -> tuple[float, float, str]:
        over = _OVERRIDES.get() or {}
        return over[name] if name in over else _DEFAULTS[name]

    def __iter__(self) -> Iterator[str]:
        return iter(_DEFAULTS)

    def __len__(self) -> int:
        return len(_DEFAULTS)

    def __repr__(self) -> str:
        return repr(dict(self))


RANGES: Mapping[str, tuple[float, float, str]] = _Ranges()
"""(low, high, unit) of each quantity in force in the calling thread (a read-only
mapping: the defaults with this thread's `relaxed` blocks on top): temperatures an HRG is
built and tested for (−100 … +150 °C; −40 … +60 °C is the seed's bench), table rates (±10
turns/s), wave angles (±1e7°: an angle that has turned 27 000 times is a unit error), the
wave's turn over the table's on the rotation runs (|Δwave/Δtable| 0.05 … 2, `wave_table_ratio`:
`check_wave_angle_units`), the length of one run or segment (30 days), the wave angle's step between adjacent samples of a run beyond what the table and
a commanded precession move it (5° plus 100 °/h of drift over the time between them: the
wave drifts at °/h, Earth's rate included, so a step of degrees between close samples is two
runs under one id or a glitch), a vehicle's speed (10 km/s, above low-orbit speed: a speed in
km/h or mm/s read as m/s is refused) and the median specific force |Δv|/Δt over a record of
accelerometer increments (5 g: a navigating vehicle spends most of its time near 1 g, a 60°
banked turn is 2 g; more means accelerations [m/s²] given for increments [m/s]) and a
`Profile`'s specific force along each case axis (±20 g: a fighter's 9 g turn, a launch, a
centrifuge test of the g-sensitivity; beyond it the g-sensitivity term is all a simulation
shows; a data file's `accel_*_g` columns hold it for their middle half, vibration peaks
beyond it are taken), and a `Profile`'s commanded precession (±2·10⁴ °/s electrical: a trapezoid pulse of
force-to-rebalance slews at thousands of °/s; the averaging needs the wave slow against the
carrier's ≈ 10⁶ °/s of phase, and a rate in °/h read as °/s is 3600× too large), and the
errors of an `hrgjax.ins.sensors.ImuModel` in SI (`imu_*`): a gyro bias of 0.75 rad/s
(≈ 43 °/s: a consumer MEMS gyro's zero-rate offset is up to ±20 °/s, and as much again over
temperature, MPU-6050), an accelerometer bias of 3 m/s² (≈ 0.3 g: ADXL345's offset reaches
±250 mg), a scale factor of 0.1 (10⁵ ppm), a misalignment of 0.1 rad, an ARW of
2.5·10⁻³ rad/√s (≈ 0.14 °/s/√Hz, 8.6 °/√h: consumer gyros' 0.003–0.014 °/s/√Hz typed as
rad/√s lie beyond it, the noisiest MEMS gyros' 0.05–0.1 °/s/√Hz inside), a VRW of
0.05 m/s/√s (≈ 5 mg/√Hz), bias instabilities of 0.01 rad/s (≈ 2000 °/h) and 0.1 m/s², rate
and acceleration random walks of 10⁻⁴ rad/s/√s (≈ 1200 °/h/√h) and 0.01 m/s²/√s — a value
beyond, or on a bound (`plausible.EXCLUSIVE`), is one in a datasheet's
unit (°/h or °/s, ppm or %, °/√h or °/s/√Hz, µg or mg), named so with the factors that
convert each; and an Earth model's gravity (9 … 10.5 m/s²), radius (6.0 … 6.6·10⁶ m) and
rotation rate (0 … 10⁻⁴ rad/s) in `hrgjax.ins.constants.Earth` and
`hrgjax.ins.platform.PlatformINS` (`EARTH_HINTS`: 981 is cm/s², 6371 km, 15.04 °/h); and
an [`hrgjax.Noise`][hrgjax.Noise]'s standard deviations (`noise_*`, `NOISE_HINTS`: sized for
a gyro, an HRG's to a MEMS gyro's: an ARW up to 10⁻³ rad/√s, 3.4 °/√h) and a
[`hrgjax.Gyro`][hrgjax.Gyro]'s rate bias (±0.1 rad/s, 5.7 °/s), g-sensitivity and
[`DriftTerms`][hrgjax.DriftTerms] (`gyro_*`, `GYRO_HINTS`), in SI; and a GNSS antenna's
lever arm (±100 m per body axis, `gnss_lever_arm_m`: a vehicle's size; cm or mm beyond):
each bound's reason is a comment in `hrgjax/_plausible_ranges.py`."""

_HINTS = IMU_HINTS | EARTH_HINTS | NOISE_HINTS | GYRO_HINTS | GNSS_HINTS

KELVIN_HINT_C = 200.0
"""A temperature column whose every value is ≥ this [°C] looks like kelvin (250–400 K is
−23 … +127 °C)."""


@contextlib.contextmanager
def relaxed(**ranges: tuple[float, float]) -> Iterator[None]:
    """Widen (or narrow) ranges of `RANGES` inside a `with` block, e.g.
    `relaxed(temperature_c=(-200.0, 200.0))` [in the quantity's own unit]. The change holds
    for the calling thread (and asyncio task) only, until the block ends; blocks nest.
    Naming `specific_force_g` also takes a specific force whose magnitude holds ≈ 9.8 as
    g (a centrifuge run), not as m/s²
    ([`check_specific_force`][hrgjax.plausible.check_specific_force]). Traced values are
    held to the ranges in force when their program is traced: a function of yours under
    `jax.jit` keeps the ranges of its first call (`hg.sweep` traces each call anew) — call it
    first inside the block, or `jax.jit` it again there."""
    new = dict(_OVERRIDES.get() or {})
    for name, bounds in ranges.items():
        if name not in _DEFAULTS:
            raise KeyError(f"plausible.relaxed: unknown quantity {name!r}; known: "
                           f"{sorted(_DEFAULTS)}")  # fmt: skip
        low, high = _bounds(name, bounds)
        if not low < high:
            raise ValueError(f"plausible.relaxed: {name} needs low < high; got {(low, high)}")
        new[name] = (low, high, _DEFAULTS[name][2])
    token = _OVERRIDES.set(new)
    try:
        yield
    finally:
        _OVERRIDES.reset(token)


def _bounds(name: str, bounds) -> tuple[float, float]:
    """`relaxed`'s (low, high) of `name` — any two real numbers: a tuple, a list, a NumPy or
    JAX array — as two floats, or a one-line `TypeError`."""
    from ._checks import describe, numeric_problem

    flags = isinstance(bounds, tuple | list) and any(isinstance(b, bool | np.bool_) for b in bounds)
    if flags or numeric_problem(bounds) is not None or np.shape(bounds) != (2,):
        raise TypeError(f"plausible.relaxed: {name} must be (low, high) "
                        f"[{_DEFAULTS[name][2]}]; got {describe(bounds)}")  # fmt: skip
    return float(bounds[0]), float(bounds[1])


def _hint(name: str, values: np.ndarray) -> str:
    if name == "temperature_c" and values.size and np.min(values) >= KELVIN_HINT_C:
        return (f" — these look like kelvin ({np.min(values):g} … {np.max(values):g}): "
                "subtract 273.15")  # fmt: skip
    return f" — {_HINTS[name]}" if name in _HINTS else ""


def _widens(quantity: str) -> str:
    """The tail of a range's message: the `relaxed` call that widens it."""
    return f" (hrgjax.plausible.relaxed({quantity}=…) widens it)"


def check(name: str, values, quantity: str | None = None) -> None:
    """Refuse `values` (concrete numbers; traced values are not checked) outside the range
    of `quantity` (default: `name`), naming `name`.

    **Raises:** `ValueError`: "<name> = <value> at index i is outside the plausible range
    low … high <unit>" and, for a temperature that looks like kelvin or an IMU error that
    looks like another unit, a hint."""
    quantity = quantity or name
    if quantity not in _DEFAULTS:
        raise KeyError(f"plausible.check: unknown quantity {quantity!r}; known: "
                       f"{sorted(_DEFAULTS)}")  # fmt: skip
    try:
        arr = np.asarray(values, dtype=float)
    except Exception:  # a tracer: checked where it is concrete
        if _is_tracer(values):
            return
        raise TypeError(f"{name} must be real numbers [{RANGES[quantity][2]}]; got "
                        f"{type(values).__name__} {values!r}"[:200]) from None  # fmt: skip
    _check_range(name, arr, quantity, None)


def _is_tracer(x) -> bool:
    import jax

    return any(isinstance(v, jax.core.Tracer) for v in jax.tree_util.tree_leaves(x))


def _check_range(name: str, arr: np.ndarray, quantity: str, hint: str | None) -> None:
    """`check` on a concrete array, with `hint` (None: the quantity's own) in its message."""
    low, high, unit = RANGES[quantity]
    ok = (arr >= low) & (arr <= high)
    if quantity in EXCLUSIVE:  # a nonzero bound is a round datasheet value in another unit
        ok &= ((arr != low) | (low == 0.0)) & ((arr != high) | (high == 0.0))
    bad = np.flatnonzero(~ok & np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        x = arr.ravel()[i]
        where = f" at index {i}" if arr.ndim else ""
        hint = _hint(quantity, arr.ravel()) if hint is None else hint
        edge = ", its bounds excluded" if x in (low, high) else ""
        raise ValueError(
            f"{name} = {x:g}{where} is outside the plausible range {low:g} … {high:g} "
            f"{unit}{edge}{hint}{_widens(quantity)}"
        )


STATIC_G_TOLERANCE = 0.02
"""Relative half-width of the bands around 9.80665 (1 g in m/s²) and 1000 (1 g in mg) in
which the median magnitude |f| of a specific force given in g reads as written in that
other unit ([`check_specific_force`][hrgjax.plausible.check_specific_force]): local gravity
spans 9.780–9.832 m/s² (±0.3 %), a ride with 0.1 g rms of vibration per axis raises the
median by 1 %. A steady 9.6–10.0 g is refused (a centrifuge holding it passes inside
`relaxed(specific_force_g=…)`); 9.0, 9.55 or 10.05 g (9 or 10 g radial and 1 g vertical)
pass."""

STATIC_G_SPREAD = 0.15
"""…and the middle half of |f| (its 25th and 75th percentiles) must lie within this
relative distance of the same 1 g: a ride in m/s² with up to 0.14 g rms per axis does, a
record that rests at 1 g for a quarter of its rows or more and holds ≈ 9.8 g the rest does
not, nor a random vibration whose |f| has a median of 9.8 g (6.4 g rms per axis)."""


def _middle_within(x: np.ndarray, n: int, low: float, high: float, share: float) -> bool:
    """True where no more than `share` of the `n` values `x` lie below `low` and no more than
    `share` above `high` (`share` 1/2: the median within; 1/4: the middle half): counts, not
    a sort — 10⁶ rows cost a few comparisons."""
    return bool(np.count_nonzero(x < low) <= share * n and np.count_nonzero(x > high) <= share * n)


def _specific_force_unit(norm: np.ndarray) -> str:
    """' — …: divide by …' where the magnitude `norm` [the columns' unit] (one per row),
    over the rows that carry a specific force (|f| > 0.5), has its median within
    `STATIC_G_TOLERANCE` of 1 g in m/s² or in mg and its middle half within
    `STATIC_G_SPREAD` of it, else ''."""
    carry = norm > 0.5  # NaN: left out
    n = int(np.count_nonzero(carry))
    if not n:
        return ""
    x = np.where(carry, norm, np.nan)  # NaN compares False: counted on neither side
    for one_g, unit, fix in ((9.80665, "m/s²", "divide by 9.80665"),
                             (1000.0, "mg", "divide by 1000")):  # fmt: skip
        near, spread = STATIC_G_TOLERANCE * one_g, STATIC_G_SPREAD * one_g
        if (_middle_within(x, n, one_g - near, one_g + near, 0.5)
                and _middle_within(x, n, one_g - spread, one_g + spread, 0.25)):  # fmt: skip
            q25, q50, q75 = np.percentile(norm[carry], (25.0, 50.0, 75.0))
            return (f" — the specific force's magnitude has its median at {q50:.5g} (its "
                    f"middle half {q25:.5g} … {q75:.5g}), within {STATIC_G_TOLERANCE:.0%} of "
                    f"{one_g:g}, as 1 g written in {unit} has: {fix} to give g")  # fmt: skip
    return ""


SMOOTH_S = 0.5
"""A data file's specific force is also judged after a mean of each axis over blocks of this
many seconds ([`check_specific_force`][hrgjax.plausible.check_specific_force]'s `rate_hz`):
zero-mean vibration averages out, where it raises the magnitude's median in quadrature (a
ride in m/s² with 0.2 g rms per axis read a median |f| of 1.041 g and passed as g)."""


def _block_means(a: np.ndarray, rate_hz) -> np.ndarray | None:
    """Each axis of `a` (N, k) averaged over blocks of `SMOOTH_S` at `rate_hz` [Hz] (the last
    partial block left out), or None where a block is one row or longer than the record."""
    if rate_hz is None or not np.isfinite(rate_hz) or rate_hz <= 0:
        return None
    rows = int(round(float(rate_hz) * SMOOTH_S))
    blocks = a.shape[0] // max(rows, 1)
    if rows < 2 or blocks < 1:
        return None
    return a[: blocks * rows].reshape(blocks, rows, a.shape[1]).mean(axis=1)


def _check_middle_half(name: str, column: np.ndarray, hint: str) -> None:
    """Refuse a data column [g] whose middle half (25th … 75th percentile) leaves
    `RANGES["specific_force_g"]`: a unit error scales every sample, vibration only peaks."""
    low, high, unit = RANGES["specific_force_g"]
    if not _middle_within(column, column.size, low, high, 0.25):
        q25, q75 = np.percentile(column, (25.0, 75.0))
        raise ValueError(
            f"{name} has its middle half (25th … 75th percentile) at {q25:g} … {q75:g}, "
            f"outside the plausible range {low:g} … {high:g} {unit}{hint} (in a data file the "
            "range holds for the middle half of the samples, not for vibration peaks; "
            "hrgjax.plausible.relaxed(specific_force_g=…) widens it)"
        )


def check_specific_force(
    what: str, names, accel, *, samples: bool = True, rate_hz: float | None = None
) -> None:
    """Refuse a specific force in g (concrete; traced values are not checked) outside
    `RANGES["specific_force_g"]` along any axis, or written in another unit.

    The unit: where the magnitude |f| over the given axes, on the rows carrying one
    (|f| > 0.5), has its median within `STATIC_G_TOLERANCE` (2 %) of 9.80665 and its
    25th and 75th percentiles within `STATIC_G_SPREAD` (15 %) of it, it is a static or
    riding log's 1 g written in m/s² — the g-sensitivity drift would be 9.81× too large
    (≈ 1000: in mg, beyond the range anyway). A run that truly holds 9.6–10.0 g (a
    centrifuge) passes inside `relaxed(specific_force_g=…)`; a high-g run at another level,
    a sweep through 9.8 g, or a hold that rests at 1 g over more than a quarter of the
    rows is not refused. A data file's rows (without `samples`) sampled at `rate_hz` [Hz]
    are judged twice, as they are and after a mean of each axis over `SMOOTH_S` (0.5 s)
    blocks, and refused where either reads as m/s²: vibration (zero mean) raises the
    magnitude's median in quadrature (1.041 g at 0.2 g rms per axis, a ride in m/s² taken as
    g past ~0.15 g rms) and averages out of the means, and the rows as they are keep a
    gravity that turns with a rate table within a block.

    The range: with `samples` (a `Profile`'s knots) every value along every axis; without
    (a data file, `MeasuredData`) each column's middle half, its 25th … 75th percentile —
    the range catches units, and a shaker's 3σ peaks (1 g + 8 g rms) pass beyond it.

    Traced values (inside `jit`, `vmap`, `hg.sweep`) get the range check's twin
    (`traced_violations`), not this one.

    **Arguments:** `what`, the field's name for the unit message; `names`, one name per
    column of `accel`; `accel` (N, k) [g], k = len(names) axes (1 to 3) on N rows (knots);
    without `samples`, finite values (the data loader's columns are); `rate_hz` [Hz], the
    rows' sample rate (data files; None: the rows as they are only).

    **Raises:** `ValueError`: the range message naming the column (with the unit hint where
    the magnitude points at one), or "<what> — the specific force's magnitude has its
    median at 9.913 (its middle half 9.85 … 9.98), within 2% of 9.80665, as 1 g written in
    m/s² has: divide by 9.80665 to give g …"."""
    try:
        a = np.asarray(accel, dtype=float).reshape(-1, len(names))
    except Exception:  # a tracer: checked where it is concrete
        return
    norm = np.sqrt(np.einsum("ij,ij->i", a, a))  # a row with NaN: NaN, left out
    hint = _specific_force_unit(norm)
    means = None if samples or hint else _block_means(a, rate_hz)
    if means is not None:  # vibration averaged out: its quadrature no longer lifts |f|
        hint = _specific_force_unit(np.sqrt(np.einsum("ij,ij->i", means, means)))
        hint = hint.replace("magnitude has", f"magnitude over {SMOOTH_S:g}-s means has")
    for j, name in enumerate(names):
        if samples:
            _check_range(name, a[:, j], "specific_force_g", hint)
        else:
            _check_middle_half(name, a[:, j], hint)
    if hint and "specific_force_g" not in (_OVERRIDES.get() or {}):
        raise ValueError(
            f"{what}{hint} (a run that holds 9.6–10.0 g: hrgjax.plausible.relaxed("
            "specific_force_g=…) takes it)"
        )


def traced_violations(name: str, values, quantity: str | None = None) -> list:
    """The run-time twin of [`check`][hrgjax.plausible.check] for traced `values` (inside
    `jit`, `vmap` or `hg.sweep`): `[(bad, message), …]`, `bad` a traced boolean that is true
    where a finite value lies outside the range of `quantity` (default: `name`), `message`
    `check`'s one line without the value, its index read " at one or more points" after the
    range (a temperature that looks like kelvin: its own entry, with the hint; an
    `EXCLUSIVE` quantity's nonzero bounds are outside, as eagerly: a value on one, none
    beyond, is its own entry, with `check`'s ", its bounds excluded"; the datasheet units
    are named, as `check` names them). The range is read when traced. NaN and inf are not
    flagged here (they are the finite check's)."""
    import jax.numpy as jnp

    quantity = quantity or name
    low, high, unit = RANGES[quantity]
    v = jnp.asarray(values, dtype=float)
    out = jnp.any(jnp.isfinite(v) & ~((v >= low) & (v <= high)))
    where = " at one or more points" if v.ndim else ""
    head = f"{name} is outside the plausible range {low:g} … {high:g} {unit}{where}"
    tail = (f" — {_HINTS[quantity]}" if quantity in _HINTS else "") + _widens(quantity)
    if quantity in EXCLUSIVE:  # a nonzero bound is a round datasheet value in another unit
        edge = jnp.any(((v == low) & (low != 0.0)) | ((v == high) & (high != 0.0)))
        return [(out, head + tail), (edge, f"{head}, its bounds excluded{tail}")]
    if quantity != "temperature_c":
        return [(out, head + tail)]
    kelvin = jnp.min(v) >= KELVIN_HINT_C
    return [(out & ~kelvin, head + tail),
            (out & kelvin, f"{head} — these look like kelvin: subtract 273.15{tail}")]  # fmt: skip


WAVE_TURN_OVER_DRIFT = 3.0
"""A rotation run counts for `check_wave_angle_units` where its table turns ≥ 1 (in the
file's units) or, whatever the table column's unit, where its wave angle turns by at least
this many times the most drift `RANGES["wave_drift_dph"]` allows over the run (and ≥ 1°):
then the table, not drift, moves the wave, and the ratio read is −k_e within a factor
1.5 — far inside `WAVE_TABLE_RATIO` and far from the unit errors' ratios (×57.3, ×1/57.3)."""


WAVE_TABLE_RATIO = _DEFAULTS["wave_table_ratio"][:2]
"""The default of `RANGES["wave_table_ratio"]`, the range of |Δwave / Δtable| over the
rotation runs that `check_wave_angle_units` accepts: an HRG's wave turns k_e (0.554 for a
hemisphere's electrical angle, 1 for a Foucault pendulum) times the table, either way round
(the sign is a convention the calibration fits)."""

MECHANICAL_TOLERANCE = 0.15
"""Relative half-width of the band around k_e/2 in which |Δwave/Δtable| over the rotation
runs reads as a wave angle logged in mechanical degrees (the n = 2 pattern's angle against
the case, half the electrical one; `check_wave_angle_units`), widened by the ratio's own
worst-case error e: the most drift `RANGES["wave_drift_dph"]` allows over each run against
the wave's turn over it (the median run's; 2 % on runs of one turn at 5 °/s, whose ratios
agree within 0.3 % of each other). The 15 % is the gyro's: thin-shell theory gives
K = k_e/2 = 0.277, real hemispherical shells ≈ 0.3 (+8 %). It is named only where
e ≤ 15 %: the band then ends at 0.36, below what a hemisphere within 15 % of k_e = 0.554
reads in electrical degrees under that error (≥ 0.40); a ring (k_e ≈ 0.8) and a Foucault
pendulum (1) lie far above. A gyro whose electrical k_e truly lies near 0.28 (not an n = 2
shell or ring: their Bryan factor K ≈ 0.25–0.4 puts k_e = 2K at 0.5–0.8) passes inside
`relaxed(wave_table_ratio=…)`. A wave angle logged at twice the electrical angle (2 k_e =
1.11) is not named: it lies 11 % from a Foucault pendulum's 1 and 40 % from a ring's 0.8,
the gains the wide `WAVE_TABLE_RATIO` takes."""


def check_wave_angle_units(wave_angle_deg, table_angle_deg, run, moving, k_e: float,
                           integrated: bool = False, time_s=None) -> None:  # fmt: skip
    """Refuse columns whose units cannot be the contract's: over the rotation runs the
    measured wave angle turns by ≈ −k_e times the table (both in degrees). Read as a ratio
    (the median over the runs), a wave angle in radians gives −k_e·π/180, a table in radians
    (a rate in rad/s, or a `table_angle_deg` column in radians) −k_e·180/π, a table rate in
    °/min −k_e/60, time stamps in milliseconds −k_e/1000 (where the table angle is the
    rate's integral over time, `integrated`), a wave angle in mechanical degrees −k_e/2
    (within [`MECHANICAL_TOLERANCE`][hrgjax.plausible.MECHANICAL_TOLERANCE]; naming
    `wave_table_ratio` in `relaxed` takes it); any other |ratio| outside
    `RANGES["wave_table_ratio"]` is refused naming all four columns.

    **Arguments:** per-row arrays (`run` ids, `moving`: the row's run turns the table,
    `time_s`: the time stamps, None: not known) and the nominal angular gain `k_e`. A run
    counts where its table turns by ≥ 1 in the file's units or (with `time_s`) its wave angle
    turns beyond what drift can ([`WAVE_TURN_OVER_DRIFT`][hrgjax.plausible.WAVE_TURN_OVER_DRIFT]):
    a rate in rad/s integrates to < 1 over any run shorter than 57.3°, so the table's turn
    alone cannot pick the runs.

    **Raises:** `ValueError` naming the column the ratio points at, and the ratio found."""
    wave_turn, drift = np.inf, None
    if time_s is not None:
        t = np.asarray(time_s, dtype=float)
        ids = np.unique(np.asarray(run), return_inverse=True)[1].ravel()
        span = np.zeros(ids.max() + 1)
        np.maximum.at(span, ids, t)
        low_t = np.full(span.size, np.inf)
        np.minimum.at(low_t, ids, t)
        drift = RANGES["wave_drift_dph"][1] / 3600.0 * (span - low_t)
        wave_turn = np.maximum(1.0, WAVE_TURN_OVER_DRIFT * drift)
    num, den, use = run_turns(wave_angle_deg, table_angle_deg, run, moving, 1.0, wave_turn)
    if not use.any():
        return
    ratio = float(np.median(num[use] / den[use]))
    with np.errstate(divide="ignore"):  # the ratio's worst-case error from drift
        error = 0.0 if drift is None else float(np.median(drift[use] / np.abs(num[use])))
    said = f"column 'wave_angle_deg' turns {ratio:.4g} × the table over the rotation runs"
    degrees = f"in degrees, ≈ −k_e = {-k_e:.4g}"
    near = [x for x in wave_ratio_looks(k_e, integrated) if abs(ratio - x[0]) < 0.3 * abs(x[0])]
    if near:  # 57.3 (radians) and 60 (minutes, °/min) lie within k_e's tolerance: all named
        like = " or ".join(f"{like} ({expected:.4g})" for expected, like, _ in near)
        fix = " or ".join(dict.fromkeys(f for _, _, f in near))
        raise ValueError(f"{said}, {like} ({degrees}): {fix}")
    half, tol = 0.5 * k_e, MECHANICAL_TOLERANCE + error
    if (error <= MECHANICAL_TOLERANCE and abs(abs(ratio) - half) <= tol * half
            and "wave_table_ratio" not in (_OVERRIDES.get() or {})):  # fmt: skip
        sign = "−" if ratio < 0 else "+"
        raise ValueError(
            f"{said}, as a wave angle in mechanical degrees would ({sign}k_e/2 = "
            f"{np.copysign(half, ratio):.4g}; {degrees}): column 'wave_angle_deg' must be in "
            "electrical degrees, 2× the mechanical angle of the n = 2 pattern: multiply it by 2 "
            f"(a gyro whose k_e truly is {abs(ratio):.3g}: hrgjax.plausible.relaxed("
            "wave_table_ratio=…) takes it)"
        )
    low, high, _ = RANGES["wave_table_ratio"]
    if not low <= abs(ratio) <= high:
        raise ValueError(
            f"{said} ({degrees}; hrgjax takes |ratio| in {low:g} … {high:g}): check the units "
            "of 'wave_angle_deg' [° electrical], 'table_rate_dps' [°/s], 'table_angle_deg' [°] "
            f"and 'time_s' [s]{_widens('wave_table_ratio')}"
        )


def check_table_angle(table_angle_deg, integral_deg, run, moving) -> None:
    """Refuse a `table_angle_deg` column that does not turn as the integral of
    `table_rate_dps` over `time_s` (`integral_deg`, per row) over the rotation runs: their
    median within 10 %, or named as radians (π/180), a rate in rad/s (180/π) or in °/min
    (1/60), time stamps in milliseconds (1/1000) (`TABLE_ANGLE_HINTS`); and then each run
    within 10 % (a run of another file, in another unit), naming the run and its rows. A
    run counts where either turns by ≥ 1 (in the file's units: a table angle or a rate in
    radians turns < 1 over a run shorter than 57.3°, the other one does not).

    **Raises:** `ValueError` naming `table_angle_deg` and the ratio found."""
    num, den, use = run_turns(table_angle_deg, integral_deg, run, moving, 1.0, 1.0)
    if not use.any():
        return
    each = num / np.where(use, den, 1.0)
    ratio = float(np.median(each[use]))
    bad = use & (np.abs(each - 1.0) > 0.1)
    if not bad.any():
        return
    first, last = run_ends(run)
    k = int(np.argmin(np.where(bad, first, np.iinfo(np.int64).max)))  # the first such run
    whole = abs(ratio - 1.0) > 0.1
    found = ratio if whole else float(each[k])
    why = next((h for r, h in TABLE_ANGLE_HINTS.items() if abs(found - r) < 0.02 * r), "")
    if whole:
        raise ValueError(
            f"column 'table_angle_deg' turns {ratio:.4g} × the integral of 'table_rate_dps' "
            f"over 'time_s' over the rotation runs; the two must agree (within 10 %){why}"
        )
    raise ValueError(
        f"column 'table_angle_deg' turns {found:.4g} × the integral of 'table_rate_dps' over "
        f"'time_s' in run {np.asarray(run)[first[k]]} (from row {first[k]} to row {last[k]}), "
        f"where the rotation runs' median is {ratio:.4g}; the two must agree (within 10 %) "
        f"in every run{why}"
    )


def check_wave_angle_jumps(wave_angle_deg, table_angle_deg, time_s, run, k_e: float,
                           precession_dps=0.0) -> None:  # fmt: skip
    """Refuse a wave angle that jumps between two adjacent samples of one run by more than
    `RANGES["wave_step_deg"]` plus `RANGES["wave_drift_dph"]` over the time between them,
    beyond what the table's turn and a commanded precession (`precession_dps`, per row) move
    it (2·k_e × the turn, 2 × the commanded angle): the wave moves at drift rates (°/h) plus
    −k_e Ω and the precession, so a step of degrees between close samples is two runs under
    one id, or a glitch (a gap in time is not: the drift allowance grows with it).

    **Raises:** `ValueError` naming the run, the rows and the jump."""
    wave, table, t = (np.asarray(x, dtype=float) for x in (wave_angle_deg, table_angle_deg,
                                                            time_s))  # fmt: skip
    run = np.asarray(run)
    order = np.lexsort((t, run))
    same = run[order][1:] == run[order][:-1]
    rho = np.broadcast_to(np.asarray(precession_dps, dtype=float), t.shape)[order]
    commanded = 0.5 * np.abs(rho[1:] + rho[:-1]) * np.diff(t[order])
    step = (np.abs(np.diff(wave[order])) - 2.0 * k_e * np.abs(np.diff(table[order]))
            - 2.0 * commanded)  # fmt: skip
    allowed = RANGES["wave_step_deg"][1] + RANGES["wave_drift_dph"][1] / 3600.0 * np.diff(t[order])
    bad = np.flatnonzero(same & (step > allowed))
    if bad.size:
        i, j = int(order[bad[0]]), int(order[bad[0] + 1])
        raise ValueError(
            f"column 'wave_angle_deg' jumps {wave[j] - wave[i]:+.4g}° from row {i} to row {j} "
            f"of run {run[i]} (times {t[i]:g} → {t[j]:g} s), beyond what the table's turn "
            "and a commanded precession move it: two runs under one 'run' id, a glitch to "
            "cut out, or a precession without its 'precession_dps' column (the wave angle "
            "must be unwrapped; hrgjax.plausible.relaxed(wave_step_deg=…) widens it)"
        )


BYTES_PER_SAMPLE = 100
"""Host and device memory one output sample of a simulated run holds, all fields [bytes]
(a finished `Record`: 120; the sweep's byte limit is `MAX_OUTPUT_SAMPLES` × this)."""

PEAK_BYTES_PER_SAMPLE = 400
"""Peak host memory one `simulate` call takes per output sample while it runs [bytes]:
120 (the record alone) up to 2²⁰ outputs, 396 beyond, where the run goes in chunks
(`benchmarks/simulate_memory.py`: 4 h and 8 h at 100 Hz, the slope of the peak RSS). At
`MAX_OUTPUT_SAMPLES` that is ≈ 19 GiB."""

MAX_OUTPUT_SAMPLES = 50_000_000
"""Largest output grid `simulate` builds from `dt_out` (checked before anything is
allocated; pass `ts=` explicitly for more), and the most output samples a plan may hold
([`check_size`][hrgjax.plausible.check_size]). Also readable and settable as
`hrgjax.simulate.MAX_OUTPUT_SAMPLES`, its old place."""


def check_size(what: str, samples: float, runs: int) -> None:
    """Refuse, before anything is allocated, work whose output would exceed
    [`MAX_OUTPUT_SAMPLES`][hrgjax.plausible.MAX_OUTPUT_SAMPLES] samples (set that constant
    higher to allow more), with the estimate.

    **Raises:** `ValueError`: "<what>: N runs hold S output samples (≈ M GiB) …"."""
    if hasattr(samples, "dtype") and np.ndim(samples) == 0:  # a 0-d NumPy or JAX array
        from ._checks import concrete_value

        value = concrete_value(samples)
        samples = value.item() if value is not None and value.dtype.kind in "iuf" else samples
    if (
        isinstance(samples, bool)
        or not isinstance(samples, int | float | np.number)
        or not (samples >= 0)
    ):  # a NaN (or a str) is no count: it passed, and a str failed on ">"
        raise ValueError(f"{what}: the output samples must be a number ≥ 0; got {samples!r}")
    if samples > MAX_OUTPUT_SAMPLES:
        gib = samples * BYTES_PER_SAMPLE / 2**30
        raise ValueError(
            f"{what}: {runs} runs hold {samples:.3g} output samples (≈ {gib:.3g} GiB at "
            f"≈ {BYTES_PER_SAMPLE} bytes each), more than the {MAX_OUTPUT_SAMPLES:.0e} hrgjax "
            "allocates at once; split the plan, lengthen dt_out, or raise "
            "hrgjax.plausible.MAX_OUTPUT_SAMPLES"
        )
