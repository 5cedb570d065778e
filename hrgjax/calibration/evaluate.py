r"""Accuracy tables of seed 000 (MISSION.md §1), computed on a test grid.

How each figure is computed (state of the art is to say it exactly):

- **Static drift error** at a temperature: for every static test run, the compensated case
  angle after the run divided by its duration is the run's mean residual rate [°/h] (the
  table is at rest, so any rate is error). The figure is the RMS of these over the test
  wave angles at that temperature.
- **Angle error after rotation**: for every rotation test run (5 °/s for 5 min), the
  compensated case angle at the end minus the table angle turned [°]. The figure is the RMS
  over the test wave angles at that temperature.
- **Largest angle error during rotation** (ours, not in the seed): the largest
  |compensated − table| angle over the whole run, RMS over the test wave angles. The end-of-run
  error averages the 180°-periodic errors over whole turns of the pattern; this one does not.

"Raw" applies no compensation: the nominal angular gain k_e,nom only.

These figures keep the test session's constant offset. On a session in another switch-on
than the calibration's it is the change of switch-on bias, the same for every compensator,
and it hides what the compensation leaves: [`compare`][hrgjax.calibration.compare]
(`hrgjax compare`, `hrgjax correct`) states it apart, with its σ, and tabulates the figures
after it (`hrgjax.calibration.session`); `offset_dph` below takes a given offset off.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .._checks import check_1d, check_finite_host, check_numbers, finite_number
from ..data import MeasuredData
from ..pattern_noise import STILL_RATE_DPS
from ._compensator import AbstractCompensator
from ._compensator import (
    NoCompensation as NoCompensation,  # its home until the pass-through needed it
)
from ._grouping import nearest_multiples

SEED_TABLE = {
    "static_drift_dph": {-40.0: (1.28, 0.054), 60.0: (0.51, 0.043)},
    "angle_error_deg": {-40.0: (1.4, 0.06), 60.0: (0.7, 0.07)},
}
"""Seed 000's figures, (Fourier base algorithm, neural network), by temperature [°C]."""


def run_errors(
    comp: AbstractCompensator, data: MeasuredData, *, offset_dph: float = 0.0, warn: bool = True
):
    """Per-run errors of a compensator on test data.

    **Arguments:**

    - `comp`: the fitted compensator.
    - `data`: test data (static and/or moving runs), not yet corrected.
    - `offset_dph`: a constant rate [°/h] taken off the compensated rate before the errors
      are formed (a session's offset, see
      [`session_offset`][hrgjax.calibration.session_offset]); 0 leaves them as measured.
    - `warn`: `correct`'s (False: no
      [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning] for samples
      outside the calibrated temperature range).

    **Returns:** dict of arrays, one entry per run (see
    [`corrected_run_errors`][hrgjax.calibration.corrected_run_errors]).
    """
    check_compensator("run_errors: comp", comp)
    finite_number("run_errors: offset_dph", offset_dph, "°/h")
    return corrected_run_errors(comp.correct(data, warn=warn), offset_dph=offset_dph)


def check_compensator(name: str, comp) -> None:
    """Refuse `comp` unless it has a `correct` method (a fitted compensator), in one line."""
    if not callable(getattr(comp, "correct", None)):
        raise TypeError(f"{name} must be a fitted compensator (e.g. FourierCompensator().fit("
                        f"data)); got {type(comp).__name__}")  # fmt: skip


def check_compensators(who: str, compensators) -> None:
    """Refuse `compensators` unless it is a non-empty {label: fitted compensator}."""
    if not isinstance(compensators, Mapping):
        raise TypeError(f"{who}: compensators must be a dict {{label: fitted compensator}}; got "
                        f"{type(compensators).__name__}")  # fmt: skip
    if not compensators:
        raise ValueError(f"{who}: give at least one compensator")
    for label, comp in compensators.items():
        check_compensator(f"{who}: compensators[{label!r}]", comp)


