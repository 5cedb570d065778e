"""Values of the wrong type in the gyro's modules, the profile builders and the feature flags
are refused in one line naming the field (not taken as a number, a truthy flag or a
sub-module), while traced values, tree operations and serialisation keep working."""

import io

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import resonator

import hrgjax as hg

P = hg.Profile
RES = resonator()


@pytest.mark.parametrize(
    "kw,match",
    [
        (dict(noise=False), r"^Gyro\.noise must be a hrgjax\.Noise or None; got bool False "
                            r"\(for a noise-free gyro use gyro\.without_noise\(\) or noise=None\)$"),
        (dict(noise=0.0), r"^Gyro\.noise must be .*; got float 0\.0 \(for a noise-free"),
        (dict(noise=hg.Noise), r"^Gyro\.noise must be .*; got the class itself"),
        (dict(drift_terms=0.0), r"^Gyro\.drift_terms must be a hrgjax\.DriftTerms or None; got float"),
        (dict(control=None), r"^Gyro\.control must be a hrgjax\.Control; got None"),
        (dict(control="ftr"), r"^Gyro\.control must be a hrgjax\.Control; got str 'ftr'$"),
        (dict(readout=None), r"^Gyro\.readout must be a hrgjax\.Readout; got None"),
        (dict(noise=np.ones(3)), r"^Gyro\.noise must be .*; got ndarray \(dtype float64, shape \(3,\)\)$"),
        (dict(rate_bias="1e-5"), r"^Gyro\.rate_bias must be a real number, .*; got str '1e-5'$"),
        (dict(g_sensitivity=None), r"^Gyro\.g_sensitivity must be 3 real numbers .*; got None$"),
    ],
)  # fmt: skip
def test_gyro_parts_typed(kw, match):
    with pytest.raises(TypeError, match=match):
        hg.Gyro(resonator=RES, **kw)


@pytest.mark.parametrize("res", [None, "x", 1.0])
def test_gyro_needs_a_resonator(res):
    with pytest.raises(TypeError, match=r"^Gyro\.resonator must be a hrgjax\.Resonator; got"):
        hg.Gyro(resonator=res)
    with pytest.raises(TypeError, match=r"^Gyro\.resonator must be"):
        hg.presets.ideal(res)


BAD = {
    "ragged": ([[1.0, 2.0], [3.0]], "ragged list"),
    "dict": ({"a": 1}, "dict"),
    "complex": (1 + 2j, "complex"),
    "None": (None, "None"),
    "str": ("5", "str '5'"),
    "bool": (True, "bool True"),
    "key": (jax.random.key(0), "JAX PRNG key"),
    "complex array": (np.array([1 + 2j]), r"ndarray \(dtype complex128"),
}


@pytest.mark.parametrize("bad", BAD, ids=list(BAD))
@pytest.mark.parametrize(
    "build,field",
    [
        (lambda v: hg.Resonator(omega=v, tau=640.0), "Resonator.omega"),
        (lambda v: hg.Resonator(omega=3e4, tau=640.0, chi=v), "Resonator.chi"),
        (lambda v: hg.Noise(angle_white=v), "Noise.angle_white"),
        (lambda v: hg.Control(amplitude=v), "Control.amplitude"),
        (lambda v: hg.Readout(gain_mismatch=v), "Readout.gain_mismatch"),
        (lambda v: hg.DriftTerms(lag=v), "DriftTerms.lag"),
        (lambda v: hg.TemperatureLaw(v), "TemperatureLaw.p0"),
    ],
)
def test_parameter_fields_named(build, field, bad):
    value, found = BAD[bad]
    with pytest.raises(TypeError, match=rf"^{field} must be a real number.*; got .*{found}"):
        build(value)


def test_rebalance_limit_none_still_means_none():
    assert hg.Control(rebalance_limit=None).rebalance_limit is None
    with pytest.raises(TypeError, match=r"^Control\.rebalance_limit must be .*; got str"):
        hg.Control(rebalance_limit="5")


