"""One long run of the carrier-resolving model with the loops closed: the default gyro
(temperature laws, closed loops, noise off) at 5 °/s with the chamber ramping 20 → 25 °C,
1-s outputs, on the fixed-step carrier path with the loops held over each step
(`fixed_step="held"`: 10 steps per carrier cycle, a digital controller at 1/h; `--default`:
the default call instead, every stage demodulating its state, ≈ 4× slower with the loops
closed). Prints the wall time and the time per simulated second. Target (issue 20): 1 h of
simulated time ≤ 10 min on the 2-core machine.

`python benchmarks/carrier_long.py [--seconds S] [--default]` (default 3600). A short run
(S ≤ 60) also compares the wave angle with the adaptive solver on the same equations.
"""

import argparse
import time

import numpy as np
from _common import machine, report

import hrgjax as hg


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=3600.0)
    ap.add_argument("--default", action="store_true", help="the default call, not held loops")
    args = ap.parse_args()
    span = args.seconds
    gyro = hg.presets.tvg3_like(noise=False)
    prof = hg.Profile(
        t=np.array([0.0, span]),
        rate=np.deg2rad([5.0, 5.0]),
        temperature=np.array([20.0, 25.0]),
        accel=np.zeros((2, 3)),
    )
    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    path = "auto" if args.default else "held"
    rec = hg.simulate(gyro, prof, model="full", dt_out=1.0, fixed_step=path)
    wall = time.perf_counter() - t0
    theta = np.rad2deg(np.asarray(rec.wave_angle))
    print(
        f"full model, closed loops, {span:.0f} s simulated ({span * 5000:.3g} carrier cycles, "
        f"{int(span * 5000 * 10):.3g} steps): {wall:.1f} s wall (compile included), "
        f"{wall / span * 1e3:.1f} ms per simulated second; final wave angle {theta[-1]:.6f}°"
    )
    if span <= 60:
        ref = hg.simulate(gyro, prof, model="full", dt_out=1.0, max_steps=2**23, fixed_step=None)
        d = np.max(np.abs(theta - np.rad2deg(np.asarray(ref.wave_angle))))
        print(f"adaptive Dopri8 rtol 1e-8 on the same run: max |Δθ| = {d:.2e}°")
    report(
        f"full model, closed loops, {span:.0f} s simulated, fixed_step={path!r}",
        wall,
        "s",
        "wall time / 600 s",
        wall / 600.0,
        "≤ 1 (10 min) for 3600 s",
    )


if __name__ == "__main__":
    main()
