r"""What compensation buys in navigation (seed 000 §INS).

Level flight at constant speed and heading ψ, two level HRGs along the body axes x
(forward) and y (right), each with its own wave angle, in an IMU that warms up during the
flight. Each gyro's residual rate error after compensation, $\varepsilon_x, \varepsilon_y$,
drives the strapdown φ-angle error model of [`hrgjax.ins.strapdown`][hrgjax.ins.strapdown]
along the flight (WGS-84, Earth-rate and transport-rate coupling, altitude aided). The
reported figures are the horizontal velocity and position error magnitudes after the
flight.

[`schuler_errors`][hrgjax.calibration.ins_impact.schuler_errors] keeps the classical
two-channel model (Earth-rate coupling neglected, PHYSICS.md §12) for comparison:
$\delta\dot v = g\,\phi$, $\dot\phi = -\delta v/R + \varepsilon$, $\delta\dot p = \delta v$,
so a constant ε gives $\delta p = R\varepsilon\,(t - \sin\omega_s t/\omega_s)$.
"""

from __future__ import annotations

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_1d, check_finite, check_numbers, concrete_value, finite_number
from .._compiled import Check, device, program
from .._x64 import require_x64
from ..data import MeasuredData, concat
from ..gyro import Gyro
from ..profiles import Profile
from ..simulate import simulate
from ..units import DEG
from ._compensator import AbstractCompensator

EARTH_RADIUS = 6_378_137.0
"""WGS-84 equatorial radius [m]."""
GRAVITY = 9.80665
"""Standard gravity [m/s²]."""


def schuler_errors(t, eps_north, eps_east):
    r"""Integrate the two Schuler channels (module docstring) with diffrax.

    **Arguments:** `t` [s] shape (N,); `eps_north`, `eps_east`: gyro error about the north and
    east axes [rad/s] at `t` (linearly interpolated between samples).

    **Returns:** `(velocity_error, position_error)` [m/s], [m], each shape (N, 2) for the
    (east, north) channels, signed as the NED strapdown error model's
    ([`hrgjax.ins.strapdown.propagate`][]): a north-axis gyro error ε drives the east
    channel, +Rε(t − sin ω_s t/ω_s); an east-axis one the north channel, with the opposite
    sign (δv̇_N = +gφ_E, δv̇_E = −gφ_N: a level tilt about east accelerates north).

    **Raises:** `ValueError` in one line for times that are not at least two finite,
    increasing values or errors that are not finite or not one per time (checked when the
    values are known; shapes under `jit` too); `RuntimeError` when the solver fails.
    """
    require_x64("hrgjax.calibration.ins_impact.schuler_errors")
    form = "a 1-D array of one gyro error [rad/s] per time in t"
    n = check_1d("t", check_numbers("t", t, "a 1-D array of times [s]"), "times [s]")[0]
    if n < 2:
        raise ValueError(f"t must hold at least 2 times [s]; got {n}")
    eps = [check_numbers(name, x, form, shape=(n,))
           for name, x in (("eps_north", eps_north), ("eps_east", eps_east))]  # fmt: skip
    times = concrete_value(t)
    if times is not None and not (np.isfinite(times).all() and (np.diff(times) > 0).all()):
        raise ValueError("t must be finite times [s], strictly increasing")
    # strongly typed float64: one compiled program whatever array types the caller holds
    t = jnp.asarray(t, dtype=jnp.float64)
    eps = [check_finite(name, jnp.asarray(x, dtype=jnp.float64))
           for name, x in zip(("eps_north", "eps_east"), eps, strict=True)]  # fmt: skip
    return _schuler(t, *eps)[:2]


@program(check=Check("schuler_errors", result_index=2))
def _schuler(t, eps_north, eps_east):
    path = diffrax.LinearInterpolation(ts=t, ys=jnp.stack([eps_north, eps_east], axis=-1))

    def field(s, y, args):
        dv, phi, _ = y[0:2], y[2:4], y[4:6]
        eps = path.evaluate(s) * jnp.array([1.0, -1.0])  # the north channel's drive is −ε_E
        return jnp.concatenate([GRAVITY * phi, -dv / EARTH_RADIUS + eps, dv])

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Tsit5(),
        t0=t[0],
        t1=t[-1],
        dt0=None,
        y0=jnp.zeros(6),
        saveat=diffrax.SaveAt(ts=t),
        stepsize_controller=diffrax.PIDController(rtol=1e-9, atol=1e-9, jump_ts=t),
        max_steps=16 * t.shape[0],
        throw=False,
    )
    return sol.ys[:, 0:2], sol.ys[:, 4:6], sol.result


