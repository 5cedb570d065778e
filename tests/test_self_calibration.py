"""Self-calibration without a turntable (hrgjax.calibration.self_calibration): the sweeps'
least squares against a known answer, the compensator against the gyro's own static drift,
its gradient against finite differences, and mode reversal."""

import json

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import cli_fails

import hrgjax as hg
from hrgjax.calibration import self_calibration as sc
from hrgjax.units import DEG, DEG_PER_H, DEG_PER_S

BASE = hg.presets.tvg3_like(temperature_laws=False, noise=False)


def _integrate(s, d, rho, theta0, t):
    """θ(t) of θ̇ = S(θ)ρ + D(θ) by RK4 on a 20× finer grid (a second method)."""
    c = rho * s + d
    f = lambda th: c[0] + c[1] * np.cos(2 * th) + c[2] * np.sin(2 * th) + c[3] * np.cos(
        4 * th) + c[4] * np.sin(4 * th)  # fmt: skip
    out, th = [theta0], theta0
    for a, b in zip(t[:-1], t[1:], strict=True):
        h = (b - a) / 20
        for _ in range(20):
            k1 = f(th)
            k2 = f(th + 0.5 * h * k1)
            k3 = f(th + 0.5 * h * k2)
            k4 = f(th + h * k3)
            th = th + h * (k1 + 2 * k2 + 2 * k3 + k4) / 6
        out.append(th)
    return np.asarray(out)


def test_fit_sweeps_recovers_a_known_gain_and_drift():
    """Two sweeps ±ρ of θ̇ = S(θ)ρ + D(θ) integrated independently: the coefficients come
    back to 1e-7 of S and 1e-5 of D's peak (the path's curvature within a step), whatever the start angles and offsets."""
    s = np.array([1.01, -0.01, 0.004, 0.001, -0.0005])
    d = np.array([2e-6, 1e-6, -3e-6, 5e-7, 2e-7])  # rad/s: the drift at rest
    rho = 1.0 * DEG_PER_S
    t = np.arange(0.0, 200.0, 1.0)
    up = _integrate(s, d, rho, -1.6, t)
    down = _integrate(s, d, -rho, 1.7, t)
    used = np.ones((2, t.size))
    used[:, :5] = 0.0  # the settling left out
    fit_s, fit_d = sc.fit_sweeps(jnp.asarray(np.stack([t, t])), jnp.asarray(np.stack([up, down])),
                                 jnp.asarray(np.array([[rho], [-rho]]) * np.ones(t.size)),
                                 jnp.asarray(used))  # fmt: skip
    np.testing.assert_allclose(np.asarray(fit_s), s, atol=1e-7)
    np.testing.assert_allclose(np.asarray(fit_d), d, atol=1e-5 * np.max(np.abs(d)))


@pytest.fixture(scope="module")
def sweeps():
    plan = sc.precession_plan((20.0,), precession_dps=1.0, settle_s=15.0)
    return sc.run_precession_plan(BASE, plan)


def test_self_calibration_reads_the_gyros_static_drift(sweeps):
    """Sweeps at rest, the default gyro's defects: the compensator's drift at every angle
    equals what a static whole-angle run at that angle reads (−θ̂̇/k_e,nom over its first
    20 s), to 1 % of the drift's peak-to-peak (what is left grows as ρ²: 0.54 % at 1 °/s,
    0.13 % at the default 0.5 °/s — a term even in ρ lands in the drift)."""
    comp = sc.PrecessionCompensator().fit(sweeps)
    assert comp.temperatures_c == (20.0,)
    assert "precession_dps" in sweeps and np.all(np.abs(sweeps["precession_dps"]) == 1.0)
    angles = np.arange(-90.0, 90.0, 15.0)

    def static(theta):
        p = eqx.tree_at(lambda p: p.wave_angle0, hg.Profile.static(40.0), theta)
        return hg.simulate(BASE, p, dt_out=1.0).wave_angle

    wave = np.asarray(jax.vmap(static)(jnp.asarray(angles * DEG)))
    truth = -(wave[:, 40] - wave[:, 20]) / 20.0 / comp.k_e
    got = comp.drift_dph(wave[:, 30] / DEG, 20.0) * DEG_PER_H
    assert np.max(np.abs(got - truth)) < 0.01 * np.ptp(truth), (got / DEG_PER_H, truth / DEG_PER_H)
    # the gain S: the readout's scale factor 1 − 2g cos 2θ times the true over the estimated
    # amplitude the AGC holds, 1 + g cos 2θ (g = 0.46 % at 20 °C; forcers ideal): 1 − g cos 2θ
    g = float(BASE.readout.gain_mismatch)
    np.testing.assert_allclose(np.asarray(comp.gain_coef[0, :3]), [1.0, -g, 0.0], atol=1e-4)
    np.testing.assert_allclose(comp.readout_gain_mismatch, [g], rtol=0.02)
    np.testing.assert_array_equal(comp.scale_factor_at(angles, 20.0), 1.0)


