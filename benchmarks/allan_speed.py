"""Allan statistics against allantools (issue 21): time side by side on one record.

10⁶ rate samples (white + random walk), an octave grid, every kind: allantools' deviation
(`at.<kind>(…, data_type="freq", taus="octave")`) against `hrgjax.allan.deviation` once
compiled, and the first call (compile included); ours also identifies the noise and computes
the EDF and intervals at every τ, which allantools' call does not. Also: a new τ grid after
the first compiles nothing (second column of the compile line).

Usage: `.venv/bin/python benchmarks/allan_speed.py [--quick]` (needs allantools, a dev extra).
"""

import sys
import time

import numpy as np
from _common import best_of, machine, report

from hrgjax import allan

try:
    import allantools as at
except ImportError:  # pragma: no cover
    sys.exit("allan_speed.py needs allantools: pip install -e '.[dev]'")


if __name__ == "__main__":
    n = 100_000 if "--quick" in sys.argv else 1_000_000
    rng = np.random.default_rng(0)
    y = rng.normal(size=n) + 1e-3 * np.cumsum(rng.normal(size=n))
    print(machine())
    print(f"{n} samples, octave grid\n")
    print(f"{'kind':>7} {'allantools [s]':>15} {'hrgjax first [s]':>17} {'hrgjax [s]':>11} "
          f"{'ratio':>6} {'max rel. diff':>14}")  # fmt: skip
    for kind in allan.KINDS:
        t0 = time.perf_counter()
        ours = allan.deviation(y, 1.0, kind=kind)
        first = time.perf_counter() - t0
        t_ours = best_of(lambda kind=kind: allan.deviation(y, 1.0, kind=kind))
        t_at = best_of(
            lambda kind=kind: getattr(at, kind)(y, rate=1.0, data_type="freq", taus="octave")
        )
        _, dev, _, _ = getattr(at, kind)(y, rate=1.0, data_type="freq", taus="octave")
        diff = float(np.max(np.abs(ours.dev / dev - 1)))
        print(
            f"{kind:>7} {t_at:>15.3f} {first:>17.2f} {t_ours:>11.3f} {t_ours / t_at:>6.2f} {diff:>14.1e}"
        )
        report(f"allan.deviation {kind}, {n} samples, octave", t_ours, "s",
               comparison="vs allantools", ratio=t_ours / t_at, target="≤ 2×")  # fmt: skip
    t0 = time.perf_counter()
    allan.deviation(y, 1.0, kind="oadev", taus=[3.0, 30.0, 300.0, 3000.0])
    print(
        f"\noadev on a new τ grid (4 τ in seconds): {time.perf_counter() - t0:.3f} s "
        "(no compile: the same program)"
    )
