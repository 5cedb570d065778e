"""Averaged model: agreement with the full model, reduced forms of PHYSICS.md §10,
gradients, vmap and compilation behaviour."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import OMEGA, CompileCounter, resonator, slope

import hrgjax as hg
from hrgjax.simulate import simulate_with_stats
from hrgjax.units import DEG

THETAS = jnp.deg2rad(jnp.array([5.0, 35.0, 65.0, 95.0, 125.0, 155.0]))
DEFECTS = {
    "damping_anisotropy": dict(delta_inv_tau=0.01, theta_tau=0.3),
    "frequency_split": dict(delta_omega=0.02, theta_omega=-0.2),
    "nonlinearity": dict(chi=300.0),
    "all": dict(delta_inv_tau=0.01, theta_tau=0.3, delta_omega=0.02, theta_omega=-0.2, chi=300.0),
}


def _rates(gyro, model):
    prof = hg.Profile.constant_rate(2.0, 3.0, wave_angle0_deg=0.0)

    def one(th):
        p = eqx.tree_at(lambda p: p.wave_angle0, prof, th)
        return hg.simulate(gyro, p, model=model, dt_out=0.25)

    recs = jax.vmap(one)(THETAS)
    return np.array([slope(recs.t[i], recs.true_wave_angle[i]) for i in range(len(THETAS))])


@pytest.mark.parametrize("defect", list(DEFECTS))
def test_averaged_matches_full_loops_closed(defect):
    """Pattern-angle rate within 1 % of the defect rate over a grid of θ, loops closed
    (force AGC with an excitation-phase error and a readout gain mismatch to couple q)."""
    res = resonator(tau=20.0, **DEFECTS[defect])
    gyro = hg.Gyro(
        res,
        control=hg.Control(excitation_phase=0.05),
        readout=hg.Readout(gain_mismatch=0.002),
    )
    full = _rates(gyro, "full")
    avg = _rates(gyro, "averaged")
    table = -0.554 * 2.0 * DEG
    defect_rate = np.max(np.abs(full - table))
    assert defect_rate > 2e-5
    np.testing.assert_allclose(avg, full, atol=0.01 * defect_rate)


def test_averaged_matches_full_parametric_drive():
    res = resonator(tau=20.0, **DEFECTS["all"])
    gyro = hg.Gyro(res, control=hg.Control(drive="parametric", excitation_phase=0.05))
    full, avg = _rates(gyro, "full"), _rates(gyro, "averaged")
    defect_rate = np.max(np.abs(full + 0.554 * 2.0 * DEG))
    np.testing.assert_allclose(avg, full, atol=0.01 * defect_rate)


@pytest.fixture(scope="module")
def ideal_rates():
    """Drift of the ideal-loop averaged model over a grid of θ, temperatures frozen."""

    def run(gyro, theta, rate_dps=0.0, accel_z=0.0):
        prof = hg.Profile.constant_rate(rate_dps, 10.0, accel_g=(0.0, 0.0, accel_z))
        prof = eqx.tree_at(lambda p: p.wave_angle0, prof, theta)
        rec = hg.simulate(gyro, prof, dt_out=1.0)
        return rec

    return jax.vmap(run, in_axes=(None, 0, None, None))


def test_reduced_damping_anisotropy_bias_gain_accel(ideal_rates):
    """θ̇ = −k_e(Ω + b + G a_z) + d sin2(θ−θτ), d = ½Δ(1/τ) (§10 nominal + acceleration)."""
    res = resonator(delta_inv_tau=2e-5, theta_tau=0.4)
    gyro = eqx.tree_at(
        lambda g: (g.rate_bias, g.g_sensitivity),
        hg.presets.ideal(res),
        (jnp.asarray(3e-6), jnp.array([0.0, 0.0, 2e-6])),
    )
    recs = ideal_rates(gyro, THETAS, 1.0, 0.5)
    rates = np.array([slope(recs.t[i], recs.wave_angle[i]) for i in range(len(THETAS))])
    th = np.asarray(recs.wave_angle[:, 5])
    expect = -0.554 * (DEG + 3e-6 + 0.5 * 2e-6) + 1e-5 * np.sin(2 * (th - 0.4))
    # tolerance: curvature of sin2(θ−θτ) over the 10-s fit window (≈ 0.1 % of d)
    np.testing.assert_allclose(rates, expect, rtol=0, atol=2e-8)


def test_reduced_drive_gain_mismatch():
    """Forcer gain mismatch g with force AGC: θ̇ = −(g/τ) sin 2θ (§10 drive_gain_mismatch)."""
    g, tau = 0.004, 20.0
    gyro = hg.Gyro(resonator(tau=tau), control=hg.Control(forcer_gain_mismatch=g))
    rates = _rates(gyro, "averaged") + 0.554 * 2.0 * DEG
    th = np.asarray(THETAS) - 0.554 * 2.0 * DEG * 1.5
    np.testing.assert_allclose(rates, -(g / tau) * np.sin(2 * th), rtol=2e-2, atol=1e-7)


def test_reduced_readout_gain_mismatch():
    """θ_meas − θ = ½ε₁ sin2θ + ½ε₂ cos2θ with ε₁ = −2g, ε₂ = 2(c − ε_m) (§10 readout)."""
    g, c, m = 3e-3, 1e-3, 4e-4
    gyro = hg.presets.ideal(resonator())
    gyro = eqx.tree_at(lambda gy: gy.readout, gyro, hg.Readout(g, c, m))
    prof = hg.Profile.constant_rate(30.0, 6.0)
    rec = hg.simulate(gyro, prof, dt_out=0.05)
    th = np.asarray(rec.true_wave_angle)
    err = np.asarray(rec.wave_angle) - th
    expect = -g * np.sin(2 * th) + (c - m) * np.cos(2 * th) - m
    np.testing.assert_allclose(err, expect, atol=3 * (g**2 + c**2))


def test_frequency_split_and_nonlinearity_instantaneous_laws():
    """With q ≠ 0 (quadrature loop open): θ̇ = −½Δω cos2(θ−θω)·2aq/(a²−q²) − χaq/(4ω)."""
    dw, thw, chi = 0.01, 0.3, 200.0
    res = resonator(tau=1e6, delta_omega=dw, theta_omega=thw, chi=chi)
    gyro = hg.Gyro(res, control=hg.Control.free())
    rec = hg.simulate(
        gyro, hg.Profile.static(4.0, wave_angle0_deg=5.0), quadrature0=0.02, dt_out=0.1
    )
    th, a, q = (np.asarray(x) for x in (rec.wave_angle, rec.amplitude, rec.quadrature))
    t = np.asarray(rec.t)
    rate = (th[2:] - th[:-2]) / (t[2:] - t[:-2])
    pi_ = 2 * a * q / (a**2 - q**2)
    expect = -0.5 * dw * np.cos(2 * (th - thw)) * pi_ - chi * a * q / (4 * OMEGA)
    np.testing.assert_allclose(rate, expect[1:-1], rtol=1e-3, atol=1e-9)


def test_wave_angle_past_a_circular_ellipse():
    """Audit: a free wave 45° off a 0.5 Hz split turns circular at 0.5 s (q = a); after it
    the averaged wave_angle flipped by π from sample to sample (the state keeps θ while
    |q| > |a|). The closed form (PHYSICS.md §4.3, principal-axis frame, u₀ = π/4):
    θ − θ_ω = ½·atan2(cos Δωt, 0), i.e. +45° before 0.5 s and −45° after (the full model and
    the auditor's integrator gave −45°); read on the canonical branch |a| ≥ |q|."""
    from hrgjax.resonator.averaged import canonical_angle

    res = resonator(omega=2 * np.pi * 5e3, tau=640.0, delta_omega=2 * np.pi * 0.5)
    gyro = hg.Gyro(res, control=hg.Control.free())
    ts = np.array([0.0, 0.2, 0.4, 0.45, 0.55, 0.6, 0.8, 1.0])
    rec = hg.simulate(gyro, hg.Profile.static(1.0, 20.0, wave_angle0_deg=45.0), ts=ts)
    expect = np.where(ts < 0.5, 45.0, -45.0)
    np.testing.assert_allclose(np.asarray(rec.wave_angle) / DEG, expect, atol=1e-4)
    np.testing.assert_allclose(np.asarray(rec.true_wave_angle) / DEG, expect, atol=1e-4)
    half = np.tan(np.pi * ts / 2)  # the state turns at Δω/2 in the (a, q) plane: q/a = tan
    ratio = np.asarray(rec.quadrature) / np.asarray(rec.amplitude)
    np.testing.assert_allclose(ratio, np.minimum(half, 1 / np.maximum(half, 1e-300)), atol=1e-6)
    assert float(canonical_angle(0.6, 0.8, 0.3)) == 0.3 - np.pi / 2
    assert float(canonical_angle(-0.8, 0.6, 0.3)) == 0.3


@pytest.mark.slow(
    "~50 s: the reverse pass, its forward runs and the 4-checkpoint pass compiled; fast "
    "tier: jacfwd = jacrev through simulate (test_forward_mode_sensitivities), reverse = "
    "forward = finite differences on the full model "
    "(test_carrier::test_reverse_gradient_equals_finite_differences)"
)
def test_grad_matches_finite_differences():
    """∂(final wave angle)/∂(Δ(1/τ), θτ, k_e) through diffrax == central differences; with
    fewer checkpoints than steps (what runs longer than 256 steps do: recomputation between
    checkpoints) the gradient is the same to round-off."""
    import diffrax

    base = resonator(delta_inv_tau=0.02, theta_tau=0.3)
    prof = hg.Profile.constant_rate(3.0, 5.0, wave_angle0_deg=20.0)
    gyro = hg.Gyro(base)

    def loss(p, adjoint=None):
        r = eqx.tree_at(lambda r: (r.delta_inv_tau, r.theta_tau, r.k_e), base, tuple(p))
        g = eqx.tree_at(lambda g: g.resonator, gyro, r)
        rec = hg.simulate(g, prof, dt_out=5.0, rtol=1e-11, atol=1e-13, adjoint=adjoint)
        return rec.wave_angle[-1]

    p0 = jnp.array([0.02, 0.3, 0.554])
    grad = jax.grad(loss)(p0)
    h = jnp.array([1e-6, 1e-6, 1e-6])
    fd = jnp.stack(
        [(loss(p0.at[i].add(h[i])) - loss(p0.at[i].add(-h[i]))) / (2 * h[i]) for i in range(3)]
    )
    np.testing.assert_allclose(grad, fd, rtol=1e-5)
    assert np.all(np.abs(grad) > 0)
    _, steps, _ = simulate_with_stats(gyro, prof, dt_out=5.0, rtol=1e-11, atol=1e-13)
    assert int(steps) > 4 * 4  # 4 checkpoints: most steps are recomputed
    few = diffrax.RecursiveCheckpointAdjoint(checkpoints=4)
    np.testing.assert_allclose(jax.grad(lambda p: loss(p, few))(p0), grad, rtol=1e-10)


def test_vmap_equals_loop_and_no_recompile():
    gyro = hg.presets.tvg3_like(noise=False)
    temps = jnp.array([-40.0, 10.0, 60.0])
    run = lambda T: hg.simulate(gyro, hg.Profile.static(30.0, T, 10.0), dt_out=5.0).wave_angle
    batched = jax.vmap(run)(temps)
    looped = jnp.stack([run(T) for T in temps])
    _ = run(jnp.asarray(20.0))  # a weakly typed scalar is a new input type: traced once
    new = (jnp.asarray(-5.0), temps[1] + 1.0)
    with CompileCounter() as c:  # new values of the same types: nothing traced or compiled
        for T in new:
            _ = run(T)
    assert (c.traces, c.compiles) == (0, 0), c.names
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-12)


