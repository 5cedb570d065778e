"""Long eager `hg.simulate` runs solve in parts behind a progress bar
(`hrgjax._solve_parts`): the cost of that, side by side with the one-program solve, and the
check that both give the same record bit for bit (noise included; XLA's default flags).

Usage: `.venv/bin/python benchmarks/simulate_progress.py [HOURS_BELOW] [HOURS_ABOVE]`
(default 2 h and 72 h of the default gyro at rest, noisy, 10 Hz output; the threshold
`hrgjax._solve_parts.STEPPED_FROM` is 2^20 samples ≈ 29 h). Each run is timed warm: its
programs compiled by a first call, then one timed call.
"""

import importlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402
import hrgjax._solve_parts as parts  # noqa: E402

simulate = importlib.import_module("hrgjax.simulate").simulate_with_stats
ONE_PROGRAM = 1 << 62


def timed(gyro, profile, stepped_from):
    parts.STEPPED_FROM = stepped_from
    best, out = None, None
    for _ in range(2):  # the first compiles
        t0 = time.perf_counter()
        out = simulate(gyro, profile, key=jax.random.key(0))
        jax.block_until_ready(out[0].wave_angle)
        best = time.perf_counter() - t0
    return best, out


def main(below=2.0, above=72.0):
    default = parts.STEPPED_FROM
    gyro = hg.presets.tvg3_like()
    for hours in (below, above):
        profile = hg.Profile.static(hours * 3600.0)
        n = int(hours * 36000) + 1
        t_one, one = timed(gyro, profile, ONE_PROGRAM)
        t_parts, stepped = timed(gyro, profile, 1)
        leaves = jax.tree_util.tree_leaves
        same = all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
                   for a, b in zip(leaves(one[0]), leaves(stepped[0]), strict=True))  # fmt: skip
        path = "parts" if n >= default else "one program"
        print(f"{hours:g} h ({n} samples, {int(one[1])} steps; default path: {path}): one "
              f"program {t_one:.2f} s, in parts {t_parts:.2f} s (ratio {t_parts / t_one:.2f}); "
              f"bit-identical: {same}, steps "
              f"{int(one[1])} / {int(stepped[1])}")  # fmt: skip
    parts.STEPPED_FROM = default


if __name__ == "__main__":
    main(*map(float, sys.argv[1:3]))
