"""Time and peak memory of reading a CSV log with gaps (`hrgjax.data.read_csv_table` with
`empty_as_nan` and the time and one data column checked for exact integers, as `hrgjax allan`
reads; `hg.imu.load` and `hg.load` read `nan` the same way):
the numeric fast path (NumPy's C parser in chunks of lines, `hrgjax/_csv_numeric.py`), which a
gap no longer leaves, against the validating reader (Python's csv module), which every file
with one `nan` or empty field took before.

Files of N rows × 7 columns (`time,gx,gy,gz,ax,ay,az`, `%.6f`, as an IMU log): clean, with
one `nan`, with one empty field, with one `inf` (in `gx`, a column checked exactly: allan
then refuses it, naming the line) and with an empty field in every row (`dense`: the last
column); each read in a fresh process, which reports its wall
time and peak resident memory (VmHWM of /proc/self/status, Linux: `ru_maxrss` would count
the parent's memory at the fork; the interpreter and NumPy included, ≈ 30 MB). The
fast path must give the validating reader's columns and lines (checked on the empty-field,
`inf` and dense files of the smallest N, which the validating reader reads; it is timed on
the `nan` and dense files).

Usage: `.venv/bin/python benchmarks/csv_gaps.py [--rows 1e5 1e6 2e6] [--slow-max 2e6]`
(≈ 4 min on 2 shared cores; the validating reader is timed up to `--slow-max` rows).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

CHILD = r"""
import json, sys, time
import numpy as np
from hrgjax import _data_files
from hrgjax.data import read_csv_table
if sys.argv[2] == "slow":
    _data_files._numeric_table = lambda path, *args: None
t0 = time.perf_counter()
cols, lines = read_csv_table(sys.argv[1], empty_as_nan=True, exact_integers=["time", "gx"])
dt = time.perf_counter() - t0
with open("/proc/self/status") as fh:  # (ru_maxrss keeps the parent's RSS at the fork)
    peak = next(int(ln.split()[1]) for ln in fh if ln.startswith("VmHWM:")) / 1024
if len(sys.argv) > 3:
    np.savez(sys.argv[3], lines=lines, **cols)
print(json.dumps({"s": dt, "peak_mb": peak, "rows": int(lines.size),
                  "gaps": int(sum((~np.isfinite(v)).sum() for v in cols.values()))}))
"""


def write_file(path: str, rows: int, gap: str) -> int:
    """An IMU-like log; `gap`: "" (none), "nan", "empty" or "inf" (one field of row N/3),
    "dense" (the last field of every row empty)."""
    rng = np.random.default_rng(0)
    with open(path, "w") as fh:
        fh.write("time,gx,gy,gz,ax,ay,az\n")
        for start in range(0, rows, 200_000):
            n = min(200_000, rows - start)
            block = np.column_stack([(start + np.arange(n)) / 100.0, rng.normal(size=(n, 6))])
            text = "\n".join(",".join(f"{v:.6f}" for v in row) for row in block.tolist())
            if gap in ("nan", "empty", "inf") and start <= rows // 3 < start + n:
                lines = text.split("\n")
                fields = lines[rows // 3 - start].split(",")
                fields[1] = "" if gap == "empty" else gap
                lines[rows // 3 - start] = ",".join(fields)
                text = "\n".join(lines)
            if gap == "dense":
                text = "\n".join(t.rsplit(",", 1)[0] + "," for t in text.split("\n"))
            fh.write(text + "\n")
    return os.path.getsize(path)


def measure(path: str, which: str, save: str | None = None) -> dict:
    argv = [sys.executable, "-c", CHILD, path, which] + ([save] if save else [])
    out = subprocess.run(argv, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def same(a: str, b: str) -> bool:
    x, y = np.load(a), np.load(b)
    return sorted(x.files) == sorted(y.files) and all(
        x[k].dtype == y[k].dtype and np.array_equal(x[k], y[k], equal_nan=True) for k in x.files
    )


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=float, nargs="+", default=[1e5, 1e6, 2e6])
    ap.add_argument("--slow-max", type=float, default=2e6)
    args = ap.parse_args()
    print(f"{'rows':>9} {'file':>6} {'MB':>5} {'path':>10} {'time [s]':>9} {'peak RSS [MB]':>14}")
    checked = []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "log.csv")
        for rows in map(int, args.rows):
            for gap in ("", "nan", "empty", "inf", "dense"):
                size = write_file(path, rows, gap)
                check = rows == min(args.rows) and gap in ("empty", "inf", "dense")
                slow = gap in ("nan", "dense") and rows <= args.slow_max or check
                for way in ["fast"] + (["slow"] if slow else []):
                    save = os.path.join(tmp, f"{way}.npz") if check else None
                    r = measure(path, way, save)
                    gaps = rows if gap == "dense" else 1 if gap else 0
                    assert r["rows"] == rows and r["gaps"] == gaps, r
                    name = "fast" if way == "fast" else "validating"
                    print(f"{rows:>9} {gap or 'clean':>6} {size / 1e6:>5.0f} {name:>10} "
                          f"{r['s']:>9.2f} {r['peak_mb']:>14.0f}", flush=True)  # fmt: skip
                if check:
                    checked.append(same(*(os.path.join(tmp, f"{w}.npz") for w in ("fast", "slow"))))
    checked = len(checked) == 3 and all(checked)
    print(f"\nfast path = validating reader (columns, dtypes, lines): {checked}")
    if not checked:
        sys.exit(1)
