r"""`PhysicalCompensator`: the grey box — resonator temperature laws fitted through the simulator.

The model gyro is the averaged simulator with the loops closed ideally (amplitude held,
quadrature nulled; PHYSICS.md §10) and these laws, ΔT = T − 20 °C:

| parameter | law | fitted |
|---|---|---|
| angular gain | $k_e(T) = k_{e0}(1 + \kappa\,\Delta T)$ | $k_{e0}$, κ [1/°C] |
| rate bias | $b_0 + b_1\Delta T + b_2\Delta T^2$ | [rad/s], [rad/s/°C], [rad/s/°C²] |
| damping anisotropy | $\Delta(1/\tau)(T) = d_0\,e^{\lambda\Delta T}$ | $d_0$ [1/s], λ [1/°C] |
| damping axis | $\theta_\tau(T) = \theta_{\tau0} + \theta_{\tau1}\Delta T$ | [rad], [rad/°C] (electrical) |
| readout gain mismatch | $g(T) = g_0 + g_1\Delta T$ | [–], [1/°C] |
| readout cross-talk | $c$ | [–] |

`fit` simulates every calibration run (same times, rates, temperatures, measured initial
angle) and reduces the simulated wave angle with the same window slopes as the measured one;
Levenberg–Marquardt (`optimistix`) minimises the weighted rate residuals. Weights are the
residual scatter of each kind of window (static, moving), re-estimated after a first pass;
the parameter covariance is the Gauss–Newton $(J^\top W J)^{-1}$ scaled by the reduced χ².

The compensator's D and SF follow from the fitted gyro itself: the readout map
$\theta\mapsto\hat\theta$ is inverted at the measured angle, the rest-state pattern rate comes
from the averaged vector field, and $\mathrm{SF} = (d\hat\theta/d\theta)\,k_e(T)/k_{e,\rm nom}$.
It also knows $\partial\hat\theta/\partial T$, the apparent rate a changing readout mismatch
gives while the temperature changes, which the empirical compensators cannot learn from bench
data taken at constant temperatures.
"""

from __future__ import annotations

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._compiled import Check, device, first_failure, program
from .._least_squares import least_squares
from .._x64 import require_x64
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..resonator.averaged import averaged_vector_field, measured_estimates
from ..resonator.control import Control
from ..resonator.params import Resonator, TemperatureLaw
from ..resonator.readout import Readout
from ..simulate import simulate
from ..units import DEG, DEG_PER_H, T_REF_C
from ._compensator import AbstractCompensator, split_targets
from ._physical_start import initial_values
from .reduce import K_E_NOMINAL, _window_stats, reduce, window_slopes

PARAMETERS = (
    ("k_e0", "", 1e-4),
    ("k_e_tc", "1/°C", 1e-6),
    ("bias0", "rad/s", 0.01 * DEG_PER_H),
    ("bias1", "rad/s/°C", 1e-4 * DEG_PER_H),
    ("bias2", "rad/s/°C²", 1e-6 * DEG_PER_H),
    ("delta_inv_tau0", "1/s", 0.01 * DEG_PER_H),
    ("delta_inv_tau_lam", "1/°C", 1e-3),
    ("theta_tau0", "rad", 1e-2),
    ("theta_tau1", "rad/°C", 1e-4),
    ("gain_mismatch0", "", 1e-5),
    ("gain_mismatch1", "1/°C", 1e-7),
    ("cross_talk", "", 1e-5),
)
"""Fitted parameters: (name, unit, typical uncertainty used to scale the LM problem)."""
NAMES = tuple(p[0] for p in PARAMETERS)
_SCALE = np.array([p[2] for p in PARAMETERS])


MODEL_OMEGA = 2 * math.pi * 5000.0
"""Mean natural angular frequency of the model gyro [rad/s] (not fitted: with ideal loops the
averaged pattern rate does not depend on it)."""
MODEL_TAU = 640.0
"""Mean decay time of the model gyro [s] (not fitted: the ideal amplitude loop holds the
amplitude whatever τ is; the damping *anisotropy* Δ(1/τ) is fitted)."""


def model_gyro(values, omega: float = MODEL_OMEGA, tau: float = MODEL_TAU) -> Gyro:
    """The ideal-loop model gyro of the parameter vector `values` (order of `PARAMETERS`),
    with mean frequency `omega` [rad/s] and decay time `tau` [s]."""
    v = {name: values[i] for i, name in enumerate(NAMES)}
    law = lambda p0, p1=0.0, p2=0.0, lam=0.0: TemperatureLaw(p0, p1, p2, lam, T_REF_C)
    res = Resonator(
        omega=omega,
        tau=tau,
        k_e=law(v["k_e0"], v["k_e0"] * v["k_e_tc"]),
        delta_inv_tau=law(v["delta_inv_tau0"], lam=v["delta_inv_tau_lam"]),
        theta_tau=law(v["theta_tau0"], v["theta_tau1"]),
    )
    readout = Readout(
        gain_mismatch=law(v["gain_mismatch0"], v["gain_mismatch1"]), cross_talk=v["cross_talk"]
    )
    return Gyro(
        resonator=res,
        control=Control(ideal=True),
        readout=readout,
        rate_bias=law(v["bias0"], v["bias1"], v["bias2"]),
    )


