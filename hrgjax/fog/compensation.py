r"""Vibration-error compensation of a strapdown FOG IMU (seed 003, steps 3–5).

**Samples.** [`training_set`][hrgjax.fog.compensation.training_set] runs the IMU on the table
over a grid of conditions (f, A), each as rest → vibration → rest, and again at rest with
other noise; per window of `window_s` it keeps the vibration features (f, A) from the
misalignment-compensated accelerometers' PSD
([`vibration_features`][hrgjax.fog.spectrum.vibration_features]) and the vibration-error
sample, vibrating − static gyro output mapped to the body frame
([`error_samples`][hrgjax.fog.vibration.error_samples]).

**Networks.** A [`VibrationCompensator`][hrgjax.fog.compensation.VibrationCompensator] holds
one of the patent's 2–7–1 networks (inputs f, A; 7 tanh hidden units; linear output) per
body axis: an [`Elman`][hrgjax.nn.elman.Elman] network, whose context carries the error's
memory, or, as the baseline without memory, an [`MLP`][hrgjax.nn.mlp.MLP] of the same size.
[`fit`][hrgjax.fog.compensation.fit] trains it with Adam (optax) on mini-batches of whole
sequences, `epochs` passes (the patent's ~120);
[`fit_end_to_end`][hrgjax.fog.compensation.fit_end_to_end] trains it instead through the
IMU output: the loss is the compensated raw gyro output (prediction mapped to sensor axes and
subtracted) against the static model's reference, without forming the samples.

**Compensation.** [`compensate`][hrgjax.fog.compensation.compensate] predicts the body-frame
error window by window, maps it back to sensor axes by diag(1+k)(I+E) and subtracts it from
the raw gyro output (held over each window), except in windows whose (f, A) lie outside the
range `fit` recorded, vibrate off the trained axis or hold a tone too near DC or Nyquist to
measure: those pass through uncompensated (the first two unless `extrapolate=True`).

**Alignment** ([`fog.heading`][hrgjax.fog.heading]; its names are importable from here too):
[`align_record`][hrgjax.fog.heading.align_record] runs the coarse + fine alignment of
[`ins.alignment`][hrgjax.ins.alignment] on the misalignment-compensated outputs, and
[`heading_limit_deg`][hrgjax.fog.heading.heading_limit_deg] is the stationary heading error
the remaining biases set.
"""

from __future__ import annotations

import dataclasses
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import concrete_value, host_value
from .._compiled import device, fused
from .._x64 import require_x64
from ..ins.constants import earth_rate_ned
from ..nn.elman import Elman
from ..nn.mlp import MLP
from ..nn.train import adam_epochs
from ..units import DEG_PER_H
from .heading import align_record, heading_limit_deg, imu_log
from .spectrum import EdgeToneWarning, off_axis, vibration_features
from .vibration import (
    FogImu,
    VibrationRecord,
    VibrationSchedule,
    error_samples,
    simulate,
    to_body,
    to_sensor,
    window_means,
)

KINDS = ("elman", "mlp")