FLIGHT_UNITS = {
    "duration_s": "s",
    "heading_deg": "°, clockwise from north",
    "wave_angle_x_deg": "° electrical",
    "wave_angle_y_deg": "° electrical",
    "temperature_start_c": "°C",
    "temperature_end_c": "°C",
    "warmup_s": "s",
    "dt_out": "s",
    "speed_mps": "m/s",
    "lat_deg": "°",
}
"""The unit of each `Flight` field (named in its errors)."""


class Flight(eqx.Module):
    """A level flight for the INS-impact study.

    **Arguments:** `duration_s` [s]; `heading_deg` (clockwise from north); `wave_angle_x_deg`,
    `wave_angle_y_deg`: initial wave angles of the two level gyros [° electrical];
    `temperature_start_c`, `temperature_end_c` [°C] and `warmup_s` [s]: IMU temperature
    $T(t) = T_{end} + (T_{start} - T_{end})e^{-t/t_w}$; `dt_out` [s]; `speed_mps` [m/s] and
    `lat_deg` [°] (start) of the level flight.

    **Raises** (when built, one line naming the field, its expected form and unit):
    `TypeError` for a field that is not a number; `ValueError` for one not finite, a
    `duration_s` ≤ 0, a `dt_out` that is not > 0 or does not divide `duration_s` into whole
    steps, a `warmup_s` ≤ 0, a temperature outside `hrgjax.plausible.RANGES` (kelvin: the
    hint says so), a `speed_mps` < 0 or a `lat_deg` beyond ±89°.
    """

    duration_s: float = eqx.field(static=True, default=3600.0)
    heading_deg: float = eqx.field(static=True, default=40.0)
    wave_angle_x_deg: float = eqx.field(static=True, default=30.0)
    wave_angle_y_deg: float = eqx.field(static=True, default=-55.0)
    temperature_start_c: float = eqx.field(static=True, default=-40.0)
    temperature_end_c: float = eqx.field(static=True, default=20.0)
    warmup_s: float = eqx.field(static=True, default=1200.0)
    dt_out: float = eqx.field(static=True, default=1.0)
    speed_mps: float = eqx.field(static=True, default=200.0)
    lat_deg: float = eqx.field(static=True, default=45.0)

    def __check_init__(self):
        from ..ins.trajectory import check_position

        for name, unit in FLIGHT_UNITS.items():
            finite_number(f"Flight.{name}", getattr(self, name), unit)
        duration, dt = float(self.duration_s), float(self.dt_out)
        if duration <= 0:
            raise ValueError(f"Flight.duration_s must be > 0 s; got {self.duration_s!r}")
        plausible.check("Flight.duration_s", duration, "duration_s")
        steps = duration / dt if dt > 0 else np.nan
        if not (0 < dt <= duration and abs(steps - round(steps)) <= 1e-6):
            count = f" ({steps:.6g} steps)" if dt > 0 else ""
            raise ValueError(f"Flight.dt_out must be > 0 s and divide duration_s = {duration:g} s "
                             f"into whole steps; got {self.dt_out!r}{count}")  # fmt: skip
        if float(self.warmup_s) <= 0:
            raise ValueError("Flight.warmup_s must be > 0 s (the time constant t_w of the "
                             f"warm-up T(t)); got {self.warmup_s!r}")  # fmt: skip
        for name in ("temperature_start_c", "temperature_end_c"):
            plausible.check(f"Flight.{name}", getattr(self, name), "temperature_c")
        for name in ("wave_angle_x_deg", "wave_angle_y_deg"):
            plausible.check(f"Flight.{name}", getattr(self, name), "wave_angle_deg")
        plausible.check("Flight.speed_mps", self.speed_mps, "speed_mps")
        check_position(self.lat_deg, 0.0, 0.0, where="Flight.")

    def trajectory(self):
        """The flight as an [`hrgjax.ins.trajectory.Trajectory`][hrgjax.ins.trajectory.Trajectory]."""
        from ..ins.trajectory import constant_velocity

        return constant_velocity(
            self.lat_deg,
            speed=self.speed_mps,
            heading_deg=self.heading_deg,
            duration_s=self.duration_s,
            dt=self.dt_out,
        )

    def temperature(self, t):
        """IMU temperature [°C] at `t` [s]."""
        return self.temperature_end_c + (
            self.temperature_start_c - self.temperature_end_c
        ) * np.exp(-np.asarray(t) / self.warmup_s)

    def temperature_rate(self, t):
        """Its rate of change Ṫ [°C/s] at `t` [s]."""
        return (
            (self.temperature_end_c - self.temperature_start_c)
            / self.warmup_s
            * np.exp(-np.asarray(t) / self.warmup_s)
        )


