"""Long eager `hg.simulate` runs solve in parts behind a progress bar
(`hrgjax._solve_parts`): the cost of that, side by side with the one-program solve, and the
check that both give the same record bit for bit (noise included; XLA's default flags).

Usage: `.venv/bin/python benchmarks/simulate_progress.py [HOURS_BELOW] [HOURS_ABOVE]`
(default 2 h and 72 h of the default gyro at rest, noisy, 10 Hz output; the threshold
`hrgjax._solve_parts.STEPPED_FROM` is 2^20 samples ≈ 29 h). Each run is timed warm: its
programs compiled by a first call, then one timed call.

`.venv/bin/python benchmarks/simulate_progress.py cases` (≈ 4 min on 2 shared cores): short
runs forced into small parts, each against the one program: an implicit solver (Kvaerno5), a
constant step longer than a part's window, and the host memory the parts' outputs hold.
"""

import importlib
import sys
import time
import types

import diffrax
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


def forced(gyro, profile, steps, outputs, **options):
    """(one program, in parts of `steps` steps and `outputs` outputs), bit-identical?"""
    saved = parts.STEPPED_FROM, parts.PART_STEPS, parts.PART_OUTPUTS
    parts.STEPPED_FROM = ONE_PROGRAM
    one = simulate(gyro, profile, **options)
    parts.STEPPED_FROM, parts.PART_STEPS, parts.PART_OUTPUTS = 1, steps, outputs
    try:
        stepped = simulate(gyro, profile, **options)
    except (ValueError, RuntimeError) as error:  # the code before the fixes: shown, not fatal
        print("  in parts, raised:", str(error).splitlines()[0][:160])
        return one, (one[0], -1), False
    finally:
        parts.STEPPED_FROM, parts.PART_STEPS, parts.PART_OUTPUTS = saved
    leaves = jax.tree_util.tree_leaves
    same = all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
               for a, b in zip(leaves(one[0]), leaves(stepped[0]), strict=True))  # fmt: skip
    return one, stepped, same


def cases():
    gyro, key = hg.presets.tvg3_like(), jax.random.key(7)
    knots = hg.Profile.piecewise([0.0, 40.0, 90.0, 200.0], [0.0, 20.0, 20.0, -5.0], 25.0)
    for name, solver in (("Tsit5 (default)", None), ("Kvaerno5", diffrax.Kvaerno5())):
        options = dict(key=key, dt_out=0.05) | ({} if solver is None else dict(solver=solver))
        one, stepped, same = forced(gyro, knots, 40, 256, **options)
        print(f"{name}, 200 s noisy, 3 knots, parts of 40 steps / 256 outputs: steps "
              f"{int(one[1])} / {int(stepped[1])}, bit-identical: {same}")  # fmt: skip
    profile = hg.Profile.piecewise([0.0, 40.0, 90.0, 100.0], [0.0, 20.0, 20.0, -5.0], 25.0)
    for step in (1.0, 0.16):
        one, stepped, same = forced(gyro, profile, 40, 16, key=key, dt_out=0.01, fixed_step=step)
        print(f"fixed_step={step} s, dt_out 0.01 s, parts of 16 outputs: steps "
              f"{int(one[1])} / {int(stepped[1])}, bit-identical: {same}")  # fmt: skip
    held = []  # the arrays run_parts joins, and the buffers they keep alive

    def concatenate(arrays, *args, **kwargs):
        if len(arrays) > 2:  # the parts' outputs (not a window padded: 2 arrays)
            held.extend(arrays)
        return np.concatenate(arrays, *args, **kwargs)

    parts.np = types.SimpleNamespace(**{**vars(np), "concatenate": concatenate})
    try:
        profile = hg.Profile.piecewise([0.0, 0.02, 0.05], [0.0, 50.0, 50.0], 25.0)
        forced(gyro.without_noise(), profile, 200, 4096, model="full", fixed_step=None,
               dt_out=2e-5)  # fmt: skip
    finally:
        parts.np = np
    buffers = {}
    for a in held:
        while isinstance(a.base, np.ndarray):
            a = a.base
        buffers[id(a)] = a.nbytes
    print(f"full model, 0.05 s at 50 kHz out, parts of 200 steps / 4096 outputs: "
          f"{len(held)} parts' outputs, {sum(a.nbytes for a in held)} B needed, "
          f"{sum(buffers.values())} B held")  # fmt: skip


if __name__ == "__main__":
    if sys.argv[1:2] == ["cases"]:
        cases()
    else:
        main(*map(float, sys.argv[1:3]))
