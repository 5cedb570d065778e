r"""Allan-family deviations of rate samples (NIST SP 1065 definitions), computed in JAX.

Inputs are *rate* ("frequency") samples $y_k$ at interval $\tau_0$; the phase is
$x_k = \tau_0\sum_{j<k} y_j$ ($x_0 = 0$). The averaging factor `m` is a static integer
($\tau = m\tau_0$). Checked against the NBS14 data set (PHYSICS.md §12).

The single-factor estimators (`adev` … `totdev`), one compiled curve over many factors
([`allan_deviation`][hrgjax.allan_deviation]) and [`deviation`][hrgjax.allan.deviation]:
that curve on allantools' τ grids, with the statistics of `hrgjax.allan.uncertainty`
(noise type, EDF, χ² interval) attached.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import operator

import jax
import jax.numpy as jnp
import numpy as np

from .._compiled import device, fused
from .._x64 import require_x64
from .uncertainty import (
    NOISE_RULES,
    ONE_SIGMA,
    confidence_interval,
    edf_greenhall,
    edf_totdev,
    noise_id,
)


def _phase(y, tau0):
    y = jnp.asarray(y, dtype=float)
    return jnp.concatenate([jnp.zeros(1), jnp.cumsum(y) * tau0])


def _check(y, m, needed, name):
    n = np.shape(y)[0]
    if int(m) != m or m < 1:
        raise ValueError(f"{name}: m must be a positive integer; got {m}")
    if n < needed:
        raise ValueError(f"{name}: m = {m} needs at least {needed} samples; got {n}")


def _per_tau(fn):
    """One deviation at one τ as one compiled program per data length and `m` (`fused`),
    behind the eager checks: `y` may be any array-like (a list too), `m` any integer (a
    NumPy or 0-d JAX integer too)."""
    core = fused(fn, static_argnames="m")

    @functools.wraps(fn)
    def call(y, m: int = 1, tau0: float = 1.0):
        try:
            m = operator.index(m)
        except TypeError:
            pass  # `_check` names the problem
        return core(y if isinstance(y, jax.Array) else device(y, float), m, tau0)

    return call


@_per_tau
def adev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Allan deviation of rate samples `y` at τ = m·τ0."""
    _check(y, m, 2 * m, "adev")
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    ybar = y[: k * m].reshape(k, m).mean(axis=1)
    return jnp.sqrt(0.5 * jnp.mean(jnp.diff(ybar) ** 2))


@_per_tau
def oadev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Allan deviation at τ = m·τ0."""
    _check(y, m, 2 * m, "oadev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (2 * tau**2))


@_per_tau
def mdev(y, m: int = 1, tau0: float = 1.0):
    """Modified Allan deviation at τ = m·τ0."""
    _check(y, m, 3 * m - 1, "mdev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = c[m:] - c[:-m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(s**2) / (2 * m**2 * tau**2))


@_per_tau
def hdev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Hadamard deviation at τ = m·τ0."""
    _check(y, m, 3 * m, "hdev")
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    ybar = y[: k * m].reshape(k, m).mean(axis=1)
    d = ybar[2:] - 2 * ybar[1:-1] + ybar[:-2]
    return jnp.sqrt(jnp.mean(d**2) / 6)