@pytest.mark.parametrize(
    "kw,match",
    [
        (dict(ideal="False"), r"^Control\.ideal must be True or False; got str 'False'$"),
        (dict(ideal=0.0), r"^Control\.ideal must be True or False; got float 0\.0$"),
        (dict(enabled="no"), r"^Control\.enabled must be True or False; got str 'no'$"),
        (dict(enabled=None), r"^Control\.enabled must be True or False; got None$"),
        (dict(k_e_nominal="0.5"), r"^Control\.k_e_nominal must be a single real number; got str"),
    ],
)
def test_control_flags_are_bools(kw, match):
    with pytest.raises(TypeError, match=match):
        hg.Control(**kw)


def test_a_traced_nominal_gain_is_refused_not_differentiated_as_zero():
    """`Control.k_e_nominal` is static: traced (grad, vmap) it compiled a program holding the
    tracer, and its derivative read 0 after an eager call; now one line says what to do."""
    for transform in (jax.grad, jax.vmap):
        with pytest.raises(TypeError, match=r"^Control.k_e_nominal is a setting of the elec"):
            transform(lambda k: hg.Control(mode="ftr", k_e_nominal=k).amplitude)(
                jnp.asarray(0.554) if transform is jax.grad else jnp.array([0.5, 0.6])
            )


def test_control_mode_array_one_line():
    with pytest.warns(UserWarning, match="static"):  # equinox's own, before the check
        with pytest.raises(ValueError, match=r"^Control\.mode must be one of .*; got ndarray of"):
            hg.Control(mode=np.array([1, 2]))


def test_numpy_bools_are_flags():
    assert hg.Control(ideal=np.True_).ideal
    assert hg.presets.tvg3_like(noise=np.False_, temperature_laws=np.True_).noise is None


@pytest.mark.parametrize("flag", ["noise", "temperature_laws"])
def test_preset_flags_are_bools(flag):
    with pytest.raises(TypeError, match=rf"^presets\.tvg3_like: {flag} must be True or False; "
                                        r"got str 'no'$"):  # fmt: skip
        hg.presets.tvg3_like(**{flag: "no"})


def test_measured_data_allow_extra_is_a_bool():
    t = np.arange(5.0)
    cols = dict(time_s=t, temperature_c=np.full(5, 20.0), table_rate_dps=np.zeros(5),
                wave_angle_deg=0.001 * t, foo=t)  # fmt: skip
    with pytest.raises(TypeError, match=r"^MeasuredData: allow_extra must be True or False; "
                                        r"got str 'no'$"):  # fmt: skip
        hg.MeasuredData(cols, allow_extra="no")
    assert "foo" in hg.MeasuredData(cols, allow_extra=np.True_).columns


@pytest.mark.parametrize(
    "build,exc,match",
    [
        (lambda: P.constant_rate(np.array([1, 2]), 10.0), ValueError,
         r"^Profile\.constant_rate: rate_dps must be a single real number \[°/s\]; "
         r"got ndarray of shape \(2,\)$"),
        (lambda: P.constant_rate(1.0, np.array([1, 2])), ValueError,
         r"^Profile\.constant_rate: duration_s must be a single real number \[s\]"),
        (lambda: P.static(10.0, np.array([1, 2])), ValueError,
         r"^Profile\.static: temperature_c must be a single real number \[°C\]"),
        (lambda: P.constant_rate(True, 10), TypeError,
         r"^Profile\.constant_rate: rate_dps must be .*; got bool True$"),
        (lambda: P.constant_rate(None, 10), TypeError,
         r"^Profile\.constant_rate: rate_dps must be .*; got None$"),
        (lambda: P.constant_rate("5", 10), TypeError,
         r"^Profile\.constant_rate: rate_dps must be .*; got str '5'$"),
        (lambda: P.constant_rate(jax.random.PRNGKey(0), 10), ValueError,
         r"^Profile\.constant_rate: rate_dps must be .*; got jax\.Array of shape \(2,\)$"),
        (lambda: P.constant_rate(jax.random.key(0), 10), TypeError,
         r"^Profile\.constant_rate: rate_dps must be .*; got a JAX PRNG key"),
        (lambda: P.static(10, 20, 0, accel_g=0.0), ValueError,
         r"^Profile\.static: accel_g must be 3 values .*shape \(3,\); got float of shape \(\)$"),
        (lambda: P.static(10, 20, np.ones(2)), ValueError,
         r"^Profile\.static: wave_angle0_deg must be a single real number"),
        (lambda: P.virtual_precession(np.array([1, 2]), 10), ValueError,
         r"^Profile\.virtual_precession: precession_dps must be a single real number"),
        (lambda: P.virtual_precession(1.0, 10, rate_dps=True), TypeError,
         r"^Profile\.virtual_precession: rate_dps must be .*; got bool True$"),
        (lambda: P.held_angles([0, 90], "5"), TypeError,
         r"^Profile\.held_angles: dwell_s must be a single real number \[s\]; got str '5'$"),
        (lambda: P.held_angles([0, 90], 5.0, slew_s=np.ones(2)), ValueError,
         r"^Profile\.held_angles: slew_s must be a single real number"),
        (lambda: P.held_angles(np.ones((2, 2)), 5.0), ValueError,
         r"^Profile\.held_angles: angles_deg must be .*; got shape \(2, 2\)$"),
        (lambda: P.held_angles(None, 5.0), TypeError,
         r"^Profile\.held_angles: angles_deg must be .*; got None$"),
        (lambda: P.piecewise([0.0, 1.0], "5", 20.0), TypeError,
         r"^Profile\.piecewise: rate_dps must be real numbers; got str '5'$"),
        (lambda: P.piecewise([0.0, 1.0], 1.0, 20.0, wave_angle0_deg=[1, 2]), ValueError,
         r"^Profile\.piecewise: wave_angle0_deg must be a single real number"),
        (lambda: P(t=None, rate=[0, 0], temperature=[20, 20], accel=np.zeros((2, 3))), TypeError,
         r"^Profile\.t must be real numbers .*; got None$"),
    ],
)  # fmt: skip
def test_profile_builders_refuse_non_scalars(build, exc, match):
    with pytest.raises(exc, match=match):
        build()


