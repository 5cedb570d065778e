r"""Nonlinear strapdown mechanization in NED on WGS-84: attitude, velocity and position from
IMU increments, with two-sample coning and sculling corrections (Savage, *Strapdown
Analytics*, ch. 7; Groves ch. 5.4).

The IMU gives, for each interval $[t_{k-1}, t_k]$ of length Δt, the gyro and accelerometer
**increments** $\Delta\theta_k = \int\omega_{ib}^b\,dt$ [rad] and $\Delta v_k = \int f^b\,dt$
[m/s] (each integrand in the body frame of its instant). One step from state k−1:

1. The navigation-frame terms at the interval's midpoint, extrapolated from the two previous
   states ($x_m = \tfrac32x_{k-1} - \tfrac12x_{k-2}$ for latitude, height and velocity):
   $\zeta = (\omega_{ie}^n + \omega_{en}^n)\,\Delta t$ and
   $a_m = g^n - (2\omega_{ie}^n + \omega_{en}^n)\times v^n$.
2. Coning and sculling with the previous interval's increments:
   $\phi = \Delta\theta_k + \tfrac1{12}\Delta\theta_{k-1}\times\Delta\theta_k$,
   $\Delta v_{sf}^b = \Delta v_k + \tfrac12\Delta\theta_k\times\Delta v_k
   + \tfrac1{12}(\Delta\theta_{k-1}\times\Delta v_k + \Delta v_{k-1}\times\Delta\theta_k)$.
3. Velocity: $v_k = v_{k-1} + (I - \tfrac12[\zeta\times])\,C_{b,k-1}^n\Delta v_{sf}^b
   + a_m\Delta t$.
4. Position (height, then latitude, then longitude) by the trapezoid of the two velocities
   with the radii of curvature at the interval's midpoint.
5. Attitude: $C_{b,k}^n = e^{-[\zeta\times]}\,C_{b,k-1}^n\,e^{[\phi\times]}$, as unit
   quaternions (scalar first, body to NED).

Every step is explicit and exactly invertible:
[`increments_from_states`][hrgjax.ins.mechanization.increments_from_states] solves it for
the increments that carry one state into the next, which is how
[`hrgjax.ins.motion`][hrgjax.ins.motion] makes increments that this integrator returns to
the trajectory at round-off. Everything is `jax.lax.scan` (jit / vmap / grad).
"""

from __future__ import annotations

import contextlib

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _upstream, plausible
from .._checks import check_finite_host, check_numbers, describe, host_value, is_concrete
from .._compiled import Check, device, fused, program, single_run_device
from .._progress import bar
from .._x64 import require_x64
from .constants import G0, WGS84, Earth, check_heights, check_latitude_radians, refuse_over_pole

UNROLL = 4
"""Steps per iteration of the compiled loops: the step is a few dozen scalar operations, so the
loop's own overhead dominates; 4 runs an hour at 100 Hz 2.5× faster than 1, for the same
compile time (benchmarks/navigation.py)."""

CHUNK_STEPS = 1 << 18
"""Steps per compiled call of an eager [`mechanize`][hrgjax.ins.mechanization.mechanize] of
more steps (≈ 1 s on one CPU core; 44 min at 100 Hz): the run goes chunk by chunk behind a
progress bar, its carry handed on, with the same results bit for bit (one program for the
chunk's shape, one for the last, shorter one). Under a caller's jit / vmap / grad: one scan."""

# --- rotations ----------------------------------------------------------------------------


@fused
def skew(w):
    r"""$[w\times]$, the cross-product matrix of `w` (..., 3)."""
    z = jnp.zeros_like(w[..., 0])
    return jnp.stack(
        [
            jnp.stack([z, -w[..., 2], w[..., 1]], -1),
            jnp.stack([w[..., 2], z, -w[..., 0]], -1),
            jnp.stack([-w[..., 1], w[..., 0], z], -1),
        ],
        -2,
    )


@fused
def quat_multiply(p, q):
    """Hamilton product p ⊗ q of quaternions (..., 4), scalar first."""
    pw, pv = p[..., :1], p[..., 1:]
    qw, qv = q[..., :1], q[..., 1:]
    w = pw * qw - jnp.sum(pv * qv, -1, keepdims=True)
    v = pw * qv + qw * pv + jnp.cross(pv, qv)
    return jnp.concatenate([w, v], -1)


