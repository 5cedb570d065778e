r"""Ferraris calibration of a six-axis IMU (Ferraris et al. 1995, *Procedure for effortless
in-field calibration of three-axis rate gyros and accelerometers*; imucal's implementation).

**Model** (SI; a = specific force, ω = angular rate, both along orthogonal body axes):

$$a_s = M_a\,a + b_a, \qquad \omega_s = M_g\,\omega + G\,a + b_g,$$

M_a, M_g (3 × 3) scale and misalignment, b_a [m/s²] and b_g [rad/s] biases, G
[rad/s per m/s²] the gyros' g-sensitivity.

**Estimates.** With $u^\pm_i$ the mean accelerometer output on face $i_\pm$ (a = ±g e_i) and
$w^\pm_i$ the gyros' (ω = 0: the Earth's rate, 7.3e-5 rad/s, is neglected as in the
original method — a tactical or navigation-grade gyro needs a rate table and north):

- $M_a e_i = (u^+_i - u^-_i) / 2g$; each accelerometer's bias from its own ± pair,
  $b_{a,i} = (u^+_{i,i} + u^-_{i,i}) / 2$ (the axis along gravity, insensitive to small
  tilts of the face);
- $G e_i = (w^+_i - w^-_i) / 2g$; $b_g = \frac13\sum_i (w^+_i + w^-_i)/2$ (G cancels in each
  pair);
- a turn of angle φ about axis i (that axis vertical) integrates to
  $\sum_k (\omega_{s,k} - b_g - G\,\hat a_k)\,\Delta t_k = M_g\,\varphi\,e_i$ with
  $\hat a_k = M_a^{-1}(a_{s,k} - b_a)$, which gives M_g column by column.

Everything is a function of each section's sums, so the standard errors follow by linear
propagation (`jax.jacfwd` of the estimator) of those sums' covariance, formed as follows
(`sigma_source` names the parts used):

- **"repeats"**: a key with ≥ 2 ranges contributes the scatter of its repeats / R (which
  holds whatever changes when the IMU is put down again);
- **"white noise"**: a key with one range, white noise of the static faces' per-sample
  scatter (σ²/n for a face mean, σ²ΣΔt² for a turn's sums);
- **"bias drift"**: where every key has one range, an in-run random walk of each
  channel's bias from the session's start, q² min(s − t₀, t − t₀), propagated exactly
  into every section sum (`hrgjax.imu._drift`); q (one for the gyros, one for the
  accelerometers, `bias_walk`) is the maximum-likelihood value given the twelve
  combinations of face means that vanish for any calibration (each channel's three ±
  pair sums are equal) — zero where the faces agree within the white noise, when the
  source is "white noise" alone. The biases are then those at the session's start (its
  earliest section's first row).

Monte Carlo with known truth (`benchmarks/coverage_ferraris.py`, docs/imu.md: 200 sessions)
puts 65.6–71.8 % of the truths within ±1σ and 92.8–96.4 % within ±2σ with white noise, a
random walk and a Gauss–Markov drift of the biases; the white-noise σ alone covered 39.8 %
and 67.5 % under the random walk. Not covered: the repeats' σ (Student-t with R − 1
degrees of freedom, and blind to the drift common to all repeats); face tilts (inexact
flips), which the accelerometers' q absorbs only in part."""

from __future__ import annotations

import json
import os
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._x64 import require_x64
from ..units import DEG
from ._drift import walk_intensity, walk_kernel
from .data import ImuData
from .sections import FACES, SECTION_KEYS, TURNS, Sections, parse_sections
from .triad import ANGLE_AXES, TriadCalibration

PARAMETERS = (
    [f"accel_matrix[{i}{j}]" for i in "xyz" for j in "xyz"]
    + [f"accel_bias[{i}]" for i in "xyz"]
    + [f"gyro_matrix[{i}{j}]" for i in "xyz" for j in "xyz"]
    + [f"gyro_bias[{i}]" for i in "xyz"]
    + [f"gyro_g_sensitivity[{i}{j}]" for i in "xyz" for j in "xyz"]
)
"""Order of the 33 parameters in `ImuCalibration.covariance` (matrices row-major)."""
FORMAT = "hrgjax.imu_calibration"
G_RANGE_M_S2 = (9.76, 9.84)
"""The local gravity `g` [m/s²] a Ferraris session may declare: the range of the Earth's
surface (9.780 at the equator to 9.832 at the poles at sea level, about −3e-6 m/s² per m of
height), with a margin. A g outside it is a unit slip (981 in cm/s², 1 in units of g) that
would scale M_a by that factor without a word."""
G_DATA_TOLERANCE = 0.05
"""How far (relative) the declared `g` may be from the mean |specific force| the static
faces read. The raw faces carry the accelerometers' scale errors (±3 % per axis is a common
MEMS tolerance, and the six faces' mean averages them), so 5 % accepts any sensor worth
calibrating and refuses a g or a unit that the data contradict."""
TURN_OFF_AXIS = 0.1
"""The most a turn section may integrate about the two other axes, as a fraction of its
turn (a section spanning two turns, or a turn about the wrong axis, reads far more)."""


