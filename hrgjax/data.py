"""`MeasuredData`: the measured-data contract (DESIGN.md), validation, CSV and NetCDF I/O."""

from __future__ import annotations

import csv
import os
from collections.abc import Iterator, Mapping

import numpy as np

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


class MeasuredData:
    """A measured (or simulated) gyro record in the units of the data contract.

    One row per sample; columns are 1-D float arrays (``run`` is integer). The data are
    validated on construction and never altered: an absent ``run`` reads as all zeros and an
    absent ``table_angle_deg`` as the per-run integral of the rate, without adding columns.

    **Arguments:**

    - `columns`: mapping of column name → 1-D array.
    - `allow_extra`: keep columns not in [`hrgjax.data.COLUMNS`][] (otherwise an error).

    **Raises:** `ValueError` naming the column (and first bad row) for a missing required
    column, an unknown column, mismatched lengths, non-numeric, NaN or infinite values,
    a non-integer run id, or time that does not strictly increase within a run.
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
            arr = np.asarray(value)
            if arr.ndim != 1:
                raise ValueError(
                    f"column {name!r} must be 1-D (one value per row); got shape {arr.shape}"
                )
            if n is None:
                n = arr.shape[0]
            elif arr.shape[0] != n:
                raise ValueError(
                    f"column {name!r} has {arr.shape[0]} rows but 'time_s'/the first column has {n}"
                )
            try:
                farr = arr.astype(float)
            except (TypeError, ValueError):
                raise ValueError(f"column {name!r} must be numeric") from None
            bad = np.nonzero(~np.isfinite(farr))[0]
            if bad.size:
                i = int(bad[0])
                raise ValueError(f"column {name!r} has a non-finite value ({farr[i]}) at row {i}")
            if name == "run":
                if np.any(farr != np.round(farr)):
                    i = int(np.nonzero(farr != np.round(farr))[0][0])
                    raise ValueError(f"column 'run' must hold integers; row {i} has {farr[i]}")
                arr = farr.astype(np.int64)
            else:
                arr = farr
            arr = arr.copy()
            arr.setflags(write=False)
            cols[name] = arr
        if n == 0:
            raise ValueError("the data have no rows")
        self._columns = cols
        t, run = cols["time_s"], self.run
        same = run[1:] == run[:-1]
        bad = np.nonzero(same & (np.diff(t) <= 0))[0]
        if bad.size:
            i = int(bad[0]) + 1
            raise ValueError(
                f"column 'time_s' must strictly increase within a run; row {i} "
                f"(time {t[i]}, run {run[i]}) does not follow row {i - 1} (time {t[i - 1]}) "
                "— unsorted or duplicate time stamp"
            )

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

    def save(self, path: str | os.PathLike) -> str:
        """Write CSV (``.csv``) or NetCDF (``.nc``); returns the path. Round trips are exact."""
        path = os.fspath(path)
        ext = os.path.splitext(path)[1].lower()
        if ext == ".csv":
            _write_csv(self, path)
        elif ext in (".nc", ".nc4", ".netcdf"):
            self.to_xarray().to_netcdf(path, engine="h5netcdf")
        else:
            raise ValueError(f"unknown data file extension {ext!r}; use .csv or .nc")
        return path

    def to_xarray(self):
        """An `xarray.Dataset` with one variable per column along dimension ``sample``."""
        xr = _import_xarray()
        return xr.Dataset({k: ("sample", v) for k, v in self._columns.items()})

    @classmethod
    def from_xarray(cls, ds, allow_extra: bool = False) -> MeasuredData:
        """Build from an `xarray.Dataset` with 1-D variables."""
        return cls({k: ds[k].values for k in ds.data_vars}, allow_extra=allow_extra)


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


def _write_csv(data: MeasuredData, path: str) -> None:
    cols = data.columns
    names = list(cols)
    d = os.path.dirname(path)
    if d:
        os.makedirs(d, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(names)
        fmt = [(lambda v: str(int(v))) if cols[k].dtype.kind == "i" else repr for k in names]
        for row in zip(*(cols[k].tolist() for k in names), strict=True):
            w.writerow([f(v) for f, v in zip(fmt, row, strict=True)])


def load(path: str | os.PathLike, allow_extra: bool = False) -> MeasuredData:
    """Load a CSV or NetCDF file in the data contract; validated like [`MeasuredData`][hrgjax.MeasuredData]."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in (".nc", ".nc4", ".netcdf"):
        xr = _import_xarray()
        with xr.open_dataset(path, engine="h5netcdf") as ds:
            return MeasuredData.from_xarray(ds.load(), allow_extra=allow_extra)
    if ext != ".csv":
        raise ValueError(f"unknown data file extension {ext!r}; use .csv or .nc")
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise ValueError(f"{path}: empty file (expected a header row)")
    header = [h.strip() for h in rows[0]]
    if len(set(header)) != len(header):
        raise ValueError(f"{path}: duplicate column names in header {header}")
    body = [r for r in rows[1:] if r]
    cols: dict[str, list] = {h: [] for h in header}
    for i, r in enumerate(body):
        if len(r) != len(header):
            raise ValueError(f"{path}: row {i} has {len(r)} fields, header has {len(header)}")
        for h, v in zip(header, r, strict=True):
            try:
                cols[h].append(float(v))
            except ValueError:
                raise ValueError(f"{path}: column {h!r} row {i}: {v!r} is not a number") from None
    return MeasuredData({h: np.asarray(v) for h, v in cols.items()}, allow_extra=allow_extra)
