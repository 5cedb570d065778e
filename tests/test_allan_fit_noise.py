"""fit_noise's σ are the overlapping estimator's (issue 58): checked against a covariance
built here by brute force from the record's Gaussian law, and by a small Monte Carlo with
known truth."""

import math

import numpy as np
import pytest

from hrgjax import allan

N_SAMPLES, TAU0 = 300, 0.5
TERMS = ("angle_random_walk", "rate_random_walk")


def _brute_omega(value, ms, n, tau0, ok=None):
    """Cov(σ̂²(m_a), σ̂²(m_b)) of the overlapping Allan variance of n rate samples every tau0
    with white rate noise N²/τ₀ per sample and a rate random walk K, as the Gaussian quadratic
    forms' 2·tr(A Σ B Σ) over the record's phase (X = Σy); with `ok` (n booleans, False where
    a sample is missing) each estimate averages only the differences whose 2m samples are
    all there (hg.allan.deviation's gapped oadev). The samples are interval means
    (fit_noise's records are rates from angle differences): y_i = (1/τ₀)∫ W over
    [iτ₀, (i + 1)τ₀] of a Brownian rate W with Cov(W(s), W(t)) = K²·min(s, t), so
    Cov(y_i, y_j) = K²τ₀(min(i, j) + 1/2) for i ≠ j and K²τ₀(i + 1/3) on the diagonal."""
    idx = np.arange(n)
    sy = np.eye(n) * value["angle_random_walk"] ** 2 / tau0
    walk = np.minimum.outer(idx, idx) + 0.5 - np.eye(n) / 6.0
    sy += value["rate_random_walk"] ** 2 * tau0 * walk
    x = np.vstack([np.zeros(n), np.tril(np.ones((n, n)))])  # X_j = Σ_{k<j} y_k
    sx = x @ sy @ x.T
    forms = []
    for m in ms:
        i = np.arange(n + 1 - 2 * m)
        if ok is not None:  # windows of 2m samples clear of every gap
            i = i[[bool(ok[j : j + 2 * m].all()) for j in i]]
        rows = i.size
        d = np.zeros((rows, n + 1))
        d[np.arange(rows), i] = 1.0
        d[np.arange(rows), i + m] = -2.0
        d[np.arange(rows), i + 2 * m] = 1.0
        forms.append(sx @ (d.T @ d) / (2.0 * m * m * rows))  # A Σ with A the quadratic form
    return np.array([[2 * np.sum(a * b.T) for b in forms] for a in forms])


def _record(gaps):
    """A record of 300 samples with white rate noise and a rate random walk (with `gaps`:
    one sample missing at 100 and ten at 180–189), its oadev on the octave grid, fit_noise's
    N and K, the basis and the brute-force Ω at the fit."""
    rng = np.random.default_rng(3)
    y = 1.0 * rng.normal(size=N_SAMPLES) + 0.02 * np.cumsum(rng.normal(size=N_SAMPLES))
    ok = np.ones(N_SAMPLES, dtype=bool)
    if gaps:
        ok[100] = ok[180:190] = False
    res = allan.deviation(np.where(ok, y, np.nan), 1.0 / TAU0, kind="oadev", taus="octave")
    fit = allan.fit_noise(res, terms=TERMS)
    ms = np.asarray(res.m, dtype=int)
    omega = _brute_omega(fit.value, ms, N_SAMPLES, TAU0, ok if gaps else None)
    basis = np.stack([f(res.taus) for n, _, _, f in allan.NOISE_TERMS if n in TERMS], axis=1)
    return res, fit, ms, basis, omega


@pytest.fixture(scope="module")
def one_record():
    return _record(gaps=False)