def test_profile_builders_still_take_numbers_and_traced_scalars():
    p = P.constant_rate(np.array(5.0), np.float32(10.0), 20, np.int64(0), [0, 0, 1])
    np.testing.assert_allclose(np.asarray(p.t), [0.0, 10.0])
    assert P.piecewise([0.0, 1.0], 1.0, 20.0, rebalance=[True, False]).rebalance is not None
    t = jax.jit(lambda r, d: P.constant_rate(r, d).t)(1.0, 10.0)
    np.testing.assert_allclose(np.asarray(t), [0.0, 10.0])
    rho = jax.vmap(lambda r: P.virtual_precession(r, 10.0).precession)(jnp.array([1.0, 2.0]))
    assert rho.shape == (2, 2)
    g = jax.grad(lambda temp: P.static(10.0, temp).temperature.sum())(20.0)
    assert float(g) == 2.0


def test_checks_survive_tree_operations():
    gyro = hg.presets.tvg3_like()
    # rebuilt with non-module leaves: no __init__, no check
    sentinels = jax.tree_util.tree_map(lambda _: object(), gyro)
    assert isinstance(sentinels.resonator, hg.Resonator)
    nones = jax.tree_util.tree_map(lambda _: None, gyro)
    assert isinstance(nones, hg.Gyro)
    assert gyro.without_noise().noise is None
    swapped = eqx.tree_at(lambda g: g.noise, gyro, None, is_leaf=lambda x: x is None)
    assert swapped.noise is None
    taus = jnp.array([500.0, 600.0])
    batch = jax.vmap(lambda tau: hg.Gyro(resonator=hg.Resonator(omega=3e4, tau=tau)))(taus)
    assert batch.resonator.tau.shape == (2,)
    out = eqx.filter_vmap(lambda g: g.resonator.tau * 2.0)(batch)
    assert out.shape == (2,)
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, gyro)
    buf.seek(0)
    template = eqx.tree_at(lambda g: g.resonator.tau.p0, gyro, 2.0 * gyro.resonator.tau.p0)
    back = eqx.tree_deserialise_leaves(buf, template)  # into a gyro with other values
    assert float(back.resonator.tau.p0) == float(gyro.resonator.tau.p0)
    sweep = hg.sweep(lambda r: P.constant_rate(r, 10.0).rate[0], r=jnp.array([1.0, 2.0]))
    np.testing.assert_allclose(sweep, np.deg2rad([1.0, 2.0]), rtol=1e-15)
    # a traced number inside a list (an acceleration, a g-sensitivity) is stacked, not refused
    accel = jax.vmap(lambda x: P.static(10.0, 20.0, accel_g=[0.0, 0.0, x]).accel)(jnp.ones(2))
    assert accel.shape[0] == 2 and np.all(np.asarray(accel)[..., 2] == 1.0)
    g_s = jax.vmap(lambda x: hg.Gyro(hg.Resonator(omega=3e4, tau=500.0), g_sensitivity=[x, x, x]))
    assert g_s(jnp.ones(2)).g_sensitivity.shape == (2, 3)


