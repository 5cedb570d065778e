r"""The HRG's control loops (PHYSICS.md §5): PLL, amplitude (AGC), quadrature null and, in
force-to-rebalance mode, the rebalance loop; the commanded (virtual) precession.

Every loop is a PI controller acting on an *estimate* (readout errors feed back):

- PLL: reference frequency $\omega_r = \omega + k_p\hat\varphi + I_\varphi$;
- AGC by force: antinode force $f_a = -F\sin(\psi_r+\gamma_e)$,
  $F = k_p(a_0-\hat a) + I_F$; or by parametric pump: depth $h = k_p(a_0-\hat a) + I_h$,
  pump $-\omega^2h\cos(2\psi_r + 2\gamma)$ with $2\gamma = \pi/2 + \gamma_e$;
- quadrature: node force $f_q = f_{qc}\cos\psi_r$, $f_{qc} = -k_p\hat q + I_q$;
- commanded precession at $\rho$ [rad/s, electrical] (virtual precession, the profile's
  schedule): a feed-forward node force in phase with the velocity,
  $f_{qs}^{\rm ff} = -2\omega_r\hat a\,\rho$, which turns the wave at $\dot\theta = \rho$
  through $\dot\theta \ni -f_{qs}/(2\omega a)$ (PHYSICS.md §3.2) — up to the forcers' own errors;
- force-to-rebalance (`mode="ftr"`): a PI loop on $x = \hat\theta - \theta_{\rm cmd}$ (the
  commanded angle: the start angle plus $\int\rho\,dt$) adds $u = -k_p x + I_r$ to
  $f_{qs}$. The plant is $\dot x = -u/(2\omega a_0) + d$, so $b = -1/(2\omega a_0)$; at rest
  $u = 2\omega a\,d$ with $d = -k_e\Omega + $ (the drift at the held angle), and the output
  is the rate $\hat\Omega = -u/(2\omega_r\hat a\,k_{e,\rm nom})$
  ([`ftr_rate`][hrgjax.resonator.control.ftr_rate]).

Gains are set from loop bandwidths: for a plant $\dot e = b\,u$ the PI gains
$k_p = 2\beta/b$, $k_i = \beta^2/b$ place a double closed-loop pole at $-\beta$.
The loops are "slow time" loops: bandwidths must be far below ω for averaging to hold.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_flag, numeric_problem
from ..units import K_E_NOMINAL
from .params import TemperatureLaw, as_parameter, refuse_unconverted
from .readout import check_limits, wrap_half_pi

DRIVES = ("force", "parametric")
MODES = ("wa", "ftr")
"""Operating modes: whole-angle (rate-integrating) and force-to-rebalance (rate)."""

LIMITS = {  # field: (rule of `hrgjax._checks.RULES`, unit); why: `Control`'s docstring
    "amplitude": ("> 0", "readout units"),
    "excitation_phase": ("in (-π/4, π/4)", "rad"),
    **{f"{loop}_bandwidth": (">= 0", "rad/s") for loop in ("pll", "agc", "quadrature")},
    "rebalance_bandwidth": (">= 0", "rad/s"),
    "forcer_gain_mismatch": ("in (-0.5, 0.5)", "(a fraction, not percent)"),
    "forcer_gain": ("> -1", "(a fraction, not percent: the forcers' gain is 1 + forcer_gain)"),
    "forcer_angle": ("in (-π/4, π/4)", "rad (electrical)"),
    "rebalance_limit": ("> 0", "readout units · rad²/s²"),
    "k_e_nominal": ("in (0, 1]", "(the electrical angular gain 2K, ≈ 0.554)"),
}
"""The range of each `Control` field; `simulate` holds temperature laws and traced values to
them too (`hrgjax._run_checks.LAW_LIMITS`)."""
FTR_LIMITS = {"rebalance_bandwidth": ("> 0", "rad/s in FTR mode (at 0 the rebalance loop is "
                                      "open: its output is not the rate)")}  # fmt: skip
"""The fields whose range is narrower in force-to-rebalance mode (`mode="ftr"`), in `LIMITS`'s
form: its loop must be closed (whole-angle mode does not read it: any bandwidth ≥ 0)."""


IDEAL_LIMIT = (
    "Control.rebalance_limit needs Control.ideal=False in mode='ftr' with the averaged model: "
    "its ideal loops hold the wave with whatever force it takes and cannot saturate; give "
    "rebalance_limit=None, or ideal=False (the PI loops, which saturate and let the wave "
    "drift; the full model always runs them)"
)
"""The one line refusing ideal force-to-rebalance loops with a force limit (`Control`)."""

AVERAGED_BANDWIDTH = 0.1
"""The largest loop bandwidth the averaged model takes, as a fraction of the carrier ω: its
loops act on the slow variables averaged over a carrier cycle, an error that grows about as
(β/ω)² (full − averaged wave angle 0.23″, 1.4″, 8.9″ at β/ω = 0.02, 0.08, 0.2 over 11° of
travel; a real HRG's loops close at 1–100 Hz on a 5 kHz carrier, β/ω ≤ 0.02); `simulate` refuses a
bandwidth at or above 0.1 ω at any of the run's temperatures (`model="full"` resolves
the carrier), and so a damping rate 1/τ (1/τ + ½|Δ(1/τ)| on an axis) or a split |Δω|
(`hrgjax._run_checks.check_bandwidths`)."""


def _plain_bool(x):
    """A NumPy bool as a Python one (a static field must not hold a NumPy scalar); anything
    else as it is, for `Control.__check_init__` to refuse unless it is a bool."""
    return bool(x) if isinstance(x, np.bool_) else x


def _untraced_gain(value):
    """`Control.k_e_nominal` as given, or a one-line `TypeError` for a traced one (a static
    field: JAX warned, and its derivative read 0 after an eager call)."""
    if isinstance(value, jax.core.Tracer):
        raise TypeError(
            "Control.k_e_nominal is a setting of the electronics (static: one compiled "
            "program per value), not a traced value: give it as a number, outside "
            "jit/vmap/grad; sweep or differentiate the resonator's k_e instead"
        )
    return value


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
    - `mode`: `"wa"` (whole-angle: the wave turns with the case, the output is its angle) or
      `"ftr"` (force-to-rebalance: a node force holds the wave at the commanded angle, the
      output is the rate read from that force; [`Record.rebalance_rate`][hrgjax.Record]).
    - `rebalance_bandwidth`: closed-loop bandwidth of the rebalance loop [rad/s] (`"ftr"`;
      > 0 there: an open rebalance loop holds its start force, and the output is not the
      rate. Whole-angle mode does not read it).
    - `rebalance_limit`: largest node force the rebalance loop may command (forcer
      saturation) [readout units · rad²/s²]; `None` for none. At the default gyro
      (ω = 2π·5 kHz, a₀ = 1, k_e = 0.554) 1 °/s needs 2ωa₀k_eΩ ≈ 608. While saturated the
      loop's integrator stops (anti-windup). Needs the PI loops (`ideal=False`): ideal loops
      cannot saturate, and the pair is refused.
    - `k_e_nominal`: the angular gain the electronics divide the rebalance force by to read
      the rate (FTR output) — the nominal one, as whole-angle data are read with, so a gyro
      whose k_e differs from it, or varies with temperature, shows it as a scale factor. A
      number (static: each value compiles its own program; a traced one is refused — the
      resonator's `k_e` is the value to sweep or differentiate).
    - `forcer_gain`: common relative gain error of both forcers (1 + `forcer_gain`): it scales
      every force, so the FTR scale factor by 1/(1 + g_f) and a commanded precession by
      (1 + g_f); the loops' own efforts absorb it.
    - `forcer_angle`: angle error of the applied force [rad, electrical]: each force is
      applied turned by this angle from where it is meant (a node force leaks onto the
      antinode).

    A loop with bandwidth 0 holds its effort at the initial steady-state value (open loop);
    not the rebalance loop in FTR mode (`FTR_LIMITS`).

    Each field must lie in its range (`LIMITS`), or is refused in one line: the set point
    `amplitude` > 0 (the loops divide by it); bandwidths ≥ 0 (a negative one is an unstable
    loop); the angle errors `excitation_phase` and `forcer_angle` within ±π/4 rad (real ones
    are milliradians; at π/4 the drive or the node force puts as much into the wrong
    quadrature as into the right one, and the steady drive grows as 1/cos γ_e: a larger
    value is degrees given as radians); `forcer_gain_mismatch` within ±0.5 and
    `forcer_gain` > −1, fractions, not percent (the forcers' common gain 1 + g_f must stay
    positive, g is a small difference of the two); `rebalance_limit` > 0; `k_e_nominal`
    in (0, 1] (as `Resonator.k_e`).
    """

    amplitude: jax.Array = eqx.field(converter=as_parameter, default=1.0)
    drive: str = eqx.field(static=True, default="force")
    excitation_phase: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    pll_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=2.0)
    agc_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=1.0)
    quadrature_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=2.0)
    ideal: bool = eqx.field(static=True, converter=_plain_bool, default=False)
    forcer_gain_mismatch: jax.Array | TemperatureLaw = eqx.field(
        converter=as_parameter, default=0.0
    )
    enabled: bool = eqx.field(static=True, converter=_plain_bool, default=True)
    mode: str = eqx.field(static=True, default="wa")
    rebalance_bandwidth: jax.Array = eqx.field(converter=as_parameter, default=2.0)
    rebalance_limit: jax.Array | None = eqx.field(
        converter=lambda x: None if x is None else as_parameter(x), default=None
    )
    forcer_gain: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    forcer_angle: jax.Array | TemperatureLaw = eqx.field(converter=as_parameter, default=0.0)
    k_e_nominal: float = eqx.field(static=True, default=K_E_NOMINAL, converter=_untraced_gain)

    @classmethod
    def free(cls, amplitude=1.0) -> Control:
        """No loops: no forces, no pump, reference at ω (free oscillation or decay from
        amplitude `amplitude`)."""
        return cls(amplitude=amplitude, enabled=False)

    def __check_init__(self):
        refuse_unconverted(self)
        for name in ("ideal", "enabled"):
            check_flag(f"Control.{name}", getattr(self, name))
        if not isinstance(self.drive, str) or self.drive not in DRIVES:
            raise ValueError(f"Control.drive must be one of {DRIVES}; got {_shown(self.drive)}")
        if not isinstance(self.mode, str) or self.mode not in MODES:
            raise ValueError(
                f"Control.mode must be one of {MODES} (whole-angle or force-to-rebalance); "
                f"got {_shown(self.mode)}"
            )
        k_e_problem = numeric_problem(self.k_e_nominal)
        if k_e_problem is None and np.shape(self.k_e_nominal) != ():
            k_e_problem = f"{type(self.k_e_nominal).__name__} of shape {np.shape(self.k_e_nominal)}"
        if k_e_problem is not None:
            raise TypeError(f"Control.k_e_nominal must be a single real number; got {k_e_problem}")
        if self.mode == "ftr" and not self.enabled:
            raise ValueError("Control.mode='ftr' needs the loops: a free resonator has none")
        check_limits("Control", self, LIMITS | FTR_LIMITS if self.mode == "ftr" else LIMITS)

    def forcer_matrix(self):
        """Forcer gain matrix diag(1 + g_f + g, 1 + g_f − g) applied to the electrode-frame
        force (g_f = `forcer_gain`, g = `forcer_gain_mismatch`)."""
        g, c = self.forcer_gain_mismatch, self.forcer_gain
        return jnp.stack([jnp.stack([1.0 + c + g, 0.0 * g]), jnp.stack([0.0 * g, 1.0 + c - g])])


