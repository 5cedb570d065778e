"""Resonator models refused outside their domain (validity audit).

Independent truth: the averaged model with the PI loops integrated as states (the slow
manifold must give its mean wave-angle rate); the damping condition 1/τ₁,₂ = 1/τ ± Δ(1/τ)/2
> 0 (PHYSICS.md §2).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
from hrgjax.calibration import PhysicalCompensator
from hrgjax.resonator.averaged import input_rate
from hrgjax.resonator.slow import reduced_rate, slow_manifold

jax.config.update("jax_enable_x64", True)


def _with_split(split_hz):
    g = hg.presets.tvg3_like(temperature_laws=False, noise=False)
    return eqx.tree_at(lambda g: g.resonator.delta_omega, g, 2 * np.pi * split_hz)


def test_negative_damping_refused():
    """Audit: Resonator(delta_inv_tau=3·2/τ) built and simulated (1/τ₂ < 0: the free
    amplitude grew). |Δ(1/τ)| < 2/τ is refused at construction, and where a law crosses it."""
    with pytest.raises(ValueError, match=r"Resonator\.delta_inv_tau = 0\.009375 1/s .* < 2/τ"):
        hg.Resonator(omega=2 * np.pi * 5e3, tau=640.0, delta_inv_tau=3 * 2 / 640.0)
    with pytest.raises(ValueError, match="negative damping"):
        hg.Resonator(omega=1.0, tau=640.0, delta_inv_tau=[0.0, -0.01])
    hg.Resonator(omega=1.0, tau=640.0, delta_inv_tau=-1.99 / 640.0)  # both axes damped
    res = hg.Resonator(omega=1.0, tau=hg.TemperatureLaw(640.0, 6.0), delta_inv_tau=2.5e-3)
    res.at(20.0)  # 2/τ = 3.1e-3 1/s there; at 80 °C τ = 1000 s, 2/τ = 2e-3
    with pytest.raises(ValueError, match=r"delta_inv_tau .* at 80 °C"):
        res.at(jnp.array([20.0, 80.0]))
    # simulate holds a law (or a value put in with eqx.tree_at) to it over the profile
    gyro = hg.presets.tvg3_like(noise=False)
    lawful = eqx.tree_at(lambda g: g.resonator.delta_inv_tau, gyro, 2.5e-3)
    tau_law = hg.TemperatureLaw(640.0, 6.0)  # 1000 s at 80 °C: 2/τ = 2e-3 1/s < 2.5e-3
    lawful = eqx.tree_at(lambda g: g.resonator.tau, lawful, tau_law)
    with pytest.raises(ValueError, match=r"gyro\.resonator: .*negative damping"):
        hg.simulate(lawful, hg.Profile.static(1.0, 80.0))
    # and a traced Δ(1/τ) (a sweep over it) at run time (review: it integrated the unstable
    # mode silently under jit and hg.sweep)
    run = jax.jit(lambda d: hg.simulate(eqx.tree_at(lambda g: g.resonator.delta_inv_tau, gyro, d),
                                        hg.Profile.static(1.0, 20.0)).wave_angle)  # fmt: skip
    run(0.0)
    with pytest.raises(Exception, match="negative damping"):
        run(4 / 640.0)


def test_axis_angles_in_degrees_are_refused():
    """Audit: `Resonator(theta_tau=30.0)` and `theta_omega=45.0` (degrees typed for radians)
    were taken silently, while Readout's and Control's angles are range-checked. The axes
    repeat every π (electrical), so no radian value needs more than ±2π: beyond is refused,
    as a value, a law where it is evaluated, naming the field, the unit and the degrees hint."""
    res = lambda **kw: hg.Resonator(omega=2 * np.pi * 5e3, tau=640.0, **kw)  # noqa: E731
    for kw in (dict(theta_tau=30.0), dict(theta_omega=45.0), dict(theta_omega=[0.1, -7.0])):
        name = next(iter(kw))
        with pytest.raises(ValueError, match=rf"^Resonator.{name} must be finite and in \[-2π, 2π\] "
                           r"rad \(electrical; from degrees: × hrgjax.units.DEG\); got -?\d+$"):  # fmt: skip
            res(**kw)
    res(theta_omega=2 * np.pi, theta_tau=-2 * np.pi)  # a turn either way: still radians
    law = res(theta_tau=hg.TemperatureLaw(0.5, 0.1))  # 6.5 rad at 80 °C
    law.at(20.0)
    with pytest.raises(ValueError, match=r"^the temperature law of gyro.resonator.theta_tau "
                       r"gives 6.5 rad \(electrical; .* at 80 °C; it must be .* \[-2π, 2π\]"):  # fmt: skip
        hg.Gyro(law).at(jnp.array([20.0, 80.0]))


def test_slow_manifold_refuses_a_split_beyond_its_domain():
    """Audit: at Δω = 2π·0.5 Hz (Δω/β_q = 1.57 with the 2 rad/s quadrature loop) the
    linearised manifold's drift was 2.4× the PI loops' (8.2 vs 19.5 rad over 1297 s at
    10 °/s); a split beyond MAX_SPLIT_RATIO·β_q is refused, for reduced_rate and for a
    compensator's plant."""
    gyro = _with_split(0.5)
    g = gyro.at(20.0)
    with pytest.raises(ValueError, match=r"gyro\.resonator\.delta_omega = 3\.142 rad/s"):
        reduced_rate(g, 0.1, 0.3)
    with pytest.raises(ValueError, match=r"PhysicalCompensator\.plant\.resonator\.delta_omega"):
        PhysicalCompensator(plant=gyro)
    traced = jax.jit(lambda d: reduced_rate(eqx.tree_at(lambda x: x.resonator.delta_omega,
                                                        g, d), 0.1, 0.3))  # fmt: skip
    assert np.isfinite(float(traced(1.0)))  # Δω/β_q = 0.5
    with pytest.raises(Exception, match="delta_omega exceeds it"):
        traced(2 * np.pi * 0.5)