def test_precession_in_the_wrong_unit_is_refused(sweeps):
    """A `precession_dps` column in rad/s fitted S₀ = 180/π and g 57× too large, silently:
    the fit refuses a constant gain S₀ further than `GAIN_TOLERANCE` from 1, naming the
    column and the unit it looks like."""
    for factor, hint in ((DEG, "looks like rad/s"), (1 / DEG, "57.3× too large"),
                         (-1.0, "unit .* and sign")):  # fmt: skip
        bad = hg.MeasuredData(sweeps.columns | {"precession_dps": sweeps["precession_dps"] * factor},
                              allow_extra=True)  # fmt: skip
        with pytest.raises(ValueError, match=f"precession_dps: at 20 °C .*S₀ = .*{hint}"):
            sc.PrecessionCompensator().fit(bad)


def test_sweeps_take_earths_rate_as_rest_as_mode_reversal_does(sweeps):
    """Audit (s33): a bench above 14° latitude reads Earth's vertical rate (10.6 °/h at 45°)
    beyond `STILL_RATE_DPS`; mode reversal took it, the sweeps refused it ("the table
    turns"). Now one rule (`_sweeps.at_rest`): a constant rate no larger than Earth's is
    rest (the sweeps' fit reads the wave, so the same compensator), and a rate that varies
    or exceeds Earth's is refused."""
    base = sc.PrecessionCompensator().fit(sweeps)
    earth = 10.6 / 3600.0 * np.ones_like(sweeps["table_rate_dps"])
    comp = sc.PrecessionCompensator().fit(sweeps.with_column("table_rate_dps", earth))
    np.testing.assert_array_equal(comp.drift_coef, base.drift_coef)
    for rate in (earth + 1e-6 * np.sin(sweeps["time_s"]), 1.2 * sc.EARTH_RATE_DPS + 0 * earth):
        with pytest.raises(ValueError, match=r"^run \d+: the table turns .* or constant and no "
                           r"larger than Earth's"):  # fmt: skip
            sc.PrecessionCompensator().fit(sweeps.with_column("table_rate_dps", rate))


def test_sweeps_in_force_to_rebalance_mode_are_refused(sweeps):
    """Audit: an FTR gyro given a precession plan holds the wave where the commanded
    precession puts it, and the fit found S = 1, D = 0 (a confident "no drift" where the
    truth was ±3 °/h). Data with a `rebalance_rate_dps` column and the loop on are refused;
    with `rebalance_on` 0 throughout (the loop off: whole-angle data) they fit as before."""
    n = len(sweeps["time_s"])
    held = sweeps.columns | {"rebalance_rate_dps": np.zeros(n)}
    with pytest.raises(ValueError, match=r"^self-calibration reads whole-angle sweeps; .*held"):
        sc.PrecessionCompensator().fit(hg.MeasuredData(held))
    on = held | {"rebalance_on": np.r_[np.zeros(n - 1), 1.0]}
    with pytest.raises(ValueError, match=r"force-to-rebalance output"):
        sc.PrecessionCompensator().fit(hg.MeasuredData(on))
    off = hg.MeasuredData(held | {"rebalance_on": np.zeros(n)})
    np.testing.assert_array_equal(
        sc.PrecessionCompensator().fit(off).drift_coef,
        sc.PrecessionCompensator().fit(sweeps).drift_coef,
    )


def test_readout_gain_mismatch_is_free_of_the_forcers_common_gain(sweeps):
    """A common forcer gain g_f scales the whole gain S = (1 + g_f)(1 − g cos 2θ) (a
    simulated forcer_gain of 5 % read S₀ = 1.05, −S₁ = 1.056 g, −S₁/S₀ = g to 3e-4): the
    recorded command ρ/(1 + g_f) for a wave turned at ρ is the same fit. g = −S₁/S₀; −S₁
    alone was 5 % off."""
    g_f = 0.05
    cols = sweeps.columns | {"precession_dps": sweeps["precession_dps"] / (1 + g_f)}
    comp = sc.PrecessionCompensator().fit(hg.MeasuredData(cols, allow_extra=True))
    np.testing.assert_allclose(np.asarray(comp.gain_coef[:, 0]), 1 + g_f, rtol=1e-4)
    np.testing.assert_allclose(comp.readout_gain_mismatch, [float(BASE.readout.gain_mismatch)],
                               rtol=0.02)  # fmt: skip


