"""Time to answer: commands and first calls, cold and warm, as ratios to importing JAX.

`.venv/bin/python benchmarks/latency.py [--quick] [--full-demo]`

Every figure is a ratio to the time of `python -c "import jax, diffrax, equinox, optax,
optimistix"` measured in the same run (the machines vary 2–5× from day to day; the ratio
does not). Commands run as a user runs them, each in a fresh process; "cold" uses an empty
compile cache folder, "warm" the same folder again.

- `hrgjax --help`;
- `hrgjax simulate --preset tvg3 --plan static`, cold and warm;
- `hrgjax demo --quick`, cold and warm, with the number of XLA compilations of the warm run
  (compile requests the cache did not answer);
- the first `simulate` in a process with a warm cache, against the same call compiled;
- a second identical `hg.sweep` against `jax.jit(jax.vmap(…))` compiled;
- `allan_deviation` on 10⁶ samples (all octave factors): the one-program curve against the
  former one-program-per-factor loop;
- `--full-demo`: the full `hrgjax demo` on a cold cache (minutes).

`--quick` repeats each timing once instead of three times (best of).
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from _common import report

HERE = Path(__file__).resolve().parent
_CLI = Path(sys.executable).with_name("hrgjax")
CLI = [str(_CLI)] if _CLI.exists() else [sys.executable, "-m", "hrgjax.cli"]

# Counts XLA compilations the persistent cache did not answer, printed at exit.
_COUNTING = textwrap.dedent(
    """
    import atexit, sys, collections
    import jax.monitoring as mon
    seen = collections.Counter()
    mon.register_event_duration_secs_listener(lambda e, d, **k: seen.update([e]))
    mon.register_event_listener(lambda e, **k: seen.update([e]))
    atexit.register(lambda: print(
        "XLA_COMPILES", seen["/jax/core/compile/backend_compile_duration"]
        - seen["/jax/compilation_cache/cache_hits"], file=sys.stderr))
    from hrgjax.cli import main
    sys.exit(main(sys.argv[1:]))
    """
)


def timed(argv, env, repeat=1):
    """Best wall time [s] of `repeat` runs of argv, and the last run's output."""
    best, out = float("inf"), ""
    for _ in range(repeat):
        t0 = time.perf_counter()
        proc = subprocess.run(argv, env=env, capture_output=True, text=True)
        best = min(best, time.perf_counter() - t0)
        out = proc.stdout + proc.stderr
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(argv)} failed:\n{out[-3000:]}")
    return best, out


def compiles(output: str):
    lines = [ln for ln in output.splitlines() if ln.startswith("XLA_COMPILES")]
    return int(lines[-1].split()[1]) if lines else None


_FIRST_CALL = textwrap.dedent(
    """
    import time, jax
    jax.config.update("jax_enable_x64", True)
    import hrgjax as hg
    if hasattr(hg, "enable_cache"):
        hg.enable_cache()
    else:  # an hrgjax before the cache API: JAX's own cache, as its CLI did
        import os
        jax.config.update("jax_compilation_cache_dir", os.environ["XDG_CACHE_HOME"] + "/jax")
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)
    gyro = hg.presets.tvg3_like()
    prof = hg.Profile.constant_rate(5.0, 60.0, -40.0, 30.0)
    t0 = time.perf_counter()
    hg.simulate(gyro, prof, key=jax.random.key(0), dt_out=0.1).wave_angle.block_until_ready()
    first = time.perf_counter() - t0
    best = min(
        (lambda t: (hg.simulate(gyro, prof, key=jax.random.key(k), dt_out=0.1)
                    .wave_angle.block_until_ready(), time.perf_counter() - t)[1])(
            time.perf_counter())
        for k in range(1, 6))
    print("FIRST", first, "COMPILED", best)
    """
)


