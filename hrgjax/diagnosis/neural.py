r"""Neural fault detectors of seed 002 (§3 of the thesis), trained on simulated complexes.

All detectors look at the last `taps` = 20 pairwise measurements
([`complex.measurements`][hrgjax.diagnosis.complex.measurements]) and name the *transition*
S0 → S_i (the onset of a fault in INS i) or none; [`latch`][hrgjax.diagnosis.neural.latch]
turns these into the state trace S0 … S_n the thesis plots (a fault, once named, stays).
A window's level, trend and curvature carry no information about a fault — they are dominated by each
INS's own Markov and Schuler errors, and a window long after an onset looks like a healthy
INS with a larger drift — so the inputs are the window's shape with its level, trend and curvature
removed (second differences less their mean), in units of the nominal sensor error
([`features`][hrgjax.diagnosis.neural.features]).

Training data come from the simulator: healthy complexes (their own keys), with fault
onsets added by linearity — the error model is linear, so a complex with a fault of size e
in INS i is the healthy one plus e times the noise-free unit response
([`onset_templates`][hrgjax.diagnosis.neural.onset_templates]) — at random positions and
sizes ([`training_windows`][hrgjax.diagnosis.neural.training_windows]).

Detectors (each has `classify(x) → (N,)` onset classes, 0 = none; a concrete `x` must be
finite — a NaN window was named a confident class, the arg-max over NaN scores — a traced
one, under the caller's `jit`/`vmap`, passes unchecked):

- [`PNNBank`][hrgjax.diagnosis.neural.PNNBank]: one two-class probabilistic neural network
  per transition S0 → S_i (alg. 3.1.1);
- [`PNNDirect`][hrgjax.diagnosis.neural.PNNDirect]: one PNN over all classes (alg. 3.1.2);
- [`SOMDetector`][hrgjax.diagnosis.neural.SOMDetector]: a Kohonen map, self-organised,
  then labelled (alg. 3.2.1);
- [`MLPClassifier`][hrgjax.diagnosis.neural.MLPClassifier]: one tapped-delay MLP per fault
  state, 20 and 10 tanh hidden units, sigmoid output, Rprop (alg. 3.4.1);
- [`MLPPredictor`][hrgjax.diagnosis.neural.MLPPredictor]: one MLP per hypothesis (50 tanh
  hidden, linear output) predicting the next measurement, trained by Levenberg–Marquardt
  (optimistix); the hypothesis with the least residual wins (alg. 3.3.1). The hypotheses
  are S0 and an onset per INS *and sign*
  ([`predictor_sets`][hrgjax.diagnosis.neural.predictor_sets]): at an onset in the
  predicted step the window holds nothing of the fault, so its sign is only in that step.
"""

from __future__ import annotations

import operator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from .._checks import (
    check_finite_host,
    concrete_value,
    describe,
    is_finite_real,
    numeric_problem,
    whole_number,
)
from .._compiled import fused
from .._least_squares import least_squares
from ..ins.platform import Fault, PlatformINS, simulate
from ..nn.mlp import MLP
from ..nn.pnn import PNN, check_labels, check_n_classes, check_samples
from ..nn.som import SOM
from ..nn.tapped_delay import windows
from ..nn.train import train_module
from .complex import measurements

TAPS = 20
"""Tapped-delay length of seed 002's networks."""


def features(w, unit: float = 1e-7):
    """Detector inputs from measurement windows `w` (..., taps, m): second differences along
    the window minus their mean (level, trend and curvature removed), over `unit`, flattened
    → (..., (taps − 2)·m)."""
    w = jnp.asarray(w, float)
    if w.ndim < 2 or w.shape[-2] < 3:
        raise ValueError(f"w must be windows (..., taps >= 3, m); got shape {w.shape}")
    _check_unit(unit)
    d = jnp.diff(w, n=2, axis=-2)
    d = (d - jnp.mean(d, axis=-2, keepdims=True)) / unit
    return d.reshape(*d.shape[:-2], -1)


