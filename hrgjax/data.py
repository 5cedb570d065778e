"""`MeasuredData`: the measured-data contract (DESIGN.md) as one validated, read-only table,
its runs stacked in SI (`RunStack`), and loading and saving it (CSV and NetCDF). The column
checks live in `hrgjax._data_columns`, the file formats in `hrgjax._data_files`; their
public names are re-exported here."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator, Mapping

import numpy as np

from . import _data_files, plausible
from ._data_columns import COLUMNS as COLUMNS
from ._data_columns import MAX_EXACT_INTEGER as MAX_EXACT_INTEGER
from ._data_columns import REQUIRED as REQUIRED
from ._data_columns import check_table_wraps, check_time, checked_column
from ._data_columns import is_number as is_number
from ._data_files import NETCDF_EXTENSIONS as NETCDF_EXTENSIONS
from ._data_files import UNITS as UNITS
from ._data_files import dataset_columns, import_xarray, netcdf_columns
from ._data_files import read_csv_table as read_csv_table
from ._data_files import with_file_line as with_file_line
from ._io import atomic_path, atomic_write
from .units import DEG, K_E_NOMINAL, STILL_RATE_DPS

SAMPLE_DIM = "sample"
"""The one dimension of the NetCDF files `MeasuredData.save` writes (no column may take its
name)."""


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
    column, an unknown column, a name that is empty or begins or ends with blanks (a CSV
    file would not keep it), mismatched lengths, values that are not real numbers (text in
    a contract column, booleans, complex numbers, dates or durations), NaN or infinite
    values, integers too large to hold exactly, a run id that is not an exactly representable
    integer, time that does not strictly increase within a run (checked run by run, also
    when the rows of several runs are interleaved), or values [`hrgjax.plausible`][] refuses
    (a temperature in kelvin; a specific force in m/s² or mg: `accel_*_g` whose magnitude
    has its median within 2 % of 9.80665 and its middle half within 15 %, or a column whose
    middle half (25th … 75th percentile) leaves ±20 g — vibration peaks beyond it are
    taken; `check_specific_force`).
    """

    def __init__(self, columns: Mapping[str, object], allow_extra: bool = False):
        if not isinstance(columns, Mapping):
            raise TypeError(f"columns must be a mapping of name -> 1-D array; got {type(columns)}")
        if not isinstance(allow_extra, bool | np.bool_):
            shown = repr(allow_extra) if isinstance(allow_extra, str | int | float) else ""
            raise TypeError(f"MeasuredData: allow_extra must be True or False; got "
                            f"{type(allow_extra).__name__} {shown[:60]}".rstrip())  # fmt: skip
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
            if not name.strip():
                raise ValueError(f"column name {name!r} is empty; name every column")
            if name != name.strip():
                raise ValueError(
                    f"column name {name!r} begins or ends with blanks, which a CSV header does "
                    f"not keep (the reader strips them): rename it {name.strip()!r}"
                )
            arr = checked_column(name, value)
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
        check_time(cols["time_s"], self.run)
        for name in ("temperature_c", "table_rate_dps", "wave_angle_deg"):
            plausible.check(f"column {name!r}", cols[name], name)
        accel = [k for k in ("accel_x_g", "accel_y_g", "accel_z_g") if k in cols]
        if accel:  # each column's middle half within ±20 g, and not 1 g in m/s² or mg
            plausible.check_specific_force(
                f"column(s) {', '.join(map(repr, accel))}",
                [f"column {k!r}" for k in accel],
                np.stack([cols[k] for k in accel]).T,  # (N, k), each column contiguous
                samples=False,
                rate_hz=_row_rate(cols["time_s"]),
            )
        turning = cols["table_rate_dps"] != 0.0
        given = "table_angle_deg" in cols
        # the wave turns against the table where it runs free: not where force-to-rebalance
        # holds it, nor where a commanded precession moves it too
        precession = cols.get("precession_dps", np.zeros(len(self)))
        steered = precession != 0.0
        if "rebalance_rate_dps" in cols:  # held wherever rebalance_on is absent or 1
            steered |= cols.get("rebalance_on", np.ones(len(self))) != 0
        free = ~np.isin(self.run, np.unique(self.run[steered]))
        integral = self._rate_integral()  # the rate's per-run integral (once)
        table = cols["table_angle_deg"] if given else integral
        if given:  # an encoder's azimuth wrapped to one turn, in any run: named with the run
            check_table_wraps(table, integral, self.run, cols["time_s"])
        if (turning & free).any():
            moving = np.isin(self.run, np.unique(self.run[turning])) & free
            if given:  # the median over the runs, then each run
                plausible.check_table_angle(table, integral, self.run, moving)
            plausible.check_wave_angle_units(cols["wave_angle_deg"], table, self.run, moving,
                                             K_E_NOMINAL, integrated=not given,
                                             time_s=cols["time_s"])  # fmt: skip
        plausible.check_wave_angle_jumps(cols["wave_angle_deg"], table, cols["time_s"],
                                         self.run, K_E_NOMINAL, precession)  # fmt: skip

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
        return self._rate_integral()

    def _rate_integral(self) -> np.ndarray:
        """The trapezoidal integral of `table_rate_dps` over `time_s`, per run [°]."""
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
        """Iterate over runs as separate datasets (their rows as this one's, checked once:
        when this dataset was built, e.g. inside a `plausible.relaxed` block that has ended)."""
        for idx in self.run_indices():
            yield MeasuredData._checked({k: v[idx] for k, v in self._columns.items()})

    def select(self, rows) -> MeasuredData:
        """The dataset of `rows` (a boolean mask over the samples, or increasing sample
        indices; the order within each run kept), each column a new read-only array, not
        checked again: the checks held for this dataset when
        it was built (inside a `plausible.relaxed` block that may have ended since)."""
        rows, n = np.asarray(rows), len(self)
        form = (f"a boolean mask of shape ({n},) or increasing sample indices in 0 … {n - 1}, "
                "at least one")  # fmt: skip
        if rows.dtype == bool:
            if rows.shape != (n,):
                raise ValueError(f"MeasuredData.select: rows must be {form}; got a mask of "
                                 f"shape {rows.shape}")  # fmt: skip
            rows = np.flatnonzero(rows)
        elif rows.dtype.kind not in "iu" or rows.ndim != 1:
            raise ValueError(f"MeasuredData.select: rows must be {form}; got {rows.dtype} of "
                             f"shape {rows.shape}")  # fmt: skip
        if rows.size == 0 or rows[0] < 0 or rows[-1] >= n or np.any(np.diff(rows) <= 0):
            raise ValueError(f"MeasuredData.select: rows must be {form}; got "
                             f"{rows.size} indices" + (f" from {rows[0]} to {rows[-1]}" if rows.size
                             else ""))  # fmt: skip
        return MeasuredData._checked({k: v[rows] for k, v in self._columns.items()})

    def with_column(self, name: str, values) -> MeasuredData:
        """This dataset with its column `name` replaced by `values` (as many rows; the
        other columns shared, read-only), e.g. a temperature filtered or interpolated through
        its readings. The new column is checked as a column is (numbers, finite). A
        `temperature_c` (or extra column) whose values stay within the old column's span is
        not held to the plausible ranges again: the old one passed them when this dataset was
        built, perhaps inside a `plausible.relaxed` block that has ended. Any other
        replacement is checked as a new dataset is, against the ranges in force now.

        **Raises:** `KeyError` when there is no such column; `ValueError` in one line when
        `values` is not a finite numeric column of `len(self)` rows."""
        if name not in self._columns:
            raise KeyError(f"MeasuredData.with_column: no column {name!r}; this dataset has "
                           f"{self.names}")  # fmt: skip
        arr = checked_column(name, values)
        if arr.shape != (len(self),):
            raise ValueError(f"MeasuredData.with_column: {name} must be one value per row "
                             f"({len(self)} rows); got shape {arr.shape}")  # fmt: skip
        old, cols = self._columns[name], {**self._columns, name: arr}
        alone = name == "temperature_c" or name not in COLUMNS  # no check reads it with others
        if alone and old.min() <= arr.min() and arr.max() <= old.max():
            return MeasuredData._checked(cols)
        return MeasuredData(cols, allow_extra=True)

    @classmethod
    def _checked(cls, columns: dict[str, np.ndarray]) -> MeasuredData:
        """A dataset of `columns`, rows of an already checked dataset (each a new array), not
        checked again: its checks held for the whole, whatever ranges are in force now."""
        out = cls.__new__(cls)
        for arr in columns.values():
            arr.setflags(write=False)
        out._columns = columns
        return out

    def stacked(self) -> list[RunStack]:
        """The runs in SI, stacked: one [`RunStack`][hrgjax.data.RunStack] per (length,
        sample interval), ordered by length then interval, runs in order of first appearance.

        Runs share a sample interval when their median intervals agree within
        `INTERVAL_RTOL` of it or within `JITTER_SPREAD` × either run's own jitter (the robust
        scatter of its intervals, 1.4826 × their median absolute deviation, counted up to
        `INTERVAL_JITTER_MAX` of the interval): logged time stamps jitter (µs to ms), and
        runs apart only by that share one stack — and one compiled program in each
        consumer — instead of one each (36 runs stamped with 1 µs jitter made 34 stacks).
        Each run keeps its own time stamps (`RunStack.t`); the stack's `dt` (the interval of
        every run it pools, across lengths) only sets how many samples a window, block or
        solver step spans.

        The one "group runs, stack, convert" view that calibration (physical fit, end-to-end
        MLP training) and discovery (continuous records) build on; the data are not altered.
        """
        t_all = self._columns["time_s"]
        runs = self.run_indices()
        dts = _interval_classes([np.diff(t_all[idx]) for idx in runs])
        buckets: dict[tuple[int, float], list[np.ndarray]] = {}
        for idx, dt in zip(runs, dts, strict=True):
            buckets.setdefault((idx.size, dt), []).append(idx)
        return [RunStack._of(self, rows, dt) for (_, dt), rows in sorted(buckets.items())]

    def save(self, path: str | os.PathLike) -> str:
        """Write CSV (``.csv``) or NetCDF (``.nc``, with each column's ``units``); returns the
        path. Round trips are exact. The file is written under a temporary name and renamed
        when complete, so an interrupted save never leaves a partial file."""
        path = os.fspath(path)
        ext = os.path.splitext(path)[1].lower()
        if ext == ".csv":
            with atomic_write(path, "w", newline="", encoding="utf-8") as fh:
                _data_files.write_csv(self, fh)  # looked up here: tests replace it
        elif ext in NETCDF_EXTENSIONS:
            ds = self.to_xarray()
            with atomic_path(path) as tmp:
                ds.to_netcdf(tmp, engine="h5netcdf")
        else:
            raise ValueError(f"unknown data file extension {ext!r}; use .csv or .nc")
        return path

    def to_xarray(self):
        """An `xarray.Dataset` with one variable per column along dimension ``sample``, each
        contract column with its ``units`` attribute (UDUNITS spelling, but for the
        accelerations' ``g``, hrgjax's own, which UDUNITS reads as the gram; on reading,
        UDUNITS' ``standard_free_fall`` and ``gravity`` are taken as g too).

        **Raises:** `ValueError` for an extra column named ``sample``: it would become the
        dimension's coordinate, read back in another place (or, holding 0, 1, 2, …, not at
        all) — rename it."""
        xr = import_xarray()
        if SAMPLE_DIM in self._columns:
            raise ValueError(
                f"column {SAMPLE_DIM!r} has the name of the NetCDF sample dimension, which "
                "would not read back as a column: rename it (or save as .csv)"
            )
        return xr.Dataset(
            {
                k: (SAMPLE_DIM, v, {"units": UNITS[k][0]} if k in UNITS else {})
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
        return cls(dataset_columns(ds, "the dataset"), allow_extra=allow_extra)


@dataclasses.dataclass(frozen=True, eq=False)
class RunStack:
    """Runs of one length and one sample interval, stacked in SI (leading axis = run).

    Built by [`MeasuredData.stacked`][hrgjax.data.MeasuredData.stacked]; NumPy arrays, read
    only. Angles are in rad (the wave angle electrical), rates in rad/s, specific force in g.

    **Fields:**

    - `run`: (R,) run ids; `rows`: (R, N) row indices into the dataset.
    - `t`: (R, N) each run's own time stamps [s]; `dt`: the runs' sample interval [s], the
      median of their median intervals over every run of the dataset that shares it
      (`MeasuredData.stacked`: equal within `INTERVAL_RTOL` or the runs' jitter).
    - `wave_angle`: (R, N) measured wave angle [rad, electrical].
    - `rate`: (R, N) reference rate [rad/s]; `table_angle`: (R, N) reference angle since the
      start of each run [rad].
    - `temperature`: (R, N) [°C].
    - `accel`: (R, N, 3) specific force along case x, y, z [g] (absent axes read 0).
    - `amplitude`, `quadrature`: (R, N) [readout units] (absent: 1 and 0).
    - `static`: (R,) true for runs with the table at rest throughout (|rate| within
      [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS]: readback jitter is rest).
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
    def _of(cls, data: MeasuredData, rows: list[np.ndarray], dt: float) -> RunStack:
        rows = np.stack(rows)
        cols = data._columns

        def col(name, default):
            return cols[name][rows] if name in cols else np.full(rows.shape, default)

        table = data.table_angle_deg[rows] * DEG
        rate = cols["table_rate_dps"][rows] * DEG
        t = cols["time_s"][rows]
        out = cls(
            run=data.run[rows[:, 0]],
            rows=rows,
            t=t,
            dt=dt,
            wave_angle=cols["wave_angle_deg"][rows] * DEG,
            rate=rate,
            table_angle=table - table[:, :1],
            temperature=cols["temperature_c"][rows],
            accel=np.stack([col(f"accel_{a}_g", 0.0) for a in "xyz"], axis=-1),
            amplitude=col("amplitude", 1.0),
            quadrature=col("quadrature", 0.0),
            static=np.all(np.abs(rate) <= STILL_RATE_DPS * DEG, axis=1),  # jitter is rest
        )
        for f in dataclasses.fields(out):
            v = getattr(out, f.name)
            if isinstance(v, np.ndarray):
                v.setflags(write=False)
        return out


def concat(parts: list[MeasuredData]) -> MeasuredData:
    """Stack datasets row-wise (e.g. a static and a rotation plan of one bench session).

    **Raises:** `ValueError` if the parts have different columns or share a run id.
    """
    if isinstance(parts, MeasuredData | Mapping | str | bytes) or not hasattr(parts, "__iter__"):
        raise TypeError(f"concat: parts must be a list of MeasuredData; got "
                        f"{type(parts).__name__}")  # fmt: skip
    parts = list(parts)
    for i, p in enumerate(parts):
        if not isinstance(p, MeasuredData):
            raise TypeError(f"concat: parts[{i}] must be a MeasuredData; got {type(p).__name__}")
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


def load(path: str | os.PathLike, allow_extra: bool = False) -> MeasuredData:
    """Load a CSV or NetCDF file in the data contract; validated like
    [`MeasuredData`][hrgjax.MeasuredData], errors naming the file, the column and the row (and
    for CSV the line of the file).

    CSV: UTF-8 (a byte-order mark is fine), a header row, comma-separated; a line starting
    with ``#`` is a comment where a row begins (not inside a quoted field); blank lines are
    skipped, a row of empty fields is refused; numbers in decimal or scientific notation (no
    thousands separators or underscores); extra columns (with `allow_extra`) that are not all numbers are kept as
    text; an integer beyond 2**53 that a float would round (not one a float holds exactly,
    as `%.0f` writes 1e20) is refused in every column (extra ones too), naming it, its row
    and its line. NetCDF: as [`MeasuredData.from_xarray`][hrgjax.MeasuredData.from_xarray]."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext in NETCDF_EXTENSIONS:
        columns = netcdf_columns(path)
        try:
            return MeasuredData(columns, allow_extra=allow_extra)
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None
    if ext != ".csv":
        raise ValueError(f"unknown data file extension {ext!r}; use .csv or .nc")
    # an unknown column is refused as such first; only one the user keeps is checked for size
    columns, lines = read_csv_table(path, exact_integers=allow_extra)
    try:
        return MeasuredData(columns, allow_extra=allow_extra)
    except ValueError as err:
        raise ValueError(f"{path}: {with_file_line(str(err), lines)}") from None


INTERVAL_RTOL = 1e-5
"""Relative difference [-] of two runs' median sample intervals below which they are one
interval (`MeasuredData.stacked`) even without jitter: above a clock's few-ppm rate error
between sessions (runs stamped by clocks 2–5 ppm apart split at 1e-6) and the rounding of
Unix-epoch stamps (the median step of a 2-ms grid 4.7e-5 s off, the same in every run), far
below any real difference in sample rate."""

JITTER_SPREAD = 3.0
"""How many times a run's own jitter (its steps' robust scatter) two runs' median intervals
may differ by and be one interval: with few samples a median scatters by about the jitter
itself (36 jittered runs of 9 samples made up to 2 classes at 1×, always 1 at 3×)."""

INTERVAL_JITTER_MAX = 1e-2
"""The most [-, relative to the interval] a run's own jitter widens `INTERVAL_RTOL`: runs
pooled under one interval then differ by under 1 % (a window of a given number of samples
spans the same time to 1 %), and a run sampled irregularly does not pool different rates."""


def _interval_classes(steps: list[np.ndarray]) -> list[float]:
    """Each run's sample interval [s] from its time steps `steps` (one array per run): runs
    whose median steps agree within `INTERVAL_RTOL` or within `JITTER_SPREAD` × either run's
    jitter (1.4826 × the median absolute deviation of its steps; at most
    `INTERVAL_JITTER_MAX` of the interval) get one value, the median of their medians; 0 for a run of one sample. Classes are built in increasing order of the median
    step, each run compared with its class's first run, so a class spans at most one
    tolerance (no chaining)."""
    med = np.array([float(np.median(d)) if d.size else 0.0 for d in steps])
    jit = np.array([1.4826 * float(np.median(np.abs(d - m))) if d.size else 0.0
                    for d, m in zip(steps, med, strict=True)])  # fmt: skip
    out = np.zeros(med.size)
    order = np.argsort(med, kind="stable")
    start = 0
    while start < order.size:
        first = order[start]
        end = start + 1
        scale = abs(med[first])
        while end < order.size:
            j = order[end]
            jitter = min(JITTER_SPREAD * max(jit[first], jit[j]), INTERVAL_JITTER_MAX * scale)
            if med[j] - med[first] > max(INTERVAL_RTOL * scale, jitter):
                break
            end += 1
        members = order[start:end]
        out[members] = float(np.median(med[members]))
        start = end
    return out.tolist()


def _row_rate(time_s) -> float | None:
    """The rows' sample rate [Hz]: 1 / the median of the increasing steps of `time_s` [s]
    (runs may restart the clock), or None where none increases."""
    dt = np.diff(np.asarray(time_s, dtype=float))
    dt = dt[dt > 0]
    return 1.0 / float(np.median(dt)) if dt.size else None
