"""PHYSICS.md §8 checks C1–C11 against the carrier-resolving model.

The free-resonator checks run on one output grid (`FREE`: 8 s every 0.05 s) and the
closed-loop ones on another (`CLOSED`: 40 s every 0.1 s), each reading the part of the run it
needs: one compiled program per grid and control structure, not one per check (the fixed step
is the same 2.5 ms on both grids, so a check's samples are those of a run of its own length)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import OMEGA, bryan_factor, local_rate, resonator, slope

import hrgjax as hg


def free(res):
    return hg.Gyro(res, control=hg.Control.free())


def sim(gyro, prof, **kw):
    kw.setdefault("dt_out", 0.05)
    return hg.simulate(gyro, prof, model="full", **kw)


FREE = (8.0, 0.05)  # the free resonator's run [s] and output interval [s]
CLOSED = (40.0, 0.1)  # the closed loops'


def sim_free(res, rate_dps=0.0, wave_angle0_deg=0.0, **kw):
    prof = hg.Profile.constant_rate(rate_dps, FREE[0], wave_angle0_deg=wave_angle0_deg)
    return sim(free(res), prof, dt_out=FREE[1], **kw)


def sim_closed(gyro, rate_dps=0.0, wave_angle0_deg=0.0, accel_g=(0.0, 0.0, 0.0), **kw):
    prof = hg.Profile.constant_rate(rate_dps, CLOSED[0], wave_angle0_deg=wave_angle0_deg,
                                    accel_g=accel_g)  # fmt: skip
    return sim(gyro, prof, dt_out=CLOSED[1], **kw)


def until(rec, t_s):
    """The samples of `rec` up to `t_s` [s]: (t, index slice)."""
    n = int(np.searchsorted(np.asarray(rec.t), t_s + 1e-9))
    return np.asarray(rec.t)[:n], slice(0, n)


def test_c1_bryan_factor():
    assert bryan_factor(2) == pytest.approx(0.2770, abs=5e-4)
    assert bryan_factor(3) == pytest.approx(0.1622, abs=5e-4)


def test_c2_ideal_precession_any_rate():
    """θ = θ₀ − k_e∫Ω for a rate ramp; E constant; Q stays 0."""
    res = resonator(tau=1e9)
    prof = hg.Profile.piecewise([0.0, 1.0, 2.0], [0.0, 60.0, -30.0], 20.0, wave_angle0_deg=20.0)
    rec = sim(free(res), prof)
    expect = prof.wave_angle0 - 0.554 * rec.table_angle
    np.testing.assert_allclose(rec.wave_angle, expect, atol=2e-4)
    assert np.ptp(np.asarray(rec.amplitude)) < 1e-3
    assert np.max(np.abs(np.asarray(rec.quadrature))) < 1e-5


def test_c2_frequency_shift_with_rotation():
    """Oscillation frequency √(ω² + k_e²Ω²): the PLL settles on it."""
    res = resonator()
    rate = 200.0  # °/s
    rec = sim_closed(hg.Gyro(res), rate)
    w = 0.554 * np.deg2rad(rate)
    assert rec.frequency[-1] == pytest.approx(np.sqrt(OMEGA**2 + w**2), rel=0, abs=2e-3)


def test_c3_damping_anisotropy_free_decay_closed_form():
    d, th_tau, th0 = 0.02, 0.3, 0.9
    res = resonator(tau=30.0, delta_inv_tau=d, theta_tau=th_tau)
    rec = sim_free(res, wave_angle0_deg=np.rad2deg(th0))
    expect = th_tau + np.arctan(np.tan(th0 - th_tau) * np.exp(d * np.asarray(rec.t)))
    np.testing.assert_allclose(rec.wave_angle, expect, atol=3e-4)
    energy = np.asarray(rec.amplitude) ** 2 + np.asarray(rec.quadrature) ** 2
    dlog = slope(rec.t[:5], np.log(energy[:5]))
    assert dlog == pytest.approx(-2 / 30.0 - d * np.cos(2 * (th0 - th_tau)), rel=2e-2)


@pytest.mark.parametrize(
    "rate_over_threshold",
    [0.5, 1.6],
    ids=["locked", "adler"],
)
def test_c4_lock_in_and_adler(rate_over_threshold):
    """Below threshold the pattern locks at sin2(θ*−θτ) = 2k_eΩ/Δ(1/τ); above, Adler's law."""
    d, th_tau = 0.2, 0.1
    # τ = 5 s: both axes damped (|Δ(1/τ)| < 2/τ, PHYSICS.md §2); lock-in needs only Δ(1/τ)
    res = resonator(tau=5.0, delta_inv_tau=d, theta_tau=th_tau)
    omega_in = rate_over_threshold * 0.5 * d / 0.554
    rec = sim_closed(hg.Gyro(res), np.rad2deg(omega_in), wave_angle0_deg=70.0)
    th = np.asarray(rec.true_wave_angle)
    if rate_over_threshold < 1:
        s = np.sin(2 * (th[-1] - th_tau))
        assert s == pytest.approx(2 * 0.554 * omega_in / d, abs=2e-3)
        assert np.cos(2 * (th[-1] - th_tau)) < 0
    else:
        t = np.asarray(rec.t)
        # mean rate over whole periods of the Adler beat
        mean_rate = -np.sqrt((0.554 * omega_in) ** 2 - (0.5 * d) ** 2)
        period = np.pi / abs(mean_rate)
        k = int((t[-1] - t[0] - 5) // period)
        i0 = np.searchsorted(t, 5.0)
        i1 = np.searchsorted(t, 5.0 + k * period)
        # interpolate the end of the last whole period
        th_end = np.interp(5.0 + k * period, t, th)
        measured = (th_end - th[i0]) / (k * period)
        assert i1 > i0 and measured == pytest.approx(mean_rate, rel=5e-3)


def test_c5_split_beat():
    """No damping, no control: θ oscillates between θ₀ and 2θ_ω − θ₀ with period 2π/Δω."""
    dw, th_w, th0 = 1.0, 0.2, 0.6
    res = resonator(tau=1e9, delta_omega=dw, theta_omega=th_w)
    rec = sim_free(res, wave_angle0_deg=np.rad2deg(th0))
    t, period = until(rec, 2 * np.pi / dw)  # one beat period (to the sample before 2π/Δω)
    th = np.asarray(rec.wave_angle)[period]
    assert th.max() == pytest.approx(th0, abs=3e-3)
    assert th.min() == pytest.approx(2 * th_w - th0, abs=3e-3)
    assert th[-1] == pytest.approx(th0, abs=3e-3)
    a, q = np.asarray(rec.amplitude)[period], np.asarray(rec.quadrature)[period]
    big_q = 2 * a * q
    np.testing.assert_allclose(big_q, np.sin(2 * (th0 - th_w)) * np.sin(dw * t), atol=3e-3)


def test_c6_eqrs_linear_system_and_invariant():
    """Demodulated E, Q, R, S of the full model follow the 4×4 linear system of §3.3."""
    from hrgjax.resonator.readout import from_pendulum

    d, th_t, dw, th_w, omg = 0.05, 0.4, 0.3, -0.2, 0.1
    res = resonator(tau=20.0, delta_inv_tau=d, theta_tau=th_t, delta_omega=dw, theta_omega=th_w)
    rec = sim_free(res, np.rad2deg(omg), wave_angle0_deg=25.0)
    every = slice(0, 81, 10)  # 0, 0.5, … 4 s
    demod = jax.vmap(lambda a, q, th: from_pendulum(a, q, th, 0.0))(
        rec.amplitude[every], rec.quadrature[every], rec.wave_angle[every]
    )
    eqrs = np.stack(jax.vmap(lambda dm: jnp.stack(dm.eqrs()))(demod))
    assert np.max(np.abs(eqrs[:, 0] ** 2 - (eqrs[:, 1:] ** 2).sum(1))) < 1e-12
    c2t, s2t, c2w, s2w = np.cos(2 * th_t), np.sin(2 * th_t), np.cos(2 * th_w), np.sin(2 * th_w)
    kw = 0.554 * omg
    m = np.array(
        [
            [-2 / 20, 0, -d * c2t, -d * s2t],
            [0, -2 / 20, -dw * s2w, dw * c2w],
            [-d * c2t, dw * s2w, -2 / 20, 2 * kw],
            [-d * s2t, -dw * c2w, -2 * kw, -2 / 20],
        ]
    )
    from scipy.linalg import expm

    pred = np.stack([expm(m * t) @ eqrs[0] for t in np.asarray(rec.t)[every]])
    np.testing.assert_allclose(eqrs, pred, atol=2e-3)


def test_c7_force_response_through_loop_efforts():
    """Steady loop efforts follow ȧ = −f_as/2ω and q̇ = f_qc/2ω: F = 2ωa(1/τ + ½Δ(1/τ)cos2(θ−θτ))
    and f_qc = −ωΔω a sin2(θ−θω)."""
    d, th_t, dw, th_w = 0.02, 0.3, 0.05, -0.4
    res = resonator(tau=30.0, delta_inv_tau=d, theta_tau=th_t, delta_omega=dw, theta_omega=th_w)
    ctl = hg.Control(agc_bandwidth=3.0, quadrature_bandwidth=3.0)
    rec = sim_closed(hg.Gyro(res, control=ctl), wave_angle0_deg=50.0)
    i = until(rec, 8.0)[1].stop - 1  # at 8 s (the loops settled: 1/3 s time constants)
    th = np.asarray(rec.true_wave_angle)[i]
    f_expect = 2 * OMEGA * (1 / 30.0 + 0.5 * d * np.cos(2 * (th - th_t)))
    assert rec.drive[i] == pytest.approx(f_expect, rel=2e-3)
    fq_expect = -OMEGA * dw * np.sin(2 * (th - th_w))
    assert rec.quadrature_force[i] == pytest.approx(fq_expect, rel=1e-2)


def test_c8_isotropic_duffing():
    """θ̇ = −χaq/(4ω); frequency shift 3χ(a²+q²)/(8ω)."""
    chi, q0 = 400.0, 0.1
    res = resonator(tau=1e9, chi=chi)
    rec = sim_free(res, wave_angle0_deg=10.0, quadrature0=q0)
    t, first = until(rec, 3.0)
    a, q = np.asarray(rec.amplitude)[first], np.asarray(rec.quadrature)[first]
    rate = slope(t, np.asarray(rec.wave_angle)[first])
    assert rate == pytest.approx(np.mean(-chi * a * q / (4 * OMEGA)), rel=2e-2)
    # frequency: closed PLL on the same resonator (quadrature nulled, q = 0)
    rec2 = sim_closed(hg.Gyro(res))
    shift = rec2.frequency[-1] - OMEGA
    assert shift == pytest.approx(3 * chi / (8 * OMEGA), rel=2e-2)


def test_c9_parametric_pump_threshold_and_quadrature_damping():
    """With the pump held at h = 4/(ωτ) = 2/Q (AGC open) the amplitude neither grows nor
    decays, and the quadrature decays at ωh/4 + 1/τ = 2/τ."""
    tau = 20.0
    res = resonator(tau=tau)
    ctl = hg.Control(drive="parametric", agc_bandwidth=0.0, quadrature_bandwidth=0.0)
    prof = hg.Profile.static(6.0, wave_angle0_deg=30.0)
    rec = sim(hg.Gyro(res, control=ctl), prof, quadrature0=0.05, dt_out=0.1)
    assert rec.drive[0] == pytest.approx(4 / (OMEGA * tau), rel=1e-9)
    q = np.asarray(rec.quadrature)
    assert slope(rec.t, np.log(q)) == pytest.approx(-2 / tau, rel=2e-2)
    a = np.asarray(rec.amplitude)
    assert abs(slope(rec.t, np.log(a))) < 2e-3 / tau


def test_c10_pickoff_gain_mismatch_closed_loop():
    """Gain mismatch diag(1+g, 1−g), force AGC steered by the estimate: θ̇ = −(g/τ) sin 2θ."""
    g, tau = 0.005, 10.0
    res = resonator(tau=tau)
    gyro = hg.Gyro(res, readout=hg.Readout(gain_mismatch=g))
    thetas = np.deg2rad([20.0, 45.0, 70.0])
    err = []
    for th in thetas:
        rec = sim_closed(gyro, wave_angle0_deg=np.rad2deg(th))
        t, first = until(rec, 4.0)
        rate = slope(t, np.asarray(rec.true_wave_angle)[first])
        assert rate == pytest.approx(-(g / tau) * np.sin(2 * th), rel=1.5e-2)
        err.append(rec.wave_angle[0] - rec.true_wave_angle[0])
    # readout: θ_est − θ = −g sin 2θ
    np.testing.assert_allclose(err, -g * np.sin(2 * thetas), atol=2 * g**2)


def test_c11_excitation_phase_error():
    """AGC phase error γ_e with quadrature q: θ̇ = −aq/(a²−q²)·tan γ_e/τ (instantaneous)."""
    ge, tau = 0.3, 10.0
    res = resonator(tau=tau)
    ctl = hg.Control(excitation_phase=ge, quadrature_bandwidth=0.0, pll_bandwidth=3.0)
    rec = sim_closed(hg.Gyro(res, control=ctl), wave_angle0_deg=10.0, quadrature0=0.05)
    t, first = until(rec, 3.0)
    a, q = np.asarray(rec.amplitude)[first][1:-1], np.asarray(rec.quadrature)[first][1:-1]
    rate = local_rate(t, np.asarray(rec.wave_angle)[first])
    expect = -a * q / (a**2 - q**2) * np.tan(ge) / tau
    np.testing.assert_allclose(rate, expect, rtol=3e-2)


def test_bias_and_acceleration_sensitivity_full_model():
    """§10 `bias` and `acceleration_sensitivity` on the full model: θ̇ = −k_e(Ω + b + G·f)."""
    b, gz = 2e-3, 1e-3
    gyro = hg.Gyro(resonator(tau=1e9), rate_bias=b, g_sensitivity=(0.0, 0.0, gz))
    rec = sim_closed(gyro, 1.0, wave_angle0_deg=15.0, accel_g=(0.3, 0.2, 0.5))
    t, first = until(rec, 4.0)
    expect = -0.554 * (np.deg2rad(1.0) + b + 0.5 * gz)
    assert slope(t, np.asarray(rec.wave_angle)[first]) == pytest.approx(expect, rel=1e-5)


def test_a_wave_turning_over_90_degrees_a_sample_is_not_aliased():
    """Audit: θ is read modulo π at the output times, and the full model unwrapped it along
    the turn nearest zero — at 200 °/s (−110.8 °/s electrical) and 1-s samples it read
    +69.2 °/s. It is now continued along the turn the table (−k_eΩ) and a commanded
    precession (ρ) expect: both read as the averaged model does, with or without a readout
    error, and with a precession that turns the wave the other way (ρ − k_eΩ = +189.2 °/s)."""
    gyro = hg.Gyro(resonator(tau=20.0), readout=hg.Readout(gain_mismatch=0.005))
    rate, rho = np.radians(200.0), np.radians(300.0)
    spin = hg.Profile.constant_rate(200.0, 2.0)
    both = hg.Profile(t=[0.0, 2.0], rate=[rate, rate], temperature=[20.0, 20.0],
                      accel=np.zeros((2, 3)), precession=[rho, rho])  # fmt: skip
    for prof, turn in ((spin, -0.554 * rate), (both, rho - 0.554 * rate)):
        full = sim(gyro, prof, dt_out=1.0)
        avg = hg.simulate(gyro, prof, dt_out=1.0)
        np.testing.assert_allclose(full.true_wave_angle, turn * np.asarray(full.t), rtol=1e-3)
        np.testing.assert_allclose(full.true_wave_angle, avg.true_wave_angle, atol=1e-3)
        np.testing.assert_allclose(full.wave_angle, avg.wave_angle, atol=1e-3)


def test_force_to_rebalance_reads_a_released_wave_without_aliasing():
    """The same for force-to-rebalance: held for 1 s, then released (the schedule runs
    whole-angle) at 200 °/s, read every 1 s. The angle is read next to the held angle (a
    state that follows the estimate while released): it was unwrapped along the turn nearest
    zero and read +69.2 °/s electrical."""
    gyro = hg.Gyro(resonator(tau=20.0), control=hg.Control(mode="ftr"))
    rate = np.radians(200.0)
    prof = hg.Profile(t=[0.0, 1.0, 3.0], rate=[rate] * 3, temperature=[20.0] * 3,
                      accel=np.zeros((3, 3)), rebalance=[1.0, 0.0, 0.0])  # fmt: skip
    full, avg = sim(gyro, prof, dt_out=1.0), hg.simulate(gyro, prof, dt_out=1.0)
    expect = -0.554 * rate * np.maximum(np.asarray(full.t) - 1.0, 0.0)
    for name in ("true_wave_angle", "wave_angle"):
        np.testing.assert_allclose(getattr(full, name), expect, atol=1e-4)
        np.testing.assert_allclose(getattr(full, name), getattr(avg, name), atol=1e-4)
