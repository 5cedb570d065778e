"""Compiled programs that JAX's persistent cache can keep, with errors raised on the host.

JAX does not write a program that calls back into Python to its on-disk cache (the callback
is a pointer into the running process). Equinox's `error_if` — used by hrgjax, diffrax and
optimistix for run-time checks — is such a callback, so every program with a check in it
compiled afresh in every process. `program` fixes that for our own entry points:

- called with concrete arrays (the usual case: a script, the CLI), the function is traced
  with equinox's checks in their NaN form (no callback; a failed check poisons its value),
  the compiled program is cacheable, and `check(output)` turns a failure into the usual
  one-line Python error after the call;
- called under someone else's `jit`/`vmap`/`grad` trace, the function is traced exactly as
  before (checks raise from inside the program), so nothing changes for the caller;
- called while one of our programs is being traced, it joins that program's mode and the
  outer program's check sees the failure.

The two modes are two separate `eqx.filter_jit` functions, so a trace of one is never
reused by the other.
"""

from __future__ import annotations

import contextlib
import functools
import threading

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

try:  # the trace-time switch of equinox's error_if (a module global read at trace time)
    import equinox._errors as _eqx_errors

    _CAN_SWITCH = hasattr(_eqx_errors, "EQX_ON_ERROR")
except ImportError:  # pragma: no cover - a future equinox
    _eqx_errors, _CAN_SWITCH = None, False

_state = threading.local()


def tracing_callback_free() -> bool:
    """Whether the current trace is one of our callback-free programs (trace-time flag)."""
    return getattr(_state, "depth", 0) > 0


@contextlib.contextmanager
def _callback_free():
    depth = getattr(_state, "depth", 0)
    _state.depth = depth + 1
    old = _eqx_errors.EQX_ON_ERROR if _CAN_SWITCH else None
    if _CAN_SWITCH:
        _eqx_errors.EQX_ON_ERROR = "nan"
    try:
        yield
    finally:
        if _CAN_SWITCH:
            _eqx_errors.EQX_ON_ERROR = old
        _state.depth = depth


def _is_traced(tree) -> bool:
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def all_finite(tree) -> bool:
    """Host check: every floating leaf of `tree` is finite."""
    for x in jax.tree_util.tree_leaves(tree):
        if eqx.is_inexact_array(x) and not np.all(np.isfinite(np.asarray(x))):
            return False
    return True


def finite_check(what: str):
    """A `check` for `program`: a non-finite floating output is an error naming `what`."""

    def check(out):
        if not all_finite(out):
            return (
                f"{what} produced NaN or inf (a solver failed or an input is out of its "
                "range); check the inputs, or run under jax.jit to see the failing check"
            )
        return None

    return check


def program(fn=None, *, check=None, error=RuntimeError):
    """Decorate `fn` as a compiled program (see the module docstring).

    **Arguments:**

    - `check`: `check(output) -> str | None`, run on the host on concrete outputs; a string
      is raised as `error(string)`. Default: every floating output must be finite.
    - `error`: the exception type raised.
    """
    if fn is None:
        return functools.partial(program, check=check, error=error)
    check = finite_check(fn.__name__.lstrip("_")) if check is None else check
    plain = eqx.filter_jit(fn)

    @functools.wraps(fn)
    def _callback_free_fn(*args, **kwargs):
        return fn(*args, **kwargs)

    quiet = eqx.filter_jit(_callback_free_fn)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        if tracing_callback_free():
            out = quiet(*args, **kwargs)
        elif _is_traced((args, kwargs)):
            return plain(*args, **kwargs)
        else:
            with _callback_free():
                out = quiet(*args, **kwargs)
        if not _is_traced(out):
            message = check(out)
            if message:
                raise error(message)
        return out

    call.plain = plain
    call.callback_free = quiet
    return call


def first_failure(result, enumeration) -> str | None:
    """Host: the message of the first failed member of an equinox result enumeration item
    (diffrax or optimistix `RESULTS`), or None when all succeeded."""
    codes = np.asarray(result._value).ravel()
    bad = np.flatnonzero(codes != 0)
    if bad.size == 0:
        return None
    item = eqx.tree_at(lambda r: r._value, result, jnp.asarray(codes[bad[0]]))
    return enumeration[item]


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


def keep_result_check(value, result):
    """Inside a program: under a caller's own trace, raise `result`'s failure from inside the
    program (as a solver's `throw=True` would); in our callback-free programs leave it to
    the host check. Returns `value`."""
    if tracing_callback_free():
        return value
    return result.error_if(value, result != result._enumeration.successful)


def solver_check(what: str, enumeration=None):
    """A `check` for programs returning `(…, result)`: the solver's failure message, else
    any non-finite floating output, names `what`."""

    def check(out):
        import diffrax

        message = first_failure(out[-1], enumeration or diffrax.RESULTS)
        if message is not None:
            return f"{what}: the solver failed: {message}"
        return finite_check(what)(out[:-1])

    return check
