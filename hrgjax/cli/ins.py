"""`hrgjax align`, `diagnose`, `vibration` and `imu-calibrate`: the navigation-side
commands (seeds 001–003 and six-axis IMU calibration)."""

from __future__ import annotations

import contextlib
import re
import sys

from .._time_units import TIME_UNITS
from ._common import (
    PLOT_EXTENSIONS,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    POSITIVE_SECONDS,
    UsageError,
    figure,
    finish,
    start,
    usage_errors,
    write_json,
)
from .calibrate import cli_words

GYRO_UNIT_NAMES = ("deg/s", "rad/s", "deg/h", "mrad/s")
"""`imu-calibrate --gyro-unit` choices (a subset of hrgjax.imu.GYRO_UNITS)."""
ACCEL_UNIT_NAMES = ("m/s^2", "g", "mg")
"""`imu-calibrate --accel-unit` choices (a subset of hrgjax.imu.ACCEL_UNITS)."""
DIAGNOSIS_METHODS = (
    "filter_bank", "filter_bank_full", "filter_bank_rest", "pnn_bank", "pnn_direct", "som",
    "mlp_classifier", "mlp_predictor",
)  # fmt: skip
"""`hrgjax.diagnosis.compare.METHODS`, restated so that `--help` imports no JAX (a test
checks that they agree)."""


def _log(msg) -> None:
    print(f"  … {msg}", file=sys.stderr, flush=True)


def ticker(what: str = ""):
    """A line whose elapsed time moves (redrawn each second) until closed, "  … [00:12] `what`"
    (or "    [00:12]" under the last note line): a long step with no progress of its own is
    not a silence. Only at a terminal (`hrgjax._progress.bar`): not in logs."""
    from .._progress import bar

    shown = bar(None, what, tick=True)
    shown.bar_format = "  … [{elapsed}] {desc}" if what else "    [{elapsed}]"
    shown.refresh()  # its first draw, in tqdm's own format, is overdrawn at once
    return shown


@contextlib.contextmanager
def steps(first: str = ""):
    """`log=` for the library's long runs (diagnose, vibration): each step's message a note on
    stderr, with a `ticker` until the next (the library's own bars nest under it); `first`:
    a `ticker`'s words for the work before the first message (at a terminal only)."""
    shown = [ticker(first)] if first else []

    def log(msg):
        while shown:
            shown.pop().close()
        _log(msg)
        shown.append(ticker())

    try:
        yield log
    finally:
        while shown:
            shown.pop().close()


