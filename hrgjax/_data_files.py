"""The data contract's files: CSV read with each row's line in the file
(`read_csv_table`, `with_file_line`) and written (`write_csv`); NetCDF through xarray, each
variable's `units` checked against the contract's (`UNITS`, `dataset_columns`,
`netcdf_columns`)."""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import re
from collections.abc import Collection

import numpy as np

from ._csv_numeric import PROGRESS_LINES, numeric_rows
from ._data_columns import COLUMNS, MAX_EXACT_INTEGER, is_number, unit_hint
from ._progress import bar

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
    run ids as integers, text as is, floats exactly (`repr`). A row with a field that begins
    with `#` is written with every field quoted, so that the reader does not take the row
    for a comment.

    **Raises:** `ValueError` naming the column for a text column whose every field looks
    like a number (`'nan'`, `'1'`): CSV cannot mark it as text, so it would read back as
    numbers (or not at all); nothing is written then."""
    cols = data.columns
    names = list(cols)
    for k in names:
        check_csv_text(k, cols[k])
    w = csv.writer(fh)
    quoted = csv.writer(fh, quoting=csv.QUOTE_ALL)
    (quoted if any(_hashed(h) for h in names) else w).writerow(names)
    kinds = [cols[k].dtype.kind for k in names]
    fmt = [(lambda v: str(int(v))) if k == "i" else str if k in "US" else repr for k in kinds]
    text = any(k in "US" for k in kinds)
    for row in zip(*(cols[k].tolist() for k in names), strict=True):
        fields = [f(v) for f, v in zip(fmt, row, strict=True)]
        (quoted if text and any(_hashed(f) for f in fields) else w).writerow(fields)


def _hashed(field: str) -> bool:
    return field.lstrip().startswith("#")


def check_csv_text(name: str, values: np.ndarray) -> None:
    """Refuse a text column that a CSV file cannot hold as text: one whose every field is a
    number as the reader takes it (it would be read back as numbers, or refused for a
    'nan')."""
    if values.dtype.kind not in "US" or not all(is_number(str(v)) for v in values):
        return
    shown = ", ".join(repr(str(v)) for v in values[:3]) + (", …" if values.size > 3 else "")
    raise ValueError(
        f"column {name!r} is text whose every field looks like a number ({shown}); a CSV "
        "file would read it back as numbers: convert it (np.asarray(x, float)) or save as .nc"
    )


NETCDF_EXTENSIONS = (".nc", ".nc4", ".netcdf")
"""File extensions read and written as NetCDF (HDF5, through h5netcdf)."""

UNITS: dict[str, tuple[str, ...]] = {
    "time_s": ("s", "second", "seconds", "sec"),
    "run": ("1", "", "-", "count"),
    "temperature_c": ("degC", "°C", "celsius", "degree_Celsius", "degrees_Celsius", "deg_C"),
    "table_rate_dps": ("degree/s", "deg/s", "degrees/s", "°/s", "deg s-1", "degree s-1"),
    "rate_corrected_dps": ("degree/s", "deg/s", "degrees/s", "°/s", "deg s-1", "degree s-1"),
    "rebalance_rate_dps": ("degree/s", "deg/s", "degrees/s", "°/s", "deg s-1", "degree s-1"),
    "precession_dps": ("degree/s", "deg/s", "degrees/s", "°/s", "deg s-1", "degree s-1"),
    "table_angle_deg": ("degree", "deg", "degrees", "°"),
    "wave_angle_deg": ("degree", "deg", "degrees", "°"),
    "angle_corrected_deg": ("degree", "deg", "degrees", "°"),
    "accel_x_g": ("g", "g0", "standard_gravity", "standard_free_fall", "gravity"),
    "accel_y_g": ("g", "g0", "standard_gravity", "standard_free_fall", "gravity"),
    "accel_z_g": ("g", "g0", "standard_gravity", "standard_free_fall", "gravity"),
}
"""`units` attributes accepted on NetCDF variables (the first is the one written; compared
without case or spaces): every contract column but those of `ANY_UNIT`."""

ANY_UNIT = ("amplitude", "quadrature", "rebalance_on")
"""Contract columns in readout units, and the 0/1 flag `rebalance_on`, which take any
`units` attribute (as extra columns do: a unit check cannot catch an error in them, and other
tools write "dimensionless", "none", "bool" …) and are written without one."""

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
    # A coordinate is a column too, unless it is a plain sample index (0, 1, 2, …) named
    # like no contract column (a 'time_s' of 0, 1, 2 s is data).
    for k in ds.coords:
        c = ds.coords[k]
        index = c.dims == (k,) and c.ndim == 1 and np.array_equal(c.values, np.arange(c.size))
        if index and str(k) not in COLUMNS:
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
    if accepted is None:  # amplitude, quadrature, rebalance_on and extra columns: any unit
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

    NetCDF-4 (HDF5) through h5netcdf; NetCDF-3 (classic, 64-bit offset or data) through
    scipy where scipy is installed, else a one-line error saying so.

    **Raises:** `FileNotFoundError` for no file; `ValueError` for a file that h5netcdf
    cannot read or a variable that is not a column."""
    xr = import_xarray()
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file")
    with open(path, "rb") as fh:
        classic = fh.read(4) in (b"CDF\x01", b"CDF\x02", b"CDF\x05")
    engine, kind = "h5netcdf", "NetCDF (HDF5)"
    if classic:  # NetCDF-3: read through scipy where it is installed
        import importlib.util

        if importlib.util.find_spec("scipy") is None:
            raise ValueError(
                f"{path}: a NetCDF-3 (classic) file; hrgjax reads NetCDF-4 (HDF5): install "
                "scipy to read NetCDF-3, or convert it (nccopy -k nc4 in.nc out.nc)"
            )
        engine, kind = "scipy", "NetCDF-3"
    failure = None
    with _quiet_h5netcdf_finalisers():
        try:
            ds = xr.open_dataset(
                path, engine=engine, decode_times=False, decode_timedelta=False
            ).load()
        except Exception as err:  # h5py/h5netcdf raise many types for a damaged file
            failure = f"{path}: not a readable {kind} file ({type(err).__name__}: {_flat(err)})"
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
    path: str,
    empty_as_nan: bool = False,
    exact_integers: bool | Collection[str] = False,
    integer_offsets: Collection[str] = (),
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """A CSV file as `(columns, lines)`: each column parsed (numbers as float, `run` ids as
    exact integers, a column not in `COLUMNS` that is not all numbers as text) and the file's
    line number of each data row.

    UTF-8, a header row; a line whose first non-blank character is `#` is a comment where a
    record begins (inside a quoted field it is data; a field that begins with `#` is quoted
    by `write_csv`); a blank line (nothing but spaces) is skipped. A row whose every field is
    empty (`,,,`) is a missing sample: with `empty_as_nan` (an empty field is a missing
    number, NaN, as in a log with gaps: `hrgjax allan`) a row of NaN, else an error; without
    `empty_as_nan` an empty field is refused in a known column and makes an extra column text.
    An integer beyond 2**53, which a float64 would round, is refused in a contract column,
    and with `exact_integers` (as [`hrgjax.load`][hrgjax.load] reads) in an extra column too
    (True: every one; a collection of names: those, as `hrgjax.imu.load` and `hrgjax allan`
    read the columns they use); elsewhere an extra column's such integer reads as the
    nearest float. A column in `integer_offsets` whose every field is an integer and one
    beyond 2**53 reads as each one less the first, exact, then as float (nanosecond epoch
    stamps, 1.7e18, to the nanosecond: their differences fit a float64; `hrgjax allan
    --time-unit ns`); below 2**53 it reads as it is.

    A plain numeric file — numbers, `nan`/`inf` and, with `empty_as_nan`, empty fields (a log
    with gaps) — is streamed through NumPy's C parser in chunks (`hrgjax._csv_numeric`: ≈ 145
    MB and 1–1.5 s for 10⁶ rows × 7 columns, an empty field in every row too; where comments,
    blank lines, rows of empty fields or blanks in empty fields are frequent, up to ≈ 5 s,
    read line by line); any other (quotes, text, an integer to check exactly, a field to
    refuse) is read by Python's csv module, one string per field (≈ 750 bytes a row), which
    names what is wrong. Both give the same columns and lines. A read of more than 10⁶ lines
    shows a progress bar (stderr, at a terminal; `HRGJAX_QUIET`).

    **Raises:** `ValueError` naming the file and its line for text that is not UTF-8, a
    malformed row, a row of empty fields, an empty, numeric or duplicate header, or a known
    column with text in it."""
    line = [0]
    at_start = [True]  # the CSV reader asks for a line that begins a record (not one inside quotes)

    def source(fh, progress):
        for i, text in enumerate(fh, 1):
            line[0] = i
            if progress is not None and not i & 0xFFFF:
                progress.update(0x10000)
            if at_start[0] and text.lstrip().startswith("#"):
                continue
            at_start[0] = False
            yield text

    if not isinstance(exact_integers, bool):
        exact_integers = frozenset([exact_integers] if isinstance(exact_integers, str)
                                   else exact_integers)  # fmt: skip
    fast = _numeric_table(path, empty_as_nan, exact_integers, integer_offsets)
    if fast is not None:
        return fast
    with open(path, "rb") as fh:
        blob = fh.read()
    try:
        blob.decode("utf-8-sig")  # (checked whole; read below a part at a time)
    except UnicodeDecodeError as err:
        at = blob[: err.start].count(b"\n") + 1
        raise ValueError(
            f"{path}: line {at}: not UTF-8 text ({err.reason}); save the file as UTF-8 CSV"
        ) from None
    # lines as a StringIO(text, newline="") gives them, without its 4 bytes a character
    text = io.TextIOWrapper(io.BytesIO(blob), encoding="utf-8-sig", newline="")
    header, rows, lines = None, [], []
    total = blob.count(b"\n")
    shown = (
        bar(total, f"reading {os.path.basename(path)}", unit="line")
        if total > PROGRESS_LINES
        else contextlib.nullcontext()
    )
    try:
        with shown as progress:
            for row in csv.reader(source(text, progress)):
                at_start[0] = True
                if not row or (len(row) == 1 and not row[0].strip()):
                    continue  # a blank line
                if header is None:
                    header = [h.strip() for h in row]
                    header_line = line[0]
                    continue
                rows.append(row)
                lines.append(line[0])
            if progress is not None:
                progress.update(progress.total - (line[0] & ~0xFFFF))
    except csv.Error as err:
        raise ValueError(f"{path}: line {line[0]}: not a readable CSV row ({err})") from None
    del text, blob  # (each field is its own string now)
    empty = [all(not f.strip() for f in row) for row in rows]
    while rows and empty[-1]:  # a spreadsheet's trailing rows of empty fields hold no sample
        rows.pop(), lines.pop(), empty.pop()
    if any(empty) and not empty_as_nan:
        raise ValueError(
            f"{path}: line {lines[empty.index(True)]}: every field is empty (a missing "
            "sample?); only blank lines and empty rows after the data are skipped: fill the "
            "row in or delete it"
        )
    if header is None:
        raise ValueError(f"{path}: empty file (expected a header row)")
    check_header(path, header, header_line)
    for r, ln in zip(rows, lines, strict=True):
        if len(r) != len(header):
            raise ValueError(f"{path}: line {ln} has {len(r)} fields, the header has {len(header)}")
    lines_arr = np.asarray(lines, dtype=np.int64)

    def fields(j: int) -> list[str]:  # (one column's strings at a time, not every one's)
        v = [r[j] for r in rows]
        return [f if f.strip() else "nan" for f in v] if empty_as_nan else v

    offsets = {h: _offsets(fields(j)) for j, h in enumerate(header) if h in integer_offsets}
    columns = {}
    shown = (
        bar(len(header), f"parsing {os.path.basename(path)}", unit="column")
        if total > PROGRESS_LINES  # (as the reading's bar)
        else contextlib.nullcontext()
    )
    with shown as progress:
        for j, h in enumerate(header):
            exact = offsets.get(h)
            columns[h] = (
                _parse(path, h, fields(j), lines_arr, exact_integers) if exact is None else exact
            )
            if progress is not None:
                progress.update(1)
    return columns, lines_arr


