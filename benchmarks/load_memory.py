"""Memory and time of the CSV reader (`hrgjax.data.read_csv_table`): the numeric fast path
(NumPy's C parser, each data line checked to hold only the characters of numbers) against the
validating reader (Python's csv module, one string per field), side by side on one file.

A 1 M rows × 8 columns CSV (≈ 129 MB: the data contract's columns as `repr` floats, run ids
as integers) is written once; each path then reads it in a fresh process, which reports its
peak resident memory (`ru_maxrss`), the growth of its resident memory during the read, and the
read's wall time (the growth is sampled from /proc/self/statm every 2 ms: Linux). The two
paths must return the same columns, dtypes and lines (checked).

Usage: `.venv/bin/python benchmarks/load_memory.py [--rows N]` (default 1 000 000).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np
from _common import machine

CHILD = r"""
import json, os, resource, sys, threading, time
import numpy as np
from hrgjax import _data_files
from hrgjax.data import read_csv_table
if sys.argv[2] == "slow":
    _data_files._numeric_table = lambda path, *args: None
page = os.sysconf("SC_PAGE_SIZE") / 2**20
def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * page
base, top, done = rss(), [0.0], threading.Event()
def sample():
    while not done.is_set():
        top[0] = max(top[0], rss())
        time.sleep(0.002)
th = threading.Thread(target=sample); th.start()
t0 = time.perf_counter()
cols, lines = read_csv_table(sys.argv[1])
dt = time.perf_counter() - t0
done.set(); th.join()
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
digest = float(sum(np.nansum(np.asarray(v, dtype=float)) for v in cols.values()))
print(json.dumps({"peak_mb": peak, "delta_mb": max(top[0], rss()) - base, "s": dt,
                  "rows": int(lines.size), "digest": digest, "last_line": int(lines[-1]),
                  "dtypes": {k: str(v.dtype) for k, v in cols.items()}}))
"""


def write_file(path: str, rows: int) -> int:
    rng = np.random.default_rng(0)
    with open(path, "w", newline="") as fh:
        fh.write("time_s,run,temperature_c,table_rate_dps,wave_angle_deg,amplitude,quadrature,"
                 "accel_z_g\n")  # fmt: skip
        for start in range(0, rows, 100_000):
            n = min(100_000, rows - start)
            t = (start + np.arange(n)) * 0.01
            block = zip(
                t.tolist(), ((start + np.arange(n)) // 10_000).tolist(),
                (20.0 + rng.normal(0, 0.1, n)).tolist(), rng.normal(0, 5, n).tolist(),
                rng.normal(0, 100, n).tolist(), (1.0 + rng.normal(0, 1e-3, n)).tolist(),
                rng.normal(0, 1e-3, n).tolist(), (1.0 + rng.normal(0, 1e-4, n)).tolist(),
                strict=True,
            )  # fmt: skip
            fh.write("".join(",".join([repr(v[0]), str(v[1]), *map(repr, v[2:])]) + "\n"
                             for v in block))  # fmt: skip
    return os.path.getsize(path)


def measure(path: str, which: str) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, path, which], check=True,
                         capture_output=True, text=True)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    args = ap.parse_args()
    print(machine())
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "big.csv")
        size = write_file(path, args.rows)
        print(f"{args.rows} rows × 8 columns, {size / 1e6:.0f} MB\n")
        fast, slow = measure(path, "fast"), measure(path, "slow")
    same = all(fast[k] == slow[k] for k in ("rows", "digest", "last_line", "dtypes"))
    print(f"{'path':>18} {'peak RSS [MB]':>14} {'growth in read [MB]':>19} {'time [s]':>9}")
    for name, r in (("fast (NumPy)", fast), ("validating (csv)", slow)):
        print(f"{name:>18} {r['peak_mb']:>14.0f} {r['delta_mb']:>19.0f} {r['s']:>9.2f}")
    print(f"{'ratio slow/fast':>18} {slow['peak_mb'] / fast['peak_mb']:>14.1f} "
          f"{slow['delta_mb'] / max(fast['delta_mb'], 1.0):>19.1f} "
          f"{slow['s'] / fast['s']:>9.1f}")  # fmt: skip
    print(f"\nsame columns and lines from both paths: {same}")
    if not same:
        sys.exit(1)
