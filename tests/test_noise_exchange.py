"""Noise-model exchange (identify_noise ↔ Kalibr, ↔ the simulator): rate samples that are
interval means (Δθ/Δt) have the continuous process's Allan variance — IEEE 952 Annex C's for a
Gauss–Markov rate, K²τ/3 for a rate random walk — and the octaves' exact covariance; Kalibr's
white-noise-plus-random-walk entries carry the white angle noise and the Gauss–Markov terms
instead of dropping them. Truths: 50-digit closed forms (`decimal`), the exact Gaussian
covariance of the estimates as quadratic forms in the angle, records drawn from the exact
joint law of a Gauss–Markov rate and its interval integral, a record's per-sample variance."""

import math
from decimal import Decimal, localcontext

import numpy as np
import pytest
from helpers import octave_pairs

import hrgjax as hg
from hrgjax.allan import octave_covariance as oc


def ieee_markov_avar(s2, t_c, tau):
    """IEEE 952 Annex C: σ²(τ) = (2σ²T/τ)[1 − T/(2τ)(3 − 4e^{−τ/T} + e^{−2τ/T})], in 50
    digits (the bracket cancels to (τ/T)/3 where τ ≪ T)."""
    with localcontext() as ctx:
        ctx.prec = 50
        s2, t_c, tau = Decimal(s2), Decimal(t_c), Decimal(tau)
        x = tau / t_c
        br = 1 - (3 - 4 * (-x).exp() + (-2 * x).exp()) / (2 * x)
        return float(2 * s2 * br / x)


def ou_angle_structure(s2, t_c, t):
    """E[(θ(t) − θ(0))²] of the integral of a stationary Gauss–Markov rate: 2σ²T²(t/T − 1 +
    e^{−t/T}), in 50 digits."""
    with localcontext() as ctx:
        ctx.prec = 50
        s2, t_c, t = Decimal(s2), Decimal(t_c), Decimal(t)
        return float(2 * s2 * t_c * t_c * (t / t_c - 1 + (-t / t_c).exp()))


def test_gauss_markov_allan_variance_of_interval_means_is_ieee_952_annex_c():
    """`unit_avar("gauss_markov")` — the default, interval means — equals Annex C's Markov
    Allan variance to 1e-10 from T = 0.3τ₀ to 10⁵τ₀ and τ = τ₀ to 4 096τ₀ (the old model,
    point samples of an AR(1), is 1.54× it at τ₀ for T = 10τ₀)."""
    tau0 = 0.1
    ms = np.array([1, 2, 3, 8, 100, 4096], dtype=float)
    for t_c in (0.03, 0.1, 1.0, 10.0, 1e3, 1e4):
        got = oc.unit_avar("gauss_markov", ms, tau0, tau0 / t_c)
        ref = np.array([ieee_markov_avar(1.0, t_c, m * tau0) for m in ms])
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=0)


def test_the_angle_structure_is_the_continuous_one_across_the_series_switch():
    """The Gauss–Markov G is −D/2 with D the integrated rate's structure function, accurate
    to 1e-13 at εt from 1e-9 (its series) through the switch at 0.1 to 10³ (closed form)."""
    tau0, t_c = 1.0, 1e3
    g = oc.term_g("gauss_markov", tau0, tau0 / t_c)
    ts = np.array([1e-6, 1.0, 7.0, 99.0, 99.999, 100.0, 100.001, 101.0, 3e3, 1e6])
    ref = [ou_angle_structure(1.0, t_c, t * tau0) / tau0**2 for t in ts]
    np.testing.assert_allclose(-2.0 * g(ts), ref, rtol=1e-13)
    assert -2.0 * float(g(np.float64(100.0))) == pytest.approx(ref[5], rel=1e-13)  # a scalar


