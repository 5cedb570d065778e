"""Effect catalogue (issue 4, PHYSICS.md §10): contract names, exact nulls, and each term
against the simulator's own physics where the simulator has the mechanism."""

import dataclasses
import re
from types import SimpleNamespace

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
from hrgjax.discovery import CATALOGUE, NOMINAL, Covariates, null_params, pattern_rate
from hrgjax.discovery.effects import rate_term, rate_term_with_gain, readout_angle, readout_term
from hrgjax.resonator.averaged import averaged_vector_field
from hrgjax.units import DEG, DEG_PER_H

CONTRACT = {
    "bias_temperature",
    "angular_gain_temperature",
    "rate_scale_factor",
    "damping_anisotropy_temperature",
    "frequency_split",
    "excitation_phase",
    "nonlinearity",
    "drive_gain_mismatch",
    "thermal_rate",
    "thermal_lag",
    "warmup_transient",
    "acceleration_sensitivity",
    "readout_gain_mismatch",
}
ADDED = {"readout_gain_mismatch_temperature", "loop_ripple"}  # DISCOVERY.md H9; issue 19
K_E = 0.554
THETA = jnp.linspace(-1.5, 1.5, 11)


def test_catalogue_has_exactly_the_contract_names():
    assert set(CATALOGUE) == CONTRACT | set(NOMINAL) | ADDED
    for name, effect in CATALOGUE.items():
        assert effect.where in ("rate", "readout"), name
        assert all(p.scale > 0 for p in effect.params), name
        assert set(effect.aliases) <= set(CATALOGUE), name


def _covariates(key):
    k = jax.random.split(key, 8)
    n = 16
    return Covariates(
        theta=jax.random.uniform(k[0], (n,), minval=-3, maxval=3),
        rate=jax.random.normal(k[1], (n,)),
        temperature=jax.random.uniform(k[2], (n,), minval=-40, maxval=60),
        temperature_rate=jax.random.normal(k[3], (n,)),
        temperature_lagged=jax.random.uniform(k[4], (n,), minval=-40, maxval=60),
        amplitude=1.0 + 0.1 * jax.random.uniform(k[5], (n,)),
        quadrature=0.01 * jax.random.normal(k[6], (n,)),
        accel_z=jax.random.normal(k[7], (n,)),
        t_run=jnp.linspace(0.0, 600.0, n),
    )


def test_every_term_is_exactly_zero_at_its_null(key):
    c = _covariates(key)
    nulls = null_params([n for n in CATALOGUE if n != "angular_gain"])
    for name, p in nulls.items():
        effect = CATALOGUE[name]
        if effect.where == "readout":
            out = readout_term(name, p, c)
        elif effect.scales_gain:
            out = rate_term_with_gain(name, p, c, K_E)
        else:
            out = rate_term(name, p, c)
        np.testing.assert_array_equal(out, 0.0, err_msg=name)
    # The superset at its null is the nominal −k_e·Ω alone.
    params = {"angular_gain": jnp.asarray([K_E])} | {
        n: p for n, p in nulls.items() if CATALOGUE[n].where == "rate"
    }
    np.testing.assert_allclose(pattern_rate(params, c), -K_E * c.rate, rtol=1e-15, atol=0)


def _ideal_rate(gyro, temperature=20.0, theta=THETA, accel=(0.0, 0.0, 0.0)):
    """Pattern rate of the ideal-loop averaged model at rest, straight from its vector field."""
    prof = hg.Profile.static(1.0, temperature, accel_g=accel)
    return jax.vmap(lambda th: averaged_vector_field(0.0, th[None], (gyro, prof))[0])(theta)


def _ideal(**res_kw):
    base = dict(omega=2 * np.pi * 5000.0, tau=640.0, k_e=K_E)
    base.update(res_kw)
    return hg.presets.ideal(hg.Resonator(**base))


def test_damping_anisotropy_and_its_temperature_law_match_the_simulator():
    d0, slope_d, th0 = 4e-6, -3e-8, 0.4
    gyro = _ideal(delta_inv_tau=hg.TemperatureLaw(d0, slope_d), theta_tau=th0)
    for temp in (20.0, -40.0):
        dt = temp - 20.0
        p0 = jnp.asarray([0.5 * d0 * np.cos(2 * th0), 0.5 * d0 * np.sin(2 * th0)])
        p1 = jnp.asarray([0.5 * slope_d * np.cos(2 * th0), 0.5 * slope_d * np.sin(2 * th0)])
        c = Covariates(theta=THETA, temperature=jnp.asarray(temp))
        term = rate_term("damping_anisotropy", p0, c)
        term = term + rate_term("damping_anisotropy_temperature", p1, c)
        np.testing.assert_allclose(_ideal_rate(gyro, temp), term, rtol=1e-12, atol=1e-20)
        assert dt == 0.0 or not np.allclose(term, rate_term("damping_anisotropy", p0, c))


