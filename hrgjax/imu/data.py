"""`ImuData`: a six-axis IMU record (3-axis gyro + 3-axis accelerometer) in SI units, and
`load` for CSV logs whose rows are samples.

Inside, every record is SI: time [s], angular rate [rad/s], specific force [m/s²],
temperature [°C]. The units of a file are declared when it is read (`units=`) and checked
against what the data can tell: a record that is mostly at rest reads about one g of
specific force, so an accelerometer declared in m/s² that reads ≈ 1 is in g (and the
other way round) — an error, never a silent rescale; and its median |angular rate| is far
below `GYRO_MEDIAN_LIMIT_RAD_S` (a gyro in °/h declared as rad/s reads thousands)."""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Mapping, Sequence

import numpy as np

from .. import plausible
from .._time_units import TIME_UNITS, stamps_per_second
from .._timebase import regular_step
from ..units import DEG, G0

GYRO_UNITS: dict[str, float] = {
    "rad/s": 1.0,
    "deg/s": DEG,
    "dps": DEG,
    "°/s": DEG,
    "deg/h": DEG / 3600.0,
    "°/h": DEG / 3600.0,
    "mrad/s": 1e-3,
}
"""Angular-rate units `load` and `ImuData.from_arrays` accept, with their size in rad/s."""
GYRO_MEDIAN_LIMIT_RAD_S = 10.0
"""The largest median |angular rate| [rad/s] (573 °/s, 1.6 turns/s) a gyro record may read
with `check_units`. A record that is mostly at rest reads its gyros' bias plus the Earth's
rate (7.3e-5 rad/s): well under 0.1 rad/s for any MEMS, tactical or navigation gyro, and
no vehicle turns at 573 °/s for half of a log. The same rates in °/h read as rad/s are at
least the Earth's rate, 15 "rad/s" (a MEMS bias of 0.5 °/s: 1800), and in °/s read as rad/s
a record turning at over 10 °/s half the time. (`hrgjax.plausible`'s table rate, ±3600 °/s,
is a rate table's peak, not a log's median: 62.8 rad/s would let a navigation gyro's
Earth rate in °/h through.) Pass `check_units=False` for a spin test."""
ACCEL_UNITS: dict[str, float] = {
    "m/s^2": 1.0,
    "m/s2": 1.0,
    "m/s²": 1.0,
    "g": G0,
    "mg": 1e-3 * G0,
}
"""Specific-force units accepted, with their size in m/s² (g is standard gravity, 9.80665)."""
AXES = ("x", "y", "z")
RATE_TOLERANCE = 0.01
"""How far (relative) a declared `rate_hz` may be from 1 / the time column's median step."""


