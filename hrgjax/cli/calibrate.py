"""`hrgjax calibrate`, `correct` and `compare`: fit a compensator to bench data, compensate a
session with it, and weigh several on one test session."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
import time
from typing import TYPE_CHECKING, NamedTuple

from ..units import DEG_PER_H, K_E_NOMINAL, K_E_RANGE, PHYSICAL_WINDOW_S, WINDOW_S
from ._common import (
    DATA_EXTENSIONS,
    K_E,
    NONNEGATIVE_FLOAT,
    NONNEGATIVE_INT,
    PLOT_EXTENSIONS,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    POSITIVE_SECONDS,
    UsageError,
    allow_extra_option,
    beside,
    finish,
    load_data,
    one_line,
    preset_gyro,
    say,
    start,
    usage_errors,
)

if TYPE_CHECKING:  # the calibration package imports JAX; `--help` must not
    from ..calibration import AbstractCompensator


class Method(NamedTuple):
    """A `--method`, built from the options: the compensator to fit (its settings as
    fields), what to say while it fits, and the ramp window its reduction needs."""

    compensator: AbstractCompensator
    message: str | None = None
    ramp_window_s: float | None = None


class Given(argparse.Action):
    """Store the option's value and note the option as given by the user (`args.given`, a
    frozenset of option strings): `check_given` refuses one the command will not read."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.given = getattr(namespace, "given", frozenset()) | {self.option_strings[0]}


def check_given(args, options_of: dict, chosen: str) -> None:
    """Refuse an option the user gave (`Given`) that `chosen` does not read: one line naming the
    option and the choices that read it. `options_of` maps each choice, in words (`--method
    fourier`), to the options it reads; options in no entry are read by every choice."""
    given = getattr(args, "given", frozenset())
    specific = {o for options in options_of.values() for o in options}
    for option in sorted(given & specific):
        if option not in options_of.get(chosen, ()):
            takes = [c for c, options in options_of.items() if option in options]
            raise UsageError(f"{option} is for {' and '.join(takes)}: it does not apply to "
                             f"{chosen}")  # fmt: skip


OPTIONS_OF_METHOD = {
    "--method fourier": ("--harmonics", "--temperature-degree"),
    "--method mlp": ("--mode", "--st-width", "--seed"),
    "--method physical": ("--plant",),
}
"""`calibrate`: the method-specific options each `--method` reads (one given to another method
is refused, not ignored; `--k-e` and `--window` apply to all)."""


def TEMPERATURE_DEGREE(text):  # noqa: N802 (an argparse type, named like _common's)
    """`--temperature-degree`: a whole number ≥ 0, or -1 for the seed's base algorithm."""
    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or value < -1:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 0 (the polynomial degree in "
                                         f"T) or -1 (the seed's base algorithm); got {text!r}")  # fmt: skip
    return value


def _window(args) -> dict:
    """`window_s` for the constructor when `--window` is given (else the class's default)."""
    return {} if args.window is None else {"window_s": args.window}


def _fourier(args) -> Method:
    from ..calibration import FourierCompensator

    degree = None if args.temperature_degree < 0 else args.temperature_degree
    return Method(FourierCompensator(harmonics=args.harmonics, temperature_degree=degree,
                                     k_e=args.k_e, **_window(args)))  # fmt: skip


def _mlp(args) -> Method:
    from ..calibration import MLPCompensator
    from ..calibration.reduce import RAMP_WINDOW_S

    # --window is the class's window_s, as for the others: the reduction's and the end-to-end
    # loss's, and what the file records (a re-fit of it uses the same window)
    comp = MLPCompensator(k_e=args.k_e, st_width=args.st_width, mode=args.mode, **_window(args))
    message = f"training the MLP ({args.mode}{', with s_T' if args.st_width else ''})"
    return Method(comp, message, RAMP_WINDOW_S if args.st_width else None)


def _physical(args) -> Method:
    from ..calibration import PhysicalCompensator

    plant = None if args.plant is None else preset_gyro(args.plant, noise=False)
    comp = PhysicalCompensator(k_e=args.k_e, plant=plant, **_window(args))
    return Method(comp, "fitting the physical model through the simulator (Levenberg–Marquardt)")


COMPENSATORS = {"fourier": _fourier, "mlp": _mlp, "physical": _physical}
"""`calibrate --method`: the name → a `Method` built from the parsed options."""
METHODS = tuple(COMPENSATORS)


