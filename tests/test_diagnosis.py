"""Diagnosis building blocks: the pairwise measurements of eqs. (7)–(8) and the multiple-model
filter bank (log-space probabilities with a floor)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import batched_lapack

from hrgjax import kalman
from hrgjax.diagnosis import filter_bank as fb
from hrgjax.diagnosis import measurements as ms


def test_pairwise_measurements_by_hand():
    z = jnp.array([[0.0, 1.0, 4.0, 9.0], [0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0]])
    d2 = ms.second_difference_pairs(z, 0.5)
    # z₀ = k²: second difference 2, over Δt² = 0.25 → 8; the other two are flat
    np.testing.assert_allclose(d2, [[8.0, 8.0], [8.0, 8.0], [0.0, 0.0]])
    d1 = ms.first_difference_pairs(z, 0.5)
    np.testing.assert_allclose(d1, [[4.0, 12.0, 20.0], [4.0, 12.0, 20.0], [0.0, 0.0, 0.0]])
    assert ms.pairs(3) == ((0, 1), (0, 2), (1, 2))
    # common motion cancels
    common = jnp.sin(jnp.arange(10.0))[None, :]
    np.testing.assert_allclose(ms.second_difference_pairs(z[:, :1] * 0 + common, 1.0), 0.0)
    with pytest.raises(ValueError, match="n_ins, K"):
        ms.second_difference_pairs(jnp.zeros(5), 1.0)
    with pytest.raises(ValueError, match="dt must be"):
        ms.first_difference_pairs(z, 0.0)
    # dt inf gave zeros, text or an array a raw comparison error; n_ins 2.5 a raw TypeError
    for dt, kind in ((np.inf, ValueError), ("a", TypeError), (np.array([1.0, 2.0]), ValueError)):
        with pytest.raises(kind, match=r"^dt must be a finite number > 0 s"):
            ms.second_difference_pairs(z, dt)
    with pytest.raises(ValueError, match=r"^n_ins must be an integer >= 2"):
        ms.pairs(2.5)


def test_neural_detectors_refuse_bad_settings_in_one_line():
    """Each was a silent answer or a raw error: a threshold of 2 (no fault ever named), a
    bank of one class ("Need at least one array to stack"), a label out of range (a
    detector trained on no fault), a query of the wrong width (raw broadcasting), unit 0
    (inf features), confirm 1.5 (cut to 1), windows with p_fault 2 or sizes reversed, an
    empty σ grid (None returned)."""
    from hrgjax.diagnosis import neural as nn_

    x = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.1, 5.0], [-5.0, 5.0], [-5.1, 5.0]])
    y = np.array([0, 0, 1, 1, 2, 2])
    with pytest.raises(ValueError, match=r"^threshold must be a number in \[0, 1\)"):
        nn_.PNNDirect.fit(x, y, 3, 1.0, threshold=2.0)
    with pytest.raises(ValueError, match=r"^n_classes must be >= 2"):
        nn_.PNNBank.fit(x, y, 1, 1.0)
    with pytest.raises(ValueError, match=r"^y must be integer class labels in \[0, 3\)"):
        nn_.PNNBank.fit(x, y + 3, 3, 1.0)
    with pytest.raises(ValueError, match=r"^x \(PNNBank query features\) must have shape"):
        nn_.PNNBank.fit(x, y, 3, 1.0).classify(np.ones((2, 4)))
    with pytest.raises(ValueError, match=r"^grid must be one or more kernel widths"):
        nn_.choose_sigma(nn_.PNNDirect, x, y, x, y, 3, grid=())
    with pytest.raises(ValueError, match=r"^unit must be a finite number > 0"):
        nn_.features(np.ones((2, 5, 2)), 0.0)
    with pytest.raises(ValueError, match=r"^latch: confirm must be an integer >= 1"):
        nn_.latch(np.array([0, 1, 1]), 1.5)
    np.testing.assert_array_equal(nn_.latch(np.array([0, 1, 1]), 5), [0, 0, 0])
    zh, tm, key = np.zeros((2, 30, 2)), np.ones((3, 21, 2)), jax.random.key(0)
    for kw, msg in (({"p_fault": 2.0}, r"^p_fault must be a probability in \[0, 1\]"),
                    ({"sizes": (2.0, 1.0)}, r"^sizes must be \(low, high\), finite, low <= high"),
                    ({"onset_within_last": 0}, r"^onset_within_last must be an integer in")):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            nn_.training_windows(zh, tm, key, 4, **{"sizes": (1.0, 2.0), **kw})
    with pytest.raises(ValueError, match=r"^templates must be \(n_ins, L, m = 2\)"):
        nn_.training_windows(zh, tm[0], key, 4, sizes=(1.0, 2.0))


def _toy(n, q=1e-4, r=0.04, p_level=1.0):
    """`n` copies of a scalar random walk observed directly (hypotheses differ by offsets)."""
    m = (
        jnp.eye(1),
        jnp.eye(1) * q,
        jnp.eye(1),
        jnp.array([[r]]),
        jnp.zeros(1),
        jnp.eye(1) * p_level,
    )
    return [m] * n


def test_one_model_bank_equals_a_plain_kalman_filter():
    (phi, qd, h, r, x0, p0) = _toy(1)[0]
    zs = jnp.asarray(np.random.default_rng(0).normal(size=(50, 1)) * 0.2)
    probs, dec, means = fb.run_bank(fb.Bank.build([(phi, qd, h, r, x0, p0)]), zs, floor=0.5)
    xs, _, _ = kalman.kalman_filter(kalman.Gaussian(x0, p0), phi, qd, h, r, zs)
    np.testing.assert_allclose(means[:, 0], xs, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(probs, 1.0)
    # an IMM of identical models is the same filter
    bank = fb.Bank.build(_toy(2), switch_prob=0.01)
    _, _, means2 = fb.run_bank(bank, zs, interacting=True)
    np.testing.assert_allclose(means2[:, 1], xs, rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("interacting", [False, True])
def test_bank_probabilities_stay_normalised_never_lock_and_recover(interacting):
    rng = np.random.default_rng(1)
    offsets = [jnp.zeros(1), jnp.ones(1)]
    bank = fb.Bank.build(_toy(2, q=1e-12, p_level=1e-8), switch_prob=1e-4, z_offsets=offsets)
    # 300 steps of hypothesis 1 (offset 1), then 300 of hypothesis 0
    truth = np.r_[np.ones(300), np.zeros(300)]
    zs = jnp.asarray((truth + rng.normal(size=600) * 0.2)[:, None])
    probs, dec, _ = fb.run_bank(bank, zs, floor=1e-6, threshold=0.99, interacting=interacting)
    p = np.asarray(probs)
    np.testing.assert_allclose(p.sum(1), 1.0, rtol=1e-12)
    assert p.min() > 0.0 and p.max() < 1.0
    assert np.all(np.asarray(dec[20:300]) == 1)
    # after the change it comes back within a few steps (no lock-in at 0)
    back = int(np.argmax(np.asarray(dec[300:]) == 0))
    assert back < 10
    assert np.all(np.asarray(dec[320:]) == 0)
    # a static bank (no hypothesis transitions) relies on the floor alone: with it, it comes
    # back as fast; with a useless floor, S0 sinks for 300 steps and takes far longer
    static = fb.Bank.build(_toy(2, q=1e-12, p_level=1e-8), z_offsets=offsets)
    _, dec_floor, _ = fb.run_bank(static, zs, floor=1e-6, threshold=0.99)
    _, dec_nofloor, _ = fb.run_bank(static, zs, floor=1e-300, threshold=0.99)
    fast = int(np.argmax(np.asarray(dec_floor[300:]) == 0))
    slow = int(np.argmax(np.asarray(dec_nofloor[300:]) == 0))
    assert fast < 10 and slow > 20, (fast, slow)


def test_bank_refuses_bad_settings():
    bank = fb.Bank.build(_toy(2))
    with pytest.raises(ValueError, match="floor"):
        fb.run_bank(bank, jnp.zeros((3, 1)), floor=0.0)
    with pytest.raises(ValueError, match="switch_prob"):
        fb.Bank.build(_toy(1), switch_prob=1.0)
    with pytest.raises(ValueError, match="z_offsets"):
        fb.Bank.build(_toy(2), z_offsets=[jnp.zeros(2), jnp.zeros(2)])
    with pytest.raises(ValueError, match="n_steps"):
        fb.GainBank.from_bank(bank, 0)
    # a short schedule takes a warm-up that fits; a bad one is refused before any work
    assert fb.GainBank.from_bank(bank, 10).warmup == 10
    with pytest.raises(ValueError, match=r"warmup must be an integer in \[0, n_steps=10\]"):
        fb.GainBank.from_bank(bank, 10, warmup=11)
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import PlatformINS

    with pytest.raises(ValueError, match="meas_sigma must be > 0"):
        cx.fault_bank(PlatformINS(), "accel_y", 1.0, meas_sigma=0.0)
    with pytest.raises(ValueError, match="dt must be > 0"):
        cx.fault_bank(PlatformINS(), "accel_y", -1.0)
    with pytest.raises(ValueError, match="no diagnosis channel"):
        cx.fault_bank(PlatformINS(), "accel_z", 1.0)
    # audit: the model-fit settings — a text level raised a raw TypeError, an array NumPy's
    # truth-value error, a text window '5' ran as 5; model_fit's window 0 gave NaN p-values,
    # level 2 failed every step, a 1-D nis broadcast to (K, K)
    z3 = jnp.zeros((3, 1))
    for kw, msg in (({"fit_level": "0.01"}, r"^fit_level must be a number in \(0, 1\) or None"),
                    ({"fit_level": np.array([0.01, 0.02])}, r"^fit_level must be a number in"),
                    ({"fit_window": "5"}, r"^fit_window must be an integer >= 1 \(steps\)")):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            fb.run_bank(bank, z3, **kw)
    for kw, msg in (({"window": 0}, r"^window must be an integer >= 1"),
                    ({"level": 2.0}, r"^level must be a number in \(0, 1\); got 2.0$"),
                    ({"level": None}, r"^level must be a number in \(0, 1\); got None$")):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            fb.model_fit(np.ones((5, 2)), 2, **kw)
    with pytest.raises(ValueError, match=r"^nis must have shape \(K, M\)"):
        fb.model_fit(np.ones(5), 2)
    with pytest.raises(ValueError, match=r"^m must be an integer >= 1"):
        fb.model_fit(np.ones((5, 2)), 0)


def test_gain_schedule_bank_equals_the_full_independent_bank():
    """The covariance recursion does not depend on the data: the bank run with gains
    computed ahead is the full bank, step for step, and batched runs equal single ones."""
    rng = np.random.default_rng(4)
    offsets = [jnp.zeros(1), jnp.ones(1)]
    bank = fb.Bank.build(_toy(2, q=1e-3, p_level=1e-2), switch_prob=1e-3, z_offsets=offsets)
    truth = np.r_[np.zeros(400), np.ones(400)]
    zs = jnp.asarray((truth + rng.normal(size=800) * 0.2)[:, None])
    p_full, d_full, _ = fb.run_bank(bank, zs)
    for n_steps in (800, 200):  # the whole run, or a converged tail held
        gb = fb.GainBank.from_bank(bank, n_steps)
        p_g, d_g = fb.run_gains(gb, zs)
        np.testing.assert_allclose(p_g, p_full, rtol=1e-8, atol=1e-12)
        np.testing.assert_array_equal(d_g, d_full)
    pb, _ = fb.run_gains(gb, jnp.stack([zs, zs[::-1]]))
    np.testing.assert_allclose(pb[0], p_g, rtol=1e-12)
    with pytest.raises(ValueError, match="zs must have shape"):
        fb.run_gains(gb, jnp.zeros(5))


@pytest.fixture(scope="module")
def accel_bank():
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import PlatformINS

    ins = PlatformINS()
    # compare's bank (its fault walk pinned at the former default; fault_bank's is now 1e-9)
    return ins, cx.fault_bank(ins, "accel_y", 1.0, switch_prob=1e-4, fault_walk=1e-8)


@pytest.fixture(scope="module")
def accel_gains(accel_bank):
    return fb.GainBank.from_bank(accel_bank[1], 400)


def test_three_ins_bank_names_the_faulty_ins_within_seconds(accel_bank, accel_gains):
    """Seed 002: a north-accelerometer fault of 1.5e-7 (nominal error 1e-7) in INS 2 at
    t = 200 s is named S2 within 2 s by the interacting bank and held; the healthy complex
    stays S0. The independent bank sees the onset too but lets S0 absorb the step into its
    accelerometer-error state and falls back (the reason for the interacting version)."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import Fault

    ins, bank = accel_bank
    fault = Fault.on("accel_y", 1.5e-7, 200.0)
    _, nav = cx.simulate_complex(
        ins, dt=1.0, n_steps=400, key=jax.random.key(11), fault_ins=1, fault=fault
    )
    z = cx.measurements(nav, 1.0, "accel_y", ins)  # step k ↔ time k + 2
    probs, dec, _ = fb.run_bank(bank, z, interacting=True)
    d = np.asarray(dec)
    assert np.all(d[20:198] == 0)  # before the fault: healthy
    first = int(np.argmax(d[198:] == 2))
    assert first <= 2 and np.all(d[198 + first :] == 2)  # S2 = fault in INS index 1
    p = np.asarray(probs)
    assert p.min() > 0.0 and p.max() < 1.0
    _, d_ind, _ = fb.run_bank(bank, z, interacting=False)
    assert np.asarray(d_ind)[198 + first] == 2 and np.mean(np.asarray(d_ind)[250:] == 2) < 0.5
    # the gain-schedule IMM (what the Monte Carlo comparison runs) decides the same way
    gb = accel_gains
    _, d_g = fb.run_gains(gb, z, interacting=True)
    assert np.mean(np.asarray(d_g)[20:] == d[20:]) >= 0.99
    # threshold A chosen on a healthy training run: the largest fault probability seen
    # after 20 s, with a margin; then a healthy test run (own key) is S0 on ≥ 99 % of steps
    _, nav_tr = cx.simulate_complex(ins, dt=1.0, n_steps=400, key=jax.random.key(13))
    p_tr, _ = fb.run_gains(gb, cx.measurements(nav_tr, 1.0, "accel_y", ins), interacting=True)
    a = min(0.5 * (1.0 + float(np.max(np.asarray(p_tr)[20:, 1:]))), 0.999)
    _, nav0 = cx.simulate_complex(ins, dt=1.0, n_steps=400, key=jax.random.key(12))
    z0 = cx.measurements(nav0, 1.0, "accel_y", ins)
    for dec0 in (fb.run_bank(bank, z0, interacting=True, threshold=a)[1],
                 fb.run_gains(gb, z0, interacting=True, threshold=a)[1]):  # fmt: skip
        assert np.mean(np.asarray(dec0)[20:] <= 0) >= 0.99
    with pytest.raises(ValueError, match="no diagnosis channel"):
        cx.measurements(nav0, 1.0, "accel_z", ins)
    with pytest.raises(ValueError, match="both fault and fault_ins"):
        cx.simulate_complex(ins, dt=1.0, n_steps=10, key=jax.random.key(0), fault_ins=1)
    # audit: fault_ins 1.5 raised a raw indexing TypeError, True ran as INS index 1, and a
    # complex of one INS was simulated (it has no pairs to diagnose)
    for kw, msg in (({"fault_ins": 1.5}, r"^fault_ins must be an INS index in \[0, 3\)"),
                    ({"fault_ins": True}, r"^fault_ins must be an INS index in \[0, 3\)"),
                    ({"fault_ins": 1, "n_ins": 1}, r"^n_ins must be an integer >= 2")):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            cx.simulate_complex(ins, dt=1.0, n_steps=10, key=jax.random.key(0), fault=fault, **kw)


