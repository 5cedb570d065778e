r"""Stationary initial alignment of a strapdown IMU: coarse (analytic levelling +
gyrocompassing) then fine (Kalman filter on zero velocity). The record and the PSINS loader
are [`imu_log`][hrgjax.ins.imu_log] (`ImuLog`, `load_psins`, `PSINS_FIELDS` import from here
too).

Frames: navigation NED, body FRD (x forward, y right, z down); heading clockwise from north.
**Coarse** ([`coarse_align`][hrgjax.ins.alignment.coarse_align]): the mean specific force
and angular rate over the first `coarse_s` seconds against their NED values
$f^n = (0, 0, -g)$, $\omega_{ie}^n = \omega_{ie}(\cos\varphi, 0, -\sin\varphi)$, by TRIAD.

**Fine** ([`fine_align`][hrgjax.ins.fine_alignment.fine_align], its own module, importable
from here too), on the data after the coarse span: a 12-state Kalman filter on zero velocity,
one compiled program for every record length in a power-of-two bucket.
East gyro bias and level accelerometer biases are unobservable, so the attitude converges to
the analytic limits of PHYSICS.md §12 ($\phi_E = -\nabla_N/g$, $\phi_N = \nabla_E/g$,
$\phi_D = \varepsilon_E/(\omega_{ie}\cos\varphi) - (\nabla_E/g)\tan\varphi$).

**What the heading σ rests on.** The east gyro bias is not measured, so the heading's 1σ
ends at $\sigma_\varepsilon/(\omega_{ie}\cos\varphi)$ for the *assumed* gyro-bias σ
`gyro_bias_std` (0.05 °/h by default): a property of the assumption, not of the data. The
coarse heading's error comes from the same bias, so `align`'s prior holds that correlation
(`start_bias_jacobian`, counted once) and the coarse means' white noise, whose heading part
$(\sigma_{ARW}/\sqrt{T})/(\omega_{ie}\cos\varphi)$ grows towards the pole
([`coarse_error_model`][hrgjax.ins.alignment.coarse_error_model]); the fine data are
independent of it (run over the coarse span too, they counted that noise twice: z-RMS
1.14–1.20 for ARW 0.05 °/√h at 88°). A vehicle that sways makes the coarse means err beyond
that white noise, so the prior takes the larger of it and the span's own scatter
([`coarse_scatter`][hrgjax.ins.alignment.coarse_scatter]). The σ is a linearised one: it
covers while the heading error is small (`AlignmentWarning`) and the zero-velocity noise is
white as `velocity_noise` assumes (`AlignmentResult.sway` tests the innovations' whiteness,
not the heading; disjoint windows' spread tests that).
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaincc

from .._checks import check_finite_host, check_number, host_value
from .._compiled import device, fused
from .._x64 import require_x64
from ..units import DEG, DEG_PER_H
from .constants import OMEGA_IE, WGS84, check_latitude_radians, earth_rate_ned
from .fine_alignment import (
    FINE_DEFAULTS,
    check_fine_options,
    check_gyrocompass_latitude,
    check_log,
    check_step,
    euler_std_deg,
    fine_run,
)
from .fine_alignment import euler_deg as euler_deg
from .fine_alignment import fine_align as fine_align
from .imu_log import PSINS_FIELDS as PSINS_FIELDS
from .imu_log import ImuLog as ImuLog
from .imu_log import load_psins as load_psins

_LOG_FIELDS = {
    "interval": "the log's time stamps ImuLog.t [s]",
    "gyro": "the gyro increments ImuLog.dtheta [rad]",
    "accel": "the velocity increments ImuLog.dvel [m/s]",
}

EARTH_RATE_RATIO = (0.5, 2.0)
"""Range of |mean angular rate| / ω_ie over the coarse span that `align` accepts. At rest a
gyro reads the Earth's rate (15.04 °/h) plus its bias; gyrocompassing with a bias of half the
Earth's rate is already tens of degrees off, so a wider spread is no gyro `align` serves; a
parked vehicle's sway adds apparent rate (the PSINS log: 0.84–1.50 ω_ie over its 60-s
windows). Unit errors land far outside: ×10 or ÷10 in an increment unit, ×3600 (°/h for
°/s), ×57.3 (degrees for radians). Read over `RATE_SPAN_S`."""

RATE_SPAN_S = 60.0
"""The span [s] the mean angular rate is read over for `EARTH_RATE_RATIO`: the coarse span
or this, whichever is longer (the whole record where shorter): a parked vehicle's sway is tens
of °/h over a few seconds (the PSINS log: 55 °/h over its first 10 s), a short span aligns."""


def _check_coarse(where: str, coarse_name: str, coarse_s, dt: float) -> None:
    """Refuse, in one line prefixed by `where`, a `coarse_s` [s] that is not a finite number
    > 0 or spans no sample: the span is `coarse_s / dt` samples rounded to even, so half a
    sample interval `dt` [s] is none."""
    check_number(f"{where}{coarse_name}", coarse_s, "s")
    if not (math.isfinite(coarse_s) and coarse_s > 0):
        raise ValueError(f"{where}{coarse_name} must be a finite number > 0 s; got {coarse_s}")
    if round(coarse_s / dt) < 1:
        raise ValueError(f"{where}{coarse_name} must be over half the sample interval "
                         f"({dt:.4g} s): the coarse span needs a sample; got "
                         f"{coarse_s!r} s")  # fmt: skip


def check_stationary(log: ImuLog, coarse_s: float = 60.0, *, fields: dict | None = None,
                     coarse_name: str = "coarse_s", where: str = "") -> None:  # fmt: skip
    """Refuse, before any work, a log that cannot be a stationary record of the first
    `coarse_s` seconds: one shorter than `coarse_s`, a mean specific force beyond 5 % of g,
    or a mean angular rate (over [`RATE_SPAN_S`][hrgjax.ins.alignment.RATE_SPAN_S] or the
    coarse span) outside [`EARTH_RATE_RATIO`][hrgjax.ins.alignment.EARTH_RATE_RATIO] × the
    Earth's rate — the signatures of a unit error in the time stamps, accelerometer or
    gyro increments. `fields` names where each comes from (`PSINS_FIELDS` for `load_psins`;
    default: the `ImuLog` fields), `coarse_name` the span's option, `where` a prefix (a file).

    **Raises:** `ValueError`, one line, naming the quantity, its source and what was expected."""
    fields = {**_LOG_FIELDS, **(fields or {})}
    _check_coarse(where or "check_stationary: ", coarse_name, coarse_s, log.dt)
    dt, size = log.dt, int(log.t.shape[0])
    n = int(round(coarse_s / dt))
    if n > size:
        raise ValueError(
            f"{where}the record spans {size * dt:.4g} s ({size} samples at {dt * 1e3:.4g} ms), "
            f"shorter than {coarse_name} = {coarse_s:g} s: check {fields['interval']}"
        )
    f = float(np.linalg.norm(np.asarray(log.dvel)[:n].sum(0) / (n * dt)))  # host: no program
    g = float(WGS84.gravity(log.lat, log.h))
    if abs(f - g) > 0.05 * g:
        raise ValueError(
            f"{where}mean specific force {f:.4g} m/s² over the first {coarse_s:g} s is not g "
            f"({g:.4g}): is the IMU stationary, are {fields['accel']} and {fields['interval']} "
            "right?"
        )
    m = min(size, max(n, int(round(RATE_SPAN_S / dt))))
    w = float(np.linalg.norm(np.asarray(log.dtheta)[:m].sum(0) / (m * dt)))
    low, high = EARTH_RATE_RATIO
    if not low * OMEGA_IE <= w <= high * OMEGA_IE:
        raise ValueError(
            f"{where}mean angular rate {w / DEG_PER_H:.4g} °/h over the first {m * dt:g} s is "
            f"not the Earth's rate ({OMEGA_IE / DEG_PER_H:.4g} °/h; alignment takes "
            f"{low:g}–{high:g} × it): is the IMU stationary, is {fields['gyro']} right?"
        )


def coarse_align(f_b, w_b, lat):
    """Body-to-NED matrix from the mean specific force `f_b` [m/s²] and angular rate `w_b`
    [rad/s] of a stationary IMU at latitude `lat` [rad] (TRIAD). Refused in one line: `f_b`
    or `w_b` not (3,); a concrete NaN or inf, or a latitude beyond ±π/2 (degrees)."""
    for name, v in (("f_b", f_b), ("w_b", w_b)):
        if np.shape(v) != (3,):
            raise ValueError(f"{name} must be (3,), the body-frame mean [x, y, z]; got shape "
                             f"{np.shape(v)}")  # fmt: skip
        check_finite_host(name, v)
    check_finite_host("lat", lat)
    check_latitude_radians("coarse_align: lat", lat)
    return _coarse_align(f_b, w_b, lat)


@fused
def _coarse_align(f_b, w_b, lat):
    """`coarse_align` without its checks (fused: one compiled program)."""
    f_n = jnp.array([0.0, 0.0, -1.0])
    w_n = earth_rate_ned(lat)

    def triad(f, w):
        a = f / jnp.linalg.norm(f)
        b = jnp.cross(f, w)
        b = b / jnp.linalg.norm(b)
        return jnp.stack([a, b, jnp.cross(a, b)], axis=-1)

    return triad(f_n, w_n) @ triad(f_b, w_b).T


@fused
def coarse_bias_jacobian(f_b, w_b, lat):
    """(3, 6) ∂φ/∂(gyro bias [rad/s], accelerometer bias [m/s²]), body frame, of the attitude
    error φ (C_true = (I + [φ×]) Ĉ) of [`coarse_align`][hrgjax.ins.alignment.coarse_align]'s
    Ĉ for means `f_b`, `w_b` at latitude `lat` [rad] holding constant sensor biases (plus
    noise and sway): [`fine_align`][hrgjax.ins.fine_alignment.fine_align]'s
    `start_bias_jacobian`."""
    c = coarse_align(f_b, w_b, lat)

    def phi(b):
        m = coarse_align(f_b - b[3:], w_b - b[:3], lat) @ c.T  # C_true Ĉᵀ = I + [φ×]
        return 0.5 * jnp.stack([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])

    return jax.jacfwd(phi)(jnp.zeros(6))


END_HEADING_STD_DEG = 15.0
"""Heading σ [°] at the fine stage's end beyond which `align` warns (`AlignmentWarning`): the
bias-limited σ_ε/(ω_ie cos φ), where an east gyro bias as large as ω_ie cos φ is within reach
and the error atan2(ε_E, ω_ie cos φ + ε_N) heavy-tailed (z-RMS 1.04, 93.9 % within ±1.96σ at
15°; 1.10, 93.0 % at 20°; 1.17, 91.9 % at 25°: `benchmarks/coverage_alignment.py`)."""

START_HEADING_STD_DEG = 20.0
"""Heading σ [°] at the fine stage's start beyond which `align` warns (`AlignmentWarning`).
The grade's white noise's: the coarse heading's tail reaches 140–180°, where the fine filter
does not recover (z-RMS 1.15 at 26°, 1.35 at 43°; 1.02–1.03 at 15–18°, 300 draws at 88°).
The span's own scatter's (over twice that), a conservative bound: a sway note."""

NO_HEADING_STD_DEG = 90.0
"""Start heading σ [°] from which `align`'s warning says the coarse span holds no heading
information: a linearised σ this large describes nothing (|error| ≤ 180°)."""


class AlignmentWarning(UserWarning):
    """`align`'s heading σ is not small, so the linearised σ may understate the error (module
    docstring), or (a sway note) the coarse span sways and its σ is its own scatter's bound.
    `warnings.simplefilter("ignore", AlignmentWarning)` silences it."""


@fused
def coarse_error_model(c0, lat, h, span_s, arw, vrw):
    """The coarse attitude `c0`'s error model for
    [`fine_align`][hrgjax.ins.fine_alignment.fine_align]'s prior: `(A (3, 6), var (3,))`, A = ∂φ/∂(gyro bias [rad/s], accelerometer bias [m/s²])
    (body frame, [`coarse_bias_jacobian`][hrgjax.ins.alignment.coarse_bias_jacobian]) taken
    at the means a stationary IMU with attitude `c0` reads at latitude `lat` [rad], height
    `h` [m] — the point the fine filter's model is linearised at, so the coarse and fine
    headings share one bias dependence — and `var` [rad²] the variances of φ (north, east,
    down) that the white noise (`arw` [rad/√s], `vrw` [m/s/√s]) of means over `span_s` [s]
    leaves: the coarse heading's is (arw/√span_s)/(ω_ie cos lat) (8.45° for 0.01 °/√h over
    60 s at 88°)."""
    g = jnp.linalg.norm(WGS84.gravity_ned(jnp.asarray(lat), jnp.asarray(h)))
    jac = coarse_bias_jacobian(c0.T @ jnp.array([0.0, 0.0, -g]), c0.T @ earth_rate_ned(lat), lat)
    white = jnp.concatenate([jnp.full(3, arw**2), jnp.full(3, vrw**2)]) / span_s
    return jac, jnp.sum(jac**2 * white[None, :], axis=1)


COARSE_PARTS = 10
"""The number of equal parts [`coarse_scatter`][hrgjax.ins.alignment.coarse_scatter] splits
the coarse span into (9 degrees of freedom: its σ scatters by ±24 % under white noise)."""


def coarse_scatter(dtheta, dvel, dt, parts: int = COARSE_PARTS):
    r"""(6, 6) covariance of the coarse means' error (gyro [rad/s], then accelerometer
    [m/s²]) from the span's own increments `dtheta`, `dvel` (n, 3) [rad, m/s] at interval `dt`
    [s]: the scatter over `parts` of the means of `parts` equal parts (n mod parts samples left
    out; `ValueError` unless 2 ≤ parts ≤ n): the span's mean's variance for independent parts.

    White noise: unbiased ($\mathrm{arw}^2/T$, the model of
    [`coarse_error_model`][hrgjax.ins.alignment.coarse_error_model]). A sway whose angle is
    bounded errs the span's mean by its angle change over T, each part's by parts/T (and
    neighbours share an end): ≈ √(parts + 1) = 3.3× in σ where the angle decorrelates within
    a part; more for sway periodic near the span (6.6× at 0.95 or 1.05 spans; at whole or
    half spans the span's error is 0); under-covers periods beyond about 1.5 spans (0.73× at
    1.5, 0.40× at 2, 0.23× at 3), and a disturbance slower still is a bias to it: the
    assumed grade's (`gyro_bias_std`). On the PSINS log's 60-s windows the heading σ it
    gives is 1.3× the error (z-RMS 0.75)."""
    if (
        len(np.shape(dtheta)) != 2
        or np.shape(dtheta)[1:] != (3,)
        or np.shape(dvel) != np.shape(dtheta)
    ):
        raise ValueError(f"dtheta and dvel must both be (n, 3) increments [rad, m/s]; got "
                         f"{np.shape(dtheta)} and {np.shape(dvel)}")  # fmt: skip
    v = host_value(dt)
    if v is not None and not (v.shape == () and np.isfinite(v) and v > 0):
        raise ValueError(f"dt must be the increments' interval, one number > 0 [s]; got {dt}")
    if not 2 <= parts <= dtheta.shape[0]:
        raise ValueError(f"coarse_scatter needs 2 <= parts <= samples; got parts={parts} for "
                         f"{dtheta.shape[0]} samples")  # fmt: skip
    return _coarse_scatter(dtheta, dvel, dt, parts)


@fused(static_argnames=("parts",))
def _coarse_scatter(dtheta, dvel, dt, parts):
    """`coarse_scatter` without its checks (fused: one compiled program)."""
    n = (dtheta.shape[0] // parts) * parts
    x = jnp.concatenate([dtheta[:n], dvel[:n]], axis=1).reshape(parts, n // parts, 6)
    means = x.sum(1) / ((n // parts) * dt)
    d = means - means.mean(0, keepdims=True)
    return d.T @ d / ((parts - 1) * parts)


SWAY_BLOCKS = 10
"""`AlignmentResult.sway`'s `slow_ratio` averages the normalised innovations over blocks of
K // this many of the K fine steps: m = 10 blocks for K ≥ 100, 10–14 below, K for K < 20."""

