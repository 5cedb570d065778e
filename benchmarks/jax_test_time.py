"""Where `make test`'s time goes, per test: a pytest plugin summing JAX's own compile events
(issue 45), and its summary.

As a plugin it appends one JSON line per test to `$JAX_TEST_TIME_OUT` (default
`out/jax_test_time.jsonl`): the test's wall time and the seconds JAX reported tracing
(`jaxpr_trace_duration`), lowering to MLIR (`jaxpr_to_mlir_module_duration`) and compiling
(`backend_compile_duration`), with each compiled program's name and time. Run as a script it
sums a file: per file, and the compiles by size (≥ 0.1 s: programs; below: eager operations).

Usage (2 workers, as `make test`; the plugin copied to a folder of its own, since
`benchmarks/` on the path would shadow the `coverage` package with `benchmarks/coverage.py`):

    mkdir -p out/plugin && cp benchmarks/jax_test_time.py out/plugin/
    rm -f out/jax_test_time.jsonl
    PYTHONPATH=out/plugin .venv/bin/python -m pytest -q -n 2 --dist loadfile -p jax_test_time
    .venv/bin/python benchmarks/jax_test_time.py out/jax_test_time.jsonl
"""

import collections
import json
import os
import sys
import time

import pytest

_EVENTS = {
    "/jax/core/compile/jaxpr_trace_duration": "trace",
    "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower",
    "/jax/core/compile/backend_compile_duration": "compile",
}
_now: dict = {}
_registered = False


def _listen(event, duration, **kwargs):
    what = _EVENTS.get(event)
    if what is None:
        return
    _now[what] = _now.get(what, 0.0) + duration
    if what == "compile":
        _now.setdefault("programs", []).append([kwargs.get("fun_name"), round(duration, 4)])


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):  # pragma: no cover - a plugin hook
    global _registered
    if not _registered:
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(_listen)
        _registered = True
    _now.clear()
    start = time.perf_counter()
    yield
    row = {"test": item.nodeid, "wall": time.perf_counter() - start, **_now}
    path = os.environ.get("JAX_TEST_TIME_OUT", os.path.join("out", "jax_test_time.jsonl"))
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    with open(path, "a") as fh:
        fh.write(json.dumps(row) + "\n")


def summarise(path: str) -> None:
    rows = [json.loads(line) for line in open(path)]
    keys = ("wall", "compile", "trace", "lower")
    total = {k: sum(r.get(k, 0.0) for r in rows) for k in keys}
    programs = [t for r in rows for _, t in r.get("programs", [])]
    big = [t for t in programs if t >= 0.1]
    print(f"{len(rows)} tests: {total['wall']:.0f} test-s; compiling {total['compile']:.0f} s "
          f"({len(big)} programs ≥ 0.1 s: {sum(big):.0f} s; {len(programs) - len(big)} below: "
          f"{sum(programs) - sum(big):.0f} s), tracing {total['trace']:.0f} s, lowering "
          f"{total['lower']:.0f} s, the rest "
          f"{total['wall'] - total['compile'] - total['trace'] - total['lower']:.0f} s")  # fmt: skip
    by_file = collections.defaultdict(lambda: dict.fromkeys(keys, 0.0))
    for r in rows:
        f = by_file[r["test"].split("::")[0]]
        for k in keys:
            f[k] += r.get(k, 0.0)
    print(f"\n{'file':<40} {'wall':>7} {'compile':>8} {'trace':>7} {'lower':>7}")
    for name, f in sorted(by_file.items(), key=lambda kv: -kv[1]["wall"])[:25]:
        print(f"{name:<40} {f['wall']:7.1f} {f['compile']:8.1f} {f['trace']:7.1f} "
              f"{f['lower']:7.1f}")  # fmt: skip


if __name__ == "__main__":
    where = sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "jax_test_time.jsonl")
    if not os.path.exists(where):  # run_all.py runs every script: say what to run first
        print(f"jax_test_time.py: no {where} to sum; run pytest with `-p jax_test_time` first "
              "(this file's docstring)")  # fmt: skip
        sys.exit(0)
    summarise(where)