@fused
def quat_conjugate(q):
    """The conjugate (inverse of a unit quaternion), scalar first."""
    return jnp.concatenate([q[..., :1], -q[..., 1:]], -1)


@fused
def rotvec_to_quat(phi):
    r"""Unit quaternion of the rotation vector `phi` (..., 3) [rad]: $(\cos\frac{|\phi|}2,
    \frac{\phi}{|\phi|}\sin\frac{|\phi|}2)$, by its series below 1e-2 rad (exact to
    round-off, differentiable at 0)."""
    a2 = jnp.sum(phi * phi, -1, keepdims=True)
    small = a2 < 1e-4
    a = jnp.sqrt(jnp.where(small, 1.0, a2))
    w = jnp.where(small, 1.0 - a2 / 8.0 + a2**2 / 384.0, jnp.cos(0.5 * a))
    s = jnp.where(small, 0.5 - a2 / 48.0 + a2**2 / 3840.0, jnp.sin(0.5 * a) / a)
    return jnp.concatenate([w, s * phi], -1)


@fused
def quat_to_rotvec(q):
    """Rotation vector [rad] (..., 3) of a unit quaternion (..., 4), angle in [0, π]."""
    q = jnp.where(q[..., :1] < 0, -q, q)
    w, v = q[..., :1], q[..., 1:]
    s2 = jnp.sum(v * v, -1, keepdims=True)
    small = s2 < 1e-8
    s = jnp.sqrt(jnp.where(small, 1.0, s2))
    # 2·atan2(s, w)/s, by its series in s/w for small s
    r2 = s2 / jnp.where(small, w * w, 1.0)
    k = jnp.where(small, 2.0 / w * (1.0 - r2 / 3.0 + r2**2 / 5.0), 2.0 * jnp.arctan2(s, w) / s)
    return k * v


