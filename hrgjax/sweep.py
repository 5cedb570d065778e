"""`sweep`: a function over the Cartesian product of parameter grids, batched by vmap."""

from __future__ import annotations

import math
import types
import weakref

import jax
import jax.numpy as jnp
import numpy as np

from . import _cost, _upstream, plausible
from ._checks import check_flag, whole_number


class _FnCache:
    """Values kept per swept function while it lives: by the function itself where it is
    hashable, else by its identity — a callable equinox Module with array fields cannot be
    hashed, and a fresh `jax.jit` on every sweep compiled its same shapes again each time.
    A value reaches its function only through a weak reference, so the cache never keeps a
    function (and the arrays it holds) alive: the entry goes when the function goes. A bound
    method (`obj.method`, a new object at each access) is kept by its function and its
    object, so `sweep(obj.method, …)` reuses the batch while `obj` lives."""

    def __init__(self):
        self.by_key: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
        self.by_id: dict = {}
        self.by_method: dict = {}

    def get(self, fn, make):
        """`make(ref)`'s value kept for `fn`, where `ref()` returns `fn` (the value must
        reach `fn` only through it); a `fn` that cannot be weakly referenced (a builtin)
        gets a fresh one each time."""
        if isinstance(fn, types.MethodType):
            return self._get_method(fn, make)
        try:
            ref = weakref.ref(fn)
        except TypeError:
            return make(lambda: fn)
        try:
            value = self.by_key.get(fn)
        except TypeError:  # unhashable: by identity
            key = id(fn)
            kept = self.by_id.get(key)
            if kept is not None and kept[0]() is fn:
                return kept[1]
            value = make(ref)
            gone = weakref.ref(fn, lambda _, key=key: self.by_id.pop(key, None))
            self.by_id[key] = (gone, value)
            return value
        if value is None:
            value = self.by_key[fn] = make(ref)
        return value

    def _get_method(self, fn, make):
        """`get` for a bound method: keyed by (its function, its object's identity)."""
        try:
            ref = weakref.WeakMethod(fn)
        except TypeError:  # an object that cannot be weakly referenced
            return make(lambda: fn)
        func, obj = fn.__func__, fn.__self__
        key = (id(func), id(obj))
        kept = self.by_method.get(key)
        if kept is not None and kept[0]() is obj and kept[1] is func:
            return kept[2]
        value = make(ref)
        gone = weakref.ref(obj, lambda _, key=key: self.by_method.pop(key, None))
        self.by_method[key] = (gone, func, value)
        return value


_BATCHED = _FnCache()
_PROBES = _FnCache()