def _sweep_jacobian(mode):
    """d(fitted 2θ drift coefficients)/d(Δ(1/τ), θ_τ) through the simulated sweeps and the
    least squares (`mode` "forward" or "reverse"), and central finite differences."""
    plan = sc.precession_plan((20.0,), precession_dps=3.0, settle_s=10.0, dt_out=1.0)
    profiles = plan.profiles()
    ts = jnp.arange(0.0, plan.duration_s + 0.5, 1.0)
    used = (ts >= 10.0).astype(float)[None, :] * jnp.ones((2, 1))
    rho = jnp.asarray(np.asarray(plan.precession_dps)[:, None] * DEG_PER_S) * jnp.ones_like(used)
    options = dict(ts=ts, fixed_step=0.5)
    if mode == "forward":
        options["adjoint"] = diffrax.ForwardMode()

    def estimate(params):
        gyro = eqx.tree_at(lambda g: (g.resonator.delta_inv_tau, g.resonator.theta_tau),
                           BASE, (params[0] * 1e-5, params[1]))  # fmt: skip
        rec = jax.vmap(lambda p: hg.simulate(gyro, p, **options))(profiles)
        _, d = sc.fit_sweeps(rec.t, rec.wave_angle, rho, used)
        return jnp.stack([d[1], d[2]]) * 1e6  # the 2θ terms of the drift [µrad/s]

    x = jnp.array([float(BASE.resonator.delta_inv_tau) * 1e5, float(BASE.resonator.theta_tau)])
    jac = np.asarray(jax.jit((jax.jacfwd if mode == "forward" else jax.jacrev)(estimate))(x))
    estimate = jax.jit(estimate)
    fd = np.zeros_like(jac)
    h = 1e-4
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        fd[:, j] = (np.asarray(estimate(x + e)) - np.asarray(estimate(x - e))) / (2 * h)
    return jac, fd


def test_self_calibration_estimate_is_differentiable_in_the_gyros_defects():
    """The self-calibration's drift estimate, differentiated through the simulated sweeps
    and the least squares (forward mode), equals central finite differences to 1e-6."""
    jac, fd = _sweep_jacobian("forward")
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(fd)))


@pytest.mark.slow(
    "~50 s on two cores: the reverse pass through the checkpointed sweeps compiled; fast "
    "tier: the same Jacobian by forward mode (test_self_calibration_estimate_is_"
    "differentiable_in_the_gyros_defects)"
)
def test_self_calibration_gradient_by_reverse_mode():
    """As above, by reverse mode (the recursive-checkpoint adjoint): equals finite
    differences to 1e-6."""
    jac, fd = _sweep_jacobian("reverse")
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-6 * np.max(np.abs(fd)))


def test_mode_reversal_reduces_a_held_angle_run():
    """Held at θ and at θ + 90° (electrical), the damping anisotropy's bias changes sign and
    the rate bias does not: `mode_reversal`'s bias (the mean of the two readings) is the rate
    bias and its anisotropy (half their difference) the drift law of PHYSICS.md §4.1, to
    1e-6 of the drift; the slew between the holds (a commanded precession) lands on 130°."""
    bias = 0.3 * DEG_PER_H
    ctl = hg.Control(mode="ftr", drive="force")
    gyro = hg.Gyro(resonator=BASE.resonator, control=ctl, rate_bias=bias)
    prof = hg.Profile.held_angles([40.0, 130.0], dwell_s=60.0, slew_s=10.0)
    rec = hg.simulate(gyro, prof, dt_out=1.0, rtol=1e-10, atol=1e-12)
    # the reading is scaled by ω/ω_r (the Duffing pull on the PLL, 2e-6): taken out here
    out = sc.mode_reversal(rec.t, rec.rebalance_rate * rec.frequency / BASE.resonator.omega, prof)
    res = BASE.resonator
    law = -0.5 * res.delta_inv_tau * np.sin(2 * (40.0 * DEG - res.theta_tau)) / res.k_e
    assert out.angles_deg == (40.0, 130.0)
    assert abs(float(out.bias) - bias) < 1e-6 * abs(law)
    assert abs(float(out.anisotropy) - law) < 1e-6 * abs(law)
    assert abs(float(rec.wave_angle[-1]) - 130.0 * DEG) < 1e-9
    # the same from the data, the holds found in the samples (the ramps' corners fall
    # between them: 2.5-s ramps, 1-s samples)
    row = sc.mode_reversal_data(rec.to_data())[0]
    assert row["angles_deg"] == pytest.approx([40.0, 130.0], abs=1e-6)
    assert abs(row["anisotropy_dph"] * DEG_PER_H - law) < 1e-4 * abs(law)


