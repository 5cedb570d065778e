"""Kalman smoother, EKF and UKF (issue 21, scope 5): against the batch Gaussian posterior,
the linear filter, and exact moments of a quadratic."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import batched_lapack

from hrgjax import kalman

RNG = np.random.default_rng(2)
K, N = 7, 2
PHI = jnp.array([[1.0, 0.5], [0.0, 0.9]])
QD = jnp.array([[0.02, 0.005], [0.005, 0.03]])
H = jnp.array([[1.0, 0.0]])
R = jnp.array([[0.3]])
PRIOR = kalman.Gaussian(jnp.array([0.2, -0.1]), jnp.array([[1.0, 0.1], [0.1, 0.5]]))
ZS = jnp.asarray(RNG.normal(size=(K, 1)))
US = jnp.asarray(RNG.normal(size=(K, N)) * 0.1)
MASK = jnp.array([True, True, False, True, True, False, True])


def _batch_posterior():
    """Every state x_1 … x_K and measurement jointly Gaussian: condition directly."""
    phi, qd, h, r = (np.asarray(a) for a in (PHI, QD, H, R))
    mean, cov = [], []
    m, p = np.asarray(PRIOR.x), np.asarray(PRIOR.P)
    # x_k = Φ^k x_0 + Σ Φ^(k−j) (u_j + w_j): build the linear map from (x0, w_1..w_K)
    a = np.zeros((K * N, N * (K + 1)))
    b = np.zeros(K * N)
    for k in range(K):
        for j in range(k + 1):
            blk = np.linalg.matrix_power(phi, k - j)
            a[k * N : (k + 1) * N, (j + 1) * N : (j + 2) * N] = blk
            b[k * N : (k + 1) * N] += blk @ np.asarray(US[j])
        a[k * N : (k + 1) * N, :N] = np.linalg.matrix_power(phi, k + 1)
    src_cov = np.zeros((N * (K + 1),) * 2)
    src_cov[:N, :N] = p
    for j in range(1, K + 1):
        src_cov[j * N : (j + 1) * N, j * N : (j + 1) * N] = qd
    mean_x = a[:, :N] @ m + b
    cov_x = a @ src_cov @ a.T
    seen = [k for k in range(K) if bool(MASK[k])]
    hh = np.zeros((len(seen), K * N))
    for i, k in enumerate(seen):
        hh[i, k * N : (k + 1) * N] = h[0]
    s = hh @ cov_x @ hh.T + r[0, 0] * np.eye(len(seen))
    gain = cov_x @ hh.T @ np.linalg.inv(s)
    z = np.asarray(ZS)[seen, 0]
    post_mean = mean_x + gain @ (z - hh @ mean_x)
    post_cov = cov_x - gain @ hh @ cov_x
    mean = post_mean.reshape(K, N)
    cov = np.stack([post_cov[k * N : (k + 1) * N, k * N : (k + 1) * N] for k in range(K)])
    # the measurements' marginal likelihood
    innov = z - hh @ mean_x
    loglik = -0.5 * (innov @ np.linalg.solve(s, innov) + np.linalg.slogdet(s)[1]
                     + len(seen) * np.log(2 * np.pi))  # fmt: skip
    return mean, cov, loglik


def test_rts_smoother_is_the_batch_posterior():
    xs, ps, ll = kalman.rts_smoother(PRIOR, PHI, QD, H, R, ZS, mask=MASK, us=US)
    mean, cov, loglik = _batch_posterior()
    np.testing.assert_allclose(xs, mean, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ps, cov, rtol=1e-10, atol=1e-12)
    assert float(ll) == pytest.approx(loglik, rel=1e-10)
    # the filter's last estimate is the smoother's; the control input is honoured
    xf, pf, llf = kalman.kalman_filter(PRIOR, PHI, QD, H, R, ZS, mask=MASK, us=US)
    np.testing.assert_allclose(xf[-1], xs[-1], rtol=1e-12)
    assert float(llf) == pytest.approx(float(ll), rel=1e-12)
    x0, _, _ = kalman.kalman_filter(PRIOR, PHI, QD, H, R, ZS, mask=MASK)
    assert not np.allclose(x0, xf)


def test_a_masked_nan_reaches_neither_the_result_nor_its_gradient():
    """A missing measurement written as NaN at a masked step: the smoother's result and the
    gradient of its log-likelihood in the measurements are those of any finite value there
    (the masked step's gradient 0), not NaN."""
    loss = lambda zs: kalman.rts_smoother(PRIOR, PHI, QD, H, R, zs, mask=MASK, us=US)[2]  # noqa: E731
    holes = ZS.at[2].set(jnp.nan).at[5].set(jnp.nan)  # the two masked steps
    np.testing.assert_array_equal(loss(holes), loss(ZS))
    g_holes, g = jax.grad(loss)(holes), jax.grad(loss)(ZS)
    np.testing.assert_allclose(g_holes, g, rtol=1e-12, atol=0)
    assert np.all(np.asarray(g)[~np.asarray(MASK)] == 0.0)


def test_ekf_and_ukf_are_the_kalman_filter_on_a_linear_model():
    f = lambda x, u: PHI @ x + u
    h = lambda x: H @ x
    ref = kalman.kalman_filter(PRIOR, PHI, QD, H, R, ZS, mask=MASK, us=US)
    for run in (kalman.extended_kalman_filter, kalman.unscented_kalman_filter):
        got = run(PRIOR, f, QD, h, R, ZS, mask=MASK, us=US)
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


def test_ukf_moments_of_a_nonlinear_model():
    """One prediction through f(x) = (x₀², x₀x₁ + sin x₁): the unscented mean is exact for
    the quadratic part, and agrees with a Monte Carlo mean of the whole within its error;
    the EKF's (the function at the mean) misses E[x₀²] by P₀₀."""
    f = lambda x, u: jnp.stack([x[0] ** 2, x[0] * x[1] + jnp.sin(x[1])])
    h = lambda x: x[:1]
    none = jnp.array([False])
    z0 = jnp.zeros((1, 1))
    q = jnp.zeros((2, 2))
    xs, _, _ = kalman.unscented_kalman_filter(PRIOR, f, q, h, R, z0, mask=none)
    m, p = np.asarray(PRIOR.x), np.asarray(PRIOR.P)
    assert float(xs[0, 0]) == pytest.approx(m[0] ** 2 + p[0, 0], rel=1e-12)
    draws = jax.random.multivariate_normal(jax.random.key(0), PRIOR.x, PRIOR.P, (400_000,))
    mc = jax.vmap(lambda x: f(x, None))(draws)
    err = np.asarray(mc.std(axis=0)) / np.sqrt(draws.shape[0])
    assert np.all(np.abs(np.asarray(xs[0]) - np.asarray(mc.mean(axis=0))) < 5 * err + 2e-3)
    xe, _, _ = kalman.extended_kalman_filter(PRIOR, f, q, h, R, z0, mask=none)
    assert float(xe[0, 0]) == pytest.approx(m[0] ** 2)


def test_smoother_and_ekf_vmap_over_records():
    """A batch of records in one call equals one call per record."""
    zs = jnp.asarray(RNG.normal(size=(3, K, 1)))
    f = lambda x, u: PHI @ x + u
    batch = jax.vmap(lambda z: kalman.rts_smoother(PRIOR, PHI, QD, H, R, z, us=US))(zs)
    ekf = jax.vmap(
        lambda z: kalman.extended_kalman_filter(PRIOR, f, QD, lambda x: H @ x, R, z, us=US)
    )(zs)
    for i in range(3):
        one = kalman.rts_smoother(PRIOR, PHI, QD, H, R, zs[i], us=US)
        np.testing.assert_allclose(batch[0][i], one[0], rtol=1e-12, atol=1e-14)
        assert float(batch[2][i]) == pytest.approx(float(one[2]), rel=1e-12)
        lin = kalman.kalman_filter(PRIOR, PHI, QD, H, R, zs[i], us=US)
        np.testing.assert_allclose(ekf[0][i], lin[0], rtol=1e-9, atol=1e-12)


def test_batched_filters_run_no_lapack_kernel():
    """Batched over records with their own noise (so that S and P are batched too), every
    filter's factorisations are plain XLA operations (`hrgjax._linalg`): jaxlib's LAPACK
    kernels split a batch over XLA:CPU's pool, and two at once wedged a two-thread pool for
    ever (hrgjax/_threads.py)."""
    zs = jnp.zeros((3, K, 1))
    rs = R[None] * jnp.arange(1.0, 4.0)[:, None, None]
    f, h = (lambda x, u: PHI @ x + u), (lambda x: H @ x)
    runs = {
        "kalman_filter": lambda z, r: kalman.kalman_filter(PRIOR, PHI, QD, H, r, z, us=US),
        "rts_smoother": lambda z, r: kalman.rts_smoother(PRIOR, PHI, QD, H, r, z, us=US),
        "extended": lambda z, r: kalman.extended_kalman_filter(PRIOR, f, QD, h, r, z, us=US),
        "unscented": lambda z, r: kalman.unscented_kalman_filter(PRIOR, f, QD, h, r, z, us=US),
        "steady_state": lambda z, r: kalman.steady_state(PHI, QD, H, r, PRIOR.P, 8),
    }
    for name, run in runs.items():
        assert not batched_lapack(jax.vmap(run), zs, rs), name


def test_psd_factor_is_exact_per_state_continuous_and_differentiable():
    """`psd_factor` of a singular covariance whose states span 14 decades (latitude in
    radians beside velocity in m/s, as the INS error model's Q_d) with exactly-zero states:
    LLᵀ = M to round-off *relative to each pair of states* (an eigen-factor, whose clipping
    works at the largest eigenvalue's resolution, missed the 1e-11 state's variance by 74 %
    here); L
    continuous in M (a 1e-9 change moved an eigen-factor's sample by 2×its size) and its
    gradient finite and right where zero variances repeat."""
    scales = jnp.array([1e-11, 3e-12, 1.0, 0.0, 2e-4, 0.0])
    a = jnp.asarray(RNG.normal(size=(6, 4)))  # rank 4 before the zero states
    m = scales[:, None] * (a @ a.T) * scales[None, :]
    low = kalman.psd_factor(m)
    assert np.all(np.triu(np.asarray(low), 1) == 0.0)
    d = np.sqrt(np.diag(np.asarray(m)))
    scale = np.where(np.outer(d, d) > 0, np.outer(d, d), 1.0)
    assert np.max(np.abs(np.asarray(low @ low.T - m)) / scale) < 1e-12
    assert np.all(np.asarray(low)[[3, 5]] == 0.0)
    # not PSD beyond round-off (Cauchy–Schwarz broken 10¹⁴×): bounded, not LLᵀ₁₁ = 100
    bad = kalman.psd_factor(jnp.array([[1e-30, 1e-14], [1e-14, 1.0]]))
    assert float((bad @ bad.T)[1, 1]) <= 1.0 + 1e-12
    # continuity: a change in the last bits of M changes L in its last bits too
    m2 = jnp.array([[2.0, 0.1], [0.1, 2.0]])
    tweak = jnp.array([[1e-9, 0.0], [0.0, -1e-9]])
    jump = kalman.psd_factor(m2 + tweak) - kalman.psd_factor(m2 - tweak)
    assert float(jnp.max(jnp.abs(jump))) < 1e-8
    # Σ_i (L 1)_i of diag(s, s, 0, 0, 1) is 2√s + 1: d/ds = 1/√s (NaN from eigh)
    total = lambda s: jnp.sum(kalman.psd_factor(jnp.diag(jnp.array([s, s, 0.0, 0.0, 1.0]))))
    np.testing.assert_allclose(jax.grad(total)(2.0), 2.0**-0.5, rtol=1e-12)
    # reverse mode against a central difference on a full positive-definite matrix
    w = jnp.asarray(RNG.normal(size=(4, 4)))
    pd = w @ w.T + jnp.eye(4)
    probe = jnp.asarray(RNG.normal(size=(4, 4)))
    loss = lambda t: jnp.sum(kalman.psd_factor(pd + t * (probe + probe.T)) * probe)
    h = 1e-6
    fd = (loss(h) - loss(-h)) / (2 * h)
    np.testing.assert_allclose(jax.grad(loss)(0.0), fd, rtol=1e-6)


def test_eager_filters_and_steady_state_compile_once_per_shape():
    """A later eager call on new values of the same shapes runs the program of the first
    (each compiled its `lax.scan` on every call: ≈ 0.4–1 s, `benchmarks/kalman_calls.py`)
    and gives the plain function's values."""
    from helpers import CompileCounter

    zs, r2 = ZS + 0.25, 2.0 * R
    kalman.kalman_filter(PRIOR, PHI, QD, H, R, ZS)
    kalman.steady_state(PHI, QD, H, R, PRIOR.P, 9)
    with CompileCounter() as again:
        kf = kalman.kalman_filter(PRIOR, PHI, QD, H, r2, zs)
        ss = kalman.steady_state(PHI, QD, H, r2, PRIOR.P, 9)
    assert again.compiles == 0, again.names
    plain = kalman.steady_state.__wrapped__(PHI, QD, H, r2, PRIOR.P, 9)
    for a, b in zip(ss, plain, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13)
    np.testing.assert_allclose(kf[2], kalman.kalman_filter.__wrapped__(PRIOR, PHI, QD, H, r2, zs)[2],
                               rtol=1e-13)  # fmt: skip


def test_eager_ekf_and_ukf_compile_once_per_shape_and_model():
    """A later eager EKF/UKF call with the same `f`, `h` (a plain function, a callable
    equinox Module) on new values of the same shapes compiles nothing (each
    compiled its `lax.scan` on every call) and gives the plain pass's values; a Module with
    new parameter values is a new input, not a stale program; a model that is not a function
    is refused in one line."""
    import equinox as eqx
    from helpers import CompileCounter

    class Measure(eqx.Module):
        h: jax.Array

        def __call__(self, x):
            return self.h @ x

    class Plant:  # a plain object: its state may change between calls
        def __init__(self, a):
            self.a = a

        def transition(self, x, u):
            return self.a * (PHI @ x) + u

    @dataclasses.dataclass
    class Callable:  # eq=True: cannot be hashed
        a: float

        def __call__(self, x, u):
            return self.a * (PHI @ x) + u

    f = lambda x, u: PHI @ x + u
    zs, r2, h2 = ZS + 0.25, 2.0 * R, 2.0 * H
    for run in (kalman.extended_kalman_filter, kalman.unscented_kalman_filter):
        for fn, h, h_new in ((f, lambda x: H @ x, None), (f, Measure(H), Measure(h2))):
            run(PRIOR, fn, QD, h, R, ZS, us=US)
            with CompileCounter() as again:
                got = [
                    run(PRIOR, fn, QD, model, r2, zs, us=US)
                    for model in (h, h_new)
                    if model is not None
                ]
            assert again.compiles == 0, (run.__name__, again.names)
            for out, model in zip(got, (h, h_new), strict=False):
                plain = run.__wrapped__(PRIOR, fn, QD, model, r2, zs, us=US)
                for a, b in zip(out, plain, strict=True):
                    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)
            assert len(got) == 1 or not np.allclose(got[1][2], got[0][2])
        # a model that may hold state the program cannot see is run afresh: never stale
        plant, h = Plant(1.0), Measure(H)
        for a in (1.0, 0.5):
            plant.a = a
            for model in (plant.transition, Callable(a)):
                got = run(PRIOR, model, QD, h, R, ZS, us=US)[2]
                np.testing.assert_allclose(got, run.__wrapped__(PRIOR, model, QD, h, R, ZS, us=US)[2],
                                           rtol=1e-12)  # fmt: skip
        assert not np.isclose(got, run(PRIOR, Plant(1.0).transition, QD, h, R, ZS, us=US)[2])
        with pytest.raises(ValueError, match=r"^h must be a function h\(x\) -> z; got ArrayImpl$"):
            run(PRIOR, f, QD, H, R, ZS)


