"""A simulated Ferraris session: a six-axis IMU with a known calibration, put on its six
faces and turned once about each axis, with rigid-body kinematics between the positions.

For rehearsing a bench procedure, testing detection and checking that a calibration's
standard errors hold (the truth is known)."""

from __future__ import annotations

import jax
import numpy as np

from .._checks import check_key, describe, finite_number, whole_number
from .._x64 import require_x64
from ..units import DEG, EARTH_RATE
from ._calibration import ImuCalibration, check_g
from ._earth import check_lat_deg
from .data import ImuData
from .sections import FACES, TURNS, Sections

_UP = np.array([0.0, 0.0, 1.0])


def face_attitude(key: str) -> np.ndarray:
    """Attitude C (3, 3) of face `key` ("x_p" … "z_a"): columns are the sensor axes in a
    world frame with z up (sensor axis i up or down, the next axis east)."""
    if not isinstance(key, str) or key not in FACES:  # "q_p": "substring not found"
        raise ValueError(f"key must be a face, one of {', '.join(FACES)}; got {describe(key)}")
    i, sign = "xyz".index(key[0]), 1.0 if key.endswith("_p") else -1.0
    c = np.zeros((3, 3))
    c[:, i] = sign * _UP
    c[:, (i + 1) % 3] = [1.0, 0.0, 0.0]
    c[:, (i + 2) % 3] = np.cross(c[:, i], c[:, (i + 1) % 3])
    return c


def _check_session(truth, key, rate_hz, static_s, move_s, turn_s, gyro_noise, accel_noise,
                   gyro_walk, accel_walk, turn_deg) -> None:  # fmt: skip
    """`ferraris_session`'s arguments, each refused in one line naming it (a rate of 0 was a
    ZeroDivisionError, NaN "cannot convert float NaN to integer", a negative duration two
    samples, a negative σ a silent |σ|)."""
    if not isinstance(truth, ImuCalibration):
        raise TypeError(f"truth must be an hg.imu.ImuCalibration; got {type(truth).__name__}")
    check_key("key", key)
    for name, value, unit, least in (
        ("rate_hz", rate_hz, "Hz", 0), ("static_s", static_s, "s", 0), ("move_s", move_s, "s", 0),
        ("turn_s", turn_s, "s", 0), ("gyro_noise", gyro_noise, "rad/s", None),
        ("accel_noise", accel_noise, "m/s²", None), ("gyro_walk", gyro_walk, "rad/s/√s", None),
        ("accel_walk", accel_walk, "m/s²/√s", None),
    ):  # fmt: skip
        v = finite_number(name, value, unit)
        if (least is not None and v <= least) or v < 0:
            raise ValueError(f"{name} must be {'> 0' if least is not None else '>= 0'} [{unit}]; "
                             f"got {v}")  # fmt: skip
    if finite_number("turn_deg", turn_deg, "°") == 0:
        raise ValueError("turn_deg must be a non-zero angle [°], e.g. 360 or -360; got 0")


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _axis_angle(r: np.ndarray) -> tuple[np.ndarray, float]:
    angle = float(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)))
    if angle < 1e-12:
        return np.array([1.0, 0.0, 0.0]), 0.0
    if np.pi - angle < 1e-6:
        b = (r + np.eye(3)) / 2
        i = int(np.argmax(np.diag(b)))
        return b[:, i] / np.sqrt(b[i, i]), angle
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    return v / (2 * np.sin(angle)), angle


def _turn(c0, axis, angle, n, rate_hz, g):
    """Samples of a smooth turn of `angle` [rad] about the body `axis`, starting at rest in
    attitude `c0` and ending at rest: rate (1 − cos) shaped, so that its n-sample rectangle
    sum is exactly `angle`. Returns ω (n, 3) [rad/s], a (n, 3) [m/s²], final attitude and
    the attitudes (n, 3, 3)."""
    t = np.arange(n) / rate_hz
    period = n / rate_hz
    phi = angle * (t / period - np.sin(2 * np.pi * t / period) / (2 * np.pi))
    dphi = angle / period * (1 - np.cos(2 * np.pi * t / period))
    omega = dphi[:, None] * axis[None, :]
    att = np.stack([c0 @ _rotation(axis, p) for p in phi])
    accel = np.stack([a.T @ (g * _UP) for a in att])
    return omega, accel, c0 @ _rotation(axis, angle), att