def test_rate_random_walk_of_interval_means_is_k2_tau_over_3():
    """A continuous rate random walk's interval means have IEEE 952's K²τ/3 exactly; point
    samples of a discrete walk keep the + K²τ₀/(6m) of their steps."""
    tau0, ms = 0.25, np.array([1.0, 2.0, 5.0, 64.0])
    np.testing.assert_allclose(oc.unit_avar("rate_random_walk", ms, tau0), ms * tau0 / 3,
                               rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose(oc.unit_avar("rate_random_walk", ms, tau0, sampling="point"),
                               ms * tau0 / 3 + tau0 / (6 * ms), rtol=1e-12)  # fmt: skip


def test_sampling_is_an_explicit_argument_not_context_state():
    """`sampling` reaches every Allan variance and covariance as an argument: the public
    functions default to a plain `"interval"` (no context manager or module state can
    change what a call without it returns), and `"point"` changes the random walk's
    covariance."""
    import inspect

    for fn in (oc.unit_avar, oc.term_g, oc.covariance):
        assert inspect.signature(fn).parameters["sampling"].default == "interval", fn
    coef, ms, n, tau0 = {"angle_random_walk": 1.0, "rate_random_walk": 1e-3}, [1, 2, 4], 256, 0.5
    default = oc.covariance(coef, [(0.1, 3.0)], ms, n, tau0)
    np.testing.assert_array_equal(default, oc.covariance(coef, [(0.1, 3.0)], ms, n, tau0,
                                                         sampling="interval"))  # fmt: skip
    assert not np.allclose(default, oc.covariance(coef, [(0.1, 3.0)], ms, n, tau0,
                                                  sampling="point"))  # fmt: skip


def test_point_samples_keep_the_ar1_model():
    """`sampling="point"`: the Allan variance of point samples of an AR(1) rate (variance
    σ² = 1, φ = e^{−τ₀/T}) from its autocovariance φ^{|k|} summed directly."""
    tau0, t_c = 0.5, 4.0
    phi = math.exp(-tau0 / t_c)
    for m in (1, 2, 3, 16):
        w = np.r_[-np.ones(m), np.ones(m)] / m  # ȳ₂ − ȳ₁
        k = np.arange(2 * m)
        r = phi ** np.abs(k[:, None] - k[None, :])
        ref = w @ r @ w / 2
        got = oc.unit_avar("gauss_markov", float(m), tau0, tau0 / t_c, sampling="point")
        assert got == pytest.approx(ref, rel=1e-12)
    with pytest.raises(ValueError, match="sampling must be one of"):
        oc.unit_avar("gauss_markov", 1.0, tau0, 0.1, sampling="points")


def angle_covariance(t, q2, n2, k2, gm):
    """Cov(θ(s), θ(t)) at the sample instants `t` [s], θ(0) = 0: white angle noise q2 per
    sample, a Brownian angle n2·min(s, t), an integrated Brownian motion k2(s²t/2 − s³/6)
    (s ≤ t) and integrated stationary Gauss–Markov rates ½[D(s) + D(t) − D(|t − s|)], D(x) =
    2σ²T²(v − 1 + e^{−v}), v = x/T, by its Taylor series σ²x²·2Σ(−v)ᵏ/(k + 2)! where v < 0.1
    (the closed form cancels there)."""
    s, u = np.minimum.outer(t, t), np.maximum.outer(t, t)
    cov = q2 * np.eye(t.size) + n2 * s + k2 * (s * s * u / 2 - s**3 / 6)
    for s2, t_c in gm:

        def d(x, s2=s2, t_c=t_c):
            v = x / t_c
            series = sum(2 * (-v) ** k / math.factorial(k + 2) for k in range(12))
            return np.where(v < 0.1, s2 * x * x * series, 2 * s2 * t_c**2 * (v - 1 + np.exp(-v)))

        cov += 0.5 * (d(s) + d(u) - d(u - s))
    return cov


def test_covariance_of_interval_means_is_the_quadratic_forms():
    """The octaves' covariance for a record of 300 interval means (Q, N, K, a drift R, a
    fast, a mid and a slow Gauss–Markov rate — the last, T = 2·10⁴ samples, on the pointwise
    path) equals the exact Gaussian covariance of the estimates as quadratic forms θᵀAθ in
    the angle at the sample instants — 2 tr(AΣBΣ) + 4μᵀAΣBμ with Σ from the continuous
    processes' closed forms — to 1e-6 of the diagonal (its pieces are under 48 lags: summed
    exactly); the means tr(AΣ) + μᵀAμ equal `unit_avar`'s sum to 1e-10."""
    n, tau0, ms = 300, 0.5, [1, 2, 4, 8, 16, 32]
    q2, n2, k2, r2 = 1e-3, 1e-3, 1e-5, 1e-7
    gm = [(0.04, 1.5), (0.02, 40.0), (0.03, 1e4)]
    t = tau0 * np.arange(n + 1)
    sigma = angle_covariance(t, q2, n2, k2, gm)
    mu = math.sqrt(r2) * t**2 / 2  # θ of a drift y = R·t
    forms = []
    for m in ms:
        d = np.zeros((n + 1 - 2 * m, n + 1))
        i = np.arange(d.shape[0])
        d[i, i], d[i, i + m], d[i, i + 2 * m] = 1.0, -2.0, 1.0
        forms.append(d.T @ d / (2 * (m * tau0) ** 2 * d.shape[0]))
    a_sigma = [a @ sigma for a in forms]  # tr(AΣBΣ) = Σ (AΣ) ∘ (BΣ)ᵀ
    ref = np.array([[2 * np.sum(x * y.T) + 4 * mu @ x @ b @ mu
                     for y, b in zip(a_sigma, forms, strict=True)] for x in a_sigma])  # fmt: skip
    coef = {"quantization": q2, "angle_random_walk": n2, "rate_random_walk": k2, "rate_ramp": r2}
    got = oc.covariance(coef, gm, ms, n, tau0)
    scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    np.testing.assert_allclose(got / scale, ref / scale, atol=1e-6)
    mean = np.array([np.trace(a @ sigma) + mu @ a @ mu for a in forms])
    m = np.asarray(ms, dtype=float)
    model = sum(c * oc.unit_avar(name, m, tau0) for name, c in coef.items())
    model = model + sum(s2 * oc.unit_avar("gauss_markov", m, tau0, tau0 / tc) for s2, tc in gm)
    np.testing.assert_allclose(model, mean, rtol=1e-10)


def filter_covariance(n2, k2, gm, ms, n, tau0):
    """The octaves' covariance summed over every lag ℓ, each c(ℓ) = Σ_d w(d)·r(ℓ + d) from the
    interval means' autocovariance r (white: N²/τ₀ at 0; a Gauss–Markov rate:
    2σ²T²(ε − 1 + φ)/τ₀² at 0, σ²T²(1 − φ)²φ^{k−1}/τ₀² at k ≥ 1) and the second
    differences' filters h (−1 × m, +1 × m), w = h_a ⋆ h_b; a continuous random walk's interval
    means as a discrete walk's (its steps through h's running sums) less a white rate of
    K²τ₀/6 per sample (their G differ by |t|/12)."""
    from scipy.signal import fftconvolve

    out = np.zeros((len(ms), len(ms)))
    for a, b, ma, mb, na, nb, ell, ha, hb in octave_pairs(ms, n):
        w = np.correlate(hb, ha, "full")  # w[d + 2ma − 1] = Σ_{k − j = d} h_a(j)h_b(k)
        k = np.arange(-(n + 2 * ma + 2 * mb), n + 2 * ma + 2 * mb + 1)  # the rate's lags
        r = np.where(k == 0, n2 / tau0, 0.0)
        for s2, t_c in gm:
            phi, kk, e = math.exp(-tau0 / t_c), np.abs(k), math.expm1(-tau0 / t_c)
            r0 = 2 * s2 * t_c**2 * (tau0 / t_c + e) / tau0**2
            r = r + np.where(kk == 0, r0, s2 * t_c**2 * e * e * phi ** (np.maximum(kk, 1) - 1.0)
                             / tau0**2)  # fmt: skip
        c = fftconvolve(r, w[::-1])[ell - k[0] + 2 * mb - 1]
        if k2:
            ga, gb = np.cumsum(ha[::-1])[::-1], np.cumsum(hb[::-1])[::-1]
            walk = np.convolve(ga[::-1], gb) * k2 * tau0
            idx = 2 * ma - 1 - ell
            ok = (idx >= 0) & (idx < walk.size)
            c[ok] += walk[idx[ok]]
            ok = (idx >= 0) & (idx < w.size)  # the white rate's c(ℓ) = w(−ℓ)
            c[ok] -= k2 * tau0 / 6 * w[idx[ok]]
        count = np.maximum(np.minimum(na, nb - ell) - np.maximum(0, -ell), 0)
        out[a, b] = out[b, a] = np.sum(count * 2 * c * c) / (4.0 * ma**2 * mb**2 * na * nb)
    return out


def test_covariance_of_a_long_record_of_interval_means_equals_the_sum_over_every_lag():
    """10⁵ interval means (N, K, a Gauss–Markov rate of T = 6 samples and one of 4·10⁴): the
    piecewise quadrature equals the direct sum over every lag to 1e-4 of the diagonal."""
    tau0, ms, n = 0.5, [1, 2, 8, 64], 100_000
    n2, k2, gm = 1e-4, 1e-4, [(0.1, 3.0), (0.1, 2e4)]
    ref = filter_covariance(n2, k2, gm, ms, n, tau0)
    got = oc.covariance({"angle_random_walk": n2, "rate_random_walk": k2}, gm, ms, n, tau0)
    scale = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    np.testing.assert_allclose(got / scale, ref / scale, atol=1e-4)


def gauss_markov_record(rng, n, tau0, s2, t_c):
    """A stationary Gauss–Markov rate of variance s2 and time t_c: its point samples r_k and
    interval means ∫r/τ₀ over each interval, drawn from their exact joint law (the integral
    regressed on the step's innovation)."""
    from scipy.signal import lfilter

    phi = math.exp(-tau0 / t_c)
    v1 = s2 * (1 - phi**2)  # r_{k+1} = φr_k + w1
    v2 = s2 * t_c**2 * (2 * (tau0 / t_c - 1 + phi) - (1 - phi) ** 2)  # I_k = T(1 − φ)r_k + w2
    c12 = s2 * t_c * (1 - phi) ** 2
    w1, z = rng.normal(size=(2, n))
    r0 = math.sqrt(s2) * rng.normal()
    steps = lfilter([1.0], [1.0, -phi], math.sqrt(v1) * w1, zi=[phi * r0])[0]  # r_1 … r_n
    r_prev = np.r_[r0, steps[:-1]]  # r_k at the start of each interval
    w2 = c12 / math.sqrt(v1) * w1 + math.sqrt(v2 - c12**2 / v1) * z
    return r_prev, (t_c * (1 - phi) * r_prev + w2) / tau0


def test_the_exact_gauss_markov_record_has_the_continuous_allan_variance():
    """The record generator above (this file's truth for the identification) gives interval
    means whose Allan variance is Annex C's: the mean over 400 records within 3 %."""
    rng = np.random.default_rng(1)
    tau0, t_c, ms = 0.1, 1.0, np.array([1, 2, 4])
    est = []
    for _ in range(400):
        _, y = gauss_markov_record(rng, 512, tau0, 1.0, t_c)
        x = np.r_[0.0, np.cumsum(y)]
        est.append([np.mean((x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]) ** 2) / (2 * m * m)
                    for m in ms])  # fmt: skip
    ref = [ieee_markov_avar(1.0, t_c, m * tau0) for m in ms]
    np.testing.assert_allclose(np.mean(est, axis=0), ref, rtol=0.03)