def test_slow_manifold_holds_a_large_split():
    """Δω = 2π·0.2 Hz (Δω/β_q = 0.63, inside the domain), 10 °/s: the mean wave-angle
    rate over one turn of 2θ on the slow manifold equals the averaged PI-loop run's to
    < 1e-3 of the loops' defect drift (≈ 23 % of the rate here). The linearised balance
    (before the Newton steps) was 31 % off it."""
    gyro, rate_dps = _with_split(0.2), 10.0
    prof = hg.Profile.constant_rate(rate_dps, 60.0, 20.0, wave_angle0_deg=30.0)
    rec = hg.simulate(gyro, prof, dt_out=0.05)
    t, theta = np.asarray(rec.t), np.asarray(rec.true_wave_angle)
    g = gyro.at(20.0)
    w = input_rate(g, prof, 0.0)
    ideal = -float(g.resonator.k_e) * float(w)
    i0 = np.searchsorted(t, 10.0)  # the loops' transient (1/β = 0.5 s) has passed
    turned = np.abs(theta[i0:] - theta[i0])
    period = np.interp(np.pi, turned, t[i0:]) - t[i0]
    sim = -np.pi / period - ideal
    angles = jnp.linspace(0.0, jnp.pi, 16)[:-1]
    slow = np.asarray(jax.jit(jax.vmap(lambda x: reduced_rate(g, w, x)))(angles))
    reduced = 1.0 / np.mean(1.0 / slow) - ideal  # mean rate over a period: π / ∫dθ/θ̇
    assert sim > 0.2 * abs(ideal)  # the loops' defect drift is there
    assert abs(reduced - sim) < 1e-3 * sim