def cmd_align(args) -> int:
    """`hrgjax align IMU_LOG`: stationary coarse + fine alignment of a strapdown IMU log."""
    if args.format != "psins":
        raise UsageError(f"unknown --format {args.format!r}; choose 'psins'")
    start(args, [args.imu_log], json=(".json",), plot=PLOT_EXTENSIONS)
    import warnings

    from ..ins.alignment import PSINS_FIELDS, AlignmentWarning, align, check_stationary, load_psins
    from ..ins.fine_alignment import check_step
    from ..units import DEG, DEG_PER_H

    _check_align_options(args)
    with usage_errors(missing=f"{args.imu_log}: no such file"), cli_words(ALIGN_WORDS):
        log = load_psins(args.imu_log)
        check_stationary(log, args.coarse, fields=PSINS_FIELDS, coarse_name="--coarse",
                         where=f"{args.imu_log}: ")  # fmt: skip
        check_step("align", args.step, log.dt)
        what = (f"aligning: coarse over the first {args.coarse:g} s, then the Kalman filter in "
                f"{args.step:g}-s steps over {float(log.t[-1] - log.t[0]) - args.coarse:.0f} s "
                "(compiled first unless the cache holds it)")  # fmt: skip
        with warnings.catch_warnings(record=True) as caught, contextlib.closing(ticker(what)):
            warnings.simplefilter("always", AlignmentWarning)
            result = align(log, coarse_s=args.coarse, coarse_name="--coarse", step_s=args.step,
                           gyro_bias_std=args.gyro_bias * DEG_PER_H, arw=args.arw * DEG / 60.0,
                           velocity_noise=args.velocity_noise)  # fmt: skip
    for w in caught:  # the alignment's warning in one line: "hrgjax align: heading σ …"
        if issubclass(w.category, AlignmentWarning):
            print(f"hrgjax {' '.join(str(w.message).split())}", file=sys.stderr, flush=True)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    out = result.to_json()
    span = float(log.t[-1] - log.t[0])
    print(f"hrgjax align: {args.imu_log} ({log.t.shape[0]} samples, {span:.0f} s)")
    c = out["coarse"]
    print(f"  coarse ({args.coarse:g} s): heading {c['heading_deg']:.3f}° ± "
          f"{c['heading_std_deg']:.3g}° (the span's own scatter {c['scatter_heading_std_deg']:.3g}°),"
          f" pitch {c['pitch_deg']:.3f}°, roll {c['roll_deg']:.3f}°")  # fmt: skip
    for k in ("heading", "pitch", "roll"):
        why = (f", assuming gyro bias σ {args.gyro_bias:g} °/h: stationary alignment cannot "
               "measure the east gyro bias" if k == "heading" else "")  # fmt: skip
        print(f"  {k:>7}: {out[k + '_deg']:9.4f}° ± {out[k + '_std_deg']:.4f}° (1σ{why})")
    print(_sway_line(out["sway"]))
    header = log.header_attitude_deg
    if header is not None:
        print(f"  file header heading: {header[2]:.2f}° (clockwise from north)")
    return finish((args.json, out),
                  (args.plot, lambda p: figure("alignment_figure")(result, p, header)))  # fmt: skip


VELOCITY_NOISE_MAX = 1.0
"""`align --velocity-noise` above this [m/s] is refused: the zero-velocity measurement's noise
of a vehicle at rest is its sway, mm/s to cm/s (the PSINS log's innovations: 2–3 mm/s; a ship
at its mooring, a vehicle in wind: 0.1 m/s); 1 m/s is walking pace, not standing still, so a
value beyond it is one in mm/s or cm/s read as m/s."""
ALIGN_WORDS = ((r"\balign: step_s = (\S+) s", r"--step \1 s"),)
"""`align`'s `cli_words`: the library's names as the command line's options."""


def _check_align_options(args) -> None:
    """Refuse --arw or --gyro-bias beyond `hrgjax.plausible.RANGES`' `imu_arw` or
    `imu_gyro_bias` (as `--relax` leaves them) and --velocity-noise beyond
    `VELOCITY_NOISE_MAX`, in one line naming the option in its CLI unit."""
    from .. import plausible
    from ..units import DEG, DEG_PER_H

    for option, value, si, quantity, unit, other in (
        ("--arw", args.arw, DEG / 60.0, "imu_arw", "°/√h",
         "°/s/√Hz × 60 or °/h/√Hz ÷ 60 is °/√h"),
        ("--gyro-bias", args.gyro_bias, DEG_PER_H, "imu_gyro_bias", "°/h",
         "°/s × 3600 is °/h"),
    ):  # fmt: skip
        high = plausible.RANGES[quantity][1]
        if value * si >= high:
            raise UsageError(f"{option} {value:g} {unit} is beyond the plausible {high / si:.3g} "
                             f"{unit} (the option is in {unit}: {other}; --relax "
                             f"{quantity}=LOW,HIGH, in {plausible.RANGES[quantity][2]}, "
                             "widens it)")  # fmt: skip
    if args.velocity_noise > VELOCITY_NOISE_MAX:
        raise UsageError(f"--velocity-noise {args.velocity_noise:g} m/s is more than a vehicle at "
                         f"rest sways (≤ {VELOCITY_NOISE_MAX:g} m/s; mm/s to cm/s parked): the "
                         f"option is in m/s ({args.velocity_noise:g} mm/s is --velocity-noise "
                         f"{args.velocity_noise / 1e3:g})")  # fmt: skip