def test_filter_inputs_are_refused_in_one_line():
    """Impossible inputs used to run silently (a NaN measurement without a mask, a negative
    variance: NaN means and log-likelihood; an indefinite P0: a finite log-likelihood) or
    failed deep in JAX (`dot_general requires contracting dimensions`)."""
    bad_z = np.asarray(ZS).copy()
    bad_z[3] = np.nan
    indefinite = kalman.Gaussian(PRIOR.x, jnp.array([[1.0, 3.0], [3.0, 1.0]]))
    mixed = kalman.Gaussian(PRIOR.x, jnp.diag(jnp.array([100.0, -1e-14])))
    qd_steps = np.stack([np.asarray(QD)] * (K - 1) + [-np.asarray(QD)])
    cases = [
        ((PRIOR, PHI, QD, H, R, bad_z), r"zs has NaN at step 3: mark a missing measurement"),
        ((PRIOR, PHI, QD, H, -R, ZS), r"R must be a symmetric positive-definite \(m, m\) = "
                                      r"\(1, 1\) covariance; its variance \[0, 0\] is -0.3"),
        ((PRIOR, PHI, -QD, H, R, ZS), r"qd must be a symmetric positive semi-definite"),
        ((PRIOR, PHI, qd_steps, H, R, ZS), r"qd must be .* at step 6"),
        # the tests do not depend on the states' units: a negative bias variance beside a
        # position variance of 100 m² is refused (it passed the largest variance's round-off)
        ((mixed, PHI, QD, H, R, ZS), r"prior.P must .* its variance \[1, 1\] is -1e-14"),
        ((indefinite, PHI, QD, H, R, ZS), r"prior.P must be a symmetric positive semi-definite "
                                          r"\(n, n\) = \(2, 2\) covariance; its smallest eigen"),
        ((PRIOR, PHI * np.nan, QD, H, R, ZS), r"phi must be finite; it has nan"),
        ((PRIOR, PHI, QD, H, R, ZS.T), r"zs must be \(K, m\) = \(K, 1\) .*got \(1, 7\) \(transp"),
        ((PRIOR, PHI, QD, jnp.ones((1, 3)), R, ZS), r"H must be \(m, n\) = \(m, 2\)"),
        ((PRIOR, PHI, QD, H, jnp.eye(2), ZS), r"R must be \(m, m\) = \(1, 1\)"),
    ]  # fmt: skip
    for run in (kalman.kalman_filter, kalman.rts_smoother):
        for args, message in cases:
            with pytest.raises(ValueError, match=message):
                run(*args)
        with pytest.raises(ValueError, match=r"mask must be \(K,\) = \(7,\)"):
            run(PRIOR, PHI, QD, H, R, ZS, mask=MASK[:3])
        # shapes are refused under the caller's jit too (they are known when tracing)
        with pytest.raises(ValueError, match=r"zs must be \(K, m\)"):
            jax.jit(lambda z, run=run: run(PRIOR, PHI, QD, H, R, z))(ZS.T)
    # a NaN at a step without a measurement is a missing measurement (documented)
    masked = kalman.kalman_filter(PRIOR, PHI, QD, H, R, bad_z, mask=MASK.at[3].set(False))
    assert np.isfinite(masked[2]) and np.isfinite(masked[0]).all()
    with pytest.raises(ValueError, match=r"z must be finite where mask is True"):
        kalman.update(PRIOR, jnp.array([np.nan]), H, R)
    with pytest.raises(ValueError, match=r"R must be a symmetric positive-definite"):
        kalman.update(PRIOR, ZS[0], H, -R)
    assert kalman.update(PRIOR, jnp.array([np.nan]), H, R, mask=False)[3] == 0.0
    # a valid R whose σ span 12 decades (correlated: its eigenvalues in its own units reach
    # the round-off of the largest, and it was refused) and a P0 with exact zeros pass
    sig = np.logspace(-6, 6, 5)
    corr = 0.5 * np.eye(5) + 0.5 * np.exp(-np.abs(np.subtract.outer(range(5), range(5))))
    g = kalman.Gaussian(jnp.zeros(5), jnp.diag(jnp.array([1.0, 0.0, 1e-12, 0.0, 1e6])))
    assert np.isfinite(kalman.update(g, jnp.zeros(5), jnp.eye(5), corr * np.outer(sig, sig))[3])


