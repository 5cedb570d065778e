r"""WGS-84 constants, normal gravity, radii of curvature and Earth rate (PHYSICS.md §12).

Navigation frame: NED (north, east, down). Latitude `lat` and longitude in radians, height
`h` in metres above the ellipsoid. Every function is plain `jax.numpy` (jit / vmap / grad);
a concrete `lat` beyond ±π/2 (degrees given for radians) or a concrete height `h` outside
`HEIGHT_RANGE_M` is refused in one line, a traced one is not checked (no cost inside `jit`:
the mechanization, the filter and the trajectories check their heights where they are
concrete).
"""

from __future__ import annotations

import functools
import inspect
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._compiled import fused

A = 6_378_137.0
"""WGS-84 semi-major axis [m]."""
FLATTENING = 1.0 / 298.257223563
"""WGS-84 flattening."""
B = A * (1.0 - FLATTENING)
"""WGS-84 semi-minor axis [m]."""
E2 = FLATTENING * (2.0 - FLATTENING)
"""First eccentricity squared (6.69437999014e-3)."""
OMEGA_IE = 7.292115e-5
"""Earth rotation rate [rad/s] (15.04107 °/h)."""
GAMMA_E = 9.7803253359
"""Normal gravity at the equator [m/s²]."""
GAMMA_P = 9.8321849378
"""Normal gravity at the poles [m/s²]."""
GM = 3.986004418e14
"""Earth's gravitational constant [m³/s²]."""
K_SOMIGLIANA = B * GAMMA_P / (A * GAMMA_E) - 1.0
"""Somigliana's constant k = bγ_p/(aγ_e) − 1."""
M_GRAVITY = OMEGA_IE**2 * A**2 * B / GM
"""m = ω²a²b/GM of the free-air height correction."""
G0 = 9.80665
"""Standard gravity [m/s²] (for the classical Schuler figures)."""
SCHULER_PERIOD = 2.0 * math.pi * math.sqrt(A / G0)
"""Schuler period 2π√(a/g) [s] (84.45 min)."""

MAX_LAT_DEG = 89.0
"""Largest |latitude| [°] a motion, a trajectory or an alignment accepts: the NED frame is
singular at the poles (the longitude rate v_E / (R cos φ) is infinite there, and
gyrocompassing finds north from the horizontal Earth rate ω_ie cos φ, which vanishes)."""


HEIGHT_RANGE_M = (-1e4, 1e5)
"""Heights [m above the ellipsoid] (bounds excluded) that a motion, a trajectory (built or by
hand) and the initial state of the mechanization and the filter take: a height below −10 km
is below the deepest ocean floor, and above 100 km normal gravity's free-air series and an
aircraft's navigation equations no longer hold (−7e6 m, a radius given as a height, ran and
returned numbers before; gravity there reads 66.8 m/s²). The functions and `Earth` methods
below that take `h` refuse a concrete one outside it too."""


def check_heights(name: str, h) -> None:
    """A one-line `ValueError` naming `name` if a concrete `h` [m] (any shape) lies outside
    [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M]; a traced one is not checked."""
    if isinstance(h, jax.core.Tracer):
        return
    try:
        a = np.asarray(h, float)
    except Exception:  # a value JAX keeps abstract: checked where it is concrete
        return
    low, high = HEIGHT_RANGE_M
    bad = ~((a > low) & (a < high))  # NaN counts as outside
    if np.any(bad):
        i = tuple(int(k) for k in np.argwhere(bad)[0])
        at = f" at index {i}" if a.ndim else ""
        raise ValueError(f"{name} must be a height in metres above the ellipsoid in "
                         f"({low:g}, {high:g}); got {a[i]:g}{at}")  # fmt: skip


