"""`MeasuredData`: the measured-data contract (DESIGN.md), validation, CSV and NetCDF I/O."""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import numbers
import os
import re
from collections.abc import Iterator, Mapping

import numpy as np

from . import plausible
from ._io import atomic_path, atomic_write
from .units import DEG, K_E_NOMINAL

COLUMNS: dict[str, str] = {
    "time_s": "time [s], strictly increasing within a run",
    "run": "integer id of a segment (default 0)",
    "temperature_c": "resonator temperature [°C]",
    "table_rate_dps": "reference rate about the sensitive axis [°/s]",
    "table_angle_deg": "reference angle [°] (integrated from the rate when absent)",
    "wave_angle_deg": "measured wave angle [°, electrical], unwrapped",
    "amplitude": "principal amplitude [readout units]",
    "quadrature": "quadrature amplitude [readout units]",
    "accel_x_g": "specific force along case x [g]",
    "accel_y_g": "specific force along case y [g]",
    "accel_z_g": "specific force along case z (sensitive axis) [g]",
    "rate_corrected_dps": "equivalent input rate after compensation [°/s] (`hrgjax correct`)",
    "angle_corrected_deg": "case rotation angle since the start of the run [°] (`hrgjax correct`)",
}
"""Known columns and their meaning (units in brackets)."""
REQUIRED = ("time_s", "temperature_c", "table_rate_dps", "wave_angle_deg")
"""Columns every dataset must have."""

_NUMBER = re.compile(
    r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?|[+-]?(?:nan|inf|infinity)", re.IGNORECASE
)
"""A number as the CSV reader accepts it: decimal or scientific notation, or nan/inf (which
the validation then names); no thousands separators or underscores."""
_INTEGER = re.compile(r"[+-]?\d+")


def is_number(field: str) -> bool:
    """Whether a CSV field (surrounding blanks ignored) is a number as the CSV reader takes
    it: decimal or scientific notation, or nan/inf."""
    return _NUMBER.fullmatch(field.strip()) is not None