def _offsets(fields: list[str]) -> np.ndarray | None:
    """Integer fields that reach 2**53 as each one less the first, exact (`read_csv_table`'s
    `integer_offsets`); None for any other column."""
    stripped = [f.strip() for f in fields]
    if not stripped or not all(_INTEGER.fullmatch(f) for f in stripped):
        return None
    ints = [int(f) for f in stripped]
    if max(abs(v) for v in ints) < MAX_EXACT_INTEGER:
        return None
    return np.array([float(v - ints[0]) for v in ints], dtype=float)


def check_header(path: str, header: list[str], at: int) -> None:
    """Refuse a CSV header (stripped fields, from line `at`) that does not name the columns:
    an empty field (a pandas index), a row of numbers (a header commented out with `#`), one
    field holding another separator, or a name given twice."""
    empty = [i for i, h in enumerate(header) if not h]
    if empty:
        hint = (
            " (an unnamed first column is the index pandas writes: save with "
            "df.to_csv(path, index=False))"
            if empty[0] == 0 and len(header) > 1
            else ""
        )
        raise ValueError(f"{path}: header field {empty[0] + 1} is empty; name every column{hint}")
    if all(is_number(h) for h in header):
        raise ValueError(
            f"{path}: line {at}, the header row, holds numbers ({', '.join(header[:3])}"
            f"{', …' if len(header) > 3 else ''}); the first row that is not a comment must "
            "name the columns — is the header commented out with '#' (np.savetxt(header=…) "
            "writes '# time_s,…'; pass comments='')?"
        )
    if len(header) == 1:
        sep = next((c for c in (";", "\t", "|") if c in header[0]), None)
        if sep is not None:
            raise ValueError(
                f"{path}: the header has one field {header[0][:60]!r}; columns must be "
                f"separated by commas, and this file looks separated by {sep!r}"
            )
    if len(set(header)) != len(header):
        dup = sorted({h for h in header if header.count(h) > 1})
        raise ValueError(f"{path}: duplicate column names {dup} in the header")


