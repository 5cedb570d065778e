r"""Whole-angle control loops (PHYSICS.md §5): PLL, amplitude (AGC), quadrature null.

Every loop is a PI controller acting on an *estimate* (readout errors feed back):

- PLL: reference frequency $\omega_r = \omega + k_p\hat\varphi + I_\varphi$;
- AGC by force: antinode force $f_a = -F\sin(\psi_r+\gamma_e)$,
  $F = k_p(a_0-\hat a) + I_F$; or by parametric pump: depth $h = k_p(a_0-\hat a) + I_h$,
  pump $-\omega^2h\cos(2\psi_r + 2\gamma)$ with $2\gamma = \pi/2 + \gamma_e$;
- quadrature: node force $f_q = f_{qc}\cos\psi_r$, $f_{qc} = -k_p\hat q + I_q$.

Gains are set from loop bandwidths: for a plant $\dot e = b\,u$ the PI gains
$k_p = 2\beta/b$, $k_i = \beta^2/b$ place a double closed-loop pole at $-\beta$.
The loops are "slow time" loops: bandwidths must be far below ω for averaging to hold.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from .params import TemperatureLaw, as_parameter

DRIVES = ("force", "parametric")


class Control(eqx.Module):
    """Whole-angle mode loops.

    **Arguments:**

    - `amplitude`: AGC set point $a_0$ (readout units, > 0).
    - `drive`: `"force"` (discrete-electrode AGC along the estimated antinode) or
      `"parametric"` (ring-electrode pump at $2\\omega_r$, isotropic).
    - `excitation_phase`: $\\gamma_e$ [rad], phase error of the excitation (force drive:
      of the antinode force; parametric: of the pump in $2\\psi$, β = π/2 + γ_e).
    - `pll_bandwidth`, `agc_bandwidth`, `quadrature_bandwidth`: closed-loop bandwidths
      [rad/s]; 0 opens that loop.
    - `ideal`: loops held perfectly at their set points (a = a₀, q = 0, φ = 0). The averaged
      model then integrates only the wave angle; the full model uses the PI loops.
    - `forcer_gain_mismatch`: relative gain difference of the x and y forcers.
    - `enabled`: `False` for a free-running resonator (see [`Control.free`][hrgjax.Control.free]).

    A loop with bandwidth 0 holds its effort at the initial steady-state value (open loop).
    """

    amplitude: jax.Array = eqx.field(converter=as_parameter, default=1.0)
    drive: str = eqx.field(static=True, default="force")
    excitation_phase: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    pll_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=2.0)
    agc_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=1.0)
    quadrature_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=2.0)
    ideal: bool = eqx.field(static=True, default=False)
    forcer_gain_mismatch: jax.Array | TemperatureLaw = eqx.field(
        converter=as_parameter, default=0.0
    )
    enabled: bool = eqx.field(static=True, default=True)

    @classmethod
    def free(cls, amplitude=1.0) -> Control:
        """No loops: no forces, no pump, reference at ω (free oscillation or decay from
        amplitude `amplitude`)."""
        return cls(amplitude=amplitude, enabled=False)

    def __check_init__(self):
        if self.drive not in DRIVES:
            raise ValueError(f"Control.drive must be one of {DRIVES}; got {self.drive!r}")

    def forcer_matrix(self):
        """Forcer gain matrix diag(1 + g, 1 − g) applied to the electrode-frame force."""
        g = self.forcer_gain_mismatch
        return jnp.stack([jnp.stack([1.0 + g, 0.0 * g]), jnp.stack([0.0 * g, 1.0 - g])])


class LoopOutputs(eqx.Module):
    omega_r: jax.Array
    """Reference (PLL) frequency [rad/s]."""
    force: jax.Array
    """AGC force amplitude F (force drive) [readout units · rad²/s²]."""
    pump: jax.Array
    """Parametric pump depth h (parametric drive) [-]."""
    quad_force: jax.Array
    """Quadrature force $f_{qc}$."""


def _gains(bandwidth, plant_gain):
    return 2.0 * bandwidth / plant_gain, bandwidth**2 / plant_gain


def loop_gains(control: Control, omega):
    """PI gains (kp, ki) of the PLL, AGC and quadrature loops."""
    pll = _gains(control.pll_bandwidth, 1.0)
    if control.drive == "force":
        agc = _gains(control.agc_bandwidth, 1.0 / (2.0 * omega))
    else:
        agc = _gains(control.agc_bandwidth, omega * control.amplitude / 4.0)
    quad = _gains(control.quadrature_bandwidth, 1.0 / (2.0 * omega))
    return pll, agc, quad


def loop_outputs(control: Control, omega, est, integrators) -> LoopOutputs:
    """Loop efforts from estimates and integrator states `(I_pll, I_agc, I_quad)`."""
    (kp_p, _), (kp_a, _), (kp_q, _) = loop_gains(control, omega)
    i_pll, i_agc, i_quad = integrators
    agc = kp_a * (control.amplitude - est.amplitude) + i_agc
    zero = jnp.zeros_like(agc)
    if not control.enabled:
        return LoopOutputs(omega_r=omega + zero, force=zero, pump=zero, quad_force=zero)
    return LoopOutputs(
        omega_r=omega + kp_p * est.phase + i_pll,
        force=agc if control.drive == "force" else zero,
        pump=agc if control.drive == "parametric" else zero,
        quad_force=-kp_q * est.quadrature + i_quad,
    )


def integrator_rates(control: Control, omega, est):
    """Time derivatives of the loop integrators."""
    (_, ki_p), (_, ki_a), (_, ki_q) = loop_gains(control, omega)
    if not control.enabled:
        return jnp.zeros(3) * est.phase
    return jnp.stack(
        [
            ki_p * est.phase,
            ki_a * (control.amplitude - est.amplitude),
            ki_q * (-est.quadrature),
        ]
    )


def drive_vectors(control: Control, loops: LoopOutputs, theta_est):
    r"""Electrode-frame force as $\mathbf f = \mathbf u\cos\psi_r + \mathbf v\sin\psi_r$.

    The AGC force lies along the estimated antinode, the quadrature force along the
    estimated node; the forcer gain mismatch is applied last.
    """
    c, s = jnp.cos(theta_est), jnp.sin(theta_est)  # e_a = (c, s), e_q = (−s, c)
    g = control.excitation_phase if control.drive == "force" else 0.0
    fs, fc, fq = -loops.force * jnp.sin(g), -loops.force * jnp.cos(g), loops.quad_force
    m = control.forcer_matrix()  # diagonal: applied elementwise (no 2 × 2 dot kernel)
    u = jnp.stack([m[0, 0] * (fs * c - fq * s), m[1, 1] * (fs * s + fq * c)])
    v = jnp.stack([m[0, 0] * fc * c, m[1, 1] * fc * s])
    return u, v


def pump_phase(control: Control):
    """Pump phase γ with 2γ = π/2 + γ_e (optimal pumping at γ_e = 0)."""
    e = control.excitation_phase if control.drive == "parametric" else 0.0
    return 0.25 * jnp.pi + 0.5 * e


def steady_integrators(control: Control, res, a, theta):
    """Integrator values at the loops' steady state (used as initial conditions).

    AGC: $F = 2\\omega a[1/\\tau + \\tfrac12\\Delta(1/\\tau)\\cos2(\\theta-\\theta_\\tau)]/\\cos\\gamma_e$
    or $h = 4[\\dots]/\\omega$; quadrature: $f_{qc} = -\\omega\\Delta\\omega\\,a\\sin2(\\theta-\\theta_\\omega)$;
    PLL: $\\omega_r = \\omega + \\tfrac12\\Delta\\omega\\cos2(\\theta-\\theta_\\omega)$.
    """
    if not control.enabled:
        return jnp.zeros(3) * a
    loss = 1.0 / res.tau + 0.5 * res.delta_inv_tau * jnp.cos(2 * (theta - res.theta_tau))
    if control.drive == "force":
        i_agc = 2.0 * res.omega * a * loss / jnp.cos(control.excitation_phase)
    else:
        i_agc = 4.0 * loss / (res.omega * jnp.cos(control.excitation_phase))
    i_quad = -res.omega * res.delta_omega * a * jnp.sin(2 * (theta - res.theta_omega))
    i_pll = 0.5 * res.delta_omega * jnp.cos(2 * (theta - res.theta_omega)) + 3 * res.chi * a**2 / (
        8 * res.omega
    )
    return jnp.stack([i_pll, i_agc, i_quad])