class ImuCalibration(eqx.Module):
    r"""A six-axis IMU calibration: $a_s = M_a a + b_a$, $\omega_s = M_g\omega + G a + b_g$.

    **Fields:** `accel_matrix` M_a (3, 3) [-]; `accel_bias` b_a (3,) [m/s²]; `gyro_matrix`
    M_g (3, 3) [-]; `gyro_bias` b_g (3,) [rad/s]; `gyro_g_sensitivity` G (3, 3) [rad/s per
    m/s²]; `covariance` (33, 33) of the parameters in
    [`PARAMETERS`][hrgjax.imu.ferraris.PARAMETERS] order (zeros when set by hand);
    `noise_std` (6,): per-sample white-noise σ of the gyros [rad/s] and the accelerometers
    [m/s²] seen on the static faces; `g` [m/s²] and `turn_deg` (3,) [°] the session's
    references; `sigma_source` ("repeats", "white noise", "white noise and bias drift",
    "repeats and white noise" or "none": see the module notes); `bias_walk` (2,) or None:
    the in-run random walk of the biases the session showed, gyros [rad/s/√s] and
    accelerometers [m/s²/√s] (None when set by hand).

    Standard errors: `accel_matrix_std`, `accel_bias_std`, `gyro_matrix_std`, `gyro_bias_std`,
    `gyro_g_sensitivity_std`; the six-angle form of
    [`TriadCalibration`][hrgjax.imu.triad.TriadCalibration]: [`accel_triad`][hrgjax.imu.ImuCalibration.accel_triad],
    [`gyro_triad`][hrgjax.imu.ImuCalibration.gyro_triad]."""

    accel_matrix: jax.Array
    accel_bias: jax.Array
    gyro_matrix: jax.Array
    gyro_bias: jax.Array
    gyro_g_sensitivity: jax.Array
    covariance: jax.Array
    noise_std: jax.Array
    g: float = eqx.field(static=True, default=9.81)
    turn_deg: tuple[float, float, float] = eqx.field(static=True, default=(360.0, 360.0, 360.0))
    sigma_source: str = eqx.field(static=True, default="none")
    bias_walk: jax.Array | None = None

    @classmethod
    def known(
        cls, accel_matrix=None, accel_bias=None, gyro_matrix=None, gyro_bias=None,
        gyro_g_sensitivity=None,
    ) -> ImuCalibration:  # fmt: skip
        """A calibration set by hand (identity matrices and zero biases by default; no
        uncertainty): M_a (3, 3), b_a (3,) [m/s²], M_g (3, 3), b_g (3,) [rad/s], G (3, 3)
        [rad/s per m/s²]."""
        eye, z = jnp.eye(3), jnp.zeros(3)
        parts = {
            "accel_matrix": (accel_matrix, eye), "accel_bias": (accel_bias, z),
            "gyro_matrix": (gyro_matrix, eye), "gyro_bias": (gyro_bias, z),
            "gyro_g_sensitivity": (gyro_g_sensitivity, jnp.zeros((3, 3))),
        }  # fmt: skip
        values = {}
        for name, (x, default) in parts.items():
            x = default if x is None else jnp.asarray(x, float)
            if x.shape != default.shape:
                raise ValueError(f"{name} must have shape {default.shape}; got {x.shape}")
            values[name] = x
        return cls(**values, covariance=jnp.zeros((33, 33)), noise_std=jnp.zeros(6))

    # ---- the model -----------------------------------------------------------------------
    def sensor(self, omega, accel):
        """Sensor outputs from true body-frame values: `omega` (..., 3) [rad/s] and `accel`
        (..., 3) [m/s²] → (gyro (..., 3) [rad/s], accel (..., 3) [m/s²]). Differentiable."""
        omega, accel = jnp.asarray(omega), jnp.asarray(accel)
        a_s = accel @ self.accel_matrix.T + _row(self.accel_bias, accel)
        w_s = omega @ self.gyro_matrix.T + accel @ self.gyro_g_sensitivity.T
        return w_s + _row(self.gyro_bias, omega), a_s

    def correct(self, gyro, accel):
        """Calibrated body-frame values from sensor outputs (the exact inverse of `sensor`):
        `gyro` (..., 3) [rad/s], `accel` (..., 3) [m/s²] → (ω (..., 3) [rad/s], a (..., 3)
        [m/s²]). Pure JAX: `jit`, `vmap` and `grad` through it."""
        gyro, accel = jnp.asarray(gyro), jnp.asarray(accel)
        a = (accel - _row(self.accel_bias, accel)) @ jnp.linalg.inv(self.accel_matrix).T
        rhs = gyro - _row(self.gyro_bias, gyro) - a @ self.gyro_g_sensitivity.T
        return rhs @ jnp.linalg.inv(self.gyro_matrix).T, a

    def apply(self, data: ImuData) -> ImuData:
        """The record `data` calibrated (a new `ImuData`; `data` is not changed)."""
        if not isinstance(data, ImuData):
            raise TypeError(f"apply takes an hg.imu.ImuData; got {type(data).__name__}")
        w, a = self.correct(data.gyro, data.accel)
        return ImuData(data.time, np.asarray(w), np.asarray(a), data.temperature, data.rate_hz)

    # ---- uncertainty -------------------------------------------------------------------
    def _std(self, lo: int, shape) -> jax.Array:
        n = int(np.prod(shape))
        var = jnp.diag(self.covariance)[lo : lo + n]
        return _sqrt_variance(var, PARAMETERS[lo : lo + n]).reshape(shape)

    @property
    def accel_matrix_std(self) -> jax.Array:
        """Standard errors of M_a (3, 3) [-]."""
        return self._std(0, (3, 3))

    @property
    def accel_bias_std(self) -> jax.Array:
        """Standard errors of b_a (3,) [m/s²]."""
        return self._std(9, (3,))

    @property
    def gyro_matrix_std(self) -> jax.Array:
        """Standard errors of M_g (3, 3) [-]."""
        return self._std(12, (3, 3))

    @property
    def gyro_bias_std(self) -> jax.Array:
        """Standard errors of b_g (3,) [rad/s]."""
        return self._std(21, (3,))

    @property
    def gyro_g_sensitivity_std(self) -> jax.Array:
        """Standard errors of G (3, 3) [rad/s per m/s²]."""
        return self._std(24, (3, 3))

    def vector(self) -> jax.Array:
        """The 33 parameters as one vector in `PARAMETERS` order."""
        return _flat(self.accel_matrix, self.accel_bias, self.gyro_matrix, self.gyro_bias,
                     self.gyro_g_sensitivity)  # fmt: skip

    def accel_triad(self) -> TriadCalibration:
        """The accelerometers in the six-angle form of `imu.triad`: M_a = diag(1 +
        scale)(I + E(angles)) exactly (scale_i = M_ii − 1, θ_ij = M_ij / M_ii), bias b_a
        [m/s²], with propagated standard errors."""
        return self._triad(0, 9, self.accel_bias, self.noise_std[3:])

    def gyro_triad(self) -> TriadCalibration:
        """The gyros in the six-angle form (as `accel_triad`), bias b_g [rad/s]."""
        return self._triad(12, 21, self.gyro_bias, self.noise_std[:3])

    def _triad(self, m_at: int, b_at: int, bias, noise) -> TriadCalibration:
        idx = np.r_[m_at : m_at + 9, b_at : b_at + 3]
        cov = self.covariance[np.ix_(idx, idx)]
        x = self.vector()[idx]
        jac = jax.jacfwd(_six_angle)(x)
        sensor = "accel" if m_at == 0 else "gyro"
        names = [f"{sensor} angle {a}" for a in ("xy", "xz", "yx", "yz", "zx", "zy")]
        names += [f"{sensor} scale {a}" for a in "xyz"] + [PARAMETERS[b_at + i] for i in range(3)]
        std = _sqrt_variance(jnp.diag(jac @ cov @ jac.T), names)
        y = _six_angle(x)
        return TriadCalibration(y[:6], y[6:9], bias, std[:6], std[6:9], std[9:12], noise)

    # ---- files -------------------------------------------------------------------------
    def to_json(self) -> dict:
        """JSON-ready dict: the contract's matrices and biases with units in the key names,
        their standard errors, the covariance, the six-angle forms (read-only extras)."""

        def lst(x):
            return np.asarray(x).tolist()

        acc, gyr = self.accel_triad(), self.gyro_triad()
        walk = [0.0, 0.0] if self.bias_walk is None else lst(self.bias_walk)
        return {
            "format": FORMAT,
            "version": 1,
            "model": "accel_sensor = accel_matrix @ a + accel_bias; gyro_sensor = gyro_matrix @ "
            "omega + gyro_g_sensitivity @ a + gyro_bias (SI: a [m/s^2], omega [rad/s])",
            "accel_matrix": lst(self.accel_matrix),
            "accel_bias_m_s2": lst(self.accel_bias),
            "gyro_matrix": lst(self.gyro_matrix),
            "gyro_bias_rad_s": lst(self.gyro_bias),
            "gyro_g_sensitivity_rad_s_per_m_s2": lst(self.gyro_g_sensitivity),
            "accel_matrix_std": lst(self.accel_matrix_std),
            "accel_bias_std_m_s2": lst(self.accel_bias_std),
            "gyro_matrix_std": lst(self.gyro_matrix_std),
            "gyro_bias_std_rad_s": lst(self.gyro_bias_std),
            "gyro_g_sensitivity_std_rad_s_per_m_s2": lst(self.gyro_g_sensitivity_std),
            "covariance": lst(self.covariance),
            "parameters": list(PARAMETERS),
            "noise_std": {
                "gyro_rad_s": lst(self.noise_std[:3]),
                "accel_m_s2": lst(self.noise_std[3:]),
            },
            "g_m_s2": self.g,
            "turn_deg": list(self.turn_deg),
            "sigma_source": self.sigma_source,
            "bias_walk": {
                "gyro_rad_s_per_sqrt_s": walk[0],
                "accel_m_s2_per_sqrt_s": walk[1],
            },
            "six_angle_form": {
                "angle_order": ["xy", "xz", "yx", "yz", "zx", "zy"],
                "accel_scale": lst(acc.scale),
                "accel_misalignment_rad": lst(acc.angles),
                "gyro_scale": lst(gyr.scale),
                "gyro_misalignment_rad": lst(gyr.angles),
            },
        }

    def save(self, path: str | os.PathLike) -> str:
        """Write the calibration as JSON (`to_json`), atomically; returns the path. Read it
        back with [`load_calibration`][hrgjax.imu.load_calibration]."""
        from .._io import atomic_write

        with atomic_write(path, "w") as fh:
            json.dump(self.to_json(), fh, indent=2)
        return os.fspath(path)