def cmd_calibrate(args) -> int:
    """`hrgjax calibrate DATA --method …`: fit a compensator to bench data."""
    check_given(args, OPTIONS_OF_METHOD, f"--method {args.method}")
    beside(args, "json", "out", ".json")
    start(args, [args.data], out=(".eqx",), json=(".json",))
    import jax
    import numpy as np

    from ..calibration import export_json, reduce, save_compensator
    from ..calibration.mlp import MIN_RAMP_RATE
    from ..units import group_temperatures

    data = load_data(args.data, args.allow_extra)
    progress = say(time.perf_counter())
    with usage_errors():
        method = COMPENSATORS[args.method](args)
    # --window, else the class's own default (10 s for the grey box, 3 s for the others)
    window = method.compensator.window_s if args.window is None else args.window
    with usage_errors(args.data):
        windows = reduce(data, k_e=args.k_e, window_s=window, ramp_window_s=method.ramp_window_s)
    n_static = len(np.unique(windows.run[windows.static]))
    n_moving = len(np.unique(windows.run[~windows.static]))
    temps = np.unique(np.round(group_temperatures(windows.temperature_c), 2))
    print(
        f"hrgjax calibrate: {args.data}: {n_static} static and {n_moving} rotation runs, "
        f"{len(windows)} windows, temperatures {temps.tolist()} °C"
    )
    if method.message:
        progress(method.message)
    with usage_errors(), cli_words(CALIBRATE_WORDS):
        comp = method.compensator.fit(windows, key=jax.random.key(args.seed), raw=data)
    progress("fitted")
    static = windows.select(windows.static & (np.abs(windows.temperature_rate_cps) < MIN_RAMP_RATE))
    # every bench temperature on purpose, those beyond the calibrated range too (marked below)
    resid = static.drift_dph - comp.drift_dph(static.wave_angle_deg, static.temperature_c,
                                              warn=False)  # fmt: skip
    span = comp.calibrated_range
    if span is not None:
        beyond = "extrapolates" if comp.extrapolates else "passes samples beyond it through"
        print(f"  calibrated temperature range {span[0]:+.1f} … {span[1]:+.1f} °C "
              f"({comp.n_temperature_levels} levels); correct {beyond}")  # fmt: skip
    _scale_factor_check(comp, args.k_e)
    print("  in-sample drift residual RMS per temperature [°/h]:")
    groups = group_temperatures(static.temperature_c)  # one row per temperature
    for T in np.unique(groups):
        r = resid[groups == T]
        out = "" if comp.in_range(np.array([T]))[0] else "  (beyond its range: extrapolated)"
        print(f"    {T:+7.1f} °C  {np.sqrt(np.mean(r**2)):.4f}{out}")
    stats = getattr(comp, "fit_stats", None)  # the grey box: each kind of window's scatter
    if stats:  # χ²/dof is 1 by construction: the rotation scatter is what flags a bad bench
        print(f"  fit residual RMS [°/h]: at-rest windows {stats['static_rms_dph']:.4f}, "
              f"rotation windows {stats['moving_rms_dph']:.4f} (χ²/dof "
              f"{stats['chi2_per_dof']:.3f} by construction: each kind is weighed by its own "
              "scatter; a rotation RMS well above a clean session's points at the table or "
              "the bench, not at noise)")  # fmt: skip
    if hasattr(comp, "equations"):  # a model that prints its fitted laws (the grey box)
        print(comp.equations())
    return finish((args.out, lambda p: save_compensator(comp, p)),
                  (args.json, lambda p: export_json(comp, p)))  # fmt: skip


SCALE_FACTOR_TOLERANCE = 0.1
"""`calibrate` warns when the fitted scale factor is further than this from 1: with the data's
own k_e an HRG's is 1 to well under 1 % (readout gain mismatch, laws in T), so 10 % is a --k-e
typed wrong (K for 2K: 2.0; 0.5 for 0.554: 1.108) or a table rate in another unit or sign."""


