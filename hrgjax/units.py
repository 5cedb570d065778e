"""Units and named conversions.

hrgjax works in SI inside (rad, s, rad/s, m/s², °C for temperature). The data format and
the CLI speak degrees, degrees per hour and g; every conversion happens through the names
below so that a unit mistake has one place to live.
"""

import math

DEG = math.pi / 180.0
"""One degree in radians."""
ARCSEC = DEG / 3600.0
"""One arc-second in radians."""
HOUR = 3600.0
"""One hour in seconds."""
DEG_PER_S = DEG
"""One degree per second in rad/s."""
DEG_PER_H = DEG / HOUR
"""One degree per hour in rad/s (4.848e-6)."""
DEG_PER_SQRT_H = DEG / math.sqrt(HOUR)
"""One degree per root hour (angle random walk) in rad/√s."""
G0 = 9.80665
"""Standard gravity [m/s²]."""
EARTH_RATE = 7.292115e-5
"""Earth's rotation rate (WGS-84) [rad/s]."""
T_REF_C = 20.0
"""Reference temperature of temperature laws and of the reduced model [°C]."""
K_BRYAN = 0.277
"""Bryan factor of a thin hemisphere, n = 2 (PHYSICS.md §1.1)."""
K_E_NOMINAL = 2 * K_BRYAN
"""Nominal angular gain k_e = 2K = 0.554 used to turn wave-angle rates into input rates."""
K_E_RANGE = (0.0, 1.0)
"""Interval (0, 1] a nominal angular gain k_e = 2K must lie in: the Bryan factor K of a
hemispherical resonator's n = 2 mode is ≈ 0.277–0.3 (k_e ≈ 0.554), 0 < K < 1/2 for any
shell or ring, and k_e = 1 is a Foucault pendulum (PHYSICS.md §1) — a k_e of 55.4 is the
gain in percent."""


K_E_WANTED = "the electrical angular gain k_e = 2K, a number in (0, 1] (≈ 0.554)"
"""What a `k_e` argument must be, as the errors say it."""


def k_e_problem(k_e: float) -> str | None:
    """What is wrong with a nominal angular gain `k_e` (a float), or None: the one check
    behind every `k_e` argument and the CLI's `--k-e` (`K_E_RANGE`)."""
    low, high = K_E_RANGE
    if math.isfinite(k_e) and low < k_e <= high:
        return None
    hint = " (a gain in percent? give 0.554, not 55.4)" if 1.0 < k_e <= 100.0 else ""
    return f"{K_E_WANTED}; got {k_e:g}{hint}"


WINDOW_S = 3.0
"""Default window of moving runs [s]. A window's slope averages the rate over the wave angles
it spans, weighted as the least-squares slope weighs them: at 5 °/s a 3-s window spans 8° of
electrical wave angle and holds 0.998 of a 2θ term's value at its mean angle, a 10-s one 28°
and 0.977; at 50 °/s 3 s span 83° and hold 0.805, at 100 °/s 0.377 (and the 4θ term
averages out near 77 °/s). The Fourier and MLP fits model that average
(`hrgjax.calibration._window_arc`), so it no longer shrinks their fitted ripple (it did: 0.97
of the truth at 20 °/s, 0.80 at 50 °/s); what it costs is resolution of the higher
harmonics at high rates (`calibration.fourier.GAIN_FLOOR`)."""
PHYSICAL_WINDOW_S = 10.0
"""Default window of moving runs for the physical grey box [s] (API, CLI and docs alike). It
reduces the simulated wave angle with the same windows as the measured one, so a window's
arc averaging biases nothing there, and 10-s windows carry ≈ 3× less white angle noise per
window than 3-s ones (the fitted parameters' σ are ≈ 3× smaller)."""


def _real(name: str, x):
    """`x` for a conversion: real numbers (a number, an array, a tracer; a list or tuple as
    an array), else a one-line `TypeError` naming the conversion (a str, None or a bool is
    no angle or rate)."""
    from ._checks import numeric_problem

    problem = numeric_problem(x)
    if problem is not None:
        raise TypeError(f"units.{name}: x must be a real number or an array of them; got {problem}")
    if isinstance(x, list | tuple):
        import numpy as np

        try:
            return np.asarray(x, dtype=float)
        except Exception:  # noqa: BLE001 — a list holding a tracer
            import jax.numpy as jnp

            return jnp.asarray(x, dtype=float)
    return x


def deg(x):
    """Degrees → radians."""
    return _real("deg", x) * DEG


def to_deg(x):
    """Radians → degrees."""
    return _real("to_deg", x) / DEG


def dph(x):
    """Degrees per hour → rad/s."""
    return _real("dph", x) * DEG_PER_H


def to_dph(x):
    """rad/s → degrees per hour."""
    return _real("to_dph", x) / DEG_PER_H


def dps(x):
    """Degrees per second → rad/s."""
    return _real("dps", x) * DEG_PER_S


def to_dps(x):
    """rad/s → degrees per second."""
    return _real("to_dps", x) / DEG_PER_S


STILL_RATE_DPS = 1e-3
"""The table is still where its measured rate is within this of zero [°/s] (3.6 °/h: a rate
table's readback jitter does not turn a static run into a rotation; a turning table, at
tenths of a degree per second and more, is far above it)."""


TEMPERATURE_TOLERANCE_C = 0.05
"""Temperatures closer than this are one temperature in a report [°C]: half the bench
resolution a designed plan is rounded to (0.1 °C), far above the last-bit differences
that a temperature column's arithmetic leaves (2.6 and 2.6000000000000001 °C)."""


def group_temperatures(values, tol: float = TEMPERATURE_TOLERANCE_C):
    """The report group of each temperature in `values` [°C]: the median of its group's
    values, one number per group, so that `np.unique` of the result lists each temperature
    once and `labels == T` selects its members.

    Groups are formed greedily from the coldest value: a group takes every value within
    `tol` [°C] of its coldest member, and the next value starts the next group — so a group
    spans at most `tol`, and values further apart than `tol` are never merged (a slow ramp's
    values are not chained into one group). NaN stays NaN.

    **Arguments:** `values`, temperatures [°C] (any shape); `tol`, the width of a group
    [°C] (≥ 0; 0 groups equal values only).

    **Returns:** float array of `values`' shape, each value's group temperature [°C].
    """
    import numpy as np

    from ._checks import check_numbers

    check_numbers("values", values, "temperatures [°C]: real numbers")
    if isinstance(tol, bool) or not (
        isinstance(tol, (int, float)) and math.isfinite(tol) and tol >= 0
    ):
        raise ValueError(f"tol must be a finite number ≥ 0 [°C]; got {tol!r}")
    x = np.asarray(values, dtype=float)
    flat = x.ravel()
    labels = np.full(flat.shape, np.nan)
    finite = np.flatnonzero(np.isfinite(flat))
    order = finite[np.argsort(flat[finite], kind="stable")]
    ordered = flat[order]
    start = 0
    while start < order.size:
        stop = int(np.searchsorted(ordered, ordered[start] + tol, side="right"))
        labels[order[start:stop]] = np.median(ordered[start:stop])
        start = stop
    return labels.reshape(x.shape)