def onset_templates(
    ins: PlatformINS, sensor: str, dt: float, *, n_ins: int = 3, length: int = TAPS + 1
):
    """The noise-free measurements after a unit fault (sensor units) in each INS, from the
    first measurement it changes: `(n_ins, length, m)`."""
    lead = 4
    fault = Fault.on(sensor, 1.0, lead * dt)
    _, _, nav1 = simulate(ins, dt=dt, n_steps=length + lead + 4, key=None, fault=fault)
    out = []
    for i in range(n_ins):
        nav = jnp.zeros((n_ins,) + nav1.shape).at[i].set(nav1)
        z = np.asarray(measurements(nav, dt, sensor, ins, pairs=tuple(range(n_ins - 1))))
        k_on = int(np.argmax(np.any(z != 0.0, axis=-1)))
        out.append(z[k_on : k_on + length])
    return jnp.asarray(np.stack(out))


def training_windows(
    z_healthy,
    templates,
    key: jax.Array,
    n: int,
    *,
    sizes: tuple[float, float],
    p_fault: float = 0.5,
    taps: int = TAPS,
    onset_within_last: int | None = None,
    signed: bool = True,
):
    """`n` windows of `taps` + 1 measurements cut from healthy complexes `z_healthy`
    (runs, K, m); a share `p_fault` carries a fault onset in INS i (uniform) of size
    U(`sizes`) — with a random sign (±, even odds) when `signed`, as a sensor error may jump
    either way — at window position q (uniform in 1 … taps, or over the last
    `onset_within_last` positions). Trained on positive sizes only, the detectors named
    the wrong INS for a negative fault (its signature in the pairs is another INS's, of
    the other sign). **Returns** `(windows (n, taps+1, m), fault class (n,) 0 = none,
    onset position q (n,), 0 where none)`."""
    z = jnp.asarray(z_healthy, float)
    templates = jnp.asarray(templates, float)
    n = whole_number("n", n, "an integer >= 0 (windows)")
    taps = whole_number("taps", taps, "an integer >= 1 (samples)")
    if n < 0 or taps < 1:
        raise ValueError(f"n must be >= 0 and taps >= 1; got n={n}, taps={taps}")
    if z.ndim != 3 or z.shape[1] < taps + 1:
        raise ValueError(f"z_healthy must be (runs, K >= {taps + 1}, m); got {z.shape}")
    if templates.ndim != 3 or templates.shape[0] < 1 or templates.shape[2] != z.shape[2]:
        raise ValueError(f"templates must be (n_ins, L, m = {z.shape[2]}); got {templates.shape}")
    check_finite_host("z_healthy", z)
    check_finite_host("templates", templates)
    if onset_within_last is not None:
        last = whole_number("onset_within_last", onset_within_last, f"an integer in [1, {taps}]")
        if not 1 <= last <= taps:
            raise ValueError(f"onset_within_last must be an integer in [1, {taps}]; got {last}")
    if isinstance(sizes, str | bytes) or not hasattr(sizes, "__len__") or len(sizes) != 2:
        raise ValueError(f"sizes must be (low, high), two fault sizes; got {describe(sizes)}")
    lo, hi = (concrete_value(v) for v in sizes)
    if lo is not None and hi is not None and not (np.isfinite([lo, hi]).all() and lo <= hi):
        raise ValueError(f"sizes must be (low, high), finite, low <= high; got {describe(sizes)}")
    p = concrete_value(p_fault)
    if p is not None and not (np.ndim(p) == 0 and 0.0 <= p <= 1.0):
        raise ValueError(f"p_fault must be a probability in [0, 1]; got {describe(p_fault)}")
    return _training_windows(z, templates, key, n, sizes=sizes, p_fault=p_fault, taps=taps,
                             onset_within_last=onset_within_last, signed=signed)  # fmt: skip


