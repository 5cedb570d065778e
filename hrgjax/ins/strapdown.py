r"""The strapdown φ-angle error model in NED (Titterton & Weston ch. 12; Groves ch. 14).

State (9): position error $\delta r = (\delta\varphi, \delta\lambda, \delta h)$ [rad, rad, m],
velocity error $\delta v^n$ [m/s] and the attitude error φ [rad] of the computed
body-to-NED matrix, $\hat C_b^n = (I - [\phi\times])C_b^n$. With gyro error $\delta\omega_{ib}^b$
and accelerometer error $\delta f^b$ (measured − true, body frame):

$$\begin{aligned}
\dot\phi &= -\omega_{in}^n\times\phi + \delta\omega_{in}^n - C_b^n\,\delta\omega_{ib}^b,\\
\delta\dot v^n &= f^n\times\phi + C_b^n\,\delta f^b - (2\omega_{ie}^n+\omega_{en}^n)\times\delta v^n
 - (2\delta\omega_{ie}^n+\delta\omega_{en}^n)\times v^n + \delta g^n,\\
\delta\dot r &= \delta\big(\dot\varphi, \dot\lambda, \dot h\big)(\varphi, h, v^n),
\end{aligned}$$

where every δ(·) of a navigation quantity (Earth and transport rate, gravity, position rate)
is its exact directional derivative, taken by `jax.jvp` of the same function the trajectory
uses — no hand-linearised term to get wrong. The augmented model (15 states) appends
constant gyro and accelerometer biases.

- [`error_rate`][hrgjax.ins.strapdown.error_rate] — the vector field at one trajectory point.
- [`error_matrices`][hrgjax.ins.strapdown.error_matrices] — F, and the gyro and accelerometer
  input matrices, along a trajectory.
- [`propagate`][hrgjax.ins.strapdown.propagate] — deterministic error histories driven by
  any gyro / accelerometer error time series (diffrax), e.g. hrgjax's simulated HRG output.
- [`discretise`][hrgjax.ins.strapdown.discretise], [`covariance`][hrgjax.ins.strapdown.covariance],
  [`monte_carlo`][hrgjax.ins.strapdown.monte_carlo] — exact (Van Loan) discretisation of the
  15-state model with white sensor noise; propagated covariance and vmapped Monte Carlo.

**Domain.** The model is the first-order expansion in the error state, so it holds while the
error state is small. Its horizontal position error, against two runs of the nonlinear
mechanisation (`benchmarks/ins_linear_domain.py`, docs/ins.md), is off by about half of
$a = \max_t\max(|\phi_N|, |\phi_E|, |\phi_D|, |\delta\varphi|)$ [rad] — ≈ 10 % at
$a$ = `MAX_ANGLE` = 0.2 rad, 25 % at 0.5 rad, 60 % at 1 rad (longitude does not enter the
dynamics: the model is exactly linear in δλ). An initial attitude error, or its σ, above
`MAX_ANGLE` is refused (the EKF's `MAX_ATTITUDE_SIGMA`); a result whose error state (or its
σ) grows past it — a gyro bias ε reaches it after ≈ 0.2/ε seconds — comes with a
`LinearisationWarning` naming when.
"""

from __future__ import annotations

import warnings

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import (
    ROUND_OFF,
    check_covariance,
    check_finite,
    check_finite_host,
    check_flag,
    check_key,
    finite_number,
    host_value,
    is_concrete,
    whole_number,
)
from .._compiled import Check, device, fused, program
from .._x64 import require_x64
from ..kalman import psd_factor, van_loan
from .constants import Earth
from .trajectory import Trajectory

STATES = ("dlat", "dlon", "dh", "dv_n", "dv_e", "dv_d", "phi_n", "phi_e", "phi_d")
"""Names of the 9 error states, in order."""
BIAS_STATES = ("bg_x", "bg_y", "bg_z", "ba_x", "ba_y", "ba_z")
"""The 6 bias states of the augmented model (body frame)."""
MAX_ANGLE = 0.2
"""The linear model's domain [rad] (module docstring): the largest initial attitude error or
attitude σ accepted (the EKF's `MAX_ATTITUDE_SIGMA`), and the size of the error state's
angles (|φ_N|, |φ_E|, |φ_D|, |δφ|, or their σ) past which a result warns; there the
horizontal position error is off by ≈ 10 % (docs/ins.md)."""


