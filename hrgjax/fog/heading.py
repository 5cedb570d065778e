r"""Alignment of a vibration record and the stationary heading error that constant sensor
biases set (seed 003, step 5).

[`align_record`][hrgjax.fog.heading.align_record] runs the coarse + fine alignment of
[`ins.alignment`][hrgjax.ins.alignment] on a record's misalignment-compensated outputs
([`imu_log`][hrgjax.fog.heading.imu_log]); the biases stay in.

A stationary IMU whose gyros drift by ε and whose accelerometers are biased by ∇ (body
frame) reads, on average, $\tilde f^b = C_n^b(-g^n) + \nabla$ and
$\tilde\omega^b = C_n^b\omega_{ie}^n + \varepsilon$. An alignment that treats these means as
bias-free settles where they look like the truth: level from $\tilde f$, north from the
component of $\tilde\omega$ perpendicular to it. That is the TRIAD of the biased means
([`coarse_align`][hrgjax.ins.alignment.coarse_align]), and its heading minus the true one is
[`heading_limit_deg`][hrgjax.fog.heading.heading_limit_deg]. For a level IMU without
accelerometer bias it is exactly
$\delta\psi = -\operatorname{atan2}(\varepsilon_E,\ \omega_{ie}\cos\varphi + \varepsilon_N)$.

PHYSICS.md §12's $\delta\psi = -\varepsilon_E/(\omega_{ie}\cos\varphi) + (\nabla_E/g)\tan\varphi$
is the small-angle form of the same equilibrium for a **level** IMU, first order in each
bias alone. Its relative error is $\approx\delta\psi^2/3$ (0.5 % at 7°) only when also
$\varepsilon_N \ll \omega_{ie}\cos\varphi$: the north drift enters at first order through
$\operatorname{atan2}(\varepsilon_E,\ \omega_{ie}\cos\varphi + \varepsilon_N)$, a relative
$-\varepsilon_N/(\omega_{ie}\cos\varphi)$ (0.94 % for 0.1 °/h north at 45°, where δψ²/3 is
3e-5). At pitch θ the Euler heading error (what this module and
[`align_record`][hrgjax.fog.heading.align_record] report) also carries the tilt error across
the heading times tan θ: $-\tan\theta\,\nabla_\perp/g$ with
$\nabla_\perp = \nabla_E\cos\psi - \nabla_N\sin\psi$ (1 mg north and east, 0.01 °/h east,
pitch 80°, heading 30°: −0.116° against the formula's +0.0034°). It has no bound: 5 °/h east
at 45° gives −26.9° against the exact −25.2°, and at 80° −109.7° against −62.4°.

Near a pole the horizontal Earth rate $\omega_{ie}\cos\varphi$ that north is found from
vanishes, so latitudes beyond
±[`MAX_LAT_DEG`][hrgjax.ins.constants.MAX_LAT_DEG] are refused, as
[`align`][hrgjax.ins.alignment.align] refuses them.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import concrete_value, is_concrete, numeric_problem
from .._compiled import fused
from ..ins import alignment as _al
from ..ins.alignment import coarse_align, euler_deg
from ..ins.constants import MAX_LAT_DEG, WGS84, earth_rate_ned
from ..units import DEG
from .vibration import FogImu, VibrationRecord, to_body


def heading_limit_deg(eps_body, nabla_body, c_bn, lat) -> float | jax.Array:
    """Stationary heading error [°] (estimate − truth, wrapped to ±180°) set by a constant
    body-frame gyro drift `eps_body` [rad/s] and accelerometer bias `nabla_body` [m/s²]. It
    is the heading of the TRIAD of the biased mean specific force and rate (module
    docstring) minus the true heading: the same Euler-heading difference that
    [`align_record`][hrgjax.fog.heading.align_record] reports. For small errors of a level
    IMU it is PHYSICS.md §12's
    $\\delta\\psi = -\\varepsilon_E/(\\omega_{ie}\\cos\\varphi) + (\\nabla_E/g)\\tan\\varphi$
    (NED components), to a relative δψ²/3 (δψ in radians) when ε_N ≪ ω_ie cos φ; ε_N changes
    it at first order, by −ε_N/(ω_ie cos φ) relative, and at pitch θ the Euler heading adds
    −tan θ·(∇_E cos ψ − ∇_N sin ψ)/g (module docstring).

    **Arguments:** `eps_body` (3,) [rad/s]; `nabla_body` (3,) [m/s²]; `c_bn` (3, 3), the
    body-to-NED direction cosine matrix; `lat`, the geodetic latitude φ **in radians**
    (`np.radians(45.0)` for 45°), |φ| ≤ [`MAX_LAT_DEG`][hrgjax.ins.constants.MAX_LAT_DEG].

    **Returns:** the heading error [°]: for concrete inputs a `np.float64` (a `float`, as
    before); traced, a 0-d array: `jit`, `vmap` (over latitude, drift, …) and `grad` (the
    sensitivity ∂δψ/∂ε) run it, compiled once per shape.

    **Raises:** `ValueError` for a wrong shape (`eps_body`, `nabla_body` (3,), `c_bn`
    (3, 3), `lat` one number: `jax.vmap` over several), a concrete `c_bn` that is not a
    rotation (max |CᵀC − I| > [`ROTATION_TOL`][hrgjax.fog.heading.ROTATION_TOL] = 1e-6, or
    det < 0: a scaled, sheared, reflected or zero matrix gave a wrong heading or NaN), a
    latitude beyond ±π/2 (degrees given for radians) or not finite, one within 1° of a pole
    (no north to find), a drift beyond 1e-3 rad/s (≈ 206 °/h: °/h given for rad/s) or a
    bias beyond 1 m/s² (mg given for m/s²); `TypeError` for an argument that is not real
    numbers. Traced values (inside `jit`, `vmap`, `hg.sweep`) are held to the latitude,
    drift and bias rules at run time (`eqx.error_if`: the message without the value); a
    traced `c_bn` is not checked."""
    _check_shapes(eps_body, nabla_body, c_bn, lat)
    value = concrete_value(lat)
    if value is not None:
        if value.dtype.kind not in "iuf":
            raise TypeError(f"lat must be a number, the latitude [rad]; got {type(lat).__name__}")
        bad = ~(np.abs(value) <= np.pi / 2)  # NaN too
        if np.any(bad):
            v = float(value[bad].ravel()[0]) if value.ndim else float(value)
            hint = f" (degrees? give np.radians({v:g}))" if np.isfinite(v) else ""
            raise ValueError(f"lat must be the latitude in radians, |lat| ≤ π/2; got {v:g}{hint}")
        polar = np.abs(value) > MAX_LAT_DEG * DEG
        if np.any(polar):
            v = float(value[polar].ravel()[0]) if value.ndim else float(value)
            raise ValueError(
                f"lat must be within ±{MAX_LAT_DEG:g}° (MAX_LAT_DEG) of the equator; got "
                f"{v:.6g} rad ({v / DEG:.4g}°): the heading is found from the horizontal Earth "
                "rate ω_ie·cos(lat), which vanishes at a pole"
            )
    for name, x, top, unit, hint in (
        ("eps_body", eps_body, 1e-3, "rad/s", "°/h? multiply by hrgjax.units.DEG_PER_H"),
        ("nabla_body", nabla_body, 1.0, "m/s²", "mg? multiply by 9.80665e-3"),
    ):  # fmt: skip
        v = concrete_value(x)
        if v is not None and not np.all(np.abs(v) <= top):  # NaN too
            raise ValueError(
                f"{name} must be a bias in {unit}, |{name}| <= {top:g} (a stationary "
                f"alignment's error); got {np.asarray(v).tolist()} ({hint})"
            )
    as_f = lambda x: jnp.asarray(x, float)  # noqa: E731
    eps_body, nabla_body, c_bn, lat = map(as_f, (eps_body, nabla_body, c_bn, lat))
    out = _traced_checks(_heading_error(eps_body, nabla_body, c_bn, lat), eps_body, nabla_body, lat)
    return np.float64(out) if is_concrete(out) else out


ROTATION_TOL = 1e-6
"""Largest max |CᵀC − I| of a `c_bn` that
[`heading_limit_deg`][hrgjax.fog.heading.heading_limit_deg] takes as a rotation (float32
round-off is ~1e-7; a DCM from Euler angles in float64, 1e-16)."""

_SHAPES = (
    ("eps_body", (3,), "the body-frame gyro drift [rad/s], [x, y, z]"),
    ("nabla_body", (3,), "the body-frame accelerometer bias [m/s²], [x, y, z]"),
    ("c_bn", (3, 3), "the body-to-NED direction cosine matrix"),
    ("lat", (), "one latitude [rad] (several: jax.vmap over them)"),
)


def _check_shapes(eps_body, nabla_body, c_bn, lat) -> None:
    """One line for an argument of `heading_limit_deg` that is not real numbers or has the
    wrong shape (they surfaced as JAX broadcasting errors), and for a concrete `c_bn` that
    is not a rotation."""
    for (name, shape, form), x in zip(_SHAPES, (eps_body, nabla_body, c_bn, lat), strict=True):
        problem = numeric_problem(x)
        if problem is not None:
            raise TypeError(f"{name} must be {form}; got {problem}")
        if jnp.shape(x) != shape:
            raise ValueError(f"{name} must have shape {shape}, {form}; got {jnp.shape(x)}")
    c = concrete_value(c_bn)
    if c is None:
        return
    c = np.asarray(c, float)
    with np.errstate(invalid="ignore"):  # NaN: refused below, as not a rotation
        off = float(np.max(np.abs(c.T @ c - np.eye(3))))
        det = float(np.linalg.det(c))
    if not (off <= ROTATION_TOL and det > 0):  # NaN too
        raise ValueError(
            f"c_bn must be a rotation matrix, the body-to-NED direction cosines (CᵀC = I within "
            f"{ROTATION_TOL:g}, det = +1); got max|CᵀC − I| = {off:.3g}, det = {det:.4g} (a "
            "scaled, sheared or reflected matrix: build it with hrgjax.ins.trajectory.euler_to_dcm)"
        )


_TRACED_RULES = (
    "lat must be the latitude in radians, finite and |lat| ≤ π/2 (degrees? give np.radians(…))",
    f"lat must be within ±{MAX_LAT_DEG:g}° (MAX_LAT_DEG) of the equator: the heading is found "
    "from the horizontal Earth rate ω_ie·cos(lat), which vanishes at a pole",
    "eps_body must be a bias in rad/s, finite and |eps_body| <= 0.001 (a stationary alignment's "
    "error; °/h? multiply by hrgjax.units.DEG_PER_H)",
    "nabla_body must be a bias in m/s², finite and |nabla_body| <= 1 (a stationary alignment's "
    "error; mg? multiply by 9.80665e-3)",
)


def _traced_checks(out, eps_b, nab_b, lat):
    """`out` with the eager checks of the traced inputs (inside `jit`, `vmap`, `hg.sweep`) held
    at run time by one `eqx.branched_error_if` (the first rule broken raises its one line);
    concrete inputs were checked eagerly and add nothing."""
    traced = [concrete_value(x) is None for x in (lat, lat, eps_b, nab_b)]
    if not any(traced):
        return out
    bad = (
        ~(jnp.abs(lat) <= jnp.pi / 2),  # NaN too
        jnp.abs(lat) > MAX_LAT_DEG * DEG,
        ~jnp.all(jnp.abs(eps_b) <= 1e-3),
        ~jnp.all(jnp.abs(nab_b) <= 1.0),
    )
    bad = jnp.stack(
        [jnp.any(b) if t else jnp.asarray(False) for b, t in zip(bad, traced, strict=True)]
    )
    return eqx.branched_error_if(out, jnp.any(bad), jnp.argmax(bad), _TRACED_RULES)


@fused
def _heading_error(eps_b, nab_b, c_bn, lat):
    """Heading of the TRIAD of the biased stationary means minus the true heading [°]."""
    f_b = c_bn.T @ -WGS84.gravity_ned(lat, 0.0) + nab_b
    w_b = c_bn.T @ earth_rate_ned(lat) + eps_b
    d = euler_deg(coarse_align(f_b, w_b, lat))[0] - euler_deg(c_bn)[0]
    return jnp.mod(d + 180.0, 360.0) - 180.0


def imu_log(imu: FogImu, record: VibrationRecord, gyro=None) -> _al.ImuLog:
    """The record as an [`ImuLog`][hrgjax.ins.imu_log.ImuLog] (body-frame increments):
    installation misalignment and scale compensated by the triad models' linear part (the
    patent's step 2); biases stay in (the alignment's business). `gyro` replaces the raw
    gyro output (e.g. the vibration-compensated one)."""
    g = record.gyro if gyro is None else jnp.asarray(gyro)
    dt = 1.0 / record.fs
    return _al.ImuLog(
        record.t + dt, to_body(imu.gyro, g) * dt, to_body(imu.accel, record.accel) * dt,
        record.lat,
    )  # fmt: skip


def align_record(imu: FogImu, record: VibrationRecord, gyro=None, *, coarse_s=60.0, **fine_kw):
    """Coarse + fine alignment ([`align`][hrgjax.ins.alignment.align]) of the record (raw, or
    with `gyro` replacing its gyro output). **Returns** `(result, errors)`: the
    [`AlignmentResult`][hrgjax.ins.alignment.AlignmentResult] and the errors
    (heading, pitch, roll) [°] against the true attitude, heading wrapped to ±180°."""
    log = imu_log(imu, record, gyro)
    fine_kw.setdefault("velocity_noise", 0.05)
    res = _al.align(log, coarse_s=coarse_s, **fine_kw)
    truth = np.asarray(_al.euler_deg(record.c_bn))
    est = np.array([res.heading_deg, res.pitch_deg, res.roll_deg])
    err = est - truth
    err[0] = (err[0] + 180.0) % 360.0 - 180.0
    return res, err


__all__ = ["imu_log", "align_record", "heading_limit_deg", "ROTATION_TOL"]
