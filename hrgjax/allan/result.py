r"""A deviation curve with its statistics: [`deviation`][hrgjax.allan.deviation] evaluates the
compiled curve of `hrgjax.allan.deviations` on allantools' τ grids and attaches the noise
type of `hrgjax.allan.noise_ident`, the equivalent degrees of freedom and the χ² interval of
`hrgjax.allan.uncertainty`,
as an [`AllanResult`][hrgjax.allan.AllanResult]."""

from __future__ import annotations

import collections
import contextlib
import functools
import math
import numbers

import jax.numpy as jnp
import numpy as np

from .._checks import check_1d, check_flag, check_numbers, describe, is_finite_real
from .._progress import bar
from .._x64 import require_x64
from .curve_result import AllanResult
from .deviations import CURVE_CHUNK, curve, curve_parts
from .noise_ident import (
    B1_AVERAGES,
    NOISE_RULES,
    check_rate_has_noise,
    gapped_alpha,
    noise_id,
    noise_id_each,
)
from .totvar import TOTVAR_BIAS, edf_totdev, totvar_bias
from .uncertainty import ONE_SIGMA, confidence_interval, edf_greenhall

KINDS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev", "mtotdev", "ttotdev")
"""The deviations [`deviation`][hrgjax.allan.deviation] computes (mtotdev and ttotdev in
NumPy: [`hrgjax.allan.total`][hrgjax.allan.total])."""


STEPPED_COST = 22 << 22
"""Estimated work (`work_estimate` in this module, sample passes) from
which [`deviation`][hrgjax.allan.deviation] works in host-side steps behind a progress bar,
with the same results bit for bit: ≈ 9·10⁷, ≈ 2 s on a 2-core CPU — an octave oadev of
4·10⁶ samples (22 factors × 2²²: the sample count that decided it before), an mtotdev of
≈ 6 500 samples (its cost grows as N²: 10⁴ samples ≈ 5 s, 4·10⁴ ≈ 60 s). The compiled
kinds then identify the noise one factor at a time and sum the curve
`hrgjax.allan.deviations.CURVE_CHUNK` factors a call; mtotdev and ttotdev count the points
of each factor (`hrgjax.allan.total.mtotdev_points`) on the bar."""


def work_estimate(kind: str, n_phase: int, m) -> int:
    """The work of a `kind` deviation over `n_phase` phase points at factors `m`, in sample
    passes: one O(N) pass per factor for the compiled kinds (N·len(m)); mtotdev and ttotdev
    every run of 3m points extended to 9m, Σ 9m·(N − 3m + 1) (≈ N² at the long factors)."""
    if kind in ("mtotdev", "ttotdev"):
        from .total import mtotdev_points

        return int(sum(mtotdev_points(n_phase, m)))
    return int(n_phase) * len(m)


class _NoProgress(contextlib.nullcontext):
    """What `deviation` updates below `STEPPED_COST`: nothing shown."""

    def update(self, n=1):
        pass

    def __enter__(self):
        return self