@pytest.mark.parametrize("gaps", [False, True], ids=["gap-free", "gaps"])
def test_sigma_is_the_gls_covariance_of_the_overlapping_estimates(one_record, gaps):
    """On one record the reported σ of N and K equal √((AᵀΩ⁻¹A)⁻¹) (delta method to the
    coefficients) with Ω the estimates' covariance at the fitted model computed here by
    brute force, and the fit is GLS's fixed point under that Ω (fit_noise before: σ 27 %
    too small) — also with 11 samples missing (gapped_covariance; fit_noise before: τ
    independent with EDF weights, σ of N 0.74× and of K 1.12× the GLS σ at its fit)."""
    res, fit, _, basis, omega = _record(gaps=True) if gaps else one_record
    w = np.linalg.inv(omega)
    cov = np.linalg.inv(basis.T @ w @ basis)
    c2 = np.array([fit.value[t] ** 2 for t in TERMS])
    sigma = np.sqrt(np.diag(cov)) / (2 * np.sqrt(c2))
    np.testing.assert_allclose([fit.sigma[t] for t in TERMS], sigma, rtol=2e-3)
    gls = cov @ basis.T @ w @ res.dev**2  # both coefficients positive: the unconstrained GLS
    # the fixed point to 1 % of σ(c²) (four rounds: with gaps K² moved 2.8e-5, 0.5 % of σ)
    np.testing.assert_allclose(c2, gls, rtol=2e-3, atol=0.01 * np.sqrt(np.diag(cov)).min())
    assert fit.method == "gls"


def test_interval_inverts_the_estimates_skewed_law(one_record):
    """The interval on each coefficient² is where the estimate's law puts the estimate at
    its (1 ± ci)/2 quantiles: ĉ² = L·σ̂² (L the GLS rows under the brute-force Ω) has
    variance own·θ² + rest — own = L Ω₁ Lᵀ with Ω₁ the term's own covariance at unit
    coefficient², rest the others' share at the fit — and the third cumulant of its own part
    θχ²_ν/ν (ν = 2/own), as a Pearson III law (a gamma of shape 4/skew², shifted to mean θ):
    inverted here by bisection with scipy's incomplete gamma. The intervals (at the default
    68.3 %) are asymmetric: K's upper end 1.7× as far from K as its lower (fit_noise before:
    c² ± zσ(c²), K's low 0 and its high 25 % lower)."""
    from scipy.special import gammainc

    res, fit, ms, basis, omega = one_record
    w = np.linalg.inv(omega)
    weights = np.linalg.inv(basis.T @ w @ basis) @ basis.T @ w
    q = (1 + res.ci) / 2
    for i, t in enumerate(TERMS):
        alone = {s: float(s == t) for s in TERMS}
        own = weights[i] @ _brute_omega(alone, ms, N_SAMPLES, TAU0) @ weights[i]
        c2 = fit.value[t] ** 2
        rest = weights[i] @ omega @ weights[i] - own * c2**2

        def cdf(theta, own=own, rest=rest, c2=c2):  # Pearson III: P(ĉ² ≤ c2 | θ)
            sd = math.sqrt(own * theta**2 + rest)
            skew = 2 * own**2 * theta**3 / sd**3
            shape, scale = 4 / skew**2, sd * skew / 2
            return gammainc(shape, max(c2 - theta + shape * scale, 0.0) / scale)

        def solve(p, lo, hi, cdf=cdf):  # the θ where the falling cdf crosses p
            for _ in range(200):
                mid = math.sqrt(lo * hi)
                lo, hi = (mid, hi) if cdf(mid) > p else (lo, mid)
            return lo

        assert fit.low[t] == pytest.approx(math.sqrt(solve(q, 1e-3 * c2, c2)), rel=1e-6)
        assert fit.high[t] == pytest.approx(math.sqrt(solve(1 - q, c2, 1e3 * c2)), rel=1e-6)
    k = "rate_random_walk"
    assert fit.high[k] - fit.value[k] > 1.5 * (fit.value[k] - fit.low[k])


