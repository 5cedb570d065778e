"""The data contract's columns (`COLUMNS`, `REQUIRED`) and the checks of one given column:
numbers in the column's unit, no NaN or infinity, exact integers and run ids, host data
(`checked_column`), time strictly increasing within a run (`check_time`) and a table angle
that is not wrapped to one turn (`check_table_wraps`)."""

from __future__ import annotations

import numbers
import re

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
    "rebalance_rate_dps": "force-to-rebalance output: the rate read from the rebalance force "
    "[°/s] (`hrgjax simulate --mode ftr`)",
    "rebalance_on": "1 where force-to-rebalance held the wave (read rebalance_rate_dps), 0 "
    "where the gyro ran whole-angle (read wave_angle_deg)",
    "precession_dps": "commanded precession rate of the wave [°/s, electrical] (virtual "
    "precession, angle switching)",
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


def is_number(field: str) -> bool:
    """Whether a CSV field (surrounding blanks ignored) is a number as the CSV reader takes
    it: decimal or scientific notation, or nan/inf."""
    return _NUMBER.fullmatch(field.strip()) is not None


MAX_EXACT_INTEGER = 2**53
"""Largest integer magnitude a float64 holds exactly; larger run ids or integer values are
refused rather than rounded."""


def checked_column(name: str, value) -> np.ndarray:
    """One column as a new array: float64 (``run``: int64; an extra column: float64 or text),
    or a `ValueError` naming the column, the row and the expected form (a `TypeError` for a
    traced value: inside `jax.jit` or `jax.vmap` there are no numbers to check or keep)."""
    try:
        arr = np.asarray(value)
    except Exception:
        if _traced(value):
            raise TypeError(
                f"MeasuredData holds host data, and column {name!r} is traced (inside jax.jit, "
                "jax.vmap or jax.grad): build it outside them (from a Record returned by the "
                "jitted function: record.to_data())"
            ) from None
        raise
    if arr.ndim != 1:
        raise ValueError(f"column {name!r} must be 1-D (one value per row); got shape {arr.shape}")
    unit = unit_hint(name)
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
        beyond = (arr > MAX_EXACT_INTEGER) | (arr < -MAX_EXACT_INTEGER)
        big = [i for i in np.flatnonzero(beyond) if int(float(arr[i])) != int(arr[i])]
        big = np.asarray(big, dtype=int)
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


def unit_hint(name: str) -> str:
    """The unit of column `name` as error messages give it ("[°/s]", "[integer id]", or "the
    column's unit" for a column without one)."""
    if name == "run":
        return "[integer id]"
    meaning = COLUMNS.get(name)
    if meaning is None or "[" not in meaning:
        return "the column's unit"
    return meaning[meaning.rindex("[") : meaning.rindex("]") + 1]


def check_time(t: np.ndarray, run: np.ndarray) -> None:
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


def _traced(value) -> bool:
    """Whether `value` (an array, or a list of them) holds a JAX tracer."""
    import jax

    return any(isinstance(v, jax.core.Tracer) for v in jax.tree_util.tree_leaves(value))


WRAP_TOLERANCE_DEG = 5.0
"""How far [°] (plus 10 % of the integral's step) a step of `table_angle_deg` between two
adjacent rows of a run may lie from the integral of `table_rate_dps` over them ± one turn
and be read as a wrap (`check_table_wraps`): the trapezoid misses a true step by
|Δrate|·Δt/2 at most (1.25° where a table starts at 5 °/s between samples 0.5 s apart); a
column in another unit (arc-minutes, a rate in rad/s, time in ms) lands that near a whole
turn only by chance."""


def check_table_wraps(table_angle_deg, integral_deg, run, time_s) -> None:
    """Refuse a `table_angle_deg` column wrapped to one turn (an encoder's azimuth in
    [0, 360) or (−180, 180]), in any run, turning or at rest: between two adjacent rows of a
    run where the integral of `table_rate_dps` (`integral_deg`, per row) moves less than half
    a turn (a wrap is then unambiguous), it steps one turn (within `WRAP_TOLERANCE_DEG` +
    10 % of the integral's step) away from that integral — a step the table does not make
    and its rate does not show. Each run's windows read their table rate from this column,
    so one wrapped run among many is refused too, naming the run and the rows."""
    table, integral, t = (np.asarray(x, dtype=float) for x in (table_angle_deg, integral_deg,
                                                                time_s))  # fmt: skip
    run = np.asarray(run)
    order = np.argsort(run, kind="stable")  # rows of a run in time order (`check_time`)
    same = run[order][1:] == run[order][:-1]
    step = np.diff(integral[order])
    off = np.diff(table[order]) - step
    tol = WRAP_TOLERANCE_DEG + 0.1 * np.abs(step)
    turn = (np.abs(step) < 180.0) & (np.abs(np.abs(off) - 360.0) <= tol)
    bad = np.flatnonzero(same & turn)
    if not bad.size:
        return
    i, j = int(order[bad[0]]), int(order[bad[0] + 1])
    own = table[run == run[i]]
    lo, hi = own.min(), own.max()
    form = "[0, 360)" if lo >= 0.0 and hi < 360.0 else ""
    form = "(−180, 180]" if not form and lo >= -180.0 and hi <= 180.0 else form or "one turn"
    raise ValueError(
        f"column 'table_angle_deg' steps {table[j] - table[i]:+.4g}° from row {i} to row {j} of "
        f"run {run[i]} (times {t[i]:g} → {t[j]:g} s), {off[bad[0]]:+.4g}° off the integral of "
        f"'table_rate_dps' over them: it looks wrapped to {form} (an encoder's azimuth); the "
        "table angle must be unwrapped (np.unwrap(a, period=360.0) run by run), or leave the "
        "column out to take the rate's integral"
    )