@fused
def quat_to_dcm(q):
    """Rotation matrix (..., 3, 3) of a unit quaternion: body-to-NED $C_b^n$ for `q_bn`."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return jnp.stack(
        [
            jnp.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            jnp.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            jnp.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


@fused
def euler_to_quat(roll, pitch, heading):
    """Body (FRD)-to-NED quaternion from roll, pitch, heading [rad] (3-2-1 order, as
    [`euler_to_dcm`][hrgjax.ins.trajectory.euler_to_dcm])."""
    roll, pitch, heading = (jnp.asarray(x, float) for x in (roll, pitch, heading))
    cr, sr = jnp.cos(0.5 * roll), jnp.sin(0.5 * roll)
    cp, sp = jnp.cos(0.5 * pitch), jnp.sin(0.5 * pitch)
    ch, sh = jnp.cos(0.5 * heading), jnp.sin(0.5 * heading)
    return jnp.stack(
        [
            ch * cp * cr + sh * sp * sr,
            ch * cp * sr - sh * sp * cr,
            ch * sp * cr + sh * cp * sr,
            sh * cp * cr - ch * sp * sr,
        ],
        -1,
    )


# --- the navigation state -----------------------------------------------------------------


GIMBAL_LOCK = 1e-14
"""Below this |cos pitch| (√(c00² + c10²)),
[`dcm_to_euler`][hrgjax.ins.mechanization.dcm_to_euler] treats a matrix as at pitch ±90°
(gimbal lock): roll 0, the heading carrying the whole
rotation about the vertical. A matrix of unit quaternion holds cos pitch to ≈ 3e-16."""


@fused
def dcm_to_euler(c):
    r"""(roll, pitch, heading) [rad] of a body-to-NED matrix (..., 3, 3) (3-2-1 order, as
    [`euler_to_dcm`][hrgjax.ins.trajectory.euler_to_dcm]; heading in [−π, π], roll in
    [−π, π], pitch in [−π/2, π/2]): angles that rebuild `c` to round-off at every pitch.

    Pitch is $\operatorname{atan2}(-c_{20}, \sqrt{c_{00}^2 + c_{10}^2})$ (accurate near ±90°,
    where $\arcsin c_{20}$ is not); heading $\operatorname{atan2}(c_{10}, c_{00})$; roll
    from the heading, $\sin\phi = \sin\psi\,c_{02} - \cos\psi\,c_{12}$,
    $\cos\phi = \cos\psi\,c_{11} - \sin\psi\,c_{01}$, so that roll and heading agree
    even where pitch nears ±90° and they are ill-conditioned apart. At gimbal lock (cos pitch
    below [`GIMBAL_LOCK`][hrgjax.ins.mechanization.GIMBAL_LOCK]) only heading ∓ roll is
    defined: roll is 0 and the heading $\operatorname{atan2}(-c_{01}, c_{11})$, which is
    ψ − φ at pitch +90° ($c_{01} = \sin(\phi - \psi)$, $c_{11} = \cos(\phi - \psi)$)
    and ψ + φ at −90° ($c_{01} = -\sin(\phi + \psi)$, $c_{11} = \cos(\phi + \psi)$).
    Differentiable (jit / vmap / grad) with finite gradients at and away from the lock."""
    c00, c01, c02 = c[..., 0, 0], c[..., 0, 1], c[..., 0, 2]
    c10, c11, c12 = c[..., 1, 0], c[..., 1, 1], c[..., 1, 2]
    c20 = c[..., 2, 0]
    cp2 = c00 * c00 + c10 * c10
    lock = cp2 < GIMBAL_LOCK**2
    # every branch's arguments kept away from atan2(0, 0) and √0, whose gradients are NaN
    cp = jnp.where(lock, 0.0, jnp.sqrt(jnp.where(lock, 1.0, cp2)))
    pitch = jnp.arctan2(-c20, cp)
    heading_free = jnp.arctan2(jnp.where(lock, 0.0, c10), jnp.where(lock, 1.0, c00))
    sh, ch = jnp.sin(heading_free), jnp.cos(heading_free)
    roll_free = jnp.arctan2(sh * c02 - ch * c12, ch * c11 - sh * c01)
    heading_lock = jnp.arctan2(jnp.where(lock, -c01, 0.0), jnp.where(lock, c11, 1.0))
    roll = jnp.where(lock, 0.0, roll_free)
    heading = jnp.where(lock, heading_lock, heading_free)
    return roll, pitch, heading


@fused
def wrap_angle(a):
    r"""Angles `a` [rad] (any shape) wrapped to [−π, π): $((a + π) \bmod 2π) − π$, derivative
    1 (jit / vmap / grad). For differences of longitudes, which a trajectory may carry
    continuously past ±180° while a receiver or a truth file writes them in (−180°, 180°]."""
    return jnp.mod(a + jnp.pi, 2.0 * jnp.pi) - jnp.pi


class NavState(eqx.Module):
    """Position, velocity and attitude of a strapdown INS (one epoch, or a history with a
    leading time axis).

    **Fields:** `lat`, `lon` [rad]; `h` [m above the WGS-84 ellipsoid]; `v_ned` (..., 3)
    [m/s]; `q_bn` (..., 4) the body (FRD)-to-NED unit quaternion, scalar first."""

    lat: jax.Array
    lon: jax.Array
    h: jax.Array
    v_ned: jax.Array
    q_bn: jax.Array

    @classmethod
    def from_euler(cls, lat, lon, h, v_ned, roll, pitch, heading) -> NavState:
        """A state from geodetic position [rad, rad, m], NED velocity [m/s] and roll, pitch,
        heading [rad].

        **Raises:** `ValueError` for a concrete `lat` or `pitch` beyond ±π/2, `roll` beyond
        ±π, `heading` beyond ±2π (angles in degrees), an `h` outside
        [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M] (traced values are not
        checked)."""
        check_latitude_radians("NavState.from_euler: lat", lat)
        check_heights("NavState.from_euler: h", h)
        for name, x, limit, text in (("roll", roll, np.pi, "±π"), ("pitch", pitch, np.pi / 2,
                                     "±π/2"), ("heading", heading, 2 * np.pi, "±2π")):  # fmt: skip
            v = None if isinstance(x, jax.core.Tracer) or not is_concrete(x) else np.asarray(x)
            if v is not None and np.any(bad := np.abs(v) > limit * (1 + 1e-12)):
                a = float(np.asarray(v, float)[bad].flat[0])
                raise ValueError(f"NavState.from_euler: {name} = {a:g} rad is beyond {text}: "
                                 f"angles are in radians here (degrees? use np.radians({a:g}) "
                                 f"= {np.radians(a):.6g})")  # fmt: skip
        f = lambda x: jnp.asarray(x, float)
        return cls(f(lat), f(lon), f(h), f(v_ned), euler_to_quat(roll, pitch, heading))

    @property
    def c_bn(self):
        """Body-to-NED matrix (..., 3, 3)."""
        return quat_to_dcm(self.q_bn)

    @property
    def euler(self):
        """(roll, pitch, heading) [rad]."""
        return dcm_to_euler(self.c_bn)

    def __getitem__(self, k) -> NavState:
        """Epoch(s) `k` of a history."""
        return jax.tree_util.tree_map(lambda x: x[k], self)


@fused
def navigation_errors(nav: NavState, truth: NavState, earth: Earth = WGS84):
    r"""Errors of `nav` against `truth` (same epochs), in the strapdown error model's
    conventions ([`hrgjax.ins.strapdown`][hrgjax.ins.strapdown]).

    **Returns** `(position (..., 3) [m, north east down], velocity (..., 3) [m/s, NED],
    attitude (..., 3) [rad])`, the attitude error φ defined by
    $\hat C_b^n = e^{-[\phi\times]}C_b^n \approx (I - [\phi\times])C_b^n$. The longitude
    difference is wrapped to ±π ([`wrap_angle`][hrgjax.ins.mechanization.wrap_angle]): the
    same meridian written as +180° and −180° (or 0° and 360°) is no error. `nav` and `truth`
    broadcast (runs (R, N) against one truth (N,), or all epochs against one); shapes that
    do not are refused in one line."""
    for field in ("lat", "lon", "h", "v_ned", "q_bn"):
        a, b = jnp.shape(getattr(nav, field)), jnp.shape(getattr(truth, field))
        try:
            np.broadcast_shapes(a, b)
        except ValueError:
            msg = (f"nav and truth must hold the same epochs (or broadcast); got nav.{field} "
                   f"of shape {a}, truth.{field} of shape {b}")  # fmt: skip
            raise ValueError(msg) from None
    r_m, r_n = earth.radii(truth.lat)
    pos = jnp.stack(
        [
            (nav.lat - truth.lat) * (r_m + truth.h),
            wrap_angle(nav.lon - truth.lon) * (r_n + truth.h) * jnp.cos(truth.lat),
            -(nav.h - truth.h),
        ],
        -1,
    )
    err = quat_multiply(nav.q_bn, quat_conjugate(truth.q_bn))
    return pos, nav.v_ned - truth.v_ned, -quat_to_rotvec(err)


# --- one step and its inverse -------------------------------------------------------------


def _midpoint_terms(earth, prev, prev2, dt):
    """ζ and the gravity-minus-Coriolis acceleration at the interval's extrapolated midpoint."""
    lat, h, v = (1.5 * a - 0.5 * b for a, b in zip(prev, prev2, strict=True))
    w_ie, w_en = earth.earth_rate(lat), earth.transport_rate(lat, h, v)
    acc = earth.gravity_ned(lat, h) - jnp.cross(2.0 * w_ie + w_en, v)
    return (w_ie + w_en) * dt, acc


