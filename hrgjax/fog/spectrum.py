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
power-weighted mean frequency of the lobe.

**Edges.** A peak at bin 1 or 2 (resolution fs/`nperseg`, 1/`window_s` for the features)
or at the Nyquist bin or the one below it is not measurable: the Hann main lobe (±2 bins)
reaches DC, which the mean removal empties and the lobe sum leaves out, or crosses Nyquist
into the tone's mirror image at fs − f. [`tone`][hrgjax.fog.spectrum.tone] and
[`vibration_features`][hrgjax.fog.spectrum.vibration_features] return NaN there and warn
([`EdgeToneWarning`][hrgjax.fog.spectrum.EdgeToneWarning]). A tone is measurable from about
bin 2.5 to 1.5 bins below Nyquist: 2.5/`window_s` to fs/2 − 1.5/`window_s` [Hz]. Measured
(`benchmarks/fog_spectrum_edges.py`: one periodic-Hann segment of 100 samples, tones
stepped by 0.02 bin, 13 phases each), the amplitude error with the peak at bin 1, 2, 3, 4 is
up to 86 %, 8.3 %, 1.0 %, 0.12 %; at the Nyquist bin and one, two, three below it up to 91 %,
90 %, 0.23 %, 0.02 %."""

from __future__ import annotations

import warnings

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


EDGE_BINS = (2, 1)
"""A PSD peak at most this many bins above DC, or below the Nyquist bin, gives NaN (module
docstring, **Edges**): (DC side, Nyquist side)."""


class EdgeToneWarning(UserWarning):
    """A tone peaks within [`EDGE_BINS`][hrgjax.fog.spectrum.EDGE_BINS] of DC or of
    Nyquist, where its frequency and amplitude are not measurable (returned as NaN)."""


def _warn_edge(what: str, n: int, total: int, fs: float, df: float, window: str) -> None:
    top = fs / 2
    warnings.warn(
        f"{what}: {n} of {total} tone(s) peak within {EDGE_BINS[0]} bins (resolution "
        f"{window} = {df:.4g} Hz) of DC or {EDGE_BINS[1]} of Nyquist ({top:g} Hz), where "
        f"frequency and amplitude are not measurable: NaN. Measurable from about "
        f"{2.5 * df:.4g} to {top - 1.5 * df:.4g} Hz; use a longer window or a higher fs",
        EdgeToneWarning,
        stacklevel=3,
    )


def tone(x, fs: float, nperseg: int | None = None, lobe: int = 3):
    """Frequency [Hz] and amplitude (units of `x`) of the strongest tone in `x` (N,): the PSD
    peak (DC excluded), the power within ±`lobe` bins of it (the Hann main lobe is ±2).
    Both are NaN, with an [`EdgeToneWarning`][hrgjax.fog.spectrum.EdgeToneWarning], for a
    peak within 2 bins of DC or 1 of Nyquist (module docstring, **Edges**)."""
    if jnp.ndim(x) != 1:
        raise ValueError(f"x must have shape (N,); got {jnp.shape(x)}")
    f, p = psd(x, fs, nperseg)
    freq, amp, edge = _peak(f, p, _lobe(lobe))
    e = concrete_value(edge)
    if e is not None and bool(e):
        _warn_edge("tone", 1, 1, fs, float(f[1] - f[0]), "fs/nperseg")
    nan = jnp.asarray(jnp.nan, freq.dtype)
    return jnp.where(edge, nan, freq), jnp.where(edge, nan, amp)


def _lobe(lobe) -> int:
    if isinstance(lobe, bool) or not float(lobe).is_integer() or int(lobe) < 0:
        raise ValueError(f"lobe must be an integer number of bins >= 0; got {lobe!r}")
    return int(lobe)


def _peak(f, p, lobe):
    """Power-weighted frequency and amplitude √(2·power) of the main lobe around the PSD
    peak (DC excluded), and whether the peak lies within `EDGE_BINS` of DC or Nyquist."""
    low, high = EDGE_BINS
    df = f[1] - f[0]
    k = jnp.argmax(p[1:]) + 1
    bins = jnp.arange(p.shape[-1])
    near = (jnp.abs(bins - k) <= lobe) & (bins > 0)
    pw = jnp.where(near, p, 0.0)
    edge = (k <= low) | (k >= p.shape[-1] - 1 - high)
    return jnp.sum(pw * f) / jnp.sum(pw), jnp.sqrt(2.0 * jnp.sum(pw) * df), edge


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
    noise peak means nothing. A vibrating window whose peak lies within 2 bins of DC or 1 of
    Nyquist (below about 2.5/`window_s` Hz or above fs/2 − 1.5/`window_s`) is not measurable: its
    features are (NaN, NaN), which
    [`compensate`][hrgjax.fog.compensation.compensate] counts out of range, with one
    [`EdgeToneWarning`][hrgjax.fog.spectrum.EdgeToneWarning] per call (module docstring,
    **Edges**). **Returns** (K, 2), K = N // (window_s·fs)."""
    a, m = _windows(accel, fs, window_s)
    if axis is not None:
        axis = jnp.asarray(axis, a.dtype)
        if axis.shape != (3,):
            raise ValueError(f"axis must have shape (3,); got {axis.shape}")
    out = _features(a, axis, fs, min_amp_g, m=m, lobe=_lobe(lobe))
    v = concrete_value(out)
    if v is not None and np.isnan(v[:, 0]).any():
        n = int(np.isnan(v[:, 0]).sum())
        _warn_edge("vibration_features", n, len(v), fs, fs / m, "1/window_s")
    return out