@fused(static_argnames=("n", "taps", "onset_within_last", "signed"))
def _training_windows(z, templates, key, n, *, sizes, p_fault, taps, onset_within_last, signed):
    """`training_windows` past its checks, as one compiled program."""
    runs, k_len, m = z.shape
    n_ins = templates.shape[0]
    kr, kp, kf, kc, kq, ks = jax.random.split(key, 6)
    r = jax.random.randint(kr, (n,), 0, runs)
    p = jax.random.randint(kp, (n,), 0, k_len - taps)
    idx = p[:, None] + jnp.arange(taps + 1)[None, :]
    w = z[r[:, None], idx]
    faulty = jax.random.uniform(kf, (n,)) < p_fault
    c = jnp.where(faulty, jax.random.randint(kc, (n,), 1, n_ins + 1), 0)
    lo = 1 if onset_within_last is None else taps + 1 - int(onset_within_last)
    q = jax.random.randint(kq, (n,), max(lo, 1), taps + 1)
    q = jnp.where(faulty, q, 0)
    e = jax.random.uniform(ks, (n,), minval=sizes[0], maxval=sizes[1])
    if signed:
        e = jnp.where(jax.random.bernoulli(jax.random.fold_in(ks, 1), 0.5, (n,)), e, -e)
    # template sample j lands at window position q + j
    j = jnp.arange(taps + 1)[None, :] - q[:, None]
    tmpl = templates[jnp.maximum(c - 1, 0)[:, None], jnp.clip(j, 0, templates.shape[1] - 1)]
    add = jnp.where(((j >= 0) & faulty[:, None])[..., None], tmpl, 0.0)
    return w + e[:, None, None] * add, c, q


@fused
def classifier_set(w, c, q, unit: float = 1e-7):
    """Classifier inputs and labels from [`training_windows`][hrgjax.diagnosis.neural.training_windows]:
    the features of the last `taps` samples, labelled with the fault class (an onset at any
    position 1 … taps changes them: the fault's first sample, half a step under the
    zero-order hold, is at position q)."""
    del q
    return features(w[:, 1:], unit), jnp.asarray(c)


def latch(classes, confirm: int = 1):
    """State trace from per-step onset classes (..., K): S0 until a nonzero class has been
    named on `confirm` consecutive steps, that class from then on (faults do not clear).
    `confirm` > 1 trades that many steps of detection delay for immunity to isolated
    misclassifications, which a latched decision would otherwise keep for good."""
    whole_number("latch: confirm", confirm, "an integer >= 1 (steps)", minimum=1)
    form = "per-step onset classes (..., K), whole numbers >= 0 (0 = no fault)"
    problem = numeric_problem(classes, bools=True)
    if problem is not None:
        raise TypeError(f"latch: classes must be {form}; got {problem}")
    v = concrete_value(classes)  # traced classes pass (no run-time check)
    if v is not None and v.ndim >= 1 and v.dtype.kind in "fi":  # 1.5 latched as a class
        bad = ~(np.isfinite(v) & (v == np.round(v)) & (v >= 0))
        if bad.any():
            i = tuple(int(k) for k in np.argwhere(bad)[0])
            raise ValueError(f"latch: classes must be {form}; got {v[i]:g} at index {i}")
    return _latch(classes, confirm)


@fused(static_argnames="confirm")
def _latch(classes, confirm):
    c = jnp.asarray(classes)
    if c.ndim < 1:
        raise ValueError(f"latch: classes must be per-step onset classes (..., K); got shape "
                         f"{c.shape}")  # fmt: skip
    if int(confirm) > c.shape[-1]:  # never named on so many steps: S0 throughout
        return jnp.zeros_like(c)
    ok = c != 0
    for lag in range(1, int(confirm)):
        same = jnp.concatenate([jnp.zeros(c.shape[:-1] + (lag,), bool),
                                c[..., lag:] == c[..., :-lag]], axis=-1)  # fmt: skip
        ok = ok & same
    first = jnp.argmax(ok, axis=-1)
    any_ = jnp.any(ok, axis=-1)
    val = jnp.take_along_axis(c, first[..., None], axis=-1)
    k = jnp.arange(c.shape[-1]).reshape((1,) * (c.ndim - 1) + (-1,))
    return jnp.where(any_[..., None] & (k >= first[..., None]), val, 0)


def _check_unit(unit) -> None:
    """Refuse a concrete `unit` (the features' scale) that is not finite and > 0: 0 gave
    inf features, a negative one flipped their sign; a traced one passes."""
    if numeric_problem(unit) is not None:
        raise TypeError(f"unit must be a number > 0 (sensor units); got {describe(unit)}")
    if not isinstance(unit, jax.core.Tracer) and not (is_finite_real(unit) and unit > 0):
        raise ValueError(f"unit must be a finite number > 0 (sensor units); got {describe(unit)}")


