"""`hrgjax simulate`, `design` and `demo`: bench data from a preset gyro, the bench plan that
calibrates best within a budget, and seed 000's whole study."""

from __future__ import annotations

import argparse
import os
import time

from ._common import (
    DATA_EXTENSIONS,
    NONNEGATIVE_INT,
    PLOT_EXTENSIONS,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    POSITIVE_SECONDS,
    PRESETS,
    UsageError,
    check_folder,
    figure,
    finish,
    in_tool_folder,
    preset_gyro,
    say,
    setup,
    start,
    usage_errors,
)

STREAMS = {"static": 10, "rotation": 11, "precession": 12, "reversal": 13}
"""The noise stream each plan kind draws from ``fold_in(key(seed), stream)``: one `--seed`
is one switch-on (the run bias from ``fold_in(key, 1)``), and each kind has noise of its own
— ``--plan static`` and ``--plan rotation`` with one seed are not one noise realisation read
twice (they were: both drew stream 10); ``--plan seed`` draws 10 and 11 as before."""


def _run_plans(gyro, plans, seed: int, first_stream: int = STREAMS["static"]):
    import jax

    from ..calibration import run_plan
    from ..data import concat

    key = jax.random.key(seed)
    bias_key = jax.random.fold_in(key, 1)
    parts, first = [], 0
    for i, plan in enumerate(plans):
        _simulating(f"{plan.size} runs × {plan.duration_s:g} s", first=i == 0)
        t0 = time.perf_counter()
        data = run_plan(
            gyro,
            plan,
            key=jax.random.fold_in(key, first_stream + i),
            bias_key=bias_key,
            first_run=first,
        )
        print(
            f"  simulated {plan.size} runs × {plan.duration_s:g} s in "
            f"{time.perf_counter() - t0:.1f} s",
            flush=True,
        )
        parts.append(data)
        first += plan.size
    return parts[0] if len(parts) == 1 else concat(parts)


def _simulating(what: str, first: bool = True) -> None:
    """The line said before a simulation starts: what it runs, and that the first call
    compiles (seconds of silence otherwise, before the line that says it is done)."""
    compiles = (
        " (compiling the simulator first, unless the compile cache holds it)" if first else ""
    )
    print(f"  simulating {what} …{compiles}", flush=True)


def _rows(data):
    """The writer of simulated data: saves it and says how much."""
    return lambda path: f"{len(data)} rows ({len(data.run_indices())} runs) to {data.save(path)}"


PRECESSION_DPS = 0.5
"""`--precession`'s default [°/s, electrical]."""
DURATION_S = 180.0
"""`--duration`'s default [s]."""
_OPTIONS_OF = {
    "--plan static": ("--duration",),
    "--plan rotation": ("--duration",),
    "--plan seed": ("--quick",),
    "--plan precession": ("--precession", "--quick"),
    "--plan reversal": ("--duration", "--quick"),
}
"""The plan options each plan reads (one given to another plan is refused, not ignored)."""


def cmd_simulate(args) -> int:
    """`hrgjax simulate`: run a bench plan on a preset gyro and write the data."""
    start(args, [args.plan_file], out=DATA_EXTENSIONS)
    if args.plan_file is not None and os.path.isdir(args.plan_file):
        raise UsageError(f"--plan-file {args.plan_file} is a folder; give a plan file (JSON, "
                         "as hrgjax design writes)")  # fmt: skip
    from ..calibration import rotation_plan, seed_plan, static_plan

    plan = "a --plan-file" if args.plan_file is not None else f"--plan {args.plan or 'static'}"
    given = [o for o, v in (("--precession", args.precession), ("--duration", args.duration),
                            ("--quick", args.quick or None)) if v is not None]  # fmt: skip
    unused = [o for o in given if o not in _OPTIONS_OF.get(plan, ())]
    if unused:
        takes = [p for p, options in _OPTIONS_OF.items() if unused[0] in options]
        raise UsageError(f"{unused[0]} does not apply to {plan} (it applies to "
                         f"{', '.join(takes)})")  # fmt: skip
    args.precession = PRECESSION_DPS if args.precession is None else args.precession
    args.duration = DURATION_S if args.duration is None else args.duration
    gyro = preset_gyro(args.preset, noise=not args.no_noise).in_mode(args.mode)
    if args.plan_file is not None:
        return _simulate_plan_file(args, gyro)
    if args.plan is None:
        args.plan = "static"
    if args.plan in ("precession", "reversal"):
        return _self_calibration_plan(args, gyro)
    if args.plan == "static":
        plans = [static_plan(duration_s=args.duration)]
    elif args.plan == "rotation":
        plans = [rotation_plan(duration_s=args.duration)]
    else:
        plans = list(seed_plan(quick=args.quick))
    mode = "" if args.mode == "wa" else ", force-to-rebalance"
    print(f"hrgjax simulate: preset {args.preset}{mode}, plan {args.plan}")
    data = _run_plans(gyro, plans, args.seed, STREAMS.get(args.plan, STREAMS["static"]))
    return finish((args.out, _rows(data)))