class LinearisationWarning(UserWarning):
    """A linear error-model result whose error state (or its σ) grew past `MAX_ANGLE`: from the
    time named on, its position error may be off by more than ≈ 10 % (docs/ins.md). Use the
    nonlinear mechanization ([`hrgjax.ins.mechanization`][hrgjax.ins.mechanization]) there,
    or silence it with `warnings.simplefilter("ignore", LinearisationWarning)` to study the
    linear model itself."""


_ANGLES = (6, 7, 8, 0)  # φ_N, φ_E, φ_D, δlat: the angles of the domain (module docstring)
_HOW = "align first, or use the nonlinear mechanization (hg.ins.mechanization); domain: docs/ins.md"


def _refuse_attitude(name: str, values, what: str):
    """Refuse concrete attitude errors (or σ) `values` (3,) [rad] above `MAX_ANGLE`, in one
    line naming the field `name` and `what` it is."""
    v = host_value(values)
    if v is not None and np.any(np.abs(v) > MAX_ANGLE):
        raise ValueError(
            f"{name} ({what}, N E D [rad]) must be within ±{MAX_ANGLE} rad on every axis, the "
            f"linear error model's domain (≈ 10 % position error there); got "
            f"{np.array2string(v, precision=4)}: {_HOW}"
        )


def _warn_domain(fn: str, angle, where, what: str = ""):
    """Warn (`LinearisationWarning`) if the concrete per-sample angle size `angle` (N,) [rad]
    passes `MAX_ANGLE`, naming the first sample by `where(k)`; a traced `angle` passes."""
    a = host_value(angle)
    if a is None or not np.any(a > MAX_ANGLE):
        return
    k = int(np.argmax(a > MAX_ANGLE))
    warnings.warn(
        f"{fn}: the error state's {what}angles (|φ_N|, |φ_E|, |φ_D|, |δlat|) pass the linear "
        f"model's {MAX_ANGLE}-rad domain at {where(k)} and reach {np.nanmax(a):.3g} rad: "
        "from there the position error may be off by more than ≈ 10 % (docs/ins.md); use "
        "the nonlinear mechanization (hg.ins.mechanization)",
        LinearisationWarning,
        stacklevel=3,
    )


def error_rate(earth: Earth, lat, h, v, c_bn, f_ned, dx, dgyro, daccel, altitude_aided=False):
    """Time derivative of the 9 error states `dx` at one trajectory point (module
    docstring), for body-frame gyro error `dgyro` [rad/s] and accelerometer error
    `daccel` [m/s²]. `altitude_aided=True` holds δh and δv_D at zero (perfect altitude
    aiding: the free vertical channel diverges with time constant √(R/2g) ≈ 570 s)."""
    dr, dv, phi = dx[0:3], dx[3:6], dx[6:9]
    tangent = (dr[0], dr[2], dv)

    def rates(lat, h, v):
        w_ie = earth.earth_rate(lat)
        w_en = earth.transport_rate(lat, h, v)
        return earth.position_rate(lat, h, v), w_ie + w_en, 2.0 * w_ie + w_en

    (_, w_in, w_cor), (d_pos, dw_in, dw_cor) = jax.jvp(rates, (lat, h, v), tangent)
    _, dg = jax.jvp(earth.gravity_ned, (lat, h), (dr[0], dr[2]))
    dphi = -jnp.cross(w_in, phi) + dw_in - c_bn @ dgyro
    ddv = jnp.cross(f_ned, phi) + c_bn @ daccel - jnp.cross(w_cor, dv) - jnp.cross(dw_cor, v) + dg
    if altitude_aided:
        d_pos, ddv = d_pos.at[2].set(0.0), ddv.at[2].set(0.0)
    return jnp.concatenate([d_pos, ddv, dphi])


@fused(static_argnums=(0, 1))
def error_matrices_at(earth, altitude_aided, lat, h, v, c_bn, f_ned):
    """(F (9, 9), G_gyro (9, 3), G_accel (9, 3)) of [`error_rate`][hrgjax.ins.strapdown.error_rate]
    on `earth` at one point: latitude `lat` [rad], height `h` [m], velocity `v` (3,) [m/s,
    NED], attitude `c_bn` (3, 3) and specific force `f_ned` (3,) [m/s²]
    ([`error_matrices`][hrgjax.ins.strapdown.error_matrices] along a trajectory)."""
    fn = lambda dx, dg, da: error_rate(earth, lat, h, v, c_bn, f_ned, dx, dg, da, altitude_aided)
    z9, z3 = jnp.zeros(9), jnp.zeros(3)
    return jax.jacfwd(fn, argnums=(0, 1, 2))(z9, z3, z3)