def test_profile_nan_index_is_a_plain_int():
    with pytest.raises(
        ValueError, match=r"^Profile\.rate must be finite; it has nan at index \(1,\)$"
    ):
        P.piecewise([0.0, 1.0, 2.0], [0.0, np.nan, 1.0], 20.0)
    # and in the parameters' own check (it printed np.int64(0))
    with pytest.raises(ValueError, match=r"found nan at index \(1,\)$"):
        hg.Resonator(omega=[1.0, np.nan], tau=500.0)


def test_simulate_refuses_a_key_given_as_the_run_id():
    """`run=jax.random.key(0)` (a key where the integer run id goes) made `record.run` a
    key array; it is refused naming `run`."""
    with pytest.raises(ValueError, match=r"^run must be an integer run id .*PRNG key"):
        hg.simulate(hg.presets.ideal(RES), P.static(1.0), run=jax.random.key(0))


GYRO_AT = hg.Gyro(resonator=resonator(tau=hg.TemperatureLaw(600.0, p1=-1.0)))


@pytest.mark.parametrize(
    "value,exc,match",
    [
        ("20", TypeError, r"^temperature_c must be a temperature \[°C\]: .*; got str '20'$"),
        (True, TypeError, r"^temperature_c must be .*; got bool True$"),
        (None, TypeError, r"^temperature_c must be .*; got None$"),
        (float("nan"), ValueError, r"^temperature_c must be finite; found nan$"),
        (293.15, ValueError, r"^temperature_c = 293\.15 is outside .* look like kelvin"),
        ([20.0, 1e6], ValueError, r"^temperature_c = 1e\+06 at index 1 is outside"),
    ],
)  # fmt: skip
@pytest.mark.parametrize("owner", ["gyro", "resonator"])
def test_at_refuses_what_is_not_a_temperature(owner, value, exc, match):
    """`Gyro.at` / `Resonator.at` evaluate temperature laws: a string, a flag, NaN or kelvin
    was evaluated as a number (`at(1e6)` gave τ = −959 341 s)."""
    target = GYRO_AT if owner == "gyro" else GYRO_AT.resonator
    with pytest.raises(exc, match=match):
        target.at(value)


def test_at_still_evaluates_numbers_and_traced_temperatures():
    law = lambda t: 600.0 - (t - hg.units.T_REF_C)  # noqa: E731 — the law above, by hand
    assert float(GYRO_AT.at(30).resonator.tau) == pytest.approx(law(30.0))
    temps = jnp.array([-20.0, 30.0])
    np.testing.assert_allclose(jax.vmap(GYRO_AT.resonator.at)(temps).tau, law(temps))
    assert float(jax.jit(lambda t: GYRO_AT.at(t).resonator.tau)(40.0)) == pytest.approx(law(40.0))
    with hg.plausible.relaxed(temperature_c=(-300.0, 400.0)):
        assert float(GYRO_AT.at(300.0).resonator.tau) == pytest.approx(law(300.0))


def test_the_carrier_steps_temperature_span_is_not_the_users_temperature():
    """A traced temperature inside a narrowed `plausible.relaxed` range: the carrier step
    rule reads the resonator's frequency over its own span (−60 … 100 °C), which `at`'s
    check refused as if the user had passed −60 °C (a reviewer's finding)."""
    from hrgjax.resonator.carrier import steps_per_interval

    gyro, ts = hg.presets.tvg3_like(), np.linspace(0.0, 0.01, 3)
    steps = lambda t: steps_per_interval(gyro, P.constant_rate(1.0, 0.01, t), ts, "auto", 1e-8)  # noqa: E731
    with hg.plausible.relaxed(temperature_c=(0.0, 50.0)):
        jax.eval_shape(steps, 20.0)  # traced: the step count from the span, no error
        with pytest.raises(ValueError, match="^temperature_c = -60 is outside"):
            gyro.at(-60.0)  # the user's own value is still checked
