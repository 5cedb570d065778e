"""The static residual by start table azimuth (F3 of the 2026-12-01 bench audit): a rate that
turns with the table (a gyro axis tilted from the table's: the horizontal Earth rate) was
visible in nothing `compare` and `hrgjax correct` printed.

Oracles: `scipy.optimize.curve_fit` (weighted, covariance scaled by the residual scatter) and
`scipy.stats.f` for the fit; a closed-form session whose static runs carry a known
A·cos(azimuth) rate for the report."""

import math

import numpy as np
import pytest
from helpers import AMPLITUDE_DPH, azimuth_session, closed_form_session
from scipy import optimize, stats

from hrgjax.calibration import (
    FourierCompensator,
    compare,
    corrected_run_errors,
    reduce,
    table_azimuth_fit,
)


def _errors(n=20, noise_seed=0):
    """Static runs at six azimuths (some given a turn off), random lengths (one design);
    `noise_seed` draws the white noise."""
    rng = np.random.default_rng(0)
    az = rng.choice([0.0, 45.0, 90.0, 180.0, 270.0, 315.0], n) + 360.0 * rng.integers(-1, 2, n)
    duration = rng.uniform(60.0, 600.0, n)
    a = np.deg2rad(az)
    noise = np.random.default_rng(noise_seed).standard_normal(n)
    r = 0.1 + 0.2 * np.cos(a) - 0.05 * np.sin(a) + 0.3 * noise / np.sqrt(duration)
    static = np.ones(n + 2, bool)
    static[-2:] = False  # moving runs: NaN, left out
    return {"static": static, "drift_error_dph": np.concatenate([r, [np.nan, np.nan]]),
            "duration_s": np.concatenate([duration, [60.0, 60.0]]),
            "table_angle0_deg": np.concatenate([az, [0.0, 90.0]])}  # fmt: skip


def test_azimuth_fit_is_weighted_least_squares_with_sigma_from_the_scatter():
    e = _errors()
    fit = table_azimuth_fit(e)
    keep = e["static"]
    az, r, dur = (e[k][keep] for k in ("table_angle0_deg", "drift_error_dph", "duration_s"))
    model = lambda a, m, c, s: m + c * np.cos(np.deg2rad(a)) + s * np.sin(np.deg2rad(a))
    jac = lambda a, *_: np.stack([np.ones_like(a), np.cos(np.deg2rad(a)),
                                  np.sin(np.deg2rad(a))], axis=1)  # fmt: skip
    p, cov = optimize.curve_fit(model, az, r, sigma=1 / np.sqrt(dur), absolute_sigma=False,
                                jac=jac)  # fmt: skip
    got = [fit.mean_dph, fit.cos_dph, fit.sin_dph]
    np.testing.assert_allclose(got, p, rtol=1e-9, atol=1e-12)
    sd = [fit.sigma_mean_dph, fit.sigma_cos_dph, fit.sigma_sin_dph]
    np.testing.assert_allclose(sd, np.sqrt(np.diag(cov)), rtol=1e-8)
    assert fit.cov_cos_sin == pytest.approx(cov[1, 2], rel=1e-8, abs=1e-15)
    assert fit.amplitude_dph == pytest.approx(math.hypot(p[1], p[2]), rel=1e-9)
    assert fit.azimuth_deg == pytest.approx(math.degrees(math.atan2(p[2], p[1])) % 360, abs=1e-7)
    beta = p[1:]
    f = beta @ np.linalg.solve(cov[1:, 1:], beta) / 2
    assert fit.p_value == pytest.approx(stats.f.sf(f, 2, 17), rel=1e-8)
    assert (fit.n_runs, fit.n_azimuths, fit.dof) == (20, len(set(az % 360.0)), 17)
    # the amplitude's first-order σ against 400 noise draws on the same design
    fits = [table_azimuth_fit(_errors(noise_seed=s)) for s in range(1, 401)]
    spread = np.std([f.amplitude_dph for f in fits])
    assert spread == pytest.approx(np.sqrt(np.mean([f.sigma_amplitude_dph**2 for f in fits])),
                                   rel=0.12)  # fmt: skip


def test_azimuth_fit_needs_three_azimuths_and_the_column():
    e = _errors()
    two = {**e, "table_angle0_deg": np.where(e["table_angle0_deg"] % 180 == 0, 0.0, 90.0)}
    assert table_azimuth_fit(two) is None
    three = {k: v[[0, 1, 2, 20]] for k, v in e.items()}
    three["table_angle0_deg"] = np.array([0.0, 120.0, 240.0, 0.0])
    fit = table_azimuth_fit(three)
    assert fit.dof == 0 and math.isnan(fit.sigma_cos_dph) and "σ unknown" in str(fit)
    with pytest.raises(ValueError, match="table_angle0_deg"):
        table_azimuth_fit({k: v for k, v in e.items() if k != "table_angle0_deg"})


@pytest.fixture(scope="module")
def fourier():
    return FourierCompensator(harmonics=1, temperature_degree=2).fit(reduce(closed_form_session()))


def test_compare_reports_the_residual_by_table_azimuth(fourier):
    data = azimuth_session()
    e = corrected_run_errors(fourier.correct(data))
    np.testing.assert_array_equal(e["table_angle0_deg"], 90.0 * (np.arange(36) % 4))
    c = compare({"F": fourier}, data)
    assert c.table_azimuths_deg == [0.0, 90.0, 180.0, 270.0]
    fit = c.azimuth_fit("F")
    # the injected A cos(az): c = A, s = 0, within the fit's σ (what the Fourier leaves)
    assert abs(fit.cos_dph - AMPLITUDE_DPH) < 3 * fit.sigma_cos_dph < 0.03
    assert abs(fit.sin_dph) < 3 * fit.sigma_sin_dph and fit.resolved()
    text = c.format()
    assert "by start table azimuth" in text and "c = +0.18" in text and "resolved at 95 %" in text
    assert "Earth rate" in text
    f = c.to_json()["compensators"][0]
    assert list(f["by_table_azimuth"]["n_static_runs"].values()) == [5, 5, 4, 4]
    assert f["table_azimuth_fit"]["cos_dph"] == pytest.approx(fit.cos_dph, rel=1e-12)
    # at one azimuth (the usual simulated session): no table, no fit
    plain = compare({"F": fourier}, closed_form_session(0.43))
    assert plain.azimuth_fit("F") is None and "table azimuth" not in plain.format()
    assert plain.to_json()["compensators"][0]["table_azimuth_fit"] is None
