r"""Vibration features from an accelerometer record (seed 003, step 3): the power spectral
density by Welch's method, the vibration frequency at its peak and the amplitude from the
peak's power.

Welch (1967): the record is cut into segments of `nperseg` samples overlapping by
`nperseg // 2` (half; `scipy.signal.welch`'s default, also for odd `nperseg`), each is
detrended (mean removed) and Hann-windowed, and the one-sided periodograms are averaged:

$$P(f_k) = \frac{2\,|X_k|^2}{f_s \sum_n w_n^2} \quad [\text{unit}^2/\text{Hz}]$$

(the DC and Nyquist bins not doubled). A tone $A\sin(2\pi f t)$ puts its power $A^2/2$ into
the few bins around $f$ (the window's main lobe), so
[`tone`][hrgjax.fog.spectrum.tone] returns $A = \sqrt{2\sum_\text{lobe} P\,\Delta f}$ and the
power-weighted mean frequency of the lobe."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_finite, concrete_value
from .._compiled import fused
from ..units import G0


def psd(x, fs: float, nperseg: int | None = None):
    """One-sided power spectral density of `x` (..., N) sampled at `fs` [Hz] (module
    docstring). `nperseg` defaults to the largest power of two ≤ N/4, at least 16 and at most
    N (scipy's default is 256, or N when shorter).
    **Returns** `(f (nperseg//2 + 1,) [Hz], P (..., nperseg//2 + 1) [unit²/Hz])`."""
    x = check_finite("x", x)
    n = x.shape[-1]
    if not fs > 0:
        raise ValueError(f"fs must be > 0 Hz; got {fs}")
    if n < 2:
        raise ValueError(f"x must have at least 2 samples along its last axis; got {n}")
    if nperseg is None:
        nperseg = min(n, max(16, 1 << int(max(n // 4, 1)).bit_length() - 1))
    nperseg = int(nperseg)
    if not 2 <= nperseg <= n:
        raise ValueError(f"nperseg must be in [2, {n}] samples; got {nperseg}")
    return _psd(x, fs, nperseg=nperseg)


@fused(static_argnames="nperseg")
def _psd(x, fs, *, nperseg):
    """`psd` past its checks, as one compiled program per length and segment."""
    n = x.shape[-1]
    step = nperseg - nperseg // 2  # overlap nperseg // 2, scipy.signal.welch's default
    starts = jnp.arange(0, n - nperseg + 1, step)
    idx = starts[:, None] + jnp.arange(nperseg)[None, :]
    seg = x[..., idx]  # (..., S, nperseg)
    seg = seg - jnp.mean(seg, axis=-1, keepdims=True)
    k = jnp.arange(nperseg, dtype=x.dtype)
    w = 0.5 - 0.5 * jnp.cos(2.0 * jnp.pi * k / nperseg)  # periodic Hann
    w_b = w.reshape((1,) * (seg.ndim - 1) + (-1,))
    spec = jnp.abs(jnp.fft.rfft(seg * w_b, axis=-1)) ** 2 / (fs * jnp.sum(w**2))
    nf = nperseg // 2 + 1
    double = jnp.ones(nf, x.dtype).at[1:].set(2.0)
    if nperseg % 2 == 0:
        double = double.at[-1].set(1.0)
    p = jnp.mean(spec, axis=-2) * double.reshape((1,) * (spec.ndim - 2) + (-1,))
    return jnp.fft.rfftfreq(nperseg, 1.0 / fs).astype(x.dtype), p


def tone(x, fs: float, nperseg: int | None = None, lobe: int = 3):
    """Frequency [Hz] and amplitude (units of `x`) of the strongest tone in `x` (N,): the PSD
    peak (DC excluded), the power within ±`lobe` bins of it (the Hann main lobe is ±2)."""
    if jnp.ndim(x) != 1:
        raise ValueError(f"x must have shape (N,); got {jnp.shape(x)}")
    return _peak(*psd(x, fs, nperseg), _lobe(lobe))


def _lobe(lobe) -> int:
    if isinstance(lobe, bool) or not float(lobe).is_integer() or int(lobe) < 0:
        raise ValueError(f"lobe must be an integer number of bins >= 0; got {lobe!r}")
    return int(lobe)


def _peak(f, p, lobe):
    """Power-weighted frequency and amplitude √(2·power) of the main lobe around the PSD
    peak (DC excluded)."""
    df = f[1] - f[0]
    k = jnp.argmax(p[1:]) + 1
    bins = jnp.arange(p.shape[-1])
    near = (jnp.abs(bins - k) <= lobe) & (bins > 0)
    pw = jnp.where(near, p, 0.0)
    return jnp.sum(pw * f) / jnp.sum(pw), jnp.sqrt(2.0 * jnp.sum(pw) * df)


def vibration_features(
    accel, fs: float, window_s: float = 1.0, axis=None, min_amp_g: float = 0.05, lobe: int = 3
):
    """The patent's vibration features, window by window: frequency [Hz] and amplitude [g] of
    the tone in the misalignment-compensated specific force `accel` (N, 3) [m/s²] along the
    vibration direction, from each window's PSD ([`tone`][hrgjax.fog.spectrum.tone] on one
    Hann segment of `window_s`, resolution 1/`window_s` Hz).

    `axis` (3,): the direction to analyse; by default the body axis with the largest AC
    power over the record (the patent's "sensitive vibration direction"). A window whose
    amplitude is below `min_amp_g` is at rest: its features are (0, 0) — the frequency of a
    noise peak means nothing. **Returns** (K, 2), K = N // (window_s·fs)."""
    a = check_finite("accel", accel)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"accel must have shape (N, 3) [m/s²]; got {a.shape}")
    if not fs > 0:
        raise ValueError(f"fs must be > 0 Hz; got {fs}")
    v = concrete_value(a)
    norm = float(np.median(np.linalg.norm(v, axis=1))) if v is not None else np.nan
    if 0.5 < norm < 2.0:
        raise ValueError(
            f"accel must be specific force in m/s² (|f| ≈ 9.8 at rest); its median |f| is "
            f"{norm:.3g}: in g? multiply by {G0}"
        )
    m = int(round(window_s * fs))
    k = a.shape[0] // m
    if m < 8 or k < 1:
        raise ValueError(
            f"window_s·fs must be >= 8 samples and the record at least one window; got "
            f"window {m} samples, record {a.shape[0]}"
        )
    if axis is not None:
        axis = jnp.asarray(axis, a.dtype)
        if axis.shape != (3,):
            raise ValueError(f"axis must have shape (3,); got {axis.shape}")
    return _features(a, axis, fs, min_amp_g, m=m, lobe=_lobe(lobe))


@fused(static_argnames=("m", "lobe"))
def _features(a, axis, fs, min_amp_g, *, m, lobe):
    """`vibration_features` past its checks, as one compiled program (windows of `m`
    samples, each one Hann segment)."""
    k = a.shape[0] // m
    if axis is None:
        var = jnp.var(a, axis=0)
        u = jnp.zeros(3, a.dtype).at[jnp.argmax(var)].set(1.0)
    else:
        u = axis / jnp.linalg.norm(axis)
    x = (a[: k * m] @ u).reshape(k, m)
    f, amp = jax.vmap(lambda w: _peak(*_psd(w, fs, nperseg=m), lobe))(x)
    amp = amp / G0
    on = amp >= min_amp_g
    return jnp.stack([jnp.where(on, f, 0.0), jnp.where(on, amp, 0.0)], axis=-1)
