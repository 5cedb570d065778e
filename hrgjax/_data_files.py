"""The data contract's files: CSV read with each row's line in the file
(`read_csv_table`, `with_file_line`) and written (`write_csv`); NetCDF through xarray, each
variable's `units` checked against the contract's (`UNITS`, `dataset_columns`,
`netcdf_columns`)."""

from __future__ import annotations

import contextlib
import csv
import io
import os
import re

import numpy as np

from ._data_columns import COLUMNS, MAX_EXACT_INTEGER, is_number, unit_hint

_INTEGER = re.compile(r"[+-]?\d+")


def import_xarray():
    """The `xarray` module, or an `ImportError` naming the extra that installs it."""
    try:
        import xarray as xr
    except ImportError as err:  # pragma: no cover
        raise ImportError(
            "NetCDF/xarray support needs the data extra: pip install hrgjax[data]"
        ) from err
    return xr


def write_csv(data, fh) -> None:
    """A [`MeasuredData`][hrgjax.MeasuredData] as CSV to the text file `fh`: a header row,
    run ids as integers, text as is, floats exactly (`repr`)."""
    cols = data.columns
    names = list(cols)
    w = csv.writer(fh)
    w.writerow(names)
    kinds = [cols[k].dtype.kind for k in names]
    fmt = [(lambda v: str(int(v))) if k == "i" else str if k in "US" else repr for k in kinds]
    for row in zip(*(cols[k].tolist() for k in names), strict=True):
        w.writerow([f(v) for f, v in zip(fmt, row, strict=True)])


NETCDF_EXTENSIONS = (".nc", ".nc4", ".netcdf")
"""File extensions read and written as NetCDF (HDF5, through h5netcdf)."""

UNITS: dict[str, tuple[str, ...]] = {
    "time_s": ("s", "second", "seconds", "sec"),
    "run": ("1", "", "-", "count"),
    "temperature_c": ("degC", "°C", "celsius", "degree_Celsius", "degrees_Celsius", "deg_C"),
    "table_rate_dps": ("degree/s", "deg/s", "degrees/s", "°/s", "deg s-1", "degree s-1"),
    "rate_corrected_dps": ("degree/s", "deg/s", "degrees/s", "°/s", "deg s-1", "degree s-1"),
    "table_angle_deg": ("degree", "deg", "degrees", "°"),
    "wave_angle_deg": ("degree", "deg", "degrees", "°"),
    "angle_corrected_deg": ("degree", "deg", "degrees", "°"),
    "accel_x_g": ("g", "g0", "standard_gravity"),
    "accel_y_g": ("g", "g0", "standard_gravity"),
    "accel_z_g": ("g", "g0", "standard_gravity"),
}
"""`units` attributes accepted on NetCDF variables (the first is the one written; compared
without case or spaces). `amplitude`, `quadrature` and extra columns take any unit."""

_CF_TIME = re.compile(r"\s*(\w+)\s+since\s+(.+)", re.IGNORECASE)
_CF_FACTOR = {
    "days": 86400.0, "day": 86400.0, "d": 86400.0,
    "hours": 3600.0, "hour": 3600.0, "h": 3600.0, "hr": 3600.0,
    "minutes": 60.0, "minute": 60.0, "min": 60.0,
    "seconds": 1.0, "second": 1.0, "s": 1.0, "sec": 1.0,
    "milliseconds": 1e-3, "millisecond": 1e-3, "ms": 1e-3,
    "microseconds": 1e-6, "microsecond": 1e-6, "us": 1e-6,
}  # fmt: skip


def _norm_unit(u) -> str:
    return "".join(str(u).split()).lower()


