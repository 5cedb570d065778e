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
from collections.abc import Iterator

import numpy as np

RANGES: dict[str, tuple[float, float, str]] = {
    "temperature_c": (-100.0, 150.0, "°C"),
    "table_rate_dps": (-3600.0, 3600.0, "°/s"),
    "wave_angle_deg": (-1e7, 1e7, "° electrical"),
    "duration_s": (0.0, 30 * 86400.0, "s"),
    "speed_mps": (0.0, 10_000.0, "m/s"),
    "median_specific_force_mps2": (0.0, 5.0 * 9.80665, "m/s²"),
}
"""(low, high, unit) of each quantity: temperatures an HRG is built and tested for (−100 …
+150 °C; −40 … +60 °C is the seed's bench), table rates (±10 turns/s), wave angles (±1e7°:
an angle that has turned 27 000 times is a unit error), the length of one run or
segment (30 days), a vehicle's speed (10 km/s, above low-orbit speed: a speed in km/h or
mm/s read as m/s is refused) and the median specific force |Δv|/Δt over a record of
accelerometer increments (5 g: a navigating vehicle spends most of its time near 1 g, a 60°
banked turn is 2 g; more means accelerations [m/s²] given for increments [m/s])."""

KELVIN_HINT_C = 200.0
"""A temperature column whose every value is ≥ this [°C] looks like kelvin (250–400 K is
−23 … +127 °C)."""


@contextlib.contextmanager
def relaxed(**ranges: tuple[float, float]) -> Iterator[None]:
    """Widen (or narrow) ranges of `RANGES` inside a `with` block, e.g.
    `relaxed(temperature_c=(-200.0, 200.0))` [in the quantity's own unit]."""
    old = dict(RANGES)
    try:
        for name, (low, high) in ranges.items():
            if name not in RANGES:
                raise KeyError(f"plausible.relaxed: unknown quantity {name!r}; known: "
                               f"{sorted(RANGES)}")  # fmt: skip
            if not low < high:
                raise ValueError(f"plausible.relaxed: {name} needs low < high; got {(low, high)}")
            RANGES[name] = (float(low), float(high), RANGES[name][2])
        yield
    finally:
        RANGES.clear()
        RANGES.update(old)


def _hint(name: str, values: np.ndarray) -> str:
    if name == "temperature_c" and values.size and np.min(values) >= KELVIN_HINT_C:
        return (f" — these look like kelvin ({np.min(values):g} … {np.max(values):g}): "
                "subtract 273.15")  # fmt: skip
    return ""


def check(name: str, values, quantity: str | None = None) -> None:
    """Refuse `values` (concrete numbers; traced values are not checked) outside the range
    of `quantity` (default: `name`), naming `name`.

    **Raises:** `ValueError`: "<name> = <value> at index i is outside the plausible range
    low … high <unit>" and, for a temperature that looks like kelvin, a hint."""
    quantity = quantity or name
    low, high, unit = RANGES[quantity]
    try:
        arr = np.asarray(values, dtype=float)
    except Exception:  # a tracer: checked where it is concrete
        return
    bad = np.flatnonzero(~((arr >= low) & (arr <= high)) & np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        where = f" at index {i}" if arr.ndim else ""
        raise ValueError(
            f"{name} = {arr.ravel()[i]:g}{where} is outside the plausible range {low:g} … "
            f"{high:g} {unit}{_hint(quantity, arr.ravel())} (hrgjax.plausible.relaxed widens "
            "it)"
        )


def check_wave_angle_units(wave_angle_deg, table_angle_deg, run, moving, k_e: float) -> None:
    """Refuse a wave-angle column that is in radians: over the rotation runs the measured
    wave angle turns by ≈ −k_e times the table (in degrees); in radians by ≈ −k_e·π/180.

    **Arguments:** per-row arrays (`run` ids, `moving`: the row's run turns the table) and
    the nominal angular gain `k_e`. Runs whose table turns less than 10° are not used.

    **Raises:** `ValueError` naming `wave_angle_deg` and the ratio found."""
    wave, table = (np.asarray(x, dtype=float) for x in (wave_angle_deg, table_angle_deg))
    run, moving = np.asarray(run), np.asarray(moving, bool)
    if not moving.any():
        return
    n = run.size
    _, first = np.unique(run, return_index=True)
    _, last = np.unique(run[::-1], return_index=True)
    last = n - 1 - last
    turn = table[last] - table[first]
    use = moving[first] & (np.abs(turn) >= 10.0)
    if not use.any():
        return
    ratio = float(np.median((wave[last] - wave[first])[use] / turn[use]))
    radians = -k_e * np.pi / 180.0
    if abs(ratio - radians) < 0.3 * abs(radians):
        raise ValueError(
            f"column 'wave_angle_deg' turns {ratio:.4g} × the table over the rotation runs, as "
            f"an angle in radians would (−k_e·π/180 = {radians:.4g}; in degrees ≈ −k_e = "
            f"{-k_e:.4g}): give the wave angle in degrees (np.degrees)"
        )


BYTES_PER_SAMPLE = 100
"""Host and device memory one output sample of a simulated run takes, all fields [bytes]."""

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
    if samples > MAX_OUTPUT_SAMPLES:
        gib = samples * BYTES_PER_SAMPLE / 2**30
        raise ValueError(
            f"{what}: {runs} runs hold {samples:.3g} output samples (≈ {gib:.3g} GiB at "
            f"≈ {BYTES_PER_SAMPLE} bytes each), more than the {MAX_OUTPUT_SAMPLES:.0e} hrgjax "
            "allocates at once; split the plan, lengthen dt_out, or raise "
            "hrgjax.plausible.MAX_OUTPUT_SAMPLES"
        )