def test_one_tau_interval_is_the_allan_variances_chi2_interval():
    """Exact truth: N fitted to one τ of a non-overlapping Allan deviation (τ points taken
    as independent with the estimate's EDF) is N = σ̂√τ, and its interval must be the
    Allan deviation's own χ² interval (NIST SP 1065 eq. 45: ν σ̂²/χ²_ν((1 ± ci)/2)) times √τ;
    and so it is for a χ² of 4.6, 16 and 82 EDF, at 95 % and 68.27 % (fit_noise before:
    c² ± zσ(c²), at 4.6 EDF and 95 % its low 0 and its high 42 % short)."""
    rng = np.random.default_rng(5)
    y = rng.normal(size=480)
    for m in (80, 20, 4):
        for ci in (0.95, 0.6827):
            res = allan.deviation(y, 1.0, kind="adev", taus=[m], ci=ci)
            fit = allan.fit_noise(res, terms=("angle_random_walk",))
            root_tau = math.sqrt(res.taus[0])
            assert fit.value["angle_random_walk"] == pytest.approx(res.dev[0] * root_tau)
            assert fit.low["angle_random_walk"] == pytest.approx(res.dev_low[0] * root_tau,
                                                                 rel=1e-6)  # fmt: skip
            assert fit.high["angle_random_walk"] == pytest.approx(res.dev_high[0] * root_tau,
                                                                  rel=1e-6)  # fmt: skip


def test_reported_sigma_of_k_matches_its_monte_carlo_spread():
    """100 records of 4 096 s of white rate noise and a rate random walk with known N and K:
    the empirical spread of the fitted K is the mean reported σ within 25 % (measured 1.07×;
    the τ-independent σ fit_noise gave before: 1.77×), and the z-RMS of K is within 0.8–1.3
    (measured 1.12; before: 1.93)."""
    rng = np.random.default_rng(0)
    n, arw, rrw = 4096, 1.0, 0.03
    ks, sigmas = [], []
    for _ in range(100):
        y = arw * rng.normal(size=n) + rrw * np.cumsum(rng.normal(size=n))
        fit = allan.fit_noise(allan.deviation(y, 1.0, kind="oadev", taus="octave"), terms=TERMS)
        ks.append(fit.value["rate_random_walk"])
        sigmas.append(fit.sigma["rate_random_walk"])
    ks, sigmas = np.asarray(ks), np.asarray(sigmas)
    ratio = np.std(ks) / np.mean(sigmas)
    z_rms = float(np.sqrt(np.mean(((ks - rrw) / sigmas) ** 2)))
    assert 0.8 < ratio < 1.25, (ratio, z_rms)
    assert 0.8 < z_rms < 1.3, (ratio, z_rms)


def test_kinds_without_the_covariance_say_so():
    """adev, angle data with gaps and a hand-made result fall back to independent τ points
    and name why in `method`; bias instability's flicker is flagged as approximated."""
    rng = np.random.default_rng(1)
    y = rng.normal(size=512) + 0.01 * np.cumsum(rng.normal(size=512))
    fit = allan.fit_noise(allan.deviation(y, 1.0, kind="adev"), terms=TERMS)
    assert fit.method.startswith("independent: adev")
    gappy = np.cumsum(y)  # angles
    gappy[100:110] = np.nan
    fit = allan.fit_noise(allan.deviation(gappy, 1.0, kind="oadev", data="phase"), terms=TERMS)
    assert fit.method.startswith("independent: a record with gaps")
    fit = allan.fit_noise(allan.deviation(y, 1.0, kind="oadev"))
    assert fit.method == "gls, flicker approximated"
    assert all(fit.low[t] <= fit.value[t] <= fit.high[t] for t in fit.value)