def refuse_over_pole(where: str, lat, step_s: float) -> None:
    """A one-line `RuntimeError` if a computed latitude history `lat` [rad] (epochs `step_s`
    [s] apart) passes ±π/2: the NED mechanization cannot fly over a pole (its latitude runs
    on past 90°: 300 m/s north from 89.99° ended at 90.15°, finite and unrefused)."""
    a = np.abs(np.asarray(lat, float))
    if np.any(over := a > np.pi / 2):
        k = int(np.argmax(over))
        raise RuntimeError(
            f"{where}: the latitude passes ±90° at epoch {k} (t = {k * step_s:g} s, "
            f"{np.degrees(a[k]):.6g}°): the NED navigation frame cannot fly over a pole"
        )


LAT_TOLERANCE = 1e-6
"""Margin [rad] beyond ±π/2 that `check_latitude_radians` takes: a pole rounded through
float32 (`float(np.float32(np.pi / 2))` = 1.5707964, 4.4e-8 beyond) is a latitude in
radians. A latitude in degrees is refused from 1.570797° on; below it the two units cannot
be told apart."""

_LAT_LIMIT = math.pi / 2 + LAT_TOLERANCE


def check_latitude_radians(name: str, lat) -> None:
    """A one-line `ValueError` naming `name` if a concrete `lat` [rad] (any shape) is beyond
    ±π/2 (+ `LAT_TOLERANCE`) anywhere: a latitude in degrees. Traced values are not
    checked."""
    if isinstance(lat, float | int | np.integer | np.floating):  # eager scalars: no array
        if not abs(lat) > _LAT_LIMIT:
            return
        a = np.asarray(float(lat))
    elif isinstance(lat, jax.core.Tracer):
        return
    else:
        try:
            a = np.asarray(lat, float)
        except Exception:  # a value JAX keeps abstract: checked where it is concrete
            return
    bad = np.abs(a) > _LAT_LIMIT
    if np.any(bad):
        x = float(a[bad].flat[0])
        raise ValueError(
            f"{name} = {x:g} rad is beyond ±π/2: the latitude is in radians here (degrees? "
            f"np.deg2rad({x:g}) = {np.deg2rad(x):.6g})"
        )


def _check_height(name: str, h) -> None:
    """`check_heights` with a fast path for an eager Python or NumPy scalar (no array)."""
    if isinstance(h, float | int | np.integer | np.floating):
        if HEIGHT_RANGE_M[0] < h < HEIGHT_RANGE_M[1]:
            return
    check_heights(name, h)


def _lat_checked(fn, at: int = 0):
    """`fn` (`lat` its positional argument `at`, or `lat=`; a height `h`, if it takes one,
    its argument `at + 1` or `h=`) with a concrete `lat` checked by `check_latitude_radians`
    and a concrete `h` by `check_heights` before the call; inside a trace each check is one
    `isinstance` at trace time, nothing in the compiled program."""
    takes_h = "h" in inspect.signature(fn).parameters

    @functools.wraps(fn)
    def checked(*args, **kwargs):
        lat = kwargs.get("lat", args[at] if len(args) > at else None)
        if lat is not None and not isinstance(lat, jax.core.Tracer):
            check_latitude_radians(f"{fn.__qualname__}: lat", lat)
        if takes_h:
            h = kwargs.get("h", args[at + 1] if len(args) > at + 1 else None)
            if h is not None and not isinstance(h, jax.core.Tracer):
                _check_height(f"{fn.__qualname__}: h", h)
        return fn(*args, **kwargs)

    return checked


