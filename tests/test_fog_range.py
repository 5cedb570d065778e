"""The FOG vibration compensator does not extrapolate silently (audit 2026-11-30, item 5).

Trained on 5–30 Hz and 0.25–1.25 g, the Elman network's error at 45 Hz 1 g was 0.226 °/h
against 0.036 °/h with no compensation, at 80 Hz 0.239 against 0.0024, at 25 Hz 0.1 g 0.033
against 0.013: `fit` recorded no range and `compensate` checked none. Now `fit` records the
range of the vibrating training windows' (f, A) and `compensate` passes windows outside it
through uncompensated (and counts them), unless `extrapolate=True`.

Cheap: 2-epoch networks on 16-s sequences at 50 Hz — the rule does not depend on how well
the network is trained."""

import io

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

from hrgjax.fog import compensation as cp
from hrgjax.fog import vibration as vb
from hrgjax.fog.spectrum import vibration_features

FS, W = 50.0, 2.0
KW = dict(fs=FS, window_s=W, lead_s=2.0, on_s=10.0, off_s=4.0)
# rest 4 s | 15 Hz 0.75 g (inside) | 23 Hz 0.75 g (f above) | 15 Hz 0.2 g (A below) | rest
SCHEDULE = vb.VibrationSchedule([4.0, 8.0, 8.0, 8.0, 4.0], [0, 15, 23, 15, 0],
                                [0, 0.75, 0.75, 0.2, 0])  # fmt: skip
INSIDE, ABOVE_F, BELOW_A = slice(2, 6), slice(6, 10), slice(10, 14)  # 2-s windows


@pytest.fixture(scope="module")
def setup():
    imu = vb.default_imu()
    data = cp.training_set(imu, [(10.0, 0.5), (20.0, 1.0)], key=jax.random.key(1), **KW)
    nets = {
        kind: cp.fit(cp.VibrationCompensator(kind, key=jax.random.key(2)), data,
                     key=jax.random.key(3), epochs=2)[0]
        for kind in cp.KINDS
    }  # fmt: skip
    rec = vb.simulate(imu, SCHEDULE, fs=FS, key=jax.random.key(4))
    feats = vibration_features(vb.to_body(imu.accel, rec.accel), FS, W, (0.0, 0.0, 1.0))
    return imu, data, nets, rec, feats


def test_fit_records_the_min_and_max_of_the_vibrating_training_features(setup):
    imu, data, nets, _, _ = setup
    x = np.asarray(data.features).reshape(-1, 2)
    on = x[:, 1] > 0  # rest windows are (0, 0)
    assert on.sum() == 2 * 5 and (~on).sum() > 0  # 10 s of vibration per sequence
    truth = ((x[on, 0].min(), x[on, 0].max()), (x[on, 1].min(), x[on, 1].max()))
    for c in nets.values():
        assert c.feature_range == truth
    np.testing.assert_allclose(truth, [[10.0, 20.0], [0.5, 1.0]], rtol=1e-4)
    c, _ = cp.fit_end_to_end(cp.VibrationCompensator("mlp", key=jax.random.key(2)), imu, data,
                             key=jax.random.key(3), epochs=1)  # fmt: skip
    assert c.feature_range == truth
    assert cp.VibrationCompensator("mlp", key=jax.random.key(0)).feature_range is None


def test_compensate_passes_windows_outside_the_range_through_and_counts_them(setup):
    imu, _, nets, rec, feats = setup
    f = np.asarray(feats)
    assert f.shape == (16, 2) and (f[:2] == 0).all() and (f[-2:] == 0).all()
    np.testing.assert_allclose(f[ABOVE_F], [[23.0, 0.75]] * 4, rtol=1e-3)
    np.testing.assert_allclose(f[BELOW_A], [[15.0, 0.2]] * 4, rtol=1e-3)
    out = np.zeros(16, bool)
    out[ABOVE_F] = out[BELOW_A] = True
    m = int(W * FS)
    for kind, c in nets.items():
        gyro, pred = map(np.asarray, cp.compensate(c, imu, rec))
        assert (pred[out] == 0.0).all() and (np.abs(pred[~out]) > 0).all()
        gyro, raw = gyro.reshape(16, m, 3), np.asarray(rec.gyro).reshape(16, m, 3)
        np.testing.assert_array_equal(gyro[out], raw[out])  # bit for bit uncompensated
        assert (gyro[~out] != raw[~out]).all()
        r = cp.compensate(c, imu, rec)
        np.testing.assert_array_equal(r.in_range, ~out)
        assert r.n_out_of_range == 8
        # the network never sees an out-of-range window: it is fed rest (0, 0) there
        rest_fed = np.asarray(c(jnp.where(jnp.asarray(out)[:, None], 0.0, feats)))
        np.testing.assert_allclose(pred[~out], rest_fed[~out], rtol=1e-12, atol=0.0)
        if kind == "mlp":  # no memory: the in-range windows are what the network gives
            np.testing.assert_allclose(pred[~out], np.asarray(c(feats))[~out], rtol=1e-12)
        # the opt-in keeps the old behaviour: the network on every window
        g_x, p_x = cp.compensate(c, imu, rec, extrapolate=True)
        np.testing.assert_array_equal(p_x, c(feats))
        assert (np.asarray(p_x)[out] != 0.0).all()
        held = jnp.repeat(vb.to_sensor(imu.gyro, p_x), m, axis=0)
        np.testing.assert_array_equal(g_x, rec.gyro - held)


