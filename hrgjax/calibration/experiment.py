"""Bench plans (seed 000's design) and running them on a simulated gyro."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_finite, is_concrete
from .._compiled import Check, device, program
from .._progress import bar
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..simulate import _simulate
from ..units import DEG, DEG_PER_S

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
    """

    temperature_c: jax.Array
    wave_angle0_deg: jax.Array
    rate_dps: jax.Array
    duration_s: float = eqx.field(static=True)
    dt_out: float = eqx.field(static=True, default=1.0)

    def __check_init__(self):
        shapes = {a.shape for a in (self.temperature_c, self.wave_angle0_deg, self.rate_dps)}
        if len(shapes) != 1 or len(next(iter(shapes))) != 1:
            raise ValueError(
                "Plan.temperature_c, wave_angle0_deg and rate_dps must be 1-D of equal length; "
                f"got {[a.shape for a in (self.temperature_c, self.wave_angle0_deg, self.rate_dps)]}"
            )
        if not self.duration_s > 0 or not self.dt_out > 0:
            raise ValueError("Plan.duration_s and Plan.dt_out must be > 0 [s]")
        plausible.check("Plan.duration_s", self.duration_s, "duration_s")
        plausible.check("Plan.temperature_c", self.temperature_c, "temperature_c")
        plausible.check("Plan.wave_angle0_deg", self.wave_angle0_deg, "wave_angle_deg")
        plausible.check("Plan.rate_dps", self.rate_dps, "table_rate_dps")

    @property
    def size(self) -> int:
        """Number of points (runs) in the plan."""
        return int(self.temperature_c.shape[0])

    def profiles(self) -> Profile:
        """A batch of profiles, one per point (leading axis P)."""
        one = lambda T, a, w: Profile.constant_rate(w, self.duration_s, T, a)
        fields = (self.temperature_c, self.wave_angle0_deg, self.rate_dps)
        if not all(is_concrete(x) for x in fields):
            return jax.vmap(one)(*fields)
        # Concrete plan: build the batch on the host (checked here), not by an eager vmap
        # of the constructor, which would compile its checks for every plan size.
        temp, angle, rate = (np.asarray(x, dtype=float) for x in fields)
        for name, x in zip(("temperature_c", "wave_angle0_deg", "rate_dps"), fields, strict=True):
            check_finite(f"Plan.{name}", x)
        ones = np.ones((self.size, 2))
        return eqx.tree_at(
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


def _grid(temps, angles, rate, duration, dt_out):
    for name, values, unit in (("temperatures_c", temps, "°C"), ("angles_deg", angles, "°")):
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
    """Seed 000's drift calibration: static gyro, every (temperature, wave angle) for 3 min."""
    return _grid(temperatures_c, angles_deg, 0.0, duration_s, dt_out)


def rotation_plan(
    temperatures_c=SEED_TEMPERATURES,
    angles_deg=SEED_ANGLES,
    rate_dps: float = 5.0,
    duration_s: float = 180.0,
    dt_out: float = 0.5,
) -> Plan:
    """Seed 000's scale-factor calibration: rotation at 5 °/s from each grid point."""
    return _grid(temperatures_c, angles_deg, rate_dps, duration_s, dt_out)


QUICK_TEMPERATURES = (-40.0, 20.0, 60.0)
"""Temperatures of the quick plans [°C]."""
QUICK_DURATION = 120.0
"""Run length of the quick plans [s] (calibration and test alike: one compiled simulator)."""


def seed_plan(quick: bool = False) -> tuple[Plan, Plan]:
    """The seed's static and 5 °/s plans; `quick` keeps 3 temperatures and 2-min runs,
    sampled every 0.5 s."""
    if quick:
        temps, dur = QUICK_TEMPERATURES, QUICK_DURATION
        return (
            static_plan(temps, duration_s=dur, dt_out=0.5),
            rotation_plan(temps, duration_s=dur),
        )
    return static_plan(), rotation_plan()


TEST_ANGLES = tuple(float(a) for a in range(-90, 91, 5))
"""Test grid of the seed: wave angle −90…+90° in 5° steps."""


def test_plan(quick: bool = False, rate_dps: float = 5.0) -> tuple[Plan, Plan]:
    """The seed's test grid: static and 5 °/s runs at 5° steps, 5 min per point.

    `quick` keeps −40, +20, +60 °C, 15° steps and 2-min runs sampled every 0.5 s."""
    if quick:
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


class _ChunkCheck(Check):
    """`Check` of a vmapped chunk that also says which member failed, as
    "(batch member (j,))": the first whose solve failed or whose outputs are not finite."""

    def host(self, out):
        message = super().host(out)
        if message is None:
            return None
        rec, result = out
        bad = np.zeros(np.shape(rec.t)[0], bool)
        try:
            bad |= np.asarray(result._value) != self._enumeration().successful._value
        except AttributeError:  # another JAX/diffrax layout: the outputs still tell
            pass
        for x in (rec.wave_angle, rec.amplitude, rec.quadrature):
            bad |= ~np.all(np.isfinite(np.asarray(x)), axis=-1)
        if bad.any():
            message += f" (batch member ({int(np.flatnonzero(bad)[0])},))"
        return message


_CHUNK_WHAT = "run_plan (simulating a plan point)"


@program(check=_ChunkCheck(_CHUNK_WHAT, result_index=1))
def _simulate_chunk(gyro, profiles, keys, bias_key, ts, model):
    def one(p, k):
        rec, _, result = _simulate(gyro, p, model, key=k, bias_key=bias_key, ts=ts)
        return rec, result

    if keys is None:
        return jax.vmap(lambda p: one(p, None))(profiles)
    return jax.vmap(one)(profiles, keys)


def failed_member(message: str) -> tuple[int | None, str]:
    """(the batch member a `_ChunkCheck` message names, or None; the message without that
    note and without the chunk program's own prefix) — for callers that name the point."""
    import re

    found = re.search(r"\s*\(batch member \((\d+),?\)\)", message)
    detail = message if found is None else message.replace(found.group(0), "")
    detail = detail.removeprefix(f"{_CHUNK_WHAT}: ")
    return (None if found is None else int(found.group(1))), detail


def _failed_point(plan: Plan, order, start: int, message: str) -> str:
    """A chunk's failure with the plan point named (from the check's batch member)."""
    member, detail = failed_member(message)
    if member is None:
        return message
    j = min(start + member, plan.size - 1)
    i = int(order[j]) if order is not None else j
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
    `order_by_cost=False` keeps the plan's order.
    """
    n_out = int(round(plan.duration_s / plan.dt_out)) + 1
    plausible.check_size("run_plan", float(n_out) * plan.size, plan.size)
    profiles = plan.profiles()
    ts = device(np.arange(n_out) * plan.dt_out)
    keys = None
    if gyro.noise is not None:
        if key is None:
            raise ValueError("this gyro has noise: pass key=jax.random.key(…)")
        k_points, k_bias = jax.random.split(key)
        bias_key = k_bias if bias_key is None else bias_key
        keys = jax.random.split(k_points, plan.size)
    size = plan.size
    chunk = min(CHUNK, size)
    n_pad = -size % chunk
    # Padding and chunking on the host where the plan is concrete (no eager device ops).
    xp = np if all(is_concrete(x) for x in jax.tree_util.tree_leaves(profiles)) else jnp
    order = None
    if order_by_cost and xp is np and size > chunk:
        speed = np.abs(np.asarray(plan.rate_dps, dtype=float))
        if speed.max() > speed.min():
            order = np.argsort(speed, kind="stable")
            profiles = jax.tree_util.tree_map(lambda x: np.asarray(x)[order], profiles)
            if keys is not None:  # each point keeps its own key
                impl, data = jax.random.key_impl(keys), np.asarray(jax.random.key_data(keys))
                keys = jax.random.wrap_key_data(device(data[order]), impl=impl)
    pad_np = lambda x, xp=xp: xp.concatenate([x, xp.repeat(x[-1:], n_pad, axis=0)])
    profiles = jax.tree_util.tree_map(
        lambda x: pad_np(xp.asarray(x)) if n_pad else xp.asarray(x), profiles
    )
    starts = range(0, size + n_pad, chunk)
    if keys is not None and xp is np:  # key data padded and sliced on the host too
        impl, data = jax.random.key_impl(keys), np.asarray(jax.random.key_data(keys))
        data = pad_np(data) if n_pad else data
        keys = [jax.random.wrap_key_data(device(data[s : s + chunk]), impl=impl) for s in starts]
    elif keys is not None:
        keys = jnp.concatenate([keys, jnp.repeat(keys[-1:], n_pad, axis=0)]) if n_pad else keys
        keys = [keys[s : s + chunk] for s in starts]
    parts = []
    with bar(size, f"simulating {size} runs", unit="run") as progress:
        for i, start in enumerate(starts):
            take = lambda x, s=start: x[s : s + chunk]
            try:
                rec, _ = _simulate_chunk(
                    gyro,
                    jax.tree_util.tree_map(take, profiles),
                    None if keys is None else keys[i],
                    bias_key,
                    ts,
                    model,
                )
            except RuntimeError as err:
                raise RuntimeError(_failed_point(plan, order, start, str(err))) from None
            parts.append(rec)
            progress.update(min(chunk, size - start))
    join = lambda *xs: (np if xp is np else jnp).concatenate(xs)[:size]
    rec = jax.tree_util.tree_map(join, *parts)
    if order is not None:  # back to the plan's order
        back = np.argsort(order)
        rec = jax.tree_util.tree_map(lambda x: np.asarray(x)[back], rec)
    data = rec.to_data()
    if first_run:
        cols = data.columns
        cols["run"] = cols["run"] + first_run
        data = MeasuredData(cols)
    return data
