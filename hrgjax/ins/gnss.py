r"""GNSS position and velocity fixes of a sampled motion: white noise in NED metres, an
antenna lever arm, outages.

The antenna sits at the body-frame lever arm $l^b$ from the IMU: its position is
$r + C_b^n l^b$ (NED offset turned into latitude, longitude and height with the radii of
curvature) and its velocity $v^n + C_b^n(\omega_{eb}^b\times l^b)$, with
$\omega_{eb}^b \approx \Delta\theta/\Delta t - C_n^b\omega_{ie}^n$ from the interval's
increment. A fix is taken every 1/`rate_hz` s where the motion has GNSS visible and no
outage window covers it.
"""

from __future__ import annotations

import math
import numbers

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_flag, check_key, finite_number, is_concrete, vec3, whole_number
from .._compiled import fused
from .constants import Earth

_FIELDS = {
    "position_sigma": "m, north east down",
    "velocity_sigma": "m/s, north east down",
    "lever_arm": "m, body FRD",
}


def _vec3(name):
    return vec3("Gnss", name, _FIELDS[name])


SIGMA_MAX = {
    "position_sigma": (100.0, "m", "cm → ÷100; mm → ÷1000"),
    "velocity_sigma": (10.0, "m/s", "cm/s → ÷100; mm/s → ÷1000"),
}
"""The largest `Gnss.position_sigma` [m] and `velocity_sigma` [m/s], with the units a value
beyond is typed in: a standalone fix's σ is 1–10 m and 0.05–0.5 m/s (RTK's cm), so 150
(1.5 m in cm) read as 150 m would have the filter all but ignore its fixes."""


_OUTAGES = "((start_s, end_s), …) with 0 <= start < end, finite, in seconds"


def _windows(x):
    """`outages` as a tuple of (start, end) float pairs [s], or a one-line error."""
    try:
        if isinstance(x, str):
            raise TypeError
        pairs = [tuple(w) for w in x]
    except TypeError:
        flat = isinstance(x, (tuple, list)) and len(x) == 2
        fix = f" (one window is written ({tuple(x)!r},))" if flat else ""
        raise ValueError(f"Gnss.outages must be {_OUTAGES}; got {x!r}{fix}") from None
    out = []
    for w in pairs:
        if len(w) != 2:
            raise ValueError(f"Gnss.outages: each window is (start_s, end_s); got {w!r}")
        if not all(isinstance(v, (int, float, np.integer, np.floating)) for v in w) or any(
            isinstance(v, bool) for v in w
        ):
            raise TypeError(f"Gnss.outages: each window is two numbers [s]; got {w!r}")
        a, b = float(w[0]), float(w[1])
        if not (math.isfinite(a) and math.isfinite(b) and 0 <= a < b):
            raise ValueError(
                f"Gnss.outages: each window is (start_s, end_s) with 0 <= start < end, finite, "
                f"in seconds; got {w!r}"
            )
        out.append((a, b))
    return tuple(out)


class Gnss(eqx.Module):
    """A GNSS receiver (module docstring).

    **Fields:** `rate_hz` [Hz]; `position_sigma` (3,) [m, north east down];
    `velocity_sigma` (3,) [m/s, NED], or `use_velocity=False` for position fixes only;
    `lever_arm` (3,) [m, body FRD]; `outages`: ((start, end), …) [s] without fixes, each
    with 0 <= start < end (one window is `((start, end),)`). A concrete σ beyond `SIGMA_MAX`
    (100 m, 10 m/s: in cm or mm) is refused, and a concrete lever arm beyond ±100 m on an
    axis (`hrgjax.plausible.RANGES["gnss_lever_arm_m"]`: a vehicle's size;
    `hrgjax.plausible.relaxed(gnss_lever_arm_m=…)` widens it)."""

    rate_hz: float = eqx.field(static=True, default=1.0)
    position_sigma: jax.Array = eqx.field(
        converter=_vec3("position_sigma"), default=(1.5, 1.5, 3.0)
    )
    velocity_sigma: jax.Array = eqx.field(converter=_vec3("velocity_sigma"), default=0.05)
    lever_arm: jax.Array = eqx.field(converter=_vec3("lever_arm"), default=0.0)
    use_velocity: bool = eqx.field(static=True, default=True)
    outages: tuple = eqx.field(static=True, default=(), converter=_windows)

    def __check_init__(self):
        r = self.rate_hz
        if not (isinstance(r, numbers.Real) and not isinstance(r, bool) and math.isfinite(r)
                and r > 0):  # fmt: skip
            raise ValueError(f"Gnss.rate_hz must be a number > 0 [Hz]; got {r!r}")
        for name in ("position_sigma", "velocity_sigma"):
            v = getattr(self, name)
            if is_concrete(v) and not np.all(np.isfinite(np.asarray(v)) & (np.asarray(v) > 0)):
                raise ValueError(f"Gnss.{name} must be > 0 (a 1σ per NED axis); got {v}")
            high, unit, hint = SIGMA_MAX[name]
            if is_concrete(v) and np.any(np.asarray(v) > high):
                raise ValueError(f"Gnss.{name} = {float(np.max(v)):g} {unit} is beyond the "
                                 f"{high:g} {unit} of a GNSS fix's 1σ — {hint}")  # fmt: skip
        v = self.lever_arm
        if is_concrete(v) and not np.all(np.isfinite(np.asarray(v))):
            raise ValueError(f"Gnss.lever_arm must be finite [m, body FRD]; got {v}")
        if is_concrete(v):  # a vehicle's size: cm or mm typed as m (or 1e6) beyond
            plausible.check("Gnss.lever_arm", v, "gnss_lever_arm_m")
        check_flag("Gnss.use_velocity", self.use_velocity)  # "no" must not switch it on

    def without_outages(self) -> Gnss:
        """The same receiver with no outage windows: what a compiled filter or Monte Carlo
        program needs of it (the outages, static, travel as a mask of the fixes instead, so a
        new outage set compiles nothing)."""
        return Gnss(
            rate_hz=self.rate_hz,
            position_sigma=self.position_sigma,
            velocity_sigma=self.velocity_sigma,
            lever_arm=self.lever_arm,
            use_velocity=self.use_velocity,
        )

    def noise_covariance(self):
        """Diagonal measurement covariance in NED [m², (m/s)²]: (3,) or (6,) with velocity."""
        p = self.position_sigma**2
        return jnp.concatenate([p, self.velocity_sigma**2]) if self.use_velocity else p

    def epochs(self, n_intervals: int, dt: float) -> np.ndarray:
        """IMU epoch indices of the fixes (every 1/`rate_hz` s). **Raises** `ValueError`
        when the IMU interval does not divide the GNSS interval, `dt` is not > 0 or
        `n_intervals` not a whole number >= 0."""
        n_intervals = whole_number("n_intervals", n_intervals, "a whole number >= 0")
        if n_intervals < 0 or finite_number("dt", dt, "s") <= 0:
            raise ValueError(f"Gnss.epochs needs n_intervals >= 0 and dt > 0 [s] (the IMU "
                             f"interval); got n_intervals = {n_intervals}, dt = {dt}")  # fmt: skip
        m = 1.0 / (self.rate_hz * dt)
        if abs(m - round(m)) > 1e-6 or round(m) < 1:
            raise ValueError(
                f"Gnss.rate_hz: the GNSS interval 1/{self.rate_hz} s must be a whole number of "
                f"IMU intervals ({dt} s)"
            )
        return np.arange(int(round(m)), n_intervals + 1, int(round(m)))


