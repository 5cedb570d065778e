"""Precision losses an audit found, each against an independent truth: the physical fit's
covariance on an ill-conditioned Jacobian (its exact SVD form), `kalman.van_loan` on a fast
Gauss–Markov state (the closed form), `discovery.stats.wls` on columns 1e12 apart (a known
truth and its own σ)."""

import jax
import numpy as np
import pytest
import scipy.linalg

from hrgjax import kalman
from hrgjax.calibration import physical
from hrgjax.discovery import stats


def test_physical_covariance_is_exact_where_inverting_jtj_was_not():
    """Audit: `_covariance` inverted JᵀJ (condition cond(J)²): at cond(J) = 1e9 its σ's were
    0.6–2.2× the truth and some variances negative. Truth: J = U diag(s) Vᵀ D built with
    known factors, so (JᵀJ)⁻¹ = D⁻¹ V diag(1/s²) Vᵀ D⁻¹ (J's own rounding moves it by
    ≈ cond·ε ≈ 1e-7)."""
    p = len(physical.NAMES)
    rng = np.random.default_rng(0)
    u, _ = np.linalg.qr(rng.standard_normal((400, p)))
    v, _ = np.linalg.qr(rng.standard_normal((p, p)))
    d = 10.0 ** rng.uniform(-1, 1, p)  # columns in different units
    for cond in (1e8, 1e9):
        s = np.geomspace(1.0, 1.0 / cond, p)
        jac = ((u * s) @ v.T) * d
        cov = physical._covariance(jac, 1.0) / np.outer(physical.SCALE, physical.SCALE)
        truth = (v / s**2) @ v.T / np.outer(d, d)
        sigma = np.sqrt(np.diag(truth))
        np.testing.assert_allclose(np.sqrt(np.diag(cov)), sigma, rtol=1e-5)
        np.testing.assert_allclose(cov / np.outer(sigma, sigma), truth / np.outer(sigma, sigma),
                                   atol=1e-5)  # fmt: skip


def _gauss_markov(q, tau, T):
    """Angle + first-order Gauss–Markov rate (time constant τ [s], rate PSD q): F, Q and the
    closed-form Qd over T [s]."""
    f = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    a, b = -np.expm1(-T / tau), -np.expm1(-2 * T / tau)
    qd = q * tau**2 * np.array([[T - 2 * tau * a + tau / 2 * b, a - b / 2],
                                [a - b / 2, b / (2 * tau)]])  # fmt: skip
    return f, np.diag([0.0, q]), qd


@pytest.mark.parametrize("ratio", [40.0, 60.0, 1e4])
def test_van_loan_meets_the_gauss_markov_closed_form_at_long_steps(ratio):
    """Audit: Qd came from Φ·(Φ⁻¹Qd) with ‖Φ⁻¹‖ ≈ e^{dt/τ}: 50 % off at dt/τ = 40 (still
    PSD, so silent), indefinite at 60, NaN from ≈ 700."""
    f, q, qd_exact = _gauss_markov(2.0, 1.0, ratio)
    phi, qd = kalman.van_loan(f, q, ratio)
    np.testing.assert_allclose(np.asarray(qd), qd_exact, rtol=1e-13)
    np.testing.assert_allclose(np.asarray(phi), [[1.0, -np.expm1(-ratio)], [0.0, np.exp(-ratio)]],
                               rtol=1e-13, atol=1e-300)  # fmt: skip