@pytest.fixture(scope="module")
def gauss_markov_records():
    """2¹⁷ samples at 10 Hz of a Gauss–Markov rate (σ = 1 rad/s, T = 10 s: 100 samples)
    plus white rate noise N = 0.01 rad/s·√s, as interval means and as point samples."""
    rng = np.random.default_rng(5)
    n, fs = 2**17, 10.0
    point, mean = gauss_markov_record(rng, n, 1 / fs, 1.0, 10.0)
    white = 0.01 * math.sqrt(fs) * rng.normal(size=n)
    return point + white, mean + white, fs


def test_identify_recovers_a_gauss_markov_rate_from_its_interval_means(gauss_markov_records):
    """Interval means (the default `sampling`): T = 10 s and σ = 1 inside their 95 %
    intervals, the white noise kept, and the model fits (before: the point-sample model
    took T ≈ 13 s with its interval excluding 10, J in the thousands and N = 0)."""
    _, y, fs = gauss_markov_records
    model = hg.allan.identify_noise(y, fs, unit="rad/s", gauss_markov=1,
                                    terms=("angle_random_walk",))  # fmt: skip
    gm = model.terms["gauss_markov_1"]
    assert gm["correlation_time"]["low"] < 10.0 < gm["correlation_time"]["high"]
    assert gm["sigma"]["low"] < 1.0 < gm["sigma"]["high"]
    assert model.p_value > 1e-3
    n = model.terms["angle_random_walk"]
    assert n["low"] < 0.01 < n["high"]
    assert model.sampling == "interval" and model.to_dict()["sampling"] == "interval"