def rounded_integer(field: str) -> bool:
    """Whether the text `field` (surrounding blanks ignored) is an integer that a float64
    does not hold exactly: beyond 2**53 and not a float64's value (2**60 and 1e20 as "%.0f"
    writes it are; 2**53 + 1 and an integer beyond float range are not). The check of every
    loader that reads integers as floats (`read_csv_table`, `hrgjax.ins.alignment.load_psins`)."""
    v = field.strip()
    if len(v) < 16 or not _INTEGER.fullmatch(v):  # (fewer than 16 digits: below 2**53)
        return False
    n = int(v)
    if abs(n) <= MAX_EXACT_INTEGER:
        return False
    f = float(v)
    return not (math.isfinite(f) and int(f) == n)


def rounded_integer_error(where: str, field: str) -> str:
    """The one-line message refusing the integer text `field` (see `rounded_integer`) at
    `where` (the file, the column and the row)."""
    return (
        f"{where}: the integer {field.strip()} is too large to hold exactly as a float64; "
        "write it in scientific notation if rounding is intended"
    )


def _wants_exact(name: str, exact_integers: bool | Collection[str]) -> bool:
    if isinstance(exact_integers, bool):
        return exact_integers
    return name in exact_integers


def _parse(
    path: str,
    name: str,
    values: list[str],
    lines: np.ndarray,
    exact_integers: bool | Collection[str] = False,
) -> np.ndarray:
    """A CSV column's fields as numbers (run ids as exact integers); an extra column that is
    not all numbers stays text. An integer beyond 2**53 is refused in a contract column (an
    extra one too with `exact_integers`)."""
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
    checked = name in COLUMNS or _wants_exact(name, exact_integers)
    if checked and name != "run":
        for i, v in enumerate(stripped):
            if rounded_integer(v):
                where = f"{path}: column {name!r} row {i} (line {lines[i]})"
                raise ValueError(rounded_integer_error(where, v))
    out = np.array([float(v) for v in stripped], dtype=float)
    if name == "run" and np.all(np.abs(out) < MAX_EXACT_INTEGER) and np.all(out == np.round(out)):
        return out.astype(np.int64)  # run ids written 1.0 or 1e2: exact integers too
    return out


