"""Every place hrgjax reaches past the public API of JAX, equinox or optimistix, in one module.

Each function here guards one upstream internal (named in its docstring) or states why a
public API does the job; `tests/test_upstream.py` checks each against the installed
versions and names the attribute that moved when one fails. Nothing else in hrgjax imports
`jax._src`, `equinox._…` or reads a result's `_value`.
"""

from __future__ import annotations

import contextlib
import logging
import threading

import equinox as eqx
import jax
import numpy as np

# Whether `errors_as_nan` can switch equinox's checks (False: it does nothing).
try:  # equinox's trace-time switch of error_if, and its compiled-check cache
    import equinox._errors as _eqx_errors

    CAN_SWITCH_ERRORS = hasattr(_eqx_errors, "EQX_ON_ERROR") and hasattr(
        _eqx_errors, "branched_error_if_impl_jit"
    )
except ImportError:  # pragma: no cover - a future equinox: programs keep their callbacks
    _eqx_errors, CAN_SWITCH_ERRORS = None, False


def _private_check(*args, **kwargs):
    # A function of our own: equinox keys its compiled functions by the function wrapped,
    # so this one's traces (NaN form) are kept apart from equinox's own (raising form).
    return _eqx_errors.branched_error_if_impl(*args, **kwargs)


_PRIVATE_CHECKS = eqx.filter_jit(_private_check) if CAN_SWITCH_ERRORS else None
_switch = threading.Lock()


@contextlib.contextmanager
def errors_as_nan():
    """While inside, `eqx.error_if` traces in its NaN form (no host callback: a failed check
    poisons its value), and its compiled checks go to a cache of our own, apart from those
    that raise. Process-wide (held under a lock); does nothing when `CAN_SWITCH_ERRORS` is
    False. A known limit (docs/speed.md, Threads): a user's own `eqx.error_if` traced in
    another thread while this is held compiles in the NaN form too (returns NaN, no raise);
    equinox has no per-thread setting to switch instead.

    Upstream internal: `equinox._errors.EQX_ON_ERROR` (read at trace time; the public switch
    is the `EQX_ON_ERROR` environment variable, read once at import) and
    `equinox._errors.branched_error_if_impl` / `branched_error_if_impl_jit`."""
    if not CAN_SWITCH_ERRORS:
        yield
        return
    with _switch:
        old = _eqx_errors.EQX_ON_ERROR, _eqx_errors.branched_error_if_impl_jit
        _eqx_errors.EQX_ON_ERROR = "nan"
        _eqx_errors.branched_error_if_impl_jit = _PRIVATE_CHECKS
        try:
            yield
        finally:
            _eqx_errors.EQX_ON_ERROR, _eqx_errors.branched_error_if_impl_jit = old


def trace_state_clean() -> bool:
    """Whether no trace is active (no jit/vmap/grad around the call, even one whose inputs
    are all closed-over constants); False where this JAX cannot tell.

    Upstream internal: `jax._src.core.trace_state_clean` (no public equivalent:
    `jax.extend.core.find_top_trace` gives the trace, not whether it is the eval trace with
    an empty axis environment)."""
    try:
        from jax._src.core import trace_state_clean as clean
    except ImportError:  # pragma: no cover - a future JAX
        return False
    return clean()


def concrete_value(x):
    """The value a tracer of an eager transformation carries (`jax.grad` outside `jit`
    carries the primal), `x` itself when it is not a tracer, or None (under `jit`).

    Public API: `jax.extend.core.concrete_or_error` (it raises where there is no value)."""
    from jax.extend.core import concrete_or_error

    try:
        return concrete_or_error(None, x)
    except Exception:
        return None


def decompress_executable(blob: bytes) -> bytes:
    """A persistent-compile-cache entry decompressed (zstd or zlib, as JAX wrote it); raises
    on a damaged entry.

    Upstream internal: `jax._src.compilation_cache.decompress_executable`."""
    from jax._src import compilation_cache as cc

    return cc.decompress_executable(blob)


