r"""A strapdown FOG IMU on a vibration table (seed 003, steps 1–2): the table's linear
vibration, the sensors' static model and a vibration-error model with memory.

**Table.** A [`VibrationSchedule`][hrgjax.fog.vibration.VibrationSchedule] is a sequence of
segments, each a sinusoid of frequency f [Hz] and amplitude A [g] along one body-frame
direction u (A = 0: at rest). The phase is continuous across segments,
$a(t) = A(t)\,g_0 \sin\theta(t)$, $\dot\theta = 2\pi f(t)$, and the body's specific force is
$f^b = C_n^b(-g^n) + a(t)\,u$. The table holds the attitude: the angular rate is the Earth's,
$\omega^b = C_n^b\omega_{ie}^n$.

**Sensors.** Each triad follows its static model ([`TriadCalibration`][hrgjax.imu.triad.TriadCalibration]),
$s = \mathrm{diag}(1+k)(I+E)\,b + \beta$, plus white noise (angle and velocity random walk)
and the vibration errors below, which arise on each sensor's own axis.

**Gyro vibration error** ([`VibrationError`][hrgjax.fog.vibration.VibrationError]), per gyro
i, is a rectified drift with memory plus a periodic part:

- the fibre coil and its mount respond to the table through a resonance
  $|H(f)|^2 = 1/\big((1 - f^2/f_r^2)^2 + (f/(Q f_r))^2\big)$; the coil sees
  $u = (A\,|H(f)|)^2$ [g²];
- the steady rectified drift saturates in amplitude (the coil's potting slips):
  $\varepsilon_{ss,i}(f, A) = r_i\,u/(1 + u/A_{sat}^2)$;
- the drift follows it with the coil's stress-relaxation time constant τ:
  $\tau\,\dot\varepsilon_i = \varepsilon_{ss,i}(f(t), A(t)) - \varepsilon_i$ (the memory: after
  a change of vibration the error keeps its past for several τ, which a static map of
  (f, A) cannot know);
- a linear g-sensitivity $s_i\,a(t)/g_0$ adds a zero-mean periodic error at f.

**Accelerometer vibration error:** a second-order nonlinearity $K_{2,i}\,a_i^2$ on each
accelerometer's input along its axis, which rectifies to $K_{2,i}(A g_0 u_i)^2/2$.

The defaults ([`default_imu`][hrgjax.fog.vibration.default_imu]) describe a navigation-grade
FOG IMU: ARW 0.0005 °/√h, static gyro biases ~0.01 °/h, rectified drift 0.2–0.35 °/h at
(10 Hz, 1 g) and up to 0.85 °/h near the 25 Hz coil resonance, τ = 20 s, installation angles of a few arc-minutes.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import concrete_value, finite_number, numeric_problem
from .._compiled import device, fused
from .._x64 import require_x64
from ..ins.constants import WGS84, earth_rate_ned
from ..ins.trajectory import euler_to_dcm
from ..units import DEG, DEG_PER_H, DEG_PER_SQRT_H, G0
from .misalignment import TriadCalibration

ARCMIN = DEG / 60.0


class VibrationSchedule(eqx.Module):
    """Piecewise-constant table vibration: segments of `durations_s` [s] at `freq_hz` [Hz]
    and `amp_g` [g] along the body-frame unit direction `axis` (normalised). An amplitude
    of 0 is rest. All fields are static (numbers known before tracing)."""

    durations_s: tuple = eqx.field(static=True)
    freq_hz: tuple = eqx.field(static=True)
    amp_g: tuple = eqx.field(static=True)
    axis: tuple = eqx.field(static=True, default=(0.0, 0.0, 1.0))

    def __init__(self, durations_s, freq_hz, amp_g, axis=(0.0, 0.0, 1.0)):
        d, f, a = (np.atleast_1d(np.asarray(x, float)) for x in (durations_s, freq_hz, amp_g))
        if not (d.ndim == f.ndim == a.ndim == 1 and d.size == f.size == a.size >= 1):
            raise ValueError(
                "durations_s, freq_hz and amp_g must be 1-D of one length; got shapes "
                f"{d.shape}, {f.shape}, {a.shape}"
            )
        for name, x in (("durations_s", d), ("freq_hz", f), ("amp_g", a)):
            if not np.all(np.isfinite(x)):
                raise ValueError(f"VibrationSchedule.{name} must be finite; got {x}")
        if np.any(d <= 0):
            raise ValueError(f"VibrationSchedule.durations_s must be > 0 s; got {d}")
        if np.any(f < 0) or np.any(a < 0):
            raise ValueError("VibrationSchedule.freq_hz [Hz] and amp_g [g] must be >= 0")
        if np.any((f == 0) & (a > 0)):
            raise ValueError(
                "VibrationSchedule: a segment with amp_g > 0 needs freq_hz > 0 (a 0-Hz "
                f"vibration is a constant acceleration); got freq_hz {f.tolist()}, amp_g "
                f"{a.tolist()} (rest is amp_g 0)"
            )
        if np.any(a > 50):
            raise ValueError(
                f"VibrationSchedule.amp_g is in g (standard gravity), not m/s²; got {a.max()}"
            )
        u = np.asarray(axis, float)
        if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
            raise ValueError(f"VibrationSchedule.axis must be a non-zero 3-vector; got {axis}")
        self.durations_s = tuple(d.tolist())
        self.freq_hz = tuple(f.tolist())
        self.amp_g = tuple(a.tolist())
        self.axis = tuple((u / np.linalg.norm(u)).tolist())

    @classmethod
    def constant(cls, freq_hz: float, amp_g: float, duration_s: float, axis=(0.0, 0.0, 1.0)):
        """One condition for `duration_s`, switched on at t = 0."""
        return cls([duration_s], [freq_hz], [amp_g], axis)

    @classmethod
    def on_off(
        cls, conditions, on_s: float, off_s: float, lead_s: float = 0.0, axis=(0.0, 0.0, 1.0)
    ):
        """Rest for `lead_s`, then each `(f [Hz], A [g])` of `conditions` for `on_s`
        followed by `off_s` of rest — the switch-on and switch-off transients are what an
        error model with memory has to get right."""
        lead_s = finite_number("VibrationSchedule.on_off: lead_s", lead_s, "s")
        if lead_s < 0:
            raise ValueError(f"VibrationSchedule.on_off: lead_s must be >= 0 [s]; got {lead_s:g}")
        d, f, a = [], [], []
        if lead_s > 0:
            d, f, a = [lead_s], [0.0], [0.0]
        for fc, ac in conditions:
            d += [on_s, off_s]
            f += [fc, 0.0]
            a += [ac, 0.0]
        return cls(d, f, a, axis)

    @property
    def duration_s(self) -> float:
        """Total length [s]."""
        return float(sum(self.durations_s))

    def samples(self, fs: float):
        """Per-sample frequency [Hz] and amplitude [g] at `t = k/fs`, k = 0 … N−1, with
        N = round(duration·fs) (numpy)."""
        fs = finite_number("VibrationSchedule.samples: fs", fs, "Hz")
        if fs <= 0:
            raise ValueError(f"VibrationSchedule.samples: fs must be > 0 [Hz]; got {fs:g}")
        n = int(round(self.duration_s * fs))
        t = np.arange(n) / fs
        edges = np.cumsum(self.durations_s)
        seg = np.minimum(np.searchsorted(edges, t, side="right"), len(edges) - 1)
        return np.asarray(self.freq_hz)[seg], np.asarray(self.amp_g)[seg]


class VibrationError(eqx.Module):
    """Vibration-error parameters (module docstring). **Fields:** `rectification` (3,)
    [rad/s per g²] r_i per gyro; `g_sensitivity` (3,) [rad/s per g] s_i; `f_res` [Hz] and
    `q_res` [-]: the coil resonance; `a_sat_g` [g]: amplitude saturation; `tau_s` [s]: the
    memory time constant; `accel_k2` (3,) [1/(m/s²)]: accelerometer second-order
    coefficients."""

    rectification: jax.Array
    g_sensitivity: jax.Array
    f_res: jax.Array
    q_res: jax.Array
    a_sat_g: jax.Array
    tau_s: jax.Array
    accel_k2: jax.Array

    def __check_init__(self):
        for name in ("rectification", "g_sensitivity", "accel_k2"):
            if jnp.shape(getattr(self, name)) != (3,):
                raise ValueError(
                    f"VibrationError.{name} must have shape (3,) (one per sensor axis); "
                    f"got {jnp.shape(getattr(self, name))}"
                )
        for name, unit in (("f_res", "Hz"), ("q_res", ""), ("a_sat_g", "g"), ("tau_s", "s")):
            x = getattr(self, name)
            try:
                v = float(x)
            except Exception:  # traced (vmap/grad over parameters): values not checkable
                continue
            if not v > 0:
                raise ValueError(
                    f"VibrationError.{name} must be > 0 {unit}".rstrip() + f"; got {v}"
                )

    def coil_gain(self, freq_hz):
        """|H(f)|² of the coil resonance (1 at f = 0, Q² at f_r)."""
        r = jnp.asarray(freq_hz) / self.f_res
        return 1.0 / ((1.0 - r**2) ** 2 + (r / self.q_res) ** 2)

    def steady(self, freq_hz, amp_g):
        """Steady rectified gyro drift ε_ss (..., 3) [rad/s] at `freq_hz`, `amp_g` (...)."""
        u = jnp.asarray(amp_g) ** 2 * self.coil_gain(freq_hz)
        sat = u / (1.0 + u / self.a_sat_g**2)
        return sat[..., None] * self.rectification.reshape((1,) * sat.ndim + (3,))


class FogImu(eqx.Module):
    """A strapdown FOG IMU: `gyro` and `accel` static models
    ([`TriadCalibration`][hrgjax.imu.triad.TriadCalibration]; gyro bias in rad/s,
    accelerometer bias in m/s²), its `vibration` error, white noise `arw` [rad/√s] and
    `vrw` [m/s/√s]."""

    gyro: TriadCalibration
    accel: TriadCalibration
    vibration: VibrationError
    arw: jax.Array
    vrw: jax.Array

    def __check_init__(self):
        # a noise density < 0, NaN or a bias in °/s read as rad/s simulated without a word
        for name, value, quantity in (
            ("arw [rad/√s]", self.arw, "imu_arw"), ("vrw [m/s/√s]", self.vrw, "imu_vrw"),
            ("gyro.bias [rad/s]", self.gyro.bias, "imu_gyro_bias"),
            ("accel.bias [m/s²]", self.accel.bias, "imu_accel_bias"),
        ):  # fmt: skip
            v = concrete_value(value)
            if v is not None and not np.all(np.isfinite(v)):
                raise ValueError(f"FogImu.{name} must be finite; got {v}")
            if v is not None:
                plausible.check(f"FogImu.{name}", v, quantity)


def default_imu() -> FogImu:
    """The built-in navigation-grade FOG IMU (module docstring; the numbers are typical of a
    0.01 °/h class system, chosen so that the vibration drift, not noise, limits alignment)."""
    gyro = TriadCalibration.known(
        angles=jnp.array([2.0, -1.5, 1.0, 2.5, -2.0, 1.5]) * ARCMIN,
        scale=jnp.array([30e-6, -20e-6, 10e-6]),
        bias=jnp.array([0.008, -0.01, 0.006]) * DEG_PER_H,
    )
    accel = TriadCalibration.known(
        angles=jnp.array([-1.0, 2.0, 1.5, -2.5, 1.0, 2.0]) * ARCMIN,
        scale=jnp.array([-50e-6, 40e-6, 60e-6]),
        bias=jnp.array([50e-6, -30e-6, 80e-6]) * G0,
    )
    vib = VibrationError(
        rectification=jnp.array([0.25, 0.35, -0.2]) * DEG_PER_H,
        g_sensitivity=jnp.array([0.5, 0.3, 0.2]) * DEG_PER_H,
        f_res=jnp.asarray(25.0),
        q_res=jnp.asarray(2.5),
        a_sat_g=jnp.asarray(2.0),
        tau_s=jnp.asarray(20.0),
        accel_k2=jnp.array([20e-6, 20e-6, 30e-6]) / G0,
    )
    return FogImu(gyro, accel, vib, jnp.asarray(0.0005 * DEG_PER_SQRT_H), jnp.asarray(2e-5))


class VibrationRecord(eqx.Module):
    """Simulated raw IMU output on the table. **Fields:** `t` (N,) [s] (sample times k/fs);
    `gyro` (N, 3) [rad/s] and `accel` (N, 3) [m/s²]: raw outputs in sensor axes;
    `gyro_error` (N, 3) [rad/s]: the noise-free gyro vibration error in sensor axes (truth);
    `freq_hz`, `amp_g` (N,): the table's condition; `c_bn` (3, 3): the true attitude;
    `fs` [Hz], `lat` [rad] (static)."""

    t: jax.Array
    gyro: jax.Array
    accel: jax.Array
    gyro_error: jax.Array
    freq_hz: jax.Array
    amp_g: jax.Array
    c_bn: jax.Array
    fs: float = eqx.field(static=True)
    lat: float = eqx.field(static=True)


def _lag(ss, a):
    """x_0 = (1 − a) ss_0, x_n = a x_{n−1} + (1 − a) ss_n along axis 0 (associative scan)."""
    b = (1.0 - a) * ss
    aa = jnp.full(ss.shape, a, ss.dtype)

    def combine(p, q):
        return p[0] * q[0], q[0] * p[1] + q[1]

    return jax.lax.associative_scan(combine, (aa, b))[1]


def simulate(
    imu: FogImu,
    schedule: VibrationSchedule,
    *,
    fs: float = 200.0,
    key: jax.Array,
    lat_deg: float = 45.0,
    attitude_deg=(0.0, 0.0, 0.0),
) -> VibrationRecord:
    """Raw outputs of `imu` on the table running `schedule`, sampled at `fs` [Hz], at
    latitude `lat_deg`, body attitude `attitude_deg` = (roll, pitch, heading) [°] (heading
    clockwise from north; FRD body). `key` drives the sensor noise.

    **Raises:** `ValueError` when a vibration frequency is not below the Nyquist frequency,
    the schedule is shorter than two samples at `fs`, or the arguments are malformed; `RuntimeError` when float64 is off."""
    require_x64("fog.vibration.simulate")
    if not fs > 0:
        raise ValueError(f"fs must be > 0 Hz; got {fs}")
    if max(schedule.freq_hz) >= fs / 2:
        raise ValueError(
            f"schedule frequency {max(schedule.freq_hz)} Hz must be below the Nyquist "
            f"frequency fs/2 = {fs / 2} Hz"
        )
    if not -90.0 <= lat_deg <= 90.0:
        raise ValueError(f"lat_deg must be in [-90, 90]; got {lat_deg}")
    att = np.asarray(attitude_deg, float)
    if att.shape != (3,) or not np.all(np.isfinite(att)):
        raise ValueError(
            f"attitude_deg must be (roll, pitch, heading) in degrees; got {attitude_deg}"
        )
    freq, amp = schedule.samples(fs)
    if freq.size < 2:  # it returned (0, 3) arrays: a record of nothing
        raise ValueError(
            f"schedule lasts {schedule.duration_s:g} s: {freq.size} sample(s) at fs = {fs:g} Hz; "
            "a record needs at least 2 (a longer schedule or a higher fs)"
        )
    c_bn = euler_to_dcm(*(jnp.asarray(x * DEG) for x in att))
    gyro, accel, err = _run(
        imu, jnp.asarray(freq), jnp.asarray(amp), jnp.asarray(schedule.axis), float(fs), key,
        device(lat_deg * DEG, float), c_bn,  # an array: a new latitude, no new program
    )  # fmt: skip
    return VibrationRecord(
        jnp.asarray(np.arange(freq.size) / fs), gyro, accel, err, jnp.asarray(freq), jnp.asarray(amp),
        c_bn, float(fs), lat_deg * DEG,
    )  # fmt: skip


@eqx.filter_jit
def _run(imu, freq, amp, axis, fs, key, lat, c_bn):
    """(gyro, accel, gyro_error) (N, 3) each, in sensor axes."""
    n = freq.shape[0]
    dt = 1.0 / fs
    lat_a = jnp.asarray(lat)
    g_n = WGS84.gravity_ned(lat_a, jnp.asarray(0.0))
    f_b = c_bn.T @ (-g_n)
    w_b = c_bn.T @ earth_rate_ned(lat_a)
    theta = 2.0 * jnp.pi * jnp.concatenate([jnp.zeros(1), jnp.cumsum(freq[:-1]) * dt])
    a_vib = amp * G0 * jnp.sin(theta)  # (N,) [m/s²] along `axis`
    vib = imu.vibration
    ss = vib.steady(freq, amp)  # (N, 3)
    drift = _lag(ss, jnp.exp(-dt / vib.tau_s))
    err = drift + (a_vib / G0).reshape(n, 1) * vib.g_sensitivity.reshape(1, 3)
    kg, ka = jax.random.split(key)
    ones = jnp.ones((n, 1))
    w_s = imu.gyro.sensor(ones * w_b.reshape(1, 3)) + err
    w_s = w_s + imu.arw * math.sqrt(fs) * jax.random.normal(kg, (n, 3))
    f_body = ones * f_b.reshape(1, 3) + a_vib.reshape(n, 1) * axis.reshape(1, 3)
    a_s = imu.accel.sensor(f_body)
    a_along = a_vib.reshape(n, 1) * (imu.accel.matrix @ axis).reshape(1, 3)
    a_s = a_s + vib.accel_k2.reshape(1, 3) * a_along**2
    a_s = a_s + imu.vrw * math.sqrt(fs) * jax.random.normal(ka, (n, 3))
    return w_s, a_s, err


@fused(static_argnames=("fs", "window_s"))
def window_means(x, fs: float, window_s: float):
    """Means of `x` (..., N, c) over consecutive windows of `window_s` [s] → (..., K, c);
    a partial last window is left out (K = N // (window_s·fs))."""
    fs = finite_number("window_means: fs", fs, "Hz")
    window_s = finite_number("window_means: window_s", window_s, "s")
    if fs <= 0 or window_s <= 0:
        raise ValueError(f"window_means: fs and window_s must be > 0; got fs = {fs:g} Hz, "
                         f"window_s = {window_s:g} s")  # fmt: skip
    if np.ndim(x) < 2:
        raise ValueError(f"window_means: x must be (..., N, c) samples × channels; got shape "
                         f"{np.shape(x)} (one channel: x[:, None])")  # fmt: skip
    m = int(round(window_s * fs))
    if m < 1:
        raise ValueError(f"window_s·fs must be >= 1 sample; got {window_s}·{fs}")
    n = x.shape[-2]
    k = n // m
    if k < 1:
        raise ValueError(f"the record ({n} samples) is shorter than one window ({m} samples)")
    x = x[..., : k * m, :]
    return jnp.mean(x.reshape(x.shape[:-2] + (k, m, x.shape[-1])), axis=-2)


def error_samples(imu: FogImu, vibrating: VibrationRecord, static: VibrationRecord, window_s=2.0):
    """The patent's vibration-error samples: vibrating − static gyro output per window of
    `window_s`, mapped to the orthogonal (body) frame by the gyro triad's linear map —
    (K, 3) [rad/s]. The two records must share rate, length, attitude (`c_bn`) and
    latitude: the Earth rate each gyro senses depends on both, so records at two headings
    differed by a spurious "vibration error" (a `ValueError` names the mismatch)."""
    if vibrating.gyro.shape != static.gyro.shape or vibrating.fs != static.fs:
        raise ValueError(
            "vibrating and static records must have the same length and rate; got "
            f"{vibrating.gyro.shape} at {vibrating.fs} Hz and {static.gyro.shape} at {static.fs} Hz"
        )
    c_v, c_s = concrete_value(vibrating.c_bn), concrete_value(static.c_bn)
    if c_v is not None and c_s is not None and not np.allclose(c_v, c_s, rtol=0.0, atol=1e-9):
        raise ValueError(
            "vibrating and static records must have the same attitude c_bn; they differ by up "
            f"to {np.abs(c_v - c_s).max():.3g} (simulate both with the same attitude_deg)"
        )
    if not np.isclose(vibrating.lat, static.lat, rtol=0.0, atol=1e-12):
        raise ValueError(
            "vibrating and static records must have the same latitude lat [rad]; got "
            f"{vibrating.lat:.9g} and {static.lat:.9g}"
        )
    d = window_means(vibrating.gyro - static.gyro, vibrating.fs, window_s)
    return to_body(imu.gyro, d)


def _check_triad(fn: str, calib, name: str, x, frame: str) -> None:
    """Refuse, in one line naming `fn`, a `calib` that is not a `TriadCalibration` or an `x`
    that is not real numbers of shape (..., 3) (a (n, 2) or (n, 4) array raised JAX's
    dot_general error; a FogImu raised an AttributeError)."""
    if not isinstance(calib, TriadCalibration):
        raise TypeError(f"{fn}: calib must be a TriadCalibration (e.g. imu.gyro or imu.accel); "
                        f"got {type(calib).__name__}")  # fmt: skip
    form = f"{frame} values of shape (..., 3)"
    problem = numeric_problem(x)
    if problem is not None:
        raise TypeError(f"{fn}: {name} must be {form}; got {problem}")
    shape = tuple(np.shape(x))
    if len(shape) < 1 or shape[-1] != 3:
        raise ValueError(f"{fn}: {name} must be {form}; got shape {shape}")


def to_body(calib: TriadCalibration, s):
    """Sensor-axis increments `s` (..., 3) → body frame by the linear part of the triad model,
    (diag(1+k)(I+E))⁻¹ (no bias: for differences and errors)."""
    _check_triad("to_body", calib, "s", s, "sensor-axis")
    return _to_body(calib, s)


@fused
def _to_body(calib, s):
    return jnp.asarray(s) @ jnp.linalg.inv(calib.matrix).T


def to_sensor(calib: TriadCalibration, b):
    """Body-frame errors `b` (..., 3) → sensor axes, diag(1+k)(I+E) b (no bias)."""
    _check_triad("to_sensor", calib, "b", b, "body-frame")
    return _to_sensor(calib, b)


@fused
def _to_sensor(calib, b):
    return jnp.asarray(b) @ calib.matrix.T
