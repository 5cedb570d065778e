"""An IMU record as body-frame increments ([`ImuLog`][hrgjax.ins.imu_log.ImuLog]) and the
PSINS text log loader ([`load_psins`][hrgjax.ins.imu_log.load_psins]): what
[`align`][hrgjax.ins.alignment.align] reads. Both are importable from
`hrgjax.ins.alignment` too, where they were defined before.

**Orderings.** `ImuLog.header_attitude_deg` keeps the file's order, (pitch, roll, heading);
the alignment's results (`AlignmentResult.coarse_deg`, `history_deg`) are (heading, pitch,
roll). Headings are clockwise from north in [0, 360) in both.
"""

from __future__ import annotations

import math
import os
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_numbers, describe, host_value, numeric_problem
from .._compiled import device
from .._data_files import beyond_exact, rounded_integer, rounded_integer_error
from ..units import ARCSEC, DEG
from .constants import check_heights


def _python_float(x):
    """A number (a NumPy or JAX scalar too) as a Python float, so that the static field holds
    no array; anything else unchanged (`ImuLog.__check_init__` refuses it)."""
    if isinstance(x, bool | str):
        return x
    try:
        return float(x) if np.ndim(x) == 0 else x
    except (TypeError, ValueError):
        return x


HEADING_SNAP_DEG = 1e-9
"""A heading within this of 360° [°] reads 0 (`wrap_heading_deg`, `euler_deg`): the mod of
−1e-13° is 359.9999999999999, which prints as 360.0000°."""


def wrap_heading_deg(x):
    """The heading `x` [°] (a number or an array, traced too) in [0, 360): mod 360, and a
    value within [`HEADING_SNAP_DEG`][hrgjax.ins.imu_log.HEADING_SNAP_DEG] below 360 is 0.
    A Python number stays a Python float."""
    if isinstance(x, int | float):
        r = float(x) % 360.0
        return 0.0 if r >= 360.0 - HEADING_SNAP_DEG else r
    r = jnp.mod(x, 360.0)
    return jnp.where(r >= 360.0 - HEADING_SNAP_DEG, 0.0, r)


_ARRAYS = {
    "t": "(N,) times [s], N >= 2 (their spacing is the interval)",
    "dtheta": "(N, 3) gyro increments [rad]",
    "dvel": "(N, 3) velocity increments [m/s]",
}
"""`ImuLog`'s arrays and the form its errors name."""


def _array(x):
    """A list or tuple of numbers as a float NumPy array (`ImuLog` reads its `.shape`);
    anything else unchanged (`ImuLog.__check_init__` refuses what is not numbers)."""
    if isinstance(x, list | tuple) and numeric_problem(x) is None:
        return np.asarray(x, dtype=float)
    return x


