"""Compiled programs that JAX's persistent cache can keep, with errors raised on the host.

JAX does not write a program that calls back into Python to its on-disk cache (the callback
is a pointer into the running process). Equinox's `error_if` — used by hrgjax, diffrax and
optimistix for run-time checks — is such a callback, so every program with a check in it
compiled afresh in every process. `program` fixes that for our own entry points: the
function is always traced with equinox's checks in their NaN form (no callback: a failed
check poisons its value), and its failures come out as values — a solver's result code, a
NaN — that a `Check` inspects after the call:

- on concrete outputs (a script, the CLI), `Check.host` raises the usual one-line Python
  error;
- under a caller's own `jit`/`vmap`/`grad` trace, `Check.traced` puts an `eqx.error_if` on
  the outputs, in the caller's program, so the caller sees the same error as before;
- while one of our programs is itself being traced, nothing is added: the outermost
  program's check sees the failure.

While our programs trace, equinox's error checks also go to a private compiled-check cache,
so a check traced here in NaN form is never reused by code that expects it to raise.
"""

from __future__ import annotations

import contextlib
import functools
import threading
import types

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from hrgjax import _export, _upstream

_state = threading.local()


def tracing_callback_free() -> bool:
    """Whether the current trace is one of our callback-free programs (trace-time flag)."""
    return getattr(_state, "depth", 0) > 0


@contextlib.contextmanager
def callback_free():
    """While inside, programs trace callback-free (equinox's checks in NaN form)."""
    depth = getattr(_state, "depth", 0)
    _state.depth = depth + 1
    switch = contextlib.nullcontext() if depth else _upstream.errors_as_nan()
    try:
        with switch:
            yield
    finally:
        _state.depth = depth


def device(x, dtype=None) -> jax.Array:
    """A host value (NumPy array, list, number) as a device array, without an XLA program.

    Outside a trace `jnp.asarray` stages the value through a small compiled program, one per
    new shape (≈ 10 ms each, a persistent-cache read even when warm). Always a copy: on CPU
    `jax.device_put` (even `may_alias=False`) shares a 64-byte-aligned NumPy buffer, and a
    later edit of the user's array would change the result; such a share is copied here.
    Floats become float64 (x64 on) and are not weakly typed, as `jnp.asarray` of a NumPy
    array. Inside a trace (`jit`), `jnp.asarray`."""
    if isinstance(x, jax.Array):
        return x if dtype is None else x.astype(dtype)
    if not _upstream.trace_state_clean():  # inside a trace: a constant of the caller's program
        try:  # (strongly typed, as outside: a Python 2.0 would be weak)
            return jnp.asarray(np.asarray(x, dtype=dtype))
        except jax.errors.TracerArrayConversionError:  # a list holding traced values
            return jnp.asarray(x, dtype=dtype)
    host = np.asarray(x, dtype=dtype)
    out = jax.device_put(host)
    if host.size and out.unsafe_buffer_pointer() == host.ctypes.data:  # shared, not copied
        out = jax.device_put(host.copy())
    return out


def fused(fn=None, *, prepare=None, **jit_kwargs):
    """Decorate an array function so that a call outside a trace runs it as *one* compiled
    program, and a call inside the caller's `jit`/`vmap`/`grad` trace inlines it (no nested
    call in the caller's program). `jit_kwargs` go to `jax.jit` (`static_argnames`, …).

    Called eagerly, each `jax.numpy` operation is a program of its own, compiled on its first
    call with each new shape: ≈ 20–40 ms on a CPU, so a 30-operation helper cost ≈ 1 s the
    first time a script called it on a new length (`benchmarks/eager_ops.py`). Fused, it is
    one compile of ≈ the cost of one such operation.

    `prepare(*args, **kwargs)`, when given, runs first on the host and returns the positional
    arguments for `fn` (the argument checks of `hg.noise`'s draws).

    NumPy float64, int64 and bool scalars are passed as the Python numbers of the same value
    (`_as_python`), so a value read from a file meets the program of a literal one.

    Not for functions with equinox checks (`eqx.error_if`, `check_finite`) inside: JAX keeps
    the traced function by its argument shapes, and equinox reads its error mode (raise, or
    NaN inside `program`) while tracing, so the first caller's mode would stick."""
    if fn is None:
        return functools.partial(fused, prepare=prepare, **jit_kwargs)
    return Fused(fn, jax.jit(fn, inline=True, **jit_kwargs), prepare)


