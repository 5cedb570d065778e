"""Network building blocks: tapped-delay windows, the PNN against the Bayes classifier, and
Rprop training."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hrgjax.nn import pnn, tapped_delay, train


def test_tapped_delay_windows_by_hand():
    x = jnp.arange(10.0).reshape(5, 2)  # rows (0,1), (2,3), …
    w = tapped_delay.windows(x, 3)
    assert w.shape == (3, 6)
    np.testing.assert_array_equal(w[0], [0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(w[-1], [4, 5, 6, 7, 8, 9])
    with pytest.raises(ValueError, match="taps"):
        tapped_delay.windows(x, 6)
    with pytest.raises(ValueError, match="channels"):
        tapped_delay.windows(jnp.arange(5.0), 2)


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