def position_step(earth: Earth, lat, lon, h, v0, v1, dt):
    """Geodetic position after one interval Δt = `dt` [s] from (`lat`, `lon` [rad], `h` [m])
    with velocities `v0` → `v1` [m/s, NED] at its ends (trapezoid; radii at the midpoint;
    height first, then latitude, then longitude). **Returns** `(lat, lon, h)`."""
    va = 0.5 * (v0 + v1)
    h1 = h - dt * va[..., 2]
    hm = 0.5 * (h + h1)
    r_m, _ = earth.radii(lat)
    lat_half = lat + 0.5 * dt * va[..., 0] / (r_m + hm)
    r_m, _ = earth.radii(lat_half)
    lat1 = lat + dt * va[..., 0] / (r_m + hm)
    lat_m = 0.5 * (lat + lat1)
    _, r_n = earth.radii(lat_m)
    lon1 = lon + dt * va[..., 1] / ((r_n + hm) * jnp.cos(lat_m))
    return lat1, lon1, h1


def step(earth, dt, carry, inc):
    """One mechanisation interval (module docstring), a `lax.scan` body: `carry` from
    [`start_carry`][hrgjax.ins.mechanization.start_carry] or the last step, `inc` the
    interval's (gyro [rad], accelerometer [m/s]) increments, with (height [m], down velocity
    [m/s]) appended for vertical aiding; `dt` [s]. Returns (carry, the new `NavState`)."""
    state, prev2, (dth_p, dv_p) = carry
    dth, dv = inc[:2]
    zeta, acc = _midpoint_terms(earth, (state.lat, state.h, state.v_ned), prev2, dt)
    phi = dth + jnp.cross(dth_p, dth) / 12.0
    dv_sf = dv + 0.5 * jnp.cross(dth, dv) + (jnp.cross(dth_p, dv) + jnp.cross(dv_p, dth)) / 12.0
    dv_n = state.c_bn @ dv_sf
    v1 = state.v_ned + dv_n - 0.5 * jnp.cross(zeta, dv_n) + acc * dt
    lat1, lon1, h1 = position_step(earth, state.lat, state.lon, state.h, state.v_ned, v1, dt)
    q1 = quat_multiply(quat_multiply(rotvec_to_quat(-zeta), state.q_bn), rotvec_to_quat(phi))
    q1 = q1 / jnp.linalg.norm(q1)
    if len(inc) == 3:  # vertical aiding: height and vertical velocity given
        h1, v1 = inc[2][0], v1.at[2].set(inc[2][1])
    new = NavState(lat1, lon1, h1, v1, q1)
    return (new, (state.lat, state.h, state.v_ned), (dth, dv)), new


