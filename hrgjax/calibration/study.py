"""The whole study of seed 000 in one call: bench plans → reduction → compensators → table."""

from __future__ import annotations

import time
from typing import Any

import jax
import numpy as np

from .._checks import check_flag
from ..data import MeasuredData, concat
from ..gyro import Gyro
from ..presets import tvg3_like
from ._compensator import AbstractCompensator
from .evaluate import NoCompensation, accuracy_table, out_of_range
from .experiment import run_plan, seed_plan, test_plan
from .fourier import FourierCompensator
from .ins_impact import FLIGHTS as FLIGHTS
from .ins_impact import ins_impact
from .mlp import MLPCompensator
from .physical import PhysicalCompensator
from .reduce import RateWindows, reduce
from .session import Comparison, compare

METHODS = ("fourier", "fourier_t", "mlp", "mlp_e2e", "physical")
"""Compensators the study fits: seed base algorithm, its temperature-polynomial variant,
the MLP on reduced targets, the MLP trained end to end, and the physical grey box."""


class Study:
    """Results of [`run_study`][hrgjax.calibration.run_study].

    Attributes: `calibration` and `test` ([`hrgjax.MeasuredData`][]), `windows` (the reduced
    calibration data), `compensators` ({label: fitted compensator}, "raw" first), `table`
    (see [`accuracy_table`][hrgjax.calibration.accuracy_table]), `ins` (navigation errors per
    compensator, see [`ins_impact`][hrgjax.calibration.ins_impact.ins_impact]; `None` when
    skipped), `timings` ({step: seconds}), `domains` (where the test grid lies outside each
    compensator's calibrated temperature range, an
    [`out_of_range`][hrgjax.calibration.evaluate.out_of_range] record: the study applies
    `Fourier @+20°C`, calibrated at +20 °C only, at −40 and +60 °C on purpose, so it records
    this instead of warning; the flights' count is in `ins`).
    """

    def __init__(
        self, calibration, test, windows, compensators, table, timings, ins=None, domains=None
    ):
        self.calibration: MeasuredData = calibration
        self.test: MeasuredData = test
        self.windows: RateWindows = windows
        self.compensators: dict[str, AbstractCompensator] = compensators
        self.table: dict[str, Any] = table
        self.timings: dict[str, float] = timings
        self.ins = ins
        self.domains: dict = {} if domains is None else domains

    def compare(self, data: MeasuredData | None = None) -> Comparison:
        """The study's compensators on `data` (default: its test grid, run in the
        calibration's switch-on, so the offset is zero within σ and `before_offset()` is
        `table`), the session's offset apart: [`compare`][hrgjax.calibration.compare] (no
        [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning] on its own
        test grid, whose samples outside the calibrated ranges are in `domains`)."""
        return compare(self.compensators, self.test if data is None else data,
                       warn=data is not None)  # fmt: skip


def bench_session(
    gyro: Gyro, plans, *, key: jax.Array, bias_key: jax.Array, first_run: int = 0
) -> MeasuredData:
    """Run several plans in one switch-on (shared `bias_key`), runs numbered consecutively."""
    parts = []
    for i, plan in enumerate(plans):
        parts.append(
            run_plan(
                gyro, plan, key=jax.random.fold_in(key, i), bias_key=bias_key, first_run=first_run
            )
        )
        first_run += plan.size
    return concat(parts)


def run_study(
    gyro: Gyro | None = None,
    *,
    key: jax.Array,
    quick: bool = False,
    methods=METHODS,
    ins: bool = True,
    progress=None,
) -> Study:
    """Simulate the bench campaign on `gyro`, fit every compensator, tabulate the test errors.

    The calibration plans ([`seed_plan`][hrgjax.calibration.seed_plan]) and the test grid
    ([`test_plan`][hrgjax.calibration.test_plan]) run in **one switch-on** (one run bias, as
    in one bench campaign) with independent noise.

    **Arguments:**

    - `gyro`: the gyro to calibrate (default `presets.tvg3_like()`).
    - `key`: PRNG key (noise, switch-on bias, network weights).
    - `quick`: 3 temperatures and short runs (the demo's `--quick`).
    - `methods`: subset of [`METHODS`][hrgjax.calibration.study.METHODS].
    - `ins`: also fly [`FLIGHTS`][hrgjax.calibration.study.FLIGHTS] (one in quick mode) and
      report the navigation errors with each compensator.
    - `progress`: optional callable `progress(message)`.

    **Returns:** a [`Study`][hrgjax.calibration.Study].
    """
    if isinstance(methods, str) or not hasattr(methods, "__iter__"):
        raise TypeError(f"run_study: methods must be a list of method names from {METHODS}; "
                        f"got {type(methods).__name__} {methods!r}"[:200])  # fmt: skip
    quick, ins = check_flag("run_study: quick", quick), check_flag("run_study: ins", ins)
    if progress is not None and not callable(progress):
        raise TypeError(f"run_study: progress must be None or a callable progress(message); "
                        f"got {type(progress).__name__}")  # fmt: skip
    unknown = set(methods) - set(METHODS)
    if unknown:
        raise ValueError(f"unknown methods {sorted(unknown)}; choose from {METHODS}")
    say = progress or (lambda _msg: None)
    gyro = tvg3_like() if gyro is None else gyro
    k_cal, k_test, k_bias, k_net = jax.random.split(key, 4)
    timings = {}

    t0 = time.perf_counter()
    say("simulating the calibration plans")
    cal = bench_session(gyro, seed_plan(quick), key=k_cal, bias_key=k_bias)
    n_cal = len(np.unique(cal.run))
    say("simulating the test grid")
    test = bench_session(gyro, test_plan(quick), key=k_test, bias_key=k_bias, first_run=n_cal)
    timings["simulate"] = time.perf_counter() - t0

    windows = reduce(cal)
    comps: dict[str, AbstractCompensator] = {"raw": NoCompensation()}
    compensators = {  # method: (label, the compensator to fit, its settings as fields)
        "fourier": ("Fourier @+20°C", lambda: FourierCompensator()),
        "fourier_t": (
            "Fourier+T",
            lambda: FourierCompensator(temperature_degree=2 if quick else 3),
        ),
        "mlp": ("MLP", lambda: MLPCompensator()),
        "mlp_e2e": (
            "MLP end-to-end",
            lambda: MLPCompensator(e2e_steps=100 if quick else 200, mode="end_to_end"),
        ),
        "physical": ("physical", lambda: PhysicalCompensator()),
    }
    for m in methods:
        label, build = compensators[m]
        say(f"fitting {label}")
        t0 = time.perf_counter()
        comps[label] = build().fit(windows, key=k_net, raw=cal)
        timings[f"fit {label}"] = time.perf_counter() - t0
    say("evaluating on the test grid")
    t0 = time.perf_counter()
    table = accuracy_table(comps, test, warn=False)  # the baseline at −40/+60 °C on purpose
    domains = out_of_range(comps, test["temperature_c"])
    timings["evaluate"] = time.perf_counter() - t0
    nav = None
    if ins:
        say("flying the INS-impact flights")
        t0 = time.perf_counter()
        flights = FLIGHTS[:1] if quick else FLIGHTS
        nav = ins_impact(
            comps,
            gyro,
            list(flights),
            key=jax.random.fold_in(k_test, 99),
            bias_key=k_bias,
            warn=False,
        )
        timings["INS impact"] = time.perf_counter() - t0
    return Study(cal, test, windows, comps, table, timings, nav, domains)