def test_mode_reversal_warns_of_a_settle_shorter_than_the_loops_transient():
    """Audit: `settle_s = 0` was taken silently, and the rebalance loop's transient after the
    slew went into the reading. With 2 % forcer gain error a 10-s slew lands 2 % off and the
    loop pulls the wave back: at settle_s = 0 the anisotropy read 2.4× its law off; both
    reductions now warn below MIN_SETTLE_S (10 s), where the readings are the FTR law —
    (rate bias − b)/(1 + g_f), b the anisotropy's bias — to 1e-5 of it (the program of
    test_mode_reversal_reduces_a_held_angle_run, one compile)."""
    bias, gf, res = 0.3 * DEG_PER_H, 0.02, BASE.resonator
    ctl = hg.Control(mode="ftr", drive="force", forcer_gain=gf)
    gyro = hg.Gyro(resonator=res, control=ctl, rate_bias=bias)
    prof = hg.Profile.held_angles([40.0, 130.0], dwell_s=60.0, slew_s=10.0)
    rec = hg.simulate(gyro, prof, dt_out=1.0, rtol=1e-10, atol=1e-12)
    rate = rec.rebalance_rate * rec.frequency / res.omega
    law = -0.5 * res.delta_inv_tau * np.sin(2 * (40.0 * DEG - res.theta_tau)) / res.k_e
    with pytest.warns(sc.ShortSettleWarning, match=r"^mode_reversal: settle_s = 0 s is shorter "
                      r"than MIN_SETTLE_S = 10 s: the rebalance loop's transient"):  # fmt: skip
        short = sc.mode_reversal(rec.t, rate, prof, settle_s=0.0)
    assert abs(float(short.anisotropy) * (1 + gf) - law) > 1.0 * abs(law)
    out = sc.mode_reversal(rec.t, rate, prof, settle_s=sc.MIN_SETTLE_S)  # no warning
    assert abs(float(out.bias) * (1 + gf) - bias) < 1e-5 * abs(law)
    assert abs(float(out.anisotropy) * (1 + gf) - law) < 1e-5 * abs(law)
    with pytest.warns(sc.ShortSettleWarning, match=r"^mode_reversal_data: settle_s = 3 s"):
        sc.mode_reversal_data(rec.to_data(), settle_s=3.0)


def test_compensator_interpolates_in_temperature_for_any_shapes():
    """Between calibrated temperatures the drift is linear in T, held beyond; θ and T
    broadcast (a vector of angles at one temperature, one angle at many)."""
    d = jnp.array([[1e-6, 2e-6, 0.0, 0.0, 0.0], [3e-6, -2e-6, 0.0, 0.0, 0.0]])
    comp = eqx.tree_at(lambda c: (c.drift_coef, c.gain_coef),
                       sc.PrecessionCompensator(temperatures_c=(0.0, 40.0)), (d, d),
                       is_leaf=lambda x: x is None)  # fmt: skip
    theta = jnp.array([0.0, 0.3, 0.9])
    at10 = comp.drift(theta, 10.0)
    expected = 0.75 * (1e-6 + 2e-6 * jnp.cos(2 * theta)) + 0.25 * (3e-6 - 2e-6 * jnp.cos(2 * theta))
    np.testing.assert_allclose(np.asarray(at10), np.asarray(expected), rtol=1e-12)
    temps = jnp.array([-20.0, 0.0, 20.0, 60.0])
    one = comp.drift(0.0, temps)
    np.testing.assert_allclose(np.asarray(one), [3e-6, 3e-6, 2e-6, 1e-6], rtol=1e-12)
    assert comp.scale_factor(theta, 10.0).shape == (3,)


def test_self_calibration_inputs_are_named():
    with pytest.raises(ValueError, match="precession_dps must be a positive"):
        sc.precession_plan(precession_dps=0.0)
    with pytest.raises(ValueError, match="turns must be"):
        sc.precession_plan(turns=0)
    data = hg.MeasuredData({"time_s": np.arange(5.0), "temperature_c": np.full(5, 20.0),
                            "table_rate_dps": np.zeros(5), "wave_angle_deg": np.zeros(5)})  # fmt: skip
    with pytest.raises(ValueError, match="needs virtual-precession data"):
        sc.PrecessionCompensator().fit(data)
    n = 25  # a sweep keeps ≥ 20 samples (checked first), in one direction
    one_way = hg.MeasuredData({"time_s": np.arange(float(n)), "temperature_c": np.full(n, 20.0),
                               "table_rate_dps": np.zeros(n), "wave_angle_deg": np.arange(n) * 1.0,
                               "precession_dps": np.full(n, 1.0)})  # fmt: skip
    with pytest.raises(ValueError, match="one way only"):
        sc.PrecessionCompensator(settle_s=0.0).fit(one_way)
    with pytest.raises(ValueError, match="two holds"):
        sc.mode_reversal(np.arange(3.0), np.zeros(3), hg.Profile.static(2.0))
    with pytest.raises(ValueError, match="90° apart"):
        sc.mode_reversal(np.arange(3.0), np.zeros(3), hg.Profile.held_angles([0.0, 60.0], 60.0))
    with pytest.raises(ValueError, match="not fitted"):
        from hrgjax.calibration import save_compensator

        save_compensator(sc.PrecessionCompensator(), "/nonexistent/x.eqx")
    paused = hg.MeasuredData(data.columns | {"precession_dps": np.array([1.0, 1, 0, 1, 1])})
    with pytest.raises(ValueError, match="pauses"):
        sc.PrecessionCompensator(settle_s=0.0).fit(paused)
    with pytest.raises(ValueError, match="force-to-rebalance output"):
        from hrgjax.calibration import reduce

        reduce(hg.MeasuredData(data.columns | {"rebalance_rate_dps": np.zeros(5)}))


