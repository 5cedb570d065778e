"""When `make test`'s time passes (issue 45): a pytest plugin stamping each test's start and
end per xdist worker, and each process's session end, exit hooks and `atexit`; run as a
script it summarises a file: each worker's first test, last test and busy time, and the
time from the last test's end to the controller's end.

Usage (the plugin copied to a folder of its own, as `jax_test_time.py`):

    mkdir -p out/plugin && cp benchmarks/run_timeline.py out/plugin/
    rm -f out/timeline.jsonl; date +%s.%N > out/timeline.start
    PYTHONPATH=out/plugin .venv/bin/python -m pytest -q -n auto --dist loadfile -p run_timeline
    .venv/bin/python benchmarks/run_timeline.py out/timeline.jsonl out/timeline.start
"""

import atexit
import collections
import json
import os
import sys
import time

import pytest

_PATH = os.environ.get("RUN_TIMELINE_OUT", os.path.join("out", "timeline.jsonl"))


def _write(row):
    with open(_PATH, "a") as fh:
        fh.write(json.dumps({"w": os.environ.get("PYTEST_XDIST_WORKER"), **row}) + "\n")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):  # pragma: no cover - a plugin hook
    start = time.time()
    yield
    _write({"test": item.nodeid, "s": start, "e": time.time()})


@pytest.hookimpl(tryfirst=True)
def pytest_sessionfinish(session):  # pragma: no cover - a plugin hook
    _write({"mark": "sessionfinish", "t": time.time()})


@pytest.hookimpl(tryfirst=True)
def pytest_unconfigure(config):  # pragma: no cover - a plugin hook
    _write({"mark": "unconfigure", "t": time.time()})
    atexit.register(lambda: _write({"mark": "atexit", "t": time.time()}))


def main(path=os.path.join("out", "timeline.jsonl"),
         start_file=os.path.join("out", "timeline.start")):  # fmt: skip
    if not (os.path.exists(path) and os.path.exists(start_file)):
        print(f"run_timeline.py: no {path} and {start_file} to sum; run pytest with "
              "`-p run_timeline` first (module docstring)")  # fmt: skip
        return
    t0 = float(open(start_file).read())
    rows = [json.loads(line) for line in open(path)]
    tests = [r for r in rows if "test" in r]
    by = collections.defaultdict(list)
    for r in tests:
        by[r["w"]].append(r)
    for w, rs in sorted(by.items()):
        print(f"{w}: first test at +{min(r['s'] for r in rs) - t0:.1f} s, last end "
              f"+{max(r['e'] for r in rs) - t0:.1f} s, busy {sum(r['e'] - r['s'] for r in rs):.1f} s")  # fmt: skip
    for r in rows:
        if "mark" in r:
            print(f"{r['w'] or 'controller'}: {r['mark']} at +{r['t'] - t0:.1f} s")
    last = max(r["e"] for r in tests)
    end = max(r["t"] for r in rows if r.get("mark") == "atexit" and r["w"] is None)
    print(f"from the last test's end to the controller's exit: {end - last:.1f} s")


if __name__ == "__main__":
    main(*sys.argv[1:3])
