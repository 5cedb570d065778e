"""The `hrgjax` command."""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings

from .units import K_E_NOMINAL, PHYSICAL_WINDOW_S, WINDOW_S

PRESETS = ("tvg3", "ideal")
DATA_EXTENSIONS = (".csv", ".nc")
PLOT_EXTENSIONS = (".png", ".pdf", ".svg")
EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_INTERRUPTED = 2, 1, 130
"""Exit statuses: bad input (a file, a column, an option), a failure during the work,
Ctrl-C."""


class UsageError(Exception):
    """The command's input is bad; `main` prints the message and exits with status 2."""


def _positive(kind, what):
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}; got {text!r}") from None
        if not value > 0 or value != value or value in (float("inf"),):
            raise argparse.ArgumentTypeError(f"expected {what} > 0; got {text}")
        return value

    return parse


POSITIVE_SECONDS = _positive(float, "a number of seconds")
POSITIVE_INT = _positive(int, "a whole number")
POSITIVE_FLOAT = _positive(float, "a number")


def NONNEGATIVE_INT(text):  # noqa: N802 (an argparse type, named like the others)
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 0; got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number ≥ 0; got {text}")
    return value


def _check_output(option: str, path, extensions=(), inputs=()) -> None:
    """Refuse an output path before any work: wrong extension, a folder, an input file, or a
    place that cannot be written."""
    if path is None:
        return
    from ._io import same_file

    ext = os.path.splitext(path)[1].lower()
    if extensions and ext not in extensions:
        raise UsageError(f"{option} {path}: the file name must end in {' or '.join(extensions)}")
    if os.path.isdir(path):
        raise UsageError(f"{option} {path} is a folder; give a file name")
    for source in inputs:
        if source and same_file(path, source):
            raise UsageError(
                f"{option} {path} is the input file {source}; write to another file "
                "(hrgjax never overwrites its input)"
            )
    _check_folder(option, os.path.dirname(os.path.abspath(path)))