def start_carry(initial: NavState, dtype):
    """The scan carry of [`step`][hrgjax.ins.mechanization.step] at `initial`: the state,
    its (lat, h, v_ned) as the previous epoch and zero previous increments (`dtype`)."""
    zeros = jnp.zeros(3, dtype)
    return (initial, (initial.lat, initial.h, initial.v_ned), (zeros, zeros))


def _check_dt(dt):
    """Refuse a concrete `dt` that is not one finite number > 0 [s] in one line."""
    if is_concrete(dt):
        d = np.asarray(dt)
        if d.shape != () or not np.issubdtype(d.dtype, np.number):
            raise ValueError(
                f"dt must be one number, the increments' interval [s]; got {type(dt).__name__} "
                f"of shape {d.shape}"
            )
        if not (np.isfinite(d) and d > 0):
            raise ValueError(f"dt must be the increments' interval in seconds (> 0); got {d}")


MIN_MEAN_SPECIFIC_FORCE = 0.2 * G0
"""The least mean specific force |dv|/dt [m/s²] over a record that `check_increments` takes
(0.2 g): a navigating vehicle spends most of its time near 1 g (a zero-g parabola is 20 s
between 1.8-g pull-ups), so a record under it is a `dt` too long — 100-Hz increments at
dt = 1 s read 0.01 g and ended 353 km off in height — as `check_stationary` refuses a mean
specific force off g for the `ImuLog.t` [s]; free fall itself is physical (no bound per
sample; all-zero increments pass)."""


