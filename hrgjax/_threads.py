"""XLA:CPU's intra-op thread pool, widened before JAX's CPU backend starts.

With jaxlib 0.10 on a machine with few cores (two, as on CI runners), a compiled program can
wait for ever: XLA runs its operations on a pool of one thread per core (`tf_XLAEigen`), and
a batched LAPACK kernel (a `vmap`ped `jnp.linalg.solve`, e.g. `resonator.slow`'s Newton
steps under the grey box's `scale_factor_at`) splits its batch onto that same pool and
blocks until the pieces finish. When every thread of the pool is such a blocked kernel, no
thread is left to run the pieces: the process sits idle, every thread in a futex wait. Seen
twice in `tests/test_loops_plant.py` (a `make test` held at 469 of 470 tests until CI's
limit); the native stacks show both `tf_XLAEigen` threads inside `LuDecomposition` →
`ParallelBatchMap`. XLA's `--xla_cpu_multi_thread_eigen=false` did not prevent it (the pool
stays, and the kernels still split onto it).

XLA sizes that pool from `PJRT_NPROC` (else `NPROC`, else the core count). With at least
`MIN_THREADS` threads, the pool can only wedge when that many batched kernels block at
once (the wedges seen had two). Threads beyond the cores cost some time on a small machine
(`benchmarks/thread_pool.py`, 2 cores: one `simulate` 1.0×, a 32-run `vmap` 1.08–1.12×);
on 8 cores or more nothing changes.

Where the wedge was seen, the library no longer depends on this: the slow manifold and the
Kalman filters (`kalman`, the INS filter behind `ins.flights.fly`, whose twenty flights wedged
a two-thread pool in `lapack_dtrsm_ffi` → `ParallelBatchMap`, and the diagnosis filter bank)
factorise their small matrices in plain XLA operations (`hrgjax/_linalg.py`), which a pool
of any size runs. What still batches a LAPACK kernel runs one at a time: `ins.strapdown`'s
discretisation (one LU and its solves per step, `kalman.van_loan` under `vmap`) and its
Monte Carlo (one eigen-decomposition of every factor). The wider pool guards those and a
user's own `vmap`ped LAPACK calls.

The library itself never changes process-wide settings: `widen_cpu_thread_pool` is called
by the `hrgjax` command, the test suite and the benchmarks, which own their processes. A
user's script may call it (`hg.widen_cpu_thread_pool()`) first thing, before any JAX work,
or export `PJRT_NPROC=8`.
"""

from __future__ import annotations

import os

MIN_THREADS = 8
"""Threads in XLA:CPU's pool at least (more where the machine has more cores)."""


def widen_cpu_thread_pool(environ=None) -> bool:
    """Set `PJRT_NPROC` to max(cores, `MIN_THREADS`) unless `PJRT_NPROC` or `NPROC` is set
    already (a choice made there is kept). Takes effect only when called before JAX's first
    computation in this process (its CPU backend reads it once, when it starts), and in every
    process started after it with this environment.

    **Arguments:** `environ`, the mapping to change (default `os.environ`).

    **Returns:** True when it was set, False when the environment already chose.
    """
    env = os.environ if environ is None else environ
    if env.get("PJRT_NPROC") or env.get("NPROC"):
        return False
    env["PJRT_NPROC"] = str(max(os.cpu_count() or 1, MIN_THREADS))
    return True
