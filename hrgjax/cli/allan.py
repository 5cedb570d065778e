"""`hrgjax allan LOG`: the Allan-family deviation of one column of a log, with its
confidence intervals and noise types, and (`--fit`) the composite noise model the record
needs, exported for Kalibr and for simulation."""

from __future__ import annotations

import math
import sys

import numpy as np

from .._time_units import TIME_UNITS, named_time_unit, seconds_look_like, stamps_per_second
from .._timebase import is_uniform, rate_from_stamps, regular_step, stamp_resolution
from ._common import (
    PLOT_EXTENSIONS,
    POSITIVE_FLOAT,
    UsageError,
    figure,
    finish,
    start,
    usage_errors,
)
from .ins import ACCEL_UNIT_NAMES, GYRO_UNIT_NAMES

KINDS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev", "mtotdev", "ttotdev")
UNIT_CHOICES = (*GYRO_UNIT_NAMES, *ACCEL_UNIT_NAMES)


def read_column(path: str, column: str | None, time_column: str | None, rate_hz,
                time_unit: str | None = None):  # fmt: skip
    """`(samples, rate [Hz], column name, file line of each row)` from a CSV log: the column named (or the only
    numeric one that is not the time), its rate from `rate_hz` or the time column (in
    `time_unit`, a key of `TIME_UNITS`; None: seconds, checked by `per_second`; stamps
    that are not uniform: resampled onto `rate_hz` or their median step by the angle).
    Bad input raises `UsageError` naming the file, the column and the row (an integer a
    float64 would round, such as a nanosecond time stamp, too, in the columns used)."""
    from .._data_files import beyond_exact, read_csv_table

    if not path.lower().endswith((".csv", ".txt")):
        raise UsageError(f"{path}: hrgjax allan reads CSV logs (.csv: a header row, one "
                         "sample per row)")  # fmt: skip
    used = [c for c in (column, time_column) if c is not None]
    with usage_errors(missing=f"{path}: no such file"):
        try:
            table, lines = read_csv_table(
                path,
                empty_as_nan=True,
                exact_integers=used,
                integer_offsets=[time_column] if time_unit in ("us", "ns") else (),
            )
        except ValueError as err:  # integer stamps beyond 2**53: ns (or µs) are read exactly
            if time_unit is None and f"column {time_column!r} row" in str(err):
                raise ValueError(f"{err} (time stamps in ns? give --time-unit ns)") from None
            raise
    numeric = [k for k, v in table.items() if np.asarray(v).dtype.kind == "f"]
    if column is None:
        choices = [k for k in numeric if k != time_column and k.lower() not in ("t", "time")]
        if len(choices) != 1:
            raise UsageError(f"{path}: give --column (numeric columns: {', '.join(numeric)})")
        column = choices[0]
        if beyond_exact({column: table[column]}):  # read again to name a rounded integer
            with usage_errors():
                read_csv_table(path, empty_as_nan=True, exact_integers=[column])
    if column not in table:
        raise UsageError(f"{path}: no column {column!r} (columns: {', '.join(table)})")
    if column not in numeric:
        raise UsageError(f"{path}: column {column!r} holds text, not numbers")
    y = np.asarray(table[column], dtype=float)
    bad = np.flatnonzero(np.isinf(y))
    if bad.size:
        raise UsageError(f"{path}: column {column!r} line {int(lines[bad[0]])}: an infinite "
                         "value (missing samples are NaN or an empty field)")  # fmt: skip
    if time_column is not None:
        if time_column not in numeric:
            raise UsageError(f"{path}: no numeric time column {time_column!r} (columns: "
                             f"{', '.join(table)})")  # fmt: skip
        t = np.asarray(table[time_column], dtype=float)
        missing = np.flatnonzero(~np.isfinite(t))
        if missing.size:
            raise UsageError(f"{path}: line {int(lines[missing[0]])}: no time stamp in "
                             f"{time_column!r} (a row of empty fields?); every sample needs "
                             "its time: fill it in or delete the row")  # fmt: skip
        dt = np.diff(t)
        if dt.size == 0:
            raise UsageError(f"{path}: the time column {time_column!r} has one sample; a "
                             "deviation needs a record")  # fmt: skip
        bad = np.flatnonzero(~(dt > 0))
        if bad.size:
            i = int(bad[0])
            what = "a duplicate time stamp" if dt[i] == 0 else "time goes backwards"
            raise UsageError(f"{path}: line {int(lines[i + 1])}: {what} in {time_column!r} "
                             f"({float(t[i + 1])!r} after {float(t[i])!r} on line {int(lines[i])}); the "
                             "time column must increase")  # fmt: skip
        t = t / per_second(path, time_column, t, time_unit, rate_hz)
        dt = np.diff(t)
        step = regular_step(t)  # the mean regular step: a median is quantised at an epoch
        found = rate_from_stamps(t, step)  # to the digits the stamps resolve
        if not is_uniform(t, step):  # onto a uniform grid by the angle (hrgjax.allan.resample)
            from ..allan import to_uniform

            with usage_errors(prefix=path):
                u = to_uniform(t, y, rate_hz=rate_hz or found)
            gaps = f", {len(u.gaps)} interval(s) over 2.5 steps left as gaps" if u.gaps else ""
            if u.interpolated == 0 and u.breaks:  # a uniform clock that stalled: no sample read
                print(f"hrgjax allan: {path}: time stamps uniform at {u.rate_hz:g} Hz but for "
                      f"{len(u.breaks)} stall(s) of a fraction of a step (the first at "
                      f"{u.breaks[0][0]:.6g} s): the grid restarts after each, its samples "
                      f"are NaN, every other sample is the log's own{gaps} "
                      "(docs/allan.md)", file=sys.stderr, flush=True)  # fmt: skip
            else:
                print(f"hrgjax allan: {path}: time stamps not uniform (steps {dt.min():.6g} "
                      f"to {dt.max():.6g} s): resampled at {u.rate_hz:g} Hz by the integrated "
                      f"angle{gaps}; white noise reads low at the shortest τ "
                      "(docs/allan.md)", file=sys.stderr, flush=True)  # fmt: skip
            stamp = np.searchsorted(t, u.t0 + np.arange(1, u.y.size + 1) * (1.0 / u.rate_hz))
            return u.y, u.rate_hz, column, np.asarray(lines)[np.minimum(stamp, t.size - 1)]
        if rate_hz is not None and abs(found / rate_hz - 1) > max(1e-3, stamp_resolution(t)):
            hint = ""  # stamps in ms, µs or ns read as seconds: 1e3, 1e6 or 1e9 times slow
            for unit in ("ms", "us", "ns") if time_unit is None else ():
                if abs(found * TIME_UNITS[unit] / rate_hz - 1) <= 1e-3:
                    hint = f" (stamps in {unit}? give --time-unit {unit})"
            raise UsageError(f"{path}: --rate-hz {rate_hz:g} contradicts the time column's "
                             f"{found:g} Hz{hint}")  # fmt: skip
        rate_hz = found
    if rate_hz is None:
        raise UsageError(f"{path}: give --rate-hz or --time-column (the sample rate)")
    return y, float(rate_hz), column, lines