def test_bias_terms_and_acceleration_match_the_simulator():
    b0, b1, b2 = 0.3 * DEG_PER_H, 0.005 * DEG_PER_H, 1e-4 * DEG_PER_H
    g_z = 0.01 * DEG_PER_H
    gyro = eqx.tree_at(
        lambda g: (g.rate_bias, g.g_sensitivity),
        _ideal(),
        (hg.TemperatureLaw(b0, b1, b2), jnp.asarray([0.0, 0.0, g_z])),
    )
    temp, a_z = -30.0, 0.7
    c = Covariates(theta=THETA, temperature=jnp.asarray(temp), accel_z=jnp.asarray(a_z))
    term = (
        rate_term("bias", jnp.asarray([-K_E * b0]), c)
        + rate_term("bias_temperature", jnp.asarray([-K_E * b1, -K_E * b2]), c)
        + rate_term("acceleration_sensitivity", jnp.asarray([-K_E * g_z]), c)
    )
    sim = _ideal_rate(gyro, temp, accel=(0.0, 0.0, a_z))
    np.testing.assert_allclose(sim, term, rtol=1e-12)


def test_angular_gain_temperature_matches_a_k_e_law():
    kappa = 2e-5
    gyro = _ideal(k_e=hg.TemperatureLaw(K_E, K_E * kappa))
    temp, omega = 50.0, 5.0 * DEG
    prof = hg.Profile.constant_rate(5.0, 1.0, temp)
    sim = averaged_vector_field(0.0, jnp.zeros(1), (gyro, prof))[0]
    c = Covariates(theta=jnp.asarray(0.0), rate=jnp.asarray(omega), temperature=jnp.asarray(temp))
    term = -K_E * omega + rate_term_with_gain(
        "angular_gain_temperature", jnp.asarray([kappa]), c, K_E
    )
    np.testing.assert_allclose(sim, term, rtol=1e-14)


@pytest.mark.parametrize("q", [1e-3, -2e-3])
def test_split_and_nonlinearity_terms_match_the_free_vector_field(q):
    """PHYSICS §4.3, §4.5: to first order in q/a the averaged θ̇ is
    −Δω (q/a) cos2(θ − θ_ω) − χ a q /(4ω)."""
    omega, dw, th_w, chi = 2 * np.pi * 5000.0, 2 * np.pi * 5e-4, 0.2, 5000.0
    res = hg.Resonator(omega=omega, tau=640.0, k_e=K_E, delta_omega=dw, theta_omega=th_w, chi=chi)
    gyro = hg.Gyro(res, control=hg.Control.free())
    prof = hg.Profile.static(1.0)
    a = 1.0

    def theta_dot(th):
        y = jnp.stack([a, q, th, 0.0, 0.0, 0.0, 0.0])
        return averaged_vector_field(0.0, y, (gyro, prof))[2]

    sim = jax.vmap(theta_dot)(THETA)
    c = Covariates(theta=THETA, amplitude=jnp.asarray(a), quadrature=jnp.asarray(q))
    split = jnp.asarray([dw * np.cos(2 * th_w), dw * np.sin(2 * th_w)])
    term = rate_term("frequency_split", split, c) + rate_term(
        "nonlinearity", jnp.asarray([chi / (4 * omega)]), c
    )
    # First order in q/a: the neglected part is O((q/a)²) relative.
    np.testing.assert_allclose(sim, term, rtol=10 * q**2, atol=1e-12)


def test_readout_terms_match_the_simulated_readout_exactly():
    # A gain mismatch that changes with T plus a cross-talk, read at −20 °C: the two readout
    # terms' mismatch pairs add in the pickoff matrix and the atan form is exact (no O(g²)).
    g0, g1, xt, temp = 3e-3, -1e-4, 1e-3, -20.0
    law = hg.TemperatureLaw(g0, g1, 0.0, 0.0)
    gyro = eqx.tree_at(
        lambda gy: gy.readout, _ideal(), hg.Readout(gain_mismatch=law, cross_talk=xt)
    )
    prof = hg.Profile.constant_rate(5.0, 60.0, temp, wave_angle0_deg=10.0)
    rec = hg.simulate(gyro, prof, dt_out=1.0)
    c = Covariates(theta=rec.true_wave_angle, temperature=temp)
    params = {
        "readout_gain_mismatch": jnp.asarray([-2 * g0, 2 * xt]),  # at +20 °C
        "readout_gain_mismatch_temperature": jnp.asarray([-2 * g1, 0.0]),
    }
    err = rec.wave_angle - rec.true_wave_angle
    np.testing.assert_allclose(err, readout_angle(params, c), rtol=0, atol=1e-12)
    first = readout_term("readout_gain_mismatch", params["readout_gain_mismatch"], c)
    first = first + readout_term(
        "readout_gain_mismatch_temperature", params["readout_gain_mismatch_temperature"], c
    )
    assert np.max(np.abs(err - first)) > 1e-7  # the sum of separate terms is not the matrix
    assert np.max(np.abs(err)) > 0.5 * g0


