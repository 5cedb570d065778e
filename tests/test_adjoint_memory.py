"""Gradient memory through long averaged simulations stays bounded (XLA's account of the
compiled programs; nothing is run): the checkpointed gradient of a 1-hour run needs at most
twice the forward's memory, and for a loss on the final angle it does not grow with length."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import pytest

import hrgjax as hg


def peak_bytes(fn, x):
    m = jax.jit(fn).lower(x).compile().memory_analysis()
    return m.temp_size_in_bytes + m.argument_size_in_bytes + m.output_size_in_bytes


@pytest.fixture(scope="module")
def setup():
    pi_loops = hg.presets.tvg3_like(noise=False)
    params, static = eqx.partition(pi_loops.resonator, eqx.is_inexact_array)

    def loss_for(length, final=False, adjoint=None, gyro=pi_loops):
        prof = hg.Profile.piecewise([0.0, length], [5.0, 5.0], [-40.0, 20.0])
        kw = {"ts": jnp.array([0.0, length])} if final else {"dt_out": 1.0}

        def loss(p):
            g = eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(p, static))
            return jnp.mean(hg.simulate(g, prof, adjoint=adjoint, **kw).wave_angle ** 2)

        return loss

    return params, loss_for


@pytest.mark.slow(
    "~60 s: three compiles of an hour's gradient (nothing run); fast tier: the "
    "final-angle gradient's memory independent of the run's length "
    "(test_final_angle_gradient_memory_independent_of_length)"
)
def test_one_hour_gradient_within_twice_the_forward(setup):
    params, loss_for = setup
    loss = loss_for(3600.0)
    forward, gradient = peak_bytes(loss, params), peak_bytes(jax.grad(loss), params)
    assert gradient <= 2.0 * forward, (gradient, forward)
    # A checkpoint per step (18 458 steps; what plain backpropagation keeps) would not fit:
    store_all = peak_bytes(
        jax.grad(loss_for(3600.0, adjoint=diffrax.RecursiveCheckpointAdjoint(20_000))), params
    )
    assert store_all > 3.0 * gradient


def test_final_angle_gradient_memory_independent_of_length(setup):
    """The default adjoint keeps 256 checkpoints whatever the step limit (65 536 steps for
    300 s, 131 072 for an hour): the gyro's ideal loops trace and compile in half the time of
    its PI loops (the test above keeps those), and the adjoint's storage is the same."""
    params, loss_for = setup
    ideal = hg.presets.ideal(hg.presets.tvg3_like(noise=False).resonator)
    short, long = (peak_bytes(jax.grad(loss_for(L, final=True, gyro=ideal)), params)
                   for L in (300.0, 3600.0))  # fmt: skip
    assert long == short
    assert long < 200_000  # 256 checkpoints of a few dozen float64 each, plus the program