def _noise_in_steps(x, m, progress, **options):
    """[`noise_id`][hrgjax.allan.noise_id]`(x, m, **options)`, one progress step a factor
    (the whole-record work done once: `noise_id_each`)."""
    out = []
    for a in noise_id_each(x, m, **options):
        out.append(a)
        progress.update()
    return np.asarray(out, dtype=int)


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
    mixture: bool = True,
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
    - `bias_correction`: totdev divided by √(E[Totvar]/σ²) for the identified noise
      ([`totvar_bias`][hrgjax.allan.totvar_bias]: 1 − a·τ/T for flicker and random-walk
      rate noise as SP 1065 and Stable32; for white and flicker angle noise, which SP 1065
      leaves uncorrected, 1 + (4/3)·τ/T and about ¾ of that excess — not under
      `noise_rule="stable32"`, which reports totdev as Stable32 does), mtotdev and ttotdev by
      √[`mtotvar_bias`][hrgjax.allan.total.mtotvar_bias] (exact for the noise type and m;
      under `noise_rule="stable32"` by √[`MTOTVAR_BIAS`][hrgjax.allan.total.MTOTVAR_BIAS],
      as Stable32 reports them); `False`
      gives the raw estimators (allantools').
    - `noise_rule`: how the noise type is read where the lag-1 autocorrelation cannot:
      `"hrgjax"` (default; intervals checked by Monte Carlo) or `"stable32"` (the rule read
      off Stable32 1.60's octave tables of an OCXO record, whose α, intervals and totdev it
      reproduces at all 90 τ; for comparing with Stable32, its intervals are less well
      calibrated); [`noise_id`][hrgjax.allan.noise_id] says both.
    - `unit`: the samples' unit (e.g. "°/h"; for `data="phase"` an angle unit, "°"): the
      table, files and plots name the deviation's, `AllanResult.dev_unit` (rates in °/h:
      °/h, tdev °/h·s; angles in °: °/s, tdev °).
    - `mixture`: under `noise_rule="hrgjax"`, take oadev's EDF (grids of up to 64 τ) and
      mtotdev's and ttotdev's bias divisor from the IEEE 952 mixture fitted to the record
      ([`hrgjax.allan.mixture`][hrgjax.allan.mixture]; ≈ 10–100 ms of CPU a call on 10³–10⁵
      samples) where the fit holds (`AllanResult.mixture`); `False` keeps the one type
      read at each τ and skips the fit (sweeps of many short records).

    **Gaps**: NaN samples are missing data. Every kind but the total ones then averages only
    the differences whose windows avoid every gap, as allantools' `gradev` (NumPy, not the
    compiled curve: [`hrgjax.allan.gaps`][hrgjax.allan.gaps]; the noise type read on the
    bridged record, an approximation, and under the default rule arbitrated from m = 4 on
    by R(n) of the gap-free windows alone, `hrgjax.allan.noise_ident.gapped_alpha`).
    The EDF pools the gap-free segments' EDFs (each a
    gap-free record's under the same `noise_rule`), (Σ nₛ)²/Σ nₛ²/EDFₛ over segments of nₛ terms: fragments are less correlated than one
    record with as many terms — except for flicker noise (odd α), whose differences stay
    correlated across a gap: there one record's EDF, a conservative one; and on angle data,
    where differences step over a missing angle, at most that one record's EDF. NaN before
    the first sample or after the last are not gaps: the record is that between them.
    `n_terms` counts the differences used.

    One compiled program per kind and data length serves every τ grid (factors are run-time
    values, padded to a power-of-two count), so a new grid compiles nothing.
    Where the work is estimated at `hrgjax.allan.result.STEPPED_COST` or more (≈ 2 s: an
    octave oadev of 4·10⁶ samples, an mtotdev of ≈ 6 500, whose cost grows as N²), it goes
    in host-side steps behind a progress bar (shown at a terminal), with the same results.

    **Returns:** an [`AllanResult`][hrgjax.allan.AllanResult].

    **Raises:** `ValueError` naming the argument for an unknown kind or data type, a
    rate that is not one positive number, samples that are not 1-D, infinite samples, a `ci` outside (0, 1), data too short for any τ, or
    gaps in a totdev;
    `RuntimeError` when JAX is in float32 mode (a summed phase's differences need float64).
    """
    require_x64("hrgjax.allan.deviation (differences of a summed phase)")
    if not isinstance(kind, str) or kind not in KINDS:
        raise ValueError(f"kind must be one of {list(KINDS)}; got {describe(kind)}")
    if not isinstance(noise_rule, str) or noise_rule not in NOISE_RULES:
        raise ValueError(
            f"noise_rule must be one of {list(NOISE_RULES)}; got {describe(noise_rule)}"
        )
    if not isinstance(data, str) or data not in ("rate", "phase"):
        raise ValueError(f"data must be 'rate' or 'phase'; got {describe(data)}")
    if not (is_finite_real(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive sample rate [Hz]; got {describe(rate_hz)}")
    if not (is_finite_real(ci) and 0.0 < ci < 1.0):
        raise ValueError(f"ci must be a confidence level in (0, 1); got {describe(ci)}")
    if not isinstance(mixture, bool | np.bool_):
        raise ValueError(f"mixture must be True or False; got {describe(mixture)}")
    check_flag("bias_correction", bias_correction)  # "no" corrected the deviation
    check_1d("y", y, "one sample per interval")
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
    present = np.flatnonzero(~np.isnan(y))
    if present.size < 3:
        raise ValueError(f"y has {present.size} values that are not NaN; at least 3 are needed")
    # NaN before the first sample or after the last are a shorter record, not gaps: as gaps
    # they anchored adev's and hdev's windows at index 0 and moved the noise type read on the
    # bridged record (EDF up to 3.1× the truncated record's)
    offset = int(present[0])
    y = y[offset : int(present[-1]) + 1]
    gaps = bool(np.any(np.isnan(y)))
    if gaps:
        from .gaps import bridged, gapped_curve

        filled = bridged(y, data)
    else:
        filled = y
    if data == "phase":
        x = filled - filled[0]
        rate = np.diff(filled) / tau0
    else:
        rate = filled
        # less the mean rate: a large constant rate summed as it is drowns the noise's digits
        x = np.concatenate([[0.0], np.cumsum(filled - np.mean(filled)) * tau0])
    n_phase = x.size
    m = _factors(taus, rate_hz, n_phase)
    n_terms = np.asarray([_n_terms(kind, int(k), n_phase) for k in m], dtype=int)
    m, n_terms = m[n_terms > 1], n_terms[n_terms > 1]
    if m.size == 0:
        raise ValueError(_no_tau(kind, taus, tau0, n_phase, y.size))
    # long records: work in host-side steps behind a progress bar (bit-identical results)
    total = kind in ("mtotdev", "ttotdev")  # its curve counted in points on the bar
    work = work_estimate(kind, n_phase, m)
    stepped = work >= STEPPED_COST
    steps = 1 + m.size * (1 + (not gaps and not total)) + (work if total else 0)
    counted = "pt" if total else "step"
    with bar(steps, f"allan {kind}", unit=counted) if stepped else _NoProgress() as progress:
        if data == "rate":
            check_rate_has_noise(y)
        progress.update()
        base = "mdev" if kind == "tdev" else kind
        if kind in ("mtotdev", "ttotdev"):  # each run detrended and reflected (hrgjax.allan.total)
            from .total import mtotdev_curve

            if gaps:
                raise ValueError(f"y has gaps (NaN): {kind} reflects every run of 3m points "
                                 "and has no gap-tolerant form; split the record, or use "
                                 "mdev")  # fmt: skip
            dev = mtotdev_curve(x, m, progress=progress)[0] / tau0
            n_eff = np.full(m.size, n_phase)
        elif gaps:  # windows across a gap left out (hrgjax.allan.gaps), in NumPy
            dev, n_terms = gapped_curve(kind, y, data, m)
            dev = dev / tau0 if data == "phase" else dev
            m, n_terms, dev = m[n_terms > 1], n_terms[n_terms > 1], dev[n_terms > 1]
            if m.size == 0:
                raise ValueError(f"y: its gaps leave fewer than 2 {kind} terms at every τ asked")
            # the EDF of a gap-free record with as many differences as the gaps leave at each τ
            # (used where no gap-free segment holds a difference: angle data whose differences
            # step over a missing angle)
            extra = {"adev": 2, "oadev": 2, "hdev": 3, "ohdev": 3, "mdev": 3, "tdev": 3}[kind]
            stride = m if kind in ("adev", "hdev") else 1
            n_eff = np.minimum(stride * n_terms + extra * m - (kind in ("mdev", "tdev")), n_phase)
            segments = _segments(y, data)
        else:
            # one program for every grid of ≤ 32 τ (octave grids up to 2³² samples), powers of
            # two beyond; JAX runs the curve asynchronously while NumPy identifies the noise
            if stepped:  # the same values, CURVE_CHUNK factors a program call (progress)
                parts = curve_parts(jnp.asarray(rate), m, tau0, base)
            else:
                pad = max(32, 1 << int(math.ceil(math.log2(m.size))))
                ms = np.concatenate([m, np.full(pad - m.size, m[-1])])
                pending = curve(jnp.asarray(rate), jnp.asarray(ms), tau0, base)
            n_eff = np.full(m.size, n_phase)
        dmax = 3 if kind in ("hdev", "ohdev") else 2
        options = dict(dmax=dmax, rule=noise_rule, overlapping=kind not in ("adev", "hdev"))
        alpha = _noise_in_steps(x, m, progress, **options) if stepped else noise_id(x, m, **options)
        if gaps and noise_rule == "hrgjax":  # R(n) of the gap-free windows arbitrates: the
            from .gaps import gapped_rn  # bridge's steps read as rate noise (gapped_alpha)

            alpha = np.asarray([gapped_alpha(int(a), int(k), rn) for a, k, rn
                                in zip(alpha, m, gapped_rn(y, data, m), strict=True)])  # fmt: skip
        edf = np.asarray([_edf(kind, int(a), int(k), int(n), noise_rule)
                          for a, k, n in zip(alpha, m, n_eff, strict=True)])  # fmt: skip
        if gaps:  # the gap-free segments' EDFs pooled: their differences are independent for
            # white angle noise, white rate noise and a rate random walk, not for flicker noise
            # (odd α: ±1, and −3 for the Hadamard kinds: long-range correlated), which keeps
            # one record's EDF (conservative)
            edf = np.asarray([e if int(a) % 2 else  # odd α: flicker (α = ±1, −3), correlated
                              _gapped_edf(kind, int(a), int(k), int(t), segments, e, noise_rule,
                                          angles=data == "phase")
                              for a, k, t, e in zip(alpha, m, n_terms, edf,
                                                    strict=True)])  # fmt: skip
        # the fitted IEEE 952 mixture's bias (mtotdev, ttotdev) or EDF (oadev) where it holds
        mixed, mix_value = np.zeros(m.size, dtype=bool), None
        if mixture and noise_rule == "hrgjax" and not gaps and (kind == "oadev" or (
                kind in ("mtotdev", "ttotdev") and bias_correction)):  # fmt: skip
            from .mixture import mixture_statistics

            mixed, mix_value = mixture_statistics(kind, x, tau0, m)
            if kind == "oadev" and mix_value is not None:
                edf = np.where(mixed, mix_value, edf)
        if not gaps and kind not in ("mtotdev", "ttotdev"):
            if stepped:
                done = []
                for part in parts:
                    done.append(np.asarray(part))
                    progress.update(min(CURVE_CHUNK, m.size - CURVE_CHUNK * (len(done) - 1)))
                pending = np.concatenate(done)
            dev = np.asarray(pending)[: m.size]
        taus_s = m * tau0
        if kind in ("tdev", "ttotdev"):
            dev = dev * taus_s / math.sqrt(3.0)
        factor = np.ones_like(dev)
        if kind in ("mtotdev", "ttotdev") and bias_correction:
            from .total import MTOTVAR_BIAS, mtotvar_bias

            if noise_rule == "stable32":  # Stable32's divisors, by α alone (as its tables)
                bias = [MTOTVAR_BIAS[int(min(max(a, -2), 2))] for a in alpha]
            else:  # the estimator's own, exact: ½ at m = 1 (mtotdev(τ₀) = mdev(τ₀))
                bias = [mtotvar_bias(int(a), int(k)) for a, k in zip(alpha, m, strict=True)]
                bias = np.where(mixed, mix_value, bias) if mix_value is not None else bias
            factor = 1.0 / np.sqrt(bias)
            dev = dev * factor
        if kind == "totdev" and bias_correction:
            angle = noise_rule == "hrgjax"  # Stable32 (SP 1065) corrects rate noises only
            factor = 1.0 / np.sqrt([totvar_bias(int(a), int(k), n_phase, angle_noise=angle)
                                    for a, k in zip(alpha, m, strict=True)])  # fmt: skip
            dev = dev * factor
        low, high = confidence_interval(dev, edf, ci)
        if kind == "totdev" and bias_correction and noise_rule == "hrgjax":
            edf, low, high = _rate_noise_span(dev / factor, alpha, m, n_phase, edf, low, high, ci)
    return AllanResult(
        kind=kind, ci=float(ci), taus=taus_s, m=m, dev=dev, dev_low=low, dev_high=high,
        edf=edf, n_terms=n_terms, alpha=alpha, bias_factor=factor, unit=str(unit),
        segments=_runs(y, offset) if gaps and data == "rate" else None, mixture=mixed, data=data,
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
                f"taus must be 'octave', 'decade', 'all' or τ values in seconds; "
                f"got {describe(taus)}"
            )
    else:  # a 2-D grid was flattened; str, dict, complex items failed in float()
        form = "'octave', 'decade', 'all' or τ values in seconds (a number or a 1-D list)"
        check_numbers("taus", taus, form)
        if np.ndim(taus) > 1:
            raise ValueError(f"taus must be {form}; got {describe(taus)}")
        t = np.asarray(taus, dtype=float).ravel()
        if t.size == 0 or not np.all(np.isfinite(t)):
            raise ValueError(f"taus must be finite τ values in seconds; got {describe(taus)}")
        if np.any(t <= 0):
            i = int(np.argmax(t <= 0))
            raise ValueError(f"taus must be > 0 s; got {float(t[i]):g} at index {i} of "
                             f"{describe(taus)}")  # fmt: skip
        m = np.round(t * rate_hz)
    m = m[(m > 0) & (m < n_phase)]
    return np.unique(m).astype(int)


def _longest_factor(kind: str, n: int) -> int:
    """The largest m at which `kind` averages at least 2 terms over n phase points (0: none);
    the terms fall as m grows."""
    lo, hi = 0, n - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if _n_terms(kind, mid, n) > 1 else (lo, mid - 1)
    return lo


def _no_tau(kind: str, taus, tau0: float, n_phase: int, n_samples: int) -> str:
    """Why no τ of `taus` is left: too few samples for any, or τ asked outside the range
    (τ₀ … the longest τ with 2 terms; each τ rounded to a whole number of samples)."""
    longest = _longest_factor(kind, n_phase)
    if longest == 0 or isinstance(taus, str):
        return f"y: {n_samples} samples are too few for {kind} at any τ (2 terms are needed)"
    return (f"taus must lie within {kind}'s range on {n_samples} samples: τ₀ = {tau0:g} s to "
            f"{longest * tau0:g} s (m = 1 … {longest}, at least 2 terms; each τ rounded to whole "
            f"samples); got {describe(taus)}")  # fmt: skip


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


def _segments(y: np.ndarray, data: str) -> list[int]:
    """Phase points in each gap-free stretch of `y` (NaN: missing): a run of L rate samples
    gives L + 1 angles, a run of L angles L."""
    ok = np.concatenate([[False], np.isfinite(y), [False]])
    edges = np.flatnonzero(np.diff(ok.astype(np.int8)))
    runs = edges[1::2] - edges[::2]
    return [int(r) + (data == "rate") for r in runs]


def _runs(y: np.ndarray, offset: int = 0) -> np.ndarray:
    """(start, length) of each run of finite samples of `y`, in order [samples], the starts
    counted from `offset` (the samples cut off before `y`)."""
    ok = np.concatenate([[False], np.isfinite(y), [False]])
    edges = np.flatnonzero(np.diff(ok.astype(np.int8)))
    runs = np.stack([edges[::2] + offset, edges[1::2] - edges[::2]], axis=1)
    return runs.astype(np.int64)


def _gapped_edf(
    kind: str, alpha: int, m: int, n_terms: int, segments, fallback, rule, angles: bool = False
) -> float:
    """EDF at factor m of a record with gaps: that of the pooled gap-free segments' estimates
    (a segment's differences are not correlated with another's), scaled by the differences used
    over those the segments hold; `fallback` (one record with as many differences) where no
    segment holds one; `rule` the noise rule (each segment's EDF as `_edf` gives it under
    that rule). A record cut into fragments has 2–3× the EDF of one gap-free record
    with as many differences (oadev, white rate noise, a NaN every 50 samples: Monte Carlo
    241 and 156 at m = 16 and 20, one record's 126 and 57; the exact EDF of the quadratic
    form is met to 1e-6 where Greenhall's is exact).

    `angles`: on angle data a difference may step over a missing angle (adev, oadev, hdev,
    ohdev at m ≥ 2), and those differences tie the segments together: where the segments
    hold fewer differences than are used, the EDF is at most `fallback`. Scaling the few
    held up to all used overstated it (white angle noise, 1 000 angles, 2 % missing: oadev
    at m = 64 830 against a Monte Carlo 473 and `fallback`'s 445; white rate noise's angle
    67 against 21.4 and 20.2)."""
    lengths = collections.Counter(s for s in segments if _n_terms(kind, m, s) > 0)
    held = sum(count * _n_terms(kind, m, s) for s, count in lengths.items())
    if held == 0:
        return float(fallback)
    # the pooled mean of independent segments' estimates weighted by their terms n_s:
    # EDF = (Σ n_s)² / Σ n_s²/EDF_s (the plain sum of EDFs where the segments are equal)
    spread = sum(count * _n_terms(kind, m, s) ** 2 / _edf(kind, alpha, m, s, rule)
                 for s, count in lengths.items())  # fmt: skip
    pooled = max(held * n_terms / spread, 1.0)
    return min(pooled, float(fallback)) if angles and held < n_terms else pooled


SPAN_REACH = 1
"""How far from the α read (in steps of α) totdev's interval reaches where B1 reads a rate noise
on ≤ [`B1_AVERAGES`][hrgjax.allan.B1_AVERAGES] averages (τ ≥ T/8, default rule, bias
correction on): the interval spans the intervals of the rate noises α = 0, −1, −2 within one
step of it (read 0: white and flicker; −1: all three; −2: flicker and random walk). B1 on 8
averages reads white rate noise as 0/−1/−2 in 68/27/3 % of records, flicker 35/46/19 %, a
random walk 10/31/59 % (2 048 samples): a type two steps from the one read is rare, and
spanning it too made white rate noise's interval 1.4× wider at τ = T than one step does
(±1σ 77–82 % at τ/T = 1/8 … 1; one step 74–81 %, every rate noise and white + walk mixture
≥ 68 %: `benchmarks/coverage_totdev.py`, docs/allan.md)."""

_SPAN_TYPES = np.array([0, -1, -2])
_TABLE7 = np.array([[1.50, 0.0], [1.17, 0.22], [0.93, 0.36]])  # SP 1065 Table 7: b, c
_TOTVAR_A = np.array([0.0, TOTVAR_BIAS[-1], TOTVAR_BIAS[-2]])
_CAP_FROM = 64  # edf_totdev's cap: binds at m ≤ 6 (Greenhall's, stable32: ≤ 20), not above


def _rate_noise_span(raw, alpha, m, n, edf, low, high, ci):
    """totdev's (EDF, low, high) where its α, a rate noise (≤ 0), is read by B1 on at most
    `B1_AVERAGES` averages (τ ≥ T/8: its scatter spans the rate noises there): the interval
    spanning those of the rate noises within `SPAN_REACH` of the α read, each its own bias
    correction (1, 1/(1 − 0.481·τ/T), 1/(1 − ¾·τ/T)) and EDF, the smallest EDF reported.

    The EDFs are SP 1065 Table 7's line max(b·N/m − c, 1) as arrays, which is
    [`edf_totdev`][hrgjax.allan.edf_totdev] there: its cap (oadev's exact EDF up to m = 64,
    Greenhall's beyond) binds only at m ≤ 6 (every n ≤ 9m + 1 of m ≤ 64: from m = 33 on it is
    ≥ 1.05× the line; Greenhall's, ≥ 1.02× from m = 33 on every n sampled to 10⁶ + 1 points),
    so `edf_totdev` itself is asked only at m ≤ 64; one `confidence_interval` call for all τ."""
    edf, low, high = edf.astype(float), low.copy(), high.copy()
    j = np.flatnonzero((alpha <= 0) & ((n - 1) // m <= B1_AVERAGES))
    if j.size == 0:
        return edf, low, high
    k = m[j].astype(float)
    near = np.abs(_SPAN_TYPES[None, :] - alpha[j, None]) <= SPAN_REACH
    types = near & (_SPAN_TYPES[None, :] != alpha[j, None])  # (τ, type) spanned, the read one's
    if not types.any():  # interval already in (low, high)
        return edf, low, high
    e = np.maximum(_TABLE7[:, 0] * n / k[:, None] - _TABLE7[:, 1], 1.0)
    for i in np.flatnonzero(k <= _CAP_FROM):
        e[i] = [edf_totdev(int(a), int(k[i]), n) for a in _SPAN_TYPES]
    bias = 1.0 - _TOTVAR_A * k[:, None] / (n - 1)
    lo, hi = confidence_interval((raw[j, None] / np.sqrt(bias))[types], e[types], ci)
    row = np.nonzero(types)[0]
    span_lo, span_hi, span_e = low[j], high[j], edf[j]
    np.minimum.at(span_lo, row, lo)
    np.maximum.at(span_hi, row, hi)
    np.minimum.at(span_e, row, e[types])
    low[j], high[j], edf[j] = span_lo, span_hi, span_e
    return edf, low, high


@functools.lru_cache(maxsize=65536)  # a gapped record asks for each segment length per τ
def _edf(kind: str, alpha: int, m: int, n: int, rule: str = "hrgjax") -> float:
    if kind == "totdev":
        return edf_totdev(alpha, m, n, discrete=rule != "stable32")
    if kind in ("mtotdev", "ttotdev"):
        from .total import edf_mtotdev

        return edf_mtotdev(alpha, m, n, rule)
    d = 3 if kind in ("hdev", "ohdev") else 2
    alpha = max(alpha, 2 - 2 * d)  # the variance converges for α > 1 − 2d
    return edf_greenhall(
        alpha, d, m, n, overlapping=kind in ("oadev", "ohdev", "mdev", "tdev"),
        modified=kind in ("mdev", "tdev"), discrete=rule != "stable32",
    )  # fmt: skip