def load_calibration(path: str | os.PathLike) -> ImuCalibration:
    """Read a calibration written by [`ImuCalibration.save`][hrgjax.imu.ImuCalibration.save].

    **Raises:** `ValueError` naming the file and the field for a file of another format, a
    field of the wrong shape or holding text or booleans where numbers belong, a singular `accel_matrix` or `gyro_matrix`, a negative
    variance, a `g_m_s2` outside [`G_RANGE_M_S2`][hrgjax.imu.ferraris.G_RANGE_M_S2] or a
    `turn_deg` that is not three non-zero angles."""
    from .._io import read_json

    path = os.fspath(path)
    obj = read_json(path)
    if not isinstance(obj, dict) or obj.get("format") != FORMAT:
        raise ValueError(f'{path}: not an hrgjax IMU calibration (no "format": "{FORMAT}")')
    shapes = {
        "accel_matrix": (3, 3), "accel_bias_m_s2": (3,), "gyro_matrix": (3, 3),
        "gyro_bias_rad_s": (3,), "gyro_g_sensitivity_rad_s_per_m_s2": (3, 3),
        "covariance": (33, 33),
    }  # fmt: skip
    got = {}
    for key, shape in shapes.items():
        try:
            x = np.asarray(obj[key], dtype=float)
        except KeyError:
            raise ValueError(f"{path}: field {key!r} is missing") from None
        except (TypeError, ValueError):
            raise ValueError(f"{path}: field {key!r} must be numbers of shape {shape}") from None
        odd = _not_a_number(obj[key])  # text ("1.5") or booleans (true would read 1.0)
        if odd is not None:
            raise ValueError(f"{path}: field {key!r} must be numbers of shape {shape}; got {odd}")
        if x.shape != shape or not np.all(np.isfinite(x)):
            raise ValueError(f"{path}: field {key!r} must be finite numbers of shape {shape}")
        got[key] = jnp.asarray(x)
    for key in ("accel_matrix", "gyro_matrix"):
        sv = np.linalg.svd(np.asarray(got[key]), compute_uv=False)
        if not sv[-1] > 1e-9 * sv[0]:
            raise ValueError(
                f"{path}: field {key!r} is singular (singular values "
                f"{np.array2string(sv, precision=3)}): correct() inverts it; expected an "
                "invertible scale-and-misalignment matrix, near the identity"
            )
    var = np.diag(np.asarray(got["covariance"]))
    if np.any(var < 0):
        i = int(np.flatnonzero(var < 0)[0])
        raise ValueError(
            f"{path}: field 'covariance' has the variance {var[i]:.3g} < 0 for {PARAMETERS[i]} "
            f"(row {i}); expected a covariance with a non-negative diagonal"
        )
    noise_std = _nonnegative(path, "noise_std", obj.get("noise_std", {}),
                             ("gyro_rad_s", "accel_m_s2"), 3)  # fmt: skip
    bias_walk = _nonnegative(path, "bias_walk", obj.get("bias_walk", {}),
                             ("gyro_rad_s_per_sqrt_s", "accel_m_s2_per_sqrt_s"), None)  # fmt: skip
    g = _check_g(obj.get("g_m_s2", 9.81), f"{path}: field 'g_m_s2'")
    turn_deg = _check_turn_deg(obj.get("turn_deg", [360.0] * 3), f"{path}: field 'turn_deg'")
    source = obj.get("sigma_source", "none")
    if not isinstance(source, str):
        raise ValueError(f"{path}: field 'sigma_source' must be text; got {source!r}")
    return ImuCalibration(
        got["accel_matrix"], got["accel_bias_m_s2"], got["gyro_matrix"], got["gyro_bias_rad_s"],
        got["gyro_g_sensitivity_rad_s_per_m_s2"], got["covariance"], noise_std,
        g=g, turn_deg=tuple(float(t) for t in turn_deg),
        sigma_source=source, bias_walk=bias_walk,
    )  # fmt: skip


