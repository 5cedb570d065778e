r"""`ImuCalibration`: a six-axis IMU's calibration as a model — $a_s = M_a a + b_a$,
$\omega_s = M_g\omega + G a + b_g$ — with its uncertainty, the six-angle form of each triad,
and its JSON file (`save`, `load_calibration`). The Ferraris method that estimates it is
`hrgjax.imu.ferraris`."""

from __future__ import annotations

import json
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_numbers, concrete_value
from .._x64 import require_x64
from .data import ImuData
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


_KNOWN_RANGES = {
    "accel_matrix": "m/s² to m/s²", "gyro_matrix": "rad/s to rad/s",
    "accel_bias": ("imu_accel_bias", "m/s²"), "gyro_bias": ("imu_gyro_bias", "rad/s"),
}  # fmt: skip
"""The fields `ImuCalibration.known` holds to `hrgjax.plausible`'s ranges: a matrix's
mapping, a bias's (range, unit)."""


def _check_known(name: str, v: np.ndarray) -> None:
    """`ImuCalibration.known`'s plausibility of the concrete field `name` = `v`: a matrix is
    I plus small scale and misalignment errors (`imu_scale`, `imu_misalignment`), a bias
    within `imu_gyro_bias` / `imu_accel_bias` (one line each, with the likely unit)."""
    if not name.endswith("matrix"):
        quantity, unit = _KNOWN_RANGES[name]
        plausible.check(f"{name} [{unit}]", v, quantity)
        return
    d = np.diag(v)
    shown = np.array2string(d, precision=4)
    head = (f"{name} must be I plus small scale and misalignment errors (it maps "
            f"{_KNOWN_RANGES[name]}); its diagonal is {shown}")  # fmt: skip
    if np.all(np.abs(d) < 0.5):
        raise ValueError(f"{head}: the deviation M − I alone? pass np.eye(3) + it")
    if np.all(d < -0.5):
        raise ValueError(f"{head}: M ≈ −I reverses every axis; flip the signs of the data's "
                         "axes instead")  # fmt: skip
    if np.all(np.abs(d) > 2.0):
        raise ValueError(f"{head}: a unit ratio between output and input (1000: mg; 9.81: "
                         "m/s² and g; 57.3: ° and rad), not a scale error; give both in one "
                         "unit")  # fmt: skip
    plausible.check(f"{name} diagonal − 1 (scale error) [-]", d - 1.0, "imu_scale")
    plausible.check(f"{name} off the diagonal (misalignment) [rad]", v[~np.eye(3, dtype=bool)],
                    "imu_misalignment")  # fmt: skip