def test_self_calibrate_command_fits_sweeps_and_reduces_holds(sweeps, tmp_path, capsys):
    """`hrgjax self-calibrate` on sweeps writes the compensator the Python fit gives (and
    `correct` reads it, on whole-angle data at rest); on FTR holds (`simulate --mode ftr --plan reversal`) it prints and
    writes the bias and anisotropy; either with the wrong data is one clear line. Each
    value is printed ± its 1σ (s34), "n/a" from the one ±ρ pair (NaN, saved as NaN)."""
    from hrgjax.calibration import load_compensator
    from hrgjax.cli import main

    path = sweeps.save(tmp_path / "sweeps.csv")
    model = tmp_path / "self.eqx"
    assert main(["self-calibrate", str(path), "--out", str(model), "--settle", "15"]) == 0
    comp = load_compensator(model)
    direct = sc.PrecessionCompensator(settle_s=15.0).fit(hg.load(path))
    np.testing.assert_allclose(np.asarray(comp.drift_coef), np.asarray(direct.drift_coef))
    assert comp.drift_std.shape == direct.drift_std.shape and np.all(np.isnan(comp.drift_std))
    text = capsys.readouterr().out
    assert "virtual-precession sweeps at [20.0] °C" in text
    assert f"{float(direct.drift_coef[0, 0]) / DEG_PER_H:+10.4f} ± n/a" in text
    assert "± n/a (fewer than 6 sweeps: give a noise model" in text
    static = hg.simulate(BASE, hg.Profile.static(30.0, 20.0, 10.0), dt_out=1.0).to_data()
    still = static.save(tmp_path / "static.csv")  # sweeps themselves are refused (below)
    assert main(["correct", str(still), "--model", str(model), "--out",
                 str(tmp_path / "c.csv")]) == 0  # fmt: skip
    from hrgjax.calibration import load_json

    back = load_json(tmp_path / "self.json")  # the JSON export round trip
    assert back.temperatures_c == comp.temperatures_c
    np.testing.assert_array_equal(np.asarray(back.gain_coef), np.asarray(comp.gain_coef))
    np.testing.assert_array_equal(np.asarray(back.gain_std), np.asarray(comp.gain_std))  # null
    theta = np.linspace(-90.0, 90.0, 7)
    np.testing.assert_array_equal(back.drift_dph(theta, 20.0), comp.drift_dph(theta, 20.0))

    holds = sc.run_reversal_plan(BASE.in_mode("ftr"), (20.0,), 10.0, dwell_s=60.3)
    rev = holds.save(tmp_path / "rev.csv")
    table = tmp_path / "rev.json"
    capsys.readouterr()
    assert main(["self-calibrate", str(rev), "--json", str(table), "--settle", "20"]) == 0
    row = json.loads(table.read_text())["mode_reversal"][0]
    text = capsys.readouterr().out
    for k in ("bias", "anisotropy"):  # noise-free: σ ~0, printed beside the value
        assert f"{row[k + '_dph']:+10.5f} ± {row[k + '_std_dph']:.5f}" in text
    res = BASE.resonator
    law = -0.5 * res.delta_inv_tau * np.sin(2 * (10.0 * DEG - res.theta_tau)) / res.k_e
    assert abs(row["anisotropy_dph"] * DEG_PER_H - law) < 0.02 * abs(law)  # readout, 0.5 %
    assert row["angles_deg"] == pytest.approx([10.0, 100.0], abs=0.01)

    cli_fails(["simulate", "--plan", "reversal", "--quick", "--out", str(tmp_path / "x.csv")],
              capsys, "add --mode ftr")  # fmt: skip
    plain = tmp_path / "plain.csv"
    hg.MeasuredData({c: sweeps[c] for c in ("time_s", "run", "temperature_c", "table_rate_dps",
                                            "wave_angle_deg")}).save(plain)  # fmt: skip
    cli_fails(["self-calibrate", str(plain), "--out", str(model), "--force"], capsys,
              "needs virtual-precession data")  # fmt: skip


@pytest.fixture(scope="module")
def reversal_at_minus_45():
    """Noise-free FTR holds at −45° and +45° (electrical), the case at rest."""
    prof = hg.Profile.held_angles([-45.0, 45.0], dwell_s=90.0, slew_s=20.0)
    return prof, hg.simulate(BASE.in_mode("ftr"), prof, dt_out=1.0)


def test_mode_reversal_anisotropy_is_the_bias_as_read_on_the_output(
    reversal_at_minus_45, tmp_path, capsys
):
    """Half the difference of the two readings SF·(Ω − b) is −b: the anisotropy is the
    damping anisotropy's bias as it shows on the output, −½Δ(1/τ)sin2(θ−θ_τ)/k_e (the
    compensators' drift convention), to the readout's 1 %; at −45° it is positive. The
    CLI's column says which it is."""
    from hrgjax.cli import main

    prof, rec = reversal_at_minus_45
    out = sc.mode_reversal(rec.t, rec.rebalance_rate, prof, settle_s=30.0)
    res = BASE.resonator
    law = -0.5 * res.delta_inv_tau * np.sin(2 * (-45.0 * DEG - res.theta_tau)) / res.k_e
    assert law > 0 and float(out.anisotropy) > 0
    assert abs(float(out.anisotropy) - law) < 0.01 * abs(law)
    assert "as it shows on the output" in " ".join(sc.ModeReversal.__doc__.split())
    path = rec.to_data().save(tmp_path / "rev.csv")
    capsys.readouterr()
    assert main(["self-calibrate", str(path), "--settle", "30"]) == 0
    text = capsys.readouterr().out
    assert "anisotropy at the first, as read (−½Δ(1/τ)sin2(θ−θτ)/k_e)" in text
    row = sc.mode_reversal_data(rec.to_data(), settle_s=30.0)[0]
    assert abs(row["anisotropy_dph"] * DEG_PER_H - law) < 0.01 * abs(law)