def _check_folder(option: str, folder: str) -> None:
    """The folder exists or can be made, and can be written."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise UsageError(f"{option}: {folder} is a file, not a folder")
    d = folder
    while not os.path.exists(d):
        d = os.path.dirname(d)
    if not os.path.isdir(d):
        raise UsageError(f"{option}: cannot make the folder {folder}: {d} is a file")
    if not os.access(d, os.W_OK | os.X_OK):
        raise UsageError(f"{option}: cannot write in {d} (permission denied)")


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return text or type(err).__name__


_python_warning = warnings.formatwarning


def _setup():
    """float64 on, and the persistent compile cache (hrgjax.enable_cache: $HRGJAX_CACHE_DIR,
    else $XDG_CACHE_HOME/hrgjax, else ~/.cache/hrgjax; HRGJAX_NO_CACHE=1 switches it off),
    so a second run loads what the first compiled."""
    import jax

    from ._cache import enable_cache

    jax.config.update("jax_enable_x64", True)
    # hrgjax's own warnings (a cache it cannot use, a damaged entry) as one line each
    warnings.formatwarning = _one_line_warning
    enable_cache()
    return jax


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    text = str(message)
    return f"{text}\n" if text.startswith("hrgjax") else _python_warning(
        message, category, filename, lineno, line)  # fmt: skip


def _say(t0):
    return lambda msg: print(f"  [{time.perf_counter() - t0:6.1f} s] {msg}", flush=True)


def _gyro(name: str, noise: bool = True):
    import hrgjax as hg

    if name == "tvg3":
        return hg.presets.tvg3_like(noise=noise)
    if name == "ideal":
        return hg.presets.ideal(hg.presets.tvg3_like(temperature_laws=False).resonator)
    raise UsageError(f"unknown --preset {name!r}; choose from {PRESETS}")


def _run_plans(gyro, plans, seed: int):
    import jax

    from .calibration import run_plan
    from .data import concat

    key = jax.random.key(seed)
    bias_key = jax.random.fold_in(key, 1)
    parts, first = [], 0
    for i, plan in enumerate(plans):
        t0 = time.perf_counter()
        data = run_plan(
            gyro, plan, key=jax.random.fold_in(key, 10 + i), bias_key=bias_key, first_run=first
        )
        print(
            f"  simulated {plan.size} runs × {plan.duration_s:g} s in "
            f"{time.perf_counter() - t0:.1f} s",
            flush=True,
        )
        parts.append(data)
        first += plan.size
    return parts[0] if len(parts) == 1 else concat(parts)


def cmd_simulate(args) -> int:
    """`hrgjax simulate`: run a bench plan on a preset gyro and write the data."""
    _setup()
    from .calibration import rotation_plan, seed_plan, static_plan

    _check_output("--out", args.out, DATA_EXTENSIONS, inputs=(args.plan_file,))
    gyro = _gyro(args.preset, noise=not args.no_noise)
    if args.plan_file is not None:
        return _simulate_plan_file(args, gyro)
    if args.plan is None:
        args.plan = "static"
    if args.plan == "static":
        plans = [static_plan(duration_s=args.duration)]
    elif args.plan == "rotation":
        plans = [rotation_plan(duration_s=args.duration)]
    else:
        plans = list(seed_plan(quick=args.quick))
    print(f"hrgjax simulate: preset {args.preset}, plan {args.plan}")
    data = _run_plans(gyro, plans, args.seed)
    path = data.save(args.out)
    print(f"wrote {len(data)} rows ({len(data.run_indices())} runs) to {path}")
    return 0


def _simulate_plan_file(args, gyro) -> int:
    import jax

    from .calibration.design import load_plan, simulate_plan

    if args.plan is not None:
        raise UsageError("give either --plan or --plan-file, not both")
    try:
        plan, bench = load_plan(args.plan_file)
    except (FileNotFoundError, ValueError) as err:
        raise UsageError(f"--plan-file: {err}") from None
    try:
        bench.check(plan)
    except ValueError as err:
        raise UsageError(f"--plan-file {args.plan_file}: {err}") from None
    hours = bench.breakdown_h(plan)
    print(
        f"hrgjax simulate: preset {args.preset}, plan file {args.plan_file}: {plan.size} "
        f"segments, bench time {hours['total']:.2f} h (measuring {hours['measuring']:.2f} h)"
    )
    t0 = time.perf_counter()
    key = jax.random.key(args.seed)
    data = simulate_plan(gyro, plan, key=key, bias_key=jax.random.fold_in(key, 1))
    print(f"  simulated {plan.size} segments in {time.perf_counter() - t0:.1f} s", flush=True)
    path = data.save(args.out)
    print(f"wrote {len(data)} rows ({len(data.run_indices())} runs) to {path}")
    return 0


def _levels(text):
    try:
        out = tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected whole numbers like 2,3,4; got {text!r}"
        ) from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"expected positive whole numbers; got {text!r}")
    return out


def cmd_design(args) -> int:
    """`hrgjax design`: the bench plan that calibrates best within a bench-time budget."""
    _setup()
    import jax

    from .calibration import design as d

    _check_output("--out", args.out, (".json",))
    _check_output("--plot", args.plot, (".png", ".pdf", ".svg"))
    levels = d.DEFAULT_LEVELS[args.model] if args.levels is None else args.levels
    lr = d.DEFAULT_LEARNING_RATE if args.learning_rate is None else args.learning_rate
    print(
        f"hrgjax design: {args.budget_h:g} h of bench time, criterion {args.criterion} "
        f"({args.model} model), levels {','.join(map(str, levels))}"
    )
    t0 = time.perf_counter()
    result = d.design(
        args.budget_h, criterion=args.criterion, levels=levels, statics=args.statics,
        rotations=args.rotations, ramps=not args.no_ramps, steps=args.steps, model=args.model,
        learning_rate=lr, key=jax.random.key(args.seed),
        temperature_step=args.temperature_step, angle_step=args.angle_step,
        time_step=args.time_step, rate_step=args.rate_step,
    )  # fmt: skip
    took = time.perf_counter() - t0
    unit = d.CRITERION_UNITS[args.criterion]
    unit = bare = f" {unit}" if unit else ""
    if args.model != "physical":
        unit += f" ({args.model} surrogate)"
    hours = result.bench.breakdown_h(result.plan)
    print(f"  searched {len(result.search)} structures in {took:.1f} s:")
    for n, v in result.search.items():
        if v is None:
            print(f"    {n} temperature levels: does not fit the budget")
            continue
        mark = "  <- chosen" if n == result.levels else ""
        print(f"    {n} temperature levels: {args.criterion} {v:.4g}{unit}{mark}")
    print(
        f"  plan: {result.plan.size} segments, bench time {hours['total']:.2f} h (measuring "
        f"{hours['measuring']:.2f} h, slew {hours['slew']:.2f} h, soak {hours['settle']:.2f} h, "
        f"re-positioning {hours['reposition']:.2f} h)"
    )
    change = (result.value / result.optimised_value - 1.0) * 100.0
    print(
        f"  rounded for the bench: {args.temperature_step:g} °C, {args.angle_step:g}° electrical "
        f"within (−90°, 90°], {args.time_step:g} s, {args.rate_step:g} °/s\n"
        f"    {args.criterion} {result.optimised_value:.6g}{bare} optimised → "
        f"{result.value:.6g}{bare} as rounded ({change:+.2f} %)"
    )
    what = "ideal-loop grey box" if args.model == "physical" else f"{args.model} surrogate"
    print(f"  predicted (ARW, readout and Gauss–Markov noise, {what}; docs/design.md):")
    for name, plan in (("designed", result.plan), ("seed quick", d.seed_bench_plan(True)),
                       ("seed", d.seed_bench_plan())):  # fmt: skip
        parts = ""
        if args.criterion == "drift+warmup":  # and its two terms (one compiled program)
            value, drift, warm = (float(v) for v in d.drift_warmup_error(plan, model=args.model,
                                                                          terms=True))  # fmt: skip
            parts = f" (drift {drift:.4g} °/h, warm-up {warm:.4g} °)"
        else:
            value = float(d.criterion(plan, args.criterion, model=args.model))
        print(f"    {name:10s} {float(d.bench_time_h(plan, result.bench)):6.2f} h  "
              f"{args.criterion} {value:.4g}{unit}{parts}")  # fmt: skip
    path = result.save(args.out)  # the rounded plan, both criterion values, the resolution
    print(f"wrote {path}")
    if args.plot is not None:
        from .plots import plan_figure

        plan_figure(result.plan, args.plot, result.bench,
                    title=f"designed plan: {args.budget_h:g} h budget, {args.criterion}")  # fmt: skip
        print(f"wrote {args.plot}")
    return 0


def cmd_demo(args) -> int:
    """`hrgjax demo`: seed 000's whole calibration study on tvg3_like()."""
    _setup()
    import jax

    from .calibration import export_json, format_table, run_study, save_compensator
    from .calibration.evaluate import SEED_TABLE
    from .plots import compensation_residuals, drift_and_scale_factor, error_vs_temperature

    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise UsageError(f"--out {args.out} is a file; give a folder for the demo's outputs")
    _check_folder("--out", os.path.abspath(args.out))
    os.makedirs(args.out, exist_ok=True)
    mode = "quick" if args.quick else "full"
    print(f"hrgjax demo ({mode}): seed 000's calibration study on the built-in TVG-3-like gyro")
    t0 = time.perf_counter()
    study = run_study(key=jax.random.key(args.seed), quick=args.quick, progress=_say(t0))
    print()
    print(format_table(study.table))
    if study.ins is not None:
        from .calibration.ins_impact import format_ins_table

        print(format_ins_table(study.ins) + "\n")
    print("times [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in study.timings.items()))
    phys = study.compensators.get("physical")
    if phys is not None:
        print("\nphysical fit (1σ):\n" + phys.equations())
    written = [study.calibration.save(os.path.join(args.out, "calibration.csv"))]
    from .calibration import scale_factor_vs_angle, static_drift

    written.append(
        drift_and_scale_factor(
            static_drift(study.calibration),
            scale_factor_vs_angle(study.calibration),
            os.path.join(args.out, "drift_scale_factor.png"),
            "hrgjax: tvg3_like() bench data",
        )
    )
    written.append(
        compensation_residuals(
            study.windows,
            study.compensators,
            os.path.join(args.out, "drift_residuals.png"),
            "static drift and what each compensator leaves",
        )
    )
    written.append(
        error_vs_temperature(
            study.table, os.path.join(args.out, "error_vs_temperature.png"), SEED_TABLE
        )
    )
    for label, comp in study.compensators.items():
        if label == "raw":
            continue
        slug = "_".join("".join(c if c.isalnum() else " " for c in label.lower()).split())
        stem = os.path.join(args.out, "model_" + slug)
        written.append(save_compensator(comp, stem + ".eqx"))
        written.append(export_json(comp, stem + ".json"))
    print(f"\ntotal {time.perf_counter() - t0:.1f} s; wrote:")
    for w in written:
        print(f"  {w}")
    return 0


METHODS = ("fourier", "mlp", "physical")
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
EXAMPLES = {
    "demo": "hrgjax demo --quick --out out/demo",
    "simulate": "hrgjax simulate --preset tvg3 --plan seed --quick --out out/bench.csv",
    "calibrate": "hrgjax calibrate out/bench.csv --method fourier --out out/model.eqx "
    "(bench.csv from the simulate example)",
    "correct": "hrgjax correct out/test.csv --model out/model.eqx --out out/corrected.csv "
    "--plot out/corrected.png (test.csv: a second session, e.g. the simulate example with "
    "--seed 1)",
    "compare": "hrgjax compare out/test.csv --models out/model.eqx out/mlp.eqx --json "
    "out/compare.json --plot out/compare.png (models from calibrate on out/bench.csv, "
    "test.csv from the simulate example with --seed 1: another switch-on)",
    "discover": "hrgjax discover out/bench.csv --json out/report.json --plot out/report.png",
    "align": "hrgjax align psins_lasergyro.imu --json out/align.json --plot out/align.png",
    "diagnose": "hrgjax diagnose --scenario stationary --runs 3 --methods filter_bank,pnn_direct",
    "vibration": "hrgjax vibration --quick --json out/vib.json --plot out/vib.png",
    "design": "hrgjax design --budget-h 4 --out out/plan.json --plot out/plan.png",
    "imu-calibrate": "hrgjax imu-calibrate session.csv --sections sections.json --rate-hz 102.4 "
    "--gyro-unit deg/s --accel-unit m/s^2 --turn-deg -360 --json out/imu_cal.json --plot "
    "out/imu.png (a session with imucal's columns gyr_x … acc_z and its section-list JSON)",
}
"""One runnable example per command, shown at the end of `hrgjax CMD --help`."""


def _load_data(path, allow_extra):
    import hrgjax as hg

    try:
        return hg.load(path, allow_extra=allow_extra)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such file") from None
    except (OSError, ValueError) as err:
        raise UsageError(f"cannot read {path}: {_one_line(err)}") from None


def cmd_calibrate(args) -> int:
    """`hrgjax calibrate DATA --method …`: fit a compensator to bench data."""
    _setup()
    import jax
    import numpy as np

    from .calibration import (
        FourierCompensator,
        MLPCompensator,
        PhysicalCompensator,
        export_json,
        reduce,
        save_compensator,
    )
    from .calibration.mlp import MIN_RAMP_RATE
    from .calibration.reduce import RAMP_WINDOW_S
    from .units import group_temperatures

    json_out = args.json or os.path.splitext(args.out)[0] + ".json"
    _check_output("--out", args.out, (".eqx",), [args.data])
    _check_output("--json", json_out, (".json",), [args.data])
    data = _load_data(args.data, args.allow_extra)
    t0 = time.perf_counter()
    say = _say(t0)
    ramp_window = RAMP_WINDOW_S if args.method == "mlp" and args.st_width else None
    if args.plant is not None and args.method != "physical":
        raise UsageError(f"--plant is for --method physical (the grey box); got --method "
                         f"{args.method}")  # fmt: skip
    if args.window is None:  # each method's own default, as its Python class has it
        args.window = PHYSICAL_WINDOW_S if args.method == "physical" else WINDOW_S
    try:
        windows = reduce(data, k_e=args.k_e, window_s=args.window, ramp_window_s=ramp_window)
    except ValueError as err:
        raise UsageError(f"{args.data}: {_one_line(err)}") from None
    n_static = len(np.unique(windows.run[windows.static]))
    n_moving = len(np.unique(windows.run[~windows.static]))
    temps = np.unique(np.round(group_temperatures(windows.temperature_c), 2))
    print(
        f"hrgjax calibrate: {args.data}: {n_static} static and {n_moving} rotation runs, "
        f"{len(windows)} windows, temperatures {temps.tolist()} °C"
    )
    try:
        if args.method == "fourier":
            degree = None if args.temperature_degree < 0 else args.temperature_degree
            comp = FourierCompensator(
                harmonics=args.harmonics, temperature_degree=degree, k_e=args.k_e
            ).fit(windows)
        elif args.method == "mlp":
            say(f"training the MLP ({args.mode}{', with s_T' if args.st_width else ''})")
            comp = MLPCompensator(k_e=args.k_e, st_width=args.st_width).fit(
                windows, key=jax.random.key(args.seed), mode=args.mode, raw=data
            )
        else:
            say("fitting the physical model through the simulator (Levenberg–Marquardt)")
            plant = None if args.plant is None else _gyro(args.plant, noise=False)
            comp = PhysicalCompensator(k_e=args.k_e, window_s=args.window, plant=plant).fit(data)
    except ValueError as err:
        raise UsageError(_one_line(err)) from None
    say("fitted")
    static = windows.select(windows.static & (np.abs(windows.temperature_rate_cps) < MIN_RAMP_RATE))
    resid = static.drift_dph - comp.drift_dph(static.wave_angle_deg, static.temperature_c)
    print("  in-sample drift residual RMS per temperature [°/h]:")
    groups = group_temperatures(static.temperature_c)  # one row per temperature
    for T in np.unique(groups):
        r = resid[groups == T]
        print(f"    {T:+7.1f} °C  {np.sqrt(np.mean(r**2)):.4f}")
    if args.method == "physical":
        print(comp.equations())
    out = save_compensator(comp, args.out)
    js = export_json(comp, json_out)
    print(f"wrote {out}\nwrote {js}")
    return 0


def _load_model(option: str, path: str):
    """A compensator file, or a one-line error naming `option` and the file."""
    from .calibration import load_compensator

    try:
        return load_compensator(path)
    except FileNotFoundError:
        raise UsageError(f"{option} {path}: no such file") from None
    except IsADirectoryError:
        raise UsageError(f"{option} {path} is a folder; give a compensator file (.eqx)") from None
    except (OSError, ValueError) as err:
        raise UsageError(f"{option}: {_one_line(err)}") from None


def _report(result, args) -> None:
    """Print a comparison and write its --json and --plot (atomically); say where."""
    print(result.format(by_wave_angle=not args.no_angles), end="")
    if args.json:
        print(f"wrote {result.write_json(args.json)}")
    if args.plot:
        print(f"wrote {result.plot(args.plot)}")


def cmd_correct(args) -> int:
    """`hrgjax correct DATA --model model.eqx`: compensate data with a fitted compensator, and
    report the session's offset and what the compensation leaves after it."""
    _setup()
    import numpy as np

    from .calibration import compare_corrected, corrected_run_errors

    inputs = [args.data, args.model]
    _check_output("--out", args.out, DATA_EXTENSIONS, inputs)
    _check_output("--json", args.json, (".json",), inputs)
    _check_output("--plot", args.plot, PLOT_EXTENSIONS, inputs)
    comp = _load_model("--model", args.model)
    data = _load_data(args.data, args.allow_extra)
    try:
        out = comp.correct(data)
    except ValueError as err:
        raise UsageError(f"{args.data}: {_one_line(err)}") from None
    e = corrected_run_errors(out)
    print(f"hrgjax correct: {args.data} with {args.model} ({type(comp).__name__})")
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
        {label: out}, names={label: label}, files={label: args.model},
        temperature_bin_c=args.temperature_bin, angle_bin_deg=args.angle_bin, data=args.data,
    )  # fmt: skip
    print()
    _report(result, args)
    path = out.save(args.out)
    print(f"wrote {len(out)} rows with rate_corrected_dps, angle_corrected_deg to {path}")
    return 0


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
    _setup()
    from ._io import same_file
    from .calibration import compare

    inputs = [args.data, *args.models]
    _check_output("--json", args.json, (".json",), inputs)
    _check_output("--plot", args.plot, PLOT_EXTENSIONS, inputs)
    for i, a in enumerate(args.models):
        for b in args.models[:i]:
            if same_file(a, b):
                raise UsageError(f"--models: {b} and {a} are the same file; give each once")
    comps = [_load_model("--models", path) for path in args.models]
    labels = _labels(comps, args.models)
    offset_from = args.offset_from
    if offset_from is not None:
        by_file = [lab for lab, p in zip(labels, args.models, strict=True) if p == offset_from]
        if by_file:
            offset_from = by_file[0]
        elif offset_from not in labels:
            raise UsageError(
                f"--offset-from {args.offset_from!r}: give one of the --models files or a label "
                f"({', '.join(labels)})"
            )
    data = _load_data(args.data, args.allow_extra)
    try:
        result = compare(
            dict(zip(labels, comps, strict=True)), data,
            files=dict(zip(labels, args.models, strict=True)), offset_from=offset_from,
            temperature_bin_c=args.temperature_bin, angle_bin_deg=args.angle_bin, name=args.data,
        )  # fmt: skip
    except ValueError as err:
        raise UsageError(f"{args.data}: {_one_line(err)}") from None
    n = result.counts()
    print(
        f"hrgjax compare: {args.data} ({n['static']} static, {n['rotation']} rotation runs), "
        f"{len(labels)} compensators: "
        + ", ".join(f"{lab} ({p})" for lab, p in zip(labels, args.models, strict=True))
    )
    print()
    _report(result, args)
    return 0


