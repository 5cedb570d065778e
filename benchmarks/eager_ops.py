"""First calls of set-up and post-processing functions, before and after `fused` (issue 45).

Called outside a trace, each `jax.numpy` operation is an XLA program of its own, compiled on
its first call with each new shape (≈ 20–40 ms on a CPU). Functions a script calls eagerly —
trajectory builders, error matrices, alignment, per-τ deviations — paid that for every
operation; `hrgjax._compiled.fused` compiles each as one program. This script times the
*first* call of each case in a fresh process (set-up excluded, XLA's default flags, compile
cache off), on this tree and on an earlier commit checked out beside it (`git worktree`),
and prints both with their ratio. Best of `--repeat` fresh processes per case and tree.

Usage: `.venv/bin/python benchmarks/eager_ops.py [--before REV] [--repeat N]`
(default REV: 7e2e598, the last commit before `fused`).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from _common import machine

ROOT = Path(__file__).resolve().parents[1]

SETUP = """
import time, jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
"""

CASES = {
    "stationary trajectory, 60 s at 1 Hz (ins.trajectory.stationary)": (
        "from hrgjax.ins import trajectory as tr",
        "tr.stationary(45.0, duration_s=60.0)",
    ),
    "15-state discretisation along it (ins.strapdown.discretise)": (
        "from hrgjax.ins import trajectory as tr, strapdown as sd\n"
        "traj = tr.stationary(45.0, duration_s=60.0); imu = sd.ImuErrors(1e-7, 1e-4, 1e-6, 1e-5)",
        "sd.discretise(traj, imu)",
    ),
    "navigation errors of a 500-epoch history (ins.mechanization.navigation_errors)": (
        "from hrgjax.ins import mechanization as me\n"
        "n = 500; q = me.euler_to_quat(np.zeros(n), np.zeros(n), np.linspace(0, 1, n))\n"
        "a = me.NavState(jnp.full(n, 0.7), jnp.zeros(n), jnp.zeros(n), jnp.zeros((n, 3)), q)\n"
        "b = me.NavState(a.lat + 1e-7, a.lon, a.h + 1.0, a.v_ned + 0.1, q)",
        "me.navigation_errors(b, a)",
    ),
    "Van Loan discretisation, 15 states (kalman.van_loan)": (
        "from hrgjax import kalman\nF = np.eye(15) * -0.1; Q = np.eye(15) * 1e-6",
        "kalman.van_loan(F, Q, 0.5)",
    ),
    "vibration features of a 20-s record at 200 Hz (fog.spectrum.vibration_features)": (
        "from hrgjax.fog.spectrum import vibration_features\n"
        "a = np.random.default_rng(0).normal(size=(4000, 3))",
        "vibration_features(a, 200.0, 2.0)",
    ),
    "overlapping Allan deviation at m = 8 of 4 096 samples (allan.deviations.oadev)": (
        "from hrgjax.allan import deviations as dv\ny = np.random.default_rng(0).normal(size=4096)",
        "dv.oadev(y, 8, 0.1)",
    ),
    "total deviation at m = 8 of 1 024 samples (allan.deviations.totdev)": (
        "from hrgjax.allan import deviations as dv\ny = np.random.default_rng(0).normal(size=1024)",
        "dv.totdev(y, 8, 0.1)",
    ),
}


def first_call(tree, setup, call):
    code = (
        SETUP
        + setup
        + f"\nt0 = time.perf_counter(); jax.block_until_ready({call}); "
        + "print(time.perf_counter() - t0)"
    )
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env |= {"PYTHONPATH": str(tree), "HRGJAX_NO_CACHE": "1", "JAX_ENABLE_COMPILATION_CACHE": "0"}
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=tree, capture_output=True,
                         text=True, check=True)  # fmt: skip
    return float(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default="7e2e598")
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    print(machine())
    with tempfile.TemporaryDirectory(dir=ROOT / "out" if (ROOT / "out").is_dir() else None) as d:
        old = Path(d) / "before"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(old),
                        args.before], check=True)  # fmt: skip
        try:
            rows = []
            for name, (setup, call) in CASES.items():
                t_old = min(first_call(old, setup, call) for _ in range(args.repeat))
                t_new = min(first_call(ROOT, setup, call) for _ in range(args.repeat))
                rows.append({"case": name, "before_s": t_old, "after_s": t_new})
                print(f"{name}\n    first call {t_old * 1e3:8.1f} ms -> {t_new * 1e3:8.1f} ms"
                      f"  ({t_old / t_new:.1f}x faster)", flush=True)  # fmt: skip
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(old)],
                           check=False)  # fmt: skip
    out = ROOT / "out" / "eager_ops.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"before": args.before, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
