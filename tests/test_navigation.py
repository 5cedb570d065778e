"""Navigation-grade INS: the nonlinear mechanization against closed forms, against the
physical integrals of a closed-form motion, and against the linear error model; motion
files."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax import plausible
from hrgjax.ins import constants as C
from hrgjax.ins import mechanization as me
from hrgjax.ins import motion as mo
from hrgjax.ins import strapdown as sd
from hrgjax.ins import trajectory as tr
from hrgjax.units import DEG, DEG_PER_H, G0

Z = (0.0, 0.0, 0.0)


def _short_motion():
    """240 s with a take-off run, a climb, a banked turn and a descent: every kind of
    segment, rates changing axis abruptly."""
    s = mo.Segment
    return mo.Motion(
        30.0,
        -20.0,
        50.0,
        (5.0, 0.0, 0.0),
        80.0,
        0.0,
        0.0,
        (
            s(1, Z, (3.0, 0.0, 0.0), 40.0),
            s(2, (80.0, 6.0, 0.0), (125.0, 0.0, 0.0), 10.0),
            s(1, Z, Z, 50.0),
            s(5, (0.0, -6.0, 25.0), (125.0, 0.0, 0.0), 10.0),
            s(1, (2.0, 0.0, 0.0), Z, 60.0, False),
            s(4, (-170.0, -2.0, 0.0), (-5.0, 0.0, 0.0), 20.0),
            s(3, (0.0, 2.0, 0.0), Z, 50.0),
        ),
    )


@pytest.fixture(scope="module")
def motion():
    return _short_motion()


@pytest.fixture(scope="module")
def truth50(motion):
    return motion.truth(50.0)


@pytest.fixture(scope="module")
def truth25(motion):
    return motion.truth(25.0)


def _physical_increments(motion, truth, nodes=5):
    """∫ω_ib^b dt and ∫f^b dt over each interval by Gauss–Legendre quadrature of the closed-
    form motion (NumPy; the Earth terms at linearly interpolated latitude and height)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    dt, n = truth.dt, truth.dtheta.shape[0]
    mid = (np.arange(n) + 0.5) * dt
    tt = mid[:, None] + 0.5 * dt * x[None]
    eu, er, vb, ab = motion.kinematics(mid[:, None] + 0 * x[None])  # the interval's segment
    eu, vb = eu + er * (tt - mid[:, None])[..., None], vb + ab * (tt - mid[:, None])[..., None]
    c = np.asarray(tr.euler_to_dcm(eu[..., 2], eu[..., 1], eu[..., 0]))
    w_nb = mo.body_rate(eu, er)
    v_n = np.einsum("...ij,...j->...i", c, vb)
    vdot = np.einsum("...ij,...j->...i", c, np.cross(w_nb, vb) + ab)
    t = np.asarray(truth.t)
    lat, h = (
        np.interp(tt, t, np.asarray(truth.states.lat)),
        np.interp(tt, t, np.asarray(truth.states.h)),
    )
    e = truth.earth
    w_ie, w_en = np.asarray(e.earth_rate(lat)), np.asarray(e.transport_rate(lat, h, v_n))
    f_n = vdot + np.cross(2 * w_ie + w_en, v_n) - np.asarray(e.gravity_ned(lat, h))
    c_nb = np.swapaxes(c, -1, -2)
    w_ib = np.einsum("...ij,...j->...i", c_nb, w_ie + w_en) + w_nb
    f_b = np.einsum("...ij,...j->...i", c_nb, f_n)
    integral = lambda y: 0.5 * dt * np.einsum("k,nkj->nj", w, y)
    return integral(w_ib), integral(f_b)


def test_rotations_agree_with_the_direction_cosines_and_invert():
    rng = np.random.default_rng(0)
    r, p, h = rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)
    q = me.euler_to_quat(r, p, h)
    np.testing.assert_allclose(me.quat_to_dcm(q), tr.euler_to_dcm(r, p, h), atol=1e-15)
    # rotation vectors across the series/trig switch (1e-2 rad) and up to π
    u = rng.normal(size=(200, 3))
    phi = (
        u / np.linalg.norm(u, axis=1, keepdims=True) * np.logspace(-9, np.log10(3.1), 200)[:, None]
    )
    np.testing.assert_allclose(
        me.quat_to_rotvec(me.rotvec_to_quat(phi)), phi, rtol=1e-13, atol=1e-16
    )
    a = np.linalg.norm(phi, axis=1, keepdims=True)
    qt = np.concatenate([np.cos(a / 2), np.sin(a / 2) * phi / a], 1)
    np.testing.assert_allclose(me.rotvec_to_quat(phi), qt, rtol=1e-15, atol=1e-16)
    # composition: q(φ)⊗q(ψ) is the product of the matrices
    p1, p2 = me.rotvec_to_quat(phi[-1]), me.rotvec_to_quat(phi[-7])
    np.testing.assert_allclose(
        me.quat_to_dcm(me.quat_multiply(p1, p2)),
        me.quat_to_dcm(p1) @ me.quat_to_dcm(p2),
        atol=1e-15,
    )
    # differentiable at zero
    g = jax.jacfwd(me.rotvec_to_quat)(jnp.zeros(3))
    np.testing.assert_allclose(g, np.vstack([np.zeros(3), 0.5 * np.eye(3)]), atol=0)


