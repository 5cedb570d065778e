"""Run every benchmark and write one machine-readable summary.

`.venv/bin/python benchmarks/run_all.py [--quick] [--only a,b] [--timeout S]`

Each script runs in its own process (its log in `out/benchmarks/NAME.log`) and hands its
headline figures back through `_common.report`. The summary goes to `out/benchmarks.json`
(every figure with its value, unit, comparison and ratio, plus the device kind, the
versions and the commit) and `out/benchmarks.md` (the same as a table). `--quick` passes
`--quick` to the scripts that have a reduced size (the figures say so). Exit status 1 if any
script failed or ran out of time; the others' figures are still written.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OUT = ROOT / "out"
QUICK_ARGS = {  # scripts with a reduced size, and how to ask for it
    "adjoint_memory": ["--quick"],
    "calibration_study": ["--quick"],
    "coverage_continuous": ["--n", "10"],
    "design_dwell": ["--seeds", "3"],
    "design_mc": ["--seeds", "3", "--budgets"],  # the seed plan only: no designed plan to compile
    "diagnosis": ["--quick"],
    "discovery": ["--quick"],
    "ins_errors": ["--runs", "200"],
    "session_offset": ["--sessions", "4"],
    "sweep_scaling": ["--quick"],
    "vibration": ["--quick"],
}
PACKAGES = ("jax", "jaxlib", "equinox", "diffrax", "optax", "optimistix", "lineax", "numpy")


def scripts():
    return sorted(p.stem for p in HERE.glob("*.py") if p.stem not in ("_common", "run_all"))


def environment():
    """Device kind and versions, from a child process (the parent starts no backend)."""
    probe = (
        "import json, jax; d = jax.devices()[0]; "
        "print(json.dumps({'device_kind': d.device_kind, 'platform': d.platform, "
        "'device_count': jax.device_count()}))"
    )
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    env = json.loads(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 else {}
    from importlib.metadata import PackageNotFoundError, version

    versions = {"python": platform.python_version()}
    for pkg in PACKAGES + ("hrgjax",):
        try:
            versions[pkg] = version(pkg)
        except PackageNotFoundError:
            versions[pkg] = None
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT
    )
    env.update(
        machine=platform.machine(),
        processor=platform.processor(),
        cpu_count=os.cpu_count(),
        versions=versions,
        commit=commit.stdout.strip() or None,
    )
    return env


def run(script: Path, args: list[str], timeout: float, logs: Path):
    """One script in its own process: its status and wall time, and the figures it reported
    through `_common.report` (tagged with the script's name)."""
    name = script.stem
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        sink = f.name
    env = dict(os.environ, HRGJAX_BENCH_OUT=sink)
    log = logs / f"{name}.log"
    t0 = time.perf_counter()
    with open(log, "w") as fh:
        try:
            proc = subprocess.run(
                [sys.executable, str(script), *args],
                cwd=ROOT,
                env=env,
                stdout=fh,
                stderr=subprocess.STDOUT,
                timeout=timeout,
            )
            status = "ok" if proc.returncode == 0 else f"failed (exit {proc.returncode})"
        except subprocess.TimeoutExpired:
            status = f"timed out after {timeout:g} s"
    wall = time.perf_counter() - t0
    try:
        figures = json.loads(Path(sink).read_text() or "[]")
    except (FileNotFoundError, json.JSONDecodeError):
        figures = []
    Path(sink).unlink(missing_ok=True)
    for fig in figures:
        fig["script"] = name
        fig["quick"] = bool(args)
    return {"script": name, "status": status, "wall_s": round(wall, 1), "args": args,
            "log": str(log)}, figures  # fmt: skip


def markdown(summary):
    env = summary["environment"]
    v = env["versions"]
    lines = [
        f"Benchmarks: {env.get('device_count', '?')}× {env.get('device_kind', '?')} "
        f"({env.get('platform', '?')}), {env['cpu_count']} CPU cores, jax {v['jax']}, "
        f"diffrax {v['diffrax']}, equinox {v['equinox']}, commit {env['commit']}"
        + (", quick sizes" if summary["quick"] else ""),
        "",
        "| script | figure | value | unit | comparison | ratio | target |",
        "|---|---|---|---|---|---|---|",
    ]
    for f in summary["figures"]:
        ratio = "" if f["ratio"] is None else f"{f['ratio']:.3g}×"
        value = "" if f["value"] is None else f"{f['value']:.4g}"
        lines.append(
            f"| {f['script']} | {f['figure']} | {value} | {f['unit']} | {f['comparison']} "
            f"| {ratio} | {f['target']} |"
        )
    lines += ["", "| script | status | wall [s] |", "|---|---|---|"]
    lines += [f"| {s['script']} | {s['status']} | {s['wall_s']} |" for s in summary["scripts"]]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="reduced sizes where a script has them")
    ap.add_argument("--only", help="comma-separated script names (default: all)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="per script [s]")
    a = ap.parse_args(argv)
    names = scripts()
    if a.only:
        wanted = [n.strip().removesuffix(".py") for n in a.only.split(",")]
        unknown = sorted(set(wanted) - set(names))
        if unknown:
            ap.error(f"--only: unknown script(s) {unknown}; known: {names}")
        names = [n for n in names if n in wanted]
    logs = OUT / "benchmarks"
    logs.mkdir(parents=True, exist_ok=True)
    summary = {"environment": environment(), "quick": a.quick, "scripts": [], "figures": []}
    for name in names:
        print(f"{name} …", end=" ", flush=True)
        args = QUICK_ARGS.get(name, []) if a.quick else []
        status, figures = run(HERE / f"{name}.py", args, a.timeout, logs)
        print(f"{status['status']} in {status['wall_s']} s, {len(figures)} figures", flush=True)
        summary["scripts"].append(status)
        summary["figures"].extend(figures)
    (OUT / "benchmarks.json").write_text(json.dumps(summary, indent=2))
    (OUT / "benchmarks.md").write_text(markdown(summary))
    print(f"wrote {OUT / 'benchmarks.json'} and {OUT / 'benchmarks.md'}")
    return 0 if all(s["status"] == "ok" for s in summary["scripts"]) else 1


if __name__ == "__main__":
    sys.exit(main())