class VibrationCompensator(eqx.Module):
    """Per-axis vibration-error networks. Call on features (K, 2) [Hz, g] → body-frame gyro
    error (K, 3) [rad/s]. **Fields:** `net`: three stacked 2–`hidden`–1 networks (Elman or
    MLP); `x_scale` (2,) [Hz, g] and `y_scale` [rad/s]: input and output normalisation;
    `kind`: "elman" or "mlp"; `warmup`: steps of rest input run before a sequence to set the
    Elman context (the record is assumed to start from rest); `window_s` [s]: the feature
    window it was trained on (set by [`fit`][hrgjax.fog.compensation.fit]; None until
    then) — the Elman context steps once per window, so features of another window length
    would step it at the wrong rate, and [`compensate`][hrgjax.fog.compensation.compensate]
    refuses them. `axis` (unit 3-vector): the body-frame vibration direction its features
    were taken along (set by `fit` from the training set; None until then, and in a
    compensator rebuilt without it, e.g. the skeleton of a file saved before it was
    recorded — `compensate` then falls back to the body axis with the largest AC power).
    `feature_range` ((f_min, f_max) [Hz], (A_min, A_max) [g]): the range of the vibrating
    training windows' features (set by `fit`; None until then and in a skeleton rebuilt
    without it: nothing is checked), which `in_range` tests. `recurrent_init` ρ starts the
    context weights at ρ·I.

    **Raises:** `ValueError` for an unknown `kind`, `x_scale` not two finite numbers > 0 or
    `y_scale` not one (a zero scale gave NaN losses reported as "training diverged")."""

    net: eqx.Module
    x_scale: jax.Array
    y_scale: jax.Array
    kind: str = eqx.field(static=True)
    warmup: int = eqx.field(static=True)
    window_s: float | None = eqx.field(static=True)
    axis: tuple | None = eqx.field(static=True, default=None)
    feature_range: tuple | None = eqx.field(static=True, default=None)

    def __init__(
        self, kind: str = "elman", *, key: jax.Array, hidden: int = 7, x_scale=(25.0, 1.0),
        y_scale: float = 0.2 * DEG_PER_H, warmup: int = 30,
        recurrent_init: float = 0.5, window_s: float | None = None, axis=None,
        feature_range=None,
    ):  # fmt: skip
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}; got {kind!r}")
        x_scale = _scale("x_scale", x_scale, (2,), "(frequency Hz, amplitude g)")
        y_scale = _scale("y_scale", y_scale, (), "[rad/s]")
        keys = jax.random.split(key, 3)
        if kind == "elman":
            net = eqx.filter_vmap(lambda k: Elman(2, hidden, 1, key=k))(keys)
            # context weights start at ρ·I (a leaky memory), which trains faster and more
            # reliably than the random start for an error with a time constant of many windows
            w_h = jnp.broadcast_to(recurrent_init * jnp.eye(hidden), (3, hidden, hidden))
            self.net = eqx.tree_at(lambda n: n.w_h.weight, net, w_h)
        else:
            self.net = eqx.filter_vmap(lambda k: MLP((2, hidden, 1), key=k))(keys)
        self.x_scale = jnp.asarray(x_scale)
        self.y_scale = jnp.asarray(y_scale)
        self.kind = kind
        self.warmup = int(warmup)
        self.window_s = None if window_s is None else _window(window_s)
        self.axis = None if axis is None else _unit(axis)
        self.feature_range = None if feature_range is None else _box(feature_range)

    def in_range(self, features, margin: float = 0.01):
        """Mask (...,) of `features` (..., 2) [Hz, g]: True for a window at rest (A = 0, as
        [`vibration_features`][hrgjax.fog.spectrum.vibration_features] gives below its
        threshold: the network is trained on rest) or whose f and A both lie within
        `feature_range`, each bound widened by `margin` (relative, default 1 %, for the
        estimates' scatter); all True when no range is recorded, except NaN features (a tone
        too near DC or Nyquist to measure), which are never in range. Traceable."""
        f = jnp.asarray(features)
        if self.feature_range is None:
            return jnp.all(~jnp.isnan(f), axis=-1)
        m = float(margin)
        if not (np.isfinite(m) and m >= 0):
            raise ValueError(f"margin must be a finite fraction >= 0; got {margin!r}")
        widen = lambda b, s: b + s * m * abs(b) if np.isfinite(b) else b
        b = jnp.asarray([(widen(r[0], -1), widen(r[1], 1)) for r in self.feature_range], f.dtype)
        lo, hi = b.T.reshape((2,) + (1,) * (f.ndim - 1) + (2,))  # bounds (..., 2) [Hz, g]
        return jnp.all((f >= lo) & (f <= hi), axis=-1) | (f[..., 1] == 0)

    def normalised(self, features):
        """Network outputs (K, 3) in units of `y_scale`."""
        x = jnp.asarray(features) / self.x_scale.reshape(1, 2)
        if self.kind == "elman":
            # the context starts where rest leaves it: the record is assumed to start from
            # rest (`warmup` steps at zero features first, discarded)
            warm = jnp.zeros((self.warmup, 2), x.dtype)
            y = eqx.filter_vmap(lambda n: n(jnp.concatenate([warm, x]))[self.warmup :])(self.net)
        else:
            y = eqx.filter_vmap(lambda n: jax.vmap(n)(x))(self.net)
        return jnp.transpose(y[..., 0])

    def __call__(self, features):
        f = jnp.asarray(features)
        if f.ndim != 2 or f.shape[1] != 2:
            raise ValueError(
                f"features must have shape (K, 2) = (frequency Hz, amplitude g); got {f.shape}"
            )
        return self.normalised(f) * self.y_scale


