"""A sweep over flights through the design criteria: compiles per flight, and the sweep's
time against the same number of calls with one flight (issue 45: compile once).

`ins_impact.Flight` holds its heading, wave angles, temperatures and length as static fields.
*Before* (up to commit cba2834) the criteria's programs took the flights as they are, so every
new flight — another heading, pair of angles or warm-up — traced and compiled
`evaluate_criterion` and `_ins_sensitivity` again. *After*: the flights enter as arrays
(`FlightNodes`, their Gauss–Legendre nodes built on the host), so flights of one count share
one program. The figure: `criterion(plan, "ins", flight=f)` and `warmup_sensitivity` over 8
flights of different headings, angles and warm-ups, against 8 calls with the first flight
(after one call of each to compile); the ratio is 1 when nothing compiles again.

The second figure, the same for the prior's scale: `criterion(plan, prior_scale=s)` and the
four public parts (`drift_warmup_error`, `ins_error`, `warmup_error`, `drift_error`) over 4
scales against 4 calls at one scale. *Before* (up to 5619d8d) the scale was a static float
(a new program per value) and the parts ran eagerly, primitive by primitive; *after* it is an
array argument and each part one compiled program (the criterion's).

Usage: `.venv/bin/python benchmarks/design_flight_sweep.py` (runs at any commit with the
public API, for the before figure)
"""

import time

import _common  # noqa: F401  (x64, thread pool)
import jax
import numpy as np
from _common import machine, report

from hrgjax.calibration import design as d
from hrgjax.calibration.ins_impact import Flight

FLIGHTS = [Flight(heading_deg=45.0 * i, wave_angle_x_deg=-80.0 + 20.0 * i,
                  wave_angle_y_deg=70.0 - 15.0 * i, temperature_start_c=-40.0 + 5.0 * i,
                  warmup_s=900.0 + 100.0 * i) for i in range(8)]  # fmt: skip


COMPILES = []
jax.monitoring.register_event_duration_secs_listener(
    lambda event, secs, **kw: (
        COMPILES.append(1) if event.endswith("backend_compile_duration") else None
    )
)


def _sweep(plan, values, flights):
    before, t0 = len(COMPILES), time.perf_counter()
    for f in flights:
        float(d.criterion(plan, "ins", flight=f))
        np.asarray(d.warmup_sensitivity(values, f))
    return time.perf_counter() - t0, len(COMPILES) - before


def main():
    print(machine())
    plan = d.seed_bench_plan(quick=True)
    values = d.nominal_values()
    _sweep(plan, values, FLIGHTS[:1])  # compile with the first flight
    same, n_same = _sweep(plan, values, FLIGHTS[:1] * len(FLIGHTS))
    distinct, n_distinct = _sweep(plan, values, FLIGHTS)
    print(f"compiles: {n_distinct} over {len(FLIGHTS)} distinct flights, {n_same} over "
          f"{len(FLIGHTS)} calls of one")  # fmt: skip
    report(f"{len(FLIGHTS)} calls with one flight (ins criterion + warm-up M)", same, "s")
    report(f"{len(FLIGHTS)} distinct flights", distinct, "s", "distinct / one flight",
           distinct / same)  # fmt: skip
    prior_sweep()


def _scales(plan, scales):
    before, t0 = len(COMPILES), time.perf_counter()
    for s in scales:
        float(d.criterion(plan, prior_scale=s))
        d.drift_warmup_error(plan, prior_scale=s, terms=True)
        float(d.ins_error(plan, prior_scale=s))
        float(d.warmup_error(plan, prior_scale=s))
        float(d.drift_error(plan, prior_scale=s))
    return time.perf_counter() - t0, len(COMPILES) - before


def prior_sweep():
    plan = d.seed_bench_plan(quick=True)
    scales = (10.0, 30.0, 300.0, 1000.0)
    first, n_first = _scales(plan, (100.0,))  # compile (and run) at the default scale
    same, n_same = _scales(plan, (100.0,) * len(scales))
    distinct, n_distinct = _scales(plan, scales)
    print(f"compiles: {n_first} at the first call, {n_distinct} over {len(scales)} distinct "
          f"prior scales, {n_same} over {len(scales)} calls at one")  # fmt: skip
    report("first call of the criterion and its four parts", first, "s")
    report(f"{len(scales)} calls at one prior scale", same, "s")
    report(f"{len(scales)} distinct prior scales", distinct, "s", "distinct / one scale",
           distinct / same)  # fmt: skip


if __name__ == "__main__":
    main()