@dataclasses.dataclass(frozen=True, eq=False)
class ImuData:
    """A six-axis IMU record in SI units; arrays are read-only copies of the input.

    **Fields:**

    - `time` (N,) [s], strictly increasing (uniform `arange(N) / rate_hz` when the source
      had no time column);
    - `gyro` (N, 3) [rad/s], sensor axes x, y, z;
    - `accel` (N, 3) [m/s²], specific force along the sensor axes (at rest and level, the
      axis that points up reads +g);
    - `temperature` (N,) [°C] or None, within the plausible range of `hrgjax.plausible`
      (a column in kelvin is refused);
    - `rate_hz` [Hz]: the nominal sample rate (given, or 1 / median time step).

    Build it in SI with `ImuData(time, gyro, accel, temperature, rate_hz)` (validated), from
    arrays in other units with [`from_arrays`][hrgjax.imu.ImuData.from_arrays], or from a
    CSV file with [`load`][hrgjax.imu.load].

    **Raises:** `ValueError` naming the field (and the first bad row) for a wrong shape,
    complex or boolean values, a value that is not finite, a time that does not increase,
    a `rate_hz` more than 1 % from the time column's (1 / median step) or a temperature
    outside the plausible range (in kelvin?)."""

    time: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    temperature: np.ndarray | None = None
    rate_hz: float | None = None

    def __post_init__(self):
        gyro = _triad("gyro", self.gyro)
        accel = _triad("accel", self.accel)
        n = gyro.shape[0]
        if accel.shape[0] != n:
            raise ValueError(
                f"accel has {accel.shape[0]} samples, gyro has {n}; give one row per sample"
            )
        if n < 2:
            raise ValueError(f"gyro: need at least 2 samples, got {n}")
        time = _vector("time", self.time, n)
        with np.errstate(over="ignore"):  # steps beyond 1.8e308 s: inf, refused below
            step = np.diff(time)
        bad = np.flatnonzero(~(step > 0))
        if bad.size:
            i = int(bad[0]) + 1
            raise ValueError(
                f"time row {i}: {float(time[i])!r} s does not increase (row {i - 1}: "
                f"{float(time[i - 1])!r} s); "
                "time must be strictly increasing"
            )
        rate = self.rate_hz
        median = regular_step(time)  # the mean regular step: a median is quantised at an epoch
        step_rate = 1.0 / median if median > 1.0 / np.finfo(float).max else np.inf
        if not (np.isfinite(step_rate) and step_rate > 0):
            raise ValueError(
                f"time: the step {median:.6g} s gives no finite sample rate; time must be "
                "in seconds"
            )
        if rate is None:
            rate = step_rate
        else:
            rate = _positive("rate_hz", rate, "number of samples per second")
            if abs(rate / step_rate - 1.0) > RATE_TOLERANCE:
                raise ValueError(
                    f"rate_hz = {rate:g} Hz disagrees with the time column, whose step "
                    f"{median:.6g} s is {step_rate:.6g} Hz (more than "
                    f"{RATE_TOLERANCE:.0%} apart); give the time column's rate, or leave rate_hz "
                    "out"
                )
        temp = None if self.temperature is None else _vector("temperature", self.temperature, n)
        if temp is not None:
            plausible.check("temperature", temp, "temperature_c")
        for name, value in (
            ("time", time), ("gyro", gyro), ("accel", accel), ("temperature", temp),
        ):  # fmt: skip
            object.__setattr__(self, name, value)
        object.__setattr__(self, "rate_hz", float(rate))

    @classmethod
    def from_arrays(
        cls,
        gyro,
        accel,
        *,
        units: Mapping[str, str],
        rate_hz: float | None = None,
        time=None,
        temperature=None,
        check_units: bool = True,
    ) -> ImuData:
        """An `ImuData` from arrays in declared units.

        **Arguments:** `gyro` (N, 3) and `accel` (N, 3) in `units["gyro"]` (one of
        [`GYRO_UNITS`][hrgjax.imu.data.GYRO_UNITS], e.g. "deg/s") and `units["accel"]` (one of
        [`ACCEL_UNITS`][hrgjax.imu.data.ACCEL_UNITS], e.g. "m/s^2" or "g"); `rate_hz` [Hz]
        (needed without `time`); `time` (N,) in `units["time"]` (optional: "s" — the
        default —, "ms", "us" or "ns"); `temperature` (N,) [°C]; `check_units`:
        compare the declared accelerometer unit with the data's median |specific force|,
        and refuse a gyro record whose median |angular rate| exceeds
        [`GYRO_MEDIAN_LIMIT_RAD_S`][hrgjax.imu.data.GYRO_MEDIAN_LIMIT_RAD_S] (10 rad/s)."""
        gyro_unit, accel_unit = _declared(units)
        if time is None and units.get("time") is not None:
            raise ValueError(
                f'units["time"] = {units["time"]!r} is the time column\'s unit, but there is no '
                'time column: give time= (or columns["time"]), or leave units["time"] out'
            )
        if time is not None:
            time = _real("time", time, "(N,)") / TIME_UNITS[units.get("time") or "s"]
        g = _triad("gyro", gyro)
        a = _triad("accel", accel)
        if time is None:
            if rate_hz is None:
                raise ValueError("rate_hz: give the sample rate [Hz] when there is no time column")
            rate_hz = _positive("rate_hz", rate_hz)
            time = np.arange(g.shape[0]) / rate_hz
        if check_units:
            _check_accel_unit(a, accel_unit)
            _check_gyro_unit(g, gyro_unit)
        return cls(
            time=time,
            gyro=_to_si("gyro", g, gyro_unit, GYRO_UNITS[gyro_unit], "rad/s"),
            accel=_to_si("accel", a, accel_unit, ACCEL_UNITS[accel_unit], "m/s²"),
            temperature=temperature,
            rate_hz=rate_hz,
        )

    def __len__(self) -> int:
        return int(self.gyro.shape[0])

    @property
    def dt(self) -> np.ndarray:
        """Each sample's time step (N,) [s]: the forward difference of `time`, the last
        sample's the median step (1 / `rate_hz` for uniform data)."""
        step = np.diff(self.time)
        return np.append(step, np.median(step))

    def __repr__(self) -> str:
        span = float(self.time[-1] - self.time[0])
        temp = "" if self.temperature is None else ", temperature"
        return f"ImuData({len(self)} samples, {span:.1f} s at {self.rate_hz:g} Hz{temp})"

    def save(self, path: str | os.PathLike) -> str:
        """Write the record as CSV in SI units (columns `time_s`, `gyro_x_rad_s` … `gyro_z_rad_s`,
        `accel_x_m_s2` … `accel_z_m_s2`, `temperature_c`), after a comment line
        `# rate_hz = …` holding the nominal sample rate [Hz] exactly, atomically; returns the
        path. Read it back with `load(path, columns=SI_COLUMNS, units=SI_UNITS)`, which takes
        the rate from that comment and the temperature from the `temperature_c` column where
        the file has one: the same record, every value bit for bit."""
        from .._io import atomic_write

        names = [SI_COLUMNS["time"], *SI_COLUMNS["gyro"], *SI_COLUMNS["accel"]]
        cols = [self.time[:, None], self.gyro, self.accel]
        if self.temperature is not None:
            names.append(_SAVED_TEMPERATURE)
            cols.append(self.temperature[:, None])
        table = np.concatenate(cols, axis=1)
        with atomic_write(path, "w", newline="", encoding="utf-8") as fh:
            fh.write(f"# rate_hz = {self.rate_hz!r}\n")
            fh.write(",".join(names) + "\n")
            np.savetxt(fh, table, delimiter=",", fmt="%.17g")
        return os.fspath(path)


