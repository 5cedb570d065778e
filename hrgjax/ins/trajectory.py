r"""Trajectories for the INS error models: stationary, constant velocity, turns, a 1-hour
flight ([`flight`][hrgjax.ins.trajectory.flight]).

A [`Trajectory`][hrgjax.ins.trajectory.Trajectory] holds, on a time grid, everything the
strapdown error model needs — latitude, longitude, height, NED velocity, the body-to-NED
attitude matrix and the specific force in NED — consistent with the navigation equations
$\dot v^n = f^n - (2\omega_{ie}^n + \omega_{en}^n)\times v^n + g^n$. Its
[`imu`][hrgjax.ins.trajectory.Trajectory.imu] method gives the ideal body-frame IMU outputs.
Body frame FRD (x forward, y right, z down); heading clockwise from north.

Builders run once in NumPy (they are set-up, not traced) and return JAX arrays.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_finite_host, check_number, describe, finite_number, host_value
from .._compiled import fused
from ..units import DEG
from .constants import E2, HEIGHT_RANGE_M, MAX_LAT_DEG, WGS84, A, Earth, check_heights
from .mechanization import check_latitude_radians
from .mechanization import dcm_to_euler as dcm_to_euler


@fused
def euler_to_dcm(roll, pitch, heading):
    r"""Body (FRD)-to-NED matrix $C_b^n$ from roll, pitch, heading [rad] (3-2-1 order)."""
    cr, sr = jnp.cos(roll), jnp.sin(roll)
    cp, sp = jnp.cos(pitch), jnp.sin(pitch)
    ch, sh = jnp.cos(heading), jnp.sin(heading)
    return jnp.stack(
        [
            jnp.stack([cp * ch, -cr * sh + sr * sp * ch, sr * sh + cr * sp * ch], -1),
            jnp.stack([cp * sh, cr * ch + sr * sp * sh, -sr * ch + cr * sp * sh], -1),
            jnp.stack([-sp, sr * cp, cr * cp], -1),
        ],
        -2,
    )


class Trajectory(eqx.Module):
    """A reference trajectory on a time grid (module docstring).

    **Fields:** `t` (N,) [s]; `lat`, `lon` (N,) [rad]; `h` (N,) [m]; `v_ned` (N, 3) [m/s];
    `c_bn` (N, 3, 3) body-to-NED; `f_ned` (N, 3) specific force [m/s²]; `earth` (static).

    **Raises:** `ValueError`, one line naming the field, for concrete fields that are not
    finite, of shapes other than the above for the N times of a 1-d `t`, times that do not
    increase, a `lat` beyond ±π/2 (a latitude in degrees) or an `h` outside
    [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M] (a NaN time went to the
    integrator, which ran out of steps; −7e6 m returned numbers)."""

    t: jax.Array
    lat: jax.Array
    lon: jax.Array
    h: jax.Array
    v_ned: jax.Array
    c_bn: jax.Array
    f_ned: jax.Array
    earth: Earth = eqx.field(static=True, default=WGS84)

    def __check_init__(self):
        names = ("t", "lat", "lon", "h", "v_ned", "c_bn", "f_ned")
        n = jnp.shape(self.t)[0] if jnp.ndim(self.t) == 1 else None
        for name, tail in zip(names, ((), (), (), (), (3,), (3, 3), (3,)), strict=True):
            got = jnp.shape(getattr(self, name))
            if n is not None and got != (n, *tail):
                raise ValueError(f"Trajectory.{name} must be {(n, *tail)} for the {n} times of "
                                 f"t; got shape {got}")  # fmt: skip
            check_finite_host(f"Trajectory.{name}", getattr(self, name))
        t = host_value(self.t)
        if t is not None and t.ndim == 1 and (t.size < 2 or not np.all(np.diff(t) > 0)):
            raise ValueError("Trajectory.t must hold at least 2 strictly increasing times")
        check_latitude_radians("Trajectory.lat", self.lat)
        check_heights("Trajectory.h", self.h)

    @property
    def attitude(self):
        """(roll, pitch, heading) [rad], each (N,)."""
        return dcm_to_euler(self.c_bn)

    def imu(self):
        r"""Ideal IMU outputs along the trajectory: specific force $f^b = C_n^b f^n$ and
        angular rate $\omega_{ib}^b = C_n^b(\omega_{ie}^n + \omega_{en}^n) + \omega_{nb}^b$,
        with $\omega_{nb}^b$ from central differences of $C_b^n$. **Returns** `(f_b, w_b)`,
        each (N, 3)."""
        c_nb = jnp.swapaxes(self.c_bn, -1, -2)
        f_b = jnp.einsum("nij,nj->ni", c_nb, self.f_ned)
        w_in = self.earth.earth_rate(self.lat) + self.earth.transport_rate(
            self.lat, self.h, self.v_ned
        )
        c = np.asarray(self.c_bn)
        dc = np.gradient(c, np.asarray(self.t), axis=0)
        skew = np.einsum("nji,njk->nik", c, dc)  # C_nb Ċ_bn = [ω_nb^b ×]
        w_nb = np.stack([skew[:, 2, 1], skew[:, 0, 2], skew[:, 1, 0]], axis=-1)
        return f_b, jnp.einsum("nij,nj->ni", c_nb, w_in) + jnp.asarray(w_nb)


def _from_kinematics(t, lat0, lon0, h0, speed, heading, gamma, earth, roll=None, where=""):
    """Integrate position from speed, heading and flight-path angle (trapezoid on the grid)
    and derive velocity, attitude (coordinated turns) and specific force; `where` prefixes
    the errors (the builder: `"stationary: "`)."""
    if not isinstance(earth, Earth):
        raise TypeError(f"{where}earth must be an Earth model (hrgjax.ins.constants: WGS84, "
                        f"SPHERE or Earth(...)); got {describe(earth)}")  # fmt: skip
    v = np.stack(
        [
            speed * np.cos(gamma) * np.cos(heading),
            speed * np.cos(gamma) * np.sin(heading),
            -speed * np.sin(gamma),
        ],
        axis=-1,
    )
    n = t.size
    lat, lon, h = np.empty(n), np.empty(n), np.empty(n)
    lat[0], lon[0], h[0] = lat0, lon0, h0

    def rate(la, hh, vv):  # Earth.position_rate in NumPy: a jnp call per step is 4× slower
        if earth.radius is None:
            w = 1.0 - E2 * np.sin(la) ** 2
            r_n = A / np.sqrt(w)
            r_m = r_n * (1.0 - E2) / w
        else:
            r_m = r_n = earth.radius
        return vv[0] / (r_m + hh), vv[1] / ((r_n + hh) * np.cos(la)), -vv[2]

    for i in range(n - 1):  # Heun step of the position equations
        dt = t[i + 1] - t[i]
        r0 = rate(lat[i], h[i], v[i])
        r1 = rate(lat[i] + dt * r0[0], h[i] + dt * r0[2], v[i + 1])
        lat[i + 1] = lat[i] + 0.5 * dt * (r0[0] + r1[0])
        lon[i + 1] = lon[i] + 0.5 * dt * (r0[1] + r1[1])
        h[i + 1] = h[i] + 0.5 * dt * (r0[2] + r1[2])
    check_latitudes(t, lat, "the trajectory")
    check_path_heights(t, h, "the trajectory")
    vdot = np.gradient(v, t, axis=0)
    w = 2 * np.asarray(earth.earth_rate(lat)) + np.asarray(earth.transport_rate(lat, h, v))
    g = np.asarray(earth.gravity_ned(lat, h))
    f = vdot + np.cross(w, v) - g
    if roll is None:  # coordinated turn: tan φ = V ψ̇ / g
        roll = np.arctan2(speed * np.gradient(np.unwrap(heading), t), g[:, 2])
    c = euler_to_dcm(jnp.asarray(roll), jnp.asarray(gamma), jnp.asarray(heading))
    arr = jnp.asarray
    return Trajectory(arr(t), arr(lat), arr(lon), arr(h), arr(v), c, arr(f), earth)


def check_path_heights(t, h, what: str) -> None:
    """A one-line `ValueError` if the integrated heights `h` [m] at times `t` [s] leave
    [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M], naming `what` and the time they
    first do (the start is checked where it is given: a climb at 1 km/s from 99 km reached
    618 km unrefused)."""
    h = np.asarray(h, float)
    out = ~((h > HEIGHT_RANGE_M[0]) & (h < HEIGHT_RANGE_M[1]))  # NaN counts as outside
    if np.any(out):
        k = int(np.argmax(out))
        raise ValueError(
            f"{what} leaves the heights ({HEIGHT_RANGE_M[0]:g}, {HEIGHT_RANGE_M[1]:g}) m at "
            f"t = {float(t[k]):g} s (h = {h[k]:.6g} m)"
        )


def check_latitudes(t, lat, what: str) -> None:
    """A one-line `ValueError` if the integrated latitudes `lat` [rad] at times `t` [s] go
    beyond ±[`MAX_LAT_DEG`][hrgjax.ins.constants.MAX_LAT_DEG], naming `what` and the time
    they first do (a flight over or near a pole: the NED frame is singular there)."""
    lat = np.asarray(lat, float)
    over = ~(np.abs(lat) <= MAX_LAT_DEG * DEG)  # NaN counts as beyond
    if np.any(over):
        k = int(np.argmax(over))
        raise ValueError(
            f"{what} goes beyond latitude ±{MAX_LAT_DEG:g}° at t = {float(t[k]):g} s "
            f"({np.degrees(lat[k]):.6g}°): the navigation frame is singular at the poles; "
            "fly it away from them"
        )


def _grid(duration_s, dt, where=""):
    check_number(f"{where}duration_s", duration_s, "s")
    check_number(f"{where}dt", dt, "s")
    if not (np.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"{where}duration_s must be > 0 s; got {duration_s}")
    if not (np.isfinite(dt) and 0 < dt <= duration_s):
        raise ValueError(f"{where}dt must be in (0, duration_s]; got {dt}")
    steps = duration_s / dt
    if abs(steps - round(steps)) > 1e-6:
        raise ValueError(
            f"{where}dt = {dt} s must divide duration_s = {duration_s} s into whole steps; got "
            f"{steps:.6g} steps"
        )
    return np.arange(int(round(duration_s / dt)) + 1) * dt


def check_position(lat_deg, lon_deg, h, where: str = "") -> None:
    """A one-line `ValueError` (`TypeError` for a non-number) naming the field unless
    `lat_deg` [°] is within ±[`MAX_LAT_DEG`][hrgjax.ins.constants.MAX_LAT_DEG] (the NED frame
    is singular at the poles), `lon_deg` in [−180, 360] ° and `h` a height in (−1e4, 1e5) m;
    `where` prefixes the field names (e.g. `"Motion."`). A traced one (`jit`, `vmap`, `grad`)
    is a `TypeError` in one line: the builders integrate in NumPy, set-up not traced."""
    for name, x, unit in (("lat_deg", lat_deg, "°"), ("lon_deg", lon_deg, "°"), ("h", h, "m")):
        if isinstance(x, jax.core.Tracer):  # float() of it was a ConcretizationTypeError
            raise TypeError(
                f"{where}{name} must be a number [{unit}], not a traced value: trajectories are "
                "built once in NumPy (set-up, not traced); build one per value outside "
                "jit/vmap/grad (a Python loop)"
            )
    lat = finite_number(f"{where}lat_deg", lat_deg, "°")
    if abs(lat) > MAX_LAT_DEG:
        hint = " (the navigation frame is singular at the poles)" if abs(lat) <= 90.0 else ""
        raise ValueError(
            f"{where}lat_deg must be in [-{MAX_LAT_DEG:g}, {MAX_LAT_DEG:g}] °{hint}; got {lat}"
        )
    lon = finite_number(f"{where}lon_deg", lon_deg, "°")
    if not -180.0 <= lon <= 360.0:
        raise ValueError(f"{where}lon_deg must be in [-180, 360] °; got {lon}")
    h = finite_number(f"{where}h", h, "m")
    if not HEIGHT_RANGE_M[0] < h < HEIGHT_RANGE_M[1]:
        raise ValueError(f"{where}h must be a height in metres in (-1e4, 1e5); got {h}")


def stationary(
    lat_deg: float,
    lon_deg: float = 0.0,
    h: float = 0.0,
    *,
    heading_deg: float = 0.0,
    pitch_deg: float = 0.0,
    roll_deg: float = 0.0,
    duration_s: float = 3600.0,
    dt: float = 1.0,
    earth: Earth = WGS84,
) -> Trajectory:
    """A vehicle at rest at (`lat_deg`, `lon_deg`, `h`) with the given attitude [°]: any
    heading and roll, a pitch within ±90° (beyond, the same attitude is pitch 180° − θ with
    heading and roll turned by 180°: refused). Built in NumPy (set-up): a traced `lat_deg`
    (`jax.vmap` over latitudes) is refused in one line; one call per latitude."""
    return _steady(lat_deg, lon_deg, h, 0.0, (heading_deg, pitch_deg, roll_deg), duration_s, dt,
                   earth, "stationary")  # fmt: skip


def constant_velocity(
    lat_deg: float,
    lon_deg: float = 0.0,
    h: float = 0.0,
    *,
    speed: float = 90.0,
    heading_deg: float = 90.0,
    duration_s: float = 3600.0,
    dt: float = 1.0,
    earth: Earth = WGS84,
) -> Trajectory:
    """Level flight at `speed` [m/s] (>= 0: the direction is the heading's) on a constant
    heading [°, clockwise from north] (a rhumb line)."""
    return _steady(lat_deg, lon_deg, h, speed, (heading_deg, 0.0, 0.0), duration_s, dt, earth,
                   "constant_velocity")  # fmt: skip


def _steady(lat_deg, lon_deg, h, speed, attitude_deg, duration_s, dt, earth,
            where: str) -> Trajectory:  # fmt: skip
    """Constant `speed` [m/s] and attitude (heading, pitch = flight-path angle, roll) [°];
    `where`: the builder, as its errors name it."""
    check_position(lat_deg, lon_deg, h)
    speed = finite_number("speed", speed, "m/s")
    if speed < 0:  # it flew backwards, nose on the heading
        raise ValueError(f"{where}: speed must be >= 0 m/s, the speed along heading_deg (turn "
                         f"the heading by 180° to fly the other way); got {speed:g}")  # fmt: skip
    plausible.check("speed", speed, "speed_mps")
    for name, a in zip(("heading_deg", "pitch_deg", "roll_deg"), attitude_deg, strict=True):
        finite_number(name, a, "°")
    if abs(float(attitude_deg[1])) > 90.0:
        raise ValueError(f"{where}: pitch_deg must be in [-90, 90] ° (beyond, the attitude is "
                         f"pitch 180° − θ with heading and roll turned by 180°); got "
                         f"{float(attitude_deg[1])!r}")  # fmt: skip
    t = _grid(duration_s, dt, f"{where}: ")
    heading, pitch, roll = (np.full(t.size, float(a) * DEG) for a in attitude_deg)
    speeds = np.full(t.size, float(speed))
    return _from_kinematics(t, lat_deg * DEG, lon_deg * DEG, h, speeds, heading, pitch, earth,
                            roll=roll, where=f"{where}: ")  # fmt: skip


def segments(
    lat_deg: float,
    lon_deg: float,
    h: float,
    legs,
    *,
    speed0: float = 0.0,
    heading0_deg: float = 0.0,
    dt: float = 1.0,
    earth: Earth = WGS84,
) -> Trajectory:
    """A trajectory from legs `(duration_s, accel m/s², turn rate °/s, climb rate m/s)`, each
    held constant over exactly its leg: speed and heading integrate (each sample interval at
    the rates of its leg), the flight-path angle is asin(climb/speed) (the speed is along the
    flight path), turns are coordinated.

    **Raises:** `ValueError` (one line, naming the leg) for a leg that is not a whole number
    of samples `dt` [s] long (to 1e-9 relative: it could not be held over its duration),
    where the speed would become negative or a climb rate exceeds the speed (sin 89° of it:
    the pitch is the flight-path angle, and Euler angles are singular at ±90°); a climb from
    rest is refused so."""
    check_position(lat_deg, lon_deg, h)
    speed0 = finite_number("speed0", speed0, "m/s")
    if speed0 < 0:
        raise ValueError(f"speed0 must be >= 0 m/s (along the flight path); got {speed0}")
    heading0_deg = finite_number("heading0_deg", heading0_deg, "°")
    try:
        legs = [tuple(float(x) for x in leg) for leg in legs]
    except (TypeError, ValueError):  # a string, a number for a leg: the one line below
        legs = [()]
    if not legs or any(
        len(leg) != 4 or not np.all(np.isfinite(leg)) or leg[0] <= 0 for leg in legs
    ):
        raise ValueError(
            "legs: a non-empty list of finite (duration_s > 0, accel m/s², turn °/s, climb m/s)"
        )
    dt = finite_number("dt", dt, "s")
    if dt <= 0:
        raise ValueError(f"dt must be a sample interval > 0 s; got {dt}")
    for i, leg in enumerate(legs, 1):
        k = leg[0] / dt
        if abs(k - round(k)) > 1e-9 * max(1.0, k) or round(k) < 1:
            raise ValueError(
                f"legs: leg {i}'s duration {leg[0]:g} s is not a whole number of samples at "
                f"dt = {dt:g} s ({k:.6g} samples): each leg's rates are held over exactly "
                "its duration"
            )
    t = _grid(sum(leg[0] for leg in legs), dt)
    edges = np.cumsum([0.0] + [leg[0] for leg in legs])
    table = np.asarray([leg[1:] for leg in legs])  # (accel, turn, climb) per leg
    leg_of = lambda x: np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(legs) - 1)
    idx = leg_of(t)  # a sample on a boundary belongs to the leg it starts
    mid = leg_of(0.5 * (t[1:] + t[:-1]))  # the leg of each interval
    step = lambda rate: np.concatenate([[0.0], np.cumsum(rate * np.diff(t))])
    speed = speed0 + step(table[mid, 0])
    if np.any(speed < 0):
        k = int(np.argmax(speed < 0))
        raise ValueError(
            f"legs: the speed would become negative in leg {int(mid[k - 1]) + 1} "
            f"(at t = {t[k]:g} s)"
        )
    plausible.check("legs: the speed reached", speed.max(), "speed_mps")
    heading = heading0_deg * DEG + step(table[mid, 1]) * DEG
    climb = table[idx, 2]
    steep = np.abs(climb) > np.sin(89.0 * DEG) * speed
    if np.any(steep):
        k = int(np.argmax(steep))
        limit = "exceeds the speed" if abs(climb[k]) > speed[k] else "is within 1° of the speed"
        raise ValueError(
            f"legs: leg {int(idx[k]) + 1}'s climb rate {climb[k]:g} m/s {limit} {speed[k]:.6g} "
            f"m/s at t = {t[k]:g} s (the flight-path angle asin(climb/speed) must stay within "
            "±89°)"
        )
    gamma = np.arcsin(np.divide(climb, speed, out=np.zeros_like(speed), where=climb != 0))
    return _from_kinematics(t, lat_deg * DEG, lon_deg * DEG, h, speed, heading, gamma, earth)


def flight(
    lat_deg: float = 45.0,
    lon_deg: float = 30.0,
    *,
    dt: float = 1.0,
    earth: Earth = WGS84,
) -> Trajectory:
    """A 1-hour flight: take-off run and climb to 200 m/s, cruise north-east, a 90° turn to
    the right, cruise, a 180° turn to the left, cruise, a shallow descent (3600 s).

    `dt` [s] must divide every leg (45 s and 995 s among them: a divisor of 5 s, such as
    0.01, 0.1, 0.5 or 1); another is refused naming `dt`."""
    step = finite_number("dt", dt, "s")
    if not (step > 0 and abs(5.0 / step - round(5.0 / step)) <= 1e-9 * (5.0 / step)):
        raise ValueError(f"flight: dt must divide its legs of 45 s and 995 s (a divisor of 5 s, "
                         f"e.g. 0.01, 0.1, 0.5, 1); got dt = {dt!r}")  # fmt: skip
    legs = [
        (100.0, 2.0, 0.0, 0.0),  # take-off run to 200 m/s
        (300.0, 0.0, 0.0, 15.0),  # climb 4.5 km
        (1000.0, 0.0, 0.0, 0.0),  # cruise
        (45.0, 0.0, 2.0, 0.0),  # 90° right turn
        (800.0, 0.0, 0.0, 0.0),
        (60.0, 0.0, -3.0, 0.0),  # 180° left turn
        (995.0, 0.0, 0.0, 0.0),
        (300.0, 0.0, 0.0, -10.0),  # descent
    ]
    return segments(
        lat_deg, lon_deg, 100.0, legs, speed0=0.0, heading0_deg=45.0, dt=dt, earth=earth
    )