class ImuLog(eqx.Module):
    """An IMU record as increments in the body frame (FRD).

    **Fields:** `t` (N,) [s] (end of each increment); `dtheta` (N, 3) [rad]; `dvel` (N, 3)
    [m/s]; `lat`, `lon` [rad], `h` [m]; `header_attitude_deg`: (pitch, roll, heading) [°]
    from the file, in the file's order — not the (heading, pitch, roll) of
    `AlignmentResult.coarse_deg` and `history_deg` — the heading clockwise from north in
    [0, 360) (or `None`). Lists are taken as arrays. Refused in one line: arrays that are not
    real numbers or of other shapes (N >= 2), a height `h` outside
    [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M], and where their values are known (not under
    `jit`) a NaN or inf, times that do not increase, or times not uniformly sampled up to
    jitter (a rate change, a gap: [`check_uniform`][hrgjax.ins.imu_log.check_uniform])."""

    t: jax.Array = eqx.field(converter=_array)
    dtheta: jax.Array = eqx.field(converter=_array)
    dvel: jax.Array = eqx.field(converter=_array)
    lat: float = eqx.field(static=True, converter=_python_float)
    lon: float = eqx.field(static=True, default=0.0, converter=_python_float)
    h: float = eqx.field(static=True, default=0.0, converter=_python_float)
    header_attitude_deg: tuple | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        for name, unit in (("lat", "rad"), ("lon", "rad"), ("h", "m")):
            v = getattr(self, name)
            if not isinstance(v, float):
                raise TypeError(f"ImuLog.{name} must be a number [{unit}]; got {type(v).__name__}")
            if not math.isfinite(v):
                raise ValueError(f"ImuLog.{name} must be finite [{unit}]; got {v}")
        if not -math.pi / 2 <= self.lat <= math.pi / 2:
            raise ValueError(
                f"ImuLog.lat must be in [-π/2, π/2] rad; got {self.lat} (degrees? "
                f"np.deg2rad({self.lat:g}) = {math.radians(self.lat):.6g})"
            )
        check_heights("ImuLog.h", self.h)  # HEIGHT_RANGE_M, as the alignment's gravity
        head = self.header_attitude_deg
        if head is not None and (numeric_problem(head) or np.shape(head) != (3,)
                                 or not np.all(np.isfinite(head))):  # fmt: skip
            raise (TypeError if numeric_problem(head) else ValueError)(
                "ImuLog.header_attitude_deg must be None or (pitch, roll, heading), 3 finite "
                f"numbers [°]; got {describe(head)}"
            )
        for name, form in _ARRAYS.items():  # values where concrete: a traced log passes
            check_numbers(f"ImuLog.{name}", getattr(self, name), form)
        shape = np.shape(self.t)
        if len(shape) != 1 or shape[0] < 2:
            raise ValueError(f"ImuLog.t must be {_ARRAYS['t']}; got shape {shape}")
        for name in ("t", "dtheta", "dvel"):
            a = getattr(self, name)
            if name != "t" and np.shape(a) != (shape[0], 3):
                raise ValueError(f"ImuLog.{name} must have shape ({shape[0]}, 3); got "
                                 f"{np.shape(a)}")  # fmt: skip
            a = host_value(a)
            if a is not None and not np.all(np.isfinite(a)):
                raise ValueError(f"ImuLog.{name} must be finite (row "
                                 f"{np.argwhere(~np.isfinite(a))[0, 0]})")  # fmt: skip
        t = host_value(self.t)
        d = np.diff(t) if t is not None else np.zeros(0)
        if np.any(d <= 0):
            raise ValueError(
                f"ImuLog.t must be strictly increasing (row {int(np.argmax(d <= 0)) + 1})"
            )
        if t is not None:
            check_uniform(t)

    @property
    def dt(self) -> float:
        """Median sampling interval [s]."""
        return float(np.median(np.diff(np.asarray(self.t))))


UNIFORM_TOL = 0.5
"""How far, in sample intervals, an `ImuLog`'s time stamps may stray from one uniform grid
(the least-squares line through them: a clock's ppm rate error is its slope), and each step
from that interval, before the log is refused as not uniformly sampled (`check_uniform`):
logged stamps jitter by µs to ms on a 10-ms interval and pass; a rate change (1 Hz, then
2 Hz) or a gap (a dropped sample: a step of 2 intervals) does not — `align` reads every
increment as one `ImuLog.dt` (the median step), and read such a log with 31σ–55σ of
confidence in a wrong heading."""