class TrainingSet(eqx.Module):
    """Sequences of window features and targets. **Fields:** `features` (S, K, 2) [Hz, g];
    `samples` (S, K, 3) [rad/s]: the patent's vibration-error samples (vibrating − static,
    body frame; noisy); `truth` (S, K, 3) [rad/s]: the noise-free error, body frame;
    `raw` (S, K, 3) [rad/s]: window means of the raw vibrating gyro output, sensor axes;
    `reference` (3,) [rad/s]: the static model's output at the test attitude, sensor axes;
    `conditions` (S, 2): the (f, A) of each sequence; `window_s` (static); `axis` (static):
    the unit vibration direction the features were taken along (None: not recorded)."""

    features: jax.Array
    samples: jax.Array
    truth: jax.Array
    raw: jax.Array
    reference: jax.Array
    conditions: jax.Array
    window_s: float = eqx.field(static=True)
    axis: tuple | None = eqx.field(static=True, default=None)


def grid(freqs_hz, amps_g, exclude=()):
    """All (f, A) pairs of two lists, less `exclude` — e.g. the held-out test conditions."""
    ex = {(float(f), float(a)) for f, a in exclude}
    return [
        (float(f), float(a)) for f in freqs_hz for a in amps_g if (float(f), float(a)) not in ex
    ]


def training_set(
    imu: FogImu, conditions, *, key: jax.Array, fs: float = 200.0, window_s: float = 2.0,
    lead_s: float = 20.0, on_s: float = 200.0, off_s: float = 100.0, lat_deg: float = 45.0,
    attitude_deg=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0), model: FogImu | None = None,
) -> TrainingSet:  # fmt: skip
    """Simulate one rest → (f, A) → rest sequence per condition of `conditions` (list of
    (f [Hz], A [g])) and a static record with independent noise, and cut both into windows
    (module docstring). `imu` is the true IMU; `model` is the IMU as the user knows it (its
    triad models, e.g. from [`calibrated`][hrgjax.fog.study.calibrated]), which maps the
    outputs to the body frame (default: `imu` itself)."""
    require_x64("fog.compensation.training_set")
    conditions = [(float(f), float(a)) for f, a in conditions]
    if not conditions:
        raise ValueError("conditions must list at least one (frequency Hz, amplitude g) pair")
    axis = _unit(axis)
    proc = imu if model is None else model
    feats, samples, truths, raws = [], [], [], []
    keys = jax.random.split(key, 2 * len(conditions))
    for i, (f, a) in enumerate(conditions):
        sch = VibrationSchedule.on_off([(f, a)], on_s, off_s, lead_s, axis)
        rest = VibrationSchedule.constant(0.0, 0.0, sch.duration_s, axis)
        kw = dict(fs=fs, lat_deg=lat_deg, attitude_deg=attitude_deg)
        vib = simulate(imu, sch, key=keys[2 * i], **kw)
        st = simulate(imu, rest, key=keys[2 * i + 1], **kw)
        with warnings.catch_warnings():  # refused below in one line
            warnings.simplefilter("ignore", EdgeToneWarning)
            feats.append(vibration_features(to_body(proc.accel, vib.accel), fs, window_s, axis))
        if np.isnan(np.asarray(feats[-1])).any():
            raise ValueError(
                f"conditions: ({f:g} Hz, {a:g} g) peaks within 2 bins of DC or 1 of Nyquist at "
                f"resolution 1/window_s = {1 / window_s:g} Hz, fs = {fs:g} Hz (features not "
                "measurable); use a longer window_s or a higher fs"
            )
        samples.append(error_samples(proc, vib, st, window_s))
        truths.append(to_body(proc.gyro, window_means(vib.gyro_error, fs, window_s)))
        raws.append(window_means(vib.gyro, fs, window_s))
    ref = reference_output(proc, vib)
    return TrainingSet(
        jnp.stack(feats), jnp.stack(samples), jnp.stack(truths), jnp.stack(raws), ref,
        jnp.asarray(conditions), float(window_s), axis,
    )  # fmt: skip


def reference_output(imu: FogImu, rec: VibrationRecord):
    """Static model output (3,) [rad/s, sensor axes] at the record's attitude: M ω_b + β."""
    w_b = rec.c_bn.T @ earth_rate_ned(jnp.asarray(rec.lat))
    return imu.gyro.sensor(w_b)


