"""The test suite's quick-compile XLA flags (tests/conftest.py, issue 45): what they save and
what they cost, side by side in one run.

Each program is compiled and run in a child process twice, once with XLA's defaults and once
with `QUICK_COMPILE_FLAGS` (the flags are read when JAX's CPU backend starts, so a process
has one setting): the averaged model (PI loops, 20 s, 201 outputs) and the carrier-resolving
model (50 ms on fixed steps). Printed per program: trace + lower, compile and one run
(best of 3) in both settings, and the ratios. With `--tests FILE…` the given test files are
also run under pytest in both settings (one process each, no xdist), wall time and ratio.

Usage: `.venv/bin/python benchmarks/compile_flags.py [--tests tests/test_x.py …]`
"""

import argparse
import ast
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _conftest_flags() -> tuple:
    """`QUICK_COMPILE_FLAGS` as tests/conftest.py writes it (read, not imported: importing it
    would set them in this process's environment)."""
    tree = ast.parse((ROOT / "tests" / "conftest.py").read_text())
    for node in tree.body:
        target = node.targets[0] if isinstance(node, ast.Assign) else None
        if isinstance(target, ast.Name) and target.id == "QUICK_COMPILE_FLAGS":
            return ast.literal_eval(node.value)
    raise LookupError("tests/conftest.py: no QUICK_COMPILE_FLAGS")


QUICK_COMPILE_FLAGS = _conftest_flags()

CHILD = r"""
import json, os, time
from hrgjax._threads import widen_cpu_thread_pool
widen_cpu_thread_pool()
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import hrgjax as hg
gyro = hg.presets.tvg3_like(noise=False)
cases = {
    "averaged, PI loops, 20 s": (hg.Profile.constant_rate(10.0, 20.0), jnp.linspace(0, 20, 201), {}),
    "full (carrier), 50 ms": (hg.Profile.constant_rate(10.0, 0.05), jnp.linspace(0, 0.05, 51),
                              {"model": "full"}),
}
out = {}
for name, (prof, ts, kw) in cases.items():
    fn = jax.jit(lambda g: hg.simulate(g, prof, ts=ts, **kw).true_wave_angle)
    t0 = time.perf_counter(); low = fn.lower(gyro); t1 = time.perf_counter()
    run = low.compile(); t2 = time.perf_counter()
    run(gyro).block_until_ready()
    best = 1e9
    for _ in range(3):
        t3 = time.perf_counter(); run(gyro).block_until_ready(); best = min(best, time.perf_counter() - t3)
    out[name] = (t1 - t0, t2 - t1, best)
print("RESULT " + json.dumps(out))
"""


def without_quick_flags(flags: str) -> str:
    names = {f.split("=")[0] for f in QUICK_COMPILE_FLAGS}
    return " ".join(f for f in flags.split() if f.split("=")[0] not in names)


def child_env(quick: bool) -> dict:
    env = dict(os.environ, HRGJAX_NO_CACHE="1")
    env.pop("HRGJAX_TEST_COMPILE_FLAGS", None)
    env["XLA_FLAGS"] = without_quick_flags(env.get("XLA_FLAGS", ""))
    if quick:
        env["XLA_FLAGS"] = f"{env['XLA_FLAGS']} {' '.join(QUICK_COMPILE_FLAGS)}".strip()
    return env


def programs() -> None:
    res = {}
    for quick in (False, True):
        out = subprocess.run([sys.executable, "-c", CHILD], env=child_env(quick), cwd=ROOT,
                             capture_output=True, text=True, check=True)  # fmt: skip
        line = next(ln for ln in out.stdout.splitlines() if ln.startswith("RESULT "))
        res[quick] = json.loads(line[len("RESULT ") :])
    print(f"quick-compile flags: {' '.join(QUICK_COMPILE_FLAGS)}")
    print(f"{'program':28s} {'setting':8s} {'trace+lower':>11s} {'compile':>9s} {'run':>10s}")
    for name in res[False]:
        for quick in (False, True):
            lo, co, run = res[quick][name]
            label = "quick" if quick else "default"
            print(f"{name:28s} {label:8s} {lo:10.2f}s {co:8.2f}s {run * 1e3:8.2f}ms")
        d, q = res[False][name], res[True][name]
        print(f"{'':28s} {'ratio':8s} {q[0] / d[0]:10.2f}× {q[1] / d[1]:8.2f}× {q[2] / d[2]:9.2f}×"
              "  (quick / default)")  # fmt: skip


def suite(files) -> None:
    walls = {}
    for quick in (False, True):
        env = dict(os.environ, XLA_FLAGS=without_quick_flags(os.environ.get("XLA_FLAGS", "")))
        env.pop("HRGJAX_TEST_FULL", None)  # the full tier keeps XLA's defaults
        if quick:
            env.pop("HRGJAX_TEST_COMPILE_FLAGS", None)
        else:
            env["HRGJAX_TEST_COMPILE_FLAGS"] = ""  # conftest: leave XLA's defaults
        t0 = time.perf_counter()
        out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                              *files], env=env, cwd=ROOT, capture_output=True, text=True)  # fmt: skip
        walls[quick] = time.perf_counter() - t0
        last = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else "?"
        print(f"tests, {'quick' if quick else 'default'}: {walls[quick]:.0f} s ({last})")
    print(f"tests, quick / default: {walls[True] / walls[False]:.2f}×")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tests", nargs="*", default=[], help="test files to run in both settings")
    args = ap.parse_args()
    programs()
    if args.tests:
        suite(args.tests)