def test_gapped_covariance_is_the_quadratic_forms_covariance():
    """gapped_covariance against the Gaussian law built here: 130 rate samples every 0.5 s,
    missing at 41, 77–79 and 100, with quantization, white rate noise, a rate random walk, a
    ramp and two Gauss–Markov terms (T 3 s and 40 s: correlated across the gaps) — the rate
    samples' covariance written out (interval means), the angle's white noise added, and
    Cov(σ̂²_a, σ̂²_b) = Σ 2C² + 4μμC over the differences clear of the gaps. Agreement
    3e-5 of the entries (measured 7e-13; the gap-free covariance at 130 samples is 0.72 off)."""
    from hrgjax.allan.octave_covariance import gapped_covariance

    n, tau0, ms = 130, 0.5, [1, 2, 4, 8, 16]
    q, arw, rrw, ramp, gm = 0.3, 1.0, 0.05, 0.01, [(0.5, 3.0), (0.7, 40.0)]
    ok = np.ones(n, dtype=bool)
    ok[41] = ok[77:80] = ok[100] = False
    j = np.arange(n)
    d = np.abs(np.subtract.outer(j, j))
    low = np.minimum.outer(j, j)
    sy = arw**2 / tau0 * np.eye(n) + rrw**2 * tau0 * np.where(d == 0, low + 1 / 3, low + 0.5)
    for s2, big_t in gm:  # interval means of a Gauss–Markov rate of variance s2
        e = tau0 / big_t
        sy += s2 * np.where(d == 0, 2 * (e - 1 + math.exp(-e)) / e**2,
                            np.exp(-e * (d - 1.0)) * (1 - math.exp(-e)) ** 2 / e**2)  # fmt: skip
    x = np.vstack([np.zeros(n), np.tril(np.ones((n, n)))])  # X_k = Σ_{i<k} y_i
    sx = x @ sy @ x.T + (q / tau0) ** 2 * np.eye(n + 1)
    mean_x = x @ (ramp * tau0 * (j + 0.5))
    rows = []
    for m in ms:
        starts = [i for i in range(n + 1 - 2 * m) if ok[i : i + 2 * m].all()]
        r = np.zeros((len(starts), n + 1))
        for k, i in enumerate(starts):
            r[k, [i, i + m, i + 2 * m]] = np.array([1.0, -2.0, 1.0]) / (m * math.sqrt(2))
        rows.append(r)
    want = np.zeros((len(ms), len(ms)))
    for a, ra in enumerate(rows):
        for b, rb in enumerate(rows):
            c = ra @ sx @ rb.T
            mu = np.outer(ra @ mean_x, rb @ mean_x)
            want[a, b] = np.sum(2 * c * c + 4 * mu * c) / (len(ra) * len(rb))
    edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
    runs = np.stack([edges[::2], edges[1::2] - edges[::2]], axis=1)
    coef = {"quantization": q**2, "angle_random_walk": arw**2, "rate_random_walk": rrw**2,
            "rate_ramp": ramp**2}  # fmt: skip
    got = gapped_covariance(coef, gm, ms, runs, tau0)
    scale = np.sqrt(np.outer(np.diag(want), np.diag(want)))
    np.testing.assert_allclose(got / scale, want / scale, atol=3e-5)