def _sample_loss(params, data, idx):
    """`fit`'s loss on sequences `idx`: mean squared error of the predicted samples, in units
    of `y_scale`."""
    c = eqx.combine(params, data["frozen"])
    pred = jax.vmap(c.normalised)(data["x"][idx])
    return jnp.mean((pred - data["y"][idx] / c.y_scale) ** 2)


def _output_loss(params, data, idx):
    """`fit_end_to_end`'s loss on sequences `idx`: the compensated raw output against the
    static reference, in units of `y_scale`."""
    c = eqx.combine(params, data["frozen"])
    pred = jax.vmap(c)(data["x"][idx])
    resid = data["raw"][idx] - to_sensor(data["gyro"], pred) - data["ref"].reshape(1, 1, 3)
    return jnp.mean((resid / c.y_scale) ** 2)


def _scores(loss, params, data):
    """Per epoch: the loss over all training sequences and, with a test set, its sample
    loss and its RMSE against the noise-free error [rad/s]."""
    out = [loss(params, data, jnp.arange(data["x"].shape[0]))]
    test = data["test"]
    if test is not None:
        c = eqx.combine(params, data["frozen"])
        out.append(
            jnp.mean((jax.vmap(c.normalised)(test.features) - test.samples / c.y_scale) ** 2)
        )
        out.append(rmse(c, test, extrapolate=True))
    return jnp.stack(out)


def _sample_scores(params, data):
    return _scores(_sample_loss, params, data)


def _output_scores(params, data):
    return _scores(_output_loss, params, data)


def fit(
    comp: VibrationCompensator, train: TrainingSet, *, key: jax.Array, epochs: int = 120,
    batch_size: int = 2, learning_rate: float | None = None, test: TrainingSet | None = None,
):  # fmt: skip
    """Train `comp` on the vibration-error samples of `train` (mean squared error in units of
    `y_scale`). **Returns** `(trained, history)`: `history` has the per-epoch `train` loss
    and, with `test`, the `test` loss and RMSE against the noise-free truth [rad/s]."""
    require_x64("fog.compensation.fit")
    data = dict(x=train.features, y=train.samples)
    return _fit(comp, _sample_loss, _sample_scores, data, train, test, key, epochs, batch_size,
                learning_rate)  # fmt: skip


def fit_end_to_end(
    comp: VibrationCompensator, imu: FogImu, train: TrainingSet, *, key: jax.Array,
    epochs: int = 120, batch_size: int = 2, learning_rate: float | None = None,
    test: TrainingSet | None = None,
):  # fmt: skip
    """Train `comp` through the IMU output: the loss is the compensated raw gyro output —
    window means, prediction mapped to sensor axes by the gyro triad's model and subtracted —
    against the static model's reference output, in units of `y_scale`. No static record and
    no error samples are formed. **Returns** `(trained, history)` as [`fit`][hrgjax.fog.compensation.fit]."""
    require_x64("fog.compensation.fit_end_to_end")
    data = dict(x=train.features, raw=train.raw, ref=train.reference, gyro=imu.gyro)
    return _fit(comp, _output_loss, _output_scores, data, train, test, key, epochs, batch_size,
                learning_rate)  # fmt: skip


LEARNING_RATE = {"elman": 1e-2, "mlp": 5e-2}
"""Default peak learning rates: the best of (1e-2, 2e-2, 5e-2) for each kind in a scan over
four seeds on the default IMU's grid (issue 7 development; at 1e-2 the MLP does not converge
in 120 epochs, at 5e-2 the Elman network is unstable)."""


def _window(window_s) -> float:
    w = float(window_s)
    if not (np.isfinite(w) and w > 0):
        raise ValueError(f"window_s must be a finite duration > 0 s; got {window_s!r}")
    return w


def _scale(name: str, x, shape: tuple, form: str):
    """A normalisation constant as a float64 array of `shape`, every value finite and > 0,
    or a one-line `ValueError` naming `name` and its `form`."""
    v = host_value(x)
    if v is None:  # traced: passes unchecked
        return jnp.asarray(x, float)
    if v.shape != shape or not (np.isfinite(v).all() and (v > 0).all()):
        raise ValueError(f"{name} must be {'two' if shape else 'one'} finite number"
                         f"{'s' if shape else ''} > 0 {form}; got {v.tolist()}")  # fmt: skip
    return v


