"""Bench plans (seed 000's design) and running them on a simulated gyro."""

from __future__ import annotations

import equinox as eqx
import jax
import numpy as np

from .. import plausible
from .._checks import (
    check_1d,
    check_finite,
    check_finite_host,
    check_flag,
    check_numbers,
    finite_number,
    is_concrete,
    whole_number,
)
from .._compiled import device
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..units import DEG, DEG_PER_S
from ._runs import RunGroup, simulate_runs, switch_on_keys
from ._runs import failed_member as failed_member  # its home until issue 45; now `_runs`

SEED_TEMPERATURES = tuple(float(t) for t in range(-40, 61, 10))
"""−40…+60 °C in 10 °C steps."""
SEED_ANGLES = tuple(float(a) for a in range(-90, 91, 10))
"""Wave angle −90…+90° in 10° steps (electrical)."""


class Plan(eqx.Module):
    """A list of dwell points: each is one run at constant rate and temperature.

    **Arguments:**

    - `temperature_c`: temperature of each point [°C], shape (P,).
    - `wave_angle0_deg`: initial electrical wave angle of each point [°], shape (P,).
    - `rate_dps`: table rate of each point [°/s], shape (P,).
    - `duration_s`: length of every run [s] (static: one output grid for the whole plan).
    - `dt_out`: output interval [s].
    - `precession_dps`: commanded precession rate of each point [°/s, electrical], shape
      (P,), or `None`: virtual-precession sweeps
      ([`precession_plan`][hrgjax.calibration.precession_plan]).
    """

    temperature_c: jax.Array
    wave_angle0_deg: jax.Array
    rate_dps: jax.Array
    duration_s: float = eqx.field(static=True)
    dt_out: float = eqx.field(static=True, default=1.0)
    precession_dps: jax.Array | None = None

    def __check_init__(self):
        for name in ("temperature_c", "wave_angle0_deg", "rate_dps", "precession_dps"):
            x = getattr(self, name)
            if x is None and name == "precession_dps":
                continue
            check_numbers(f"Plan.{name}", x, "an array of real numbers, shape (P,)")
            if not hasattr(x, "shape"):
                raise TypeError(f"Plan.{name} must be an array of real numbers, shape (P,) "
                                f"(np.asarray(…)); got {type(x).__name__}")  # fmt: skip
            check_finite_host(f"Plan.{name}", x)
        for name in ("duration_s", "dt_out"):
            finite_number(f"Plan.{name}", getattr(self, name), "s")
        shapes = {a.shape for a in (self.temperature_c, self.wave_angle0_deg, self.rate_dps)}
        if len(shapes) != 1 or len(next(iter(shapes))) != 1:
            raise ValueError(
                "Plan.temperature_c, wave_angle0_deg and rate_dps must be 1-D of equal length; "
                f"got {[a.shape for a in (self.temperature_c, self.wave_angle0_deg, self.rate_dps)]}"
            )
        if not self.duration_s > 0 or not self.dt_out > 0:
            raise ValueError("Plan.duration_s and Plan.dt_out must be > 0 [s]")
        if self.dt_out > self.duration_s:
            raise ValueError(f"Plan.dt_out must be ≤ Plan.duration_s (at least two samples a "
                             f"run); got dt_out {self.dt_out:g} s > duration_s "
                             f"{self.duration_s:g} s")  # fmt: skip
        plausible.check("Plan.duration_s", self.duration_s, "duration_s")
        plausible.check("Plan.temperature_c", self.temperature_c, "temperature_c")
        plausible.check("Plan.wave_angle0_deg", self.wave_angle0_deg, "wave_angle_deg")
        plausible.check("Plan.rate_dps", self.rate_dps, "table_rate_dps")
        if self.precession_dps is not None:
            if np.shape(self.precession_dps) != np.shape(self.rate_dps):
                raise ValueError(
                    f"Plan.precession_dps must have the plan's shape {np.shape(self.rate_dps)} "
                    f"[°/s]; got {np.shape(self.precession_dps)}"
                )
            check_finite("Plan.precession_dps", self.precession_dps)

    @property
    def size(self) -> int:
        """Number of points (runs) in the plan."""
        return int(self.temperature_c.shape[0])

    def profiles(self) -> Profile:
        """A batch of profiles, one per point (leading axis P)."""
        one = lambda T, a, w: Profile.constant_rate(w, self.duration_s, T, a)
        fields = (self.temperature_c, self.wave_angle0_deg, self.rate_dps)
        if not all(is_concrete(x) for x in fields) and self.precession_dps is None:
            return jax.vmap(one)(*fields)
        # Concrete plan: build the batch on the host (checked here), not by an eager vmap
        # of the constructor, which would compile its checks for every plan size.
        temp, angle, rate = (np.asarray(x, dtype=float) for x in fields)
        for name, x in zip(("temperature_c", "wave_angle0_deg", "rate_dps"), fields, strict=True):
            check_finite(f"Plan.{name}", x)
        ones = np.ones((self.size, 2))
        batch = eqx.tree_at(
            lambda p: (p.t, p.rate, p.temperature, p.accel, p.wave_angle0),
            one(0.0, 0.0, 0.0),
            (
                device(ones * np.array([0.0, self.duration_s])),
                device(ones * rate[:, None] * DEG_PER_S),
                device(ones * temp[:, None]),
                device(np.zeros((self.size, 2, 3))),
                device(angle * DEG),
            ),
        )
        if self.precession_dps is None:
            return batch
        rho = np.asarray(self.precession_dps, dtype=float)[:, None] * DEG_PER_S
        return eqx.tree_at(lambda p: p.precession, batch, device(ones * rho),
                           is_leaf=lambda x: x is None)  # fmt: skip