def _readout_angle(gyro_t: Gyro, theta):
    a0 = gyro_t.control.amplitude
    return measured_estimates(gyro_t, a0, 0.0 * a0, theta, 0.0 * a0).theta


def true_angle(gyro_t: Gyro, theta_meas, iterations: int = 4):
    """Invert the readout map at one temperature: θ with θ̂(θ) = `theta_meas` [rad]."""
    theta = theta_meas
    for _ in range(iterations):
        theta = theta - (_readout_angle(gyro_t, theta) - theta_meas)
    return theta


class PhysicalCompensator(AbstractCompensator):
    """Grey-box compensator (module docstring).

    **Arguments:**

    - `k_e`: nominal angular gain of the data reduction.
    - `values`: fitted parameters in the order of
      [`PARAMETERS`][hrgjax.calibration.physical.PARAMETERS] (SI); `None` before `fit`.
    - `covariance`: their covariance; `stats`: fit statistics as pairs (see `fit_stats`).
    - `window_s`: rotation-run window [s]; `max_steps`: LM step limit.
    """

    k_e: float = eqx.field(static=True, default=K_E_NOMINAL)
    window_s: float = eqx.field(static=True, default=10.0)
    max_steps: int = eqx.field(static=True, default=64)
    values: jax.Array | None = None
    covariance: jax.Array | None = None
    stats: tuple = eqx.field(static=True, default=())

    @property
    def fit_stats(self) -> dict:
        """χ²/dof, residual RMS of static and moving windows [°/h], LM steps, window count."""
        return dict(self.stats)

    @property
    def name(self) -> str:
        """Short label used in tables."""
        return "physical"

    def gyro(self) -> Gyro:
        """The fitted model gyro (ideal loops, fitted laws)."""
        if self.values is None:
            raise ValueError("this PhysicalCompensator is not fitted; use comp = comp.fit(data)")
        return model_gyro(self.values)

    def parameters(self) -> dict[str, tuple[float, float]]:
        """{name: (value, standard error)} in SI units."""
        err = np.sqrt(np.diag(np.asarray(self.covariance)))
        return {
            n: (float(v), float(e))
            for n, v, e in zip(NAMES, np.asarray(self.values), err, strict=True)
        }

    def _derivatives(self, theta_meas, temperature_c):
        g = self.gyro().at(temperature_c)
        theta = true_angle(g, theta_meas)
        slope = jax.jvp(lambda th: _readout_angle(g, th), (theta,), (jnp.ones_like(theta),))[1]
        rest = Profile.static(1.0, temperature_c)
        theta_dot = averaged_vector_field(0.0, theta[None], (g, rest))[0]
        return slope, theta_dot, g.resonator.k_e

    def readout_temperature_sensitivity(self, theta, temperature_c):
        gyro = self.gyro()
        true = true_angle(gyro.at(temperature_c), theta)
        meas = lambda temp: _readout_angle(gyro.at(temp), true)
        return jax.jvp(meas, (temperature_c,), (jnp.ones_like(temperature_c),))[1]

    def drift(self, theta, temperature_c):
        slope, theta_dot, _ = self._derivatives(theta, temperature_c)
        return -slope * theta_dot / self.k_e

    def scale_factor(self, theta, temperature_c):
        slope, _, k_e = self._derivatives(theta, temperature_c)
        return slope * k_e / self.k_e

    def equations(self) -> str:
        """The fitted laws with 1σ uncertainties, as text."""
        p = self.parameters()
        f = lambda n, s=1.0, fmt=".4g": f"{p[n][0] * s:{fmt}} ± {p[n][1] * s:.2g}"
        lines = [
            f"k_e(T)      = {f('k_e0', 1, '.6f')} · (1 + ({f('k_e_tc', 1e6)}) ppm/°C · ΔT)",
            f"bias(T)     = {f('bias0', 1 / DEG_PER_H)} + ({f('bias1', 1 / DEG_PER_H)}) ΔT"
            f" + ({f('bias2', 1 / DEG_PER_H)}) ΔT²   [°/h]",
            f"Δ(1/τ)(T)   = {f('delta_inv_tau0')} 1/s · exp(({f('delta_inv_tau_lam')}) ΔT)",
            f"θ_τ(T)      = {f('theta_tau0', 1 / DEG)}° + ({f('theta_tau1', 1 / DEG)})°/°C · ΔT",
            f"g(T)        = {f('gain_mismatch0', 100)} % + ({f('gain_mismatch1', 100)}) %/°C · ΔT",
            f"cross-talk  = {f('cross_talk', 100)} %",
        ]
        return "\n".join(lines)

    def fit(self, data: MeasuredData, initial=None) -> PhysicalCompensator:
        """Fit the laws to bench data by Levenberg–Marquardt through the averaged simulator.

        **Arguments:**

        - `data`: [`hrgjax.MeasuredData`][] with static and rotation runs (the raw samples
          are needed: the simulator reproduces each run).
        - `initial`: optional starting values (order of `PARAMETERS`); by default they come
          from harmonic fits of the reduced drift and scale factor at each temperature.

        **Returns:** a new fitted `PhysicalCompensator` (values, covariance, stats).

        **Raises:** `RuntimeError` without float64; `ValueError` without static or rotation
        runs.
        """
        require_x64("PhysicalCompensator.fit")
        if not isinstance(data, MeasuredData):
            raise TypeError("PhysicalCompensator.fit needs MeasuredData (the raw samples)")
        windows = reduce(data, self.k_e, window_s=self.window_s)
        split_targets(windows)
        groups = _groups(data, self.window_s, self.k_e)
        x0 = np.asarray(initial if initial is not None else initial_values(windows, self.k_e))
        values, steps, res, sigma, jac = _fit(groups, device(x0), self.k_e, self.max_steps)
        values, steps, jac = np.asarray(values), int(steps), np.asarray(jac) * _SCALE
        res = {k: np.asarray(v) for k, v in res.items()}
        sigma = {k: float(v) for k, v in sigma.items()}
        r = np.concatenate([res[k] / sigma[k] for k in (True, False)])
        dof = max(r.size - len(NAMES), 1)
        chi2 = float(r @ r) / dof
        cov = np.linalg.inv(jac.T @ jac) * chi2 * np.outer(_SCALE, _SCALE)
        stats = {
            "chi2_per_dof": chi2,
            "static_rms_dph": sigma[True] / DEG * 3600,
            "moving_rms_dph": sigma[False] / DEG * 3600,
            "lm_steps": int(steps),
            "n_windows": int(r.size),
        }
        return PhysicalCompensator(
            k_e=self.k_e,
            window_s=self.window_s,
            max_steps=self.max_steps,
            values=device(values),
            covariance=device(cov),
            stats=tuple(stats.items()),
        )