def corrected_run_errors(corrected: MeasuredData, *, offset_dph: float = 0.0):
    r"""Per-run errors of data already compensated (the output of
    [`AbstractCompensator.correct`][hrgjax.calibration.AbstractCompensator.correct], or a file
    written by `hrgjax correct`).

    With $b$ = `offset_dph` taken off the compensated rate, for a run of duration $T$ whose
    compensated case angle is $\hat\phi(t)$ (0 at its start) and table angle $\phi(t)$:

    - static runs (|table rate| within
      [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS] throughout: a rate table's
      readback jitter is rest; a slower rotation counts as static, its turn subtracted):
      `drift_error_dph` $= (\hat\phi(T) - \Delta\phi)/T - b$ [°/h];
    - moving runs: `angle_error_deg` $= \hat\phi(T) - b\,T - \Delta\phi$ [°] and
      `max_angle_error_deg` $= \max_t |\hat\phi(t) - b\,(t - t_0) - (\phi(t) - \phi(t_0))|$ [°]
      ($b$ converted to °/s).

    **Returns:** dict of arrays, one entry per run: `run`, `temperature_c` (the run's mean
    [°C]), `wave_angle0_deg` (measured wave angle at the run's start [° electrical]),
    `table_angle0_deg` (the table angle column at the run's start [°], as given: the table
    azimuth the run starts at where the bench logs its absolute angle; 0 where the column is
    absent and integrated from the rate per run), `duration_s` [s], `static` (bool), `drift_error_dph` (static runs; NaN otherwise),
    `angle_error_deg` and `max_angle_error_deg` (moving runs; NaN otherwise).

    **Raises:** `ValueError` if `corrected` has no `angle_corrected_deg` column.
    """
    if not isinstance(corrected, MeasuredData):
        raise TypeError(f"corrected_run_errors: corrected must be hrgjax.MeasuredData (what "
                        f"comp.correct(data) returns); got {type(corrected).__name__}")  # fmt: skip
    offset_dph = finite_number("corrected_run_errors: offset_dph", offset_dph, "°/h")
    if "angle_corrected_deg" not in corrected:
        raise ValueError(
            "data have no angle_corrected_deg column; compensate them first (comp.correct(data) "
            "or hrgjax correct)"
        )
    names = ("run", "temperature_c", "wave_angle0_deg", "table_angle0_deg", "duration_s", "static")
    rows = {k: [] for k in names + ("drift_error_dph", "angle_error_deg", "max_angle_error_deg")}
    table = corrected.table_angle_deg
    offset_dps = float(offset_dph) / 3600.0
    for idx in corrected.run_indices():
        t = corrected["time_s"][idx]
        # at rest: |rate| within STILL_RATE_DPS (readback jitter); what the table turned is
        # subtracted all the same
        static = bool(np.all(np.abs(corrected["table_rate_dps"][idx]) <= STILL_RATE_DPS))
        angle = corrected["angle_corrected_deg"][idx] - offset_dps * (t - t[0])
        turned = table[idx][-1] - table[idx][0]
        duration = t[-1] - t[0]
        rows["run"].append(int(corrected.run[idx[0]]))
        rows["temperature_c"].append(float(np.mean(corrected["temperature_c"][idx])))
        rows["wave_angle0_deg"].append(float(corrected["wave_angle_deg"][idx[0]]))
        rows["table_angle0_deg"].append(float(table[idx[0]]))
        rows["duration_s"].append(float(duration))
        rows["static"].append(static)
        rows["drift_error_dph"].append(
            (angle[-1] - turned) / duration * 3600.0 if static else np.nan
        )
        rows["angle_error_deg"].append(np.nan if static else angle[-1] - turned)
        track = np.max(np.abs(angle - (table[idx] - table[idx][0])))
        rows["max_angle_error_deg"].append(np.nan if static else track)
    return {k: np.asarray(v) for k, v in rows.items()}


TEMPERATURE_BIN_C = 1.0
"""Width of the temperature groups of the accuracy tables [°C]: a run's mean temperature
rounded to the nearest multiple (as [`compare`][hrgjax.calibration.compare] groups them), so
measured temperatures that jitter by hundredths of a degree make one row, not one each."""


def _rms_by_temperature(temps, values, at):
    keys = nearest_multiples(temps, TEMPERATURE_BIN_C)
    out = {}
    for temp in nearest_multiples(at, TEMPERATURE_BIN_C):
        m = (keys == temp) & np.isfinite(values)
        out[float(temp)] = float(np.sqrt(np.mean(values[m] ** 2))) if np.any(m) else np.nan
    return out


def accuracy_table(
    compensators: dict[str, AbstractCompensator],
    data: MeasuredData,
    temperatures_c=None,
    *,
    warn: bool = True,
):
    """The seed's accuracy table for several compensators.

    **Arguments:**

    - `compensators`: {label: fitted compensator}.
    - `data`: test data with static and/or rotation runs.
    - `temperatures_c`: temperatures to tabulate [°C] (default: every run's mean
      temperature); runs are grouped by mean temperature rounded to `TEMPERATURE_BIN_C`
      (1 °C), and so are these.
    - `warn`: False: no
      [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning] where a
      compensator is applied outside its calibrated temperature range (as `run_study`, which
      tests the +20 °C baseline at −40 and +60 °C on purpose and records it:
      [`out_of_range`][hrgjax.calibration.evaluate.out_of_range]).

    **Returns:** {label: {"static_drift_dph": {T: RMS}, "angle_error_deg": {T: RMS},
    "max_angle_error_deg": {T: RMS}}} (module docstring for the definitions).
    """
    check_compensators("accuracy_table", compensators)
    if temperatures_c is not None:
        check_numbers("accuracy_table: temperatures_c", temperatures_c, "real numbers [°C]")
        check_1d("accuracy_table: temperatures_c", temperatures_c, "temperatures [°C]")
        check_finite_host("accuracy_table: temperatures_c", temperatures_c)
    errors = {label: run_errors(comp, data, warn=warn) for label, comp in compensators.items()}
    if temperatures_c is None:
        temps = [e["temperature_c"] for e in errors.values()]
        temperatures_c = np.unique(nearest_multiples(np.concatenate(temps), TEMPERATURE_BIN_C))
    table = {}
    for label, e in errors.items():
        table[label] = {
            "static_drift_dph": _rms_by_temperature(
                e["temperature_c"], e["drift_error_dph"], temperatures_c
            ),
            "angle_error_deg": _rms_by_temperature(
                e["temperature_c"], e["angle_error_deg"], temperatures_c
            ),
            "max_angle_error_deg": _rms_by_temperature(
                e["temperature_c"], e["max_angle_error_deg"], temperatures_c
            ),
        }
    return table


