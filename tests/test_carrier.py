"""The fixed-step carrier path (`simulate(model="full", fixed_step=…)`) against adaptive
stepping of the same equations: its convergence order on the free resonator, its accuracy
with the loops closed and temperature laws on, gradients (reverse mode = finite
differences ≈ −k_e·T) and batching."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

import hrgjax as hg

F0 = 5000.0
FREE = hg.Gyro(
    hg.Resonator(
        omega=2 * np.pi * F0, tau=640.0, k_e=0.554, delta_omega=2 * np.pi * 0.05,
        theta_omega=0.2, delta_inv_tau=2e-3, theta_tau=0.5, chi=2e4,
    ),
    control=hg.Control.free(),
)  # fmt: skip


def _errors(rec, ref):
    return max(
        float(np.max(np.abs(np.asarray(rec.wave_angle) - np.asarray(ref.wave_angle)))),
        float(np.max(np.abs(np.asarray(rec.amplitude) - np.asarray(ref.amplitude)))),
    )


def test_free_resonator_converges_at_eighth_order():
    prof = hg.Profile.constant_rate(100.0, 0.02, wave_angle0_deg=20.0)  # 100 carrier cycles
    ts = np.array([0.01, 0.02])
    # the adaptive reference and the adaptive run at rtol 1e-8 below: tolerances as arrays,
    # one compiled program for both
    adaptive = lambda rtol, atol: hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=None,  # noqa: E731
                                              rtol=jnp.asarray(rtol), atol=jnp.asarray(atol))  # fmt: skip
    ref = adaptive(1e-13, 1e-15)
    # "auto" at rtol 1e-8 takes 10 steps per cycle, 500 an interval, rounded up to the
    # step ladder: 512 (10.24 a cycle)
    auto = hg.simulate(FREE, prof, model="full", ts=ts, fixed_step="auto")
    assert hg.resonator.carrier.ladder_steps(500) == 512
    per_cycle = np.array([7.0, 10.24, 13.0])
    err = [
        _errors(auto if n == 10.24 else
                hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=1 / (F0 * n)), ref)
        for n in per_cycle
    ]  # fmt: skip
    slope = -np.polyfit(np.log(per_cycle), np.log(err), 1)[0]
    assert 7.0 < slope < 10.0, (err, slope)  # Dormand–Prince's 8th-order solution
    # 2 steps a cycle damp the carrier itself (87 % of the amplitude lost): refused
    with pytest.raises(ValueError, match=r"^fixed_step = .* is 2 steps per carrier cycle"):
        hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=1 / (F0 * 2))
    # and is as accurate as adaptive stepping at rtol 1e-8
    adaptive = adaptive(1e-8, 1e-10)  # simulate's default tolerances
    assert err[1] < 2.0 * max(_errors(adaptive, ref), 1e-9), (err, _errors(adaptive, ref))


def test_stages_in_a_loop_are_the_unrolled_step():
    # Runs with the loops closed of at most LOOPED_STAGES_STEPS steps (CPU) evaluate the 13
    # stages in a loop (the right-hand side once in the program), longer ones unrolled: the same
    # Dormand–Prince 8 step, summed in another order. A time-dependent Duffing oscillator
    # (c: the stage's fraction of the step), from several states and step lengths.
    from hrgjax.resonator.carrier import _rk_step, _rk_step_looped

    def field(t0, h):
        def f(c, w):
            t = t0 + c * h
            return jnp.stack([w[1], -(1.0 + 0.3 * t) * w[0] - 0.1 * w[0] ** 3 - 0.02 * w[1]])

        return f

    def both(w, t0, h):
        return _rk_step(field(t0, h), w, h), _rk_step_looped(field(t0, h), w, h)

    both = jax.jit(jax.vmap(both))
    key = jax.random.key(3)
    w = jax.random.normal(key, (6, 2))
    h = jnp.array([1e-3, 0.01, 0.1, 0.3, 0.5, 1.0])
    unrolled, looped = both(w, jnp.linspace(0.0, 2.0, 6), h)
    np.testing.assert_allclose(looped, unrolled, rtol=1e-14, atol=1e-15)
    # and the step is Dormand–Prince's 8th-order one: halving h divides its error by ≈ 2⁹
    # (one step's local error), against 64 steps of h/64
    fine = jax.jit(lambda w, h: jax.lax.fori_loop(
        0, 64, lambda i, w: _rk_step_looped(field(i * h / 64, h / 64), w, h / 64), w))  # fmt: skip
    w0 = jnp.array([1.0, 0.0])
    e = [float(jnp.max(jnp.abs(_rk_step_looped(field(0.0, h), w0, h) - fine(w0, h))))
         for h in (0.4, 0.2)]  # fmt: skip
    assert 2.0**8.5 < e[0] / e[1] < 2.0**10.5, e  # a 7th-order step gives 2⁸
    # the rule: loops closed, at most LOOPED_STAGES_STEPS steps on the platform of the call
    # (a static argument of the simulator's program: a new setting compiles its own)
    from hrgjax.resonator import carrier

    gyro, prof = hg.presets.tvg3_like(noise=False), hg.Profile.constant_rate(10.0, 1.0)
    ts = np.linspace(0.1, 1.0, 10)
    limit = carrier.LOOPED_STAGES_STEPS["cpu"]
    with jax.default_device(jax.devices("cpu")[0]):
        assert carrier.looped_stages(gyro, prof, ts, limit // 10, held=False)
        assert not carrier.looped_stages(gyro, prof, ts, limit // 10 + 1, held=False)
        assert not carrier.looped_stages(gyro, prof, ts, 10, held=True)
        assert not carrier.looped_stages(FREE, prof, ts, 10, held=False)


@pytest.fixture(scope="module")
def ramp():
    """The default gyro (laws, closed loops) through a rate ramp and a temperature change,
    with a knot inside the run; adaptive references at rtol 1e-11 and 1e-8 (tolerances as
    arrays: one compiled program for both)."""
    gyro = hg.presets.tvg3_like(noise=False)
    prof = hg.Profile(
        t=np.array([0.0, 0.012, 0.03]),
        rate=np.deg2rad([0.0, 40.0, 40.0]),
        temperature=np.array([20.0, 20.5, 21.0]),
        accel=np.zeros((3, 3)),
        wave_angle0=np.deg2rad(30.0),
    )
    ts = np.linspace(0.005, 0.03, 6)

    def adaptive(rtol):
        tol = dict(rtol=jnp.asarray(rtol), atol=jnp.asarray(rtol * 1e-2))
        return hg.simulate(gyro, prof, model="full", ts=ts, fixed_step=None, **tol)

    return gyro, prof, ts, adaptive(1e-11), adaptive(1e-8)


FIELDS = ("wave_angle", "amplitude", "quadrature", "frequency")


def _field_errors(rec, ref):
    return {n: float(np.max(np.abs(np.asarray(getattr(rec, n)) - np.asarray(getattr(ref, n)))))
            for n in FIELDS}  # fmt: skip


def test_the_default_meets_rtol_with_closed_loops_and_laws(ramp):
    """The default call (the fixed-step path, every stage demodulating its state) is as close
    to the continuous equations' solution as adaptive stepping at the same rtol (1e-8), field
    by field, with the loops closed, the laws moving and a knot inside the run."""
    gyro, prof, ts, ref, adaptive = ramp
    default = hg.simulate(gyro, prof, model="full", ts=ts)
    err, err_ad = _field_errors(default, ref), _field_errors(adaptive, ref)
    assert not np.array_equal(default.wave_angle, adaptive.wave_angle)  # another path
    for name in FIELDS:
        assert err[name] <= 2.0 * err_ad[name] + 1e-12, (name, err, err_ad)
    # the table's rate turned the pattern: the true angle moved by −k_e·(table angle)
    turn = np.asarray(default.true_wave_angle) - float(prof.wave_angle0)
    np.testing.assert_allclose(turn, -0.554 * np.asarray(default.table_angle), rtol=1e-3)


def test_a_commanded_precession_ramp_is_integrated_within_the_step():
    """Force-to-rebalance through a fast trapezoid precession pulse (`Profile.held_angles`:
    30° in 8 ms, ρ ramping inside segments): the default's held and true angles are as close
    to a tight reference as adaptive stepping at the same rtol (2e-9 rad against 6e-9) — ρ
    and its angle are taken at each stage's time (held at the step's start: 5e-4 rad)."""
    gyro = hg.presets.tvg3_like(noise=False).in_mode("ftr")
    prof = hg.Profile.held_angles([10.0, 40.0], dwell_s=0.002, slew_s=0.008)
    ts = np.linspace(0.001, float(prof.t[-1]), 5)

    def adaptive(rtol):  # tolerances as arrays: one compiled program for both
        tol = dict(rtol=jnp.asarray(rtol), atol=jnp.asarray(rtol * 1e-2))
        return hg.simulate(gyro, prof, model="full", ts=ts, fixed_step=None, **tol)

    ref, loose = adaptive(1e-10), adaptive(1e-8)
    default = hg.simulate(gyro, prof, model="full", ts=ts)
    assert abs(float(ref.wave_angle[-1] - ref.wave_angle[0])) > 0.1  # the pulse moved it
    for name in ("wave_angle", "true_wave_angle"):
        err = np.max(np.abs(np.asarray(getattr(default, name)) - np.asarray(getattr(ref, name))))
        err_ad = np.max(np.abs(np.asarray(getattr(loose, name)) - np.asarray(getattr(ref, name))))
        assert err <= max(2.0 * err_ad, 1e-10) and err < 1e-8, (name, err, err_ad)


@pytest.mark.slow(
    "~20 s: one more compile of the full model; fast tier: the default (continuous) fixed "
    "step against the same references (test_the_default_meets_rtol_with_closed_loops_and_laws)"
)
def test_held_loops_stay_close_to_adaptive_stepping(ramp):
    """`fixed_step="held"` (efforts sampled once per step and held over it; laws at
    each step's midpoint temperature): the wave angle within 1e-9 rad of the continuous equations,
    amplitude and quadrature within 1e-6 of the set point's scale, frequency within 1e-4
    rad/s — close to, but not as close as, adaptive stepping at rtol 1e-8."""
    gyro, prof, ts, ref, adaptive = ramp
    held = hg.simulate(gyro, prof, model="full", ts=ts, fixed_step="held")
    err = _field_errors(held, ref)
    bounds = dict(wave_angle=1e-9, amplitude=1e-6, quadrature=1e-6, frequency=1e-4)
    for name in FIELDS:
        assert err[name] < bounds[name], (name, err, _field_errors(adaptive, ref))


def test_reverse_gradient_equals_finite_differences():
    """Reverse mode through the stored-state derivatives (forward mode is the same rule,
    tested against plain scans in tests/test_stepped.py), across an empty first interval."""

    def final_angle(rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 0.004, wave_angle0_deg=10.0)
        # an output at the start: an empty first interval (its steps of h = 0); the output
        # times of test_vmap_over_rates_equals_single_runs: one program for both
        ts = np.array([0.0, 0.002, 0.004])
        rec = hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=2e-5)
        return rec.wave_angle[-1]

    rate = jnp.asarray(50.0)
    rev = jax.jit(jax.grad(final_angle))(rate)
    fd = (final_angle(rate + 1e-3) - final_angle(rate - 1e-3)) / 2e-3
    np.testing.assert_allclose(rev, fd, rtol=1e-6)
    # dθ/dΩ = −k_e·T (rate in °/s, θ in rad)
    np.testing.assert_allclose(rev, -0.554 * 0.004 * np.pi / 180, rtol=2e-3)


@pytest.mark.slow(
    "~60 s: the checkpointed reverse pass compiled beside the stored-state one; fast tier: "
    "reverse mode = finite differences on the stored-state path "
    "(test_reverse_gradient_equals_finite_differences), the stored-state rule "
    "against plain scans (tests/test_stepped.py)"
)
def test_stored_state_and_checkpointed_gradients_agree(monkeypatch):
    """Runs longer than `carrier.STORE_STEPS` differentiate through the checkpointed step
    loop: the same gradient, with the loops closed (every stage demodulating)."""
    gyro = hg.presets.tvg3_like(noise=False)

    def grad():
        def final_angle(rate_dps):
            prof = hg.Profile.constant_rate(rate_dps, 0.002, wave_angle0_deg=10.0)
            ts = np.array([0.001, 0.002])
            return jnp.sum(hg.simulate(gyro, prof, "full", ts=ts, fixed_step=2e-5).wave_angle)

        return jax.jit(jax.grad(final_angle))(jnp.asarray(50.0))

    stored = grad()
    monkeypatch.setattr(hg.resonator.carrier, "STORE_STEPS", 0)
    jax.clear_caches()  # the compiled programs chose their path when traced
    checkpointed = grad()
    assert checkpointed != stored  # another program: round-off apart
    np.testing.assert_allclose(checkpointed, stored, rtol=1e-10)


def test_vmap_over_rates_equals_single_runs():
    ts = np.array([0.0, 0.002, 0.004])  # the single runs: test_reverse_gradient's program

    def run(rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 0.004, wave_angle0_deg=10.0)
        return hg.simulate(FREE, prof, model="full", ts=ts, fixed_step=2e-5).wave_angle

    rates = jnp.array([-30.0, 5.0, 80.0])
    batch = jax.vmap(run)(rates)
    for k, r in enumerate(rates):
        np.testing.assert_allclose(batch[k], run(r), rtol=0, atol=1e-13)


def test_fixed_step_options_are_checked():
    prof = hg.Profile.constant_rate(10.0, 0.002)
    with pytest.raises(ValueError, match='fixed_step must be .*"auto"'):
        hg.simulate(FREE, prof, model="full", dt_out=0.001, fixed_step="fast")
    # "auto" (the default) lets hrgjax choose: the averaged model steps adaptively
    auto = hg.simulate(FREE, prof, model="averaged", dt_out=0.001, fixed_step="auto")
    adaptive = hg.simulate(FREE, prof, model="averaged", dt_out=0.001, fixed_step=None)
    np.testing.assert_array_equal(auto.wave_angle, adaptive.wave_angle)


def test_the_default_takes_fixed_steps_where_they_meet_rtol():
    """`fixed_step="auto"` (the default) on the full model: the carrier path with the step the
    rule picks (10 steps per carrier cycle at rtol 1e-8, rounded up to the step ladder: the
    same answer as that step given in seconds) where the rule allows it; the adaptive answer (`fixed_step=None`) for rtol below
    the floor, a named step budget, or output times traced inside `jit`."""
    from hrgjax.simulate import AUTO_RTOL_FLOOR

    prof = hg.Profile.constant_rate(20.0, 0.004, wave_angle0_deg=10.0)
    ts = np.array([0.002, 0.004])
    angle = lambda **kw: np.asarray(hg.simulate(FREE, prof, "full", ts=ts, **kw).wave_angle)  # noqa: E731
    per_interval = 0.002 * F0 * hg.resonator.carrier.steps_per_cycle(1e-8)
    assert per_interval == 100.0
    steps = hg.resonator.carrier.ladder_steps(per_interval)
    assert steps == 108  # ⌈2^(27/4)⌉
    default, adaptive = angle(), angle(fixed_step=None)
    with CompileCounter() as c:  # the same step in seconds: the same program
        np.testing.assert_array_equal(default, angle(fixed_step=0.002 / steps))
    assert c.compiles == 0, c.names
    assert np.all(default != adaptive)
    np.testing.assert_allclose(default, adaptive, rtol=0, atol=1e-10)  # both meet rtol 1e-8
    tight = dict(rtol=0.1 * AUTO_RTOL_FLOOR, atol=1e-12)
    np.testing.assert_array_equal(angle(**tight), angle(fixed_step=None, **tight))
    np.testing.assert_array_equal(angle(max_steps=2**18), angle(fixed_step=None, max_steps=2**18))
    traced = jax.jit(lambda t: hg.simulate(FREE, prof, "full", ts=t).wave_angle)(ts)
    np.testing.assert_allclose(traced, adaptive, rtol=0, atol=1e-13)
    # output times from dt_out are built on the host, so under jit (and in sweeps) the rule
    # still sees them and takes the same fixed steps as an eager call (it fell back to
    # adaptive there, without a word)
    on_grid = jax.jit(lambda: hg.simulate(FREE, prof, "full", dt_out=0.002).wave_angle)()
    np.testing.assert_array_equal(on_grid[1:], default)


def test_temperature_laws_follow_a_steep_ramp_at_a_low_carrier():
    """Free decay under a steep Δ(1/τ) law on a temperature ramp at 40 Hz, where a chunk of
    `CHUNK` steps spans ≈ 0.5 s: the laws are taken at each step's midpoint temperature, so
    the wave angle follows the closed form tan(θ−θ_τ) = tan(θ₀−θ_τ)·exp(∫Δ(1/τ)(T(t))dt)
    (interpolating the laws' values over chunks was off by 0.22 rad)."""
    p0, p1, lam, t_a, t_b, dur, th_tau, th0 = 0.2, 0.01, 0.05, -20.0, 60.0, 1.0, 0.5, 0.8
    law = hg.TemperatureLaw(p0=p0, p1=p1, lam=lam)
    # τ = 0.44 s: both axes damped where Δ(1/τ) peaks (4.43 /s < 2/τ = 4.55 /s)
    res = hg.Resonator(omega=2 * np.pi * 40.0, tau=0.44, k_e=0.554, delta_inv_tau=law,
                       theta_tau=th_tau)  # fmt: skip
    gyro = hg.Gyro(res, control=hg.Control.free(), readout=hg.Readout(), noise=None)
    prof = hg.Profile.piecewise([0.0, dur], 0.0, [t_a, t_b], wave_angle0_deg=np.degrees(th0))
    run = hg.simulate(gyro, prof, model="full", dt_out=dur)  # the default: fixed steps
    # ∫(p0 + p1·u)e^{λu} du in u = T − t_ref, over the linear ramp
    prim = lambda u: np.exp(lam * u) * (p0 / lam + p1 * (u / lam - 1 / lam**2))  # noqa: E731
    integral = (prim(t_b - 20.0) - prim(t_a - 20.0)) * dur / (t_b - t_a)
    exact = th_tau + np.arctan(np.tan(th0 - th_tau) * np.exp(integral))
    # what is left is the full model's own averaging error (Δ(1/τ) reaches 4.4 /s here)
    np.testing.assert_allclose(float(run.true_wave_angle[-1]), exact, rtol=0, atol=1e-4)


def test_nearby_carrier_frequencies_share_the_default_program():
    """The default step count is static in the compiled solve: rounded up to the step ladder
    (`carrier.ladder_steps`), a resonator 1 % faster (101 steps an interval instead of 100,
    both run as 108) or another temperature reuses the program; each new count compiled one of
    its own (7–13 s on the default gyro). A frequency 20 % higher (120 → 128 steps) compiles."""
    import equinox as eqx

    prof = lambda temp: hg.Profile.constant_rate(20.0, 0.004, temp, wave_angle0_deg=10.0)  # noqa: E731
    ts = np.array([0.002, 0.004])

    def angle(scale, temp=20.0):
        gyro = eqx.tree_at(lambda g: g.resonator.omega, FREE, FREE.resonator.omega * scale)
        return hg.simulate(gyro, prof(temp), "full", ts=ts).wave_angle

    jax.block_until_ready(angle(1.0))
    with CompileCounter() as c:
        jax.block_until_ready(angle(1.01, temp=35.0))
    assert c.compiles == 0, c.names  # the solve's program (jit(run)) among them before
    ladder = hg.resonator.carrier.ladder_steps
    assert ladder(100) == ladder(101) == 108 and ladder(120) == 128
    with CompileCounter() as c:
        jax.block_until_ready(angle(1.2))
    assert c.compiles >= 1, c.names  # another step count: the solve compiles