def test_integer_and_list_inputs_are_floats():
    """Audit: a prior written with integers (`jnp.array([0, 0])`, `np.eye(2, dtype=int)`)
    gave a 5-line scan-carry TypeError (kalman_filter, rts_smoother, the UKF) or "jacfwd
    requires real-valued inputs" (the EKF); `Gaussian(x=[0, 0], …)` an AttributeError. An
    integer or list state is a valid way to write it: the same result as floats."""
    zs = np.asarray(ZS)
    as_int = kalman.Gaussian(jnp.array([0, 0]), np.eye(2, dtype=int))
    as_list = kalman.Gaussian([0, 0], [[1, 0], [0, 1]])
    floats = kalman.Gaussian(jnp.zeros(2), jnp.eye(2))
    assert as_int.x.dtype == as_list.P.dtype == jnp.float64
    f = lambda x, u: PHI @ x  # noqa: E731
    h = lambda x: H @ x  # noqa: E731
    runs = {
        "kalman_filter": lambda g, *m: kalman.kalman_filter(g, *m[:2], H, *m[2:]),
        "rts_smoother": lambda g, *m: kalman.rts_smoother(g, *m[:2], H, *m[2:]),
        "ekf": lambda g, phi, qd, r, z: kalman.extended_kalman_filter(g, f, qd, h, r, z),
        "ukf": lambda g, phi, qd, r, z: kalman.unscented_kalman_filter(g, f, qd, h, r, z),
    }
    for name, run in runs.items():
        want = run(floats, PHI, QD, R, zs)
        for g in (as_int, as_list):
            got = run(g, PHI, QD, R, zs)
            for a, b in zip(got, want, strict=True):
                np.testing.assert_allclose(a, b, rtol=1e-12, err_msg=name)
        # integer model matrices and measurements too
        got = run(floats, np.eye(2, dtype=int), np.eye(2, dtype=int), np.array([[1]]),
                  np.round(zs).astype(int))  # fmt: skip
        want = run(floats, jnp.eye(2), jnp.eye(2), jnp.ones((1, 1)), np.round(zs))
        for a, b in zip(got, want, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-12, err_msg=name)
    # traced integers convert too (jit), and the float path keeps its gradient
    xs = jax.jit(lambda x0: kalman.kalman_filter(kalman.Gaussian(x0, jnp.eye(2)), PHI, QD, H,
                                                 R, ZS)[0])(jnp.array([0, 0]))  # fmt: skip
    np.testing.assert_allclose(xs, kalman.kalman_filter(floats, PHI, QD, H, R, ZS)[0], rtol=1e-12)
    grad = jax.grad(lambda s: kalman.kalman_filter(kalman.Gaussian(jnp.zeros(2), s * jnp.eye(2)),
                                                   PHI, QD, H, R, ZS)[2])(1.0)  # fmt: skip
    assert np.isfinite(grad)


