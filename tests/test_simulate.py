"""`hrgjax.simulate`'s inputs and failures: bad gyros, profiles and options get clear errors
naming the field; a solver that runs out of steps, a NaN in a traced profile and float32
mode raise rather than return NaN; temperature laws vmap."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, resonator

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
    with pytest.raises(
        TypeError, match=r"^key must be one JAX PRNG key, e.g. jax.random.key\(0\); got 0$"
    ):
        hg.simulate(hg.presets.tvg3_like(), prof, key=0)
    with pytest.raises(ValueError, match="drive"):
        hg.Control(drive="magic")
    with pytest.raises(ValueError, match="g_sensitivity"):
        hg.Gyro(resonator(), g_sensitivity=[1.0, 2.0])
    # audit (off the paved path): each was a raw NumPy/JAX/diffrax error, a silent answer
    # (fixed_step=True: a 1-s step; ts=[False, True]) or a NaN reported as a solver failure
    for kw, err, match in [
        (dict(ts=[0.0, np.nan, 0.5]), ValueError, r"^ts must be finite; found nan at index \(1,\)"),
        (dict(ts=["a"]), TypeError, r"^ts must be a 1-D array of output times \[s\]; got list"),
        (dict(ts=[False, True]), TypeError, r"^ts must be a 1-D array of output times"),
        (dict(rtol="1e-8"), TypeError, r"^rtol must be a positive number \(a solver tolerance\)"),
        (dict(atol=None), TypeError, r"^atol must be a positive number"),
        (dict(quadrature0=True), TypeError, r"^quadrature0 must be a finite number"),
        (dict(fixed_step=True), ValueError, r"^fixed_step must be a positive number of seconds"),
        (dict(solver="Tsit5"), TypeError, r"^solver must be a diffrax solver"),
        (dict(solver=diffrax.Tsit5), TypeError, r"^solver must be .* the class Tsit5 itself"),
        (dict(adjoint="x"), TypeError, r"^adjoint must be a diffrax adjoint"),
        (dict(key=jax.random.split(jax.random.key(0), 3)), ValueError,
         r"^key must be one JAX PRNG key, e.g. jax.random.key\(0\); got a key array of shape \(3,\)"),
        (dict(bias_key=jnp.arange(5, dtype=jnp.uint32)), ValueError, r"^bias_key must be one JAX"),
    ]:  # fmt: skip
        with pytest.raises(err, match=match):
            hg.simulate(gyro, prof, **kw)
    with pytest.raises(ValueError, match=r"^model must be one of"):
        hg.simulate(gyro, prof, np.array("averaged"))
    for batch, match in [  # a batch of gyros outside vmap: a shape error deep in the solve
        (hg.presets.ideal(resonator(omega=[1e4, 2e4])), r"^gyro.resonator.omega must be one value"),
        (hg.Gyro(resonator(), g_sensitivity=np.zeros((2, 3))),
         r"^gyro.g_sensitivity must be 3 values, shape \(3,\); got shape \(2, 3\)"),
        (hg.Gyro(resonator(), rate_bias=hg.TemperatureLaw([0.0, 1e-5])), r"^gyro.rate_bias.p0"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=match):
            hg.simulate(batch, prof)


def test_impossible_profiles_and_grids_are_refused_in_one_line():
    """Audit: a 1e5-°/s table, a 1e9-s profile, a 1e9° wave, a rate list one short of the
    knots (numpy's broadcast error), a dt_out longer than the run (its start alone) and
    k_e = 55.4 (a percentage) were taken or failed without naming the field."""
    for build, match in [
        (lambda: hg.Profile.constant_rate(1e5, 1.0), r"^Profile.rate \[°/s\] = 100000 .* 3600 °/s"),
        (lambda: hg.Profile.static(1e9), r"^Profile's length \[s\] = 1e\+09"),
        (lambda: hg.Profile.static(10.0, wave_angle0_deg=1e9), r"^Profile.wave_angle0 \[°\]"),
        (lambda: hg.Profile.piecewise([0.0, 10.0, 20.0], [0.0, 1.0], 20.0),
         r"^Profile.piecewise: rate_dps must be one value or one per knot of t_s, shape \(3,\)"),
        (lambda: resonator(k_e=55.4), r"^Resonator.k_e must be .*percent"),
        (lambda: hg.simulate(hg.presets.ideal(resonator()), hg.Profile.static(10.0), dt_out=30.0),
         r"^dt_out = 30 s is longer than the profile \(10 s\)"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=match):
            build()
    resonator(k_e=1.0)  # a Foucault pendulum's gain: allowed


def test_a_long_fast_run_gets_the_steps_it_needs():
    """The averaged solver's step limit follows the run (`default_max_steps`): an hour at
    100 °/s takes ≈ 7.7·10⁴ steps and stopped at the old fixed limit of 2¹⁶ (at t ≈ 3 050 s);
    a 3-min run keeps 2¹⁶ (its program is the one every short run shares)."""
    from hrgjax.simulate import MAX_STEPS, default_max_steps

    gyro = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    fast = hg.Profile.constant_rate(100.0, 3600.0)
    assert default_max_steps(gyro, hg.Profile.constant_rate(5.0, 180.0), "averaged") == 2**16
    assert default_max_steps(gyro, fast, "averaged") >= 4 * 7.7e4
    assert default_max_steps(gyro, fast, "full") == MAX_STEPS["full"]
    # a batch of profiles (a plan's chunk: concrete outside its program) gets its longest
    # member's: a 4-h rotation at 5 °/s in a plan file stopped at the fixed limit
    batch = jax.tree_util.tree_map(lambda *x: np.stack(x), hg.Profile.constant_rate(5.0, 60.0),
                                   hg.Profile.constant_rate(5.0, 14400.0))  # fmt: skip
    assert (
        default_max_steps(gyro, batch, "averaged")
        == default_max_steps(gyro, hg.Profile.constant_rate(5.0, 14400.0), "averaged")
        > MAX_STEPS["averaged"]
    )
    rec = hg.simulate(gyro, fast, dt_out=3600.0)
    k_e = float(rec.k_e[-1])  # −k_e Ω, and the drift's few °/h beside 2·10⁵° of precession
    assert float(rec.wave_angle[-1]) == pytest.approx(-k_e * np.radians(100.0) * 3600.0, rel=1e-4)


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

    def run_tau(tau):  # under jit a module's own checks are dropped; simulate's stay
        slow = eqx.tree_at(lambda g: g.resonator.tau, gyro, tau)
        return hg.simulate(slow, hg.Profile.constant_rate(1.0, 1.0), dt_out=0.5).wave_angle

    with pytest.raises(Exception, match=r"gyro\.resonator\.tau must be finite"):
        jax.block_until_ready(jax.jit(run_tau)(jnp.nan))
    # a finite but impossible traced value too: the laws' limits (it ran out of steps)
    with pytest.raises(Exception, match=r"gyro\.resonator\.tau must be finite and > 0 s"):
        jax.block_until_ready(jax.jit(run_tau)(0.0))


def test_python_floats_put_in_with_tree_at_compile_nothing_new():
    """A float put in with `eqx.tree_at` (as docs/simulate.md shows) runs the program of the
    same gyro built the usual way: one per shape, not one per value (each compiled again)."""
    gyro, prof = hg.presets.ideal(resonator()), hg.Profile.constant_rate(1.0, 1.0)
    base = hg.simulate(gyro, prof, dt_out=0.5).wave_angle
    with CompileCounter() as c:
        for tau in (600.0, 700.0):  # decay times [s]
            hg.simulate(eqx.tree_at(lambda g: g.resonator.tau, gyro, tau), prof, dt_out=0.5)
    assert c.compiles == 0, c.names
    assert np.all(np.isfinite(base))
    # an int put in the same way is a number too: checked (it skipped every check) and traced
    with pytest.raises(ValueError, match=r"gyro.resonator.tau = 0 s; it must be > 0"):
        hg.simulate(eqx.tree_at(lambda g: g.resonator.tau, gyro, 0), prof, dt_out=0.5)
    with CompileCounter() as c:
        hg.simulate(eqx.tree_at(lambda g: g.resonator.tau, gyro, 600), prof, dt_out=0.5)
    assert c.compiles == 0, c.names
    with CompileCounter() as c:  # a weakly typed JAX number compiled the whole solve again
        weak = jnp.asarray(650.0)
        hg.simulate(eqx.tree_at(lambda g: g.resonator.tau, gyro, weak), prof, dt_out=0.5)
    assert "jit(_solve)" not in c.names, c.names  # (a small eager program may be new)
    # the solver's tolerances and a fixed step are values too (a convergence study compiled
    # the solve again per tolerance, ≈ 3.6 s each)
    with CompileCounter() as c:
        loose = hg.simulate(gyro, prof, dt_out=0.5, rtol=1e-6, atol=1e-8).wave_angle
    assert c.compiles == 0, c.names
    np.testing.assert_allclose(loose, base, rtol=0, atol=1e-9)  # a constant rate: exact
    hg.simulate(gyro, prof, dt_out=0.5, fixed_step=0.01)
    with CompileCounter() as c:
        hg.simulate(gyro, prof, dt_out=0.5, fixed_step=0.02)
    assert c.compiles == 0, c.names


def test_a_given_switch_on_key_runs_the_program_of_a_drawn_one():
    """`bias_key` given or drawn from `key` is one program (a given one compiled the solve
    again, ≈ 2.6 s), and a given key sets the switch-on bias alone: two runs with the same
    `bias_key` and different `key`s share it, so their difference has no bias slope."""
    noisy = hg.presets.tvg3_like().noise
    gyro = eqx.tree_at(lambda g: g.noise, hg.presets.ideal(resonator()), noisy,
                       is_leaf=lambda x: x is None)  # fmt: skip
    prof = hg.Profile.constant_rate(1.0, 1.0)
    drawn = hg.simulate(gyro, prof, key=jax.random.key(0), dt_out=0.5).wave_angle
    with CompileCounter() as c:
        given = [hg.simulate(gyro, prof, key=jax.random.key(k), bias_key=jax.random.key(7),
                             dt_out=0.5).wave_angle for k in (0, 1)]  # fmt: skip
    assert c.compiles == 0, c.names
    assert np.all(np.isfinite(drawn)) and not np.array_equal(drawn, given[0])


def test_float32_mode_raises():
    gyro = hg.presets.ideal(resonator())
    prof = hg.Profile.static(1.0)
    y, k = np.zeros(64), hg.kalman
    prior = k.Gaussian(np.zeros(1), np.eye(1))
    entry_points = {  # each refuses before any JAX work (float32 oadev was 6.8× off at m = 1)
        "hrgjax.simulate": lambda: hg.simulate(gyro, prof),
        "hrgjax.allan.oadev": lambda: hg.allan.oadev(y, 2),
        "hrgjax.allan.allan_deviation": lambda: hg.allan_deviation(y, 1.0),
        "hrgjax.kalman.kalman_filter": lambda: k.kalman_filter(
            prior, np.eye(1), np.eye(1), np.eye(1), np.eye(1), np.zeros((4, 1))
        ),
        "FourierCompensator.fit": lambda: hg.calibration.FourierCompensator().fit(None),
    }
    jax.config.update("jax_enable_x64", False)
    try:
        for name, call in entry_points.items():
            with pytest.raises(RuntimeError, match=f"{name} needs float64"):
                call()
    finally:
        jax.config.update("jax_enable_x64", True)


def test_temperature_law_vmap():
    law = hg.TemperatureLaw(2.0, 0.1, 0.0, 0.0)
    res = resonator(tau=law)
    taus = jax.vmap(lambda T: res.at(T).tau)(jnp.array([10.0, 20.0, 30.0]))
    np.testing.assert_allclose(taus, [1.0, 2.0, 3.0])
    assert not isinstance(res.at(10.0).tau, hg.TemperatureLaw)
    with pytest.raises(
        ValueError, match=r"^the temperature law of Resonator.tau gives 0 s at 0 °C"
    ):
        res.at(0.0)  # τ = 0 there: refused as Resonator(tau=0.0) is (it was returned)


def test_loops_at_exact_equilibrium_give_the_right_sensitivities():
    """A gyro with no defects, at rest, noise off, sits exactly on its loops' equilibrium:
    the step-size controller sees nothing and took 5 steps of 4 s over 20 s, beyond the
    explicit solver's stability on the loops' double pole at −β, so the sensitivities the
    loops drive through those steps came out with the wrong sign and 10⁶ too large
    (d amplitude / d gain mismatch −1.9e4 against 1.3e-2). `max_step` bounds the step at
    `LOOP_STEPS`/β: the gradient now equals central differences."""
    from hrgjax.resonator.control import LOOP_STEPS, max_step

    gyro = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    zero = eqx.tree_at(
        lambda g: (g.resonator.delta_omega, g.resonator.delta_inv_tau, g.resonator.chi,
                   g.control.excitation_phase, g.readout.gain_mismatch, g.readout.cross_talk,
                   g.readout.misalignment, g.rate_bias),
        gyro, (0.0,) * 8,
    )  # fmt: skip
    beta = max(float(gyro.control.pll_bandwidth), float(gyro.control.agc_bandwidth),
               float(gyro.control.quadrature_bandwidth))  # fmt: skip
    assert float(max_step(zero.control)) == pytest.approx(LOOP_STEPS / beta)
    assert float(max_step(hg.Control.free())) == np.inf
    prof = hg.Profile.static(10.0, 20.0, 30.0)

    def loss(g):
        rec = hg.simulate(g, prof, dt_out=1.0)
        return jnp.mean(rec.amplitude) + 1e3 * jnp.mean(rec.quadrature)

    def at(x):
        return eqx.tree_at(lambda g: g.readout.gain_mismatch, zero, x)

    tangent = jax.grad(lambda x: loss(at(x)))(jnp.asarray(0.0))
    h = 1e-7
    fd = (loss(at(h)) - loss(at(-h))) / (2 * h)
    assert abs(float(fd)) > 1e-2  # the loss does respond (≈ 0.03)
    np.testing.assert_allclose(float(tangent), float(fd), rtol=1e-5)


def test_a_loop_bandwidth_may_follow_a_temperature_law():
    """A bandwidth given as a temperature law bounds the step at its largest value over the
    profile's temperatures (the bound crashed on a law: "maximum requires ndarray")."""
    from hrgjax.resonator.control import LOOP_STEPS, max_step
    from hrgjax.simulate import default_max_steps

    gyro = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    law = hg.TemperatureLaw(2.0, 0.1)  # 2 rad/s at the reference 20 °C, +0.1 rad/s per °C
    warm = eqx.tree_at(lambda g: g.control.pll_bandwidth, gyro, law)
    temps = np.array([20.0, 40.0])
    beta = float(np.max(law(jnp.asarray(temps))))
    assert float(max_step(warm.control, "averaged", temps)) == pytest.approx(LOOP_STEPS / beta)
    # a batch of three gyros' laws over five temperatures: each gyro its own largest
    batch = eqx.tree_at(lambda c: c.pll_bandwidth, warm.control,
                        hg.TemperatureLaw(jnp.array([1.0, 2.0, 4.0]), 0.1))  # fmt: skip
    five = np.linspace(0.0, 40.0, 5)
    want = LOOP_STEPS / np.maximum(np.array([1.0, 2.0, 4.0]) + 0.1 * 20.0, 2.0)
    np.testing.assert_allclose(max_step(batch, "averaged", five), want, rtol=1e-12)
    prof = hg.Profile.static(4.0, 40.0, 30.0)
    assert default_max_steps(warm, prof, "averaged") >= 1
    rec = hg.simulate(warm, prof, dt_out=1.0)
    np.testing.assert_allclose(rec.amplitude, 1.0, rtol=1e-2)  # the AGC holds its set point


def test_readout_and_control_refuse_values_out_of_range():
    """Audit: `Readout` and `Control` took any value — a gain mismatch of 1 (1 % given as 1)
    read wave angle 0 at every sample; 100, or a misalignment of 5 (degrees as radians), ran
    out of solver steps; a negative amplitude or bandwidth ran on with garbage. Each field has
    a range (`LIMITS`, justified in the docstrings), refused in one line naming the field,
    the range and the unit: where the module is built, as a temperature law over the run's
    temperatures, and as a traced value inside the run. A bandwidth of 0 (open loop) stays."""
    import re

    bad = [
        (hg.Readout, "gain_mismatch", 1.0, "in (-0.5, 0.5) (a fraction, not percent); got 1"),
        (hg.Readout, "gain_mismatch", 100.0, "(a fraction, not percent)"),
        (hg.Readout, "cross_talk", np.nan, "got nan"),
        (hg.Readout, "misalignment", 5.0, "in (-π/4, π/4) rad (mechanical); got 5"),
        (hg.Control, "amplitude", 0.0, "> 0 readout units"),
        (hg.Control, "amplitude", -1.0, "> 0 readout units"),
        (hg.Control, "excitation_phase", 5.0, "in (-π/4, π/4) rad"),
        (hg.Control, "pll_bandwidth", -2.0, ">= 0 rad/s"),
        (hg.Control, "quadrature_bandwidth", -2.0, ">= 0 rad/s"),
        (hg.Control, "agc_bandwidth", np.nan, ">= 0 rad/s"),
        (hg.Control, "forcer_gain", -1.0, "> -1 (a fraction, not percent"),
        (hg.Control, "forcer_gain_mismatch", 100.0, "in (-0.5, 0.5)"),
        (hg.Control, "forcer_angle", 2.0, "in (-π/4, π/4) rad (electrical)"),
        (hg.Control, "k_e_nominal", 0.0, "in (0, 1]"),
        (hg.Control, "rebalance_limit", -5.0, "> 0 readout units · rad²/s²"),
    ]
    for cls, field, value, words in bad:
        with pytest.raises(ValueError, match=f"{cls.__name__}.{field} must be finite and") as e:
            cls(**{field: value})
        assert words in str(e.value) and "\n" not in str(e.value), str(e.value)
    hg.Control(pll_bandwidth=0.0, agc_bandwidth=0.0, quadrature_bandwidth=0.0)  # open loops
    gyro, prof = hg.presets.ideal(resonator()), hg.Profile.static(1.0, 80.0)
    law = hg.Readout(gain_mismatch=hg.TemperatureLaw(0.0, 0.01))  # 0.01/°C: 0.6 at 80 °C
    with pytest.raises(ValueError, match=re.escape("gyro.readout.gain_mismatch gives 0.6 (a")):
        hg.simulate(eqx.tree_at(lambda g: g.readout, gyro, law), prof)

    def run(amplitude):  # under jit the module's own check is dropped; simulate's stays
        ctl = eqx.tree_at(lambda g: g.control.amplitude, gyro, amplitude)
        return hg.simulate(ctl, prof, dt_out=0.5).amplitude

    with pytest.raises(Exception, match=re.escape("gyro.control.amplitude must be finite and > 0")):
        jax.block_until_ready(jax.jit(run)(-1.0))


def test_implausible_traced_values_are_refused_in_a_sweep_as_eagerly():
    """Inside `hg.sweep` (jit + vmap) `Profile` sees no values, so `simulate` holds traced
    ones to the eager rules at run time: a temperature of 1000 °C and a τ law driven negative
    over the run's temperatures raise one line naming the field (they returned a confident
    angle with τ < 0); a plausible grid still equals the runs one by one."""
    gyro = hg.presets.ideal(resonator())

    def final(temperature_c):
        prof = hg.Profile.constant_rate(1.0, 2.0, temperature_c)
        return hg.simulate(gyro, prof, dt_out=1.0).wave_angle[-1]

    good = hg.sweep(final, temperature_c=jnp.array([20.0, 60.0]))
    one = [float(final(t)) for t in (20.0, 60.0)]
    np.testing.assert_allclose(good, one, rtol=1e-12)
    with pytest.raises(RuntimeError) as err:
        hg.sweep(final, temperature_c=jnp.array([20.0, 1000.0]))
    message = str(err.value)
    assert message.startswith("sweep: at one or more grid points, Profile.temperature is "
                              "outside the plausible range -100 … 150 °C") and "kelvin" in message  # fmt: skip
    assert "\n" not in message
    # under the user's own eager vmap (or grad): the same rule in one line, not JAX's
    # callback traceback and equinox's banner (43 lines)
    with pytest.raises(RuntimeError, match=r"^simulate: Profile.temperature is outside the pl"):
        jax.vmap(final)(jnp.array([20.0, 1000.0]))
    with hg.plausible.relaxed(temperature_c=(-100.0, 1100.0)):  # the same fn, swept again
        np.testing.assert_allclose(hg.sweep(final, temperature_c=jnp.array([60.0, 1000.0]))[0],
                                   one[1], rtol=1e-12)  # fmt: skip

    def tau_slope(p1):  # τ = 50 s + p1 (T − 20 °C): at 60 °C, p1 = −2 s/°C gives τ = −30 s
        hot = eqx.tree_at(lambda g: g.resonator.tau, gyro, hg.TemperatureLaw(50.0, p1))
        return hg.simulate(hot, hg.Profile.constant_rate(1.0, 2.0, 60.0), dt_out=1.0).wave_angle

    with pytest.raises(ValueError, match=r"law of gyro\.resonator\.tau gives -30 s at 60"):
        tau_slope(-2.0)  # eagerly
    with pytest.raises(RuntimeError, match=r"grid points, the temperature law of gyro\.resonator"
                       r"\.tau leaves its range .* it must be > 0 s there$"):  # fmt: skip
        hg.sweep(tau_slope, p1=jnp.array([0.0, -2.0]))


def test_implausible_traced_rates_and_knots_are_refused_under_jit_and_vmap():
    """The same under the caller's own `jax.jit(jax.vmap(…))`: a table rate of 10⁶ °/s and a
    run of negative length (its knots out of order) raise the eager rule's line."""
    gyro = hg.presets.ideal(resonator())

    def run(rate_dps, duration_s):
        prof = hg.Profile.constant_rate(rate_dps, duration_s)
        return hg.simulate(gyro, prof, ts=jnp.array([0.0, 0.5])).wave_angle

    batch = jax.jit(jax.vmap(run))
    ok = batch(jnp.array([1.0, 2.0]), jnp.array([1.0, 1.0]))
    assert np.all(np.isfinite(ok))
    with pytest.raises(Exception, match=r"Profile.rate \[°/s\] is outside the plausible range"):
        jax.block_until_ready(batch(jnp.array([1.0, 1e6]), jnp.array([1.0, 1.0])))
    with pytest.raises(Exception, match="Profile.t must be strictly increasing"):
        jax.block_until_ready(batch(jnp.array([1.0, 1.0]), jnp.array([1.0, -1.0])))
    # an output time past the end of a run whose length is traced: the eager rule's line
    # (the solver's "simulate produced NaN or inf (a solver failed …)" before)
    with pytest.raises(Exception, match=r"ts must lie within the profile \[its first, its last"):
        jax.block_until_ready(batch(jnp.array([1.0, 1.0]), jnp.array([1.0, 0.25])))


def test_traced_gyro_rates_outside_their_ranges_are_refused_under_vmap():
    """A rate bias swept to 0.3 (0.3 °/h typed as rad/s) and a switch-on bias σ of 0.2 put in
    under the caller's eager `jax.vmap` raise their range's line, unit hint included; a
    plausible batch runs."""
    gyro = hg.presets.ideal(resonator())
    prof = hg.Profile.constant_rate(1.0, 1.0)

    def run(bias):
        return hg.simulate(eqx.tree_at(lambda g: g.rate_bias, gyro, bias), prof,
                           ts=jnp.array([0.0, 0.5])).wave_angle  # fmt: skip

    assert np.all(np.isfinite(jax.vmap(run)(jnp.array([0.0, 1e-5]))))
    with pytest.raises(RuntimeError, match=r"^simulate: gyro.rate_bias is outside the plausible "
                       r"range -0.1 … 0.1 rad/s — °/h → ×hrgjax.units.DEG_PER_H"):  # fmt: skip
        jax.vmap(run)(jnp.array([0.0, 0.3]))


def test_forward_mode_and_loops_above_the_carrier_get_one_line():
    """`jax.jvp`/`jax.jacfwd` through the default (reverse-mode) adjoint raise one line naming
    `diffrax.ForwardMode()` (JAX's "can't apply forward-mode autodiff (jvp) to a custom_vjp
    function" before); a loop bandwidth above the carrier is refused by the averaged model."""
    from hrgjax._simulate_options import forward_mode_hint

    gyro, prof = hg.Gyro(resonator()), hg.Profile.static(0.05)

    def final(bias):  # the error comes while tracing: nothing compiles
        run = hg.simulate(eqx.tree_at(lambda g: g.rate_bias, gyro, bias), prof, dt_out=0.01)
        return run.wave_angle[-1]

    with pytest.raises(TypeError, match=r"^simulate: forward-mode derivatives .* "
                       r"adjoint=diffrax.ForwardMode\(\) for jvp/jacfwd, diffrax.DirectAdjoint"):  # fmt: skip
        jax.jvp(final, (0.0,), (1.0,))
    with pytest.raises(ValueError, match="^other"), forward_mode_hint():
        raise ValueError("other")
    res = resonator(omega=2 * np.pi * 5e3)  # ≈ 3.1e4 rad/s
    fast = hg.Gyro(res, control=hg.Control(pll_bandwidth=5e4))
    with pytest.raises(ValueError, match=r"^gyro.control.pll_bandwidth = 50000 rad/s at 20 °C is "
                       r"at or above 0.1 × the carrier ω = 31415.9 rad/s: .* model=\"full\"$"):  # fmt: skip
        hg.simulate(fast, hg.Profile.static(0.01), dt_out=0.01)
    from hrgjax._run_checks import check_bandwidths

    check_bandwidths(fast, hg.Profile.static(0.01), "full")  # the full model resolves ω
    check_bandwidths(hg.Gyro(res, control=hg.Control(pll_bandwidth=3e3)), hg.Profile.static(0.01),
                     "averaged")  # fmt: skip
    # the resonator's own rates too (audit: Q = 2.5 put θ 0.05 rad off, Δω = 0.2 ω 0.25 rad)
    free, prof = hg.Control.free(), hg.Profile.static(0.01)
    w = 2 * np.pi * 5e3
    for kw, match in (
        (dict(tau=2e-4), r"^gyro.resonator.tau = 0.0002 s at 20 °C \(the damping rate "
                         r"1/τ = 5000 1/s\) is at or above 0.1 × the carrier ω"),  # Q = 3.1
        (dict(omega=10.0, tau=1.5, delta_inv_tau=-1.0), r"^gyro.resonator.delta_inv_tau = -1 "
                                                         r"1/s .*½\|Δ\(1/τ\)\| = 1.16667 1/s"),
        (dict(omega=10.0, tau=640.0, delta_omega=-1.0), r"^gyro.resonator.delta_omega = -1 rad/s"
                                                         r" at 20 °C is at or above 0.1 × .* ω = 10"),
    ):  # fmt: skip
        gyro = hg.Gyro(resonator(**({"omega": w} | kw)), control=free)
        with pytest.raises(ValueError, match=match + r".*model=\"full\"$"):
            check_bandwidths(gyro, prof, "averaged")
        check_bandwidths(gyro, prof, "full")
    check_bandwidths(hg.Gyro(resonator(omega=10.0, tau=640.0, delta_omega=0.99), control=free),
                     prof, "averaged")  # fmt: skip