def _check_threshold(threshold, low: float = 0.0) -> float:
    """`threshold` (a posterior or sigmoid output a class must exceed) as a float in
    [`low`, 1), or a one-line error (2 or NaN named no fault ever, silently)."""
    if not (is_finite_real(threshold) and low <= threshold < 1.0):
        kind = TypeError if numeric_problem(threshold) is not None else ValueError
        raise kind(f"threshold must be a number in [{low:g}, 1); got {describe(threshold)}")
    return float(threshold)


def _threshold_value(threshold):
    """A detector's `threshold` field as a float64 0-d array — a value, so a sweep over it
    compiles nothing (a static float compiled `classify` again per value) — checked by
    `_check_threshold` where it is known; a traced one passes."""
    return jnp.asarray(threshold if _is_traced(threshold) else _check_threshold(threshold), float)


def _is_traced(x) -> bool:
    return isinstance(x, jax.core.Tracer)


def _check_fault_classes(y, n_classes):
    """`n_classes` >= 2 (none and at least one fault) and `y` integer labels in
    [0, n_classes), or a one-line error: a bank of no detector raised "Need at least one
    array to stack", and a label out of range trained a detector on no fault."""
    n_classes = check_n_classes(n_classes)
    if n_classes < 2:
        raise ValueError(f"n_classes must be >= 2 (none and at least one fault); got {n_classes}")
    return n_classes, check_labels("y", y, n_classes)


def _scores_to_class(p_fault, threshold):
    """(N, n_faults) posterior of each fault class → class (0 when none passes)."""
    best = jnp.argmax(p_fault, axis=-1)
    top = jnp.max(p_fault, axis=-1)
    return jnp.where(top > threshold, best + 1, 0)


class PNNDirect(eqx.Module):
    """One PNN over the classes none, onset in INS 1 … n (alg. 3.1.2); a fault class is named
    when its posterior exceeds `threshold`."""

    pnn: PNN
    threshold: jax.Array = eqx.field(converter=_threshold_value, default=0.9)

    @classmethod
    def fit(cls, x, y, n_classes: int, sigma: float, threshold: float = 0.9):
        n_classes, _ = _check_fault_classes(y, n_classes)
        return cls(PNN.fit(x, y, n_classes, sigma), _threshold_value(threshold))

    def classify(self, x):
        """Onset class of each feature row of `x` (N, d), finite, → (N,) (0 = none)."""
        x = check_samples("x (PNNDirect query features)", x, self.pnn.centres.shape[1])
        check_finite_host("x (PNNDirect query features)", x)
        return self._classify(x)

    @fused
    def _classify(self, x):
        ls = jax.vmap(self.pnn.log_scores)(jnp.asarray(x, float))
        post = jax.nn.softmax(ls, axis=-1)
        return _scores_to_class(post[:, 1:], self.threshold)


class PNNBank(eqx.Module):
    """One two-class PNN per transition S0 → S_i (alg. 3.1.1); the transition whose 'yes'
    posterior is largest, if above `threshold`."""

    pnns: list[PNN]
    threshold: jax.Array = eqx.field(converter=_threshold_value, default=0.9)

    @classmethod
    def fit(cls, x, y, n_classes: int, sigma: float, threshold: float = 0.9):
        n_classes, y = _check_fault_classes(y, n_classes)
        threshold = _threshold_value(threshold)  # a traced one (a sweep) passes
        pnns = [PNN.fit(x, (y == i).astype(int), 2, sigma) for i in range(1, n_classes)]
        return cls(pnns, threshold)

    def classify(self, x):
        """Onset class of each feature row of `x` (N, d), finite, → (N,) (0 = none)."""
        x = check_samples("x (PNNBank query features)", x, self.pnns[0].centres.shape[1])
        check_finite_host("x (PNNBank query features)", x)
        return self._classify(x)

    @fused
    def _classify(self, x):
        x = jnp.asarray(x, float)
        yes = [jax.nn.softmax(jax.vmap(p.log_scores)(x), axis=-1)[:, 1] for p in self.pnns]
        return _scores_to_class(jnp.stack(yes, axis=-1), self.threshold)


class SOMDetector(eqx.Module):
    """A labelled Kohonen map (alg. 3.2.1)."""

    som: SOM

    @classmethod
    def fit(cls, x, y, n_classes: int, *, key, shape=(10, 10), steps: int = 20000):
        som = SOM.train(x, shape, key=key, steps=steps)
        return cls(som.label(x, y, n_classes))

    def classify(self, x):
        """Onset class of each feature row of `x` (N, d), finite, → (N,) (0 = none)."""
        check_finite_host("x (SOMDetector query features)", x)
        return self._classify(x)

    @fused
    def _classify(self, x):
        return self.som.predict(x)


