"""How far to trust a second session's comparison (hrgjax.calibration.session, .paired),
against independent truth: the offset's σ by Monte Carlo with a known offset, the paired
test's false-"different" rate on equal compensators, and its interval against scipy's."""

import math

import numpy as np
import pytest
from scipy import stats

from hrgjax.calibration import Offset, session_offset


def _binomial_tol(p, n, k=4.0):
    return k * math.sqrt(p * (1 - p) / n)


@pytest.mark.parametrize("durations", [[3600.0] + [60.0] * 10, [3600.0, 60.0, 60.0]])
def test_offset_sigma_covers_the_truth_with_unequal_static_runs(durations):
    # white rate noise: a run's variance ∝ 1/T, the model the duration weighting assumes;
    # (b − truth)/σ must then be Student-t with n − 1 dof
    rng = np.random.default_rng(11)
    T = np.asarray(durations)
    n, draws, truth = T.size, 2000, 0.43
    z, inside95 = [], []
    for _ in range(draws):
        r = truth + 0.02 * np.sqrt(300.0 / T) * rng.normal(size=n)
        off = session_offset({"static": np.ones(n, bool), "drift_error_dph": r, "duration_s": T})
        z.append(abs(off.value_dph - truth) / off.sigma_dph)
        inside95.append(abs(off.value_dph - truth) <= getattr(off, "half_width", lambda _: 0)(0.95))
    z = np.asarray(z)
    for k in (1.0, 2.0):
        expected = 2 * stats.t.cdf(k, n - 1) - 1  # t10: 0.659, 0.927; t2: 0.577, 0.816
        assert abs(np.mean(z < k) - expected) < _binomial_tol(expected, draws), (k, np.mean(z < k))
    assert abs(np.mean(inside95) - 0.95) < _binomial_tol(0.95, draws)


def test_offset_reports_its_t_degrees_of_freedom():
    rate = np.array([0.41, 0.45, 0.43, 0.44])
    off = session_offset({"static": np.ones(4, bool), "drift_error_dph": rate,
                          "duration_s": np.array([600.0, 60.0, 60.0, 120.0])})  # fmt: skip
    T = np.array([600.0, 60.0, 60.0, 120.0])
    b = np.sum(T * rate) / T.sum()
    assert off.sigma_dph == pytest.approx(math.sqrt(np.sum(T * (rate - b) ** 2) / 3 / T.sum()))
    assert off.dof == 3
    assert off.half_width(0.95) == pytest.approx(stats.t.ppf(0.975, 3) * off.sigma_dph)
    js = off.to_json()
    assert js["dof"] == 3 and js["half_width_95"] == pytest.approx(off.half_width(0.95))
    assert "t with 3 dof" in str(off)
    one = Offset(0.5, math.nan, 1)
    assert one.dof == 0 and math.isnan(one.half_width()) and one.to_json()["half_width_95"] is None


def test_paired_test_says_different_at_the_nominal_rate_on_equal_compensators():
    from hrgjax.calibration import paired_difference

    # two compensators of equal quality on the same runs: the sensor noise is shared
    rng = np.random.default_rng(5)
    draws, n_runs = 2000, 20
    noise = 0.022 * rng.normal(size=(draws, n_runs))
    ea = noise + 0.012 * rng.normal(size=(draws, n_runs))
    eb = noise + 0.012 * rng.normal(size=(draws, n_runs))
    verdicts = [paired_difference(ea[k], eb[k]).verdict for k in range(draws)]
    rate = np.mean([v != "none" for v in verdicts])
    assert abs(rate - 0.05) < _binomial_tol(0.05, draws), rate
    # and a truly worse B is told apart, the right way round, far more often
    eb_worse = noise + 0.03 * rng.normal(size=(draws, n_runs))
    found = [paired_difference(ea[k], eb_worse[k]).verdict for k in range(400)]
    assert np.mean([v == "a" for v in found]) > 0.3
    assert np.mean([v == "b" for v in found]) < 0.01


def test_paired_interval_is_the_t_interval_of_the_squared_differences():
    from hrgjax.calibration import paired_difference

    rng = np.random.default_rng(2)
    ea, eb = 0.02 * rng.normal(size=30), 0.03 * rng.normal(size=30)
    ea[4], eb[7] = np.nan, np.nan  # a run without the figure is left out of both
    ok = np.isfinite(ea) & np.isfinite(eb)
    ref = stats.ttest_rel(ea[ok] ** 2, eb[ok] ** 2)
    ci = ref.confidence_interval(0.90)
    p = paired_difference(ea, eb, a="F", b="P", level=0.90)
    assert p.n_runs == 28 and p.dof == 27
    assert p.mean == pytest.approx(np.mean(ea[ok] ** 2 - eb[ok] ** 2), rel=1e-12)
    assert (p.low, p.high) == (pytest.approx(ci.low, rel=1e-10), pytest.approx(ci.high, rel=1e-10))
    assert p.p_value == pytest.approx(ref.pvalue, rel=1e-10)
    assert p.rms_a == pytest.approx(np.sqrt(np.mean(ea[ok] ** 2)))
    want = {"a": "F better than P", "b": "P better than F", "none": "not told apart"}[p.verdict]
    assert want in p.statement() and "at 90 %" in p.statement()
    same = paired_difference(ea, ea)
    assert same.verdict == "none" and "not told apart" in str(same)
    assert paired_difference(ea, eb * 0 + 1.0).statement() == "A better than B at 95 %"
    with pytest.raises(ValueError, match="level"):
        paired_difference(ea, eb, level=95)


def test_comparison_prints_and_writes_the_paired_test():
    from hrgjax.calibration import Comparison

    rng = np.random.default_rng(3)
    n = 24
    static = np.arange(n) < 12
    base = {"run": np.arange(n), "static": static, "duration_s": np.full(n, 120.0),
            "temperature_c": np.repeat([-40.0, 20.0, 60.0], 8),
            "wave_angle0_deg": np.tile([0.0, 30.0, 60.0, -30.0], 6)}  # fmt: skip

    def errors(scale, shift=0.0):  # shift: a constant error the offset does not take off
        rate = np.where(static, shift + scale * rng.normal(size=n), np.nan)
        angle = np.where(static, np.nan, shift + scale * rng.normal(size=n))
        return {**base, "drift_error_dph": rate, "angle_error_deg": angle,
                "max_angle_error_deg": np.abs(angle)}  # fmt: skip

    res = {"good": errors(0.01), "bad": errors(0.1, shift=1.0)}
    off = Offset(0.0, 0.001, 12, "good")
    comp = Comparison(labels=("good", "bad"), names={"good": "good", "bad": "bad"},
                      files={"good": None, "bad": None}, offset=off,
                      own_offsets={"good": off, "bad": off}, errors=res, residuals=res)  # fmt: skip
    p = comp.paired("good", "bad")
    assert p.verdict == "a" and p.n_runs == 12 and p.statement() == "good better than bad at 95 %"
    q = comp.paired("good", "bad", key="angle_error_deg")
    assert q.n_runs == 12 and q.unit == "°"
    report = comp.to_json()
    assert [(r["a"], r["b"], r["key"]) for r in report["paired"]] == [
        ("good", "bad", "static_residual_dph"), ("good", "bad", "angle_error_deg")]  # fmt: skip
    assert report["paired"][0]["statement"] == "good better than bad at 95 %"
    assert report["offset_dph"]["dof"] == 11
    text = comp.format()
    assert "told apart?" in text and "good better than bad at 95 %" in text
    with pytest.raises(ValueError, match="labels"):
        comp.paired("good", "nope")
