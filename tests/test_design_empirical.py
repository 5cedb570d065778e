"""Experiment design for an empirical compensator (`design.Empirical`): the linear surrogate's
basis against NumPy's Legendre series, its Fisher information against the closed form of a
static segment, the prior it keeps where a plan does not look, and its criterion's gradient
against finite differences."""

import equinox as eqx
import jax
import numpy as np
import pytest
from helpers import CompileCounter

from hrgjax.calibration import design as d
from hrgjax.units import DEG

STATIC = {"kind": "static", "temperature_c": -20.0, "wave_angle_deg": 10.0, "duration_s": 600.0}
RAMP = {"kind": "ramp", "temperature_start_c": -40.0, "temperature_end_c": 20.0,
        "wave_angle_deg": 30.0, "duration_s": 3600.0}  # fmt: skip
MODEL = d.Empirical(harmonics=1, degree=2)  # 3 × 3 terms per law: small and quick


def test_basis_is_harmonics_times_legendre_polynomials():
    model = d.Empirical(harmonics=2, degree=5)
    theta, temp = 0.3, -25.0
    x = (temp - 10.0) / 50.0
    legendre = [np.polynomial.legendre.legval(x, np.eye(6)[k]) for k in range(6)]
    angle = [1.0, np.cos(2 * theta), np.sin(2 * theta), np.cos(4 * theta), np.sin(4 * theta)]
    expected = np.outer(angle, legendre).ravel()
    np.testing.assert_allclose(np.asarray(model.basis(theta, temp)), expected, rtol=1e-13)
    assert model.terms == 30 and model.nominal().shape == (90,)
    # the measured rate: −k_e(SF Ω + D) + s_T Ṫ with the three laws' coefficients
    v = np.random.default_rng(0).normal(size=90) * 1e-3
    b = expected
    want = -model.k_e * ((1 + b @ v[30:60]) * 0.1 + b @ v[:30]) + (b @ v[60:]) * 0.02
    assert float(model.rate(v, theta, temp, 0.1, 0.02)) == pytest.approx(want, rel=1e-12)


def test_static_information_is_the_basis_outer_product_and_s_t_keeps_its_prior():
    """One static segment: F = k_e² b bᵀ D / N_w² × (Gauss–Markov share), b the basis at its
    (θ, T) in the drift block, zero elsewhere. Without a ramp the s_T coefficients keep
    exactly their prior variance ((100 × scale)² = the prior magnitude²); a ramp at 30°
    teaches s_T at 30° (up and down: s_T separates from the drift, the variance falls
    10⁴-fold) and nothing at the orthogonal −60°."""
    plan = d.BenchPlan.from_segments([STATIC])
    f = np.asarray(d.information(plan, model=MODEL))
    n = MODEL.terms
    b = np.asarray(MODEL.basis(10.0 * DEG, -20.0))
    dur, dt = STATIC["duration_s"], d.DT_OUT["static"]
    arw, white = d.pattern_arw(), d.pattern_angle_white()
    sigma, tau = d.pattern_gauss_markov()
    density = float(d.window_density(arw, white, dur / dt + 1.0, dt, dur))
    share = float(d.gauss_markov_discount(dur, density, sigma, tau))
    expected = np.zeros((3 * n, 3 * n))
    expected[:n, :n] = MODEL.k_e**2 * np.outer(b, b) * dur / density**2 * share
    np.testing.assert_allclose(f, expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())

    prior = (100.0 * np.asarray(MODEL.scale())) ** 2
    cov = np.asarray(d.posterior_covariance(plan, model=MODEL))
    np.testing.assert_allclose(np.diag(cov)[2 * n :], prior[2 * n :], rtol=1e-9)
    # the magnitudes and k_e are values of these programs (static, each new one compiled
    # four again, ≈ 5 s): F scales with k_e², s_T keeps its new prior
    other = d.Empirical(harmonics=1, degree=2, st_rad_per_c=3e-4, k_e=0.6)
    with CompileCounter() as c:
        f_other = np.asarray(d.information(plan, model=other))
        cov_other = np.asarray(d.posterior_covariance(plan, model=other))
    assert c.compiles == 0, c.names
    np.testing.assert_allclose(f_other, f * (0.6 / MODEL.k_e) ** 2, rtol=1e-12,
                               atol=1e-12 * np.abs(f_other).max())  # fmt: skip
    np.testing.assert_allclose(np.diag(cov_other)[2 * n :], 9.0 * prior[2 * n :], rtol=1e-9)

    # s_T where a ramp looks, and where it does not: with harmonics = 1 the basis at 30° and
    # at −60° are orthogonal (1 + cos 60° cos(−120°) + sin 60° sin(−120°) = 0)
    back = {**RAMP, "temperature_start_c": 20.0, "temperature_end_c": -40.0}
    at = [np.asarray(MODEL.basis(a * DEG, -10.0)) for a in (30.0, -60.0)]

    def shrink(segments):  # posterior / prior variance of s_T at (30°, −10 °C), (−60°, −10 °C)
        c = np.asarray(d.posterior_covariance(d.BenchPlan.from_segments(segments), model=MODEL))
        c, p = c[2 * n :, 2 * n :], prior[2 * n :]
        return [float(x @ c @ x / (x @ (p * x))) for x in at]

    one_way, both_ways = shrink([STATIC, RAMP]), shrink([STATIC, RAMP, back])
    assert one_way[0] < 0.3 and both_ways[0] < 1e-4  # up and down: s_T apart from the drift
    assert one_way[1] == pytest.approx(1.0, rel=1e-9)
    assert both_ways[1] == pytest.approx(1.0, rel=1e-9)
    with pytest.raises(ValueError, match="model must be one of"):
        d.criterion(plan, model="neural")


def test_empirical_ins_criterion_gradient_equals_finite_differences():
    """jax.grad of the `ins` criterion for the surrogate = central differences in a ramp's
    duration and angle and a static segment's temperature (both its ends move)."""
    plan = d.BenchPlan.from_segments([STATIC, RAMP])
    value = lambda p: d.criterion(p, "ins", model=MODEL)
    g = jax.grad(value)(plan)

    def moved(field, i, h):
        p = eqx.tree_at(lambda q: getattr(q, field), plan, getattr(plan, field).at[i].add(h))
        if field == "temperature_c" and plan.kind[i] != "ramp":
            p = eqx.tree_at(lambda q: q.temperature_end_c, p, p.temperature_end_c.at[i].add(h))
        return p

    for field, i, h in (("duration_s", 1, 1.0), ("wave_angle_deg", 1, 0.01),
                        ("temperature_c", 0, 0.01)):  # fmt: skip
        got = float(np.asarray(getattr(g, field))[i])
        if field == "temperature_c":
            got += float(np.asarray(g.temperature_end_c)[i])
        fd = (float(value(moved(field, i, h))) - float(value(moved(field, i, -h)))) / (2 * h)
        assert got == pytest.approx(fd, rel=1e-5), field
