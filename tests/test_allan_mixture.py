"""mtotdev's bias divisor and oadev's EDF under the record's fitted noise mixture
(hrgjax.allan.mixture): checked against the exact values of a two-component mixture (white
angle + white rate noise, crossing at m = 4) built here from the phase's own covariance — the
components' Mod σ² and the estimator's Gaussian quadratic form — and against the one-type
values that `deviation` used before (which a type read at a crossover cannot give). mtotdev's
EDF against the exact 2E²/Var of its raw estimator's dense quadratic form, built here from
SP 1065 eq. 27's steps (detrend by the halves' means, reflect, average, difference)."""

import math

import numpy as np
import pytest

from hrgjax import allan
from hrgjax.allan.total import mtotvar_bias

Q2, N2 = 4.0 / 3.0, 1.0  # white angle variance per phase point, white rate per sample (τ₀ = 1 s)
VALUE = {"quantization": math.sqrt(Q2), "angle_random_walk": math.sqrt(N2)}  # cross at m = 4


def _phase_cov(n):
    """Cov of the phase x₀ … x_n: white angle Q² on each point plus a white rate's walk."""
    idx = np.arange(n + 1)
    return Q2 * np.eye(n + 1), N2 * np.minimum.outer(idx, idx).astype(float)


def _second_difference(m, size, start=0):
    d = np.zeros(size)
    d[[start, start + m, start + 2 * m]] = 1.0, -2.0, 1.0
    return d


def _exact_bias(m):
    """b_mix(m) = Σ b(αᵢ, m)·Mod σ²ᵢ/Σ Mod σ²ᵢ, each Mod σ²ᵢ = c Σᵢ c/(2m⁴) with c the m
    second differences summed (the modified Allan variance's filter over 3m + 1 points)."""
    wpm, wfm = _phase_cov(3 * m)
    c = sum(_second_difference(m, 3 * m + 1, i) for i in range(m))
    mod = np.array([c @ wpm @ c, c @ wfm @ c]) / (2 * m**4)
    b = np.array([mtotvar_bias(2, m), mtotvar_bias(0, m)])
    return float(b @ mod / mod.sum())


def _exact_oadev_edf(m, n):
    """(tr AΣ)²/tr (AΣ)² of the overlapping Allan variance's quadratic form over n rate
    samples, from the second differences' stationary covariance R_k:
    (M R₀)²/(M R₀² + 2Σ_k (M − k) R_k²), M = n + 1 − 2m terms. White angle noise: Q²·(6, −4, 1)
    at lags 0, m, 2m; the white rate's walk: 2o(k) − o(k − m) − o(k + m), o(j) = max(m − |j|, 0)."""
    terms = n + 1 - 2 * m
    k = np.arange(min(terms, 2 * m + 1))
    r = Q2 * np.select([k == 0, k == m, k == 2 * m], [6.0, -4.0, 1.0], 0.0)

    def o(j):
        return np.maximum(m - np.abs(j), 0.0)

    r = r + N2 * (2 * o(k) - o(k - m) - o(k + m))
    return float(
        (terms * r[0]) ** 2 / (terms * r[0] ** 2 + 2 * np.sum((terms - k[1:]) * r[1:] ** 2))
    )


def test_mixture_bias_and_edf_are_the_exact_ones_of_a_known_mixture():
    """`mixture_bias` and `mixture_oadev_edf` at the true coefficients against the dense
    forms above (the EDF's: the covariance's quadrature, 1e-5 of each entry); the rate random walk's Mod/Allan ratio against interval means of a
    Brownian rate (Cov(y_i, y_j) = min(i, j) + ½, i + ⅓ on the diagonal)."""
    from hrgjax.allan import mixture  # (new in this module's commit)

    ms = np.array([1, 2, 3, 4, 8, 16])
    want = [_exact_bias(int(m)) for m in ms]
    np.testing.assert_allclose(mixture.mixture_bias(VALUE, ms, 1.0), want, rtol=1e-12)
    assert want[0] == pytest.approx(0.5) and 0.9 < want[1] < 0.95  # b(2, 2) 0.998, b(0, 2) 0.814
    n = 160
    edf = mixture.mixture_oadev_edf(VALUE, ms, n, 1.0)
    np.testing.assert_allclose(edf, [_exact_oadev_edf(int(m), n) for m in ms], rtol=1e-4)
    for m in (2, 3, 5):
        idx = np.arange(3 * m)
        sy = np.minimum.outer(idx, idx) + 0.5 - np.eye(3 * m) / 6.0
        x = np.vstack([np.zeros(3 * m), np.tril(np.ones((3 * m, 3 * m)))])
        sx = x @ sy @ x.T
        c = sum(_second_difference(m, 3 * m + 1, i) for i in range(m))
        d = _second_difference(m, 3 * m + 1)
        ratio = (c @ sx @ c / m**2) / (d @ sx @ d)
        assert mixture.modvar_ratio("rate_random_walk", [m])[0] == pytest.approx(ratio, rel=1e-10)


