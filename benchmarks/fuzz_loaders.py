"""Fuzz `hg.load` (CSV and NetCDF) and count what happens to each file.

`.venv/bin/python benchmarks/fuzz_loaders.py [--csv 20000] [--nc 2000] [--plans 2000]
[--sections 2000] [--calibrations 2000] [--imu 2000] [--seed 0]`

It also fuzzes the other file loaders: bench plans (`load_plan`), Ferraris sections
(`parse_sections` on a JSON file), IMU calibrations (`load_calibration`) and IMU CSVs
(`hg.imu.load`). Each JSON file starts as a valid document and gets one or two mutations
(a value replaced by text, None, a bool, nested lists, a huge, negative or tiny number; a
key or item dropped, duplicated or renamed; a raw token JSON or Python cannot hold — NaN,
1e400, 24 digits, 3000-deep nesting —; a duplicated top-level key; a truncated file); each
IMU CSV starts as a valid record (`ImuData.save`'s columns) and gets text, empty fields,
huge values, missing or misspelt columns, short rows, reordered rows, other units, bytes
that are not UTF-8. Their outcomes are **loaded** (no round trip: these loaders have no
matching writer for a mutated document), **clear error** or **other** — which also counts
a warning printed (NumPy's overflow, say) while loading.

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
from functools import partial

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


def _error_outcome(err: Exception, path: str):
    """A one-line ValueError / FileNotFoundError naming the file is a clear error; anything
    else escaped."""
    text = str(err)
    if isinstance(err, ValueError | FileNotFoundError) and path in text and "\n" not in text:
        return "clear error", None
    return "other", f"{type(err).__name__}: {text[:300]}"


def _outcome(path, folder):
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = hg.load(path, allow_extra=True)
    except Exception as err:  # noqa: BLE001 - counting what escapes is the point
        return _error_outcome(err, path)
    again_path = os.path.join(folder, "again" + os.path.splitext(path)[1])
    try:
        again = hg.load(data.save(again_path), allow_extra=True)
    except Exception as err:  # noqa: BLE001
        return "other", f"round trip: {type(err).__name__}: {str(err)[:300]}"
    return ("loaded-equal", None) if again == data else ("other", "round trip changed the data")


# --- JSON files (plans, sections, calibrations) and IMU CSVs --------------------------------

_JUNK = [None, True, False, "", "abc", "1.5", "nan", "NaN", "inf", "-1", [], {}, [[[1]]],
         [1, "a"], {"start": 1}, 0, -1, -1e300, 1e308, 10**18, -(10**18), 0.5, 1e-320,
         [0, 1], [[0, 1], [1, 2]], {"a": {"b": [None]}}]  # fmt: skip
_RAW = ["NaN", "Infinity", "-Infinity", "1e400", "-1e400", "123456789012345678901234",
        "[" * 3000 + "]" * 3000, '"\\ud800"', "1E+308", "-0"]  # fmt: skip


def _mutate_json(rng, doc):
    """One random mutation of a JSON value (a copy): a value replaced (strings, None, bools,
    nested lists, huge, negative or tiny numbers), a key or item dropped, duplicated or
    renamed, a value wrapped in a list, a raw token JSON or Python cannot hold (NaN, 1e400,
    24 digits, deep nesting), or the whole document replaced. Returns JSON text."""
    import copy
    import json

    doc = copy.deepcopy(doc)
    parent, key, node = None, None, doc
    for _ in range(rng.integers(0, 5)):  # walk down a random path
        if isinstance(node, dict) and node:
            k = list(node)[rng.integers(len(node))]
        elif isinstance(node, list) and node:
            k = int(rng.integers(len(node)))
        else:
            break
        parent, key, node = node, k, node[k]
    op = rng.integers(7)
    raw = None
    if parent is None or op == 0:  # replace the value (or the whole document)
        value = copy.deepcopy(_JUNK[rng.integers(len(_JUNK))])
        if parent is None:
            doc = value
        else:
            parent[key] = value
    elif op == 1:  # drop it
        del parent[key]
    elif op == 2:  # duplicate it (a list item twice; a key under another name)
        if isinstance(parent, list):
            parent.insert(key, copy.deepcopy(node))
        else:
            parent[f"{key}_2"] = copy.deepcopy(node)
    elif op == 3:  # wrap it in a list
        parent[key] = [node]
    elif op == 4:  # a raw token
        parent[key] = "\x00RAW\x00"
        raw = _RAW[rng.integers(len(_RAW))]
    elif op == 5:  # a number made negative, huge or zero
        parent[key] = (
            -node if isinstance(node, (int, float)) and not isinstance(node, bool) else 1e308
        )
        if rng.random() < 0.3:
            parent[key] = 0
    else:  # the same value with its type changed: text or a one-element list
        parent[key] = str(node) if rng.random() < 0.5 else [node]
    text = json.dumps(doc)
    if raw is not None:
        text = text.replace('"\\u0000RAW\\u0000"', raw)
    k = rng.integers(12)
    if k == 0:  # a duplicated top-level key (the later one wins in JSON)
        text = text[:-1] + ', "segments": null}' if text.endswith("}") else text
    elif k == 1:
        text = text[: rng.integers(len(text) + 1)]  # truncated
    return text


def _json_outcome(load, path):
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            load(path)
    except Exception as err:  # noqa: BLE001 - counting what escapes is the point
        return _error_outcome(err, path)
    if caught:
        return "other", f"warning: {caught[0].category.__name__}: {str(caught[0].message)[:200]}"
    return "loaded", None


def _base_documents():
    """Valid plan, sections and calibration documents (one small Ferraris fit, seconds)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from hrgjax.calibration import design
    from hrgjax.imu import ferraris, ferraris_session
    from hrgjax.imu.ferraris import ImuCalibration
    from hrgjax.imu.sections import sections_to_json

    segs = design.seed_bench_plan(quick=True).segments()[::19]
    segs.append({"kind": "ramp", "temperature_start_c": 20.0, "temperature_end_c": 25.0,
                 "wave_angle_deg": 10.0, "rate_dps": 5.0, "duration_s": 600.0})  # fmt: skip
    plan = design.BenchPlan.from_segments(segs)
    plan_doc = design.plan_to_json(
        plan, resolution={"temperature_c": 0.1, "wave_angle_deg": 0.1, "duration_s": 1.0}
    )
    truth = ImuCalibration.known(gyro_bias=np.array([0.01, -0.02, 0.005]))
    data, sections = ferraris_session(truth, jax.random.key(0), rate_hz=50.0, repeats=2,
                                      static_s=3.0)  # fmt: skip
    cal = ferraris(data, sections)
    return plan_doc, (sections_to_json(sections), len(data)), cal.to_json(), data


