"""The real loops' lag (resonator/slow.py) and the grey box that models it (plant=).

Independent truth: the averaged model with the PI loops integrated as states (the simulator's
own path) — the slow manifold must reproduce its wave-angle rate, and a grey box given the
gyro's loops must return the gyro's own laws, where the ideal-loop grey box is pulled.
"""

import dataclasses
import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, batched_lapack

import hrgjax as hg
from hrgjax.calibration import (
    PhysicalCompensator,
    export_json,
    load_compensator,
    load_json,
    physical,
    run_plan,
    save_compensator,
)
from hrgjax.calibration.design import nominal_values
from hrgjax.calibration.export import checksum
from hrgjax.resonator.averaged import input_rate
from hrgjax.resonator.slow import reduced_rate

jax.config.update("jax_enable_x64", True)


@pytest.fixture(scope="module")
def gyro():
    return hg.presets.tvg3_like(noise=False)


def test_slow_manifold_holds_the_pi_loops_lag(gyro):
    """At 10 °/s, once the loops' transient has passed (t ≥ 8 s; 1/β = 0.5 s), the wave-angle
    rate of the PI loops equals θ̇ on the slow manifold to < 1 % of what the ideal loops miss
    (a 2θ ripple of ≈ 3e-5 of the rate)."""
    rate_dps, temp = 10.0, 0.0
    prof = hg.Profile.constant_rate(rate_dps, 40.0, temperature_c=temp)
    ts = jnp.linspace(0.0, 40.0, 801)
    rec = hg.simulate(gyro, prof, ts=ts, rtol=1e-11, atol=1e-13)
    theta = np.asarray(rec.true_wave_angle)
    rate = np.gradient(theta, np.asarray(ts), edge_order=2)[160:-1:20]  # t = 8 … 39 s

    @eqx.filter_jit  # one program, not one per eager operation
    def slow_and_ideal(gyro, th):
        g = gyro.at(temp)
        w = input_rate(g, prof, 0.0)
        res = g.resonator
        ideal = -res.k_e * w + 0.5 * res.delta_inv_tau * jnp.sin(2 * (th - res.theta_tau))
        return jax.vmap(lambda x: reduced_rate(g, w, x))(th), ideal

    slow, ideal = (np.asarray(x) for x in slow_and_ideal(gyro, jnp.asarray(theta[160:-1:20])))
    lag = np.max(np.abs(rate - ideal))
    assert lag > 1e-5 * abs(float(ideal[0]))  # the lag is there (a full ripple period: 32 s)
    assert np.max(np.abs(rate - slow)) < 0.01 * lag
    # batched over angles (as the grey box's scale_factor_at runs it), the manifold's Newton
    # and harmonic-balance solves run no LAPACK kernel: two at once wedged a two-thread pool
    assert not batched_lapack(slow_and_ideal, gyro, jnp.asarray(theta[160:-1:20]))


def test_grey_box_with_the_plant_returns_the_laws(gyro, tmp_path):
    """Noise-free bench data from the default gyro (PI loops, Δω, χ): the ideal-loop grey
    box takes the loops' 2θ ripple as readout gain mismatch (≈ +1.5e-5); given the plant it
    returns the gyro's own laws, and both compensate the same scale factor."""
    temps, angles = (-40.0, 20.0, 60.0), (-67.5, -22.5, 22.5, 67.5)
    static = hg.calibration.static_plan(temps, angles, duration_s=30.0, dt_out=0.5)
    rotation = hg.calibration.rotation_plan(temps, angles, duration_s=30.0, dt_out=0.5)
    d1 = run_plan(gyro, static)
    d2 = run_plan(gyro, rotation, first_run=static.size)
    data = hg.data.concat([d1, d2])
    laws = dict(zip(physical.NAMES, np.asarray(nominal_values(gyro)), strict=True))
    ideal = PhysicalCompensator().fit(data)
    plant = PhysicalCompensator(plant=gyro).fit(data)
    g_ideal = ideal.parameters()["gain_mismatch0"][0]
    assert g_ideal - laws["gain_mismatch0"] == pytest.approx(1.5e-5, rel=0.1)
    for name in ("k_e0", "gain_mismatch0", "cross_talk", "theta_tau0", "bias0"):
        scale = {"theta_tau0": 1e-6, "bias0": 1e-12}.get(name, 1e-9)
        assert plant.parameters()[name][0] == pytest.approx(laws[name], abs=scale), name
    # one scale factor, two readings: effective readout (ideal) = readout + loops' lag (plant)
    th = np.linspace(-90.0, 90.0, 7)
    sf_i, sf_p = ideal.scale_factor_at(th, 20.0), plant.scale_factor_at(th, 20.0)
    bare = PhysicalCompensator(values=plant.values, covariance=plant.covariance)  # no loops
    with CompileCounter() as c:  # another fit of the same structure: the same program
        sf_bare = bare.scale_factor_at(th, 20.0)
    assert c.compiles == 0, c.names
    ripple = np.max(np.abs(sf_i - sf_bare))
    assert ripple > 1e-5  # the loops' lag in SF: ≈ 3e-5
    assert np.max(np.abs(sf_p - sf_i)) < 0.1 * ripple  # (30-s runs: their transients ≈ 4 %)
    # the plant travels with the saved compensator; a plant fitted at another table rate
    # shares its program too
    back = load_compensator(save_compensator(plant, tmp_path / "p.eqx"))
    np.testing.assert_array_equal(back.scale_factor_at(th, 20.0), sf_p)
    # a plant fitted before the nonlinear balance (a0eb9e0: no `balance` in its header) is
    # evaluated with the new balance: it loads (same numbers), but says so
    first, payload = (tmp_path / "p.eqx").read_bytes().split(b"\n", 1)
    header = json.loads(first)
    assert header["hyper"].pop("balance") == "newton"
    header["sha256"] = checksum(header, payload)
    (tmp_path / "old.eqx").write_bytes(json.dumps(header).encode() + b"\n" + payload)
    with pytest.warns(UserWarning, match="linearised slow-manifold balance"):
        old = load_compensator(tmp_path / "old.eqx")
    np.testing.assert_array_equal(old.values, plant.values)
    d = json.loads((tmp_path / export_json(plant, tmp_path / "p.json")).read_text())
    del d["hyper"]["balance"]
    (tmp_path / "old.json").write_text(json.dumps(d))
    with pytest.warns(UserWarning, match="refit it on its data"):
        load_json(tmp_path / "old.json")
    load_json(tmp_path / "p.json")  # today's file: no warning (warnings are errors here)
    d["hyper"]["balance"] = "secant"  # a balance this hrgjax does not know: refused
    (tmp_path / "odd.json").write_text(json.dumps(d))
    with pytest.raises(ValueError, match="hyper.balance 'secant'"):
        load_json(tmp_path / "odd.json")
    with CompileCounter() as c:
        other = dataclasses.replace(plant, sf_rate=2 * plant.sf_rate)
        assert np.max(np.abs(other.scale_factor_at(th, 20.0) - sf_p)) > 0
    assert c.compiles == 0, c.names
    assert "PI loops" in back.equations()
    with pytest.raises(ValueError, match="plant=None"):
        PhysicalCompensator(plant=hg.presets.ideal(gyro.resonator))