SWAY_FALSE_ALARM = 0.05
"""`AlignmentResult.sway`'s `not_white` rate under the filter's own model: north or east
beyond its χ²_m/m quantile at 1 − √0.95 = 2.53 % each (m blocks; 2.05 for m = 10)."""


class AlignmentResult(eqx.Module):
    """Attitude after alignment and its history.

    **Fields:** `heading_deg` (clockwise from north, [0, 360)), `pitch_deg`, `roll_deg` and
    their `*_std_deg` (1σ); `t` (K,) [s] and `history_deg` (K, 3) (heading, pitch, roll),
    `std_history_deg` (K, 3); `coarse_deg` (heading, pitch, roll) of the coarse stage;
    `biases`: estimated gyro [rad/s] and accelerometer [m/s²] biases (6,); `c_bn`: the
    final body-to-NED matrix; `gyro_bias_std_deg_h`: the gyro-bias σ [°/h] the filter
    assumed. Diagnostics (`None` where not computed): `bias_std` (6,) the biases' 1σ, body
    frame, same units (the east gyro bias's stays at the assumed grade: unobservable);
    `innovations` (K, 3) [m/s]: the zero-velocity innovations (N, E, D), `innovation_std`
    (K, 3) [m/s] their predicted σ (√diag S), `nis` (K,) νᵀS⁻¹ν (χ²₃ under the model),
    `velocity_noise` [m/s] the assumed; `coarse_std_deg` (heading, pitch, roll) the coarse
    attitude's 1σ in the fine stage's prior, `coarse_scatter_heading_deg` the heading σ the coarse span's own
    scatter gives ([`coarse_scatter`][hrgjax.ins.alignment.coarse_scatter]).

    **The heading σ is an assumption's:** it ends at `gyro_bias_std / (ω_ie cos lat)` for the
    *assumed* `gyro_bias_std` (0.28° at 45° for 0.05 °/h); a gyro whose bias is larger has a
    heading error larger in proportion: give [`align`][hrgjax.ins.alignment.align] the grade.
    Its part beyond that assumes white zero-velocity noise of `velocity_noise` (`sway()`
    tests the innovations' whiteness, not the heading)."""

    heading_deg: float
    pitch_deg: float
    roll_deg: float
    heading_std_deg: float
    pitch_std_deg: float
    roll_std_deg: float
    t: jax.Array
    history_deg: jax.Array
    std_history_deg: jax.Array
    coarse_deg: tuple
    biases: jax.Array
    c_bn: jax.Array
    gyro_bias_std_deg_h: float = 0.05
    bias_std: jax.Array | None = None
    innovations: jax.Array | None = None
    innovation_std: jax.Array | None = None
    nis: jax.Array | None = None
    velocity_noise: float | None = None
    coarse_std_deg: tuple | None = None
    coarse_scatter_heading_deg: float | None = None

    def sway(self) -> dict:
        """A whiteness test of the zero-velocity innovations against the filter's white
        `velocity_noise`: `innovation_rms_m_s` (N, E, D) [m/s], `velocity_noise_m_s`,
        `mean_nis` (3 under the model; far less where the noise is smaller than assumed),
        `slow_ratio` (N, E, D): the power of the normalised innovations' block means (m =
        `blocks`, [`SWAY_BLOCKS`][hrgjax.ins.alignment.SWAY_BLOCKS]) × the block length over
        the model's (1; χ²_m/m under it), `slow_p` its chance under the model, `not_white`:
        north or east beyond [`SWAY_FALSE_ALARM`][hrgjax.ins.alignment.SWAY_FALSE_ALARM]. A
        vehicle swaying slower than a filter step has a slow ratio above 1 however small its
        NIS: the innovations are not white as the filter assumes.

        **Not whether the heading σ is too small, or by how much:** sway much faster than the
        fine stage averages out of the heading (a 120-s, 5-cm/s sway in a 1200-s stage:
        flagged every time, heading error as the σ); sway near the stage's length looks like a
        heading error (the PSINS log's first 150-s window, 4.5σ off: not flagged). Disjoint
        windows' spread checks the heading. **Raises:** `ValueError` without innovations."""
        if self.innovations is None or self.innovation_std is None or self.nis is None:
            raise ValueError("AlignmentResult.innovations is None: sway() needs align's result")
        nu = np.asarray(self.innovations)
        white = nu / np.asarray(self.innovation_std)
        b = max(1, white.shape[0] // SWAY_BLOCKS)
        m = white.shape[0] // b
        slow = b * np.mean(white[: m * b].reshape(m, b, 3).mean(1) ** 2, axis=0)
        p = np.asarray(gammaincc(m / 2.0, jnp.asarray(m * slow / 2.0)))  # P(χ²_m > m·slow)
        return {
            "innovation_rms_m_s": np.sqrt(np.mean(nu**2, axis=0)).tolist(),
            "velocity_noise_m_s": self.velocity_noise,
            "mean_nis": float(np.mean(np.asarray(self.nis))),
            "slow_ratio": slow.tolist(),
            "blocks": int(m),
            "slow_p": p.tolist(),
            "not_white": bool(min(p[:2]) < 1.0 - math.sqrt(1.0 - SWAY_FALSE_ALARM)),
        }

    def to_json(self) -> dict:
        """The DESIGN.md keys (and the coarse result with its σ, `assumed_gyro_bias_std_deg_h`:
        the gyro-bias σ the heading σ rests on, `bias_std` (gyro [°/h], accelerometer [m/s²])
        and `sway`, where computed)."""
        keys = ("heading", "pitch", "roll")
        out = {f"{k}_deg": float(getattr(self, f"{k}_deg")) for k in keys}
        out |= {f"{k}_std_deg": float(getattr(self, f"{k}_std_deg")) for k in keys}
        out["coarse"] = dict(
            zip((f"{k}_deg" for k in keys), map(float, self.coarse_deg), strict=True)
        )
        if self.coarse_std_deg is not None:
            out["coarse"] |= {f"{k}_std_deg": float(v) for k, v in zip(keys, self.coarse_std_deg,
                                                                          strict=True)}  # fmt: skip
            out["coarse"]["scatter_heading_std_deg"] = float(self.coarse_scatter_heading_deg)
        out["assumed_gyro_bias_std_deg_h"] = float(self.gyro_bias_std_deg_h)
        if self.bias_std is not None:
            sd = np.asarray(self.bias_std)
            out["bias_std"] = {"gyro_deg_h": (sd[:3] / DEG_PER_H).tolist(),
                               "accel_m_s2": sd[3:].tolist()}  # fmt: skip
        if self.innovations is not None:
            out["sway"] = self.sway()
        return out


def _warn_heading(start: float, end: float, floor: float, lat: float, coarse: str,
                  sway: float = 0.0, white: float = 0.0) -> None:  # fmt: skip
    """`AlignmentWarning` for heading σ [°] `start`, `end` beyond the thresholds, by the cause:
    the grade's limit `floor` [°], the span's scatter `sway` [°] (over 2 × `white`), its noise."""
    span, by_sway = f"a longer {coarse} shrinks it (as 1/√span)", sway > 2 * white
    src = (f"the coarse span's own scatter ({sway:.3g}°, the grade's white noise {white:.2g}°)"
           if by_sway else "the grade's white noise over the coarse span")  # fmt: skip
    at = f"{start:.3g}° at the fine stage's start"
    if floor > END_HEADING_STD_DEG:
        why = (f"{end:.3g}° at the end: the assumed gyro grade's limit σ_ε/(ω_ie cos lat) is "
               f"{floor:.3g}° (over {END_HEADING_STD_DEG:g}°), a gyro of this grade cannot find "
               f"north at {abs(lat) / DEG:.3g}° (its error is heavy-tailed: z-RMS 1.1–1.2 at "
               "20–30°); no longer span helps: take the heading from outside or a better gyro")  # fmt: skip
    elif end > END_HEADING_STD_DEG:
        why = (f"{end:.3g}° at the end (over {END_HEADING_STD_DEG:g}°; the grade's limit "
               f"{floor:.3g}°): the fine stage has not converged; a longer record or {coarse} "
               "shrinks it")  # fmt: skip
    elif start >= NO_HEADING_STD_DEG:
        why = (f"{at}, from {src}: the coarse heading holds no heading information (a "
               f"linearised σ over {NO_HEADING_STD_DEG:g}° describes nothing); the fine filter "
               f"starts anywhere and may not recover; {span}")  # fmt: skip
    elif start > START_HEADING_STD_DEG:
        why = (f"{at} (over {START_HEADING_STD_DEG:g}°) is {src}: the IMU sways over the span; "
               "the scatter is a conservative bound (about √11× for sway decorrelating within a "
               "tenth of it: the PSINS log's 36° for a 21° error), the fine stage usually "
               f"recovers; check the sway line, or use a calmer stretch or a longer {coarse}"
               if by_sway else f"{at} (over {START_HEADING_STD_DEG:g}°): the coarse heading may be 140–180° "
               "off, where the fine filter does not recover (z-RMS 1.15–1.35 at 26–43°); "
               + span)  # fmt: skip
    else:
        return
    warnings.warn(f"align: heading σ {why}", AlignmentWarning, stacklevel=3)


def align(log: ImuLog, *, coarse_s: float = 60.0, coarse_name: str = "coarse_s",
          **fine_kw) -> AlignmentResult:  # fmt: skip
    """Coarse alignment on the first `coarse_s` seconds, then fine alignment on the rest from
    that start (module docstring; `fine_kw` go to `fine_align`: the gyro's grade
    `gyro_bias_std` [rad/s] and `arw` [rad/√s] among them). The prior holds the coarse
    attitude's correlation with the sensor biases (`coarse_bias_jacobian`, or the
    `start_bias_jacobian` given), so the heading σ ends at `gyro_bias_std / (ω_ie cos lat)`:
    what the assumed grade allows (`AlignmentResult`). Its part beyond the biases is
    `attitude_std_deg` (default (0.5, 0.5, 5)°) plus the coarse means' noise, whatever
    jacobian is given: per axis the larger of the grade's white noise
    ([`coarse_error_model`][hrgjax.ins.alignment.coarse_error_model]; 8.45° of heading at 88°
    for the default ARW over 60 s) and the span's own scatter (`coarse_scatter`: 5–60° of
    heading over the PSINS log's 60-s windows, whose coarse headings err 16.5° RMS).
    `coarse_name`: the span's name in messages. The result holds the diagnostics
    (innovations, NIS, bias σ, the coarse σ; `AlignmentResult.sway`).

    **Warns:** `AlignmentWarning` where the heading σ is not small (`END_HEADING_STD_DEG`,
    `START_HEADING_STD_DEG`), naming the cure. **Raises:** `ValueError` for a log not 2 steps
    longer than `coarse_s`, not a stationary record
    ([`check_stationary`][hrgjax.ins.alignment.check_stationary]), or within 1° of a pole;
    `TypeError` for a `fine_kw` that `fine_align` does not take (`start_s` among them: the
    fine stage starts where `coarse_s` ends); as `fine_align` for the options' values."""
    require_x64("ins.alignment.align")
    check_log("align", log)
    unknown = sorted(set(fine_kw) - {*FINE_DEFAULTS, "step_s", "start_bias_jacobian"})
    if unknown:  # start_s among them: the fine stage starts where the coarse span ends
        raise TypeError(f"align: unknown option {unknown[0]!r}; fine_kw are step_s, "
                        f"start_bias_jacobian, {', '.join(FINE_DEFAULTS)} (fine_align's but "
                        "start_s: the fine stage starts where coarse_s ends)")  # fmt: skip
    check_fine_options("align", **fine_kw)
    _check_coarse("align: ", coarse_name, coarse_s, log.dt)
    check_gyrocompass_latitude(log.lat)
    check_stationary(log, coarse_s, coarse_name=coarse_name)
    dt, step = log.dt, fine_kw.get("step_s", 1.0)
    check_step("align", step, dt)
    n = int(round(coarse_s / dt))
    if (log.t.shape[0] - n) // max(1, int(round(step / dt))) < 2:
        raise ValueError(f"the record ({log.t.shape[0] * dt:.4g} s) needs 2 fine steps "
                         f"({2 * step:g} s) after {coarse_name} = {coarse_s:g} s")  # fmt: skip
    # the coarse span cut on the host: slicing the device arrays compiled per record length
    dth_c, dv_c = device(np.asarray(log.dtheta)[:n]), device(np.asarray(log.dvel)[:n])
    f_b = jnp.sum(dv_c, 0) / (n * dt)
    w_b = jnp.sum(dth_c, 0) / (n * dt)
    c0 = coarse_align(f_b, w_b, log.lat)
    coarse = tuple(float(x) for x in euler_deg(c0))
    fine_kw = {**FINE_DEFAULTS, **fine_kw}
    jac, noise_var = coarse_error_model(c0, log.lat, log.h, n * dt, fine_kw["arw"], fine_kw["vrw"])
    fine_kw.setdefault("start_bias_jacobian", jac)
    parts = min(COARSE_PARTS, n)  # a span of fewer samples: one a part; of one: no scatter
    scatter = np.zeros(3) if n < 2 else np.diag(np.asarray(jac @ coarse_scatter(
        dth_c, dv_c, dt, parts=parts) @ jac.T))  # fmt: skip
    std = np.asarray(fine_kw["attitude_std_deg"], dtype=float)
    var = np.maximum(np.asarray(noise_var), scatter)  # white noise, or the span's sway
    fine_kw["attitude_std_deg"] = tuple(np.sqrt(std**2 + var / DEG**2))
    bg, ba = float(fine_kw["gyro_bias_std"]), float(fine_kw["accel_bias_std"])
    a = np.asarray(fine_kw["start_bias_jacobian"], dtype=float)
    p_start = np.diag(np.square(fine_kw["attitude_std_deg"]) * DEG**2) + (a * np.repeat(
        [bg**2, ba**2], 3)) @ a.T if a.shape == (3, 6) else None  # fmt: skip
    run = fine_run(log, c0, start_s=n * dt, **fine_kw)
    std = np.asarray(run.std_history_deg)
    last, s = np.asarray(run.history_deg)[-1], std[-1]
    floor = bg / (OMEGA_IE * math.cos(log.lat)) / DEG
    sway_deg = float(euler_std_deg(c0, jnp.diag(jnp.asarray(scatter)))[0])
    white_deg = float(euler_std_deg(c0, jnp.diag(noise_var))[0])
    _warn_heading(float(std[0, 0]), float(s[0]), floor, log.lat, coarse_name, sway_deg,
                  white_deg)  # fmt: skip
    c_end, p_end = np.asarray(run.c_bn)[-1], np.asarray(run.p)[-1]
    bias_std = np.sqrt(np.concatenate([np.diag(c_end.T @ p_end[k:k + 3, k:k + 3] @ c_end)
                                       for k in (6, 9)]))  # fmt: skip
    return AlignmentResult(
        float(last[0]), float(last[1]), float(last[2]), float(s[0]), float(s[1]), float(s[2]),
        run.t, run.history_deg, run.std_history_deg, coarse, run.biases, device(c_end),
        bg / DEG_PER_H, device(bias_std), run.innovations, run.innovation_std, run.nis,
        float(fine_kw["velocity_noise"]),
        None if p_start is None else tuple(float(x) for x in euler_std_deg(c0, p_start)),
        sway_deg,
    )  # fmt: skip