def _face_attitudes(headings) -> dict[str, np.ndarray]:
    """Each face's attitude: `face_attitude`'s, turned about the vertical by the face's
    heading [°] (`ferraris_session`'s `face_headings_deg`)."""
    if headings is None:
        return {k: face_attitude(k) for k in FACES}
    form = ("None, a mapping of face keys (x_p … z_a) to angles [°] about the vertical, or six "
            "such angles in the order x_p, x_a, y_p, y_a, z_p, z_a")  # fmt: skip
    if isinstance(headings, dict):
        unknown = sorted(set(headings) - set(FACES), key=str)
        if unknown:
            raise ValueError(f"face_headings_deg must be {form}; got the keys {unknown!r}")
        values = [headings.get(k, 0.0) for k in FACES]
    else:
        values = headings
    if isinstance(values, str | bytes) or np.ndim(values) != 1 or len(values) != len(FACES):
        raise ValueError(f"face_headings_deg must be {form}; got {headings!r}")
    try:
        psi = np.array([float(v) for v in values]) * DEG
    except (TypeError, ValueError):
        raise ValueError(f"face_headings_deg must be {form}; got {headings!r}") from None
    if not np.all(np.isfinite(psi)):
        raise ValueError(f"face_headings_deg must be {form} (finite); got {headings!r}")
    return {k: _rotation(_UP, p) @ face_attitude(k) for k, p in zip(FACES, psi, strict=True)}


def _bias_drift(key, n: int, rate_hz: float, walk: np.ndarray, tau_s: float | None) -> np.ndarray:
    """(n, 6) bias drift, zero on the first sample: a random walk of intensity `walk` (6,)
    [unit/√s] per channel, or a first-order Gauss–Markov process with that driving noise
    and correlation time `tau_s` [s] (exact discretisation)."""
    dt = 1.0 / rate_hz
    eps = np.asarray(jax.random.normal(key, (n - 1, 6), dtype=float))
    if tau_s is None:
        steps = walk * np.sqrt(dt) * eps
        return np.concatenate([np.zeros((1, 6)), np.cumsum(steps, axis=0)])
    if not (np.isfinite(tau_s) and tau_s > 0):
        raise ValueError(f"drift_tau_s must be a positive time [s] or None; got {tau_s!r}")
    phi = np.exp(-dt / tau_s)
    step = walk * np.sqrt(tau_s / 2 * (1 - phi**2))
    out = np.zeros((n, 6))
    for k in range(1, n):
        out[k] = phi * out[k - 1] + step * eps[k - 1]
    return out


