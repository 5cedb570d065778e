"""Network building blocks: tapped-delay windows, the PNN against the Bayes classifier, and
Rprop training."""

import dataclasses
import gc
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.nn import pnn, som, tapped_delay, train


def test_tapped_delay_windows_by_hand():
    x = jnp.arange(10.0).reshape(5, 2)  # rows (0,1), (2,3), …
    w = tapped_delay.windows(x, 3)
    assert w.shape == (3, 6)
    np.testing.assert_array_equal(w[0], [0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(w[-1], [4, 5, 6, 7, 8, 9])
    with pytest.raises(ValueError, match=r"^taps must be in \[1, K = 5\] \(K: the samples of x\); got 6$"):  # fmt: skip
        tapped_delay.windows(x, 6)
    with pytest.raises(ValueError, match="channels"):
        tapped_delay.windows(jnp.arange(5.0), 2)
    # a fractional or text tap count raised a raw JAX indexing / comparison error
    for taps in (2.5, "3", True):
        with pytest.raises(ValueError, match=r"^taps must be an integer in \[1, 5\]"):
            tapped_delay.windows(x, taps)


def test_elman_and_mlp_refuse_bad_sizes_and_inputs_of_the_wrong_width():
    """A fractional width (3.5: JAX's "Shapes must be 1D sequences"), an input of the wrong
    width or a context of the wrong size (raw dot_general errors) are refused in one line."""
    from hrgjax.nn import elman, mlp

    key = jax.random.key(0)
    with pytest.raises(ValueError, match=r"^hidden_size must be a positive integer"):
        elman.Elman(2, 3.5, 1, key=key)
    with pytest.raises(ValueError, match=r"^sizes must be layer widths, integers >= 1"):
        mlp.MLP([2, 2.5, 1], key=key)
    # an int seed, None or a batch of keys: JAX's "invalid PRNG key data" named no field
    for bad in (0, None, jax.random.split(key, 2)):
        with pytest.raises((TypeError, ValueError), match=r"^Elman: key .* must be one JAX PRNG"):
            elman.Elman(2, 3, 1, key=bad)
        with pytest.raises((TypeError, ValueError), match=r"^MLP: key .* must be one JAX PRNG"):
            mlp.MLP([2, 3, 1], key=bad)
    net, m = elman.Elman(2, 3, 1, key=key), mlp.MLP([2, 3, 1], key=key)
    with pytest.raises(ValueError, match=r"^xs must have shape \(T, in_size\) = \(T, 2\)"):
        net(jnp.ones((4, 3)))
    with pytest.raises(ValueError, match=r"^h0 must have shape \(hidden_size,\) = \(3,\)"):
        net(jnp.ones((4, 2)), h0=jnp.zeros(2))
    for x in (jnp.ones(3), jnp.ones((4, 2))):
        with pytest.raises(ValueError, match=r"^x must be one sample of shape \(2,\)"):
            m(x)
    # the recurrence against NumPy, h = tanh(W_x x + b + W_h h), y = W_y h + c; float32 or
    # integer samples beside float64 weights raised a raw "carry input and carry output" error
    xs = np.random.default_rng(0).normal(size=(5, 2))
    h, ref = np.array([0.1, -0.2, 0.3]), []
    for x in xs:
        h = np.tanh(net.w_x.weight @ x + net.w_x.bias + net.w_h.weight @ h)
        ref.append(net.w_y.weight @ h + net.w_y.bias)
    np.testing.assert_allclose(net(xs, h0=np.array([0.1, -0.2, 0.3])), ref, rtol=1e-13)
    x32 = xs.astype(np.float32)
    np.testing.assert_array_equal(net(x32), net(x32.astype(float)))
    np.testing.assert_array_equal(net(np.ones((3, 2), int)), net(np.ones((3, 2))))


def test_pnn_approaches_the_bayes_classifier():
    """Two unit-variance Gaussian classes 2 apart: Bayes accuracy Φ(1) = 0.841."""
    k1, k2, k3, k4 = jax.random.split(jax.random.key(0), 4)
    n = 2000
    x = jnp.concatenate([jax.random.normal(k1, (n, 1)), 2.0 + jax.random.normal(k2, (n, 1))])
    y = jnp.concatenate([jnp.zeros(n, int), jnp.ones(n, int)])
    xt = jnp.concatenate([jax.random.normal(k3, (n, 1)), 2.0 + jax.random.normal(k4, (n, 1))])
    model = pnn.PNN.fit(x, y, 2, sigma=0.3)
    acc = float(jnp.mean(model.predict(xt) == y))
    assert acc == pytest.approx(0.841, abs=0.03)
    # far from every centre the log-space scores still decide (no 0/0 tie)
    assert int(model.predict(jnp.array([[40.0]]))[0]) == 1
    with pytest.raises(ValueError, match="sigma"):
        pnn.PNN.fit(x, y, 2, sigma=0.0)


def test_rprop_minimises_and_is_deterministic():
    target = jnp.array([1.0, -2.0, 3.0])
    loss = lambda p: jnp.sum((p["w"] - target) ** 2)
    p = train.rprop(loss, {"w": jnp.zeros(3)}, 200, 1e-2)
    np.testing.assert_allclose(p["w"], target, atol=1e-6)
    q = train.rprop(loss, {"w": jnp.zeros(3)}, 200, 1e-2)
    np.testing.assert_array_equal(p["w"], q["w"])


def test_rprop_with_progress_runs_a_prime_step_count_in_few_blocks(monkeypatch):
    """199 steps (prime) ran as 199 one-step programs (997 steps of the MLP compensator's
    nets: 5.4 s against 0.06 s for 1000); now 22 blocks of 9 and one of 1, the same updates
    as `rprop`'s one scan."""
    target = jnp.array([1.0, -2.0, 3.0])
    calls = []
    block = train._rprop_block
    monkeypatch.setattr(train, "_rprop_block", lambda *a: calls.append(a[4]) or block(*a))
    p, losses = train.rprop_with_progress(_quadratic_data, jnp.zeros(3), target, 199, 1e-2)
    assert calls == [9] * 22 + [1] and losses.shape == (199,)
    q = train.rprop(lambda w: _quadratic_data(w, target), jnp.zeros(3), 199, 1e-2)
    np.testing.assert_allclose(p, q, rtol=1e-12, atol=1e-15)


def _quadratic_data(p, target):
    return jnp.sum((p - target) ** 2)


def _quadratic(p, *, target):
    return jnp.sum((p["w"] - target) ** 2)


def test_rprop_and_train_module_compile_once_with_the_data_traced():
    """With `compile_once=True` a second `rprop`/`train_module` of the same loss and shapes
    compiles nothing (by default each call traces afresh, one compile each time); data passed
    as an `eqx.Partial`'s arrays is traced, not baked in: each call reaches its own
    minimiser of sum((w - target)²), w = target; a new learning rate and largest step are
    values too (they were static: each new rate compiled the training again), weakly typed
    (float32 weights train in float32). A loss that is not a Module is refused for it (a
    closure's data would be fixed in the program)."""
    from helpers import CompileCounter

    targets = [jnp.array([1.0, -2.0, 3.0]), jnp.array([0.5, 4.0, -1.0])]
    loss = lambda t: eqx.Partial(_quadratic, target=t)
    once = {"compile_once": True}
    train.rprop(loss(targets[0]), {"w": jnp.zeros(3)}, 200, 1e-2, **once)  # compiles
    train.train_module({"w": jnp.zeros(3)}, loss(targets[0]), 200, 1e-2, **once)
    for t, rate, top in zip(targets, (1e-2, 3e-2), (50.0, 20.0), strict=True):
        with CompileCounter() as c:
            p = train.rprop(loss(t), {"w": jnp.zeros(3)}, 200, rate, top, **once)
            m = train.train_module({"w": jnp.zeros(3)}, loss(t), 200, rate, top, **once)
        assert c.compiles == 0 and c.traces == 0, c.names
        np.testing.assert_allclose(p["w"], t, atol=1e-6)
        np.testing.assert_allclose(m["w"], t, atol=1e-6)
    w32 = train.rprop(loss(targets[0].astype(jnp.float32)), {"w": jnp.zeros(3, jnp.float32)},
                      200, 1e-2, **once)["w"]  # fmt: skip
    assert w32.dtype == jnp.float32
    with pytest.raises(ValueError, match="compile_once=True needs an equinox.Module loss"):
        train.rprop(lambda p: _quadratic(p, target=targets[0]), {"w": jnp.zeros(3)}, 5,
                    compile_once=True)  # fmt: skip


class _Fitter:  # a plain object holding its data; its bound method is the loss
    def __init__(self, t):
        self.t = t

    def loss(self, p):
        return jnp.sum((p - self.t) ** 2)


def test_rprop_trains_on_the_data_the_loss_reads_now():
    """The same loss object with its data changed between two fits: each fit reaches the
    minimiser w = target of sum((w - target)²) for the data of its own call (a program
    cached by the loss object returned the first data's weights again: [1, -2, 3])."""
    first, second = jnp.array([1.0, -2.0, 3.0]), jnp.array([10.0, 20.0, 30.0])
    data = {"t": first}
    closure = lambda p: jnp.sum((p - data["t"]) ** 2)
    fitter = _Fitter(first)
    module_loss = lambda m: closure(m["w"])
    wrapped = eqx.Partial(lambda p, *, scale: scale * closure(p), scale=1.0)  # a Module too
    for t in (first, second):
        data["t"], fitter.t = t, t
        np.testing.assert_allclose(train.rprop(wrapped, jnp.zeros(3), 300, 1e-2), t, atol=1e-6)
        np.testing.assert_allclose(train.rprop(closure, jnp.zeros(3), 300, 1e-2), t, atol=1e-6)
        np.testing.assert_allclose(train.rprop(fitter.loss, jnp.zeros(3), 300, 1e-2), t,
                                   atol=1e-6)  # fmt: skip
        m = train.train_module({"w": jnp.zeros(3)}, module_loss, 300, 1e-2)
        np.testing.assert_allclose(m["w"], t, atol=1e-6)


def _positive_first(p, *, t):
    p = eqx.error_if(p, p[0] < 0.0, "variance went negative")
    return jnp.sum((p - t) ** 2)


def test_a_users_error_if_inside_the_loss_raises_its_message():
    """A loss whose optimum leaves the parameter's range (`eqx.error_if`): the user's
    message is raised, eagerly, under the caller's `jit` and on the compiled-once path of
    an `eqx.Partial` (the program traced equinox's checks as NaN: "training diverged"
    eagerly, NaN weights returned silently under `jit`)."""
    bad = eqx.Partial(_positive_first, t=jnp.array([-1.0, 2.0]))
    plain = lambda p: bad(p)
    p0 = jnp.array([1.0, 0.0])
    for run in (
        lambda: train.rprop(plain, p0, 50, 0.1),
        lambda: jax.jit(lambda p: train.rprop(plain, p, 50, 0.1))(p0),
        lambda: train.rprop(bad, p0, 50, 0.1),
        lambda: train.rprop(bad, p0, 50, 0.1, compile_once=True),
        lambda: train.train_module({"w": p0}, lambda m: bad(m["w"]), 50, 0.1)["w"],
    ):
        with pytest.raises(Exception, match="variance went negative"):
            jax.block_until_ready(run())


@dataclasses.dataclass(frozen=True)
class _DataclassLoss:  # unhashable: its field is an array
    t: jax.Array

    def __call__(self, p):
        return jnp.sum((p - self.t) ** 2)


class _IntLeaf(eqx.Module):
    w: jax.Array
    n: jax.Array  # an integer array: not trained, read as a concrete count


def _first_n_ones(m):
    k = int(m.n)
    return jnp.sum((m.w[:k] - 1.0) ** 2) + jnp.sum(m.w[k:] ** 2)


def test_unhashable_losses_and_concrete_integer_leaves_train():
    """An unhashable callable loss (a frozen dataclass with an array field) and a module
    whose integer array is read as a concrete count (`int(m.n)`) train to their minimisers
    (refused: "Non-hashable static arguments", and a ConcretizationTypeError)."""
    t = jnp.array([1.0, 2.0])
    np.testing.assert_allclose(train.rprop(_DataclassLoss(t), jnp.zeros(2), 200, 1e-2), t,
                               atol=1e-6)  # fmt: skip
    m = train.train_module(_IntLeaf(jnp.zeros(4), jnp.array(2)), _first_n_ones, 200, 1e-2)
    np.testing.assert_allclose(m.w, [1.0, 1.0, 0.0, 0.0], atol=1e-6)
    # an eqx.Partial holding the count: compiled-once path tried, trained as before
    count = eqx.Partial(lambda p, *, n: _first_n_ones(_IntLeaf(p, n)), n=jnp.array(3))
    np.testing.assert_allclose(train.rprop(count, jnp.zeros(4), 200, 1e-2, compile_once=True),
                               [1, 1, 1, 0], atol=1e-6)  # fmt: skip


def test_a_fitted_closure_is_not_kept_alive():
    """A closure loss (and the data it holds) is freed after the fit (a program cached by
    the loss object kept every fit's closure: +21 MB a fit over 4-MB data sets)."""
    x = jnp.ones(8)
    loss = lambda p: jnp.sum((p - x) ** 2)
    ref = weakref.ref(loss)
    train.rprop(loss, jnp.zeros(8), 5, 1e-2)
    del loss
    gc.collect()
    assert ref() is None


def test_pnn_refuses_nan_samples_bad_priors_and_labels_out_of_range():
    """A NaN query or training sample and a negative prior made every prediction a confident
    class 0 (argmax over NaN); a label outside [0, n_classes) was dropped (one_hot of 2 is
    zeros), 1.7 was taken as a class: each refused in one line."""
    x = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.1, 5.0]])
    y = np.array([0, 0, 1, 1])
    model = pnn.PNN.fit(x, y, 2, sigma=0.5, prior=[1.0, 3.0])  # normalised to [0.25, 0.75]
    np.testing.assert_allclose(np.exp(model.log_prior), [0.25, 0.75])
    np.testing.assert_array_equal(model.predict(x), y)
    with pytest.raises(ValueError, match=r"^x \(PNN query samples\) must be finite; it has nan"):
        model.predict(np.array([[np.nan, 0.0]]))
    xn = x.copy()
    xn[1, 0] = np.nan
    with pytest.raises(ValueError, match=r"^x \(PNN training samples\) must be finite"):
        pnn.PNN.fit(xn, y, 2, sigma=0.5)
    for prior, found in (([-0.5, 1.5], r"\[-0\.5, 1\.5\]"), ([0.2, 0.3, 0.5], r"\(3,\)"),
                         ([0.0, 0.0], r"\[0\.0, 0\.0\]"), ([np.nan, 1.0], r"\[nan, 1\.0\]")):  # fmt: skip
        with pytest.raises(
            ValueError, match=rf"^prior must be 2 finite class priors >= 0 .*got {found}$"
        ):
            pnn.PNN.fit(x, y, 2, sigma=0.5, prior=prior)
    for labels, found in (([0, 0, 2, 2], "2 at index \\(2,\\)"), ([0.0, 0.0, 1.7, 1.7], "1.7"),
                          ([-1, 0, 1, 1], "-1 at index \\(0,\\)")):  # fmt: skip
        with pytest.raises(
            ValueError, match=rf"^y must be integer class labels in \[0, 2\); got {found}"
        ):
            pnn.PNN.fit(x, np.array(labels), 2, sigma=0.5)
    # sigma inf (every kernel 1: the prior decides), text, an empty training set (every
    # query class 0); a query of the wrong width or without its batch axis (raw errors)
    for sigma, kind in ((np.inf, ValueError), ("a", TypeError), (np.array([1.0, 2.0]), ValueError)):
        with pytest.raises(kind, match=r"^sigma must be a finite number > 0"):
            pnn.PNN.fit(x, y, 2, sigma=sigma)
    with pytest.raises(ValueError, match=r"^x must be \(n, d\) and y \(n,\), n >= 1"):
        pnn.PNN.fit(np.zeros((0, 2)), np.zeros(0, int), 2, sigma=0.5)
    for q in (np.ones((3, 3)), np.ones(2)):
        with pytest.raises(ValueError, match=r"^x \(PNN query samples\) must have shape \(m, 2\)"):
            model.predict(q)