def check_increments(dtheta, dv, dt):
    """`dtheta` [rad] and `dv` [m/s] as float arrays of shape (N, 3), and `dt` [s] > 0; a
    `ValueError` naming the field for another shape, NaN or inf, a gyro increment of π or
    more (degrees or rates given for radians), a median specific force |dv|/dt beyond
    `hrgjax.plausible.RANGES["median_specific_force_mps2"]` (5 g: accelerations [m/s²] given
    for increments) or a mean one under `MIN_MEAN_SPECIFIC_FORCE` (0.2 g: a `dt` too long).
    Concrete values only: traced ones pass."""
    dtheta, dv = jnp.asarray(dtheta, float), jnp.asarray(dv, float)
    if dtheta.ndim != 2 or dtheta.shape[-1] != 3 or dtheta.shape != dv.shape:
        raise ValueError(
            "dtheta and dv must both have shape (N, 3) (one gyro [rad] and one accelerometer "
            f"[m/s] increment per interval); got {dtheta.shape} and {dv.shape}"
        )
    _check_dt(dt)
    for name, x in (("dtheta", dtheta), ("dv", dv)):
        if is_concrete(x) and not np.all(np.isfinite(np.asarray(x))):
            row = int(np.argmax(~np.all(np.isfinite(np.asarray(x)), axis=1)))
            raise ValueError(
                f"{name} holds NaN or inf (first at row {row}); increments must be finite"
            )
    if is_concrete(dtheta):
        turn = np.linalg.norm(np.asarray(dtheta), axis=1)
        if turn.size and turn.max() >= np.pi:
            raise ValueError(
                f"dtheta turns {turn.max():.3g} rad in one interval (row {int(turn.argmax())}): "
                "gyro increments are in radians per interval, not degrees or rates"
            )
    if is_concrete(dv) and is_concrete(dt) and dv.shape[0]:
        force = float(np.median(np.linalg.norm(np.asarray(dv), axis=1))) / float(dt)
        high = plausible.RANGES["median_specific_force_mps2"][1]
        if force > high:
            raise ValueError(
                f"dv: the median specific force |dv|/dt is {force:.4g} m/s² "
                f"({force / G0:.3g} g) with dt = {float(dt):g} s, beyond the {high / G0:g} g of "
                "a navigating vehicle (hrgjax.plausible): accelerometer increments are velocity "
                "changes [m/s] per interval (specific force × dt), not accelerations [m/s²], "
                "and dt is their interval"
            )
        mean = float(np.mean(np.linalg.norm(np.asarray(dv), axis=1))) / float(dt)
        if 0 < mean < MIN_MEAN_SPECIFIC_FORCE:  # all zeros: no scale a dt could set
            raise ValueError(
                f"dt: the mean specific force |dv|/dt is {mean:.4g} m/s² ({mean / G0:.3g} g) "
                f"with dt = {float(dt):g} s, under the {MIN_MEAN_SPECIFIC_FORCE / G0:g} g of a "
                f"navigating vehicle (in free fall throughout?): is dt the increments' interval "
                f"[s]? (dt = {float(dt) * mean / G0:.4g} s gives 1 g)"
            )
    return dtheta, dv


def check_state(initial):
    """A `TypeError` unless `initial` is a `NavState`, a `ValueError` unless it is one finite
    epoch with a latitude within ±π/2 rad (one beyond is in degrees), a height in
    [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M], a speed within `hrgjax.plausible`'s
    `speed_mps` and a unit `q_bn` (|q| within 1e-6 of 1: another's first step is not a
    rotation). Concrete values only."""
    if not isinstance(initial, NavState):
        raise TypeError(
            f"initial must be a NavState (hrgjax.ins.mechanization); got {type(initial).__name__}"
        )
    for field in ("lat", "lon", "h", "v_ned", "q_bn"):
        check_finite_host(f"initial.{field}", getattr(initial, field))
    if jnp.shape(initial.v_ned) != (3,) or jnp.shape(initial.q_bn) != (4,):
        raise ValueError(
            "initial must be one epoch: v_ned (3,) [m/s] and q_bn (4,); got "
            f"{jnp.shape(initial.v_ned)} and {jnp.shape(initial.q_bn)}"
        )
    check_latitude_radians("initial.lat", initial.lat)
    check_heights("initial.h", initial.h)
    if (v := host_value(initial.v_ned)) is not None:
        plausible.check("initial.v_ned: the speed", np.linalg.norm(v), "speed_mps")
    if (q := host_value(initial.q_bn)) is not None and abs(np.linalg.norm(q) - 1.0) > 1e-6:
        raise ValueError(f"initial.q_bn must be a unit quaternion; got |q| = "
                         f"{np.linalg.norm(q):.9g} (normalise it: q / |q|)")  # fmt: skip