def main():
    if "--only-sweep-allan" in sys.argv:  # for a side-by-side run on an older checkout
        return sweep_and_allan("--quick" in sys.argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one repeat per timing")
    parser.add_argument("--full-demo", action="store_true", help="also time the full demo")
    args = parser.parse_args()
    repeat = 1 if args.quick else 3
    work = Path(tempfile.mkdtemp(prefix="hrgjax-latency-"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("HRGJAX_")}
    env.update(
        HRGJAX_CACHE_DIR=str(work / "cache"),
        XDG_CACHE_HOME=str(work / "cache"),  # where an older hrgjax kept its cache
        HRGJAX_QUIET="1",
    )
    try:
        base, _ = timed(
            [sys.executable, "-c", "import jax, diffrax, equinox, optax, optimistix"], env, 3
        )
        report("import jax + diffrax + equinox + optax + optimistix", base, "s")
        ratio = lambda s: s / base

        t, _ = timed(CLI + ["--help"], env, 3)
        report("hrgjax --help", t, "s", "/ import", ratio(t), "≤ 0.3×")

        sim = CLI + ["simulate", "--preset", "tvg3", "--plan", "static"]
        sim += ["--out", str(work / "s.csv"), "--force"]
        t, _ = timed(sim, env)
        report("hrgjax simulate --plan static, cold cache", t, "s", "/ import", ratio(t))
        t, _ = timed(sim, env, repeat)
        report(
            "hrgjax simulate --plan static, second invocation",
            t, "s", "/ import", ratio(t), "≤ 3×",
        )  # fmt: skip

        demo = [sys.executable, "-c", _COUNTING, "demo", "--quick", "--out", str(work / "d")]
        t, out = timed(demo, env)
        report("hrgjax demo --quick, cold cache", t, "s", "/ import", ratio(t))
        report("XLA compilations, demo --quick cold", compiles(out), "")
        t, out = timed(demo, env)
        report("hrgjax demo --quick, second invocation", t, "s", "/ import", ratio(t), "≤ 10×")
        report("XLA compilations, demo --quick second invocation", compiles(out), "", "", None, "0")

        # Twice: the first process meets this call's program for the first time (it compiles
        # and stores it); the second is the "warm cache" case.
        timed([sys.executable, "-c", _FIRST_CALL], env)
        _, out = timed([sys.executable, "-c", _FIRST_CALL], env)
        first, compiled = (float(x) for x in out.split("FIRST")[1].split("COMPILED"))
        report(
            "first simulate in a process (warm cache)", first, "s",
            "/ the same call compiled", first / compiled,
        )  # fmt: skip

        sweep_and_allan(args.quick)

        if args.full_demo:
            shutil.rmtree(work / "cache", ignore_errors=True)
            full = CLI + ["demo", "--out", str(work / "full")]
            t, _ = timed(full, env)
            report("hrgjax demo (full), cold cache", t, "s", "/ import", ratio(t), "≤ 3 min")
    finally:
        shutil.rmtree(work, ignore_errors=True)


def sweep_and_allan(quick):
    import jax
    import jax.numpy as jnp
    import numpy as np

    import hrgjax as hg
    from hrgjax import allan

    gyro = hg.presets.tvg3_like(noise=False)

    ts = jnp.linspace(0.0, 20.0, 5)  # explicit output times: jit-able in any hrgjax version

    def final_angle(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 20.0, temperature_c)
        return hg.simulate(gyro, prof, ts=ts).wave_angle[-1]

    n = 8 if quick else 20
    grids = dict(temperature_c=jnp.linspace(-40.0, 60.0, n), rate_dps=jnp.linspace(0.1, 50.0, n))
    jax.block_until_ready(hg.sweep(final_angle, **grids))
    t0 = time.perf_counter()
    again = jax.block_until_ready(hg.sweep(final_angle, **grids))
    second = time.perf_counter() - t0
    mesh = [m.ravel() for m in jnp.meshgrid(*grids.values(), indexing="ij")]
    ref = jax.jit(jax.vmap(final_angle))
    jax.block_until_ready(ref(*mesh))
    t0 = time.perf_counter()
    direct = jax.block_until_ready(ref(*mesh))
    compiled = time.perf_counter() - t0
    assert np.allclose(np.asarray(again).ravel(), np.asarray(direct), rtol=1e-12, atol=0)
    report(
        f"second identical {n}×{n} hg.sweep", second, "s",
        "/ jax.jit(jax.vmap) compiled", second / compiled, "≈ 1×",
    )  # fmt: skip

    y = np.random.default_rng(0).normal(size=10**5 if quick else 10**6)
    ms = [2**k for k in range(int(np.log2(len(y) // 4)) + 1)]
    for kind in ("oadev", "mdev"):
        t0 = time.perf_counter()
        curve = np.asarray(hg.allan_deviation(y, 0.01, kind=kind)[1])
        one = time.perf_counter() - t0
        t0 = time.perf_counter()
        each = np.array([float(getattr(allan, kind)(y, m, 0.01)) for m in ms])
        per_m = time.perf_counter() - t0
        assert np.allclose(curve, each, rtol=1e-10)
        report(
            f"allan_deviation {kind}, {len(y):.0e} samples, {len(ms)} factors, first call",
            one, "s", "one program per factor / one per kind", per_m / one,
        )  # fmt: skip


if __name__ == "__main__":
    main()
