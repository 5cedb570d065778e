r"""Probabilistic neural network (Specht 1990): each class's density is a Parzen sum of
Gaussian kernels centred on its training samples,

$$\hat f_c(x) = \frac{1}{n_c}\sum_{i\in c} \exp\!\left(-\frac{\lVert x - x_i\rVert^2}{2\sigma^2}\right),$$

and a sample goes to $\arg\max_c \pi_c \hat f_c(x)$. Evaluated in log space (log-sum-exp),
so far-away samples do not underflow to a tie."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import logsumexp

from .._compiled import fused


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
        """Store the training samples `x` (n, d) with labels `y` (n,)."""
        x, y = jnp.asarray(x, float), jnp.asarray(y)
        if x.ndim != 2 or y.shape != (x.shape[0],):
            raise ValueError(f"x must be (n, d) and y (n,); got {x.shape}, {y.shape}")
        if not sigma > 0:
            raise ValueError(f"sigma must be > 0; got {sigma}")
        if prior is None:
            log_prior = jnp.full(n_classes, -jnp.log(float(n_classes)))
        else:
            log_prior = jnp.log(jnp.asarray(prior, float))
        return cls(x, y, jnp.asarray(float(sigma)), log_prior, n_classes)

    def log_scores(self, x):
        """Unnormalised log posterior of each class for one sample `x` (d,) → (n_classes,)."""
        d2 = jnp.sum((self.centres - x[None, :]) ** 2, axis=-1)
        k = -d2 / (2.0 * self.sigma**2)
        onehot = jax.nn.one_hot(self.labels, self.n_classes, dtype=bool)  # (n, C)
        masked = jnp.where(onehot, k[:, None], -jnp.inf)
        n_c = jnp.sum(onehot, axis=0)
        return logsumexp(masked, axis=0) - jnp.log(jnp.maximum(n_c, 1)) + self.log_prior

    @fused
    def predict(self, x):
        """Class of each sample of `x` (m, d) → (m,)."""
        return jnp.argmax(jax.vmap(self.log_scores)(jnp.asarray(x, float)), axis=-1)
