"""A multilayer perceptron with any hidden sizes (the thesis's 20–10 classifier and 50-unit
predictor), in equinox."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp

from .._checks import check_key, whole_number


class MLP(eqx.Module):
    """Fully connected layers `sizes[0] → … → sizes[-1]`, `activation` on every hidden layer,
    `final_activation` on the output (identity for a predictor, `jax.nn.sigmoid` for a
    classifier). Call on one sample (in,) → (out,); `vmap` for a batch."""

    layers: list[eqx.nn.Linear]
    activation: Callable = eqx.field(static=True)
    final_activation: Callable = eqx.field(static=True)

    def __init__(
        self,
        sizes: Sequence[int],
        *,
        key: jax.Array,
        activation: Callable = jnp.tanh,
        final_activation: Callable = lambda x: x,
    ):
        sizes = tuple(whole_number("sizes", s, "layer widths, integers >= 1") for s in sizes)
        if len(sizes) < 2 or min(sizes) < 1:
            raise ValueError(f"sizes must be >= 2 positive layer widths; got {sizes}")
        check_key("MLP: key (the PRNG key of the initial weights)", key)
        keys = jax.random.split(key, len(sizes) - 1)
        self.layers = [
            eqx.nn.Linear(a, b, key=k) for a, b, k in zip(sizes[:-1], sizes[1:], keys, strict=True)
        ]
        self.activation = activation
        self.final_activation = final_activation

    def __call__(self, x):
        n_in = self.layers[0].in_features
        if jnp.shape(x) != (n_in,):
            raise ValueError(
                f"x must be one sample of shape ({n_in},) (vmap for a batch); got {jnp.shape(x)}"
            )
        for layer in self.layers[:-1]:
            x = self.activation(layer(x))
        return self.final_activation(self.layers[-1](x))