def _self_calibration_plan(args, gyro) -> int:
    """The plans of the self-calibration (case at rest): virtual-precession sweeps (±ρ at
    each temperature, whole-angle) or mode reversal (held at θ and θ + 90°, FTR)."""
    import jax

    from ..calibration import self_calibration as sc
    from ..calibration.experiment import QUICK_TEMPERATURES, SEED_TEMPERATURES

    temps = QUICK_TEMPERATURES if args.quick else SEED_TEMPERATURES
    key = jax.random.key(args.seed)
    bias_key = jax.random.fold_in(key, 1)
    t0 = time.perf_counter()
    if args.plan == "precession":
        if args.mode != "wa":
            raise UsageError(
                "--plan precession sweeps the wave in whole-angle mode: drop --mode ftr"
            )
        plan = sc.precession_plan(temps, args.precession)
        _check_sweep(plan, args.precession, sc.SETTLE_S)
        print(f"hrgjax simulate: preset {args.preset}, virtual precession at ±{args.precession:g} "
              f"°/s, {len(temps)} temperatures, {plan.size} sweeps × {plan.duration_s:g} s")  # fmt: skip
        _simulating(f"{plan.size} sweeps × {plan.duration_s:g} s")
        data = sc.run_precession_plan(gyro, plan, key=jax.random.fold_in(key, STREAMS["precession"]),
                                      bias_key=bias_key)  # fmt: skip
    else:
        if args.mode != "ftr":
            raise UsageError("--plan reversal holds the wave: add --mode ftr")
        print(f"hrgjax simulate: preset {args.preset}, force-to-rebalance, mode reversal at "
              f"{len(temps)} temperatures, held {args.duration:g} s at 0° and 90°")  # fmt: skip
        _simulating(f"{len(temps)} runs of two {args.duration:g}-s holds")
        data = sc.run_reversal_plan(gyro, temps, 0.0, args.duration,
                                    key=jax.random.fold_in(key, STREAMS["reversal"]), bias_key=bias_key)  # fmt: skip
    print(f"  simulated in {time.perf_counter() - t0:.1f} s", flush=True)
    return finish((args.out, _rows(data)))


def _check_sweep(plan, rate_dps: float, settle_s: float) -> None:
    """Refuse, before the work, sweeps that `self-calibrate` would refuse after it: each must
    keep `MIN_SWEEP_SAMPLES` output samples after the settling (`--precession 500` swept its
    180° in 0.36 s, at 1 Hz: one sample, and the simulation ran to the end)."""
    from ..calibration._sweeps import MIN_SWEEP_SAMPLES

    sweep_s = plan.duration_s - settle_s
    if sweep_s / plan.dt_out < MIN_SWEEP_SAMPLES:
        fastest = 180.0 / (MIN_SWEEP_SAMPLES * plan.dt_out)
        raise UsageError(
            f"--precession {rate_dps:g}: a sweep over 180° (electrical) would last "
            f"{sweep_s:.3g} s, under {MIN_SWEEP_SAMPLES} samples at {1 / plan.dt_out:g} Hz, "
            f"fewer than self-calibrate needs; give --precession {fastest:g} °/s or less"
        )


def _simulate_plan_file(args, gyro) -> int:
    import jax

    from ..calibration.design import load_plan, simulate_plan

    if args.plan is not None:
        raise UsageError("give either --plan or --plan-file, not both")
    with usage_errors("--plan-file", errors=(FileNotFoundError, ValueError)):
        plan, bench = load_plan(args.plan_file)
    with usage_errors(f"--plan-file {args.plan_file}"):
        bench.check(plan)
    hours = bench.breakdown_h(plan)
    print(
        f"hrgjax simulate: preset {args.preset}, plan file {args.plan_file}: {plan.size} "
        f"segments, bench time {hours['total']:.2f} h (measuring {hours['measuring']:.2f} h)"
    )
    _simulating(f"{plan.size} segments")
    t0 = time.perf_counter()
    key = jax.random.key(args.seed)
    data = simulate_plan(gyro, plan, key=key, bias_key=jax.random.fold_in(key, 1))
    print(f"  simulated {plan.size} segments in {time.perf_counter() - t0:.1f} s", flush=True)
    return finish((args.out, _rows(data)))


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
    start(args, out=(".json",), plot=PLOT_EXTENSIONS)
    import jax

    from ..calibration import design as d

    levels = d.DEFAULT_LEVELS[args.model] if args.levels is None else args.levels
    lr = d.DEFAULT_LEARNING_RATE if args.learning_rate is None else args.learning_rate
    print(
        f"hrgjax design: {args.budget_h:g} h of bench time, criterion {args.criterion} "
        f"({args.model} model), levels {','.join(map(str, levels))}"
    )
    # said before the search: each structure's Adam step compiles first (a minute or more of
    # silence in a log, where no bar shows: 67 s at --steps 3)
    print(f"  searching {len(levels)} structures × {args.steps} Adam steps … (each structure's "
          "step compiles first, unless the compile cache holds it)", flush=True)  # fmt: skip
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
            parts = f" (drift {drift:.4g} °/h, warm-up tilt {warm:.4g} °)"
        else:
            value = float(d.criterion(plan, args.criterion, model=args.model))
        print(f"    {name:10s} {float(d.bench_time_h(plan, result.bench)):6.2f} h  "
              f"{args.criterion} {value:.4g}{unit}{parts}")  # fmt: skip
    title = f"designed plan: {args.budget_h:g} h budget, {args.criterion}"
    return finish(
        (args.out, result.save),  # the rounded plan, both criterion values, the resolution
        (args.plot, lambda p: figure("plan_figure")(result.plan, p, result.bench, title=title)),
    )