class Fused:
    """A `fused` function: called, the compiled program (NumPy scalars as Python numbers);
    `lower`, `trace`, `eval_shape`, `clear_cache` and `_cache_size` are the program's. Beside
    an array of fewer than 64 bits the NumPy scalars pass as they are (`_narrow`). They
    are properties of the class, not attributes of the object: `jax.vmap` copies a function's
    attributes onto its own wrapper (`functools.wraps`), so `jax.jit(jax.vmap(f)).lower` was
    the unbatched program's. As a class attribute it binds as a method (`profile.sample`)."""

    def __init__(self, fn, compiled, prepare=None):
        functools.update_wrapper(self, fn)
        self._program, self._prepare = compiled, prepare

    def __call__(self, *args, **kwargs):
        if self._prepare is not None:
            args, kwargs = self._prepare(*args, **kwargs), {}
        values = (*args, *kwargs.values())
        if any(map(_python_type, values)) and not _narrow(values):
            args = tuple(map(_as_python, args))
            kwargs = {k: _as_python(v) for k, v in kwargs.items()}
        return self._program(*args, **kwargs)

    def __get__(self, obj, objtype=None):
        return self if obj is None else types.MethodType(self, obj)

    lower = property(lambda self: self._program.lower)
    trace = property(lambda self: self._program.trace)
    eval_shape = property(lambda self: self._program.eval_shape)
    clear_cache = property(lambda self: self._program.clear_cache)
    _cache_size = property(lambda self: self._program._cache_size)


_PYTHON = {np.dtype(np.float64): float, np.dtype(np.int64): int, np.dtype(np.bool_): bool}
"""The NumPy scalar types `fused` passes as the Python number of the same value and dtype."""


def _python_type(x):
    """The Python type `_as_python` gives `x`, or None when it leaves `x` as it is."""
    if isinstance(x, np.generic | np.ndarray) and x.ndim == 0:
        return _PYTHON.get(x.dtype)
    return None


def _narrow(values) -> bool:
    """Whether an array of fewer than 64 bits (float32, int32, complex64) is among `values`'
    leaves: beside it a weak number takes its precision, where a strong float64 gave float64
    (`fused` then passes NumPy scalars as they are, `strong_floats` weak floats)."""
    leaves = jax.tree_util.tree_leaves(values)
    return any(isinstance(x, np.ndarray | jax.Array) and x.dtype != bool
               and x.dtype.itemsize * (1 + (x.dtype.kind != "c")) < 16 for x in leaves)  # fmt: skip


def _as_python(x):
    """`x` as a Python number when it is a NumPy float64, int64 or bool scalar (or 0-d array):
    JAX types a Python number weakly and a NumPy one strongly, and keeps a compiled program by
    its arguments' weak types, so `tau0=np.float64(1.0)` after `tau0=1.0` (a value read from a
    file, `np.diff(t)[0]`) compiled the same program again. Same value, same dtype."""
    python = _python_type(x)
    return x if python is None else python(x)


def strong_floats(tree):
    """`tree` with its concrete, weakly typed floating arrays made strongly typed (same dtype,
    value and placement, committed or not). `jnp.asarray(2.0)`, `jnp.full(n, 2.0)` and
    arithmetic on them are weakly typed, and a compiled program is kept by its arguments'
    weak types as well as their shapes: a gyro with one such leaf recompiled `simulate`'s
    whole solve (1 compile, ≈ 2 s) although its numbers were those of the strong gyro
    before. Copied through the host, not an XLA program (`device`); traced leaves are the
    caller's and pass as they are, and so does every leaf where an array of fewer than 64
    bits is among them (`_narrow`: a weak float keeps its precision; strong, it would
    promote the result to float64)."""
    leaves, treedef = jax.tree_util.tree_flatten(tree)
    weak = [i for i, x in enumerate(leaves)
            if isinstance(x, jax.Array) and not isinstance(x, jax.core.Tracer)
            and jnp.issubdtype(x.dtype, jnp.inexact) and x.weak_type]  # fmt: skip
    if not weak or _narrow(leaves):
        return tree
    for i in weak:
        x = leaves[i]
        leaves[i] = jax.device_put(np.asarray(x), x.sharding if x.committed else None)
    return jax.tree_util.tree_unflatten(treedef, leaves)