class MLPClassifier(eqx.Module):
    """One tapped-delay MLP per fault state, hidden 20 and 10 (tanh), sigmoid output
    (alg. 3.4.1), trained with Rprop on the cross-entropy; the largest output above
    `threshold` names the class. (The networks are stored up to their output's logit; the
    sigmoid is applied in [`outputs`][hrgjax.diagnosis.neural.MLPClassifier.outputs].)"""

    nets: list[MLP]
    threshold: jax.Array = eqx.field(converter=_threshold_value, default=0.5)

    @classmethod
    def fit(cls, x, y, n_classes: int, *, key, hidden=(20, 10), steps: int = 1000,
            threshold=0.5):  # fmt: skip
        x, y = jnp.asarray(x, float), jnp.asarray(y)
        if x.ndim != 2 or y.shape != (x.shape[0],) or x.shape[0] < 1:
            raise ValueError(f"x must be (n, d) and y (n,), n >= 1; got {x.shape}, {y.shape}")
        n_classes, y = _check_fault_classes(y, n_classes)
        threshold = _threshold_value(threshold)  # a traced one (a sweep) passes
        check_finite_host("x (MLPClassifier training features)", x)
        nets = []
        for i, k in zip(range(1, n_classes), jax.random.split(key, n_classes - 1), strict=True):
            net = MLP((x.shape[1], *hidden, 1), key=k)
            # a module-level loss with the data as traced arguments: one compiled training
            # program for every net and every later fit of the same shapes
            loss = eqx.Partial(_classifier_loss, x=x, target=(y == i).astype(x.dtype))
            nets.append(
                train_module(net, loss, steps, learning_rate=0.01, max_step=0.5, compile_once=True)
            )
        return cls(nets, threshold)

    def outputs(self, x):
        """Sigmoid output of every network for the feature rows of `x` (N, d), finite:
        (N, n_faults)."""
        x = check_samples("x (MLPClassifier query features)", x, self.nets[0].layers[0].in_features)
        check_finite_host("x (MLPClassifier query features)", x)
        return self._outputs(x)

    @fused
    def _outputs(self, x):
        x = jnp.asarray(x, float)
        return jax.nn.sigmoid(jnp.stack([jax.vmap(n)(x)[:, 0] for n in self.nets], axis=-1))

    def classify(self, x):
        """Onset class of each feature row of `x` (N, d), finite, → (N,) (0 = none)."""
        x = check_samples("x (MLPClassifier query features)", x, self.nets[0].layers[0].in_features)
        check_finite_host("x (MLPClassifier query features)", x)
        return self._classify(x)

    @fused
    def _classify(self, x):
        return _scores_to_class(self._outputs(x), self.threshold)


def _classifier_loss(m, *, x, target):
    """Mean sigmoid cross-entropy of network `m`'s logits on the rows of `x` against
    `target` (0/1)."""
    logit = jax.vmap(m)(x)[:, 0]
    return jnp.mean(optax.sigmoid_binary_cross_entropy(logit, target))


@fused
def predictor_set(w, unit: float = 1e-7):
    """Predictor inputs and targets from windows (n, taps+1, m): the features of the first
    `taps` samples, and the last sample's second difference less the input's mean second
    difference, over `unit`."""
    w = jnp.asarray(w, float)
    head = w[:, :-1]
    mean_d2 = jnp.mean(jnp.diff(head, n=2, axis=-2), axis=-2)
    return features(head, unit), (w[:, -1] - 2.0 * w[:, -2] + w[:, -3] - mean_d2) / unit