def install_compile_cache_store(store) -> bool:
    """Make `store` (an object with JAX's cache interface: `get(key)`, `put(key, value)`) the
    persistent compile cache's file store. Returns False (JAX's own store stays) where this
    JAX has no such hook.

    Upstream internal: `jax._src.compilation_cache.reset_cache`, `._cache` and
    `._cache_initialized` (public: only `jax_compilation_cache_dir`, with JAX's own store)."""
    try:
        from jax._src import compilation_cache as cc

        if not (hasattr(cc, "_cache") and hasattr(cc, "_cache_initialized")):
            return False
        cc.reset_cache()
        cc._cache = store
        cc._cache_initialized = True
    except (ImportError, AttributeError):
        return False
    return True


def weakly_typed(x):
    """`x` with JAX's weak type set (as a Python scalar's), same dtype and value.

    Upstream internal: `jax._src.lax.lax._convert_element_type(..., weak_type=True)` (no
    public way to set a weak type; `jax.typeof(x).weak_type` only reads it)."""
    from jax._src.lax import lax as lax_internal

    return lax_internal._convert_element_type(x, x.dtype, weak_type=True)


def result_codes(result) -> np.ndarray:
    """Host: the integer code(s) of an equinox enumeration item — a diffrax or optimistix
    `RESULTS` item, batched or not — as a NumPy array.

    Public API: the item is a pytree whose one array leaf is its code (`jax.tree.leaves`);
    what a code means is told by comparing items (`==`) or by the enumeration's message
    (`enumeration[item]`)."""
    (codes,) = jax.tree.leaves(result)
    return np.asarray(codes)


def succeeded(result, enumeration) -> np.ndarray:
    """Host: where `result` (an item of `enumeration`, batched or not) is
    `enumeration.successful`, as a boolean NumPy array of its shape (no device program: the
    same as `np.asarray(result == enumeration.successful)`)."""
    return result_codes(result) == result_codes(enumeration.successful)


def result_member(result, index: int):
    """The item of member `index` (flat, C order) of a batched enumeration item, a host
    value (`enumeration[item]` gives its message)."""
    return jax.tree.map(lambda codes: np.asarray(np.asarray(codes).ravel()[index]), result)


def _runtime_errors() -> tuple[type, ...]:
    if hasattr(jax.errors, "JaxRuntimeError"):
        return (jax.errors.JaxRuntimeError,)
    try:  # pragma: no cover - JAX before `jax.errors.JaxRuntimeError`: jaxlib's own
        from jaxlib.xla_extension import XlaRuntimeError
    except ImportError:  # pragma: no cover
        return (RuntimeError,)
    return (XlaRuntimeError,)


RUNTIME_ERRORS = _runtime_errors()
"""What a compiled program raises when a check inside it fails at run time (an
`eqx.error_if` under `jax.jit`): `jax.errors.JaxRuntimeError`, or jaxlib's
`XlaRuntimeError` where JAX has no public name for it."""


CHECK_ERRORS = (*RUNTIME_ERRORS, ValueError)
"""What a compiled program raises when an `eqx.error_if` inside it fails: one of
`RUNTIME_ERRORS` on the call that compiled it, a `ValueError` ("INTERNAL: CpuCallback
error …") when JAX's fast path runs the same program again (a repeat call, a later chunk).
Catch these, then keep only what `failed_check_message` recognises.

Upstream internal: the fast path's exception type."""


def failed_check_message(err: BaseException) -> str | None:
    """The message of the `eqx.error_if` whose failure `err` (one of `CHECK_ERRORS`)
    reports, or None when `err` is some other run-time failure.

    Upstream internal: the text equinox puts into the error (its exception class name,
    `EquinoxRuntimeError`, then `: ` and the message, inside JAX's callback traceback)."""
    import re

    found = re.findall(r"EquinoxRuntimeError: (.+)", str(err))
    return found[-1].strip() if found else None


class _CheckFailures(logging.Filter):
    def filter(self, record):  # keep every record but a failed equinox check's
        kind = record.exc_info[0] if record.exc_info else None
        return kind is None or "EquinoxRuntimeError" not in kind.__name__


@contextlib.contextmanager
def quiet_failed_checks():
    """While inside, JAX does not log the traceback of a failed `eqx.error_if` in a compiled
    program (the caller raises its message as one line); other callback failures are logged
    as before.

    Upstream internal: the logger of `jax._src.callback`, which logs "jax.pure_callback
    failed" with the traceback before the program raises."""
    log, quiet = logging.getLogger("jax._src.callback"), _CheckFailures()
    log.addFilter(quiet)
    try:
        yield
    finally:
        log.removeFilter(quiet)