def _sqrt_variance(var, names) -> jax.Array:
    """Standard errors √var, refusing a negative variance (a damaged or hand-made covariance)
    with its parameter's name instead of returning NaN; a negative of round-off size (1e-12
    of the largest variance) is zero. Traced values (inside `jit`) are not checked."""
    if isinstance(var, jax.core.Tracer):
        return jnp.sqrt(var)
    v = np.asarray(var, dtype=float)
    tol = 1e-12 * float(np.max(np.abs(v[np.isfinite(v)]), initial=0.0))
    bad = np.flatnonzero(~(v >= -tol))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"covariance: the variance of {names[i]} is {v[i]:.3g}, not a number >= 0, so it has "
            "no standard error; the calibration's covariance must be symmetric positive "
            "semi-definite (33 x 33, PARAMETERS order)"
        )
    return jnp.sqrt(jnp.maximum(jnp.asarray(var), 0.0))


def _check_g(g, name: str = "g") -> float:
    """The declared local gravity [m/s²] as a float, within `G_RANGE_M_S2`."""
    lo, hi = G_RANGE_M_S2
    form = f"the local gravity in m/s² on the Earth's surface, {lo}–{hi} (9.81 standard)"
    if isinstance(g, bool | np.bool_ | str):
        raise ValueError(f"{name} must be {form}; got {g!r}")
    try:
        v = float(g)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {form}; got {g!r}") from None
    if not (np.isfinite(v) and lo <= v <= hi):
        hint = ""
        if lo <= v / 100.0 <= hi:
            hint = " (that is cm/s²)"
        elif 0.99 <= v <= 1.01:
            hint = " (that is in units of g)"
        raise ValueError(f"{name} = {g!r}{hint}: expected {form}")
    return v


