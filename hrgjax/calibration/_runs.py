"""Running simulated bench runs of one switch-on: runs grouped by their output times, each
group vmapped in chunks through one compiled simulator — the runner behind `run_plan` (a
grid of dwell points) and `simulate_plan` (a bench plan's segments)."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import NamedTuple

import jax
import numpy as np

from .. import _upstream
from .._checks import check_key
from .._compiled import Check, device, program
from .._cost import MAX_STEPS, default_max_steps
from .._progress import bar
from ..data import MeasuredData
from ..gyro import Gyro
from ..profiles import Profile
from ..simulate import simulate_with_stats


class _ChunkCheck(Check):
    """`Check` of a vmapped chunk that also says which member failed, as
    "(batch member (j,))": the first whose solve failed or whose outputs are not finite."""

    def host(self, out):
        message = super().host(out)
        if message is None:
            return None
        rec, result = out
        bad = np.zeros(np.shape(rec.t)[0], bool)
        bad |= ~_upstream.succeeded(result, self._enumeration())
        for x in (rec.wave_angle, rec.amplitude, rec.quadrature):
            bad |= ~np.all(np.isfinite(np.asarray(x)), axis=-1)
        if bad.any():
            message += f" (batch member ({int(np.flatnonzero(bad)[0])},))"
        return message


_CHUNK_WHAT = "run_plan (simulating a plan point)"


@program(check=_ChunkCheck(_CHUNK_WHAT, result_index=1))
def _simulate_chunk(gyro, profiles, keys, bias_key, ts, model, max_steps=None):
    def one(p, k):
        rec, _, result = simulate_with_stats(gyro, p, model, key=k, bias_key=bias_key, ts=ts,
                                             max_steps=max_steps)  # fmt: skip
        return rec, result

    if keys is None:
        return jax.vmap(lambda p: one(p, None))(profiles)
    return jax.vmap(one)(profiles, keys)


def failed_member(message: str) -> tuple[int | None, str]:
    """(the batch member a `_ChunkCheck` message names, or None; the message without that
    note and without the chunk program's own prefix) — for callers that name the point."""
    found = re.search(r"\s*\(batch member \((\d+),?\)\)", message)
    detail = message if found is None else message.replace(found.group(0), "")
    detail = detail.removeprefix(f"{_CHUNK_WHAT}: ")
    return (None if found is None else int(found.group(1))), detail


def switch_on_keys(
    gyro: Gyro, key: jax.Array | None, bias_key: jax.Array | None, size: int, owner: str
) -> tuple[jax.Array | None, jax.Array | None]:
    """(one noise key per run, the switch-on key) of `size` runs of one switch-on: `key`
    split in two, the first half split again into the runs' keys (so a run's data do not
    depend on the other runs' — with JAX's `jax_threefry_partitionable`, on by default since
    JAX 0.5, `split(k, n)[i]` does not depend on `n`), the second the switch-on's unless `bias_key` is given.
    Without noise: `(None, bias_key)`.

    **Raises:** `ValueError` when the gyro has noise and `key` is None; `TypeError` or
    `ValueError` for a key that is not one PRNG key (naming `owner`, the public caller)."""
    for name, k in (("key", key), ("bias_key", bias_key)):
        if k is not None:
            check_key(f"{owner}: {name} (or None)", k, "one call per switch-on")
    if gyro.noise is None:
        return None, bias_key
    if key is None:
        raise ValueError("this gyro has noise: pass key=jax.random.key(…)")
    k_runs, k_bias = jax.random.split(key)
    return jax.random.split(k_runs, size), (k_bias if bias_key is None else bias_key)


class RunGroup(NamedTuple):
    """Runs simulated by one compiled simulator.

    - `ts`: their output times [s] (host array, from 0).
    - `members`: the runs' indices, in the order they are simulated.
    - `chunk`: runs per compiled call; the last call is padded with the group's last run.
    """

    ts: np.ndarray
    members: np.ndarray
    chunk: int


def simulate_runs(
    gyro: Gyro,
    groups: Sequence[RunGroup],
    profiles: Callable[[np.ndarray, float], Profile],
    keys: jax.Array | None,
    bias_key: jax.Array | None,
    model: str,
    *,
    samples: np.ndarray,
    failure: Callable[[np.ndarray, str], str],
    unit: str,
    first_run: int = 0,
) -> MeasuredData:
    """Simulate runs `0 … S−1` (every run in exactly one of `groups`) and return their data,
    run i numbered `first_run + i`, in run order.

    - `profiles(take, length_s)`: the batch of profiles of runs `take` (host indices), each
      running at least `length_s` [s] (the group's last output time).
    - `keys`: one noise key per run (`switch_on_keys`), or None without noise; `bias_key`:
      the switch-on's, shared by every run.
    - `samples`: per run, how many of its group's output samples it keeps (host ints) —
      a run padded to a longer group is cut back.
    - `failure(take, message)`: the `RuntimeError` message of a failed call on runs `take`
      (`failed_member` finds the batch member in `message`).
    - `unit`: what a run is called in the progress bar (`run`, `segment`).
    """
    size = len(samples)
    impl = data = None
    if keys is not None:
        impl, data = jax.random.key_impl(keys), np.asarray(jax.random.key_data(keys))
    per_run: list[dict | None] = [None] * size
    with bar(size, f"simulating {size} {unit}s", unit=unit) as progress:
        for group in groups:
            members = np.asarray(group.members)
            ts = np.asarray(group.ts)
            ts_device, length_s = device(ts), float(ts[-1])
            n_pad = -len(members) % group.chunk
            padded = np.concatenate([members, np.repeat(members[-1:], n_pad)])
            for s in range(0, len(padded), group.chunk):
                take = padded[s : s + group.chunk]
                k = None
                if data is not None:
                    k = jax.random.wrap_key_data(device(data[take]), impl=impl)
                batch = profiles(take, length_s)
                # the solver's step limit for the batch's longest member (its profiles are
                # concrete here, traced inside); None keeps the short runs' shared program
                steps = default_max_steps(gyro, batch, model)
                steps = None if steps == MAX_STEPS.get(model) else steps
                try:
                    rec, _ = _simulate_chunk(gyro, batch, k, bias_key, ts_device, model, steps)
                except RuntimeError as err:
                    raise RuntimeError(failure(take, str(err))) from None
                cols = rec.to_data().columns  # consecutive runs of len(ts) rows each
                real = min(group.chunk, len(members) - s)
                for j in range(real):
                    rows = slice(j * len(ts), j * len(ts) + int(samples[take[j]]))
                    run = {c: v[rows] for c, v in cols.items()}
                    run["run"] = np.full(len(run["run"]), take[j] + first_run, dtype=np.int64)
                    per_run[take[j]] = run
                progress.update(real)
    names = list(per_run[0])
    return MeasuredData({c: np.concatenate([r[c] for r in per_run]) for c in names})
