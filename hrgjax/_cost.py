"""What a batched run will cost, known before it runs: the order of `sweep`'s members.

An adaptive solver under `vmap` steps every member until the slowest is done, so a batch
costs its most expensive member's steps times its size. `sweep` therefore estimates each
member's cost first, sorts the members by it and runs them in chunks of similar cost.

The estimate comes from `simulate` itself: `sweep` traces the user's function once more with
a *probe* on; the first `simulate` call it reaches raises [`Found`][hrgjax._cost.Found] with
[`steps_estimate`][hrgjax._cost.steps_estimate] of its profile, which ends the trace there (no
solver is traced or compiled). A function that calls no `simulate` has no estimate and runs
in the caller's order.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ._checks import concrete_value

_PROBING = contextvars.ContextVar("hrgjax_cost_probe", default=False)

STEPS_PER_S = (1.0, 25.0)
"""Accepted steps per simulated second of the averaged model at the default tolerances:
a + b·√|k_eΩ|max [k_eΩ in rad/s] (measured on `presets.tvg3_like()`, 60–180-s runs at
0–400 °/s: 1.2 steps/s at rest, 5.2 at 5 °/s, 21.5 at 100 °/s, 54 at 400 °/s)."""

CARRIER_STEPS = 10.0
"""Steps per carrier cycle of the full (carrier-resolving) model, about."""


class Found(Exception):
    """Raised by `simulate` while probing: carries its (traced) cost estimate."""

    def __init__(self, cost):
        super().__init__("cost probe")
        self.cost = cost


@contextlib.contextmanager
def probing():
    """Within this block `simulate` raises [`Found`][hrgjax._cost.Found] instead of solving."""
    token = _PROBING.set(True)
    try:
        yield
    finally:
        _PROBING.reset(token)


AD_LEVELS = 8
"""Levels of differentiation (`jax.grad`, `jvp`, `linearize`, `jacfwd`, … nested) around
`simulate` inside a swept function whose estimate `report` takes the primal of."""


def report(gyro, profile, model: str) -> None:
    """Called by `simulate` before it solves: while probing, stop with the estimate.

    `simulate` may be differentiated inside the swept function (`jax.grad` of it, say): its
    estimate is then a tracer of that differentiation, which would escape it with the
    exception. Each `jax.lax.stop_gradient` returns the primal of the innermost such level
    the value has (the estimate is not differentiated; its value is the undifferentiated
    run's), so after `AD_LEVELS` of them the estimate is the probe's own value. A
    transformation that leaves no primal (`fn`'s own `jax.jit`, a `vmap` inside `fn`, a
    `lax.scan` around `simulate`) still lets it escape: `sweep` then keeps the
    grid order (`hrgjax.sweep.member_costs`)."""
    if _PROBING.get():
        cost = steps_estimate(gyro, profile, model)
        for _ in range(AD_LEVELS):
            cost = jax.lax.stop_gradient(cost)
        raise Found(cost)


def steps_per_s(precession):
    """Accepted steps per simulated second of the averaged model at precession rate
    |k_eΩ| [rad/s] (`STEPS_PER_S`); a float or an array, traced or not."""
    a, b = STEPS_PER_S
    return a + b * precession**0.5


def steps_estimate(gyro, profile, model: str = "averaged"):
    """Expected solver steps of `simulate(gyro, profile, model)` (module docstring): the run's
    length [s] times the steps per second of `STEPS_PER_S` (averaged) or of `CARRIER_STEPS`
    per carrier cycle (full), at the largest precession rate |k_eΩ| of the profile, and at
    least one step per `resonator.control.max_step` (fast loops bound the step)."""
    from .resonator.control import max_step

    g = gyro.at(jnp.mean(profile.temperature))
    duration = profile.t[-1] - profile.t[0]
    per_s = steps_per_s(jnp.max(jnp.abs(g.resonator.k_e * profile.rate)))
    per_s = jnp.maximum(per_s, 1.0 / max_step(gyro.control, model, profile.temperature))
    if model != "averaged":
        per_s = per_s + CARRIER_STEPS * jnp.abs(g.resonator.omega) / (2 * np.pi)
    return duration * per_s


CPU_STEP_S = (47e-6, 7.2e-6)
"""Seconds per batched solver step of the averaged model on a CPU: fixed + per member
(measured on 2 cores)."""

OVERHEAD_MEMBERS = {"cpu": 6.0}
"""The fixed cost of one batched solver step, in members' worth of per-member work:
`CPU_STEP_S`, 47 µs per step plus 7.2 µs per member (averaged model). Accelerators
run a step of any batch in about the time of one member: every other backend counts as
10⁴, so there one batch is always chosen."""


SPREADS = (1.0, 3.0, 10.0, 30.0)
"""Cost spreads (costliest over cheapest member, costs log-uniform between) `chunk_length`
plans for: members alike, up to a sweep of the averaged model over 0.1–400 °/s (≈ 30× the
steps)."""


MAX_CHUNKS = 256
"""The most chunks `chunk_length` splits a sweep into by itself."""


def _estimate(srt, c: int, overhead: float) -> float:
    """Σ_chunks max cost · (overhead + size) of sorted costs `srt` in chunks of `c`."""
    total = srt.size
    n = -(-total // c)
    return float(np.sum(srt[np.minimum(np.arange(1, n + 1) * c, total) - 1])) * (overhead + c)


def chunk_length(total: int, devices: int, backend: str, chunk_size: int | None = None) -> int:
    """Members per batch of `sweep` for `total` members ordered by cost: `chunk_size` rounded
    up to a multiple of `devices`, or, when `None`, the size among those that split the batch
    into 1 … `MAX_CHUNKS` equal chunks whose estimated time Σ_chunks max cost · (overhead +
    size) is within the smallest factor of the best size's for every cost spread of `SPREADS`
    (`OVERHEAD_MEMBERS` by backend).

    It depends on the number of members only, never on their costs: the batch's shape is
    static in its compiled program, and a size picked from the costs compiled the batch again
    for a grid of the same size with other values. On a CPU the factor is ≤ 1.34 at every
    size (one batch up to 13 members), 1.11 at 256 members (52 a chunk, also for alike
    members against one batch)."""
    if chunk_size is not None:
        return -(-int(chunk_size) // int(devices)) * int(devices)
    return _auto_length(int(total), int(devices), str(backend))


@functools.lru_cache(maxsize=128)
def _auto_length(total: int, devices: int, backend: str) -> int:
    per = lambda c: -(-int(c) // devices) * devices
    overhead = OVERHEAD_MEMBERS.get(backend, 1e4)
    sizes = sorted({per(-(-total // n)) for n in range(1, min(total, MAX_CHUNKS) + 1)})
    worst = dict.fromkeys(sizes, 0.0)
    for spread in SPREADS:
        srt = np.geomspace(1.0, spread, total)
        est = {c: _estimate(srt, c, overhead) for c in sizes}
        best = min(est.values())
        for c in sizes:
            worst[c] = max(worst[c], est[c] / best)
    return min(sizes, key=lambda c: (round(worst[c], 9), -c))  # a tie: the larger chunk


def plan(costs: np.ndarray, devices: int, backend: str, chunk_size: int | None = None):
    """Order and chunk size for members of estimated `costs`: **returns** `(order, chunk)`,
    `order` the permutation that sorts them by cost (stable, so equal costs keep the caller's
    order) and `chunk` the members per batch, `chunk_length` of their number (not of their
    costs: one compiled batch per grid size)."""
    costs = np.asarray(costs, dtype=float)
    order = np.argsort(costs, kind="stable")
    return order, chunk_length(int(costs.size), int(devices), backend, chunk_size)


MAX_STEPS = {"averaged": 2**16, "full": 2**20}
"""`simulate`'s solver step limit by model when `max_steps` is not given, for runs whose
expected steps fit 4 times over (`default_max_steps`)."""


def default_max_steps(gyro, profile, model: str) -> int:
    """The step limit `simulate` gives the adaptive solver: `MAX_STEPS[model]`, or for the
    averaged model on a concrete profile (or batch of profiles: the most any member needs)
    that needs more, the power of two ≥ 4 × its expected steps (`steps_per_s` at the
    profile's largest |k_e Ω|, k_e taken as 1 where it is traced or a temperature law; at
    least one step per `resonator.control.max_step` where the loops' bandwidths are concrete): a
    long or fast run (an hour at 100 °/s is ≈ 7.7·10⁴ steps, a day at rest ≈ 10⁵) is
    solved, not stopped at the limit. A power of two, so that runs of similar length share
    one program."""
    base = MAX_STEPS.get(model, MAX_STEPS["full"])
    t, rate = concrete_value(profile.t), concrete_value(profile.rate)
    if model != "averaged" or t is None or rate is None or t.shape[-1] < 2:
        return base
    from .resonator.control import max_step
    from .resonator.params import TemperatureLaw

    k_e = gyro.resonator.k_e
    k_e = None if isinstance(k_e, TemperatureLaw) else concrete_value(k_e)
    k = 1.0 if k_e is None else float(np.max(np.abs(k_e)))
    span = float(np.max(t[..., -1] - t[..., 0]))  # a batch of profiles: its longest
    per_s = float(steps_per_s(k * np.max(np.abs(rate))))
    longest = concrete_value(max_step(gyro.control, model, profile.temperature))
    per_s = per_s if longest is None else max(per_s, float(np.max(1.0 / longest)))
    need = 4.0 * span * per_s
    return base if need <= base else int(2 ** math.ceil(math.log2(need)))