def test_point_sampling_recovers_a_gauss_markov_rate_from_its_point_samples(
    gauss_markov_records,
):
    """`sampling="point"`: the same rate's point samples give T and σ within their
    intervals, and the model's Allan variance is the point-sample one."""
    y, _, fs = gauss_markov_records
    model = hg.allan.identify_noise(y, fs, unit="rad/s", gauss_markov=1,
                                    terms=("angle_random_walk",), sampling="point")  # fmt: skip
    gm = model.terms["gauss_markov_1"]
    assert gm["correlation_time"]["low"] < 10.0 < gm["correlation_time"]["high"]
    assert gm["sigma"]["low"] < 1.0 < gm["sigma"]["high"]
    s, t_c = gm["sigma"]["value"], gm["correlation_time"]["value"]
    want = s**2 * oc.unit_avar("gauss_markov", 1.0, 0.1, 0.1 / t_c, sampling="point")
    assert model.term_avar("gauss_markov_1", [0.1])[0] == pytest.approx(want, rel=1e-12)
    with pytest.raises(ValueError, match="sampling must be one of"):
        hg.allan.identify_noise(y[:256], fs, sampling="sampled")


def test_to_kalibr_carries_the_white_angle_noise_at_the_record_rate(tmp_path):
    """White angle noise Q = 1.805 °/h·s and white rate noise N = 0.12 °/h·√s at 1 Hz
    (docs/allan.md's default gyro): Kalibr's per-sample σ, noise_density/√Δt, is the
    record's own per-sample σ (2.55 °/h; before: N alone, 0.12 °/h, 21× below) — within
    2 % — and √(N² + 2Q²/Δt) of the identified Q and N; the file says the fold holds at this
    update rate only."""
    rng = np.random.default_rng(4)
    fs, n, q, nn = 1.0, 20_000, 1.805, 0.12
    angle = q * rng.normal(size=n + 1) + np.r_[0.0, np.cumsum(nn * rng.normal(size=n))]
    y = np.diff(angle) * fs
    model = hg.allan.identify_noise(y, fs, unit="°/h")
    out = model.to_kalibr(tmp_path / "imu.yaml")
    sd = out["gyroscope_noise_density"] * math.sqrt(fs) / hg.units.DEG_PER_H
    assert sd == pytest.approx(y.std(), rel=0.02)
    assert sd == pytest.approx(math.sqrt(nn**2 * fs + 2 * q**2 * fs**2), rel=0.02)
    qm, nm = model.value("quantization"), model.value("angle_random_walk")
    assert sd == pytest.approx(math.sqrt(nm**2 * fs + 2 * qm**2 * fs**2), rel=1e-12)
    text = (tmp_path / "imu.yaml").read_text(encoding="utf-8")
    assert "folded in" in text and "this update_rate only" in text


