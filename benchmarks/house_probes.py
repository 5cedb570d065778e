"""Two costs behind `make test`'s time (issue 45), each measured in fresh processes:

- **a `jnp` ufunc inside a trace** against the `lax` primitive: `jax.make_jaxpr` of 2 000
  repetitions of `sin(x)·c + cos(x)` (8 000 operations) written both ways;
- **a process's exit** with N small compiled programs held (what an xdist worker that
  compiled thousands spent freeing them before the run could end; `tests/conftest.py` now
  leaves without that teardown): the time from the last line of the script to the process's
  end, for N = 50 and 400;
- **exporting a program** (`hrgjax._export`, what lets a later process skip the trace): a
  first `hg.simulate` with the compile cache off against one into an empty cache folder,
  with JAX's trace, lowering and compile events, under the tests' quick-compile flags.

Usage: `.venv/bin/python benchmarks/house_probes.py` (≈ 1 min on 2 cores).
"""

import subprocess
import sys
import time

TRACE = """
import time, jax, jax.numpy as jnp
from jax import lax
jax.config.update("jax_enable_x64", True)
def with_jnp(x):
    for _ in range(2000):
        x = jnp.sin(x) * 1.0001 + jnp.cos(x)
    return x
def with_lax(x):
    for _ in range(2000):
        x = lax.add(lax.mul(lax.sin(x), 1.0001), lax.cos(x))
    return x
x = jnp.ones(3)
for f in (with_jnp, with_lax):
    t = time.perf_counter(); jax.make_jaxpr(f)(x); print(f.__name__, time.perf_counter() - t)
"""

EXIT = """
import sys, time, jax, jax.numpy as jnp
fs = []
for i in range(int(sys.argv[1])):
    f = jax.jit(lambda x, i=i: jnp.sin(x * i) + jnp.cos(x) ** i)
    f(jnp.ones(i + 1)).block_until_ready()
    fs.append(f)
print(time.time(), flush=True)
"""


FIRST = """
import time, jax, os
jax.config.update("jax_enable_x64", True)
import hrgjax as hg, jax.monitoring
if os.environ.get("HRGJAX_NO_CACHE") != "1":
    hg.enable_cache()
ev = {}
jax.monitoring.register_event_duration_secs_listener(
    lambda e, d, **k: ev.__setitem__(e.split("/")[-1], ev.get(e.split("/")[-1], 0.0) + d))
g = hg.presets.tvg3_like(noise=False)
t = time.perf_counter()
hg.simulate(g, hg.Profile.constant_rate(10.0, 20.0, temperature_c=0.0), dt_out=0.5)
print(time.perf_counter() - t, ev.get("jaxpr_to_mlir_module_duration", 0.0),
      ev.get("backend_compile_duration", 0.0))
"""
QUICK = (
    "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0 "
    "--xla_llvm_disable_expensive_passes=true"
)


def first_call(env):
    import os

    full = {k: v for k, v in os.environ.items() if not k.startswith("HRGJAX_")}
    full.update(env, XLA_FLAGS=QUICK)
    out = subprocess.run([sys.executable, "-c", FIRST], env=full, capture_output=True,
                         text=True, check=True).stdout.split()  # fmt: skip
    return [float(x) for x in out]


def main():
    sys.path.insert(0, __file__.rsplit("/", 1)[0])
    from _common import machine

    print(f"machine: {machine()}")
    out = subprocess.run([sys.executable, "-c", TRACE], capture_output=True, text=True,
                         check=True).stdout.split()  # fmt: skip
    t_jnp, t_lax = float(out[1]), float(out[3])
    print(f"make_jaxpr of 8 000 operations: jnp {t_jnp * 1e3:.0f} ms, lax {t_lax * 1e3:.0f} ms: "
          f"{(t_jnp - t_lax) / 8000 * 1e6:.1f} µs more an operation with jnp")  # fmt: skip
    for n in (50, 400):
        proc = subprocess.Popen([sys.executable, "-c", EXIT, str(n)], stdout=subprocess.PIPE,
                                text=True)  # fmt: skip
        last = float(proc.stdout.readline())
        proc.wait()
        print(f"exit with {n:3d} compiled programs held: {time.time() - last:.2f} s")
    import tempfile

    for _ in range(2):
        off = first_call({"HRGJAX_NO_CACHE": "1"})
        with tempfile.TemporaryDirectory() as folder:
            cold = first_call({"HRGJAX_CACHE_DIR": folder})
        print(f"first simulate: cache off {off[0]:.2f} s (lowering {off[1]:.2f}, compile "
              f"{off[2]:.2f}), exported into an empty cache {cold[0]:.2f} s (lowering "
              f"{cold[1]:.2f}, compile {cold[2]:.2f}): {cold[0] - off[0]:+.2f} s")  # fmt: skip


if __name__ == "__main__":
    main()