@fused(static_argnames="altitude_aided")
def error_matrices(traj: Trajectory, altitude_aided: bool = False):
    """(F (N, 9, 9), G_gyro (N, 9, 3), G_accel (N, 9, 3)) along `traj`: the error rate is
    `F dx + G_gyro dgyro + G_accel daccel`."""
    return jax.vmap(lambda *p: error_matrices_at(traj.earth, altitude_aided, *p))(
        traj.lat, traj.h, traj.v_ned, traj.c_bn, traj.f_ned
    )


@fused
def augmented(f, gg, ga):
    """The 15-state matrix with constant gyro and accelerometer biases appended."""
    top = jnp.concatenate([f, gg, ga], axis=-1)
    bottom = jnp.zeros(f.shape[:-2] + (6, 15))
    return jnp.concatenate([top, bottom], axis=-2)


def position_metres(traj: Trajectory, dx):
    """Position errors (north, east, down) [m] from error states `dx` (…, N, ≥3) on `traj`
    (N its samples; leading axes are runs, e.g. `monte_carlo`'s; a shape without them is
    refused in one line)."""
    n, shape = traj.t.shape[0], np.shape(dx)
    if len(shape) < 2 or shape[-2] != n or shape[-1] < 3:
        raise ValueError(f"dx must be (…, N, >=3) error states with N = {n}, one row per "
                         f"sample of traj (propagate's result); got {shape}")  # fmt: skip
    return _position_metres(traj, dx)


@fused
def _position_metres(traj: Trajectory, dx):
    """`position_metres` without its shape check (fused: one compiled program)."""
    r_m, r_n = traj.earth.radii(traj.lat)
    return jnp.stack(
        [
            dx[..., 0] * (r_m + traj.h),
            dx[..., 1] * (r_n + traj.h) * jnp.cos(traj.lat),
            -dx[..., 2],
        ],
        axis=-1,
    )


def _check_series(name, x, n):
    if x is None:
        return jnp.zeros((n, 3))
    x = check_finite(name, jnp.asarray(x, float))  # (a NaN there ran the solver out of steps)
    if x.shape == (3,):
        return jnp.broadcast_to(x, (n, 3))
    if x.shape != (n, 3):
        raise ValueError(
            f"{name} must have shape (3,) or ({n}, 3) (one row per trajectory "
            f"sample); got {x.shape}"
        )
    return x


def propagate(
    traj: Trajectory,
    dx0=None,
    gyro_error=None,
    accel_error=None,
    *,
    altitude_aided: bool = False,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int | None = None,
):
    """Error history along `traj` driven by body-frame sensor errors (module docstring),
    integrated by diffrax (Tsit5, adaptive; trajectory and errors linearly interpolated
    between samples, steps stopped at every sample).

    **Arguments:** `dx0` (9,) initial errors (default 0); `gyro_error` [rad/s] and
    `accel_error` [m/s²], each (3,) constant or (N, 3) sampled on `traj.t`;
    `altitude_aided` (see [`error_rate`][hrgjax.ins.strapdown.error_rate]).

    **Returns:** (N, 9) error states at `traj.t` (names in `STATES`; see
    [`position_metres`][hrgjax.ins.strapdown.position_metres]).

    **Raises:** `ValueError` for wrongly shaped inputs, or an initial attitude error
    `dx0[6:9]` above `MAX_ANGLE` on any axis; `RuntimeError` (from the solver) when it runs
    out of steps. **Warns** `LinearisationWarning` when the computed error state leaves the
    model's domain (module docstring), naming the time."""
    require_x64("ins.strapdown.propagate")
    altitude_aided = check_flag("altitude_aided", altitude_aided)
    for name, tol in (("rtol", rtol), ("atol", atol)):
        if finite_number(name, tol, "relative" if name == "rtol" else "state units") < 0:
            raise ValueError(f"{name} must be >= 0 (a solver tolerance); got {tol}")
    if max_steps is not None:
        max_steps = whole_number("max_steps", max_steps, "None or a whole number of steps >= 1")
        if max_steps < 1:
            raise ValueError(
                f"max_steps must be None or a whole number of steps >= 1; got {max_steps}"
            )
    n = traj.t.shape[0]
    dx0 = jnp.zeros(9) if dx0 is None else jnp.asarray(dx0, float)
    if dx0.shape != (9,):
        raise ValueError(f"dx0 must have shape (9,) (states {STATES}); got {dx0.shape}")
    dx0 = check_finite("dx0", dx0)
    v0 = host_value(dx0)  # (on the host: no device op, no compilation)
    if v0 is not None:
        _refuse_attitude("dx0[6:9]", v0[6:9], "the initial attitude error φ")
    eg = _check_series("gyro_error", gyro_error, n)
    ea = _check_series("accel_error", accel_error, n)
    tol = (device(rtol, float), device(atol, float))  # values: a new tolerance compiles nothing
    dx = _propagate(traj, dx0, eg, ea, altitude_aided, *tol, max_steps or 64 * n)[0]
    v, t = host_value(dx), host_value(traj.t)
    if v is not None and t is not None:
        angle = np.abs(v[:, _ANGLES]).max(axis=1)
        _warn_domain("ins.strapdown.propagate", angle, lambda k: f"t = {t[k] - t[0]:.6g} s")
    return dx


