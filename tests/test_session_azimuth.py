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
    for bad, name in ((0.0, "width"), (float("nan"), "width"), (-0.1, "min_spread")):
        kw = {name: bad}
        with pytest.raises(ValueError, match=f"table_azimuth_fit: {name}"):
            table_azimuth_fit(e, **kw)
    with pytest.raises(TypeError, match="table_azimuth_fit: width"):
        table_azimuth_fit(e, width="5")


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


# review of 82f3348 (rev1): a narrow arc of azimuths, null fits' azimuth, NaN runs, 359.7°, docs


def _static(az, r, duration=None):
    """Error dicts of static runs at start azimuths `az` [°] with residuals `r` [°/h]."""
    n = len(az)
    return {"run": np.arange(n), "temperature_c": np.full(n, 20.0),
            "wave_angle0_deg": np.zeros(n), "static": np.ones(n, bool),
            "duration_s": np.full(n, 60.0) if duration is None else np.asarray(duration, float),
            "drift_error_dph": np.asarray(r, float), "angle_error_deg": np.full(n, np.nan),
            "max_angle_error_deg": np.full(n, np.nan), "table_angle0_deg": np.asarray(az, float)}  # fmt: skip


def _comparison(e):
    """A one-compensator Comparison on hand-made errors (no compensator, no JAX)."""
    from hrgjax.calibration import Comparison, session_offset

    off = session_offset(e, "A")
    return Comparison(labels=("A",), names={"A": "A"}, files={"A": None}, offset=off,
                      own_offsets={"A": off}, errors={"A": e}, residuals={"A": e})  # fmt: skip


def _spread(az, w):
    """Smallest eigenvalue of the weighted covariance of (cos a, sin a), written out."""
    a, w = np.deg2rad(az), np.asarray(w, float) / np.sum(w)
    cc, ss = np.cos(a) - w @ np.cos(a), np.sin(a) - w @ np.sin(a)
    vcc, vss, cs = w @ cc**2, w @ ss**2, w @ (cc * ss)
    return (vcc + vss) / 2 - math.sqrt(((vcc - vss) / 2) ** 2 + cs**2)


def test_azimuth_fit_refuses_a_narrow_arc():
    """Static runs parked at one azimuth whose logged angle creeps (here 0.5° per run over
    three 5° groups) read an unmodelled temperature curvature as a huge "resolved" c; three
    equal groups on an arc of half-width h have spread (2/9)(1 − cos h)², 0.5 round the turn."""
    temps = np.repeat([-40.0, 20.0, 60.0], 6)
    creep = 0.5 * np.arange(18)
    e = _static(creep, 0.002 * (temps - 20.0) ** 2 / 40.0, duration=np.linspace(60, 600, 18))
    assert table_azimuth_fit(e) is None
    text = _comparison(e).format()
    assert "too narrow an arc" in text and "Earth rate" not in text and "c = " not in text
    from hrgjax.calibration._azimuth import AZIMUTH_MIN_SPREAD, azimuth_spread

    assert azimuth_spread(creep, e["duration_s"]) == pytest.approx(
        _spread(creep, e["duration_s"]), rel=1e-6)  # fmt: skip
    for h in (30.0, 45.0, 60.0, 90.0, 120.0):
        az = np.repeat([-h, 0.0, h], 4)
        lam = 2 / 9 * (1 - math.cos(math.radians(h))) ** 2 if h <= 90 else 0.5
        assert azimuth_spread(az, np.ones(12)) == pytest.approx(lam, rel=1e-9)
        fit = table_azimuth_fit(_static(az, np.random.default_rng(1).standard_normal(12)))
        assert (fit is None) == (lam < AZIMUTH_MIN_SPREAD)
    # the threshold is an option: 0/45/90° (spread 0.019) fits when asked
    az = np.repeat([0.0, 45.0, 90.0], 4)
    e = _static(az, np.random.default_rng(2).standard_normal(12))
    assert table_azimuth_fit(e) is None
    assert table_azimuth_fit(e, min_spread=0.01).spread == pytest.approx(_spread(az, np.ones(12)))
    # a 0.4° scatter about one parking azimuth is one 5° group: no table
    jitter = _static(np.random.default_rng(5).normal(0.0, 0.4, 18), 0.01 * temps)
    assert _comparison(jitter).table_azimuths_deg == [0.0]


def test_azimuth_is_printed_only_when_resolved():
    """A null fit's azimuth is noise (the F test's p = 0.28 here): not printed."""
    az = 90.0 * (np.arange(16) % 4)
    noise = 0.03 * np.random.default_rng(4).standard_normal(16)
    null = table_azimuth_fit(_static(az, noise))
    assert not null.resolved() and "largest at azimuth" not in str(null)
    assert "azimuth undetermined" in str(null)


def test_the_printed_azimuth_is_folded_after_rounding():
    """A resolved term largest at 359.7°: "0°", not "360°"."""
    az = 90.0 * (np.arange(16) % 4)
    noise = 0.03 * np.random.default_rng(4).standard_normal(16)
    tilt = 0.2 * np.cos(np.deg2rad(az - 359.7)) + 1e-4 * noise
    fit = table_azimuth_fit(_static(az, tilt))
    assert fit.resolved() and fit.azimuth_deg == pytest.approx(359.7, abs=0.05)
    assert "largest at azimuth 0° ± 0°" in str(fit) and "360°" not in str(fit)


def test_a_nan_static_run_is_left_out_of_its_azimuth_row():
    r = 0.01 * np.random.default_rng(0).standard_normal(12)
    r[3] = np.nan  # a static run too short to give a rate
    c = _comparison(_static(90.0 * (np.arange(12) % 4), r))
    f = c.to_json()["compensators"][0]["by_table_azimuth"]
    assert f["n_static_runs"] == {"0": 3, "90": 3, "180": 3, "270": 2}
    assert f["mean_static_residual_dph"]["270"] == pytest.approx(np.mean(r[[7, 11]]), rel=1e-12)
    assert "nan" not in c.format().split("by start table azimuth")[1]


def test_the_json_layout_is_documented():
    """Every compensator key of `Comparison.to_json` is in its docstring and docs/cli.md."""
    from pathlib import Path

    from hrgjax.calibration import Comparison

    c = _comparison(_static(90.0 * (np.arange(12) % 4), np.zeros(12)))
    docs = Path(__file__).parents[1] / "docs"
    cli = (docs / "cli.md").read_text()
    for key in c.to_json()["compensators"][0]:
        assert f'"{key}"' in Comparison.to_json.__doc__ and f'"{key}"' in cli, key
    assert "`_azimuth`" in (docs / "architecture.md").read_text()
    assert "table azimuth" in cli.split("`--no-angles` ")[1].split(".")[0]