def dataset_columns(ds, where: str) -> dict[str, np.ndarray]:
    """The columns of an xarray Dataset, every variable and coordinate checked (as
    [`MeasuredData.from_xarray`][hrgjax.MeasuredData.from_xarray] says); errors begin with
    `where`."""
    columns: dict[str, np.ndarray] = {}
    dims = set()
    items = [(k, ds.data_vars[k]) for k in ds.data_vars]
    # A coordinate is a column too, unless it is a plain sample index (0, 1, 2, …).
    for k in ds.coords:
        c = ds.coords[k]
        if c.dims == (k,) and c.ndim == 1 and np.array_equal(c.values, np.arange(c.size)):
            continue
        items.append((k, c))
    for name, var in items:
        name = str(name)
        if var.ndim != 1:
            raise ValueError(
                f"{where}: variable {name!r} has dimensions {var.dims}; every column must be "
                "1-D along the one sample dimension"
            )
        dims.add(var.dims[0])
        if len(dims) > 1:
            raise ValueError(
                f"{where}: variables lie along different dimensions {sorted(dims)}; every "
                "column must be 1-D along the one sample dimension"
            )
        values = var.values
        units = var.attrs.get("units", var.encoding.get("units"))
        if units is not None:
            values = _apply_units(name, values, units, where)
        columns[name] = values
    return columns


def _apply_units(name: str, values, units, where: str):
    """`values` in the contract's unit for `name`, given its `units` attribute: checked, and
    for CF time units ("<unit> since <epoch>") converted to seconds (the epoch dropped)."""
    if name == "time_s":
        m = _CF_TIME.fullmatch(str(units))
        if m:
            factor = _CF_FACTOR.get(m.group(1).lower())
            if factor is None:
                raise ValueError(
                    f"{where}: 'time_s' has CF units {units!r}; the unit before 'since' must be "
                    f"one of {sorted(set(_CF_FACTOR))}"
                )
            if np.asarray(values).dtype.kind not in "iuf":
                raise ValueError(f"{where}: 'time_s' with units {units!r} must hold numbers")
            return np.asarray(values) * factor if factor != 1.0 else values
    accepted = UNITS.get(name)
    if accepted is None:  # amplitude, quadrature and extra columns: any unit
        return values
    if _norm_unit(units) not in {_norm_unit(u) for u in accepted}:
        hint = " or CF '<unit> since <epoch>'" if name == "time_s" else ""
        raise ValueError(
            f"{where}: variable {name!r} has units {units!r}; the data contract wants "
            f"{unit_hint(name)} ({', '.join(repr(u) for u in accepted if u)}{hint})"
        )
    return values


def netcdf_columns(path: str) -> dict[str, np.ndarray]:
    """The columns of a NetCDF file (as `dataset_columns`), or an error naming the file.

    **Raises:** `FileNotFoundError` for no file; `ValueError` for a file that h5netcdf
    cannot read or a variable that is not a column."""
    xr = import_xarray()
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file")
    failure = None
    with _quiet_h5netcdf_finalisers():
        try:
            ds = xr.open_dataset(
                path, engine="h5netcdf", decode_times=False, decode_timedelta=False
            ).load()
        except Exception as err:  # h5py/h5netcdf raise many types for a damaged file
            failure = (
                f"{path}: not a readable NetCDF (HDF5) file ({type(err).__name__}: {_flat(err)})"
            )
    if failure is not None:
        raise ValueError(failure)
    with ds:
        return dataset_columns(ds, path)


def _flat(err: BaseException) -> str:
    return " ".join(str(err).split())


@contextlib.contextmanager
def _quiet_h5netcdf_finalisers():
    """Silence the "Exception ignored in File.close" banner that h5netcdf's finaliser prints
    for a file it failed to open (the error itself is reported, in one line); the half-opened
    objects are collected before leaving."""
    import gc
    import sys

    old = sys.unraisablehook

    def hook(u):
        if not str(getattr(getattr(u, "object", None), "__module__", "")).startswith("h5netcdf"):
            old(u)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        gc.collect()
        sys.unraisablehook = old


def with_file_line(message: str, lines: np.ndarray) -> str:
    """`message` with the file's line added after the first "row i" it names (`lines`: the
    file's line of each data row, from [`read_csv_table`][hrgjax.data.read_csv_table])."""
    m = re.search(r"\brow (\d+)\b", message)
    if m is None or int(m.group(1)) >= lines.size:
        return message
    i = int(m.group(1))
    return message[: m.end()] + f" (line {lines[i]} of the file)" + message[m.end() :]


