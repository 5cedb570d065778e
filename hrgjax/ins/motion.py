r"""Trajectories from a motion definition, with exact IMU increments.

A [`Motion`][hrgjax.ins.motion.Motion] is an initial state and a list of segments, as in
gnss-ins-sim's motion files: in each segment the Euler angles (yaw, pitch, roll, 3-2-1) and
the velocity in the body frame (x forward, y right, z down) change at constant rates, so the
vehicle's attitude and Earth-referenced velocity $v^n = C_b^n v^b$ are known in closed form at
every instant ([`Motion.kinematics`][hrgjax.ins.motion.Motion.kinematics]). Segment commands
(column `command type`):

| type | yaw, pitch, roll | vx, vy, vz (body) |
|---|---|---|
| 1 | rates [°/s] | rates [m/s²] |
| 2 | absolute angles [°] reached at the segment's end | absolute velocity [m/s] reached at its end |
| 3 | changes [°] over the segment | changes [m/s] over the segment |
| 4 | absolute [°] | changes [m/s] |
| 5 | changes [°] | absolute [m/s] |

Types 2–5 reach their targets at a constant rate over the whole segment (gnss-ins-sim
reaches them at its configured maximum rates, then holds); an absolute heading is reached
by the shorter turn. Each segment's duration must be a whole number of samples.

[`Motion.truth`][hrgjax.ins.motion.Motion.truth] samples the motion at the IMU rate and makes
the **exact increments**: those that the strapdown integrator
([`mechanize`][hrgjax.ins.mechanization.mechanize]) carries exactly through the sampled
attitudes and velocities ([`increments_from_states`][hrgjax.ins.mechanization.increments_from_states]),
with the positions the integrator's trapezoid gives. Free integration of them returns the
trajectory at round-off, so a navigation error computed from perturbed increments is the
sensors' alone. They equal the physical integrals $\int\omega_{ib}^b\,dt$, $\int f^b\,dt$ to
the two-sample algorithm's own error (≈ (ωΔt)²/12 where a rate changes axis abruptly,
O(Δt³) elsewhere; tests/test_navigation.py measures both).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import numbers
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import describe, finite_number, whole_number
from .._x64 import require_x64
from ..units import DEG
from .constants import WGS84, Earth
from .mechanization import NavState, euler_to_quat, increments_from_states, quat_to_dcm
from .trajectory import Trajectory, check_latitudes, check_path_heights, check_position

_HEAD_INIT = (
    "ini lat (deg),ini lon (deg),ini alt (m),ini vx_body (m/s),ini vy_body (m/s),"
    "ini vz_body (m/s),ini yaw (deg),ini pitch (deg),ini roll (deg)"
)
_HEAD_CMD = (
    "command type,yaw (deg),pitch (deg),roll (deg),vx_body (m/s),vy_body (m/s),"
    "vz_body (m/s),command duration (s),GPS visibility"
)


def _triple(name, x, what, unit):
    """`x` as 3 finite floats, or a one-line error naming `name`."""
    try:
        n = len(x)
    except TypeError:
        n = None
    if n != 3:
        raise ValueError(f"{name} must be 3 values {what} [{unit}]; got {x!r}")
    return np.array([finite_number(name, v, unit) for v in x])


_INIT_COLUMNS = tuple((c,) for c in _HEAD_INIT.split(","))
_CMD_COLUMNS = tuple(
    (c, "reserved") if c.startswith(("vy_body", "vz_body", "GPS")) else (c,)
    for c in _HEAD_CMD.split(",")
)
"""The accepted names of each header column (module docstring, `Motion.from_csv`)."""


def _column_name(x: str) -> str:
    """A header cell without case, spacing or a trailing "(unit)"."""
    x = " ".join(x.lower().split())
    return x[: x.index("(")].rstrip() if x.endswith(")") and "(" in x else x


def _check_header(path, line, row, columns, layout, which):
    """A one-line `ValueError` naming the first header cell of `row` that is not the
    gnss-ins-sim column expected there (the GPS visibility column may be left out)."""
    row = list(row)
    while row and not row[-1].strip():
        row.pop()
    optional = 1 if which == "command" else 0
    for j, names in enumerate(columns, 1):
        want = " or ".join(repr(n) for n in names)
        if j > len(row):
            if j > len(columns) - optional:
                return
            got = "missing"
        elif _column_name(row[j - 1]) in {_column_name(n) for n in names}:
            continue
        else:
            got = f"{row[j - 1]!r}"
        semi = any(";" in x for x in row)
        hint = " (the cells are separated by ';': use commas)" if semi else ""
        raise ValueError(
            f"{path}:{line}: header column {j} is {got}, expected {want}{hint}: the {which} "
            f"header of a gnss-ins-sim motion file is {layout}"
        )
    if len(row) > len(columns):
        raise ValueError(
            f"{path}:{line}: header column {len(columns) + 1} ({row[len(columns)]!r}) is not "
            f"in the layout: the {which} header of a gnss-ins-sim motion file is {layout}"
        )


@dataclasses.dataclass(frozen=True)
class Segment:
    """One motion command (module docstring's table): `kind` 1–5; `attitude` (yaw, pitch,
    roll) [° or °/s]; `velocity` (vx, vy, vz) body [m/s or m/s²]; `duration` [s]; `gnss`:
    whether GNSS is visible during it."""

    kind: int
    attitude: tuple[float, float, float]
    velocity: tuple[float, float, float]
    duration: float
    gnss: bool = True


@dataclasses.dataclass(frozen=True)
class Motion:
    """A motion definition (module docstring).

    **Fields:** `lat_deg`, `lon_deg` [°], `h` [m above the ellipsoid]; `velocity` initial
    body-frame velocity (3,) [m/s]; `yaw_deg`, `pitch_deg`, `roll_deg` initial attitude [°];
    `segments` a tuple of [`Segment`][hrgjax.ins.motion.Segment]."""

    lat_deg: float
    lon_deg: float
    h: float
    velocity: tuple[float, float, float]
    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    segments: tuple[Segment, ...]

    def __post_init__(self):
        check_position(self.lat_deg, self.lon_deg, self.h, "Motion.")
        v0 = _triple("Motion.velocity", self.velocity, "(vx, vy, vz) body", "m/s")
        for name in ("yaw_deg", "pitch_deg", "roll_deg"):
            finite_number(f"Motion.{name}", getattr(self, name), "°")
        if abs(self.pitch_deg) >= 89.0:
            raise ValueError(
                f"Motion.pitch_deg must be within ±89° (Euler angles are singular at ±90°); got "
                f"{self.pitch_deg}"
            )
        if not self.segments:
            raise ValueError("Motion.segments: give at least one segment")
        for i, s in enumerate(self.segments, 1):
            if not isinstance(s, Segment):
                raise TypeError(
                    f"Motion segment {i}: expected a motion.Segment; got {type(s).__name__}"
                )
            if s.kind not in (1, 2, 3, 4, 5):
                raise ValueError(f"Motion segment {i}: command type must be 1-5; got {s.kind}")
            d = finite_number(f"Motion segment {i}: duration", s.duration, "s")
            if d <= 0:
                raise ValueError(f"Motion segment {i}: duration must be > 0 s; got {s.duration}")
            plausible.check(f"Motion segment {i}: duration", d, "duration_s")
            _triple(f"Motion segment {i}: attitude", s.attitude, "(yaw, pitch, roll)", "° or °/s")
            _triple(f"Motion segment {i}: velocity", s.velocity, "(vx, vy, vz) body",
                    "m/s or m/s²")  # fmt: skip
        plausible.check("Motion.velocity: the initial speed", np.linalg.norm(v0), "speed_mps")
        _, _, ends = self._rates()
        speed = np.linalg.norm(ends[:, 3:], axis=1)  # |v| along a segment peaks at an end
        for i, s in enumerate(speed):  # (an acceleration in another unit, for one)
            plausible.check(f"Motion: the speed by the end of segment {i + 1}", s, "speed_mps")
        if np.any(np.abs(ends[:, 1]) >= 89.0 * DEG):
            bad = int(np.argmax(np.abs(ends[:, 1]) >= 89.0 * DEG))
            raise ValueError(
                f"Motion: the pitch reaches ±89° by the end of segment {bad + 1} (Euler angles are "
                "singular at ±90°)"
            )

    # --- reading and writing ---------------------------------------------------------

    @classmethod
    def from_csv(cls, path) -> Motion:
        """Read a gnss-ins-sim motion file: a header line, the initial state (lat, lon [°],
        alt [m], body velocity [m/s], yaw, pitch, roll [°]), a header line, then one command
        per line (type, three attitude values, three velocity values, duration [s], GNSS
        visibility 0/1, optional).

        The two header lines must name gnss-ins-sim's columns in its order, as `to_csv`
        writes them (docs/navigation.md lists both). The names are compared without case,
        spacing or the unit in parentheses (gnss-ins-sim's own files label the command
        angles "(rad)" while holding degrees: the values are read in the units above,
        whatever the label), and a command column vy_body, vz_body or GPS visibility may be
        headed "reserved", as in gnss-ins-sim's older files.

        **Raises:** `ValueError` starting with the path and the line: a header naming other
        columns (the first that differs and what was expected), a row that is not numbers,
        or a value `Motion` refuses."""
        try:
            text = Path(path).read_text(encoding="utf-8-sig")
        except UnicodeDecodeError:
            raise ValueError(f"{path}: not a UTF-8 text file (a gnss-ins-sim motion CSV)") from None
        rows = [(i, r) for i, r in enumerate(csv.reader(text.splitlines()), 1) if any(r)]
        if len(rows) < 4:
            raise ValueError(
                f"{path}: a motion file needs a header, the initial state, a header and at "
                "least one command"
            )

        def semicolons(row):
            return " (separated by ';': use commas)" if any(";" in x for x in row) else ""

        def numbers(row, line, n):
            try:
                vals = [float(x) for x in row]
            except ValueError:
                raise ValueError(
                    f"{path}:{line}: expected numbers; got {row}{semicolons(row)}"
                ) from None
            if len(vals) not in n:
                raise ValueError(
                    f"{path}:{line}: expected {n[-1]} values; got {len(vals)}{semicolons(row)}"
                )
            return vals

        _check_header(path, *rows[0], _INIT_COLUMNS, _HEAD_INIT, "initial-state")
        _check_header(path, *rows[2], _CMD_COLUMNS, _HEAD_CMD, "command")
        ini_line, ini = rows[1][0], numbers(rows[1][1], rows[1][0], (9,))
        segs, lines = [], []
        for line, row in rows[3:]:
            v = numbers(row, line, (8, 9))
            if v[0] not in (1, 2, 3, 4, 5):
                raise ValueError(f"{path}:{line}: command type must be 1-5; got {v[0]:g}")
            if len(v) > 8 and v[8] not in (0, 1):
                raise ValueError(f"{path}:{line}: GPS visibility must be 0 or 1; got {v[8]:g}")
            lines.append(line)
            segs.append(
                Segment(
                    int(v[0]), tuple(v[1:4]), tuple(v[4:7]), v[7], bool(v[8] if len(v) > 8 else 1)
                )
            )
        try:
            return cls(ini[0], ini[1], ini[2], tuple(ini[3:6]), ini[6], ini[7], ini[8], tuple(segs))
        except ValueError as err:  # name the line: the initial state's or the command's
            msg = str(err)
            where = ini_line if msg.startswith("Motion.") else None
            if msg.startswith("Motion segment "):
                where = lines[int(msg.split()[2].rstrip(":")) - 1]
            at = f"{path}:{where}" if where is not None else f"{path}"
            raise ValueError(f"{at}: {msg}") from None

    def to_csv(self, path) -> None:
        """Write the motion as a gnss-ins-sim motion file, every number exactly (`repr`: the
        shortest text that reads back as the same float, so `from_csv` returns an equal
        `Motion`), atomically (missing folders are made)."""
        from .._io import atomic_write

        def g(x):
            return str(int(x)) if isinstance(x, numbers.Integral) else repr(float(x))

        lines = [
            _HEAD_INIT,
            ",".join(
                g(x)
                for x in (self.lat_deg, self.lon_deg, self.h, *self.velocity)
                + (self.yaw_deg, self.pitch_deg, self.roll_deg)
            ),
            _HEAD_CMD,
        ]
        for s in self.segments:
            vals = (s.kind, *s.attitude, *s.velocity, s.duration, int(s.gnss))
            lines.append(",".join(g(x) for x in vals))
        with atomic_write(path, "w", encoding="utf-8") as fh:
            fh.write("\n".join(lines) + "\n")

    # --- kinematics ------------------------------------------------------------------

    @property
    def duration(self) -> float:
        """Total duration [s]."""
        return float(sum(s.duration for s in self.segments))

    def _rates(self):
        """Per segment: start (yaw, pitch, roll, vx, vy, vz) [rad, m/s], rates, end values."""
        cur = np.array(
            [self.yaw_deg * DEG, self.pitch_deg * DEG, self.roll_deg * DEG, *self.velocity]
        )
        starts, rates = [], []
        for s in self.segments:
            att = np.asarray(s.attitude) * DEG
            vel = np.asarray(s.velocity, float)
            if s.kind == 1:
                rate = np.concatenate([att, vel])
            else:
                d_att = att - cur[:3] if s.kind in (2, 4) else att
                if s.kind in (2, 4):  # an absolute heading by the shorter turn
                    d_att[0] = (d_att[0] + np.pi) % (2 * np.pi) - np.pi
                d_vel = vel - cur[3:] if s.kind in (2, 5) else vel
                rate = np.concatenate([d_att, d_vel]) / s.duration
            starts.append(cur)
            rates.append(rate)
            cur = cur + rate * s.duration
        starts, rates = np.asarray(starts), np.asarray(rates)
        return (
            starts,
            rates,
            starts + rates * np.asarray([s.duration for s in self.segments])[:, None],
        )

    def kinematics(self, t):
        """The closed-form motion at times `t` [s] (any shape; a time on a segment boundary
        belongs to the segment it starts). **Returns** `(euler, euler_rate, v_body,
        a_body)`, each t.shape + (3,): (yaw, pitch, roll) [rad] and their rates [rad/s], the
        body-frame velocity [m/s] and its rate of change [m/s²]."""
        t = np.asarray(t, float)
        starts, rates, _ = self._rates()
        edges = np.cumsum([0.0] + [s.duration for s in self.segments])
        i = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(self.segments) - 1)
        x = starts[i] + rates[i] * (t - edges[i])[..., None]
        return x[..., :3], rates[i][..., :3], x[..., 3:], rates[i][..., 3:]

    def gnss_visible(self, t):
        """Whether GNSS is visible at times `t` [s] (boolean, t's shape)."""
        edges = np.cumsum([0.0] + [s.duration for s in self.segments])
        i = np.clip(np.searchsorted(edges, np.asarray(t), side="right") - 1, 0, len(edges) - 2)
        return np.asarray([s.gnss for s in self.segments])[i]

    # --- sampling --------------------------------------------------------------------

    def truth(self, rate_hz: float = 100.0, *, earth: Earth = WGS84) -> Truth:
        """The trajectory sampled at `rate_hz` [Hz] with its exact increments (module
        docstring). **Raises** `ValueError` when a segment is not a whole number of
        samples long, or when the motion goes beyond latitude
        ±[`MAX_LAT_DEG`][hrgjax.ins.constants.MAX_LAT_DEG] (over or near a pole: the
        navigation frame is singular there) or leaves the heights
        [`HEIGHT_RANGE_M`][hrgjax.ins.constants.HEIGHT_RANGE_M], naming the time it first
        does."""
        require_x64("ins.Motion.truth")
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be a sampling rate in Hz (> 0); got {rate_hz}")
        dt = 1.0 / rate_hz
        for i, s in enumerate(self.segments, 1):
            k = s.duration * rate_hz
            if abs(k - round(k)) > 1e-6 or round(k) < 1:
                raise ValueError(
                    f"Motion segment {i}: duration {s.duration} s is not a whole number of "
                    f"samples at {rate_hz} Hz"
                )
        n = int(round(self.duration * rate_hz))
        t = np.arange(n + 1) * dt
        euler, euler_rate, vb, ab = self.kinematics(t)
        q = euler_to_quat(euler[:, 2], euler[:, 1], euler[:, 0])
        c = np.asarray(quat_to_dcm(q))
        v_ned = np.einsum("nij,nj->ni", c, vb)
        w_nb = body_rate(euler, euler_rate)
        vdot = np.einsum("nij,nj->ni", c, np.cross(w_nb, vb) + ab)
        lat0, lon0 = self.lat_deg * DEG, self.lon_deg * DEG
        initial = NavState(
            jnp.asarray(lat0),
            jnp.asarray(lon0),
            jnp.asarray(float(self.h)),
            jnp.asarray(v_ned[0]),
            q[0],
        )
        states, dth, dv = increments_from_states(initial, v_ned[1:], q[1:], dt, earth=earth)
        lat, h = np.asarray(states.lat), np.asarray(states.h)
        check_latitudes(t, lat, "the motion")
        check_path_heights(t, h, "the motion")
        w_ie, w_en = earth.earth_rate(lat), earth.transport_rate(lat, h, v_ned)
        f_ned = vdot + np.cross(2 * np.asarray(w_ie) + np.asarray(w_en), v_ned)
        f_ned = f_ned - np.asarray(earth.gravity_ned(lat, h))
        return Truth(
            states, dth, dv, jnp.asarray(f_ned), jnp.asarray(self.gnss_visible(t)), dt, earth
        )


def body_rate(euler, euler_rate):
    r"""Body angular rate relative to NED, $\omega_{nb}^b$ [rad/s] (..., 3), from (yaw, pitch,
    roll) [rad] and their rates (3-2-1 Euler kinematics):
    $p = \dot\phi - \dot\psi\sin\theta$, $q = \dot\theta\cos\phi + \dot\psi\sin\phi\cos\theta$,
    $r = -\dot\theta\sin\phi + \dot\psi\cos\phi\cos\theta$."""
    psi_d, th_d, ph_d = euler_rate[..., 0], euler_rate[..., 1], euler_rate[..., 2]
    th, ph = euler[..., 1], euler[..., 2]
    return np.stack(
        [
            ph_d - psi_d * np.sin(th),
            th_d * np.cos(ph) + psi_d * np.sin(ph) * np.cos(th),
            -th_d * np.sin(ph) + psi_d * np.cos(ph) * np.cos(th),
        ],
        -1,
    )


class Truth(eqx.Module):
    """A sampled motion with its exact increments ([`Motion.truth`][hrgjax.ins.motion.Motion.truth]).

    **Fields:** `states` the true [`NavState`][hrgjax.ins.mechanization.NavState] at N + 1
    epochs; `dtheta`, `dv` (N, 3) exact gyro [rad] and accelerometer [m/s] increments;
    `f_ned` (N + 1, 3) specific force [m/s²]; `gnss` (N + 1,) GNSS visibility; `dt` [s];
    `earth`."""

    states: NavState
    dtheta: jax.Array
    dv: jax.Array
    f_ned: jax.Array
    gnss: jax.Array
    dt: float = eqx.field(static=True)
    earth: Earth = eqx.field(static=True, default=WGS84)

    @property
    def t(self):
        """Epoch times [s], (N + 1,)."""
        return jnp.arange(self.f_ned.shape[0], dtype=float) * self.dt

    @property
    def initial(self) -> NavState:
        """The first epoch."""
        return self.states[0]

    def trajectory(self, every: int = 1) -> Trajectory:
        """The truth as a [`Trajectory`][hrgjax.ins.trajectory.Trajectory] for the linear
        error models, every `every`-th epoch (`every` must divide the N intervals: the last
        epoch is kept)."""
        n = self.dtheta.shape[0]
        what = f"a positive divisor of the {n} intervals"
        k = whole_number("every", every, what)  # a NumPy or 0-d JAX integer too
        if k < 1 or n % k:
            raise ValueError(f"every must be {what}; got {describe(every)}")
        every = k
        s = self.states[::every]
        return Trajectory(
            self.t[::every], s.lat, s.lon, s.h, s.v_ned, s.c_bn, self.f_ned[::every], self.earth
        )


def example() -> Motion:
    """A one-hour flight with turns and climbs (3600 s, starting at 45° N, 30° E, heading
    north-east): a ground run to 200 m/s, rotation and a climb to about 5 km, a 90° right
    turn and a 180° left turn (banked 30°), a GNSS outage of 60 s in cruise, and a shallow
    descent with deceleration."""
    s = lambda kind, att, vel, dur, gnss=True: Segment(kind, att, vel, dur, gnss)
    z = (0.0, 0.0, 0.0)
    segs = (
        s(1, z, z, 60.0),  # at rest
        s(1, z, (2.5, 0.0, 0.0), 80.0),  # ground run to 200 m/s
        s(3, (0.0, 5.0, 0.0), z, 10.0),  # rotate
        s(1, z, z, 290.0),  # climb at 5° (≈ 17 m/s)
        s(3, (0.0, -5.0, 0.0), z, 10.0),  # level off
        s(1, z, z, 600.0),  # cruise
        s(3, (0.0, 0.0, 30.0), z, 10.0),  # roll in
        s(1, (1.5, 0.0, 0.0), z, 60.0),  # 90° right turn
        s(3, (0.0, 0.0, -30.0), z, 10.0),  # roll out
        s(1, z, z, 400.0),
        s(1, z, z, 60.0, False),  # GNSS outage
        s(1, z, z, 400.0),
        s(3, (0.0, 0.0, -30.0), z, 10.0),
        s(1, (-1.5, 0.0, 0.0), z, 120.0),  # 180° left turn
        s(3, (0.0, 0.0, 30.0), z, 10.0),
        s(1, z, z, 800.0),
        s(3, (0.0, -3.0, 0.0), z, 10.0),  # descent at 3°, slowing to 120 m/s
        s(1, z, (-0.3, 0.0, 0.0), 260.0),
        s(3, (0.0, 3.0, 0.0), z, 10.0),
        s(1, z, z, 390.0),
    )
    return Motion(45.0, 30.0, 100.0, z, 45.0, 0.0, 0.0, segs)