def _numeric_table(
    path: str,
    empty_as_nan: bool = False,
    exact_integers: bool | Collection[str] = False,
    integer_offsets: Collection[str] = (),
):
    """`read_csv_table`'s result for a plain numeric file (numbers, `nan`/`inf`, and with
    `empty_as_nan` empty fields), streamed through NumPy's C parser in chunks of lines
    (`hrgjax._csv_numeric`: no Python string per field, no copy of the whole text); None for
    anything else — text that is not UTF-8, quotes, a lone carriage return, any character
    but those of numbers, commas and blanks in a data line, a row with another number of
    fields, an empty field without `empty_as_nan`, a value of 2**53 or more that may be an
    integer the float rounded, in a column whose integers are checked exactly (the
    contract's, those `exact_integers` names, those of `integer_offsets`) — which the
    validating reader then reads and names. Over that alphabet NumPy accepts exactly the
    fields `is_number` accepts (tests/test_files.py), so both paths give the same columns.
    An inf there is the text `inf` where every line is shorter than `_INF_DIGITS` bytes."""
    got = numeric_rows(path, empty_as_nan)
    if got is None:
        return None
    header, at, values, lines, longest = got
    check_header(path, header, at)
    inf_is_text = longest < _INF_DIGITS
    columns = {}
    for j, name in enumerate(header):
        col = np.ascontiguousarray(values[:, j])
        checked = name in COLUMNS or _wants_exact(name, exact_integers) or name in integer_offsets
        if checked and beyond_exact({name: col}, inf_is_text):
            return None  # (2**53 + 1 reads 2**53: the validating reader checks the text)
        if (
            name == "run"
            and np.all(np.abs(col) < MAX_EXACT_INTEGER)
            and np.all(col == np.round(col))
        ):
            col = col.astype(np.int64)  # (else floats, as the validating reader's)
        columns[name] = col
    return columns, lines


_INF_DIGITS = len(str(2**1024 - 2**970))
"""309: the fewest digits of an integer that a float64 rounds to inf (2**1024 - 2**970, half
an ulp above the largest float); a line with no more bytes holds no such integer."""


def beyond_exact(columns: dict[str, np.ndarray], inf_is_text: bool = False) -> bool:
    """Whether a float column holds a value of magnitude 2**53 or more: there the text may
    have been an integer that the float rounded (2**53 + 1 reads 2**53), which the validating
    reader checks exactly (`read_csv_table` with `exact_integers`); NaN (a gap) is not, nor
    inf where `inf_is_text` (the text was `inf`: no line long enough for an integer that
    rounds to inf, `_INF_DIGITS`)."""
    top = MAX_EXACT_INTEGER
    return any(
        c.dtype.kind == "f" and bool(np.any((np.abs(c) >= top) & ~(inf_is_text & np.isinf(c))))
        for c in columns.values()
    )