def _unit(axis) -> tuple:
    """A vibration direction as a unit 3-tuple, or a one-line `ValueError`."""
    u = np.asarray(axis, dtype=float)
    if u.shape != (3,) or not np.isfinite(u).all() or not np.linalg.norm(u) > 0:
        raise ValueError(f"axis must be a non-zero finite 3-vector (body frame); got {axis!r}")
    return tuple((u / np.linalg.norm(u)).tolist())


def _box(feature_range) -> tuple:
    """A feature range as ((f_min, f_max), (A_min, A_max)) floats, or a one-line `ValueError`."""
    r = np.asarray(feature_range, dtype=float)
    if r.shape != (2, 2) or np.isnan(r).any():
        raise ValueError(f"feature_range must be ((f_min, f_max) Hz, (A_min, A_max) g); "
                         f"got {feature_range!r}")  # fmt: skip
    return tuple(tuple(float(v) for v in row) for row in r)


def _trained_box(features) -> tuple:
    """The range of the vibrating (A > 0) windows of `features` (..., 2); an empty one,
    (inf, -inf), when none vibrates."""
    x = np.asarray(features, dtype=float).reshape(-1, 2)
    x = x[x[:, 1] > 0]
    lo, hi = (x.min(0), x.max(0)) if len(x) else (np.full(2, np.inf), np.full(2, -np.inf))
    return tuple(zip(lo.tolist(), hi.tolist(), strict=True))


def _same_axis(trained, axis, what: str):
    """`axis` checked against the vibration direction `trained` a compensator was trained on
    (`trained` when None; None when neither is known). A direction and its opposite give the
    same features."""
    if axis is None:
        return trained
    u = _unit(axis)
    if trained is not None and not (
        np.allclose(u, trained, rtol=0.0, atol=1e-9)
        or np.allclose(u, np.negative(trained), rtol=0.0, atol=1e-9)
    ):
        shown = lambda v: "(" + ", ".join(f"{c:.4g}" for c in v) + ")"  # noqa: E731
        raise ValueError(
            f"{what}: axis={shown(u)}, but the compensator was trained on features along "
            f"{shown(trained)} (the amplitude it sees depends on the direction); use its axis"
        )
    return u


def _same_window(comp: VibrationCompensator, window_s, what: str) -> float:
    """`window_s` checked against the window `comp` was trained on (its own when None)."""
    if window_s is None:
        if comp.window_s is None:
            raise ValueError(f"{what}: give window_s (the compensator has not been trained)")
        return comp.window_s
    w = _window(window_s)
    if comp.window_s is not None and not np.isclose(w, comp.window_s, rtol=1e-9, atol=0.0):
        raise ValueError(
            f"{what}: window_s={w:g} s, but the compensator was trained on {comp.window_s:g}-s "
            "windows (its Elman context steps once per window); use its window_s"
        )
    return w


def _replaced(comp: VibrationCompensator, **fields):
    """A copy of `comp` with `fields` set (static fields, which `eqx.tree_at` cannot set)."""
    new = object.__new__(type(comp))
    for f in dataclasses.fields(comp):
        object.__setattr__(new, f.name, fields.get(f.name, getattr(comp, f.name)))
    return new


def _with_window(comp: VibrationCompensator, window_s: float, axis=None, box=None):
    """A copy of `comp` that records the window (and, when known, the vibration direction
    and feature range) it was trained on."""
    new = {"window_s": _window(window_s)}
    if axis is not None:
        new["axis"] = _unit(axis)
    if box is not None:
        new["feature_range"] = _box(box)
    return _replaced(comp, **new)


