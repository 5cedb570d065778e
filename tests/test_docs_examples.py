"""Every python block in `docs/` runs: a page's blocks in order, in one fresh process per
page, so a later block sees what the earlier ones defined (as a reader copying them would).

The run happens in a scratch directory with an `out/` folder (where the examples write) and
`tests/data` beside it (the measured data the pages load). Where a page names a file the
reader brings (`bench.csv`, `session.csv`), a short setup step — run in the same process just
before that block, shown in the failure message — writes one. Where a page's example is
slow, the run shrinks its sizes by the literal replacements in `QUICK` below; each must
still match the page (a test checks), so the examples cannot drift away from what is run.
`HRGJAX_DOCS_FULL=1` runs every page exactly as written. The pages in `HEAVY_PAGES` (a run
that is mostly compiling) run only then; by default their blocks are compiled as Python.

A block is left out only with an HTML comment directly above it: `<!-- docs-test: skip —
why -->` (never run here: the reason names the test that runs the same thing) or
`<!-- docs-test: full — why -->` (runs only with `HRGJAX_DOCS_FULL=1`, `make docs-test`:
a block whose cost is compiling, which no size reduces; the default run lists it as
skipped, with the tests that cover the same path). Later blocks must not depend on either.

Tracebacks name the page and its line (`File "docs/imu.md", line 54`)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
FULL = os.environ.get("HRGJAX_DOCS_FULL", "") not in ("", "0")

_FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```", re.S | re.M)
_MARK = re.compile(r"<!--\s*docs-test:\s*(skip|full)\b((?:(?!-->).)*)-->\s*\Z", re.S)

# Literal (page text, what runs instead) pairs: the same code at smaller sizes.
QUICK: dict[str, list[tuple[str, str]]] = {
    "allan.md": [("size=200_000", "size=20_000")],
    "calibration.md": [
        ("cal.seed_plan()", "cal.seed_plan(quick=True)"),
        ("cal.test_plan()", "cal.test_plan(quick=True)"),
        ("cal.MLPCompensator()", "cal.MLPCompensator(steps=100, e2e_steps=5)"),
    ],
    "ins.md": [
        (
            "monte_carlo(phi, qd, p0, jax.random.key(0), 1000, every=60)",
            "monte_carlo(phi, qd, p0, jax.random.key(0), 50, every=60)",
        ),
        ("n_steps=7200", "n_steps=600"),
        ("3700.0", "300.0"),
    ],
    "scaling.md": [
        ("jnp.linspace(-40.0, 60.0, 100)", "jnp.linspace(-40.0, 60.0, 4)"),
        ("jnp.log10(400.0), 100)", "jnp.log10(400.0), 4)"),
        ("rate_dps=jnp.geomspace(0.1, 400.0, 64)", "rate_dps=jnp.geomspace(0.1, 400.0, 8)"),
    ],
    "noise.md": [("hg.Profile.static(20000.0)", "hg.Profile.static(2000.0)")],
    "design.md": [
        ('"temperature_end_c": 60.0', '"temperature_end_c": -30.0'),
        ('"duration_s": 6000.0}', '"duration_s": 600.0}'),
    ],
    "fog.md": [("epochs=300", "epochs=5"), ("600.0), fs=100.0", "120.0), fs=100.0")],
}

# Code run just before block `i` of a page (0-based): the files the page asks the reader for.
SETUP: dict[str, dict[int, str]] = {
    "discovery.md": {
        0: """
            import jax
            jax.config.update("jax_enable_x64", True)
            from hrgjax.discovery.generate import hidden_effect_dataset
            hidden_effect_dataset(None, key=jax.random.key(7)).save("bench.csv")
        """
    },
    "imu.md": {
        1: """
            import json as _json
            _d, _s = hg.imu.ferraris_session(truth, jax.random.key(9), turn_deg=-360.0)
            _g = np.rad2deg(np.asarray(_d.gyro))
            _a = np.asarray(_d.accel)
            np.savetxt(
                "session.csv", np.column_stack([np.asarray(_d.time), _g, _a]), delimiter=",",
                header="t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z", comments="",
            )
            with open("sections.json", "w") as _f:
                _json.dump(hg.imu.sections_to_json(_s), _f)
        """
    },
}


def _blocks(page: Path) -> list[dict]:
    """The page's python blocks: code, first line number (1-based), and the marker above
    it (`mark`: None, "skip" or "full"; `why`: its reason)."""
    text = page.read_text(encoding="utf-8")
    out = []
    for m in _FENCE.finditer(text):
        before = text[: m.start()]
        mark = _MARK.search(before.rstrip())
        out.append(
            {
                "code": m.group(1),
                "line": before.count("\n") + 2,  # the fence's line + 1
                "mark": mark.group(1) if mark else None,
                "why": " ".join(mark.group(2).strip(" —-:\n").split()) if mark else "",
            }
        )
    return out


PAGES = sorted(p.name for p in DOCS.glob("*.md") if _blocks(p))

_RUNNER = textwrap.dedent(
    """
    import json, sys, time
    import hrgjax
    hrgjax.enable_cache()  # the run's shared folder: a program one page compiled, the next loads
    ns = {"__name__": "__main__"}
    for b in json.load(open(sys.argv[1], encoding="utf-8")):
        t0 = time.perf_counter()
        exec(compile("\\n" * (b["line"] - 1) + b["code"], b["file"], "exec"), ns)
        print(f"{b['file']}:{b['line']}: {time.perf_counter() - t0:.1f} s", flush=True)
    """
)


def _script(name: str) -> list[dict]:
    blocks = _blocks(DOCS / name)
    setup = SETUP.get(name, {})
    run = []
    for i, b in enumerate(blocks):
        if i in setup:
            code = textwrap.dedent(setup[i])
            run.append({"code": code, "line": 1, "file": f"<setup before docs/{name} block {i}>"})
        if b["mark"] == "skip" or (b["mark"] == "full" and not FULL):
            continue
        code = b["code"]
        if not FULL:
            for old, new in QUICK.get(name, []):
                code = code.replace(old, new)
        run.append({"code": code, "line": b["line"], "file": f"docs/{name}"})
    return run


def test_every_replacement_still_matches_its_page():
    """A QUICK replacement that no longer matches would silently run the full size (or a
    stale example): each must be found in its page's blocks, and every SETUP page exists."""
    for name, pairs in QUICK.items():
        code = "".join(b["code"] for b in _blocks(DOCS / name))
        for old, _ in pairs:
            assert old in code, f"docs/{name}: QUICK replacement {old!r} not found"
    for name, steps in SETUP.items():
        n = len(_blocks(DOCS / name))
        assert all(i < n for i in steps), f"docs/{name}: SETUP block index out of range"