def predictor_sets(z_healthy, templates, key: jax.Array, n: int, *, sizes: tuple[float, float],
                   onset_within_last: int = 3, unit: float = 1e-7):  # fmt: skip
    """Training sets of an [`MLPPredictor`][hrgjax.diagnosis.neural.MLPPredictor] bank: one
    hypothesis for S0 (healthy windows) and one per INS i and fault sign (windows with an
    onset of +e, then of −e, e ~ U(`sizes`) in sensor units, in INS i within the last
    `onset_within_last` samples), cut from healthy complexes `z_healthy` (runs, K, m) with
    the unit responses `templates` (n_ins, L, m); `n` windows per hypothesis, `unit` as in
    [`predictor_set`][hrgjax.diagnosis.neural.predictor_set].

    The signs get a predictor each because, at an onset, the input window holds nothing of
    the fault yet: the sign is only in the predicted step (±e times the template). One
    predictor trained on both signs predicts their mean, no jump, and loses to S0's: such a
    bank named 0.63–0.74 of held-out signed onsets right (chance 0.48), the per-sign bank
    0.935–0.975 (12 draws, `tests/test_diagnosis_neural.py`'s small bank).

    **Returns** `(sets, classes)`: the `(x, y)` pairs of
    [`predictor_set`][hrgjax.diagnosis.neural.predictor_set], S0 first, then INS 1 +,
    INS 1 −, INS 2 +, …; and the onset class each names (0, 1, 1, 2, 2, …), for
    [`MLPPredictor.fit`][hrgjax.diagnosis.neural.MLPPredictor.fit]."""
    templates = jnp.asarray(templates, float)
    hyps = [(0, 1.0)] + [(i, s) for i in range(1, templates.shape[0] + 1) for s in (1.0, -1.0)]
    sets = []
    for (i, s), k in zip(hyps, jax.random.split(key, len(hyps)), strict=True):
        # S0 draws no onset (p_fault 0): the template only fixes the shapes, one program
        t = s * templates[max(i - 1, 0) : max(i, 1)]
        w, _, _ = training_windows(z_healthy, t, k, n, sizes=sizes, p_fault=float(i > 0),
                                   onset_within_last=onset_within_last, signed=False)  # fmt: skip
        sets.append(predictor_set(w, unit))
    return sets, tuple(i for i, _ in hyps)


def _class_index(c) -> int | None:
    """`c` as an int where it is an integer (Python, NumPy, a 0-d array; not a bool), else
    None."""
    if isinstance(c, (bool, np.bool_)) or np.dtype(getattr(c, "dtype", int)).kind == "b":
        return None
    try:
        return operator.index(c)
    except TypeError:
        return None


class MLPPredictor(eqx.Module):
    """A bank of MLPs, one per hypothesis, each with 50 tanh hidden units (by default) and a
    linear output, predicting the next measurement step (alg. 3.3.1) in units of the
    nominal sensor error ([`predictor_set`][hrgjax.diagnosis.neural.predictor_set]);
    trained by Levenberg–Marquardt. The hypotheses: S0 (no onset) and an onset at the
    predicted sample or one or two samples before it (the span of its signature in the
    second differences) — per INS and fault sign, as
    [`predictor_sets`][hrgjax.diagnosis.neural.predictor_sets] builds them. At each step
    the hypothesis with the least residual sum over the channels wins, and `classes` maps it
    to its onset class (0 none, i = INS i; `None`: the hypothesis's index is its class)."""

    nets: list[MLP]
    classes: tuple[int, ...] | None = eqx.field(static=True, default=None)

    @classmethod
    def fit(cls, sets, *, key, hidden: int = 50, max_steps: int = 60, classes=None):
        """`sets`: one `(x (n, d), y (n, m))` per hypothesis, S0 first; `classes`: the onset
        class each hypothesis names (default: its index). A fault that may jump either way
        needs one hypothesis per sign ([`predictor_sets`][hrgjax.diagnosis.neural.predictor_sets]
        returns both); `hidden` units, `max_steps` Levenberg–Marquardt steps per net."""
        sets = list(sets)
        if classes is not None:
            given = tuple(classes)
            classes = tuple(_class_index(c) for c in given)
            classes = tuple(c for c in classes if c is not None)
            if (len(classes) != len(sets) or len(given) != len(sets) or classes[0] != 0
                    or min(classes[1:], default=1) < 1):  # fmt: skip
                raise ValueError(
                    f"classes must name one onset class per hypothesis ({len(sets)}): integers, "
                    f"S0 (0) first, every other ≥ 1; got {given}"
                )
        nets = []
        for (x, y), k in zip(sets, jax.random.split(key, len(sets)), strict=True):
            net = MLP((x.shape[1], hidden, y.shape[1]), key=k)
            nets.append(_levenberg_marquardt(net, jnp.asarray(x), jnp.asarray(y), max_steps))
        return cls(nets, classes)

    def residuals(self, x, y):
        """Squared residual of each hypothesis's prediction (units of the nominal sensor
        error, squared): (n, M), M hypotheses in the order of `nets`."""
        return jnp.stack([jnp.sum((jax.vmap(n)(x) - y) ** 2, axis=-1) for n in self.nets], axis=-1)

    def classify_pairs(self, x, y):
        """Onset class (0 none, i = INS i) from inputs `x` and the measured next step `y`:
        the class of the hypothesis with the least residual. `x` and `y` must be finite
        (the arg-min over NaN residuals named S0); traced ones pass unchecked."""
        check_finite_host("x (MLPPredictor query features)", x)
        check_finite_host("y (MLPPredictor measured next steps)", y)
        h = jnp.argmin(self.residuals(x, y), axis=-1)
        return h if self.classes is None else jnp.asarray(self.classes)[h]