def _is_traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def all_finite(tree) -> bool:
    """Host check: every floating leaf of `tree` is finite."""
    for x in jax.tree_util.tree_leaves(tree):
        if eqx.is_inexact_array(x) and not np.all(np.isfinite(np.asarray(x))):
            return False
    return True


def _traced_all_finite(tree):
    return _all_finite([x for x in jax.tree_util.tree_leaves(tree) if eqx.is_inexact_array(x)])


@fused
def _all_finite(arrays):
    flags = [jnp.all(jnp.isfinite(x)) for x in arrays]
    return jnp.all(jnp.stack(flags)) if flags else jnp.asarray(True)


class Check:
    """What `program` checks on its outputs: every floating output is finite; with
    `result_index`, the solver result (a diffrax or optimistix `RESULTS` item) at that
    position of the output tuple must be successful first."""

    def __init__(
        self, what: str, *, result_index: int | None = None, enumeration=None, nonfinite=None
    ):
        self.what = what
        self.result_index = result_index
        self.enumeration = enumeration
        self.nonfinite = nonfinite

    def _split(self, out):
        if self.result_index is None:
            return out, None
        rest = tuple(x for i, x in enumerate(out) if i != self.result_index % len(out))
        return rest, out[self.result_index]

    def _enumeration(self):
        if self.enumeration is not None:
            return self.enumeration
        import diffrax

        return diffrax.RESULTS

    def _nonfinite(self) -> str:
        if self.nonfinite:
            return self.nonfinite
        return (
            f"{self.what} produced NaN or inf (a solver failed or an input is out of its "
            "range); check the inputs"
        )

    def host(self, out) -> str | None:
        """The error message for concrete outputs, or None."""
        values, result = self._split(out)
        if result is not None:
            message = first_failure(result, self._enumeration())
            if message is not None:
                return f"{self.what}: the solver failed: {message}"
        return None if all_finite(values) else self._nonfinite()

    def traced(self, out):
        """The outputs with the same checks as `eqx.error_if`s in the caller's trace."""
        values, result = self._split(out)
        if result is not None:
            out = result.error_if(out, result != self._enumeration().successful)
        return eqx.error_if(out, ~_traced_all_finite(values), self._nonfinite())


class Unchecked(Check):
    """No check: the caller inspects the outputs itself."""

    def __init__(self):
        super().__init__("")

    def host(self, out):
        return None

    def traced(self, out):
        return out


def single_run_device():
    """Where an eager single simulation runs: the CPU when JAX's default backend is an
    accelerator and the caller has chosen no device (`jax.default_device`), else None (JAX's
    default). One trajectory steps sequentially, each step a few small kernels: beside an
    NVIDIA H200 its 16-core host ran one averaged 180-s run in 11 ms against the GPU's 2.2 s,
    a full-model run 25× faster (benchmarks/gpu_backend.py, docs/scaling.md)."""
    if jax.config.jax_default_device is not None or jax.default_backend() == "cpu":
        return None
    try:
        return jax.devices("cpu")[0]
    except RuntimeError:  # JAX_PLATFORMS without the CPU
        return None


def single_run_entry(fn):
    """Decorate a public single-trajectory entry point (`hg.simulate`): an eager call on a
    machine whose default backend is an accelerator runs *all* of its work — the argument
    checks, the eager set-up and the compiled program — on `single_run_device()`, with the
    arguments' arrays moved there in one batched transfer. Placing only the compiled program
    (as `program(single_run=True)` does) left the set-up's small eager operations and each
    leaf's own transfer on the accelerator: 29.9 ms against 18.3 ms on the CPU alone beside
    an H200 (benchmarks/README.md, issue 49). Under a trace, or inside the caller's
    `jax.default_device`, `fn` runs as called."""

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if not _upstream.trace_state_clean() or _is_traced((args, kwargs)):
            return fn(*args, **kwargs)
        device = single_run_device()
        if device is None:
            return fn(*args, **kwargs)
        leaves, tree = jax.tree_util.tree_flatten((args, kwargs))
        moving = [i for i, x in enumerate(leaves)
                  if isinstance(x, jax.Array) and x.devices() != {device}]  # fmt: skip
        moved = jax.device_put([leaves[i] for i in moving], device)
        for i, x in zip(moving, moved, strict=True):
            leaves[i] = x
        args, kwargs = jax.tree_util.tree_unflatten(tree, leaves)
        with jax.default_device(device):
            return fn(*args, **kwargs)

    return call


