r"""Allan-family deviations in JAX (NIST SP 1065 definitions).

Inputs are *rate* ("frequency") samples $y_k$ at interval $\tau_0$; the phase is
$x_k = \tau_0\sum_{j<k} y_j$ ($x_0 = 0$). The averaging factor `m` is a static integer
($\tau = m\tau_0$). Checked against the NBS14 data set (PHYSICS.md §12).

IEEE 952 noise terms on an Allan-deviation plot: quantisation $\sqrt3 Q/\tau$, angle random
walk $N/\sqrt\tau$, bias instability flat at $0.6643B$, rate random walk $K\sqrt{\tau/3}$,
rate ramp $R\tau/\sqrt2$.
"""

from __future__ import annotations

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

    **Arguments:**

    - `ms`: averaging factors (static ints); default: octaves 1, 2, 4, … up to N/4.
    - `kind`: one of `adev`, `oadev`, `mdev`, `hdev`, `ohdev`, `totdev`.

    **Returns:** `(taus [s], deviations [rate unit])` as arrays.
    """
    if kind not in _KINDS:
        raise ValueError(f"kind must be one of {list(_KINDS)}; got {kind!r}")
    n = np.shape(rate)[0]
    if ms is None:
        ms = [2**k for k in range(int(np.log2(max(n // 4, 1))) + 1)]
    fn = _KINDS[kind]
    devs = jnp.stack([fn(rate, int(m), dt) for m in ms])
    return jnp.asarray(ms, dtype=float) * dt, devs