def test_skipped_blocks_say_why():
    for name in PAGES:
        for b in _blocks(DOCS / name):
            if b["mark"] is not None:
                assert len(b["why"]) > 20, f"docs/{name}:{b['line']}: say why it is left out"


FULL_ONLY = [
    (name, b["line"], b["why"])
    for name in PAGES
    for b in _blocks(DOCS / name)
    if b["mark"] == "full"
]


@pytest.mark.parametrize(
    "page,line,why", FULL_ONLY, ids=[f"{n}:{line}" for n, line, _ in FULL_ONLY]
)
def test_full_only_blocks_run_with_HRGJAX_DOCS_FULL(page, line, why):
    """Listed so that a default run reports them; with HRGJAX_DOCS_FULL=1 they run inside
    their page's run (test_docs_page_runs)."""
    if not FULL:
        pytest.skip(f"docs/{page}:{line} runs with HRGJAX_DOCS_FULL=1 (make docs-test): {why}")
    assert any(b["line"] == line for b in _script(page))


# Pages whose run is mostly compiling (each in a fresh process): they run with
# HRGJAX_DOCS_FULL=1 (`make docs-test`), as the compile-bound blocks do, and the default run
# compiles their code (test_every_block_is_python) and tests the same calls in the modules
# named. Seconds: one page's run on the 2-core machine, four helpers beside it (2026-11-26).
HEAVY_PAGES = {
    "discovery.md": "260 s; tests/test_discovery_*.py, test_cli.py::test_discover_*",
    "fog.md": "156 s; tests/test_fog.py",
    "modes.md": "≈ 60 s; tests/test_modes.py, test_self_calibration.py",
    "simulate.md": "150 s; tests/test_resonator_*.py, test_sweep.py, test_cli.py",
    "design.md": "145 s; tests/test_design*.py",
    "resonator.md": "143 s; tests/test_resonator_*.py, test_carrier.py",
    "calibration.md": "136 s; tests/test_calibration.py, test_session.py, test_cli.py",
    "diagnosis.md": "129 s; tests/test_diagnosis*.py",
    "ins.md": "125 s; tests/test_ins_*.py, test_kalman.py",
    "navigation.md": "≈ 90 s (an hour at 100 Hz, 20 flights compiled); tests/test_navigation*.py",
    "scaling.md": "111 s; tests/test_sweep.py, test_cache.py",
}


def test_every_block_is_python():
    """Every block of every page, as the run would execute it (QUICK sizes, SETUP steps),
    compiles as Python: a heavy page left to `make docs-test` cannot rot into a syntax
    error unseen, and HEAVY_PAGES names only pages that exist."""
    assert set(HEAVY_PAGES) <= set(PAGES), set(HEAVY_PAGES) - set(PAGES)
    for name in PAGES:
        for b in _script(name):
            compile("\n" * (b["line"] - 1) + b["code"], b["file"], "exec")


@pytest.mark.parametrize("page", PAGES)
def test_docs_page_runs(page, tmp_path, _run_compile_cache):
    if page in HEAVY_PAGES and not FULL:
        pytest.skip(
            f"docs/{page} runs with HRGJAX_DOCS_FULL=1 (make docs-test): {HEAVY_PAGES[page]}"
        )
    (tmp_path / "out").mkdir()
    (tmp_path / "tests").mkdir()
    (tmp_path / "tests" / "data").symlink_to(ROOT / "tests" / "data")
    blocks = tmp_path / "blocks.json"
    blocks.write_text(json.dumps(_script(page)), encoding="utf-8")
    env = dict(
        os.environ,
        MPLBACKEND="Agg",
        PYTHONPATH=str(ROOT),
        HRGJAX_NO_CACHE="0",
        HRGJAX_CACHE_DIR=str(_run_compile_cache),
    )
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", _RUNNER, str(blocks)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    took = time.perf_counter() - t0
    assert proc.returncode == 0, (
        f"docs/{page} failed after {took:.0f} s:\n{proc.stdout[-2000:]}\n{proc.stderr[-6000:]}"
    )