def cmd_discover(args) -> int:
    """`hrgjax discover DATA`: name the effect missing from the nominal model."""
    _setup()
    from .discovery import NOMINAL, discover

    if args.nominal != "base":
        raise UsageError(f"unknown --nominal {args.nominal!r}; choose 'base'")
    _check_output("--json", args.json, (".json",), [args.data])
    _check_output("--plot", args.plot, PLOT_EXTENSIONS, [args.data])
    data = _load_data(args.data, args.allow_extra)
    try:
        found = discover(data, nominal=NOMINAL, k_e=args.k_e, shape=args.shape)
    except ValueError as err:
        raise UsageError(f"{args.data}: {_one_line(err)}") from None
    print(f"hrgjax discover: {args.data} ({found.shape} data)")
    print(f"  verdict: {found.verdict}; missing effect: {found.missing_effect}")
    if found.ambiguous_with:
        print(f"  hard to tell apart from: {', '.join(found.ambiguous_with)}")
    if found.accepted[1:]:
        print(f"  also accepted: {', '.join(found.accepted[1:])}")
    if found.structure_left or found.verdict == "unexplained":
        print("  structure is left above the noise floor that no catalogue effect explains")
    print("  fitted model:")
    print("\n".join("    " + line for line in found.equations().splitlines()[1:]))
    print(
        "  screening, first round — each candidate against the nominal model alone (score, p, "
        "ΔBIC, aliasing; a shape that outshines it there):"
    )
    for r in found.screening[:6]:
        outshone = f"  outshone by {r['outshone_by']}" if r.get("outshone_by") else ""
        if r.get("accepted_in_round"):
            round_ = r["accepted_in_round"]
            outshone = "  accepted" + (f" (round {round_})" if round_ > 1 else "")
        print(
            f"    {r['effect']:>32} {r['score']:12.4g} {r['p_value']:9.2g} "
            f"{r['delta_bic']:10.4g} {r['aliasing']:6.2f}{outshone}"
        )
    if args.json:
        print(f"wrote {found.write_json(args.json)}")
    if args.plot:
        print(f"wrote {found.plot(args.plot)}")
    return 0


