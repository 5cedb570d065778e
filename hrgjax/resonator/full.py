r"""Carrier-resolving two-pendulum vector field (PHYSICS.md §2) with the loops closed.

State $\mathbf y = (x, y, \dot x/\omega_s, \dot y/\omega_s, \psi_r, I_\varphi, I_{\rm agc}, I_q)$,
where $\omega_s$ is a fixed velocity scale (ω at the start) and $\psi_r$ the reference
phase of the PLL. The pickoff signals are demodulated instantaneously against $\psi_r$
(readout.py), the loops (control.py) form forces along the *estimated* antinode and node,
and the parametric pump acts at $2\psi_r + 2\gamma$.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .averaged import _input, input_rate
from .control import (
    drive_vectors,
    integrator_rates,
    loop_outputs,
    pump_phase,
    steady_integrators,
)
from .readout import estimate, from_signals

N_STATE = 8
_J = np.array([[0.0, -1.0], [1.0, 0.0]])  # NumPy: a module constant must not be a JAX array


def full_estimates(gyro, y, omega_scale, omega_in, readout=True):
    r"""Estimates from the full state (through the pickoff errors when `readout`).

    Emulates a low-pass demodulator of the displacement signals, which does not see the
    kinematic angular momentum $k_e\Omega E/\omega$ of a precessing pattern: the velocity is
    taken relative to the frame precessing at $-k_e\Omega$ ($\dot{\mathbf z} + k_e\Omega\mathbf J\mathbf z$).
    Without this the quadrature loop would null a fake $q = -k_e\Omega a/2\omega$ by creating
    real quadrature.

    The velocity channel is scaled by the PLL's tracked frequency ω + I_φ (the frequency
    the resonator actually oscillates at in lock): scaling by the mean ω instead leaves a 2ω
    ripple of relative size (ω_r − ω)/ω in the estimates, which the loops' proportional
    gains would rectify into a bias of the efforts.
    """
    z, zdot = y[0:2], y[2:4] * omega_scale
    zdot = zdot + gyro.resonator.k_e * omega_in * (_J @ z)
    demod = from_signals(z, zdot, y[4], gyro.resonator.omega + y[5])
    if readout:
        demod = demod.transform(gyro.readout.matrix())
    return estimate(demod)


def full_vector_field(t, y, args):
    """Right-hand side of the full model; `args = (gyro, profile, omega_scale)`."""
    gyro, profile, omega_scale = args
    rate, omega_dot, temperature, accel = profile.sample(t)
    g = gyro.at(temperature)
    res, ctl = g.resonator, g.control
    z, zdot = y[0:2], y[2:4] * omega_scale
    psi_r = y[4]
    omega_in = _input(g, profile, t, rate, accel)
    if ctl.enabled:
        est = full_estimates(g, y, omega_scale, omega_in)
        loops = loop_outputs(ctl, res.omega, est, y[5:8])
        u, v = drive_vectors(ctl, loops, est.theta)
        force = u * jnp.cos(psi_r) + v * jnp.sin(psi_r)
        pump = res.omega**2 * loops.pump * jnp.cos(2 * psi_r + 2 * pump_phase(ctl))
        d_int = integrator_rates(ctl, res.omega, est)
        omega_r = loops.omega_r
    else:
        force, pump, d_int, omega_r = 0.0 * z, 0.0, jnp.zeros(3), res.omega
    zddot = (
        force
        - res.damping_matrix @ zdot
        - res.stiffness_matrix @ z
        - 2 * res.k_e * omega_in * (_J @ zdot)
        - res.k_e * omega_dot * (_J @ z)
        - res.chi * (z @ z) * z
        + pump * z
    )
    return jnp.concatenate([zdot, zddot / omega_scale, jnp.reshape(omega_r, (1,)), d_int])


def full_initial_state(gyro, profile, quadrature0=0.0):
    """x = a₀cosθ₀, y = a₀sinθ₀ at ψ_r = 0, with the velocity of a pattern already precessing
    at −k_eΩ (no start transient); loop integrators at steady state."""
    g = gyro.at(profile.temperature[0])
    res = g.resonator
    a0 = g.control.amplitude
    th = profile.wave_angle0
    z0 = a0 * jnp.stack([jnp.cos(th), jnp.sin(th)])
    q_vel = quadrature0 * res.omega * jnp.stack([-jnp.sin(th), jnp.cos(th)])
    zdot0 = -res.k_e * input_rate(g, profile, profile.t[0]) * (_J @ z0) + q_vel
    integ = steady_integrators(g.control, res, a0, th)
    omega_scale = res.omega
    return jnp.concatenate([z0, zdot0 / omega_scale, jnp.zeros(1), integ]), omega_scale