def mechanize(
    initial: NavState,
    dtheta,
    dv,
    dt: float,
    *,
    earth: Earth = WGS84,
    every: int = 1,
    vertical=None,
) -> NavState:
    """Free-inertial navigation from increments (module docstring).

    **Arguments:** `initial` the state at the first increment's start; `dtheta` (N, 3) gyro
    increments [rad] and `dv` (N, 3) accelerometer increments [m/s] over intervals of `dt`
    [s]; `earth` the Earth model; `every`: keep every `every`-th epoch (it must divide N) to
    bound memory on long runs; `vertical`: `(h, v_down)`, each (N,) [m, m/s] at the N epochs
    after the first, to aid the (unstable) vertical channel: each step's height and vertical
    velocity are replaced by them (as the linear model's `altitude_aided`).

    **Returns:** the [`NavState`][hrgjax.ins.mechanization.NavState] history, N/every + 1
    epochs, the initial state first.

    An eager run of more than [`CHUNK_STEPS`][hrgjax.ins.mechanization.CHUNK_STEPS] steps
    goes chunk by chunk behind a progress bar (shown at a terminal), with the same results.

    **Raises:** `ValueError` for mis-shaped increments or an `initial.lat` beyond ±π/2 (in
    degrees); `RuntimeError` if the solution stops being finite (e.g. increments in degrees,
    or a vertical channel run into the ground) or, eagerly, passes latitude ±90° (over a pole)."""
    require_x64("ins.mechanize")
    check_state(initial)
    dtheta, dv = check_increments(dtheta, dv, dt)
    n = dtheta.shape[0]
    if not (isinstance(every, int) and every >= 1 and n % every == 0):
        raise ValueError(
            f"every must be a positive divisor of the {n} intervals; got {describe(every)}"
        )
    xs = (dtheta, dv)
    if vertical is not None:
        form = f"(h, v_down), each ({n},) [m, m/s] (the epochs after the first)"
        check_numbers("vertical", vertical, form)
        hv = jnp.stack([jnp.asarray(x, float) for x in vertical], -1)
        check_finite_host("vertical", hv)
        if hv.shape != (n, 2):
            raise ValueError(
                f"vertical must be (h, v_down), each ({n},) [m, m/s] (the epochs after the "
                f"first); got shape {hv.shape[:-1]}"
            )
        xs = xs + (hv,)
    dt = jnp.asarray(dt, float)
    eager = _upstream.trace_state_clean() and not _traced((initial, xs, dt, earth))
    run = _mechanize_in_chunks if n > CHUNK_STEPS and eager else _mechanize
    nav = run(initial, xs, dt, earth, every)
    if eager:  # over a pole the latitude runs on past 90°, finite
        refuse_over_pole("ins.mechanize", nav.lat, float(dt) * every)
    return nav


def _traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _mechanize_in_chunks(initial, xs, dt, earth, every):
    """`_mechanize` as chunks of whole `every`-blocks (and whole `UNROLL` groups) of about
    `CHUNK_STEPS` steps, each a compiled call handing its scan carry to the next, with a
    progress bar: the same steps in the same order, so the same history bit for bit."""
    n = xs[0].shape[0]
    size = max(CHUNK_STEPS // (every * UNROLL), 1) * every * UNROLL
    carry, parts = start_carry(initial, xs[0].dtype), []
    host = [np.asarray(a) for a in xs]  # sliced here: a device array's slice compiles per start
    with bar(n, "mechanize", unit="step") as progress:
        for i in range(0, n, size):
            chunk = tuple(device(a[i : i + size]) for a in host)
            carry, hist = _mechanize_chunk(carry, chunk, dt, earth, every)
            parts.append(hist)
            progress.update(min(size, n - i))
    place = single_run_device()  # where the program ran (an accelerator's host CPU)
    with contextlib.nullcontext() if place is None else jax.default_device(place):
        return _join(initial, tuple(parts))


@program(check=Check("ins.mechanize"), single_run=True)
def _mechanize_chunk(carry, xs, dt, earth, every):
    return _scan_steps(carry, xs, dt, earth, every)


@jax.jit
def _join(initial, parts):
    return jax.tree_util.tree_map(lambda a, *b: jnp.concatenate([a[None], *b]), initial, *parts)


@program(check=Check("ins.mechanize"), single_run=True)
def _mechanize(initial, xs, dt, earth, every):
    _, hist = _scan_steps(start_carry(initial, xs[0].dtype), xs, dt, earth, every)
    return jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), initial, hist)


