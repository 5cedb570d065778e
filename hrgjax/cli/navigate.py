"""`hrgjax navigate MOTION.csv`: a motion flown by Monte Carlo IMUs, navigated free-inertially
and by the loosely-coupled GNSS/INS filter and smoother (hrgjax.ins.flights)."""

from __future__ import annotations

import math

from ._common import (
    PLOT_EXTENSIONS,
    POSITIVE_FLOAT,
    POSITIVE_INT,
    UsageError,
    figure,
    finish,
    start,
    usage_errors,
)

IMU_PRESETS = ("navigation", "tactical", "industrial", "consumer")
"""`--imu` choices (hrgjax.ins.sensors.PRESETS, restated so that `--help` imports no JAX)."""


def _outage(text: str):
    try:
        a, b = (float(x) for x in text.split(":"))
    except ValueError:
        raise UsageError(
            f"--outage {text!r}: expected START:END in seconds, e.g. 600:660"
        ) from None
    if not (math.isfinite(b) and 0 <= a < b):
        raise UsageError(f"--outage {text!r}: expected 0 <= START < END seconds, finite")
    return (a, b)


def _lever_arm(text: str):
    try:
        v = tuple(float(x) for x in text.split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise UsageError(
            f"--lever-arm {text!r}: expected x,y,z in metres, finite (body: forward, right, down)"
        )
    return v


def used_outages(mot, outages) -> list[tuple[float, float]]:
    """The GNSS outages a flight has [s], sorted and merged: the motion's own (its segments
    without GNSS: the example's 60 s in cruise) and `--outage`'s."""
    windows, t = list(outages), 0.0
    for segment in mot.segments:
        if not segment.gnss:
            windows.append((t, t + segment.duration))
        t += segment.duration
    merged: list[tuple[float, float]] = []
    for a, b in sorted(windows):
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return merged


def cmd_navigate(args) -> int:
    """`hrgjax navigate MOTION.csv`: Monte Carlo flights of a motion definition."""
    inputs = [] if args.motion == "example" else [args.motion]
    start(args, inputs, json=(".json",), plot=PLOT_EXTENSIONS)
    import jax

    from .._progress import bar
    from ..ins import ekf, flights, gnss, motion, sensors

    outages = tuple(_outage(o) for o in args.outage or ())
    # Motion.from_csv names the file (and the line) in every error it raises
    with usage_errors(missing=f"{args.motion}: no such file"):
        mot = motion.example() if args.motion == "example" else motion.Motion.from_csv(args.motion)
    for a, b in outages:
        if a > mot.duration:
            raise UsageError(
                f"--outage {a:g}:{b:g}: starts after the flight, which lasts {mot.duration:g} s "
                f"(outage windows are seconds from the motion's start)"
            )
    with usage_errors():
        imu = sensors.preset(args.imu)
        receiver = gnss.Gnss(
            rate_hz=args.gnss_hz,
            outages=outages,
            lever_arm=_lever_arm(args.lever_arm),
            use_velocity=not args.no_gnss_velocity,
        )
        settings = ekf.LooselyCoupled(imu, receiver, scale_factors=args.states == 21,
                                      gauss_markov=args.gauss_markov)  # fmt: skip
    gaps = used_outages(mot, outages)
    said = ", ".join(f"{a:g}–{b:g} s" for a, b in gaps) or "none"
    # said before the work: sampling the motion takes seconds, the flights' first call
    # compiles for a minute (a bar, at a terminal, shows its clock; a log showed nothing)
    print(f"hrgjax navigate: {args.motion} ({mot.duration:g} s at {args.rate_hz:g} Hz), "
          f"{args.imu} IMU, GNSS {args.gnss_hz:g} Hz (outages: {said}), {args.runs} run(s), "
          f"{settings.n_states} states; flying (the first call compiles) …", flush=True)  # fmt: skip
    with usage_errors():
        with bar(1, f"sampling the motion at {args.rate_hz:g} Hz", unit="motion", tick=True) as b:
            truth = mot.truth(args.rate_hz)  # seconds: the clock moves at a terminal
            b.update(1)
        result = flights.fly(truth, imu, settings, key=jax.random.key(args.seed), runs=args.runs)
    out = result.summary()
    out.update(motion=args.motion, imu=args.imu, rate_hz=args.rate_hz, gnss_hz=args.gnss_hz,
               outages=[list(o) for o in gaps])  # fmt: skip
    print(
        f"{'horizontal position error [m]':>32} {'RMS':>9} {'max':>9} {'in gaps':>9} {'final':>9}"
    )
    for name in ("filter", "smoother", "free"):
        r = out[name]
        gap = r.get("gap_horizontal_max_m")  # absent without a gap in the fixes
        gap = f"{'—':>9}" if gap is None else f"{gap:9.2f}"
        label = {"free": "free inertial (height held)"}.get(name, name)
        print(f"{label:>32} {r['horizontal_rms_m']:9.2f} {r['horizontal_max_m']:9.2f} "
              f"{gap} {r['final_horizontal_median_m']:9.2f}")  # fmt: skip
    lo, hi = out["nees_band_95"]
    lo9, hi9 = out["nees_navigation_band_95"]
    meaning = {
        "consistent": "can be trusted",
        "conservative": "is larger than the errors (conservative)",
        "overconfident": "cannot be trusted: it is smaller than the errors",
        "undefined": "cannot be judged: the NEES is not finite on some epochs (a covariance "
        "not positive definite there)",
    }
    missing = "misalignments" + (", scale factors" if args.states == 15 else "")
    for name in ("filter", "smoother"):
        r = out[name]
        print(f"  {name} NEES, navigation states: mean {r['nees_navigation_mean']:.1f} (95 % band "
              f"{lo9:.1f}–{hi9:.1f}), inside on {100 * r['nees_navigation_inside_95_band']:.0f} % "
              f"of epochs: its position, velocity and attitude σ "
              f"{meaning[r['nees_navigation_verdict']]}")  # fmt: skip
        why = "" if r["nees_verdict"] != "overconfident" else (
            f" (the IMU has errors the filter does not model: {missing})")  # fmt: skip
        print(f"  {name} NEES, all {out['n_states']} states: mean {r['nees_mean']:.1f} (band "
              f"{lo:.1f}–{hi:.1f}), inside on {100 * r['nees_inside_95_band']:.0f} %: its sensor "
              f"estimates' σ {meaning[r['nees_verdict']]}{why}")  # fmt: skip
    if out["nis_mean"] is None:
        print("  NIS mean: none (every GNSS fix fell in an outage)")
    else:
        c = out["nis_check"]
        lo, hi = c["band"]
        print(f"  NIS mean {out['nis_mean']:.2f} (expected {out['innovation_dim']}; "
              f"{100 * c['level']:g} % band {lo:.3f}–{hi:.3f} for {c['fixes']} fixes): "
              f"{c['verdict']}; each run's first {c['early']} fixes {c['early_nis_mean']:.2f} "
              f"(99.9 % point {c['early_bound']:.2f}): {c['early_verdict']}")  # fmt: skip
        for line in filter(None, c["message"].split("\n")):
            print(f"  {line}")
    return finish((args.json, out),
                  (args.plot, lambda p: figure("navigation_figure")(truth, result, p)))  # fmt: skip


def _navigate_parser(sub):
    p = sub.add_parser("navigate", help="Monte Carlo flights: free inertial, GNSS/INS filter, smoother",
                       description=cmd_navigate.__doc__)  # fmt: skip
    p.add_argument(
        "motion", help="motion definition (gnss-ins-sim CSV) or 'example' (a 1-h flight)"
    )
    p.add_argument("--imu", default="tactical", choices=IMU_PRESETS, help="IMU grade")
    p.add_argument("--rate-hz", type=POSITIVE_FLOAT, default=100.0, help="IMU rate [Hz]")
    p.add_argument("--gnss-hz", type=POSITIVE_FLOAT, default=1.0, help="GNSS fix rate [Hz]")
    p.add_argument("--outage", action="append", default=None,
                   help="GNSS outage START:END [s] (repeat for several)")  # fmt: skip
    p.add_argument("--lever-arm", default="0,0,0", help="GNSS antenna from the IMU, x,y,z [m] body")
    p.add_argument("--no-gnss-velocity", action="store_true", help="position fixes only")
    p.add_argument("--states", type=int, default=15, choices=(15, 21),
                   help="filter states: 15, or 21 with gyro and accelerometer scale factors")  # fmt: skip
    p.add_argument("--gauss-markov", action="store_true",
                   help="6 more states: the bias instabilities as Gauss–Markov biases (decaying "
                        "at 1/τ) instead of a walk of density 2σ²/τ (honest σ where τ is short)")  # fmt: skip
    p.add_argument("--runs", type=POSITIVE_INT, default=1, help="Monte Carlo runs")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.add_argument("--json", default=None, help="write the summary here (JSON)")
    p.add_argument("--plot", default=None, help="write the trajectory and error figure (PNG)")
    return p


PARSERS = {"navigate": _navigate_parser}
"""Command → the function that adds its parser to the subparsers (`hrgjax.cli`)."""
