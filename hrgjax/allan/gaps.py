r"""Allan-family deviations of records with gaps (NaN samples), in NumPy.

Each estimate averages differences of the angle over windows; a window that touches a gap
is left out and the rest averaged, as allantools' gap-resistant `gradev` does for the
overlapping Allan deviation (equal to it on angle data), for every kind but totdev:

- rate samples $y_k$ (NaN where missing): the angle's differences are window sums of $y$,
  so a window counts when none of its samples is missing — a gap costs the windows across
  it, not the record after it;
- angle samples $x_k$: a difference counts when each angle it uses is there.

`totdev` reflects the record at its ends and has no gap-tolerant form: split the record.

The noise type at each τ is read on the record with its gaps bridged (each run of missing
rates by the mean of the present rates on either side; missing angles by a straight line
between their neighbours), an approximation
fair while the gaps are a small part of the record; under the default rule R(n) of the
gap-free windows alone ([`gapped_rn`][hrgjax.allan.gaps.gapped_rn]) then arbitrates
angle against rate noise from m = 4 on
(`hrgjax.allan.noise_ident.gapped_alpha`): a bridge steps the angle at every
gap, which made white angle noise in rate data read as rate noise. The EDF at each τ pools the gap-free
segments' EDFs (`hrgjax.allan.result.deviation`: fragments are less correlated than one
record with as many differences).
"""

from __future__ import annotations

import numpy as np


def gapped_curve(kind: str, y: np.ndarray, data: str, ms) -> tuple[np.ndarray, np.ndarray]:
    """`(dev, n_terms)` of `kind` at factors `ms` (rate units, τ0 = 1: the caller scales
    tdev) from `y` with NaN gaps; `n_terms` counts the differences that avoid every gap."""
    if kind == "totdev":
        raise ValueError(
            "y has gaps (NaN): totdev reflects the record at its ends and has no gap-tolerant "
            "form; split the record at its gaps, or use oadev, mdev or ohdev"
        )
    if data == "rate":
        ok = np.isfinite(y)
        centre = np.mean(y[ok]) if ok.any() else 0.0  # a constant rate cancels in d; its sum
        level = np.concatenate([[0.0], np.cumsum(np.where(ok, y - centre, 0.0))])  # angle / τ0
        holes = np.concatenate([[0], np.cumsum(~ok)])
    else:
        level = y - y[np.flatnonzero(np.isfinite(y))[0]]
        holes = None
    devs, counts = [], []
    for m in (int(k) for k in ms):
        if kind in ("hdev", "ohdev"):
            d, valid = _difference(level, holes, m, (1, -3, 3, -1))
            norm = 6.0
        else:
            d, valid = _difference(level, holes, m, (1, -2, 1))
            norm = 2.0
        if kind in ("adev", "hdev"):
            keep = np.arange(d.size) % m == 0
            d, valid = d[keep], valid[keep]
        if kind in ("mdev", "tdev"):  # sums of m consecutive second differences
            c = np.concatenate([[0.0], np.cumsum(np.where(valid, d, 0.0))])
            bad = np.concatenate([[0], np.cumsum(~valid)])
            d = (c[m:] - c[:-m]) / m
            valid = bad[m:] - bad[:-m] == 0
        n = int(valid.sum())
        counts.append(n)
        dev = np.sqrt(np.sum(d[valid] ** 2) / (norm * m * m * n)) if n else np.nan
        devs.append(dev)
    return np.asarray(devs), np.asarray(counts, dtype=int)


RN_WINDOWS = 3
"""Gap-free modified windows, per unit of m, that [`gapped_rn`][hrgjax.allan.gaps.gapped_rn]
needs at factor m: with fewer it is NaN and the bridged record's type stands. 2 % of 4 096
rates missing, m = 64, R(n) read white angle noise in (records with R(n), of 200): white
angle noise 90/90, 49/49, 19/19 with ≥ 1, 2, 3 m windows; flicker angle noise 13/90, 5/49,
0/19; white rate noise 1/90, 0/49, 0/19."""