def _scale_factor_check(comp, k_e: float) -> None:
    """Print the fitted scale factor SF (measured over true rate, drift removed; 1 = as
    `--k-e` reads the rates) at the calibrated temperature nearest +20 °C, its mean over the
    wave angle: `scale_factor_at` for every `--method` (the Fourier series, the MLP's network,
    the grey box's fitted k_e(T) over the given one). Beyond `SCALE_FACTOR_TOLERANCE`: one
    warning line on stderr naming --k-e and the k_e the data imply (SF × --k-e)."""
    import numpy as np

    from ..units import T_REF_C

    span = comp.calibrated_range
    t_ref = T_REF_C if span is None else float(np.clip(T_REF_C, *span))
    angles = np.arange(-90.0, 90.0, 1.0)  # electrical [°]: a whole period of the 2nθ terms
    sf = float(np.mean(comp.scale_factor_at(angles, np.full(angles.shape, t_ref), warn=False)))
    print(f"  fitted scale factor at {t_ref:+.1f} °C: {sf:.6f} (mean over the wave angle; 1 = "
          f"the rates as --k-e {k_e:g} reads them)")  # fmt: skip
    if abs(sf - 1.0) <= SCALE_FACTOR_TOLERANCE:
        return
    implied = sf * k_e  # measured/true = k_e(data) / k_e(given)
    if K_E_RANGE[0] < implied <= K_E_RANGE[1]:
        why = (f"the data's k_e ≈ {sf:.4f} × {k_e:g} = {implied:.3g} (k_e = 2K ≈ "
               f"{K_E_NOMINAL:.3g} for an HRG): calibrate again with --k-e {implied:.3g}, or "
               "check table_rate_dps (°/s)")  # fmt: skip
    else:
        why = ("no k_e in (0, 1] explains it: check table_rate_dps (its unit, °/s, and its sign) "
               "and --k-e")  # fmt: skip
    print(f"hrgjax calibrate: --k-e looks wrong: fitted scale factor {sf:.4f}, "
          f"{abs(sf - 1.0):.0%} from 1 — {why}", file=sys.stderr, flush=True)  # fmt: skip


CALIBRATE_WORDS = (
    (r"\(e\.g\. calibration\.rotation_plan\)", "(runs at a constant non-zero table rate: "
     "hrgjax simulate --plan rotation simulates them, hrgjax design plans a bench)"),
    (r"(FourierCompensator\(window_s=…\), )?CLI (--\w+)", r"\2"),
)  # fmt: skip
SELF_CALIBRATE_WORDS = (
    (r"\bsettle_s( =)?", "--settle"),
    (r"\(?\bprecession_plan (runs ±ρ|does)\)?", r"(hrgjax simulate --plan precession \1)"),
)  # fmt: skip
"""`calibrate`'s and `self-calibrate`'s `cli_words`: a library message's Python way out or
parameter (pattern) as the command line says it (replacement)."""


@contextlib.contextmanager
def cli_words(words):
    """A `ValueError` raised inside the block comes out with `re.sub(pattern, replacement)`
    of each pair of `words` applied to its message: the library's names as the CLI's."""
    try:
        yield
    except ValueError as err:
        text = str(err)
        for pattern, replacement in words:
            text = re.sub(pattern, replacement, text)
        raise ValueError(text) from None


def _load_model(option: str, path: str):
    """A compensator file, or a one-line error naming `option` and the file."""
    from ..calibration import load_compensator

    try:
        return load_compensator(path)
    except FileNotFoundError:
        raise UsageError(f"{option} {path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{option} {path} is a folder; give a compensator file (.eqx)") from None
    except (OSError, ValueError) as err:
        raise UsageError(f"{option}: {one_line(err)}") from None


def _domain_report(label: str, comp, data, bin_c: float, extrapolate: bool = True,
                   outside_too: bool = True) -> None:  # fmt: skip
    """Print how `data`'s samples stand to `comp`'s calibrated temperature range: the samples
    outside it per temperature (rounded to a multiple of `bin_c` [°C]; extrapolated, or
    passed through uncompensated with `extrapolate=False`; not with `outside_too=False`: the
    comparison's report says it), or that the range is unknown (a file saved before it was
    recorded)."""
    import numpy as np

    from ..calibration.compensators import DOMAIN_MARGIN_C

    span = comp.calibrated_range
    if span is None:
        if "temperature_range" in getattr(type(comp), "__dataclass_fields__", {}):
            print(f"  {label}: calibrated temperature range unknown (a file saved before "
                  "hrgjax recorded it): every sample compensated, as before")  # fmt: skip
        return
    outside = ~comp.in_range(data["temperature_c"])
    if not outside.any() or not outside_too:
        return
    temps, counts = np.unique(
        np.round(data["temperature_c"][outside] / bin_c) * bin_c + 0.0, return_counts=True
    )
    where = ", ".join(f"{n} at {t:+g} °C" for t, n in zip(temps, counts, strict=True))
    how = ("extrapolated (the model applied beyond its range)" if extrapolate
           else "passed through uncompensated")  # fmt: skip
    print(f"  {label}: {int(outside.sum())} samples outside the calibrated temperature range "
          f"{span[0]:+.1f} … {span[1]:+.1f} °C (± {DOMAIN_MARGIN_C:g} °C): {where} — {how}")  # fmt: skip


