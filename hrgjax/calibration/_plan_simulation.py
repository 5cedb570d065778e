"""Simulating a bench plan as one switch-on, its segments grouped to share compiled
simulators."""

from __future__ import annotations

import math
from collections.abc import Mapping

import equinox as eqx
import jax
import numpy as np

from .. import plausible
from .._checks import is_concrete
from .._compiled import device
from .._x64 import require_x64
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..units import DEG, DEG_PER_S
from ._grouping import ladder, partition
from ._plan import DT_OUT, KINDS, BenchPlan
from ._runs import RunGroup, failed_member, simulate_runs, switch_on_keys
from .experiment import CHUNK


def _profiles(plan: BenchPlan, idx: np.ndarray, length_s: float | None = None) -> Profile:
    """The segments `idx` as one batch of two-knot profiles (host arrays); with `length_s`,
    each runs on to that time [s] (rate held, temperature continuing its ramp)."""
    v = {k: np.asarray(x, dtype=float)[idx] for k, x in plan._fields().items()}
    n = len(idx)
    if length_s is not None:
        stretch = length_s / v["duration_s"]
        v["temperature_end_c"] = v["temperature_c"] + stretch * (
            v["temperature_end_c"] - v["temperature_c"]
        )
        v["duration_s"] = np.full(n, float(length_s))
    t = np.stack([np.zeros(n), v["duration_s"]], axis=1)
    # One checked profile, its arrays replaced by the batch (as Plan.profiles: no eager vmap
    # of the constructor); the batch's values were checked by BenchPlan.
    return eqx.tree_at(
        lambda p: (p.t, p.rate, p.temperature, p.accel, p.wave_angle0),
        Profile.piecewise([0.0, 1.0], [0.0, 0.0], [0.0, 0.0]),
        (
            device(t),
            device(np.repeat(v["rate_dps"][:, None], 2, axis=1) * DEG_PER_S),
            device(np.stack([v["temperature_c"], v["temperature_end_c"]], axis=1)),
            device(np.zeros((n, 2, 3))),
            device(v["wave_angle_deg"] * DEG),
        ),
    )


SIMULATOR_COMPILE_S = 3.5
"""Seconds one batched simulator of `simulate_plan` takes to compile (averaged model, 2-core
CPU: `benchmarks/plan_first_calibration.py`'s first simulation of a 12-h plan in 7 groups
39.0 s, in 3 groups 17.6 s, ≈ 5 s a group with its first run) — what running two groups of
segment lengths as one saves, against the steps the shorter segments then run on for
(`simulation_groups`; steps cost `hrgjax._cost.CPU_STEP_S`)."""

RUNS_PER_COMPILE = 4.0
"""How many times a plan is simulated per compile, as `simulation_groups` weighs run time
against compile time (a study simulates a plan a few times; a Monte Carlo, many)."""

MERGED_STEPS_MAX = 2**13
"""Estimated solver steps beyond which `simulation_groups` merges no further (the averaged
model's `max_steps` is 2¹⁶)."""


def _chunk(members: int) -> int:
    """Batch size for a group of `members` segments: a power of two up to `CHUNK`, so that
    groups of one length and different sizes share a compiled simulator."""
    return min(CHUNK, ladder(members))