IMU_COLUMNS = {"time": "time_s", "gyro": ["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"],
               "accel": ["accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"]}  # fmt: skip
IMU_UNITS = {"gyro": "rad/s", "accel": "m/s^2"}
_IMU_TEXT = ["", " ", "abc", "nan", "inf", "-inf", "1_000", "1,000", "1e", "1e400", "1e308",
             "-1e308", "1e300", "0x1f", "99999999999999999999999", "True", "½", "١٢", "1.5",
             '"', "\x00", "2024-01-01"]  # fmt: skip


def _imu_csv(rng, base_rows):
    header = ["time_s", *IMU_COLUMNS["gyro"], *IMU_COLUMNS["accel"], "temperature_c"]
    rows = [list(r) for r in base_rows]
    units = dict(IMU_UNITS)
    for _ in range(rng.integers(1, 4)):
        kind = rng.integers(10)
        r = rng.integers(len(rows)) if rows else 0
        if kind == 0 and rows:  # a field replaced by odd text or a huge value
            c = rng.integers(len(header))
            if c < len(rows[r]):
                rows[r][c] = str(_IMU_TEXT[rng.integers(len(_IMU_TEXT))])
        elif kind == 1 and rows and rows[r]:  # an empty field
            rows[r][rng.integers(len(rows[r]))] = ""
        elif kind == 2:  # a column missing, duplicated or misspelt in the header
            c = rng.integers(len(header))
            header[c] = [header[(c + 1) % len(header)], header[c] + "x"][rng.integers(2)]
            if rng.random() < 0.3:
                header.pop(c)
        elif kind == 3 and rows and rows[r]:  # a row cut short or lengthened
            rows[r] = (
                rows[r][: rng.integers(len(rows[r]))] if rng.random() < 0.5 else rows[r] + ["1"]
            )
        elif kind == 4 and rows:  # rows swapped or duplicated (time backwards, repeated)
            j = rng.integers(len(rows))
            if rng.random() < 0.5:
                rows[r], rows[j] = rows[j], rows[r]
            else:
                rows.insert(j, list(rows[r]))
        elif kind == 5:  # all rows or all but one gone
            del rows[rng.integers(0, 2) :]
        elif kind == 6:  # other declared units (deg/s, g: the accel check)
            units = {"gyro": str(rng.choice(["deg/s", "rad/s"])),
                     "accel": str(rng.choice(["g", "m/s^2"]))}  # fmt: skip
        elif kind == 7 and rows:  # a whole column scaled by a huge factor
            c = rng.integers(len(header))
            for row in rows:
                if c < len(row):
                    row[c] = repr(float(row[c]) * 1e306) if _num(row[c]) else row[c]
        elif kind == 8 and rows:  # a comment line or a blank line inside
            rows.insert(r, ["# note"] if rng.random() < 0.5 else [])
        elif kind == 9 and rows:  # a time step of zero or a constant time
            for row in rows:
                if row and _num(row[0]):
                    row[0] = "0"
    text = ",".join(header) + "\n" + "\n".join(",".join(r) for r in rows) + "\n"
    blob = text.encode("utf-8")
    k = rng.integers(10)
    if k == 0:
        i = rng.integers(len(blob) + 1)
        blob = blob[:i] + b"\xff" + blob[i:]
    elif k == 1:
        blob = blob[: rng.integers(len(blob) + 1)]
    return blob, units


