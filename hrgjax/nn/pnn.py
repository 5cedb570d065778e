r"""Probabilistic neural network (Specht 1990): each class's density is a Parzen sum of
Gaussian kernels centred on its training samples,

$$\hat f_c(x) = \frac{1}{n_c}\sum_{i\in c} \exp\!\left(-\frac{\lVert x - x_i\rVert^2}{2\sigma^2}\right),$$

and a sample goes to $\arg\max_c \pi_c \hat f_c(x)$. Evaluated in log space (log-sum-exp),
so far-away samples do not underflow to a tie."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import logsumexp

from .._checks import check_finite_host, describe, host_value, is_finite_real, numeric_problem
from .._compiled import fused


def check_labels(name: str, y, n_classes: int):
    """`y` as an int array, refused in one line naming `name` unless every label is an
    integer in [0, `n_classes`) (a label out of range was dropped or wrapped round; 1.7 was
    taken as a class); a traced `y` passes unchecked."""
    v = host_value(y)
    if v is None:
        return jnp.asarray(y).astype(int)
    bad = ~(np.isfinite(v) & (v == np.round(v)) & (v >= 0) & (v < n_classes))
    if bad.any():
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        raise ValueError(f"{name} must be integer class labels in [0, {n_classes}); "
                         f"got {v[i]:g} at index {i}")  # fmt: skip
    return jnp.asarray(v.astype(int))


def check_samples(name: str, x, d: int):
    """`x` as a float array, refused in one line naming `name` unless it is (m, `d`): a
    sample of another length, or one sample (d,) without its batch axis, raised a raw
    broadcasting or indexing error."""
    x = jnp.asarray(x, float)
    if x.ndim != 2 or x.shape[1] != d:
        raise ValueError(f"{name} must have shape (m, {d}) (one sample per row); got {x.shape}")
    return x


def check_n_classes(n_classes) -> int:
    """`n_classes` as an int >= 1, or a one-line `ValueError`."""
    if isinstance(n_classes, bool) or not isinstance(n_classes, (int, np.integer)):
        raise ValueError(f"n_classes must be an integer >= 1; got {n_classes!r}")
    if n_classes < 1:
        raise ValueError(f"n_classes must be an integer >= 1; got {n_classes}")
    return int(n_classes)


class PNN(eqx.Module):
    """A trained PNN: `centres` (n, d), `labels` (n,) int in [0, `n_classes`), kernel width
    `sigma`, class log-priors `log_prior` (n_classes,)."""

    centres: jax.Array
    labels: jax.Array
    sigma: jax.Array
    log_prior: jax.Array
    n_classes: int = eqx.field(static=True)

    @classmethod
    def fit(cls, x, y, n_classes: int, sigma: float, prior=None):
        """Store the training samples `x` (n, d), finite, with labels `y` (n,), integers in
        [0, `n_classes`). `prior` (n_classes,): class priors, finite, >= 0 with a positive
        sum (normalised here; default: equal).

        **Raises:** `ValueError` for a malformed or non-finite `x`, a label that is not an
        integer in [0, n_classes), `sigma` not > 0, or a bad `prior`."""
        n_classes = check_n_classes(n_classes)
        x, y = jnp.asarray(x, float), jnp.asarray(y)
        if x.ndim != 2 or y.shape != (x.shape[0],) or x.shape[0] < 1:
            raise ValueError(f"x must be (n, d) and y (n,), n >= 1; got {x.shape}, {y.shape}")
        check_finite_host("x (PNN training samples)", x)
        y = check_labels("y", y, n_classes)
        if not (is_finite_real(sigma) and sigma > 0):
            kind = TypeError if numeric_problem(sigma) else ValueError
            raise kind(f"sigma must be a finite number > 0 (kernel width); got {describe(sigma)}")
        if prior is None:
            log_prior = jnp.full(n_classes, -jnp.log(float(n_classes)))
        else:
            p = jnp.asarray(prior, float)
            v = host_value(p)
            if p.shape != (n_classes,) or (
                v is not None and not (np.isfinite(v).all() and (v >= 0).all() and v.sum() > 0)
            ):
                shown = p.shape if p.shape != (n_classes,) else np.asarray(v).tolist()
                raise ValueError(f"prior must be {n_classes} finite class priors >= 0 with a "
                                 f"positive sum, shape ({n_classes},); got {shown}")  # fmt: skip
            log_prior = jnp.log(p / jnp.sum(p))
        return cls(x, y, jnp.asarray(float(sigma)), log_prior, n_classes)

    def log_scores(self, x):
        """Unnormalised log posterior of each class for one sample `x` (d,) → (n_classes,)."""
        d2 = jnp.sum((self.centres - x[None, :]) ** 2, axis=-1)
        k = -d2 / (2.0 * self.sigma**2)
        onehot = jax.nn.one_hot(self.labels, self.n_classes, dtype=bool)  # (n, C)
        masked = jnp.where(onehot, k[:, None], -jnp.inf)
        n_c = jnp.sum(onehot, axis=0)
        return logsumexp(masked, axis=0) - jnp.log(jnp.maximum(n_c, 1)) + self.log_prior

    def predict(self, x):
        """Class of each sample of `x` (m, d), finite, → (m,) (a NaN sample was given class
        0, the argmax over NaN scores); a traced `x` passes unchecked."""
        x = check_samples("x (PNN query samples)", x, self.centres.shape[1])
        check_finite_host("x (PNN query samples)", x)
        return self._predict(x)

    @fused
    def _predict(self, x):
        return jnp.argmax(jax.vmap(self.log_scores)(x), axis=-1)