SI_COLUMNS = {
    "time": "time_s",
    "gyro": ["gyro_x_rad_s", "gyro_y_rad_s", "gyro_z_rad_s"],
    "accel": ["accel_x_m_s2", "accel_y_m_s2", "accel_z_m_s2"],
}
"""The column map of files written by [`ImuData.save`][hrgjax.imu.ImuData.save]. `load` with
these gyro and accelerometer columns also reads the `temperature_c` column of a file
`ImuData.save` wrote (one with its `# rate_hz` comment line), as the record's temperature [°C]; `"temperature": "temperature_c"` makes that
column required, `"temperature": None` leaves it out."""
_SAVED_TEMPERATURE = "temperature_c"  # the temperature column [°C] ImuData.save writes
SI_UNITS = {"gyro": "rad/s", "accel": "m/s^2"}
"""The units of files written by [`ImuData.save`][hrgjax.imu.ImuData.save]."""


def load(
    path: str | os.PathLike,
    columns: Mapping[str, object],
    units: Mapping[str, str],
    rate_hz: float | None = None,
    check_units: bool = True,
) -> ImuData:
    """Read a six-axis IMU log from a CSV file whose rows are samples.

    **Arguments:**

    - `path`: CSV file (UTF-8, a header row, comma-separated; `#` lines are comments).
    - `columns`: `{"gyro": [x, y, z column names], "accel": [x, y, z column names]}`, and
      optionally `"time"` (a column in `units["time"]`, seconds by default) and
      `"temperature"` (°C). Other columns are
      ignored, except that with the gyro and accelerometer columns of
      [`SI_COLUMNS`][hrgjax.imu.data.SI_COLUMNS], no `"temperature"` key and a file
      `ImuData.save` wrote (its `# rate_hz` comment line), a `temperature_c` column is read as the temperature, so that a
      saved record comes back whole; `"temperature": None` leaves it out.
    - `units`: `{"gyro": "deg/s" | "rad/s" | …, "accel": "m/s^2" | "g" | …}`
      ([`GYRO_UNITS`][hrgjax.imu.data.GYRO_UNITS], [`ACCEL_UNITS`][hrgjax.imu.data.ACCEL_UNITS]),
      and optionally `"time": "s" | "ms" | "us" | "ns"` (the time column's unit; default
      seconds). A time column named in another unit (`t_ms`, `stamp_nsec`) than the one
      declared, or stamps that as seconds would reach 3 000 years (an epoch in ms, µs or
      ns) without a unit declared, are refused; µs and ns stamps beyond 2**53 read exactly
      as each one less the first.
    - `rate_hz`: sample rate [Hz]; needed when there is no time column, otherwise the
      file's `# rate_hz = …` comment (before the header, as `ImuData.save` writes it) or
      1 / median time step unless given.
    - `check_units`: refuse an accelerometer unit the data contradict, and a gyro record
      whose median |angular rate| is beyond 10 rad/s (see the module notes).

    **Returns:** an [`ImuData`][hrgjax.imu.ImuData] in SI units.

    **Raises:** `ValueError` naming the file, the column and the row (and the file's line)
    for a missing column, text where a number belongs, an integer beyond 2**53 that a
    float64 would round (a nanosecond time stamp: `1700000000000000001`) in a column used, a
    value that is not finite (or not in SI units: 1e308 g), a time column without a finite
    sample rate, or a temperature outside the plausible range (kelvin?)."""
    from ..data import read_csv_table

    path = os.fspath(path)
    if os.path.splitext(path)[1].lower() != ".csv":
        raise ValueError(f"{path}: hg.imu.load reads .csv files")
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file")
    names = _column_map(columns)
    _declared(units)
    saved_layout = (
        "temperature" not in columns  # an explicit None leaves the saved temperature out
        and names["gyro"] == SI_COLUMNS["gyro"]
        and names["accel"] == SI_COLUMNS["accel"]
    )
    comment = None  # (line, text) of the file's `# rate_hz = …` when the rate comes from it
    if rate_hz is None:
        rate_hz, comment = _saved_rate(path)
    # the saved temperature is read unasked only from a file ImuData.save wrote (its comment
    # line): another file's `temperature_c` (NaN where a sensor was off) stays unread
    saved_layout = saved_layout and (comment is not None or _saved_rate(path)[1] is not None)
    # a plain numeric file: NumPy's C parser, streamed; an integer a float64 would round (a
    # nanosecond time stamp) refused in the columns used, naming the column, row and line
    table, lines = read_csv_table(
        path,
        exact_integers=_all_names(names),
        integer_offsets=[names["time"]] if units.get("time") in ("us", "ns") else (),
    )
    unasked = saved_layout and _SAVED_TEMPERATURE in table
    if unasked:
        names["temperature"] = _SAVED_TEMPERATURE  # ImuData.save's: not dropped
    try:
        return _build(path, names, table, lines, units, rate_hz, check_units)
    except ValueError as err:
        if unasked and f"'{_SAVED_TEMPERATURE}'" in str(err):
            raise ValueError(
                f"{err} (read as the temperature: the file has ImuData.save's layout; "
                "columns={…, 'temperature': None} leaves it out)"
            ) from None
        if comment is None or "rate_hz" not in str(err):
            raise
        raise ValueError(
            f"{err} (rate_hz here is the file's comment {comment[1]!r} on line {comment[0]}: "
            "correct or delete that line, or pass rate_hz=)"
        ) from None