def _report(result, args, *more) -> int:
    """Print a comparison; write its --json and --plot and any `more` outputs."""
    print(result.format(by_wave_angle=not args.no_angles), end="")
    return finish((args.json, result.write_json), (args.plot, result.plot), *more)


def cmd_correct(args) -> int:
    """`hrgjax correct DATA --model model.eqx`: compensate data with a fitted compensator, and
    report the session's offset and what the compensation leaves after it."""
    inputs = [args.data, args.model]
    start(args, inputs, out=DATA_EXTENSIONS, json=(".json",), plot=PLOT_EXTENSIONS)
    import numpy as np

    from ..calibration import compare_corrected, corrected_run_errors
    from ..calibration.compensators import Corrected

    comp = _load_model("--model", args.model)
    data = load_data(args.data, args.allow_extra)
    with usage_errors(args.data):  # outside the range: said below, in the report
        out = comp.correct(data, extrapolate=False if args.no_extrapolate else None, warn=False)
    print(f"hrgjax correct: {args.data} with {args.model} ({type(comp).__name__})")
    # extrapolated, the samples outside are in the comparison's report below
    _domain_report("temperature domain", comp, data, args.temperature_bin, out.extrapolated,
                   outside_too=not out.extrapolated)  # fmt: skip
    passed = 0 if out.extrapolated else out.n_out_of_range  # the file carries no mark of them
    rows = lambda p: (f"{len(out)} rows with rate_corrected_dps, angle_corrected_deg to "
                      f"{out.save(p)}" + (f" ({passed} of them outside the calibrated "
                      "temperature range, uncompensated: their rate_corrected_dps is the raw "
                      "rate)" if passed else ""))  # fmt: skip
    judged = out  # the runs the offset and the tables are about: the compensated ones
    if passed:
        keep = np.zeros(len(out), dtype=bool)
        n_out = 0
        for i in out.run_indices():
            keep[i] = out.in_range[i].all()
            n_out += not keep[i[0]]
        if not keep.any():  # nothing compensated to judge: the data still written
            print("  every run has samples outside it: no offset and no tables (drop "
                  "--no-extrapolate to compensate them)")  # fmt: skip
            return finish((args.out, rows))
        print(f"  {n_out} run(s) with samples outside it are left out of the offset and the "
              "tables below (passed through, they would be the raw gyro's)")  # fmt: skip
        judged = Corrected({k: v[keep] for k, v in out.columns.items()},
                           in_range=out.in_range[keep], temperature_range=out.temperature_range,
                           margin_c=out.margin_c, extrapolated=False)  # fmt: skip
    e = corrected_run_errors(judged)
    if np.any(e["static"]):
        d = e["drift_error_dph"][e["static"]]
        print(f"  static runs: residual rate RMS {np.sqrt(np.mean(d**2)):.4f} °/h (offset kept)")
    if np.any(~e["static"]):
        a = e["angle_error_deg"][~e["static"]]
        print(
            f"  moving runs: end-of-run angle error RMS {np.sqrt(np.mean(a**2)):.4f}° (offset kept)"
        )
    label = comp.name
    result = compare_corrected(
        {label: judged}, names={label: label}, files={label: args.model},
        temperature_bin_c=args.temperature_bin, angle_bin_deg=args.angle_bin, data=args.data,
    )  # fmt: skip
    print()
    return _report(result, args, (args.out, rows))