def _write_json(obj: dict, path: str) -> str:
    """Write `obj` as indented JSON at `path` (folders made); returns the path."""
    import json

    from ._io import atomic_write

    with atomic_write(path, "w") as fh:
        fh.write(json.dumps(obj, indent=2))
    return str(path)


def cmd_align(args) -> int:
    """`hrgjax align IMU_LOG`: stationary coarse + fine alignment of a strapdown IMU log."""
    _setup()

    from .ins.alignment import align, load_psins

    if args.format != "psins":
        raise UsageError(f"unknown --format {args.format!r}; choose 'psins'")
    _check_output("--json", args.json, (".json",), [args.imu_log])
    _check_output("--plot", args.plot, PLOT_EXTENSIONS, [args.imu_log])
    try:
        log = load_psins(args.imu_log)
        result = align(log, coarse_s=args.coarse, step_s=args.step)
    except FileNotFoundError:
        raise UsageError(f"{args.imu_log}: no such file") from None
    except ValueError as err:
        raise UsageError(_one_line(err)) from None
    out = result.to_json()
    span = float(log.t[-1] - log.t[0])
    print(f"hrgjax align: {args.imu_log} ({log.t.shape[0]} samples, {span:.0f} s)")
    c = out["coarse"]
    print(
        f"  coarse ({args.coarse:g} s): heading {c['heading_deg']:.3f}°, pitch "
        f"{c['pitch_deg']:.3f}°, roll {c['roll_deg']:.3f}°"
    )
    for k in ("heading", "pitch", "roll"):
        print(f"  {k:>7}: {out[k + '_deg']:9.4f}° ± {out[k + '_std_deg']:.4f}° (1σ)")
    if log.header_attitude_deg is not None:
        print(f"  file header heading: {log.header_attitude_deg[2]:.2f}° (clockwise from north)")
    if args.json:
        print(f"wrote {_write_json(out, args.json)}")
    if args.plot:
        from .plots import alignment_figure

        print(f"wrote {alignment_figure(result, args.plot, log.header_attitude_deg)}")
    return 0