class MeasuredData:
    """A measured (or simulated) gyro record in the units of the data contract.

    One row per sample; columns are 1-D float arrays (``run`` is integer; extra columns kept
    with `allow_extra` may also hold text). The data are validated on construction and never
    altered: an absent ``run`` reads as all zeros and an absent ``table_angle_deg`` as the
    per-run integral of the rate, without adding columns.

    **Arguments:**

    - `columns`: mapping of column name → 1-D array.
    - `allow_extra`: keep columns not in [`hrgjax.data.COLUMNS`][] (otherwise an error).

    **Raises:** `ValueError` naming the column (and first bad row) for a missing required
    column, an unknown column, mismatched lengths, values that are not real numbers (text in
    a contract column, booleans, complex numbers, dates or durations), NaN or infinite
    values, integers too large to hold exactly, a run id that is not an exactly representable
    integer, or time that does not strictly increase within a run (checked run by run, also
    when the rows of several runs are interleaved).
    """

    def __init__(self, columns: Mapping[str, object], allow_extra: bool = False):
        if not isinstance(columns, Mapping):
            raise TypeError(f"columns must be a mapping of name -> 1-D array; got {type(columns)}")
        unknown = [k for k in columns if k not in COLUMNS]
        if unknown and not allow_extra:
            raise ValueError(
                f"unknown column(s) {unknown}; known columns are {list(COLUMNS)} "
                "(pass allow_extra=True / --allow-extra to keep extra columns)"
            )
        missing = [k for k in REQUIRED if k not in columns]
        if missing:
            raise ValueError(f"missing required column(s) {missing}; required are {list(REQUIRED)}")
        cols: dict[str, np.ndarray] = {}
        n = None
        for name, value in columns.items():
            if not isinstance(name, str):
                raise ValueError(f"column names must be strings; got {name!r}")
            arr = _column(name, value)
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise ValueError(
                    f"column {name!r} has {arr.shape[0]} rows but 'time_s'/the first column has {n}"
                )
            arr.setflags(write=False)
            cols[name] = arr
        if n == 0:
            raise ValueError("the data have no rows")
        self._columns = cols
        _check_time(cols["time_s"], self.run)
        for name in ("temperature_c", "table_rate_dps", "wave_angle_deg"):
            plausible.check(f"column {name!r}", cols[name], name)
        turning = cols["table_rate_dps"] != 0.0
        if turning.any():  # the table angle (a per-run integral) only where the table turns
            moving = np.isin(self.run, np.unique(self.run[turning]))
            plausible.check_wave_angle_units(cols["wave_angle_deg"], self.table_angle_deg,
                                             self.run, moving, K_E_NOMINAL)  # fmt: skip

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """The columns as given (read-only arrays)."""
        return dict(self._columns)

    @property
    def names(self) -> list[str]:
        """Column names, in the order given."""
        return list(self._columns)

    def __len__(self) -> int:
        return self._columns["time_s"].shape[0]

    def __contains__(self, name) -> bool:
        return name in self._columns

    def __getitem__(self, name: str) -> np.ndarray:
        if name == "run" and "run" not in self._columns:
            return self.run
        if name == "table_angle_deg" and name not in self._columns:
            return self.table_angle_deg
        if name not in self._columns:
            raise KeyError(f"no column {name!r}; this dataset has {self.names}")
        return self._columns[name]

    def __eq__(self, other) -> bool:
        if not isinstance(other, MeasuredData) or self.names != other.names:
            return False
        return all(np.array_equal(self._columns[k], other._columns[k]) for k in self.names)

    def __repr__(self) -> str:
        return (
            f"MeasuredData({len(self)} rows, runs={len(np.unique(self.run))}, columns={self.names})"
        )

    @property
    def run(self) -> np.ndarray:
        """Run ids (zeros when the column is absent)."""
        if "run" in self._columns:
            return self._columns["run"]
        return np.zeros(self._columns["time_s"].shape[0], dtype=np.int64)

    @property
    def table_angle_deg(self) -> np.ndarray:
        """Reference angle [°]: the column, or the trapezoidal integral of the rate per run."""
        if "table_angle_deg" in self._columns:
            return self._columns["table_angle_deg"]
        out = np.empty(len(self))
        t, w = self._columns["time_s"], self._columns["table_rate_dps"]
        for idx in self.run_indices():
            seg = 0.5 * (w[idx][1:] + w[idx][:-1]) * np.diff(t[idx])
            out[idx] = np.concatenate([[0.0], np.cumsum(seg)])
        return out

    def run_indices(self) -> list[np.ndarray]:
        """Row indices of each run, in order of first appearance."""
        run = self.run
        _, first = np.unique(run, return_index=True)
        return [np.nonzero(run == run[i])[0] for i in sorted(first)]

    def runs(self) -> Iterator[MeasuredData]:
        """Iterate over runs as separate datasets."""
        for idx in self.run_indices():
            yield MeasuredData({k: v[idx] for k, v in self._columns.items()}, allow_extra=True)

    def stacked(self) -> list[RunStack]:
        """The runs in SI, stacked: one [`RunStack`][hrgjax.data.RunStack] per (length,
        sample interval), ordered by length then interval, runs in order of first appearance.

        The one "group runs, stack, convert" view that calibration (physical fit, end-to-end
        MLP training) and discovery (continuous records) build on; the data are not altered.
        """
        buckets: dict[tuple[int, float], list[np.ndarray]] = {}
        t_all = self._columns["time_s"]
        for idx in self.run_indices():
            dt = float(np.median(np.diff(t_all[idx]))) if idx.size > 1 else 0.0
            buckets.setdefault((idx.size, float(f"{dt:.9g}")), []).append(idx)
        return [RunStack._of(self, rows) for _, rows in sorted(buckets.items())]

    def save(self, path: str | os.PathLike) -> str:
        """Write CSV (``.csv``) or NetCDF (``.nc``, with each column's ``units``); returns the
        path. Round trips are exact. The file is written under a temporary name and renamed
        when complete, so an interrupted save never leaves a partial file."""
        path = os.fspath(path)
        ext = os.path.splitext(path)[1].lower()
        if ext == ".csv":
            with atomic_write(path, "w", newline="", encoding="utf-8") as fh:
                _write_csv(self, fh)
        elif ext in NETCDF_EXTENSIONS:
            ds = self.to_xarray()
            with atomic_path(path) as tmp:
                ds.to_netcdf(tmp, engine="h5netcdf")
        else:
            raise ValueError(f"unknown data file extension {ext!r}; use .csv or .nc")
        return path

    def to_xarray(self):
        """An `xarray.Dataset` with one variable per column along dimension ``sample``, each
        contract column with its ``units`` attribute (UDUNITS spelling)."""
        xr = _import_xarray()
        return xr.Dataset(
            {
                k: ("sample", v, {"units": UNITS[k][0]} if k in UNITS else {})
                for k, v in self._columns.items()
            }
        )

    @classmethod
    def from_xarray(cls, ds, allow_extra: bool = False) -> MeasuredData:
        """Build from an `xarray.Dataset` whose variables (and coordinates) are 1-D along one
        dimension. A ``units`` attribute must agree with the column's unit
        ([`hrgjax.data.UNITS`][]); ``time_s`` may also carry CF units ("seconds since …",
        "minutes since …", …), converted to seconds; coordinates other than a plain sample
        index are columns like any other (unknown ones need `allow_extra`)."""
        return cls(_dataset_columns(ds, "the dataset"), allow_extra=allow_extra)