def test_van_loan_names_a_step_that_is_not_a_number():
    """Audit: `van_loan(F, Q, "0.1")` gave a 2-line jit message naming no argument."""
    for fn, b in ((kalman.van_loan, QD), (kalman.discretise_input, jnp.ones((2, 1)))):
        for bad in ("0.1", None, np.ones(3), float("nan")):
            with pytest.raises(ValueError, match=r"^dt must be the step, one finite number \[s\]") as err:  # fmt: skip
                fn(PHI, b, bad)
            assert "\n" not in str(err.value)
    # traced steps pass (vmap over steps, as the INS models do)
    phis, _ = jax.vmap(kalman.van_loan, in_axes=(None, None, 0))(PHI, QD, jnp.array([0.1, 0.2]))
    np.testing.assert_allclose(phis[1], kalman.van_loan(PHI, QD, 0.2)[0], rtol=1e-12)


def test_ukf_takes_a_measurement_far_more_precise_than_its_prior():
    """Prior variance 10⁴, measurement variance 10⁻¹²: the update leaves P indefinite by
    round-off (−6e-28), and a plain Cholesky of it gave NaN from the first step, silently,
    where the Kalman filter and the EKF answer; the UKF now equals them."""
    phi, h = jnp.array([[1.0, 1.0], [0.0, 1.0]]), jnp.array([[1.0, 0.0]])
    qd, r = jnp.diag(jnp.array([1e-4, 1e-6])), jnp.array([[1e-12]])
    noise = 1e-6 * np.random.default_rng(0).normal(size=50)
    zs = jnp.asarray((0.02 * np.arange(50) + noise)[:, None])
    prior = kalman.Gaussian(jnp.zeros(2), 1e4 * jnp.eye(2))
    xs, _, ll = kalman.kalman_filter(prior, phi, qd, h, r, zs)
    uxs, _, ull = kalman.unscented_kalman_filter(
        prior, lambda x, u: phi @ x, qd, lambda x: h @ x, r, zs
    )
    assert np.isfinite(np.asarray(uxs)).all() and float(ull) == pytest.approx(float(ll), abs=1e-6)
    np.testing.assert_allclose(uxs, xs, rtol=1e-6, atol=1e-9)