def test_mode_reversal_refuses_a_turning_case():
    """With an input rate the FTR scale factor (a/â ≈ 1 − g cos 2θ) reads it differently at
    the two holds, so it does not cancel (36 °/h put a third of the anisotropy off): both
    reductions refuse a case turning faster than STILL_RATE_DPS, naming the rate."""
    from hrgjax.pattern_noise import STILL_RATE_DPS

    # the fixture's dwells and slew: the simulation below is its program
    turning = hg.Profile.held_angles([0.0, 90.0], dwell_s=90.0, slew_s=20.0, rate_dps=0.01)
    with pytest.raises(ValueError, match=r"case at rest .*profile's rate reaches 0\.01 °/s"):
        sc.mode_reversal(np.arange(201.0), np.zeros(201), turning)
    slow = hg.Profile.held_angles([0.0, 90.0], dwell_s=60.0, slew_s=10.0,
                                  rate_dps=0.5 * STILL_RATE_DPS)  # fmt: skip
    sc.mode_reversal(np.arange(131.0), np.zeros(131), slow)  # readback jitter is rest
    rec = hg.simulate(BASE.in_mode("ftr"), turning, dt_out=1.0)
    with pytest.raises(ValueError, match=r"run 0's table_rate_dps reaches 0\.01 °/s"):
        sc.mode_reversal_data(rec.to_data())


def test_mode_reversal_refuses_a_hold_without_samples():
    """Audit: a hold with no output time inside [start + settle_s, end] (dt_out = 200 s on
    120-s dwells, or a record starting late) gave a NaN reading, bias and anisotropy with no
    word. It is refused in one line naming the hold's angle and window and what to change,
    for a batch too (any member without samples); a t traced under jit is not judged."""
    prof = hg.Profile.held_angles([70.0, 160.0], dwell_s=120.0, slew_s=20.0)  # holds 0-120, 140-260
    hold = r"^mode_reversal: no sample of t in the hold at {} \({} s, after settle_s = 30 s\): "
    with pytest.raises(ValueError, match=hold.format("70°", "30 … 120") + "give output times"):
        sc.mode_reversal(np.array([0.0, 200.0]), np.zeros(2), prof, settle_s=30.0)
    late = np.arange(150.0, 261.0)
    with pytest.raises(ValueError, match=hold.format("70°", "30 … 120") + ".* a shorter settle_s"):
        sc.mode_reversal(late, np.zeros(late.size), prof, settle_s=30.0)
    early = np.stack([np.arange(261.0), np.minimum(np.arange(261.0), 150.0)])  # 2nd: no 2nd hold
    with pytest.raises(ValueError, match=hold.format("160°", "170 … 260")):
        sc.mode_reversal(early, np.zeros(early.shape), prof, settle_s=30.0)
    t = np.arange(261.0)
    rate = jnp.where(t < 130.0, 2e-6, -2e-6)
    out = jax.jit(lambda t: sc.mode_reversal(t, rate, prof, settle_s=30.0).anisotropy)(t)
    assert float(out) == pytest.approx(2e-6, rel=1e-12)