def _shown(x) -> str:
    """`x` for a one-line error: its repr when short and not an array, else its type (and
    shape)."""
    if hasattr(x, "shape"):
        return f"{type(x).__name__} of shape {tuple(np.shape(x))}"
    text = repr(x)
    return text if len(text) <= 60 and "\n" not in text else type(x).__name__


class LoopOutputs(eqx.Module):
    omega_r: jax.Array
    """Reference (PLL) frequency [rad/s]."""
    force: jax.Array
    """AGC force amplitude F (force drive) [readout units · rad²/s²]."""
    pump: jax.Array
    """Parametric pump depth h (parametric drive) [-]."""
    quad_force: jax.Array
    """Quadrature force $f_{qc}$."""
    rebalance: jax.Array
    """Rebalance loop's node force $u$ (FTR; 0 in whole-angle mode) [readout units · rad²/s²]."""
    precession_force: jax.Array
    r"""Feed-forward node force of the commanded precession, $-2\omega_r\hat a\rho$."""


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


def rebalance_gains(control: Control, omega):
    r"""PI gains (kp, ki) of the rebalance loop: plant $\dot x = -u/(2\omega a_0)$."""
    return _gains(control.rebalance_bandwidth, -1.0 / (2.0 * omega * control.amplitude))


LOOP_STEPS = 3.0
"""The adaptive solver's longest step, in time constants of the fastest closed loop
(1/bandwidth): `max_step`."""