def test_unknown_or_misused_names_are_refused():
    c = Covariates(theta=THETA)
    with pytest.raises(ValueError, match="not a rate term"):
        rate_term("readout_gain_mismatch", jnp.zeros(2), c)
    with pytest.raises(ValueError, match="not a readout term"):
        readout_term("bias", jnp.zeros(1), c)
    with pytest.raises(ValueError, match="angular_gain"):
        pattern_rate({"bias": jnp.zeros(1)}, c)


def test_user_units_read_as_the_input_rate_each_term_imitates():
    from hrgjax.discovery.result import to_user_units

    k_e = 0.554
    c = Covariates(theta=jnp.asarray(0.3), rate=jnp.asarray(0.0), temperature=jnp.asarray(30.0))
    # a +0.3 °/h bias of input rate is the pattern-rate term b = −k_e·0.3 °/h
    b = float(rate_term("bias", jnp.asarray([-k_e * 0.3 * DEG_PER_H]), c))
    user = to_user_units({"bias": {"b": {"value": b, "std": 0.01 * abs(b)}}}, k_e)["bias"]["b"]
    assert user["unit"] == "°/h"
    assert user["value"] == pytest.approx(0.3) and user["sigma"] == pytest.approx(0.003)
    # b1 of the drift's temperature law: °/h per °C of input rate, at ΔT = 10 °C
    p = jnp.asarray([1e-7, 0.0])
    term = float(rate_term("bias_temperature", p, c))
    u = to_user_units({"bias_temperature": {"b1": {"value": 1e-7}}}, k_e)["bias_temperature"]
    assert u["b1"]["sigma"] is None
    assert -term / k_e / DEG_PER_H == pytest.approx(u["b1"]["value"] * 10.0)
    # scale-factor laws in ppm: Ω_apparent = Ω − term/k_e = Ω·(1 + ppm·1e-6·…)
    omega = 10 * DEG
    c = Covariates(theta=jnp.asarray(0.0), rate=jnp.asarray(omega), temperature=jnp.asarray(30.0))
    for name, pname, p, factor in (
        ("angular_gain_temperature", "kappa_T", 2e-5, 10.0),  # ΔT = 10 °C
        ("rate_scale_factor", "kappa_Omega", 3e-4, 10.0**2),  # Ω² in (°/s)²
    ):
        term = float(rate_term_with_gain(name, jnp.asarray([p]), c, k_e))
        ppm = to_user_units({name: {pname: {"value": p}}}, k_e)[name][pname]["value"]
        assert omega - term / k_e == pytest.approx(omega * (1 + 1e-6 * ppm * factor), rel=1e-12)