def _fit(comp, loss, scores, data, train, test, key, epochs, batch_size, learning_rate):
    """`comp` trained by Adam on `loss` over `data` (`nn.train.adam_epochs`: one compiled
    program per loss, shapes and settings; the data, weights, key and learning rate are
    its arguments, so a second fit of the same shapes compiles nothing)."""
    _same_window(comp, train.window_s, "fit")
    axis = _same_axis(comp.axis, train.axis, "fit")
    if test is not None:
        _same_window(comp, test.window_s, "fit (test set)")
        _same_axis(axis, test.axis, "fit (test set)")
    if learning_rate is None:
        learning_rate = LEARNING_RATE[comp.kind]
    # the static fields the training does not read (a trained compensator's window, axis
    # and range: set again below) are cleared, so that a refit runs the same program; the
    # normalisation constants are not trained
    bare = _replaced(comp, window_s=None, axis=None, feature_range=None)
    params, frozen = eqx.partition(bare, eqx.is_inexact_array)
    scales = (comp.x_scale, comp.y_scale)
    params = eqx.tree_at(lambda c: (c.x_scale, c.y_scale), params, replace=(None, None))
    frozen = eqx.tree_at(lambda c: (c.x_scale, c.y_scale), frozen, replace=scales,
                         is_leaf=lambda x: x is None)  # fmt: skip
    p, hist = adam_epochs(
        loss, scores, params, data | {"frozen": frozen, "test": test}, train.features.shape[0],
        key=key, epochs=epochs, batch_size=batch_size, learning_rate=learning_rate,
    )  # fmt: skip
    trained = eqx.combine(p, frozen)
    hist = np.asarray(hist)  # checked and split on the host: no eager device programs
    if not np.isfinite(hist[:, 0]).all():
        bad = int(np.argmax(~np.isfinite(hist[:, 0])))
        raise RuntimeError(
            f"training diverged: the loss is not finite from epoch {bad} (lower learning_rate)"
        )
    history = {"train": device(hist[:, 0])}
    if test is not None:
        history |= {"test": device(hist[:, 1]), "test_rmse": device(hist[:, 2])}
    return _with_window(trained, train.window_s, axis, _trained_box(train.features)), history


def rmse(comp: VibrationCompensator | None, data: TrainingSet, *, extrapolate=False, margin=0.01):
    """RMS over sequences, windows and axes of prediction − noise-free error [rad/s];
    `comp=None` is no compensation (the error itself). The prediction is what
    [`compensate`][hrgjax.fog.compensation.compensate] applies: zero in windows outside
    `comp.feature_range` unless `extrapolate`."""
    if comp is None:
        return jnp.sqrt(jnp.mean(data.truth**2))
    _same_window(comp, data.window_s, "rmse")
    _same_axis(comp.axis, data.axis, "rmse")
    pred, _ = _predict(comp, data.features, extrapolate, margin)
    return jnp.sqrt(jnp.mean((pred - data.truth) ** 2))


def _predict(comp: VibrationCompensator, feats, extrapolate: bool, margin: float, off=None):
    """Prediction on features (K, 2) or (S, K, 2) and the in-range mask: windows out of range
    (or `off` the trained axis) are fed to the network as rest (its context never sees them)
    and predict zero. NaN features (not measurable) are out even with `extrapolate`."""
    call = comp if feats.ndim == 2 else jax.vmap(comp)
    inside, x = _gate(comp, feats, off, extrapolate=extrapolate, margin=margin)
    return jnp.where(inside[..., None], call(x), 0.0), inside


@fused(static_argnames=("extrapolate", "margin"))
def _gate(comp, feats, off, *, extrapolate, margin):
    """`_predict`'s mask and the features fed to the network (rest outside it), as one
    compiled program (eagerly a dozen operations compiled one by one on a first call)."""
    valid = jnp.all(~jnp.isnan(feats), axis=-1)
    feats = jnp.where(valid[..., None], feats, 0.0)
    if extrapolate:
        return valid, feats
    inside = comp.in_range(feats, margin) & valid
    inside = inside if off is None else inside & ~off
    return inside, jnp.where(inside[..., None], feats, 0.0)


AXIS_TOL_DEG = 8.0
"""Largest angle [°] between a window's vibration direction and the compensator's trained
axis that [`compensate`][hrgjax.fog.compensation.compensate] still compensates: the amplitude
along the axis then understates the vibration's by 1 − cos 8° = 1 %, the default range
margin."""


class Compensated(eqx.Module):
    """What `compensate` returns; unpacks (and indexes) as the pair `(gyro, prediction)` it
    returned before. **Fields:** `gyro` (N, 3) [rad/s, sensor axes]; `prediction` (K, 3)
    [rad/s, body frame], zero out of range; `in_range` (K,) bool: the windows compensated."""

    gyro: jax.Array
    prediction: jax.Array
    in_range: jax.Array

    def __iter__(self):  # the pair returned before
        return iter((self.gyro, self.prediction))

    def __getitem__(self, i):
        return (self.gyro, self.prediction)[i]

    @property
    def n_out_of_range(self) -> int:
        """Windows passed through uncompensated: outside the trained range, vibrating off
        the trained axis, or not measurable (NaN features: a tone too near DC or Nyquist)."""
        return int(jnp.sum(~self.in_range))