def max_step(control: Control, model: str = "averaged", temperatures_c=None):
    r"""The longest step [s] the adaptive solver may take with these loops: `LOOP_STEPS` /
    (the largest closed-loop bandwidth β, rad/s), ∞ with no loop integrated. A bandwidth
    that follows a temperature law counts at its largest over `temperatures_c` [°C] (the
    profile's; its reference temperature when not given).

    Why a bound: a closed loop's linearisation has its double pole at −β, and an explicit
    Runge–Kutta step is stable only for $h\beta$ ≲ 3.3 (Tsit5 and Dopri5 on the real axis).
    A run whose loops sit exactly at their equilibrium (a gyro with no defects, or defects of
    1e-7, at rest, noise off) gives the step-size controller nothing to measure, so its steps
    grow to minutes; its sensitivities, which the loops drive through the same unstable
    steps, came out wrong (`jax.grad` of the amplitude or the quadrature with the wrong sign
    and 10⁶ too large against central differences), and the run itself moved by the solver's
    tolerance. At $h\beta = 3$ every loop is stable on its step, and a run with defects,
    whose controller already holds its steps near that limit (1.3 s at β = 2 rad/s at rest),
    takes as many steps or fewer: `benchmarks/max_step.py` prints the steps and gradients
    with and without.

    ∞ for ideal averaged loops and a free resonator is safe because their θ, the state that
    only accumulates the turn, is solved less the turn the profile gives
    (`hrgjax.resonator.averaged.reference_angle`): a tolerance of rtol·|θ| after thousands
    of radians (≈ 1e-4 rad a step) had let the steps grow past the period π/(k_eΩ) of the
    anisotropy term ½Δ(1/τ)·sin2(θ − θ_τ) (3e-2 rad lost in an hour at 400 °/s). On the
    residual the steps follow the defect (32 501 for that hour, error 3e-10 rad) and a run
    with no defect still takes a handful (docs/simulate.md, "Turned angle";
    `benchmarks/turned_angle.py`). A cap at a fraction of π/(k_eΩ) would cost as many steps
    with a defect and as many again without one."""
    if not control.enabled or (control.ideal and model == "averaged"):
        return jnp.inf
    rates = [control.pll_bandwidth, control.agc_bandwidth, control.quadrature_bandwidth]
    if control.mode == "ftr":
        rates.append(control.rebalance_bandwidth)

    def largest(rate):  # a law: its largest over the temperatures (per gyro of a batch)
        if not isinstance(rate, TemperatureLaw):
            return rate
        if temperatures_c is None:
            return rate(rate.t_ref)
        return jnp.max(jax.vmap(rate)(jnp.ravel(jnp.asarray(temperatures_c))), axis=0)

    fastest = functools.reduce(jnp.maximum, [largest(r) for r in rates])  # (a batch: each)
    return jnp.where(fastest > 0, LOOP_STEPS / jnp.where(fastest > 0, fastest, 1.0), jnp.inf)