MAX_EXACT_INTEGER = 2**53
"""Largest integer magnitude a float64 holds exactly; larger run ids or integer values are
refused rather than rounded."""


@dataclasses.dataclass(frozen=True, eq=False)
class RunStack:
    """Runs of one length and one sample interval, stacked in SI (leading axis = run).

    Built by [`MeasuredData.stacked`][hrgjax.data.MeasuredData.stacked]; NumPy arrays, read
    only. Angles are in rad (the wave angle electrical), rates in rad/s, specific force in g.

    **Fields:**

    - `run`: (R,) run ids; `rows`: (R, N) row indices into the dataset.
    - `t`: (R, N) time [s]; `dt`: the first run's median sample interval [s].
    - `wave_angle`: (R, N) measured wave angle [rad, electrical].
    - `rate`: (R, N) reference rate [rad/s]; `table_angle`: (R, N) reference angle since the
      start of each run [rad].
    - `temperature`: (R, N) [°C].
    - `accel`: (R, N, 3) specific force along case x, y, z [g] (absent axes read 0).
    - `amplitude`, `quadrature`: (R, N) [readout units] (absent: 1 and 0).
    - `static`: (R,) true for runs with the table at rest throughout.
    """

    run: np.ndarray
    rows: np.ndarray
    t: np.ndarray
    dt: float
    wave_angle: np.ndarray
    rate: np.ndarray
    table_angle: np.ndarray
    temperature: np.ndarray
    accel: np.ndarray
    amplitude: np.ndarray
    quadrature: np.ndarray
    static: np.ndarray

    def __len__(self) -> int:
        return self.run.shape[0]

    @property
    def n_samples(self) -> int:
        """Samples per run."""
        return self.rows.shape[1]

    @classmethod
    def _of(cls, data: MeasuredData, rows: list[np.ndarray]) -> RunStack:
        rows = np.stack(rows)
        cols = data._columns
        n = rows.shape[1]

        def col(name, default):
            return cols[name][rows] if name in cols else np.full(rows.shape, default)

        table = data.table_angle_deg[rows] * DEG
        rate = cols["table_rate_dps"][rows] * DEG
        t = cols["time_s"][rows]
        out = cls(
            run=data.run[rows[:, 0]],
            rows=rows,
            t=t,
            dt=float(np.median(np.diff(t[0]))) if n > 1 else 0.0,
            wave_angle=cols["wave_angle_deg"][rows] * DEG,
            rate=rate,
            table_angle=table - table[:, :1],
            temperature=cols["temperature_c"][rows],
            accel=np.stack([col(f"accel_{a}_g", 0.0) for a in "xyz"], axis=-1),
            amplitude=col("amplitude", 1.0),
            quadrature=col("quadrature", 0.0),
            static=np.all(rate == 0.0, axis=1),
        )
        for f in dataclasses.fields(out):
            v = getattr(out, f.name)
            if isinstance(v, np.ndarray):
                v.setflags(write=False)
        return out