FLIGHTS = (
    Flight(heading_deg=40.0, wave_angle_x_deg=30.0, wave_angle_y_deg=-55.0),
    Flight(heading_deg=130.0, wave_angle_x_deg=-20.0, wave_angle_y_deg=70.0),
    Flight(heading_deg=250.0, wave_angle_x_deg=80.0, wave_angle_y_deg=5.0),
)
"""The 1-h flights of the INS-impact step: IMU warming from −40 °C to +20 °C (20-min time
constant), three headings and wave-angle pairs."""


def fly(gyro: Gyro, flight: Flight, *, key: jax.Array, bias_key: jax.Array) -> MeasuredData:
    """Records of the two level gyros during `flight` (runs 0 = x, 1 = y; table rate 0, so
    all they read is error), sampled every `flight.dt_out` [s] through the flight's
    temperature history at its wave angles [° electrical]. `key`: PRNG key of the noise;
    `bias_key`: of the switch-on bias (the same draw for both runs). **Returns** the
    `MeasuredData` (the data contract's columns: `time_s`, `temperature_c`,
    `table_rate_dps` = 0, the measured `wave_angle_deg`, …)."""
    require_x64("calibration.ins_impact.fly")
    knots = np.linspace(0.0, flight.duration_s, 61)
    ts = device(np.arange(0.0, flight.duration_s + 1e-9, flight.dt_out))
    parts = []
    for i, angle in enumerate((flight.wave_angle_x_deg, flight.wave_angle_y_deg)):
        prof = Profile.piecewise(knots, 0.0, flight.temperature(knots), wave_angle0_deg=angle)
        rec = simulate(gyro, prof, key=jax.random.fold_in(key, i), bias_key=bias_key, ts=ts, run=i)
        parts.append(rec.to_data())
    return concat(parts)


def navigation_errors(
    comp: AbstractCompensator, records: MeasuredData, flight: Flight, trajectory=None, *,
    warn: bool = True,
):  # fmt: skip
    """Horizontal velocity and position error magnitudes [m/s], [m] at the end of `flight`
    when the level gyros' outputs are compensated with `comp` (rates in `records` from
    [`fly`][hrgjax.calibration.ins_impact.fly]); `trajectory`: `flight.trajectory()`, if
    already built; `warn`: `correct`'s (False: no warning for samples outside the calibrated
    temperature range, e.g. the warm-up from −40 °C)."""
    from ..ins.strapdown import propagate

    out = comp.correct(records, warn=warn)
    idx = records.run_indices()
    eps_x = out["rate_corrected_dps"][idx[0]] * DEG  # true rate is 0: all of it is error
    eps_y = out["rate_corrected_dps"][idx[1]] * DEG
    traj = flight.trajectory() if trajectory is None else trajectory
    if traj.t.shape[0] != eps_x.shape[0]:
        raise ValueError(
            f"the records hold {eps_x.shape[0]} samples per gyro, the flight {traj.t.shape[0]}"
        )
    gyro_error = device(np.stack([eps_x, eps_y, np.zeros(eps_x.shape)], -1))
    dx = propagate(traj, gyro_error=gyro_error, altitude_aided=True, rtol=1e-8, atol=1e-10)
    velocity, position = _final_errors(traj, dx)
    return float(velocity), float(position)


def mechanized_errors(
    comp: AbstractCompensator, records: MeasuredData, flight: Flight, rate_hz: float = 10.0, *,
    warn: bool = True,
):  # fmt: skip
    """[`navigation_errors`][hrgjax.calibration.ins_impact.navigation_errors] through the
    nonlinear strapdown mechanization instead of the linear error model: the flight as a
    motion ([`hrgjax.ins.motion`][hrgjax.ins.motion]) sampled at `rate_hz` [Hz], its exact
    increments with the compensated rates added to the x and y gyros (linearly interpolated
    between records, as the linear model does), altitude held.

    **Returns** the horizontal velocity and position error magnitudes [m/s], [m] after the
    flight; `warn`: `correct`'s."""
    from ..ins import mechanization, motion

    out = comp.correct(records, warn=warn)
    idx = records.run_indices()
    eps = [np.asarray(out["rate_corrected_dps"][idx[k]]) * DEG for k in (0, 1)]
    t_rec = np.arange(eps[0].shape[0]) * flight.dt_out
    z = (0.0, 0.0, 0.0)
    mot = motion.Motion(
        flight.lat_deg, 0.0, 0.0, (flight.speed_mps, 0.0, 0.0), flight.heading_deg, 0.0, 0.0,
        (motion.Segment(1, z, z, flight.duration_s),),
    )  # fmt: skip
    truth = mot.truth(rate_hz)
    n = truth.dtheta.shape[0]
    mid = (np.arange(n) + 0.5) * truth.dt
    err = np.stack([np.interp(mid, t_rec, e) for e in eps] + [np.zeros(n)], -1)
    nav = mechanization.mechanize(
        truth.initial,
        truth.dtheta + device(err * truth.dt),
        truth.dv,
        truth.dt,
        every=n,
        vertical=(truth.states.h[1:], truth.states.v_ned[1:, 2]),
    )
    p, v, _ = mechanization.navigation_errors(nav, truth.states[::n])
    return float(jnp.linalg.norm(v[-1, :2])), float(jnp.linalg.norm(p[-1, :2]))