def test_som_refuses_zero_schedule_ends_nan_samples_and_bad_labels():
    """radius end 0 gave NaN weights (÷ 2σ²), rate start 0 a raw ZeroDivisionError, a NaN
    sample NaN weights; a label out of range was dropped (scatter out of bounds) or wrapped
    round (−1 → the last class)."""
    x = np.array([[0.0, 0.0], [0.1, 0.0], [5.0, 5.0], [5.1, 5.0]])
    key = jax.random.key(0)
    for kw, field in (({"radius": (1.0, 0.0)}, "radius"), ({"rate": (0.0, 0.01)}, "rate"),
                      ({"rate": (0.5, np.inf)}, "rate")):  # fmt: skip
        with pytest.raises(
            ValueError, match=rf"^{field}.* must be \(start, end\), two finite numbers > 0"
        ):
            som.SOM.train(x, (2, 2), key=key, steps=20, **kw)
    with pytest.raises(ValueError, match=r"^x \(SOM training samples\) must be finite"):
        som.SOM.train(np.array([[0.0, 0.0], [np.nan, 1.0]]), (2, 2), key=key, steps=20)
    with pytest.raises(ValueError, match=r"^steps must be an integer >= 1"):
        som.SOM.train(x, (2, 2), key=key, steps=0)
    with pytest.raises(TypeError, match=r"^SOM.train: key .* must be one JAX PRNG key"):
        som.SOM.train(x, (2, 2), key=0, steps=20)
    m = som.SOM.train(x, (2, 2), key=key, steps=200)
    with pytest.raises(ValueError, match=r"^this SOM is not labelled"):
        m.predict(x)  # every sample was class -1
    labelled = m.label(x, np.array([0, 0, 1, 1]), 2)
    np.testing.assert_array_equal(labelled.predict(x), [0, 0, 1, 1])
    with pytest.raises(ValueError, match=r"^x \(SOM query samples\) must be finite"):
        labelled.predict(np.array([[np.nan, 5.0]]))
    for labels in ([0, 0, 5, 5], [0, 0, -1, -1], [0.0, 0.0, 0.5, 1.0]):
        with pytest.raises(ValueError, match=r"^y must be integer class labels in \[0, 2\)"):
            m.label(x, np.array(labels), 2)
    # a malformed grid shape (IndexError, or 2.5 cut to 2), a sample of the wrong width
    for shape in ((2,), (2.5, 2), 2):
        with pytest.raises(ValueError, match=r"^shape must be two positive ints"):
            som.SOM.train(x, shape, key=key, steps=20)
    with pytest.raises(ValueError, match=r"^x \(SOM query samples\) must have shape \(m, 2\)"):
        labelled.predict(np.ones((3, 3)))
    with pytest.raises(ValueError, match=r"^x \(SOM labelling samples\) must have shape"):
        m.label(np.ones((4, 3)), np.array([0, 0, 1, 1]), 2)
    # a traced schedule (a sweep over the rate, its gradient) is not refused
    trained = lambda r: som.SOM.train(x, (2, 2), key=key, steps=20, rate=(r, 0.01)).weights
    np.testing.assert_allclose(jax.vmap(trained)(jnp.array([0.5]))[0], trained(0.5), rtol=1e-12)
    assert np.isfinite(jax.grad(lambda r: trained(r).sum())(0.5))