def _column(name: str, value) -> np.ndarray:
    """One column as a new array: float64 (``run``: int64; an extra column: float64 or text),
    or a `ValueError` naming the column, the row and the expected form."""
    arr = np.asarray(value)
    if arr.ndim != 1:
        raise ValueError(f"column {name!r} must be 1-D (one value per row); got shape {arr.shape}")
    unit = _unit_hint(name)
    kind = arr.dtype.kind
    if kind in "Mm":
        example = ", e.g. (t - t[0]) / np.timedelta64(1, 's')" if name == "time_s" else ""
        raise ValueError(
            f"column {name!r} holds {arr.dtype} values (dates or durations); give plain "
            f"numbers in {unit}{example}"
        )
    if kind == "c":
        raise ValueError(f"column {name!r} holds complex numbers; give real numbers in {unit}")
    if kind == "b":
        raise ValueError(
            f"column {name!r} holds booleans; give numbers in {unit} (e.g. x.astype(float))"
        )
    if kind == "O":
        arr = _from_objects(name, arr, unit)
        kind = arr.dtype.kind
    if kind == "S":  # bytes (a NetCDF char array): text, if it is UTF-8
        try:
            arr = np.char.decode(arr, "utf-8")
        except UnicodeDecodeError:
            raise ValueError(f"column {name!r} holds bytes that are not UTF-8 text") from None
        kind = "U"
    if kind in "US":
        if name in COLUMNS:
            bad = np.flatnonzero(_not_number(arr))
            i = int(bad[0]) if bad.size else 0
            raise ValueError(
                f"column {name!r} must hold numbers in {unit}; row {i} has {arr[i]!r} (text)"
            )
        return np.array(arr, dtype=str)  # an extra text column, kept as text
    if kind in "iu":
        if name == "run":
            top = np.iinfo(np.int64).max
            if kind == "u" and np.any(arr > top):
                i = int(np.flatnonzero(arr > top)[0])
                raise ValueError(
                    f"column 'run' row {i}: {arr[i]} exceeds the int64 range of run ids"
                )
            return arr.astype(np.int64)
        big = np.flatnonzero((arr > MAX_EXACT_INTEGER) | (arr < -MAX_EXACT_INTEGER))
        if big.size:
            i = int(big[0])
            raise ValueError(
                f"column {name!r} row {i}: the integer {arr[i]} is too large to hold exactly as "
                "a float64 (|x| > 2**53); give it as a float if rounding is intended"
            )
        return arr.astype(float)
    if kind != "f":
        raise ValueError(f"column {name!r} must hold numbers in {unit}; got dtype {arr.dtype}")
    farr = arr.astype(float)
    bad = np.flatnonzero(~np.isfinite(farr))
    if bad.size:
        i = int(bad[0])
        raise ValueError(f"column {name!r} has a non-finite value ({farr[i]}) at row {i}")
    if name == "run":
        frac = np.flatnonzero(farr != np.round(farr))
        if frac.size:
            i = int(frac[0])
            raise ValueError(f"column 'run' must hold integers; row {i} has {farr[i]}")
        big = np.flatnonzero(np.abs(farr) > MAX_EXACT_INTEGER)
        if big.size:
            i = int(big[0])
            raise ValueError(
                f"column 'run' row {i}: {farr[i]:.17g} is beyond 2**53, where floats no longer "
                "hold every integer; give run ids as integers (int64) or smaller numbers"
            )
        return farr.astype(np.int64)
    return farr


def _from_objects(name: str, arr: np.ndarray, unit: str) -> np.ndarray:
    """An object column (e.g. from pandas) as numbers or text, refusing a mixture."""
    items = arr.tolist()
    if all(isinstance(v, str) for v in items):
        return np.array(items, dtype=str)
    if all(isinstance(v, bytes) for v in items):
        return np.array(items, dtype=bytes)  # decoded as UTF-8 by the caller
    for i, v in enumerate(items):
        if isinstance(v, bool | np.bool_) or not isinstance(v, numbers.Real):
            raise ValueError(
                f"column {name!r} must hold numbers in {unit}; row {i} has {v!r} "
                f"({type(v).__name__})"
            )
    if all(isinstance(v, numbers.Integral) for v in items):
        try:
            return np.array(items, dtype=np.int64)  # checked for exactness by the caller
        except OverflowError:
            i = next(i for i, v in enumerate(items) if abs(int(v)) > np.iinfo(np.int64).max)
            raise ValueError(
                f"column {name!r} row {i}: the integer {items[i]} exceeds the int64 range"
            ) from None
    return np.array(items, dtype=float)


def _not_number(arr: np.ndarray) -> np.ndarray:
    return np.array([_NUMBER.fullmatch(str(v).strip()) is None for v in arr], dtype=bool)


def _unit_hint(name: str) -> str:
    if name == "run":
        return "[integer id]"
    meaning = COLUMNS.get(name)
    if meaning is None or "[" not in meaning:
        return "the column's unit"
    return meaning[meaning.rindex("[") : meaning.rindex("]") + 1]