def _num(v) -> bool:
    try:
        float(v)
    except ValueError:
        return False
    return True


def _imu_rows(data):
    table = np.column_stack([data.time, data.gyro, data.accel, data.temperature
                             if data.temperature is not None else np.full(len(data), 20.0)])  # fmt: skip
    return [[repr(float(v)) for v in row] for row in table[:40]]


def fuzz_documents(rng, n_plans, n_sections, n_calibrations, n_imu, folder, counts, examples):
    """Count the outcomes of mutated plan, sections and calibration files and IMU CSVs."""
    import json

    from hrgjax.calibration.design import load_plan
    from hrgjax.imu import load as imu_load
    from hrgjax.imu.ferraris import load_calibration
    from hrgjax.imu.sections import parse_sections

    plan_doc, (sec_doc, n_samples), cal_doc, data = _base_documents()
    imu_rows = _imu_rows(data)
    families = [
        ("plans", n_plans, plan_doc, load_plan),
        ("sections", n_sections, sec_doc, lambda p: parse_sections(p, n_samples)),
        ("calibrations", n_calibrations, cal_doc, load_calibration),
    ]
    for kind, n, doc, load in families:
        c = counts.setdefault(kind, dict.fromkeys(("loaded", "clear error", "other"), 0))
        path = os.path.join(folder, f"fuzz_{kind}.json")
        with bar(n, f"fuzzing {kind}", unit="file") as progress:
            for _ in range(n):
                text = _mutate_json(rng, doc)
                for _ in range(rng.integers(0, 2)):  # sometimes a second mutation
                    try:
                        text = _mutate_json(rng, json.loads(text))
                    except (ValueError, RecursionError):  # a raw token: keep the first
                        break
                with open(path, "w", encoding="utf-8") as fh:
                    fh.write(text)
                outcome, why = _json_outcome(load, path)
                c[outcome] += 1
                if why and len(examples) < 10:
                    examples.append(f"{kind}: {why} <- {text[:200]!r}")
                progress.update(1)
    c = counts.setdefault("imu csv", dict.fromkeys(("loaded", "clear error", "other"), 0))
    path = os.path.join(folder, "fuzz_imu.csv")
    with bar(n_imu, "fuzzing imu csv", unit="file") as progress:
        for _ in range(n_imu):
            blob, units = _imu_csv(rng, imu_rows)
            with open(path, "wb") as fh:
                fh.write(blob)
            outcome, why = _json_outcome(partial(imu_load, columns=IMU_COLUMNS, units=units), path)
            c[outcome] += 1
            if why and len(examples) < 10:
                examples.append(f"imu csv: {why} <- {blob[:200]!r}")
            progress.update(1)


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
    for name in ("plans", "sections", "calibrations", "imu"):
        parser.add_argument(f"--{name}", type=int, default=2_000,
                            help=f"{name} files (default 2000)")  # fmt: skip
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
        fuzz_documents(rng, args.plans, args.sections, args.calibrations, args.imu, folder,
                       counts, examples)  # fmt: skip
    worker.close()
    print(f"fuzzed in {time.perf_counter() - t0:.0f} s")
    print("| loader | files | loaded(-equal) | clear error | other | libhdf5 hang |")
    print("|---|---|---|---|---|---|")
    for kind, c in counts.items():
        if not sum(c.values()):
            continue
        loaded = c.get("loaded-equal", c.get("loaded"))
        print(f"| {kind} | {sum(c.values())} | {loaded} | {c['clear error']} | "
              f"{c['other']} | {c.get('hang', '–')} |")  # fmt: skip
    for e in examples:
        print("  not clear:", e)
    return 1 if any(c["other"] for c in counts.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