@program
def _final_errors(traj, dx):
    """Horizontal velocity [m/s] and position [m] error magnitudes at the last state (one
    compiled program, not a handful of eager operations)."""
    from ..ins.strapdown import position_metres

    end = jax.tree_util.tree_map(lambda x: x[-1:], traj)
    dp = position_metres(end, dx[-1:])[-1, :2]
    return jnp.linalg.norm(dx[-1, 3:5]), jnp.linalg.norm(dp)


def ins_impact(
    compensators: dict[str, AbstractCompensator],
    gyro: Gyro,
    flights: list[Flight],
    *,
    key: jax.Array,
    bias_key: jax.Array,
    warn: bool = True,
):
    """Navigation errors after each flight for each compensator.

    `warn`: `correct`'s (False: no
    [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning] for the samples
    of the flights' warm-up outside a compensator's calibrated range; they are counted in
    the result either way).

    **Returns:** {label: {"velocity_error_mps": [per flight], "position_error_km": [...],
    "samples_out_of_range": [per flight: samples outside the calibrated temperature range,
    of "samples" per flight]}}.
    """
    records = [
        fly(gyro, f, key=jax.random.fold_in(key, i), bias_key=bias_key)
        for i, f in enumerate(flights)
    ]
    table = {}
    trajs = [f.trajectory() for f in flights]
    for label, comp in compensators.items():
        errs = [
            navigation_errors(comp, r, f, tr, warn=warn)
            for r, f, tr in zip(records, flights, trajs, strict=True)
        ]
        table[label] = {
            "velocity_error_mps": [e[0] for e in errs],
            "position_error_km": [e[1] / 1000 for e in errs],
            "samples_out_of_range": [int(np.sum(~comp.in_range(r["temperature_c"])))
                                     for r in records],
            "samples": [len(r) for r in records],
        }  # fmt: skip
    return table


SEED_INS = {"velocity_error_mps": ((16, 26), (6, 8)), "position_error_km": ((79, 82), (14, 28))}
"""Seed 000 (An-72 flight data, 1 h): (baseline range, neural range)."""


def format_ins_table(table) -> str:
    """Text table of [`ins_impact`][hrgjax.calibration.ins_impact.ins_impact] with the seed's
    ranges."""
    lines = ["navigation error after the flight (min–max over flights)"]
    lines.append(f"{'method':>16} {'velocity [m/s]':>16} {'position [km]':>16}")
    for label, row in table.items():
        v, p = row["velocity_error_mps"], row["position_error_km"]
        lines.append(f"{label:>16} {min(v):7.2f}–{max(v):<7.2f} {min(p):8.2f}–{max(p):<7.2f}")
    sv, sp = SEED_INS["velocity_error_mps"], SEED_INS["position_error_km"]
    lines.append(
        f"{'seed baseline':>16} {sv[0][0]:7.0f}–{sv[0][1]:<7.0f} {sp[0][0]:8.0f}–{sp[0][1]:<7.0f}"
    )
    lines.append(
        f"{'seed neural':>16} {sv[1][0]:7.0f}–{sv[1][1]:<7.0f} {sp[1][0]:8.0f}–{sp[1][1]:<7.0f}"
    )
    outside = [f"  {label}: {sum(row['samples_out_of_range'])} of {sum(row['samples'])} "
               "samples (extrapolated)" for label, row in table.items()
               if sum(row.get("samples_out_of_range", ())) > 0]  # fmt: skip
    if outside:
        lines += ["outside the calibrated temperature range on the flights (on purpose):", *outside]
    return "\n".join(lines)
