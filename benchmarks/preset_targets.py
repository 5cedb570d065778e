"""The default gyro's bench figures, measured from simulated bench data and printed next to
the targets of PHYSICS.md §11 (the same measurements tests/test_presets.py asserts)."""

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, report

import hrgjax as hg
from hrgjax.units import DEG_PER_H

K_E = 0.554


def harmonic(theta, values):
    m = np.stack([np.ones_like(theta), np.cos(2 * theta), np.sin(2 * theta)], 1)
    _, c, s = np.linalg.lstsq(m, values, rcond=None)[0]
    return 2 * np.hypot(c, s), np.rad2deg(0.5 * np.arctan2(s, c))


def main():
    gyro = hg.presets.tvg3_like()
    data = hg.calibration.run_plan(
        gyro,
        hg.calibration.static_plan((-40.0, 60.0)),
        key=jax.random.key(0),
    )
    drift = hg.calibration.static_drift(data, K_E)
    pp, ph = {}, {}
    for T in (-40.0, 60.0):
        m = drift["temperature_c"] == T
        pp[T], ph[T] = harmonic(np.deg2rad(drift["wave_angle_deg"][m]), drift["drift_dph"][m])

    def ripple(T):
        duration = 200.0 / (K_E * 5.0)
        rec = hg.simulate(
            gyro,
            hg.Profile.constant_rate(5.0, duration, T),
            key=jax.random.key(1),
            dt_out=duration / 400,
        )
        th, t = np.asarray(rec.wave_angle), np.asarray(rec.t)
        lin = np.polyval(np.polyfit(t, th, 1), t)
        m = np.stack([np.ones_like(t), t, np.sin(2 * lin), np.cos(2 * lin)], 1)
        _, _, a1, b1 = np.linalg.lstsq(m, th, rcond=None)[0]
        return 2 * np.hypot(a1, b1) * 100

    quiet = gyro.without_noise()

    def mean_sf(rate):
        out = []
        for sign in (1.0, -1.0):
            d = 180.0 / (K_E * rate)
            rec = hg.simulate(quiet, hg.Profile.constant_rate(sign * rate, d), dt_out=d / 4)
            out.append((rec.wave_angle[-1] - rec.wave_angle[0]) / (-K_E * rec.table_angle[-1]))
        return 0.5 * (out[0] + out[1])

    def drift_at(az):
        rec = hg.simulate(quiet, hg.Profile.static(180.0, 20.0, 30.0, (0.0, 0.0, az)), dt_out=10.0)
        return -np.polyfit(rec.t, rec.wave_angle, 1)[0] / K_E / DEG_PER_H

    prof = hg.Profile.static(180.0, 20.0, 30.0)

    def one(key):
        rec = hg.simulate(gyro, prof, key=key, dt_out=2.0)
        t = rec.t - rec.t.mean()
        return -jnp.sum(t * rec.wave_angle) / jnp.sum(t**2) / K_E / DEG_PER_H

    spread = float(jnp.std(jax.vmap(one)(jax.random.split(jax.random.key(7), 200))))
    rate_dep = abs(float(mean_sf(400.0) - mean_sf(0.1))) * 100
    shift = (ph[60.0] - ph[-40.0] + 90) % 180 - 90
    print(f"machine: {machine()}")
    print("tvg3_like(): figures measured from simulated bench data (targets: PHYSICS.md §11)")
    rows = [
        ("drift p-p at −40 °C [°/h]", f"{pp[-40.0]:.3f}", "3.5"),
        ("drift p-p at +60 °C [°/h]", f"{pp[60.0]:.3f}", "0.7"),
        ("drift axis shift −40→+60 °C [°]", f"{abs(shift):.2f}", "16"),
        ("SF ripple at 0 °C [%]", f"{ripple(0.0):.3f}", "1.3"),
        ("SF ripple at +60 °C [%]", f"{ripple(60.0):.3f}", "0.15"),
        ("SF change 0.1 → 400 °/s [%]", f"{rate_dep:.5f}", "≤ 0.02"),
        ("drift change −g → +g [°/h]", f"{abs(drift_at(1.0) - drift_at(-1.0)):.4f}", "< 0.03"),
        ("switch-on bias spread, 200 runs [°/h]", f"{spread:.3f}", "0.1–0.3"),
    ]
    for name, value, target in rows:
        print(f"  {name:40s} {value:>10s}   target {target}")
        label, unit = name.rsplit(" [", 1)
        report(f"tvg3_like {label}", float(value), unit.rstrip("]"), target=target)


if __name__ == "__main__":
    main()