def test_leftover_names_a_planted_shape_with_its_size_and_nothing_in_noise():
    from hrgjax.discovery import leftover

    rng = np.random.default_rng(0)
    n, k_e, sigma = 600, 0.554, 1e-7  # window rates [rad/s] and their noise
    theta = rng.uniform(-np.pi, np.pi, n)
    cov = {"theta": theta, "dT": rng.uniform(-40, 40, n), "Tdot": np.zeros(n),
           "rate": np.zeros(n), "accel_z": np.zeros(n), "t_run": np.zeros(n)}  # fmt: skip
    cols = {k: g / sigma for k, g in leftover.columns(cov).items()}
    assert "Ω" not in cols and "dT/dt" not in cols  # shapes the data cannot show are left out
    j = np.ones((n, 1)) / sigma  # the fitted model: a bias
    noise = rng.normal(size=n)
    # 0.4 °/h of input rate as a 3θ harmonic with its axis at 10° el.: pattern rate −k_e·…
    amp, axis = 0.4, np.deg2rad(10.0)
    planted = -k_e * amp * DEG_PER_H * np.cos(3 * (theta - axis)) / sigma
    left = leftover.describe(noise + planted, j, cols, k_e)
    assert left["shape"] == "3θ" and left["significant"]
    assert abs(left["size"] - amp) < 4 * left["sigma"] and left["unit"] == "°/h"
    assert left["axis_deg"] == pytest.approx(10.0, abs=2.0)
    assert "constant over temperature" in left["words"]
    assert not leftover.describe(noise, j, cols, k_e)["significant"]
    # a cubic drift over five temperature levels, the model holding bias, ΔT and ΔT²: named
    # ΔT³, not the ΔT³+ΔT⁴ pair that holds its column and so always scores as high
    levels = rng.choice([-40.0, -20.0, 0.0, 20.0, 40.0], n)
    cols_t = {k: g / sigma for k, g in leftover.columns(dict(cov, dT=levels)).items()}
    j_t = np.stack([np.ones(n), levels, levels**2], axis=1) / sigma
    cubic = -k_e * 5e-6 * DEG_PER_H * levels**3 / sigma  # 5e-6 °/h/°C³ of input rate
    left = leftover.describe(noise + cubic, j_t, cols_t, k_e)
    assert left["shape"] == "ΔT³" and left["significant"], left
    assert abs(left["size"] - 5e-6) < 4 * left["sigma"] and left["unit"] == "°/h/°C³"
    # a loop's lag: a 2θ scale factor growing with the rate, 2 ppm per °/s at two rates, the
    # model holding the 2θ·Ω ripple and a scale factor — named 2θ·Ω² with its size
    rate = np.deg2rad(rng.choice([-20.0, -5.0, 5.0, 20.0], n))
    cols = {k: g / sigma for k, g in leftover.columns(dict(cov, rate=rate)).items()}
    j = np.concatenate([j, cols["2θ·Ω"], cols["Ω"]], axis=1)
    sf = 2e-6 * np.rad2deg(rate) * np.cos(2 * (theta - axis))  # input-rate scale factor
    left = leftover.describe(noise - k_e * sf * rate / sigma, j, cols, k_e)
    assert left["shape"] == "2θ·Ω²" and left["unit"] == "ppm/(°/s)"
    assert abs(left["size"] - 2.0) < 4 * left["sigma"] and "loop's lag" in left["words"]
    assert left["axis_deg"] == pytest.approx(10.0, abs=3.0)


def test_loop_ripple_is_the_closed_loops_ripple_of_the_default_gyro():
    # The preset with only its frequency split left (Δω at θ_ω = 10° el.): the closed loops
    # put a ripple ∝ Ω·cos 2(θ − θ_ω) on the *true* pattern rate whose axis lags as 2k_eΩ
    # nears the loops' bandwidth. The catalogue term, fitted over both directions and three
    # rates, explains ≥ 98 % of it, with the lag at the amplitude loop's 1 rad/s, the axis at
    # 2θ_ω, and a size in proportion to Δω.
    base = hg.presets.tvg3_like(temperature_laws=False, noise=False)
    base = eqx.tree_at(
        lambda g: (g.resonator.delta_inv_tau, g.rate_bias, g.readout.gain_mismatch),
        base,
        (0.0, 0.0, 0.0),
    )
    k_e = float(base.resonator.k_e)

    def ripple(gyro, rates):
        out = []
        for om in rates:
            cycle = 2 * np.pi / (k_e * abs(om) * DEG)  # one turn of 2θ
            rec = hg.simulate(gyro, hg.Profile.constant_rate(om, cycle + 30.0), dt_out=0.2)
            t, th = np.asarray(rec.t), np.asarray(rec.true_wave_angle)
            keep = t > 30.0  # past the loops' settling
            out.append(
                (
                    np.full(keep.sum(), om * DEG),
                    th[keep],
                    (np.gradient(th, t) + k_e * om * DEG)[keep],
                )
            )
        return (np.concatenate(x) for x in zip(*out, strict=True))

    def fit(rate, theta, err):
        c = Covariates(theta=jnp.asarray(theta), rate=jnp.asarray(rate))
        best = None
        for bw in np.arange(0.5, 2.0, 0.02):
            cols = np.stack(
                [np.asarray(rate_term_with_gain("loop_ripple", jnp.asarray([*e, bw]), c, k_e))
                 for e in ((1.0, 0.0), (0.0, 1.0))], axis=1,
            )  # fmt: skip
            coef, *_ = np.linalg.lstsq(cols, err, rcond=None)
            ss = float(np.sum((err - cols @ coef) ** 2))
            best = min(best or (np.inf,), (ss, bw, coef), key=lambda b: b[0])
        return best

    rate, theta, err = ripple(base, (5.0, 20.0, -5.0))
    ss, bw, (r_c, r_s) = fit(rate, theta, err)
    assert ss < 0.02 * np.sum(err**2)  # ≥ 98 % of the ripple
    assert 0.8 < bw < 1.2  # rad/s: the amplitude loop's bandwidth
    axis = np.degrees(np.arctan2(-r_s, -r_c))  # r·cos(2θ − α) with r < 0 here
    assert axis == pytest.approx(2 * 10.0, abs=3.0)
    size = np.hypot(r_c, r_s)
    assert 2e-5 < size < 5e-5  # 3·10⁻⁵ of the rate (benchmarks/README.md)
    doubled = eqx.tree_at(lambda g: g.resonator.delta_omega, base, 2 * base.resonator.delta_omega)

    def share(gyro):  # the ripple's coefficient at 5 °/s on the fitted term's shape
        rate, theta, err = ripple(gyro, (5.0,))
        c = Covariates(theta=jnp.asarray(theta), rate=jnp.asarray(rate))
        model = np.asarray(rate_term_with_gain("loop_ripple", jnp.asarray([r_c, r_s, bw]), c, k_e))
        # besides the ripple, Δω² terms (a constant and a 4θ part, ≤ 2 ppm) grow fourfold
        rest = [np.ones_like(theta), np.cos(4 * theta), np.sin(4 * theta)]
        coef, *_ = np.linalg.lstsq(np.stack([model, *rest], axis=1), err, rcond=None)
        return coef[0]

    assert share(doubled) / share(base) == pytest.approx(2.0, rel=0.01)