@program(check=Check("ins.strapdown.propagate", result_index=1))
def _propagate(traj, dx0, eg, ea, aided, rtol, atol, max_steps):
    ys = (traj.lat, traj.h, traj.v_ned, traj.c_bn, traj.f_ned, eg, ea)
    path = diffrax.LinearInterpolation(ts=traj.t, ys=ys)

    def field(t, dx, args):
        lat, h, v, c, f, g, a = path.evaluate(t)
        return error_rate(traj.earth, lat, h, v, c, f, dx, g, a, aided)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Tsit5(),
        t0=traj.t[0],
        t1=traj.t[-1],
        dt0=None,
        y0=dx0,
        saveat=diffrax.SaveAt(ts=traj.t),
        stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol, jump_ts=traj.t),
        max_steps=max_steps,
        throw=False,
    )
    return sol.ys, sol.result


class ImuErrors(eqx.Module):
    """Random IMU errors for covariance analysis and Monte Carlo (body frame, per axis).

    **Arguments:** `gyro_bias` [rad/s] and `accel_bias` [m/s²]: standard deviations of
    random constant biases; `arw` [rad/√s] and `vrw` [m/s/√s]: white-noise spectral
    densities (angle and velocity random walk). A concrete value outside `ImuModel`'s range
    (`hrgjax.plausible.RANGES["imu_gyro_bias"]`, …, bounds excluded) is refused, named with
    the datasheet units it may be in (`gyro_bias=1.0`: °/h typed as rad/s)."""

    gyro_bias: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)
    accel_bias: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)
    arw: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)
    vrw: jax.Array = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        for name in ("gyro_bias", "accel_bias", "arw", "vrw"):
            v = getattr(self, name)
            if is_concrete(v) and not (np.all(np.isfinite(v)) and np.all(np.asarray(v) >= 0)):
                raise ValueError(f"ImuErrors.{name} must be finite and >= 0 (a 1σ); got {v}")
            if np.ndim(v) > 1 or np.size(v) not in (1, 3):
                raise ValueError(
                    f"ImuErrors.{name} must be a scalar or 3 values; got shape {np.shape(v)}"
                )
            unit = plausible.RANGES[f"imu_{name}"][2]  # ImuModel's range (°/h, µg, °/√h hint)
            plausible.check(f"ImuErrors.{name} [{unit}]", v, f"imu_{name}")

    def bias_covariance(self):
        """6×6 covariance of the bias states."""
        v = jnp.concatenate(
            [jnp.broadcast_to(self.gyro_bias, (3,)), jnp.broadcast_to(self.accel_bias, (3,))]
        )
        return jnp.diag(v**2)


@fused(static_argnames="altitude_aided")
def discretise(traj: Trajectory, imu: ImuErrors, altitude_aided: bool = False):
    r"""Exact discretisation of the 15-state model between trajectory samples: for each step
    k → k+1, $\Phi_k = e^{F\,\Delta t}$ and $Q_{d,k}$ (Van Loan) with F at the step's midpoint
    (the mean of the two samples' matrices) and the white noise entering through the gyro and
    accelerometer input matrices. **Returns** `(Phi (N−1, 15, 15), Qd (N−1, 15, 15))`."""
    f, gg, ga = error_matrices(traj, altitude_aided)
    fa = augmented(f, gg, ga)
    fm = 0.5 * (fa[1:] + fa[:-1])
    g15 = lambda g: jnp.concatenate([g, jnp.zeros(g.shape[:-2] + (6, 3))], axis=-2)
    ggm, gam = g15(0.5 * (gg[1:] + gg[:-1])), g15(0.5 * (ga[1:] + ga[:-1]))
    arw = jnp.broadcast_to(imu.arw, (3,)) ** 2
    vrw = jnp.broadcast_to(imu.vrw, (3,)) ** 2
    q = jnp.einsum("nij,j,nkj->nik", ggm, arw, ggm) + jnp.einsum("nij,j,nkj->nik", gam, vrw, gam)
    dt = jnp.diff(traj.t)
    return jax.vmap(van_loan)(fm, q, dt)