def gapped_rn(y: np.ndarray, data: str, ms) -> np.ndarray:
    """R(n) = MVAR/AVAR at each factor of `ms` from the windows that avoid every gap of `y`
    (rate or angle samples, NaN missing; `gapped_curve`'s mdev over its oadev, squared),
    with the rates' least-squares line (angles: quadratic) over the present samples taken
    out first, as `noise_id` takes the phase's curvature out; NaN where fewer than
    `RN_WINDOWS`·m modified windows avoid the gaps. What
    `hrgjax.allan.noise_ident.gapped_alpha` arbitrates the bridged record's noise type
    with: the bridge's steps at the gaps are not in it."""
    ok = np.isfinite(y)
    t = np.flatnonzero(ok).astype(float)
    fit = np.polyval(np.polyfit(t - t.mean(), y[ok], 1 if data == "rate" else 2),
                     np.arange(y.size) - t.mean())  # fmt: skip
    flat = np.where(ok, y - fit, np.nan)
    ms = [int(k) for k in ms]
    mod, mod_n = gapped_curve("mdev", flat, data, ms)
    allan, _ = gapped_curve("oadev", flat, data, ms)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(mod_n >= RN_WINDOWS * np.asarray(ms), (mod / allan) ** 2, np.nan)


def _difference(level, holes, m, coef):
    """The angle's finite difference with coefficients `coef` at lag m for every start, and
    whether it avoids every gap."""
    k = len(coef) - 1
    size = level.size - k * m
    d = sum(c * level[j * m : j * m + size] for j, c in enumerate(coef))
    if holes is None:  # angle data: each angle used must be there
        valid = np.all([np.isfinite(level[j * m : j * m + size]) for j in range(k + 1)], axis=0)
    else:  # rate data: no missing sample inside the k·m window
        valid = holes[k * m : k * m + size] - holes[:size] == 0
    return np.where(valid, d, 0.0), valid


BRIDGE_REACH = 16
"""Present rate samples on each side of a gap whose mean bridges it for noise identification
([`bridged`][hrgjax.allan.gaps.bridged])."""


def bridged(y: np.ndarray, data: str) -> np.ndarray:
    """`y` with its gaps bridged for noise identification: each run of missing rates by the
    mean of the present rates within its length, and at least `BRIDGE_REACH`, before and
    after it (the local rate), missing angles by a straight line between their neighbours.
    The reach grows with the run: a run of L rates filled at a mean of fewer than L would
    add an angle step larger than the noise's own over L (flicker angle noise read as rate
    noise at T/64 … T/32 past a 300-sample gap with a reach of 16).

    The record's mean rate, used until 2026-12-03, put a spike of (mean − local rate) into a
    wandering rate at every gap: a rate random walk with 2 % of its samples missing read as
    flicker rate noise at τ₀ and 2τ₀ in every record (now as the gap-free record: −2 in
    100 %); white and flicker rate and angle noise read as before."""
    ok = np.isfinite(y)
    idx = np.arange(y.size)
    if data != "rate":
        return np.interp(idx, idx[ok], y[ok])
    centre = y[ok].mean()  # sums of y − centre keep a large constant rate's digits
    total = np.concatenate([[0.0], np.cumsum(y[ok] - centre)])  # over the present samples
    before = np.cumsum(ok)[~ok]  # present samples before each missing one (one count a run)
    _, run, length = np.unique(before, return_inverse=True, return_counts=True)
    reach = np.maximum(length[run], BRIDGE_REACH)  # a run's length at least: see above
    lo = np.maximum(before - reach, 0)
    hi = np.minimum(before + reach, total.size - 1)
    out = y.copy()
    out[~ok] = centre + (total[hi] - total[lo]) / (hi - lo)
    return out