def _scan_steps(start, xs, dt, earth, every):
    """The scan of `step` over the increments `xs` from the carry `start`: (carry, every
    `every`-th state)."""
    body = lambda c, x: step(earth, dt, c, x)
    if every == 1:
        return jax.lax.scan(body, start, xs, unroll=UNROLL)
    blocks = lambda a: a.reshape((-1, every) + a.shape[1:])

    def block(c, x):
        c, _ = jax.lax.scan(body, c, x, unroll=UNROLL)
        return c, c[0]

    return jax.lax.scan(block, start, tuple(blocks(a) for a in xs))


def _solve_cross(a, b):
    r"""$x$ with $x + a\times x = b$: $x = (b - a\times b + (a\cdot b)\,a)/(1 + |a|^2)$."""
    return (b - jnp.cross(a, b) + jnp.dot(a, b) * a) / (1.0 + jnp.dot(a, a))


def _inverse_step(earth, dt, carry, target):
    state, prev2, (dth_p, dv_p) = carry
    v1, q1 = target
    zeta, acc = _midpoint_terms(earth, (state.lat, state.h, state.v_ned), prev2, dt)
    qphi = quat_multiply(quat_multiply(quat_conjugate(state.q_bn), rotvec_to_quat(zeta)), q1)
    dth = _solve_cross(dth_p / 12.0, quat_to_rotvec(qphi))
    dv_sf = state.c_bn.T @ _solve_cross(-0.5 * zeta, v1 - state.v_ned - acc * dt)
    dv = _solve_cross(0.5 * dth + dth_p / 12.0, dv_sf - jnp.cross(dv_p, dth) / 12.0)
    lat1, lon1, h1 = position_step(earth, state.lat, state.lon, state.h, state.v_ned, v1, dt)
    new = NavState(lat1, lon1, h1, v1, q1)
    return (new, (state.lat, state.h, state.v_ned), (dth, dv)), (new, dth, dv)


def increments_from_states(initial: NavState, v_ned, q_bn, dt: float, *, earth: Earth = WGS84):
    """The increments that [`mechanize`][hrgjax.ins.mechanization.mechanize] turns into a
    given velocity and attitude history, and the positions it then computes (the inverse of
    its step, solved exactly: three 3×3 linear solves and a quaternion logarithm per step).

    **Arguments:** `initial` the first epoch; `v_ned` (N, 3) [m/s] and `q_bn` (N, 4) the
    velocity and attitude at the N following epochs, `dt` [s] apart.

    **Returns:** `(states, dtheta, dv)`: the N + 1 epochs (positions from the trapezoid of the
    velocities, as the integrator computes them) and the (N, 3) increments [rad, m/s]."""
    require_x64("ins.increments_from_states")
    check_state(initial)
    check_numbers("v_ned", v_ned, "(N, 3) velocities [m/s], one row per epoch after the first")
    check_numbers("q_bn", q_bn, "(N, 4) attitude quaternions, one row per epoch after the first")
    v_ned, q_bn = jnp.asarray(v_ned, float), jnp.asarray(q_bn, float)
    n = v_ned.shape[0] if v_ned.ndim == 2 else None
    if n is None or n == 0 or v_ned.shape != (n, 3) or q_bn.shape != (n, 4):
        raise ValueError(f"v_ned and q_bn must be (N, 3) and (N, 4), N >= 1 epochs after the "
                         f"first; got {v_ned.shape} and {q_bn.shape}")  # fmt: skip
    _check_dt(dt)
    check_finite_host("v_ned", v_ned)
    check_finite_host("q_bn", q_bn)
    return _invert(initial, v_ned, q_bn, device(dt, float), earth)  # dt a value, as mechanize's


@eqx.filter_jit
def _invert(initial, v_ned, q_bn, dt, earth):
    body = lambda c, x: _inverse_step(earth, dt, c, x)
    _, (hist, dth, dv) = jax.lax.scan(
        body, start_carry(initial, v_ned.dtype), (v_ned, q_bn), unroll=UNROLL
    )
    states = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), initial, hist)
    return states, dth, dv
