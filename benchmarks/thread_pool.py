"""XLA:CPU's pool at the core count (XLA's default) and widened (`hg.widen_cpu_thread_pool`,
max(cores, 8) threads), side by side on the same machine: does the wider pool cost time?

Each setting runs in its own process (the pool is sized when JAX's CPU backend starts):
one `hg.simulate` of the default gyro (10 min static, 1-s output), a 32-member `vmap`
of it, and the grey box's slow-manifold rate (`resonator.slow.reduced_rate`, the batched
LAPACK kernels that once wedged a 2-core pool) on 64 angles; best of 5 after the compile.

    .venv/bin/python benchmarks/thread_pool.py      # about 1 minute
"""

import json
import os
import subprocess
import sys

from _common import report

CHILD = r"""
import json, sys, time
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
import hrgjax as hg
from hrgjax.resonator.slow import reduced_rate

def best(fn, repeat=5):
    jax.block_until_ready(fn())
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter(); jax.block_until_ready(fn()); out.append(time.perf_counter() - t0)
    return min(out)

gyro = hg.presets.tvg3_like(noise=False)
one = jax.jit(lambda t: hg.simulate(gyro, hg.Profile.static(600.0, t), dt_out=1.0).wave_angle)
many = jax.jit(jax.vmap(one))
temps = jnp.linspace(-40.0, 60.0, 32)
g = gyro.at(20.0)
rates = jax.jit(jax.vmap(lambda th: reduced_rate(g, 0.1, th)))
angles = jnp.linspace(-1.5, 1.5, 64)
print(json.dumps({
    "simulate": best(lambda: one(20.0)),
    "vmap32": best(lambda: many(temps)),
    "slow_manifold64": best(lambda: rates(angles)),
}))
"""


def run(nproc):
    env = {k: v for k, v in os.environ.items() if k not in ("PJRT_NPROC", "NPROC")}
    if nproc is not None:
        env["PJRT_NPROC"] = str(nproc)
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True,
                         text=True, check=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    from hrgjax._threads import MIN_THREADS

    cores = os.cpu_count() or 1
    wide = max(cores, MIN_THREADS)
    base, widened = run(None), run(wide)
    print(f"{cores} cores: XLA's pool {cores} threads (default) vs {wide} (widened)")
    for name in base:
        print(f"{name}: {1e3 * base[name]:.2f} ms (default) → {1e3 * widened[name]:.2f} ms")
        report(f"{name}, widened pool", 1e3 * widened[name], "ms", "widened / default",
               widened[name] / base[name], "≈ 1")  # fmt: skip


if __name__ == "__main__":
    main()
