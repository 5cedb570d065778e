r"""Allan-family deviations of rate samples (NIST SP 1065 definitions), computed in JAX.

Inputs are *rate* ("frequency") samples $y_k$ at interval $\tau_0$; the phase is
$x_k = \tau_0\sum_{j<k} y_j$ ($x_0 = 0$). The averaging factor `m` is a static integer
($\tau = m\tau_0$). Checked against the NBS14 data set (PHYSICS.md §12).

The single-factor estimators (`adev` … `totdev`) and one compiled curve over many factors
(`curve`, behind [`allan_deviation`][hrgjax.allan_deviation]); `hrgjax.allan.result` puts
that curve on allantools' τ grids with its statistics
([`deviation`][hrgjax.allan.deviation]).

Each takes one record: samples that are not 1-D (an (N, 3) array of three axes) are refused
in one line, not flattened into one record.
"""

from __future__ import annotations

import functools
import math
import numbers
import operator

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_1d, check_numbers, concrete_value, describe, int_as_float
from .._compiled import device, fused
from .._progress import bar
from .._upstream import trace_state_clean
from .._x64 import require_x64


def _phase(y, tau0):
    """The angle of rate samples `y` less their mean rate (every deviation ignores a constant
    rate; a record of 2π·5 kHz ± 1e-5 rad/s summed as it is lost half of oadev's digits at
    10⁷ samples — allantools' `frequency2phase` centres too)."""
    y = jnp.asarray(y, dtype=float)
    return jnp.concatenate([jnp.zeros(1), jnp.cumsum(y - jnp.mean(y)) * tau0])


def _block_means(y, m):
    """Means of the k = ⌊N/m⌋ whole blocks of m samples."""
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    return y[: k * m].reshape(k, m).mean(axis=1)


def _check(y, m, needed, name):
    require_x64(f"hrgjax.allan.{name}")  # float32 sums of 2¹⁸ samples: oadev 6.8× off at m = 1
    n = np.shape(y)[0]
    if int(m) != m or m < 1:
        raise ValueError(f"{name}: m must be a positive integer; got {m}")
    if n < needed:
        raise ValueError(f"{name}: m = {m} needs at least {needed} samples; got {n}")


_TRACED_FACTOR = (  # how a traced averaging factor is refused (after "name: arg")
    "must be concrete (static), not traced by jax.jit/vmap (it sets the program's shapes): "
    "give a Python int (jax.jit(f, static_argnums=...) for a jitted function's argument), "
    "or sweep factors with hg.allan_deviation(y, dt, ms=[...]) (one program for every "
    "list of that length)"
)


def _factor(m, name: str, arg: str = "m", form: str = "a positive integer") -> int:
    """The averaging factor as a Python int: any integer, or a whole real number (2.0);
    anything else is refused naming `name` and its argument `arg` (the range is
    `_check`'s). A value traced by `jax.jit`/`jax.vmap` is refused in one line saying that
    the factor must be concrete and how to sweep factors."""
    if isinstance(m, jax.core.Tracer) and concrete_value(m) is None:
        raise ValueError(f"{name}: {arg} {_TRACED_FACTOR}")
    try:
        return operator.index(m)
    except TypeError:
        pass
    if isinstance(m, numbers.Real) and math.isfinite(m) and float(m).is_integer():
        return int(m)
    raise ValueError(f"{name}: {arg} must be {form}; got {describe(m)}")


def _check_inputs(name, y, tau0, tau_name="tau0"):
    """The sample interval a positive finite number of seconds, and host samples (a list or
    NumPy array; a JAX array is not copied back to be read) finite: NaN samples are gaps only
    to [`hrgjax.allan.deviation`][hrgjax.allan.deviation]. Traced values pass."""
    # complex or boolean samples were read as their real part or 0/1, a str as shape ()
    check_numbers(f"{name}: y", y, "real rate samples, 1-D (one per interval)")
    check_1d(f"{name}: y", y, "one rate sample per interval")
    step = concrete_value(tau0)  # None when traced
    if step is not None and not (
        step.ndim == 0 and step.dtype.kind in "iuf" and np.isfinite(step) and step > 0
    ):
        raise ValueError(f"{name}: {tau_name} must be the sample interval, a number > 0 [s]; "
                         f"got {describe(tau0)}")  # fmt: skip
    values = None if isinstance(y, jax.Array) else concrete_value(y)
    if values is not None and np.asarray(values).dtype.kind in "fc":
        bad = np.flatnonzero(~np.isfinite(np.ravel(values)))
        if bad.size:
            raise ValueError(f"{name}: y must be finite; found {np.ravel(values)[bad[0]]} at "
                             f"index {int(bad[0])} (for records with gaps (NaN): "
                             "hrgjax.allan.deviation)")  # fmt: skip