DEMO_FIGURES = ("drift_scale_factor.png", "drift_residuals.png", "error_vs_temperature.png")
"""The demo's figures, in its `--out` folder (beside `calibration.csv` and the models)."""
DEMO_MODELS = ("Fourier @+20°C", "Fourier+T", "MLP", "MLP end-to-end", "physical")
"""The labels of the compensators `run_study` fits (every method): each is written as
`model_<slug>.eqx` and `.json` (`_model_stem`)."""


def _model_stem(label: str) -> str:
    """`model_fourier_20_c` of "Fourier @+20°C": the label's letters and digits, by `_`."""
    return "model_" + "_".join("".join(c if c.isalnum() else " " for c in label.lower()).split())


def demo_files() -> tuple[str, ...]:
    """The names of the files `hrgjax demo` writes in its `--out` folder."""
    models = [_model_stem(label) + ext for label in DEMO_MODELS for ext in (".eqx", ".json")]
    return ("calibration.csv", *DEMO_FIGURES, *models)


def _check_demo_folder(args) -> None:
    """Before any work: `--out` is a folder (or can be made), and none of the demo's files
    in it exists outside `out/` unless `--force` (the user's calibration.csv was replaced)."""
    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise UsageError(f"--out {args.out} is a file; give a folder for the demo's outputs")
    check_folder("--out", os.path.abspath(args.out))
    if args.force:
        return
    paths = [os.path.join(args.out, name) for name in demo_files()]
    there = [os.path.basename(p) for p in paths if os.path.lexists(p) and not in_tool_folder(p)]
    if there:
        names = ", ".join(there[:3]) + (f" and {len(there) - 3} more" if len(there) > 3 else "")
        raise UsageError(f"--out {args.out} holds {names} already (files the demo writes); "
                         "give another folder, or --force to replace them")  # fmt: skip


def cmd_demo(args) -> int:
    """`hrgjax demo`: seed 000's whole calibration study on tvg3_like()."""
    _check_demo_folder(args)
    setup()
    import jax

    from ..calibration import export_json, format_table, run_study, save_compensator
    from ..calibration.evaluate import SEED_TABLE
    from ..plots import compensation_residuals, drift_and_scale_factor, error_vs_temperature

    os.makedirs(args.out, exist_ok=True)
    mode = "quick" if args.quick else "full"
    print(f"hrgjax demo ({mode}): seed 000's calibration study on the built-in TVG-3-like gyro")
    t0 = time.perf_counter()
    study = run_study(key=jax.random.key(args.seed), quick=args.quick, progress=say(t0))
    print()
    print(format_table(study.table, domains=study.domains))
    if study.ins is not None:
        from ..calibration.ins_impact import format_ins_table

        print(format_ins_table(study.ins) + "\n")
    print("times [s]: " + ", ".join(f"{k} {v:.1f}" for k, v in study.timings.items()))
    phys = study.compensators.get("physical")
    if phys is not None:
        print("\nphysical fit (1σ):\n" + phys.equations())
    written = [study.calibration.save(os.path.join(args.out, "calibration.csv"))]
    from ..calibration import scale_factor_vs_angle, static_drift

    written.append(
        drift_and_scale_factor(
            static_drift(study.calibration),
            scale_factor_vs_angle(study.calibration),
            os.path.join(args.out, DEMO_FIGURES[0]),
            "hrgjax: tvg3_like() bench data",
        )
    )
    written.append(
        compensation_residuals(
            study.windows,
            study.compensators,
            os.path.join(args.out, DEMO_FIGURES[1]),
            "static drift and what each compensator leaves",
        )
    )
    written.append(
        error_vs_temperature(study.table, os.path.join(args.out, DEMO_FIGURES[2]), SEED_TABLE)
    )
    for label, comp in study.compensators.items():
        if label == "raw":
            continue
        stem = os.path.join(args.out, _model_stem(label))
        written.append(save_compensator(comp, stem + ".eqx"))
        written.append(export_json(comp, stem + ".json"))
    print(f"\ntotal {time.perf_counter() - t0:.1f} s; wrote:")
    for w in written:
        print(f"  {w}")
    return 0