def _not_a_number(value) -> str | None:
    """What a JSON value holds that is not a number (`"text"`, `"booleans"`, `None`), looking
    through nested lists; None when every leaf is a number."""
    stack = [value]
    while stack:
        x = stack.pop()
        if isinstance(x, list | tuple):
            stack.extend(x)
        elif isinstance(x, bool):
            return "booleans"
        elif not isinstance(x, int | float):
            return "text" if isinstance(x, str) else repr(x)[:40]
    return None


def _nonnegative(path: str, field: str, value, keys, size) -> jax.Array:
    """`{keys[0]: …, keys[1]: …}` of a calibration file as one vector of finite numbers >= 0
    (each `size` numbers, or one where size is None); missing keys read 0."""
    each = "[3 numbers]" if size else "a number"
    form = "{" + ", ".join(f"{k!r}: {each}" for k in keys) + "} with finite values >= 0"
    if not isinstance(value, dict):
        raise ValueError(f"{path}: field {field!r} must be {form}; got {value!r}")
    out = []
    for k in keys:
        try:
            raw = value.get(k, [0.0] * size if size else 0.0)
            x = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{path}: field {field!r} must be {form}; got {value!r}") from None
        if (
            _not_a_number(raw) is not None  # text or booleans (true would read 1.0)
            or x.shape != ((size,) if size else ())
            or not np.all(np.isfinite(x) & (x >= 0))
        ):
            raise ValueError(f"{path}: field {field!r} must be {form}; got {value!r}")
        out.append(np.atleast_1d(x))
    return jnp.asarray(np.concatenate(out))


def _row(v, like):
    """`v` (3,) shaped to broadcast against `like` (..., 3) (explicit rank)."""
    return v.reshape((1,) * (like.ndim - 1) + (3,))


# ---- the estimator ------------------------------------------------------------------------
def _flat(*parts) -> jax.Array:
    return jnp.concatenate([jnp.ravel(p) for p in parts])


def _six_angle(x):
    """M (9 row-major) and bias (3) → angles (6), scale (3), bias (3)."""
    m = x[:9].reshape(3, 3)
    angles = jnp.stack([m[i, j] / m[i, i] for i, j in ANGLE_AXES])
    return jnp.concatenate([angles, jnp.diag(m) - 1.0, x[9:12]])


# Flat layout of a session's section statistics: per face (x_p, x_a, …) mean accel (3) and
# mean gyro (3); per turn (x, y, z) Σ gyro·Δt (3), Σ accel·Δt (3) and Σ Δt (1).
_FACE_AT = {k: 6 * i for i, k in enumerate(FACES)}
_TURN_AT = {k: 36 + 7 * i for i, k in enumerate(TURNS)}
N_STATS = 57


