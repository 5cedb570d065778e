"""`hrgjax.simulate`'s inputs and failures: bad gyros, profiles and options get clear errors
naming the field; a solver that runs out of steps, a NaN in a traced profile and float32
mode raise rather than return NaN; temperature laws vmap."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import resonator

import hrgjax as hg


@pytest.mark.parametrize(
    "kw,match",
    [
        (dict(tau=-1.0), "tau"),
        (dict(tau=0.0), "tau"),
        (dict(omega=-5.0), "omega"),
        (dict(delta_inv_tau=np.nan), "delta_inv_tau"),
    ],
)
def test_bad_resonator(kw, match):
    with pytest.raises(ValueError, match=match):
        resonator(**kw)


@pytest.mark.parametrize(
    "build,match",
    [
        (lambda: hg.Profile.piecewise([0.0, 2.0, 1.0], 0.0, 20.0), "unsorted"),
        (lambda: hg.Profile.piecewise([0.0, 1.0, 1.0], 0.0, 20.0), "duplicate"),
        (lambda: hg.Profile.piecewise([0.0, 1.0], [0.0, np.nan], 20.0), "Profile.rate"),
        (lambda: hg.Profile.piecewise([0.0, 1.0], 0.0, [20.0, np.inf]), "Profile.temperature"),
        (
            lambda: hg.Profile(
                t=[0.0, 1.0], rate=[0.0, 1.0, 2.0], temperature=[20.0, 20.0], accel=np.zeros((2, 3))
            ),
            "Profile.rate",
        ),
        (
            lambda: hg.Profile(
                t=[0.0, 1.0], rate=[0.0, 1.0], temperature=[20.0, 20.0], accel=np.zeros((2, 2))
            ),
            "Profile.accel",
        ),
        (
            lambda: hg.Profile(t=[0.0], rate=[0.0], temperature=[20.0], accel=np.zeros((1, 3))),
            "N >= 2",
        ),
    ],
    ids=["unsorted", "duplicate", "nan-rate", "inf-temp", "length", "accel-shape", "one-knot"],
)
def test_bad_profile(build, match):
    with pytest.raises(ValueError, match=match):
        build()


def test_bad_simulate_arguments():
    gyro = hg.presets.ideal(resonator())
    prof = hg.Profile.static(1.0)
    with pytest.raises(ValueError, match="model"):
        hg.simulate(gyro, prof, model="fast")
    with pytest.raises(ValueError, match="dt_out"):
        hg.simulate(gyro, prof, dt_out=-0.1)
    with pytest.raises(ValueError, match="ts must be strictly increasing"):
        hg.simulate(gyro, prof, ts=jnp.array([0.0, 0.5, 0.5]))
    with pytest.raises(ValueError, match="within the profile"):
        hg.simulate(gyro, prof, ts=jnp.array([0.0, 2.0]))
    with pytest.raises(TypeError, match="Profile"):
        hg.simulate(gyro, {"t": [0, 1]})
    with pytest.raises(ValueError, match="key"):
        hg.simulate(hg.presets.tvg3_like(), prof)
    with pytest.raises(ValueError, match="drive"):
        hg.Control(drive="magic")
    with pytest.raises(ValueError, match="g_sensitivity"):
        hg.Gyro(resonator(), g_sensitivity=[1.0, 2.0])


def test_max_steps_raises_not_nan():
    gyro = hg.Gyro(resonator())
    with pytest.raises(RuntimeError, match="maximum number of solver steps") as err:
        hg.simulate(gyro, hg.Profile.static(1.0), model="full", max_steps=50)
    # one line that says where it stopped: before the end of the 1-s run
    assert "\n" not in str(err.value)
    stop = float(str(err.value).split("finite at t = ")[1].split(" s")[0])
    assert 0.0 <= stop < 1.0


def test_traced_nan_in_profile_raises():
    gyro = hg.presets.ideal(resonator())

    def run(rate):
        prof = hg.Profile.constant_rate(rate, 1.0)
        return hg.simulate(gyro, prof, dt_out=0.5).wave_angle

    with pytest.raises(Exception, match="Profile.rate must be finite"):
        jax.vmap(run)(jnp.array([jnp.nan]))


def test_float32_mode_raises():
    gyro = hg.presets.ideal(resonator())
    prof = hg.Profile.static(1.0)
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="float64"):
            hg.simulate(gyro, prof)
    finally:
        jax.config.update("jax_enable_x64", True)


def test_temperature_law_vmap():
    law = hg.TemperatureLaw(2.0, 0.1, 0.0, 0.0)
    res = resonator(tau=law)
    taus = jax.vmap(lambda T: res.at(T).tau)(jnp.array([10.0, 20.0, 30.0]))
    np.testing.assert_allclose(taus, [1.0, 2.0, 3.0])
    assert not isinstance(res.at(0.0).tau, hg.TemperatureLaw)