def vibration_direction(accel, fs: float, window_s: float = 1.0, min_amp_g: float = 0.05,
                        lobe: int = 3):  # fmt: skip
    """Body-frame direction (K, 3) of the strongest tone in each window of `accel` (N, 3)
    [m/s²] (windows as [`vibration_features`][hrgjax.fog.spectrum.vibration_features]'): the
    principal axis of the three axes' cross-spectral matrix summed over ±`lobe` bins around
    the peak of their summed PSD (DC excluded), a unit vector with its largest component
    positive. It is zero in a window whose tone, all axes together, is below `min_amp_g`
    [g] (at rest). A linear vibration along u gives ±u whatever the analysis axis, so it
    tells whether a record vibrates along the direction a compensator was trained on.
    Carries no gradient."""
    a, m = _windows(accel, fs, window_s)
    return _directions(a, fs, min_amp_g, m=m, lobe=_lobe(lobe))


def _windows(accel, fs, window_s):
    """`accel` checked (finite, (N, 3), m/s² not g) and the window length `m` [samples]."""
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
    if m < 8 or a.shape[0] // m < 1:
        raise ValueError(
            f"window_s·fs must be >= 8 samples and the record at least one window; got "
            f"window {m} samples, record {a.shape[0]}"
        )
    return a, m


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
    f, amp, edge = jax.vmap(lambda w: _peak(*_psd(w, fs, nperseg=m), lobe))(x)
    amp = amp / G0
    on = amp >= min_amp_g
    nan = jnp.asarray(jnp.nan, amp.dtype)
    f, amp = (jnp.where(on, jnp.where(edge, nan, v), 0.0) for v in (f, amp))
    return jnp.stack([f, amp], axis=-1)


@fused(static_argnames=("m", "lobe"))
def _directions(a, fs, min_amp_g, *, m, lobe):
    """`vibration_direction` past its checks, as one compiled program."""
    k = a.shape[0] // m
    x = jax.lax.stop_gradient(a[: k * m]).reshape(k, m, 3)
    x = x - jnp.mean(x, axis=1, keepdims=True)
    w = 0.5 - 0.5 * jnp.cos(2.0 * jnp.pi * jnp.arange(m, dtype=a.dtype) / m)  # periodic Hann
    spec = jnp.fft.rfft(x * w.reshape(1, m, 1), axis=1)  # (K, nf, 3)
    power = jnp.sum(jnp.abs(spec) ** 2, axis=-1)  # (K, nf)
    peak = jnp.argmax(power[:, 1:], axis=-1) + 1
    bins = jnp.arange(power.shape[-1])
    near = (jnp.abs(bins[None, :] - peak[:, None]) <= lobe) & (bins[None, :] > 0)
    cross = jnp.einsum(
        "kn,kni,knj->kij", near.astype(spec.dtype), spec, jnp.conj(spec)
    ).real  # (K, 3, 3)
    # amplitude √(2 Σ P Δf) with the one-sided PSD P = 2|X|²/(fs Σw²) and Δf = fs/m
    amp = jnp.sqrt(4.0 * jnp.trace(cross, axis1=-2, axis2=-1) / (m * jnp.sum(w**2))) / G0
    vec = jnp.linalg.eigh(cross)[1][..., -1]  # eigenvalues ascending: the principal axis
    big = jnp.take_along_axis(vec, jnp.argmax(jnp.abs(vec), -1)[:, None], axis=-1)
    vec = vec * jnp.where(big < 0, -1.0, 1.0)
    return jnp.where((amp >= min_amp_g)[:, None], vec, 0.0)
