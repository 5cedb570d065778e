"""Peak host memory of one `hg.simulate` per output sample, beside what the finished record
holds (scale audit 2026-11-30: the size guard's message said ≈ 100 bytes a sample).

    .venv/bin/python benchmarks/simulate_memory.py [--hours 1 2] [--dt 0.01]

Each size runs in its own process (peak RSS from `resource`, the process's high-water mark);
the slope between two sizes removes the interpreter's and the compiled programs' baseline.
Prints the record's bytes a sample, each size's peak, and the slope, which
`hrgjax.plausible.PEAK_BYTES_PER_SAMPLE` states."""

from __future__ import annotations

import argparse
import subprocess
import sys

CHILD = r"""
import resource, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import hrgjax as hg
hours, dt = float(sys.argv[1]), float(sys.argv[2])
prof = hg.Profile.static(duration_s=hours * 3600.0, temperature_c=20.0)
rec = hg.simulate(hg.presets.tvg3_like(), prof, key=jax.random.key(0), dt_out=dt)
jax.block_until_ready(rec)
n = rec.t.shape[0]
held = sum(np.asarray(x).nbytes for x in jax.tree_util.tree_leaves(rec)
           if hasattr(x, "shape") and x.shape and x.shape[0] == n)
print(n, held, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024)
"""


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hours", type=float, nargs=2, default=(1.0, 2.0))
    p.add_argument("--dt", type=float, default=0.01, help="dt_out [s]")
    args = p.parse_args()
    rows = []
    for h in args.hours:
        out = subprocess.run([sys.executable, "-c", CHILD, str(h), str(args.dt)], check=True,
                             capture_output=True, text=True).stdout.split()  # fmt: skip
        n, held, peak = int(out[0]), int(out[1]), int(out[2])
        rows.append((n, peak))
        print(f"{h:g} h at dt_out {args.dt:g} s: {n} samples, record {held / n:.0f} B/sample, "
              f"peak RSS {peak / 2**20:.0f} MiB")  # fmt: skip
    (n0, p0), (n1, p1) = rows
    print(f"peak slope: {(p1 - p0) / (n1 - n0):.0f} bytes per output sample")


if __name__ == "__main__":
    main()