def _group(temp) -> float:
    return float(nearest_multiples(temp, TEMPERATURE_BIN_C))


def out_of_range(compensators: dict[str, AbstractCompensator], temperature_c) -> dict:
    """Where samples lie outside each compensator's calibrated temperature range (widened by
    `DOMAIN_MARGIN_C`, as [`correct`][hrgjax.calibration.AbstractCompensator.correct] counts
    them), without compensating anything.

    **Arguments:** `compensators` ({label: fitted compensator}); `temperature_c`: the
    samples' temperatures [°C] (a data set's `temperature_c` column).

    **Returns:** {label: {"calibrated_range_c": [T_min, T_max] or None (unknown: nothing
    checked), "n_samples", "n_out_of_range", "extrapolated" (`correct`'s default for them:
    compensated, or passed through), "temperatures_c": the whole-degree temperatures
    [°C] of the samples outside, sorted}}: the record a study keeps where it applies a
    compensator outside its range on purpose (`correct(warn=False)`)."""
    temp = np.asarray(temperature_c, dtype=float).ravel()
    out = {}
    for label, comp in compensators.items():
        outside = ~comp.in_range(temp)
        span = comp.calibrated_range
        groups = np.unique(nearest_multiples(temp[outside], TEMPERATURE_BIN_C))
        out[label] = {
            "calibrated_range_c": None if span is None else [float(span[0]), float(span[1])],
            "n_samples": int(temp.size),
            "n_out_of_range": int(np.sum(outside)),
            "extrapolated": bool(comp.extrapolates),
            "temperatures_c": [float(g) for g in groups],
        }
    return out


def domain_note(record: dict, what: str) -> str:
    """Lines naming the compensators of an [`out_of_range`][hrgjax.calibration.evaluate.out_of_range]
    record that were applied outside their calibrated range on `what` ("" when none)."""
    lines = []
    for label, r in record.items():
        if r["n_out_of_range"]:
            lo, hi = r["calibrated_range_c"]
            temps = r["temperatures_c"]
            where = (", ".join(f"{t:+g}" for t in temps) if len(temps) <= 6
                     else f"{temps[0]:+g} … {temps[-1]:+g}")  # fmt: skip
            how = "extrapolated" if r["extrapolated"] else "passed through"
            lines.append(f"  {label}: calibrated {lo:+.1f} … {hi:+.1f} °C, {how} on "
                         f"{r['n_out_of_range']} of {r['n_samples']} {what} samples "
                         f"({where} °C)")  # fmt: skip
    return (
        "outside the calibrated temperature range (on purpose):\n" + "\n".join(lines)
        if lines
        else ""
    )


def format_table(table, temperatures_c=(-40.0, 20.0, 60.0), domains: dict | None = None) -> str:
    """Text table of [`accuracy_table`][hrgjax.calibration.accuracy_table] with seed 000's
    figures beside ours; with `domains` (an
    [`out_of_range`][hrgjax.calibration.evaluate.out_of_range] record of the same data), the
    compensators applied outside their calibrated temperature range named below it."""
    labels = list(table)
    lines = []
    for key, title, unit in (
        ("static_drift_dph", "static drift error, RMS over test angles", "°/h"),
        ("angle_error_deg", "angle error at the end of the 5 °/s runs, RMS over test angles", "°"),
        ("max_angle_error_deg", "largest angle error during the 5 °/s runs (ours)", "°"),
    ):
        lines.append(f"{title} [{unit}]")
        head = f"{'T [°C]':>7} " + " ".join(f"{lab:>14}" for lab in labels)
        head += f" {'seed Fourier':>13} {'seed MLP':>9}"
        lines.append(head)
        for temp in temperatures_c:
            row = f"{temp:>7.0f} " + " ".join(
                f"{table[lab][key].get(_group(temp), np.nan):>14.4g}" for lab in labels
            )
            seed = SEED_TABLE.get(key, {}).get(float(temp))
            if seed:
                row += f" {seed[0]:>13.3g} {seed[1]:>9.3g}"
            elif key in SEED_TABLE:
                row += f" {'≈ equal':>13}"
            lines.append(row)
        lines.append("")
    if note := domain_note(domains or {}, "test"):
        lines += [note, ""]
    return "\n".join(lines)