def test_equations_print_every_catalogue_effect_with_held_parameters():
    """`Discovery.equations()` writes each accepted effect's formula in user units; a
    parameter the fit held (not regular: `loop_ripple`'s bandwidth in a dwell fit) reads at
    its held value instead of failing."""
    from hrgjax.discovery.effects import CATALOGUE
    from hrgjax.discovery.result import Discovery, tidy_signs

    fitted = {
        name: {p.name: {"value": p.scale, "std": 0.1 * p.scale} for p in e.params if p.regular}
        for name, e in CATALOGUE.items()
    }
    rep = Discovery(
        verdict="found", missing_effect="loop_ripple", accepted=tuple(fitted),
        ambiguous_with=(), discriminate={}, gap_before=1.0, gap_after=0.5, noise_floor=0.5,
        metric="rms", structure_left=False, fit_parameters=fitted, k_e=0.554, ranking=(),
        screening=(), consistency={}, noise={}, split={}, shape="dwell", residuals={},
    )  # fmt: skip
    text = rep.equations()
    for name in CATALOGUE:
        if name != "angular_gain":
            assert f"[{name}]" in text, name
    assert "1 rad/s (held)" in text and "{" not in text
    # negative values: one sign between terms, never '− (-x)' or '+ −x'
    flipped = {n: {k: {"value": -v["value"], "std": v["std"]} for k, v in ps.items()}
               for n, ps in fitted.items()}  # fmt: skip
    for eq in (text, dataclasses.replace(rep, fit_parameters=flipped).equations()):
        assert not re.search(r"[+−] (½·)?\(?[-−]", eq), eq
    # a law the runs cannot tell from a session drift, and a null report's upper limits
    # (disc, session 33): 1σ = 1e-4 °/h/°C of b₁ in model units → |b1| < 1.96e-4 °/h/°C
    note = dataclasses.replace(rep, run_order_confound={"bias_temperature": 0.98}).equations()
    assert "bias_temperature is 98 % the same as a bias drifting steadily" in note
    std = 1e-4 * DEG_PER_H * 0.554  # rad/s/°C of pattern rate
    limits = {"bias_temperature": {"b1": {"value": 0.0, "std": std, "ci95_upper": 1.96 * std}}}
    none = dataclasses.replace(rep, verdict="none", upper_limits=limits)
    assert "bias_temperature: |b1| < 0.0002 °/h/°C" in none.equations()
    assert none.to_json()["upper_limits"]["bias_temperature"]["b1"]["ci95_upper"] == (
        pytest.approx(1.96e-4)
    )
    assert (
        tidy_signs("a − (-0.3 ± 0.1)·x + -2·y + ½·(-4 ± 1)")
        == "a + (0.3 ± 0.1)·x − 2·y − ½·(4 ± 1)"
    )


def test_a_thermal_rate_beside_a_bias_law_names_the_thermometer_lag_it_equals():
    """Audit finding (bench2 F2): a thermometer lagging the gyro by τ = 600 s was named
    `thermal_rate` at 90σ, c = 0.1976 ± 0.0022 °/h per °C/min beside b₁ = 0.01988 °/h/°C —
    c = b₁τ exactly (T = T_read + τṪ_read for a first-order lag, so b₁T = b₁T_read +
    b₁τṪ_read), and the entry named only `thermal_lag`. The entry now names the sensor lag
    and the experiment that separates it, and the report prints c/b₁ in s."""
    from hrgjax.discovery.result import Discovery

    entry = CATALOGUE["thermal_rate"]
    assert "thermometer" in entry.signature and "thermometer" in entry.discriminate
    b1 = 0.01988 * DEG_PER_H  # rad/s/°C
    c = 0.1976 * DEG_PER_H * 60.0  # rad/s per °C/s (0.1976 °/h per °C/min)
    fit = {"bias_temperature": {"b1": {"value": b1}}, "thermal_rate": {"c_Tdot": {"value": c}}}
    lag = Discovery.sensor_lag_s(SimpleNamespace(fit_parameters=fit))
    assert lag == pytest.approx(0.1976 / 0.01988 * 60.0, rel=1e-12)  # 596 s: τ = 600 s
    assert Discovery.sensor_lag_s(SimpleNamespace(fit_parameters={"thermal_rate": {}})) is None