def angle_error(est, command):
    r"""Rebalance loop error $\hat\theta - \theta_{\rm cmd}$ [rad], wrapped to [−π/2, π/2)
    (θ and θ + π are the same standing wave)."""
    return wrap_half_pi(est.theta - command[0])


def loop_outputs(control: Control, omega, est, integrators, command=None) -> LoopOutputs:
    """Loop efforts from estimates and integrator states `(I_pll, I_agc, I_quad[, I_r])`;
    `command` = (commanded angle θ_cmd [rad], commanded precession ρ [rad/s], rebalance on 1 /
    off 0) (`None`: hold the start, no precession)."""
    (kp_p, _), (kp_a, _), (kp_q, _) = loop_gains(control, omega)
    i_pll, i_agc, i_quad = integrators[0], integrators[1], integrators[2]
    agc = kp_a * (control.amplitude - est.amplitude) + i_agc
    zero = jnp.zeros_like(agc)
    if not control.enabled:
        return LoopOutputs(omega_r=omega + zero, force=zero, pump=zero, quad_force=zero,
                           rebalance=zero, precession_force=zero)  # fmt: skip
    omega_r = omega + kp_p * est.phase + i_pll
    rho = zero if command is None else command[1]
    rebalance = zero
    if control.mode == "ftr":
        kp_r, _ = rebalance_gains(control, omega)
        x = zero if command is None else angle_error(est, command)
        rebalance = -kp_r * x + integrators[3]
        if control.rebalance_limit is not None:
            lim = control.rebalance_limit
            rebalance = jnp.clip(rebalance, -lim, lim)
        if command is not None:
            rebalance = command[2] * rebalance  # off (0) where the schedule runs whole-angle
    return LoopOutputs(
        omega_r=omega_r,
        force=agc if control.drive == "force" else zero,
        pump=agc if control.drive == "parametric" else zero,
        quad_force=-kp_q * est.quadrature + i_quad,
        rebalance=rebalance,
        precession_force=-2.0 * omega_r * est.amplitude * rho,
    )