def ferraris_session(
    truth: ImuCalibration,
    key: jax.Array,
    *,
    rate_hz: float = 100.0,
    static_s: float = 6.0,
    move_s: float = 2.0,
    turn_s: float = 4.0,
    repeats: int = 1,
    gyro_noise: float = 1e-3,
    accel_noise: float = 0.01,
    g: float = 9.81,
    turn_deg: float = 360.0,
    gyro_walk: float = 0.0,
    accel_walk: float = 0.0,
    drift_tau_s: float | None = None,
    lat_deg: float | None = None,
    face_headings_deg=None,
) -> tuple[ImuData, Sections]:
    """Simulate a Ferraris session of an IMU whose sensors follow `truth`.

    The IMU rests `static_s` [s] on each face x_p, x_a, y_p, y_a, z_p, z_a, then, for each
    axis, goes to that axis's `p` face, rests `move_s`, turns `turn_deg` [°] about the axis
    in `turn_s` [s] and rests `move_s`; between positions it rotates in `move_s` [s] about a
    fixed body axis. The whole sequence runs `repeats` times. Noise: white, `gyro_noise`
    [rad/s] and `accel_noise` [m/s²] per sample (σ), drawn from `key`; and, where
    `gyro_walk` [rad/s/√s] or `accel_walk` [m/s²/√s] is set, an in-run drift of every
    channel's bias: a random walk of that intensity (`drift_tau_s` None), or a first-order
    Gauss–Markov process with that driving noise and correlation time `drift_tau_s` [s]
    (steady-state σ = walk·√(τ/2)). The drift is zero at the session's start (the first
    face's first row), so that `truth`'s biases are those at the start of the session.

    `lat_deg` [°] (None, the default: no Earth's rate, as before): the bench turns with the
    Earth at that latitude, and the gyros sense its rate, 7.292115e-5 rad/s, along every
    sample's attitude (world frame x east, y north, z up; the faces' attitudes are
    [`face_attitude`][hrgjax.imu.face_attitude]'s: each face's next axis east, so
    each ± pair reverses the horizontal rate, the largest it can do to G, and none of it
    reaches the pair sums, b_g).

    `face_headings_deg` (None, the default: `face_attitude`'s placements): each face's
    attitude turned about the vertical by ψ [°] (counterclockwise seen from above: east
    towards north), as a mapping face key → ψ (keys left out: 0) or six angles in the
    order x_p, x_a, y_p, y_a, z_p, z_a. The faces' headings decide where the Earth's
    horizontal rate goes: with h± its body vector on face i±, (h⁺ − h⁻)/2 into G's column
    i and (h⁺ + h⁻)/2 into the pair sum, so that b_g reads M_g Σ h / 6 over the six faces.
    E.g. `{"x_p": 90, "x_a": 90, "z_a": 180}` keeps the y axis north on the x and z
    faces (a tumble about north: those pairs keep the rate, b_g's y reads 2Ω cos φ / 3,
    twice the σ `ferraris` gives it; the y pair still reverses it into G); random angles
    model a bench whose headings are free.

    **Returns:** `(data, sections)`: the record (`ImuData`, SI) and its true sections
    (faces: the rests; turns: the turn with half of each neighbouring rest)."""
    require_x64("hg.imu.ferraris_session")
    _check_session(truth, key, rate_hz, static_s, move_s, turn_s, gyro_noise, accel_noise,
                   gyro_walk, accel_walk, turn_deg)  # fmt: skip
    repeats = whole_number("repeats", repeats, "a positive integer")  # 1.5, "2": raw errors
    if repeats < 1:
        raise ValueError(f"repeats must be a positive integer; got {repeats!r}")
    g = check_g(g)  # g ≤ 0 simulated an upside-down session ferraris then refuses
    n_static, n_move, n_turn = (max(int(round(s * rate_hz)), 2) for s in (static_s, move_s, turn_s))
    lat = None if lat_deg is None else check_lat_deg(lat_deg) * DEG
    attitudes = _face_attitudes(face_headings_deg)
    omega, accel, attitude = [], [], []
    sections: Sections = {k: [] for k in (*FACES, *TURNS)}
    count = 0
    c = attitudes["z_p"]

    def add(w, a, att):
        nonlocal count
        omega.append(w)
        accel.append(a)
        attitude.append(att)
        count += w.shape[0]

    def rest(n):
        a = c.T @ (g * _UP)
        add(np.zeros((n, 3)), np.tile(a, (n, 1)), np.broadcast_to(c, (n, 3, 3)))

    def go_to(face):
        nonlocal c
        target = attitudes[face]
        axis, angle = _axis_angle(c.T @ target)
        if angle == 0.0:
            return
        w, a, _, att = _turn(c, axis, angle, n_move, rate_hz, g)
        add(w, a, att)
        c = target

    for _ in range(repeats):
        for face in FACES:
            go_to(face)
            start = count
            rest(n_static)
            sections[face].append((start, count))
        for i, turn in enumerate(TURNS):
            go_to(f"{'xyz'[i]}_p")
            rest(n_move)
            start = count - n_move // 2
            w, a, c, att = _turn(c, np.eye(3)[i], np.deg2rad(turn_deg), n_turn, rate_hz, g)
            add(w, a, att)
            rest(n_move)
            sections[turn].append((start, count - n_move + n_move // 2))
    w_true = np.concatenate(omega)
    a_true = np.concatenate(accel)
    if lat is not None:  # the Earth's rate (east, north, up) seen along each sample's attitude
        earth = EARTH_RATE * np.array([0.0, np.cos(lat), np.sin(lat)])
        w_true = w_true + np.einsum("nji,j->ni", np.concatenate(attitude), earth)
    w_s, a_s = (np.asarray(x) for x in truth.sensor(w_true, a_true))
    kg, ka, kd = jax.random.split(key, 3)
    w_s = w_s + gyro_noise * np.asarray(jax.random.normal(kg, w_s.shape, dtype=float))
    a_s = a_s + accel_noise * np.asarray(jax.random.normal(ka, a_s.shape, dtype=float))
    if gyro_walk or accel_walk:
        walk = np.repeat([float(gyro_walk), float(accel_walk)], 3)
        drift = _bias_drift(kd, count, rate_hz, walk, drift_tau_s)
        drift = drift - drift[sections[FACES[0]][0][0]]
        w_s, a_s = w_s + drift[:, :3], a_s + drift[:, 3:]
    data = ImuData(np.arange(count) / rate_hz, w_s, a_s, rate_hz=rate_hz)
    return data, sections