class ImuCalibration(eqx.Module):
    r"""A six-axis IMU calibration: $a_s = M_a a + b_a$, $\omega_s = M_g\omega + G a + b_g$.

    **Fields:** `accel_matrix` M_a (3, 3) [-]; `accel_bias` b_a (3,) [m/s²]; `gyro_matrix`
    M_g (3, 3) [-]; `gyro_bias` b_g (3,) [rad/s]; `gyro_g_sensitivity` G (3, 3) [rad/s per
    m/s²]; `covariance` (33, 33) of the parameters in
    [`PARAMETERS`][hrgjax.imu.ferraris.PARAMETERS] order (zeros when set by hand);
    `noise_std` (6,): per-sample white-noise σ of the gyros [rad/s] and the accelerometers
    [m/s²] seen on the static faces; `g` [m/s²] and `turn_deg` (3,) [°] the session's
    references; `sigma_source` ("repeats", "white noise", "white noise and bias drift",
    "repeats and white noise" or "none": see `hrgjax.imu.ferraris`); `bias_walk` (2,) or None:
    the in-run random walk of the biases the session showed (the posterior mean of its
    intensity from the face contrasts: `hrgjax.imu._drift.walk_posterior_mean`), gyros
    [rad/s/√s] and accelerometers [m/s²/√s] (None when set by hand: saved as `null` and
    read back as None, never as a zero walk).

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
        [rad/s per m/s²].

        **Raises:** `ValueError` for a wrong shape, a NaN or inf, a singular matrix, or
        (concrete values) one outside `hrgjax.plausible.RANGES`, as
        [`ImuModel`][hrgjax.ins.sensors.ImuModel] holds its errors: a matrix is I plus small
        errors, |M_ii − 1| < 0.1 (`imu_scale`) and |M_ij| < 0.1 rad (`imu_misalignment`) —
        the deviation M − I alone, −I or a unit ratio such as 1000·I are named so —, |b_g| <
        0.75 rad/s (`imu_gyro_bias`: °/h or °/s typed as rad/s) and |b_a| < 3 m/s²
        (`imu_accel_bias`: mg or µg), each with the units it may be in."""
        eye, z = jnp.eye(3), jnp.zeros(3)
        parts = {
            "accel_matrix": (accel_matrix, eye), "accel_bias": (accel_bias, z),
            "gyro_matrix": (gyro_matrix, eye), "gyro_bias": (gyro_bias, z),
            "gyro_g_sensitivity": (gyro_g_sensitivity, jnp.zeros((3, 3))),
        }  # fmt: skip
        values = {}
        for name, (x, default) in parts.items():
            if x is not None:  # str, complex: NumPy's errors; True read as 1.0
                check_numbers(name, x, f"real numbers of shape {default.shape}")
            x = default if x is None else jnp.array(x, float)  # a copy, not a view of `x`
            if x.shape != default.shape:
                raise ValueError(f"{name} must have shape {default.shape}; got {x.shape}")
            v = concrete_value(x)  # NaN, or a singular matrix correct() inverts into NaN
            if v is not None and not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be finite; got {v[~np.isfinite(v)][0]}")
            sv = np.linalg.svd(v, compute_uv=False) if v is not None and v.ndim == 2 else None
            if name.endswith("matrix") and sv is not None and not sv[-1] > 1e-9 * sv[0]:
                raise ValueError(f"{name} must be an invertible scale-and-misalignment matrix "
                                 f"(correct() inverts it); its singular values are "
                                 f"{np.array2string(sv, precision=3)}")  # fmt: skip
            if v is not None and name in _KNOWN_RANGES:
                _check_known(name, v)
            values[name] = x
        return cls(**values, covariance=jnp.zeros((33, 33)), noise_std=jnp.zeros(6))

    # ---- the model -----------------------------------------------------------------------
    def sensor(self, omega, accel):
        """Sensor outputs from true body-frame values: `omega` (..., 3) [rad/s] and `accel`
        (..., 3) [m/s²] → (gyro (..., 3) [rad/s], accel (..., 3) [m/s²]). Differentiable."""
        omega, accel = _pair("sensor", "omega", omega, accel)
        a_s = accel @ self.accel_matrix.T + _row(self.accel_bias, accel)
        w_s = omega @ self.gyro_matrix.T + accel @ self.gyro_g_sensitivity.T
        return w_s + _row(self.gyro_bias, omega), a_s

    def correct(self, gyro, accel):
        """Calibrated body-frame values from sensor outputs (the exact inverse of `sensor`):
        `gyro` (..., 3) [rad/s], `accel` (..., 3) [m/s²] → (ω (..., 3) [rad/s], a (..., 3)
        [m/s²]). Pure JAX: `jit`, `vmap` and `grad` through it."""
        gyro, accel = _pair("correct", "gyro", gyro, accel)
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
        return flat_parameters(self.accel_matrix, self.accel_bias, self.gyro_matrix, self.gyro_bias,
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
        their standard errors, the covariance, the six-angle forms (read-only extras);
        `"bias_walk"` is `null` for a calibration without one (set by hand)."""

        def lst(x):
            return np.asarray(x).tolist()

        acc, gyr = self.accel_triad(), self.gyro_triad()
        walk = None  # null: none measured (set by hand), not a zero walk
        if self.bias_walk is not None:
            walk = {
                "gyro_rad_s_per_sqrt_s": float(self.bias_walk[0]),
                "accel_m_s2_per_sqrt_s": float(self.bias_walk[1]),
            }
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
            "bias_walk": walk,
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
    `turn_deg` that is not three non-zero angles; `RuntimeError` (one line) when JAX's
    float64 mode is off: the calibration's arrays are JAX arrays, and float32 would round
    the saved float64 values (a gyro bias by ~3e-8 of itself) without a word.

    A `"bias_walk"` that is `null` or absent (files written before it existed) reads None;
    one written as numbers (the zeros older files wrote for None included) reads those numbers, as before."""
    from .._io import read_json

    path = os.fspath(path)
    require_x64(f"hg.imu.load_calibration({path!r})")
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
    bias_walk = obj.get("bias_walk")  # null or absent: none measured (set by hand)
    if bias_walk is not None:
        bias_walk = _nonnegative(path, "bias_walk", bias_walk,
                                 ("gyro_rad_s_per_sqrt_s", "accel_m_s2_per_sqrt_s"), None)  # fmt: skip
    g = check_g(obj.get("g_m_s2", 9.81), f"{path}: field 'g_m_s2'")
    turn_deg = check_turn_deg(obj.get("turn_deg", [360.0] * 3), f"{path}: field 'turn_deg'")
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


def check_g(g, name: str = "g") -> float:
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


def _pair(where: str, name: str, rate, accel) -> tuple:
    """`rate` and `accel` as arrays of shapes (..., 3) that broadcast together (one (3,)
    accel for every rate row too), else one line naming them (JAX's "incompatible shapes
    for broadcasting")."""
    check_numbers(f"{where}: {name}", rate, "real numbers of shape (..., 3)")
    check_numbers(f"{where}: accel", accel, "real numbers of shape (..., 3)")
    rate, accel = jnp.asarray(rate), jnp.asarray(accel)
    if rate.shape[-1:] == accel.shape[-1:] == (3,):
        try:
            jnp.broadcast_shapes(rate.shape, accel.shape)
            return rate, accel
        except ValueError:
            pass
    raise ValueError(f"{where}: {name} and accel must be of shapes (..., 3) that broadcast "
                     f"together; got {rate.shape} and {accel.shape}")  # fmt: skip


def _row(v, like):
    """`v` (3,) shaped to broadcast against `like` (..., 3) (explicit rank)."""
    return v.reshape((1,) * (like.ndim - 1) + (3,))


def flat_parameters(*parts) -> jax.Array:
    """The parts (M_a, b_a, M_g, b_g, G) as one vector in `PARAMETERS` order (matrices
    row-major)."""
    return jnp.concatenate([jnp.ravel(p) for p in parts])


def _six_angle(x):
    """M (9 row-major) and bias (3) → angles (6), scale (3), bias (3)."""
    m = x[:9].reshape(3, 3)
    angles = jnp.stack([m[i, j] / m[i, i] for i, j in ANGLE_AXES])
    return jnp.concatenate([angles, jnp.diag(m) - 1.0, x[9:12]])


def per_turn(value, name: str, form: str, ok) -> np.ndarray:
    """`value` (one real number or three: the x, y, z turns) as a (3,) float array whose
    entries all pass `ok` (a vectorised predicate); else one line naming `name` and `form`."""
    try:
        raw = np.asarray(value)
        out = np.array(raw, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be {form}; got {value!r}") from None
    if raw.dtype.kind not in "iuf" or out.shape not in ((), (3,)):
        raise ValueError(f"{name} must be {form}; got {value!r}")
    out = np.broadcast_to(out, (3,)).copy()
    if not np.all(np.isfinite(out) & ok(out)):
        raise ValueError(f"{name} must be {form}; got {value!r}")
    return out


def check_turn_deg(turn_deg, name: str) -> np.ndarray:
    """`turn_deg` (one angle or three) as (3,) non-zero finite angles [°]."""
    form = "a non-zero angle [°] or three of them (x, y, z turns), e.g. 360 or -360"
    return per_turn(turn_deg, name, form, lambda v: v != 0)