def sweep(fn, *, chunk_size: int | None = None, progress: bool = False, cost="auto", **grids):
    """Evaluate `fn(**point)` on the Cartesian product of 1-D grids.

    `hg.sweep(fn, temperature_c=jnp.linspace(-40, 60, 11), rate_dps=jnp.array([0.1, 5, 400]))`
    calls `fn(temperature_c=…, rate_dps=…)` for every pair in one `jax.jit(jax.vmap(…))` and
    returns outputs with leading shape `(11, 3)` (keyword order). The compiled batch is kept
    per `fn` (a bound method `obj.method`: per method and object): a second sweep of the
    same function on grids of the same sizes compiles nothing. So `fn` must be pure — a
    function reading a global or closure variable that changes afterwards keeps the value
    it was compiled with, as under `jax.jit` (pass the value as a grid, or sweep a new
    function); a bound method's object's arrays are constants of its batch likewise. When
    several devices are visible the flattened batch is sharded over them (padded to a
    multiple of the device count). The batch runs on JAX's default backend — an
    accelerator where there is one (measured on an H200: 2.7× its host's 16 cores at 64 members,
    23.5× at 10 000), unlike a single eager `simulate`, which goes to the CPU there.

    `fn` runs under `jax.jit`: build profiles from Python numbers (their knot times stay
    concrete, so `simulate` can derive its output grid) or pass `ts=` to `simulate`.
    A sweep differentiates and compiles in the caller's `jax.grad` / `jax.jit` with respect
    to values `fn` closes over (chunks, cost order and all; the grids themselves are concrete):
    it then returns traced arrays, not NumPy's.

    Under JAX's multi-process runtime (every process has called `jax.distributed.initialize()`
    and then runs the same `sweep` on the same grids), each process evaluates an equal share
    of the flattened grid on its own local devices — one contiguous block, or, when the
    members' costs are known (`cost`), the members sorted by cost and dealt round-robin, so
    every process gets a like mix — with no communication while `fn` runs; the shares are
    then gathered, so every process returns the whole result, as host
    (NumPy) arrays, equal to a one-process run. See docs/scaling.md.

    **Arguments:**

    - `fn`: a function of keyword arguments returning a pytree of arrays.
    - `chunk_size`: evaluate the flattened grid `chunk_size` points at a time (rounded up to
      a multiple of the device count), each chunk's result moved to host memory — for grids
      whose batch does not fit the devices at once. Every chunk has the same shape (the last
      is padded), so `fn` compiles once. `None`: the whole grid in one batch.
    - `progress`: show a progress bar over the chunks on stderr (tqdm when installed; on
      process 0 only when there are several).
    - `cost`: how members are ordered. An adaptive solver under `vmap` steps every member
      until the slowest is done, so members of very different cost (rates from 0.1 to
      400 °/s, say) waste most of a batch. `"auto"` (default): the solver steps each member
      will take, estimated from the profile of the first `simulate` call in `fn`
      (`hrgjax._cost`; `fn` is traced once more for it, no solve is compiled; a
      differentiated `simulate` counts as undifferentiated, one under `fn`'s own `jit`,
      `scan` or `vmap` gives no estimate: grid order); the members are
      sorted by it and run in chunks of similar cost — of one size that depends on the
      grid's size and the devices only (`hrgjax._cost.chunk_length`: on a CPU within 1.34×
      of the best size's estimated time for costs alike or spread up to 30×, 52 of 256
      members; on an accelerator one batch up to ≈ 2·10⁴ members), or `chunk_size`; so
      new values on a grid of the same sizes compile nothing. A callable `cost(**point)` →
      estimated cost per point (NumPy, on the flattened grids) orders by your own estimate;
      `None` keeps the grid order. Results always come back in the grid's order, equal to the unordered ones to
      round-off: each member is computed by the same compiled program, but XLA:CPU may round
      a member by an ulp differently at another place in the batch, which the adaptive step
      control carries to the end (measured ≤ 1e-14 relative in the wave angle).
    - `**grids`: 1-D arrays, one per keyword (finite).

    A sweep whose outputs over the whole grid would exceed
    `hrgjax.plausible.MAX_OUTPUT_SAMPLES` × `BYTES_PER_SAMPLE` bytes (≈ 4.7 GiB) is refused
    before the batch runs; a check that fails inside `fn` (a NaN in a traced parameter, a
    solver out of steps) is raised as one line (`RuntimeError`).
    """
    if not callable(fn):
        raise TypeError(f"sweep: fn must be a function of the grids' keywords; got "
                        f"{type(fn).__name__}")  # fmt: skip
    if not grids:
        raise ValueError(
            "sweep needs at least one grid, e.g. temperature_c=jnp.linspace(-40, 60, 11)"
        )
    if chunk_size is not None:
        chunk_size = whole_number("chunk_size", chunk_size, "None or a whole number ≥ 1 of points")
        if chunk_size < 1:
            raise ValueError(f"chunk_size must be a positive number of points; got {chunk_size}")
    if isinstance(progress, int | np.integer) and progress in (0, 1):  # 0/1 as False/True
        progress = bool(progress)
    progress = check_flag("sweep: progress", progress)
    names = list(grids)
    arrays = []
    for name in names:
        # on the host (JAX's dtype, NumPy's arrays): the grid, its order and its chunks are
        # NumPy work, not small eager programs compiled for every new chunk shape
        try:
            g = np.asarray(grids[name])
        except ValueError:  # ragged
            g = np.empty(0, dtype=object)
        if g.dtype.kind not in "biufc":
            raise TypeError(f"sweep grid {name!r} must be a non-empty 1-D array of numbers; got "
                            f"{type(grids[name]).__name__} of dtype {g.dtype}")  # fmt: skip
        g = g.astype(jax.dtypes.canonicalize_dtype(g.dtype), copy=False)  # as jnp.asarray
        if g.ndim != 1 or g.shape[0] == 0:
            raise ValueError(
                f"sweep grid {name!r} must be a non-empty 1-D array; got shape {g.shape}"
            )
        if jnp.issubdtype(g.dtype, jnp.inexact) and not np.all(np.isfinite(g)):
            i = int(np.flatnonzero(~np.isfinite(g))[0])
            raise ValueError(f"sweep grid {name!r} must be finite; {name}[{i}] is {g[i]}")
        arrays.append(g)
    shape = tuple(a.shape[0] for a in arrays)
    mesh = np.meshgrid(*arrays, indexing="ij")
    flat = {n: m.reshape(-1) for n, m in zip(names, mesh, strict=True)}
    total = int(np.prod(shape))
    call = _batched(fn)
    if not (cost is None or callable(cost) or (isinstance(cost, str) and cost == "auto")):
        raise ValueError(f'cost must be "auto", None or a callable cost(**point); got {cost!r}')
    n_proc, rank = jax.process_count(), jax.process_index()
    costs = member_costs(fn, cost, flat)  # the same on every process
    devices = jax.local_devices()
    if costs is not None:
        order = np.argsort(costs, kind="stable")
        platform = devices[0].platform
        if (
            n_proc == 1
            and chunk_size is None
            and (_cost.chunk_length(total, len(devices), platform) >= total)
        ):
            costs = None  # one batch on one process: the order is moot, keep the grid's
    if n_proc == 1 and costs is None:
        out = _local(call, flat, chunk_size, progress, total)
    else:
        # Several processes (jax.distributed) and/or members ordered by cost: each process
        # evaluates an equal share of the grid on its own devices — contiguous blocks, or
        # the members sorted by cost and dealt round-robin (every process a like mix, its
        # share still sorted) — and the shares are gathered back into the grid's order.
        per = -(-total // n_proc)
        if costs is None:
            hands = [np.arange(r * per, min((r + 1) * per, total)) for r in range(n_proc)]
        else:
            hands = [order[r::n_proc] for r in range(n_proc)]
        fill = lambda h: np.repeat(h[-1:] if h.size else [total - 1], per - h.size)
        idx = np.concatenate([np.r_[h, fill(h)] for h in hands]).astype(int)
        mine = idx[rank * per : (rank + 1) * per]
        chunk = chunk_size
        if costs is not None:
            chunk = _cost.chunk_length(per, len(devices), platform, chunk_size)
            chunk = None if chunk >= per and chunk_size is None else chunk
        pts = {n: v[mine] for n, v in flat.items()}
        out = _local(call, pts, chunk, progress and rank == 0, total)
        out = jax.tree_util.tree_map(lambda x: x[:per], out)  # (traced under grad: kept so)
        if n_proc > 1:
            out = jax.tree_util.tree_map(_gather, out)
        real = np.concatenate([np.arange(h.size) + r * per for r, h in enumerate(hands)])
        back = np.empty(total, dtype=int)
        back[idx[real]] = real
        out = jax.tree_util.tree_map(lambda x: x[back], out)
    return jax.tree_util.tree_map(lambda x: x[:total].reshape(shape + x.shape[1:]), out)


def member_costs(fn, cost, flat: dict) -> np.ndarray | None:
    """The estimated cost of every point of a flattened grid, as `sweep` orders them.

    **Arguments:** `fn` as `sweep`'s; `cost` as `sweep`'s (`"auto"`: the solver steps each
    `simulate` call inside `fn` is estimated to take, `hrgjax._cost.steps_estimate`; a
    callable of the point's named values; None); `flat`: name → 1-D array of every point.

    **Returns:** one number per point (NumPy, relative units), or None to keep the grid order
    (no cost asked for, or `fn` reaches no `simulate`)."""
    if cost is None:
        return None
    if callable(cost):
        c = np.asarray(cost(**{n: np.asarray(v) for n, v in flat.items()}), dtype=float)
        n = next(iter(flat.values())).shape[0]
        if c.shape != (n,) or not np.all(np.isfinite(c)):
            raise ValueError(
                f"cost(**point) must return {n} finite numbers, one per point; got shape {c.shape}"
            )
        return c
    probe, state = _probe(fn)
    if not state["simulates"]:
        return None
    try:
        c = np.asarray(probe(flat), dtype=float)
    except jax.errors.TracerArrayConversionError:
        # this sweep runs under the caller's `jit` (the estimate is traced): the grid's
        # order this time; `fn` itself keeps its estimate for eager sweeps
        return None
    except jax.errors.UnexpectedTracerError:
        # The estimate is a value of a transformation inside `fn` that has no primal to
        # take (`_cost.report`): `fn`'s own jit, a vmap inside `fn`, a scan around
        # `simulate`. No estimate then: the grid's order, as for a `fn` with no `simulate`.
        state["simulates"] = False
        return None
    if not state["simulates"]:  # this trace found no simulate call
        return None
    return c if np.all(np.isfinite(c)) else None


def _probe(fn):
    """`(jax.jit(jax.vmap(…)), state)`: `fn` traced with the cost probe on (hrgjax._cost),
    giving the first `simulate` call's estimated steps per point. Kept per `fn`;
    `state["simulates"]` turns False once a trace has shown that `fn` calls no `simulate`,
    or none whose estimate can leave `fn`'s own transformations (`member_costs`)."""

    def make(ref):
        state = {"simulates": True}

        def one(kw):
            with _cost.probing():
                try:
                    ref()(**kw)
                except _cost.Found as found:
                    return jnp.asarray(found.cost, dtype=float)
            state["simulates"] = False
            return jnp.zeros((), dtype=float)

        return jax.jit(jax.vmap(one)), state

    return _PROBES.get(fn, make)


def _batched(fn):
    """`jax.jit(jax.vmap(fn))` on a dict of keyword arrays, one per `fn` (kept while `fn`
    lives) and per plausible ranges (`simulate` reads `plausible.RANGES` when traced: a
    batch compiled before a `plausible.relaxed` block would hold the old ranges inside it),
    so repeated sweeps of one function reuse its compiled batch."""
    ranges = tuple(sorted(plausible.RANGES.items()))
    by_ranges, ref = _BATCHED.get(fn, lambda ref: ({}, ref))
    if ranges not in by_ranges:
        by_ranges[ranges] = jax.jit(jax.vmap(lambda kw: ref()(**kw)))
    return by_ranges[ranges]


def _local(call, flat, chunk_size, progress, total):
    """`call` over a flat batch on this process's devices, whole or in chunks (`total`: the
    points of the whole grid, whose outputs the host will hold)."""
    devices = jax.local_devices()
    if chunk_size is None:
        return _batch(call, flat, devices, total)
    n = next(iter(flat.values())).shape[0]
    chunk = -(-int(chunk_size) // len(devices)) * len(devices)
    n_chunks = -(-n // chunk)
    flat = _pad(flat, n_chunks * chunk - n)
    parts = []
    for i in _progress(range(n_chunks), progress):  # (every chunk has the first one's shapes)
        part = {k: v[i * chunk : (i + 1) * chunk] for k, v in flat.items()}
        out = _batch(call, part, devices, total if i == 0 else None)
        # traced outputs (a sweep under the caller's jax.grad or jit) stay traced: the host
        # cannot hold them, and the chunks join on the device
        traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(out))
        parts.append(out if traced else jax.device_get(out))
    join = (
        jnp.concatenate
        if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(parts))
        else np.concatenate
    )
    return jax.tree_util.tree_map(lambda *xs: join(xs), *parts)


def _gather(block):
    """Concatenate every process's equally long block, in process order, on every process."""
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(block, tiled=True))