def _mtotvar_form(m, size):
    """Mod Totvar's quadratic form over `size` phase points: each run of 3m points
    detrended by its halves' means, reflected to 9m, its 6m second differences of m-point
    averages (over m) squared, averaged and over 2m² (τ₀ = 1), the runs averaged."""
    n3, half = 3 * m, 3 * m // 2
    dist = (n3 - 1) / 2 + 1 if n3 % 2 else n3 / 2
    detrend = np.eye(n3)
    detrend[:, :half] += np.arange(n3)[:, None] / (half * dist)
    detrend[:, n3 - half :] -= np.arange(n3)[:, None] / (half * dist)
    ext = detrend[np.r_[np.arange(n3)[::-1], np.arange(n3), np.arange(n3)[::-1]]]  # 9m × 3m
    avg = np.array([ext[j : j + m].sum(axis=0) / m for j in range(8 * m)])
    rows = avg[: 6 * m] - 2 * avg[m : 7 * m] + avg[2 * m :]
    block = rows.T @ rows / (6 * m * 2 * m * m)
    runs = size - n3 + 1
    a = np.zeros((size, size))
    for i in range(runs):
        a[i : i + n3, i : i + n3] += block / runs
    return a


def _exact_mtotdev_edf(m, size):
    """2(tr AΣ)²/Var = (tr AΣ)²/tr (AΣ)², Σ = Σ_Q + Σ_N over `size` phase points."""
    wpm, wfm = _phase_cov(size - 1)
    a_s = _mtotvar_form(m, size) @ (wpm + wfm)
    return float(np.trace(a_s) ** 2 / np.sum(a_s * a_s.T))


@pytest.fixture(scope="module")
def mtotdev_exact():
    """{m: exact EDF} of mtotdev over 1 025 phase points."""
    return {m: _exact_mtotdev_edf(m, 1025) for m in (2, 4, 8, 16)}


def test_mixture_mtotdev_edf_is_the_exact_one_of_a_known_mixture(mtotdev_exact):
    """`mixture_mtotdev_edf` at the true coefficients within 4 % of the dense form's EDF
    (the one-type EDFs' own fit error; the cross terms' ρ from the tables), where the one-type
    EDFs of both components miss it by 17–20 % at the crossover (m = 4: exact 355, construction
    0.984×, ρ = 1 — the Cauchy–Schwarz end — 0.916×); on a shorter record (193 points) too."""
    from hrgjax.allan import mixture
    from hrgjax.allan.total import edf_mtotdev

    for size, exact in ((1025, mtotdev_exact), (193, {m: _exact_mtotdev_edf(m, 193)
                                                     for m in (2, 4, 8, 16, 32)})):  # fmt: skip
        ms = np.array(sorted(exact))
        got = mixture.mixture_mtotdev_edf(VALUE, ms, size, 1.0)
        np.testing.assert_allclose(got, [exact[int(m)] for m in ms], rtol=0.04)
    four = mtotdev_exact[4]
    assert edf_mtotdev(2, 4, 1025) / four > 1.15 and edf_mtotdev(0, 4, 1025) / four < 0.82


@pytest.fixture(scope="module")
def records():
    rng = np.random.default_rng(11)
    n = 4096
    return [rng.normal(size=n) * math.sqrt(N2) + np.diff(rng.normal(size=n + 1)) * math.sqrt(Q2)
            for _ in range(3)]  # fmt: skip


def test_deviation_divides_mtotdev_by_the_mixture_bias_at_the_crossover(records):
    """At m = 2, 4, 8 the mixture's b is 0.927, 0.852, 0.798 — 2–7 % from every one-type b
    (m = 2: 0.998, 0.899, 0.814 for α = 2, 1, 0): the divisor `deviation` uses is within 1 %
    of it on each record (before: the type read's, 2.2 % off at best), and `mixture` says so."""
    ms = [2, 4, 8]
    want = np.array([_exact_bias(m) for m in ms])
    for y in records:
        for kind in ("mtotdev", "ttotdev"):
            r = allan.deviation(y, 1.0, kind=kind, taus=ms)
            np.testing.assert_allclose(1 / r.bias_factor**2, want, rtol=0.01)
            assert np.all(r.mixture), kind
    s32 = allan.deviation(records[0], 1.0, kind="mtotdev", taus=ms, noise_rule="stable32")
    assert not np.any(s32.mixture)  # Stable32's divisors, by α alone, as before
    raw = allan.deviation(records[0], 1.0, kind="mtotdev", taus=ms, bias_correction=False)
    assert not np.any(raw.mixture) and np.all(raw.bias_factor == 1.0)