def initial_covariance(imu: ImuErrors, p0_nav=None):
    """15×15 initial covariance: `p0_nav` (9×9, default 0) and the bias covariance.

    **Raises:** `ValueError` when `p0_nav`'s attitude σ (√ of its diagonal [6:9]) exceeds
    `MAX_ANGLE` on any axis (the linear model's domain, module docstring), or is not a
    finite symmetric positive semi-definite (9, 9) matrix."""
    if p0_nav is not None:
        p0_nav = jnp.asarray(p0_nav)
        if p0_nav.shape != (9, 9):
            raise ValueError(
                f"p0_nav must be a (9, 9) covariance (states {STATES}); got {p0_nav.shape}"
            )
        check_covariance("p0_nav", p0_nav, form="(9, 9)")
        _refuse_attitude_sigma("p0_nav", p0_nav)
    p = jnp.zeros((15, 15)).at[9:, 9:].set(imu.bias_covariance())
    return p if p0_nav is None else p.at[:9, :9].set(p0_nav)


def _refuse_attitude_sigma(name: str, p0):
    v = host_value(p0)
    if v is not None and v.ndim == 2 and v.shape[0] >= 9:
        sigma = np.sqrt(np.abs(np.diagonal(v)[6:9]))
        _refuse_attitude(f"√diag({name})[6:9]", sigma, "the initial attitude error's σ")


def _check_steps(phi, qd, p0):
    """`covariance` / `monte_carlo`'s model: `phi` and `qd` (N, n, n) alike and `p0` (n, n),
    or one line naming the argument; concrete values: `phi` finite, `qd` finite, symmetric and
    with variances >= 0 at each step (cheap: `_steps_ok`), `p0` symmetric positive
    semi-definite."""
    shape = np.shape(phi)
    if len(shape) != 3 or shape[1] != shape[2]:
        raise ValueError(f"phi must be (N, n, n), one transition per step (discretise's Phi); "
                         f"got shape {shape}")  # fmt: skip
    if np.shape(qd) != shape:
        raise ValueError(f"qd must be (N, n, n) = {shape} as phi (discretise's Qd); got shape "
                         f"{np.shape(qd)}")  # fmt: skip
    n = shape[1]
    if np.shape(p0) != (n, n):
        raise ValueError(f"p0 must be (n, n) = ({n}, {n}) (n = states of phi, e.g. "
                         f"initial_covariance's); got shape {np.shape(p0)}")  # fmt: skip
    form = f"(n, n) = ({n}, {n})"
    if not any(isinstance(x, jax.core.Tracer) for x in (phi, qd)):
        ok = np.asarray(_steps_ok(phi, qd))  # two bools back, not (N, n, n) arrays
        if not ok[0]:
            check_finite_host("phi", phi)
        if not ok[1]:  # the host check names the step and what is wrong with it
            check_covariance("qd", qd, form=form)
    check_covariance("p0", p0, form=form)


@fused
def _steps_ok(phi, qd):
    """`[phi finite, qd finite with variances >= 0 and symmetric]`: one device reduction
    over every step, O(N n²), a sufficient test (`_check_steps` asks the full host check of
    `check_covariance` only where it fails; a symmetric `qd` with a negative eigenvalue is
    not looked for: a Cholesky per step cost more than the propagation). Symmetry within
    `ROUND_OFF` of √(q_ii q_jj) (of 1 where a variance is 0), as `check_covariance` allows."""
    var = jnp.diagonal(qd, axis1=-2, axis2=-1)
    d = jnp.where(var > 0, jnp.sqrt(jnp.abs(var)), 1.0)
    tol = ROUND_OFF * d[..., :, None] * d[..., None, :]
    sym = jnp.all(jnp.abs(qd - jnp.swapaxes(qd, -1, -2)) <= tol)
    # the sums are finite when every entry is (an overflow only sends it to the host check)
    qd_ok = jnp.isfinite(jnp.sum(qd)) & jnp.all(var >= 0) & sym
    return jnp.stack([jnp.isfinite(jnp.sum(phi)), qd_ok])


