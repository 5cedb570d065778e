import os
import subprocess
import sys

# One BLAS thread a process, before NumPy loads OpenBLAS (children inherit it): the tests
# run one process per core (`-n auto`), and OpenBLAS's second thread, spinning between
# calls, took a core from XLA's pool: discover's small SVDs took 5 ms a call instead of
# 0.13 ms, test_discovery_search 40.7 s instead of 17.7 s on a busy 2-core machine.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from hrgjax._threads import widen_cpu_thread_pool  # noqa: E402

# Before the first JAX computation, for this process and every one the tests start: on two
# cores XLA:CPU's thread pool can wedge on batched LAPACK kernels (hrgjax/_threads.py).
widen_cpu_thread_pool()

# `make test` is two-thirds XLA:CPU compiling (measured per test by JAX's compile events:
# 1 989 of 3 015 test-seconds). These flags compile ≈ 2× faster and run the compiled programs
# up to ≈ 1.8× slower (benchmarks/compile_flags.py): the fast tier's programs are small and
# run once, so pytest takes ≈ 40 % less (1 431 → 848 s on a clean clone, 2 cores). They
# change how XLA emits code, not the arithmetic asked for (no fast-math), but round-off can
# differ, as between any two programs: no test may rely on bitwise equality across
# programs. `make test-full` runs with XLA's defaults, as users do; so does any run whose
# XLA_FLAGS already names one of them. An XLA that does not know a flag would abort the
# process, so they are tried once in a child process first.
QUICK_COMPILE_FLAGS = (
    "--xla_cpu_use_fusion_emitters=false",
    "--xla_backend_optimization_level=0",
    "--xla_llvm_disable_expensive_passes=true",
)


def _quick_compile(environ=os.environ) -> None:
    if environ.get("HRGJAX_TEST_FULL") == "1" or "HRGJAX_TEST_COMPILE_FLAGS" in environ:
        return
    have = environ.get("XLA_FLAGS", "")
    if any(f.split("=")[0] in have for f in QUICK_COMPILE_FLAGS):
        return  # the caller chose
    flags = " ".join(QUICK_COMPILE_FLAGS)
    probe = "import jax; jax.numpy.zeros(1).block_until_ready(); print(jax.default_backend())"
    env = dict(environ, XLA_FLAGS=f"{have} {flags}".strip())
    try:
        out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                             text=True, timeout=120)  # fmt: skip
        ok = out.returncode == 0 and out.stdout.strip().endswith("cpu")
    except (OSError, subprocess.SubprocessError):
        ok = False
    # the xdist workers inherit the answer and do not probe again
    environ["HRGJAX_TEST_COMPILE_FLAGS"] = flags if ok else ""
    if ok:
        environ["XLA_FLAGS"] = env["XLA_FLAGS"]


_quick_compile()

import jax  # noqa: E402
import pytest  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "strict")
jax.config.update("jax_numpy_rank_promotion", "raise")

# `make test` runs the fast tier; `make test-full` (HRGJAX_TEST_FULL=1) adds the tests marked
# `slow`: whole studies (a CLI command end to end, a search over the catalogue, a gradient
# checked by finite differences through an hour of simulation) that cost 20-100 s each on
# two cores, mostly compiling. Each says why it is slow and which fast test covers the
# same behaviour on a smaller problem, and is listed as skipped with that reason.
FULL = os.environ.get("HRGJAX_TEST_FULL") == "1"


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "slow(reason): a study-sized test run only by `make test-full` (HRGJAX_TEST_FULL=1); "
        "reason: why it is slow and which fast test covers its behaviour",
    )


def pytest_collection_modifyitems(config, items):
    if FULL:
        return
    for item in items:
        mark = item.get_closest_marker("slow")
        if mark is not None:
            why = mark.args[0] if mark.args else mark.kwargs.get("reason", "")
            item.add_marker(pytest.mark.skip(reason=f"make test-full: {why}"))


@pytest.fixture(scope="session", autouse=True)
def _run_compile_cache(tmp_path_factory):
    """One fresh compile-cache folder per test run, shared by the xdist workers and by the
    processes the tests start (CLI, docs pages): a program one test compiled, the next loads,
    as a user's second call does. Nothing from earlier runs is reused, and the user's
    ~/.cache/hrgjax is never touched (test_cache runs its own processes with their own
    folders, cold)."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    folder = root / "compile-cache"
    os.environ["HRGJAX_CACHE_DIR"] = str(folder)
    os.environ["HRGJAX_NO_CACHE"] = "0"
    import hrgjax

    hrgjax.enable_cache()
    yield folder


@pytest.fixture(scope="session")
def key():
    return jax.random.key(0)


def pytest_runtest_logreport(report):
    """With HRGJAX_FAILURE_LOG set (benchmarks/on_gpu.sh), each failure's last line is
    appended to that file as it happens: a run cut off by its time limit (a device lease)
    still says why each test failed, which pytest's summary at the end would not."""
    path = os.environ.get("HRGJAX_FAILURE_LOG")
    if path and report.failed and not os.environ.get("PYTEST_XDIST_WORKER"):  # once: the controller
        lines = str(report.longrepr).strip().splitlines() or ["?"]
        reason = " | ".join(ln[1:].strip() for ln in lines if ln.startswith("E ")) or lines[-1]
        with open(path, "a") as fh:
            fh.write(f"{report.nodeid} ({report.when}): {reason[:400]}\n")


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    """An xdist worker, once it has sent its last report, leaves without Python's and XLA's
    teardown: freeing the few thousand programs a worker compiled held the run's end: the
    controller waited 6.6 s after the last worker's atexit (two cores, 2026-11-29)."""
    if os.environ.get("PYTEST_XDIST_WORKER") and hasattr(config, "workeroutput"):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(0)