def test_at_rest_the_exact_increments_are_earth_rate_and_gravity():
    m = mo.Motion(45.0, 10.0, 300.0, Z, 30.0, 2.0, -1.0, (mo.Segment(1, Z, Z, 20.0),))
    t = m.truth(10.0)
    c_nb = np.asarray(t.states.c_bn[0]).T
    lat, h = float(t.states.lat[0]), float(t.states.h[0])
    w = c_nb @ np.asarray(C.earth_rate_ned(lat)) * t.dt
    np.testing.assert_allclose(t.dtheta, np.broadcast_to(w, t.dtheta.shape), rtol=1e-10, atol=1e-20)
    # (to the step's second-order terms in the frame rotation ζ: |ζ|² ≈ 5e-11)
    f = -c_nb @ np.asarray(C.gravity_ned(lat, h)) * t.dt
    np.testing.assert_allclose(t.dv, np.broadcast_to(f, t.dv.shape), rtol=1e-9, atol=0)
    np.testing.assert_allclose(t.states.lat, lat, atol=1e-17)
    np.testing.assert_allclose(t.states.h, h, atol=1e-12)


def test_free_integration_of_exact_increments_returns_the_trajectory(motion, truth50, truth25):
    nav = me.mechanize(truth50.initial, truth50.dtheta, truth50.dv, truth50.dt)
    p, v, a = me.navigation_errors(nav, truth50.states)
    assert np.abs(p).max() < 1e-7 and np.abs(v).max() < 1e-9 and np.abs(a).max() < 1e-12
    # the sampled truth is the closed-form motion: attitude and velocity at every epoch
    eu, _, vb, _ = motion.kinematics(np.asarray(truth50.t))
    c = np.asarray(tr.euler_to_dcm(eu[:, 2], eu[:, 1], eu[:, 0]))
    np.testing.assert_allclose(truth50.states.c_bn, c, atol=1e-14)
    np.testing.assert_allclose(truth50.states.v_ned, np.einsum("nij,nj->ni", c, vb), atol=1e-12)
    # and its positions are the continuous motion's to the trapezoid's O(Δt²): 25 Hz and
    # 50 Hz differ by 3/4 of 25 Hz's error, ≈ Δt²/12·|Δ(dv/dt)| ≈ 0.6 mm
    np.testing.assert_allclose(truth25.states.lat, truth50.states.lat[::2], rtol=0, atol=2e-10)
    np.testing.assert_allclose(truth25.states.h, truth50.states.h[::2], rtol=0, atol=1e-3)
    # every-th epoch equals the full history's
    thin = me.mechanize(truth50.initial, truth50.dtheta, truth50.dv, truth50.dt, every=50)
    np.testing.assert_allclose(thin.lat, nav.lat[::50], rtol=0, atol=1e-15)


def test_exact_increments_are_the_physical_integrals_to_the_algorithms_order(
    motion, truth50, truth25
):
    """The exact increments equal ∫ω dt and ∫f dt except at a rate's change of axis, where
    they absorb the two-sample algorithm's (ωΔt)²/12; the physical integrals themselves
    navigate with that algorithm error, which falls 4× per halving of Δt (second order)."""
    errs = []
    for t in (truth25, truth50):
        dth, dv = _physical_increments(motion, t)
        d = np.abs(dth - np.asarray(t.dtheta)).max(axis=1)
        assert np.median(d) < 1e-14 and d.max() < 2e-7  # ≈ (0.26 rad/s · 0.04 s)²/12 ≈ 9e-6·…
        nav = me.mechanize(t.initial, jnp.asarray(dth), jnp.asarray(dv), t.dt)
        p, _, a = me.navigation_errors(nav, t.states)
        errs.append((np.abs(p[:, :2]).max(), np.abs(a).max()))
    (p25, a25), (p50, a50) = errs
    assert 3.5 < p25 / p50 < 4.6 and 3.5 < a25 / a50 < 4.6, errs
    assert p50 < 0.05


def test_linear_error_model_is_the_nonlinear_difference_to_second_order(truth50):
    """Constant sensor biases through the mechanization vs strapdown.propagate along the
    same truth: the relative gap is below 0.1 % for navigation-grade errors (0.01 °/h,
    10 µg) and grows in proportion to the errors (the linear model's neglected terms are
    second order) once it is above the floor of the linear model's 0.1-s interpolation of the
    trajectory (≈ 1e-4)."""
    every = 5
    traj = truth50.trajectory(every)
    bg = np.array([1.0, -0.7, 0.5]) * 0.01 * DEG_PER_H
    ba = np.array([-0.6, 1.0, 0.8]) * 10e-6 * G0
    gaps = []
    for scale in (1.0, 100.0, 1000.0):
        nav = me.mechanize(
            truth50.initial,
            truth50.dtheta + (bg * scale * truth50.dt)[None],
            truth50.dv + (ba * scale * truth50.dt)[None],
            truth50.dt,
            every=every,
        )
        p, v, a = (np.asarray(x) for x in me.navigation_errors(nav, truth50.states[::every]))
        dx = sd.propagate(traj, gyro_error=bg * scale, accel_error=ba * scale)
        lin = (
            np.asarray(sd.position_metres(traj, dx)),
            np.asarray(dx[:, 3:6]),
            np.asarray(dx[:, 6:9]),
        )
        gaps.append(
            [np.abs(x - y).max() / np.abs(y).max() for x, y in zip((p, v, a), lin, strict=True)]
        )
    small, mid, large = np.asarray(gaps)  # ×1: a few metres; ×1000: kilometres
    assert np.all(small < 1e-3), small
    np.testing.assert_allclose(large / mid, 10.0, rtol=0.2)


