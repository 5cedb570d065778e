r"""Kohonen self-organising map: a grid of prototype vectors trained without labels, then
labelled (the thesis's alg. 3.2.1).

Training (Kohonen 1982), one sample per step drawn with an explicit key: the best-matching
unit $b = \arg\min_j \lVert x - w_j\rVert$, then every unit moves towards the sample,

$$w_j \leftarrow w_j + \alpha(t)\,\exp\!\left(-\frac{\lVert r_j - r_b\rVert^2}
{2\sigma(t)^2}\right)(x - w_j),$$

with the learning rate $\alpha$ and the neighbourhood radius $\sigma$ (in grid units)
decaying exponentially from their start to their end values. Labelling: each unit takes the
majority label of the training samples it wins (a unit that wins none takes the overall
majority); a sample is classified by its best-matching unit's label."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_finite_host, check_key, describe, host_value, whole_number
from .pnn import check_labels, check_n_classes, check_samples


def _schedule(name: str, ends):
    """`ends` (start, end) of a geometric decay, unchanged, or a one-line `ValueError` naming
    `name` unless both are finite and > 0 (an end of 0 gave NaN weights or a
    `ZeroDivisionError`); a traced end (a sweep, `jax.grad` over the schedule) passes."""
    message = f"{name} must be (start, end), two finite numbers > 0; got {ends!r}"
    try:
        a, b = ends
        values = [host_value(jnp.asarray(v, float)) for v in (a, b)]
    except (TypeError, ValueError):
        raise ValueError(message) from None
    for v in values:
        if v is not None and not (v.shape == () and np.isfinite(v) and v > 0):
            raise ValueError(message)
    return a, b


class SOM(eqx.Module):
    """A trained map: `weights` (units, d), `grid` (units, 2) unit positions, `labels`
    (units,) int (−1 before [`label`][hrgjax.nn.som.SOM.label])."""

    weights: jax.Array
    grid: jax.Array
    labels: jax.Array

    @classmethod
    def train(
        cls,
        x,
        shape: tuple[int, int],
        *,
        key: jax.Array,
        steps: int = 20000,
        rate: tuple[float, float] = (0.5, 0.01),
        radius: tuple[float, float] | None = None,
    ) -> SOM:
        """Self-organise a `shape` grid on samples `x` (n, d): prototypes start at random
        samples; `rate` and `radius` (default: half the grid's larger side → 0.5) decay
        geometrically over `steps`.

        **Raises:** `ValueError` for a malformed or non-finite `x`, `rate` or `radius` ends
        not finite and > 0, or `steps` < 1."""
        x = jnp.asarray(x, float)
        if x.ndim != 2 or x.shape[0] < 1:
            raise ValueError(f"x must have shape (n, d); got {x.shape}")
        check_finite_host("x (SOM training samples)", x)
        if isinstance(shape, str | bytes) or not hasattr(shape, "__len__") or len(shape) != 2:
            raise ValueError(f"shape must be two positive ints (rows, cols); got {describe(shape)}")
        rows, cols = (whole_number("shape", s, "two positive ints (rows, cols)") for s in shape)
        if rows < 1 or cols < 1:
            raise ValueError(f"shape must be two positive ints; got {shape}")
        if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
            raise ValueError(f"steps must be an integer >= 1; got {steps!r}")
        if radius is None:
            radius = (max(rows, cols) / 2.0, 0.5)
        rate = _schedule("rate", rate)
        radius = _schedule("radius [grid units]", radius)
        grid = jnp.stack(
            jnp.meshgrid(jnp.arange(rows, dtype=x.dtype), jnp.arange(cols, dtype=x.dtype),
                         indexing="ij"), axis=-1,
        ).reshape(-1, 2)  # fmt: skip
        check_key("SOM.train: key (the PRNG key of the start and the sample order)", key)
        k0, k1 = jax.random.split(key)
        w0 = x[jax.random.choice(k0, x.shape[0], (rows * cols,), replace=x.shape[0] < rows * cols)]
        picks = jax.random.randint(k1, (int(steps),), 0, x.shape[0])
        frac = jnp.arange(int(steps), dtype=x.dtype) / max(int(steps) - 1, 1)
        alpha = rate[0] * (rate[1] / rate[0]) ** frac
        sigma = radius[0] * (radius[1] / radius[0]) ** frac
        w = _self_organise(w0, grid, x[picks], alpha, sigma)
        return cls(w, grid, jnp.full(rows * cols, -1))

    def winners(self, x):
        """Best-matching unit of each sample of `x` (n, d) → (n,)."""
        x = check_samples("x", x, self.weights.shape[1])
        d2 = jnp.sum((x[:, None, :] - self.weights[None, :, :]) ** 2, axis=-1)
        return jnp.argmin(d2, axis=-1)

    def label(self, x, y, n_classes: int) -> SOM:
        """Label each unit by the majority class of the samples `x` (n, d), `y` (n,) it
        wins; `y` must be integers in [0, `n_classes`) (`ValueError` otherwise: a label out
        of range was dropped or wrapped round)."""
        n_classes = check_n_classes(n_classes)
        x = check_samples("x (SOM labelling samples)", x, self.weights.shape[1])
        y = jnp.asarray(y)
        if x.ndim != 2 or y.shape != (x.shape[0],):
            raise ValueError(f"x must be (n, d) and y (n,); got {x.shape}, {y.shape}")
        check_finite_host("x (SOM labelling samples)", x)
        y = check_labels("y", y, n_classes)
        win = self.winners(x)
        counts = jnp.zeros((self.weights.shape[0], n_classes)).at[win, y].add(1.0)
        overall = jnp.argmax(jnp.bincount(y, length=n_classes))
        labels = jnp.where(counts.sum(-1) > 0, jnp.argmax(counts, -1), overall)
        return eqx.tree_at(lambda s: s.labels, self, labels)

    def predict(self, x):
        """Class of each sample of `x` (n, d), finite, → (n,): its best-matching unit's label
        (a NaN sample matched unit 0); a traced `x` passes unchecked. **Raises:**
        `ValueError` before [`label`][hrgjax.nn.som.SOM.label] (every sample was class −1)."""
        labels = host_value(self.labels)
        if labels is not None and (labels < 0).any():
            raise ValueError("this SOM is not labelled (its units' labels are -1); use "
                             "som = som.label(x, y, n_classes) before predict")  # fmt: skip
        x = check_samples("x (SOM query samples)", x, self.weights.shape[1])
        check_finite_host("x (SOM query samples)", x)
        return self.labels[self.winners(x)]


@jax.jit
def _self_organise(w0, grid, samples, alpha, sigma):
    def step(w, inp):
        x, a, s = inp
        b = jnp.argmin(jnp.sum((w - x[None, :]) ** 2, axis=-1))
        h = jnp.exp(-jnp.sum((grid - grid[b][None, :]) ** 2, axis=-1) / (2.0 * s**2))
        return w + (a * h)[:, None] * (x[None, :] - w), None

    w, _ = jax.lax.scan(step, w0, (samples, alpha, sigma))
    return w