def test_inside_the_range_compensation_is_unchanged_bit_for_bit(setup):
    imu, _, nets, _, _ = setup
    rec = vb.simulate(imu, vb.VibrationSchedule.on_off([(15.0, 0.75)], 8.0, 4.0, 4.0), fs=FS,
                      key=jax.random.key(5))  # fmt: skip
    feats = vibration_features(vb.to_body(imu.accel, rec.accel), FS, W, (0.0, 0.0, 1.0))
    for c in nets.values():
        r = cp.compensate(c, imu, rec)
        assert r.n_out_of_range == 0 and bool(r.in_range.all())
        gyro, pred = r  # unpacks as the pair it returned before
        np.testing.assert_array_equal(pred, c(feats))
        np.testing.assert_array_equal(r[0], gyro)
        held = jnp.repeat(vb.to_sensor(imu.gyro, c(feats)), int(W * FS), axis=0)
        np.testing.assert_array_equal(gyro, rec.gyro - held)


def test_a_second_record_of_the_same_shape_compiles_nothing(setup):
    """Compile once: each `compensate` call after the first compiled the Elman network's
    scan again (0.5 s on a 32-s record; `fog.study.run` paid it three times). A second record
    of the same shape now runs the programs the first compiled, for either network."""
    imu, _, nets, rec, _ = setup
    other = vb.simulate(imu, SCHEDULE, fs=FS, key=jax.random.key(8))
    for c in nets.values():
        cp.compensate(c, imu, rec)
        with CompileCounter() as counter:
            r = cp.compensate(c, imu, other)
        assert (counter.compiles, counter.traces) == (0, 0), counter.names
        assert r.n_out_of_range == 8 and bool(jnp.all(jnp.isfinite(r.gyro)))


def test_a_second_fit_of_the_same_shapes_compiles_nothing(setup):
    """Compile once: `fit` and `fit_end_to_end` jitted a fresh closure over the loss and the
    data on every call, so each fit compiled its training program again (1 compile, 2-4 s).
    A fit of other data, key or learning rate of the same shapes, or a refit of a trained
    compensator, now reruns the first fit's program — and trains on the data it is given:
    its last `train` loss is the loss of the weights it returns, recomputed in NumPy."""
    imu, data, nets, _, _ = setup
    other = eqx.tree_at(lambda d: (d.samples, d.raw), data, (-0.5 * data.samples, data.raw[::-1]))
    fresh = lambda kind: cp.VibrationCompensator(kind, key=jax.random.key(7))  # noqa: E731
    e2e = dict(key=jax.random.key(3), epochs=1)
    cp.fit_end_to_end(fresh("mlp"), imu, data, **e2e)
    for kind in cp.KINDS:
        with CompileCounter() as counter:
            c, hist = cp.fit(fresh(kind), other, key=jax.random.key(8), epochs=2,
                             learning_rate=0.03)  # fmt: skip
            cp.fit(nets[kind], data, key=jax.random.key(3), epochs=2)
            cp.fit_end_to_end(fresh("mlp"), imu, other, **e2e, learning_rate=0.02)
        assert (counter.compiles, counter.traces) == (0, 0), counter.names
    # the MLP by hand: per axis a, y = W2 tanh(W1 x/x_scale + b1) + b2, in units of y_scale
    (w1, b1), (w2, b2) = ((np.asarray(lay.weight), np.asarray(lay.bias)) for lay in c.net.layers)
    x = np.asarray(other.features) / np.asarray(c.x_scale)
    h = np.tanh(np.einsum("ahi,ski->skah", w1, x) + b1)
    pred = np.einsum("aoh,skah->skao", w2, h)[..., 0] + b2[:, 0]
    want = np.mean((pred - np.asarray(other.samples) / float(c.y_scale)) ** 2)
    np.testing.assert_allclose(hist["train"][-1], want, rtol=1e-12)
    with pytest.raises(ValueError, match=r"^epochs must be an integer >= 1; got 2.5$"):
        cp.fit(fresh("mlp"), data, key=jax.random.key(3), epochs=2.5)