def test_van_loan_is_one_exponential_for_a_slow_model_and_one_program_for_every_step():
    """A slow F (‖F‖₁dt ≤ 1: no sub-steps) gives the single Van Loan exponential (bit for bit
    the code before the sub-steps, benchmarks/precision.py; here scipy's to 1e-13); a fast
    one takes sub-steps in the same compiled program; grad through the sub-steps meets the
    closed form's dQd/dT = qτ²(1 − e^{−T/τ})² (angle variance)."""
    rng = np.random.default_rng(1)
    f, q = 0.05 * rng.standard_normal((2, 2)), np.array([[2.0, 0.3], [0.3, 1.0]])
    e = scipy.linalg.expm(np.block([[-f, q], [np.zeros((2, 2)), f.T]]) * 7.3)
    phi0 = e[2:, 2:].T
    phi, qd = kalman.van_loan(f, q, 7.3)
    np.testing.assert_allclose(phi, phi0, rtol=1e-14)
    np.testing.assert_allclose(qd, phi0 @ e[:2, 2:], rtol=1e-13)
    size = kalman._van_loan._cache_size()
    for dt in (0.1, 40.0, 3e3):
        kalman.van_loan(f, q, dt)
    assert kalman._van_loan._cache_size() == size
    fg, qg, _ = _gauss_markov(2.0, 1.0, 40.0)
    slope = jax.jit(jax.grad(lambda t: kalman.van_loan(fg, qg, t)[1][0, 0]))(40.0)
    np.testing.assert_allclose(float(slope), 2.0 * np.expm1(-40.0) ** 2, rtol=1e-12)


def test_wls_scales_its_columns_before_the_solve():
    """Audit: `lstsq` on unscaled whitened columns 1e12 apart, two of them near-parallel, cut
    the small one as rank-deficient: β 89 σ off the truth and χ² 8 300 for 397 degrees of
    freedom. Truth: the β the data were drawn from, within its reported σ."""
    rng = np.random.default_rng(0)
    n, ratio = 400, 1e12
    t = np.linspace(-1.0, 1.0, n)
    g = np.stack([np.ones(n), t, (1.0 + 0.05 * t**2) / ratio], 1)
    beta_true = np.array([1e-6, 2e-7, 3e-7 * ratio])
    sigma = np.full(n, 1e-9)
    y = g @ beta_true + sigma * rng.standard_normal(n)
    beta, r, cov = stats.wls(g, y, sigma)
    assert np.all(np.abs(beta - beta_true) < 4.0 * np.sqrt(np.diag(cov)))
    assert abs(r @ r - (n - 3)) < 4.0 * np.sqrt(2.0 * (n - 3))


def test_wls_gives_an_aliased_column_nothing_in_any_units():
    """A candidate column proportional to one of the model's (the discovery search met a
    bias candidate equal to a bias column, an angular gain twice over) is not identified:
    `lstsq`'s minimum-norm answer split the model's value between the two, by the columns'
    units (half each at equal norms). It gets β = 0, the model its fit without it."""
    rng = np.random.default_rng(2)
    n = 200
    t = np.linspace(-1.0, 1.0, n)
    sigma = np.full(n, 0.1)
    y = 1.0 + 0.5 * t + sigma * rng.standard_normal(n)
    model = np.stack([np.ones(n), t], 1)
    alone, _, _ = stats.wls(model, y, sigma)
    for scale in (1.0, 1e-3, 1e6):
        beta, r, _ = stats.wls(np.column_stack([model, scale * t]), y, sigma)
        np.testing.assert_allclose(beta, [*alone, 0.0], rtol=1e-12, atol=1e-15)


def test_a_column_the_others_span_has_no_finite_sigma():
    """Audit: one table rate and no static runs make k_e's column a multiple of the bias's;
    `wls` gave k_e β = 0, and `covariance`'s pseudo-inverse σ 8·10⁻⁷ (the bias ± 0.67 °/h)
    — the minimum-norm split's, where neither is determined. Both get σ = ∞ (the report says
    "not determined"); a column outside the pair keeps the σ of the fit without the twin."""
    from hrgjax.discovery.result import _number

    rng = np.random.default_rng(3)
    n = 200
    t = np.linspace(-1.0, 1.0, n)
    sigma = np.full(n, 0.1)
    y = 1.0 + 0.5 * t + sigma * rng.standard_normal(n)
    _, _, alone = stats.wls(np.stack([np.ones(n), t], 1), y, sigma)
    beta, _, cov = stats.wls(np.stack([np.ones(n), t, 3.0 * np.ones(n)], 1), y, sigma)
    assert beta[2] == 0.0 and np.isinf(cov[0, 0]) and np.isinf(cov[2, 2])
    assert cov[1, 1] == pytest.approx(alone[1, 1], rel=1e-9)
    shown = _number({"value": beta[0], "sigma": float(np.sqrt(cov[0, 0])), "unit": "°/h"})
    assert shown.endswith("°/h (not determined by these data)"), shown
