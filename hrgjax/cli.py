"""The `hrgjax` command."""

from __future__ import annotations

import argparse
import os
import sys
import time

PRESETS = ("tvg3", "ideal")


def _setup():
    import jax

    jax.config.update("jax_enable_x64", True)
    return jax


def _gyro(name: str, noise: bool = True):
    import hrgjax as hg

    if name == "tvg3":
        return hg.presets.tvg3_like(noise=noise)
    if name == "ideal":
        return hg.presets.ideal(hg.presets.tvg3_like(temperature_laws=False).resonator)
    raise SystemExit(f"unknown preset {name!r}; choose from {PRESETS}")


def _run_plans(gyro, plans, seed: int):
    import jax

    from .calibration import run_plan
    from .data import MeasuredData

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
    if len(parts) == 1:
        return parts[0]
    import numpy as np

    cols = {k: np.concatenate([p[k] for p in parts]) for k in parts[0].names}
    return MeasuredData(cols)


def cmd_simulate(args) -> int:
    """`hrgjax simulate`: run a bench plan on a preset gyro and write the data."""
    _setup()
    from .calibration import rotation_plan, seed_plan, static_plan

    gyro = _gyro(args.preset, noise=not args.no_noise)
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


def cmd_demo(args) -> int:
    """`hrgjax demo`: the seed's static and 5 °/s plans on tvg3_like(), data and plot."""
    _setup()
    import numpy as np

    from .calibration import scale_factor_vs_angle, seed_plan, static_drift
    from .plots import drift_and_scale_factor

    os.makedirs(args.out, exist_ok=True)
    print("hrgjax demo: seed 000 bench plans on the built-in TVG-3-like gyro")
    gyro = _gyro("tvg3")
    static, rotation = seed_plan(quick=args.quick)
    static_data = _run_plans(gyro, [static], args.seed)
    rotation_data = _run_plans(gyro, [rotation], args.seed + 1)
    p1 = static_data.save(os.path.join(args.out, "static.csv"))
    p2 = rotation_data.save(os.path.join(args.out, "rotation.csv"))
    drift = static_drift(static_data)
    sf = scale_factor_vs_angle(rotation_data)
    png = drift_and_scale_factor(
        drift, sf, os.path.join(args.out, "drift_scale_factor.png"), "hrgjax: tvg3_like()"
    )
    print("\n  temperature  drift p-p [°/h]  SF ripple [%]")
    for T in np.unique(drift["temperature_c"]):
        d = drift["drift_dph"][drift["temperature_c"] == T]
        row = sf["scale_factor"][np.argmin(np.abs(sf["temperature_c"] - T))]
        print(f"  {T:+8.0f} °C  {np.ptp(d):14.2f}  {50 * np.ptp(row):12.3f}")
    print(f"\nwrote {p1}\nwrote {p2}\nwrote {png}")
    return 0


def main(argv=None) -> int:
    """Entry point of the `hrgjax` command; `argv` defaults to `sys.argv[1:]`."""
    parser = argparse.ArgumentParser(prog="hrgjax", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("demo", help="main job on the built-in gyro")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--quick", action="store_true", help="3 temperatures, 60-s runs")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.set_defaults(func=cmd_demo)

    p = sub.add_parser("simulate", help="simulate a bench plan on a preset gyro")
    p.add_argument("--preset", default="tvg3", choices=PRESETS)
    p.add_argument("--plan", default="static", choices=("static", "rotation", "seed"))
    p.add_argument("--out", default="out/data.csv", help="CSV or .nc path")
    p.add_argument("--duration", type=float, default=180.0, help="run length [s]")
    p.add_argument("--quick", action="store_true", help="(seed plan) 3 temperatures, 60-s runs")
    p.add_argument("--no-noise", action="store_true", help="switch the gyro's noise off")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed")
    p.set_defaults(func=cmd_simulate)

    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