def per_second(path: str, name: str, t, unit: str | None, rate_hz=None) -> float:
    """How many units of the increasing stamps `t` of time column `name` make a second [1/s]:
    of `--time-unit` `unit`, or seconds (1). A name ending in another unit (`t_ms`) than the one
    given — or than seconds, when none is — is refused; a name in seconds (`elapsed_secs`) is
    seconds. Without either, stamps that read as seconds would be 3000 years and more (≥ 1e11:
    an epoch in ms, µs or ns) are refused; stamps that look like ms (`seconds_look_like`:
    every step above 1 and a round number of ms — 10, 2.5, 1.25 — or whole-number stamps
    stepping by 1, a 1-kHz log in whole ms) are read as seconds (an HRG drift log at 0.1 or
    1 Hz stamped in whole seconds) with one note line on stderr naming `--time-unit ms`,
    unless `rate_hz` is given (it checks the rate). Each refusal is one line naming the way out
    (`--time-unit`)."""
    with usage_errors(prefix=path):
        scale = stamps_per_second(name, t, unit, lambda u: f"--time-unit {u}")
    if unit is not None or named_time_unit(name) is not None:
        return scale
    guess = None if rate_hz is not None else seconds_look_like(t)
    if guess is not None:
        step = float(np.median(np.diff(t)))
        print(f"hrgjax allan: {path}: time column {name!r} steps by {step:g}: read as "
              f"seconds, {1.0 / step:.4g} Hz; stamps in {guess}? give --time-unit {guess}",
              file=sys.stderr, flush=True)  # fmt: skip
    return 1.0