def test_bad_parts_units_and_ranges_are_refused_in_one_line():
    """Audit (off the paved path): NaN parameters built silently (a NaN g-sensitivity then
    ran the solver out of steps), `Resonator.at`/`Gyro.at` returned τ < 0 or k_e = 55 from a
    law, and the units helpers, `group_temperatures`, `steps_per_cycle` and `plausible`
    failed on a str or None with raw Python errors (or let it pass: `check`)."""
    from hrgjax.resonator.carrier import steps_per_cycle

    res = hg.Resonator(omega=2 * np.pi * 5e3, tau=640.0)
    for build, err, match in [
        (lambda: hg.Gyro(res, g_sensitivity=[np.nan, 0.0, 0.0]), ValueError,
         r"^Gyro.g_sensitivity must be finite; found nan at index \(0,\)"),
        (lambda: hg.Gyro(res, rate_bias=np.inf), ValueError, r"^Gyro.rate_bias must be finite"),
        (lambda: hg.DriftTerms(warmup=np.nan), ValueError, r"^DriftTerms.warmup must be finite"),
        (lambda: hg.TemperatureLaw(np.nan), ValueError, r"^TemperatureLaw.p0 must be finite"),
        (lambda: hg.Resonator(omega=1.0, tau=hg.TemperatureLaw(640.0, -10.0)).at(100.0),
         ValueError, r"^the temperature law of Resonator.tau gives -160 s at 100 °C; it must"),
        (lambda: hg.Resonator(omega=1.0, tau=1.0, k_e=hg.TemperatureLaw(0.5, 0.01)).at(
            jnp.array([20.0, 80.0])), ValueError, r"^the temperature law of Resonator.k_e gives 1.1 .* at 80 °C"),
        (lambda: hg.Gyro(res, readout=hg.Readout(gain_mismatch=hg.TemperatureLaw(0.0, 0.01))).at(
            100.0), ValueError, r"^the temperature law of gyro.readout.gain_mismatch gives 0.8"),
        (lambda: hg.units.deg("10"), TypeError, r"^units.deg: x must be a real number"),
        (lambda: hg.units.to_dph(None), TypeError, r"^units.to_dph: x must be a real number"),
        (lambda: hg.units.group_temperatures(["a"]), TypeError, r"^values must be temperatures"),
        (lambda: hg.units.group_temperatures([1.0], tol=True), ValueError, r"^tol must be a finite"),
        (lambda: steps_per_cycle(0.0), ValueError, r"^rtol must be a positive number"),
        (lambda: hg.plausible.check("temperature_c", "hot"), TypeError,
         r"^temperature_c must be real numbers \[°C\]; got str"),
        (lambda: hg.plausible.check("x", 1.0, "tempreature_c"), KeyError, "unknown quantity"),
        (lambda: hg.plausible.relaxed(temperature_c=5).__enter__(), TypeError,
         r"^plausible.relaxed: temperature_c must be \(low, high\) \[°C\]; got 5"),
        (lambda: hg.plausible.check_size("run_plan", np.nan, 1), ValueError,
         r"^run_plan: the output samples must be a number ≥ 0; got nan"),
    ]:  # fmt: skip
        with pytest.raises(err, match=match):
            build()
    assert np.allclose(hg.units.deg([90.0, 180.0]), [np.pi / 2, np.pi])  # a list: as an array
    # what the checks let through, as before them: bounds as an array, a 0-d array count
    for bounds in (np.array([-100.0, 180.0]), jnp.array([-100.0, 180.0]), [-100, 180]):
        with hg.plausible.relaxed(temperature_c=bounds):
            hg.plausible.check("temperature_c", 170.0)  # beyond 150 °C: allowed here only
    with pytest.raises(ValueError, match="outside the plausible range"):
        hg.plausible.check("temperature_c", 170.0)
    for count in (np.asarray(10.0), jnp.asarray(10), np.int64(10)):
        hg.plausible.check_size("run_plan", count, 1)
    with pytest.raises(ValueError, match=r"^run_plan: 1 runs hold 6e\+07 output samples"):
        hg.plausible.check_size("run_plan", jnp.asarray(6e7), 1)
    hg.presets.tvg3_like().at(jnp.array([-100.0, 150.0]))  # its laws hold over the range


