"""The default gyro shows the bench figures of MISSION.md §1 / PHYSICS.md §11, *measured*
from simulated bench data (static dwell plan, rotation runs), not read from parameters."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
from hrgjax.units import DEG, DEG_PER_H

ANGLES = jnp.deg2rad(jnp.arange(-90.0, 91.0, 10.0))
K_E = 0.554


@pytest.fixture(scope="module")
def gyro():
    return hg.presets.tvg3_like()


@pytest.fixture(scope="module")
def static_drift(gyro):
    """Static dwell: 180 s per wave angle, one switch-on; drift = −(θ slope)/k_e [°/h]."""

    def point(temperature, theta0, key):
        prof = hg.Profile.static(180.0, temperature)
        prof = eqx.tree_at(lambda p: p.wave_angle0, prof, theta0)
        rec = hg.simulate(gyro, prof, key=key, bias_key=jax.random.key(99), dt_out=1.0)
        t = rec.t - rec.t.mean()
        slope = jnp.sum(t * (rec.wave_angle - rec.wave_angle.mean())) / jnp.sum(t**2)
        return -slope / K_E / DEG_PER_H, rec.wave_angle.mean()

    def curve(temperature):
        keys = jax.random.split(jax.random.key(int(temperature) + 100), ANGLES.shape[0])
        return jax.vmap(point, in_axes=(None, 0, 0))(temperature, ANGLES, keys)

    return {T: curve(T) for T in (-40.0, 60.0)}


def harmonic(theta, values):
    """Least-squares c0 + c cos2θ + s sin2θ → (peak-to-peak, phase of the maximum [°])."""
    theta = np.asarray(theta)
    m = np.stack([np.ones_like(theta), np.cos(2 * theta), np.sin(2 * theta)], 1)
    c0, c, s = np.linalg.lstsq(m, np.asarray(values), rcond=None)[0]
    return 2 * np.hypot(c, s), np.rad2deg(0.5 * np.arctan2(s, c))


def test_drift_peak_to_peak_and_axis_shift(static_drift):
    pp_cold, ph_cold = harmonic(static_drift[-40.0][1], static_drift[-40.0][0])
    pp_hot, ph_hot = harmonic(static_drift[60.0][1], static_drift[60.0][0])
    assert pp_cold == pytest.approx(3.5, rel=0.05)
    assert pp_hot == pytest.approx(0.7, rel=0.05)
    shift = (ph_hot - ph_cold + 90) % 180 - 90
    assert abs(shift) == pytest.approx(16.0, abs=1.0)


def sf_ripple(gyro, temperature, rate_dps, key):
    """Rotation run over > 180° of wave angle: θ_meas = θ + ½ε₁sin2θ + ½ε₂cos2θ; the
    scale-factor ripple amplitude is √(ε₁² + ε₂²)."""
    duration = 200.0 / (K_E * abs(rate_dps))
    prof = hg.Profile.constant_rate(rate_dps, duration, temperature, 0.0)
    rec = hg.simulate(gyro, prof, key=key, dt_out=duration / 400)
    th, t = np.asarray(rec.wave_angle), np.asarray(rec.t)
    lin = np.polyval(np.polyfit(t, th, 1), t)
    m = np.stack([np.ones_like(t), t, np.sin(2 * lin), np.cos(2 * lin)], 1)
    _, _, a1, b1 = np.linalg.lstsq(m, th, rcond=None)[0]
    return 2 * np.hypot(a1, b1)


@pytest.mark.parametrize("temperature,target", [(0.0, 1.3e-2), (60.0, 0.15e-2)])
def test_scale_factor_ripple(gyro, temperature, target):
    assert sf_ripple(gyro, temperature, 5.0, jax.random.key(1)) == pytest.approx(target, rel=0.05)


def test_scale_factor_rate_dependence(gyro):
    """Mean scale factor over whole wave periods at 0.1 and 400 °/s (CW and CCW, so the
    bias cancels), noise off: change ≤ 0.02 %."""
    quiet = gyro.without_noise()

    def mean_sf(rate_dps):
        out = []
        for sign in (1.0, -1.0):
            duration = 180.0 / (K_E * rate_dps)
            prof = hg.Profile.constant_rate(sign * rate_dps, duration, 20.0, 0.0)
            rec = hg.simulate(quiet, prof, dt_out=duration / 4)
            out.append((rec.wave_angle[-1] - rec.wave_angle[0]) / (-K_E * rec.table_angle[-1]))
        return 0.5 * (out[0] + out[1])

    change = abs(mean_sf(400.0) - mean_sf(0.1)) / mean_sf(5.0)
    assert change <= 2e-4


def test_acceleration_sensitivity(gyro):
    quiet = gyro.without_noise()

    def drift(az):
        prof = hg.Profile.static(180.0, 20.0, 30.0, accel_g=(0.0, 0.0, az))
        # 5 samples: test_scale_factor_rate_dependence's program (its runs have 5 too); the
        # change between ±1 g is that of 19 samples (dt_out 10 s) to 1e-7 relative
        rec = hg.simulate(quiet, prof, dt_out=45.0)
        return -np.polyfit(rec.t, rec.wave_angle, 1)[0] / K_E / DEG_PER_H

    change = abs(drift(1.0) - drift(-1.0))
    assert 0.0 < change < 0.03


def test_run_to_run_bias(gyro):
    """Switch-on bias: the spread of 40 switch-ons' mean drift is 0.1–0.3 °/h."""
    prof = hg.Profile.static(180.0, 20.0, 30.0)

    def one(key):
        rec = hg.simulate(gyro, prof, key=key, dt_out=2.0)
        t = rec.t - rec.t.mean()
        return -jnp.sum(t * rec.wave_angle) / jnp.sum(t**2) / K_E / DEG_PER_H

    drifts = jax.vmap(one)(jax.random.split(jax.random.key(7), 40))
    assert 0.1 <= float(jnp.std(drifts)) <= 0.3


def test_temperature_laws_frozen():
    g = hg.presets.tvg3_like(temperature_laws=False, noise=False)
    assert g.noise is None
    a, b = g.at(-40.0), g.at(60.0)
    assert float(a.resonator.delta_inv_tau) == float(b.resonator.delta_inv_tau)
    assert float(hg.presets.tvg3_like().resonator.at(20.0).omega) == pytest.approx(2 * np.pi * 5e3)
    assert DEG > 0