def _check_time(t: np.ndarray, run: np.ndarray) -> None:
    """Time strictly increases within every run, wherever the run's rows are."""
    order = np.argsort(run, kind="stable")
    same = run[order][1:] == run[order][:-1]
    bad = np.flatnonzero(same & (np.diff(t[order]) <= 0))
    if bad.size:
        i, j = int(order[bad[0] + 1]), int(order[bad[0]])
        what = "duplicate time stamp" if t[i] == t[j] else "time goes backwards"
        raise ValueError(
            f"column 'time_s' must strictly increase within a run; row {i} (time {t[i]}, run "
            f"{run[i]}) does not follow row {j} (time {t[j]}), the run's previous row — {what}"
        )


def concat(parts: list[MeasuredData]) -> MeasuredData:
    """Stack datasets row-wise (e.g. a static and a rotation plan of one bench session).

    **Raises:** `ValueError` if the parts have different columns or share a run id.
    """
    if not parts:
        raise ValueError("concat needs at least one dataset")
    names = parts[0].names
    seen: set[int] = set()
    for p in parts:
        if p.names != names:
            raise ValueError(f"cannot concat datasets with columns {names} and {p.names}")
        ids = set(np.unique(p.run).tolist())
        if ids & seen:
            raise ValueError(
                f"run ids {sorted(ids & seen)[:5]} occur in more than one part; "
                "renumber them (e.g. run_plan(..., first_run=…))"
            )
        seen |= ids
    cols = {k: np.concatenate([p[k] for p in parts]) for k in names}
    return MeasuredData(cols, allow_extra=True)


def _import_xarray():
    try:
        import xarray as xr
    except ImportError as err:  # pragma: no cover
        raise ImportError(
            "NetCDF/xarray support needs the data extra: pip install hrgjax[data]"
        ) from err
    return xr


def _write_csv(data: MeasuredData, fh) -> None:
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


def _dataset_columns(ds, where: str) -> dict[str, np.ndarray]:
    """The columns of an xarray Dataset, every variable and coordinate checked (module
    docstring of `from_xarray`)."""
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
            f"{_unit_hint(name)} ({', '.join(repr(u) for u in accepted if u)}{hint})"
        )
    return values


def load(path: str | os.PathLike, allow_extra: bool = False) -> MeasuredData:
    """Load a CSV or NetCDF file in the data contract; validated like
    [`MeasuredData`][hrgjax.MeasuredData], errors naming the file, the column and the row (and
    for CSV the line of the file).

    CSV: UTF-8 (a byte-order mark is fine), a header row, comma-separated; lines starting with
    ``#`` are comments; numbers in decimal or scientific notation (no thousands separators or
    underscores); extra columns (with `allow_extra`) that are not all numbers are kept as
    text. NetCDF: as [`MeasuredData.from_xarray`][hrgjax.MeasuredData.from_xarray]."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in NETCDF_EXTENSIONS:
        return _load_netcdf(path, allow_extra)
    if ext != ".csv":
        raise ValueError(f"unknown data file extension {ext!r}; use .csv or .nc")
    columns, lines = read_csv_table(path)
    try:
        return MeasuredData(columns, allow_extra=allow_extra)
    except ValueError as err:
        raise ValueError(f"{path}: {with_file_line(str(err), lines)}") from None


def _load_netcdf(path: str, allow_extra: bool) -> MeasuredData:
    xr = _import_xarray()
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
        columns = _dataset_columns(ds, path)
    try:
        return MeasuredData(columns, allow_extra=allow_extra)
    except ValueError as err:
        raise ValueError(f"{path}: {err}") from None


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


def read_csv_table(path: str) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """A CSV file as `(columns, lines)`: each column parsed (numbers as float, `run` ids as
    exact integers, a column not in `COLUMNS` that is not all numbers as text) and the file's
    line number of each data row. UTF-8, a header row, `#` comment lines.

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
    return {h: _parse(path, h, v, lines_arr) for h, v in fields.items()}, lines_arr


def _parse(path: str, name: str, values: list[str], lines: np.ndarray) -> np.ndarray:
    """A CSV column's fields as numbers (run ids as exact integers); an extra column that is
    not all numbers stays text."""
    stripped = [v.strip() for v in values]
    ok = [_NUMBER.fullmatch(v) is not None for v in stripped]
    if not all(ok):
        if name not in COLUMNS:
            return np.array(values, dtype=str)
        i = ok.index(False)
        raise ValueError(
            f"{path}: column {name!r} row {i} (line {lines[i]}): {values[i]!r} is not a number "
            f"in {_unit_hint(name)}" + (" (empty field)" if not stripped[i] else "")
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