def check_uniform(t) -> None:
    """Refuse, in one line naming `ImuLog.t`, increasing times `t` (N,) [s] that are not one
    uniform sampling up to jitter: a stamp off the least-squares grid by more than
    `UNIFORM_TOL` intervals, or a step beyond (1 ± `UNIFORM_TOL`) intervals."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return
    i = np.arange(t.size) - 0.5 * (t.size - 1)
    tc = t - t.mean()
    step = float(i @ tc / (i @ i))  # the grid's interval, > 0 for increasing times
    stray = float(np.abs(tc - step * i).max()) / step
    d = np.diff(t) / step
    if stray > UNIFORM_TOL or d.min() < 1 - UNIFORM_TOL or d.max() > 1 + UNIFORM_TOL:
        low, high, med = (float(x) for x in (d.min() * step, d.max() * step, np.median(d) * step))
        raise ValueError(
            f"ImuLog.t must be uniformly sampled (one interval, up to jitter); its steps span "
            f"{low:.4g} … {high:.4g} s (median {med:.4g} s) and its stamps stray "
            f"{stray:.3g} intervals from a uniform grid: a rate change or a gap — resample the "
            "log to one rate, or split it"
        )


PSINS_FIELDS = {
    "interval": "the header's sampling interval (line 2, field 5) [ms]",
    "gyro": "the header's gyro increment unit (line 3, fields 1–3) [arcsec]",
    "accel": "the header's accelerometer increment unit (line 3, fields 4–6) [µg·s] or g "
    "(line 2, field 6) [m/s²]",
}
"""What `check_stationary` names, for a log read by `load_psins`, as the source of each
quantity a unit error would spoil."""


def load_psins(path) -> ImuLog:
    """Read a PSINS-format text IMU log (provenance in `tests/data/README.md`): `%` comments
    (whole lines, or after a sample's six fields), three
    header lines (attitude [°] and velocity; lat [°], lon [°], h [m], t0 [s], interval [ms],
    g; increment units: gyro [arcsec] ×3, accelerometer [µg·s] ×3), then one line of six
    integer increments per sample, axes right–forward–up. Returned in FRD, the heading
    clockwise from north in [0, 360) (PSINS's yaw is counter-clockwise: a yaw of 150° is a
    heading of 210°). The header's attitude is a reference only: `header_attitude_deg`
    (pitch, roll, heading), `None` where it is not finite.

    **Raises:** `ValueError` naming the file (and the line, field) for text that is not
    UTF-8, a malformed header (a field of lines 2–3 not finite, a latitude beyond ±90°, a
    longitude beyond [−180, 360]°, a height beyond (−1e4, 1e5) m, a g or an increment unit
    not > 0) or sample row (a NaN or inf among them), fewer than 2 samples, or an integer
    beyond 2**53 that a float64 would round; `TypeError` for a `path` not a str or path."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(f"load_psins: path must be a file path (str or os.PathLike); got "
                        f"{describe(path)}")  # fmt: skip
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no IMU log at {path}")
    try:  # streamed: the text is never held whole (a 4-h log's was 0.8 GB with its lines)
        with path.open(encoding="utf-8") as f:
            numbered, at = _psins_header(f)
            head = _psins_head(path, numbered)
            with warnings.catch_warnings():  # no sample rows: refused below, in one line
                warnings.filterwarnings("ignore", "loadtxt: input contained no data")
                try:
                    raw = np.loadtxt(f, dtype=float, comments=("%", "#"), ndmin=2)
                except ValueError as err:
                    raise ValueError(
                        f"{path}: sample rows must hold 6 numbers each ({err})"
                    ) from err
    except UnicodeDecodeError:
        data = path.read_bytes()
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as err:  # the whole text's offset: the line
            line = data[: err.start].count(b"\n") + 1
            raise ValueError(
                f"{path}: line {line}: not UTF-8 text ({err.reason}); a PSINS log is plain text"
            ) from None
        raise
    if raw.size == 0:
        raise ValueError(f"{path}: a PSINS log needs 3 header lines and samples; got no samples")
    (pitch, roll, yaw, *_), (lat, lon, h, t0, dt_ms, g), units = head
    if not -90.0 <= lat <= 90.0:
        raise ValueError(
            f"{path}: the header's latitude (line 2, field 1) = {lat:g}° is outside ±90°"
        )
    if not dt_ms > 0:
        raise ValueError(f"{path}: the sampling interval (header line 2, field 5) must be > 0 ms")
    if raw.shape[1] != 6:
        raise ValueError(f"{path}: sample rows must hold 6 numbers; got {raw.shape[1]}")
    if raw.shape[0] < 2:
        raise ValueError(f"{path}: a PSINS log needs at least 2 samples; got {raw.shape[0]}")
    if not np.all(np.isfinite(raw)):  # "nan", "inf": integer counts cannot be
        row, j = (int(i) for i in np.argwhere(~np.isfinite(raw))[0])
        raise ValueError(f"{path}: sample row {row}, field {j + 1} ({_PSINS_SAMPLE[j]}) must "
                         f"be a finite integer count; got {raw[row, j]}")  # fmt: skip
    if beyond_exact({"samples": raw.ravel()}):  # an integer the float may have rounded
        _refuse_rounded_samples(path, at)
    gyro_rfu = raw[:, :3] * np.asarray(units[:3]) * ARCSEC
    acc_rfu = raw[:, 3:] * np.asarray(units[3:]) * 1e-6 * g
    rfu_to_frd = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    n = raw.shape[0]
    t = t0 + dt_ms * 1e-3 * np.arange(1, n + 1)
    attitude = (pitch, roll, wrap_heading_deg(-yaw))  # PSINS yaw: counter-clockwise
    return ImuLog(
        device(t),  # no program per length (jnp.asarray compiled one)
        device(gyro_rfu @ rfu_to_frd.T),
        device(acc_rfu @ rfu_to_frd.T),
        lat * DEG,
        lon * DEG,
        h,
        attitude if all(math.isfinite(a) for a in attitude) else None,
    )


