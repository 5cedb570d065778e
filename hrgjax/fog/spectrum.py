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
only bin 3). Shorter windows are refused.

**Units: m/s², told by gravity.** The features take specific force in m/s². Whether a record
is in m/s² or in g is decided from |mean f| over the whole record, not from |f| sample by
sample: zero-mean vibration averages out of the mean whatever its amplitude, so a
**DC-coupled** accelerometer's mean is gravity plus its bias, ≈ 9.8 in m/s² (≥ 6.8 with a
0.3-g bias) and ≈ 1 in g (≤ 1.3). The split is their geometric middle,
[`GRAVITY_SPLIT`][hrgjax.fog.spectrum.GRAVITY_SPLIT] = √9.80665 ≈ 3.13: a mean from it up to
20 g (`hrgjax.plausible.RANGES["specific_force_g"]`; beyond: mg) is m/s², one from
[`NO_GRAVITY`][hrgjax.fog.spectrum.NO_GRAVITY] = 0.3 up to it is 1 g written in g, refused
with the factor. (The median |f| decided before: a 3-g vibration in g, gravity on another
axis, has a median |f| of 2.03 and passed as m/s², reading 0.306 g.) An **AC-coupled**
accelerometer (or a record whose mean was removed) carries no gravity, |mean f| < 0.3
in either unit, and nothing in it tells m/s² from g: a tone's amplitude is 0.1–10 g on a
shaker, 1–100 in m/s², 0.1–10 in g. Such a record is refused unless the call says
`ac_coupled=True`, which takes it as m/s² (a record in g: multiply by 9.80665 first). The
rule holds eagerly and, traced (`jit`, `vmap`), at run time (`eqx.branched_error_if`)."""

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
    check_flag,
    concrete_value,
    describe,
    is_finite_real,
    numeric_problem,
    whole_number,
)
from .._compiled import fused
from ..plausible import RANGES
from ..units import G0


def psd(x, fs: float, nperseg: int | None = None):
    """One-sided power spectral density of `x` (..., N) sampled at `fs` [Hz] (module
    docstring): time runs along the **last** axis. `nperseg` defaults to the largest power of
    two ≤ N/4, at least 16 and at most N (scipy's default is 256, or N when shorter). Integer
    or bool samples (ADC counts) are taken as float64 (`x` itself is not changed); `fs`
    only scales the result, so it may be traced (`jit`, `vmap`, `grad` over it; checked at
    run time).
    **Returns** `(f (nperseg//2 + 1,) [Hz], P (..., nperseg//2 + 1) [unit²/Hz])`.

    **Raises:** `ValueError` for fewer than 2 samples, an `nperseg` outside [2, N], an `fs`
    not finite and > 0, or a (…, N) array with N < 16 along its last axis and a longer
    axis before it — an (N, 3) record of three channels, whose time is not the last axis
    (pass `x.T`)."""
    x = _as_float(check_finite("x", x))
    n = x.shape[-1] if x.ndim else 0
    if x.ndim >= 2 and n <= 3 and max(x.shape[:-1]) >= 16:  # an (N, 3) record: axes swapped
        raise ValueError(
            f"x must have time along its last axis (..., N); got shape {x.shape}, {n} samples "
            f"there and {max(x.shape[:-1])} along axis {int(np.argmax(x.shape[:-1]))}: "
            "channels by time, e.g. an (N, 3) record? pass x.T"
        )
    fs = _rate(fs)
    if n < 2:
        raise ValueError(f"x must have at least 2 samples along its last axis; got {n}")
    return _psd(x, fs, nperseg=_segment(n, nperseg))


def _as_float(x):
    """`x` (a JAX array) with integer or bool samples as float64 (a new array): in their own
    dtype the frequency axis and the window were cast to int (f = 0, 0, 1, 1, …)."""
    return x if jnp.issubdtype(x.dtype, jnp.inexact) else x.astype(jnp.float64)


def _rate(fs):
    """`fs` [Hz] checked: a concrete finite number > 0 (one line naming it otherwise), or a
    traced 0-d real value (`jit`, `vmap`, `grad`), held to the same rule at run time."""
    if isinstance(fs, jax.core.Tracer) and numeric_problem(fs) is None and jnp.ndim(fs) == 0:
        if concrete_value(fs) is None:
            return eqx.error_if(fs, ~(jnp.isfinite(fs) & (fs > 0)),
                                "fs must be a finite number > 0 Hz")  # fmt: skip
        fs_value = float(concrete_value(fs))
        if np.isfinite(fs_value) and fs_value > 0:
            return fs  # an eager grad's tracer: its value is known and good
        raise ValueError(f"fs must be a finite number > 0 Hz; got {fs_value:g}")
    if not (is_finite_real(fs) and fs > 0):
        kind = TypeError if numeric_problem(fs) is not None else ValueError
        raise kind(f"fs must be a finite number > 0 Hz; got {describe(fs)}")
    return fs


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

GRAVITY_SPLIT = float(np.sqrt(G0))
"""|mean f| [the record's unit] from which a record is in m/s² (gravity ≈ 9.8) rather than
in g (≈ 1): √9.80665 ≈ 3.13, the geometric middle, a factor 3.1 from either (module
docstring, **Units**)."""

NO_GRAVITY = 0.3
"""|mean f| [the record's unit] below which a record carries no gravity (an AC-coupled
accelerometer): 1 g in g with a bias of 0.3 g reads ≥ 0.7, an AC-coupled record ≈ 0 (a
tone's leftover mean over a part cycle: ≤ A/(π f T), 0.016 A for 10 Hz over 2 s). Below it
the unit cannot be told: refused unless `ac_coupled=True` (module docstring, **Units**)."""

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
    e, rate = concrete_value(edge), concrete_value(fs)
    if e is not None and bool(e) and rate is not None:
        _warn_edge("tone", 1, 1, float(rate), m, "fs/nperseg")
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
    accel, fs: float, window_s: float = 1.0, axis=None, min_amp_g: float = 0.05, lobe: int = 3,
    *, ac_coupled: bool = False,
):  # fmt: skip
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
    [`MIN_WINDOW`][hrgjax.fog.spectrum.MIN_WINDOW] = 10 samples is refused. `fs` and
    `window_s` set the window length in samples: they must be concrete (not traced).

    **Units** (module docstring): the record's mean, gravity, tells m/s² from g whatever the
    vibration — |mean f| ≥ √9.80665 ≈ 3.13 (up to 20 g) is m/s²; 0.3 … 3.13 is 1 g written
    in g, refused ("in g? multiply by 9.80665"); below 0.3 the record carries no gravity (an
    AC-coupled accelerometer), and is refused unless `ac_coupled=True`, which takes it as
    m/s² — the unit is then the caller's to get right. Eagerly, and at run time inside `jit`
    or `vmap` (`eqx.branched_error_if`).
    **Returns** (K, 2), K = N // (window_s·fs)."""
    a, m = _windows(accel, fs, window_s, ac_coupled)
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
                        lobe: int = 3, *, ac_coupled: bool = False):  # fmt: skip
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
    compensator was trained on. Carries no gradient. `ac_coupled`: as the features'."""
    a, m = _windows(accel, fs, window_s, ac_coupled)
    _check_min_amp(min_amp_g)
    return _directions(a, fs, min_amp_g, m=m, lobe=_lobe(lobe))


def off_axis(accel, fs: float, axis, window_s: float = 1.0, tol_deg: float = 8.0,
             min_amp_g: float = 0.05, lobe: int = 3, *, ac_coupled: bool = False):  # fmt: skip
    """Windows of `accel` (N, 3) [m/s²] vibrating more than `tol_deg` [°] off `axis` (3,)
    (body frame; −`axis` is the same): those with a
    [`vibration_direction`][hrgjax.fog.spectrum.vibration_direction] (arguments as there)
    at an angle above `tol_deg` from it. A window at rest or without a direction (not
    close to rank one: broadband noise) is not off: the features' own rest and range rules
    decide it. [`compensate`][hrgjax.fog.compensation.compensate] counts off windows out of
    range. **Returns** `(off (K,) bool, direction (K, 3), angle (K,) [°])`, the angle NaN
    where there is no direction. One compiled program; carries no gradient. `ac_coupled`:
    as [`vibration_features`][hrgjax.fog.spectrum.vibration_features]'."""
    a, m = _windows(accel, fs, window_s, ac_coupled)
    _check_min_amp(min_amp_g)
    u = np.asarray(axis, dtype=float)
    if u.shape != (3,) or not np.isfinite(u).all() or not np.linalg.norm(u) > 0:
        raise ValueError(f"axis must be a non-zero finite 3-vector (body frame); got {axis!r}")
    tol = float(tol_deg)
    if not 0.0 <= tol <= 90.0:
        raise ValueError(f"tol_deg must be an angle in [0, 90] °; got {tol_deg!r}")
    cos_min = jnp.asarray(np.cos(np.radians(tol)), a.dtype)
    return _off_axis(a, jnp.asarray(u, a.dtype), cos_min, fs, min_amp_g, m=m, lobe=_lobe(lobe))


def _check_min_amp(min_amp_g) -> None:
    """Refuse a `min_amp_g` that is not a number, or a concrete one not finite and >= 0 [g]:
    NaN read every window at rest, a negative one read noise peaks as vibration."""
    if numeric_problem(min_amp_g) is not None or np.ndim(min_amp_g) != 0:
        raise TypeError(f"min_amp_g must be a number >= 0 [g]; got {describe(min_amp_g)}")
    v = concrete_value(min_amp_g)
    if v is not None and not (np.isfinite(v) and v >= 0):
        raise ValueError(f"min_amp_g must be a finite number >= 0 [g]; got {float(v):g}")


def _windows(accel, fs, window_s, ac_coupled=False):
    """`accel` checked (finite, (N, 3), m/s² by its mean: module docstring, **Units**; integer
    samples as float64) and the window length `m` [samples] (`fs`, `window_s` concrete)."""
    a = _as_float(check_finite("accel", accel))
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"accel must have shape (N, 3) [m/s²]; got {a.shape}")
    ac_coupled = check_flag("ac_coupled", ac_coupled)
    for name, x, unit in (("fs", fs, "Hz"), ("window_s", window_s, "s")):
        if isinstance(x, jax.core.Tracer):
            raise ValueError(
                f"{name} must be a concrete number [{unit}] (not traced by jit/vmap/grad): "
                "with the other it sets the window length in samples, window_s·fs"
            )
        if not (is_finite_real(x) and x > 0):
            kind = TypeError if numeric_problem(x) is not None else ValueError
            raise kind(f"{name} must be a finite number > 0 {unit}; got {describe(x)}")
    fs, window_s = float(fs), float(window_s)
    top = RANGES["specific_force_g"][1] * G0
    v = concrete_value(a)
    if v is None:  # traced (jit, vmap): the same rule at run time, the value left out
        mean = jnp.linalg.norm(jnp.mean(a, axis=0))
        bad = jnp.stack(_unit_rule(mean, ac_coupled, top))
        msgs = [m.format(mean="", top=top / G0, top_ms2=top) for m in _UNIT_MESSAGES]
        a = eqx.branched_error_if(a, jnp.any(bad), jnp.argmax(bad), msgs)
    else:
        mean = float(np.linalg.norm(v.mean(axis=0)))
        bad = _unit_rule(mean, ac_coupled, top)
        if any(bad):
            shown = f" = {mean:.4g}"
            raise ValueError(
                _UNIT_MESSAGES[bad.index(True)].format(mean=shown, top=top / G0, top_ms2=top)
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


def _unit_rule(mean, ac_coupled: bool, top: float) -> tuple:
    """Which of `_UNIT_MESSAGES` the record's |mean f| `mean` breaks (module docstring,
    **Units**): in g, no gravity (unless `ac_coupled`), beyond `top` [m/s²]. NumPy or JAX."""
    in_g = (mean >= NO_GRAVITY) & (mean < GRAVITY_SPLIT)
    return in_g, (mean < NO_GRAVITY) & (not ac_coupled), mean > top


_UNIT_MESSAGES = (
    "accel must be specific force in m/s²: its mean over the record (gravity: ≈ 9.8 m/s² where "
    "DC-coupled; vibration averages out) has |mean f|{mean} within "
    f"{NO_GRAVITY:g} … {GRAVITY_SPLIT:.3g}, as 1 g written in g has; in g? multiply by {G0}",
    "accel carries no gravity: its mean over the record has |mean f|{mean} below "
    f"{NO_GRAVITY:g} (≈ 9.8 m/s² where DC-coupled), an AC-coupled record whose unit gravity "
    f"cannot tell; pass ac_coupled=True to take it as m/s² (a record in g: multiply by {G0} "
    "first)",
    "accel must be specific force in m/s²: its mean over the record has |mean f|{mean} beyond "
    "{top_ms2:.4g} m/s² ({top:g} g; gravity is ≈ 9.8 m/s²); in mg? multiply by 9.80665e-3 "
    "(hrgjax.plausible.relaxed(specific_force_g=…) widens it)",
)
"""The unit rule's one-line messages, in `_unit_rule`'s order (`{mean}`: the value, eagerly)."""


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