@_lat_checked
@fused
def gravity(lat, h=0.0):
    r"""Normal gravity magnitude γ(φ, h) [m/s²] at latitude `lat` = φ [rad] and height `h` [m]:
    Somigliana's closed form on the ellipsoid,

    $$\gamma_0 = \gamma_e\frac{1 + k\sin^2\varphi}{\sqrt{1 - e^2\sin^2\varphi}},$$

    with the second-order free-air correction
    $\gamma = \gamma_0\,[1 - \tfrac{2}{a}(1 + f + m - 2f\sin^2\varphi)h + \tfrac{3}{a^2}h^2]$
    (NIMA TR8350.2 eq. 4-3). `gravity(np.radians(45.0))` = γ(45°, 0) = 9.806197769 m/s².

    **Raises:** `ValueError` for a concrete `lat` beyond ±π/2 (degrees given for radians) or
    a concrete `h` outside [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M]
    (`gravity(0.5, -7e6)`, a radius given as a height, read 66.8 m/s²)."""
    s2 = jnp.sin(lat) ** 2
    g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / jnp.sqrt(1.0 - E2 * s2)
    corr = 1.0 - 2.0 / A * (1.0 + FLATTENING + M_GRAVITY - 2.0 * FLATTENING * s2) * h
    return g0 * (corr + 3.0 / A**2 * h**2)


@_lat_checked
@fused
def radii(lat):
    r"""Meridian and prime-vertical radii of curvature $(R_M, R_N)$ [m] at latitude `lat` [rad]:
    $R_N = a/\sqrt{1-e^2\sin^2\varphi}$, $R_M = R_N(1-e^2)/(1-e^2\sin^2\varphi)$."""
    w = 1.0 - E2 * jnp.sin(lat) ** 2
    r_n = A / jnp.sqrt(w)
    return r_n * (1.0 - E2) / w, r_n


@_lat_checked
@fused
def earth_rate_ned(lat):
    r"""Earth rate in NED, $\omega_{ie}^n = \omega_{ie}(\cos\varphi, 0, -\sin\varphi)$ [rad/s],
    at latitude `lat` = φ [rad]."""
    return OMEGA_IE * jnp.stack([jnp.cos(lat), jnp.zeros_like(lat), -jnp.sin(lat)], axis=-1)


@_lat_checked
@fused
def transport_rate_ned(lat, h, v_ned):
    r"""Transport rate $\omega_{en}^n = (v_E/(R_N+h), -v_N/(R_M+h), -v_E\tan\varphi/(R_N+h))$
    [rad/s] at latitude `lat` = φ [rad] and height `h` [m] for velocity `v_ned` [m/s] (shape
    (..., 3)), on WGS-84."""
    return WGS84.transport_rate(lat, h, v_ned)


@_lat_checked
@fused
def gravity_ned(lat, h=0.0):
    """Normal gravity vector in NED, (0, 0, γ) [m/s²] at latitude `lat` [rad] and height `h`
    [m] (plumb-line gravity, centrifugal included)."""
    return WGS84.gravity_ned(lat, h)


def _number(name, v):
    """A static field's value as a Python float (None kept), or an error naming the field."""
    if v is None and name != "rate":
        return None
    try:
        return float(v)
    except (TypeError, ValueError):
        raise ValueError(f"Earth.{name} must be a number; got {v!r}") from None