def test_reduced_rate_and_a_law_refuse_bad_arguments_before_any_work():
    """Audit: `reduced_rate(g, nan, θ)` returned NaN after seconds of eager work, a str
    angle raised NumPy's conversion error, a str gyro an AttributeError; a
    `TemperatureLaw` evaluated at "20" read it as 20 °C. (`TemperatureLaw("20")` was already
    refused at construction.) `slow_manifold` is held to the same (it gave NaN, an
    AttributeError, NumPy's index error), and both to one number each: an array of angles met
    the manifold's own samples in a broadcasting error."""
    g = _with_split(0.2).at(20.0)
    for fn in (reduced_rate, slow_manifold):
        who = fn.__name__
        for args, kind, match in (
            ((g, np.nan, 0.3), ValueError, rf"^{who}: omega_in must be one finite real number "
             r"\(the input rate \[rad/s\]; jax.vmap it over many\); got nan"),
            ((g, 0.1, np.inf), ValueError, rf"^{who}: theta must be one finite real number "
             r"\(the electrical wave angle \[rad\]; jax.vmap it over many\); got inf"),
            ((g, "a", 0.3), TypeError, rf"^{who}: omega_in must be .*; got str 'a'"),
            ((g, 0.1, None), TypeError, rf"^{who}: theta must be .*; got None"),
            ((g, 0.1, [0.3, 0.4]), ValueError, rf"^{who}: theta must be .*; got shape \(2,\)"),
            (("g", 0.1, 0.3), TypeError, rf"^{who}: g must be a hrgjax.Gyro at its "
             r"temperature \(gyro.at\(T\)\); got str"),
        ):  # fmt: skip
            with pytest.raises(kind, match=match) as err:
                fn(*args)
            assert "\n" not in str(err.value)
    law = hg.TemperatureLaw(1.0, 0.1)
    for temp, got in (("20", "str '20'"), (None, "None"), (True, "bool True")):
        with pytest.raises(TypeError, match=rf"^TemperatureLaw: temperature_c must be real "
                                            rf"numbers \[°C\]; got {got}"):  # fmt: skip
            law(temp)
    assert float(law(25.0)) == float(law(np.float64(25.0), xp=np)) == 1.5


def test_negative_stiffness_refused():
    """Audit: `Resonator(delta_omega=1.5·ω)` (axis stiffness ω² − ω|Δω| < 0) was accepted and
    the full model returned an amplitude of 4·10³⁷ after 0.5 s. |Δω| < ω (PHYSICS.md §2:
    K = ω²I + ωΔω A(θω), eigenvalues ω² ± ωΔω) is refused for every model, as a value, a
    law where it is evaluated, and a traced value at run time."""
    w = 2 * np.pi * 5e3
    with pytest.raises(ValueError, match=r"^Resonator\.delta_omega = 47123\.9 rad/s .* "
                       r"negative stiffness .* \|Δω\| must be < ω$"):  # fmt: skip
        hg.Resonator(omega=w, tau=640.0, delta_omega=1.5 * w)
    with pytest.raises(ValueError, match="negative stiffness"):
        hg.Resonator(omega=w, tau=640.0, delta_omega=[0.0, -w])  # |Δω| = ω: zero stiffness
    hg.Resonator(omega=w, tau=640.0, delta_omega=-0.99 * w)
    res = hg.Resonator(omega=w, tau=640.0, delta_omega=hg.TemperatureLaw(0.9 * w, 5e-3 * w))
    res.at(20.0)  # 1.2 ω at 80 °C
    with pytest.raises(ValueError, match=r"delta_omega .* at 80 °C"):
        res.at(jnp.array([20.0, 80.0]))
    gyro = hg.Gyro(hg.Resonator(omega=w, tau=640.0))
    split = eqx.tree_at(lambda g: g.resonator.delta_omega, gyro, 1.5 * w)
    for model in ("full", "averaged"):
        with pytest.raises(ValueError, match=r"^gyro\.resonator: .*negative stiffness"):
            hg.simulate(split, hg.Profile.static(0.01), dt_out=0.01, model=model)
    run = jax.jit(lambda d: hg.simulate(eqx.tree_at(lambda g: g.resonator.delta_omega, gyro, d),
                                        hg.Profile.static(0.01), dt_out=0.01).wave_angle)  # fmt: skip
    with pytest.raises(Exception, match="negative stiffness"):
        run(1.5 * w)
