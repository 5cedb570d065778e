"""Shared benchmark helpers: x64 on, timing with warm-up and block_until_ready, and `report`,
which prints a figure and, under `benchmarks/run_all.py`, records it for the summary."""

import atexit
import json
import os
import platform
import time

from hrgjax._threads import widen_cpu_thread_pool

widen_cpu_thread_pool()  # before any JAX work (hrgjax/_threads.py: XLA:CPU's pool on 2 cores)

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

_FIGURES: list[dict] = []
_SINK = os.environ.get("HRGJAX_BENCH_OUT")  # set by run_all.py: where the figures go


def machine() -> str:
    dev = jax.devices()[0]
    return f"{platform.processor() or platform.machine()}, {jax.device_count()}× {dev.device_kind}, jax {jax.__version__}"


def best_of(fn, repeat=5):
    """Best wall time [s] of `repeat` calls of fn (already compiled), each blocked until ready."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return min(times)


def first_call(fn):
    """Wall time [s] of the first call (compile + run) and its result."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return time.perf_counter() - t0, out


def report(figure: str, value, unit: str, comparison: str = "", ratio=None, target: str = ""):
    """One headline figure: printed now, and kept for `run_all.py`'s summary.

    `comparison` names what `ratio` compares (e.g. "gradient / forward", "vs scipy RK45");
    `target` is the issue's target in words ("≤ 2×"), empty where there is none."""
    row = {
        "figure": figure,
        "value": None if value is None else float(value),
        "unit": unit,
        "comparison": comparison,
        "ratio": None if ratio is None else float(ratio),
        "target": target,
    }
    _FIGURES.append(row)
    shown = "n/a" if value is None else f"{float(value):.6g}"
    extra = f"  [{comparison}: {float(ratio):.3g}]" if ratio is not None else ""
    print(f"FIGURE {figure}: {shown} {unit}{extra}" + (f"  target {target}" if target else ""))


def _write():
    if _SINK and _FIGURES:
        with open(_SINK, "w") as f:
            json.dump(_FIGURES, f, indent=2)


atexit.register(_write)


def child_or_main(child, main):
    """A script that runs parts of itself in child processes (`--child OUT`, one backend or
    device count each): `child(OUT)` in a child, `main()` in the parent."""
    import sys

    if "--child" in sys.argv:
        child(sys.argv[sys.argv.index("--child") + 1])
    else:
        main()