def _predictor_residuals(params, args):
    static, x, y = args
    return (jax.vmap(eqx.combine(params, static))(x) - y).reshape(-1)


def _levenberg_marquardt(net, x, y, max_steps):
    # one module-level residual with the data as arguments: optimistix compiles the solve
    # once for all hypotheses of the same shapes (a closure per net compiled it per net)
    params, static = eqx.partition(net, eqx.is_inexact_array)
    solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-9)
    # optimistix's own compiled loop (`stepwise=False`): a step takes milliseconds here
    params, _, _ = least_squares(_predictor_residuals, solver, params, (static, x, y),
                                 max_steps=max_steps, stepwise=False)  # fmt: skip
    return eqx.combine(params, static)


def stream_classes(detector, z, unit: float = 1e-7, taps: int = TAPS):
    """Per-step onset classes of `detector` over one run's measurements `z` (K, m) → (K,)
    (0 for the first steps, before a full window: `z` needs at least `taps` steps, `taps` + 1
    for an `MLPPredictor`)."""
    z = jnp.asarray(z, float)
    need = taps + 1 if isinstance(detector, MLPPredictor) else taps
    if z.ndim == 2 and isinstance(taps, int) and 1 <= taps and z.shape[0] < need:
        raise ValueError(f"z must have at least {need} steps (one full window of taps = {taps}"
                         f"{' + 1' if need > taps else ''}); got a record of {z.shape[0]}")  # fmt: skip
    if isinstance(detector, MLPPredictor):
        w = windows(z, taps + 1).reshape(-1, taps + 1, z.shape[1])
        x, y = predictor_set(w, unit)
        c = detector.classify_pairs(x, y)
        return jnp.concatenate([jnp.zeros(taps, c.dtype), c])
    w = windows(z, taps).reshape(-1, taps, z.shape[1])
    c = detector.classify(features(w, unit))
    return jnp.concatenate([jnp.zeros(taps - 1, c.dtype), c])


@eqx.filter_jit
def _accuracy(det, x, y):
    """Fraction of `x` that `det` classifies as `y` (one compiled program per detector type
    and shapes: eagerly, the kernel matrices of every window against every centre are
    materialised operation by operation)."""
    return jnp.mean(det.classify(x) == y)


def choose_sigma(cls, x, y, xv, yv, n_classes: int, grid=(0.1, 0.2, 0.5, 1.0, 2.0, 5.0)):
    """Fit `cls` ([`PNNBank`][hrgjax.diagnosis.neural.PNNBank] or
    [`PNNDirect`][hrgjax.diagnosis.neural.PNNDirect]) with each kernel width of `grid` and
    keep the one most accurate on the validation set `xv`, `yv`."""
    best, best_acc = None, -1.0
    xv, yv = jnp.asarray(xv, float), jnp.asarray(yv)
    if isinstance(grid, str | bytes) or not hasattr(grid, "__len__") or len(grid) == 0:
        raise ValueError(f"grid must be one or more kernel widths; got {describe(grid)}")
    if xv.ndim != 2 or yv.shape != (xv.shape[0],):
        raise ValueError(f"xv must be (n, d) and yv (n,); got {xv.shape}, {yv.shape}")
    for s in grid:
        det = cls.fit(x, y, n_classes, s)
        acc = float(_accuracy(det, xv, yv))
        if acc > best_acc:
            best, best_acc = det, acc
    return best