def test_vertical_aiding_holds_the_height_as_the_linear_models_altitude_aiding(truth50):
    """With the height and vertical velocity given, the mechanization's horizontal errors
    from a gyro bias follow the linear model with `altitude_aided=True`."""
    every, t = 25, truth50
    bg = np.array([2.0, -1.5, 1.0]) * DEG_PER_H
    vertical = (t.states.h[1:], t.states.v_ned[1:, 2])
    nav = me.mechanize(
        t.initial, t.dtheta + (bg * t.dt)[None], t.dv, t.dt, every=every, vertical=vertical
    )
    p, v, _ = (np.asarray(x) for x in me.navigation_errors(nav, t.states[::every]))
    np.testing.assert_allclose(p[:, 2], 0.0, atol=1e-9)
    traj = t.trajectory(every)
    dx = sd.propagate(traj, gyro_error=bg, altitude_aided=True)
    lin = np.asarray(sd.position_metres(traj, dx))
    assert np.abs(p[:, :2] - lin[:, :2]).max() < 2e-3 * np.abs(lin[:, :2]).max()
    with pytest.raises(ValueError, match=r"vertical must be \(h, v_down\)"):
        me.mechanize(t.initial, t.dtheta, t.dv, t.dt, vertical=(t.states.h, t.states.v_ned[:, 2]))


def _final_error(t, n=2500):
    """The position error after the first `n` steps (the first 50 s: the take-off run and
    the rotation into the climb) as a function of p = (gyro bias [rad/s] (3,), gyro scale
    factor (3,))."""

    def final(p):
        dth = t.dtheta[:n] * (1.0 + p[3:])[None] + (p[:3] * t.dt)[None]
        nav = me.mechanize(t.initial, dth, t.dv[:n], t.dt, every=n)
        return me.navigation_errors(nav, t.states[jnp.array([0, n])])[0][-1]

    return final


P0 = jnp.array([1e-5, -2e-5, 3e-5, 2e-4, -1e-4, 3e-4])


def test_mechanization_is_differentiable_and_vmaps(truth50):
    """The gradient of the final position error with respect to gyro biases and scale factors
    (forward mode) equals central differences to 1e-6, and a vmap over the parameters equals
    the runs one by one."""
    final = _final_error(truth50)
    e = jnp.array([1e-5] * 3 + [1e-3] * 3)  # above the positions' round-off (≈ 1e-7 m)
    steps = jnp.concatenate([jnp.diag(e), -jnp.diag(e), P0[None]])
    batch = jax.jit(jax.vmap(final))(P0[None] + steps)  # twelve differences and P0 + P0
    fd = (batch[:6] - batch[6:12]).T / (2 * e)[None]
    jac = jax.jit(jax.jacfwd(final))(P0)
    scale = np.abs(fd).max(axis=1, keepdims=True)  # per position component
    assert np.all(np.abs(jac - fd) <= 1e-6 * scale), np.abs(jac - fd) / scale
    assert np.abs(fd[:, 3:]).max() > 1.0  # the rotation makes the scale factors count
    np.testing.assert_allclose(batch[12], jax.jit(final)(2 * P0), rtol=1e-12, atol=1e-12)


