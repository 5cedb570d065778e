"""Seed 003 building blocks: installation misalignment (map, inverse, calibration) and the
Elman network."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter, cli_fails

from hrgjax.fog import misalignment as mis
from hrgjax.nn.elman import Elman
from hrgjax.nn.mlp import MLP


def test_misalignment_map_and_first_order_inverse_round_trip_to_second_order():
    rng = np.random.default_rng(0)
    for scale in (1e-3, 1e-4):
        angles = jnp.asarray(rng.normal(size=6) * scale)
        e = mis.misalignment_matrix(angles)
        assert np.allclose(np.diag(e), 0.0)
        assert e[0, 1] == angles[0] and e[2, 1] == angles[5]  # xy and zy
        rt = mis.body_from_sensor(angles) @ mis.sensor_from_body(angles) - jnp.eye(3)
        # (I − E)(I + E) − I = −E²: second order, exactly
        np.testing.assert_allclose(rt, -(e @ e), atol=1e-18)
        assert np.abs(rt).max() <= 3 * scale**2 * 10
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        mis.misalignment_matrix(jnp.zeros(5))


def _positions():
    """Six ±axis positions plus eight tilted ones (unit vectors × 9.8 m/s²)."""
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    tilted = np.array([[1, 1, 1], [1, -1, 1], [-1, 1, 1], [-1, -1, 1],
                       [1, 1, -1], [1, -1, -1], [-1, 1, -1], [-1, -1, -1]]) / np.sqrt(3)  # fmt: skip
    return np.concatenate([axes, tilted]) * 9.80665


def test_calibration_recovers_injected_angles_within_their_uncertainties():
    truth = mis.TriadCalibration(
        angles=jnp.array([3e-4, -2e-4, 1e-4, 5e-4, -4e-4, 2.5e-4]),
        scale=jnp.array([2e-4, -1e-4, 3e-4]),
        bias=jnp.array([1e-3, -2e-3, 5e-4]),
        angles_std=jnp.zeros(6), scale_std=jnp.zeros(3), bias_std=jnp.zeros(3),
        residual_std=jnp.zeros(3),
    )  # fmt: skip
    b = _positions()
    noise = 5e-5 * 9.80665  # 50 µg per averaged position
    pulls = []
    for seed in range(20):
        s = np.asarray(truth.sensor(b)) + np.random.default_rng(seed).normal(size=b.shape) * noise
        fit = mis.calibrate(b, s)
        pulls.append(
            (np.asarray(fit.angles) - np.asarray(truth.angles)) / np.asarray(fit.angles_std)
        )
        np.testing.assert_allclose(fit.scale, truth.scale, atol=5 * float(fit.scale_std.max()))
        np.testing.assert_allclose(fit.bias, truth.bias, atol=5 * float(fit.bias_std.max()))
    pulls = np.array(pulls)
    assert np.all(np.abs(pulls) < 5.0)
    # the standard errors are honest: the pulls scatter like N(0, 1)
    assert 0.6 < pulls.std() < 1.5, pulls.std()
    # compensation undoes the model
    np.testing.assert_allclose(fit.body(truth.sensor(b)), b, atol=10 * noise)
    with pytest.raises(ValueError, match=">= 5 positions"):
        mis.calibrate(b[:4], b[:4])
    with pytest.raises(ValueError, match="shape"):
        mis.calibrate(b, b[:, :2])


@pytest.fixture(scope="module")
def elman():
    return Elman(2, 7, 1, key=jax.random.key(0))


def test_elman_without_recurrence_is_an_mlp(elman):
    flat = eqx.tree_at(lambda m: m.w_h.weight, elman, jnp.zeros((7, 7)))
    mlp = MLP((2, 7, 1), key=jax.random.key(1))
    mlp = eqx.tree_at(lambda m: (m.layers[0].weight, m.layers[0].bias, m.layers[1].weight,
                                 m.layers[1].bias),
                      mlp, (flat.w_x.weight, flat.w_x.bias, flat.w_y.weight, flat.w_y.bias))  # fmt: skip
    xs = jax.random.normal(jax.random.key(2), (50, 2))
    np.testing.assert_allclose(flat(xs), jax.vmap(mlp)(xs), rtol=1e-12, atol=1e-14)
    # with its recurrence it is not: the context carries the past
    assert not np.allclose(elman(xs), flat(xs))
    with pytest.raises(ValueError, match=r"\(T, in_size\)"):
        elman(jnp.zeros(3))


def test_elman_runs_one_compiled_program_per_shape(elman):
    """Called eagerly, the scan traced a fresh closure over the network on every call and
    compiled it again (0.5-0.8 s a `compensate` call); now a second call of the
    same shape, alone or vmapped over stacked networks, compiles and traces nothing, and
    its output is the same recursion, stepped by hand."""
    xs, other = jax.random.normal(jax.random.key(5), (2, 30, 2))
    nets = eqx.filter_vmap(lambda k: Elman(2, 7, 1, key=k))(jax.random.split(jax.random.key(6), 3))
    per_net = lambda: eqx.filter_vmap(lambda n: n(xs))(nets)  # noqa: E731
    elman(xs), per_net()
    with CompileCounter() as c:
        ys, stacked = elman(other), per_net()
    assert (c.compiles, c.traces) == (0, 0), c.names
    h, ref = np.zeros(7), []  # h_t = tanh(W_x x_t + b + W_h h_(t-1)), y_t = W_y h_t + c
    wx, bx = np.asarray(elman.w_x.weight), np.asarray(elman.w_x.bias)
    wh, wy, by = (np.asarray(a) for a in (elman.w_h.weight, elman.w_y.weight, elman.w_y.bias))
    for x in np.asarray(other):
        h = np.tanh(wx @ x + bx + wh @ h)
        ref.append(wy @ h + by)
    np.testing.assert_allclose(ys, ref, rtol=1e-12, atol=1e-15)
    assert stacked.shape == (3, 30, 1)


def test_gradients_through_the_scan_match_finite_differences(elman):
    xs = jax.random.normal(jax.random.key(3), (40, 2))
    target = jnp.sin(jnp.arange(40.0))[:, None]

    def loss(w_h):
        m = eqx.tree_at(lambda m: m.w_h.weight, elman, w_h)
        return jnp.mean((m(xs) - target) ** 2)

    w = elman.w_h.weight
    g = jax.grad(loss)(w)
    d = jax.random.normal(jax.random.key(4), w.shape)
    eps = 1e-6
    fd = (loss(w + eps * d) - loss(w - eps * d)) / (2 * eps)
    np.testing.assert_allclose(jnp.sum(g * d), fd, rtol=1e-7)


def test_psd_peak_finds_a_known_tone_and_matches_scipy():
    from scipy.signal import welch

    from hrgjax.fog import spectrum

    fs, t = 200.0, np.arange(0, 40.0, 1 / 200.0)
    rng = np.random.default_rng(0)
    for f0, amp in ((10.0, 0.5 * 9.80665), (37.3, 1.0 * 9.80665)):
        x = amp * np.sin(2 * np.pi * f0 * t + 0.3) + rng.normal(size=t.size) * 0.2
        f, p = spectrum.psd(jnp.asarray(x), fs, nperseg=1024)
        fr, pr = welch(x, fs, window="hann", nperseg=1024, detrend="constant")
        np.testing.assert_allclose(f, fr)
        np.testing.assert_allclose(p, pr, rtol=1e-10, atol=1e-12 * pr.max())
        freq, a = spectrum.tone(jnp.asarray(x), fs, nperseg=1024)
        assert abs(float(freq) - f0) < 0.05 * (fs / 1024)  # 5 % of a bin
        assert abs(float(a) / amp - 1.0) < 0.01
    # odd nperseg: scipy's default overlap is nperseg // 2 = 50 (hrgjax overlapped by 51)
    x = rng.normal(size=1000)
    for nperseg in (101, 33):
        f, p = spectrum.psd(jnp.asarray(x), 100.0, nperseg=nperseg)
        fr, pr = welch(x, 100.0, nperseg=nperseg)
        np.testing.assert_allclose(f, fr)
        np.testing.assert_allclose(p, pr, rtol=1e-10, atol=1e-12 * pr.max())
    # Parseval: white noise of variance σ² has ∫P df = σ²
    w = rng.normal(size=2**15) * 0.7
    f, p = spectrum.psd(jnp.asarray(w), fs, nperseg=512)
    assert abs(float(jnp.sum(p) * (f[1] - f[0])) / 0.49 - 1.0) < 0.03
    with pytest.raises(ValueError, match="fs must be a finite number > 0"):
        spectrum.psd(jnp.asarray(w), 0.0)
    with pytest.raises(ValueError, match="x must be finite"):
        spectrum.psd(jnp.asarray(w).at[3].set(jnp.nan), fs)


# --- vibration table, error model, features, compensation, alignment (seed 003) ---------


from hrgjax.fog import compensation as cp  # noqa: E402
from hrgjax.fog import vibration as vb  # noqa: E402
from hrgjax.fog.spectrum import psd, tone, vibration_features  # noqa: E402
from hrgjax.units import DEG, G0  # noqa: E402


def _quiet(imu):
    """The IMU without sensor noise."""
    return eqx.tree_at(lambda m: (m.arw, m.vrw), imu, (jnp.asarray(0.0), jnp.asarray(0.0)))


@pytest.fixture(scope="module")
def imu():
    return vb.default_imu()


def test_vibration_error_follows_its_memory_law_and_steady_surface(imu):
    """Noise-free: the gyro error after switch-on rises as ε_ss(1 − e^{−t/τ}) (window means,
    the periodic part averaging out over whole cycles), decays as e^{−t/τ} after switch-off;
    |H|² is 1 at DC and Q² at resonance; the accelerometers rectify K₂(A g)²/2."""
    vib = imu.vibration
    assert float(vib.coil_gain(0.0)) == pytest.approx(1.0)
    assert float(vib.coil_gain(vib.f_res)) == pytest.approx(float(vib.q_res) ** 2)
    q = _quiet(imu)
    f, a, on, off = 10.0, 1.0, 100.0, 60.0
    rec = vb.simulate(q, vb.VibrationSchedule([on, off], [f, 0.0], [a, 0.0]), fs=200.0,
                      key=jax.random.key(0))  # fmt: skip
    w = 1.0
    m = np.asarray(vb.window_means(rec.gyro_error, rec.fs, w))
    tau, ss = float(vib.tau_s), np.asarray(vib.steady(f, a))
    t_mid = (np.arange(m.shape[0]) + 0.5) * w

    def window_avg(fn, t0, t1):  # exact mean of the first-order response over a window
        return (fn(t1) - fn(t0)) / (t1 - t0)

    rise = np.array([window_avg(lambda t: t + tau * np.exp(-t / tau), t - 0.5, t + 0.5)
                     for t in t_mid[: int(on)]])  # fmt: skip
    np.testing.assert_allclose(m[: int(on)], rise[:, None] * ss[None, :],
                               atol=1e-3 * np.abs(ss).max())  # fmt: skip
    ss_end = 1.0 - np.exp(-on / tau)
    decay = np.array([window_avg(lambda t: -tau * np.exp(-t / tau), t - 0.5, t + 0.5)
                      for t in t_mid[int(on):] - on])  # fmt: skip
    np.testing.assert_allclose(m[int(on):], ss_end * decay[:, None] * ss[None, :],
                               atol=1e-3 * np.abs(ss).max())  # fmt: skip
    # accelerometer rectification along z, through the triad's z row
    st = vb.simulate(q, vb.VibrationSchedule([on + off], [0.0], [0.0]), fs=200.0,
                     key=jax.random.key(1))  # fmt: skip
    n = int(on * 200)
    d = np.asarray(jnp.mean(rec.accel[:n] - st.accel[:n], axis=0))
    mz = np.asarray(q.accel.sensor(jnp.array([0.0, 0.0, 1.0])) - q.accel.bias)
    want = np.asarray(vib.accel_k2) * (a * G0 * mz) ** 2 / 2
    np.testing.assert_allclose(d, want, rtol=1e-3, atol=1e-9)


def test_features_find_the_table_condition_and_rest(imu):
    sch = vb.VibrationSchedule([10.0, 20.0, 10.0], [0.0, 12.5, 0.0], [0.0, 0.8, 0.0])
    rec = vb.simulate(imu, sch, fs=200.0, key=jax.random.key(2))
    feats = np.asarray(vibration_features(vb.to_body(imu.accel, rec.accel), rec.fs, 2.0))
    assert feats.shape == (20, 2)
    np.testing.assert_array_equal(feats[:5], 0.0)
    np.testing.assert_array_equal(feats[-5:], 0.0)
    np.testing.assert_allclose(feats[5:15, 0], 12.5, atol=0.05)
    np.testing.assert_allclose(feats[5:15, 1], 0.8, rtol=0.01)


def test_error_samples_are_the_body_frame_error_without_noise(imu):
    """The patent's sample (vibrating − static, orthogonal frame) is exactly the true error
    in body axes when the sensors are quiet; with noise its scatter is √2·ARW/√window."""
    q = _quiet(imu)
    sch = vb.VibrationSchedule.on_off([(20.0, 1.0)], 30.0, 20.0, 10.0)
    rest = vb.VibrationSchedule.constant(0.0, 0.0, sch.duration_s)
    args = dict(fs=200.0, key=jax.random.key(3))
    s = vb.error_samples(q, vb.simulate(q, sch, **args), vb.simulate(q, rest, **args), 2.0)
    truth = vb.to_body(q.gyro, vb.window_means(vb.simulate(q, sch, **args).gyro_error, 200.0, 2.0))
    np.testing.assert_allclose(s, truth, atol=1e-15)
    noisy = vb.error_samples(imu, vb.simulate(imu, rest, **args),
                             vb.simulate(imu, rest, fs=200.0, key=jax.random.key(4)), 2.0)  # fmt: skip
    sd = float(jnp.std(noisy))
    assert sd == pytest.approx(np.sqrt(2) * float(imu.arw) / np.sqrt(2.0), rel=0.2)


def test_alignment_reaches_the_analytic_limits_raw_and_with_the_error_removed(imu):
    """Raw: the heading error is the analytic one for the static plus mean vibration drift;
    with the true vibration error removed it is the remaining (static) drift's."""
    rec = vb.simulate(imu, vb.VibrationSchedule.constant(10.0, 1.0, 600.0), fs=100.0,
                      key=jax.random.key(5))  # fmt: skip
    kw = dict(arw=float(imu.arw), vrw=float(imu.vrw))
    _, raw = cp.align_record(imu, rec, **kw)
    _, perfect = cp.align_record(imu, rec, rec.gyro - rec.gyro_error, **kw)
    eps = vb.to_body(imu.gyro, imu.gyro.bias)
    nab = vb.to_body(imu.accel, imu.accel.bias)
    vib = vb.to_body(imu.gyro, jnp.mean(rec.gyro_error[rec.t.shape[0] // 2 :], axis=0))
    lim_raw = cp.heading_limit_deg(eps + vib, nab, rec.c_bn, rec.lat)
    lim = cp.heading_limit_deg(eps, nab, rec.c_bn, rec.lat)
    assert abs(lim_raw) > 1.0 and abs(lim) < 0.1  # the vibration dominates
    assert raw[0] == pytest.approx(lim_raw, rel=0.05)
    assert perfect[0] == pytest.approx(lim, abs=0.03)
    # tilt: φ_E = −∇_N/g, φ_N = ∇_E/g — well under 0.01° for these biases, raw or not
    assert np.all(np.abs(raw[1:]) < 0.01) and np.all(np.abs(perfect[1:]) < 0.01)


@pytest.fixture(scope="module")
def memory_sets(imu):
    """Quiet training sets with the error's memory (τ = 20 s) and without (τ = 0.1 s)."""
    kw = dict(fs=100.0, window_s=2.0, lead_s=10, on_s=100, off_s=60, key=jax.random.key(6))
    conds = cp.grid([5.0, 20.0], [0.5, 1.0])
    out = {}
    for tau in (20.0, 0.1):
        m = eqx.tree_at(lambda m: m.vibration.tau_s, imu, jnp.asarray(tau))
        out[tau] = cp.training_set(m, conds, **kw)
    return out


def test_elman_beats_the_mlp_where_the_error_has_memory_and_only_there(memory_sets):
    """Same 2–7–1 size and training: with τ = 20 s the Elman network's RMSE is well under
    the MLP's (which can only map (f, A) to a value); with τ = 0.1 s the two are alike."""
    r = {}
    for tau, data in memory_sets.items():
        for kind in cp.KINDS:
            c = cp.VibrationCompensator(kind, key=jax.random.key(11))
            c, hist = cp.fit(c, data, key=jax.random.key(0), epochs=300)
            assert hist["train"][-1] < 0.2 * hist["train"][0]
            r[tau, kind] = float(cp.rmse(c, data))
        assert max(r[tau, "elman"], r[tau, "mlp"]) < 0.5 * float(cp.rmse(None, data))
    assert r[20.0, "elman"] < 0.4 * r[20.0, "mlp"]
    assert r[0.1, "mlp"] < 1.5 * r[0.1, "elman"] and r[0.1, "mlp"] < 0.3 * r[20.0, "mlp"]


def test_end_to_end_training_and_compensation_remove_the_error(imu, memory_sets):
    """Trained through the IMU output (no samples formed), the Elman network compensates a
    record: the compensated gyro's window means are closer to the static output."""
    data = memory_sets[20.0]
    c = cp.VibrationCompensator("elman", key=jax.random.key(12))
    c, _ = cp.fit_end_to_end(c, imu, data, key=jax.random.key(1), epochs=300)
    assert float(cp.rmse(c, data)) < 0.25 * float(cp.rmse(None, data))
    q = _quiet(imu)
    rec = vb.simulate(q, vb.VibrationSchedule.on_off([(20.0, 1.0)], 100, 60, 10), fs=100.0,
                      key=jax.random.key(7))  # fmt: skip
    g, pred = cp.compensate(c, q, rec, window_s=2.0)
    assert pred.shape == (85, 3)
    # the compensator records the window it was trained on (the Elman context steps once per
    # window): compensate uses it by default and refuses another (it stepped at 2× the rate)
    assert c.window_s == 2.0
    np.testing.assert_array_equal(cp.compensate(c, q, rec)[1], pred)
    with pytest.raises(ValueError, match=r"^compensate: window_s=1 s, but the compensator was "
                       r"trained on 2-s windows"):  # fmt: skip
        cp.compensate(c, q, rec, window_s=1.0)
    with pytest.raises(ValueError, match=r"give window_s \(the compensator has not been trained"):
        cp.compensate(cp.VibrationCompensator("elman", key=jax.random.key(0)), q, rec)
    ref = cp.reference_output(q, rec).reshape(1, 3)
    before = vb.window_means(rec.gyro, 100.0, 2.0) - ref
    after = vb.window_means(g, 100.0, 2.0) - ref
    assert float(jnp.sqrt(jnp.mean(after**2))) < 0.25 * float(jnp.sqrt(jnp.mean(before**2)))


def test_vibration_inputs_are_checked(imu):
    with pytest.raises(ValueError, match="durations_s must be > 0"):
        vb.VibrationSchedule([0.0], [10.0], [1.0])
    with pytest.raises(ValueError, match="amp_g is in g"):
        vb.VibrationSchedule([1.0], [10.0], [9.8 * 10])
    with pytest.raises(ValueError, match="Nyquist"):
        vb.simulate(imu, vb.VibrationSchedule.constant(60.0, 1.0, 1.0), fs=100.0,
                    key=jax.random.key(0))  # fmt: skip
    with pytest.raises(ValueError, match=r"^schedule lasts 0.005 s: 0 sample\(s\) at fs = 100 Hz"):
        vb.simulate(
            imu, vb.VibrationSchedule.constant(10.0, 1.0, 0.005), fs=100.0, key=jax.random.key(0)
        )  # fmt: skip  (it returned (0, 3) arrays)
    with pytest.raises(ValueError, match="tau_s must be > 0"):
        eqx.tree_at(lambda m: m.tau_s, imu.vibration, jnp.asarray(-1.0)).__check_init__()
    with pytest.raises(ValueError, match=r"features must have shape \(K, 2\)"):
        cp.VibrationCompensator("elman", key=jax.random.key(0))(jnp.zeros((4, 3)))
    with pytest.raises(ValueError, match="kind must be one of"):
        cp.VibrationCompensator("lstm", key=jax.random.key(0))
    with pytest.raises(ValueError, match=r"accel must have shape \(N, 3\)"):
        vibration_features(jnp.zeros((100, 2)), 100.0)
    # the latitude is in radians: 45 (degrees) returned a wrong number
    eps, nab = np.array([0.0, 1e-7, 0.0]), np.zeros(3)
    with pytest.raises(ValueError, match=r"^lat must be the latitude in radians, \|lat\| ≤ π/2; "
                       r"got 45 \(degrees\? give np\.radians\(45\)\)"):  # fmt: skip
        cp.heading_limit_deg(eps, nab, np.eye(3), 45.0)
    with pytest.raises(ValueError, match=r"^lat must be the latitude in radians.*got nan$"):
        cp.heading_limit_deg(eps, nab, np.eye(3), jnp.nan)
    limit = cp.heading_limit_deg(eps, nab, np.eye(3), np.pi / 4)
    # the exact equilibrium −atan(ε_E/(ω_ie cos φ)); the linear form is 1.3e-6 larger here
    assert limit == pytest.approx(-np.arctan(1e-7 / (7.292115e-5 * np.cos(np.pi / 4))) / DEG,
                                  rel=1e-9)  # fmt: skip


@pytest.mark.slow(
    "~55 s: three network trainings end to end; fast tier: the raw and error-free "
    "alignment limits "
    "(test_alignment_reaches_the_analytic_limits_raw_and_with_the_error_removed), "
    "training and compensation "
    "(test_end_to_end_training_and_compensation_remove_the_error, "
    "test_elman_beats_the_mlp_…)"
)
def test_vibration_cli_writes_the_design_keys_and_compensation_helps(tmp_path, capsys):
    """`hrgjax vibration --quick`: the DESIGN keys; the compensated heading is nearer the
    remaining-drift limit than the raw one; every network beats no compensation."""
    import json

    from hrgjax.cli import main

    out, png = tmp_path / "vib.json", tmp_path / "vib.png"
    assert main(["vibration", "--quick", "--json", str(out), "--plot", str(png)]) == 0
    r = json.loads(out.read_text())
    assert {"raw", "compensated"} <= set(r["heading_error_deg"])
    assert {"elman", "mlp", "none"} <= set(r["prediction_rmse"])
    lim = r["heading_limit_deg"]["remaining_drift"]
    h = r["heading_error_deg"]
    assert abs(h["compensated"] - lim) < 0.5 * abs(h["raw"] - lim)
    assert h["raw"] == pytest.approx(r["heading_limit_deg"]["raw"], abs=0.1)
    assert max(r["prediction_rmse"][k] for k in ("elman", "mlp")) < r["prediction_rmse"]["none"]
    assert r["features"]["freq_hz"] == pytest.approx(10.0, abs=0.05)
    assert r["features"]["amp_g"] == pytest.approx(1.0, rel=0.01)
    assert png.stat().st_size > 10_000
    assert "| compensated |" in capsys.readouterr().out
    cli_fails(["vibration", "--scenario", "20hz"], capsys, "unknown --scenario")


def test_calibration_intervals_cover_with_student_t():
    """The standard errors come from n − 4 residual dof: a ±1.96σ interval covers well below
    95 % for few positions, t's quantile covers 95 % (numpy Monte Carlo, 1000 fits of 3 axes each;
    the binomial σ of a 95 % coverage is 0.4 %)."""
    truth = mis.TriadCalibration.known(jnp.array([3e-4, -2e-4, 1e-4, 5e-4, -4e-4, 2.5e-4]),
                                       jnp.array([2e-4, -1e-4, 3e-4]))  # fmt: skip
    pos = _positions()
    rng = np.random.default_rng(7)
    for idx in ([0, 1, 2, 3, 4], list(range(14))):  # 5 positions (1 dof), 14 (10 dof)
        b = pos[idx]
        clean = np.asarray(truth.sensor(b))
        noise = 5e-4
        cover_t = cover_g = 0
        n_mc = 1000
        for _ in range(n_mc):
            fit = mis.calibrate(b, clean + rng.normal(size=b.shape) * noise)
            err = np.abs(np.asarray(fit.scale) - np.asarray(truth.scale))
            cover_t += np.sum(err <= mis.half_width(fit.scale_std, len(idx)))
            cover_g += np.sum(err <= 1.96 * np.asarray(fit.scale_std))
        cover_t, cover_g = cover_t / (3 * n_mc), cover_g / (3 * n_mc)
        assert abs(cover_t - 0.95) < 0.015, (len(idx), cover_t)
        assert mis.dof(len(idx)) == len(idx) - 4
        if len(idx) == 5:
            assert 0.65 < cover_g < 0.75, cover_g  # 2·Φ_t1(1.96) − 1 = 0.70
    with pytest.raises(ValueError, match="n_positions must be an integer >= 5"):
        mis.dof(4)


def test_units_and_spectrum_settings_are_checked(imu):
    """Accelerometers in g, a drift in °/h given as rad/s, a 1-g vibration at 0 Hz, a short
    record's PSD and a negative lobe: each refused in one line (they gave wrong numbers, a
    NaN, or an error about an nperseg the user never passed)."""
    rng = np.random.default_rng(0)
    t = np.arange(400) / 100.0
    acc = np.zeros((400, 3))
    acc[:, 2] = -9.80665 + 9.80665 * np.sin(2 * np.pi * 10.0 * t)
    f = np.asarray(vibration_features(acc, 100.0, 1.0))
    np.testing.assert_allclose(f[:, 0], 10.0, atol=0.5)
    with pytest.raises(ValueError, match=r"^accel must be specific force in m/s².*in g\?"):
        vibration_features(acc / 9.80665, 100.0, 1.0)
    eps, nab = np.array([0.0, 0.36, 0.0]), np.zeros(3)  # 0.36 meant as °/h
    with pytest.raises(ValueError, match=r"^eps_body must be a bias in rad/s.*°/h\?"):
        cp.heading_limit_deg(eps, nab, np.eye(3), np.pi / 4)
    with pytest.raises(ValueError, match=r"^nabla_body must be a bias in m/s²"):
        cp.heading_limit_deg(np.zeros(3), np.array([0.0, 5.0, 0.0]), np.eye(3), np.pi / 4)
    with pytest.raises(ValueError, match=r"amp_g > 0 needs freq_hz > 0"):
        vb.VibrationSchedule.constant(0.0, 1.0, 10.0)
    vb.VibrationSchedule([1.0, 1.0], [0.0, 10.0], [0.0, 1.0])  # rest at 0 Hz is fine
    # a record shorter than 16 samples: the default segment is the record (as scipy's)
    import scipy.signal

    x = rng.normal(size=10)
    fr, p = psd(x, 10.0)
    fs_, ps_ = scipy.signal.welch(x, 10.0, nperseg=10)
    np.testing.assert_allclose(fr, fs_)
    np.testing.assert_allclose(p, ps_, rtol=1e-10)
    with pytest.raises(ValueError, match=r"x must have at least 2 samples"):
        psd(x[:1], 10.0)
    with pytest.raises(ValueError, match=r"^lobe must be an integer number of bins >= 0"):
        tone(np.sin(2 * np.pi * 2.0 * np.arange(64) / 16.0), 16.0, lobe=-1)


def test_error_samples_refuse_records_at_another_attitude_or_latitude(imu):
    """Rest records at heading 0° and 90° gave a spurious ~10 °/h "vibration error" (the
    Earth rate each gyro senses differs): the attitude and latitude must match."""
    rest = vb.VibrationSchedule.constant(0.0, 0.0, 4.0)
    kw = dict(fs=50.0, key=jax.random.key(1))
    a = vb.simulate(imu, rest, **kw)
    with pytest.raises(ValueError, match=r"^vibrating and static records must have the same "
                       r"attitude c_bn; they differ by up to 1 "):  # fmt: skip
        vb.error_samples(imu, a, vb.simulate(imu, rest, attitude_deg=(0, 0, 90), **kw), 2.0)
    with pytest.raises(ValueError, match=r"^vibrating and static records must have the same "
                       r"latitude lat \[rad\]; got 0\.785398163 and 0\.523598776$"):  # fmt: skip
        vb.error_samples(imu, a, vb.simulate(imu, rest, lat_deg=30.0, **kw), 2.0)
    same = vb.error_samples(imu, a, vb.simulate(imu, rest, **kw), 2.0)
    np.testing.assert_array_equal(same, 0.0)  # one key: the same record


def test_compensator_scales_must_be_finite_and_positive():
    """x_scale (0, 1) or (nan, 1) and y_scale 0 were accepted, then training failed with
    "training diverged (lower learning_rate)" — the wrong cause."""
    key = jax.random.key(0)
    for xs in ((0.0, 1.0), (np.nan, 1.0), (-25.0, 1.0), (25.0,)):
        with pytest.raises(ValueError, match=r"^x_scale must be two finite numbers > 0 "
                           r"\(frequency Hz, amplitude g\); got"):  # fmt: skip
            cp.VibrationCompensator("mlp", key=key, x_scale=xs)
    for ys in (0.0, -1.0, np.inf):
        with pytest.raises(ValueError, match=r"^y_scale must be one finite number > 0 \[rad/s\]"):
            cp.VibrationCompensator("elman", key=key, y_scale=ys)


def test_compensate_uses_the_vibration_axis_the_compensator_was_trained_on(imu):
    """`training_set(axis=u)` takes the features along u, `compensate` took them along the
    body axis of largest variance: for u = (1, 1, 1) the amplitude fed to the network was
    1/√3 of the trained one. The axis is recorded by `fit` and used by default; another is
    refused; a compensator without one (a skeleton saved before) keeps the old default."""
    import io

    u = (1.0, 1.0, 1.0)
    unit = tuple(np.asarray(u) / np.sqrt(3.0))
    kw = dict(fs=50.0, window_s=2.0, lead_s=2.0, on_s=10.0, off_s=4.0, axis=u)
    data = cp.training_set(imu, [(10.0, 1.0)], key=jax.random.key(1), **kw)
    assert data.axis == pytest.approx(unit)
    c, _ = cp.fit(cp.VibrationCompensator("mlp", key=jax.random.key(2)), data,
                  key=jax.random.key(3), epochs=2)  # fmt: skip
    assert c.axis == pytest.approx(unit) and c.window_s == 2.0
    rec = vb.simulate(imu, vb.VibrationSchedule.constant(10.0, 1.0, 8.0, axis=u), fs=50.0,
                      key=jax.random.key(4))  # fmt: skip
    body = vb.to_body(imu.accel, rec.accel)
    along = vibration_features(body, 50.0, 2.0, u)
    largest = vibration_features(body, 50.0, 2.0)
    assert float(along[1, 1]) == pytest.approx(np.sqrt(3.0) * float(largest[1, 1]), rel=0.05)
    _, pred = cp.compensate(c, imu, rec)
    np.testing.assert_array_equal(pred, c(along))
    np.testing.assert_array_equal(cp.compensate(c, imu, rec, axis=np.negative(u))[1], pred)
    # the same record from AC-coupled accelerometers (no gravity, no DC): refused as it stands,
    # compensated as the DC-coupled one with ac_coupled=True (the tone is 20 bins from DC)
    ac = eqx.tree_at(lambda r: r.accel, rec, rec.accel - jnp.mean(rec.accel, axis=0, keepdims=True))
    with pytest.raises(ValueError, match=r"pass ac_coupled=True"):
        cp.compensate(c, imu, ac)
    np.testing.assert_allclose(cp.compensate(c, imu, ac, ac_coupled=True)[1], pred, rtol=1e-6,
                               atol=1e-9 * float(jnp.max(jnp.abs(pred))))  # fmt: skip
    with pytest.raises(ValueError, match=r"^compensate: axis=\(0, 0, 1\), but the compensator "
                       r"was trained on features along \(0\.5774, 0\.5774, 0\.5774\)"):  # fmt: skip
        cp.compensate(c, imu, rec, axis=(0.0, 0.0, 1.0))
    with pytest.raises(ValueError, match=r"^fit: axis=\(0, 0, 1\), but the compensator"):
        cp.fit(c, cp.TrainingSet(*(getattr(data, f) for f in ("features", "samples", "truth",
               "raw", "reference", "conditions")), 2.0, (0.0, 0.0, 1.0)), key=jax.random.key(3),
               epochs=1)  # fmt: skip
    # equinox serialisation stores the arrays only: a skeleton built without the axis (a file
    # saved before it was recorded) loads and keeps the old default, the largest-variance axis
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, c)
    buf.seek(0)
    skeleton = cp.VibrationCompensator("mlp", key=jax.random.key(0), window_s=2.0)
    old = eqx.tree_deserialise_leaves(buf, skeleton)
    assert old.axis is None
    np.testing.assert_array_equal(cp.compensate(old, imu, rec)[1], c(largest))
    rebuilt = cp.VibrationCompensator("mlp", key=jax.random.key(0), window_s=2.0, axis=u)
    buf.seek(0)
    new = eqx.tree_deserialise_leaves(buf, rebuilt)
    np.testing.assert_array_equal(cp.compensate(new, imu, rec)[1], pred)


def test_vibration_simulate_compiles_nothing_for_a_new_latitude(imu):
    """Compile once: `lat_deg` reached the compiled record as a Python float (static), so
    each latitude compiled the whole simulation again (1.7 s); it travels as an array."""
    rest = vb.VibrationSchedule.constant(0.0, 0.0, 0.26)
    vb.simulate(imu, rest, fs=50.0, key=jax.random.key(0), lat_deg=45.0)
    with CompileCounter() as c:
        rec = vb.simulate(imu, rest, fs=50.0, key=jax.random.key(1), lat_deg=-12)
    assert c.compiles == 0, c.names
    assert rec.lat == pytest.approx(-12 * DEG)


# Audit of the FOG / IMU units (session 30): each test failed on the code before it.


def test_psd_takes_integer_samples_as_float_and_refuses_channels_by_time():
    """ADC counts (int16) cast the frequency axis and the window to int: f = 0, 0, 1, 1, …
    and a tone of 1000 counts read amplitude 0. An (N, 3) record was analysed along its
    3-sample last axis without a word."""
    from scipy.signal import welch

    t = np.arange(2000) / 100.0
    x = np.round(1000.0 * np.sin(2 * np.pi * 12.3 * t)).astype(np.int16)
    keep = x.copy()
    f, p = psd(x, 100.0, 200)
    fr, pr = welch(x.astype(float), 100.0, nperseg=200)
    assert f.dtype == np.float64 and p.dtype == np.float64
    np.testing.assert_allclose(f, fr)  # was [0, 0, 1, 1, 2, …]
    np.testing.assert_allclose(p, pr, rtol=1e-10, atol=1e-12 * pr.max())
    for dtype in (np.int16, np.int64):
        freq, amp = tone(x.astype(dtype), 100.0, 200)
        want = tone(x.astype(float), 100.0, 200)
        assert (float(freq), float(amp)) == pytest.approx((float(want[0]), float(want[1])))
        assert float(amp) == pytest.approx(1000.0, rel=1e-3)  # was 0.0
    assert x.dtype == np.int16 and np.array_equal(x, keep)  # the caller's array unchanged
    with pytest.raises(ValueError, match=r"^x must have time along its last axis \(\.\.\., N\); "
                       r"got shape \(400, 3\), 3 samples there.*pass x\.T"):  # fmt: skip
        psd(np.zeros((400, 3)), 100.0)
    f, p = psd(np.random.default_rng(0).normal(size=(400, 3)).T, 100.0)
    assert p.shape == (3, f.shape[0])


def test_vibration_units_are_told_by_gravity_not_by_the_vibration():
    """The rule was the median |f| within 0.5 … 2: a 3-g vibration in g with gravity on x
    (median |f| 2.03) passed as m/s² and read 0.306 g; records without gravity (AC-coupled)
    were refused at 0.1 g in m/s² and passed at 0.5 g in g (reading 0.051 g). The mean over
    the record (gravity; the vibration averages out) decides now, and a record without
    gravity needs `ac_coupled=True`."""
    t = np.arange(400) / 100.0
    in_g = np.zeros((400, 3))
    in_g[:, 0] = -1.0
    in_g[:, 2] = 3.0 * np.sin(2 * np.pi * 10.0 * t)
    with pytest.raises(ValueError, match=r"^accel must be specific force in m/s²: .*\|mean f\| "
                       r"= 1 within 0.3 … 3.13, as 1 g written in g has; in g\? multiply by "
                       r"9.80665"):  # fmt: skip
        vibration_features(in_g, 100.0, 1.0)
    f = np.asarray(vibration_features(in_g * G0, 100.0, 1.0))
    np.testing.assert_allclose(f, np.broadcast_to([10.0, 3.0], f.shape), rtol=1e-9)
    ac = in_g.copy()
    ac[:, 0] = 0.0  # AC-coupled: no gravity, in g or in m/s²
    for unit in (1.0, G0):
        with pytest.raises(ValueError, match=r"^accel carries no gravity: .* below 0.3 .*an "
                           r"AC-coupled record whose unit gravity cannot tell; pass "
                           r"ac_coupled=True to take it as m/s²"):  # fmt: skip
            vibration_features(ac * unit, 100.0, 1.0)
    from hrgjax.fog.spectrum import vibration_direction

    with pytest.raises(ValueError, match=r"^accel carries no gravity"):
        vibration_direction(ac * G0, 100.0, 1.0)
    f = np.asarray(vibration_features(ac * G0, 100.0, 1.0, ac_coupled=True))
    np.testing.assert_allclose(f, np.broadcast_to([10.0, 3.0], f.shape), rtol=1e-9)
    d = np.asarray(vibration_direction(ac * G0, 100.0, 1.0, ac_coupled=True))
    np.testing.assert_allclose(d, np.broadcast_to([0.0, 0.0, 1.0], d.shape), atol=1e-12)
    with pytest.raises(ValueError, match=r"in g\? multiply"):  # gravity in g: still refused
        vibration_features(in_g, 100.0, 1.0, ac_coupled=True)
    with pytest.raises(
        ValueError, match=r"beyond 196.1 m/s² \(20 g; .*in mg\? multiply by 9.80665e-3"
    ):
        vibration_features(in_g * 1000.0, 100.0, 1.0)
    with pytest.raises(TypeError, match=r"^ac_coupled must be True or False; got str 'no'"):
        vibration_features(in_g * G0, 100.0, 1.0, ac_coupled="no")


def test_calibrate_refuses_a_unit_ratio_and_traced_inputs():
    """Inputs in rad/s and outputs in °/s fitted a scale error k = 56.3 (°/h: 2.06e5), with
    no error; under vmap or jit `calibrate` and `half_width` raised
    TracerArrayConversionError."""
    from hrgjax import plausible

    b = _positions() * np.radians(20.0) / 9.80665  # ±20 °/s and tilted, in rad/s
    truth = mis.TriadCalibration.known(np.full(6, 1e-3), [3e-5, -2e-5, 1e-5])
    s = np.asarray(truth.sensor(b)) + np.random.default_rng(0).normal(size=b.shape) * 1e-6
    np.testing.assert_allclose(mis.calibrate(b, s).scale, truth.scale, atol=1e-5)
    for factor, named in ((180.0 / np.pi, r"s in ° \(°/s\) for b in rad \(rad/s\)\?"),
                          (3600.0 * 180.0 / np.pi, r"s in °/h for b in rad/s\?"),
                          (np.pi / 180.0, r"s in rad \(rad/s\) for b in ° \(°/s\)\?"),
                          (1000.0 / 9.80665, r"s in mg for b in m/s²\?"),  # review: was 1000·g
                          (-1.0, r"a reversed axis\?")):  # fmt: skip
        with pytest.raises(ValueError, match=r"^calibrate: sensor axis x reads .* × its input "
                           r"\(fitted scale k = .*, outside the plausible -0.1 … 0.1: .*\): "
                           + named):  # fmt: skip
            mis.calibrate(b, s * factor)
    with plausible.relaxed(imu_scale=(-100.0, 100.0)):  # the range is plausible's
        assert float(mis.calibrate(b, s * 180.0 / np.pi).scale[0]) == pytest.approx(56.3, rel=1e-3)
    with pytest.raises(ValueError, match=r"^calibrate runs on the host \(NumPy/SciPy\), not "
                       r"inside jit, vmap or grad: s must be concrete"):  # fmt: skip
        jax.vmap(lambda x: mis.calibrate(b, x).angles)(jnp.stack([s, s]))
    got = jax.jit(lambda x: mis.half_width(x, 14))(jnp.array([1.0, 2.0]))  # std may be traced
    np.testing.assert_allclose(got, mis.half_width(np.array([1.0, 2.0]), 14), rtol=1e-12)
    with pytest.raises(ValueError, match=r"^half_width runs on the host.*: n_positions must be "
                       r"concrete"):  # fmt: skip
        jax.jit(lambda n: mis.half_width(1.0, n))(14)


def test_triad_known_refuses_impossible_values():
    """NaN angles, angles of radians (arc-minutes typed as rad), a scale of −1 or the factor
    1.00003 for the error 3e-5 were taken silently: NaN or 5× wrong outputs."""
    from hrgjax import plausible

    z6 = np.zeros(6)
    for kw, match in (
        ({"angles": [2.0, -1.5, 1.0, 2.5, -2.0, 1.5]}, r"^angles \[rad\] = 2 at index 0 is "
         r"outside the plausible range -0.1 … 0.1 rad — .*° → ×hrgjax.units.DEG"),
        ({"angles": [np.nan, 0, 0, 0, 0, 0]}, r"^angles must be finite; got nan at index 0"),
        ({"angles": z6, "scale": [1.00003, 0, 0]}, r"^scale must be the scale-factor errors k "
         r"of diag\(1 \+ k\) .*got 1.00003 at index 0: the factor 1 \+ k\? pass scale − 1 = "
         r"3e-05"),
        ({"angles": z6, "scale": [-1.0, 0, 0]}, r"^scale \[-\] = -1 at index 0 is outside the "
         r"plausible range -0.1 … 0.1 .*ppm → ×1e-6"),
        ({"angles": z6, "bias": [0.0, np.inf, 0.0]}, r"^bias must be finite; got inf at index 1"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=match):
            mis.TriadCalibration.known(**kw)
    with plausible.relaxed(imu_misalignment=(-2.0, 2.0)):
        mis.TriadCalibration.known([1.0, 0, 0, 0, 0, 0])
    traced = jax.vmap(lambda a: mis.TriadCalibration.known(a).angles)(jnp.full((2, 6), 1e-3))
    np.testing.assert_array_equal(traced, np.full((2, 6), 1e-3))  # vmap over angles runs
