"""`check_fixes`: the one-line refusals of GNSS fixes that `loosely_coupled`
([`hrgjax.ins.ekf`][hrgjax.ins.ekf], which imports it from here) cannot use."""

from __future__ import annotations

import numpy as np

from .. import _checks
from .constants import check_latitude_radians
from .gnss import GnssData


def _dtype(x):
    """The dtype of an array, or of a list as NumPy reads it; None for a ragged list."""
    try:
        return np.dtype(x.dtype) if hasattr(x, "dtype") else np.asarray(x).dtype
    except (TypeError, ValueError):
        return None


def check_fixes(fixes, dt, where: str = "loosely_coupled") -> None:
    """Refuse, in one line naming `where`, `fixes` that are not a `GnssData` of (M,) fields
    (`v_ned` (M, 3); `valid` bools, or ints holding only 0 and 1) and, where their values
    are concrete: times `t` that do not step with `index` × `dt` [s] — each fix within half
    an IMU sample of its epoch, up to one offset common to all (GPS time, say; float32 times
    to their round-off): fixes made for another IMU interval —, a NaN in a valid fix, or a
    latitude in degrees. The filter reads `index`, never `t`: the times only catch a
    mismatch."""
    if not isinstance(fixes, GnssData):
        raise TypeError(f"{where}: fixes must be a GnssData (gnss.measure); got "
                        f"{_checks.describe(fixes)}")  # fmt: skip
    m = np.shape(fixes.lat)[0] if np.ndim(fixes.lat) == 1 else "M"
    for name in ("t", "index", "lat", "lon", "h", "v_ned", "valid"):
        x, want = getattr(fixes, name), (m, 3) if name == "v_ned" else (m,)
        mask = name == "valid" and getattr(_dtype(x), "kind", None) not in ("b", "i", "u")
        if np.shape(x) != want or mask:
            raise ValueError(f"{where}: fixes.{name} must be {want}"
                             f"{' bools (or ints 0 and 1)' * (name == 'valid')} for the {m} "
                             f"fixes; got {_checks.describe(x)}")  # fmt: skip
    ok = _checks.concrete_value(fixes.valid)
    if ok is not None and ok.dtype.kind != "b" and not np.isin(ok, (0, 1)).all():
        k = int(np.argmax(~np.isin(ok, (0, 1))))
        raise ValueError(f"{where}: fixes.valid must be ({m},) bools (or ints 0 and 1) for "
                         f"the {m} fixes; got {ok[k]} at fix {k}")  # fmt: skip
    t, i, d = (_checks.host_value(x) for x in (fixes.t, fixes.index, dt))
    if t is not None and t.size:
        _checks.check_finite_host(f"{where}: fixes.t", t)
    if not (t is None or i is None or d is None or t.size < 2):
        off = t - i * d  # one offset for every fix, to within an IMU sample
        spread, kind = float(off.max() - off.min()), _dtype(fixes.t)
        eps = np.finfo(kind if np.issubdtype(kind, np.floating) else float).eps
        if spread > max(float(d), 8 * eps * float(np.abs(t).max())):
            raise ValueError(f"{where}: fixes.t must be fixes.index × dt (dt = {float(d):g} s) "
                             "plus one offset (GPS time, say), each fix within half an IMU "
                             f"sample of its epoch; t − index·dt spans {spread:.4g} s: fixes "
                             "made for another IMU interval?")  # fmt: skip
    for name in ("lat", "lon", "h", "v_ned"):
        if (x := _checks.host_value(getattr(fixes, name))) is not None and ok is not None:
            _checks.check_finite_host(f"{where}: fixes.{name} (a valid fix)", x[ok.astype(bool)])
    check_latitude_radians(f"{where}: fixes.lat", fixes.lat)