def test_mode_reversal_takes_earths_rate_in_the_bias(reversal_at_minus_45):
    """Audit: a bench on the Earth (Ω_E sin φ = 10.6 °/h at 45°, above STILL_RATE_DPS's 3.6 °/h)
    was refused. A rate constant over the run and no larger than Earth's passes: it enters
    the bias reading (+Ω_E sin φ to 1e-4 of it, against the run at rest) and, through the
    pickoff gain mismatch g, the anisotropy as −g cos 2θ·Ω (none at ±45°; at 0° to 1e-4 of
    it). Above Earth's rate, or varying, the case turns: refused, as mode_reversal_data."""
    from hrgjax.units import EARTH_RATE

    earth = EARTH_RATE * np.sin(np.radians(45.0)) / DEG_PER_S  # °/s
    ftr, g = BASE.in_mode("ftr"), float(BASE.readout.gain_mismatch)

    def reversal(angles, rate_dps):  # the fixture's program
        prof = hg.Profile.held_angles(angles, dwell_s=90.0, slew_s=20.0, rate_dps=rate_dps)
        rec = hg.simulate(ftr, prof, dt_out=1.0)
        return rec, sc.mode_reversal(rec.t, rec.rebalance_rate, prof, settle_s=30.0)

    prof, rest = reversal_at_minus_45
    at_rest = sc.mode_reversal(rest.t, rest.rebalance_rate, prof, settle_s=30.0)
    rec, out = reversal([-45.0, 45.0], earth)
    assert float(out.bias - at_rest.bias) == pytest.approx(earth * DEG_PER_S, rel=1e-4)
    assert abs(float(out.anisotropy - at_rest.anisotropy)) < 1e-6 * earth * DEG_PER_S
    row = sc.mode_reversal_data(rec.to_data(), settle_s=30.0)[0]
    assert row["bias_dph"] * DEG_PER_H == pytest.approx(float(out.bias), rel=1e-3)
    (_, zero), (_, turned) = reversal([0.0, 90.0], 0.0), reversal([0.0, 90.0], earth)
    shift = float(turned.anisotropy - zero.anisotropy)
    assert shift == pytest.approx(-g * earth * DEG_PER_S, rel=1e-4)  # −g cos 2θ·Ω at 0°
    t, zeros = np.arange(201.0), np.zeros(201)
    above = hg.Profile.held_angles([0.0, 90.0], 90.0, 20.0, rate_dps=1.01 * EARTH_RATE / DEG_PER_S)
    with pytest.raises(ValueError, match=r"case at rest .* no larger than Earth's, 0\.004178 °/s\);"
                       r" the profile's rate reaches 0\.00421985 °/s:"):  # fmt: skip
        sc.mode_reversal(t, zeros, above)
    varying = (earth + np.linspace(0.0, 1e-5, prof.t.size)) * DEG_PER_S  # within Earth's
    with pytest.raises(ValueError, match=r"the profile's rate reaches .* and varies by 1e-05 °/s"):
        sc.mode_reversal(t, zeros, eqx.tree_at(lambda p: p.rate, prof, varying))


def test_mode_reversal_sweeps_over_temperature_and_refuses_traced_angles():
    """Audit: `mode_reversal` under jit or hg.sweep over the temperature raised a 28-line
    ConcretizationTypeError (the turn between the holds read with float() from the traced
    program). It reads the knots' concrete values: jit and the sweep equal the eager values,
    and a second temperature compiles nothing. Traced held angles (the holds are found
    where the precession is 0) are refused in one line (an eager grad carries their values)."""
    from helpers import CompileCounter

    t = np.arange(0.0, 221.0)
    first = t < 110.0  # the first hold (and the slew): 100-s dwells, a 20-s slew

    def reduce(temp):
        prof = hg.Profile.held_angles([10.0, 100.0], 100.0, 20.0, temp)
        rate = 1e-5 * (1.0 + temp) + jnp.where(first, 2e-6, -2e-6) * jnp.cos(temp / 30.0)
        out = sc.mode_reversal(t, rate, prof, settle_s=30.0)
        return out.bias, out.anisotropy

    temps = (0.0, 40.0)
    eager = np.array([reduce(temp) for temp in temps])
    run = jax.jit(reduce)
    run(temps[0])
    with CompileCounter() as count:
        second = run(temps[1])
    assert count.compiles == 0
    np.testing.assert_allclose([run(temps[0]), second], eager, rtol=1e-13)
    swept = hg.sweep(reduce, temp=jnp.array(temps))
    np.testing.assert_allclose(np.stack(swept, axis=-1), eager, rtol=1e-13)

    def anisotropy(theta):
        prof = hg.Profile.held_angles(jnp.stack([theta, theta + 90.0]), 100.0, 20.0)
        return sc.mode_reversal(t, jnp.where(first, theta, -theta), prof, settle_s=30.0).anisotropy

    with pytest.raises(ValueError, match=r"^mode_reversal: profile.wave_angle0 is traced here "
                       r"\(jit, vmap or hg.sweep .* \(a swept temperature is fine\)"):  # fmt: skip
        jax.vmap(anisotropy)(jnp.array([0.0, 45.0]))


def test_correct_and_compare_refuse_ftr_and_precession_data(
    sweeps, reversal_at_minus_45, tmp_path, capsys
):
    """The wave angle of FTR output (held) or of a sweep (turned by a force) does not
    measure the case's rate: `correct`, `compare` and the CLI refuse them in one line, as
    `calibrate` does (they printed −0.18 °/h for a 36 °/h input, −3237 °/h at rest)."""
    from hrgjax.calibration import compare, save_compensator

    comp = sc.PrecessionCompensator(settle_s=15.0).fit(sweeps)
    ftr = reversal_at_minus_45[1].to_data()
    for data, match in ((sweeps, "commanded precession"), (ftr, "force-to-rebalance output")):
        with pytest.raises(ValueError, match=match):
            comp.correct(data)
        with pytest.raises(ValueError, match=match):
            compare({"vp": comp}, data)
    model = save_compensator(comp, tmp_path / "vp.eqx")
    for data, match in ((sweeps, "commanded precession"), (ftr, "force-to-rebalance output")):
        path = str(data.save(tmp_path / "d.csv"))
        cli_fails(["correct", path, "--model", str(model)], capsys, match)
        cli_fails(["compare", path, "--models", str(model)], capsys, match)