def _psins_head(path, numbered) -> list:
    """The three header lines `numbered` ((line number, text)) of the PSINS file `path` as
    numbers, checked (`load_psins`'s errors)."""
    lines = [ln for _, ln in numbered]
    if len(lines) < 3:
        raise ValueError(
            f"{path}: a PSINS log needs 3 header lines and samples; got {len(lines)} lines"
        )
    head = []
    for k in range(3):
        fields = lines[k].replace(",", " ").split()
        _refuse_rounded(path, f"header line {k + 1} (line {numbered[k][0]})", fields)
        try:
            vals = [float(x) for x in fields]
        except ValueError as err:
            raise ValueError(f"{path}: header line {k + 1} is not numeric: {lines[k]!r}") from err
        if len(vals) != 6:
            raise ValueError(f"{path}: header line {k + 1} must hold 6 numbers; got {len(vals)}")
        head.append(vals)
    names = ("latitude [°]", "longitude [°]", "height [m]", "start time t0 [s]",
             "sampling interval [ms]", "g [m/s²]", *3 * ["gyro increment unit [arcsec]"],
             *3 * ["accelerometer increment unit [µg·s]"])  # fmt: skip
    for k, (name, v) in enumerate(zip(names, head[1] + head[2], strict=True)):
        if not math.isfinite(v):
            raise ValueError(
                f"{path}: the header's {name} (line {2 + k // 6}, field {1 + k % 6}) must be "
                f"finite; got {v}"
            )
    lon, h, g = head[1][1], head[1][2], head[1][5]
    for k, ok, want in ((1, -180.0 <= lon <= 360.0, "in [-180, 360]"),
                        (2, -1e4 < h < 1e5, "in (-1e4, 1e5)"),
                        (5, g > 0, "> 0")) + tuple(
                            (6 + j, u > 0, "> 0") for j, u in enumerate(head[2])):  # fmt: skip
        if not ok:
            raise ValueError(f"{path}: the header's {names[k]} (line {2 + k // 6}, field "
                             f"{1 + k % 6}) must be {want}; got {(head[1] + head[2])[k]:g}")  # fmt: skip
    return head


def _psins_header(f) -> tuple[list, int]:
    """The first three lines of the open PSINS file `f` that are neither blank nor `%`
    comments, as `(line number, text)`, and the number of lines read."""
    numbered, at = [], 0
    while len(numbered) < 3 and (ln := f.readline()):
        at += 1
        if ln.strip() and not ln.lstrip().startswith("%"):
            numbered.append((at, ln.rstrip("\r\n")))
    return numbered, at


def _refuse_rounded_samples(path, at: int) -> None:
    """`_refuse_rounded` on each sample row of the PSINS file `path` after its line `at` (the
    header's last), read again line by line."""
    with Path(path).open(encoding="utf-8") as f:
        row = 0
        for i, ln in enumerate(f, 1):
            if i <= at or not ln.strip() or ln.lstrip().startswith(("%", "#")):
                continue
            _refuse_rounded(path, f"line {i}, sample row {row}", ln.split(), _PSINS_SAMPLE)
            row += 1


_PSINS_SAMPLE = tuple(f"{s} increment {a}" for s in ("gyro", "accelerometer")
                      for a in ("right", "forward", "up"))  # fmt: skip
"""The fields of a PSINS sample row, as `load_psins`'s errors name them."""


def _refuse_rounded(path, where: str, fields: list[str], names=None) -> None:
    """Refuse a field of a PSINS line that is an integer a float64 would round (beyond
    2**53: a corrupted increment, a time in ns), naming the line and the field."""
    for j, v in enumerate(fields):
        if rounded_integer(v):
            name = f" ({names[j]})" if names is not None and j < len(names) else ""
            raise ValueError(rounded_integer_error(f"{path}: {where}, field {j + 1}{name}", v))