def _estimate(stats, g, turn_rad):
    """The Ferraris estimates (33 parameters, `PARAMETERS` order) from the section
    statistics (57,) — the textbook formulas, linear except for M_a⁻¹ and 1/φ."""
    face = stats[:36].reshape(6, 6)  # rows x_p, x_a, y_p, y_a, z_p, z_a; cols accel, gyro
    u_p, u_n = face[0::2, :3].T, face[1::2, :3].T  # columns: faces x, y, z
    w_p, w_n = face[0::2, 3:].T, face[1::2, 3:].T
    m_a = (u_p - u_n) / (2.0 * g)
    b_a = jnp.diag(u_p + u_n) / 2.0
    gsens = (w_p - w_n) / (2.0 * g)
    b_g = jnp.mean((w_p + w_n) / 2.0, axis=1)
    turn = stats[36:].reshape(3, 7)
    s_g, s_a, t = turn[:, :3], turn[:, 3:6], turn[:, 6]
    a_int = jnp.linalg.solve(m_a, (s_a - t[:, None] * b_a[None, :]).T)  # (3 comps, 3 turns)
    w_int = s_g.T - b_g[:, None] * t[None, :] - gsens @ a_int  # (3 comps, 3 turns)
    m_g = w_int / turn_rad[None, :]
    return _flat(m_a, b_a, m_g, b_g, gsens)


# the estimates and their Jacobian in one compiled pass (the estimate is jacfwd's aux output)
_estimate_and_jacobian = jax.jit(
    jax.jacfwd(lambda s, g, turn: (_estimate(s, g, turn),) * 2, has_aux=True)
)


def _key_stats(data: ImuData, key: str, start: int, end: int) -> np.ndarray:
    if key in FACES:
        return np.concatenate([data.accel[start:end].mean(0), data.gyro[start:end].mean(0)])
    dt = data.dt[start:end, None]
    return np.concatenate([(data.gyro[start:end] * dt).sum(0), (data.accel[start:end] * dt).sum(0),
                           [dt.sum()]])  # fmt: skip


def session_statistics(data: ImuData, sections: Sections):
    """The section statistics the estimator needs: `(stats (57,), covariance (57, 57),
    noise_std (6,), sigma_source)`. A key with repeats contributes the mean of its repeats'
    statistics; its covariance is their scatter / R where R ≥ 2, else white noise of the
    static faces' per-sample scatter (σ²/n for a face mean, σ²ΣΔt² for a turn's sums) plus,
    where every key has one range, the in-run bias drift that the faces' disagreement shows
    (a random walk of the biases from the record's start, see `hrgjax.imu._drift`)."""
    got = _statistics(data, sections)
    return got.stats, got.white + got.drift, got.noise_std, got.source


class _Statistics(NamedTuple):
    stats: np.ndarray  # (57,)
    white: np.ndarray  # (57, 57): repeats' scatter or white noise
    drift: np.ndarray  # (57, 57): the bias random walk's part (zeros where not estimated)
    noise_std: np.ndarray  # (6,): per-sample σ, gyro xyz then accel xyz
    bias_walk: np.ndarray  # (2,): q of the gyros [rad/s/√s] and the accelerometers [m/s²/√s]
    source: str


def _statistics(data: ImuData, sections: Sections) -> _Statistics:
    stats = np.zeros(N_STATS)
    cov = np.zeros((N_STATS, N_STATS))
    # per-sample noise: deviations of every face sample from its own range's mean
    dev = np.concatenate([
        np.concatenate([data.gyro[s:e], data.accel[s:e]], axis=1)
        - np.concatenate([data.gyro[s:e], data.accel[s:e]], axis=1).mean(0)
        for k in FACES for s, e in sections[k]
    ])  # fmt: skip
    dof = dev.shape[0] - sum(len(sections[k]) for k in FACES)
    sample_cov = dev.T @ dev / max(dof, 1)  # (6, 6): gyro xyz, accel xyz
    c_g, c_a = sample_cov[:3, :3], sample_cov[3:, 3:]
    noise_std = np.sqrt(np.diag(sample_cov))
    sources = set()
    for key in SECTION_KEYS:
        ranges = sections[key]
        per = np.stack([_key_stats(data, key, s, e) for s, e in ranges])
        r = per.shape[0]
        at = _FACE_AT[key] if key in FACES else _TURN_AT[key]
        width = per.shape[1]
        stats[at : at + width] = per.mean(0)
        if r >= 2:
            d = per - per.mean(0)
            block = d.T @ d / (r - 1) / r
            sources.add("repeats")
        else:
            if key in FACES:
                n = ranges[0][1] - ranges[0][0]
                block = np.zeros((6, 6))
                block[:3, :3], block[3:, 3:] = c_a / n, c_g / n
            else:
                s, e = ranges[0]
                sum_dt2 = float((data.dt[s:e] ** 2).sum())
                block = np.zeros((7, 7))
                block[:3, :3], block[3:6, 3:6] = c_g * sum_dt2, c_a * sum_dt2
            sources.add("white noise")
        cov[at : at + width, at : at + width] = block
    drift, walk = np.zeros((N_STATS, N_STATS)), np.zeros(2)
    if "repeats" not in sources:
        drift, walk = _drift_covariance(data, sections, stats, cov)
        if np.any(walk > 0):
            sources.add("bias drift")
    source = " and ".join(s for s in ("repeats", "white noise", "bias drift") if s in sources)
    return _Statistics(stats, cov, drift, noise_std, walk, source or "none")