def test_forward_mode_sensitivities():
    """jax.jacfwd through simulate (adjoint=ForwardMode) equals reverse mode."""
    import diffrax

    base = resonator(delta_inv_tau=0.02, theta_tau=0.3)
    gyro = hg.Gyro(base)
    prof = hg.Profile.constant_rate(3.0, 5.0, wave_angle0_deg=20.0)

    def angles(p, adjoint):
        r = eqx.tree_at(lambda r: (r.delta_inv_tau, r.theta_tau), base, tuple(p))
        g = eqx.tree_at(lambda g: g.resonator, gyro, r)
        return hg.simulate(g, prof, dt_out=2.5, adjoint=adjoint).wave_angle

    p0 = jnp.array([0.02, 0.3])
    fwd = jax.jit(jax.jacfwd(lambda p: angles(p, diffrax.ForwardMode())))(p0)
    rev = jax.jit(jax.jacrev(lambda p: angles(p, None)))(p0)
    np.testing.assert_allclose(fwd, rev, rtol=1e-8, atol=1e-14)
    assert fwd.shape == (3, 2)


def test_amplitude_follows_a_natural_frequency_law_adiabatically():
    """ω(T(t)) on a temperature ramp: the free amplitude goes as e^{−t/τ}·√(ω(0)/ω(t)) (E/ω
    is the adiabatic invariant; ȧ, q̇ take −½(d ln ω/dt)·a, q — the averaged model kept a
    at e^{−t/τ}, 4 % high here). At constant temperature the term is exactly zero: the same
    numbers as the gyro with ω evaluated."""
    w0, tau, dur = 2 * np.pi * 40.0, 3.0, 4.0
    law = hg.TemperatureLaw(p0=w0, p1=w0 * 1e-3)  # +1000 ppm/°C about 20 °C
    res = hg.Resonator(omega=law, tau=tau, k_e=0.554)
    gyro = hg.Gyro(res, control=hg.Control.free(), readout=hg.Readout(), noise=None)
    prof = hg.Profile.piecewise([0.0, dur], 0.0, [-20.0, 60.0], wave_angle0_deg=30.0)
    run = hg.simulate(gyro, prof, dt_out=1.0)
    t = np.asarray(run.t)
    omega = w0 * (1.0 + 1e-3 * (-40.0 + 20.0 * t))
    exact = np.exp(-t / tau) * np.sqrt(omega[0] / omega)
    np.testing.assert_allclose(np.asarray(run.amplitude), exact, rtol=1e-7)
    np.testing.assert_allclose(np.asarray(run.wave_angle), np.radians(30.0), rtol=0, atol=1e-12)
    static = hg.Profile.piecewise([0.0, dur], 0.0, [50.0, 50.0], wave_angle0_deg=30.0)
    fixed = hg.Gyro(res.at(50.0), control=hg.Control.free(), readout=hg.Readout(), noise=None)
    held, plain = hg.simulate(gyro, static, dt_out=1.0), hg.simulate(fixed, static, dt_out=1.0)
    np.testing.assert_array_equal(np.asarray(held.amplitude), np.asarray(plain.amplitude))
    np.testing.assert_array_equal(np.asarray(held.wave_angle), np.asarray(plain.wave_angle))