@_per_tau
def ohdev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Hadamard deviation at τ = m·τ0."""
    _check(y, m, 3 * m, "ohdev")
    x = _phase(y, tau0)
    d = x[3 * m :] - 3 * x[2 * m : -m] + 3 * x[m : -2 * m] - x[: -3 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (6 * tau**2))


@_per_tau
def totdev(y, m: int = 1, tau0: float = 1.0):
    """Total deviation at τ = m·τ0 (phase extended by reflection at both ends)."""
    _check(y, m, 2, "totdev")
    x = _phase(y, tau0)
    n = x.shape[0]
    if m > n - 2:
        raise ValueError(f"totdev: m = {m} needs at least {m + 1} samples")
    j = jnp.arange(1, n - 1)
    left = 2 * x[0] - x[j][::-1]
    right = 2 * x[-1] - x[n - 1 - j]
    xs = jnp.concatenate([left, x, right])
    off = n - 2
    i = jnp.arange(1, n - 1) + off
    d = xs[i - m] - 2 * xs[i] + xs[i + m]
    tau = m * tau0
    return jnp.sqrt(_sum(d**2) / (2 * tau**2 * (n - 2)))


_KINDS = {
    "adev": adev,
    "oadev": oadev,
    "mdev": mdev,
    "hdev": hdev,
    "ohdev": ohdev,
    "totdev": totdev,
}


def allan_deviation(rate, dt: float, ms=None, kind: str = "oadev"):
    """A deviation curve of rate samples `rate` [any rate unit] taken every `dt` [s].

    One compiled program per kind and data length serves every set of averaging factors of
    the same count: `m` is a run-time value inside it (masked sums), so a curve of 20 τ
    values compiles once, not 20 times.

    **Arguments:**

    - `ms`: averaging factors (positive integers); default: octaves 1, 2, 4, … up to N/4.
    - `kind`: one of `adev`, `oadev`, `mdev`, `hdev`, `ohdev`, `totdev`.

    **Returns:** `(taus [s], deviations [rate unit])` as arrays.

    **Raises:** `ValueError` for an unknown kind, or an `m` the data are too short for.
    """
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {list(_KINDS)}; got {kind!r}")
    n = np.shape(rate)[0]
    if ms is None:
        ms = [2**k for k in range(int(np.log2(max(n // 4, 1))) + 1)]
    ms = [int(m) if int(m) == m else m for m in np.asarray(ms).ravel().tolist()]
    needed = {"adev": 2, "oadev": 2, "mdev": 3, "hdev": 3, "ohdev": 3, "totdev": 0}[kind]
    for m in ms:
        _check(rate, m, max(needed * m - (kind == "mdev"), 2), kind)
        if kind == "totdev" and m > n - 1:
            raise ValueError(f"totdev: m = {m} needs at least {m + 1} samples")
    devs = _curve(jnp.asarray(rate, dtype=float), jnp.asarray(ms), float(dt), kind)
    return jnp.asarray(ms, dtype=float) * dt, devs


@functools.partial(jax.jit, static_argnames=("kind",))
def _curve(y, ms, tau0, kind):
    """Deviations of `kind` at every averaging factor in `ms` (a run-time integer array);
    `lax.map` keeps the memory at one factor's O(N)."""
    x = _phase(y, tau0)
    n = x.shape[0]
    if kind == "totdev":  # the record reflected at both ends, built once for every m
        j = jnp.arange(1, n - 1)
        xp = jnp.concatenate([2 * x[0] - x[j][::-1], x, 2 * x[-1] - x[n - 1 - j]])
    else:  # padded with its last value: x[i + k] is a contiguous slice for any k < n
        xp = jnp.concatenate([x, jnp.full(n + _LANES, x[-1])])

    def step(last, m):
        # a grid padded with repeats of its last factor: a repeat reuses the value (a real
        # branch inside the scan, so the padding costs nothing)
        value = jax.lax.cond(
            m == last[0],
            lambda: last[1],
            lambda: _AT_M[kind](y, x, xp, m, tau0).astype(last[1].dtype),
        )
        return (m, value), value

    init = (jnp.asarray(-1, ms.dtype), jnp.zeros((), x.dtype))
    return jax.lax.scan(step, init, ms)[1]


def _shifted(x, k):
    """x[i + k] for every i (k a run-time integer); past the end the last value repeats
    (masked by callers). A contiguous slice of the padded array, not a gather."""
    n = x.shape[0]
    return jax.lax.dynamic_slice(jnp.concatenate([x, jnp.full(n, x[-1])]), (k,), (n,))