def _drift_covariance(data: ImuData, sections: Sections, stats: np.ndarray, white: np.ndarray):
    """The statistics' covariance from a random walk of the biases (one intensity for the
    gyros, one for the accelerometers) estimated from the faces' ± pair sums, and the two
    intensities q [unit/√s]."""
    dt = data.dt
    pieces = [[(s, e, np.full(e - s, 1.0 / (e - s)) if key in FACES else dt[s:e], 1.0)]
              for key in SECTION_KEYS for s, e in sections[key][:1]]  # fmt: skip
    origin = min(s for ranges in sections.values() for s, _ in ranges)
    per_key = walk_kernel(data.time, pieces, origin)  # the same for every channel
    kernels = [np.zeros((N_STATS, N_STATS)) for _ in range(2)]  # gyro, accel
    for c in range(3):
        for sensor, (face_at, turn_at) in enumerate(((3 + c, c), (c, 3 + c))):
            idx = [_FACE_AT[k] + face_at for k in FACES] + [_TURN_AT[k] + turn_at for k in TURNS]
            kernels[sensor][np.ix_(idx, idx)] = per_key
    walk = np.zeros(2)
    for sensor, (kernel, offset) in enumerate(zip(kernels, (3, 0), strict=True)):
        contrasts = _pair_contrasts(offset)
        q2 = walk_intensity(contrasts @ stats, contrasts @ white
                            @ contrasts.T, contrasts @ kernel @ contrasts.T)  # fmt: skip
        walk[sensor] = np.sqrt(q2)
    return walk[0] ** 2 * kernels[0] + walk[1] ** 2 * kernels[1], walk


def _pair_contrasts(offset: int) -> np.ndarray:
    """(6, 57): for each channel c of the sensor at `offset` in a face's six numbers (0:
    accel, 3: gyro), the x pair sum minus the y pair sum and y minus z (zero without
    noise for any calibration)."""
    out = np.zeros((6, N_STATS))
    for c in range(3):
        pair = np.zeros((3, N_STATS))
        for i in range(3):
            pair[i, [12 * i + offset + c, 12 * i + 6 + offset + c]] = 1.0
        out[2 * c], out[2 * c + 1] = pair[0] - pair[1], pair[1] - pair[2]
    return out


def ferraris(
    data: ImuData,
    sections=None,
    g: float = 9.81,
    turn_deg: float | tuple[float, float, float] = 360.0,
) -> ImuCalibration:
    """Ferraris calibration of a six-axis IMU from one session (see the module notes).

    **Arguments:**

    - `data`: the session, an [`ImuData`][hrgjax.imu.ImuData] (SI inside).
    - `sections`: a mapping, a JSON file (imucal's section list reads as is) or None to find
      them with [`detect_sections`][hrgjax.imu.detect_sections]; a key may list repeated
      ranges (see [`parse_sections`][hrgjax.imu.sections.parse_sections]).
    - `g`: local gravity [m/s²] (9.81 as imucal; the local value, e.g. 9.8062 at 45° latitude
      at sea level, makes M_a absolute), within
      [`G_RANGE_M_S2`][hrgjax.imu.ferraris.G_RANGE_M_S2].
    - `turn_deg`: the angle of each turn [°], one number or (x, y, z); positive is
      right-handed about the axis (counter-clockwise seen from above with the axis up);
      imucal's default clockwise hand turn is −360.

    **Returns:** an [`ImuCalibration`][hrgjax.imu.ImuCalibration] with standard errors.

    **Raises:** `ValueError` for bad sections (overlapping keys included); for a `g` outside
    [`G_RANGE_M_S2`][hrgjax.imu.ferraris.G_RANGE_M_S2] or more than `G_DATA_TOLERANCE` (5 %)
    from the static faces' mean |specific force|; for a turn whose measured angle has the
    other sign than `turn_deg` or differs from it by more than a quarter turn, or that
    integrates more than `TURN_OFF_AXIS` (10 %) of its angle about the other two axes
    (naming it); for faces whose accelerometer readings do not put the ±g axis where the
    key says."""
    require_x64("hg.imu.ferraris")
    if not isinstance(data, ImuData):
        raise TypeError(
            f"ferraris takes an hg.imu.ImuData (hg.imu.load); got {type(data).__name__}"
        )
    if sections is None:
        from .sections import detect_sections

        sections = detect_sections(data)
    else:
        sections = parse_sections(sections, len(data))
    g = _check_g(g)
    turns = _check_turn_deg(turn_deg, "turn_deg")
    got = _statistics(data, sections)
    stats, cov = got.stats, got.white + got.drift
    _check_faces(stats, g)
    _check_gravity(stats, g)
    jac, params = _estimate_and_jacobian(jnp.asarray(stats), g, jnp.deg2rad(jnp.asarray(turns)))
    jac, params = np.asarray(jac), np.asarray(params)
    _check_turns(params, turns)
    p_cov = jac @ cov @ jac.T
    p = jnp.asarray(params)
    return ImuCalibration(
        p[:9].reshape(3, 3), p[9:12], p[12:21].reshape(3, 3), p[21:24], p[24:33].reshape(3, 3),
        jnp.asarray((p_cov + p_cov.T) / 2), jnp.asarray(got.noise_std), g=g,
        turn_deg=tuple(float(t) for t in turns), sigma_source=got.source,
        bias_walk=jnp.asarray(got.bias_walk),
    )  # fmt: skip