def read_csv_table(
    path: str, empty_as_nan: bool = False
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """A CSV file as `(columns, lines)`: each column parsed (numbers as float, `run` ids as
    exact integers, a column not in `COLUMNS` that is not all numbers as text) and the file's
    line number of each data row. UTF-8, a header row, `#` comment lines. `empty_as_nan`: an
    empty field is a missing number (NaN), as in a log with gaps (`hrgjax allan`); else it is
    refused in a known column and makes an extra column text.

    **Raises:** `ValueError` naming the file and its line for text that is not UTF-8, a
    malformed row, an empty or duplicate header, or a known column with text in it."""
    line = [0]

    def source(fh):
        for i, text in enumerate(fh, 1):
            line[0] = i
            if text.lstrip().startswith("#"):
                continue
            yield text

    with open(path, "rb") as fh:
        blob = fh.read()
    try:
        text = blob.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        at = blob[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}: line {at}: not UTF-8 text ({err.reason}); save the file as UTF-8 CSV"
        ) from None
    header, rows, lines = None, [], []
    try:
        for row in csv.reader(source(io.StringIO(text, newline=""))):
            if not row or all(not f.strip() for f in row):
                continue
            if header is None:
                header = [h.strip() for h in row]
                continue
            rows.append(row)
            lines.append(line[0])
    except csv.Error as err:
        raise ValueError(f"{path}: line {line[0]}: not a readable CSV row ({err})") from None
    if header is None:
        raise ValueError(f"{path}: empty file (expected a header row)")
    empty = [i for i, h in enumerate(header) if not h]
    if empty:
        raise ValueError(f"{path}: header field {empty[0] + 1} is empty; name every column")
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise ValueError(f"{path}: duplicate column names {dup} in the header")
    for r, ln in zip(rows, lines, strict=True):
        if len(r) != len(header):
            raise ValueError(f"{path}: line {ln} has {len(r)} fields, the header has {len(header)}")
    fields = {h: [r[j] for r in rows] for j, h in enumerate(header)}
    lines_arr = np.asarray(lines, dtype=np.int64)
    if empty_as_nan:
        fields = {h: [f if f.strip() else "nan" for f in v] for h, v in fields.items()}
    return {h: _parse(path, h, v, lines_arr) for h, v in fields.items()}, lines_arr


def _parse(path: str, name: str, values: list[str], lines: np.ndarray) -> np.ndarray:
    """A CSV column's fields as numbers (run ids as exact integers); an extra column that is
    not all numbers stays text."""
    stripped = [v.strip() for v in values]
    ok = [is_number(v) for v in stripped]
    if not all(ok):
        if name not in COLUMNS:
            return np.array(values, dtype=str)
        i = ok.index(False)
        raise ValueError(
            f"{path}: column {name!r} row {i} (line {lines[i]}): {values[i]!r} is not a number "
            f"in {unit_hint(name)}" + (" (empty field)" if not stripped[i] else "")
        )
    if name == "run" and all(_INTEGER.fullmatch(v) for v in stripped):
        ints = [int(v) for v in stripped]
        big = [i for i, v in enumerate(ints) if abs(v) > np.iinfo(np.int64).max]
        if big:
            i = big[0]
            raise ValueError(
                f"{path}: column 'run' row {i} (line {lines[i]}): {stripped[i]} exceeds the "
                "int64 range of run ids"
            )
        return np.array(ints, dtype=np.int64)
    if name in COLUMNS and name != "run" and any(_INTEGER.fullmatch(v) for v in stripped):
        for i, v in enumerate(stripped):
            if _INTEGER.fullmatch(v) and abs(int(v)) > MAX_EXACT_INTEGER:
                raise ValueError(
                    f"{path}: column {name!r} row {i} (line {lines[i]}): the integer {v} is too "
                    "large to hold exactly as a float64; write it in scientific notation if "
                    "rounding is intended"
                )
    return np.array([float(v) for v in stripped], dtype=float)