def _grid(temps, angles, rate, duration, dt_out):
    finite_number("plan rate_dps", rate, "°/s")
    finite_number("plan duration_s", duration, "s")
    finite_number("plan dt_out", dt_out, "s")
    for name, values, unit in (("temperatures_c", temps, "°C"), ("angles_deg", angles, "°")):
        check_numbers(f"plan {name}", values, f"real numbers [{unit}], shape (n,)")
        check_1d(f"plan {name}", values, f"one value per level [{unit}]")
        arr = np.asarray(values, float).ravel()
        if arr.size == 0:
            raise ValueError(f"plan {name} is empty; give at least one value [{unit}]")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"plan {name} must be finite [{unit}]; got {arr.tolist()}")
        uniq, counts = np.unique(arr, return_counts=True)
        if np.any(counts > 1):
            raise ValueError(f"plan {name} has duplicates {uniq[counts > 1].tolist()} [{unit}]")
    tt, aa = np.meshgrid(np.asarray(temps, float), np.asarray(angles, float), indexing="ij")
    return Plan(
        temperature_c=device(tt.ravel()),
        wave_angle0_deg=device(aa.ravel()),
        rate_dps=device(np.full(tt.size, float(rate))),
        duration_s=float(duration),
        dt_out=float(dt_out),
    )


def static_plan(
    temperatures_c=SEED_TEMPERATURES,
    angles_deg=SEED_ANGLES,
    duration_s: float = 180.0,
    dt_out: float = 1.0,
) -> Plan:
    """Seed 000's drift calibration: static gyro, every (temperature, wave angle) for 3 min.

    `temperatures_c` [°C] × `angles_deg` (initial electrical wave angles [°]), each point
    held `duration_s` [s] and sampled every `dt_out` [s]. **Returns** the `Plan`."""
    return _grid(temperatures_c, angles_deg, 0.0, duration_s, dt_out)


def rotation_plan(
    temperatures_c=SEED_TEMPERATURES,
    angles_deg=SEED_ANGLES,
    rate_dps: float = 5.0,
    duration_s: float = 180.0,
    dt_out: float = 0.5,
) -> Plan:
    """Seed 000's scale-factor calibration: rotation at `rate_dps` [°/s] (the seed's 5 °/s)
    from each grid point.

    `temperatures_c` [°C] × `angles_deg` (initial electrical wave angles [°]), each point
    turning for `duration_s` [s], sampled every `dt_out` [s]. **Returns** the `Plan`."""
    return _grid(temperatures_c, angles_deg, rate_dps, duration_s, dt_out)


QUICK_TEMPERATURES = (-40.0, 20.0, 60.0)
"""Temperatures of the quick plans [°C]."""
QUICK_DURATION = 120.0
"""Run length of the quick plans [s] (calibration and test alike: one compiled simulator)."""


def seed_plan(quick: bool = False) -> tuple[Plan, Plan]:
    """The seed's static and 5 °/s plans; `quick` keeps 3 temperatures and 2-min runs,
    sampled every 0.5 s."""
    if check_flag("seed_plan: quick", quick):
        temps, dur = QUICK_TEMPERATURES, QUICK_DURATION
        return (
            static_plan(temps, duration_s=dur, dt_out=0.5),
            rotation_plan(temps, duration_s=dur),
        )
    return static_plan(), rotation_plan()


TEST_ANGLES = tuple(float(a) for a in range(-90, 91, 5))
"""Test grid of the seed: wave angle −90…+90° in 5° steps."""