def test_discover_and_noise_model_refuse_bad_settings_in_one_line():
    """Each was a silent verdict or a raw error: alpha 2 or NaN, a negative ΔBIC bar,
    max_effects 0 ("none" without a search), max_aliasing 2, a name string read letter by
    letter ("unknown effect(s) ['a', 'n', …]"), holdout_every 2.5 (a slice error), data
    that is not a MeasuredData; noise_model's max_lag_s NaN reported as "no still stretch".
    The checks come before any fit: a tiny log suffices."""
    from hrgjax.discovery import discover, noise_model

    t = np.arange(4.0)
    data = hg.MeasuredData({"time_s": t, "temperature_c": 0 * t, "table_rate_dps": 0 * t,
                            "wave_angle_deg": 0.01 * t, "run": 0 * t})  # fmt: skip
    for kw, msg in (
        ({"alpha": 2.0}, r"^alpha must be a significance level in \(0, 1\); got 2"),
        ({"alpha": np.nan}, r"^alpha must be a significance level in \(0, 1\); got nan"),
        ({"min_delta_bic": -5.0}, r"^min_delta_bic must be a number >= 0"),
        ({"max_effects": 0}, r"^max_effects must be an integer >= 1; got 0"),
        ({"max_aliasing": 2.0}, r"^max_aliasing must be a share in \(0, 1\]"),
        ({"min_agreement": 1.5}, r"^min_agreement must be a share in \[0, 1\]"),
        ({"holdout_every": 2.5}, r"^holdout_every must be an integer >= 2"),
    ):
        with pytest.raises(ValueError, match=msg):
            discover(data, **kw)
    with pytest.raises(TypeError, match=r"^nominal must be a list of effect names; got 'bias'"):
        discover(data, nominal="bias")
    with pytest.raises(TypeError, match=r"^k_e must be the electrical angular gain"):
        discover(data, k_e="0.554")
    with pytest.raises(TypeError, match=r"^data must be an hrgjax.MeasuredData; got dict"):
        discover({"time_s": t})
    for lag in (np.nan, -1.0, 0.0):
        with pytest.raises(ValueError, match=r"^max_lag_s must be a finite number > 0 \[s\]"):
            noise_model(data, lag)


# -- bad input to the generator, the error bars and the shared statistics: one line each ---

_GENERATOR_CASES = [  # (call on (generate, a key, the base gyro), error, message)
    (lambda g, k, b: g.inject(b, "bias_temperature", np.nan), ValueError,
     r"^inject: size of 'bias_temperature' must be a finite real number"),  # TemperatureLaw.p1
    (lambda g, k, b: g.inject(b, "loop_ripple", np.nan), ValueError,
     r"^inject: size of 'loop_ripple' must be a finite"),  # was a gyro with Δω = NaN
    (lambda g, k, b: g.inject(b, "thermal_rate", "0.1"), TypeError,
     r"^inject: size of 'thermal_rate' must be a single real number; got str"),
    (lambda g, k, b: g.inject(b, 3), TypeError,
     r"^inject: effect must be an effect name, None or a mapping"),  # 'int' not iterable
    (lambda g, k, b: g.inject("gyro", None), TypeError,
     r"^inject: gyro must be an hrgjax.Gyro"),  # returned the string
    (lambda g, k, b: g.hidden_effect_dataset(None, key=0), TypeError,
     r"^hidden_effect_dataset: key must be one JAX PRNG key"),
    (lambda g, k, b: g.hidden_effect_dataset(None, key=k, duration_s=-1.0), ValueError,
     r"^hidden_effect_dataset: duration_s must be a finite number > 0 \[s\]; got -1"),
    (lambda g, k, b: g.hidden_effect_dataset(None, key=k, rates_dps=5.0), ValueError,
     r"^hidden_effect_dataset: rates_dps must be table rates"),  # after the statics' run
    (lambda g, k, b: g.hidden_effect_dataset(None, key=k, rates_dps=(np.nan,)), ValueError,
     r"^plan rate_dps must be finite"),  # after the statics' run
    (lambda g, k, b: g.continuous_dataset(None, key=k, dt_out=0.0), ValueError,
     r"^continuous_dataset: dt_out must be a finite number > 0"),  # ZeroDivisionError
    (lambda g, k, b: g.continuous_dataset(None, key=k, dt_out=-1.0), ValueError,
     r"^continuous_dataset: dt_out must be a finite number > 0"),  # simulated no samples
    (lambda g, k, b: g.continuous_dataset(None, key=k, dt_out=5000.0), ValueError,
     r"^continuous_dataset: dt_out must be <= duration_s"),  # one sample a run
    (lambda g, k, b: g.continuous_dataset(None, key=jax.random.split(k)), ValueError,
     r"^continuous_dataset: key must be one JAX PRNG key.*shape \(2,\)"),
    (lambda g, k, b: g.continuous_dataset(None, key=k, ramps=()), ValueError,
     r"^continuous_dataset: ramps must be rows \(start °C"),  # tree_map's missing argument
    (lambda g, k, b: g.ramp_profiles(3600.0, ((0.0, 10.0, 0.0, 0.0, 0.0),)), ValueError,
     r"^ramp_profiles: each ramp's length \(column 2\) must be > 0 s; got 0"),
    (lambda g, k, b: g.ramp_profiles("3600"), TypeError,
     r"^ramp_profiles: duration_s must be a single real number"),
    (lambda g, k, b: g.bench_log(key=None), TypeError, r"^bench_log: key must be one JAX PRNG"),
]  # fmt: skip


