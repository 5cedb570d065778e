"""The fixed-step carrier path (`simulate(model="full", fixed_step=…)`) against adaptive
stepping of the same equations: its convergence order on the free resonator, its accuracy
with the loops closed and temperature laws on, gradients (reverse = forward = finite
differences ≈ −k_e·T) and batching."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg

F0 = 5000.0
FREE = hg.Gyro(
    hg.Resonator(
        omega=2 * np.pi * F0, tau=640.0, k_e=0.554, delta_omega=2 * np.pi * 0.05,
        theta_omega=0.2, delta_inv_tau=2e-3, theta_tau=0.5, chi=2e4,
    ),
    control=hg.Control.free(),
)  # fmt: skip


def _errors(rec, ref):
    return max(
        float(np.max(np.abs(np.asarray(rec.wave_angle) - np.asarray(ref.wave_angle)))),
        float(np.max(np.abs(np.asarray(rec.amplitude) - np.asarray(ref.amplitude)))),
    )


def test_free_resonator_converges_at_eighth_order():
    prof = hg.Profile.constant_rate(100.0, 0.02, wave_angle0_deg=20.0)  # 100 carrier cycles
    ts = np.array([0.01, 0.02])
    ref = hg.simulate(FREE, prof, model="full", ts=ts, rtol=1e-13, atol=1e-15)
    # "auto" at rtol 1e-8 takes 10 steps per cycle
    auto = hg.simulate(FREE, prof, model="full", ts=ts, fixed_step="auto")
    per_cycle = np.array([7.0, 10.0, 13.0])
    err = [
        _errors(auto if n == 10 else
                hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=1 / (F0 * n)), ref)
        for n in per_cycle
    ]  # fmt: skip
    slope = -np.polyfit(np.log(per_cycle), np.log(err), 1)[0]
    assert 7.0 < slope < 10.0, (err, slope)  # Dormand–Prince's 8th-order solution
    # and is as accurate as adaptive stepping at rtol 1e-8
    adaptive = hg.simulate(FREE, prof, model="full", ts=ts)
    assert err[1] < 2.0 * max(_errors(adaptive, ref), 1e-9), (err, _errors(adaptive, ref))


@pytest.fixture(scope="module")
def ramp():
    """The default gyro (laws, closed loops) through a rate ramp and a temperature change,
    with a knot inside the run."""
    gyro = hg.presets.tvg3_like(noise=False)
    prof = hg.Profile(
        t=np.array([0.0, 0.012, 0.03]),
        rate=np.deg2rad([0.0, 40.0, 40.0]),
        temperature=np.array([20.0, 20.5, 21.0]),
        accel=np.zeros((3, 3)),
        wave_angle0=np.deg2rad(30.0),
    )
    ts = np.linspace(0.005, 0.03, 6)
    ref = hg.simulate(gyro, prof, model="full", ts=ts, rtol=1e-11, atol=1e-13)
    return gyro, prof, ts, ref


@pytest.mark.slow(
    "~40 s: an adaptive rtol-1e-11 reference of the full model with loops and laws; fast "
    "tier: the fixed step's order and its 'auto' accuracy "
    "(test_free_resonator_converges_at_eighth_order), closed loops with adaptive steps "
    "(test_resonator_full)"
)
def test_closed_loops_match_adaptive_stepping(ramp):
    """Held loops (a digital controller at 1/h) and laws interpolated over 256 steps: the
    wave angle within 1e-9 rad of the adaptive solution of the continuous equations, the
    amplitude and quadrature within 1e-5 of the set point's scale — as close as adaptive
    stepping at rtol 1e-8 gets."""
    gyro, prof, ts, ref = ramp
    fixed = hg.simulate(gyro, prof, model="full", ts=ts, fixed_step="auto")
    adaptive = hg.simulate(gyro, prof, model="full", ts=ts)
    d_theta = np.abs(np.asarray(fixed.wave_angle) - np.asarray(ref.wave_angle))
    assert d_theta.max() < 1e-9, d_theta
    for name in ("amplitude", "quadrature", "frequency"):
        d = np.abs(np.asarray(getattr(fixed, name)) - np.asarray(getattr(ref, name)))
        d_ad = np.abs(np.asarray(getattr(adaptive, name)) - np.asarray(getattr(ref, name)))
        scale = 1e-5 if name != "frequency" else 1e-3  # rad/s on 3.1e4
        assert d.max() < scale and d.max() < 10 * max(d_ad.max(), scale / 10), (name, d, d_ad)
    # the table's rate turned the pattern: the true angle moved by −k_e·(table angle)
    turn = np.asarray(fixed.true_wave_angle) - float(prof.wave_angle0)
    np.testing.assert_allclose(turn, -0.554 * np.asarray(fixed.table_angle), rtol=1e-3)


def test_gradient_reverse_equals_forward_and_finite_differences():
    def final_angle(rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 0.004, wave_angle0_deg=10.0)
        rec = hg.simulate(FREE, prof, model="full", ts=jnp.array([0.004]), fixed_step=2e-5)
        return rec.wave_angle[-1]

    rate = jnp.asarray(50.0)
    rev = jax.grad(final_angle)(rate)
    fwd = jax.jvp(final_angle, (rate,), (jnp.ones(()),))[1]
    fd = (final_angle(rate + 1e-3) - final_angle(rate - 1e-3)) / 2e-3
    np.testing.assert_allclose(rev, fwd, rtol=1e-10)
    np.testing.assert_allclose(rev, fd, rtol=1e-6)
    # dθ/dΩ = −k_e·T (rate in °/s, θ in rad)
    np.testing.assert_allclose(rev, -0.554 * 0.004 * np.pi / 180, rtol=2e-3)


def test_vmap_over_rates_equals_single_runs():
    ts = jnp.array([0.002, 0.004])

    def run(rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 0.004, wave_angle0_deg=10.0)
        return hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=2e-5).wave_angle

    rates = jnp.array([-30.0, 5.0, 80.0])
    batch = jax.vmap(run)(rates)
    for k, r in enumerate(rates):
        np.testing.assert_allclose(batch[k], run(r), rtol=0, atol=1e-13)


def test_fixed_step_options_are_checked():
    prof = hg.Profile.constant_rate(10.0, 0.002)
    with pytest.raises(ValueError, match='fixed_step must be .*"auto"'):
        hg.simulate(FREE, prof, model="full", dt_out=0.001, fixed_step="fast")
    with pytest.raises(ValueError, match='fixed_step="auto" is for model="full"'):
        hg.simulate(FREE, prof, model="averaged", dt_out=0.001, fixed_step="auto")


def test_profile_kinematics_equal_the_separate_lookups():
    """`Profile.kinematics_at` (one segment look-up per fixed step) equals `table_angle_at`,
    `rate_at` and `accel_at`, at knots and between them; the table angle is ∫rate dt."""
    prof = hg.Profile.piecewise(
        [0.0, 1.0, 2.5, 4.0], [0.0, 10.0, -5.0, -5.0], [20.0, 20.0, 21.0, 22.0],
        accel_g=[[0, 0, 1.0], [0.1, 0, 1.0], [0, 0.2, 0.9], [0, 0, 1.0]],
    )  # fmt: skip
    for t in (0.0, 0.3, 1.0, 1.7, 2.5, 3.99, 4.0):
        angle, rate, accel = prof.kinematics_at(t)
        np.testing.assert_allclose(angle, prof.table_angle_at(t), rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(rate, prof.rate_at(t), rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(accel, prof.accel_at(t), rtol=1e-14, atol=1e-15)
    # the table angle at the end, the trapezoids of the rate: 5 + 3.75 − 7.5 = 1.25°
    np.testing.assert_allclose(prof.kinematics_at(4.0)[0], np.deg2rad(5.0 + 3.75 - 7.5), rtol=1e-12)