def _build(path, names, table, lines, units, rate_hz, check_units) -> ImuData:
    """`ImuData` from parsed columns; `lines` (the file's line of each row, or None) make the
    errors name the line."""
    from ..data import with_file_line

    where = (lambda m: m) if lines is None else (lambda m: with_file_line(m, lines))
    missing = [c for c in _all_names(names) if c not in table]
    if missing:
        raise ValueError(
            f"{path}: column {missing[0]!r} (from columns=) is not in the file; its columns "
            f"are {sorted(table)}"
        )
    got = {}
    for c in _all_names(names):
        col = table[c]
        if col.dtype.kind not in "fiu":
            # the first field the CSV reader did not take as a number ("1_000", " ", "0x1f":
            # Python's float() reads some of these, the reader does not)
            bad = next((i for i, v in enumerate(col) if not _is_number(v)), 0)
            raise ValueError(
                where(f"{path}: column {c!r} row {bad}: {str(col[bad])!r} is not a number")
            )
        col = col.astype(float)
        bad = np.flatnonzero(~np.isfinite(col))
        if bad.size:
            i = int(bad[0])
            raise ValueError(where(f"{path}: column {c!r} row {i}: {col[i]!r} is not finite"))
        got[c] = col
    if "time" in names:
        c = names["time"]
        way_out = lambda u: f'units["time"] = "{u}"'  # noqa: E731
        try:
            stamps_per_second(c, got[c], units.get("time"), way_out)
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None
    if "temperature" in names:
        c = names["temperature"]
        try:
            plausible.check(f"temperature (column {c!r})", got[c], "temperature_c")
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None
    try:
        return ImuData.from_arrays(
            np.stack([got[c] for c in names["gyro"]], axis=1),
            np.stack([got[c] for c in names["accel"]], axis=1),
            units=units,
            rate_hz=rate_hz,
            time=got[names["time"]] if "time" in names else None,
            temperature=got[names["temperature"]] if "temperature" in names else None,
            check_units=check_units,
        )
    except ValueError as err:
        raise ValueError(f"{path}: {where(str(err))}") from None