def test_slow_manifold_refuses_open_loops():
    """Audit: `slow_manifold` / `reduced_rate` returned NaN for open loops (a free resonator,
    a bandwidth of 0: the Newton step's Jacobian is singular). They are refused in one line
    naming the loop; a traced bandwidth of 0 raises when the program runs."""
    import dataclasses

    from hrgjax.resonator.slow import reduced_rate

    gyro = hg.Gyro(resonator(delta_inv_tau=0.01, delta_omega=0.02, chi=300.0))
    w = np.radians(5.0)
    with_control = lambda **kw: eqx.tree_at(  # noqa: E731
        lambda g: g.control, gyro, dataclasses.replace(gyro.control, **kw)
    )
    # one program for the closed loops and the traced open one below (run eagerly, the
    # Newton and balance solves compiled ≈ 200 small programs: 10 s on two cores)
    traced = jax.jit(lambda b: reduced_rate(with_control(quadrature_bandwidth=b), w, 0.3))
    assert np.isfinite(float(traced(float(gyro.control.quadrature_bandwidth))))
    with pytest.raises(ValueError, match=r"free resonator \(Control.free\(\)\) has none"):
        reduced_rate(with_control(enabled=False), w, 0.3)
    for loop in ("pll", "agc", "quadrature"):
        with pytest.raises(ValueError, match=f"Control.{loop}_bandwidth = 0 rad/s opens that"):
            reduced_rate(with_control(**{f"{loop}_bandwidth": 0.0}), w, 0.3)
    with pytest.raises(Exception, match="a traced Control bandwidth is <= 0"):
        jax.block_until_ready(traced(0.0))
