r"""Allan-family deviations in JAX (NIST SP 1065 definitions).

Inputs are *rate* ("frequency") samples $y_k$ at interval $\tau_0$; the phase is
$x_k = \tau_0\sum_{j<k} y_j$ ($x_0 = 0$). The averaging factor `m` is a static integer
($\tau = m\tau_0$). Checked against the NBS14 data set (PHYSICS.md §12).

IEEE 952 noise terms on an Allan-deviation plot: quantisation $\sqrt3 Q/\tau$, angle random
walk $N/\sqrt\tau$, bias instability flat at $0.6643B$, rate random walk $K\sqrt{\tau/3}$,
rate ramp $R\tau/\sqrt2$.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np


def _phase(y, tau0):
    y = jnp.asarray(y, dtype=float)
    return jnp.concatenate([jnp.zeros(1), jnp.cumsum(y) * tau0])


def _check(y, m, needed, name):
    n = np.shape(y)[0]
    if int(m) != m or m < 1:
        raise ValueError(f"{name}: m must be a positive integer; got {m}")
    if n < needed:
        raise ValueError(f"{name}: m = {m} needs at least {needed} samples; got {n}")


def adev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Allan deviation of rate samples `y` at τ = m·τ0."""
    _check(y, m, 2 * m, "adev")
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    ybar = y[: k * m].reshape(k, m).mean(axis=1)
    return jnp.sqrt(0.5 * jnp.mean(jnp.diff(ybar) ** 2))


def oadev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Allan deviation at τ = m·τ0."""
    _check(y, m, 2 * m, "oadev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (2 * tau**2))


def mdev(y, m: int = 1, tau0: float = 1.0):
    """Modified Allan deviation at τ = m·τ0."""
    _check(y, m, 3 * m - 1, "mdev")
    x = _phase(y, tau0)
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = c[m:] - c[:-m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(s**2) / (2 * m**2 * tau**2))


def hdev(y, m: int = 1, tau0: float = 1.0):
    """Non-overlapping Hadamard deviation at τ = m·τ0."""
    _check(y, m, 3 * m, "hdev")
    y = jnp.asarray(y, dtype=float)
    k = y.shape[0] // m
    ybar = y[: k * m].reshape(k, m).mean(axis=1)
    d = ybar[2:] - 2 * ybar[1:-1] + ybar[:-2]
    return jnp.sqrt(jnp.mean(d**2) / 6)


def ohdev(y, m: int = 1, tau0: float = 1.0):
    """Overlapping Hadamard deviation at τ = m·τ0."""
    _check(y, m, 3 * m, "ohdev")
    x = _phase(y, tau0)
    d = x[3 * m :] - 3 * x[2 * m : -m] + 3 * x[m : -2 * m] - x[: -3 * m]
    tau = m * tau0
    return jnp.sqrt(jnp.mean(d**2) / (6 * tau**2))


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
    return jnp.sqrt(jnp.sum(d**2) / (2 * tau**2 * (n - 2)))


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
    return jax.lax.map(lambda m: _AT_M[kind](y, x, m, tau0), ms)


def _shifted(x, k):
    """x[i + k] for every i (k a run-time integer), clamped at the end (masked by callers)."""
    return x[jnp.minimum(jnp.arange(x.shape[0]) + k, x.shape[0] - 1)]


def _masked_mean(v, count):
    return jnp.sum(v) / jnp.asarray(count).astype(v.dtype)


def _tau(m, tau0, like):
    return m.astype(like.dtype) * tau0


def _oadev_m(y, x, m, tau0):
    n1 = x.shape[0]
    i = jnp.arange(n1)
    d = _shifted(x, 2 * m) - 2 * _shifted(x, m) + x
    d = jnp.where(i + 2 * m < n1, d, 0.0)
    tau = _tau(m, tau0, d)
    return jnp.sqrt(_masked_mean(d**2, n1 - 2 * m) / (2 * tau**2))


def _mdev_m(y, x, m, tau0):
    n1 = x.shape[0]
    i = jnp.arange(n1)
    length = n1 - 2 * m
    d = jnp.where(i < length, _shifted(x, 2 * m) - 2 * _shifted(x, m) + x, 0.0)
    c = jnp.concatenate([jnp.zeros(1), jnp.cumsum(d)])
    s = jnp.where(jnp.arange(n1 + 1) <= length - m, _shifted(c, m) - c, 0.0)
    tau = _tau(m, tau0, s)
    return jnp.sqrt(_masked_mean(s**2, length - m + 1) / (2 * m.astype(s.dtype) ** 2 * tau**2))


def _block_means(y, m):
    """Means of the blocks y[k m : (k+1) m], k < N // m (later entries are 0)."""
    n = y.shape[0]
    k = n // m
    idx = jnp.arange(n)
    sums = jax.ops.segment_sum(jnp.where(idx < k * m, y, 0.0), idx // m, num_segments=n)
    return sums / m.astype(y.dtype), k


def _adev_m(y, x, m, tau0):
    ybar, k = _block_means(y, m)
    j = jnp.arange(y.shape[0])
    d = jnp.where(j < k - 1, _shifted(ybar, 1) - ybar, 0.0)
    return jnp.sqrt(0.5 * _masked_mean(d**2, k - 1))


def _hdev_m(y, x, m, tau0):
    ybar, k = _block_means(y, m)
    j = jnp.arange(y.shape[0])
    d = jnp.where(j < k - 2, _shifted(ybar, 2) - 2 * _shifted(ybar, 1) + ybar, 0.0)
    return jnp.sqrt(_masked_mean(d**2, k - 2) / 6)


def _ohdev_m(y, x, m, tau0):
    n1 = x.shape[0]
    i = jnp.arange(n1)
    d = _shifted(x, 3 * m) - 3 * _shifted(x, 2 * m) + 3 * _shifted(x, m) - x
    d = jnp.where(i + 3 * m < n1, d, 0.0)
    tau = _tau(m, tau0, d)
    return jnp.sqrt(_masked_mean(d**2, n1 - 3 * m) / (6 * tau**2))


def _totdev_m(y, x, m, tau0):
    n = x.shape[0]
    j = jnp.arange(1, n - 1)
    xs = jnp.concatenate([2 * x[0] - x[j][::-1], x, 2 * x[-1] - x[n - 1 - j]])
    i = jnp.arange(1, n - 1) + (n - 2)
    d = xs[i - m] - 2 * xs[i] + xs[i + m]
    tau = _tau(m, tau0, d)
    return jnp.sqrt(jnp.sum(d**2) / (2 * tau**2 * (n - 2)))


_AT_M = {
    "adev": _adev_m,
    "oadev": _oadev_m,
    "mdev": _mdev_m,
    "hdev": _hdev_m,
    "ohdev": _ohdev_m,
    "totdev": _totdev_m,
}