def _labels(comps, paths) -> list[str]:
    """Each compensator's name; where names repeat, the name and the file's stem (the path
    as given where stems repeat too)."""
    names = [c.name for c in comps]
    stems = [os.path.splitext(os.path.basename(p))[0] for p in paths]
    labels = [n if names.count(n) == 1 else f"{n} ({s})" for n, s in zip(names, stems, strict=True)]
    return [
        lab if labels.count(lab) == 1 else f"{n} ({p})"
        for lab, n, p in zip(labels, names, paths, strict=True)
    ]


def cmd_compare(args) -> int:
    """`hrgjax compare TEST --models a.eqx b.eqx …`: several compensators on one test
    session, the session's offset apart (hrgjax.calibration.compare)."""
    inputs = [args.data, *args.models]
    start(args, inputs, json=(".json",), plot=PLOT_EXTENSIONS)
    from .._io import same_file
    from ..calibration import compare

    for i, a in enumerate(args.models):
        for b in args.models[:i]:
            if same_file(a, b):
                raise UsageError(f"--models: {b} and {a} are the same file; give each once")
    comps = [_load_model("--models", path) for path in args.models]
    labels = _labels(comps, args.models)
    offset_from = args.offset_from
    if offset_from is not None:
        by_file = [  # by file: ./f.eqx names f.eqx
            lab
            for lab, p in zip(labels, args.models, strict=True)
            if p == offset_from or same_file(p, offset_from)
        ]
        if by_file:
            offset_from = by_file[0]
        elif offset_from not in labels:
            raise UsageError(
                f"--offset-from {args.offset_from!r}: give one of the --models files or a label "
                f"({', '.join(labels)})"
            )
    data = load_data(args.data, args.allow_extra)
    with usage_errors(args.data):  # outside the range: in the report below
        result = compare(
            dict(zip(labels, comps, strict=True)), data,
            files=dict(zip(labels, args.models, strict=True)), offset_from=offset_from,
            temperature_bin_c=args.temperature_bin, angle_bin_deg=args.angle_bin, name=args.data,
            warn=False,
        )  # fmt: skip
    n = result.counts()
    print(
        f"hrgjax compare: {args.data} ({n['static']} static, {n['rotation']} rotation runs), "
        f"{len(labels)} compensators: "
        + ", ".join(f"{lab} ({p})" for lab, p in zip(labels, args.models, strict=True))
    )
    for lab, comp in zip(labels, comps, strict=True):  # outside the range: in the report
        _domain_report(lab, comp, data, args.temperature_bin, outside_too=False)
    print()
    return _report(result, args)


def _evaluation_options(p) -> None:
    p.add_argument("--json", default=None,
                   help="write the offset and the residual tables here (JSON; layout in "
                   "docs/calibration.md)")  # fmt: skip
    p.add_argument("--plot", default=None,
                   help="write the figure of the residuals after the offset per "
                   "temperature and wave angle here (.png, .pdf, .svg)")  # fmt: skip
    p.add_argument("--temperature-bin", type=POSITIVE_FLOAT, default=1.0,
                   help="runs are grouped by mean temperature rounded to a multiple of "
                   "this [°C]")  # fmt: skip
    p.add_argument("--angle-bin", type=POSITIVE_FLOAT, default=5.0,
                   help="runs are grouped by start wave angle rounded to a multiple of "
                   "this [° electrical]")  # fmt: skip
    p.add_argument("--no-angles", action="store_true",
                   help="print no tables per start wave angle (the JSON and the figure "
                   "keep them; the table per start table azimuth stays)")  # fmt: skip
    allow_extra_option(p)