def composite(terms, bounds=None, unit="rad/s", rate_hz=10.0):
    """A `CompositeNoise` with the given terms (values only; intervals equal to them)."""

    def spec(v, u):
        return {"value": v, "low": v, "high": v, "unit": u}

    out = {}
    for name, v in terms.items():
        if name.startswith("gauss_markov"):
            out[name] = {"sigma": spec(v[0], unit), "correlation_time": spec(v[1], "s")}
        else:
            out[name] = spec(v, unit)
    return hg.allan.CompositeNoise(terms=out, unit=unit, rate_hz=rate_hz, n=10**6, ci=0.95,
                                   taus=np.ones(1), avar=np.ones(1), covariance=np.ones((1, 1)),
                                   chi2=1.0, dof=1, p_value=0.5, bounds=bounds or {})  # fmt: skip


def test_to_kalibr_carries_gauss_markov_terms_as_their_short_time_random_walk(tmp_path):
    """A Gauss–Markov bias (σ, T) has E[(b(t + h) − b(t))²] = 2σ²(1 − e^{−h/T}) → (2σ²/T)·h:
    a random walk K² = 2σ²/T at h ≪ T (taken at h = 10⁻⁶T). With no rate random walk
    detected Kalibr's random_walk is that (before: K's upper bound, 8.7× below for σ = 5 °/h,
    T = 300 s); with K and two terms, √(K² + Σ2σᵢ²/Tᵢ)."""
    sig, t_c = 5 * hg.units.DEG_PER_H, 300.0
    h = 1e-6 * t_c
    walk = math.sqrt(2 * sig**2 * -math.expm1(-h / t_c) / h)
    model = composite({"angle_random_walk": 3e-6, "gauss_markov_1": (sig, t_c)},
                      bounds={"rate_random_walk": 2.3e-7})  # fmt: skip
    out = model.to_kalibr(tmp_path / "imu.yaml")
    assert out["gyroscope_random_walk"] == pytest.approx(walk, rel=1e-6)
    assert out["gyroscope_noise_density"] == pytest.approx(3e-6, rel=1e-12)
    assert "Gauss-Markov" in (tmp_path / "imu.yaml").read_text(encoding="utf-8")
    two = composite({"angle_random_walk": 3e-6, "rate_random_walk": 1e-6,
                     "gauss_markov_1": (sig, t_c), "gauss_markov_2": (2 * sig, 30.0)})  # fmt: skip
    want = math.sqrt(1e-12 + 2 * sig**2 / t_c + 2 * (2 * sig) ** 2 / 30.0)
    assert two.to_kalibr()["gyroscope_random_walk"] == pytest.approx(want, rel=1e-12)
    # nothing to fold: the bounds, as before
    bare = composite({"angle_random_walk": 3e-6}, bounds={"rate_random_walk": 2.3e-7})
    assert bare.to_kalibr()["gyroscope_random_walk"] == pytest.approx(2.3e-7, rel=1e-12)


def test_allan_cli_passes_the_sampling_and_refuses_it_without_a_fit(tmp_path, monkeypatch, capsys):
    """`hrgjax allan --sampling point` reaches `identify_noise` (the CLI had no way to say a
    sensor samples its rate: N read 3.8× too large on such a record), and is refused, not
    ignored, without --fit or --kalibr."""
    from helpers import cli_fails

    from hrgjax import allan
    from hrgjax.cli import main

    path = tmp_path / "rate.csv"
    y = np.random.default_rng(0).standard_normal(4096)
    np.savetxt(path, y[:, None], delimiter=",", header="gyro", comments="")
    seen = []
    real = allan.identify_noise

    def spy(*args, **kw):
        seen.append(kw.get("sampling"))
        return real(*args, **kw)

    monkeypatch.setattr(allan, "identify_noise", spy)
    assert main(["allan", str(path), "--rate-hz", "1", "--fit", "--sampling", "point"]) == 0
    assert main(["allan", str(path), "--rate-hz", "1", "--fit"]) == 0
    assert seen == ["point", "interval"]
    cli_fails(["allan", str(path), "--rate-hz", "1", "--sampling", "point"], capsys,
              "--sampling is for --fit and --kalibr")  # fmt: skip
