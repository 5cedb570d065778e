"""The MLP's readout temperature-sensitivity network (`MLPCompensator(st_width > 0)`), against
a synthetic gyro whose drift D(θ, T), scale factor and readout sensitivity s_T(θ, T) are known
in closed form: static points, rotations and temperature ramps at rest are written sample by
sample from the compensator model's own equation, θ̇ = −k_e(SF·Ω + D) + s_T·Ṫ."""

import jax
import numpy as np
import pytest

from hrgjax.calibration import MLPCompensator, reduce
from hrgjax.calibration.export import export_json, load_compensator, load_json, save_compensator
from hrgjax.cli import main
from hrgjax.data import MeasuredData, concat
from hrgjax.units import DEG, DEG_PER_H, K_E_NOMINAL

K_E = K_E_NOMINAL


def drift(theta, temp):  # [rad/s]: ~0.05 °/h, with angle and temperature structure
    return (0.03 + 0.02 * np.cos(2 * theta) + 0.01 * temp / 50.0) * DEG_PER_H


def s_t(theta, temp):  # [rad/°C]: the default gyro's size (8e-5) and angle pattern
    return 8e-5 * np.sin(4 * theta) * (1.0 + 0.2 * temp / 50.0)


def record(run, theta0_deg, temp0, temp_rate=0.0, table_rate_dps=0.0, n=180, dt=1.0):
    """One run integrated sample by sample (Euler at 1 s on a motion of < 1e-2 rad: exact to
    far below what the fit resolves)."""
    t = np.arange(n) * dt
    temp = temp0 + temp_rate * t
    theta = np.empty(n)
    theta[0] = theta0_deg * DEG
    omega = table_rate_dps * DEG
    for i in range(n - 1):
        rate = -K_E * (omega + drift(theta[i], temp[i])) + s_t(theta[i], temp[i]) * temp_rate
        theta[i + 1] = theta[i] + dt * rate
    return MeasuredData({"time_s": t, "run": np.full(n, run), "temperature_c": temp,
                         "table_rate_dps": np.full(n, table_rate_dps),
                         "wave_angle_deg": theta / DEG})  # fmt: skip


@pytest.fixture(scope="module")
def bench():
    parts, run = [], 0
    for temp in (-40.0, 10.0, 60.0):
        for angle in range(0, 180, 20):
            parts.append(record(run, angle, temp))
            run += 1
        for angle, rate in ((0.0, 5.0), (90.0, -5.0)):
            parts.append(record(run, angle, temp, table_rate_dps=rate, n=144, dt=0.5))
            run += 1
    static_and_rotation = concat(parts)
    for i, angle in enumerate(np.arange(0.0, 180.0, 22.5)):  # ramps at rest, ±2 °C/min
        up = i % 2 == 0
        parts.append(record(run, angle, -40.0 if up else 60.0, (1 if up else -1) / 30.0, n=3000))
        run += 1
    return static_and_rotation, concat(parts)


@pytest.fixture(scope="module")
def fitted(bench):
    static_and_rotation, with_ramps = bench
    plain = MLPCompensator(steps=1500).fit(static_and_rotation, key=jax.random.key(0))
    aware = MLPCompensator(steps=1500, st_width=10).fit(with_ramps, key=jax.random.key(0))
    return plain, aware


def test_st_network_learns_the_readout_sensitivity_from_ramps(fitted):
    """s_T from ramps at eight angles matches the closed form on a grid of angles and
    temperatures inside the ramps' range (RMS error < 15 % of the truth's RMS); the plain
    MLP has none (s_T = 0), and the reduction cut each ramp into 300-s windows carrying Ṫ."""
    plain, aware = fitted
    th, tc = np.meshgrid(np.arange(-90.0, 90.0, 7.5) * DEG, np.arange(-30.0, 51.0, 20.0))
    th, tc = th.ravel(), tc.ravel()
    truth = s_t(th, tc)
    got = np.asarray(jax.vmap(aware.readout_temperature_sensitivity)(th, tc))
    assert np.sqrt(np.mean((got - truth) ** 2)) < 0.15 * np.sqrt(np.mean(truth**2))
    assert np.all(np.asarray(jax.vmap(plain.readout_temperature_sensitivity)(th, tc)) == 0.0)
    assert aware.name == "MLP+Ṫ" and plain.name == "MLP"


def test_ramp_windows_carry_their_temperature_rate(bench):
    _, with_ramps = bench
    w = reduce(with_ramps, ramp_window_s=300.0)
    ramp = np.abs(w.temperature_rate_cps) > 0
    assert ramp.sum() == 8 * 10  # 3000 s ramps in 300-s windows
    np.testing.assert_allclose(np.abs(w.temperature_rate_cps[ramp]), 1 / 30.0, rtol=1e-12)
    whole = reduce(with_ramps)  # default: a ramp is one window, as every static run
    assert np.sum(np.abs(whole.temperature_rate_cps) > 0) == 8


def test_compensated_ramp_is_flat_only_with_the_st_network(fitted, tmp_path):
    """On a ramp at an angle and rate no training run had, `correct` leaves a rate error of
    the size of the drift model's with s_T, and the s_T·Ṫ/k_e term without: the plain MLP's
    error is ≥ 5× larger. A saved and loaded compensator corrects identically."""
    plain, aware = fitted
    held_out = record(0, 10.0, -30.0, 1.5 / 60.0, n=3000)
    errs = {}
    for comp in (plain, aware):
        out = comp.correct(held_out)["rate_corrected_dps"] * 3600.0  # true rate 0 [°/h]
        errs[comp.name] = np.sqrt(np.mean(out**2))
    assert errs["MLP"] > 5 * errs["MLP+Ṫ"]
    expected = aware.correct(held_out)["rate_corrected_dps"]
    again = load_compensator(save_compensator(aware, tmp_path / "aware.eqx"))
    np.testing.assert_array_equal(again.correct(held_out)["rate_corrected_dps"], expected)
    from_json = load_json(export_json(aware, tmp_path / "aware.json"))
    np.testing.assert_allclose(from_json.correct(held_out)["rate_corrected_dps"], expected,
                               rtol=0, atol=1e-15)  # fmt: skip


def test_cli_calibrate_with_the_st_network(bench, tmp_path, capsys):
    """`hrgjax calibrate --method mlp --st-width 10` trains it from a data file's ramps."""
    _, with_ramps = bench
    data = with_ramps.save(tmp_path / "bench.csv")
    model = tmp_path / "aware.eqx"
    argv = ["calibrate", data, "--method", "mlp", "--st-width", "10", "--out", str(model)]
    assert main(argv) == 0
    comp = load_compensator(model)
    assert comp.st_width == 10 and comp.st_net is not None
    assert "with s_T" in capsys.readouterr().out
    th = np.arange(-80.0, 90.0, 20.0) * DEG
    got = np.asarray(jax.vmap(comp.readout_temperature_sensitivity)(th, np.zeros_like(th)))
    truth = s_t(th, 0.0)
    assert np.sqrt(np.mean((got - truth) ** 2)) < 0.3 * np.sqrt(np.mean(truth**2))


def test_st_network_without_ramps_is_a_clear_error(bench):
    static_and_rotation, _ = bench
    with pytest.raises(ValueError, match="st_width > 0 learns s_T from ramps"):
        MLPCompensator(steps=2, st_width=4).fit(static_and_rotation, key=jax.random.key(0))
    with pytest.raises(ValueError, match="st_width must be a whole number ≥ 0"):
        MLPCompensator(st_width=-1)
