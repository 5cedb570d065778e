"""Fuzz `hg.load` (CSV and NetCDF) and count what happens to each file.

`.venv/bin/python benchmarks/fuzz_loaders.py [--csv 20000] [--nc 2000] [--seed 0]`

Every file starts as a valid bench record (two interleaved-capable runs, the contract's
columns and an extra text column) and gets one to three random mutations: fields replaced
by text, NaN/inf, huge integers, underscores, empty fields, thousands separators, dates;
rows reordered, duplicated or cut short; header names duplicated, dropped or misspelt; a
byte-order mark, comment lines, bytes that are not UTF-8, a 200 000-character field, a
truncated file; for NetCDF other dtypes (bool, complex, int, unsigned, datetime, text),
`units` attributes (CF times, kelvin, radians), extra coordinates, 2-D variables, flipped
bytes and truncation.

Each file ends in one of three outcomes:

- **loaded-equal**: `hg.load` returned data, and saving and loading them again gives the
  same data bit for bit;
- **clear error**: a `ValueError` (or `FileNotFoundError`) of one line that names the file;
- **other**: anything else (another exception type, a message over several lines, a round
  trip that changes the data). The target is 0; the script prints the first few.

NetCDF files are loaded in a child process: libhdf5 can loop forever on a file whose metadata
has flipped bits (no Python code can interrupt it), and such a file is counted as a
**hang** after 30 s (reported, not hidden; it is a limit of libhdf5, see docs/data.md).
"""

import argparse
import csv
import io
import os
import sys
import tempfile
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
import hrgjax as hg  # noqa: E402
from hrgjax._progress import bar  # noqa: E402

COLUMNS = ["time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg", "operator"]