def simulation_groups(plan, n_out, dts, model) -> dict[tuple[int, float], list[int]]:
    """Segments grouped by output samples and interval: `{(samples, dt): [segment, …]}`.

    A length at least `physical.SHARED_LENGTH_RUNS` segments share is a group of its own; a
    rarer one is padded to the next power of two of samples. Then, per output interval,
    neighbouring groups (sorted by length) are merged where the estimated steps the shorter
    segments run on for cost less than compiling another simulator: a partition of the
    sorted groups by dynamic programming on compile (`SIMULATOR_COMPILE_S`) + run time
    (`_cost.CPU_STEP_S`, steps by `physical.steps_estimate` at the group's largest rate). Padded
    segments are run on (rate held, a ramp's temperature continuing) and cut back. A designed
    12-h plan: 7 groups → 3, its first `simulate_plan` in a fresh process 35–38 → 16 s, a
    later one 0.5–0.6 → 0.8–0.9 s (`benchmarks/plan_first_calibration.py`). The full
    model's steps are far dearer than a compile: its groups stay apart."""
    from .._cost import CPU_STEP_S
    from ._physical_groups import SHARED_LENGTH_RUNS, steps_estimate

    exact: dict[tuple[int, float], int] = {}
    for i, k in enumerate(plan.kind):
        exact[(int(n_out[i]), dts[k])] = exact.get((int(n_out[i]), dts[k]), 0) + 1
    units: dict[tuple[int, float], list[int]] = {}
    for i, k in enumerate(plan.kind):
        n, dt = int(n_out[i]), dts[k]
        samples = n + 1 if exact[(n, dt)] >= SHARED_LENGTH_RUNS else ladder(n + 1)
        units.setdefault((samples, dt), []).append(i)
    if model != "averaged":
        return units
    rate = np.abs(np.asarray(plan.rate_dps, dtype=float)) * DEG_PER_S
    groups: dict[tuple[int, float], list[int]] = {}
    for dt in sorted({dt for _, dt in units}):
        keys = sorted(u for u in units if u[1] == dt)

        def cost(i, j, keys=keys, dt=dt):  # units i..j−1 as one group, run to the longest
            members = [m for u in keys[i:j] for m in units[u]]
            steps = steps_estimate((keys[j - 1][0] - 1) * dt, float(np.max(rate[members])))
            if j - i > 1 and steps > MERGED_STEPS_MAX:
                return math.inf  # far from simulate's max_steps, whatever the estimate's error
            chunk = _chunk(len(members))
            run = -(-len(members) // chunk) * steps * (CPU_STEP_S[0] + chunk * CPU_STEP_S[1])
            return SIMULATOR_COMPILE_S + RUNS_PER_COMPILE * run

        for i, j in partition(len(keys), cost):
            groups[keys[j - 1]] = [m for u in keys[i:j] for m in units[u]]
    return groups


def simulate_plan(
    gyro: Gyro,
    plan: BenchPlan,
    *,
    key: jax.Array | None = None,
    bias_key: jax.Array | None = None,
    model: str = "averaged",
    dt_out: Mapping[str, float] | None = None,
) -> MeasuredData:
    """Simulate every segment of `plan` on `gyro` as one bench session (one switch-on: the
    run-to-run bias drawn once from `bias_key`); segment i is run i of the data.

    Segments of equal length and output interval share one compiled simulator (vmapped in
    chunks of up to `CHUNK`, by the runner of `run_plan`); a length fewer than
    `physical.SHARED_LENGTH_RUNS` segments share is run on to the next power of two of
    samples (the rate held, a ramp's temperature continuing) and cut back, and neighbouring
    lengths are run as one where compiling another simulator would cost more than the
    extra steps, so a plan of many different durations compiles a few simulators.
    `dt_out`: output interval per kind [s] (default `DT_OUT`: static 1 s, rotation 0.5 s,
    ramp 1 s). Each segment gets its own noise key
    (`jax.random.split(key, S)[i]`), so a segment's data do not depend on the other
    segments' keys."""
    require_x64("hrgjax.calibration.simulate_plan")
    if not all(is_concrete(x) for x in plan._fields().values()):
        raise ValueError("simulate_plan needs a concrete plan (host values), not a traced one")
    dts = dict(DT_OUT)
    if dt_out is not None:
        unknown = set(dt_out) - set(KINDS)
        if unknown:
            raise ValueError(f"dt_out keys must be from {KINDS}; got {sorted(unknown)}")
        dts.update({k: float(v) for k, v in dt_out.items()})
        if not all(v > 0 for v in dts.values()):
            raise ValueError(f"dt_out values must be > 0 [s]; got {dts}")
    keys, bias_key = switch_on_keys(gyro, key, bias_key, plan.size, "simulate_plan")
    durations = np.asarray(plan.duration_s, dtype=float)
    n_out = np.zeros(plan.size, dtype=int)
    for i, k in enumerate(plan.kind):
        dt = dts[k]
        n_out[i] = round(durations[i] / dt)
        if n_out[i] < 1 or abs(n_out[i] * dt - durations[i]) > 1e-9 * max(1.0, durations[i]):
            raise ValueError(
                f"segment {i} ({k}): duration_s={durations[i]:g} is not a whole number of "
                f"dt_out={dt:g} s output intervals"
            )
    plausible.check_size("simulate_plan", float(np.sum(n_out + 1)), plan.size)
    groups = [
        RunGroup(np.arange(samples) * dt, np.asarray(members), _chunk(len(members)))
        for (samples, dt), members in simulation_groups(plan, n_out, dts, model).items()
    ]
    return simulate_runs(
        gyro,
        groups,
        lambda take, length_s: _profiles(plan, take, length_s),
        keys,
        bias_key,
        model,
        samples=n_out + 1,
        failure=lambda take, message: _failed_segment(plan, take, message),
        unit="segment",
    )


def _failed_segment(plan: BenchPlan, take: np.ndarray, message: str) -> str:
    """A simulator failure inside a chunk of segments `take`, with the segment named (the
    simulator's message says which batch member failed)."""
    member, detail = failed_member(message)
    members = [int(take[member])] if member is not None else sorted(set(map(int, take)))
    i = members[0]
    what = (f"segment {i} ({plan.kind[i]}, {float(plan.temperature_c[i]):g} °C, "
            f"{float(plan.rate_dps[i]):g} °/s, {float(plan.duration_s[i]):g} s)")  # fmt: skip
    if member is None and len(members) > 1:
        what = f"one of segments {members[0]}…{members[-1]} (first: {what})"
    return f"simulate_plan: {what} failed: {detail}"