_SAVED_RATE = re.compile(r"#\s*rate_hz\s*=\s*(\S+)\s*")


def _saved_rate(path: str) -> tuple[float | None, tuple[int, str] | None]:
    """The `# rate_hz = …` comment [Hz] among the comment lines before a file's header (as
    `ImuData.save` writes it) and (its line, its text), or (None, None)."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            for i, line in enumerate(fh, 1):
                if not line.strip():
                    continue
                if not line.lstrip().startswith("#"):
                    return None, None
                m = _SAVED_RATE.fullmatch(line.strip())
                if m is not None:
                    try:
                        rate = float(m.group(1))
                    except ValueError:
                        rate = math.nan
                    if not (math.isfinite(rate) and rate > 0):
                        raise ValueError(
                            f"{path}: line {i}: the comment {line.strip()!r} must give the "
                            "sample rate as a number > 0 [Hz]: correct or delete that line"
                        )
                    return rate, (i, line.strip())
    except UnicodeDecodeError:
        return None, None  # the CSV reader names the line
    return None, None


def _is_number(v) -> bool:
    """Whether a CSV field is a number as the CSV reader takes it (`data.is_number`)."""
    from ..data import is_number

    return isinstance(v, str) and is_number(v)


def _column_map(columns) -> dict:
    if not isinstance(columns, Mapping):
        raise ValueError(
            'columns must be a mapping like {"gyro": ["gx", "gy", "gz"], "accel": ["ax", "ay", '
            f'"az"], "time": "t"}}; got {type(columns).__name__}'
        )
    unknown = set(columns) - {"gyro", "accel", "time", "temperature"}
    if unknown:
        raise ValueError(
            f"columns: unknown key {sorted(unknown)[0]!r}; keys are gyro, accel, time, temperature"
        )
    out = {}
    for key in ("gyro", "accel"):
        value = columns.get(key)
        if isinstance(value, str) or not isinstance(value, Sequence) or len(value) != 3:
            raise ValueError(f'columns["{key}"] must list 3 column names (x, y, z); got {value!r}')
        out[key] = [str(v) for v in value]
    for key in ("time", "temperature"):
        if columns.get(key) is not None:
            if not isinstance(columns[key], str):
                raise ValueError(f'columns["{key}"] must be one column name; got {columns[key]!r}')
            out[key] = columns[key]
    flat = _all_names(out)
    dup = sorted({c for c in flat if flat.count(c) > 1})
    if dup:
        raise ValueError(f"columns: {dup[0]!r} is mapped twice; give each quantity its own column")
    return out


def _all_names(names: dict) -> list[str]:
    out = [*names["gyro"], *names["accel"]]
    out += [names[k] for k in ("time", "temperature") if k in names]
    return out


def _declared(units) -> tuple[str, str]:
    if not isinstance(units, Mapping) or set(units) - {"gyro", "accel", "time"}:
        raise ValueError(
            'units must be a mapping {"gyro": "deg/s" | "rad/s", "accel": "m/s^2" | "g"} '
            '(and optionally "time": "s" | "ms" | "us" | "ns"); '
            f"got {units!r}"
        )
    if units.get("time") is not None and units["time"] not in TIME_UNITS:
        raise ValueError(f'units["time"] must be one of {list(TIME_UNITS)}; got {units["time"]!r}')
    out = []
    for key, table in (("gyro", GYRO_UNITS), ("accel", ACCEL_UNITS)):
        u = units.get(key)
        if u not in table:
            raise ValueError(f'units["{key}"] must be one of {list(table)}; got {u!r}')
        out.append(u)
    return out[0], out[1]


def _real(name: str, x, form: str) -> np.ndarray:
    """`x` as a float array; complex or boolean input is refused (casting would drop the
    imaginary part, or read True as 1 of the declared unit)."""
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a numeric {form} array") from None
    if raw.dtype.kind == "c":
        raise ValueError(
            f"{name} is complex ({raw.dtype}); give a real {form} array (the imaginary part "
            "would be dropped)"
        )
    if raw.dtype.kind == "b":
        raise ValueError(f"{name} is boolean (True/False); give a numeric {form} array")
    try:
        return np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a numeric {form} array") from None


def _triad(name: str, x) -> np.ndarray:
    a = _real(name, x, "(N, 3)")
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3) (axes x, y, z); got {a.shape}")
    if a.shape[0] < 2:
        raise ValueError(f"{name} has {a.shape[0]} samples; a record needs at least 2 (a file "
                         "with only its header holds none)")  # fmt: skip
    _finite(name, a)
    a.flags.writeable = False
    return a


def _vector(name: str, x, n: int) -> np.ndarray:
    a = _real(name, x, "(N,)")
    if a.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},) like gyro; got {a.shape}")
    _finite(name, a)
    a.flags.writeable = False
    return a


def _finite(name: str, a: np.ndarray) -> None:
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        i = tuple(int(k) for k in bad[0])
        where = f"row {i[0]}" + (f", axis {AXES[i[1]]}" if len(i) > 1 else "")
        raise ValueError(f"{name} {where}: {float(a[i])!r} is not finite")


def _to_si(name: str, a: np.ndarray, unit: str, factor: float, si: str) -> np.ndarray:
    """`a` [unit] × `factor` in SI units, refusing a value that the conversion takes beyond
    float64's range (1e308 g is not a number in m/s²) instead of an overflow warning."""
    with np.errstate(over="ignore"):
        out = a * factor
    bad = np.argwhere(~np.isfinite(out))
    if bad.size:
        i = tuple(int(k) for k in bad[0])
        raise ValueError(
            f"{name} row {i[0]}, axis {AXES[i[1]]}: {float(a[i])!r} {unit} is beyond float64's "
            f"range (±1.8e308) in {si}"
        )
    return out


