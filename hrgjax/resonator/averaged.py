r"""Slow-variable (averaged) vector field, PHYSICS.md §3.2, with the loops closed.

State $\mathbf y = (a, q, \theta, \varphi, I_\varphi, I_{\rm agc}, I_q[, I_r, \theta_{\rm hold}])$:
principal and quadrature amplitudes, electrical wave angle, phase relative to the reference,
the loop integrators and, in force-to-rebalance mode, the rebalance loop's integrator and the
angle it holds ($\dot\theta_{\rm hold} = \rho$ while it holds; while a `rebalance` schedule
runs whole-angle it follows the estimate, $\dot\theta_{\rm hold} = \dot{\hat\theta}$, so that
switching back captures the wave where it is read). The forces of the loops are formed from *estimates* of the measured
demodulated signals, then projected on the true pattern frame, so readout errors act on the
dynamics exactly as in the full model.

$$\dot a = -\tfrac a\tau - \tfrac12\Delta(\tfrac1\tau)c_\tau a - \tfrac12\Delta\omega s_\omega q
  - \tfrac{f_{as}}{2\omega} + \tfrac{\omega h}4\sin\beta\,a$$
$$\dot q = -\tfrac q\tau + \tfrac12\Delta(\tfrac1\tau)c_\tau q + \tfrac12\Delta\omega s_\omega a
  + \tfrac{f_{qc}}{2\omega} - \tfrac{\omega h}4\sin\beta\,q$$
$$\dot\theta = -k_e\Omega + \tfrac12\Delta(\tfrac1\tau)s_\tau P - \tfrac12\Delta\omega c_\omega\Pi
  + \tfrac{qf_{ac}-af_{qs}}{2\omega(a^2-q^2)} - \tfrac{\chi aq}{4\omega} + \tfrac{\omega h}4\cos\beta\,\Pi$$
$$\dot\varphi = (\omega-\omega_r) + \tfrac{k_e^2\Omega^2}{2\omega} + \tfrac12\Delta\omega c_\omega P
  - \tfrac12\Delta(\tfrac1\tau)s_\tau\Pi + \tfrac{qf_{qs}-af_{ac}}{2\omega(a^2-q^2)}
  + \tfrac{3\chi(a^2+q^2)}{8\omega} - \tfrac{\omega h}4\cos\beta\,P$$

with $\beta = 2(\gamma-\varphi)$, $P = (a^2+q^2)/(a^2-q^2)$, $\Pi = 2aq/(a^2-q^2)$.
When ω follows a temperature law on a ramp, $\dot a$ and $\dot q$ also take
$-\tfrac12(\mathrm d\ln\omega/\mathrm dt)\,a$ and $-\tfrac12(\mathrm d\ln\omega/\mathrm dt)\,q$
(first-order averaging of $\ddot x + \omega(t)^2x = 0$ with $\dot x = -\omega A\sin\psi$:
$\dot A = -\tfrac{\dot\omega}{\omega}A\sin^2\psi$, $\dot\psi$'s term goes as
$\sin\psi\cos\psi$ and averages out, so θ and φ take nothing) — the adiabatic invariant
$E/\omega$: a free amplitude goes as $e^{-t/\tau}\sqrt{\omega(0)/\omega(t)}$. The laws of
Δω, θ_ω change the stiffness anisotropically; their like terms, $O(\dot{\Delta\omega}/\omega)$, are
left out.
$\Omega$ here is the equivalent input rate: table rate + rate bias + g-sensitivity · f.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .control import (
    drive_vectors,
    integrator_rates,
    loop_outputs,
    pump_phase,
    steady_integrators,
)
from .params import TemperatureLaw
from .readout import estimate, from_pendulum

N_STATE = 7
"""State size in whole-angle mode (9 in force-to-rebalance mode: + I_r, θ_hold)."""


def sampled_input_rate(gyro, profile, t, rate, accel):
    """[`input_rate`][hrgjax.resonator.averaged.input_rate] from the profile already sampled
    at `t` [s]: table `rate` [rad/s] and specific force `accel` (3,) [g] (a caller that
    samples the profile itself, or holds the rate over a step)."""
    gs = gyro.g_sensitivity  # elementwise, not a 3-dot (a kernel of its own on XLA:CPU)
    omega = rate + gyro.rate_bias + (gs[0] * accel[0] + gs[1] * accel[1] + gs[2] * accel[2])
    if gyro.drift_terms is not None:
        omega = omega + gyro.drift_terms.input_rate(profile, t)
    return omega


def input_rate(gyro, profile, t):
    """Equivalent input rate [rad/s]: table rate + rate bias + g-sensitivity · specific force
    (+ the gyro's [`DriftTerms`][hrgjax.DriftTerms])."""
    rate, _, _, accel = profile.sample(t)
    return sampled_input_rate(gyro, profile, t, rate, accel)


def pattern_forces(u, v, phi, theta):
    """Pattern-frame force coefficients $(f_{ac}, f_{as}, f_{qc}, f_{qs})$ at the true phase
    ψ = ψ_r + φ from electrode-frame $\\mathbf u\\cos\\psi_r + \\mathbf v\\sin\\psi_r$."""
    cp, sp = jnp.cos(phi), jnp.sin(phi)
    big_u = u * cp - v * sp
    big_v = u * sp + v * cp
    c, s = jnp.cos(theta), jnp.sin(theta)  # e_a = (c, s), e_q = (−s, c); written out, as
    # a 2-vector dot is an XLA:CPU kernel of its own (and so is its VJP)
    return (
        c * big_u[0] + s * big_u[1],
        c * big_v[0] + s * big_v[1],
        -s * big_u[0] + c * big_u[1],
        -s * big_v[0] + c * big_v[1],
    )


def canonical_angle(a, q, theta):
    r"""The state's wave angle θ [rad] in the canonical form |a| ≥ |q| (PHYSICS.md §3.1):
    θ where |q| ≤ |a|, else θ − π/2. The pendulum variables are two-valued,
    $(a, q, \theta, \varphi) \equiv (q, a, \theta \mp \pi/2, \varphi \pm \pi/2)$ give
    the same x, y, and the averaged equations carry the state through q = a (a free
    wave 45° off a frequency split turns its ellipse into a circle and on, Δω·t/2 in the
    (a, q) plane) without the swap: θ stays put while the antinode (the larger of |a|, |q|)
    is now on the node axis. θ ± π/2 are one standing wave (θ is known modulo π); −π/2 is
    where a slightly smaller θ − θ_ω ends. The estimates (`measured_estimates`) are read on
    this branch: on the state's own they flip by π from one sample to the next."""
    return theta - jnp.where(jnp.abs(q) > jnp.abs(a), 0.5 * jnp.pi, 0.0)


def measured_estimates(gyro, a, q, theta, phi):
    """What the electronics estimate from the pendulum state, through the pickoff errors
    (the angle on the canonical branch, |a| ≥ |q|: `canonical_angle`)."""
    demod = from_pendulum(a, q, theta, phi).transform(gyro.readout.matrix())
    return estimate(demod, theta_branch=canonical_angle(a, q, theta))


def averaged_vector_field(t, y, args):
    """Right-hand side of the averaged model; `args = (gyro, profile)`."""
    gyro, profile = args
    rate, _, temperature, accel = profile.sample(t)
    g = gyro.at(temperature)
    res, ctl = g.resonator, g.control
    omega_in = sampled_input_rate(g, profile, t, rate, accel)
    if ctl.ideal:
        if profile.rebalance is not None:
            raise ValueError("a Profile.rebalance schedule needs the PI loops: give the gyro "
                             "Control(ideal=False)")  # fmt: skip
        rho = profile.precession_at(t)
        if ctl.mode == "ftr":  # held exactly at the commanded angle
            return jnp.reshape(rho, (1,))
        d_theta = (
            -res.k_e * omega_in
            + 0.5 * res.delta_inv_tau * jnp.sin(2 * (y[0] - res.theta_tau))
            + rho
        )
        return d_theta[None]
    command = profile.command_at(t)
    ln_omega_rate = None
    if isinstance(gyro.resonator.omega, TemperatureLaw):  # d ln ω/dt along the ramp
        law = gyro.resonator.omega
        _, d_omega = jax.jvp(law, (temperature,), (profile.temperature_rate_at(t),))
        ln_omega_rate = d_omega / res.omega
    dy = loop_field(g, omega_in, y, command, profile.rebalance is not None, ln_omega_rate)
    if profile.rebalance is None or ctl.mode != "ftr":
        return dy
    # while off, θ_hold follows θ̂ — which also moves as the readout's temperature laws do
    _, d_temp = jax.jvp(lambda temp: measured_estimates(gyro.at(temp), *y[:4]).theta,
                        (temperature,), (profile.temperature_rate_at(t),))  # fmt: skip
    return dy.at[8].add(jnp.where(command[2] > 0, 0.0, d_temp))


def loop_field(g, omega_in, y, command=None, scheduled=False, ln_omega_rate=None):
    """The averaged model's right-hand side with the PI loops, for a gyro `g` already at its
    temperature, equivalent input rate `omega_in` [rad/s] and state `y` (module docstring);
    `command` = (commanded angle [rad], commanded precession [rad/s], rebalance on/off) or
    `None` — in force-to-rebalance mode the held angle is the state's θ_hold; `scheduled`: the
    profile switches the rebalance loop (θ_hold then follows the estimate while it is off);
    `ln_omega_rate`: d ln ω/dt [1/s] of a natural frequency that changes in time (a
    temperature law on a ramp), or `None` (constant: no term at all)."""
    res, ctl = g.resonator, g.control
    a, q, theta, phi = y[0], y[1], y[2], y[3]
    est = measured_estimates(g, a, q, theta, phi)
    ftr = ctl.mode == "ftr"
    if ftr:
        if command is None:
            command = (y[8], 0.0 * a, 1.0 + 0.0 * a)
        command = (y[8], command[1], command[2])
    loops = loop_outputs(ctl, res.omega, est, y[4:], command)
    u, v = drive_vectors(ctl, loops, est.theta)
    f_ac, f_as, f_qc, f_qs = pattern_forces(u, v, phi, theta)

    w = res.omega
    ct, st = jnp.cos(2 * (theta - res.theta_tau)), jnp.sin(2 * (theta - res.theta_tau))
    cw, sw = jnp.cos(2 * (theta - res.theta_omega)), jnp.sin(2 * (theta - res.theta_omega))
    d2 = a**2 - q**2
    big_p = (a**2 + q**2) / d2
    big_pi = 2 * a * q / d2
    beta = 2 * (pump_phase(ctl) - phi)
    pump = w * loops.pump / 4

    da = (
        -a / res.tau
        - 0.5 * res.delta_inv_tau * ct * a
        - 0.5 * res.delta_omega * sw * q
        - f_as / (2 * w)
        + pump * jnp.sin(beta) * a
    )
    dq = (
        -q / res.tau
        + 0.5 * res.delta_inv_tau * ct * q
        + 0.5 * res.delta_omega * sw * a
        + f_qc / (2 * w)
        - pump * jnp.sin(beta) * q
    )
    dtheta = (
        -res.k_e * omega_in
        + 0.5 * res.delta_inv_tau * st * big_p
        - 0.5 * res.delta_omega * cw * big_pi
        + (q * f_ac - a * f_qs) / (2 * w * d2)
        - res.chi * a * q / (4 * w)
        + pump * jnp.cos(beta) * big_pi
    )
    dphi = (
        (w - loops.omega_r)
        + (res.k_e * omega_in) ** 2 / (2 * w)
        + 0.5 * res.delta_omega * cw * big_p
        - 0.5 * res.delta_inv_tau * st * big_pi
        + (q * f_qs - a * f_ac) / (2 * w * d2)
        + 3 * res.chi * (a**2 + q**2) / (8 * w)
        - pump * jnp.cos(beta) * big_p
    )
    if ln_omega_rate is not None:  # adiabatic: a, q ∝ ω^(-1/2) (module docstring)
        da = da - 0.5 * ln_omega_rate * a
        dq = dq - 0.5 * ln_omega_rate * q
    d_int = integrator_rates(ctl, w, est, command, y[4:])
    if not ftr:
        return jnp.concatenate([jnp.stack([da, dq, dtheta, dphi]), d_int])
    d_hold = command[1]
    if scheduled:  # off: follow the estimate, d/dt θ̂(a, q, θ, φ) along the motion
        _, d_est = jax.jvp(lambda *s: measured_estimates(g, *s).theta, (a, q, theta, phi),
                           (da, dq, dtheta, dphi))  # fmt: skip
        d_hold = jnp.where(command[2] > 0, command[1], d_est)
    return jnp.concatenate([jnp.stack([da, dq, dtheta, dphi]), d_int, jnp.reshape(d_hold, (1,))])


def turning_index(gyro):
    """Index of the state that accumulates the turned angle where nothing else bounds the
    adaptive solver's step: θ of ideal whole-angle loops (0) or of a free resonator (2);
    `None` with the PI loops (their a, q, φ and integrators hold the step) and for ideal
    force-to-rebalance loops (no defect term in the held angle's field)."""
    ctl = gyro.control
    if ctl.ideal:
        return None if ctl.mode == "ftr" else 0
    return None if ctl.enabled else 2


def reference_angle(gyro, profile, t):
    r"""The turn that `simulate` takes out of the turning state (`turning_index`), and its
    rate: $\theta_{\rm ref}(t) = \theta_{\rm cmd}(t) - k_e(T_0)\,(\int\Omega\,\mathrm dt +
    b\,(t - t_0))$ [rad], $\dot\theta_{\rm ref}$ [rad/s] (θ_cmd = θ₀ + ∫ρ dt with ideal
    loops, θ₀ free; k_e and the rate bias b at the profile's first temperature). Exact for
    the piecewise-linear profile, so the solver integrates $r = \theta - \theta_{\rm ref}$,
    whose field is the defect terms and what the reference leaves out (other temperatures'
    k_e, g-sensitivity, drift terms): its tolerance atol + rtol·|r| no longer grows with
    the turned angle (docs/simulate.md, "Turned angle")."""
    g0 = gyro.at(profile.temperature[0])
    k_e, bias = g0.resonator.k_e, g0.rate_bias
    turn = profile.table_angle_at(t) + bias * (t - profile.t[0])
    rate = profile.rate_at(t) + bias
    if gyro.control.ideal:
        return profile.commanded_angle_at(t) - k_e * turn, profile.precession_at(t) - k_e * rate
    return profile.wave_angle0 - k_e * turn, -k_e * rate


def residual_vector_field(t, z, args):
    """`averaged_vector_field` of the state with its turning angle less `reference_angle`
    (`args = (gyro, profile)`; the gyro must have a `turning_index`)."""
    gyro, profile = args
    i = turning_index(gyro)
    ref, ref_rate = reference_angle(gyro, profile, t)
    return averaged_vector_field(t, z.at[i].add(ref), args).at[i].add(-ref_rate)


def averaged_problem(gyro, profile, quadrature0=0.0):
    """What `simulate` solves for the averaged model: `(z0, field, states)`, the start, the
    right-hand side and `states(ts, zs)`, the model's states (module docstring) at output
    times `ts` from the solved ones. Where a state only accumulates the turned angle
    (`turning_index`) the solver integrates its residual (`reference_angle`); otherwise
    `averaged_initial_state`, `averaged_vector_field` and the states as solved."""
    y0 = averaged_initial_state(gyro, profile, quadrature0)
    i = turning_index(gyro)
    if i is None:
        return y0, averaged_vector_field, lambda ts, zs: zs

    def states(ts, zs):
        return zs.at[:, i].add(jax.vmap(lambda t: reference_angle(gyro, profile, t)[0])(ts))

    z0 = y0.at[i].add(-reference_angle(gyro, profile, profile.t[0])[0])
    return z0, residual_vector_field, states


def held_angle(g, a, theta_cmd, iterations: int = 4):
    """The true wave angle [rad] at which the estimate (through the readout errors) reads
    `theta_cmd`: where force-to-rebalance holds the wave (fixed-point iteration; the readout
    error is ≈ 1e-2 rad at most, so each pass gains two orders)."""
    theta = theta_cmd
    for _ in range(iterations):
        theta = theta + (theta_cmd - measured_estimates(g, a, 0.0 * a, theta, 0.0 * a).theta)
    return theta


def averaged_initial_state(gyro, profile, quadrature0=0.0):
    """Start on the slow manifold: a = a₀, q = q₀, φ = 0, loop integrators at steady state."""
    g = gyro.at(profile.temperature[0])
    theta0 = profile.wave_angle0
    if g.control.ideal:
        return theta0[None]
    a0 = g.control.amplitude
    omega_in = input_rate(g, profile, profile.t[0])
    if g.control.mode != "ftr":
        integ = steady_integrators(g.control, g.resonator, a0, theta0, omega_in)
        return jnp.concatenate([jnp.stack([a0, quadrature0 + 0.0 * a0, theta0, 0.0 * a0]), integ])
    # FTR: held where the *estimate* reads the commanded angle; starting whole-angle (a
    # schedule's first segment off), the wave is at θ₀ and the held angle is its estimate
    on = profile.rebalance_at(profile.t[0])
    held = held_angle(g, a0, theta0)
    theta = on * held + (1.0 - on) * theta0
    read = measured_estimates(g, a0, 0.0 * a0, theta, 0.0 * a0).theta
    integ = steady_integrators(g.control, g.resonator, a0, theta, omega_in, on)
    hold = on * theta0 + (1.0 - on) * read
    return jnp.concatenate([jnp.stack([a0, quadrature0 + 0.0 * a0, theta, 0.0 * a0]), integ,
                            jnp.reshape(hold, (1,))])  # fmt: skip