class GnssData(eqx.Module):
    """Fixes: `t` (M,) [s]; `index` (M,) the IMU epochs; `lat`, `lon` [rad], `h` [m];
    `v_ned` (M, 3) [m/s]; `valid` (M,) whether a fix exists (outages are False)."""

    t: jax.Array
    index: jax.Array
    lat: jax.Array
    lon: jax.Array
    h: jax.Array
    v_ned: jax.Array
    valid: jax.Array


@fused(static_argnums=0)
def antenna(earth: Earth, lat, lon, h, v_ned, c_bn, w_eb_b, lever_arm):
    """Antenna position (lat, lon, h) and velocity (module docstring) of IMU states."""
    off = c_bn @ lever_arm
    r_m, r_n = earth.radii(lat)
    pos = (
        lat + off[..., 0] / (r_m + h),
        lon + off[..., 1] / ((r_n + h) * jnp.cos(lat)),
        h - off[..., 2],
    )
    return pos, v_ned + c_bn @ jnp.cross(w_eb_b, lever_arm)


@fused(static_argnums=0)
def body_rate_wrt_earth(earth: Earth, lat, c_bn, dtheta, dt):
    """$\\omega_{eb}^b \\approx \\Delta\\theta/\\Delta t - C_n^b\\omega_{ie}^n$ [rad/s]."""
    return dtheta / dt - jnp.swapaxes(c_bn, -1, -2) @ earth.earth_rate(lat)


def measure(truth, gnss: Gnss, key) -> GnssData:
    """GNSS fixes along `truth` (a [`Truth`][hrgjax.ins.motion.Truth]) with noise drawn
    from `key` (module docstring)."""
    check_key("gnss.measure: key", key)
    n = truth.dtheta.shape[0]
    idx = gnss.epochs(n, truth.dt)
    t = np.asarray(idx, float) * truth.dt
    valid = jnp.asarray(truth.gnss)[idx]
    for a, b in gnss.outages:
        valid = valid & jnp.asarray(~((t >= a) & (t <= b)))
    s = truth.states[idx]
    c = s.c_bn
    w = jax.vmap(lambda la, cc, th: body_rate_wrt_earth(truth.earth, la, cc, th, truth.dt))(
        s.lat, c, truth.dtheta[idx - 1]
    )
    (lat, lon, h), v = jax.vmap(
        lambda la, lo, hh, vv, cc, ww: antenna(truth.earth, la, lo, hh, vv, cc, ww, gnss.lever_arm)
    )(s.lat, s.lon, s.h, s.v_ned, c, w)
    kp, kv = jax.random.split(key)
    e = jax.random.normal(kp, (idx.size, 3)) * gnss.position_sigma[None]
    r_m, r_n = truth.earth.radii(lat)
    lat = lat + e[:, 0] / (r_m + h)
    lon = lon + e[:, 1] / ((r_n + h) * jnp.cos(lat))
    h = h - e[:, 2]
    v = v + jax.random.normal(kv, (idx.size, 3)) * gnss.velocity_sigma[None]
    return GnssData(jnp.asarray(t), jnp.asarray(idx), lat, lon, h, v, valid)
