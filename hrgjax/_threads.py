"""XLA:CPU's intra-op thread pool, made safe before JAX's CPU backend starts.

With jaxlib 0.10 on a machine with few cores (two, as on CI runners), a compiled program
whose batched LAPACK kernels (a `vmap`ped `jnp.linalg.solve`, e.g. `resonator.slow`'s Newton
steps) run on every thread of XLA's Eigen pool at once can wait forever: each kernel splits
its batch onto the same pool and blocks until the pieces finish, and no thread is left to
run them. The process then sits idle with every thread in a futex wait, for ever (seen here
in a `make test` that stopped at 469 of 470 tests; the native stack shows the two
`tf_XLAEigen` threads inside `LuDecomposition` → `ParallelBatchMap`). The same wedge is
reported upstream for other pool-splitting kernels, with this flag as the fix
(`--xla_cpu_multi_thread_eigen=false`: single-threaded Eigen inside each op; ops of one
program still run in parallel).

The library itself never changes process-wide settings: `single_threaded_eigen` is called
by the `hrgjax` command, the test suite and the benchmarks, which own their processes. A
user's own script may call it (`hg.single_threaded_eigen()`) first thing, before any JAX
work, or set
`XLA_FLAGS=--xla_cpu_multi_thread_eigen=false` in the environment.
"""

from __future__ import annotations

import os

FLAG = "--xla_cpu_multi_thread_eigen=false"


def single_threaded_eigen(environ=None) -> bool:
    """Add `FLAG` to `XLA_FLAGS` unless it names `xla_cpu_multi_thread_eigen` already (a
    choice made there is kept). Takes effect only when called before JAX's first
    computation in this process (its CPU backend reads XLA_FLAGS once, when it starts), and
    in every process started after it with this environment.

    **Arguments:** `environ`, the mapping to change (default `os.environ`).

    **Returns:** True when the flag was added, False when XLA_FLAGS already chose.
    """
    env = os.environ if environ is None else environ
    flags = env.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" in flags:
        return False
    env["XLA_FLAGS"] = f"{flags} {FLAG}".strip()
    return True