def _sum(v):
    """Σ v over a 1-D array as 16 interleaved partial sums: XLA:CPU turns a plain reduction
    into one serial chain of additions (latency-bound, ≈ 2 ns per element); 16 independent
    accumulators vectorise, 5× faster on 10⁶ samples (the order of the additions differs
    from `jnp.sum` at round-off)."""
    n = v.shape[0]
    pad = -n % _LANES
    if pad:
        v = jnp.concatenate([v, jnp.zeros(pad, v.dtype)])
    return jnp.sum(jnp.sum(v.reshape(-1, _LANES), axis=0))


_LANES = 16


def _masked_mean(v, count):
    return _sum(v) / jnp.asarray(count).astype(v.dtype)


def _tau(m, tau0, like):
    return m.astype(like.dtype) * tau0


def _slice(xp, k, n):
    return jax.lax.dynamic_slice(xp, (k,), (n,))


def _difference_dev(y, x, xp, m, tau0, order, overlapping):
    """Allan (`order` 2) or Hadamard (3) deviation at factor m from the phase's `order`-th
    differences at lag m: every start (overlapping) or starts at multiples of m. The
    differences run over a length rounded up to whole `_LANES` (the padded phase is long
    enough) so that their sum vectorises without a copy."""
    n1 = x.shape[0]
    length = -(-n1 // _LANES) * _LANES
    i = jnp.arange(length)
    if order == 2:
        d = _slice(xp, 2 * m, length) - 2 * _slice(xp, m, length) + xp[:length]
    else:
        d = (_slice(xp, 3 * m, length) - 3 * _slice(xp, 2 * m, length)
             + 3 * _slice(xp, m, length) - xp[:length])  # fmt: skip
    span = n1 - order * m  # starts i < span have all their points
    keep = i < span
    count = span
    if not overlapping:  # starts at multiples of m: (i + ½)/m floors exactly (float, as
        # integer division does not vectorise on XLA:CPU)
        mf, fi = m.astype(d.dtype), i.astype(d.dtype)
        keep = keep & (jnp.floor((fi + 0.5) * (1.0 / mf)) * mf == fi)
        count = (span + m - 1) // m
    d = jnp.where(keep, d, 0.0)
    tau = _tau(m, tau0, d)
    return jnp.sqrt(_masked_mean(d**2, count) / ((2 if order == 2 else 6) * tau**2))


def _mdev_m(y, x, xp, m, tau0):
    n1 = x.shape[0]
    i = jnp.arange(n1)
    length = n1 - 2 * m
    d = jnp.where(i < length, _slice(xp, 2 * m, n1) - 2 * _slice(xp, m, n1) + x, 0.0)
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = jnp.where(jnp.arange(n1 + 1) <= length - m, _shifted(c, m) - c, 0.0)
    tau = _tau(m, tau0, s)
    return jnp.sqrt(_masked_mean(s**2, length - m + 1) / (2 * m.astype(s.dtype) ** 2 * tau**2))


def _totdev_m(y, x, xs, m, tau0):
    n = x.shape[0]
    i0 = n - 1  # x[1] in the reflected record; the n − 2 inner points from there
    d = _slice(xs, i0 - m, n - 2) - 2 * xs[i0 : i0 + n - 2] + _slice(xs, i0 + m, n - 2)
    tau = _tau(m, tau0, d)
    return jnp.sqrt(_sum(d**2) / (2 * tau**2 * (n - 2)))


_AT_M = {
    "adev": functools.partial(_difference_dev, order=2, overlapping=False),
    "oadev": functools.partial(_difference_dev, order=2, overlapping=True),
    "mdev": _mdev_m,
    "hdev": functools.partial(_difference_dev, order=3, overlapping=False),
    "ohdev": functools.partial(_difference_dev, order=3, overlapping=True),
    "totdev": _totdev_m,
}


# ---------------------------------------------------------------------------------------
# `deviation`: τ grids, term counts, and the curve with its noise type, EDF and interval

KINDS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev", "mtotdev", "ttotdev")
"""The deviations [`deviation`][hrgjax.allan.deviation] computes (mtotdev and ttotdev in
NumPy: [`hrgjax.allan.total`][hrgjax.allan.total])."""


@dataclasses.dataclass(frozen=True)
class AllanResult:
    """A deviation curve with its uncertainty (NumPy arrays, one entry per τ).

    - `kind`: the deviation (one of [`KINDS`][hrgjax.allan.KINDS]); `ci`: the confidence level.
    - `taus` [s]; `m`: averaging factors (τ = m/rate_hz).
    - `dev`: the deviation [rate unit; tdev: rate unit × s, an angle];
      `dev_low`, `dev_high`: the χ² interval at level `ci` (NIST SP 1065 eq. 45).
    - `edf`: equivalent degrees of freedom (Greenhall–Riley; totdev: SP 1065 Table 7;
      mtotdev, ttotdev: Table 8).
    - `n_terms`: the number of differences each estimate averages.
    - `alpha`: the power-law noise identified at each τ, the exponent α of the rate PSD
      S_y(f) ∝ f^α: 2 white angle (phase) noise, 1 flicker angle, 0 white rate (angle random
      walk), −1 flicker rate (bias instability), −2 rate random walk (lag-1 autocorrelation,
      Riley & Greenhall 2004; the B1 and R(n) ratios where the record is short at that τ:
      [`noise_id`][hrgjax.allan.noise_id]).
    - `bias_factor`: what `dev` was multiplied by to remove the estimator's bias (totdev:
      1/√(1 − a·τ/T), NIST SP 1065 §5.2.11; 1 elsewhere and where the correction was off).

    `print(result)` shows it as a table; `to_dict`, `to_json(path)` and `to_csv(path)` write
    it with its units.
    """

    kind: str
    ci: float
    taus: np.ndarray
    m: np.ndarray
    dev: np.ndarray
    dev_low: np.ndarray
    dev_high: np.ndarray
    edf: np.ndarray
    n_terms: np.ndarray
    alpha: np.ndarray
    bias_factor: np.ndarray | None = None
    unit: str = ""

    def _columns(self) -> dict:
        return {
            "tau_s": self.taus, "m": self.m, "dev": self.dev, "dev_low": self.dev_low,
            "dev_high": self.dev_high, "edf": self.edf, "n_terms": self.n_terms,
            "alpha": self.alpha,
        }  # fmt: skip

    def __str__(self) -> str:
        unit = f" [{self.unit}]" if self.unit else ""
        head = f"{self.kind}{unit}, ±{self.ci:.3f} χ² interval"
        cols = (
            f"{'tau [s]':>12} {'m':>8} {'dev':>12} {'low':>12} {'high':>12} {'edf':>9} {'alpha':>6}"
        )
        rows = [
            f"{t:12.5g} {int(m):8d} {d:12.5g} {lo:12.5g} {hi:12.5g} {e:9.4g} {int(a):+6d}"
            for t, m, d, lo, hi, e, a in zip(self.taus, self.m, self.dev, self.dev_low,
                                             self.dev_high, self.edf, self.alpha, strict=True)
        ]  # fmt: skip
        return "\n".join([head, cols, *rows])

    def to_dict(self) -> dict:
        """The curve as plain lists, with its kind, level, unit and column units."""
        out = {"kind": self.kind, "ci": self.ci, "unit": self.unit,
               "units": {"tau_s": "s", "dev": self.unit, "dev_low": self.unit,
                         "dev_high": self.unit, "alpha": "S_y ∝ f^alpha"}}  # fmt: skip
        cols = self._columns()
        if self.bias_factor is not None:
            cols["bias_factor"] = self.bias_factor
        return out | {k: np.asarray(v).tolist() for k, v in cols.items()}

    def to_json(self, path) -> None:
        """Write [`to_dict`][hrgjax.allan.AllanResult.to_dict] to `path` (JSON)."""
        import json

        with open(path, "w") as fh:
            json.dump(self.to_dict(), fh, indent=1)

    def to_csv(self, path) -> None:
        """Write one row per τ to `path` (CSV: `tau_s, m, dev, dev_low, dev_high, edf,
        n_terms, alpha`, the deviation's unit in the header's `dev` column name)."""
        cols = self._columns()
        unit = f" [{self.unit}]" if self.unit else ""
        names = [f"{k}{unit}" if k.startswith("dev") else k for k in cols]
        with open(path, "w") as fh:
            fh.write(",".join(names) + "\n")
            for row in zip(*cols.values(), strict=True):
                fh.write(",".join(repr(float(v)) if isinstance(v, float | np.floating)
                                  else str(int(v)) for v in row) + "\n")  # fmt: skip


TOTVAR_BIAS = {-1: 0.481, -2: 0.750}
"""NIST SP 1065 §5.2.11: the total variance's bias a by noise type α (flicker and random-walk
rate noise; none for white rate or angle noise): E[Totvar] = (1 − a·τ/T)·σ²(τ), T the
record's length."""


def deviation(
    y,
    rate_hz: float,
    kind: str = "oadev",
    taus="octave",
    data: str = "rate",
    ci: float = ONE_SIGMA,
    *,
    bias_correction: bool = True,
    noise_rule: str = "hrgjax",
    unit: str = "",
) -> AllanResult:
    r"""An Allan-family deviation with confidence intervals, as allantools and Stable32
    compute it.

    **Arguments:**

    - `y`: the samples (1-D): rates (`data="rate"`, e.g. °/h) or angles (`data="phase"`, e.g.
      °), taken at `rate_hz` [Hz].
    - `kind`: one of [`KINDS`][hrgjax.allan.KINDS] (tdev = τ·mdev/√3 and ttotdev =
      τ·mtotdev/√3, in angle units).
    - `taus`: `"octave"` (m = 1, 2, 4, …), `"decade"` (1, 2, 4, 10, 20, 40, …), `"all"`
      (every m) or τ values in seconds (rounded to the nearest m, duplicates dropped, as
      allantools does). Factors whose estimate would average fewer than 2 terms are left
      out (allantools' and Stable32's limit).
    - `ci`: confidence level of the interval (default ±1σ, 0.683).
    - `bias_correction`: totdev divided by √(1 − a·τ/T) for the identified noise
      ([`TOTVAR_BIAS`][hrgjax.allan.TOTVAR_BIAS]), mtotdev and ttotdev by
      √[`MTOTVAR_BIAS`][hrgjax.allan.total.MTOTVAR_BIAS], as Stable32 reports them; `False`
      gives the raw estimators (allantools').
    - `noise_rule`: how the noise type is read where the lag-1 autocorrelation cannot:
      `"hrgjax"` (default; intervals checked by Monte Carlo) or `"stable32"` (the rule read
      off Stable32 1.60's octave tables of an OCXO record, whose α, intervals and totdev it
      reproduces at all 90 τ; for comparing with Stable32, its intervals are less well
      calibrated); [`noise_id`][hrgjax.allan.noise_id] says both.
    - `unit`: the samples' unit, carried into the table, files and plots (e.g. "°/h").

    **Gaps**: NaN samples are missing data. Every kind but the total ones then averages only
    the differences whose windows avoid every gap, as allantools' `gradev` (NumPy, not the
    compiled curve; noise type and EDF approximate: [`hrgjax.allan.gaps`][hrgjax.allan.gaps]).
    `n_terms` counts the differences used.

    One compiled program per kind and data length serves every τ grid (factors are run-time
    values, padded to a power-of-two count), so a new grid compiles nothing.

    **Returns:** an [`AllanResult`][hrgjax.allan.AllanResult].

    **Raises:** `ValueError` naming the argument for an unknown kind or data type, a
    non-positive rate, infinite samples, a `ci` outside (0, 1), data too short for any τ, or
    gaps in a totdev;
    `RuntimeError` when JAX is in float32 mode (a summed phase's differences need float64).
    """
    require_x64("hrgjax.allan.deviation (differences of a summed phase)")
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}; got {kind!r}")
    if noise_rule not in NOISE_RULES:
        raise ValueError(f"noise_rule must be one of {list(NOISE_RULES)}; got {noise_rule!r}")
    if data not in ("rate", "phase"):
        raise ValueError(f"data must be 'rate' or 'phase'; got {data!r}")
    if not (isinstance(rate_hz, numbers.Real) and math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate [Hz]; got {rate_hz!r}")
    if not (0.0 < ci < 1.0):
        raise ValueError(f"ci must be a confidence level in (0, 1); got {ci!r}")
    kind_of = np.asarray(y).dtype.kind
    if kind_of in "cbOUSMm":
        what = {"c": "complex numbers", "b": "booleans"}.get(kind_of, f"{np.asarray(y).dtype}")
        if kind_of not in "O" or not all(isinstance(v, numbers.Real) and not isinstance(v, bool)
                                         for v in np.ravel(y)):  # fmt: skip
            raise ValueError(f"y holds {what}; give real numbers (rates or angles)")
    y = np.asarray(y, dtype=float)
    if y.ndim != 1 or y.size < 3:
        raise ValueError(f"y must be 1-D with at least 3 samples; got shape {y.shape}")
    if np.any(np.isinf(y)):
        raise ValueError(f"y has an infinite value at index {int(np.argmax(np.isinf(y)))}")
    tau0 = 1.0 / float(rate_hz)
    gaps = bool(np.any(np.isnan(y)))
    if gaps:
        from .gaps import bridged, gapped_curve

        present = int(np.sum(np.isfinite(y)))
        if present < 3:
            raise ValueError(f"y has {present} values that are not NaN; at least 3 are needed")
        filled = bridged(y, data)
    else:
        filled = y
    if data == "phase":
        x = filled - filled[0]
        rate = np.diff(filled) / tau0
    else:
        rate = filled
        x = np.concatenate([[0.0], np.cumsum(filled) * tau0])
    n_phase = x.size
    m = _factors(taus, rate_hz, n_phase)
    n_terms = np.asarray([_n_terms(kind, int(k), n_phase) for k in m], dtype=int)
    m, n_terms = m[n_terms > 1], n_terms[n_terms > 1]
    if m.size == 0:
        raise ValueError(
            f"y: {y.size} samples are too few for {kind} at any of the τ asked (taus={taus!r})"
        )
    base = "mdev" if kind == "tdev" else kind
    if kind in ("mtotdev", "ttotdev"):  # each run detrended and reflected (hrgjax.allan.total)
        from .total import mtotdev_curve

        if gaps:
            raise ValueError(f"y has gaps (NaN): {kind} reflects every run of 3m points and "
                             "has no gap-tolerant form; split the record, or use mdev")  # fmt: skip
        dev = mtotdev_curve(x, m)[0] / tau0
        n_eff = np.full(m.size, n_phase)
    elif gaps:  # windows across a gap left out (hrgjax.allan.gaps), in NumPy
        dev, n_terms = gapped_curve(kind, y, data, m)
        dev = dev / tau0 if data == "phase" else dev
        m, n_terms, dev = m[n_terms > 1], n_terms[n_terms > 1], dev[n_terms > 1]
        if m.size == 0:
            raise ValueError(f"y: its gaps leave fewer than 2 {kind} terms at every τ asked")
        # the EDF of a gap-free record with as many differences as the gaps leave at each τ
        extra = {"adev": 2, "oadev": 2, "hdev": 3, "ohdev": 3, "mdev": 3, "tdev": 3}[kind]
        stride = m if kind in ("adev", "hdev") else 1
        n_eff = np.minimum(stride * n_terms + extra * m - (kind in ("mdev", "tdev")), n_phase)
    else:
        # one program for every grid of ≤ 32 τ (octave grids up to 2³² samples), powers of
        # two beyond; JAX runs the curve asynchronously while NumPy identifies the noise
        pad = max(32, 1 << int(math.ceil(math.log2(m.size))))
        ms = np.concatenate([m, np.full(pad - m.size, m[-1])])
        pending = _curve(jnp.asarray(rate), jnp.asarray(ms), tau0, base)
        n_eff = np.full(m.size, n_phase)
    dmax = 3 if kind in ("hdev", "ohdev") else 2
    alpha = noise_id(x, m, dmax=dmax, rule=noise_rule, overlapping=kind not in ("adev", "hdev"))
    edf = np.asarray([_edf(kind, int(a), int(k), int(n))
                      for a, k, n in zip(alpha, m, n_eff, strict=True)])  # fmt: skip
    if not gaps and kind not in ("mtotdev", "ttotdev"):
        dev = np.asarray(pending)[: m.size]
    taus_s = m * tau0
    if kind in ("tdev", "ttotdev"):
        dev = dev * taus_s / math.sqrt(3.0)
    factor = np.ones_like(dev)
    if kind in ("mtotdev", "ttotdev") and bias_correction:
        from .total import MTOTVAR_BIAS

        factor = 1.0 / np.sqrt([MTOTVAR_BIAS[int(min(max(a, -2), 2))] for a in alpha])
        dev = dev * factor
    if kind == "totdev" and bias_correction:
        a = np.asarray([TOTVAR_BIAS.get(int(k), 0.0) for k in alpha])
        factor = 1.0 / np.sqrt(1.0 - a * taus_s / ((n_phase - 1) * tau0))
        dev = dev * factor
    low, high = confidence_interval(dev, edf, ci)
    return AllanResult(
        kind=kind, ci=float(ci), taus=taus_s, m=m, dev=dev, dev_low=low, dev_high=high,
        edf=edf, n_terms=n_terms, alpha=alpha, bias_factor=factor, unit=str(unit),
    )  # fmt: skip


def _factors(taus, rate_hz: float, n_phase: int) -> np.ndarray:
    """Averaging factors of a τ grid (allantools' `tau_generator`), sorted and unique."""
    if isinstance(taus, str):
        if taus == "all":
            m = np.arange(1, n_phase + 1, dtype=float)
        elif taus == "octave":
            m = 2.0 ** np.arange(int(math.floor(math.log2(n_phase))) + 1)
        elif taus == "decade":
            m = np.asarray(
                [
                    c * 10.0**k
                    for k in range(int(math.floor(math.log10(n_phase))) + 1)
                    for c in (1, 2, 4)
                ]  # fmt: skip
            )
        else:
            raise ValueError(
                f"taus must be 'octave', 'decade', 'all' or τ values in seconds; got {taus!r}"
            )
    else:
        t = np.asarray(taus, dtype=float).ravel()
        if t.size == 0 or not np.all(np.isfinite(t)):
            raise ValueError(f"taus must be finite τ values in seconds; got {taus!r}")
        if np.any(t <= 0):
            raise ValueError(f"taus must be > 0 s; got {float(t[t <= 0][0]):g} in {taus!r}")
        m = np.round(t * rate_hz)
    m = m[(m > 0) & (m < n_phase)]
    return np.unique(m).astype(int)


def _n_terms(kind: str, m: int, n: int) -> int:
    """Differences averaged by `kind` at factor m over n phase points (allantools' `ns`)."""
    if kind == "adev":
        return max(0, -(-(n - 2 * m) // m))
    if kind == "hdev":
        return max(0, -(-(n - 3 * m) // m))
    if kind == "oadev":
        return max(0, n - 2 * m)
    if kind == "ohdev":
        return max(0, n - 3 * m)
    if kind in ("mdev", "tdev", "mtotdev", "ttotdev"):
        return max(0, n - 3 * m + 1)
    return n - 2 if m <= n - 1 else 0  # totdev: every point, the record reflected


def _edf(kind: str, alpha: int, m: int, n: int) -> float:
    if kind == "totdev":
        return edf_totdev(alpha, m, n)
    if kind in ("mtotdev", "ttotdev"):
        from .total import edf_mtotdev

        return edf_mtotdev(alpha, m, n)
    d = 3 if kind in ("hdev", "ohdev") else 2
    alpha = max(alpha, 2 - 2 * d)  # the variance converges for α > 1 − 2d
    return edf_greenhall(
        alpha, d, m, n, overlapping=kind in ("oadev", "ohdev", "mdev", "tdev"),
        modified=kind in ("mdev", "tdev"),
    )  # fmt: skip