def _sway_line(sway: dict) -> str:
    """`hrgjax align`'s whiteness test of the zero-velocity innovations
    ([`AlignmentResult.sway`][hrgjax.ins.alignment.AlignmentResult.sway]) in one line, with a
    note where they are not white as the filter assumes (not a measure of the heading's σ)."""
    rms = ", ".join(f"{v * 1e3:.3g}" for v in sway["innovation_rms_m_s"])
    slow = ", ".join(f"{v:.2g}" for v in sway["slow_ratio"])
    line = (f"  sway: zero-velocity innovations RMS (N, E, D) {rms} mm/s against the assumed "
            f"{sway['velocity_noise_m_s'] * 1e3:.3g} mm/s; mean NIS {sway['mean_nis']:.3g} (3 for "
            f"white noise as assumed); slow part {slow} × the assumed (1; {sway['blocks']} "
            "blocks)")  # fmt: skip
    if sway["not_white"]:
        line += (f" — not white (chance {min(sway['slow_p'][:2]):.2g} under the model): the "
                 "vehicle sways slower than a filter step; this does not say whether or by how "
                 "much the heading σ is off (aligning disjoint windows does); a calmer stretch "
                 "or a larger --velocity-noise models it")  # fmt: skip
    return line


def cmd_diagnose(args) -> int:
    """`hrgjax diagnose`: every seed-002 diagnosis method on one scenario, in one table."""
    start(args, json=(".json",), plot=PLOT_EXTENSIONS)
    import jax

    from ..diagnosis.compare import METHODS, compare, table

    methods = METHODS if args.methods is None else tuple(args.methods.split(","))
    n_healthy = max(args.runs // 2, 1)
    first = (f"simulating {args.runs} faulty and {n_healthy} healthy runs of the three INS "
             "(compiled first unless the cache holds them)")  # fmt: skip
    with usage_errors(), steps(first) as log:
        result = compare(
            args.scenario, key=jax.random.key(args.seed), n_faulty=args.runs,
            n_healthy=n_healthy, methods=methods, traces=bool(args.plot), log=log,
        )  # fmt: skip
    # the sizes in the faulty sensor's unit (hrgjax.ins.platform.Fault: accelerometers in g,
    # gyros in rad/s), on screen and in the JSON
    unit = "g" if result["sensor"].startswith("accel") else "rad/s"
    result["setup"] |= {"fault_sizes_unit": unit, "nominal_sensor_error_unit": unit}
    print(f"hrgjax diagnose: scenario {args.scenario}")
    print(re.sub(r"(sizes \S+)(, nominal sensor error \S+)\)", rf"\1 {unit}\2 {unit})",
                 table(result), count=1))  # fmt: skip
    traces = result.pop("traces", None)
    title = result["scenario"]
    return finish((args.json, result),
                  (args.plot, lambda p: figure("diagnosis_figure")(traces, p, title=title)))  # fmt: skip


EPOCHS, QUICK_EPOCHS = 1000, 300
"""`vibration`'s training epochs, and the most `--quick` runs (a smoke run): its default, and
a larger --epochs given with it is capped, with a note."""


def cmd_vibration(args) -> int:
    """`hrgjax vibration`: the seed-003 pipeline on one scenario (hrgjax.fog.study)."""
    epochs = (QUICK_EPOCHS if args.quick else EPOCHS) if args.epochs is None else args.epochs
    if args.quick and epochs > QUICK_EPOCHS:  # said at once, before JAX is imported
        _log(f"--quick trains at most {QUICK_EPOCHS} epochs: --epochs {epochs} capped (drop "
             "--quick for more)")  # fmt: skip
        epochs = QUICK_EPOCHS
    start(args, json=(".json",), plot=PLOT_EXTENSIONS)
    import jax

    from ..fog.study import SCENARIOS, run, table

    if args.scenario not in SCENARIOS:
        raise UsageError(f"unknown --scenario {args.scenario!r}; known: {tuple(SCENARIOS)}")
    with usage_errors(), steps() as log:
        quick = dict(freqs_hz=(5.0, 10.0, 20.0), amps_g=(0.25, 0.75, 1.25, 1.5), fs=100.0)
        result = run(args.scenario, key=jax.random.key(args.seed), epochs=epochs, log=log,
                     **(quick if args.quick else {}))  # fmt: skip
    figures = result.pop("_figures")
    print("hrgjax vibration")
    print(table(result))
    return finish((args.json, result),
                  (args.plot, lambda p: figure("vibration_figure")(figures, p)))  # fmt: skip


def cmd_imu_calibrate(args) -> int:
    """`hrgjax imu-calibrate LOG`: Ferraris calibration of a six-axis IMU session."""
    start(args, [args.log, args.sections], json=(".json",), plot=PLOT_EXTENSIONS,
          write_sections=(".json",))  # fmt: skip
    import warnings

    import numpy as np

    from .. import imu
    from ..imu.sections import TurnCutWarning
    from ..units import EARTH_RATE

    columns = {
        "gyro": _three("--gyro-columns", args.gyro_columns),
        "accel": _three("--accel-columns", args.accel_columns),
        "temperature": None,
    }  # fmt: skip  (the calibration reads no temperature)
    units = {"gyro": args.gyro_unit, "accel": args.accel_unit}
    if args.time_column:
        columns["time"] = args.time_column
        units["time"] = args.time_unit
    elif args.time_unit is not None:
        raise UsageError("--time-unit is the unit of --time-column: give the column too")
    with usage_errors(errors=(FileNotFoundError, ValueError)):
        try:
            data = imu.load(args.log, columns=columns, rate_hz=args.rate_hz, units=units)
        except ValueError as err:  # the library words the way out for its API
            msg = re.sub(r'units\["time"\] = "(\w+)"', r"--time-unit \1", _imu_words(err))
            if args.time_unit is None and f"column {args.time_column!r} row" in msg:
                msg += " (time stamps in ns? give --time-unit ns)"
            raise ValueError(msg) from None
    # stamps in ms read as seconds: a 100-Hz log at 0.1 Hz, a 1-kHz log in whole ms at 1 Hz
    # (no IMU calibration log is that slow), its turns 1000× too large
    slow = (f" (the log reads as {data.rate_hz:.3g} Hz: time stamps in ms? give --time-unit ms)"
            if args.time_column and args.time_unit is None and data.rate_hz <= 1.0 else "")  # fmt: skip
    with usage_errors(errors=(FileNotFoundError, ValueError)):
        try:
            if args.sections is None:
                sections = imu.detect_sections(data)
            else:
                sections = imu.parse_sections(args.sections, len(data))
            # the warnings filters stay the user's: a TurnCutWarning they ignore is not caught
            with warnings.catch_warnings(record=True) as caught:
                cal = imu.ferraris(data, sections, g=args.g, turn_deg=args.turn_deg,
                                   turn_deg_std=args.turn_deg_std,
                                   gyro_range_dps=args.gyro_range_dps,
                                   accel_range_g=args.accel_range_g, lat_deg=args.lat_deg,
                                   earth_rate=0.0 if args.no_earth_rate else EARTH_RATE)  # fmt: skip
        except ValueError as err:
            raise ValueError(f"{_imu_words(err)}{slow}") from None
    for w in caught:  # a turn cut short, in one line: "hrgjax imu-calibrate: turn 'x_rot' …"
        if issubclass(w.category, TurnCutWarning):
            text = str(w.message).removeprefix("hrgjax.imu.ferraris: ")
            print(f"hrgjax imu-calibrate: {' '.join(text.split())}", file=sys.stderr, flush=True)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    span = float(data.time[-1] - data.time[0])
    found = "found in the data" if args.sections is None else f"from {args.sections}"
    print(f"hrgjax imu-calibrate: {args.log} ({len(data)} samples, {span:.0f} s at "
          f"{data.rate_hz:g} Hz); sections {found}")  # fmt: skip
    if args.sections is None:
        for key, ranges in sections.items():
            print(f"  {key:>5}: " + ", ".join(f"rows {s}–{e}" for s, e in ranges))
    dps = np.rad2deg(1.0)

    def rows(name, m, sd, scale=1.0, fmt="{:+.6f}"):
        m, sd = np.atleast_2d(np.asarray(m) * scale), np.atleast_2d(np.asarray(sd) * scale)
        for k, (r, e) in enumerate(zip(m, sd, strict=True)):
            cells = "  ".join(f"{fmt.format(v)} ± {abs(x):.1e}" for v, x in zip(r, e, strict=True))
            print(f"  {name if k == 0 else '':<26}{cells}")

    print(f"  (± 1σ from {cal.sigma_source}; g = {cal.g:g} m/s², turns {list(cal.turn_deg)}°)")
    rows("accel matrix M_a", cal.accel_matrix, cal.accel_matrix_std)
    rows("accel bias [m/s²]", cal.accel_bias, cal.accel_bias_std, fmt="{:+.5f}")
    rows("gyro matrix M_g", cal.gyro_matrix, cal.gyro_matrix_std)
    rows("gyro bias [°/s]", cal.gyro_bias, cal.gyro_bias_std, dps, fmt="{:+.5f}")
    rows("gyro g-sens [°/s/(m/s²)]", cal.gyro_g_sensitivity, cal.gyro_g_sensitivity_std, dps,
         fmt="{:+.5f}")  # fmt: skip
    return finish(
        (args.json, cal.save),
        (args.write_sections, lambda p: write_json(imu.sections_to_json(sections), p)),
        (args.plot, lambda p: figure("imu_session_figure")(data, sections, p, calibration=cal)),
    )


IMU_WORDS = (
    (r"units\[\"(gyro|accel)\"\] = '([^']+)'", r"--\1-unit \2"),
    (r"declare the file's unit, or pass check_units=False for a (record that is not mostly "
     r"at rest|spin test)", r"give the file's unit (the command line checks it against the "
     r"data: a record mostly at rest)"),
    (r"pass the sections by hand, or change min_static_s / motion_threshold_dps",
     "give their rows with --sections, or check --gyro-unit and --time-unit (rests and "
     "turns are told apart by the rate in °/s)"),
    (r"pass turn_deg=(\S+)", r"give --turn-deg \1"),
    (r"the time stamps' unit", "--time-unit"),
    (r"the gyro unit", "--gyro-unit"),
    (r"^g = ", "--g "),
    (r"give the local gravity \[m/s²\]", "give the local gravity with --g [m/s²]"),
    (r"the accelerometer unit", "--accel-unit"),
    (r"\b(turn_deg_std|turn_deg|lat_deg|gyro_range_dps|accel_range_g)\b",
     lambda m: "--" + m[1].replace("_", "-")),
)  # fmt: skip
"""`imu-calibrate`: a library message's Python names and ways out (pattern), as the command
line says them (replacement; `re.sub`)."""


def _imu_words(err: BaseException) -> str:
    """`err`'s message with `IMU_WORDS` applied."""
    text = str(err)
    for pattern, replacement in IMU_WORDS:
        text = re.sub(pattern, replacement, text)
    return text


def _three(option: str, text: str) -> list[str]:
    names = [t.strip() for t in text.split(",")]
    if len(names) != 3 or not all(names):
        raise UsageError(f"{option} {text!r}: give three comma-separated column names (x,y,z)")
    return names


def _align_parser(sub):
    """`hrgjax align`'s parser."""
    p = sub.add_parser("align", help="stationary coarse + fine alignment of an IMU log")
    p.add_argument("imu_log", help="IMU log file")
    p.add_argument("--format", default="psins", help="log format (psins)")
    p.add_argument("--json", default=None, help="write heading/pitch/roll (+ _std_deg) here")
    p.add_argument("--plot", default=None, help="write the convergence figure here (PNG)")
    p.add_argument(
        "--coarse", type=POSITIVE_SECONDS, default=60.0, help="coarse-alignment span [s]"
    )
    p.add_argument("--step", type=POSITIVE_SECONDS, default=1.0, help="Kalman filter step [s]")
    p.add_argument(
        "--gyro-bias", type=POSITIVE_FLOAT, default=0.05, metavar="DEG_PER_H",
        help="the gyros' bias σ the filter assumes, in °/h — not rad/s: 0.05 °/h is 2.4e-7 "
        "rad/s (navigation grade 0.05; tactical ≈ 0.5–1): the heading σ ends at it / (ω_ie "
        "cos lat), since stationary alignment cannot measure the east gyro bias",
    )  # fmt: skip
    p.add_argument("--arw", type=POSITIVE_FLOAT, default=0.01, metavar="DEG_PER_RT_H",
                   help="the gyros' angle random walk the filter assumes, in °/√h (°/s/√Hz × "
                   "60; °/h/√Hz ÷ 60)")  # fmt: skip
    p.add_argument("--velocity-noise", type=POSITIVE_FLOAT, default=0.01, metavar="M_PER_S",
                   help="the zero-velocity measurement's white noise the filter assumes, in m/s "
                   f"(10 mm/s is 0.01; at most {VELOCITY_NOISE_MAX:g}): a parked vehicle's "
                   "sway; the printed sway line tests the innovations' whiteness")  # fmt: skip
    return p


def _diagnose_parser(sub):
    """`hrgjax diagnose`'s parser."""
    p = sub.add_parser("diagnose", help="three-INS fault diagnosis: every method, one table")
    p.add_argument("--scenario", default="stationary",
                   choices=("stationary", "accel3g", "accel10g", "gyro"),
                   help="the INS's motion and the faulty sensor (hrgjax.diagnosis.compare)")  # fmt: skip
    p.add_argument("--json", default=None, help="write the table (methods[...]) here")
    p.add_argument("--plot", default=None, help="write decision traces of one run here (PNG)")
    p.add_argument("--runs", type=POSITIVE_INT, default=12, help="faulty Monte Carlo runs")
    p.add_argument(
        "--methods", default=None, metavar="M1,M2,…",
        help=f"comma-separated subset of {', '.join(DIAGNOSIS_METHODS)} (None: all)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    return p


def _vibration_parser(sub):
    """`hrgjax vibration`'s parser."""
    p = sub.add_parser("vibration", help="FOG IMU vibration compensation (Elman) and alignment")
    p.add_argument("--scenario", default="10hz_1g", help="10hz_1g, 10hz_0.5g or on_off")
    p.add_argument("--json", default=None, help="write heading errors and RMSEs here (JSON)")
    p.add_argument("--plot", default=None, help="write the PSD/training/alignment figure (PNG)")
    p.add_argument("--epochs", type=POSITIVE_INT, default=None,
                   help=f"training epochs (None: {EPOCHS}, with --quick {QUICK_EPOCHS}, its "
                   "most; the patent's 120 under-train)")  # fmt: skip
    p.add_argument(
        "--quick",
        action="store_true",
        help=f"12-condition grid, 100 Hz, ≤ {QUICK_EPOCHS} epochs (a smoke run, < 1 min)",
    )
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    return p


def _imu_calibrate_parser(sub):
    """`hrgjax imu-calibrate`'s parser."""
    p = sub.add_parser("imu-calibrate", help="Ferraris calibration of a six-axis IMU session (CSV)")
    p.add_argument("log", help="CSV file, one row per sample")
    p.add_argument(
        "--sections", default=None,
        help="JSON {\"x_p\": {\"start\": i, \"end\": j}, …} (rows, end excluded; keys x_p x_a y_p "
        "y_a z_p z_a x_rot y_rot z_rot; a list of ranges per key for repeats); None: find them "
        "in the data",
    )  # fmt: skip
    p.add_argument("--gyro-columns", default="gyr_x,gyr_y,gyr_z", help="gyro x,y,z columns")
    p.add_argument("--accel-columns", default="acc_x,acc_y,acc_z", help="accel x,y,z columns")
    p.add_argument("--time-column", default=None,
                   help="time column, in --time-unit (None: use --rate-hz)")  # fmt: skip
    p.add_argument("--time-unit", default=None, choices=tuple(TIME_UNITS),
                   help="the time column's unit (default s; a column named in a unit, t_ms, "
                   "needs it)")  # fmt: skip
    p.add_argument("--rate-hz", type=POSITIVE_FLOAT, default=None,
                   help="sample rate [Hz] (needed without --time-column)")  # fmt: skip
    p.add_argument("--gyro-unit", default="deg/s", choices=tuple(GYRO_UNIT_NAMES),
                   help="the file's gyro unit")  # fmt: skip
    p.add_argument("--accel-unit", default="m/s^2", choices=tuple(ACCEL_UNIT_NAMES),
                   help="the file's accelerometer unit (checked against the data)")  # fmt: skip
    p.add_argument("--g", type=POSITIVE_FLOAT, default=9.81,
                   help="local gravity [m/s²], 9.76–9.84 (the Earth's surface)")  # fmt: skip
    p.add_argument("--turn-deg", type=float, default=360.0,
                   help="angle of each turn [°], right-handed positive (imucal's clockwise "
                   "hand turns: -360)")  # fmt: skip
    p.add_argument("--turn-deg-std", type=float, default=0.0,
                   help="σ of each turn's true angle [°] (0: exact turns; hand turns: about 1, "
                   "which is 0.28 %% of M_g's diagonal)")  # fmt: skip
    earth = p.add_mutually_exclusive_group()
    earth.add_argument("--lat-deg", type=float, default=None,
                       help="the bench's latitude [°], north positive: the Earth's vertical rate "
                       "is removed from G (without it the Earth's rate, latitude unknown, "
                       "enters the σ)")  # fmt: skip
    earth.add_argument("--no-earth-rate", action="store_true",
                       help="the log holds no Earth's rate (a simulation): the method's σ, "
                       "without the Earth's terms (hg.imu.ferraris(..., earth_rate=0))")  # fmt: skip
    p.add_argument("--gyro-range-dps", type=POSITIVE_FLOAT, default=None,
                   help="the gyros' full-scale range [°/s]: a turn sample at it is refused as "
                   "clipped (without it: flat tops at a channel's extreme are)")  # fmt: skip
    p.add_argument(
        "--accel-range-g",
        type=POSITIVE_FLOAT,
        default=None,
        help="the accelerometers' full-scale range [g], checked on the faces",
    )
    p.add_argument("--json", default=None, help="write the calibration here (JSON, SI units)")
    p.add_argument("--plot", default=None, help="write the session figure here (PNG)")
    p.add_argument("--write-sections", default=None,
                   help="write the sections used (found or given) here (JSON)")  # fmt: skip
    return p


PARSERS = {"align": _align_parser, "diagnose": _diagnose_parser, "vibration": _vibration_parser,
           "imu-calibrate": _imu_calibrate_parser}  # fmt: skip
"""Command → the function that adds its parser to the subparsers (`hrgjax.cli`)."""