def test_standard_errors_vanish_without_noise_and_match_the_noises_spread(
    sweeps, reversal_at_minus_45, tmp_path
):
    """Audit (s34): neither reduction gave an uncertainty. Noise-free, each σ is ~0; with a
    known noise added to the same runs it is that noise's spread. Mode reversal's σ, read
    from the holds' own samples, against the closed form (n q + 2s)/n² per hold of the
    noise put in (white angle s and white rate q: the default gyro's) and against the
    spread of 200 draws. The sweeps' drift σ from the noise model against 40 draws; from
    the data it needs 6 sweeps (3 temperatures) and is NaN from the fixture's one pair. σ
    survives `.eqx` and JSON round trips; a file without it (as before s34) loads None."""
    from hrgjax.calibration import export_json, load_compensator, load_json, save_compensator
    from hrgjax.pattern_noise import NoiseModel

    prof, rec = reversal_at_minus_45
    clean = sc.mode_reversal(rec.t, rec.rebalance_rate, prof, settle_s=30.0)
    assert float(clean.bias_std) < 1e-5 * abs(float(clean.bias))
    assert float(clean.anisotropy_std) < 1e-5 * abs(float(clean.anisotropy))
    rng = np.random.default_rng(0)
    white, rate = 8.75e-6, 1.05e-6  # [rad] σ_w/k_e per sample, [rad/s] per 1-s sample
    n = rec.t.size
    noise = -np.diff(white * rng.standard_normal((200, n + 1)), axis=-1)
    noisy = np.asarray(rec.rebalance_rate)[None] + noise + rate * rng.standard_normal((200, n))
    out = sc.mode_reversal(rec.t, noisy, prof, settle_s=30.0)
    kept = np.array([np.sum((rec.t >= a) & (rec.t <= b)) for a, b in prof.hold_windows(30.0)])
    closed = 0.5 * np.sqrt(np.sum((kept * rate**2 + 2 * white**2) / kept**2))
    np.testing.assert_allclose(np.std(out.bias - clean.bias), closed, rtol=0.15)
    np.testing.assert_allclose(np.median(out.bias_std), closed, rtol=0.15)
    assert np.all((out.anisotropy_std > 0.5 * closed) & (out.anisotropy_std < 2 * closed))
    row = sc.mode_reversal_data(rec.to_data(), settle_s=30.0)[0]
    assert row["bias_std_dph"] < 1e-5 * abs(row["bias_dph"])

    t = np.stack([sweeps["time_s"][i] for i in sweeps.run_indices()])
    theta = np.stack([sweeps["wave_angle_deg"][i] * DEG for i in sweeps.run_indices()])
    rho = np.stack([sweeps["precession_dps"][i] * DEG_PER_S for i in sweeps.run_indices()])
    used = (t - t[:, :1] >= 15.0).astype(float)
    model = NoiseModel(angle_white=4.85e-6, angle_random_walk=3.5e-7)  # pattern angle
    draws = model.angle_white * rng.standard_normal((40, *t.shape)) + np.cumsum(
        model.angle_random_walk * rng.standard_normal((40, *t.shape)), axis=-1)  # fmt: skip
    fits = [sc.fit_sweeps(*map(jnp.asarray, (t, theta + d, rho, used)))[1] for d in draws]
    ((_, sigma),) = sc.sweep_std([(t, theta, rho, used)], 2, model)
    np.testing.assert_allclose(sigma, np.std(np.asarray(fits), axis=0), rtol=0.35)
    comp = sc.PrecessionCompensator(settle_s=15.0).fit(sweeps, noise=model)
    np.testing.assert_allclose(np.asarray(comp.drift_std[0]), sigma / comp.k_e, rtol=1e-12)
    for back in (load_compensator(save_compensator(comp, tmp_path / "vp.eqx")),
                 load_json(export_json(comp, tmp_path / "vp.json"))):  # fmt: skip
        for f in ("drift_coef", "gain_coef", "drift_std", "gain_std"):
            np.testing.assert_array_equal(
                np.asarray(getattr(back, f)), np.asarray(getattr(comp, f))
            )
    bare = eqx.tree_at(lambda c: (c.drift_std, c.gain_std), comp, (None, None))
    old = save_compensator(bare, tmp_path / "old.eqx")
    with open(old, "rb") as fh:  # the header as written before s34
        assert "std" not in json.loads(fh.readline())["hyper"]
    assert load_compensator(old).drift_std is None and load_compensator(old).gain_std is None
    assert np.all(np.isnan(sc.PrecessionCompensator(settle_s=15.0).fit(sweeps).drift_std))
    ((_, still), *_) = sc.sweep_std([(t, theta, rho, used)] * 3, 2)  # noise-free, 6 sweeps
    drift = sc.fit_sweeps(*map(jnp.asarray, (t, theta, rho, used)))[1]
    assert np.all(still < 1e-4 * np.max(np.abs(np.asarray(drift))))