@pytest.mark.slow(
    "~25 s: compiling the reverse pass through the unrolled scan; fast tier: the same "
    "Jacobian by forward mode against central differences "
    "(test_mechanization_is_differentiable_and_vmaps)"
)
def test_reverse_mode_gradient_equals_forward_mode(truth50):
    final = _final_error(truth50)
    horizontal = lambda p: jnp.linalg.norm(final(p)[:2])
    grad = jax.jit(jax.grad(horizontal))(P0)
    h0 = final(P0)[:2]
    want = (h0 / jnp.linalg.norm(h0)) @ jax.jit(jax.jacfwd(final))(P0)[:2]
    np.testing.assert_allclose(grad, want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


def test_motion_files_round_trip_and_bad_input_names_the_line(motion, tmp_path):
    path = tmp_path / "motion.csv"
    motion.to_csv(path)
    assert mo.Motion.from_csv(path) == motion
    gvis = motion.gnss_visible(np.array([0.0, 109.99, 110.0, 169.99, 170.0]))
    np.testing.assert_array_equal(gvis, [True, True, False, False, True])
    # a gnss-ins-sim file (its own motion_def-3d.csv layout, GPS column optional)
    path.write_text(
        "ini lat (deg),ini lon (deg),ini alt (m),ini vx_body (m/s),ini vy_body (m/s),"
        "ini vz_body (m/s),ini yaw (deg),ini pitch (deg),ini roll (deg)\n"
        "32,120,0,0,0,0,0,0,0\n"
        "command type,yaw (deg),pitch (deg),roll (deg),vx_body (m/s),vy_body (m/s),"
        "vz_body (m/s),command duration (s),GPS visibility\n"
        "1,0,0,0,0,0,0,200,1\n5,0,45,0,10,0,0,250,1\n1,10,0,0,0,0,0,100\n"
    )
    m = mo.Motion.from_csv(path)
    assert m.duration == 550.0 and m.segments[-1].gnss
    eu, rate, vb, _ = m.kinematics(np.array([200.0, 450.0, 550.0]))
    np.testing.assert_allclose(eu[1] / DEG, [0.0, 45.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(vb[1], [10.0, 0.0, 0.0])
    np.testing.assert_allclose(eu[2, 0] / DEG, 1000.0)
    path.write_text(path.read_text().replace("5,0,45,0,10,0,0,250,1", "5,0,4x5,0,10,0,0,250,1"))
    with pytest.raises(ValueError, match=r"motion.csv:5: expected numbers"):
        mo.Motion.from_csv(path)
    with pytest.raises(ValueError, match="segment 1: duration 10.005 s is not a whole number"):
        mo.Motion(0.0, 0.0, 0.0, Z, 0.0, 0.0, 0.0, (mo.Segment(1, Z, Z, 10.005),)).truth(100.0)
    with pytest.raises(ValueError, match="pitch reaches ±89° by the end of segment 1"):
        mo.Motion(0.0, 0.0, 0.0, Z, 0.0, 0.0, 0.0, (mo.Segment(3, (0.0, 95.0, 0.0), Z, 10.0),))
    start = motion.truth(1.0).initial
    with pytest.raises(ValueError, match=r"dtheta and dv must both have shape \(N, 3\)"):
        me.mechanize(start, np.zeros((5, 3)), np.zeros((4, 3)), 1.0)
    with pytest.raises(ValueError, match="dv holds NaN or inf .first at row 2"):
        me.mechanize(
            start, np.zeros((5, 3)), np.where(np.arange(15).reshape(5, 3) == 7, np.nan, 0.0), 1.0
        )
    with pytest.raises(
        ValueError,
        match="dtheta turns 5.73 rad in one interval .row 0.: gyro increments are in radians",
    ):
        me.mechanize(
            start,
            np.full((5, 3), 0.0) + np.array([[5.73, 0, 0]] + [[0, 0, 0]] * 4),
            np.zeros((5, 3)),
            1.0,
        )
    # dt as a NumPy or JAX scalar is checked too; dv given as accelerations [m/s²]
    for dt in (np.array(-0.1), jnp.asarray(-0.1), np.array([0.1, 0.1])):
        with pytest.raises(
            ValueError, match=r"^dt must be (one number, )?the increments' interval"
        ):
            me.mechanize(start, np.zeros((5, 3)), np.zeros((5, 3)), dt)
    rates = np.tile([0.0, 0.0, -9.81], (5, 1))  # at rest, as m/s² instead of m/s per 0.1 s
    with pytest.raises(
        ValueError, match=r"^dv: the median specific force .*10 g.* not accelerations"
    ):
        me.mechanize(start, np.zeros((5, 3)), rates, 0.1)
    me.check_increments(np.zeros((5, 3)), rates * 0.1, 0.1)  # the increments themselves pass
    # and a header read in another order (lat,lon,alt,yaw,…) is refused, naming the column;
    # gnss-ins-sim's "reserved" columns, case and a missing GPS column are accepted
    head, ini, cmd, *rest = path.read_text().replace("4x5", "45").splitlines()
    path.write_text("\n".join(["lat,lon,alt,yaw,pitch,roll,vx,vy,vz", ini, cmd, *rest]))
    with pytest.raises(
        ValueError, match=r"motion.csv:1: header column 1 is 'lat', expected 'ini lat \(deg\)'"
    ):
        mo.Motion.from_csv(path)
    loose = "Command Type,yaw (rad),pitch,roll,vx_body,reserved,reserved,command duration (s)"
    path.write_text("\n".join([head, ini, loose, *rest]))
    assert mo.Motion.from_csv(path).duration == 550.0
    path.write_text("\n".join([head, ini, cmd.replace("vy_body", "vx_body"), *rest]))
    with pytest.raises(
        ValueError, match=r":3: header column 6 is 'vx_body \(m/s\)', expected 'vy_"
    ):
        mo.Motion.from_csv(path)
    path.write_text("\n".join([head, ini.replace("120", "nan"), cmd, *rest]))
    with pytest.raises(ValueError, match=r"motion.csv:2: Motion.lon_deg must be finite"):
        mo.Motion.from_csv(path)


@pytest.mark.filterwarnings("ignore:The copy keyword is deprecated")  # pyins on pandas 3
def test_the_response_to_sensor_errors_equals_pyins_integrator(truth50):
    """pyins 1.0's strapdown integrator (a peer implementation of Savage's algorithm, its
    Earth terms at each interval's start) on the same increments with pyins's gravity model:
    on the exact increments it is off by its own first-order truncation (≈ 1 cm here), but the
    response to the sensor errors — each integrator's run with errors minus its run without —
    agrees to the millimetre on a kilometre-scale error."""
    pd = pytest.importorskip("pandas")
    ps = pytest.importorskip("pyins.strapdown")
    pe = pytest.importorskip("pyins.earth")

    class PyinsGravity(C.Earth):
        def gravity(self, lat, h=0.0):
            s2 = jnp.sin(lat) ** 2
            return C.GAMMA_E * (1 + pe.F * s2) / jnp.sqrt(1 - C.E2 * s2) * (1 - 2 * h / C.A)

    earth = PyinsGravity()
    t = _short_motion().truth(50.0, earth=earth)
    cols = ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
    s = t.states
    roll, pitch, heading = (float(np.asarray(x)[0]) / DEG for x in s.euler)
    pva = pd.Series(
        {"lat": float(s.lat[0]) / DEG, "lon": float(s.lon[0]) / DEG, "alt": float(s.h[0]),
         "VN": float(s.v_ned[0, 0]), "VE": float(s.v_ned[0, 1]), "VD": float(s.v_ned[0, 2]),
         "roll": roll, "pitch": pitch, "heading": heading}
    )  # fmt: skip

    def pyins_position(dth, dv):
        rows = np.vstack([np.zeros((1, 6)), np.hstack([dth, dv])])  # a "before" sample
        imu = pd.DataFrame(rows, index=np.arange(rows.shape[0]) * t.dt, columns=cols)
        traj = ps.Integrator(pva).integrate(ps.compute_increments_from_imu(imu, "increment"))
        return np.stack([traj.lat.values * DEG, traj.lon.values * DEG, traj.alt.values], -1)

    bg = np.array([0.3, -0.2, 0.25]) * DEG_PER_H
    ba = np.array([50e-6, -80e-6, 30e-6]) * G0
    dth = np.asarray(t.dtheta) + bg * t.dt
    dv = np.asarray(t.dv) + ba * t.dt
    nav = me.mechanize(t.initial, dth, dv, t.dt, earth=earth)
    ours = np.stack([np.asarray(nav.lat), np.asarray(nav.lon), np.asarray(nav.h)], -1)
    theirs, theirs0 = (
        pyins_position(dth, dv),
        pyins_position(np.asarray(t.dtheta), np.asarray(t.dv)),
    )
    truth = np.stack([np.asarray(s.lat), np.asarray(s.lon), np.asarray(s.h)], -1)
    r_m, r_n = (np.asarray(x) for x in earth.radii(np.asarray(s.lat)))
    metres = np.stack(
        [
            r_m + np.asarray(s.h),
            (r_n + np.asarray(s.h)) * np.cos(np.asarray(s.lat)),
            np.ones_like(r_m),
        ],
        -1,
    )
    own_error = np.abs((theirs0 - truth) * metres)
    assert 1e-4 < own_error[:, :2].max() < 0.05  # pyins's truncation on exact increments
    response_ours, response_theirs = (ours - truth) * metres, (theirs - theirs0) * metres
    assert np.abs(response_ours[:, :2]).max() > 30.0
    np.testing.assert_allclose(response_ours, response_theirs, rtol=0, atol=2e-3)


@pytest.mark.slow(
    "~40 s: an HRG pair simulated for 10 min and both navigation models compiled; fast tier: "
    "test_vertical_aiding_holds_the_height_as_the_linear_models_altitude_aiding (the same "
    "comparison on constant biases); benchmarks/navigation.py --ins-impact runs the 1-h flights"
)
def test_ins_impact_through_the_mechanization_equals_the_linear_model():
    import hrgjax as hg
    from hrgjax.calibration import NoCompensation
    from hrgjax.calibration import ins_impact as ii

    flight = ii.Flight(duration_s=600.0)
    gyro = hg.presets.tvg3_like()
    rec = ii.fly(gyro, flight, key=jax.random.key(0), bias_key=jax.random.key(1))
    v_lin, p_lin = ii.navigation_errors(NoCompensation(), rec, flight)
    v_mech, p_mech = ii.mechanized_errors(NoCompensation(), rec, flight)
    assert p_lin > 1.0
    np.testing.assert_allclose([v_mech, p_mech], [v_lin, p_lin], rtol=0.02)


def test_positions_speeds_and_grids_out_of_range_are_one_line_errors():
    """Bad motions, trajectory grids and latitudes: one line naming the field, raised before
    any JAX work; a latitude in degrees where radians are expected is refused, a traced one
    is not checked."""
    seg = (mo.Segment(1, Z, Z, 10.0),)
    motion = lambda **kw: mo.Motion(**{**dict(lat_deg=45.0, lon_deg=0.0, h=0.0, velocity=Z,
                                              yaw_deg=0.0, pitch_deg=0.0, roll_deg=0.0,
                                              segments=seg), **kw})  # fmt: skip
    for field, value, match in [
        ("lon_deg", np.nan, r"Motion.lon_deg must be finite"),
        ("yaw_deg", np.nan, r"Motion.yaw_deg must be finite"),
        ("roll_deg", np.inf, r"Motion.roll_deg must be finite"),
        ("velocity", (np.nan, 0.0, 0.0), r"Motion.velocity must be finite"),
        ("velocity", (1.0, 0.0), r"Motion.velocity must be 3 values \(vx, vy, vz\) body \[m/s\]"),
        ("lon_deg", 1000.0, r"Motion.lon_deg must be in \[-180, 360\] °"),
        ("lat_deg", 90.0, r"Motion.lat_deg must be in \[-89, 89\] °"),
        ("velocity", (1e9, 0.0, 0.0), r"Motion.velocity: the initial speed = 1e\+09 is outside "
         r"the plausible range 0 … 10000 m/s"),
        ("segments", (mo.Segment(1, Z, (2000.0, 0.0, 0.0), 10.0),),
         r"Motion: the speed by the end of segment 1 = 20000 is outside the plausible range"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match="^" + match):
            motion(**{field: value})
    with plausible.relaxed(speed_mps=(0.0, 3e4)):  # an explicit override: accepted
        motion(segments=(mo.Segment(1, Z, (2000.0, 0.0, 0.0), 10.0),))
    for lat, match in [(90.0, r"in \[-89, 89\] ° \(the navigation frame is singular"),
                       (100.0, r"in \[-89, 89\] °"), (np.nan, "finite")]:  # fmt: skip
        for build in (tr.stationary, tr.constant_velocity):
            with pytest.raises(ValueError, match=r"^lat_deg must be " + match):
                build(lat, duration_s=10.0)
        with pytest.raises(ValueError, match=r"^lat_deg must be " + match):
            tr.segments(lat, 0.0, 0.0, [(10.0, 1.0, 0.0, 0.0)])
    with pytest.raises(ValueError, match=r"^legs: a non-empty list of finite"):
        tr.segments(45.0, 0.0, 0.0, [(10.0, np.nan, 0.0, 0.0)])
    with pytest.raises(ValueError, match=r"^NavState.from_euler: lat = 45 rad .* np.deg2rad"):
        me.NavState.from_euler(45.0, 0.0, 0.0, np.zeros(3), 0.0, 0.0, 0.0)
    lat = jax.jit(lambda la: me.NavState.from_euler(la, 0.0, 0.0, jnp.zeros(3), 0, 0, 0).lat)
    assert float(lat(45.0)) == 45.0  # traced: not checked


def test_a_flight_over_a_pole_is_refused_at_the_time_it_passes_the_limit():
    """300 m/s due north from 88.9° (or due south from −88.9°): the meridian arc to ±89°
    (quadrature of the WGS-84 meridian radius) takes 37.23 s, so the 1-s trajectory and the
    motion's truth are refused at t = 38 s, one line naming the time and the limit; short of
    it they are built. A motion that climbs past 100 km and free inertial navigation whose
    latitude passes 90° are refused too, naming the time."""
    phi = np.linspace(88.9 * DEG, C.MAX_LAT_DEG * DEG, 20001)
    arc = np.trapezoid(C.A * (1 - C.E2) / (1 - C.E2 * np.sin(phi) ** 2) ** 1.5, phi)
    first = int(np.ceil(arc / 300.0))
    assert first == 38
    match = rf"^the {{}} goes beyond latitude ±89° at t = {first} s \(-?89\.00\d+°\): the "
    with pytest.raises(ValueError, match=match.format("trajectory")) as err:
        tr.constant_velocity(88.9, speed=300.0, heading_deg=0.0, duration_s=60.0)
    assert "\n" not in str(err.value)
    tj = tr.constant_velocity(88.9, speed=300.0, heading_deg=0.0, duration_s=37.0)
    assert np.degrees(float(tj.lat[-1])) < C.MAX_LAT_DEG
    for lat, yaw in ((88.9, 0.0), (-88.9, 180.0)):
        m = mo.Motion(lat, 0.0, 0.0, (300.0, 0.0, 0.0), yaw, 0.0, 0.0,
                      (mo.Segment(1, Z, Z, 60.0),))  # fmt: skip
        with pytest.raises(ValueError, match=match.format("motion")):
            m.truth(1.0)
    # session 33: only the start's height was checked (a climb at 1 km/s from 99 km reached
    # 618 km): 60° pitch at 1 km/s climbs 866.03 m/s, past 100 km between t = 1 and 2 s
    climb = mo.Motion(
        45.0, 0.0, 99e3, (1e3, 0.0, 0.0), 0.0, 60.0, 0.0, (mo.Segment(1, Z, Z, 10.0),)
    )
    with pytest.raises(ValueError, match=r"^the motion leaves the heights \(-10000, 100000\) m at "
                       r"t = 2 s \(h = 100732 m\)$"):  # fmt: skip
        climb.truth(1.0)
    # ... and free inertial navigation that flies over a pole: its latitude ran on past 90°
    # (finite, unrefused). 300 m/s north from 89.99°: the meridian arc to 90° takes 3.72 s
    phi = np.linspace(89.99 * DEG, 90.0 * DEG, 2001)
    arc = np.trapezoid(C.A * (1 - C.E2) / (1 - C.E2 * np.sin(phi) ** 2) ** 1.5, phi)
    assert int(np.ceil(arc / 300.0 / 0.1)) == 38
    start = me.NavState.from_euler(89.99 * DEG, 0.0, 0.0, np.array([300.0, 0, 0]), 0, 0, 0)
    dv = np.tile([0.0, 0.0, -0.1 * float(C.gravity(89.99 * DEG))], (40, 1))
    with pytest.raises(RuntimeError, match=r"^ins.mechanize: the latitude passes ±90° at epoch "
                       r"38 \(t = 3.8 s, 90.000\d+°\): the NED navigation frame cannot fly"):  # fmt: skip
        me.mechanize(start, np.zeros((40, 3)), dv, 0.1)


def test_a_latitude_in_degrees_is_refused_by_mechanize_and_trajectory():
    """|lat| > π/2 rad is a latitude in degrees: `mechanize` (through `check_state`, as
    `loosely_coupled` and `increments_from_states`) and `Trajectory` refuse it with
    `from_euler`'s hint, before any JAX work; a traced one is not checked."""
    q = jnp.array([1.0, 0.0, 0.0, 0.0])
    nav = me.NavState(jnp.asarray(45.0), jnp.asarray(0.0), jnp.asarray(0.0), jnp.zeros(3), q)
    hint = r" = 45 rad is beyond ±π/2: the latitude is in radians here \(degrees\? " + re.escape(
        "np.deg2rad(45) = 0.785398)"
    )
    with pytest.raises(ValueError, match="^initial.lat" + hint + "$"):
        me.mechanize(nav, jnp.zeros((2, 3)), jnp.zeros((2, 3)), 0.1)
    with pytest.raises(ValueError, match="^initial.lat" + hint + "$"):
        me.increments_from_states(nav, jnp.zeros((2, 3)), jnp.tile(q, (2, 1)), 0.1)
    n = 3
    fields = (np.arange(n, dtype=float), np.full(n, 45.0), np.zeros(n), np.zeros(n),
              np.zeros((n, 3)), np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))  # fmt: skip
    with pytest.raises(ValueError, match="^Trajectory.lat" + hint + "$"):
        tr.Trajectory(*fields)
    ok = tr.Trajectory(*fields[:1], np.full(n, 45.0 * DEG), *fields[2:])
    assert float(ok.lat[0]) == pytest.approx(np.pi / 4)
    traced = jax.jit(lambda la: tr.Trajectory(fields[0], la, *fields[2:]).lat)
    assert float(traced(jnp.full(n, 45.0))[0]) == 45.0  # traced: not checked


def test_segments_integrate_each_legs_rates_over_exactly_its_duration():
    """Piecewise-constant rates over whole-sample legs integrate exactly, the first leg's
    too: 45 s at 2 °/s turns 90°, 100 s at 2 m/s² from rest reaches 200 m/s (`flight()`'s
    take-off run, as its docstring says), at dt = 1 s and 0.1 s."""
    for dt in (1.0, 0.1):
        tj = tr.segments(45.0, 0.0, 0.0, [(45.0, 0.0, 2.0, 0.0), (10.0, 0.0, 0.0, 0.0)],
                         speed0=100.0, heading0_deg=0.0, dt=dt)  # fmt: skip
        heading = np.degrees(np.asarray(tj.attitude[2]))
        np.testing.assert_allclose(heading[-1], 90.0, atol=1e-9)
        np.testing.assert_allclose(heading[int(round(20.0 / dt))], 40.0, atol=1e-9)  # at 20 s
        tj = tr.segments(45.0, 0.0, 0.0, [(100.0, 2.0, 0.0, 0.0), (10.0, 0.0, 0.0, 0.0)],
                         speed0=0.0, dt=dt)  # fmt: skip
        speed = np.linalg.norm(np.asarray(tj.v_ned), axis=1)
        np.testing.assert_allclose(speed[int(round(100.0 / dt)) :], 200.0, rtol=1e-12)
    f = tr.flight()
    np.testing.assert_allclose(np.linalg.norm(np.asarray(f.v_ned[100:400]), axis=1), 200.0,
                               rtol=1e-12)  # fmt: skip


def test_segments_hold_the_climb_rate_or_refuse_it_naming_the_leg():
    """The speed is along the flight path: a climb of 0.5 m/s at 0.8 m/s is a steep climb
    (flight-path angle asin 0.625) that gains 5 m in 10 s; a climb rate above the speed (or
    within 1° of it: pitch 90° is Euler-singular) is one line naming the leg."""
    tj = tr.segments(45.0, 0.0, 0.0, [(10.0, 0.0, 0.0, 0.5)], speed0=0.8, dt=1.0)
    np.testing.assert_allclose(tj.h[-1], 5.0, rtol=1e-12)
    np.testing.assert_allclose(-np.asarray(tj.v_ned[:, 2]), 0.5, rtol=1e-12)
    np.testing.assert_allclose(tj.attitude[1], np.arcsin(0.5 / 0.8), rtol=1e-12)
    tj = tr.segments(45.0, 0.0, 0.0, [(10.0, 0.0, 0.0, 50.0)], speed0=60.0, dt=1.0)
    np.testing.assert_allclose(tj.h[-1], 500.0, rtol=1e-12)
    for legs, speed0, match in [
        ([(10.0, 0.0, 0.0, 50.0)], 10.0, "leg 1's climb rate 50 m/s exceeds the speed 10 m/s at t = 0 s"),
        ([(5.0, 1.0, 0.0, 0.0), (10.0, 0.0, 0.0, -8.0)], 0.0,
         "leg 2's climb rate -8 m/s exceeds the speed 5 m/s at t = 5 s"),
        ([(10.0, 0.0, 0.0, 10.0)], 10.0, "leg 1's climb rate 10 m/s is within 1° of the speed"),
        ([(10.0, 1.0, 0.0, 1.0)], 0.0, "leg 1's climb rate 1 m/s exceeds the speed 0 m/s"),
        ([(10.0, 0.0, 0.0, 0.0), (10.0, -2.0, 0.0, 0.0)], 10.0,
         r"the speed would become negative in leg 2 \(at t = 16 s\)"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match="^legs: " + match) as err:
            tr.segments(45.0, 0.0, 0.0, legs, speed0=speed0, dt=1.0)
        assert "\n" not in str(err.value)


def test_longitude_differences_wrap_across_the_antimeridian(truth50):
    """The same point written as lon +180° and −180° (or 0° and 360°) is no error, and a
    track carried continuously past 180° against the same track written in (−180°, 180°]
    reads round-off; the wrapped difference keeps its derivative (1 per radian)."""
    for a, b in [(180.0, -180.0), (-180.0, 180.0), (0.0, 360.0), (179.9999, -179.9999)]:
        nav, ref = (
            me.NavState.from_euler(0.2, x * DEG, 10.0, jnp.zeros(3), 0, 0, 0) for x in (a, b)
        )
        pos, _, _ = me.navigation_errors(nav, ref)
        r_n = float(C.radii(0.2)[1]) + 10.0
        want = np.deg2rad((a - b + 180.0) % 360.0 - 180.0) * r_n * np.cos(0.2)
        np.testing.assert_allclose(pos, [0.0, want, 0.0], atol=1e-6)
    s = truth50.states
    lon = s.lon + (np.pi - float(jnp.mean(s.lon)))  # the track crosses 180°
    assert float(lon.min()) < np.pi < float(lon.max())
    ahead = me.NavState(s.lat, lon, s.h, s.v_ned, s.q_bn)
    written = me.NavState(s.lat, (lon + np.pi) % (2 * np.pi) - np.pi, s.h, s.v_ned, s.q_bn)
    for nav, ref in ((ahead, written), (written, ahead)):
        pos, vel, att = me.navigation_errors(nav, ref)
        assert np.abs(np.asarray(pos)).max() < 1e-7
    at = lambda lon: me.NavState.from_euler(0.2, lon, 0.0, jnp.zeros(3), 0.0, 0.0, 0.0)
    east = lambda lon: me.navigation_errors(at(lon), at(-np.pi))[0][1]
    slope = float(jax.grad(east)(jnp.asarray(np.pi)))
    np.testing.assert_allclose(slope, float(C.radii(0.2)[1]) * np.cos(0.2), rtol=1e-12)


def test_euler_angles_hold_at_and_near_gimbal_lock():
    """`dcm_to_euler` rebuilds the matrix to round-off at every pitch, ±90° included: there
    roll is 0 and the heading is ψ − φ (+90°) or ψ + φ (−90°); elsewhere it is scipy's 'ZYX';
    its gradient is finite at the lock, near it and at roll 90° pitch 0."""
    from scipy.spatial.transform import Rotation

    near = np.pi / 2 - np.logspace(-15, -1, 15)
    pitch = np.concatenate([[np.pi / 2, -np.pi / 2], near, -near, [0.0, 0.7, -1.2]])
    r, p, h = np.meshgrid([0.3, -2.0, 3.0], pitch, [1.0, -2.5], indexing="ij")
    c = me.quat_to_dcm(me.euler_to_quat(r, p, h))
    out = me.dcm_to_euler(c)
    np.testing.assert_allclose(tr.euler_to_dcm(*out), c, atol=2e-14)
    for sign in (1, -1):
        c = me.quat_to_dcm(me.euler_to_quat(0.3, sign * np.pi / 2, 1.0))
        got = [float(x) for x in me.dcm_to_euler(c)]
        np.testing.assert_allclose(got, [0.0, sign * np.pi / 2, 1.0 - sign * 0.3], atol=1e-14)
    rng = np.random.default_rng(2)
    e = rng.uniform([-3, -1.5, -3], [3, 1.5, 3], (200, 3))
    c = me.quat_to_dcm(me.euler_to_quat(e[:, 0], e[:, 1], e[:, 2]))
    want = Rotation.from_matrix(np.asarray(c)).as_euler("ZYX")[:, ::-1]
    np.testing.assert_allclose(np.stack(me.dcm_to_euler(c), -1), want, atol=1e-13)
    total = lambda c: sum(jnp.sum(x) for x in me.dcm_to_euler(c))
    for r0, p0 in [(0.3, np.pi / 2), (0.3, -np.pi / 2), (0.3, np.pi / 2 - 1e-9), (np.pi / 2, 0.0)]:
        g = jax.grad(total)(me.quat_to_dcm(me.euler_to_quat(r0, p0, 1.0)))
        assert np.all(np.isfinite(np.asarray(g))), (r0, p0)


def test_a_motion_starting_at_pitch_89_or_more_is_refused():
    seg = (mo.Segment(3, (0.0, -10.0, 0.0), Z, 10.0),)  # it would pitch down from the start
    for pitch in (90.0, -89.0):
        with pytest.raises(ValueError, match=rf"^Motion.pitch_deg must be within ±89° .*; got "
                                             rf"{pitch}$"):  # fmt: skip
            mo.Motion(10.0, 0.0, 0.0, (10.0, 0.0, 0.0), 30.0, pitch, 20.0, seg)
    mo.Motion(10.0, 0.0, 0.0, (10.0, 0.0, 0.0), 30.0, 88.9, 20.0, seg)


def test_segments_refuse_a_leg_that_is_not_whole_samples_naming_it():
    """A 0.5-s leg at dt = 1 s would vanish (its 10° turn lost): refused, naming the leg, its
    duration and dt, as `Motion.truth` refuses such a segment; whole legs pass at 1e-9."""
    for legs, dt, match in [
        ([(9.75, 0, 0, 0), (0.5, 0, 20.0, 0), (9.75, 0, 0, 0)], 1.0,
         r"leg 1's duration 9.75 s is not a whole number of samples at dt = 1 s \(9.75 samples\)"),
        ([(10.0, 0, 0, 0), (0.5, 0, 20.0, 0), (9.5, 0, 0, 0)], 1.0, "leg 2's duration 0.5 s"),
        ([(10.0, 0, 0, 0), (0.25, 10.0, 0, 0)], 0.1, r"leg 2's duration 0.25 s .* dt = 0.1 s"),
        ([(10.0, 0, 0, 0)], 3.0, r"leg 1's duration 10 s .* dt = 3 s"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match="^legs: " + match) as err:
            tr.segments(45.0, 0.0, 100.0, legs, speed0=100.0, dt=dt)
        assert "\n" not in str(err.value)
    tj = tr.segments(45.0, 0.0, 100.0, [(0.3, 0, 0, 0), (0.7, 0, 20.0, 0)], speed0=100.0, dt=0.1)
    np.testing.assert_allclose(np.degrees(float(tj.attitude[2][-1])), 14.0, atol=1e-9)