def cmd_allan(args) -> int:
    """`hrgjax allan LOG`: deviation, intervals and noise types of one column; `--fit`: the
    composite noise model (hrgjax.allan.identify_noise)."""
    start(args, [args.log], json=(".json",), plot=PLOT_EXTENSIONS, csv=(".csv",),
          kalibr=(".yaml", ".yml"))  # fmt: skip
    from .. import allan

    unit = {"deg/s": "°/s", "deg/h": "°/h", "m/s^2": "m/s²"}.get(args.unit, args.unit) or ""
    _refuse_unread(args)
    sensor = None
    if args.kalibr:  # the unit is checked before any work
        from ..allan.composite import TO_SI

        sensor = args.sensor or _sensor(unit)
        if unit not in TO_SI or TO_SI[unit][0] != sensor:
            raise UsageError(f"--kalibr needs --unit of a {sensor}'s rate (one of "
                             f"{', '.join(UNIT_CHOICES)}); got {unit or 'none'}")  # fmt: skip
    if args.time_unit is not None and args.time_column is None:
        raise UsageError("--time-unit is the unit of --time-column: it does not apply without it")
    y, rate_hz, column, lines = read_column(args.log, args.column, args.time_column, args.rate_hz,
                                            args.time_unit)  # fmt: skip
    gaps = np.flatnonzero(np.isnan(y))
    if gaps.size and (args.fit or args.kalibr):
        raise UsageError(
            f"{args.log}: column {column!r} has {gaps.size} missing value(s) (NaN), the first at "
            f"line {int(lines[gaps[0]])}; the noise model needs a gap-free record: split the "
            "record at its gaps (the deviation alone takes gaps: drop --fit and --kalibr)"
        )
    with usage_errors(prefix=args.log):
        result = allan.deviation(
            y, rate_hz, kind=args.kind, taus=args.taus, unit=unit, noise_rule=args.noise_rule
        )
    span = y.size / rate_hz
    missing = f", {gaps.size} missing (windows across them left out)" if gaps.size else ""
    print(f"hrgjax allan: {args.log}, column {column!r}: {y.size} samples at {rate_hz:g} Hz "
          f"({span:.6g} s){missing}")  # fmt: skip
    print(result)
    model = None
    if args.fit or args.kalibr:
        if args.kind not in ("adev", "oadev"):
            left_out = args.plot and args.kind not in allan.curve_result.ALLAN_VARIANCE_KINDS
            note = f"; --plot leaves it out: it gives the Allan deviation, not {args.kind}"
            print(f"  (the noise model is fitted to the overlapping Allan variance"
                  f"{note if left_out else ''})")  # fmt: skip
        with usage_errors(prefix=args.log):
            gauss_markov = 2 if args.gauss_markov is None else args.gauss_markov
            # the octaves the model fits are the printed deviation's: not computed twice
            same = (args.kind, args.noise_rule) == ("oadev", "hrgjax") and isinstance(
                args.taus, str) and args.taus in ("octave", "all")  # fmt: skip
            model = allan.identify_noise(y, rate_hz, unit=unit, gauss_markov=gauss_markov,
                                         terms=_terms(bool(args.drift)),
                                         sampling=args.sampling or "interval",
                                         oadev=result if same else None)  # fmt: skip
        print(model)
    kalibr = None
    if args.kalibr:
        with usage_errors(prefix="--kalibr"):
            model.to_kalibr(None, sensor=sensor)  # a term with no value nor bound: said here

        def kalibr(path, model=model, sensor=sensor):
            from .._io import atomic_path

            with atomic_path(path) as tmp:
                model.to_kalibr(tmp, sensor=sensor)
            return path

    out = {"deviation": result.to_dict(), "noise_model": None if model is None else
           model.to_dict(), "log": args.log, "column": column}  # fmt: skip
    title = f"{args.log}: {column}"

    def plot(path):
        return figure("allan_figure")(result, path, fit=model, title=title)  # the unit: result's

    def csv(path):
        from .._io import atomic_path

        with atomic_path(path) as tmp:
            result.to_csv(tmp)
        return path

    return finish((args.json, out), (args.csv, csv), (args.kalibr, kalibr), (args.plot, plot))


OPTIONS_READ_BY = {
    "--gauss-markov": ("gauss_markov", "--fit and --kalibr", "them"),
    "--drift": ("drift", "--fit and --kalibr", "them"),
    "--sampling": ("sampling", "--fit and --kalibr", "them"),
    "--sensor": ("sensor", "--kalibr", "it"),
}
"""The noise model's options (default None: given or not) and the options that read them:
given without those they are refused, not ignored."""