def integrator_rates(control: Control, omega, est, command=None, integrators=None):
    """Time derivatives of the loop integrators (`command` as in
    [`loop_outputs`][hrgjax.resonator.control.loop_outputs]; `integrators`, the current
    values, for the rebalance loop's anti-windup when it has a force limit)."""
    (_, ki_p), (_, ki_a), (_, ki_q) = loop_gains(control, omega)
    if not control.enabled:
        return jnp.zeros(3) * est.phase
    rates = [
        ki_p * est.phase,
        ki_a * (control.amplitude - est.amplitude),
        ki_q * (-est.quadrature),
    ]
    if control.mode == "ftr":
        _, ki_r = rebalance_gains(control, omega)
        x = 0.0 * est.phase if command is None else angle_error(est, command)
        rate = -ki_r * x * (1.0 if command is None else command[2])  # held while off
        if control.rebalance_limit is not None and integrators is not None:
            kp_r, _ = rebalance_gains(control, omega)
            raw = -kp_r * x + integrators[3]  # stop winding up while saturated
            rate = jnp.where((jnp.abs(raw) > control.rebalance_limit) & (rate * raw > 0), 0.0, rate)
        rates.append(rate)
    return jnp.stack(rates)


def ftr_rate(control: Control, loops: LoopOutputs, est):
    r"""The FTR output: the rate read from the rebalance force,
    $\hat\Omega = -u/(2\omega_r\hat a\,k_{e,\rm nom})$ [rad/s] — the electronics divide by
    the frequency and amplitude they measure (ratiometric) and the nominal angular gain
    (`control.k_e_nominal`), so a perfect gyro whose k_e is the nominal one reads Ω exactly;
    k_e/k_e,nom, the forcers' gain, the readout errors and the drift at the held angle are
    what is left."""
    return -loops.rebalance / (2.0 * loops.omega_r * est.amplitude * control.k_e_nominal)