def _calibrate_parser(sub):
    """`hrgjax calibrate`'s parser."""
    p = sub.add_parser("calibrate", help="fit a compensator to bench data (CSV or NetCDF)")
    p.add_argument("data", help="data file in the MeasuredData contract")
    p.add_argument("--method", default="fourier", choices=METHODS, help="compensator to fit")
    p.add_argument("--out", default="out/model.eqx", help="compensator file (.eqx)")
    p.add_argument("--json", default=None, help="JSON export (None: beside --out)")
    p.add_argument(
        "--k-e", type=K_E, default=K_E_NOMINAL,
        help="nominal electrical angular gain k_e = 2K of the data, in (0, 1]",
    )  # fmt: skip
    p.add_argument("--window", type=POSITIVE_SECONDS, default=None,
                   help=f"rotation-run window [s] (None: {WINDOW_S:g} s for fourier and mlp, "
                   f"{PHYSICAL_WINDOW_S:g} s for physical, as the Python classes)")  # fmt: skip
    p.add_argument(
        "--plant", default=None, choices=("tvg3",), action=Given,
        help="physical: the gyro whose loops and resonator constants (ω, τ, Δω, θ_ω, χ) the "
        "grey box models (their lag then leaves g, cross-talk and k_e physical); default: "
        "ideal loops (those are effective values)",
    )  # fmt: skip
    p.add_argument("--mode", default="reduced", choices=("reduced", "end_to_end"), action=Given,
                   help="mlp: training mode")  # fmt: skip
    p.add_argument("--harmonics", type=POSITIVE_INT, default=2, action=Given,
                   help="fourier: harmonics of 2θ")  # fmt: skip
    p.add_argument(
        "--temperature-degree", type=TEMPERATURE_DEGREE, default=-1, action=Given,
        help="fourier: polynomial degree in T (-1 = seed's base algorithm at +20 °C)",
    )  # fmt: skip
    p.add_argument(
        "--st-width", type=NONNEGATIVE_INT, default=0, action=Given,
        help="mlp: hidden neurons of the readout temperature-sensitivity network s_T(θ, T), "
        "learnt from ramps (at rest, temperature moving); 0 = none, the seed's MLP",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, action=Given,
                   help="mlp: PRNG seed of the initial weights")  # fmt: skip
    allow_extra_option(p)
    return p


def _correct_parser(sub):
    """`hrgjax correct`'s parser."""
    p = sub.add_parser(
        "correct",
        help="compensate data with a fitted compensator; report the session's offset and the "
        "residual after it",
    )
    p.add_argument("data", help="data file in the MeasuredData contract")
    p.add_argument("--model", required=True, help="compensator file from `calibrate` (.eqx)")
    p.add_argument("--out", default="out/corrected.csv", help="output CSV or .nc")
    p.add_argument("--no-extrapolate", action="store_true",
                   help="pass samples outside the compensator's calibrated temperature range "
                   "(± 1 °C) through uncompensated instead of applying it there (they are "
                   "counted either way)")  # fmt: skip
    _evaluation_options(p)
    return p


def _compare_parser(sub):
    """`hrgjax compare`'s parser."""
    p = sub.add_parser(
        "compare",
        help="several compensators on one test session: the session's offset, then per "
        "temperature and wave angle what each leaves",
    )
    p.add_argument("data", help="test session in the MeasuredData contract (static and/or "
                   "rotation runs)")  # fmt: skip
    p.add_argument("--models", required=True, nargs="+", metavar="MODEL.eqx",
                   help="compensator files from `calibrate` (.eqx), one or more")  # fmt: skip
    p.add_argument("--offset-from", default=None, metavar="MODEL",
                   help="the compensator (its file or label) whose mean rate at rest is the "
                   "session's offset (None: the one whose static runs scatter least); named, "
                   "every pair is judged after it")  # fmt: skip
    _evaluation_options(p)
    return p


SWEEPS = "virtual-precession sweeps (a precession_dps column)"
REVERSAL = "force-to-rebalance holds (a rebalance_rate_dps column)"
OPTIONS_OF_DATA = {SWEEPS: ("--out", "--harmonics"), REVERSAL: ()}
"""`self-calibrate`: the options each kind of data reads (the sweeps' fit writes a compensator;
mode reversal only a table, to --json); one the data's kind does not read is refused."""