class _Group(eqx.Module):
    """Runs of one length, stacked for one vmap of the simulator. Static runs are reduced as
    one window, moving runs as `n_windows` windows."""

    t: jax.Array  # (R, N)
    theta0: jax.Array  # (R,) measured initial angle [rad]
    knots: jax.Array  # (K,) sample indices of the profile knots
    rate: jax.Array  # (R, K) [rad/s]
    temperature: jax.Array  # (R, K) [°C]
    accel: jax.Array  # (R, K, 3) [g]
    measured_static: jax.Array  # (Rs, 1) window rates [rad/s]
    measured_moving: jax.Array  # (Rm, W)
    static_idx: tuple = eqx.field(static=True)
    moving_idx: tuple = eqx.field(static=True)
    n_windows: int = eqx.field(static=True)


def _groups(data: MeasuredData, window_s: float, k_e: float) -> list[_Group]:
    out = []
    for stack in data.stacked():
        length = stack.n_samples
        if length < 4:
            raise ValueError(
                f"run {int(stack.run[0])} has {length} samples; reduction needs at least 4 "
                "per window"
            )
        # one layout per stack (its runs share length and interval), as `_window_layout`
        n_win, n = 1, length
        if not stack.static.all():
            n = max(int(round(window_s / stack.dt)), 4)
            n_win = length // n
            if n_win == 0:
                n_win, n = 1, length
        knots = np.unique(np.concatenate([np.arange(0, length, n), [length - 1]]))
        t, th = stack.t, stack.wave_angle
        s_idx = tuple(np.flatnonzero(stack.static).tolist())
        m_idx = tuple(np.flatnonzero(~stack.static).tolist())
        out.append(
            _Group(
                t=device(t),
                theta0=device(th[:, 0]),
                knots=device(knots),
                rate=device(stack.rate[:, knots]),
                temperature=device(stack.temperature[:, knots]),
                accel=device(stack.accel[:, knots]),
                measured_static=device(-_slopes(t, th, s_idx, 1, length) / k_e),
                measured_moving=device(-_slopes(t, th, m_idx, n_win, n_win * n) / k_e),
                static_idx=s_idx,
                moving_idx=m_idx,
                n_windows=n_win,
            )
        )
    return out