def _valid_rows(rng, n=8):
    t = np.arange(n) * 0.5
    run = (np.arange(n) >= n // 2).astype(int)
    t[n // 2 :] = np.arange(n - n // 2) * 0.5
    rows = []
    for i in range(n):
        rows.append([repr(float(t[i])), str(run[i]), repr(float(rng.normal(20, 5))),
                     repr(float(rng.choice([0.0, 5.0]))), repr(float(rng.normal(0, 90))),
                     str(rng.choice(["ann", "bob", "c,d", "ü"]))])  # fmt: skip
    return rows


_TEXT = ["", " ", "abc", "nan", "inf", "-inf", "1_000", "1,000", "1e", "1e400", "0x1f",
         "99999999999999999999999", "9007199254740993", "2024-01-01T00:00:00", "True", "½",
         "1.5", "-0", '"', "\x00", "١٢"]  # fmt: skip


def _mutate_csv(rng, header, rows):
    """One random mutation; returns (header, rows, prefix, raw bytes or None)."""
    kind = rng.integers(0, 14)
    prefix = ""
    if kind == 0 and rows:  # a field replaced by odd text
        r, c = rng.integers(len(rows)), rng.integers(len(header))
        if c < len(rows[r]):
            rows[r][c] = str(rng.choice(_TEXT))
    elif kind == 1 and len(rows) > 1:  # rows reordered (time backwards, interleaved runs)
        i, j = rng.choice(len(rows), 2, replace=False)
        rows[i], rows[j] = rows[j], rows[i]
    elif kind == 2 and rows:  # a duplicated row
        i = rng.integers(len(rows))
        rows.insert(i, list(rows[i]))
    elif kind == 3 and rows:  # a row cut short or lengthened
        i = rng.integers(len(rows))
        cut = rng.integers(0, len(rows[i])) if rows[i] else 0
        rows[i] = rows[i][:cut] if rng.random() < 0.5 else rows[i] + ["1"]
    elif kind == 4:  # header duplicated, dropped or misspelt
        c = rng.integers(len(header))
        choice = rng.integers(3)
        if choice == 0:
            header[c] = header[(c + 1) % len(header)]
        elif choice == 1:
            header.pop(c)
        else:
            header[c] = header[c] + "x"
    elif kind == 5:
        prefix = "\ufeff"
    elif kind == 6:
        prefix = "# bench log\n#, with a comma\n"
    elif kind == 7 and rows:  # huge or non-integral run id
        r = rows[rng.integers(len(rows))]
        odd = str(rng.choice(["1.5", "2e30", "-3", "18446744073709551616"]))
        r[min(1, len(r)) : 2] = [odd]
    elif kind == 8 and rows:  # a very long field
        r = rows[rng.integers(len(rows))]
        r[min(4, len(r) - 1) :] = ["1" * 200_000]
    elif kind == 9:  # all rows gone
        rows.clear()
    elif kind == 10 and rows:  # NaN / inf in a contract column
        r = rows[rng.integers(len(rows))]
        if r:
            r[rng.integers(min(5, len(r)))] = str(rng.choice(["nan", "inf", "-inf"]))
    elif kind == 11:  # an unknown extra numeric column
        header.append("extra")
        for r in rows:
            r.append(repr(float(rng.normal())))
    elif kind == 12 and rows:  # an empty line and whitespace around numbers
        rows.insert(rng.integers(len(rows)), [])
        rows[-1] = [f" {v} " for v in rows[-1]] if rows[-1] else rows[-1]
    elif kind == 13:  # the time column as text dates
        for r in rows:
            if r:
                r[0] = "2024-01-01T00:00:0" + str(rng.integers(10))
    return header, rows, prefix


def _csv_bytes(rng):
    header, rows = list(COLUMNS), _valid_rows(rng)
    prefix = ""
    for _ in range(rng.integers(1, 4)):
        header, rows, p = _mutate_csv(rng, header, rows)
        prefix = prefix or p
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    blob = (prefix + buf.getvalue()).encode("utf-8")
    k = rng.integers(10)
    if k == 0:  # not UTF-8
        i = rng.integers(len(blob))
        blob = blob[:i] + bytes([0xFF]) + blob[i:]
    elif k == 1:  # truncated
        blob = blob[: rng.integers(len(blob))]
    return blob


def _nc_file(rng, path):
    import xarray as xr

    n = int(rng.integers(1, 6))
    variables, coords = {}, {}
    for name in COLUMNS[:5]:
        odd = ["f4", "i8", "u8", "bool", "c16", "U3", "M8[s]"]
        dt = "f8" if rng.random() < 0.8 else rng.choice(odd)
        raw = np.sort(rng.integers(0, 1000, n)) if name == "time_s" else rng.integers(-3, 3, n)
        values = raw.astype(dt) if dt != "c16" else raw + 1j
        attrs = {}
        if rng.random() < 0.15:
            attrs["units"] = str(rng.choice(["s", "seconds since 2001-01-01", "K", "degC",
                                             "rad", "degree", "weeks since 1", "deg/s"]))  # fmt: skip
        if rng.random() < 0.05:
            values = np.tile(values, (2, 1)).T
            variables[name] = (("sample", "two"), values, attrs)
        else:
            variables[name] = ("sample", values, attrs)
    if rng.random() < 0.2:
        coords["lat_deg"] = ("sample", rng.normal(size=n))
    if rng.random() < 0.2:
        variables["operator"] = ("sample", np.array(["a", "b", "c", "d", "e"][:n]))
    ds = xr.Dataset(variables, coords=coords)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            ds.to_netcdf(path, engine="h5netcdf")
    except Exception:
        return False  # a dtype the writer refuses: nothing to load
    k = rng.integers(8)
    if k == 0:
        blob = open(path, "rb").read()
        open(path, "wb").write(blob[: rng.integers(len(blob))])
    elif k == 1:
        blob = bytearray(open(path, "rb").read())
        for _ in range(4):
            blob[rng.integers(len(blob))] ^= 1 << int(rng.integers(8))
        open(path, "wb").write(bytes(blob))
    return True


def _outcome(path, folder):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = hg.load(path, allow_extra=True)
    except (ValueError, FileNotFoundError) as err:
        text = str(err)
        if path in text and "\n" not in text:
            return "clear error", None
        return "other", f"{type(err).__name__}: {text[:300]}"
    except Exception as err:  # noqa: BLE001 - counting what escapes is the point
        return "other", f"{type(err).__name__}: {str(err)[:300]}"
    again_path = os.path.join(folder, "again" + os.path.splitext(path)[1])
    try:
        again = hg.load(data.save(again_path), allow_extra=True)
    except Exception as err:  # noqa: BLE001
        return "other", f"round trip: {type(err).__name__}: {str(err)[:300]}"
    return ("loaded-equal", None) if again == data else ("other", "round trip changed the data")


class _Worker:
    """One child process that loads the NetCDF files, so that a file on which libhdf5 loops
    (a flipped bit in its metadata can do that; no Python code can interrupt it) is counted
    as a hang after `timeout` seconds instead of stopping the run."""

    def __init__(self, timeout: float = 30.0):
        import multiprocessing

        self.timeout, self.context, self.pool = timeout, multiprocessing.get_context("spawn"), None

    def outcome(self, path, folder):
        import multiprocessing

        if self.pool is None:
            self.pool = self.context.Pool(1)
        job = self.pool.apply_async(_outcome, (path, folder))
        try:
            return job.get(self.timeout)
        except multiprocessing.TimeoutError:
            self.pool.terminate()
            self.pool = None
            return "hang", f"libhdf5 did not return within {self.timeout:g} s"

    def close(self):
        if self.pool is not None:
            self.pool.terminate()


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--csv", type=int, default=20_000, help="CSV files (default 20000)")
    parser.add_argument("--nc", type=int, default=2_000, help="NetCDF files (default 2000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    counts = {}
    examples = []
    worker = _Worker()
    outcomes = ("loaded-equal", "clear error", "other", "hang")
    with tempfile.TemporaryDirectory() as folder:
        for kind, n in (("csv", args.csv), ("nc", args.nc)):
            c = counts.setdefault(kind, dict.fromkeys(outcomes, 0))
            path = os.path.join(folder, f"fuzz.{kind}")
            with bar(n, f"fuzzing {kind}", unit="file") as progress:
                for i in range(n):
                    if kind == "csv":
                        with open(path, "wb") as fh:
                            fh.write(_csv_bytes(rng))
                        outcome, why = _outcome(path, folder)
                    else:
                        path = os.path.join(folder, f"fuzz{i}.nc")  # a hung file stays open
                        if not _nc_file(rng, path):  # the writer refused: not counted
                            progress.update(1)
                            continue
                        outcome, why = worker.outcome(path, folder)
                    c[outcome] += 1
                    if why and len(examples) < 10:
                        examples.append(f"{kind}: {why}")
                    progress.update(1)
    worker.close()
    print(f"fuzzed in {time.perf_counter() - t0:.0f} s")
    print("| loader | files | loaded-equal | clear error | other | libhdf5 hang |")
    print("|---|---|---|---|---|---|")
    for kind, c in counts.items():
        print(f"| {kind} | {sum(c.values())} | {c['loaded-equal']} | {c['clear error']} | "
              f"{c['other']} | {c['hang']} |")  # fmt: skip
    for e in examples:
        print("  not clear:", e)
    return 1 if any(c["other"] for c in counts.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