def cmd_self_calibrate(args) -> int:
    """`hrgjax self-calibrate DATA`: calibrate from runs at rest — virtual-precession sweeps
    (the drift compensator) or force-to-rebalance mode reversal (bias and anisotropy)."""
    import numpy as np

    data = load_data(args.data, args.allow_extra)
    reversal = "rebalance_rate_dps" in data
    check_given(args, OPTIONS_OF_DATA, REVERSAL if reversal else SWEEPS)
    if reversal:
        start(args, [args.data], json=(".json",))
    else:
        beside(args, "json", "out", ".json")
        start(args, [args.data], out=(".eqx",), json=(".json",))
    import json

    from ..calibration import export_json, save_compensator
    from ..calibration import self_calibration as sc

    pm = lambda std, n: "± n/a" if std is None or np.isnan(std) else f"± {std:.{n}f}"  # 1σ
    if reversal:
        with usage_errors(args.data), cli_words(SELF_CALIBRATE_WORDS):
            rows = sc.mode_reversal_data(data, settle_s=args.settle)
        print(f"hrgjax self-calibrate: {args.data}: mode reversal in {len(rows)} runs")
        print("    T [°C]   held at [°]     bias ± 1σ [°/h]        anisotropy at the first, as "
              "read (−½Δ(1/τ)sin2(θ−θτ)/k_e) ± 1σ [°/h]")  # fmt: skip
        for r in rows:
            a0, a1 = (a + 0.0 for a in r["angles_deg"])  # no "-0.0"
            print(f"    {r['temperature_c']:+6.1f}   {a0:6.1f}, {a1:6.1f}   {r['bias_dph']:+10.5f} "
                  f"{pm(r['bias_std_dph'], 5):9}   {r['anisotropy_dph']:+10.5f} "
                  f"{pm(r['anisotropy_std_dph'], 5)}")  # fmt: skip
        if any(r["bias_std_dph"] is None for r in rows):
            print("  ± n/a: a hold of fewer than 16 samples (after --settle) gives no σ")

        def write(path):
            from .._io import atomic_write

            with atomic_write(path, "w") as fh:
                json.dump({"mode_reversal": rows}, fh, indent=1)
            return f"the table to {path}"

        return finish((args.json, write)) if args.json else 0
    with usage_errors(args.data), cli_words(SELF_CALIBRATE_WORDS):
        comp = sc.PrecessionCompensator(harmonics=args.harmonics, settle_s=args.settle).fit(data)
    print(f"hrgjax self-calibrate: {args.data}: virtual-precession sweeps at "
          f"{list(comp.temperatures_c)} °C")  # fmt: skip
    angles = np.arange(-90.0, 90.0, 1.0)  # whole periods: the mean is drift_coef[k, 0]
    print("    T [°C]   drift mean ± 1σ [°/h]   peak-to-peak [°/h]")
    for t, std in zip(comp.temperatures_c, np.asarray(comp.drift_std) / DEG_PER_H, strict=True):
        d = comp.drift_dph(angles, t)
        print(f"    {t:+6.1f}   {np.mean(d):+10.4f} {pm(std[0], 4):8}    {np.ptp(d):.4f}")
    if np.any(np.isnan(np.asarray(comp.drift_std))):
        print("  ± n/a (fewer than 6 sweeps: give a noise model; in Python, "
              "PrecessionCompensator.fit(data, noise=NoiseModel.from_gyro(...)), docs/modes.md)")  # fmt: skip
    print("  scale factor: nominal (sweeps at rest do not calibrate it; see docs/modes.md)")
    return finish((args.out, lambda p: save_compensator(comp, p)),
                  (args.json, lambda p: export_json(comp, p)))  # fmt: skip


def _self_calibrate_parser(sub):
    """`hrgjax self-calibrate`'s parser."""
    p = sub.add_parser("self-calibrate", help="calibrate without a turntable: "
                       "virtual-precession sweeps or FTR mode reversal")  # fmt: skip
    p.add_argument("data", help="runs at rest: virtual-precession sweeps (a precession_dps "
                   "column, whole-angle) or FTR holds (rebalance_rate_dps)")  # fmt: skip
    p.add_argument("--out", default="out/self_cal.eqx", action=Given,
                   help="(sweeps) the fitted compensator (.eqx; for correct and compare)")  # fmt: skip
    p.add_argument("--json", default=None,
                   help="(sweeps) its JSON export, default beside --out; (reversal) the table")  # fmt: skip
    p.add_argument("--harmonics", type=POSITIVE_INT, default=2, action=Given,
                   help="(sweeps) 2nθ harmonics of the drift (2: 2θ and 4θ)")  # fmt: skip
    p.add_argument("--settle", type=NONNEGATIVE_FLOAT, default=30.0,
                   help="time left out at the start of each sweep or hold [s]")  # fmt: skip
    allow_extra_option(p)
    return p


PARSERS = {"calibrate": _calibrate_parser, "correct": _correct_parser, "compare": _compare_parser,
           "self-calibrate": _self_calibrate_parser}  # fmt: skip
"""Command → the function that adds its parser to the subparsers (`hrgjax.cli`)."""