def test_margin_edges_and_rest(setup):
    c = setup[2]["mlp"]
    (f0, f1), (a0, a1) = c.feature_range
    x = jnp.asarray([[f1 * 1.009, a1], [f1 * 1.011, a1], [f0 * 0.991, a0], [f0, a0 * 0.989],
                     [0.0, 0.0], [f0, 0.06], [jnp.nan, a0]])  # fmt: skip
    np.testing.assert_array_equal(c.in_range(x), [True, False, True, False, True, False, False])
    np.testing.assert_array_equal(c.in_range(x, margin=0.0)[:3], [False, False, False])
    np.testing.assert_array_equal(c.in_range(x, margin=0.02)[:4], [True] * 4)
    # traceable: under jit and vmap (sequences of windows), as in `fit`'s loss
    jitted = eqx.filter_jit(lambda c, x: c.in_range(x))
    np.testing.assert_array_equal(jitted(c, x), c.in_range(x))
    s = jnp.stack([x, x[::-1]])
    np.testing.assert_array_equal(jax.vmap(c.in_range)(s), c.in_range(s))
    with pytest.raises(ValueError, match=r"^margin must be a finite fraction >= 0; got -0\.1"):
        c.in_range(x, margin=-0.1)
    with pytest.raises(ValueError, match=r"^feature_range must be \(\(f_min, f_max\) Hz"):
        cp.VibrationCompensator("mlp", key=jax.random.key(0), feature_range=(1.0, 2.0))


def test_rmse_scores_what_compensate_applies(setup):
    imu, data, nets, _, _ = setup
    # the same sequences with every vibrating frequency tripled (30 and 60 Hz): out of range
    far = eqx.tree_at(lambda d: d.features, data, data.features * jnp.asarray([[[3.0, 1.0]]]))
    for c in nets.values():
        # every vibrating window is out of range: zero prediction there, and the network
        # sees rest only (what it predicts at rest stays in the rest windows)
        vib = far.features[..., 1:] > 0
        assert int(vib.sum()) == 10
        pred = jnp.where(vib, 0.0, jax.vmap(c)(jnp.zeros_like(far.features)))
        truth = jnp.sqrt(jnp.mean((pred - far.truth) ** 2))
        np.testing.assert_allclose(float(cp.rmse(c, far)), float(truth), rtol=1e-12)
        old = jnp.sqrt(jnp.mean((jax.vmap(c)(far.features) - far.truth) ** 2))
        assert float(cp.rmse(c, far, extrapolate=True)) == float(old)
        inside = jnp.sqrt(jnp.mean((jax.vmap(c)(data.features) - data.truth) ** 2))
        assert float(cp.rmse(c, data)) == float(inside)


def test_a_skeleton_without_a_range_loads_and_applies_the_network_everywhere(setup):
    """Equinox serialisation stores the arrays only; a skeleton built without the range (a
    file saved before it was recorded) loads and behaves as before; one rebuilt with it
    applies the rule."""
    imu, _, nets, rec, feats = setup
    c = nets["elman"]
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, c)
    old = cp.VibrationCompensator("elman", key=jax.random.key(0), window_s=W, axis=c.axis)
    buf.seek(0)
    old = eqx.tree_deserialise_leaves(buf, old)
    r = cp.compensate(old, imu, rec)
    assert old.feature_range is None and r.n_out_of_range == 0
    np.testing.assert_array_equal(r.prediction, c(feats))
    new = cp.VibrationCompensator("elman", key=jax.random.key(0), window_s=W, axis=c.axis,
                                  feature_range=c.feature_range)  # fmt: skip
    buf.seek(0)
    new = eqx.tree_deserialise_leaves(buf, new)
    np.testing.assert_array_equal(cp.compensate(new, imu, rec).prediction,
                                  cp.compensate(c, imu, rec).prediction)  # fmt: skip


def test_a_training_set_without_vibration_leaves_every_vibrating_window_out(setup):
    imu = setup[0]
    quiet = cp.training_set(imu, [(10.0, 0.02)], key=jax.random.key(7), **KW)  # < 0.05 g: rest
    c, _ = cp.fit(cp.VibrationCompensator("mlp", key=jax.random.key(2)), quiet,
                  key=jax.random.key(3), epochs=1)  # fmt: skip
    assert c.feature_range == ((np.inf, -np.inf), (np.inf, -np.inf))
    np.testing.assert_array_equal(c.in_range(jnp.asarray([[10.0, 0.5], [0.0, 0.0]])),
                                  [False, True])  # fmt: skip