def _refuse_unread(args) -> None:
    model = bool(args.fit or args.kalibr)
    for option, (dest, takes, pronoun) in OPTIONS_READ_BY.items():
        read = bool(args.kalibr) if dest == "sensor" else model
        if getattr(args, dest) is not None and not read:
            raise UsageError(f"{option} is for {takes}: it does not apply without {pronoun}")


def _terms(drift: bool):
    base = ("quantization", "angle_random_walk", "rate_random_walk")
    return (*base, "rate_ramp") if drift else base


def _sensor(unit: str) -> str:
    from ..allan.composite import TO_SI

    if unit not in TO_SI:
        raise UsageError(f"--kalibr needs --unit, one of {', '.join(UNIT_CHOICES)}; got "
                         f"{unit or 'none'}")  # fmt: skip
    return TO_SI[unit][0]


def _taus(text: str):
    if text in ("octave", "decade", "all"):
        return text
    import argparse

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected octave, decade, all or τ values in s (1,10,100); got {text!r}"
        ) from None
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"τ values must be finite and > 0 s; got {text!r}")
    return values


def _allan_parser(sub):
    """`hrgjax allan`'s parser."""
    p = sub.add_parser("allan", help="Allan deviation with intervals and noise types; "
                       "--fit: the composite noise model (Kalibr export)")  # fmt: skip
    p.add_argument("log", help="CSV log: a header row, one sample per row")
    p.add_argument("--column", default=None,
                   help="the column to analyse (default: the only numeric non-time column)")  # fmt: skip
    p.add_argument("--unit", default=None, choices=UNIT_CHOICES,
                   help="the column's rate unit (labels, JSON; needed for --kalibr)")  # fmt: skip
    p.add_argument("--rate-hz", type=POSITIVE_FLOAT, default=None, help="sample rate [Hz]")
    p.add_argument("--time-column", default=None,
                   help="a time column (in --time-unit); stamps that are not uniform are "
                   "resampled by the integrated angle (onto --rate-hz, or the median step)")  # fmt: skip
    p.add_argument("--time-unit", default=None, choices=tuple(TIME_UNITS),
                   help="the time column's unit (default s; a name such as t_ms or an epoch "
                   "in ms, µs or ns is refused without it; steps above 1 that are a round "
                   "number of ms, 10 or 2.5, or whole stamps stepping by 1, read as seconds "
                   "with a note)")  # fmt: skip
    p.add_argument("--kind", default="oadev", choices=KINDS, help="the deviation (oadev)")
    p.add_argument("--taus", default="octave", type=_taus,
                   help="octave, decade, all, or τ values in s: 1,10,100")  # fmt: skip
    # hrgjax.allan.NOISE_RULES, written out: --help imports no JAX
    p.add_argument("--noise-rule", default="hrgjax", choices=("hrgjax", "stable32"),
                   help="the noise type where the lag-1 autocorrelation cannot read it: "
                   "hrgjax (intervals checked by Monte Carlo) or stable32 (the rule that "
                   "reproduces Stable32 1.60's OCXO tables)")  # fmt: skip
    p.add_argument("--fit", action="store_true",
                   help="identify the composite noise model (white angle/rate noise, rate "
                   "random walk, Gauss–Markov terms) with intervals")  # fmt: skip
    p.add_argument("--gauss-markov", type=int, default=None, choices=(0, 1, 2),
                   help="Gauss–Markov terms the model may use (2; with --fit or --kalibr)")  # fmt: skip
    p.add_argument("--sampling", default=None, choices=("interval", "point"),
                   help="what a sample is: the mean rate over its interval (interval: an angle "
                   "output's Δθ/Δt, the default) or an instantaneous rate sample (point); with "
                   "--fit or --kalibr")  # fmt: skip
    p.add_argument("--drift", action="store_const", const=True, default=None,
                   help="also offer a rate ramp (drift) to the model (with --fit or --kalibr)")  # fmt: skip
    p.add_argument("--json", default=None, help="write the deviation and the model here")
    p.add_argument("--csv", default=None, help="write the deviation table here (CSV)")
    p.add_argument("--plot", default=None, help="write the deviation figure here (PNG)")
    p.add_argument("--kalibr", default=None, metavar="IMU.yaml",
                   help="write Kalibr's noise parameters here (implies --fit)")  # fmt: skip
    p.add_argument("--sensor", default=None, choices=("gyroscope", "accelerometer"),
                   help="Kalibr's sensor (default: from --unit; with --kalibr)")  # fmt: skip
    return p


PARSERS = {"allan": _allan_parser}
"""Command → the function that adds its parser to the subparsers (`hrgjax.cli`)."""