def _pad(flat, pad):
    """Repeat the last point `pad` times (results for padding are dropped); NumPy."""
    if pad == 0:
        return flat
    return {n: np.concatenate([v, np.repeat(v[-1:], pad)]) for n, v in flat.items()}


def _batch(call, flat, devices, total=None):
    """`call` on one flat batch, sharded over `devices` when there are several (the result
    may be padded at the end); with `total`, refused first when the outputs of the `total`
    points of the whole grid would not fit (`_check_size`)."""
    if len(devices) > 1:
        from jax.sharding import Mesh, NamedSharding, PartitionSpec

        n = next(iter(flat.values())).shape[0]
        flat = _pad(flat, (-n) % len(devices))
        sharding = NamedSharding(Mesh(np.array(devices), ("batch",)), PartitionSpec("batch"))
        flat = jax.device_put(flat, sharding)
    if total is not None:
        _check_size(call, flat, total)
    return _run(call, flat)


def _check_size(call, flat, total):
    """Refuse a sweep whose outputs over its `total` grid points exceed what hrgjax allocates
    at once (`plausible.MAX_OUTPUT_SAMPLES` × `plausible.BYTES_PER_SAMPLE`, ≈ 4.7 GiB), before
    anything runs: `fn`'s output shapes come from its trace (`jax.eval_shape`, which the
    call then reuses), so nothing is allocated to find them."""
    shapes = jax.tree_util.tree_leaves(jax.eval_shape(call, flat))
    each = sum(math.prod(s.shape[1:]) * s.dtype.itemsize for s in shapes)
    limit = plausible.MAX_OUTPUT_SAMPLES * plausible.BYTES_PER_SAMPLE
    if each * total > limit:
        raise ValueError(
            f"sweep: fn's outputs over the {total} grid points take {each * total / 2**30:.3g} "
            f"GiB ({each} bytes a point), more than the {limit / 2**30:.3g} GiB hrgjax "
            "allocates at once; return less from fn (the samples you need), sweep a smaller "
            "grid, or raise hrgjax.plausible.MAX_OUTPUT_SAMPLES"
        )


def _run(call, flat):
    """`call(flat)`, finished; a check that fails inside it (`eqx.error_if`: a NaN in a
    traced parameter, a solver out of steps) raised as one line, not JAX's callback trace."""
    try:
        with _upstream.quiet_failed_checks():
            return jax.block_until_ready(call(flat))
    except _upstream.CHECK_ERRORS as err:
        message = _upstream.failed_check_message(err)
        if message is None:
            raise
        raise RuntimeError(f"sweep: at one or more grid points, {message}") from None


def _progress(it, show: bool):
    if not show:
        return it
    try:
        from tqdm.auto import tqdm

        return tqdm(it, desc="sweep", unit="chunk")
    except ImportError:
        import sys

        def plain():
            n = len(it)
            for i, x in enumerate(it):
                print(f"\rsweep: chunk {i + 1}/{n}", end="", file=sys.stderr, flush=True)
                yield x
            print(file=sys.stderr)

        return plain()