@pytest.mark.parametrize("case", range(len(_GENERATOR_CASES)))
def test_the_generator_refuses_bad_input_before_simulating(monkeypatch, case):
    """Each was a raw error from deep inside (JAX's "invalid PRNG key data", a
    ZeroDivisionError, a gyro law's own NaN check), a silent gyro or dataset, or a refusal
    that came only after the static runs were simulated: now one line naming the function
    and the argument, before any simulation (the simulators are stubbed out to show it)."""
    from hrgjax.discovery import generate

    def simulated(*args, **kwargs):
        raise AssertionError("simulated before the bad input was refused")

    monkeypatch.setattr(generate, "run_plan", simulated)
    monkeypatch.setattr(generate, "_simulate_runs", simulated)
    call, kind, msg = _GENERATOR_CASES[case]
    with pytest.raises(kind, match=msg):
        call(generate, jax.random.key(0), generate.base_gyro(noise=False))


def _toy_fit(r=None, model=("bias", "angular_gain", "damping_anisotropy")):
    """A `Fit` of a linear toy (40 rows, the model's regular columns at random)."""
    from hrgjax.discovery.effects import regular_parameters
    from hrgjax.discovery.problem import Fit

    rng = np.random.default_rng(0)
    labels = regular_parameters(model)
    j, r0 = rng.normal(size=(40, len(labels))), rng.normal(size=40)
    r = r0 if r is None else r
    params = {}
    for name, p in labels:
        params.setdefault(name, {})[p] = {"value": 1.0, "std": 0.1}
    return Fit(tuple(model), params, r, j, 0.0, 0.0, 0.0)