def _per_tau(fn):
    """One deviation at one τ as one compiled program per data length and `m` (`fused`),
    behind the eager checks: `y` may be any array-like (a list too), `m` any integer (a
    NumPy or 0-d JAX integer too)."""
    core = fused(fn, static_argnames="m")

    @functools.wraps(fn)
    def call(y, m: int = 1, tau0: float = 1.0):
        _check_inputs(fn.__name__, y, tau0)
        return core(y if isinstance(y, jax.Array) else device(y, float), _factor(m, fn.__name__),
                    int_as_float(tau0))  # fmt: skip

    return call


@_per_tau
def adev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Allan deviation of rate samples `y` at τ = m·τ0. `y` rate samples
    (1-D, any unit), `m` the averaging factor (int ≥ 1), `tau0` the sample interval τ0 [s].
    **Returns** the deviation in `y`'s unit."""
    _check(y, m, 2 * m, "adev")
    ybar = _block_means(y, m)
    return jnp.sqrt(0.5 * jnp.mean(jnp.diff(ybar) ** 2))


@_per_tau
def oadev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Allan deviation at τ = m·τ0. `y` rate samples (1-D, any unit), `m` the
    averaging factor (int ≥ 1), `tau0` the sample interval τ0 [s]. **Returns** the deviation
    in `y`'s unit."""
    _check(y, m, 2 * m, "oadev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (2 * tau**2))


@_per_tau
def mdev(y, m: int = 1, tau0: float = 1.0):
    """Modified Allan deviation at τ = m·τ0. `y` rate samples (1-D, any unit), `m` the
    averaging factor (int ≥ 1), `tau0` the sample interval τ0 [s]. **Returns** the deviation
    in `y`'s unit."""
    _check(y, m, 3 * m - 1, "mdev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = c[m:] - c[:-m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(s**2) / (2 * m**2 * tau**2))


@_per_tau
def hdev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Hadamard deviation at τ = m·τ0. `y` rate samples (1-D, any unit), `m` the
    averaging factor (int ≥ 1), `tau0` the sample interval τ0 [s]. **Returns** the deviation
    in `y`'s unit."""
    _check(y, m, 3 * m, "hdev")
    ybar = _block_means(y, m)
    d = ybar[2:] - 2 * ybar[1:-1] + ybar[:-2]
    return jnp.sqrt(jnp.mean(d**2) / 6)


@_per_tau
def ohdev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Hadamard deviation at τ = m·τ0. `y` rate samples (1-D, any unit), `m` the
    averaging factor (int ≥ 1), `tau0` the sample interval τ0 [s]. **Returns** the deviation
    in `y`'s unit."""
    _check(y, m, 3 * m, "ohdev")
    x = _phase(y, tau0)
    d = x[3 * m :] - 3 * x[2 * m : -m] + 3 * x[m : -2 * m] - x[: -3 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (6 * tau**2))


@_per_tau
def totdev(y, m: int = 1, tau0: float = 1.0):
    """Total deviation at τ = m·τ0 (phase extended by reflection at both ends). `y` rate samples (1-D, any unit), `m` the
    averaging factor (int ≥ 1, at most the N rate samples: τ up to the record's length T,
    as allantools and [`deviation`][hrgjax.allan.deviation]), `tau0` the sample interval τ0
    [s]. **Returns** the deviation in `y`'s unit."""
    _check(y, m, 2, "totdev")
    x = _phase(y, tau0)
    n = x.shape[0]
    if m > n - 1:  # the reflected phase reaches i ± m for every i = 1 … n − 2 up to m = n − 1
        raise ValueError(f"totdev: m = {m} needs m ≤ N = {n - 1} rate samples (τ ≤ T)")
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
    values compiles once, not 20 times. An eager call on `CURVE_STEPPED_FROM` samples or
    more shows a progress bar and computes the same values in steps (`curve_parts`).

    **Arguments:**

    - `ms`: averaging factors (positive integers); default: octaves 1, 2, 4, … up to N/4.
    - `kind`: one of `adev`, `oadev`, `mdev`, `hdev`, `ohdev`, `totdev`.

    `dt` may be traced (`jax.jit`, `jax.vmap` or `jax.grad` over the sample interval, as
    `oadev`'s `tau0`): the same values as the eager call; a traced `dt` is not checked.

    **Returns:** `(taus [s], deviations [rate unit])` as arrays.

    **Raises:** `ValueError` for an unknown kind, an `m` the data are too short for, a `dt`
    that is not a positive number, samples that are not 1-D (several records, e.g. (N, 3)
    axes: one call per record; never flattened into one), or host samples (a list, a NumPy
    array) that are not finite (gaps: `hg.allan.deviation`).
    """
    require_x64("hrgjax.allan.allan_deviation")
    if not isinstance(kind, str) or kind not in _KINDS:
        raise ValueError(f"kind must be one of {list(_KINDS)}; got {describe(kind)}")
    _check_inputs("allan_deviation", rate, dt, "dt")
    n = np.shape(rate)[0]
    if ms is None:
        ms = [2**k for k in range(int(np.log2(max(n // 4, 1))) + 1)]
    # a 2-D ms was flattened, an empty one, NaN or a str failed inside JAX or int()
    form = "the averaging factors, whole numbers >= 1 in a 1-D list"
    if any(isinstance(v, jax.core.Tracer) and concrete_value(v) is None
           for v in (ms, *(ms if isinstance(ms, list | tuple) else ()))):  # fmt: skip
        raise ValueError("allan_deviation: ms must be concrete (static) averaging factors: "
                         "they are traced (jax.jit/vmap); pass them from outside the "
                         "transformation as a list or NumPy array (one program serves every "
                         "list of the same length), or as a tuple under jax.jit's "
                         "static_argnums")  # fmt: skip
    check_numbers("allan_deviation: ms", ms, form)
    if np.ndim(ms) > 1 or np.size(ms) == 0:
        raise ValueError(f"allan_deviation: ms must be {form}; got {describe(ms)}")
    ms = [_factor(m, "allan_deviation", "ms", form) for m in np.asarray(ms).ravel().tolist()]
    needed = {"adev": 2, "oadev": 2, "mdev": 3, "hdev": 3, "ohdev": 3, "totdev": 0}[kind]
    for m in ms:
        _check(rate, m, max(needed * m - (kind == "mdev"), 2), kind)
        if kind == "totdev" and m > n:  # τ up to T, as `totdev` (m = n was refused)
            raise ValueError(f"totdev: m = {m} needs m ≤ N = {n} rate samples (τ ≤ T)")
    # a traced dt (jit, vmap or grad over the sample interval) goes into the program as it
    # is, a float64 (`oadev`'s tau0 too); a concrete one as a Python float (one program)
    traced = isinstance(dt, jax.core.Tracer)
    step = dt.astype(float) if traced else float(dt)
    if (n >= CURVE_STEPPED_FROM and trace_state_clean() and not traced
            and not isinstance(rate, jax.core.Tracer)):  # fmt: skip
        values = []  # long records: the same values in steps, behind a progress bar
        with bar(len(ms), f"allan_deviation {kind}", unit="τ") as progress:
            for part in curve_parts(jnp.asarray(rate, dtype=float), ms, step, kind):
                values.append(np.asarray(part))
                progress.update(min(CURVE_CHUNK, len(ms) - CURVE_CHUNK * (len(values) - 1)))
        devs = device(np.concatenate(values)[: len(ms)])
    else:
        devs = curve(jnp.asarray(rate, dtype=float), jnp.asarray(ms), step, kind)
    if traced:
        return jnp.asarray(ms, dtype=float) * step, devs
    # τ on the host: eagerly `jnp.asarray(ms) * dt` was an XLA multiply per type of dt
    taus = np.asarray(ms, dtype=float) * step
    return (device(taus) if trace_state_clean() else jnp.asarray(taus)), devs


@functools.partial(jax.jit, static_argnames=("kind",))
def curve(y, ms, tau0, kind):
    """Deviations of `kind` (one of `adev` … `totdev`) of rate samples `y` [any rate unit]
    every `tau0` [s], at every averaging factor in `ms` (a run-time integer array: one
    program per kind, length of `y` and count of `ms`) [rate unit]. The scan keeps the memory
    at one factor's O(N). `curve_parts` gives the same values in host-side steps (progress
    on long records)."""
    check_1d("curve: y", y, "one rate sample per interval")
    x, xp = _phases(y, tau0, kind)
    return _factor_scan(y, x, xp, ms, tau0, kind, _scan_start(ms, x))[1]


CURVE_CHUNK = 4
"""Averaging factors per compiled call of `curve_parts` (each factor costs one O(N) pass)."""

CURVE_STEPPED_FROM = 1 << 24
"""Samples from which an eager [`allan_deviation`][hrgjax.allan_deviation] computes its curve
in steps (`curve_parts`) behind a progress bar, with the same values bit for bit (≈ 2 s of
work on a 2-core CPU at 1.7·10⁷ samples)."""


def curve_parts(y, ms, tau0: float, kind: str, *, chunk: int = CURVE_CHUNK) -> list:
    """`curve` of concrete samples in host-side steps, bit for bit: the phase built once
    (one program per kind and length), then the factors `chunk` at a time (one program per
    kind, length and `chunk`, whatever the count of `ms`), every
    step dispatched at once (JAX runs them in order, asynchronously). A caller blocks on each
    part in turn to show progress; their concatenation's first `len(ms)` values are the
    curve. `ms` is padded to a whole number of chunks with its last factor, which the scan
    reuses at no cost. Not for traced values (use `curve`)."""
    ms = np.asarray(ms)
    if ms.ndim != 1 or ms.size == 0 or int(chunk) < 1:
        raise ValueError(f"curve_parts: ms must be 1-D and non-empty and chunk ≥ 1; got "
                         f"ms of shape {ms.shape}, chunk {describe(chunk)}")  # fmt: skip
    chunk = int(chunk)
    ms = np.concatenate([ms, np.full(-ms.size % chunk, ms[-1], ms.dtype)])
    y = y if isinstance(y, jax.Array) else device(y, float)
    x, xp = _phases_program(y, tau0, kind)
    carry = (device(np.asarray(-1, ms.dtype)), device(np.zeros((), x.dtype)))  # _scan_start's
    parts = []
    for i in range(0, ms.size, chunk):
        carry, values = _scan_program(y, x, xp, device(ms[i : i + chunk]), tau0, kind, carry)
        parts.append(values)
    return parts


def _phases(y, tau0, kind):
    """The phase x and its extension xp: reflected at both ends (totdev), else padded with its
    last value (x[i + k] a contiguous slice for any k < n)."""
    x = _phase(y, tau0)
    n = x.shape[0]
    if kind == "totdev":  # the record reflected at both ends, built once for every m
        j = jnp.arange(1, n - 1)
        xp = jnp.concatenate([2 * x[0] - x[j][::-1], x, 2 * x[-1] - x[n - 1 - j]])
    else:  # padded with its last value: x[i + k] is a contiguous slice for any k < n
        xp = jnp.concatenate([x, jnp.full(n + _LANES, x[-1])])
    return x, xp


def _scan_start(ms, x):
    return (jnp.asarray(-1, ms.dtype), jnp.zeros((), x.dtype))


def _factor_scan(y, x, xp, ms, tau0, kind, init):
    """The deviations at factors `ms` from the scan carry `init` (the last factor and its
    value): `(carry, values)`."""

    def step(last, m):
        # a grid padded with repeats of its last factor: a repeat reuses the value (a real
        # branch inside the scan, so the padding costs nothing)
        value = jax.lax.cond(
            m == last[0],
            lambda: last[1],
            lambda: _AT_M[kind](y, x, xp, m, tau0).astype(last[1].dtype),
        )
        return (m, value), value

    return jax.lax.scan(step, init, ms)


_phases_program = jax.jit(_phases, static_argnames="kind")
_scan_program = jax.jit(_factor_scan, static_argnames="kind")


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