def test_ukf_with_a_state_its_prior_knows_exactly_has_a_value_and_a_gradient():
    """P0 = diag(1, 0) or diag(0, 1) (a state known exactly; the KF and EKF take it): the
    UKF's plain Cholesky gave a NaN gradient of the log-likelihood in R, or a NaN value;
    now its gradient equals central differences."""
    f = lambda x, u: jnp.array([x[0] + x[1], x[1]])  # noqa: E731 — position, velocity
    h = lambda x: jnp.array([x[0] + 0.05 * x[0] ** 3])  # noqa: E731 — a mildly nonlinear sensor
    truth = 0.3 * jnp.arange(20.0)
    zs = (truth + 0.05 * truth**3 + 0.3 * jax.random.normal(jax.random.key(0), (20,)))[:, None]
    qd = jnp.diag(jnp.array([1e-3, 0.0]))
    for p0 in (jnp.diag(jnp.array([1.0, 0.0])), jnp.diag(jnp.array([0.0, 1.0]))):
        ll = lambda r, p0=p0: kalman.unscented_kalman_filter(  # noqa: E731
            kalman.Gaussian(jnp.array([0.0, 0.3]), p0), f, qd, h, jnp.array([[r]]), zs
        )[2]
        step = 1e-6
        fd = (float(ll(0.09 + step)) - float(ll(0.09 - step))) / (2 * step)
        assert np.isfinite(float(ll(0.09)))
        assert float(jax.grad(ll)(0.09)) == pytest.approx(fd, rel=1e-6)


def test_off_path_inputs_of_every_kalman_entry_point_are_one_line():
    """Audit (ins): a negative step gave a negative-definite Qd (van_loan, discretise_input);
    a NaN model or measurement ran on to NaN (van_loan, predict, the EKF/UKF, steady_state),
    psd_factor gave a factor of zeros for a NaN matrix; alpha = 0 a ZeroDivisionError;
    n_iter = -1 or 1.5 ran 0 or 1 iterations; empty zs a reshape error; wrong shapes a
    dot_general / concatenate / scan error. Nothing here compiles: each is refused first."""
    f = lambda x, u: PHI @ x  # noqa: E731
    h = lambda x: H @ x  # noqa: E731
    nan = PHI.at[0, 0].set(jnp.nan)
    cases = [
        (lambda: kalman.van_loan(PHI, QD, -1.0), r"^dt must be the step, >= 0 \[s\] .*got -1.0$"),
        (lambda: kalman.discretise_input(PHI, jnp.ones((2, 1)), -0.5), r"^dt must be the step, >= 0"),
        (lambda: kalman.van_loan(PHI, jnp.eye(3), 1.0), r"^Q must be a square \(n, n\) = \(2, 2\)"),
        (lambda: kalman.van_loan(nan, QD, 1.0), r"^F must be finite; it has nan"),
        (lambda: kalman.van_loan(PHI, -QD, 1.0), r"^Q must be a symmetric positive semi-definite"),
        (lambda: kalman.discretise_input(PHI, jnp.ones(2), 1.0), r"^B must be \(n, m\) = \(2, m\)"),
        (lambda: kalman.psd_factor(nan), r"^m must be finite; it has nan"),
        (lambda: kalman.psd_factor(jnp.ones((2, 3))), r"^m must be a square \(n, n\) matrix"),
        (lambda: kalman.predict(PRIOR, jnp.eye(3), QD), r"^phi must be \(m, n\) = \(m, 2\)"),
        (lambda: kalman.predict(PRIOR, jnp.ones((3, 2)), QD), r"^qd must be \(m, m\) = \(3, 3\)"),
        (lambda: kalman.predict(PRIOR, nan, QD), r"^phi must be finite"),
        (lambda: kalman.predict(PRIOR, PHI, QD, jnp.ones(3)), r"^u must be \(m,\) = \(2,\)"),
        (lambda: kalman.update(PRIOR, ZS[0], H, R, mask=MASK), r"^mask must be one boolean"),
        (lambda: kalman.kalman_filter(PRIOR, PHI, QD, H, R, ZS[:0]), r"^zs must have at least one"),
        (lambda: kalman.sigma_points(PRIOR, alpha=0.0), r"^alpha must be > 0"),
        (lambda: kalman.sigma_points(PRIOR, kappa=-2.0), r"^kappa must be > -n = -2"),
        (lambda: kalman.steady_state(nan, QD, H, R, PRIOR.P, 9), r"^phi must be finite"),
        (lambda: kalman.steady_state(PHI, QD, H, -R, PRIOR.P, 9), r"^r must be a symmetric posit"),
        (lambda: kalman.steady_state(PHI, QD, H, jnp.eye(2), PRIOR.P, 9), r"^r must be a square"),
        (lambda: kalman.steady_state(PHI, QD, H, R, PRIOR.P, -1), r"^n_iter must be a whole"),
        (lambda: kalman.steady_state(PHI, QD, H, R, PRIOR.P, 1.5), r"^n_iter must be a whole"),
    ]  # fmt: skip
    bad_z = ZS.at[3, 0].set(jnp.nan)
    for run in (kalman.extended_kalman_filter, kalman.unscented_kalman_filter):
        cases += [
            (lambda run=run: run(PRIOR, f, QD, h, R, bad_z), r"^zs has NaN at step 3: mark a"),
            (lambda run=run: run(PRIOR, f, QD, h, -R, ZS), r"^R must be a symmetric positive-def"),
            (lambda run=run: run(PRIOR, f, -QD, h, R, ZS), r"^qd must be a symmetric positive"),
            (lambda run=run: run(PRIOR, f, QD, h, jnp.eye(2), ZS), r"^R must be \(m, m\) = \(1, 1\)"),
            (lambda run=run: run(PRIOR, f, QD, lambda x: x, R, ZS), r"^h\(x\) must return shape \(1,\)"),
            (lambda run=run: run(PRIOR, f, QD, h, R, ZS, mask=MASK[:3]), r"^mask must be \(K,\) = \(7,\)"),
            (lambda run=run: run(PRIOR, f, QD, h, R, ZS, us=US[:3]), r"^us must be \(K, p\) = \(7, p\)"),
            (lambda run=run: run(PRIOR, f, QD, h, R, ZS[:, 0]), r"^zs must be \(K, m\)"),
        ]  # fmt: skip
    cases.append((lambda: kalman.unscented_kalman_filter(PRIOR, f, QD, h, R, ZS, alpha=0.0),
                  r"^alpha must be > 0"))  # fmt: skip
    for call, message in cases:
        with pytest.raises(ValueError, match=message) as err:
            call()
        assert "\n" not in str(err.value)
    # what the checks let through, as before them: a phi (m, n) mapping the state to a new
    # size, a scalar input u
    wide = kalman.predict(PRIOR, jnp.ones((3, 2)), jnp.eye(3))
    np.testing.assert_allclose(wide.x, np.full(3, 0.1), rtol=1e-12)
    np.testing.assert_allclose(wide.P, np.full((3, 3), 1.7) + np.eye(3), rtol=1e-12)
    shifted = kalman.predict(PRIOR, PHI, QD, 1.0)
    np.testing.assert_allclose(shifted.x, PHI @ PRIOR.x + 1.0, rtol=1e-12)


