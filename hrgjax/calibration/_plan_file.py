"""Plan files: a bench plan as JSON (DESIGN.md's contract), written and read back.

A plan file is::

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
loading, the bench time is computed again from the segments. A plan its bench cannot run
(a ramp faster than the chamber's `slew_c_per_min`: `BenchModel.check`) is neither
written nor read. A designed plan adds its
`"criterion"` and `"resolution"` blocks.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping

from .._io import read_json
from ._criteria import CRITERIA
from ._plan import SEGMENT_UNITS, BenchModel, BenchPlan, bench_time_h
from ._rounding import RESOLUTION_KEYS

_CRITERION_KEYS = ("kind", "model", "unit", "optimised", "rounded")


def plan_to_json(plan: BenchPlan, bench: BenchModel | None = None, *,
                 criterion: Mapping | None = None, resolution: Mapping | None = None) -> dict:  # fmt: skip
    """The plan file's content: segments, `bench_time_h` (computed from `plan`, as it is)
    and the `bench` model used; with `criterion` (a designed plan's: `kind`, `model`,
    `unit`, `optimised` — the search's plan — and `rounded` — this one; as
    `Design.criterion_json`) and `resolution` (the steps the plan was rounded to, by
    segment key: `temperature_c` [°C], `wave_angle_deg` [° electrical], `duration_s` [s],
    `rate_dps` [°/s]), those blocks too. **Raises:** `ValueError` (`BenchModel.check`'s)
    for a ramp faster than `bench`'s chamber."""
    bench = BenchModel() if bench is None else bench
    bench.check(plan)
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
                raise ValueError(
                    f"{where}: {k!r} must be a step > 0 [{SEGMENT_UNITS[k]}]; got {x!r}"
                )
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


def load_plan(path: str | os.PathLike, *, blocks: bool = False):
    """Read a JSON plan file: `(plan, bench)` — `bench` from its `"bench"` block where it
    has one, else `BenchModel()`. A designed plan's `"criterion"` and `"resolution"` blocks
    (`plan_to_json`) are checked; with `blocks=True` they come back too, as a third item
    (a dict holding those the file has), so `save_plan(plan, new_path, bench, **blocks)`
    writes the same file again. Files without them load as before. Errors name the file,
    the segment and the key. The values stay float64 with JAX's float64 mode off too (NumPy
    leaves: `BenchPlan.from_segments`), so `save_plan` writes the segments back bit for bit
    (`bench_time_h`, computed, in JAX's precision)."""
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
    kept = {}
    if "criterion" in doc:
        kept["criterion"] = _criterion_block(doc["criterion"], f"{where}: 'criterion'")
    if "resolution" in doc:
        kept["resolution"] = _resolution_block(doc["resolution"], f"{where}: 'resolution'")
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
    try:
        bench.check(plan)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from None
    return (plan, bench, kept) if blocks else (plan, bench)
