"""Convergence order of the full model against an exact solution."""

import diffrax
import jax
import numpy as np
import pytest
from helpers import OMEGA, resonator

import hrgjax as hg
from hrgjax.resonator.full import full_initial_state, full_vector_field


def exact(t, z0, c):
    """z = R(−ct) z₀ cos(ω′t), ω′ = √(ω² + c²), c = k_eΩ: exact for z̈ + 2cJż + ω²z = 0."""
    wp = np.sqrt(OMEGA**2 + c**2)
    a = -c * t
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    return rot @ z0 * np.cos(wp * t)


def test_full_model_convergence_order():
    rate = 30.0
    gyro = hg.Gyro(resonator(tau=1e12), control=hg.Control.free())
    prof = hg.Profile.constant_rate(rate, 0.5, wave_angle0_deg=25.0)
    y0, scale = full_initial_state(gyro, prof)
    t1 = 0.5
    z_true = exact(t1, np.asarray(y0[:2]), 0.554 * np.deg2rad(rate))

    @jax.jit
    def solve(dt):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(full_vector_field),
            diffrax.Tsit5(),
            0.0,
            t1,
            dt,
            y0,
            args=(gyro, prof, scale),
            stepsize_controller=diffrax.ConstantStepSize(),
            max_steps=100_000,
        )
        return sol.ys[-1, :2]

    steps = np.array([1000, 1414, 2000, 2828, 4000])
    errors = np.array([np.max(np.abs(np.asarray(solve(t1 / n)) - z_true)) for n in steps])
    order = np.polyfit(np.log(t1 / steps), np.log(errors), 1)[0]
    assert errors[-1] < 1e-6
    assert order == pytest.approx(5.0, abs=0.3)