def _check_turn_deg(turn_deg, name: str) -> np.ndarray:
    """`turn_deg` (one angle or three) as (3,) non-zero finite angles [°]."""
    form = "a non-zero angle [°] or three of them (x, y, z turns), e.g. 360 or -360"
    try:
        raw = np.asarray(turn_deg)
        turns = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {form}; got {turn_deg!r}") from None
    if raw.dtype.kind not in "iuf" or turns.shape not in ((), (3,)):
        raise ValueError(f"{name} must be {form}; got {turn_deg!r}")
    turns = np.broadcast_to(turns, (3,)).copy()
    if not np.all(np.isfinite(turns) & (turns != 0)):
        raise ValueError(f"{name} must be {form}; got {turn_deg!r}")
    return turns


def _check_gravity(stats: np.ndarray, g: float) -> None:
    """The declared g against the static faces' mean |specific force| (`G_DATA_TOLERANCE`)."""
    read = float(np.mean([np.linalg.norm(stats[6 * i : 6 * i + 3]) for i in range(6)]))
    if abs(read / g - 1.0) > G_DATA_TOLERANCE:
        raise ValueError(
            f"g = {g:g} m/s² but the static faces read a mean |specific force| of {read:.4g} "
            f"m/s² ({abs(read / g - 1.0):.1%} apart, more than {G_DATA_TOLERANCE:.0%}); give "
            "the local gravity [m/s²] and check the accelerometer unit and the sections"
        )


def _check_faces(stats: np.ndarray, g: float) -> None:
    for i, key in enumerate(FACES):
        a = stats[6 * i : 6 * i + 3]
        axis, sign = "xyz".index(key[0]), 1.0 if key.endswith("_p") else -1.0
        if sign * a[axis] < 0.5 * np.linalg.norm(a):
            raise ValueError(
                f"sections: face {key!r} reads accel {np.round(a, 3).tolist()} m/s²: its "
                f"{key[0]} axis is not {'up' if sign > 0 else 'down'} (expected about "
                f"{sign * g:+.2f} m/s² on {key[0]}); check the section's rows"
            )


def _check_turns(params: np.ndarray, turns: np.ndarray) -> None:
    m_g = params[12:21].reshape(3, 3)
    for i, key in enumerate(TURNS):
        measured = m_g[i, i] * turns[i]
        if m_g[i, i] < 0.75 or m_g[i, i] > 1.25:
            scale = abs(m_g[i, i])
            if 0.75 < scale < 1.25:
                hint = f"; the turn went the other way: pass turn_deg={-turns[i]:g}"
            elif 0.75 < scale / DEG < 1.25 or 0.75 < scale * DEG < 1.25:
                hint = "; the gyro unit is declared wrong (deg/s read as rad/s or the other way)"
            else:
                hint = "; check the section's rows, turn_deg and the gyro unit"
            raise ValueError(
                f"sections: turn {key!r} integrates to {measured:.1f}° about {key[0]} but "
                f"turn_deg is {turns[i]:g}°{hint}"
            )
        angles = m_g[:, i] * turns[i]  # the turn's integral about x, y, z [°]
        off = float(np.linalg.norm(np.delete(angles, i)))
        if off > TURN_OFF_AXIS * abs(turns[i]):
            raise ValueError(
                f"sections: turn {key!r} integrates to {np.round(angles, 1).tolist()}° about "
                f"x, y, z: {off:.1f}° off its {key[0]} axis, more than {TURN_OFF_AXIS:.0%} of "
                f"turn_deg ({turns[i]:g}°); a turn section must hold one turn about its own "
                "axis (check the section's rows)"
            )