def _slopes(t, theta, idx, windows, samples):
    """Window slopes of the runs `idx` (NumPy; the same formula as `window_slopes`)."""
    if not idx:
        return np.zeros((0, windows))
    return np.stack(
        [_window_stats(np, t[i, :samples], theta[i, :samples], windows, 0)[0] for i in idx]
    )


def _simulated_rates(group: _Group, values, k_e: float):
    """Simulated window rates (static (Rs, 1), moving (Rm, W)) [rad/s] of one group."""
    gyro = model_gyro(values)

    def one(t, theta0, rate, temp, acc):
        theta_start = true_angle(gyro.at(temp[0]), theta0)
        prof = Profile(
            t=t[group.knots], rate=rate, temperature=temp, accel=acc, wave_angle0=theta_start
        )
        rec = simulate(gyro, prof, ts=t, adjoint=diffrax.ForwardMode(), rtol=1e-9, atol=1e-12)
        return rec.wave_angle

    theta = jax.vmap(one)(group.t, group.theta0, group.rate, group.temperature, group.accel)
    n = group.t.shape[1]
    m = (n // group.n_windows) * group.n_windows
    s_idx, m_idx = np.asarray(group.static_idx, int), np.asarray(group.moving_idx, int)
    static = jax.vmap(lambda t, th: window_slopes(t, th, 1)[0])(group.t[s_idx], theta[s_idx])
    moving = jax.vmap(lambda t, th: window_slopes(t[:m], th[:m], group.n_windows)[0])(
        group.t[m_idx], theta[m_idx]
    )
    return -static / k_e, -moving / k_e


def _residuals(groups, values, k_e):
    """{True: static residuals, False: moving residuals} [rad/s], measured − simulated."""
    sims = [_simulated_rates(g, values, k_e) for g in groups]
    return {
        True: jnp.concatenate(
            [(g.measured_static - s[0]).ravel() for g, s in zip(groups, sims, strict=True)]
        ),
        False: jnp.concatenate(
            [(g.measured_moving - s[1]).ravel() for g, s in zip(groups, sims, strict=True)]
        ),
    }


def _weighted_residual(x, args):
    groups, x0, sigma, k_e = args
    res = _residuals(groups, x0 + x * _SCALE, k_e)
    return jnp.concatenate([res[True] / sigma[True], res[False] / sigma[False]])


@program(check=Check("PhysicalCompensator.fit (residuals and Jacobian)"))
def _residuals_jacobian(groups, values, k_e):
    """Residuals {True: static, False: moving} [rad/s] at `values` and their Jacobians with
    respect to the scaled parameters x (values + x·scale). One program serves the start
    (weights) and the end (covariance) of the fit."""
    fn = lambda x: _residuals(groups, values + x * _SCALE, k_e)
    return fn(jnp.zeros(len(NAMES))), jax.jacfwd(fn)(jnp.zeros(len(NAMES)))


def _fit(groups, x0, k_e, max_steps):
    """Weights, Levenberg–Marquardt (one compiled step at a time, with a progress bar),
    final residuals and Jacobian.

    Weights: the residual scatter of each kind of window (static, moving) at the starting
    values (robust: median absolute deviation; the harmonic start is close), re-estimated
    after the fit for the covariance."""
    r0, _ = _residuals_jacobian(groups, x0, k_e)
    sigma0 = {}
    for kind, r in r0.items():
        r = np.asarray(r)
        sigma0[kind] = device(1.4826 * np.median(np.abs(r - np.median(r))))
    # The problem is scaled so that one unit of x is about one standard error: stopping at
    # 1e-4 of that is far below anything the data can tell.
    x, steps, result = least_squares(
        _weighted_residual,
        optx.LevenbergMarquardt(rtol=1e-4, atol=1e-4),
        device(np.zeros(len(NAMES))),
        (groups, x0, sigma0, k_e),
        max_steps=max_steps,
        desc="physical fit (Levenberg–Marquardt)",
        f_struct=jax.ShapeDtypeStruct((sum(r.size for r in r0.values()),), r0[True].dtype),
    )
    message = first_failure(result, optx.RESULTS)
    if message is not None:
        raise RuntimeError(f"PhysicalCompensator.fit: Levenberg–Marquardt failed: {message}")
    # Host arithmetic between the compiled programs (eager jnp would compile each operation).
    values = np.asarray(x0) + np.asarray(x) * _SCALE
    r1, jac1 = _residuals_jacobian(groups, device(values), k_e)
    r1 = {k: np.asarray(r) for k, r in r1.items()}
    sigma1 = {k: np.sqrt(np.mean(r**2)) for k, r in r1.items()}
    jac = np.concatenate(
        [np.asarray(jac1[True]) / sigma1[True], np.asarray(jac1[False]) / sigma1[False]]
    )
    return values, steps, r1, sigma1, jac / np.asarray(_SCALE)[None, :]
