r"""The platform INS error model of seed 002, eqs. (1)–(6), with information faults.

One INS has 17 states (geographic trihedron ENH, equatorial trihedron ξ₃η₃ζ₃):

| # | state | meaning |
|---|---|---|
| 0–3 | δs_N, δV_N, α_x, Δa_y | north channel: displacement [m], velocity [m/s], vertical error [rad], "north" accelerometer error [rad = g-units] |
| 4–7 | δs_E, δV_E, α_y, Δa_x | east channel |
| 8–10 | δs_H, δV_H, Δa_z | vertical channel |
| 11–13 | δ_ξ, δ_ζ, δ_η | equatorial-trihedron errors [rad] |
| 14–16 | Δω_ξ, Δω_ζ, Δω_η | gyro drifts [rad/s] |

$$\begin{aligned}
\delta\dot V_N &= g\alpha_x + g\,u_{a,y}e_{a,y} + g\Delta a_y, &
\dot\alpha_x &= -\delta V_N/R + \dot\delta_\xi,\\
\delta\dot V_E &= -g\alpha_y + g\,u_{a,x}e_{a,x} + g\Delta a_x, &
\dot\alpha_y &= \delta V_E/R + \dot\delta_y,\quad \delta_y = -\delta_\zeta\sin\varphi + \delta_\eta\cos\varphi,\\
\delta\dot V_H &= g\Delta a_z + g\,u_{a,z}e_{a,z}, &
\dot\delta_\xi &= -u\,\delta_\zeta + \Delta\omega_\xi + u_\xi e_{\omega,\xi},\\
\dot\delta_\zeta &= u\,\delta_\xi + \Delta\omega_\zeta + u_\zeta e_{\omega,\zeta}, &
\dot\delta_\eta &= \Delta\omega_\eta + u_\eta e_{\omega,\eta},
\end{aligned}$$

$\delta\dot s = \delta V$ per channel, $\Delta\dot a = -\Delta a/\tau_a + g_a w$,
$\Delta\dot\omega = -\Delta\omega/\tau_r + g_r w$ (first-order Markov; here parameterised by
their stationary standard deviations σ, $g = \sigma\sqrt{2/\tau}$), u = Earth rate. Navigation
errors, eq. (6): latitude $\delta\varphi = -\alpha_x + \delta_\xi$, departure
$\delta w = \delta\lambda\cos\varphi = \alpha_y - \delta_y$, heading
$\alpha_z = \alpha_y\tan\varphi + \delta_\zeta/\cos\varphi$.

Notes on the seed's OCR: eq. (2)'s Markov line reads "Δα̇_x" and its force term "gΔα_z"
(both the east accelerometer error Δa_x), eq. (3) lacks the g of "gΔa_z", eq. (1) prints
"ΔV̈_N" for $\delta\dot V_N$, and eq. (6)'s heading ends in a stray "1/cos φ" — the
ζ-axis term $\delta_\zeta/\cos\varphi$ (the vertical component of the equatorial
trihedron's error, $\delta_\eta\sin\varphi + \delta_\zeta\cos\varphi = \delta_y\tan\varphi +
\delta_\zeta/\cos\varphi$, plus $\delta\lambda\sin\varphi$). A specific force beyond
gravity (the thesis's 3 g and 10 g manoeuvres) adds the cross-coupling $f\times p$ with
$p = (\alpha_x, \alpha_y, \alpha_z)$ about (E, N, H).

Faults ("information faults"): constant magnitudes e switched on at `t_fault` (u = 1 from
the first sample at or after it; the step that holds the onset takes u's mean over the step,
its share after `t_fault`, so the response is differentiable in `t_fault`). Stochastic
simulation is the exact discretisation of the linear SDE (Van Loan), driven by explicit PRNG
keys; `vmap` over keys for Monte Carlo.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import (
    check_finite,
    check_finite_host,
    check_number,
    check_positive,
    concrete_value,
    describe,
    finite_number,
    is_concrete,
    whole_number,
)
from .._compiled import device
from .._x64 import require_x64
from ..kalman import discretise_input, psd_factor, van_loan
from .constants import G0, OMEGA_IE, A

STATES = (
    "ds_n", "dv_n", "alpha_x", "da_y",
    "ds_e", "dv_e", "alpha_y", "da_x",
    "ds_h", "dv_h", "da_z",
    "d_xi", "d_zeta", "d_eta",
    "dw_xi", "dw_zeta", "dw_eta",
)  # fmt: skip
"""The 17 states of one INS, in order."""
FAULTS = ("accel_x", "accel_y", "accel_z", "gyro_xi", "gyro_zeta", "gyro_eta")
"""Sensors a fault can hit: accelerometers along E (x), N (y), H (z); gyros of ξ, ζ, η."""
NAV = ("dlat", "departure", "heading")
"""Navigation-parameter errors of eq. (6) [rad]."""

_I = {name: i for i, name in enumerate(STATES)}
_EARTH_FIELDS = {"g": "gravity_mps2", "radius": "earth_radius_m", "earth_rate": "earth_rate_radps"}


TAU_MIN = 60.0
"""The shortest correlation time `PlatformINS.tau_a`, `tau_r` [s] takes: a platform's
Markov drift varies over minutes to hours (the thesis's 3600 s); a τ of 1 s is one in hours
typed as seconds (`PlatformINS` also holds τ to `hrgjax.plausible.RANGES["duration_s"]`: a
τ in ms)."""


def _check_units(ins) -> None:
    """Refuse, in one line naming the field and its unit, a concrete `gyro_sigma` [rad/s]
    outside `ImuModel`'s `imu_gyro_bias_instability` range, an `accel_sigma` [g-units] outside
    `imu_accel_bias_instability` / g, a τ under `TAU_MIN` or beyond `duration_s` (traced
    values pass)."""
    plausible.check("PlatformINS.gyro_sigma [rad/s]", ins.gyro_sigma, "imu_gyro_bias_instability")
    high = plausible.RANGES["imu_accel_bias_instability"][1] / G0  # m/s² as g-units
    a = concrete_value(ins.accel_sigma)
    if a is not None and np.any(np.asarray(a) >= high):
        x = float(np.asarray(a, float)[np.asarray(a) >= high].flat[0])
        raise ValueError(f"PlatformINS.accel_sigma = {x:g} is outside the plausible range 0 … "
                         f"{high:.4g} g-units (a 1σ in g), its bounds excluded — µg → ×1e-6; "
                         "mg → ×1e-3 (hrgjax.plausible.relaxed(imu_accel_bias_instability=…) "
                         "widens it)")  # fmt: skip
    for name in ("tau_a", "tau_r"):
        plausible.check(f"PlatformINS.{name} [s]", getattr(ins, name), "duration_s")
        t = concrete_value(getattr(ins, name))
        if t is not None and np.any(np.asarray(t) < TAU_MIN):
            x = float(np.asarray(t, float)[np.asarray(t) < TAU_MIN].flat[0])
            raise ValueError(f"PlatformINS.{name} = {x:g} s is under the {TAU_MIN:g} s of a "
                             "platform's Markov drift (nominal 3600 s) — h → ×3600; min → ×60")  # fmt: skip


class PlatformINS(eqx.Module):
    """Parameters of one platform INS (module docstring). All SI; angles in rad.

    **Arguments:** `lat` [rad]; `tau_a`, `tau_r` [s]: correlation times of the accelerometer
    and gyro errors; `accel_sigma` [g-units, i.e. rad] and `gyro_sigma` [rad/s]: their
    stationary standard deviations (nominal 1e-7 as in the thesis); `specific_force`
    (3,) [m/s²]: specific force beyond gravity in (E, N, H) (0 for a stationary object);
    `g` [m/s²], `radius` [m], `earth_rate` [rad/s] (defaults: 9.80665, the WGS-84 semi-major
    axis, ω_ie; values, like the others: a sweep over them compiles once; each refused
    outside `hrgjax.plausible.RANGES`' `gravity_mps2`, `earth_radius_m`, `earth_rate_radps`).
    A concrete `gyro_sigma`, `accel_sigma`, `tau_a`, `tau_r` in another unit (°/h, µg, h) is
    refused (`_check_units`: `ImuModel`'s ranges, `TAU_MIN`)."""

    lat: jax.Array = eqx.field(converter=jnp.asarray, default=0.7853981633974483)
    tau_a: jax.Array = eqx.field(converter=jnp.asarray, default=3600.0)
    tau_r: jax.Array = eqx.field(converter=jnp.asarray, default=3600.0)
    accel_sigma: jax.Array = eqx.field(converter=jnp.asarray, default=1e-7)
    gyro_sigma: jax.Array = eqx.field(converter=jnp.asarray, default=1e-7)
    specific_force: jax.Array = eqx.field(converter=jnp.asarray, default=(0.0, 0.0, 0.0))
    g: jax.Array = eqx.field(converter=jnp.asarray, default=G0)
    radius: jax.Array = eqx.field(converter=jnp.asarray, default=A)
    earth_rate: jax.Array = eqx.field(converter=jnp.asarray, default=OMEGA_IE)

    def __check_init__(self):
        check_positive("PlatformINS.tau_a", self.tau_a, "s")
        check_positive("PlatformINS.tau_r", self.tau_r, "s")
        for name, quantity in _EARTH_FIELDS.items():
            check_finite(f"PlatformINS.{name}", getattr(self, name))
            plausible.check(f"PlatformINS.{name}", getattr(self, name), quantity)
        for name in ("accel_sigma", "gyro_sigma"):
            v = getattr(self, name)
            if is_concrete(v) and not (np.all(np.isfinite(v)) and np.all(np.asarray(v) >= 0)):
                raise ValueError(f"PlatformINS.{name} must be finite and >= 0; got {v}")
        _check_units(self)
        if is_concrete(self.lat) and not np.all(np.abs(np.asarray(self.lat)) < np.pi / 2):
            raise ValueError(f"PlatformINS.lat must be in (-π/2, π/2) rad; got {self.lat}")
        if is_concrete(self.specific_force) and np.shape(self.specific_force) != (3,):
            raise ValueError(
                f"PlatformINS.specific_force must have shape (3,) (E, N, H); got "
                f"{np.shape(self.specific_force)}"
            )

    def matrices(self):
        """`(F (17, 17), B (17, 6), G (17, 6))`: dynamics, fault input (per unit fault in
        `FAULTS` order) and unit white-noise input (accelerometers x, y, z; gyros ξ, ζ, η)."""
        i, g, r, u = _I, self.g, self.radius, self.earth_rate
        s, c = jnp.sin(self.lat), jnp.cos(self.lat)
        f = jnp.zeros((17, 17))
        b = jnp.zeros((17, 6))
        # equatorial trihedron rates as rows (state part, fault part)
        xi_dot = jnp.zeros(17).at[i["d_zeta"]].set(-u).at[i["dw_xi"]].set(1.0)
        zeta_dot = jnp.zeros(17).at[i["d_xi"]].set(u).at[i["dw_zeta"]].set(1.0)
        eta_dot = jnp.zeros(17).at[i["dw_eta"]].set(1.0)
        y_dot = -s * zeta_dot + c * eta_dot
        bx = jnp.zeros(6).at[3].set(1.0)
        bz = jnp.zeros(6).at[4].set(1.0)
        by = -s * bz + c * jnp.zeros(6).at[5].set(1.0)
        # heading error α_z = α_y tan φ + δ_ζ / cos φ as a row
        alpha_z = jnp.zeros(17).at[i["alpha_y"]].set(s / c).at[i["d_zeta"]].set(1.0 / c)
        fe, fn, fh = self.specific_force[0], self.specific_force[1], self.specific_force[2]
        # north channel
        f = f.at[i["ds_n"], i["dv_n"]].set(1.0)
        f = f.at[i["dv_n"], i["alpha_x"]].add(g + fh).at[i["dv_n"], i["da_y"]].set(g)
        f = f.at[i["dv_n"]].add(-fe * alpha_z)
        b = b.at[i["dv_n"], 1].set(g)
        f = f.at[i["alpha_x"]].set(xi_dot).at[i["alpha_x"], i["dv_n"]].add(-1.0 / r)
        b = b.at[i["alpha_x"]].set(bx)
        # east channel
        f = f.at[i["ds_e"], i["dv_e"]].set(1.0)
        f = f.at[i["dv_e"], i["alpha_y"]].add(-(g + fh)).at[i["dv_e"], i["da_x"]].set(g)
        f = f.at[i["dv_e"]].add(fn * alpha_z)
        b = b.at[i["dv_e"], 0].set(g)
        f = f.at[i["alpha_y"]].set(y_dot).at[i["alpha_y"], i["dv_e"]].add(1.0 / r)
        b = b.at[i["alpha_y"]].set(by)
        # vertical channel
        f = f.at[i["ds_h"], i["dv_h"]].set(1.0).at[i["dv_h"], i["da_z"]].set(g)
        f = f.at[i["dv_h"], i["alpha_y"]].add(fe).at[i["dv_h"], i["alpha_x"]].add(-fn)
        b = b.at[i["dv_h"], 2].set(g)
        # equatorial trihedron
        f = f.at[i["d_xi"]].set(xi_dot).at[i["d_zeta"]].set(zeta_dot).at[i["d_eta"]].set(eta_dot)
        b = b.at[i["d_xi"], 3].set(1.0).at[i["d_zeta"], 4].set(1.0).at[i["d_eta"], 5].set(1.0)
        # first-order Markov sensor errors
        noise = jnp.zeros((17, 6))
        for k, name in enumerate(("da_x", "da_y", "da_z")):
            f = f.at[i[name], i[name]].set(-1.0 / self.tau_a)
            noise = noise.at[i[name], k].set(self.accel_sigma * jnp.sqrt(2.0 / self.tau_a))
        for k, name in enumerate(("dw_xi", "dw_zeta", "dw_eta")):
            f = f.at[i[name], i[name]].set(-1.0 / self.tau_r)
            noise = noise.at[i[name], 3 + k].set(self.gyro_sigma * jnp.sqrt(2.0 / self.tau_r))
        return f, b, noise

    def navigation_errors(self, x):
        """Eq. (6): `(..., 3)` latitude error, departure δλ cos φ and heading error [rad]
        from states `x` (..., 17)."""
        if np.shape(x)[-1:] != (17,):
            raise ValueError(f"x must be (..., 17) platform states; got shape {np.shape(x)}")
        s, c = jnp.sin(self.lat), jnp.cos(self.lat)
        i = _I
        dy = -x[..., i["d_zeta"]] * s + x[..., i["d_eta"]] * c
        dlat = -x[..., i["alpha_x"]] + x[..., i["d_xi"]]
        dep = x[..., i["alpha_y"]] - dy
        head = x[..., i["alpha_y"]] * s / c + x[..., i["d_zeta"]] / c
        return jnp.stack([dlat, dep, head], axis=-1)

    def stationary_covariance(self):
        """17×17 covariance with the Markov sensor errors at their stationary variance and
        every navigation error zero (the state just after alignment)."""
        d = jnp.zeros(17)
        for name in ("da_x", "da_y", "da_z"):
            d = d.at[_I[name]].set(self.accel_sigma**2)
        for name in ("dw_xi", "dw_zeta", "dw_eta"):
            d = d.at[_I[name]].set(self.gyro_sigma**2)
        return jnp.diag(d)

    def discretise(self, dt):
        r"""Exact discretisation over `dt`: `(Phi, Gamma, Qd)` — transition, zero-order-hold
        fault input and process-noise covariance."""
        f, b, noise = self.matrices()
        phi, qd = van_loan(f, noise @ noise.T, dt)
        _, gam = discretise_input(f, b, dt)
        return phi, gam, qd


def _floats(x) -> jax.Array:
    """`x` as a float64 array, not weakly typed (a traced one cast in its trace)."""
    return device(x, float)


class Fault(eqx.Module):
    """An information fault: magnitudes `e` (6,) in `FAULTS` order (accelerometers in
    g-units, gyros in rad/s) switched on at `t_fault` [s]."""

    # float64, strongly typed, whatever the input: `t_fault=200` (an int leaf) compiled
    # `simulate` again beside `t_fault=200.0` (a program is kept by its leaves' dtypes)
    e: jax.Array = eqx.field(converter=_floats, default=(0.0,) * 6)
    t_fault: jax.Array = eqx.field(converter=_floats, default=jnp.inf)

    @classmethod
    def on(cls, sensor: str, size: float, t_fault: float) -> Fault:
        """A single fault of `size` in `sensor` (one of `FAULTS`) from `t_fault`."""
        if sensor not in FAULTS:
            raise ValueError(f"unknown sensor {sensor!r}; choose from {FAULTS}")
        check_number("size", size, "g or rad/s")
        v = concrete_value(size)  # a traced size (vmap, grad, jit) passes: it has no value
        if v is not None and not np.isfinite(v):
            raise ValueError(f"size must be finite [g or rad/s]; got {float(v)}")
        try:
            check_number("t_fault", t_fault, "s")
        except (TypeError, ValueError):
            raise ValueError(
                f"t_fault must be a time [s] (inf: never); got {describe(t_fault)}"
            ) from None
        v = concrete_value(t_fault)
        if v is not None and np.isnan(v):
            raise ValueError(f"t_fault must be a time [s] (inf: never); got {float(v)}")
        return cls(jnp.zeros(6).at[FAULTS.index(sensor)].set(size), t_fault)


def simulate(
    ins: PlatformINS,
    *,
    dt: float,
    n_steps: int,
    key: jax.Array | None,
    fault: Fault | None = None,
    x0=None,
):
    """Simulate one platform INS (module docstring).

    **Arguments:** `dt` [s], `n_steps`; `key`: PRNG key for the sensor noise (`None`: the
    noise-free response); `fault`; `x0` (17,) initial state (default: Markov sensor errors
    drawn from their stationary law when `key` is given, else 0).

    **Returns:** `(t (n+1,), x (n+1, 17), nav (n+1, 3))`."""
    require_x64("ins.platform.simulate")
    if not (finite_number("dt", dt, "s") > 0):
        raise ValueError(f"dt must be > 0 s; got {dt}")
    if whole_number("n_steps", n_steps, "a whole number of steps >= 1") < 1:
        raise ValueError(f"n_steps must be >= 1; got {n_steps}")
    if x0 is not None:
        if np.shape(x0) != (17,):
            raise ValueError(f"x0 must be (17,) platform states; got shape {np.shape(x0)}")
        check_finite_host("x0", x0)
    fault = Fault() if fault is None else fault
    return _simulate(ins, jnp.asarray(float(dt)), int(n_steps), key, fault, x0)


@eqx.filter_jit
def _simulate(ins, dt, n_steps, key, fault, x0):
    phi, gam, qd = ins.discretise(dt)
    t = jnp.arange(n_steps + 1, dtype=dt.dtype) * dt
    if key is None:
        x0 = jnp.zeros(17) if x0 is None else jnp.asarray(x0)
        w = jnp.zeros((n_steps, 17))
        lq = jnp.zeros((17, 17))
    else:
        k0, kw = jax.random.split(key)
        if x0 is None:
            x0 = psd_factor(ins.stationary_covariance()) @ jax.random.normal(k0, (17,))
        w = jax.random.normal(kw, (n_steps, 17))
        lq = psd_factor(qd)
    # the share of each step after the onset: 0 before it, 1 from the first sample at or after
    # it, the fraction in between within the step that holds it (the step's mean of u); so a
    # state moves smoothly with `t_fault` and ∂/∂t_fault is the onset's sensitivity (a 0/1
    # switch read 0 for every t_fault)
    on = jnp.clip((t[1:] - fault.t_fault) / dt, 0.0, 1.0)

    def step(x, inp):
        wk, uk = inp
        x = phi @ x + gam @ (fault.e * uk) + lq @ wk
        return x, x

    _, xs = jax.lax.scan(step, x0, (w, on))
    xs = jnp.concatenate([x0[None], xs])
    return t, xs, ins.navigation_errors(xs)
