"""INS: WGS-84 constants, Kalman utilities and the strapdown error model against the oracles
of PHYSICS.md §12, closed forms and a nonlinear mechanisation."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, mechanise_ned

from hrgjax import kalman
from hrgjax.ins import constants as C
from hrgjax.ins import strapdown as sd
from hrgjax.ins import trajectory as tr

DEG = np.pi / 180


def test_wgs84_constants_and_gravity():
    assert C.E2 == pytest.approx(6.69437999014e-3, rel=1e-11)
    np.testing.assert_allclose(C.gravity(45 * DEG), 9.806197769, rtol=1e-10)
    np.testing.assert_allclose(C.gravity(0.0), C.GAMMA_E, rtol=1e-12)
    np.testing.assert_allclose(C.gravity(90 * DEG), C.GAMMA_P, rtol=1e-12)
    # free-air gradient ≈ −3.086e-6 s⁻² at mid latitude
    dg = jax.grad(C.gravity, argnums=1)(45 * DEG, 0.0)
    np.testing.assert_allclose(dg, -3.086e-6, rtol=2e-3)
    r_m, r_n = C.radii(0.0)
    np.testing.assert_allclose([r_m, r_n], [C.A * (1 - C.E2), C.A], rtol=1e-12)
    assert C.SCHULER_PERIOD / 60 == pytest.approx(84.45, abs=0.01)
    assert 2 * np.pi / C.OMEGA_IE / 3600 == pytest.approx(23.934, abs=1e-3)
    with pytest.raises(ValueError, match="both radius and g"):
        C.Earth(radius=1.0)
    with pytest.raises(ValueError, match="Earth.radius must be a number"):
        C.Earth(radius="6.4e6 m", g=9.8)
    # a 0-d array is taken as its number (the fields are static: hashed, compared by value)
    assert C.Earth(radius=jnp.asarray(6.4e6), g=9.8) == C.Earth(radius=6.4e6, g=9.8)
    # a textbook's other units are named (6371 km, 981 cm/s², 15.04 °/h)
    for kw, unit in ((dict(radius=6371.0, g=9.8), "km"), (dict(radius=C.A, g=981.0), "cm/s²"),
                     (dict(rate=15.04), "°/h")):  # fmt: skip
        with pytest.raises(ValueError, match=f"outside the plausible range.*{unit}"):
            C.Earth(**kw)


def test_a_latitude_in_degrees_is_refused_by_the_earth_model():
    """`gravity(45.0)` gave 9.8178 m/s² (truth γ(45°) = 9.806197769) and `earth_rate_ned(45.0)`
    a north rate 26 % low: each function and `Earth` method refuses a concrete |lat| > π/2
    with the degrees hint; traced values pass (no check in the compiled program, one
    compile per shape as before)."""
    hint = r": lat = 45 rad is beyond ±π/2: the latitude is in radians here \(degrees\? "
    z = np.zeros(3)
    for name, call in (("gravity", lambda la: C.gravity(la)), ("radii", C.radii),
                       ("earth_rate_ned", C.earth_rate_ned),
                       ("transport_rate_ned", lambda la: C.transport_rate_ned(la, 0.0, z)),
                       ("gravity_ned", lambda la: C.gravity_ned(lat=la)),
                       ("Earth.gravity", C.WGS84.gravity), ("Earth.radii", C.SPHERE.radii),
                       ("Earth.earth_rate", C.WGS84.earth_rate),
                       ("Earth.gravity_ned", lambda la: C.WGS84.gravity_ned(la, 10.0)),
                       ("Earth.transport_rate", lambda la: C.WGS84.transport_rate(la, 0.0, z)),
                       ("Earth.position_rate",
                        lambda la: C.WGS84.position_rate(la, 0.0, z))):  # fmt: skip
        with pytest.raises(ValueError, match="^" + name + hint):
            call(np.array([0.1, 45.0]))
        call(np.radians(45.0))
    np.testing.assert_allclose(C.gravity(np.radians(45.0)), 9.806197769, rtol=1e-10)
    # a pole rounded through float32 (1.5707964, 4.4e-8 beyond π/2) is radians: γ_p
    for pole in (float(np.float32(np.pi / 2)), np.float32(-np.pi / 2), np.pi / 2 + 9e-7):
        np.testing.assert_allclose(C.gravity(pole), 9.8321849378, rtol=1e-6)  # float32 in
    for beyond in (np.pi / 2 + 1.1e-6, 1.6, -90.0):
        with pytest.raises(ValueError, match=r"^gravity: lat = \S+ rad is beyond ±π/2"):
            C.gravity(beyond)
    # a height inside the Earth (a radius given as a height: γ read 66.8 m/s²) or in space is
    # refused by every function and method taking `h`, naming it; inside the range the
    # free-air series holds: γ(45°, 1 km) = γ₀(1 − 2h/a(1 + f + m − f) + 3h²/a²)
    rng = r"h must be a height in metres above the ellipsoid in \(-10000, 100000\); got "
    for name, call in (("gravity", lambda h: C.gravity(0.5, h)),
                       ("gravity_ned", lambda h: C.gravity_ned(lat=0.5, h=h)),
                       ("transport_rate_ned", lambda h: C.transport_rate_ned(0.5, h, z)),
                       ("Earth.gravity", lambda h: C.SPHERE.gravity(0.5, h)),
                       ("Earth.position_rate",
                        lambda h: C.WGS84.position_rate(0.5, h, z))):  # fmt: skip
        with pytest.raises(ValueError, match=f"^{name}: {rng}-7e\\+06$"):
            call(-7e6)
        with pytest.raises(ValueError, match=f"^{name}: {rng}200000 at index \\(1,\\)$"):
            call(np.array([0.0, 2e5]))
    g0, k = 9.806197769, 1 + C.FLATTENING + C.M_GRAVITY - C.FLATTENING
    want = g0 * (1 - 2e3 / C.A * k + 3e6 / C.A**2)
    np.testing.assert_allclose(C.gravity(np.radians(45.0), 1e3), want, rtol=1e-10)
    w = C.earth_rate_ned(np.radians(45.0))
    np.testing.assert_allclose(w, C.OMEGA_IE * np.sqrt(0.5) * np.array([1, 0, -1]), rtol=1e-14)
    f = jax.jit(lambda la: C.gravity(la) + C.WGS84.earth_rate(la)[0])
    assert np.isfinite(float(f(45.0)))  # traced: not checked
    want, rad = float(C.gravity(np.radians(45.0))) + float(w[0]), float(np.radians(45.0))
    assert float(f(rad)) == pytest.approx(want, rel=1e-12)
    assert f._cache_size() == 1
    assert "callback" not in str(jax.make_jaxpr(C.gravity_ned)(0.5))


def test_van_loan_matches_the_closed_form_and_the_lyapunov_identity():
    dt, q = 10.0, np.diag([1.0, 3.0])
    phi, qd = kalman.van_loan(jnp.array([[0.0, 1.0], [0.0, 0.0]]), jnp.asarray(q), dt)
    np.testing.assert_allclose(phi, [[1, dt], [0, 1]], atol=1e-12)
    want = dt * np.array([[1 + 3 * dt**2 / 3, 3 * dt / 2], [3 * dt / 2, 3]])
    np.testing.assert_allclose(qd, want, rtol=1e-12)
    rng = np.random.default_rng(1)
    f = rng.normal(size=(4, 4)) * 0.3
    b = rng.normal(size=(4, 4))
    qq = b @ b.T
    phi, qd = kalman.van_loan(jnp.asarray(f), jnp.asarray(qq), 0.7)
    lyap = f @ qd + qd @ f.T + qq - phi @ qq @ phi.T
    np.testing.assert_allclose(lyap, 0.0, atol=1e-11)
    # ZOH input: a constant input u over dt moves x by ∫e^{Fs}ds B u
    phi2, gam = kalman.discretise_input(jnp.array([[0.0, 1.0], [0.0, 0.0]]), jnp.ones((2, 1)), dt)
    np.testing.assert_allclose(gam[:, 0], [dt + dt**2 / 2, dt], rtol=1e-12)


def test_one_state_filter_reaches_the_riccati_steady_state():
    q, r = 0.2, 1.5  # random walk x_{k+1} = x_k + w, z = x + v
    steady_prior = (q + np.sqrt(q * q + 4 * q * r)) / 2
    steady_post = steady_prior * r / (steady_prior + r)
    zs = jnp.asarray(np.random.default_rng(0).normal(size=(200, 1)))
    prior = kalman.Gaussian(jnp.zeros(1), jnp.eye(1) * 10.0)
    one = jnp.eye(1)
    xs, ps, _ = kalman.kalman_filter(prior, one, q * one, one, r * one, zs)
    np.testing.assert_allclose(ps[-1, 0, 0], steady_post, rtol=1e-10)
    # the mean is the scalar recursion x ← x + k (z − x) with k = P⁻/(P⁻ + r)
    x, p = 0.0, 10.0
    for z in np.asarray(zs[:, 0]):
        p += q
        k = p / (p + r)
        x, p = x + k * (z - x), (1 - k) * p
    np.testing.assert_allclose(xs[-1, 0], x, rtol=1e-10)
    p_ss, k_ss, s_ss = kalman.steady_state(one, q * one, one, r * one, one * 10.0, 500)
    np.testing.assert_allclose(p_ss[0, 0], steady_prior, rtol=1e-12)
    np.testing.assert_allclose(k_ss[0, 0], steady_prior / (steady_prior + r), rtol=1e-12)
    np.testing.assert_allclose(s_ss[0, 0], steady_prior + r, rtol=1e-12)


def test_filter_log_likelihood_is_the_joint_gaussian_density():
    rng = np.random.default_rng(2)
    phi = jnp.array([[1.0, 0.5], [0.0, 0.9]])
    qd = jnp.array([[0.1, 0.02], [0.02, 0.05]])
    h = jnp.array([[1.0, 0.0]])
    r = jnp.array([[0.3]])
    p0 = jnp.eye(2)
    zs = jnp.asarray(rng.normal(size=(6, 1)))
    _, _, ll = kalman.kalman_filter(kalman.Gaussian(jnp.zeros(2), p0), phi, qd, h, r, zs)
    # joint covariance of z_1..z_K from the state covariances and cross terms
    k = 6
    phis = [np.linalg.matrix_power(np.asarray(phi), i) for i in range(k + 1)]
    pk = [None] * (k + 1)
    p = np.asarray(p0)
    for i in range(1, k + 1):
        p = np.asarray(phi) @ p @ np.asarray(phi).T + np.asarray(qd)
        pk[i] = p
    cov = np.zeros((k, k))
    for i in range(1, k + 1):
        for j in range(i, k + 1):
            cij = (np.asarray(h) @ phis[j - i] @ pk[i] @ np.asarray(h).T)[0, 0]
            cov[i - 1, j - 1] = cov[j - 1, i - 1] = cij
    cov += np.eye(k) * 0.3
    z = np.asarray(zs[:, 0])
    want = -0.5 * (z @ np.linalg.solve(cov, z) + np.linalg.slogdet(cov)[1] + k * np.log(2 * np.pi))
    np.testing.assert_allclose(ll, want, rtol=1e-10)


def _periods(traj):
    f, _, _ = sd.error_matrices(traj)
    keep = [0, 1, 3, 4, 6, 7, 8]  # horizontal model: no δh, δv_D
    ev = np.linalg.eigvals(np.asarray(f[0])[np.ix_(keep, keep)])
    assert np.max(np.abs(ev.real)) < 1e-12  # undamped
    w = np.sort(np.abs(ev.imag))
    assert w[0] < 1e-12  # the longitude mode
    return 2 * np.pi / w[1::2]


def test_stationary_error_model_eigen_periods_at_45_degrees():
    periods = _periods(tr.stationary(45.0, duration_s=10.0, earth=C.SPHERE))
    np.testing.assert_allclose(periods / 60, [1436.07, 88.04, 81.02], rtol=1e-4)
    np.testing.assert_allclose(periods[0] / 3600, 23.934, rtol=1e-4)


def test_moving_east_eigen_periods():
    """Moving east at 90 m/s at 30°: the exact linearisation's Earth mode is the nav frame's
    inertial rotation rate ω_ie + λ̇ (an inertially fixed misalignment seen from the moving
    frame). PHYSICS.md §12 quotes 21.64 h, 87.57 and 81.48 min: those are what the model
    gives when the latitude derivative of the transport rate (v_E sec²φ/R δφ) is dropped
    (checked below); the nonlinear mechanisation (next test) sides with the exact model."""
    traj = tr.constant_velocity(30.0, speed=90.0, heading_deg=90.0, duration_s=10.0, earth=C.SPHERE)
    periods = _periods(traj)
    lam_dot = 90.0 / (C.A * np.cos(30 * DEG))
    np.testing.assert_allclose(periods[0], 2 * np.pi / (C.OMEGA_IE + lam_dot), rtol=1e-9)
    np.testing.assert_allclose(periods[1:] / 60, [87.595, 81.512], rtol=1e-4)
    # the quoted figures: the same model without ∂ω_en/∂φ
    f = np.array(sd.error_matrices(traj)[0][0])
    dw = np.array([0.0, 0.0, -90.0 / C.A / np.cos(30 * DEG) ** 2])  # ∂ω_en/∂φ
    f[6:9, 0] -= dw  # from δω_in in the attitude equation
    f[3:6, 0] += np.cross(dw, np.asarray(traj.v_ned[0]))  # and from δω_en × v
    keep = [0, 1, 3, 4, 6, 7, 8]
    w = np.sort(np.abs(np.linalg.eigvals(f[np.ix_(keep, keep)]).imag))[1::2]
    np.testing.assert_allclose(2 * np.pi / w[0] / 3600, 21.64, rtol=2e-4)
    np.testing.assert_allclose(2 * np.pi / w[1] / 60, 87.57, rtol=2e-4)
    np.testing.assert_allclose(2 * np.pi / w[2] / 60, 81.48, rtol=3e-4)


def _mechanise(traj, c0s, hours):
    """Nonlinear NED mechanisation with altitude held (aided) from each initial attitude of
    `c0s` (K, 3, 3) in one vmapped solve (`helpers.mechanise_ned`)."""
    return mechanise_ned(traj, c0s, hours)


def test_linear_model_matches_the_nonlinear_mechanisation():
    """Moving east at 90 m/s at 30° for 12 h from a 1-mrad heading error and 0.2-mrad tilt:
    the difference of two nonlinear runs equals the linear model (second-order small)."""
    hours = 12.0
    traj = tr.constant_velocity(
        30.0, speed=90.0, heading_deg=90.0, duration_s=hours * 3600, dt=60.0, earth=C.SPHERE
    )
    phi = jnp.array([2e-4, -1e-4, 1e-3])
    skew = jnp.array([[0, -phi[2], phi[1]], [phi[2], 0, -phi[0]], [-phi[1], phi[0], 0]])
    c_true = traj.c_bn[0]
    ts, (y_true, y_err) = _mechanise(traj, jnp.stack([c_true, (jnp.eye(3) - skew) @ c_true]), hours)
    dx = sd.propagate(traj, jnp.zeros(9).at[6:].set(phi), altitude_aided=True)
    with CompileCounter() as c:  # the tolerances are values (each new one compiled ≈ 1.5 s)
        again = sd.propagate(traj, jnp.zeros(9).at[6:].set(phi), altitude_aided=True, rtol=1e-9)
    assert c.compiles == 0, c.names
    np.testing.assert_allclose(again, dx, rtol=0, atol=1e-6 * float(jnp.max(jnp.abs(dx))))
    idx = np.searchsorted(np.asarray(traj.t), np.asarray(ts))
    lin = np.asarray(dx)[idx]
    d = np.asarray(y_err - y_true)
    for k, j in ((0, 0), (1, 1), (2, 3), (3, 4)):  # δlat, δlon, δv_N, δv_E
        scale = np.max(np.abs(lin[:, j]))
        np.testing.assert_allclose(d[:, k], lin[:, j], atol=3e-3 * scale)
    # (the model behind 21.64 h would be 0.37 rad out of phase in its Earth mode by 12 h)


def test_single_channel_closed_forms_without_earth_rate():
    earth = C.Earth(radius=C.A, g=C.G0, rate=0.0)
    traj = tr.stationary(0.0, duration_s=7200.0, dt=60.0, earth=earth)
    t = np.asarray(traj.t)
    ws = np.sqrt(C.G0 / C.A)
    # initial tilt δθ about east: north position R δθ (1 − cos ω_s t)
    dx = np.asarray(sd.propagate(traj, jnp.zeros(9).at[7].set(1e-4), altitude_aided=True))
    north = np.asarray(sd.position_metres(traj, jnp.asarray(dx)))[:, 0]
    np.testing.assert_allclose(np.abs(north), C.A * 1e-4 * (1 - np.cos(ws * t)), atol=1e-6)
    # accelerometer bias ∇ along north (body x = north): R ∇/g (1 − cos ω_s t), peak 2R∇/g
    nab = 1e-3
    dx = sd.propagate(traj, accel_error=jnp.array([nab, 0.0, 0.0]), altitude_aided=True)
    north = np.asarray(sd.position_metres(traj, dx))[:, 0]
    np.testing.assert_allclose(north, C.A * nab / C.G0 * (1 - np.cos(ws * t)), atol=1e-6)
    assert 2 * C.A * nab / C.G0 == pytest.approx(1300.7, abs=1.0)  # "1297 m" with R ≈ 6.36e6
    # level gyro bias ε about north (body x): east position ∓R ε (t − sin(ω_s t)/ω_s)
    eps = 1e-7
    dx = sd.propagate(traj, gyro_error=jnp.array([eps, 0.0, 0.0]), altitude_aided=True)
    east = np.asarray(sd.position_metres(traj, dx))[:, 1]
    np.testing.assert_allclose(np.abs(east), C.A * eps * (t - np.sin(ws * t) / ws), atol=1e-6)
    # initial velocity error δv₀ north: δv₀ sin(ω_s t)/ω_s
    dx = sd.propagate(traj, jnp.zeros(9).at[3].set(0.1), altitude_aided=True)
    north = np.asarray(sd.position_metres(traj, dx))[:, 0]
    np.testing.assert_allclose(north, 0.1 * np.sin(ws * t) / ws, atol=1e-6)
    # a NaN error is named, eagerly and under jit (it ran the solver out of steps)
    with pytest.raises(ValueError, match=r"gyro_error must be finite; found nan"):
        sd.propagate(traj, gyro_error=jnp.array([jnp.nan, 0.0, 0.0]), altitude_aided=True)
    run = jax.jit(lambda e: sd.propagate(traj, gyro_error=e, altitude_aided=True))
    with pytest.raises(Exception, match=r"gyro_error must be finite"):
        jax.block_until_ready(run(jnp.array([jnp.nan, 0.0, 0.0])))


def test_north_gyro_bias_grows_longitude_at_r_eps_cos2_lat():
    """1e-7 rad/s north gyro bias at 30°: long-term east error ≈ R ε_N cos²φ = 1.72 km/h."""
    period = 2 * np.pi / C.OMEGA_IE
    traj = tr.stationary(30.0, duration_s=2 * period, dt=period / 360, earth=C.SPHERE)
    dx = sd.propagate(traj, gyro_error=jnp.array([1e-7, 0.0, 0.0]), altitude_aided=True)
    east = np.asarray(sd.position_metres(traj, dx))[:, 1]
    rate = abs(east[-1]) / (2 * period) * 3600  # over whole Earth periods: the mean growth
    assert rate == pytest.approx(C.A * 1e-7 * np.cos(30 * DEG) ** 2 * 3600, rel=0.005)
    assert rate / 1000 == pytest.approx(1.72, abs=0.01)


def test_monte_carlo_covariance_matches_the_propagated_covariance():
    traj = tr.stationary(45.0, duration_s=1800.0, dt=10.0)
    imu = sd.ImuErrors(gyro_bias=1e-7, accel_bias=1e-3, arw=1e-6, vrw=1e-4)
    phi, qd = sd.discretise(traj, imu, altitude_aided=True)
    p0 = sd.initial_covariance(imu, jnp.diag(jnp.array([0, 0, 0, 0.01, 0.01, 0, 1e-8, 1e-8, 1e-6])))
    ps = sd.covariance(phi, qd, p0)
    xs = sd.monte_carlo(phi, qd, p0, jax.random.key(3), 4000)
    emp = np.var(np.asarray(xs[:, -1]), axis=0)
    want = np.diag(np.asarray(ps[-1]))
    keep = [0, 1, 3, 4, 6, 7, 8]
    # 4000 samples: relative standard error of a variance √(2/n) = 2.2 %
    np.testing.assert_allclose(emp[keep], want[keep], rtol=0.1)
    with pytest.raises(ValueError, match="gyro_error must have shape"):
        sd.propagate(traj, gyro_error=jnp.zeros((5, 3)))
    with pytest.raises(ValueError, match="dt must be"):
        tr.stationary(45.0, duration_s=10.0, dt=-1.0)
    # a grid that would silently end early (9 s of 10); latitudes: tests/test_navigation.py
    with pytest.raises(
        ValueError, match=r"^stationary: dt = 3.0 s must divide duration_s = 10.0 s"
    ):
        tr.stationary(45.0, duration_s=10.0, dt=3.0)
    with pytest.raises(ValueError, match="arw must be finite"):
        sd.ImuErrors(arw=-1.0)


def test_stationary_refuses_a_traced_latitude_in_one_line():
    """vmap over latitudes raised a ConcretizationTypeError from `float()` in the position
    checks (audit of session 29). The builders integrate in NumPy (set-up, not traced): one
    line naming lat_deg and the way out."""
    with pytest.raises(TypeError, match=r"^lat_deg must be a number \[°\], not a traced value: "
                       r"trajectories are built once in NumPy .*\(a Python loop\)"):  # fmt: skip
        jax.vmap(lambda la: tr.stationary(la, duration_s=10.0).lat[0])(jnp.array([30.0, 45.0]))


def test_error_propagation_is_differentiable():
    """d(final east error)/d(gyro bias) by reverse mode through diffrax equals a central
    finite difference (the model is linear in the bias, so both are exact up to tolerance)."""
    traj = tr.stationary(30.0, duration_s=3600.0, dt=60.0, earth=C.SPHERE)

    def east(eps):
        dx = sd.propagate(traj, gyro_error=jnp.stack([eps, 0.0 * eps, 0.0 * eps]))
        return sd.position_metres(traj, dx)[-1, 1]

    g = jax.jit(jax.grad(east))(1e-7)
    fd = (east(2e-7) - east(0.0)) / 2e-7
    np.testing.assert_allclose(g, fd, rtol=1e-6)
    assert abs(g) > 1e9  # metres per rad/s: the error is really driven


def test_off_path_inputs_of_the_ins_entry_points_are_one_line():
    """Audit (ins): each of these returned a number or failed deep in JAX — a negative step
    (ekf.discretise, increments_from_states, coarse_scatter), a NaN (coarse_align, a
    platform x0, a Fault size, mechanize's initial state: "the solution stops being
    finite"), mismatched shapes broadcast or truncated (position_metres, navigation_errors,
    Truth.trajectory(every=7)), a truthy string switching a flag on (altitude_aided="no",
    Gnss(use_velocity="no")), a negative NIS judged, n_runs = 1.5 or n_steps = 1.5 run as
    1, a p0 of the wrong size reported as an attitude σ of 1 rad, a qd or p0 not PSD, a
    NaN p0_nav. Each is refused before anything compiles."""
    from hrgjax.ins import alignment as al
    from hrgjax.ins import consistency as cs
    from hrgjax.ins import ekf, gnss, motion, platform
    from hrgjax.ins import mechanization as me

    traj = tr.stationary(45.0, duration_s=10.0, dt=1.0)
    eye15, n = jnp.eye(15) * 1e-8, 10
    phi, qd = jnp.broadcast_to(jnp.eye(15), (n, 15, 15)), jnp.broadcast_to(eye15, (n, 15, 15))
    one = me.NavState(jnp.asarray(0.5), jnp.asarray(0.0), jnp.asarray(0.0), jnp.zeros(3),
                      jnp.array([1.0, 0.0, 0.0, 0.0]))  # fmt: skip
    many = jax.tree_util.tree_map(lambda a: jnp.stack([a] * 5), one)
    bad = me.NavState(jnp.asarray(np.nan), one.lon, one.h, one.v_ned, one.q_bn)
    truth = motion.Truth(many, jnp.zeros((4, 3)), jnp.zeros((4, 3)), jnp.zeros((5, 3)),
                         jnp.ones(5, bool), 0.1)  # fmt: skip
    key, f_b, w_b = jax.random.key(0), jnp.array([0.0, 0.0, -9.8]), jnp.array([5e-5, 0, -5e-5])
    ins = platform.PlatformINS()
    hand = lambda **kw: tr.Trajectory(**{f: kw.get(f, getattr(traj, f)) for f in  # noqa: E731
                                         ("t", "lat", "lon", "h", "v_ned", "c_bn", "f_ned")})  # fmt: skip
    cases = [
        (lambda: sd.position_metres(traj, jnp.zeros((11, 2))), r"^dx must be \(…, N, >=3\) .* N = 11"),
        (lambda: sd.position_metres(traj, jnp.zeros((5, 9))), r"^dx must be \(…, N, >=3\)"),
        (lambda: sd.position_metres(traj, jnp.zeros(9)), r"^dx must be \(…, N, >=3\)"),
        (lambda: sd.propagate(traj, altitude_aided="no"), r"^altitude_aided must be True or False"),
        (lambda: sd.propagate(traj, rtol=-1.0), r"^rtol must be >= 0"),
        (lambda: sd.propagate(traj, max_steps=0), r"^max_steps must be None or a whole number"),
        (lambda: sd.initial_covariance(sd.ImuErrors(), jnp.eye(9) * np.nan),
         r"^p0_nav must be a symmetric positive semi-definite \(9, 9\) covariance; it has nan"),
        (lambda: sd.covariance(phi, qd, jnp.eye(9)), r"^p0 must be \(n, n\) = \(15, 15\)"),
        (lambda: sd.covariance(phi, qd[:3], eye15), r"^qd must be \(N, n, n\) = \(10, 15, 15\)"),
        (lambda: sd.covariance(phi[0], qd[0], eye15), r"^phi must be \(N, n, n\)"),
        (lambda: sd.covariance(phi.at[0, 0, 0].set(np.nan), qd, eye15), r"^phi must be finite"),
        (lambda: sd.covariance(phi, -qd, eye15), r"^qd must be a symmetric positive semi-def"),
        (lambda: sd.monte_carlo(phi, qd, -eye15, key, 3), r"^p0 must be a symmetric positive"),
        (lambda: sd.monte_carlo(phi, qd, eye15, key, 1.5), r"^n_runs must be a whole number of"),
        (lambda: sd.monte_carlo(phi, qd, eye15, key, 0), r"^n_runs must be a whole number of"),
        (lambda: sd.monte_carlo(phi, qd, eye15, 0, 3),  # an int seed: JAX's "invalid PRNG key"
         r"^monte_carlo: key must be one JAX PRNG key, e.g. jax.random.key\(0\); got 0$"),
        (lambda: sd.monte_carlo(phi, qd, eye15, jax.random.split(key, 2), 3),
         r"^monte_carlo: key must be one JAX PRNG key.* a key array of shape \(2,\)"),
        (lambda: tr.segments(45.0, 0.0, 0.0, "abc"), r"^legs: a non-empty list of finite"),
        (lambda: me.mechanize(bad, jnp.zeros((4, 3)), jnp.zeros((4, 3)), 0.1),
         r"^initial.lat must be finite"),
        (lambda: me.mechanize(one, jnp.zeros((4, 3)), jnp.zeros((4, 3)), 0.1, vertical="x"),
         r"^vertical must be \(h, v_down\), each \(4,\)"),
        (lambda: me.increments_from_states(one, jnp.zeros((4, 3)), many.q_bn[:4], -0.1),
         r"^dt must be the increments' interval in seconds \(> 0\); got -0.1"),
        (lambda: me.increments_from_states(one, jnp.zeros((4, 3)), many.q_bn[:3], 0.1),
         r"^v_ned and q_bn must be \(N, 3\) and \(N, 4\)"),
        (lambda: me.increments_from_states(one, jnp.full((4, 3), np.nan), many.q_bn[:4], 0.1),
         r"^v_ned must be finite"),
        (lambda: me.navigation_errors(many, many[:4]), r"^nav and truth must hold the same epochs"),
        (lambda: truth.trajectory(0), r"^every must be a positive divisor of the 4 intervals"),
        (lambda: truth.trajectory(3), r"^every must be a positive divisor of the 4 intervals"),
        (lambda: cs.nis_check(-jnp.ones(20), 3), r"^nis_check: nis must be >= 0"),
        (lambda: cs.nis_check(jnp.ones(20), 1.5), r"^nis_check: innovation_dim must be a whole"),
        (lambda: gnss.Gnss(use_velocity="no"), r"^Gnss.use_velocity must be True or False"),
        (lambda: gnss.Gnss().epochs(40, 0.0), r"^Gnss.epochs needs n_intervals >= 0 and dt > 0"),
        (lambda: platform.simulate(ins, dt=1.0, n_steps=1.5, key=key), r"^n_steps must be a whole"),
        (lambda: platform.simulate(ins, dt=1.0, n_steps=5, key=key, x0=jnp.zeros(3)),
         r"^x0 must be \(17,\) platform states"),
        (lambda: platform.simulate(ins, dt=1.0, n_steps=5, key=key, x0=jnp.full(17, np.nan)),
         r"^x0 must be finite"),
        (lambda: ins.navigation_errors(jnp.zeros(5)), r"^x must be \(\.\.\., 17\) platform"),
        (lambda: platform.Fault.on("accel_x", np.nan, 5.0), r"^size must be finite"),
        (lambda: platform.Fault.on("accel_x", 1.0, np.nan), r"^t_fault must be a time"),
        (lambda: al.coarse_align(f_b * np.nan, w_b, 0.5), r"^f_b must be finite"),
        (lambda: al.coarse_align(f_b[:2], w_b, 0.5), r"^f_b must be \(3,\)"),
        (lambda: al.coarse_align(f_b, w_b, 45.0), r"^coarse_align: lat = 45 rad is beyond ±π/2"),
        (lambda: al.coarse_scatter(jnp.zeros((20, 3)), jnp.zeros((20, 3)), -0.01),
         r"^dt must be the increments' interval, one number > 0"),
        (lambda: al.coarse_scatter(jnp.zeros((20, 3)), jnp.zeros((18, 3)), 0.01),
         r"^dtheta and dvel must both be \(n, 3\)"),
        (lambda: ekf.discretise(jnp.eye(2), jnp.eye(2), -1.0), r"^discretise: T must be the int"),
        (lambda: ekf.discretise(jnp.eye(2), jnp.eye(3), 1.0), r"^discretise: F and q must both"),
        (lambda: ekf.feedback(one, jnp.zeros(5)), r"^x must be \(n,\) error states, n >= 9"),
        # session 33: a hand-built trajectory with a NaN time reached the integrator ("the
        # maximum number of solver steps was reached"); a NaN field, a short field and a
        # height of -7000 km were accepted; mechanize ran from -7000 km (gravity 66.8 m/s²),
        # 1000 km/s, or a quaternion of norm 3 (0.68 m/s from rest after 60 s)
        (lambda: hand(t=traj.t.at[3].set(np.nan)), r"^Trajectory.t must be finite; it has nan"),
        (lambda: hand(f_ned=traj.f_ned.at[2, 0].set(np.inf)), r"^Trajectory.f_ned must be fin"),
        (lambda: hand(lat=traj.lat[:-1]), r"^Trajectory.lat must be \(11,\) for the 11 times"),
        (lambda: hand(h=traj.h - 7e6), r"^Trajectory.h must be a height in metres above the "
         r"ellipsoid in \(-10000, 100000\); got -7e\+06 at index \(0,\)$"),
        (lambda: me.mechanize(one.__class__(one.lat, one.lon, one.h - 7e6, one.v_ned, one.q_bn),
                              jnp.zeros((4, 3)), jnp.zeros((4, 3)), 0.1), r"^initial.h must be a"),
        (lambda: me.mechanize(one.__class__(one.lat, one.lon, one.h, jnp.array([1e6, 0, 0]),
                                            one.q_bn), jnp.zeros((4, 3)), jnp.zeros((4, 3)), 0.1),
         r"^initial.v_ned: the speed = 1e\+06 is outside the plausible range 0 … 10000 m/s"),
        (lambda: me.mechanize(one.__class__(one.lat, one.lon, one.h, one.v_ned, 3 * one.q_bn),
                              jnp.zeros((4, 3)), jnp.zeros((4, 3)), 0.1),
         r"^initial.q_bn must be a unit quaternion; got \|q\| = 3 \(normalise it"),
        (lambda: me.NavState.from_euler(0.7, 0.0, 6.4e6, np.zeros(3), 0.0, 0.0, 0.0),
         r"^NavState.from_euler: h must be a height in metres"),
    ]  # fmt: skip
    for call, message in cases:
        with pytest.raises((ValueError, TypeError), match=message) as err:
            call()
        assert "\n" not in str(err.value), message


def test_valid_inputs_pass_the_ins_checks_as_before():
    """What the audit's checks must let through, as before they were added: a traced fault
    size or time (vmap, grad, jit), a NumPy or JAX integer `every`, a NIS of −1e-18
    (round-off)."""
    from hrgjax.ins import consistency as cs
    from hrgjax.ins import mechanization as me
    from hrgjax.ins import motion, platform

    state = me.NavState(jnp.asarray(0.5), jnp.asarray(0.0), jnp.asarray(0.0), jnp.zeros(3),
                        jnp.array([1.0, 0.0, 0.0, 0.0]))  # fmt: skip
    truth = jax.tree_util.tree_map(lambda a: jnp.stack([a] * 5), state)
    on = platform.Fault.on
    e = jax.vmap(lambda s: on("accel_x", s, 10.0).e)(jnp.array([1e-6, 2e-6]))
    np.testing.assert_array_equal(e[:, 0], [1e-6, 2e-6])
    assert float(jax.grad(lambda s: on("accel_x", s, 10.0).e.sum())(1e-6)) == 1.0
    assert float(jax.jit(lambda t: on("accel_x", 1e-6, t).t_fault)(10.0)) == 10.0
    t = motion.Truth(truth, jnp.zeros((4, 3)), jnp.zeros((4, 3)), jnp.zeros((5, 3)),
                     jnp.ones(5, bool), 0.1)  # fmt: skip
    for every in (np.int64(2), jnp.asarray(2)):
        assert t.trajectory(every).t.shape == (3,)
    # session 33's state checks: a unit quaternion rounded through float32, heights just
    # inside ±(10, 100) km and a speed of 9.9 km/s pass
    q32 = jnp.asarray(np.asarray(me.euler_to_quat(0.1, 0.2, 0.3), np.float32), float)
    for h, v in ((-9.9e3, 0.0), (9.99e4, 9.9e3)):
        me.check_state(me.NavState(state.lat, state.lon, jnp.asarray(h),
                                   jnp.array([v, 0.0, 0.0]), q32))  # fmt: skip
    assert cs.nis_check(np.array([1.0, -1e-18, 2.0] * 10), 2)["fixes"] == 30


def test_runs_of_states_broadcast_against_one_truth():
    """Runs of error states (R, N, 9) (`monte_carlo`'s) and of navigation states (R, N)
    against one trajectory or truth broadcast, as before the shape checks."""
    from hrgjax.ins import mechanization as me

    traj = tr.stationary(45.0, duration_s=10.0, dt=1.0)
    dx = jnp.arange(33.0).reshape(11, 3) * 1e-7
    one = np.asarray(sd.position_metres(traj, dx))
    with jax.numpy_rank_promotion("allow"):  # runs (R, N, 9): broadcast, as NumPy would (the
        runs = sd.position_metres(traj, jnp.stack([dx, 2 * dx]))  # tests' config refuses it)
    np.testing.assert_array_equal(runs, np.stack([one, 2 * one]))
    state = me.NavState(jnp.asarray(0.5), jnp.asarray(0.0), jnp.asarray(0.0), jnp.zeros(3),
                        jnp.array([1.0, 0.0, 0.0, 0.0]))  # fmt: skip
    truth = jax.tree_util.tree_map(lambda a: jnp.stack([a] * 5), state)
    runs = jax.tree_util.tree_map(lambda a: jnp.stack([a, a]), truth)  # 2 runs: the 2nd north
    nav = me.NavState(runs.lat.at[1].add(1e-6), runs.lon, runs.h, runs.v_ned, runs.q_bn)
    with jax.numpy_rank_promotion("allow"):
        pos = me.navigation_errors(nav, truth)[0]
        assert me.navigation_errors(truth, state)[0].shape == (5, 3)  # all epochs against one
    assert pos.shape == (2, 5, 3) and np.all(np.asarray(pos[0]) == 0) and np.all(pos[1, :, 0] > 0)


def test_a_valid_qd_stack_is_checked_on_the_device():
    """`covariance`'s model check of a valid `qd` (N, n, n) is one device reduction: it is
    never copied to the host (`check_covariance` sees `p0` only); a bad one is named."""
    n, eye = 15, jnp.eye(15)
    phi, qd = jnp.broadcast_to(eye, (10, n, n)), jnp.broadcast_to(1e-8 * eye, (10, n, n))
    seen = []
    real = sd.check_covariance
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(
            sd, "check_covariance", lambda name, a, **kw: seen.append(name) or real(name, a, **kw)
        )
        ps = sd.covariance(phi, qd, 1e-6 * eye)
        with pytest.raises(ValueError, match=r"^qd must be a symmetric .* not symmetric at step 3"):
            sd.covariance(phi, qd.at[3, 0, 1].set(1e-9), 1e-6 * eye)
    assert seen == ["p0", "qd"]  # the valid stack: p0 only; a bad one: the host check names it
    np.testing.assert_allclose(np.diagonal(ps[-1]), 1e-6 + 10 * 1e-8, rtol=1e-12)


# -- audit (session 27): alignment, the PSINS loader, trajectories, the filter and flights ---


def _still_log(n=200, lat=45.0):
    """A stationary, level, north-facing record at 1 Hz (no JAX work: increments by hand)."""
    la = np.radians(lat)
    w = C.OMEGA_IE * np.array([np.cos(la), 0.0, -np.sin(la)])
    from hrgjax.ins import alignment as al

    rows = np.ones((n, 1))
    return al.ImuLog(np.arange(1.0, n + 1), rows * w, rows * [0.0, 0.0, -9.806], la)


def _psins(tmp_path, name, header2="34 108 380 0 10 9.8", units="1 1 1 1 1 1", rows=2,
           row="1 2 3 4 5 6"):  # fmt: skip
    path = tmp_path / name
    path.write_text(f"0 0 150 0 0 0\n{header2}\n{units}\n" + f"{row}\n" * rows)
    return path


def test_off_path_inputs_of_alignment_trajectories_filter_and_flights_are_one_line(tmp_path):
    """Audit (session 27): each of these returned a number (a negative or zero step_s, noise
    or velocity noise, a non-rotation c0, a NaN time stamp, a 2-D t, a 1-sample log, a PSINS
    g or unit of 0, a negative speed, a pitch beyond 90°, fixes for another dt or in
    degrees, runs=True), a NaN attitude (a NaN noise, c0 or jacobian), or failed deep in
    Python, NumPy or JAX (an infinite coarse_s, a negative start_s, a c0 or attitude σ of
    another shape, a non-ImuLog, fixes or settings of the wrong type, a bad key). Each is
    refused in one line before anything compiles."""
    from hrgjax.ins import alignment as al
    from hrgjax.ins import ekf, flights, gnss, motion, sensors
    from hrgjax.ins import mechanization as me

    log, eye, t3 = _still_log(), np.eye(3), np.arange(1.0, 4.0)
    z3 = np.zeros((3, 3))
    one = me.NavState(jnp.asarray(0.5), jnp.asarray(0.0), jnp.asarray(0.0), jnp.zeros(3),
                      jnp.array([1.0, 0.0, 0.0, 0.0]))  # fmt: skip
    many = jax.tree_util.tree_map(lambda a: jnp.stack([a] * 5), one)
    truth = motion.Truth(many, jnp.zeros((4, 3)), jnp.zeros((4, 3)), jnp.zeros((5, 3)),
                         jnp.ones(5, bool), 0.1)  # fmt: skip
    idx = np.arange(10, 41, 10)
    fix = dict(t=idx * 0.1, index=idx, lat=np.full(4, 0.5), lon=np.zeros(4), h=np.zeros(4),
               v_ned=np.zeros((4, 3)), valid=np.ones(4, bool))  # fmt: skip
    fixes = lambda **kw: gnss.GnssData(**{**fix, **kw})  # noqa: E731
    imu, rx = sensors.preset("tactical"), gnss.Gnss()
    settings, z40, key = ekf.LooselyCoupled(imu, rx), np.zeros((40, 3)), jax.random.key(0)
    lc = lambda f, dt=0.1, s=settings: ekf.loosely_coupled(s, one, z40, z40, dt, f)  # noqa: E731
    fly = lambda **kw: flights.fly(truth, imu, settings, **{"key": key, **kw})  # noqa: E731
    rot = r"^fine_align: c0 must be a \(3, 3\) body-to-NED rotation matrix; "
    cases = [
        (lambda: al.ImuLog(t3[:, None], z3, z3, 0.5), r"^ImuLog.t must be \(N,\) times .*got shape \(3, 1\)"),
        (lambda: al.ImuLog(t3[:1], z3[:1], z3[:1], 0.5), r"^ImuLog.t must be \(N,\) times \[s\], N >= 2"),
        (lambda: al.ImuLog(np.array([1.0, np.nan, 3.0]), z3, z3, 0.5), r"^ImuLog.t must be finite \(row 1\)"),
        (lambda: al.ImuLog("abc", z3, z3, 0.5), r"^ImuLog.t must be \(N,\) times .*; got str 'abc'"),
        (lambda: al.ImuLog(t3, [[0, 0, 0], [0, 0], [0, 0, 0]], z3, 0.5), r"^ImuLog.dtheta .*got ragged list"),
        (lambda: al.ImuLog(t3, z3 + 0j, z3, 0.5), r"^ImuLog.dtheta must be \(N, 3\) .*complex128"),
        (lambda: al.ImuLog(t3, z3, z3, 0.5, header_attitude_deg=(1.0, 2.0)),
         r"^ImuLog.header_attitude_deg must be None or \(pitch, roll, heading\)"),
        (lambda: al.align(log, coarse_s=np.inf), r"^align: coarse_s must be a finite number > 0 s; got inf"),
        (lambda: al.align(log, coarse_s="60"), r"^align: coarse_s must be a single real number \[s\]"),
        (lambda: al.align(log, coarse_s=1e-5), r"^align: coarse_s must be over half the sample interval \(1 s\).*; got 1e-05 s$"),
        (lambda: al.align(log, step_s=-1.0), r"^align: step_s must be a finite number > 0 \[s\]; got -1.0"),
        (lambda: al.align(log, arw=np.nan), r"^align: arw must be a finite number >= 0 \[rad/√s\]; got nan"),
        (lambda: al.align(log, velocity_noise=0.0), r"^align: velocity_noise must be a finite number > 0"),
        (lambda: al.align(log, attitude_std_deg=(1.0, 2.0)), r"^align: attitude_std_deg must be \(level, "),
        (lambda: al.align(log, start_s=10.0), r"^align: unknown option 'start_s'; fine_kw are step_s"),
        (lambda: al.align((t3, z3, z3)), r"^align: log must be an ImuLog"),
        (lambda: al.fine_align(log, np.eye(2)), rot + r"got ndarray of shape \(2, 2\)"),
        (lambda: al.fine_align(log, 2 * eye), rot + r"\|CᵀC − I\| reaches 3"),
        (lambda: al.fine_align(log, -eye), rot + r"det C = -1: a reflection"),
        (lambda: al.fine_align(log, eye * np.nan), r"^fine_align: c0 must be finite"),
        (lambda: al.fine_align(log, eye, step_s=0.3), r"^fine_align: step_s = 0.3 s is under half"),
        (lambda: al.fine_align(log, eye, start_s=-50.0), r"^fine_align: start_s must be a finite num"),
        (lambda: al.fine_align(log, eye, start_s=1e4), r"^fine_align: the log \(200 s\) holds fewer than 2 steps .* start_s = 10000 s"),
        (lambda: al.fine_align(log, eye, gyro_bias_std=-1e-7), r"^fine_align: gyro_bias_std must be a finite"),
        (lambda: al.fine_align(log, eye, arw=np.array([1e-6, 2e-6])), r"^fine_align: arw must be a single real number"),
        (lambda: al.fine_align(log, eye, start_bias_jacobian=np.full((3, 6), np.nan)),
         r"^fine_align: start_bias_jacobian must be finite"),
        (lambda: al.load_psins(None), r"^load_psins: path must be a file path"),
        (lambda: al.load_psins(_psins(tmp_path, "g.imu", header2="34 108 380 0 10 0")),
         r"g.imu: the header's g \[m/s²\] \(line 2, field 6\) must be > 0; got 0$"),
        (lambda: al.load_psins(_psins(tmp_path, "u.imu", units="0 1 1 1 1 1")),
         r"u.imu: the header's gyro increment unit \[arcsec\] \(line 3, field 1\) must be > 0"),
        (lambda: al.load_psins(_psins(tmp_path, "lon.imu", header2="34 500 380 0 10 9.8")),
         r"lon.imu: the header's longitude \[°\] \(line 2, field 2\) must be in \[-180, 360\]"),
        (lambda: al.load_psins(_psins(tmp_path, "one.imu", rows=1)), r"one.imu: a PSINS log needs at least 2 samples; got 1$"),
        (lambda: al.load_psins(_psins(tmp_path, "nan.imu", row="1 nan 3 4 5 6")),
         r"nan.imu: sample row 0, field 2 \(gyro increment forward\) must be a finite integer"),
        (lambda: tr.constant_velocity(45.0, speed=-5.0, duration_s=10.0), r"^constant_velocity: speed must be >= 0 m/s"),
        (lambda: tr.stationary(45.0, pitch_deg=95.0, duration_s=10.0), r"^stationary: pitch_deg must be in \[-90, 90\] °"),
        (lambda: tr.stationary(45.0, pitch_deg=-91.0, duration_s=10.0), r"^stationary: pitch_deg must be in \[-90, 90\]"),
        (lambda: tr.stationary(45.0, duration_s="10"), r"^stationary: duration_s must be a single real number \[s\]; got str"),
        (lambda: tr.stationary(45.0, duration_s=10.0, dt=np.array([1.0, 2.0])), r"^stationary: dt must be a single real number"),
        (lambda: tr.constant_velocity(45.0, duration_s=10.0, earth="wgs84"), r"^constant_velocity: earth must be an Earth model"),
        (lambda: ekf.LooselyCoupled("imu", rx), r"^LooselyCoupled.imu must be of type ImuModel; got 'imu'"),
        (lambda: ekf.LooselyCoupled(imu, None), r"^LooselyCoupled.gnss must be of type Gnss; got None"),
        (lambda: ekf.LooselyCoupled(imu, rx, earth="wgs84"), r"^LooselyCoupled.earth must be of type Earth"),
        (lambda: ekf.LooselyCoupled(imu, rx, gauss_markov="no"), r"^LooselyCoupled.gauss_markov must be True or False"),
        (lambda: ekf.LooselyCoupled(imu, rx, position_sigma="abc"), r"^LooselyCoupled.position_sigma must be > 0 .*; got str"),
        (lambda: ekf.LooselyCoupled(imu, rx, position_sigma=np.ones((1, 3))),
         r"^LooselyCoupled.position_sigma must be > 0 \(1 or 3 values\); got \[\[1.0, 1.0, 1.0\]\]$"),
        (lambda: lc(fixes(), s="x"), r"^loosely_coupled: settings must be a LooselyCoupled; got 'x'"),
        (lambda: lc("fixes"), r"^loosely_coupled: fixes must be a GnssData \(gnss.measure\); got 'fixes'"),
        (lambda: lc(fixes(lon=np.zeros(2))), r"^loosely_coupled: fixes.lon must be \(4,\) for the 4 fixes"),
        (lambda: lc(fixes(v_ned=np.zeros((4, 2)))), r"^loosely_coupled: fixes.v_ned must be \(4, 3\) for the 4 fixes"),
        (lambda: lc(fixes(valid=np.full(4, 0.5))), r"^loosely_coupled: fixes.valid must be \(4,\) bools \(or ints 0 and 1\) for the 4 fixes"),
        (lambda: lc(fixes(), dt=0.2), r"^loosely_coupled: fixes.t must be fixes.index × dt \(dt = 0.2 s\) plus one offset .*spans 3 s: fixes made for another"),
        (lambda: lc(fixes(lat=np.array([0.5, np.nan, 0.5, 0.5]))), r"^loosely_coupled: fixes.lat \(a valid fix\) must be finite"),
        (lambda: lc(fixes(lat=np.full(4, 40.0))), r"^loosely_coupled: fixes.lat = 40 rad is beyond ±π/2"),
        (lambda: flights.fly("truth", imu, settings, key=key), r"^fly: truth must be of type Truth"),
        (lambda: fly(key=0), r"^fly: key must be one JAX PRNG key, e.g. jax.random.key\(0\); got 0$"),
        (lambda: fly(runs=True), r"^fly: runs must be a whole number >= 1; got True"),
        (lambda: fly(gyro_rate_error=np.full((4, 3), np.nan)), r"^fly: gyro_rate_error must be finite"),
        (lambda: fly(gyro_rate_error="x"), r"^fly: gyro_rate_error must be \(N, 3\) or \(3,\)"),
    ]  # fmt: skip
    for call, message in cases:
        with pytest.raises((ValueError, TypeError), match=message) as err:
            call()
        assert "\n" not in str(err.value), message


def test_valid_inputs_pass_the_session_27_checks_as_before():
    """What the new checks must let through: a log built under `jit` (its values unchecked,
    as a traced log's always were) or from lists, NaN in a fix that is not valid, pitch ±90°,
    a speed of 0."""
    from hrgjax.ins import alignment as al
    from hrgjax.ins import ekf, gnss

    t, z = np.arange(1.0, 4.0), np.zeros((3, 3))
    total = jax.jit(lambda a: al.ImuLog(t, a, z, 0.5).dtheta.sum())(jnp.ones((3, 3)))
    assert float(total) == 9.0  # was a TracerArrayConversionError
    assert al.ImuLog([1.0, 2.0, 3.0], [[0.0, 0.0, 0.0]] * 3, z, 0.5).t.shape == (3,)
    idx = np.arange(10, 41, 10)
    lat = np.array([0.5, np.nan, 0.5, 0.5])  # an outage's fix: not used
    fixes = gnss.GnssData(idx * 0.1, idx, lat, np.zeros(4), np.zeros(4), np.zeros((4, 3)),
                          np.array([True, False, True, True]))  # fmt: skip
    ekf.check_fixes(fixes, 0.1)
    for pitch in (90.0, -90.0):
        assert tr.stationary(45.0, pitch_deg=pitch, duration_s=10.0).t.shape == (11,)
    assert tr.constant_velocity(45.0, speed=0.0, duration_s=10.0).t.shape == (11,)


def _review_fixes(**kw):
    """120 fixes every 3rd IMU epoch at 0.1 s (no JAX work), with fields `kw` replaced."""
    from hrgjax.ins import gnss

    idx = np.arange(3, 361, 3)
    fix = dict(t=idx * 0.1, index=idx, lat=np.full(idx.size, 0.5), lon=np.zeros(idx.size),
               h=np.zeros(idx.size), v_ned=np.zeros((idx.size, 3)),
               valid=np.ones(idx.size, bool))  # fmt: skip
    return gnss.GnssData(**{**fix, **kw})


def test_fixes_with_gps_time_or_float32_stamps_and_int_masks_are_accepted():
    """Review (session 27): fixes stamped in GPS time (t + 345600 s) or float32 `t`, and a 0/1
    int `valid` mask, were refused (`t` had to be index × dt to 1e-9; the filter reads `index`,
    never `t`). Fixes for another IMU interval, a fix a sample off its epoch, a NaN stamp and
    a mask holding a 2 are still refused, naming `loosely_coupled`."""
    from hrgjax.ins import ekf

    idx, dt = np.arange(3, 361, 3), 0.1
    for t in (idx * dt + 345600.0, (idx * dt).astype(np.float32),
              (idx * dt + 345600.0).astype(np.float32), idx * dt + 0.04 * np.sin(idx)):  # fmt: skip
        ekf.check_fixes(_review_fixes(t=t), dt)  # GPS time, float32, both; jitter < dt/2
    ekf.check_fixes(_review_fixes(valid=np.r_[1, 0, np.ones(idx.size - 2)].astype(int)), dt)
    ekf.check_fixes(_review_fixes(valid=list(np.ones(idx.size, bool))), dt)
    head = r"^loosely_coupled: fixes.t must be fixes.index × dt \(dt = 0.1 s\) plus one offset"
    for t, spread in ((idx * 0.2, "35.7"), (idx * dt + np.r_[0.0, 0.2, np.zeros(118)], "0.2")):
        with pytest.raises(ValueError, match=head + rf".*spans {spread} s: fixes made for another"):
            ekf.check_fixes(_review_fixes(t=t), dt)
    with pytest.raises(ValueError, match=r"^loosely_coupled: fixes.t must be finite; it has nan"):
        ekf.check_fixes(_review_fixes(t=np.r_[np.nan, idx[1:] * dt]), dt)
    with pytest.raises(ValueError, match=r"^loosely_coupled: fixes.valid must be \(120,\) bools "
                       r"\(or ints 0 and 1\) for the 120 fixes; got 2 at fix 1$"):  # fmt: skip
        ekf.check_fixes(_review_fixes(valid=np.r_[1, 2, np.ones(118)].astype(int)), dt)


def test_a_step_of_exactly_half_a_sample_is_accepted():
    """Review (session 27): `fine_align(log, c0, step_s=log.dt / 2)` ran one sample a step
    (max(1, round(0.5))) and was refused as "under half" (Python's round(0.5) is 0); a
    `coarse_s` of half a sample spans no sample (refused, as before), and says so."""
    from hrgjax.ins import alignment as al
    from hrgjax.ins import fine_alignment as fa

    log = _still_log(20)
    for step in (0.5, 0.5 * (1 - 1e-12), log.dt / 2):
        fa.check_step("fine_align", step, log.dt)
    with pytest.raises(ValueError, match=r"^fine_align: step_s = 0.49 s is under half the log's"):
        fa.check_step("fine_align", 0.49, log.dt)
    with pytest.raises(ValueError, match=r"^check_stationary: coarse_s must be over half the "
                       r"sample interval \(1 s\): the coarse span needs a sample; got 0.5 s$"):  # fmt: skip
        al.check_stationary(log, 0.5)


def test_review_messages_name_the_function_and_stay_short():
    """Review (session 27): a (100, 100) σ printed a 50 KB line; align's coarse_s, the
    trajectories' duration_s and earth, and loosely_coupled's settings named no function; a
    pitch 1e-12 beyond 90° read "got 90"."""
    from hrgjax.ins import alignment as al
    from hrgjax.ins import ekf, gnss, sensors
    from hrgjax.ins import mechanization as me

    log, imu, rx = _still_log(20), sensors.preset("tactical"), gnss.Gnss()
    z40 = np.zeros((40, 3))
    one = me.NavState(jnp.asarray(0.5), jnp.asarray(0.0), jnp.asarray(0.0), jnp.zeros(3),
                      jnp.array([1.0, 0.0, 0.0, 0.0]))  # fmt: skip
    cases = [
        (lambda: ekf.LooselyCoupled(imu, rx, position_sigma=np.ones((100, 100))),
         r"^LooselyCoupled.position_sigma must be > 0 \(1 or 3 values\); got jax.Array of shape "
         r"\(100, 100\) and dtype float64$"),
        (lambda: ekf.LooselyCoupled(imu, rx, velocity_sigma=[1.0, -1.0, 1.0]),
         r"^LooselyCoupled.velocity_sigma must be > 0 \(1 or 3 values\); got \[1.0, -1.0, 1.0\]$"),
        (lambda: al.align(log, coarse_s=np.inf), r"^align: coarse_s must be a finite number > 0"),
        (lambda: al.check_stationary(log, np.inf), r"^check_stationary: coarse_s must be a fini"),
        (lambda: tr.stationary(45.0, duration_s="10"), r"^stationary: duration_s must be a single"),
        (lambda: tr.stationary(45.0, duration_s=10.0, earth="wgs84"), r"^stationary: earth must "),
        (lambda: tr.constant_velocity(45.0, duration_s=-1.0), r"^constant_velocity: duration_s mu"),
        (lambda: tr.stationary(45.0, pitch_deg=90 + 1e-12, duration_s=10.0),
         r"^stationary: pitch_deg must be in \[-90, 90\] ° .*; got 90.000000000001$"),
        (lambda: ekf.loosely_coupled(None, one, z40, z40, 0.1, _review_fixes()),
         r"^loosely_coupled: settings must be a LooselyCoupled; got None$"),
    ]  # fmt: skip
    for call, message in cases:
        with pytest.raises((ValueError, TypeError), match=message):
            call()


# -- audit (session 31): a fast mode off F's diagonal, dt, Euler angles, units ----------------


def test_discretise_refuses_or_squares_a_fast_oscillation_off_the_diagonal():
    """Audit: `discretise([[−0.01, 5], [−5, −0.01]], 0.02·I, 1 s)` bounded only |F_ii|·h and
    returned a growing Φ (2.6 for expm's 0.28). Concrete F: refused in one line naming the
    `fastest` to pass, with which Φ is scipy's expm and Q_d `van_loan`'s; traced F (jit): an
    `eqx.error_if` on the same F, while a slow F passes the same program (and vmap, grad)."""
    from scipy.linalg import expm

    from hrgjax.ins import ekf

    F, q = np.array([[-0.01, 5.0], [-5.0, -0.01]]), 0.02 * np.eye(2)
    with pytest.raises(ValueError, match=r"^discretise: F has an eigenvalue \|λ\| = 5.00001 /s, "
                       r"too fast .* pass fastest=5.00001 \(the largest \|λ\| of F\)$"):  # fmt: skip
        ekf.discretise(F, q, 1.0)
    phi, qd = ekf.discretise(F, q, 1.0, fastest=5.00001)  # the printed value is taken
    np.testing.assert_allclose(phi, expm(F), rtol=0, atol=1e-12)
    np.testing.assert_allclose(qd, kalman.van_loan(F, q, 1.0)[1], rtol=0, atol=1e-12)
    step = jax.jit(lambda f: ekf.discretise(f, q, 1.0)[0])
    with pytest.raises(Exception, match=r"discretise: F \(traced\) has a mode too fast"):
        jax.block_until_ready(step(F))
    slow = np.array([[0.0, 1.0], [-0.01, 0.0]])  # 0.1 rad/s: the series over 1 s is exact
    np.testing.assert_allclose(step(slow), expm(slow), rtol=0, atol=1e-13)
    np.testing.assert_allclose(jax.vmap(step)(jnp.stack([slow, slow / 2]))[1], expm(slow / 2),
                               rtol=0, atol=1e-13)  # fmt: skip
    got = jax.grad(lambda a: step(a * slow)[0, 1])(1.0)  # d expm(aF)/da = F expm(aF) at a = 1
    assert float(got) == pytest.approx((slow @ expm(slow))[0, 1], rel=1e-10)


def test_mechanize_refuses_a_dt_under_which_the_vehicle_falls_freely():
    """Audit: stationary 100-Hz increments with dt = 1 s ran silently to h = 353 km. A mean
    specific force under 0.2 g over the record is refused naming `dt` and the dt that gives
    1 g; free fall stays physical: all-zero increments, half a record in free fall, and
    traced increments pass."""
    from hrgjax.ins import mechanization as me

    dv = np.tile([0.0, 0.0, -C.G0 * 0.01], (100, 1))  # at rest, 0.01 s each
    dth = np.zeros((100, 3))
    start = me.NavState.from_euler(0.7, 0.0, 0.0, np.zeros(3), 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match=r"^dt: the mean specific force \|dv\|/dt is 0.09807 m/s²"
                       r" \(0.01 g\) with dt = 1 s, under the 0.2 g of a navigating vehicle .*"
                       r"\(dt = 0.01 s gives 1 g\)$"):  # fmt: skip
        me.mechanize(start, dth, dv, 1.0)
    me.check_increments(dth, dv, 0.01)
    me.check_increments(dth, np.zeros((100, 3)), 1.0)
    me.check_increments(dth, np.where(np.arange(100)[:, None] < 50, dv, 0.0), 0.01)  # 0.5 g
    jax.jit(lambda d: me.check_increments(dth, d, 1.0)[1])(dv)


def test_euler_angles_in_degrees_are_refused_where_concrete():
    """Audit: `NavState.from_euler(…, roll=0, pitch=30, heading=1)` (degrees) checked only the
    latitude and built a state. Pitch beyond ±π/2, roll beyond ±π, heading beyond ±2π are
    refused with the radians; the bounds themselves and traced angles pass."""
    from hrgjax.ins import mechanization as me

    make = lambda r, p, h: me.NavState.from_euler(0.7, 0.0, 0.0, np.zeros(3), r, p, h)  # noqa: E731
    for angles, name, shown in (((0.0, 30.0, 1.0), "pitch", "30"), ((4.0, 0.0, 1.0), "roll", "4"),
                                ((0.0, 0.0, 90.0), "heading", "90")):  # fmt: skip
        with pytest.raises(ValueError, match=rf"^NavState.from_euler: {name} = {shown} rad is "
                           rf"beyond .*degrees\? use np.radians\({shown}\) = "):  # fmt: skip
            make(*angles)
    make(-np.pi, np.pi / 2, -2 * np.pi)
    jax.jit(lambda p: make(0.0, p, 0.0).q_bn)(30.0)


def test_imu_errors_and_gnss_sigmas_in_datasheet_units_are_refused():
    """Audit: `ImuErrors(gyro_bias=1.0)` (°/h typed as rad/s), `accel_bias=25` (µg) and
    `Gnss(position_sigma=150)` (cm) ran. ImuErrors holds `ImuModel`'s ranges with their unit
    hints; Gnss σ beyond 100 m, 10 m/s; valid and traced values pass."""
    from hrgjax.ins import gnss

    cases = [
        (lambda: sd.ImuErrors(gyro_bias=1.0),
         r"^ImuErrors.gyro_bias \[rad/s\] = 1 is outside the plausible range .* °/h → ×"),
        (lambda: sd.ImuErrors(accel_bias=25.0), r"^ImuErrors.accel_bias \[m/s²\] = 25 .* µg → ×"),
        (lambda: sd.ImuErrors(arw=0.01), r"^ImuErrors.arw \[rad/√s\] = 0.01 .* °/√h → ×"),
        (lambda: gnss.Gnss(position_sigma=150.0),
         r"^Gnss.position_sigma = 150 m is beyond the 100 m of a GNSS fix's 1σ — cm → ÷100"),
        (lambda: gnss.Gnss(velocity_sigma=(0.05, 0.05, 50.0)),
         r"^Gnss.velocity_sigma = 50 m/s is beyond the 10 m/s .* cm/s → ÷100"),
    ]  # fmt: skip
    for call, message in cases:
        with pytest.raises(ValueError, match=message) as err:
            call()
        assert "\n" not in str(err.value), message
    sd.ImuErrors(1e-7, 1e-4, 1e-6, 1e-5)
    gnss.Gnss(position_sigma=(1.5, 1.5, 3.0), velocity_sigma=0.05)
    jax.vmap(lambda g: sd.ImuErrors(gyro_bias=g).gyro_bias)(jnp.array([1.0, 2.0]))
