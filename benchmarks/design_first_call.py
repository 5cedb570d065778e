"""Time to a designed plan in a fresh process: `design(budget)` as the session's first call,
compiling included, and how many times it compiled the Adam-step program (one per
structure is right); then a second `design(budget)` in the same process (another key: the
compiled programs reused). Runs in a subprocess with the persistent compilation cache off.

Usage: `.venv/bin/python benchmarks/design_first_call.py [--budget-h 12]`. To compare two
versions of the code, run it on each, back to back on one machine (benchmarks/README.md)."""

import argparse
import os
import subprocess
import sys

CHILD = """
import time, jax
jax.config.update("jax_enable_x64", True)
names = []
jax.monitoring.register_event_duration_secs_listener(
    lambda e, d, **k: names.append(k.get("fun_name"))
    if e == "/jax/core/compile/backend_compile_duration" else None)
from hrgjax.calibration import design as d
t0 = time.perf_counter()
r = d.design({budget})
dt = time.perf_counter() - t0
print(f"RESULT {{dt:.1f}} {{r.value:.8g}} {{r.levels}} {{len(r.search)}} "
      f"{{names.count('jit(_design_step)')}} {{len(names)}}")
t0 = time.perf_counter()
r = d.design({budget}, key=jax.random.key(1))
print(f"SECOND {{time.perf_counter() - t0:.1f}} {{r.value:.8g}}")
"""


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget-h", type=float, default=12.0)
    a = ap.parse_args()
    env = {**os.environ, "HRGJAX_NO_CACHE": "1"}
    out = subprocess.run([sys.executable, "-c", CHILD.format(budget=a.budget_h)], env=env,
                         capture_output=True, text=True, check=True).stdout  # fmt: skip
    line = next(x for x in out.splitlines() if x.startswith("RESULT"))
    second, second_value = next(x for x in out.splitlines() if x.startswith("SECOND")).split()[1:]
    wall, value, levels, structures, steps, compiles = line.split()[1:]
    from _common import machine, report

    print(f"machine: {machine()}")
    print(
        f"design({a.budget_h:g}) as a fresh process's first call: {wall} s; criterion "
        f"{value} (drift+warmup [°]), {levels} levels chosen of {structures} structures"
    )
    print(
        f"a second design({a.budget_h:g}) in that process (key 1): {second} s; criterion {second_value}"
    )
    print(
        f"Adam-step programs compiled: {steps} (one per structure: {structures}); "
        f"XLA compiles in all: {compiles}"
    )
    report(
        f"first design({a.budget_h:g}) in a fresh process",
        float(wall),
        "s",
        "Adam-step compiles per structure",
        int(steps) / int(structures),
        "1",
    )


if __name__ == "__main__":
    main()