def _numpy_rts(prior, phi, qd, h, r, zs):
    """The RTS smoother in plain NumPy, its gain by a pseudo-inverse of the prediction."""
    x, p = np.asarray(prior.x, float), np.asarray(prior.P, float)
    xf, pf, xp, pp = [], [], [], []
    for z in zs:
        x, p = phi @ x, phi @ p @ phi.T + qd
        xp.append(x), pp.append(p)
        gain = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
        x, p = x + gain @ (z - h @ x), (np.eye(len(x)) - gain @ h) @ p
        xf.append(x), pf.append(p)
    xs, ps = np.array(xf), np.array(pf)
    for k in range(len(zs) - 2, -1, -1):
        c = pf[k] @ phi.T @ np.linalg.pinv(pp[k + 1])
        xs[k] = xf[k] + c @ (xs[k + 1] - xp[k + 1])
        ps[k] = pf[k] + c @ (ps[k + 1] - pp[k + 1]) @ c.T
    return xs, ps


def test_smoother_keeps_a_state_known_exactly():
    """Audit: a state with P0 = 0 and no process noise (a fault bank's other hypotheses' fault
    states) made P_pred singular and the smoother's Cholesky NaN on every step but the last.
    Now: the NumPy RTS (pseudo-inverse) to round-off, the known state at its value on every
    step, and a finite gradient."""
    zs = np.asarray(ZS)
    phi, r = np.eye(2), np.eye(1)
    cases = [  # (P0, Qd, H): an unmeasured known constant; a measured one beside a walk
        (np.diag([1.0, 0.0]), np.diag([0.1, 0.0]), np.array([[1.0, 0.0]])),
        (np.diag([0.0, 1.0]), np.diag([0.0, 0.1]), np.array([[1.0, 1.0]])),
    ]
    for p0, qd, h in cases:
        prior = kalman.Gaussian(np.array([0.0, 0.3]) if p0[1, 1] == 0 else np.array([0.3, 0.0]), p0)
        xs, ps, _ = kalman.rts_smoother(prior, phi, qd, h, r, zs)
        want_x, want_p = _numpy_rts(prior, phi, qd, h, r, zs)
        np.testing.assert_allclose(xs, want_x, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(ps, want_p, rtol=1e-12, atol=1e-14)
        known = int(np.argmin(np.diag(p0)))
        np.testing.assert_array_equal(np.asarray(xs)[:, known], 0.3)
    grad = jax.grad(lambda z: jnp.sum(kalman.rts_smoother(prior, phi, qd, h, r, z)[0]))(ZS)
    assert np.isfinite(np.asarray(grad)).all() and np.any(np.asarray(grad) != 0)


def test_steady_state_is_the_riccati_solution_at_any_noise_ratio():
    """Audit: `steady_state` iterated 4000 Riccati steps with no convergence test: a random
    walk at q/r = 1e-12 got K = 2.5e-4 for 1e-6. Now (doubling): the closed form
    P = (q + √(q² + 4qr))/2, K = P/(P + r) at q/r = 1, 1e-6, 1e-12, from any p0; scipy's
    `solve_discrete_are` on a 2-state model; a model without a steady state (an unstable
    state no measurement sees) is refused in one line."""
    from scipy.linalg import solve_discrete_are

    one = np.eye(1)
    for q, rtol in ((1.0, 1e-14), (1e-6, 1e-12), (1e-12, 1e-9)):
        p = (q + np.sqrt(q * q + 4 * q)) / 2
        for p0 in (None, 1e6 * one):
            pp, gain, s = kalman.steady_state(one, q * one, one, one, p0)
            np.testing.assert_allclose([pp[0, 0], gain[0, 0], s[0, 0]], [p, p / (p + 1), p + 1],
                                       rtol=rtol)  # fmt: skip
    want = solve_discrete_are(np.asarray(PHI).T, np.asarray(H).T, np.asarray(QD), np.asarray(R))
    for p0 in (None, PRIOR.P):
        pp, gain, s = kalman.steady_state(PHI, QD, H, R, p0)
        np.testing.assert_allclose(pp, want, rtol=1e-12)
        h, r = np.asarray(H), np.asarray(R)
        np.testing.assert_allclose(gain, want @ h.T @ np.linalg.inv(h @ want @ h.T + r), rtol=1e-12)
    unseen = jnp.array([[1.5, 0.0], [0.0, 0.5]])  # state 0 grows, H sees state 1 alone
    with pytest.raises(
        ValueError, match=r"^steady_state: no steady state: states x\[0\] alone"
    ) as e:
        kalman.steady_state(unseen, QD, jnp.array([[0.0, 1.0]]), R)
    assert "grow by 1.5 a step that no row of h sees" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(Exception, match="the Riccati recursion did not converge"):
        jax.jit(kalman.steady_state)(
            unseen, QD, jnp.array([[0.0, 1.0]]), R
        )  # traced: no host check


def test_steady_state_refuses_an_unseen_combination_of_random_walks():
    """Audit (s32): Φ = [[0.99, 1, 1], [0, 1, 0], [0, 0, 1]], H = [1, 0, 0]: two random walks
    drive the measured state only through their sum, so x₁ − x₂ is a random walk no
    measurement sees, its variance k·(q₁ + q₂) after k steps (the plain Riccati recursion:
    1.0e-2 at 2²⁰ steps and growing). The doubling's round-off stalled and it "converged"
    to P[1,1] = 913 at Q_d = diag(1e-2, 1e-6, 1e-8), to −6.9e13 at diag(1e-2, 1e-2, 1e-2).
    Now refused in one line naming the two states, at any noise size (PBH: the unobservable
    subspace's unit eigenvalue, driven by the noise), and a negative variance fails the
    doubling's own test under `jit`. Not refused: the same model when one walk has no noise
    and no initial uncertainty (known exactly), an unseen constant that only p0 makes
    uncertain (its variance stays p0's), and an unseen stable state with noise."""
    phi = np.array([[0.99, 1.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    h, r = np.array([[1.0, 0.0, 0.0]]), np.array([[1e-2]])
    plain = np.zeros((3, 3))  # the recursion itself: the walks' variance grows step by step
    for _ in range(2000):
        prior = phi @ plain @ phi.T + np.diag([1e-2, 1e-6, 1e-8])
        plain = prior - prior @ h.T @ h @ prior / (h @ prior @ h.T + r)
    assert prior[1, 1] > 1.5 * 1000 * (1e-6 * 1e-8) / (1e-6 + 1e-8)  # no limit: still growing
    for q in ((1e-6, 1e-8), (1e-2, 1e-2), (1e-20, 1e-24)):
        with pytest.raises(
            ValueError,
            match=r"^steady_state: no steady state: states x\[1\], "
            r"x\[2\] moving as \((-1, 1|1, -1)\) are a random walk",
        ) as e:
            kalman.steady_state(phi, np.diag([1e-2, *q]), h, r)
        assert "\n" not in str(e.value)
    with pytest.raises(Exception, match="the Riccati recursion did not converge"):
        jax.jit(kalman.steady_state)(phi, np.diag([1e-2, 1e-2, 1e-2]), h, r)
    pp, _, _ = kalman.steady_state(phi, np.diag([1e-2, 1e-6, 0.0]), h, r)  # walk 2 known
    assert np.isfinite(np.asarray(pp)).all() and float(pp[2, 2]) == 0.0
    constant = np.array([[0.9, 0.0], [0.0, 1.0]])  # state 1: unseen, no noise, p0 = 4
    pp, _, _ = kalman.steady_state(constant, np.diag([1e-2, 0.0]), np.array([[1.0, 0.0]]),
                                   np.eye(1), np.diag([0.0, 4.0]))  # fmt: skip
    b = 1.0 - 0.81 - 0.01  # the seen state: P² + bP − q r = 0 (a = 0.9, q = 0.01, r = 1)
    np.testing.assert_allclose(np.diag(pp), [(-b + np.sqrt(b * b + 0.04)) / 2, 4.0], rtol=1e-12)
    stable = np.diag([0.9, 0.5])  # state 1: unseen, noise 1e-2, decays: q / (1 − 0.25)
    pp, _, _ = kalman.steady_state(stable, np.diag([1e-2, 1e-2]), np.array([[1.0, 0.0]]), np.eye(1))
    np.testing.assert_allclose(pp[1, 1], 1e-2 / 0.75, rtol=1e-12)


def test_steady_state_balances_states_of_any_scale():
    """Audit: Φ = [[1, 9.8], [0, 0.9999]], Q_d = diag(1e-6, q₂), H = [1, 0], R = 1e-2: the
    doubling's Gauss–Jordan pivots, chosen by size in the model's units, left the small
    state's gain 5e-4 off at q₂ = 1e-24 and 36× at 1e-28. Now (balanced) the gain and P
    meet the doubling in 80-digit decimals to 1e-11 and scipy's `solve_discrete_are` to
    its own error (1.3e-9 at 1e-28)."""
    from scipy.linalg import solve_discrete_are

    phi, h, r = np.array([[1.0, 9.8], [0.0, 0.9999]]), np.array([[1.0, 0.0]]), np.array([[1e-2]])
    exact = {  # q₂: K, diag P (the doubling in Python's `decimal`, 80 digits, to convergence)
        1e-24: ([0.009950124999689497, 4.827285354970694e-16],
                [0.00010050124999699007, 5.000250000733951e-21]),
        1e-28: ([0.009950124999218806, 4.827285366559858e-20],
                [0.00010050124999218808, 5.000250012499448e-25]),
    }  # fmt: skip
    for q2, (k_exact, p_exact) in exact.items():
        qd = np.diag([1e-6, q2])
        pp, gain, _ = kalman.steady_state(phi, qd, h, r)
        np.testing.assert_allclose(gain[:, 0], k_exact, rtol=1e-11)
        np.testing.assert_allclose(np.diag(pp), p_exact, rtol=1e-11)
        want = solve_discrete_are(phi.T, h.T, qd, r)
        np.testing.assert_allclose(gain, want @ h.T / (h @ want @ h.T + r), rtol=1e-8)
        np.testing.assert_allclose(pp, want, rtol=1e-8)


def test_steady_state_keeps_exactly_known_states_at_zero():
    """Audit: Φ = [[0.99, 1, 1], [0, 1, 0], [0, 0, 1]], Q_d = diag(1e-2, 1e-6, 0), p0 = 0:
    state 2 has no noise and no initial uncertainty, so its variance is 0 at every step,
    but the doubling kept its eigenvalue 1 and amplified round-off through it: refused in
    100 doublings, state 1's variance 20× too large in 200. Now its rows of P and K are
    exactly 0 and the rest is scipy's `solve_discrete_are` on the reduced model. The set
    is found inside the compiled program, on traced values (as under a caller's `jit`)."""
    from scipy.linalg import solve_discrete_are

    phi = np.array([[0.99, 1.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    qd, h, r = np.diag([1e-2, 1e-6, 0.0]), np.array([[1.0, 0.0, 0.0]]), np.eye(1)
    want = solve_discrete_are(phi[:2, :2].T, h[:, :2].T, qd[:2, :2], r)
    want_k = want @ h[:, :2].T / (h[:, :2] @ want @ h[:, :2].T + r)
    pp, gain, _ = kalman.steady_state(phi, qd, h, r)
    assert not np.any(np.asarray(pp)[2]) and not np.any(np.asarray(pp)[:, 2])
    assert float(gain[2, 0]) == 0.0
    np.testing.assert_allclose(pp[:2, :2], want, rtol=1e-12)
    np.testing.assert_allclose(gain[:2], want_k, rtol=1e-12)
    # the closure is one function for the compiled program and `check_detectable`'s host
    # check: a chain 0 → 1 → … → 4 reached from state 0 in 4 steps, state 5 apart
    from hrgjax._riccati import reached_states

    chain, x0 = np.eye(6, k=-1), np.diag([1.0, 0, 0, 0, 0, 0])
    chain[5, 4] = 0.0
    host = reached_states(chain, x0)
    assert isinstance(host, np.ndarray) and host.tolist() == [True] * 5 + [False]
    assert np.asarray(jax.jit(reached_states)(chain, x0)).tolist() == host.tolist()


def test_steady_state_derivatives_are_the_implicit_ones_at_known_states_and_any_p0():
    """Review (s32): masking the known states gave `grad` 0 for a coupling into one, or its
    noise, at 0 (a parameter started there never moved); the derivative is now the implicit
    one of the Riccati fixed point (0.2701 against central differences' 0.2701). The
    balancing read the states' sizes from a first prior that p0 dominated: the small gain of
    `test_steady_state_balances_states_of_any_scale` was 8e-2 off with p0 = I."""
    phi, qd = jnp.array([[0.9, 0.3], [0.0, 0.5]]), jnp.diag(jnp.array([1e-2, 0.0]))
    h, r = jnp.array([[1.0, 0.0]]), jnp.eye(1)

    def total(phi, qd):
        return jnp.sum(kalman.steady_state(phi, qd, h, r)[0])

    d_phi, d_qd = jax.grad(total, argnums=(0, 1))(phi, qd)
    step = 1e-6
    central = (total(phi.at[1, 0].add(step), qd) - total(phi.at[1, 0].add(-step), qd)) / (2 * step)
    np.testing.assert_allclose(d_phi[1, 0], central, rtol=1e-7)
    assert abs(float(central)) > 0.1
    one_sided = (total(phi, qd.at[1, 1].add(1e-8)) - total(phi, qd)) / 1e-8  # qd ≥ 0
    np.testing.assert_allclose(d_qd[1, 1], one_sided, rtol=1e-5)
    big = np.array([[1.0, 9.8], [0.0, 0.9999]])
    _, gain, _ = kalman.steady_state(big, np.diag([1e-6, 1e-28]), h, np.array([[1e-2]]), np.eye(2))
    np.testing.assert_allclose(gain[1, 0], 4.827285366559858e-20, rtol=1e-10)


def test_an_overflowing_filter_is_refused_in_one_line():
    """Audit: Φ = 1.5 on a state no measurement sees, 2000 steps: the covariance overflowed
    and the filter returned NaN with no message. Now one line naming the first step (here
    Φ = 1e80: inf at step 1, on the module's shapes; the smoother carries it back to 0) and
    what is not finite: it said "the estimate" when only the log-likelihood was (a
    measurement of 1e200, whose νᵀS⁻¹ν overflows, beside a finite estimate)."""
    phi, h = jnp.array([[1e80, 0.0], [0.0, 0.9]]), jnp.array([[0.0, 1.0]])
    far = ZS.at[3, 0].set(1e200)
    for run, step in ((kalman.kalman_filter, 1), (kalman.rts_smoother, 0)):
        with pytest.raises(ValueError, match=rf"^{run.__name__}: the state estimate, the "
                                             rf"covariance and the log-likelihood are not finite "
                                             rf"from step {step} of 7 on") as e:  # fmt: skip
            run(PRIOR, phi, QD, h, R, ZS)
        assert "\n" not in str(e.value)
        with pytest.raises(ValueError, match=rf"^{run.__name__}: the log-likelihood is not finite "
                                             r"\(-inf\) though the state estimate and covariance "
                                             r"are: an innovation beyond") as e:  # fmt: skip
            run(PRIOR, PHI, QD, h, R, far)
        assert "\n" not in str(e.value)