@pytest.mark.parametrize(
    "t_fault, size, fault_ins, seed",
    [(30.0, 2e-7, 2, 21), (200.0, 5e-8, 2, 5), (200.0, -5e-8, 0, 3)],
)
def test_gain_schedule_imm_holds_the_decision_like_the_full_imm(
    accel_bank, accel_gains, t_fault, size, fault_ins, seed
):
    """The gain-schedule IMM (`compare`'s `filter_bank`) against the full IMM on the same
    data, as `compare` runs them (prior 0.97 on S0, measurement noise 1e-9): a fault of
    the documented size inside the first 50 steps, and half-size faults of either sign
    later. Both name the faulty INS and hold it to the end of the run, and they agree on
    ≥ 98 % of the steps after the first 20 (the gain-schedule bank can fall back for 2–4
    steps right after the onset). The gain-schedule bank used to name the INS and then
    fall back to S0 (healthy) within ≈ 35 s while the fault persisted (S0 kept its healthy
    gain and absorbed the step into its accelerometer-error state)."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import Fault

    ins, bank = accel_bank
    fault = Fault.on("accel_y", size, t_fault)
    _, nav = cx.simulate_complex(
        ins, dt=1.0, n_steps=400, key=jax.random.key(seed), fault_ins=fault_ins, fault=fault
    )
    z = cx.measurements(nav, 1.0, "accel_y", ins)
    z = z + 1e-9 * jax.random.normal(jax.random.key(100 + seed), z.shape)
    prior = jnp.array([0.97, 0.01, 0.01, 0.01])
    d_full = np.asarray(fb.run_bank(bank, z, interacting=True, prior=prior)[1])
    d_g = np.asarray(fb.run_gains(accel_gains, z, interacting=True, prior=prior)[1])
    onset = int(np.ceil(t_fault)) - 1  # the first measurement the fault changes
    assert np.all(d_full[onset + 6 :] == fault_ins + 1), d_full[onset:][:20]
    assert np.all(d_g[onset + 6 :] == fault_ins + 1), d_g[onset:][d_g[onset:] != fault_ins + 1]
    assert np.mean(d_g[20:] == d_full[20:]) >= 0.98


def test_the_interacting_banks_default_prior_is_a_healthy_start(accel_bank):
    """Audit: the documented call (`fault_bank` defaults, `run_bank(…, interacting=True)`)
    under the former uniform default decided a fault before there was one (S0 on none of the
    steps before a 2e-7 fault at 100 s in INS 2, key 0) and S0 on 96 % of the steps after
    it. The default is now a healthy start (`HEALTHY_START` on each fault, the rest on S0:
    `compare`'s prior): S0 before the onset, S2 from a few steps after it to the end."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import Fault

    ins, _ = accel_bank
    bank = cx.fault_bank(ins, "accel_y", dt=1.0)
    fault = Fault.on("accel_y", 2e-7, 100.0)
    _, nav = cx.simulate_complex(ins, dt=1.0, n_steps=400, key=jax.random.key(0), fault_ins=1,
                                 fault=fault)  # fmt: skip
    z = cx.measurements(nav, 1.0, "accel_y", ins)  # step k ↔ time k + 2
    d = np.asarray(fb.run_bank(bank, z, interacting=True)[1])
    assert np.all(d[20:97] == 0) and np.all(d[105:] == 2), (d[90:110], np.unique(d[105:]))
    healthy = jnp.array([0.97, 0.01, 0.01, 0.01])
    np.testing.assert_array_equal(d, fb.run_bank(bank, z, interacting=True, prior=healthy)[1])


def test_gain_schedule_imm_keeps_a_healthy_record_healthy_under_a_uniform_prior(
    accel_bank, accel_gains
):
    """With a uniform prior the hypotheses start level and a fault hypothesis
    can lead S0 for a step. The gain-schedule IMM used to step S0 from the leader's
    covariance whenever S0 did not lead (its S ≈ e^5 times larger in determinant, −2.7 nats
    a step), so S0 never took the lead back: healthy records were decided a fault in some
    INS with probability 1 (3 of these 4 keys within 60 steps; 4 of 5 over 400 s) where the
    full IMM decides S0. S0 now steps from its own schedule while its own covariance
    dominates its mixed one (its own mixing weight against the others' plus the spread of
    the mixed estimates, weighed by its own S)."""
    from hrgjax.diagnosis import complex as cx

    ins, bank = accel_bank
    for seed in range(3):
        _, nav = cx.simulate_complex(ins, dt=1.0, n_steps=60, key=jax.random.key(seed))
        z = cx.measurements(nav, 1.0, "accel_y", ins)
        uniform = jnp.full(4, 0.25)  # no longer the interacting forms' default
        d_g = np.asarray(fb.run_gains(accel_gains, z, interacting=True, prior=uniform)[1])
        d_full = np.asarray(fb.run_bank(bank, z, interacting=True, prior=uniform)[1])
        assert np.all(d_g <= 0), (seed, d_g)
        assert np.all(d_g[15:] == 0) and np.array_equal(d_g[15:], d_full[15:]), (seed, d_g)


@pytest.mark.parametrize("g_east", [0.0, 10.0])
def test_healthy_filter_is_consistent_from_the_first_step(g_east):
    """The S0 filter's model is the simulator's: on healthy data (with the measurement noise
    it assumes) its normalised innovations squared average m = 2, from the first steps on
    and under 10 g — the check that caught the filters starting one step early."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import PlatformINS

    ins = PlatformINS(specific_force=jnp.array([g_east * 9.80665, 0.0, 0.0]))
    bank = cx.fault_bank(ins, "accel_y", 1.0, meas_sigma=1e-9)
    zs = []
    for seed in range(4):
        _, nav = cx.simulate_complex(ins, dt=1.0, n_steps=302, key=jax.random.key(seed))
        z = cx.measurements(nav, 1.0, "accel_y", ins)
        zs.append(z + 1e-9 * jax.random.normal(jax.random.key(100 + seed), z.shape))

    def step(g, zk):
        g, nu, s, _ = kalman.update(kalman.predict(g, bank.phi[0], bank.qd[0]), zk,
                                    bank.h[0], bank.r[0])  # fmt: skip
        return g, nu @ jnp.linalg.solve(s, nu)

    @jax.jit  # the four seeds' filters in one program
    def innovations(z):
        return jax.lax.scan(step, kalman.Gaussian(bank.x0[0], bank.p0[0]), z)[1]

    nis = np.asarray(jax.vmap(innovations)(jnp.stack(zs)))
    assert 1.7 < nis.mean() < 2.3, nis.mean()  # sampling σ of the mean ≈ 0.08
    assert nis[:, :5].max() < 16.0, nis[:, :5]  # no start-up outlier (χ²₂ tail 3e-4)


def test_relevant_states_are_the_ones_that_reach_the_parameter():
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import STATES, PlatformINS

    def names(ins, row):
        c = jax.jacfwd(ins.navigation_errors)(jnp.zeros(17))[row]
        return {STATES[i] for i in cx.relevant_states(ins, c)}

    north = {"dv_n", "alpha_x", "da_y", "d_xi", "d_zeta", "dw_xi", "dw_zeta"}
    assert names(PlatformINS(), 0) == north
    east = {"dv_e", "alpha_y", "da_x", "dw_eta"}
    accelerated = PlatformINS(specific_force=jnp.array([30.0, 0.0, 0.0]))
    assert names(accelerated, 0) == north | east  # the heading error couples in


def test_fault_bank_takes_traced_noise_levels_and_refuses_a_traced_ins():
    """Audit: `jax.vmap` over `meas_sigma` raised TracerBoolConversionError (the host range
    checks), `jax.jit` over `switch_prob` a 20-line TracerArrayConversionError
    (`relevant_states` on traced values). The levels only set the models' values: batched,
    the banks equal the ones built one by one. Which states are kept is read from `ins`'s
    values: a traced `ins` is refused in one line."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import PlatformINS

    ins = PlatformINS()
    sigmas, switches = jnp.array([1e-9, 3e-9]), jnp.array([1e-5, 1e-3])

    def build(s, p):
        return cx.fault_bank(ins, "accel_y", 1.0, meas_sigma=s, switch_prob=p)

    batched = jax.jit(jax.vmap(build))(sigmas, switches)
    for i in range(2):
        one = build(float(sigmas[i]), float(switches[i]))
        for a, b in zip(jax.tree.leaves(batched), jax.tree.leaves(one), strict=True):
            np.testing.assert_allclose(a[i], b, rtol=1e-12)
    with pytest.raises(ValueError, match=r"^fault_bank: ins must be a concrete PlatformINS"):
        jax.vmap(lambda g: cx.fault_bank(PlatformINS(g=g), "accel_y", 1.0))(jnp.array([9.8, 9.9]))


def test_batched_banks_run_no_lapack_kernel():
    """The bank's updates, its gain schedules and their inverses run on plain XLA operations
    when batched over runs (jaxlib's LAPACK kernels can wedge XLA:CPU's pool: test_kalman)."""
    bank = fb.Bank.build(_toy(2, q=1e-3, p_level=1e-2), switch_prob=1e-3)
    zs = jnp.zeros((2, 60, 1))
    assert not batched_lapack(jax.vmap(lambda z: fb.run_bank(bank, z)), zs)
    assert not batched_lapack(lambda b: fb.GainBank.from_bank(b, 60), bank)
    gb = fb.GainBank.from_bank(bank, 60)
    assert not batched_lapack(lambda z: fb.run_gains(gb, z), zs)


def test_scores_count_post_onset_steps_that_name_no_fault_as_missed():
    """`compare`'s scores from a hand-made decision trace: after the onset (step 4) a faulty
    run's steps name the right INS, a wrong one, or none (healthy, or undecided −1): the
    three shares sum to 1, and `missed_rate` is the last (it counted nowhere before)."""
    from hrgjax.diagnosis import compare as cp

    states = np.array(
        [
            [0, 0, 0, 0, 0, 1, 1, 1],  # INS 1: 1 missed, 3 right
            [0, 0, 0, 0, -1, -1, 0, 2],  # INS 2: 3 missed (undecided counts), 1 right
            [0, 0, 0, 0, 3, 1, 1, 0],  # INS 3: 1 right, 2 wrong, 1 missed
            [0, 0, 0, 0, 0, 0, 0, 0],  # healthy: never post-onset
        ]
    )
    truth = np.array([1, 2, 3, 0])
    s = cp._score(states, truth, onset_k=4, k0=0, dt=1.0, t_fault=3.0)
    assert s["missed_rate"] == pytest.approx(5 / 12)
    assert s["wrong_diagnosis_rate"] == pytest.approx(2 / 12)
    right = np.mean((states == truth[:, None])[:3, 4:])
    assert s["missed_rate"] + s["wrong_diagnosis_rate"] + right == pytest.approx(1.0)
    assert s["detected"] == 1.0 and s["false_alarm_rate"] == 0.0
    res = {"scenario": "x", "sensor": "accel_y", "thesis": "", "methods": [
        {"name": "filter_bank", "step_cost_s": 1e-6, **s}],
        "setup": {"fault_sizes": [1e-7, 2e-7], "nominal_sensor_error": 1e-7}}  # fmt: skip
    assert "| missed |" in cp.table(res) and "41.67%" in cp.table(res)
    # a method list with nothing to run on the scenario is refused, not an empty table
    with pytest.raises(ValueError, match="nothing to run on scenario 'stationary'.*specific"):
        cp.compare("stationary", methods=("filter_bank_rest",), key=jax.random.key(0))


def test_bank_inputs_are_refused_in_one_line(accel_bank, accel_gains):
    """A NaN measurement used to make every later probability NaN silently; a bad prior,
    transposed measurements or a wrong number of pairs failed deep in JAX (or broadcast)."""
    from hrgjax.diagnosis import complex as cx

    ins, bank = accel_bank
    z = np.zeros((60, 2))
    z[37, 1] = np.nan
    for run in (lambda zz, **kw: fb.run_bank(bank, zz, **kw),
                lambda zz, **kw: fb.run_gains(accel_gains, zz, **kw)):  # fmt: skip
        with pytest.raises(ValueError, match=r"non-finite value \(nan\) at step 37, column 1"):
            run(z)
        for prior in ([1.2, -0.1, -0.05, -0.05], [0.5, 0.5], [0, 0, 0, 0], [np.nan, 1, 1, 1]):
            with pytest.raises(ValueError, match=r"prior must be 4 finite probabilities"):
                run(np.zeros((60, 2)), prior=prior)
        with pytest.raises(ValueError, match=r"zs must have shape .*m = 2.*\(transposed\?"):
            run(np.zeros((2, 60)))
        with pytest.raises(ValueError, match=r"zs must have shape .*m = 2.*got \(60, 3\)"):
            run(np.zeros((60, 3)))
        with pytest.raises(ValueError, match=r"threshold must be a probability"):
            run(np.zeros((60, 2)), threshold=1.5)
    z3 = np.zeros((2, 60, 2))
    z3[1, 5, 0] = np.inf
    with pytest.raises(ValueError, match=r"at step 5 of run 1, column 0"):
        fb.run_gains(accel_gains, z3)
    # an unnormalised prior is a prior: the same run as its normalised form
    zz = np.asarray(np.random.default_rng(0).normal(size=(60, 2))) * 1e-8
    p1 = fb.run_gains(accel_gains, zz, prior=[97.0, 1, 1, 1])[0]
    np.testing.assert_allclose(p1, fb.run_gains(accel_gains, zz, prior=[0.97, 0.01, 0.01, 0.01])[0])
    # the measurements: the bank's pairs (0, j) by default, for any number of INS; selections
    # outside the complex's pairs are refused
    nav = jnp.zeros((4, 10, 3))
    assert cx.measurements(nav, 1.0, "accel_y", ins).shape == (8, 3)
    assert cx.measurements(nav[:3], 1.0, "accel_y", ins).shape == (8, 2)
    for bad in ((0, 0), (0, 3), (), (-1,)):
        with pytest.raises(ValueError, match=r"pairs must be distinct indices into"):
            cx.measurements(nav[:3], 1.0, "accel_y", ins, pairs=bad)
    with pytest.raises(ValueError, match=r"nav must have shape \(n_ins >= 2, K, 3\)"):
        cx.measurements(jnp.zeros((10, 3)), 1.0, "accel_y", ins)


def test_bank_refuses_impossible_covariances():
    """A negative variance (R, Qd) or a NaN Φ made every probability NaN and every decision
    undecided (−1), which `compare` scored as "no false alarm"; an indefinite P0 gave
    plausible-looking probabilities."""
    from hrgjax.diagnosis import compare as cp

    good = _toy(1, r=0.1)[0]
    cases = {
        3: (-0.1 * jnp.eye(1), r"model 1's r must be a symmetric positive-definite \(m, m\) = "
                               r"\(1, 1\) covariance; its variance \[0, 0\] is -0.1"),
        1: (-jnp.eye(1), r"model 1's qd must be a symmetric positive semi-definite"),
        0: (jnp.full((1, 1), jnp.nan), r"model 1's phi must be finite"),
        2: (jnp.ones((1, 2)), r"model 1's h must be \(m, n\) = \(1, 1\)"),
    }  # fmt: skip
    for i, (value, message) in cases.items():
        bad = list(good)
        bad[i] = value
        with pytest.raises(ValueError, match=message):
            fb.Bank.build([good, tuple(bad)])
    two = (jnp.eye(2), 0.01 * jnp.eye(2), jnp.ones((1, 2)), 0.1 * jnp.eye(1), jnp.zeros(2))
    with pytest.raises(ValueError, match=r"model 1's p0 must be .* eigenvalue is -1"):
        fb.Bank.build([(*two, jnp.eye(2)), (*two, jnp.array([[1.0, 2.0], [2.0, 1.0]]))])
    # a bank changed after `build` is checked where it runs
    bank = fb.Bank.build(_toy(2))
    broken = eqx.tree_at(lambda b: b.r, bank, bank.r.at[1].set(-0.1))
    message = r"bank.r must be a symmetric positive-definite .* -0.1 at hypothesis 1"
    with pytest.raises(ValueError, match=message):
        fb.run_bank(broken, jnp.zeros((10, 1)))
    with pytest.raises(ValueError, match=message):
        fb.GainBank.from_bank(broken, 10)
    gains = fb.GainBank.from_bank(bank, 10)
    with pytest.raises(ValueError, match=message):
        fb.run_gains(eqx.tree_at(lambda g: g.bank, gains, broken), jnp.zeros((10, 1)))
    # compare does not score NaN probabilities' undecided steps as "no fault named"
    probs = jnp.array([[[0.5, 0.5], [jnp.nan, jnp.nan]]])
    out = cp._bank_run((probs, jnp.array([[-1, -1]])))
    with pytest.raises(RuntimeError, match=r"filter_bank: the hypothesis probabilities are NaN "
                                           r"from step 1 of run 0"):  # fmt: skip
        cp._bank_states("filter_bank", out)
    np.testing.assert_array_equal(
        cp._bank_states("filter_bank", cp._bank_run((probs[:, :1], jnp.array([[-1]])))), [[0]]
    )


def test_scores_without_fault_free_steps_are_refused_or_none():
    """With no fault-free step after the warm-up the false-alarm rate was NaN (and NumPy's
    "Mean of empty slice" warning); `compare` refuses a warm-up outside the run (one past the
    onset is valid: the healthy runs still count false alarms)."""
    from hrgjax.diagnosis import compare as cp

    states = np.array([[0, 0, 1, 1], [0, -1, 2, 2]])
    s = cp._score(states, np.array([1, 2]), onset_k=2, k0=2, dt=1.0, t_fault=3.0)
    assert s["false_alarm_rate"] is None and s["missed_rate"] == 0.0
    res = {"scenario": "x", "sensor": "accel_y", "thesis": "", "methods": [
        {"name": "filter_bank", "step_cost_s": 1e-6, **s}],
        "setup": {"fault_sizes": [1e-7, 2e-7], "nominal_sensor_error": 1e-7}}  # fmt: skip
    assert "| 100% | – |" in cp.table(res)
    for warmup in (4000.0, 5000.0, -1.0, np.nan):
        with pytest.raises(
            ValueError, match=r"warmup_s must be in \[0, duration\) = \[0, 4000.0\)"
        ):
            cp.compare("stationary", n_healthy=0, warmup_s=warmup, key=jax.random.key(0))


def test_false_alarms_are_scored_from_the_first_measurement_at_warmup_s():
    """Measurement k is at t = (k + 2)·dt (the trace's time grid): the first scored step is
    the first measurement at t ≥ warmup_s — `round(warmup_s / dt)` was two steps late (50 s
    of warm-up at dt = 1 s scored from t = 52 s) — and the first one for warmup_s = 0."""
    from hrgjax.diagnosis import compare as cp

    for dt, warmups in ((1.0, (0.0, 1.0, 2.0, 2.5, 3.0, 50.0)), (0.1, (0.0, 0.3, 5.0, 5.05)),
                        (0.01, (0.07, 0.5))):  # fmt: skip
        t = cp._measurement_times(int(60 / dt), dt)
        for w in warmups:
            k0 = cp._first_step_at(w, dt)
            assert k0 == np.flatnonzero(t >= w - 1e-12)[0], (dt, w, k0, t[k0])
            assert t[k0] >= w - 1e-12 and (k0 == 0 or t[k0 - 1] < w - 1e-12), (dt, w, k0)
    assert cp._first_step_at(0.0, 1.0) == 0 and cp._first_step_at(50.0, 1.0) == 48


@pytest.mark.parametrize(
    ("classes", "confirm", "kind", "match"),
    [
        (np.array([0.0, 1.5, 1.0]), 1, ValueError, r"^latch: classes must be per-step onset classes .*"
         r"whole numbers >= 0 .*; got 1.5 at index \(1,\)"),
        (np.array([0, -1, 1]), 1, ValueError, r"^latch: classes must be .*; got -1 at index \(1,\)"),
        (np.array([0.0, np.nan, 1.0]), 1, ValueError, r"^latch: classes must be .*; got nan"),
        ("abc", 1, TypeError, r"^latch: classes must be per-step onset classes .*; got str 'abc'"),
        (np.array([0, 1, 1]), 0, ValueError, r"^latch: confirm must be an integer >= 1 \(steps\); got 0"),
        (np.array([0, 1, 1]), -1, ValueError, r"^latch: confirm must be an integer >= 1 \(steps\); got -1"),
    ],
)  # fmt: skip
def test_latch_refuses_non_class_values_and_bad_confirm(classes, confirm, kind, match):
    """Audit: float classes (1.5 latched as a class, NaN latched as NaN) and negative ones
    (−1 latched as a fault) passed; confirm 0 or −1 said only "confirm must be >= 1"; a str
    raised JAX's abstract-array error. Whole-valued float classes still latch as before."""
    from hrgjax.diagnosis import neural as nn_

    with pytest.raises(kind, match=match) as err:
        nn_.latch(classes, confirm)
    assert "\n" not in str(err.value)
    np.testing.assert_array_equal(nn_.latch(np.array([0.0, 2.0, 2.0]), 2.0), [0.0, 0.0, 2.0])


def test_bank_means_are_in_physical_units(accel_bank):
    """Audit: `run_bank`'s means were the filters' internal states, divided by each state's
    spread (a 2e-7 fault read 0.659, `fault_sigma` 3e-7 the hidden unit). Now `bank.scale`
    times them: each independent filter's means equal `kalman.kalman_filter` on that
    hypothesis's model times the scale, and the interacting bank's S2 fault state ends at
    the injected 2e-7."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import Fault

    ins, bank = accel_bank
    fault = Fault.on("accel_y", 2e-7, 100.0)
    _, nav = cx.simulate_complex(
        ins, dt=1.0, n_steps=400, key=jax.random.key(11), fault_ins=1, fault=fault
    )
    z = cx.measurements(nav, 1.0, "accel_y", ins)
    _, _, means = fb.run_bank(bank, z, interacting=False)
    i = 2  # S2: the fault in INS index 1
    prior = kalman.Gaussian(bank.x0[i], bank.p0[i])
    xs, _, _ = kalman.kalman_filter(prior, bank.phi[i], bank.qd[i], bank.h[i], bank.r[i], z)
    scale = np.asarray(bank.scale[i])
    np.testing.assert_allclose(np.asarray(means[:, i]) / scale, xs, rtol=1e-9, atol=1e-12)
    fault_state = int(np.flatnonzero(np.asarray(bank.reset[i]))[0])
    imm = fb.run_bank(bank, z, interacting=True)[2]  # holds the fault (the independent: 2e-8)
    assert float(imm[-1, i, fault_state]) == pytest.approx(2e-7, rel=0.1)
    assert float(bank.scale[i, fault_state]) > 1e-7  # the hidden unit it was divided by
    with pytest.raises(ValueError, match=r"^scale must be finite and > 0 \(the states' units\); got 0.0$"):  # fmt: skip
        fb.Bank.build(_toy(2), scale=jnp.zeros(1))
    with pytest.raises(ValueError, match=r"^scale must be \(n,\) = \(1,\) or \(M, n\)"):
        fb.Bank.build(_toy(2), scale=jnp.ones(3))


def test_threshold_and_floor_may_be_traced_for_a_sweep():
    """Audit: `run_bank`/`run_gains` under `jax.jit`/`vmap` over `threshold` or `floor` (an ROC
    curve) raised TracerBoolConversionError; concrete values are still checked. A vmap over
    thresholds and floors equals one call per pair. A record of no steps is refused in one
    line, as `kalman_filter` does."""
    bank = fb.Bank.build(_toy(2, q=1e-3, p_level=1e-2), switch_prob=1e-3,
                         z_offsets=[jnp.zeros(1), jnp.ones(1) * 0.3])  # fmt: skip
    zs = jnp.asarray(np.r_[np.zeros(20), np.full(20, 0.3)][:, None]
                     + 0.2 * np.random.default_rng(1).normal(size=(40, 1)))  # fmt: skip
    gb = fb.GainBank.from_bank(bank, 40)
    ths, floors = jnp.array([0.5, 0.9, 0.999]), jnp.array([1e-6, 1e-6, 1e-2])
    for run in (lambda **kw: fb.run_bank(bank, zs, **kw), lambda **kw: fb.run_gains(gb, zs, **kw)):
        swept = jax.vmap(lambda th, f, run=run: run(threshold=th, floor=f)[:2])(ths, floors)
        for j in range(3):
            one = run(threshold=float(ths[j]), floor=float(floors[j]))
            np.testing.assert_allclose(swept[0][j], one[0], rtol=1e-12)
            np.testing.assert_array_equal(swept[1][j], one[1])
        assert len({tuple(np.asarray(d)) for d in swept[1]}) > 1  # the threshold matters here
        with pytest.raises(ValueError, match=r"^floor must be in \(0, 1/2\); got 0.7$"):
            run(floor=0.7)
    with pytest.raises(ValueError, match=r"^zs must have at least one step \(K >= 1\); got shape \(0, 1\)$"):  # fmt: skip
        fb.run_bank(bank, zs[:0])
    with pytest.raises(ValueError, match=r"^zs must have at least one step \(K >= 1\)"):
        fb.run_gains(gb, zs[:0])


def test_measurements_need_three_samples_for_every_sensor():
    """Audit: `measurements` on 2 samples refused `accel_y` (eq. 7) but gave `gyro_eta`
    (eq. 8) an empty (0, 2) array; both now need K >= 3 (each spans samples k … k + 2)."""
    from hrgjax.diagnosis import complex as cx
    from hrgjax.ins.platform import PlatformINS

    for sensor in ("accel_y", "gyro_eta"):
        with pytest.raises(ValueError, match=r"^nav must have at least 3 samples \(K >= 3"):
            cx.measurements(np.zeros((3, 2, 3)), 1.0, sensor)
        assert cx.measurements(np.zeros((3, 3, 3)), 1.0, sensor).shape == (1, 2)
    # audit: every pair of the complex was formed before the chosen ones were kept, n²/2
    # differences: a transposed (K, n_ins, 3) nav read as K INS ran for minutes. Only the
    # chosen pairs are formed now; they equal eqs. (7)–(8) by hand, R/g-scaled
    nav = np.random.default_rng(3).normal(size=(5, 6, 3))
    ins, dt = PlatformINS(), 0.5
    r_g = ins.radius / ins.g
    got = cx.measurements(nav, dt, "accel_x", ins, pairs=(8, 2))  # pairs (2, 4), (0, 3)
    d2 = lambda i: (nav[i, 2:, 1] - 2 * nav[i, 1:-1, 1] + nav[i, :-2, 1]) / dt**2
    np.testing.assert_allclose(got, r_g * np.stack([d2(2) - d2(4), d2(0) - d2(3)], -1))
    d1 = lambda i: np.diff(nav[i, :, 1])[1:] / dt**2
    got = cx.measurements(nav, dt, "gyro_eta", ins)  # default: pairs (0, j)
    np.testing.assert_allclose(got, r_g * np.stack([d1(0) - d1(j) for j in range(1, 5)], -1))
    assert cx.measurements(np.zeros((200, 3, 3)), 1.0, "accel_y").shape == (1, 199)
    with pytest.raises(ValueError, match=r"^dt must be a finite number > 0 s; got 0.0"):
        cx.measurements(nav, 0.0, "accel_y")