def test_deviation_gives_oadev_the_mixture_edf_at_the_crossover(records):
    """oadev's EDF at m = 2 … 32 within 5 % of the mixture's exact one (2 275 … 235; the
    type read's, before: 0.62–0.91× it at m = 4 … 32, white rate noise's or flicker angle's)."""
    ms = [2, 4, 8, 16, 32]
    n = records[0].size
    want = [_exact_oadev_edf(m, n) for m in ms]
    for y in records:
        r = allan.deviation(y, 1.0, kind="oadev", taus=ms)
        np.testing.assert_allclose(r.edf, want, rtol=0.05)
        assert np.all(r.mixture)


def test_a_noise_outside_the_ieee_952_terms_keeps_the_one_type_values():
    """White rate noise plus a strong Gauss–Markov rate (T = 16 samples): the four terms do
    not fit its bump, the fit is refused and every τ keeps its type read's bias and EDF."""
    from hrgjax.allan import mixture

    rng = np.random.default_rng(3)
    n, phi = 4096, math.exp(-1 / 16)
    e = rng.normal(size=n) * 3.0
    gm = np.empty(n)
    gm[0] = e[0] / math.sqrt(1 - phi * phi)
    for k in range(1, n):
        gm[k] = phi * gm[k - 1] + e[k]
    y = rng.normal(size=n) + gm
    fit, why = mixture.fit_mixture(np.concatenate([[0.0], np.cumsum(y - y.mean())]), 1.0)
    assert fit is None and "misfit" in why
    r = allan.deviation(y, 1.0, kind="mtotdev", taus=[2, 4, 8, 16])
    assert not np.any(r.mixture)
    o = allan.deviation(y, 1.0, kind="oadev", taus=[2, 4, 8, 16])
    assert not np.any(o.mixture) and o.edf.dtype == np.float64
    np.testing.assert_allclose(o.edf, [allan.edf_greenhall(max(int(a), -2), 2, int(m), n + 1,
                                                           True, False, True)
                                       for a, m in zip(o.alpha, o.m, strict=True)])  # fmt: skip
    np.testing.assert_allclose(r.bias_factor, [1 / math.sqrt(mtotvar_bias(int(a), int(m)))
                                               for a, m in zip(r.alpha, r.m, strict=True)])  # fmt: skip


def test_the_fit_runs_only_where_its_result_is_used(records, monkeypatch):
    """oadev with more than MAX_EDF_TAUS τ (`taus="all"`) and `mixture=False` never fit the
    mixture (≈ 10–100 ms of CPU a call): `mixture` False everywhere, the one-type values."""
    from hrgjax.allan import mixture

    y = records[0][:300]
    want = allan.deviation(y, 1.0, kind="oadev", taus="all")
    assert want.m.size > mixture.MAX_EDF_TAUS and not np.any(want.mixture)

    def refuse(*args, **kwargs):
        raise AssertionError("fit_mixture called where its result cannot be used")

    monkeypatch.setattr(mixture, "fit_mixture", refuse)
    r = allan.deviation(y, 1.0, kind="oadev", taus="all")
    np.testing.assert_array_equal(r.edf, want.edf)
    off = allan.deviation(records[0], 1.0, kind="oadev", mixture=False)
    assert not np.any(off.mixture)
    with pytest.raises(ValueError, match="mixture"):
        allan.deviation(records[0], 1.0, mixture="no")


def test_the_mixture_fit_skips_only_the_intervals(records):
    """`fit_terms(intervals=False)`, the mixture's fit, gives fit_noise's coefficients, χ²
    and method exactly, with NaN intervals (their term covariances not built)."""
    from hrgjax.allan.mixture import MIXTURE_TERMS
    from hrgjax.allan.noise_terms import fit_terms

    r = allan.deviation(records[1], 1.0, kind="oadev")
    full = allan.fit_noise(r, terms=list(MIXTURE_TERMS))
    bare = fit_terms(r, terms=list(MIXTURE_TERMS), intervals=False)
    assert bare.value == full.value and bare.chi2 == full.chi2 and bare.method == full.method
    assert all(math.isnan(bare.low[t]) and math.isnan(bare.high[t]) for t in MIXTURE_TERMS)


def test_octave_rows_keep_the_mixture_flags_of_their_rows(records):
    """`octave_rows` (identify_noise's oadev=) subsets every per-τ field, `mixture` too."""
    from hrgjax.allan.octave_fits import octave_rows

    r = allan.deviation(records[2], 1.0, kind="oadev")
    octaves = r.m[1:-2]
    rows = octave_rows(r, records[2], 1.0, octaves)
    assert rows.mixture.shape == rows.m.shape == octaves.shape
    np.testing.assert_array_equal(rows.mixture, r.mixture[1:-2])
