"""Operating modes (docs/modes.md): force-to-rebalance and virtual precession, each against
its analytic law (PHYSICS.md §3.2, §4.1, §4.3); mode reversal (held-angle switching) is in
test_self_calibration.py."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
from hrgjax import Control
from hrgjax.units import DEG, DEG_PER_S

BASE = hg.presets.tvg3_like(temperature_laws=False, noise=False)
RES = BASE.resonator
PERFECT = eqx.tree_at(lambda r: (r.delta_omega, r.delta_inv_tau, r.chi), RES, (0.0, 0.0, 0.0))
TIGHT = dict(rtol=1e-10, atol=1e-12)


def _ftr(res, **control):
    return hg.Gyro(resonator=res, control=Control(mode="ftr", drive="force", **control))


def test_ftr_on_a_perfect_gyro_reads_the_input_rate():
    """A perfect resonator held by the rebalance loop: the rate read from the force is Ω
    (relative error ≤ 1e-6), the wave stays at the commanded angle."""
    rec = hg.simulate(_ftr(PERFECT), hg.Profile.constant_rate(10.0, 20.0, 20.0, 30.0),
                      dt_out=1.0, **TIGHT)  # fmt: skip
    rate = np.asarray(rec.rebalance_rate)
    assert np.max(np.abs(rate / (10.0 * DEG_PER_S) - 1.0)) < 1e-6
    assert np.max(np.abs(np.asarray(rec.wave_angle) - 30.0 * DEG)) < 1e-9
    assert rec.rebalance_saturated is None  # no rebalance_limit
    cols = rec.to_data().columns
    np.testing.assert_allclose(cols["rebalance_rate_dps"], rate / DEG_PER_S)


@pytest.fixture(scope="module")
def held_with_quadrature():
    """A defective gyro (damping anisotropy, frequency split, Duffing) held at four angles
    with the quadrature loop open and 2 % quadrature left: every drift law of §3.2 acts."""
    gyro = _ftr(RES, quadrature_bandwidth=0.0)
    thetas = jnp.deg2rad(jnp.array([0.0, 35.0, 80.0, 125.0]))
    prof = hg.Profile.constant_rate(0.5, 60.0, 20.0)

    def one(th):
        p = eqx.tree_at(lambda p: p.wave_angle0, prof, th)
        return hg.simulate(gyro, p, dt_out=5.0, quadrature0=0.02, **TIGHT)

    return thetas, jax.vmap(one)(thetas)


def test_ftr_bias_follows_the_damping_split_and_duffing_laws(held_with_quadrature):
    """Held at θ, the force balances every unforced θ̇ term of PHYSICS.md §3.2:
    Ω̂ = −(ω/ω_r)·(a² − q²)/a² · d/k_e with
    d = −k_eΩ + ½Δ(1/τ)sin2(θ−θ_τ)·P − ½Δω cos2(θ−θ_ω)·Π − χaq/4ω — within 1e-4 of the law's
    θ-dependent part once the loop's start transient (q₀ is not at the loop's rest) has
    passed (β·t ≥ 20), while q decays (a, q, ω_r read from the record)."""
    thetas, rec = held_with_quadrature
    a, q, w_r = (np.asarray(x) for x in (rec.amplitude, rec.quadrature, rec.frequency))
    th = np.asarray(thetas)[:, None]
    d2 = a**2 - q**2
    drift = (
        0.5 * RES.delta_inv_tau * np.sin(2 * (th - RES.theta_tau)) * (a**2 + q**2) / d2
        - 0.5 * RES.delta_omega * np.cos(2 * (th - RES.theta_omega)) * 2 * a * q / d2
        - RES.chi * a * q / (4 * RES.omega)
    )
    omega = 0.5 * DEG_PER_S
    law = -(RES.omega / w_r) * d2 / a**2 * (drift - RES.k_e * omega) / RES.k_e
    out = np.asarray(rec.rebalance_rate)
    assert np.ptp(q[:, -1] / q[:, 0]) < 1e-3 and 0.85 < q[0, -1] / q[0, 0] < 0.99  # q decays
    err = np.abs(out - law) / np.max(np.abs(drift / RES.k_e))
    assert err[:, 2:].max() < 1e-4, err


def test_whole_angle_drift_equals_the_ftr_bias_at_the_same_angle():
    """One defective gyro, two modes: whole-angle's wave rate at θ (a static run's first
    seconds) read as a rate, −θ̇/k_e, equals force-to-rebalance's reading held at θ — the
    same drift physics — to within 1e-4 of the drift (10-20 s, after the parametric drive's
    start transient)."""
    gyro_wa = eqx.tree_at(lambda g: g.readout, BASE, hg.Readout())
    gyro_ftr = eqx.tree_at(lambda g: g.control, gyro_wa,
                           Control(amplitude=1.0, drive="parametric", excitation_phase=0.01,
                                   mode="ftr"))  # fmt: skip
    thetas = jnp.deg2rad(jnp.array([10.0, 55.0, 100.0]))
    prof = hg.Profile.static(20.0)

    def both(th):
        p = eqx.tree_at(lambda p: p.wave_angle0, prof, th)
        wa = hg.simulate(gyro_wa, p, dt_out=1.0, **TIGHT)
        ftr = hg.simulate(gyro_ftr, p, dt_out=1.0, **TIGHT)
        return wa.true_wave_angle, ftr.rebalance_rate

    angle, rate = jax.vmap(both)(thetas)
    wa_rate = -(np.asarray(angle[:, 20]) - np.asarray(angle[:, 10])) / 10.0 / RES.k_e
    ftr_rate = np.asarray(rate[:, 15])
    scale = np.max(np.abs(ftr_rate))
    assert np.max(np.abs(wa_rate - ftr_rate)) < 1e-4 * scale, (wa_rate, ftr_rate)


def test_virtual_precession_turns_the_wave_by_the_forcers_gain_and_angle():
    """A commanded precession ρ with the case at rest turns the wave by the forcers' gain on
    the node direction: ρ·(1 + g_f)·cos δ (forcer gain g_f, forcer angle δ) and
    ρ·(1 − g cos 2θ) with a forcer gain mismatch g, under the isotropic parametric drive.
    Under a force drive the AGC also takes up the node force's leak onto the antinode along
    its own misaligned axis: ρ(1 + g_f)/cos δ + tan δ/τ (PHYSICS.md §4.4's drive-axis term)."""
    rho, dur = 2.0, 30.0
    prof = hg.Profile.virtual_precession(rho, dur, wave_angle0_deg=10.0)
    cases = (
        ("parametric", 0.01, 0.0, rho * (1.01)),
        ("parametric", 0.01, 0.02, rho * 1.01 * np.cos(0.02)),
        ("force", 0.01, 0.02, rho * 1.01 / np.cos(0.02) + np.tan(0.02) / RES.tau / DEG_PER_S),
    )
    for drive, gain, delta, rate_dps in cases:
        gyro = hg.Gyro(resonator=PERFECT, control=Control(drive=drive, forcer_gain=gain,
                                                          forcer_angle=delta))  # fmt: skip
        rec = hg.simulate(gyro, prof, dt_out=1.0, **TIGHT)
        turned = float(rec.wave_angle[-1] - rec.wave_angle[0])
        assert abs(turned / (dur * rate_dps * DEG_PER_S) - 1.0) < 1e-7, (drive, gain, delta)

    g = 0.02
    gyro = hg.Gyro(resonator=PERFECT, control=Control(drive="parametric", forcer_gain_mismatch=g))
    rec = hg.simulate(gyro, prof, dt_out=1.0, **TIGHT)  # the first case's program
    th = np.asarray(rec.wave_angle)
    rate = np.diff(th) / 1.0
    mid = 0.5 * (th[1:] + th[:-1])
    law = rho * DEG_PER_S * (1.0 - g * np.cos(2 * mid))
    assert np.max(np.abs(rate / law - 1.0)) < 1e-5  # the secant's (Δθ²/24)·4g ≈ 4e-6
    assert rec.rebalance_rate is None and rec.rebalance_on is None  # whole-angle: no FTR output


def test_ftr_in_the_full_model_agrees_with_the_averaged_model():
    """The carrier-resolving model (fixed-step path) held by the same rebalance loop on the
    default gyro's defects reads what the averaged model reads, to 1e-5 of the reading."""
    control = Control(amplitude=1.0, drive="parametric", excitation_phase=0.01, mode="ftr",
                      pll_bandwidth=20.0, agc_bandwidth=10.0, quadrature_bandwidth=20.0,
                      rebalance_bandwidth=20.0)  # fmt: skip
    gyro = eqx.tree_at(lambda g: g.control, BASE, control)
    prof = hg.Profile.static(1.0, wave_angle0_deg=70.0)
    avg = hg.simulate(gyro, prof, dt_out=0.5)
    full = hg.simulate(gyro, prof, model="full", dt_out=0.5)  # the default: fixed steps
    a, f = float(avg.rebalance_rate[-1]), float(full.rebalance_rate[-1])
    assert abs(f - a) < 1e-5 * abs(a)
    assert abs(float(full.wave_angle[-1]) - 70.0 * DEG) < 1e-7


def test_ftr_rate_noise_is_on_the_rate_read_out():
    """With angle random walk N the FTR output's samples scatter by N/√Δt (the mean rate of
    each interval) and the held wave angle does not wander. White readout noise σ_w per
    sample reaches the rate too: the loop nulls the angle it reads, so the force reads
    −Δw/(k_e Δt), what a whole-angle reading of the same noise gives (std √2·σ_w/(k_e Δt),
    lag-1 autocorrelation −½); it read no readout noise at all before."""
    arw = 0.05 * DEG / 60.0  # 0.05 °/√h in rad/√s
    gyro = hg.Gyro(resonator=PERFECT, control=Control(mode="ftr", drive="force"),
                   noise=hg.Noise(angle_random_walk=arw))  # fmt: skip
    rec = hg.simulate(gyro, hg.Profile.static(2000.0), dt_out=1.0, key=jax.random.key(3))
    std = np.std(np.asarray(rec.rebalance_rate))
    assert abs(std / arw - 1.0) < 0.1
    assert np.ptp(np.asarray(rec.wave_angle)) < 1e-12
    white = eqx.tree_at(lambda g: g.noise, gyro, hg.Noise(angle_white=1e-5))
    rec = hg.simulate(white, hg.Profile.static(2000.0), dt_out=1.0, key=jax.random.key(4))
    rate = np.asarray(rec.rebalance_rate)[1:]
    assert np.std(rate) / (np.sqrt(2.0) * 1e-5 / float(rec.k_e[0])) == pytest.approx(1.0, abs=0.1)
    assert np.corrcoef(rate[:-1], rate[1:])[0, 1] == pytest.approx(-0.5, abs=0.1)


def test_bad_mode_and_schedule_inputs_name_the_field():
    with pytest.raises(ValueError, match="Control.mode must be one of"):
        Control(mode="rate")
    with pytest.raises(ValueError, match="free resonator"):
        Control(mode="ftr", enabled=False)
    with pytest.raises(ValueError, match="Profile.precession must have the shape"):
        hg.Profile(t=[0.0, 1.0], rate=[0.0, 0.0], temperature=[20.0, 20.0],
                   accel=np.zeros((2, 3)), precession=[0.0, 0.0, 0.0])  # fmt: skip
    with pytest.raises(ValueError, match=r"^Profile\.held_angles: dwell_s must be a positive"):
        hg.Profile.held_angles([0.0, 90.0], dwell_s=0.0)
    with pytest.raises(ValueError, match="rebalance_limit"):
        hg.simulate(_ftr(PERFECT, rebalance_limit=-1.0), hg.Profile.static(1.0))


def test_ideal_loops_hold_the_wave_where_the_pi_loops_settle():
    """`Control(ideal=True)` in FTR mode holds the wave where the estimate reads the
    commanded angle and reads the force that holds it there: on the default gyro (readout
    gain mismatch 0.46 %) the reading and the true held angle equal the PI loops' at rest to
    1e-7 of the reading."""
    import dataclasses

    gyro = BASE.in_mode("ftr")
    ideal = eqx.tree_at(lambda g: g.control, gyro, dataclasses.replace(gyro.control, ideal=True))
    prof = hg.Profile.static(30.0, wave_angle0_deg=30.0)
    pi, held = hg.simulate(gyro, prof, dt_out=1.0), hg.simulate(ideal, prof, dt_out=1.0)
    a, b = float(pi.rebalance_rate[-1]), float(held.rebalance_rate[-1])
    assert abs(a - b) < 1e-7 * abs(a)
    assert abs(float(pi.true_wave_angle[-1] - held.true_wave_angle[-1])) < 1e-9
    assert abs(float(held.wave_angle[-1]) - 30.0 * DEG) < 1e-10


def test_a_schedule_switches_whole_angle_and_rebalance_during_a_run(monkeypatch):
    """`Profile.rebalance` = (0, 1, 0): whole-angle for 20 s, then the rebalance loop captures
    the wave where it is read and holds it — after the loop's transient the wave is back
    where it was caught and the output reads Ω (1e-6) — then lets it go, and it turns at
    −k_eΩ again. The full model (fixed steps) agrees with the averaged one."""
    omega = 1.0
    prof = hg.Profile.piecewise([0.0, 20.0, 60.0, 80.0], omega, 20.0, rebalance=[0, 1, 0, 0])
    gyro = _ftr(PERFECT)
    rec = hg.simulate(gyro, prof, dt_out=1.0, **TIGHT)
    th = np.asarray(rec.wave_angle)
    turn = -PERFECT.k_e * omega * DEG_PER_S
    np.testing.assert_allclose(np.diff(th[:21]), turn, rtol=1e-7)  # whole-angle
    assert abs(th[59] - th[20]) < 1e-9  # caught at 20 s, held (the transient has passed)
    rate = np.asarray(rec.rebalance_rate)
    assert np.max(np.abs(rate[40:60] / (omega * DEG_PER_S) - 1.0)) < 1e-6
    np.testing.assert_allclose(np.diff(th[61:]), turn, rtol=1e-6)  # let go
    np.testing.assert_array_equal(np.asarray(rec.rebalance_on)[[0, 19, 20, 59, 60, 80]],
                                  [0, 0, 1, 1, 0, 0])  # fmt: skip
    assert rec.to_data()["rebalance_on"].sum() == 40
    # (four knots and 81 outputs: the averaged run is the run above's program). Half a
    # second: the wave turns 1.2e-3 rad before the capture at 0.125 s and would turn
    # 3.6e-3 rad more if the full model missed it (the models agree to 1e-9 here). Through
    # the step loop (`_streamed`), as a run of 1 s (4× the CPU) took: 29 040 steps would
    # otherwise go the stored-state way
    short = hg.Profile.piecewise([0.0, 0.125, 0.25, 0.5], omega, 20.0, rebalance=[0, 1, 1, 1])
    ts = np.linspace(0.0, 0.5, 81)
    from hrgjax.resonator import carrier

    monkeypatch.setattr(carrier, "STORE_STEPS", 0)
    full = hg.simulate(gyro, short, model="full", ts=ts)  # the default: fixed steps
    avg = hg.simulate(gyro, short, ts=ts, **TIGHT)
    np.testing.assert_allclose(np.asarray(full.wave_angle), np.asarray(avg.wave_angle), atol=1e-6)
    with pytest.raises(ValueError, match="give the gyro Control"):
        hg.simulate(hg.Gyro(resonator=PERFECT), prof)
    with pytest.raises(ValueError, match="Profile.rebalance\\[1\\] is 0.5"):
        hg.Profile.piecewise([0.0, 1.0], 0.0, 20.0, rebalance=[1, 0.5])


def test_a_schedule_captures_the_wave_where_it_is_read_while_the_temperature_moves():
    """The default gyro with its temperature laws and noise, whole-angle for 100 s while the
    chamber goes from −20 to +60 °C, then held: the held estimate stays where it was read at
    the switch (the readout's temperature law followed while off; without it the wave was
    kicked by 5.8e-3 rad), and the FTR output is exactly 0 where the loop is off (the rate
    noise moved the free wave instead)."""
    gyro = hg.presets.tvg3_like().in_mode("ftr")
    prof = hg.Profile.piecewise([0.0, 100.0, 160.0], 0.0, [-20.0, 60.0, 60.0], rebalance=[0, 1, 1])
    rec = hg.simulate(gyro, prof, dt_out=1.0, key=jax.random.key(1))
    th = np.asarray(rec.wave_angle)
    assert abs(np.mean(th[130:]) - th[100]) < 2e-5  # 1″ white readout noise per sample
    assert np.all(np.asarray(rec.rebalance_rate)[:100] == 0.0)
    assert np.ptp(th[:100]) > 1e-5  # the free wave moved (drift and noise)


def test_ftr_scale_factor_is_first_order_in_the_readout_errors():
    """docs/modes.md's closed-form FTR scale factor is first order in the readout errors:
    the force acts along the *estimated* node, so with large defects (readout g = 0.03,
    forcers g_f = 0.02, g_m = 0.03, Δ(1/τ) × 50) at 33° the output leaves the law by ≈ 1e-3
    of itself, and the second-order factor 1/cos(θ̂ − θ) (g_m at cos(θ + θ̂)) closes the gap
    to 1e-5."""
    from hrgjax.resonator import readout as ro

    big = eqx.tree_at(
        lambda g: (g.resonator.delta_inv_tau, g.readout.gain_mismatch, g.control.forcer_gain,
                   g.control.forcer_gain_mismatch),
        BASE, (BASE.resonator.delta_inv_tau * 50, 0.03, 0.02, 0.03),
    ).in_mode("ftr")  # fmt: skip
    rate = 1.0 * DEG_PER_S
    rec = hg.simulate(big, hg.Profile.constant_rate(1.0, 40.0, 20.0, 33.0), dt_out=1.0, **TIGHT)
    res, ctl = big.resonator, big.control
    th, th_hat = float(rec.true_wave_angle[-1]), 33.0 * DEG
    a_hat = float(rec.amplitude[-1])
    unit = ro.from_pendulum(1.0, 0.0, th, 0.0).transform(big.readout.matrix())
    a = a_hat / float(ro.estimate(unit, theta_branch=th).amplitude)
    common = res.k_e / ctl.k_e_nominal * res.omega / float(rec.frequency[-1]) * a / a_hat
    drift = 0.5 * res.delta_inv_tau * np.sin(2 * (th - res.theta_tau)) / res.k_e
    omega = rate + float(big.rate_bias)
    first = common / (1 + 0.02 - 0.03 * np.cos(2 * th)) * (omega - drift)
    second = common / (1 + 0.02 - 0.03 * np.cos(th + th_hat)) / np.cos(th_hat - th)
    second *= omega - drift
    out = float(rec.rebalance_rate[-1])
    assert 5e-4 < abs(out / first - 1) < 2e-3
    assert abs(out / second - 1) < 1e-5


def test_ideal_ftr_loops_with_a_force_limit_are_refused():
    """The averaged model's ideal loops hold the wave with whatever force it takes: with a
    `rebalance_limit` they read 2 °/s with the wave held where the PI loops saturate at
    1 °/s and the wave runs off (k_e·(2 − 1)·t). `simulate` refuses the pair there in one line
    naming both fields (the full model runs its PI loops whatever `ideal` says, so the pair
    is valid for it, and `Control` itself accepts it)."""
    limited = hg.Gyro(PERFECT, control=Control(mode="ftr", ideal=True, rebalance_limit=600.0))
    with pytest.raises(ValueError, match=r"Control.rebalance_limit needs Control.ideal=False"):
        hg.simulate(limited, hg.Profile.static(1.0))
    Control(mode="wa", ideal=True, rebalance_limit=600.0)  # read only in FTR mode


def test_held_angles_names_a_slew_too_short_for_its_pulse():
    """Audit: `held_angles(…, slew_s=1e-3)` was refused as "Profile.precession = 120000 at
    index 2 …", a field the caller never gave. The trapezoid's peak, step/(¾·slew_s), is
    checked against the plausible precession where the slew is given, naming `slew_s` and the
    least that fits (90° at ±2e4 °/s: 6 ms); a relaxed range takes it."""
    with pytest.raises(
        ValueError,
        match=r"^Profile\.held_angles: slew_s = 0\.001 s moves the "
        r"wave 90° at a peak of 120000 °/s electrical, .* give slew_s ≥ 0\.006 s",
    ):
        hg.Profile.held_angles([70.0, 160.0], dwell_s=120.0, slew_s=1e-3)
    with pytest.raises(ValueError, match=r"^Profile\.held_angles: slew_s = 0\.001 s moves the "
                       r"wave -90° at a peak of -120000"):  # fmt: skip
        hg.Profile.held_angles([160.0, 70.0], dwell_s=120.0, slew_s=1e-3)
    with pytest.raises(ValueError, match=r"^Profile\.held_angles: slew_s must be a positive"):
        hg.Profile.held_angles([0.0, 90.0], dwell_s=1.0, slew_s=0.0)
    with hg.plausible.relaxed(precession_dps=(-2e5, 2e5)):
        p = hg.Profile.held_angles([70.0, 160.0], dwell_s=120.0, slew_s=1e-3)
    assert float(p.commanded_angle_at(p.t[-1])) == pytest.approx(160.0 * DEG, abs=1e-9)


def test_ftr_refuses_an_open_rebalance_loop():
    """Audit: `rebalance_bandwidth=0` in FTR mode ran with the loop open (the force held at
    its start, 1 °/s read through a step to 5 °/s while the wave ran off). It is refused in
    one line naming the field and "> 0 in FTR mode": by `Control`, by `in_mode`, by `simulate`
    for a gyro built with `eqx.tree_at`, and for a traced value under `vmap`. Whole-angle
    mode does not read it: 0 stays valid there."""
    import dataclasses

    rule = r"rebalance_bandwidth must be finite and > 0 rad/s in FTR mode \(at 0 the rebalance"
    with pytest.raises(ValueError, match=rf"^Control\.{rule}.*; got 0$"):
        Control(mode="ftr", rebalance_bandwidth=0.0)
    wa = hg.Gyro(PERFECT, control=Control(rebalance_bandwidth=0.0))  # not read in whole-angle
    with pytest.raises(ValueError, match=rf"^Control\.{rule}"):
        wa.in_mode("ftr")
    ftr = _ftr(PERFECT)
    opened = eqx.tree_at(lambda g: g.control.rebalance_bandwidth, ftr, 0.0)
    with pytest.raises(ValueError, match=r"^gyro\.control\.rebalance_bandwidth = 0 rad/s in FTR "
                       r"mode .*; it must be > 0$"):  # fmt: skip
        hg.simulate(opened, hg.Profile.static(2.0), dt_out=1.0)
    run = lambda b: hg.simulate(eqx.tree_at(lambda g: g.control.rebalance_bandwidth, ftr, b),
                                hg.Profile.static(2.0), dt_out=1.0).rebalance_rate  # fmt: skip
    with pytest.raises(RuntimeError, match=r"^simulate: gyro\.control\.rebalance_bandwidth must "
                       r"be > 0 rad/s in FTR mode"):  # fmt: skip
        jax.vmap(run)(jnp.array([0.0, 2.0]))
    with pytest.raises(ValueError, match=r"Control\.rebalance_bandwidth must be finite and >= 0"):
        dataclasses.replace(wa.control, rebalance_bandwidth=-1.0)


def test_ftr_saturation_warns_and_is_marked_in_the_record():
    """Audit: with `rebalance_limit=100` a 1 °/s input read 0.1646 °/s (the limit's reading,
    100/608) with no sign. The record marks the samples where the force sat at its limit
    (`rebalance_saturated`), and an eager run says so in one `SaturationWarning` naming the
    limit, the share of samples and the reading there; the same program with room to spare
    (6000 ≈ 10 °/s) marks none and does not warn (warnings are errors here)."""
    from hrgjax.simulate import SaturationWarning

    gyro = _ftr(PERFECT, rebalance_limit=100.0)
    prof = hg.Profile.constant_rate(1.0, 10.0)
    with pytest.warns(SaturationWarning, match=r"^simulate: the FTR loop saturated at Control\."
                      r"rebalance_limit = 100 in 100 % of the samples .* ≈ ±0\.1646 °/s, not the "
                      r"rate"):  # fmt: skip
        rec = hg.simulate(gyro, prof, dt_out=1.0)
    np.testing.assert_array_equal(np.asarray(rec.rebalance_saturated), 1.0)
    assert abs(float(rec.rebalance_rate[-1]) / DEG_PER_S - 0.1646) < 1e-4
    roomy = eqx.tree_at(lambda g: g.control.rebalance_limit, gyro, 6000.0)
    rec = hg.simulate(roomy, prof, dt_out=1.0)  # the same program: no warning
    np.testing.assert_array_equal(np.asarray(rec.rebalance_saturated), 0.0)
    assert abs(float(rec.rebalance_rate[-1]) / DEG_PER_S - 1.0) < 1e-6
