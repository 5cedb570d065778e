r"""Carrier-resolving two-pendulum vector field (PHYSICS.md §2) with the loops closed.

State $\mathbf y = (x, y, \dot x/\omega_s, \dot y/\omega_s, \psi_r, I_\varphi, I_{\rm agc}, I_q[, I_r, \theta_{\rm hold}])$,
where $\omega_s$ is a fixed velocity scale (ω at the start) and $\psi_r$ the reference
phase of the PLL. The pickoff signals are demodulated instantaneously against $\psi_r$
(readout.py), the loops (control.py) form forces along the *estimated* antinode and node,
and the parametric pump acts at $2\psi_r + 2\gamma$.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .averaged import held_angle, input_rate, measured_estimates, sampled_input_rate
from .control import (
    drive_vectors,
    integrator_rates,
    loop_outputs,
    pump_phase,
    steady_integrators,
)
from .readout import estimate, from_signals

N_STATE = 8
"""State size in whole-angle mode (10 in force-to-rebalance mode: + I_r, θ_hold)."""


def pattern_rate(g, omega_in, command=None):
    r"""The rate the wave turns at [rad/s, electrical] by the operating mode: $-k_e\Omega + \rho$
    in whole-angle mode (and where a force-to-rebalance schedule has the loop off), the
    commanded ρ while force-to-rebalance holds it."""
    rho = 0.0 if command is None else command[1]
    if g.control.mode == "ftr":
        on = 1.0 if command is None else command[2]
        return rho - (1.0 - on) * g.resonator.k_e * omega_in
    return -g.resonator.k_e * omega_in + rho


def full_estimates(gyro, y, omega_scale, omega_in, readout=True, command=None):
    r"""Estimates from the full state (through the pickoff errors when `readout`).

    Emulates a low-pass demodulator of the displacement signals, which does not see the
    kinematic angular momentum $\dot\theta E/\omega$ of a turning pattern: the velocity is
    taken relative to the frame turning at the pattern's rate $\dot\theta$
    ($\dot{\mathbf z} - \dot\theta\mathbf J\mathbf z$; $\dot\theta = -k_e\Omega + \rho$ in whole-angle
    mode, ρ in force-to-rebalance mode, [`pattern_rate`][hrgjax.resonator.full.pattern_rate]).
    Without this the quadrature loop would null a fake $q = \dot\theta a/2\omega$ by creating
    real quadrature.

    The velocity channel is scaled by the PLL's tracked frequency ω + I_φ (the frequency
    the resonator actually oscillates at in lock): scaling by the mean ω instead leaves a 2ω
    ripple of relative size (ω_r − ω)/ω in the estimates, which the loops' proportional
    gains would rectify into a bias of the efforts.
    """
    z, zdot = y[0:2], y[2:4] * omega_scale
    zdot = zdot - pattern_rate(gyro, omega_in, command) * _rot90(z)
    demod = from_signals(z, zdot, y[4], gyro.resonator.omega + y[5])
    if readout:
        demod = demod.transform(gyro.readout.matrix())
    return estimate(demod)


def full_vector_field(t, y, args):
    """Right-hand side of the full model; `args = (gyro, profile, omega_scale)`."""
    gyro, profile, omega_scale = args
    rate, omega_dot, temperature, accel = profile.sample(t)
    g = gyro.at(temperature)
    omega_in = sampled_input_rate(g, profile, t, rate, accel)
    command = profile.command_at(t)
    scheduled = profile.rebalance is not None
    dy = carrier_rhs(g, omega_in, omega_dot, y, omega_scale, command, scheduled)
    if not scheduled or g.control.mode != "ftr":
        return dy
    # while off, θ_hold follows θ̂ — which also moves as the readout's temperature laws do
    cmd = held_command(g, y, command)
    read = lambda temp: full_estimates(gyro.at(temp), y, omega_scale, omega_in, command=cmd).theta
    _, d_temp = jax.jvp(read, (temperature,), (profile.temperature_rate_at(t),))
    return dy.at[-1].add(jnp.where(command[2] > 0, 0.0, d_temp))


def held_command(g, y, command):
    """The loops' command with the held angle from the state (force-to-rebalance: the last
    entry of `y`), or `command` as it is (whole-angle)."""
    if g.control.mode != "ftr":
        return command
    if command is None:
        return (y[-1], 0.0 * y[0], 1.0 + 0.0 * y[0])
    return (y[-1], command[1], command[2])


def carrier_rhs(g, omega_in, omega_dot, y, omega_scale, command=None, scheduled=False):
    """The full model's right-hand side for a gyro `g` whose temperature laws are evaluated,
    the input rate `omega_in` [rad/s] and angular acceleration `omega_dot` [rad/s²]:
    demodulation, loops, forces and the two-pendulum dynamics at state `y` (`command`: the
    profile's, [`hrgjax.Profile.command_at`][]; `scheduled`: the profile switches the
    rebalance loop, and the held angle follows the estimate while it is off)."""
    z, zdot = y[0:2], y[2:4] * omega_scale
    psi_r = y[4]
    eff = loop_efforts(g, omega_in, y, omega_scale, command)
    force = eff.u * jnp.cos(psi_r) + eff.v * jnp.sin(psi_r)
    pump = eff.pump * jnp.cos(2 * psi_r + eff.pump_phase2)
    zddot = mechanics(g.resonator, omega_in, omega_dot, z, zdot, force, pump)
    dy = jnp.concatenate([zdot, zddot / omega_scale, jnp.reshape(eff.omega_r, (1,)), eff.d_int])
    if g.control.mode != "ftr":
        return dy
    cmd = held_command(g, y, command)
    d_hold = cmd[1]
    if scheduled:  # off: follow the estimate, d/dt θ̂(y) along the motion
        read = lambda state: full_estimates(g, state, omega_scale, omega_in, command=cmd).theta
        _, d_est = jax.jvp(read, (y,), (jnp.concatenate([dy, jnp.zeros(1)]),))
        d_hold = jnp.where(cmd[2] > 0, cmd[1], d_est)
    return jnp.concatenate([dy, jnp.reshape(d_hold, (1,))])


class LoopEfforts(eqx.Module):
    r"""What the closed loops apply, from the demodulated state: the electrode force
    $\mathbf u\cos\psi_r + \mathbf v\sin\psi_r$, the pump $P\cos(2\psi_r + 2\gamma)$ (`pump` = P
    [1/s²], `pump_phase2` = 2γ), the loop integrators' rates `d_int` (3,) ((4,) in FTR: the
    held angle's is the caller's) and the reference frequency `omega_r` [rad/s]."""

    u: jax.Array
    v: jax.Array
    pump: jax.Array
    pump_phase2: jax.Array
    d_int: jax.Array
    omega_r: jax.Array


def loop_efforts(g, omega_in, y, omega_scale, command=None) -> LoopEfforts:
    """Demodulation and loop laws at state `y` (zero efforts for free-running control)."""
    res, ctl = g.resonator, g.control
    if not ctl.enabled:
        zero = 0.0 * y[0]
        return LoopEfforts(jnp.zeros(2), jnp.zeros(2), zero, zero, jnp.zeros(3), res.omega + zero)
    command = held_command(g, y, command)
    est = full_estimates(g, y, omega_scale, omega_in, command=command)
    loops = loop_outputs(ctl, res.omega, est, y[5:], command)
    u, v = drive_vectors(ctl, loops, est.theta)
    return LoopEfforts(
        u=u,
        v=v,
        pump=res.omega**2 * loops.pump,
        pump_phase2=2 * pump_phase(ctl),
        d_int=integrator_rates(ctl, res.omega, est, command, y[5:]),
        omega_r=loops.omega_r,
    )


def mechanics(res, omega_in, omega_dot, z, zdot, force, pump):
    r"""The two-pendulum acceleration $\ddot{\mathbf z}$ (PHYSICS.md §2): electrode force, damping
    and stiffness with their defects, Coriolis $-2k_e\Omega\mathbf J\dot{\mathbf z}$, angular
    acceleration $-k_e\dot\Omega\mathbf J\mathbf z$, Duffing $-\chi|\mathbf z|^2\mathbf z$ and the
    parametric pump (`pump` the factor multiplying z)."""
    return (
        force
        - _times(res.damping_matrix, zdot)
        - _times(res.stiffness_matrix, z)
        - 2 * res.k_e * omega_in * _rot90(zdot)
        - res.k_e * omega_dot * _rot90(z)
        - res.chi * (z[0] ** 2 + z[1] ** 2) * z
        + pump * z
    )


def _rot90(z):
    """J z = (−z_y, z_x): a quarter turn of a 2-vector."""
    return jnp.stack([-z[1], z[0]])


def _times(m, z):
    """m @ z for a 2 × 2 matrix, elementwise: a tiny dot is a kernel of its own on XLA:CPU
    that does not fuse with the arithmetic around it (this runs at every stage)."""
    return jnp.stack([m[0, 0] * z[0] + m[0, 1] * z[1], m[1, 0] * z[0] + m[1, 1] * z[1]])


def full_initial_state(gyro, profile, quadrature0=0.0):
    """x = a₀cosθ₀, y = a₀sinθ₀ at ψ_r = 0, with the velocity of a pattern already turning at
    its mode's rate (−k_eΩ + ρ whole-angle, ρ force-to-rebalance: no start transient of the
    motion; FTR holds θ₀ where the estimate reads the commanded angle); loop integrators at
    steady state (for ideal forcers: their gain and angle errors start a short transient)."""
    g = gyro.at(profile.temperature[0])
    res = g.resonator
    a0 = g.control.amplitude
    th0 = th = profile.wave_angle0
    command = profile.command_at(profile.t[0])
    on = command[2]
    ftr = g.control.mode == "ftr"
    if ftr:  # as the averaged model's start (`averaged_initial_state`)
        th = on * held_angle(g, a0, th0) + (1.0 - on) * th0
    omega_in = input_rate(g, profile, profile.t[0])
    z0 = a0 * jnp.stack([jnp.cos(th), jnp.sin(th)])
    q_vel = quadrature0 * res.omega * jnp.stack([-jnp.sin(th), jnp.cos(th)])
    rate0 = pattern_rate(g, omega_in, command)
    zdot0 = rate0 * _rot90(z0) + q_vel
    integ = steady_integrators(g.control, res, a0, th, omega_in, on)
    omega_scale = res.omega
    y0 = jnp.concatenate([z0, zdot0 / omega_scale, jnp.zeros(1), integ])
    if ftr:
        read = measured_estimates(g, a0, 0.0 * a0, th, 0.0 * a0).theta
        y0 = jnp.concatenate([y0, jnp.reshape(on * th0 + (1.0 - on) * read, (1,))])
    return y0, omega_scale