def _batch_loss(p, d, idx):
    return jnp.sum((p - d[idx].mean()) ** 2)


def _batch_eval(p, d):
    return jnp.atleast_1d(jnp.sum(p))


def test_rprop_refuses_divergence_and_zero_steps_alike_everywhere():
    """NaN data: `rprop` and `train_module` returned NaN weights silently while
    `rprop_with_progress` raised; steps=0 raised NumPy's "need at least one array to
    concatenate"."""
    data = jnp.array([1.0, np.nan])
    lf = lambda p, d: jnp.sum((p - d) ** 2)
    diverged = r"^training diverged: the loss or the weights became NaN or inf"
    with pytest.raises(RuntimeError, match=diverged):
        train.rprop(lambda p: lf(p, data), jnp.zeros(2), 10)
    with pytest.raises(RuntimeError, match=diverged):
        train.rprop_with_progress(lf, jnp.zeros(2), data, 10)
    with pytest.raises(RuntimeError, match=diverged):
        train.train_module({"w": jnp.zeros(2)}, lambda m: lf(m["w"], data), 10)
    for steps in (0, -3, 2.5):
        with pytest.raises(ValueError, match=r"^steps must be an integer >= 1"):
            train.rprop_with_progress(lf, jnp.zeros(2), jnp.ones(2), steps)
        with pytest.raises(ValueError, match=r"^steps must be an integer >= 1"):
            train.rprop(lambda p: lf(p, data), jnp.zeros(2), steps)
    # a step size of 0 or below returned the start or an un-descended point silently
    for kw in ({"learning_rate": 0.0}, {"learning_rate": -1e-2}, {"max_step": 0.0}):
        name = next(iter(kw))
        with pytest.raises(ValueError, match=rf"^{name} must be a finite number > 0"):
            train.rprop(lambda p: lf(p, jnp.ones(2)), jnp.zeros(2), 5, **kw)
        with pytest.raises(ValueError, match=rf"^{name} must be a finite number > 0"):
            train.rprop_with_progress(lf, jnp.zeros(2), jnp.ones(2), 5, **kw)
    with pytest.raises(TypeError, match=r"^learning_rate must be a number > 0"):
        train.train_module({"w": jnp.zeros(2)}, lambda m: lf(m["w"], data), 5, "a")
    adam = lambda n, lr: train.adam_epochs(_batch_loss, _batch_eval, jnp.zeros(2), jnp.ones(4),
                                           n, key=jax.random.key(0), epochs=1, batch_size=2,
                                           learning_rate=lr)  # fmt: skip
    with pytest.raises(ValueError, match=r"^n_items must be an integer >= 1"):
        adam(0, 1e-2)  # a ZeroDivisionError
    # 5 items of 4 rows: JAX clamped index 4 to row 3 and trained on it twice, silently
    with pytest.raises(ValueError, match=r"^n_items must be <= 4, the rows .* got 5 \("):
        adam(5, 1e-2)
    with pytest.raises(ValueError, match=r"^learning_rate must be a finite number > 0"):
        adam(4, -1.0)  # trained uphill, silently
    # under jit the traced result passes unchecked (no host check on tracers)
    out = jax.jit(lambda d: train.rprop(lambda p: lf(p, d), jnp.zeros(2), 5))(jnp.ones(2))
    assert np.isfinite(np.asarray(out)).all()