def _positive(name: str, x, what: str = "number") -> float:
    if isinstance(x, bool | np.bool_ | complex | np.complexfloating):
        raise ValueError(f"{name} must be a positive {what}; got {x!r}")
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a positive {what}; got {x!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive {what}; got {x!r}")
    return v


def _check_accel_unit(a: np.ndarray, unit: str) -> None:
    """Refuse an accelerometer unit the data contradict: a record that is mostly at rest has
    a median |specific force| of about one g."""
    with np.errstate(over="ignore"):  # |a| of a row beyond 1e154: inf, refused below
        norm = float(np.median(np.linalg.norm(a, axis=1))) * ACCEL_UNITS[unit]
    if 0.3 * G0 <= norm <= 3.0 * G0:
        return
    guess = min(ACCEL_UNITS, key=lambda u: abs(np.log(norm / ACCEL_UNITS[unit] * ACCEL_UNITS[u] / G0))
                if norm > 0 else 0)  # fmt: skip
    hint = f" (the data look like {guess!r})" if norm > 0 else ""
    raise ValueError(
        f'units["accel"] = {unit!r} makes the median |accel| {norm:.4g} m/s², not about one g '
        f"(9.8 m/s²){hint}; declare the file's unit, or pass check_units=False for a record "
        "that is not mostly at rest"
    )


def _check_gyro_unit(w: np.ndarray, unit: str) -> None:
    """Refuse a gyro record whose median |angular rate| is beyond `GYRO_MEDIAN_LIMIT_RAD_S`,
    naming the units that would bring it under (closest to a rest reading, 0.01 rad/s,
    first)."""
    with np.errstate(over="ignore"):  # |ω| of a row beyond 1e154: inf, refused below
        raw = float(np.median(np.linalg.norm(w, axis=1)))
        norm = raw * GYRO_UNITS[unit]
    if norm <= GYRO_MEDIAN_LIMIT_RAD_S:
        return
    names = {}  # one name per size, the first listed ("deg/s", not "dps")
    for u, f in GYRO_UNITS.items():
        names.setdefault(f, u)
    fits = sorted(((raw * f, u) for f, u in names.items() if raw * f <= GYRO_MEDIAN_LIMIT_RAD_S),
                  key=lambda m: abs(np.log10(max(m[0], 1e-300) / 1e-2)))  # fmt: skip
    hint = ("; the data look like " + " or ".join(f"{u!r} (median {m:.3g} rad/s)" for m, u in fits)
            if fits else "")  # fmt: skip
    raise ValueError(
        f'units["gyro"] = {unit!r} makes the median |gyro| {norm:.4g} rad/s ({norm / DEG:.4g} '
        f"°/s), beyond the {GYRO_MEDIAN_LIMIT_RAD_S:g} rad/s any IMU log reads for half its "
        f"rows{hint}; declare the file's unit, or pass check_units=False for a spin test"
    )