class Earth(eqx.Module):
    """The Earth model of the navigation equations: the WGS-84 ellipsoid with Somigliana
    gravity (default), or a sphere of radius `radius` with gravity `g`·(R/(R+h))² — the
    textbook model behind the classical Schuler figures of PHYSICS.md §12.

    **Arguments:** `radius` [m] and `g` [m/s²], both `None` for WGS-84 or both set;
    `rate`: rotation rate [rad/s] (default ω_ie; 0 gives the classical single-channel
    models with Earth-rate coupling removed). Each is refused outside its range in
    `hrgjax.plausible.RANGES` (`earth_radius_m`, `gravity_mps2`, `earth_rate_radps`): a
    radius in km, g in cm/s² or a rate in °/h is named so. They are static (they choose the
    model), so each new value compiles the navigation programs again."""

    radius: float | None = eqx.field(
        static=True, default=None, converter=functools.partial(_number, "radius")
    )
    g: float | None = eqx.field(
        static=True, default=None, converter=functools.partial(_number, "g")
    )
    rate: float = eqx.field(
        static=True, default=OMEGA_IE, converter=functools.partial(_number, "rate")
    )

    def __check_init__(self):
        if (self.radius is None) != (self.g is None):
            raise ValueError("Earth: give both radius and g (a sphere) or neither (WGS-84)")
        for name in ("radius", "g"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v > 0):
                raise ValueError(f"Earth.{name} must be a positive number; got {v}")
        if not (math.isfinite(self.rate) and self.rate >= 0):
            raise ValueError(f"Earth.rate must be >= 0 rad/s; got {self.rate}")
        for name, quantity in (("radius", "earth_radius_m"), ("g", "gravity_mps2"),
                               ("rate", "earth_rate_radps")):  # fmt: skip
            if getattr(self, name) is not None:
                plausible.check(f"Earth.{name}", getattr(self, name), quantity)

    @functools.partial(_lat_checked, at=1)
    @fused(static_argnums=0)
    def earth_rate(self, lat):
        """Earth rate in NED [rad/s] at latitude `lat` [rad] (see
        [`earth_rate_ned`][hrgjax.ins.constants.earth_rate_ned])."""
        return earth_rate_ned(lat) * (self.rate / OMEGA_IE)

    @functools.partial(_lat_checked, at=1)
    @fused(static_argnums=0)
    def radii(self, lat):
        """$(R_M, R_N)$ [m] at latitude `lat` [rad] (equal on the sphere)."""
        if self.radius is None:
            return radii(lat)
        r = jnp.full_like(jnp.asarray(lat, float), self.radius)
        return r, r

    @functools.partial(_lat_checked, at=1)
    @fused(static_argnums=0)
    def gravity(self, lat, h=0.0):
        """Gravity magnitude [m/s²] at latitude `lat` [rad] and height `h` [m]."""
        if self.radius is None:
            return gravity(lat, h)
        return self.g * (self.radius / (self.radius + h)) ** 2 + 0.0 * lat

    @functools.partial(_lat_checked, at=1)
    @fused(static_argnums=0)
    def gravity_ned(self, lat, h=0.0):
        """Gravity vector (0, 0, γ) in NED [m/s²] at latitude `lat` [rad] and height `h` [m]."""
        g = self.gravity(lat, h)
        z = jnp.zeros_like(g)
        return jnp.stack([z, z, g], axis=-1)

    @functools.partial(_lat_checked, at=1)
    @fused(static_argnums=0)
    def transport_rate(self, lat, h, v_ned):
        r"""$\omega_{en}^n$ [rad/s] at latitude `lat` [rad], height `h` [m], velocity `v_ned`
        [m/s] (see [`transport_rate_ned`][hrgjax.ins.constants.transport_rate_ned])."""
        r_m, r_n = self.radii(lat)
        v_n, v_e = v_ned[..., 0], v_ned[..., 1]
        return jnp.stack(
            [v_e / (r_n + h), -v_n / (r_m + h), -v_e * jnp.tan(lat) / (r_n + h)], axis=-1
        )

    @functools.partial(_lat_checked, at=1)
    @fused(static_argnums=0)
    def position_rate(self, lat, h, v_ned):
        r"""$(\dot\varphi, \dot\lambda, \dot h) = (v_N/(R_M+h),\; v_E/((R_N+h)\cos\varphi),\; -v_D)$
        [rad/s, rad/s, m/s] at latitude `lat` = φ [rad], height `h` [m], velocity `v_ned` [m/s]."""
        r_m, r_n = self.radii(lat)
        return jnp.stack(
            [
                v_ned[..., 0] / (r_m + h),
                v_ned[..., 1] / ((r_n + h) * jnp.cos(lat)),
                -v_ned[..., 2],
            ],
            axis=-1,
        )


WGS84 = Earth()
"""The WGS-84 ellipsoid with Somigliana gravity."""
SPHERE = Earth(radius=A, g=G0)
"""A sphere of radius a with g = 9.80665 m/s² (the classical Schuler figures)."""
