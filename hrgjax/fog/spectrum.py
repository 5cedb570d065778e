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
90 %, 0.23 %, 0.02 %.

**Rest at the edges.** Whether a window vibrates at all (`min_amp_g`) is decided at an edge
peak from the lobe's power *with* the DC bin: for a tone that is the window's whole AC power
(the Hann periodogram's sum over all bins, Parseval), which the lobe cut no longer distorts;
for broadband noise it is the lobe's share, as mid-band, so rest means the same there. The
lobe without DC read 0.334–0.577 A for a 0.5-Hz tone in 1-s windows (phases 0–π), so 0.13 g
read rest; with DC it reads 0.414–0.578 A, and 0.13 g reads NaN. What the window's mean
removal takes (up to 59 % of A at 0.5 Hz in 1-s windows, more below) no spectral measure
recovers: a weaker or slower tone can still read rest.

**Shortest window.** A window of m samples has bins 0 … m//2; one whose peak may be
measured needs a bin above the 2 at DC and below the 1 at Nyquist, so m ≥ 10
([`MIN_WINDOW`][hrgjax.fog.spectrum.MIN_WINDOW]; 8 or 9 samples measured nothing, 10 or 11
only bin 3). Shorter windows are refused."""

from __future__ import annotations

import os
import sys
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import (
    check_finite,
    concrete_value,
    describe,
    is_finite_real,
    numeric_problem,
    whole_number,
)
from .._compiled import fused
from ..units import G0


def psd(x, fs: float, nperseg: int | None = None):
    """One-sided power spectral density of `x` (..., N) sampled at `fs` [Hz] (module
    docstring). `nperseg` defaults to the largest power of two ≤ N/4, at least 16 and at most
    N (scipy's default is 256, or N when shorter).
    **Returns** `(f (nperseg//2 + 1,) [Hz], P (..., nperseg//2 + 1) [unit²/Hz])`."""
    x = check_finite("x", x)
    n = x.shape[-1] if x.ndim else 0
    if not (is_finite_real(fs) and fs > 0):
        kind = TypeError if numeric_problem(fs) is not None else ValueError
        raise kind(f"fs must be a finite number > 0 Hz; got {describe(fs)}")
    if n < 2:
        raise ValueError(f"x must have at least 2 samples along its last axis; got {n}")
    return _psd(x, fs, nperseg=_segment(n, nperseg))


def _segment(n: int, nperseg) -> int:
    """`psd`'s segment length for `n` samples: `nperseg` checked, or its default."""
    if nperseg is None:
        nperseg = min(n, max(16, 1 << int(max(n // 4, 1)).bit_length() - 1))
    nperseg = whole_number("nperseg", nperseg, f"a whole number of samples in [2, {n}]")
    if not 2 <= nperseg <= n:
        raise ValueError(f"nperseg must be in [2, {n}] samples; got {nperseg}")
    return nperseg


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


MIN_WINDOW = 2 * (EDGE_BINS[0] + EDGE_BINS[1] + 2)
"""Fewest samples (10) in a window, or `tone`'s segment, that leave a bin where a tone is
measurable: of the bins 1 … m//2, `EDGE_BINS` (2 at DC, 1 at Nyquist) are not, so
m//2 ≥ 2 + 1 + 2 (module docstring, **Shortest window**)."""

DIRECTIONAL_MIN = 0.9
"""Least λ₁/trace of a window's 3×3 cross-spectral matrix (over the tone's lobe) for
[`vibration_direction`][hrgjax.fog.spectrum.vibration_direction] to give it a direction:
a linear vibration gives 1 (an elliptic one λ₁/(λ₁+λ₂)). In 2-s windows at 100 Hz,
isotropic white noise gave a mean of 0.64 and ≥ 0.9 in 0.46 % of 20 000 windows; a tone
of amplitude A along one axis in noise of σ per axis fell below 0.9 in 3 % of windows at
A = 2σ and in none at 3σ (`benchmarks/fog_rest_and_direction.py`)."""


class EdgeToneWarning(UserWarning):
    """A tone peaks within [`EDGE_BINS`][hrgjax.fog.spectrum.EDGE_BINS] of DC or of
    Nyquist, where its frequency and amplitude are not measurable (returned as NaN)."""


def _warn_edge(what: str, n: int, total: int, fs: float, m: int, window: str) -> None:
    top, df = fs / 2, fs / m
    low, high = EDGE_BINS
    warnings.warn(
        f"{what}: {n} of {total} tone(s) peak within {low} bins (resolution "
        f"{window} = {df:.4g} Hz) of DC or {high} of Nyquist ({top:g} Hz), where "
        f"frequency and amplitude are not measurable: NaN. Measurable from about "
        f"{(low + 0.5) * df:.4g} to {(m // 2 - high - 0.5) * df:.4g} Hz; use a longer window "
        "or a higher fs",
        EdgeToneWarning,
        stacklevel=_user_level(),
    )


def _user_level() -> int:
    """`stacklevel` for a `warnings.warn` in the caller that points at the first frame
    outside hrgjax — the user's call, however deep the library's own calls go (an
    `EdgeToneWarning` from `compensate` pointed at compensation.py)."""
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__))) + os.sep
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(root):
        frame, level = frame.f_back, level + 1
    return level


def tone(x, fs: float, nperseg: int | None = None, lobe: int = 3):
    """Frequency [Hz] and amplitude (units of `x`) of the strongest tone in `x` (N,): the PSD
    peak (DC excluded), the power within ±`lobe` bins of it (the Hann main lobe is ±2).
    Both are NaN, with an [`EdgeToneWarning`][hrgjax.fog.spectrum.EdgeToneWarning], for a
    peak within 2 bins of DC or 1 of Nyquist (module docstring, **Edges**); a segment
    (`nperseg`, `psd`'s default when None) of fewer than
    [`MIN_WINDOW`][hrgjax.fog.spectrum.MIN_WINDOW] samples is refused."""
    if jnp.ndim(x) != 1:
        raise ValueError(f"x must have shape (N,); got {jnp.shape(x)}")
    m = _segment(jnp.shape(x)[0], nperseg)
    if m < MIN_WINDOW:
        raise ValueError(
            f"nperseg must be >= {MIN_WINDOW} samples (a shorter segment leaves no bin between "
            f"the {EDGE_BINS[0]} at DC and the {EDGE_BINS[1]} at Nyquist where a tone is "
            f"measurable); got {m}"
        )
    f, p = psd(x, fs, m)
    freq, amp, edge, _ = _peak(f, p, _lobe(lobe))
    e = concrete_value(edge)
    if e is not None and bool(e):
        _warn_edge("tone", 1, 1, fs, m, "fs/nperseg")
    nan = jnp.asarray(jnp.nan, freq.dtype)
    return jnp.where(edge, nan, freq), jnp.where(edge, nan, amp)


def _lobe(lobe) -> int:
    if isinstance(lobe, bool) or not float(lobe).is_integer() or int(lobe) < 0:
        raise ValueError(f"lobe must be an integer number of bins >= 0; got {lobe!r}")
    return int(lobe)


def _peak(f, p, lobe):
    """Power-weighted frequency and amplitude √(2·power) of the main lobe around the PSD
    peak (DC excluded), whether the peak lies within `EDGE_BINS` of DC or Nyquist, and the
    lobe's amplitude with the DC bin counted (the rest test's at an edge)."""
    low, high = EDGE_BINS
    df = f[1] - f[0]
    k = jnp.argmax(p[1:]) + 1
    bins = jnp.arange(p.shape[-1])
    lobe_dc = jnp.abs(bins - k) <= lobe
    pw = jnp.where(lobe_dc & (bins > 0), p, 0.0)
    edge = (k <= low) | (k >= p.shape[-1] - 1 - high)
    reach = jnp.sqrt(2.0 * jnp.sum(jnp.where(lobe_dc, p, 0.0)) * df)
    return jnp.sum(pw * f) / jnp.sum(pw), jnp.sqrt(2.0 * jnp.sum(pw) * df), edge, reach


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
    **Edges**); whether it vibrates is decided there from the lobe's power with its DC bin
    (**Rest at the edges**). A window of fewer than
    [`MIN_WINDOW`][hrgjax.fog.spectrum.MIN_WINDOW] = 10 samples is refused, and so is a
    record in g (median |f| within 0.5 … 2 instead of ≈ 9.8 m/s²): eagerly, and at run time
    inside `jit` or `vmap` (`eqx.error_if`).
    **Returns** (K, 2), K = N // (window_s·fs)."""
    a, m = _windows(accel, fs, window_s)
    _check_min_amp(min_amp_g)
    if axis is not None:
        axis = jnp.asarray(axis, a.dtype)
        if axis.shape != (3,):
            raise ValueError(f"axis must have shape (3,); got {axis.shape}")
        u = concrete_value(axis)  # NaN or zero: every window read (0, 0), at rest
        if u is not None and not (np.isfinite(u).all() and np.linalg.norm(u) > 0):
            raise ValueError(
                f"axis must be a non-zero finite 3-vector (body frame); got {u.tolist()}"
            )
    out = _features(a, axis, fs, min_amp_g, m=m, lobe=_lobe(lobe))
    v = concrete_value(out)
    if v is not None and np.isnan(v[:, 0]).any():
        n = int(np.isnan(v[:, 0]).sum())
        _warn_edge("vibration_features", n, len(v), fs, m, "1/window_s")
    return out


def vibration_direction(accel, fs: float, window_s: float = 1.0, min_amp_g: float = 0.05,
                        lobe: int = 3):  # fmt: skip
    """Body-frame direction (K, 3) of the strongest tone in each window of `accel` (N, 3)
    [m/s²] (windows as [`vibration_features`][hrgjax.fog.spectrum.vibration_features]'): the
    principal axis of the three axes' cross-spectral matrix summed over ±`lobe` bins around
    the peak of their summed PSD (DC excluded), a unit vector with its largest component
    positive (at an edge peak the lobe takes the DC bin too, as the features' rest test).
    It is zero in a window whose tone, all axes together, is below `min_amp_g` [g] (at
    rest), and in one without a direction: the lobe's cross-spectral matrix is not close to
    rank one, λ₁/trace < [`DIRECTIONAL_MIN`][hrgjax.fog.spectrum.DIRECTIONAL_MIN] = 0.9
    (broadband noise, or tones along several axes). A linear vibration along u gives ±u
    whatever the analysis axis, so it tells whether a record vibrates along the direction a
    compensator was trained on. Carries no gradient."""
    a, m = _windows(accel, fs, window_s)
    _check_min_amp(min_amp_g)
    return _directions(a, fs, min_amp_g, m=m, lobe=_lobe(lobe))


def off_axis(accel, fs: float, axis, window_s: float = 1.0, tol_deg: float = 8.0,
             min_amp_g: float = 0.05, lobe: int = 3):  # fmt: skip
    """Windows of `accel` (N, 3) [m/s²] vibrating more than `tol_deg` [°] off `axis` (3,)
    (body frame; −`axis` is the same): those with a
    [`vibration_direction`][hrgjax.fog.spectrum.vibration_direction] (arguments as there)
    at an angle above `tol_deg` from it. A window at rest or without a direction (not
    close to rank one: broadband noise) is not off: the features' own rest and range rules
    decide it. [`compensate`][hrgjax.fog.compensation.compensate] counts off windows out of
    range. **Returns** `(off (K,) bool, direction (K, 3), angle (K,) [°])`, the angle NaN
    where there is no direction. One compiled program; carries no gradient."""
    a, m = _windows(accel, fs, window_s)
    _check_min_amp(min_amp_g)
    u = np.asarray(axis, dtype=float)
    if u.shape != (3,) or not np.isfinite(u).all() or not np.linalg.norm(u) > 0:
        raise ValueError(f"axis must be a non-zero finite 3-vector (body frame); got {axis!r}")
    tol = float(tol_deg)
    if not 0.0 <= tol <= 90.0:
        raise ValueError(f"tol_deg must be an angle in [0, 90] °; got {tol_deg!r}")
    cos_min = jnp.asarray(np.cos(np.radians(tol)), a.dtype)
    return _off_axis(a, jnp.asarray(u, a.dtype), cos_min, fs, min_amp_g, m=m, lobe=_lobe(lobe))


def _median_within(r, low, high):
    """Whether the median of the N values `r` (NumPy's: the middle one, or the mean of the
    two middle ones for even N) lies in the open interval (`low`, `high`): traced, in two
    counting passes, no sort (`jnp.median` sorts: 10× the features' own cost at 2¹⁶
    samples). With c = #(r ≤ low) the median is > `low` where 2c < N, not where 2c > N;
    where 2c = N (even N only) the two middle values are the largest r ≤ `low` and the
    smallest r > `low`, and it is where their sum is > 2·`low` (two more passes, taken only
    then, under `jit`). Likewise at `high` with #(r < high). The same decision as NumPy's
    median, odd or even N."""
    n = r.shape[0]

    def side(c, on, bound, sign):  # median beyond `bound` on the side where c < N/2
        if n % 2:
            return 2 * c < n

        def straddle():  # N/2 values `on` the near side: the two middle ones' sum
            pair = jnp.max(jnp.where(on, r, -jnp.inf)) + jnp.min(jnp.where(on, jnp.inf, r))
            return sign * (pair - 2.0 * bound) > 0

        return (2 * c < n) | jax.lax.cond(2 * c == n, straddle, lambda: jnp.asarray(False))

    c_low, c_high = jnp.sum(r <= low), jnp.sum(r >= high)
    return side(c_low, r <= low, low, 1.0) & side(c_high, r < high, high, -1.0)


def _check_min_amp(min_amp_g) -> None:
    """Refuse a `min_amp_g` that is not a number, or a concrete one not finite and >= 0 [g]:
    NaN read every window at rest, a negative one read noise peaks as vibration."""
    if numeric_problem(min_amp_g) is not None or np.ndim(min_amp_g) != 0:
        raise TypeError(f"min_amp_g must be a number >= 0 [g]; got {describe(min_amp_g)}")
    v = concrete_value(min_amp_g)
    if v is not None and not (np.isfinite(v) and v >= 0):
        raise ValueError(f"min_amp_g must be a finite number >= 0 [g]; got {float(v):g}")


def _windows(accel, fs, window_s):
    """`accel` checked (finite, (N, 3), m/s² not g) and the window length `m` [samples]."""
    a = check_finite("accel", accel)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"accel must have shape (N, 3) [m/s²]; got {a.shape}")
    for name, x, unit in (("fs", fs, "Hz"), ("window_s", window_s, "s")):
        if not (is_finite_real(x) and x > 0):
            kind = TypeError if numeric_problem(x) is not None else ValueError
            raise kind(f"{name} must be a finite number > 0 {unit}; got {describe(x)}")
    v = concrete_value(a)
    if v is None:  # traced (jit, vmap): the same rule at run time, the value left out
        bad = _median_within(jnp.linalg.norm(a, axis=1), 0.5, 2.0)
        a = eqx.error_if(a, bad, "accel must be specific force in m/s² (|f| ≈ 9.8 at rest); "
                         f"its median |f| is within 0.5 … 2: in g? multiply by {G0}")  # fmt: skip
    norm = float(np.median(np.linalg.norm(v, axis=1))) if v is not None else np.nan
    if 0.5 < norm < 2.0:
        raise ValueError(
            f"accel must be specific force in m/s² (|f| ≈ 9.8 at rest); its median |f| is "
            f"{norm:.3g}: in g? multiply by {G0}"
        )
    m = int(round(window_s * fs))
    if m < MIN_WINDOW:
        raise ValueError(
            f"window_s·fs must be >= {MIN_WINDOW} samples (a shorter window leaves no bin between "
            f"the {EDGE_BINS[0]} at DC and the {EDGE_BINS[1]} at Nyquist where a tone is "
            f"measurable); got {m} ({window_s:g} s at {fs:g} Hz)"
        )
    if a.shape[0] < m:
        raise ValueError(
            f"accel must hold at least one window of window_s·fs = {m} samples; got {a.shape[0]}"
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
    f, amp, edge, reach = jax.vmap(lambda w: _peak(*_psd(w, fs, nperseg=m), lobe))(x)
    # at an edge the lobe without DC understates the tone (by up to 86 % at bin 1): rest is
    # decided there from the lobe with its DC bin, a tone's whole AC power (module docstring)
    on = jnp.where(edge, reach, amp) / G0 >= min_amp_g
    nan = jnp.asarray(jnp.nan, amp.dtype)
    f, amp = (jnp.where(on, jnp.where(edge, nan, v), 0.0) for v in (f, amp / G0))
    return jnp.stack([f, amp], axis=-1)


@fused(static_argnames=("m", "lobe"))
def _directions(a, fs, min_amp_g, *, m, lobe):
    """`vibration_direction` past its checks, as one compiled program."""
    k = a.shape[0] // m
    x = jax.lax.stop_gradient(a[: k * m]).reshape(k, m, 3)
    x = x - jnp.mean(x, axis=1, keepdims=True)
    w = 0.5 - 0.5 * jnp.cos(2.0 * jnp.pi * jnp.arange(m, dtype=a.dtype) / m)  # periodic Hann
    spec = jnp.fft.rfft(x * w.reshape(1, m, 1), axis=1)  # (K, nf, 3)
    nf = spec.shape[1]
    power = jnp.sum(jnp.abs(spec) ** 2, axis=-1)  # (K, nf)
    peak = jnp.argmax(power[:, 1:], axis=-1) + 1
    edge = (peak <= EDGE_BINS[0]) | (peak >= nf - 1 - EDGE_BINS[1])
    bins = jnp.arange(nf)
    # the lobe around the peak, its DC bin too at an edge (as `_features`' rest test), each
    # bin weighted as the one-sided PSD counts it (DC and an even m's Nyquist bin once)
    near = (jnp.abs(bins[None, :] - peak[:, None]) <= lobe) & ((bins[None, :] > 0) | edge[:, None])
    once = (bins == 0) | ((bins == nf - 1) & (m % 2 == 0))
    wt = jnp.where(near, jnp.where(once, 0.5, 1.0), 0.0).astype(a.dtype)
    cross = jnp.einsum("kn,kni,knj->kij", wt.astype(spec.dtype), spec, jnp.conj(spec)).real
    # amplitude √(2 Σ P Δf) with the one-sided PSD P = 2|X|²/(fs Σw²) and Δf = fs/m
    trace = jnp.trace(cross, axis1=-2, axis2=-1)
    amp = jnp.sqrt(4.0 * trace / (m * jnp.sum(w**2))) / G0
    lam, vecs = jnp.linalg.eigh(cross)  # ascending: the last is the principal axis
    vec = vecs[..., -1]
    big = jnp.take_along_axis(vec, jnp.argmax(jnp.abs(vec), -1)[:, None], axis=-1)
    vec = vec * jnp.where(big < 0, -1.0, 1.0)
    # one direction only when the lobe's power is close to rank one (a tone, not noise)
    directional = lam[:, -1] >= DIRECTIONAL_MIN * trace
    return jnp.where(((amp >= min_amp_g) & directional)[:, None], vec, 0.0)


@fused(static_argnames=("m", "lobe"))
def _off_axis(a, axis, cos_min, fs, min_amp_g, *, m, lobe):
    """`off_axis` past its checks, as one compiled program."""
    d = _directions(a, fs, min_amp_g, m=m, lobe=lobe)
    cos = jnp.abs(d @ (axis / jnp.linalg.norm(axis)))
    has = jnp.any(d != 0, axis=-1)
    angle = jnp.where(has, jnp.degrees(jnp.arccos(jnp.minimum(cos, 1.0))), jnp.nan)
    return has & (cos < cos_min), d, angle