def cmd_diagnose(args) -> int:
    """`hrgjax diagnose`: every seed-002 diagnosis method on one scenario, in one table."""
    _setup()

    import jax

    from .diagnosis.compare import METHODS, compare, table

    methods = METHODS if args.methods is None else tuple(args.methods.split(","))
    _check_output("--json", args.json, (".json",))
    _check_output("--plot", args.plot, PLOT_EXTENSIONS)
    try:
        result = compare(
            args.scenario, key=jax.random.key(args.seed), n_faulty=args.runs,
            n_healthy=max(args.runs // 2, 1), methods=methods, traces=bool(args.plot),
            log=lambda msg: print(f"  … {msg}", file=sys.stderr, flush=True),
        )  # fmt: skip
    except ValueError as err:
        raise UsageError(_one_line(err)) from None
    print(f"hrgjax diagnose: scenario {args.scenario}")
    print(table(result))
    traces = result.pop("traces", None)
    if args.json:
        print(f"wrote {_write_json(result, args.json)}")
    if args.plot:
        from .plots import diagnosis_figure

        print(f"wrote {diagnosis_figure(traces, args.plot, title=result['scenario'])}")
    return 0


def cmd_vibration(args) -> int:
    """`hrgjax vibration`: the seed-003 pipeline on one scenario (hrgjax.fog.study)."""
    _setup()

    import jax

    from .fog.study import SCENARIOS, run, table

    if args.scenario not in SCENARIOS:
        raise UsageError(f"unknown --scenario {args.scenario!r}; known: {tuple(SCENARIOS)}")
    _check_output("--json", args.json, (".json",))
    _check_output("--plot", args.plot, PLOT_EXTENSIONS)
    try:
        quick = dict(freqs_hz=(5.0, 10.0, 20.0), amps_g=(0.25, 0.75, 1.25, 1.5), fs=100.0)
        result = run(
            args.scenario, key=jax.random.key(args.seed),
            epochs=min(args.epochs, 300) if args.quick else args.epochs,
            log=lambda msg: print(f"  … {msg}", file=sys.stderr, flush=True),
            **(quick if args.quick else {}),
        )  # fmt: skip
    except ValueError as err:
        raise UsageError(_one_line(err)) from None
    figures = result.pop("_figures")
    print("hrgjax vibration")
    print(table(result))
    if args.json:
        print(f"wrote {_write_json(result, args.json)}")
    if args.plot:
        from .plots import vibration_figure

        print(f"wrote {vibration_figure(figures, args.plot)}")
    return 0


def cmd_imu_calibrate(args) -> int:
    """`hrgjax imu-calibrate LOG`: Ferraris calibration of a six-axis IMU session."""
    _setup()
    import numpy as np

    from . import imu

    _check_output("--json", args.json, (".json",), [args.log, args.sections])
    _check_output("--plot", args.plot, PLOT_EXTENSIONS, [args.log])
    _check_output("--write-sections", args.write_sections, (".json",), [args.log, args.sections])
    columns = {"gyro": _three("--gyro-columns", args.gyro_columns),
               "accel": _three("--accel-columns", args.accel_columns)}  # fmt: skip
    if args.time_column:
        columns["time"] = args.time_column
    try:
        data = imu.load(args.log, columns=columns, rate_hz=args.rate_hz,
                        units={"gyro": args.gyro_unit, "accel": args.accel_unit})  # fmt: skip
        if args.sections is None:
            sections = imu.detect_sections(data)
        else:
            sections = imu.parse_sections(args.sections, len(data))
        cal = imu.ferraris(data, sections, g=args.g, turn_deg=args.turn_deg)
    except FileNotFoundError as err:
        raise UsageError(_one_line(err)) from None
    except ValueError as err:
        raise UsageError(_one_line(err)) from None
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
            print(f"  {name if k == 0 else '':<22}{cells}")

    print(f"  (± 1σ from {cal.sigma_source}; g = {cal.g:g} m/s², turns {list(cal.turn_deg)}°)")
    rows("accel matrix M_a", cal.accel_matrix, cal.accel_matrix_std)
    rows("accel bias [m/s²]", cal.accel_bias, cal.accel_bias_std, fmt="{:+.5f}")
    rows("gyro matrix M_g", cal.gyro_matrix, cal.gyro_matrix_std)
    rows("gyro bias [°/s]", cal.gyro_bias, cal.gyro_bias_std, dps, fmt="{:+.5f}")
    rows("gyro g-sens [°/s/(m/s²)]", cal.gyro_g_sensitivity, cal.gyro_g_sensitivity_std, dps,
         fmt="{:+.5f}")  # fmt: skip
    if args.json:
        print(f"wrote {cal.save(args.json)}")
    if args.write_sections:
        print(f"wrote {_write_json(imu.sections_to_json(sections), args.write_sections)}")
    if args.plot:
        from .plots import imu_session_figure

        print(f"wrote {imu_session_figure(data, sections, args.plot, calibration=cal)}")
    return 0


def _three(option: str, text: str) -> list[str]:
    names = [t.strip() for t in text.split(",")]
    if len(names) != 3 or not all(names):
        raise UsageError(f"{option} {text!r}: give three comma-separated column names (x,y,z)")
    return names


def main(argv=None) -> int:
    """Entry point of the `hrgjax` command; `argv` defaults to `sys.argv[1:]`."""
    args = build_parser().parse_args(argv)
    if getattr(args, "quiet", False):
        os.environ["HRGJAX_QUIET"] = "1"
    return _run(args)


def build_parser() -> argparse.ArgumentParser:
    """The `hrgjax` argument parser (every option with its help and default)."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--quiet",
        action="store_true",
        default=argparse.SUPPRESS,  # before or after the command; neither overrides the other
        help="no progress bars (they are off without a terminal)",
    )
    common.add_argument(
        "--debug",
        action="store_true",
        default=argparse.SUPPRESS,
        help="show the full traceback of an error (otherwise one line)",
    )

    class fmt(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
        """Defaults shown; the description and the example kept as written."""

    parser = argparse.ArgumentParser(
        prog="hrgjax", description=__doc__, parents=[common], formatter_class=fmt
    )
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser = sub.add_parser
    sub.add_parser = lambda name, **k: add_parser(
        name, parents=[common], formatter_class=fmt, epilog=f"example: {EXAMPLES[name]}", **k
    )

    p = sub.add_parser("demo", help="main job on the built-in gyro")
    p.add_argument("--out", default="out/demo", help="output folder")
    p.add_argument("--quick", action="store_true", help="3 temperatures, short runs (< 1 min)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("calibrate", help="fit a compensator to bench data (CSV or NetCDF)")
    p.add_argument("data", help="data file in the MeasuredData contract")
    p.add_argument("--method", default="fourier", choices=METHODS, help="compensator to fit")
    p.add_argument("--out", default="out/model.eqx", help="compensator file (.eqx)")
    p.add_argument("--json", default=None, help="JSON export (None: beside --out)")
    p.add_argument(
        "--k-e", type=POSITIVE_FLOAT, default=K_E_NOMINAL, help="nominal angular gain k_e"
    )
    p.add_argument(
        "--window",
        type=POSITIVE_SECONDS,
        default=None,
        help=f"rotation-run window [s] (None: {WINDOW_S:g} s for fourier and mlp, "
        f"{PHYSICAL_WINDOW_S:g} s for physical, as the Python classes)",
    )
    p.add_argument(
        "--plant", default=None, choices=("tvg3",),
        help="physical: the gyro whose loops and resonator constants (ω, τ, Δω, θ_ω, χ) the "
        "grey box models (their lag then leaves g, cross-talk and k_e physical); default: "
        "ideal loops (those are effective values)",
    )  # fmt: skip
    p.add_argument(
        "--mode", default="reduced", choices=("reduced", "end_to_end"), help="MLP training mode"
    )
    p.add_argument("--harmonics", type=POSITIVE_INT, default=2, help="Fourier harmonics of 2θ")
    p.add_argument(
        "--temperature-degree",
        type=int,
        default=-1,
        help="Fourier: polynomial degree in T (-1 = seed's base algorithm at +20 °C)",
    )
    p.add_argument(
        "--st-width", type=NONNEGATIVE_INT, default=0,
        help="MLP: hidden neurons of the readout temperature-sensitivity network s_T(θ, T), "
        "learnt from ramps (at rest, temperature moving); 0 = none, the seed's MLP",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (MLP weights)")
    p.add_argument("--allow-extra", action="store_true", help="keep unknown data columns")
    p.set_defaults(func=cmd_calibrate)

    def evaluation_options(p):
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
                       help="print the tables per temperature only (the JSON and the figure "
                       "keep the wave angles)")  # fmt: skip
        p.add_argument("--allow-extra", action="store_true", help="keep unknown data columns")

    p = sub.add_parser(
        "correct",
        help="compensate data with a fitted compensator; report the session's offset and the "
        "residual after it",
    )
    p.add_argument("data", help="data file in the MeasuredData contract")
    p.add_argument("--model", required=True, help="compensator file from `calibrate` (.eqx)")
    p.add_argument("--out", default="out/corrected.csv", help="output CSV or .nc")
    evaluation_options(p)
    p.set_defaults(func=cmd_correct)

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
                   "session's offset (None: the one whose static runs scatter least)")  # fmt: skip
    evaluation_options(p)
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser("discover", help="name the effect missing from the nominal model")
    p.add_argument("data", help="dwell-grid or continuous data in the MeasuredData contract")
    p.add_argument("--nominal", default="base", help="nominal model (base)")
    p.add_argument(
        "--shape",
        default="auto",
        choices=("auto", "dwell", "continuous", "mixed"),
        help="data shape (auto: dwell when every run holds its rate and temperature, mixed "
        "when some do: those as dwell windows, jointly with the continuous records)",
    )
    p.add_argument("--json", default=None, help="write the report here (JSON)")
    p.add_argument("--plot", default=None, help="write the report figure here (PNG)")
    p.add_argument(
        "--k-e", type=POSITIVE_FLOAT, default=K_E_NOMINAL, help="nominal angular gain k_e"
    )
    p.add_argument("--allow-extra", action="store_true", help="keep unknown data columns")
    p.set_defaults(func=cmd_discover)

    p = sub.add_parser("align", help="stationary coarse + fine alignment of an IMU log")
    p.add_argument("imu_log", help="IMU log file")
    p.add_argument("--format", default="psins", help="log format (psins)")
    p.add_argument("--json", default=None, help="write heading/pitch/roll (+ _std_deg) here")
    p.add_argument("--plot", default=None, help="write the convergence figure here (PNG)")
    p.add_argument(
        "--coarse", type=POSITIVE_SECONDS, default=60.0, help="coarse-alignment span [s]"
    )
    p.add_argument("--step", type=POSITIVE_SECONDS, default=1.0, help="Kalman filter step [s]")
    p.set_defaults(func=cmd_align)

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
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser("vibration", help="FOG IMU vibration compensation (Elman) and alignment")
    p.add_argument("--scenario", default="10hz_1g", help="10hz_1g, 10hz_0.5g or on_off")
    p.add_argument("--json", default=None, help="write heading errors and RMSEs here (JSON)")
    p.add_argument("--plot", default=None, help="write the PSD/training/alignment figure (PNG)")
    p.add_argument("--epochs", type=POSITIVE_INT, default=1000,
                   help="training epochs (the patent's 120 under-train)")  # fmt: skip
    p.add_argument(
        "--quick",
        action="store_true",
        help="12-condition grid, 100 Hz, ≤ 300 epochs (a smoke run, < 1 min)",
    )
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.set_defaults(func=cmd_vibration)

    p = sub.add_parser("simulate", help="simulate a bench plan on a preset gyro")
    p.add_argument(
        "--preset", default="tvg3", choices=PRESETS,
        help="tvg3: the TVG-3-like gyro (temperature laws, closed loops, noise); ideal: its "
        "resonator frozen at 20 °C with ideal loops, a perfect readout and no noise",
    )  # fmt: skip
    p.add_argument(
        "--plan", default=None, choices=("static", "rotation", "seed"),
        help="static (the default): 11 temperatures × 19 wave angles at rest; rotation: the "
        "same at 5 °/s; seed: both, as seed 000's bench",
    )  # fmt: skip
    p.add_argument(
        "--plan-file", default=None, metavar="PLAN.json",
        help="a JSON bench plan (segments: static, rotation, ramp; see docs/design.md), "
        "simulated as one switch-on, one run per segment; instead of --plan",
    )  # fmt: skip
    p.add_argument("--out", default="out/data.csv", help="CSV or .nc path")
    p.add_argument(
        "--duration", type=POSITIVE_SECONDS, default=180.0,
        help="run length of the static and rotation plans [s] (the seed plan's are 180 s)",
    )  # fmt: skip
    p.add_argument(
        "--quick", action="store_true",
        help="(--plan seed) −40, +20, +60 °C × 19 wave angles, 120-s runs: 57 static and 57 "
        "rotation runs",
    )  # fmt: skip
    p.add_argument("--no-noise", action="store_true", help="switch the gyro's noise off")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser(
        "design", help="design the bench plan that calibrates best within a bench-time budget"
    )
    p.add_argument(
        "--budget-h", type=POSITIVE_FLOAT, required=True,
        help="bench time available [h], transitions (slew, soak, re-positioning) included",
    )  # fmt: skip
    p.add_argument(
        "--criterion", default="drift+warmup",
        choices=("drift+warmup", "drift", "warmup", "ins", "d", "a"),
        help="drift+warmup (default): the wave-angle error of an hour's operation — the "
        "static drift over an hour and the 1-h warm-up's own error, in quadrature [°]; "
        "drift: predicted compensated static drift RMS over −40…+60 °C × all wave angles "
        "[°/h]; warmup: predicted wave-angle error after 1-h warm-up flights (−40 → +20 °C) "
        "[°]; ins: predicted horizontal position error after them [km]; d / a: D- / "
        "A-optimal (log det / trace of the posterior covariance)",
    )  # fmt: skip
    p.add_argument(
        "--levels", type=_levels, default=None,
        help="numbers of temperature levels to try, comma-separated (default 2,3,4,5; "
        "4,5,6,7 with --model empirical)",
    )  # fmt: skip
    p.add_argument("--statics", type=POSITIVE_INT, default=6,
                   help="static segments per temperature level")  # fmt: skip
    p.add_argument("--rotations", type=int, default=2,
                   help="rotations at ±5 °/s per temperature level")  # fmt: skip
    p.add_argument("--no-ramps", action="store_true",
                   help="no measuring ramps between levels (slew and soak instead)")  # fmt: skip
    p.add_argument("--steps", type=POSITIVE_INT, default=300,
                   help="Adam steps per structure")  # fmt: skip
    p.add_argument("--learning-rate", type=POSITIVE_FLOAT, default=None,
                   help="Adam's learning rate (default: design.DEFAULT_LEARNING_RATE = 0.3)")  # fmt: skip
    p.add_argument(
        "--model", default="physical", choices=("physical", "empirical"),
        help="what the calibration will fit: physical (the grey box) or empirical (an MLP or "
        "a Fourier fit: the plan must visit what the gyro will meet)",
    )  # fmt: skip
    p.add_argument("--temperature-step", type=POSITIVE_FLOAT, default=0.1,
                   help="the bench's temperature resolution [°C]: the plan's temperatures "
                   "are rounded to it (default 0.1)")  # fmt: skip
    p.add_argument("--angle-step", type=POSITIVE_FLOAT, default=0.1,
                   help="wave-angle resolution [° electrical]: angles are wrapped to "
                   "(−90°, 90°] and rounded to it (default 0.1)")  # fmt: skip
    p.add_argument("--time-step", type=POSITIVE_FLOAT, default=1.0,
                   help="duration resolution [s] (default 1: whole seconds; static and "
                   "rotation durations rounded down, ramps up)")  # fmt: skip
    p.add_argument("--rate-step", type=POSITIVE_FLOAT, default=0.01,
                   help="table-rate resolution [°/s] (default 0.01)")  # fmt: skip
    p.add_argument("--out", default="out/plan.json", help="plan file to write (JSON)")
    p.add_argument("--plot", default=None, help="figure of the plan's time line (.png)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (start angles)")
    p.set_defaults(func=cmd_design)

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
    p.add_argument("--time-column", default=None, help="time column [s] (None: use --rate-hz)")
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
    p.add_argument("--json", default=None, help="write the calibration here (JSON, SI units)")
    p.add_argument("--plot", default=None, help="write the session figure here (PNG)")
    p.add_argument("--write-sections", default=None,
                   help="write the sections used (found or given) here (JSON)")  # fmt: skip
    p.set_defaults(func=cmd_imu_calibrate)
    return parser


INPUT_OPTIONS = ("data", "log", "imu_log", "sections", "model", "models", "plan_file",
                 "offset_from")  # fmt: skip
"""Argument names (dests) that name files a command reads."""
OUTPUT_OPTIONS = ("out", "plot", "json", "write_sections")
"""Argument names (dests) that name files a command writes."""


def _option(dest: str) -> str:
    return dest.upper() if dest in ("data", "log", "imu_log") else "--" + dest.replace("_", "-")


def check_distinct_paths(args) -> None:
    """Every output path differs from every input and from every other output, in every
    command: a `--plot` or `--json` naming the input file would overwrite the user's data.
    Inputs count where they are files (`--model` of `design` is a word, not a file).

    **Raises:** `UsageError` naming the two options and the path."""
    seen: dict[str, str] = {}
    for dest in INPUT_OPTIONS:
        value = getattr(args, dest, None)
        for v in value if isinstance(value, list) else [value]:
            if isinstance(v, str) and os.path.isfile(v):
                seen.setdefault(os.path.realpath(v), _option(dest))
    inputs = dict(seen)
    for dest in OUTPUT_OPTIONS:
        v = getattr(args, dest, None)
        if not isinstance(v, str):
            continue
        real = os.path.realpath(v)
        if real in seen:
            what = "the input" if real in inputs else "the output"
            raise UsageError(f"{_option(dest)} {v} is also {what} {seen[real]}; writing it "
                             "would overwrite that file: give another path")  # fmt: skip
        seen[real] = _option(dest)


# Commands whose work is a wide batch (a plan's runs, a design's points vmapped): they stay on
# JAX's default backend. Every other command fits or follows one trajectory at a time.
BATCH_COMMANDS = frozenset({"simulate", "design"})


def _placement(command):
    """Where a command runs: beside an accelerator, a command that is not a wide batch runs on
    the CPU, as an eager `hg.simulate` does (`hrgjax._compiled.single_run_device`). Its
    programs are sequential loops of small kernels: on an NVIDIA H200 the demo, a
    calibration fit and discovery each took over 180 s (the per-test limit of
    `benchmarks/on_gpu.sh`), where a 2-core CPU takes about a minute."""
    import contextlib

    if command in BATCH_COMMANDS:
        return contextlib.nullcontext()
    from ._compiled import single_run_device

    device = single_run_device()
    if device is None:
        return contextlib.nullcontext()
    import jax

    return jax.default_device(device)


def _run(args) -> int:
    """Run the command: a one-line error and exit status 2 for bad input, 1 for a failure
    during the work, 130 on Ctrl-C (files are written atomically, so none is left half
    written); `--debug` shows the traceback instead."""
    name, debug = f"hrgjax {args.command}", getattr(args, "debug", False)
    try:
        check_distinct_paths(args)
        with _placement(args.command):
            return args.func(args)
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"\n{name}: interrupted (no partial output files are left)", file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None
    except (UsageError, ValueError, TypeError, OSError) as err:
        if debug:
            raise
        print(f"{name}: error: {_one_line(err)}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from None
    except Exception as err:
        if debug:
            raise
        print(f"{name}: failed: {_one_line(err)} (--debug shows the traceback)", file=sys.stderr)
        raise SystemExit(EXIT_FAILURE) from None


if __name__ == "__main__":
    sys.exit(main())