def compensate(
    comp: VibrationCompensator, imu: FogImu, record: VibrationRecord, *, window_s=None,
    axis=None, extrapolate: bool = False, margin: float = 0.01, ac_coupled: bool = False,
) -> Compensated:  # fmt: skip
    """Raw gyro output (N, 3) [rad/s, sensor axes] less the predicted vibration error:
    features from the misalignment-compensated accelerometers over windows of `window_s`
    (default: the window `comp` was trained on; another one is refused) along `axis`
    (default: the vibration direction `comp` was trained on, `comp.axis`; another one is
    refused — the amplitude along (1, 1, 1)/√3 of a vibration along it is √3 times that along
    its largest body axis; a compensator without a recorded axis uses the body axis with the
    largest AC power), the prediction per window mapped to sensor axes and held over its
    window (the last window's prediction covers a partial tail).

    **Out of range.** A vibrating window whose f or A lies outside `comp.feature_range`
    (each bound widened by `margin`, relative: `VibrationCompensator.in_range`) is passed
    through uncompensated — its prediction is zero and the network is fed rest instead, so
    its context does not carry the extrapolation on — and counted: outside its training
    range the network made the error worse than none (docs/fog.md). So is a vibrating window
    whose direction ([`off_axis`][hrgjax.fog.spectrum.off_axis]) lies more than
    [`AXIS_TOL_DEG`][hrgjax.fog.compensation.AXIS_TOL_DEG] from the axis the features are
    taken along — along another axis they read rest or a smaller amplitude — with one
    `UserWarning` naming both directions (checked when the axis is known; a window without
    one direction, such as broadband noise, is left to the range rule). So is a
    window whose features are NaN (a tone too near DC or Nyquist to measure,
    [`vibration_features`][hrgjax.fog.spectrum.vibration_features]). `extrapolate=True`
    applies the network everywhere but there. `ac_coupled=True`: the record's accelerometers
    carry no gravity (AC-coupled), taken as m/s² (as
    [`vibration_features`][hrgjax.fog.spectrum.vibration_features]'). **Returns** a
    [`Compensated`][hrgjax.fog.compensation.Compensated], which unpacks as
    `(gyro (N, 3), prediction (K, 3) body frame)`."""
    window_s = _same_window(comp, window_s, "compensate")
    axis = _same_axis(comp.axis, axis, "compensate")
    body = to_body(imu.accel, record.accel)
    feats = vibration_features(body, record.fs, window_s, axis, ac_coupled=ac_coupled)
    off = None
    if axis is not None:
        off, d, angle = off_axis(body, record.fs, axis, window_s, AXIS_TOL_DEG,
                                 ac_coupled=ac_coupled)  # fmt: skip
        bad = concrete_value(off)
        if bad is not None and bad.any() and not extrapolate:
            i = int(np.argmax(bad))
            shown = lambda v: "(" + ", ".join(f"{c:.3g}" for c in v) + ")"  # noqa: E731
            warnings.warn(
                f"compensate: {int(bad.sum())} of {bad.size} windows vibrate off the trained "
                f"axis {shown(axis)} — window {i} along {shown(concrete_value(d)[i])}, "
                f"{concrete_value(angle)[i]:.3g}° from it; passed through uncompensated "
                "(n_out_of_range)",
                stacklevel=2,
            )
    pred, inside = _predict(comp, feats, extrapolate, margin, off)
    m = int(round(window_s * record.fs))
    n = record.gyro.shape[0]
    held = jnp.repeat(to_sensor(imu.gyro, pred), m, axis=0)
    tail = n - held.shape[0]
    if tail > 0:
        held = jnp.concatenate([held, jnp.repeat(held[-1:], tail, axis=0)])
    return Compensated(record.gyro - held, pred, inside)


__all__ = [
    "KINDS", "VibrationCompensator", "TrainingSet", "grid", "training_set", "fit",
    "fit_end_to_end", "rmse", "AXIS_TOL_DEG", "Compensated", "compensate", "imu_log",
    "align_record", "heading_limit_deg",
]  # fmt: skip