def _angle_sigma(var):
    """Per-step size of the domain's angle σ from variances `var` (…, n)."""
    return jnp.sqrt(jnp.max(jnp.abs(var[..., jnp.array(_ANGLES)]), axis=-1))


def covariance(phi, qd, p0):
    """Propagated covariance $P_{k+1} = \\Phi_k P_k \\Phi_k^\\top + Q_{d,k}$; (N, 15, 15).

    **Raises** `ValueError` for an attitude σ in `p0` above `MAX_ANGLE`; **warns**
    `LinearisationWarning` when an angle σ of the error state grows past it (module
    docstring), naming the step (concrete inputs; under `jit` neither is checked); refuses
    shapes that do not fit, a concrete non-finite `phi`, `qd` or `p0` not PSD, in one line."""
    _check_steps(phi, qd, p0)
    _refuse_attitude_sigma("p0", p0)
    ps, angle = _covariance(phi, qd, p0)
    _warn_domain("ins.strapdown.covariance", angle, lambda k: f"step {k}", "σ of the ")
    return ps


@jax.jit
def _covariance(phi, qd, p0):
    def step(p, fq):
        f, q = fq
        p = f @ p @ f.T + q
        p = 0.5 * (p + p.T)
        return p, p

    _, ps = jax.lax.scan(step, p0, (phi, qd))
    ps = jnp.concatenate([p0[None], ps])
    big = p0.shape[-1] >= 9
    angle = _angle_sigma(jnp.diagonal(ps, axis1=-2, axis2=-1)) if big else jnp.zeros(0)
    return ps, angle


def monte_carlo(phi, qd, p0, key, n_runs: int, every: int = 1):
    r"""`n_runs` sample error histories of the discretised model, vmapped: $x_0 \sim N(0, P_0)$
    (biases drawn once per run), $x_{k+1} = \Phi_k x_k + L_k w_k$ with $L_kL_k^\top = Q_{d,k}$.
    `every`: keep every `every`-th state (it must divide the number of steps) to bound memory.

    **Returns:** (n_runs, N_steps/every + 1, 15).

    **Raises** `ValueError` for an attitude σ in `p0` above `MAX_ANGLE`; **warns**
    `LinearisationWarning` when the runs' RMS of an angle of the error state grows past it
    (module docstring), naming the step (concrete inputs; under `jit` neither is checked)."""
    require_x64("ins.strapdown.monte_carlo")
    check_key("monte_carlo: key", key)
    _check_steps(phi, qd, p0)
    n_runs = whole_number("n_runs", n_runs, "a whole number of runs >= 1")
    if n_runs < 1:
        raise ValueError(f"n_runs must be a whole number of runs >= 1; got {n_runs}")
    steps = np.shape(phi)[0]
    every = whole_number("every", every, f"a positive divisor of the {steps} steps")
    if every < 1 or steps % every:
        raise ValueError(f"every must be a positive divisor of the {steps} steps; got {every}")
    _refuse_attitude_sigma("p0", p0)
    xs, angle = _monte_carlo(phi, qd, p0, key, n_runs, every)
    _warn_domain("ins.strapdown.monte_carlo", angle, lambda k: f"step {k * every}", "RMS ")
    return xs


@eqx.filter_jit
def _monte_carlo(phi, qd, p0, key, n_runs, every):
    # every factor at once, in plain XLA operations (no LAPACK kernel on a batch, which can
    # wedge a small XLA:CPU pool: hrgjax/_threads.py)
    factors = jax.vmap(psd_factor)(jnp.concatenate([qd, p0[None]]))
    ls, l0 = factors[:-1], factors[-1]
    n = p0.shape[0]
    blocks = phi.shape[0] // every
    shape = lambda a: a.reshape((blocks, every) + a.shape[1:])

    def one(k):
        k0, kw = jax.random.split(k)
        x0 = l0 @ jax.random.normal(k0, (n,))
        w = jax.random.normal(kw, (phi.shape[0], n))

        def step(x, inp):
            f, lq, wk = inp
            return f @ x + lq @ wk, None

        def block(x, inp):
            x, _ = jax.lax.scan(step, x, inp)
            return x, x

        _, xs = jax.lax.scan(block, x0, (shape(phi), shape(ls), shape(w)))
        return jnp.concatenate([x0[None], xs])

    xs = jax.vmap(one)(jax.random.split(key, n_runs))
    angle = _angle_sigma(jnp.mean(xs**2, axis=0)) if n >= 9 else jnp.zeros(0)
    return xs, angle
