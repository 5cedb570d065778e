"""`hrgjax._threads`: XLA:CPU's thread pool widened so batched LAPACK kernels cannot wedge it."""

import os
import subprocess
import sys

import pytest

from hrgjax._threads import MIN_THREADS, widen_cpu_thread_pool


def test_the_pool_size_is_set_once_and_a_choice_already_made_is_kept():
    env = {}
    assert widen_cpu_thread_pool(env)
    assert int(env["PJRT_NPROC"]) == max(os.cpu_count() or 1, MIN_THREADS)
    assert not widen_cpu_thread_pool(env)
    for mine in ({"PJRT_NPROC": "3"}, {"NPROC": "3"}):
        env = dict(mine)
        assert not widen_cpu_thread_pool(env) and env == mine
    # the suite itself (tests/conftest.py) runs with it, and so do the processes it starts
    assert int(os.environ["PJRT_NPROC"]) >= MIN_THREADS


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts threads in /proc")
def test_xla_runs_its_operations_on_a_pool_of_that_size():
    """The mechanism, not only the variable: XLA:CPU's intra-op pool (the threads named
    tf_XLAEigen, where the wedged LAPACK kernels sat) has PJRT_NPROC threads."""
    code = (
        "import os, jax, jax.numpy as jnp\n"
        "jax.jit(lambda x: x + 1)(jnp.ones(3)).block_until_ready()\n"
        "names = [open(f'/proc/self/task/{t}/comm').read().strip()\n"
        "         for t in os.listdir('/proc/self/task')]\n"
        "print(names.count('tf_XLAEigen'))\n"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("PJRT_NPROC", "NPROC")}
    widen_cpu_thread_pool(env)
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                         text=True, check=True, timeout=120)  # fmt: skip
    assert int(out.stdout.strip()) == int(env["PJRT_NPROC"]) >= MIN_THREADS