def drive_vectors(control: Control, loops: LoopOutputs, theta_est):
    r"""Electrode-frame force as $\mathbf f = \mathbf u\cos\psi_r + \mathbf v\sin\psi_r$.

    The AGC force lies along the estimated antinode; the quadrature force (in phase with
    the displacement) and the rebalance and precession forces (in phase with the velocity)
    along the estimated node; the forcer angle error turns them all, and the forcers' gains
    are applied last.
    """
    th = theta_est + control.forcer_angle
    c, s = jnp.cos(th), jnp.sin(th)  # e_a = (c, s), e_q = (−s, c)
    g = control.excitation_phase if control.drive == "force" else 0.0
    fs, fc, fq = -loops.force * jnp.sin(g), -loops.force * jnp.cos(g), loops.quad_force
    fn = loops.rebalance + loops.precession_force  # node, in phase with the velocity
    m = control.forcer_matrix()  # diagonal: applied elementwise (no 2 × 2 dot kernel)
    u = jnp.stack([m[0, 0] * (fs * c - fq * s), m[1, 1] * (fs * s + fq * c)])
    v = jnp.stack([m[0, 0] * (fc * c - fn * s), m[1, 1] * (fc * s + fn * c)])
    return u, v


def pump_phase(control: Control):
    """Pump phase γ with 2γ = π/2 + γ_e (optimal pumping at γ_e = 0)."""
    e = control.excitation_phase if control.drive == "parametric" else 0.0
    return 0.25 * jnp.pi + 0.5 * e


def steady_integrators(control: Control, res, a, theta, omega_in=0.0, on=1.0):
    """Integrator values at the loops' steady state (used as initial conditions).

    AGC: $F = 2\\omega a[1/\\tau + \\tfrac12\\Delta(1/\\tau)\\cos2(\\theta-\\theta_\\tau)]/\\cos\\gamma_e$
    or $h = 4[\\dots]/\\omega$; quadrature: $f_{qc} = -\\omega\\Delta\\omega\\,a\\sin2(\\theta-\\theta_\\omega)$;
    PLL: $\\omega_r = \\omega + \\tfrac12\\Delta\\omega\\cos2(\\theta-\\theta_\\omega) + 3\\chi a^2/8\\omega
    + [\\dots]\\tan\\gamma_e$ (the excitation phase error's pull, either drive); FTR (at the
    equivalent input rate `omega_in` [rad/s]):
    $u = 2\\omega a[-k_e\\Omega + \\tfrac12\\Delta(1/\\tau)\\sin2(\\theta-\\theta_\\tau)]$.
    """
    if not control.enabled:
        return jnp.zeros(3) * a
    loss = 1.0 / res.tau + 0.5 * res.delta_inv_tau * jnp.cos(2 * (theta - res.theta_tau))
    if control.drive == "force":
        i_agc = 2.0 * res.omega * a * loss / jnp.cos(control.excitation_phase)
    else:
        i_agc = 4.0 * loss / (res.omega * jnp.cos(control.excitation_phase))
    i_quad = -res.omega * res.delta_omega * a * jnp.sin(2 * (theta - res.theta_omega))
    i_pll = (
        0.5 * res.delta_omega * jnp.cos(2 * (theta - res.theta_omega))
        + 3 * res.chi * a**2 / (8 * res.omega)
        + loss * jnp.tan(control.excitation_phase)  # the drive's pull (PHYSICS.md §4.4)
    )
    integ = [i_pll, i_agc, i_quad]
    if control.mode == "ftr":
        drift = 0.5 * res.delta_inv_tau * jnp.sin(2 * (theta - res.theta_tau))
        integ.append(on * 2.0 * res.omega * a * (drift - res.k_e * omega_in))
    return jnp.stack(integ)