def _demo_parser(sub):
    """`hrgjax demo`'s parser."""
    p = sub.add_parser("demo", help="main job on the built-in gyro")
    p.add_argument("--out", default="out/demo", help="output folder")
    p.add_argument("--quick", action="store_true", help="3 temperatures, short runs (< 1 min)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    return p


def _simulate_parser(sub):
    """`hrgjax simulate`'s parser."""
    p = sub.add_parser("simulate", help="simulate a bench plan on a preset gyro")
    p.add_argument(
        "--preset", default="tvg3", choices=PRESETS,
        help="tvg3: the TVG-3-like gyro (temperature laws, closed loops, noise); ideal: its "
        "resonator frozen at 20 °C with ideal loops, a perfect readout and no noise",
    )  # fmt: skip
    p.add_argument(
        "--plan", default=None, choices=("static", "rotation", "seed", "precession", "reversal"),
        help="static (the default): 11 temperatures × 19 wave angles at rest; rotation: the "
        "same at 5 °/s; seed: both, as seed 000's bench; precession: virtual-precession "
        "sweeps ±--precession at rest at each temperature (for self-calibrate); reversal: "
        "held at 0° and 90° at each temperature (--mode ftr; --duration per hold)",
    )  # fmt: skip
    p.add_argument(
        "--mode", default="wa", choices=("wa", "ftr"),
        help="wa: whole-angle (the wave angle is the output); ftr: force-to-rebalance (the "
        "wave held, the rate read from the rebalance force: column rebalance_rate_dps)",
    )  # fmt: skip
    p.add_argument(
        "--precession", type=POSITIVE_FLOAT, default=None, metavar="DPS",
        help="(--plan precession) commanded precession rate [°/s, electrical] (default 0.5; "
        "at most 9: a 180° sweep keeps 20 samples at 1 Hz, as self-calibrate needs)",
    )  # fmt: skip
    p.add_argument(
        "--plan-file", default=None, metavar="PLAN.json",
        help="a JSON bench plan (segments: static, rotation, ramp; see docs/design.md), "
        "simulated as one switch-on, one run per segment; instead of --plan",
    )  # fmt: skip
    p.add_argument("--out", default="out/data.csv", help="CSV or .nc path")
    p.add_argument(
        "--duration", type=POSITIVE_SECONDS, default=None,
        help="run length of the static and rotation plans [s] (default 180; the seed plan's "
        "are 180 s); --plan reversal: each hold's",
    )  # fmt: skip
    p.add_argument(
        "--quick", action="store_true",
        help="(--plan seed) −40, +20, +60 °C × 19 wave angles, 120-s runs: 57 static and 57 "
        "rotation runs; (--plan precession, reversal) −40, +20, +60 °C only",
    )  # fmt: skip
    p.add_argument("--no-noise", action="store_true", help="switch the gyro's noise off")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    return p


def _design_parser(sub):
    """`hrgjax design`'s parser."""
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
        help="drift+warmup (default): the input-angle (tilt) error of an hour's operation "
        "— the static drift over an hour and the 1-h warm-up's own, in quadrature [°]; "
        "drift: predicted compensated static drift RMS over −40…+60 °C × all wave angles "
        "[°/h]; warmup: predicted input-angle (tilt) error after 1-h warm-up flights "
        "(−40 → +20 °C) [°]; ins: predicted horizontal position error after them [km]; d / a: D- / "
        "A-optimal (log det / trace of the posterior covariance)",
    )  # fmt: skip
    p.add_argument(
        "--levels", type=_levels, default=None,
        help="numbers of temperature levels to try, comma-separated (default 2,3,4,5; "
        "4,5,6,7 with --model empirical)",
    )  # fmt: skip
    p.add_argument("--statics", type=POSITIVE_INT, default=6,
                   help="static segments per temperature level")  # fmt: skip
    p.add_argument("--rotations", type=NONNEGATIVE_INT, default=2,
                   help="rotations at ±5 °/s per temperature level (0: none)")  # fmt: skip
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
    return p


PARSERS = {"demo": _demo_parser, "simulate": _simulate_parser, "design": _design_parser}
"""Command → the function that adds its parser to the subparsers (`hrgjax.cli`)."""