_NAN_R = np.where(np.arange(40) == 3, np.nan, 1.0)
_FITS = [(1, np.ones(1), np.eye(1) * 4.0), (2, np.ones(1), np.eye(1) * 4.0)]
_STATS_CASES = [  # (call on (trust, stats, records, a toy fit), error, message)
    (lambda t, s, rec, f: t.honest(f, {}, None, alpha=1.5), ValueError,
     r"^honest: alpha must be a significance level in \[0, 1\]; got 1.5"),  # every shape fitted
    (lambda t, s, rec, f: t.honest(_toy_fit(_NAN_R), {}, None), ValueError,
     r"^honest: fit.r must be finite; it has nan at index \(3,\)"),  # read as a level of ×1
    (lambda t, s, rec, f: t.honest(f, {"x": np.ones(40)}, None), ValueError,
     r"^honest: shape_columns\['x'\] must be whitened columns, shape \(N, k\)"),
    (lambda t, s, rec, f: t.honest(f, {"x": np.full((40, 1), np.nan)}, None), ValueError,
     r"^honest: shape_columns\['x'\] must be finite"),  # LAPACK's lines, LinAlgError
    (lambda t, s, rec, f: t.honest(f, {}, np.arange(40) % 2 + 0.5), ValueError,
     r"^honest: classes must be whole numbers"),  # one class named "all rows"
    (lambda t, s, rec, f: t.honest(f, {}, None, spread=(-np.ones(4), {"basis": ""})),
     ValueError, r"^honest: spread's factors must be a variance factor >= 0"),  # math domain
    (lambda t, s, rec, f: t.honest(None, {}), TypeError, r"^honest: fit must be a discovery Fit"),
    (lambda t, s, rec, f: t.statistical_p_value(f, "nope", {}), ValueError,
     r"^statistical_p_value: name must be an effect name of the catalogue; got 'nope'"),  # None
    (lambda t, s, rec, f: t.statistical_p_value(f, "bias", {}, descent=0.0), ValueError,
     r"^statistical_p_value: descent must be \+1 or -1"),
    (lambda t, s, rec, f: s.level_test(f.r, f.j, f.j[:-1]), ValueError,
     r"^level_test: g must be whitened columns, shape \(N, k\) with N = 40"),
    (lambda t, s, rec, f: s.class_levels(f.r, f.j, None, weights=np.zeros(40)), ValueError,
     r"^class_levels: weights must be one value per row"),  # LinAlgError
    (lambda t, s, rec, f: s.wls(f.j, f.r, np.zeros(40)), ValueError,
     r"^wls: sigma must be standard errors > 0; got 0"),  # "Eigenvalues did not converge"
    (lambda t, s, rec, f: s.chi2_sf(3.0, -1), ValueError,
     r"^chi2_sf: dof must be a finite number >= 0"),  # NaN
    (lambda t, s, rec, f: s.f_sf(3.0, 2, 0), ValueError,
     r"^f_sf: d2 must be a finite number > 0"),  # p = 0: a silent "significant"
    (lambda t, s, rec, f: s.orthonormal_span(np.full((4, 2), np.nan)), ValueError,
     r"^orthonormal_span: a must be finite"),  # an empty span
    (lambda t, s, rec, f: s.level_beyond(f.r, f.j, np.ones(40)), ValueError,
     r"^level_beyond: s must be whitened columns"),
    (lambda t, s, rec, f: s.follows_covariate(f.r, f.j, 1.5), ValueError,
     r"^follows_covariate: alpha must be a significance level in \[0, 1\]"),
    (lambda t, s, rec, f: rec.repeats(_FITS, [1.0], level=(-1.0, 10)), ValueError,
     r"^repeats: level must be \(s², ν\) with s² >= 0"),
    (lambda t, s, rec, f: rec.repeats(_FITS, [1.0], resolves=-1.0), ValueError,
     r"^repeats: resolves must be a finite number >= 0"),  # read as +1
    (lambda t, s, rec, f: rec.repeats(_FITS, [1.0, 2.0]), ValueError,
     r"^repeats: each of fits must be \(run, estimate \(2,\)"),
    (lambda t, s, rec, f: rec.block_index(10, 0), ValueError,
     r"^block_index: m must be an integer >= 1; got 0"),  # ZeroDivisionError
    (lambda t, s, rec, f: rec.rate_columns([], parts=0), ValueError,
     r"^rate_columns: parts must be an integer >= 1"),
    (lambda t, s, rec, f: rec.Layout(["bias", "nope"]), ValueError,
     r"^Layout: names must be a list of effect names; got .*'bias', 'nope'"),  # KeyError
    (lambda t, s, rec, f: rec.Layout(["angular_gain"]).null(np.nan), ValueError,
     r"^Layout.null: k_e must be finite"),
]  # fmt: skip


@pytest.mark.parametrize("case", range(len(_STATS_CASES)))
def test_error_bars_and_statistics_refuse_bad_input_in_one_line(case):
    """Each was a silent answer (a NaN residual read as the noise model's level, alpha 1.5
    fitting every leftover shape, an unknown effect's p-value None, F(2, 0)'s tail 0) or a
    raw NumPy/LAPACK error: now one line naming the function, the argument and its form."""
    from hrgjax.discovery import records, stats, trust

    call, kind, msg = _STATS_CASES[case]
    with pytest.raises(kind, match=msg):
        call(trust, stats, records, _toy_fit())


def test_edge_values_the_statistics_take_as_before():
    """Review of the checks above: what they refused but the code had taken (and means
    something) is taken again — a level of −1e-19 that `level_beyond` itself returns for a
    residual inside the columns' span, a generator of names (read once: `Layout` was empty),
    α of exactly 0 or 1, a boolean mask of two classes, a 1-D shape column of another length
    (not the training rows': not read, as the docstring says), a NaN χ² (NaN: not
    significant, as the search reads it)."""
    from hrgjax.discovery import records, stats, trust

    a, s = np.eye(6)[:, :4], np.eye(6)[:, 4:]
    level = stats.level_beyond(a @ np.arange(1.0, 5.0) * 1e-3, a, s)
    assert level[1] == 2 and abs(level[0]) < 1e-15
    assert records.repeats(_FITS, [1.0], level=(-9e-20, 3))["p_value"] == 1.0
    assert records.Layout(n for n in ["bias", "angular_gain"]).names == ("bias", "angular_gain")
    f = _toy_fit()
    assert trust.honest(f, {}, None, alpha=0.0) is not None
    mask = np.arange(40) % 2 == 0
    assert trust.honest(f, {"x": np.ones(7)}, mask) == trust.honest(f, {}, mask.astype(int))
    assert np.isnan(stats.chi2_sf(np.nan, 3))