def one_line_failures(label: str):
    """Decorate a public entry point so that a check failing inside it while the caller's
    eager `jax.vmap` or `jax.grad` runs it (an `eqx.error_if` on a traced value: a kelvin
    temperature, a NaN parameter) raises `RuntimeError("<label>: <the check's line>")`,
    not JAX's callback traceback and equinox's banner (`hg.sweep` does the same). Under the
    caller's `jax.jit` the check fails when the caller's program runs, outside `fn`: that
    error stays JAX's."""

    def wrap(fn):
        @functools.wraps(fn)
        def call(*args, **kwargs):
            if _upstream.trace_state_clean():
                return fn(*args, **kwargs)
            try:
                with _upstream.quiet_failed_checks():
                    return fn(*args, **kwargs)
            except (*_upstream.CHECK_ERRORS, eqx.EquinoxRuntimeError) as err:
                message = _upstream.failed_check_message(err)
                if message is None:
                    raise
                raise RuntimeError(f"{label}: {message}") from None

        return call

    return wrap


def program(
    fn=None, *, check: Check | None = None, error=RuntimeError, export=True, single_run=False
):
    """Decorate `fn` as a compiled, callback-free program (module docstring).

    **Arguments:**

    - `check`: a [`Check`][hrgjax._compiled.Check]; default: every floating output finite.
    - `error`: the exception type raised on the host.
    - `export`: keep the traced program with `jax.export` when the compile cache is on
      (`hrgjax._export`), so a later process skips tracing it.
    - `single_run`: `fn` is one sequential trajectory: an eager call (not under the caller's
      own trace) runs on `single_run_device()`.
    """
    if fn is None:
        return functools.partial(
            program, check=check, error=error, export=export, single_run=single_run
        )
    check = Check(fn.__name__.lstrip("_")) if check is None else check
    name = f"{fn.__module__}.{fn.__qualname__}"
    compiled = eqx.filter_jit(fn)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if tracing_callback_free():
            return compiled(*args, **kwargs)
        args, kwargs = strong_floats((args, kwargs))
        traced = _is_traced((args, kwargs))
        device = single_run_device() if single_run and _upstream.trace_state_clean() else None
        place = contextlib.nullcontext() if device is None else jax.default_device(device)
        with callback_free(), place:
            out = _export.NONE
            if export and not traced:
                out = _export.call(name, fn, args, kwargs)
            if out is _export.NONE:
                out = compiled(*args, **kwargs)
        if _is_traced(out):
            return check.traced(out)
        message = check.host(out)
        if message:
            raise error(message)
        return out

    call.compiled = compiled
    return call


def first_failure(result, enumeration) -> str | None:
    """Host: the message of the first failed member of an equinox result enumeration item
    (diffrax or optimistix `RESULTS`), or None when all succeeded."""
    bad = np.flatnonzero(~_upstream.succeeded(result, enumeration).ravel())
    if bad.size == 0:
        return None
    return enumeration[_upstream.result_member(result, int(bad[0]))]


def bucket_size(n: int, smallest: int = 64) -> int:
    """The padded length for `n` items: the next power of two ≥ max(n, `smallest`), so that
    inputs of any size meet one of a few compiled shapes (at most 2× the work)."""
    return max(int(smallest), 1 << max(int(n) - 1, 0).bit_length())


def bucket_pad(x, size: int, axis: int = 0):
    """`x` (NumPy) padded along `axis` to `size` by repeating its last entry (padding gives
    finite, ignorable results)."""
    x = np.asarray(x)
    pad = [(0, 0)] * x.ndim
    pad[axis] = (0, size - x.shape[axis])
    return np.pad(x, pad, mode="edge")