def test_a_gapped_fit_builds_each_runs_layout_once(monkeypatch):
    """Review of 56065c5: the runs' layouts sat in an LRU of 64, which a record of more
    distinct run lengths thrashed on each of the fit's 6–7 covariance evaluations (10⁵
    samples, 1 % missing: 282 lengths, fit_noise 8–14 s; now 1 s). 100 distinct lengths:
    each layout is built once for the fit, and a shared store changes no entry."""
    from hrgjax.allan import octave_covariance as oc

    built = []
    original = oc._layout

    def counting(ms, n):
        return original(ms, n)

    def wrapped(ms, n):
        built.append((ms, n))
        return original.__wrapped__(ms, n)

    counting.__wrapped__ = wrapped
    monkeypatch.setattr(oc, "_layout", counting)
    lengths = np.arange(30, 130)
    y = np.random.default_rng(11).normal(size=int(lengths.sum() + lengths.size))
    y[np.cumsum(lengths + 1) - 1] = np.nan  # one missing sample after each run
    r = allan.deviation(y, 1.0, taus="octave")
    assert r.segments.shape[0] == lengths.size
    fit = allan.fit_noise(r, terms=("angle_random_walk",))
    assert fit.method == "gls" and fit.value["angle_random_walk"] == pytest.approx(1.0, rel=0.05)
    assert len(built) == len(set(built)) == lengths.size  # each once (the LRU: 7× each)
    ms, tau0 = np.asarray(r.m, dtype=int), float(r.taus[0] / r.m[0])
    store = {}
    first = oc.gapped_covariance({"angle_random_walk": 1.0}, [(0.1, 20.0)], ms, r.segments,
                                 tau0, layouts=store)  # fmt: skip
    again = oc.gapped_covariance({"angle_random_walk": 2.0}, [(0.3, 5.0)], ms, r.segments,
                                 tau0, layouts=store)  # fmt: skip
    alone = oc.gapped_covariance({"angle_random_walk": 2.0}, [(0.3, 5.0)], ms, r.segments, tau0)
    np.testing.assert_array_equal(again, alone)
    assert len(store) == lengths.size and not np.array_equal(first, again)
    # review of f0f7e34: the store was unbounded (10⁶ samples, 0.1 % missing: 0.8 GB; 10⁷:
    # ~2.7 GB): it holds at most LAYOUT_STORE_BYTES, the rest built again, the same Ω
    sizes = sorted(map(oc._nbytes, store.values()))
    cap = sum(sizes[: lengths.size // 3])
    monkeypatch.setattr(oc, "LAYOUT_STORE_BYTES", cap)
    small, built[:] = {}, []
    for _ in range(2):
        capped = oc.gapped_covariance({"angle_random_walk": 2.0}, [(0.3, 5.0)], ms, r.segments,
                                      tau0, layouts=small)  # fmt: skip
        np.testing.assert_array_equal(capped, alone)
    held = sum(map(oc._nbytes, small.values()))
    assert 0 < len(small) < lengths.size and held <= cap
    assert len(built) == 2 * lengths.size - len(small)  # past the cap: built on each call


class _Bar:
    """A stand-in for `hrgjax._progress.bar` that records what a bar was told."""

    made: list = []

    def __init__(self, total, desc, unit="step", **_):
        self.total, self.n, self.desc = total, 0, desc
        _Bar.made.append(self)

    def update(self, n=1):
        self.n += n

    def refresh(self):
        pass

    def set_postfix_str(self, *_):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


def test_a_gapped_fit_counts_its_covariance_work_on_a_bar(monkeypatch):
    """Scale audit: fit_noise on 3·10⁵–3·10⁶ gapped samples sat silent 11–84 s in the
    exact gapped covariance. Its bar counts each distinct run length of each Ω evaluation
    (4 rounds + 1 at the fit + 1 per term above 0), and ends at its total."""
    from hrgjax.allan import noise_terms

    monkeypatch.setattr(noise_terms, "bar", _Bar)
    _Bar.made = []
    lengths = np.repeat(np.arange(40, 70), 2)  # 30 distinct lengths, each twice
    y = np.random.default_rng(5).normal(size=int(lengths.sum() + lengths.size))
    y[np.cumsum(lengths + 1) - 1] = np.nan
    r = allan.deviation(y, 1.0, taus="octave")
    terms = ("angle_random_walk", "rate_random_walk")
    fit = allan.fit_noise(r, terms=terms)
    assert fit.method == "gls"
    (b,) = _Bar.made
    positive = sum(fit.value[t] > 0 for t in terms)
    assert b.n == b.total == (noise_terms._ROUNDS + 1 + positive) * 30
    _Bar.made = []
    allan.fit_noise(allan.deviation(y[np.isfinite(y)], 1.0, taus="octave"), terms=terms)
    assert _Bar.made == []  # a gap-free record's Ω is one closed form: no bar