def test_plan(quick: bool = False, rate_dps: float = 5.0) -> tuple[Plan, Plan]:
    """The seed's test grid: static and `rate_dps` [°/s] (5 °/s) runs at 5° (electrical)
    steps, 5 min per point.

    `quick` keeps −40, +20, +60 °C, 15° steps and 2-min runs sampled every 0.5 s."""
    if check_flag("test_plan: quick", quick):
        temps, angles, dur = QUICK_TEMPERATURES, tuple(range(-90, 91, 15)), QUICK_DURATION
        dt_static = 0.5
    else:
        temps, angles, dur, dt_static = SEED_TEMPERATURES, TEST_ANGLES, 300.0, 1.0
    return (
        static_plan(temps, angles, duration_s=dur, dt_out=dt_static),
        rotation_plan(temps, angles, rate_dps=rate_dps, duration_s=dur),
    )


test_plan.__test__ = False  # not a pytest test


CHUNK = 32
"""Runs simulated per compiled call: every plan with the same run length and output interval
reuses one compiled simulator, whatever its number of points."""


def _failed_point(plan: Plan, take: np.ndarray, message: str) -> str:
    """A chunk's failure with the plan point named (from the check's batch member)."""
    member, detail = failed_member(message)
    if member is None:
        return message
    i = int(take[member])
    return (f"run_plan: point {i} ({float(plan.temperature_c[i]):g} °C, "
            f"{float(plan.wave_angle0_deg[i]):g}°, {float(plan.rate_dps[i]):g} °/s) failed: "
            f"{detail}")  # fmt: skip


def run_plan(
    gyro: Gyro,
    plan: Plan,
    *,
    key: jax.Array | None = None,
    bias_key: jax.Array | None = None,
    model: str = "averaged",
    first_run: int = 0,
    order_by_cost: bool = True,
) -> MeasuredData:
    """Simulate every point of `plan` and return the data (one run per point, numbered from
    `first_run`). All points share one switch-on (`bias_key`), as on a bench.

    Points are simulated with `vmap` in chunks of [`CHUNK`][hrgjax.calibration.experiment.CHUNK]
    (the last one padded), so plans of any size share one compiled simulator. A vmapped
    adaptive solve steps every point until the slowest is done, and the solver's steps grow
    with |rate| (`hrgjax._cost.STEPS_PER_S`): the points of a plan with several rates are run
    sorted by |rate| (so each chunk holds points of similar cost) and returned in the plan's
    order, each computed by the same program as unsorted: the data equal the unsorted ones to
    round-off (XLA:CPU may round a point by an ulp differently at another place in a chunk;
    measured ≤ 1e-14 relative in the wave angle, ≤ 5e-13 in amplitude and quadrature);
    `order_by_cost=False` keeps the plan's order. Point i's noise key is
    `jax.random.split(k, P)[i]` with `k, k_bias = jax.random.split(key)`, the switch-on's
    `k_bias` unless `bias_key` is given — the runner `simulate_plan` shares.
    """
    if not isinstance(gyro, Gyro):
        raise TypeError(f"run_plan: gyro must be an hrgjax.Gyro (e.g. hg.presets.tvg3_like()); "
                        f"got {type(gyro).__name__}")  # fmt: skip
    if not isinstance(plan, Plan):
        raise TypeError(f"run_plan: plan must be a calibration Plan (static_plan(), "
                        f"rotation_plan(), …); got {type(plan).__name__}")  # fmt: skip
    first_run = whole_number("run_plan: first_run", first_run, "a whole number (the first run id)")
    order_by_cost = check_flag("run_plan: order_by_cost", order_by_cost)
    n_out = int(np.floor(plan.duration_s / plan.dt_out + 1e-9)) + 1  # none past the end
    plausible.check_size("run_plan", float(n_out) * plan.size, plan.size)
    fields = (plan.temperature_c, plan.wave_angle0_deg, plan.rate_dps)
    if not all(is_concrete(x) for x in fields):
        raise ValueError("run_plan needs a concrete plan (host values), not a traced one")
    batch = jax.tree_util.tree_map(np.asarray, plan.profiles())  # chunked on the host
    keys, bias_key = switch_on_keys(gyro, key, bias_key, plan.size, "run_plan")
    size = plan.size
    chunk = min(CHUNK, size)
    members = np.arange(size)
    if order_by_cost and size > chunk:
        speed = np.abs(np.asarray(plan.rate_dps, dtype=float))
        if speed.max() > speed.min():
            members = np.argsort(speed, kind="stable")  # each point keeps its own key
    return simulate_runs(
        gyro,
        [RunGroup(np.arange(n_out) * plan.dt_out, members, chunk)],
        lambda take, _: jax.tree_util.tree_map(lambda x: x[take], batch),
        keys,
        bias_key,
        model,
        samples=np.full(size, n_out),
        failure=lambda take, message: _failed_point(plan, take, message),
        unit="run",
        first_run=first_run,
    )
