"""Logger stalls and short-correlated noise (audit of gaps): a uniform 100-Hz log with one
interval of 3.5 steps was put on one grid from its first stamp, every later sample read
between two (white noise 0.50× at τ₀ after the stall, the record's χ² interval excluding
the truth through 4τ₀); a 1.5-step interval moved the rate to 99.9987 Hz; and a
Gauss–Markov term of T ≈ 1.5 Δt (a digital low-pass) went to Kalibr as a random walk
2σ²/T (noise density 0.28×, random walk 6.4 °/h/√s for none)."""

import dataclasses

import numpy as np
import pytest

import hrgjax as hg
from hrgjax._timebase import regular_step

FS, N = 100.0, 8000


@pytest.fixture(scope="module")
def white():
    return np.random.default_rng(3).normal(size=N)


@pytest.mark.parametrize("extra, nans", [(2.5, 4), (0.5, 2), (0.4, 1), (-0.3, 1)])
def test_a_stall_keeps_every_other_sample(white, extra, nans):
    """One interval of 1 + `extra` steps: the grid starts anew after it, the samples on both
    sides are the record's own (allantools on each uniform half agrees), the stall's sample
    and the time it lasted are NaN (Stable32's gap convention: the nearest whole number of
    steps), and white noise reads σ(m) = 1/√m within its χ² interval."""
    at = pytest.importorskip("allantools")
    t = np.arange(N) / FS
    t[N // 2 :] += extra / FS
    assert 1.0 / regular_step(t) == pytest.approx(FS, rel=1e-12)  # 99.9987 Hz at 1.5 steps
    u = hg.allan.to_uniform(t, white)
    gap = np.isnan(u.y)
    np.testing.assert_array_equal(np.flatnonzero(gap), N // 2 - 1 + np.arange(nans))
    kept = np.r_[white[1 : N // 2], white[N // 2 + 1 :]]
    np.testing.assert_allclose(u.y[~gap], kept, rtol=0, atol=1e-9)
    after = u.y[N // 2 - 1 + nans :]
    r = hg.allan.deviation(after, FS, taus=[0.01, 0.04])
    _, ref, _, _ = at.oadev(white[N // 2 + 1 :], rate=FS, data_type="freq", taus=r.taus)
    np.testing.assert_allclose(r.dev, ref, rtol=1e-9)  # was 0.50× at τ₀
    whole = hg.allan.deviation(u.y, FS, taus=[0.01, 0.02, 0.04])
    truth = 1 / np.sqrt(whole.m)
    sigma = (whole.dev_high - whole.dev_low) / 2
    assert np.all(np.abs(whole.dev - truth) < 3 * sigma), whole.dev / truth
    assert u.rate_hz == pytest.approx(FS, rel=1e-12) and u.interpolated == 0
    assert u.breaks == ((t[N // 2 - 1], t[N // 2]),)


@pytest.mark.parametrize("tick", [0.0, 1e-3, 1 / 32768])
def test_two_percent_of_stalls_keep_the_rate_and_the_samples(white, tick):
    """Review of f0f7e34: the close band was centred on the mean of every regular step, which
    stalls move; past ~0.25 % of 1.4-step stalls the rate read 1.8e-3 … 7.7e-3 fast and the
    whole record was interpolated (white noise 0.70x at τ₀). 2 % of them now leave the
    rate exact, on a plain grid, on a crystal-tick clock and on `millis()` stamps at 60 Hz
    (16 or 17 ms: steps a tick off are the clock's own pattern, not stalls)."""
    rate = 60.0 if tick == 1e-3 else FS
    n = np.arange(N)
    ticks = np.floor(n / rate / tick + 0.5) if tick else n.astype(float)
    dt = np.diff(ticks)
    stall = np.random.default_rng(4).random(N - 1) < 0.02
    dt[stall] += np.round(0.4 * dt[stall]) if tick else 0.4
    t = np.r_[0.0, np.cumsum(dt)] * (tick or 1 / rate)
    truth = (N - 1) / (ticks[-1] - ticks[0]) / (tick or 1 / rate)  # the clock's mean rate
    assert 1.0 / regular_step(t) == pytest.approx(truth, rel=1e-4 if tick else 1e-12)
    if not tick:
        u = hg.allan.to_uniform(t, white)
        assert u.rate_hz == pytest.approx(FS, rel=1e-12)
        assert u.interpolated < 0.05 * N and len(u.breaks) > 100  # was all of them, no break
        d = np.diff(u.y)
        assert np.sqrt(0.5 * np.nanmean(d**2)) == pytest.approx(1.0, abs=0.05)  # was 0.70


def test_jittered_stamps_stay_on_one_grid_and_angles_keep_their_rate(white):
    """Stamps jittered ±30 %: no run is on a grid of its own, so nothing is re-anchored (the
    documented resampling, every sample read between stamps). Angle samples across a stall
    keep their samples, the record's mean rate on each point's nominal time."""
    dt = np.random.default_rng(5).uniform(0.7, 1.3, size=N - 1) / FS
    t = np.concatenate([[0.0], np.cumsum(dt)])
    u = hg.allan.to_uniform(t, white)
    assert u.breaks == () and not np.isnan(u.y).any() and u.interpolated == u.y.size
    t = np.arange(N) / FS
    t[N // 2 :] += 0.5 / FS
    x = 30.0 * t + np.cumsum(white) / FS  # a 30 °/s turn plus white rate noise, in °
    p = hg.allan.to_uniform(t, x, data="phase")
    gap = np.isnan(p.y)
    np.testing.assert_array_equal(np.flatnonzero(gap), [N // 2])
    nominal = np.flatnonzero(~gap) / FS  # each sample's time on the grid (half a step
    rate = (x[-1] - x[0]) / (t[-1] - t[0])  # from the stamp after the stall): the mean rate's
    np.testing.assert_allclose(p.y[~gap] - rate * nominal, x - rate * t, rtol=0, atol=1e-9)


def test_kalibr_takes_a_short_gauss_markov_term_as_white_noise():
    """A 100-Hz white rate (1 °/h per sample) through a first-order digital low-pass
    y_k = ½y_{k−1} + ½e_k: its PSD at low frequency is that of e, so N = 1 °/h·√(0.01 s)
    = 0.1 °/h·√s and there is no random walk. The model takes a Gauss–Markov term of T ≈
    1.5 Δt; Kalibr's file gets N² + 2σ²T (the old export: 0.28 × N, K 6.4 °/h/√s), and the
    exported model's Allan variance N²/τ meets the data's from τ = 10 T."""
    pytest.importorskip("scipy")
    from scipy.signal import lfilter

    e = np.random.default_rng(7).normal(size=40_000)
    y = lfilter([0.5], [1.0, -0.5], e)
    model = hg.allan.identify_noise(y, FS, unit="°/h")
    out = model.to_kalibr()
    si = np.pi / 180 / 3600  # °/h → rad/s
    truth = 0.1 * si
    assert out["gyroscope_noise_density"] == pytest.approx(truth, rel=0.05)
    assert out["gyroscope_random_walk"] < 1e-6  # rad/s²/√Hz: an absent K's bound (was 3e-5)
    n_export = out["gyroscope_noise_density"] / si
    r = hg.allan.deviation(y, FS, taus=[0.01, 0.04, 0.16, 0.32, 0.64, 1.28])
    white = n_export / np.sqrt(r.taus)
    assert np.all(white > r.dev)  # bounds the low-passed noise's at every τ
    sigma = (r.dev_high - r.dev_low) / 2
    assert np.all((np.abs(r.dev - white) < 3 * sigma + 0.03 * r.dev)[3:])  # from τ = 20 T


def test_the_cli_says_a_stalled_clock_kept_its_samples(tmp_path, capsys, white):
    """`hrgjax allan --time-column` on a stalled uniform clock says so (no sample read between
    stamps), not the jitter note "white noise reads low at the shortest τ"."""
    from hrgjax.cli import main

    t = np.arange(N) / FS
    t[N // 2 :] += 2.5 / FS
    log = tmp_path / "stall.csv"
    log.write_text(
        "time_s,gyro\n" + "".join(f"{a:.4f},{b:.6f}\n" for a, b in zip(t, white, strict=True))
    )
    assert main(["allan", str(log), "--column", "gyro", "--time-column", "time_s",
                 "--taus", "0.01"]) == 0  # fmt: skip
    said = capsys.readouterr()  # the note on stderr
    assert "uniform at 100 Hz but for 1 stall(s)" in said.err and "reads low" not in said.err
    assert "8002 samples at 100 Hz (80.02 s), 4 missing" in said.out, said  # 7998 own + 4 NaN


@pytest.mark.parametrize("steps", [0.25, 1.0, 4.0])
def test_kalibr_white_level_of_a_short_gauss_markov_follows_the_sampling(steps):
    """Review of 56065c5: the white level 2σ²T is the interval means'; point samples of a
    Gauss–Markov rate are an AR(1) of φ = e^{−Δt/T}, whose long-τ level N² is Δt × the sum of
    its autocovariances, σ²Δt(1 + φ)/(1 − φ) (exported N 0.694× at T = Δt/4 before). The
    model's octaves run 0.01–40.96 s (a 2¹⁵-sample fit's): over them each term goes white
    (`hrgjax.allan.kalibr`; over τ₀ alone a walk would overstate it less)."""
    dt, sigma, big_n = 1.0 / FS, 0.7, 0.1
    t = steps * dt
    phi = np.exp(-dt / t)
    lags = np.arange(-2000, 2001)
    truth = {"interval": 2 * sigma**2 * t, "point": dt * np.sum(sigma**2 * phi ** np.abs(lags))}
    unit = {"value": 0.0, "low": 0.0, "high": 0.0, "unit": ""}
    model = hg.allan.CompositeNoise(
        terms={"angle_random_walk": {**unit, "value": big_n},
               "gauss_markov_1": {"sigma": {**unit, "value": sigma},
                                  "correlation_time": {**unit, "value": t}}},
        unit="°/h", rate_hz=FS, n=2**15, ci=0.95, taus=dt * 2.0 ** np.arange(13),
        avar=np.ones(13), covariance=np.eye(13), chi2=0.0, dof=8, p_value=1.0,
        bounds={"rate_random_walk": 1e-3})  # fmt: skip
    si = np.pi / 180 / 3600
    for sampling, level in truth.items():
        out = dataclasses.replace(model, sampling=sampling).to_kalibr()
        want = np.sqrt(big_n**2 + level) * si
        assert out["gyroscope_noise_density"] == pytest.approx(want, rel=1e-12), sampling
    for sampling, level in truth.items():
        got = hg.allan.composite.gm_white_level(sigma, t, dt, sampling)
        assert got == pytest.approx(level, rel=1e-12)
