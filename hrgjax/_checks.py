"""Shared input checks: trace-time structure errors and run-time value errors."""

import math
import numbers
import operator

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _upstream


def is_concrete(x) -> bool:
    try:
        np.asarray(x)
    except Exception:
        return False
    return True


def concrete_value(x) -> np.ndarray | None:
    """`x` as a NumPy array when its value is known on the host — a concrete array, or a
    tracer of an eager transformation (`jax.grad` outside `jit` carries the primal value) —
    else None (under `jit`)."""
    if is_concrete(x):
        return np.asarray(x)
    value = _upstream.concrete_value(x)  # JAX's own unwrapping of value-carrying tracers
    return None if value is None else np.asarray(value)


def check_finite(name: str, x):
    """Raise (eagerly when concrete, via ``eqx.error_if`` when traced) if x has NaN/inf.
    Returns `x` as a jax array."""
    if is_concrete(x):
        arr = np.asarray(x)
        bad = ~np.isfinite(arr)
        if bad.any():
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            where = f" at index {idx}" if arr.ndim else ""
            raise ValueError(f"{name} must be finite; found {arr[idx]}{where}")
        return x if isinstance(x, jax.Array) else jnp.asarray(x)
    return eqx.error_if(x, ~jnp.all(jnp.isfinite(x)), f"{name} must be finite (found NaN or inf)")


RULES = {
    "> 0": lambda v: v > 0,
    ">= 0": lambda v: v >= 0,
    "in (0, 1]": lambda v: (v > 0) & (v <= 1),
    "in (-0.5, 0.5)": lambda v: (v > -0.5) & (v < 0.5),
    "in (-π/4, π/4)": lambda v: (v > -np.pi / 4) & (v < np.pi / 4),
    "in [-2π, 2π]": lambda v: (v >= -2 * np.pi) & (v <= 2 * np.pi),
    "> -1": lambda v: v > -1.0,
}
"""The value rules `check_finite_leaves` can apply to traced leaves, by their text."""


def check_finite_leaves(name: str, tree, limits=None):
    """`tree` with its traced floating leaves checked finite by one `eqx.branched_error_if`
    whose message names the first bad leaf (`gyro.resonator.omega must be finite …`);
    `limits` ({"resonator.tau": ("> 0", "s"), …}: a leaf's path, a rule of `RULES` and its
    unit) also holds a traced leaf at that path to its rule (τ = 0 under `jit`).

    A module built under `jit` or `vmap` cannot keep the `eqx.error_if`s of its
    `__check_init__` (their results are discarded), so without this a NaN in a traced
    parameter or profile shows up far downstream (a solver's "maximum number of steps").
    Concrete leaves pass unchecked: they were checked where they were built."""
    flat, treedef = jax.tree_util.tree_flatten_with_path(tree)
    leaves = [x for _, x in flat]
    traced = [
        i
        for i, x in enumerate(leaves)
        if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.floating) and not is_concrete(x)
    ]
    if not traced:
        return tree
    limits = limits or {}
    paths = [jax.tree_util.keystr(flat[i][0]) for i in traced]
    rules = [limits.get(p.lstrip("."), ("finite", "")) for p in paths]
    ok = jnp.stack([
        jnp.all(jnp.isfinite(leaves[i]) & RULES.get(rule, lambda v: True)(leaves[i]))
        for i, (rule, _) in zip(traced, rules, strict=True)
    ])  # fmt: skip
    messages = [
        f"{name}{p} must be finite (found NaN or inf)" if rule == "finite"
        else f"{name}{p} must be finite and {rule} {unit}".rstrip()
        for p, (rule, unit) in zip(paths, rules, strict=True)
    ]  # fmt: skip
    # only the traced leaves pass through the check: constants stay constants (XLA folds them)
    checked = eqx.branched_error_if(
        [leaves[i] for i in traced], ~jnp.all(ok), jnp.argmin(ok), messages
    )
    for i, x in zip(traced, checked, strict=True):
        leaves[i] = x
    return jax.tree_util.tree_unflatten(treedef, leaves)


def floats_as_arrays(tree):
    """`tree` with its Python and NumPy number leaves (floats, ints; not bools) as float64
    arrays (not weakly typed), as a module's own converters make them: a number put in with
    `eqx.tree_at` would otherwise be static to `eqx.filter_jit`, one compiled program per
    value. (No XLA program: the host value is put on the device.)"""
    number = lambda x: isinstance(x, int | float | np.number) and not isinstance(x, bool)  # noqa: E731
    return jax.tree_util.tree_map(
        lambda x: jax.device_put(np.asarray(x, dtype=float)) if number(x) else x, tree
    )


def traceable(name: str, tree, limits=None):
    """`tree` (a module `name`) ready for a compiled program: its Python floats as arrays
    (`floats_as_arrays`), its traced leaves checked finite and within `limits`
    (`check_finite_leaves`)."""
    return check_finite_leaves(name, floats_as_arrays(tree), limits)


def check_nonnegative(name: str, x, unit: str = ""):
    """Raise if any element of x is negative or not finite (concrete values only: a traced
    value passes unchecked)."""
    if not is_concrete(x):
        return x
    arr = np.asarray(x)
    check_finite(name, arr)
    if (arr < 0).any():
        idx = np.argwhere(arr < 0)[0]
        raise ValueError(
            f"{name} must be >= 0{(' ' + unit) if unit else ''}; got {arr[tuple(idx)]}"
        )
    return x


def check_positive(name: str, x, unit: str = ""):
    """Raise if any element of x is not strictly positive (and finite)."""
    x = check_finite(name, x)
    if is_concrete(x):
        arr = np.asarray(x)
        if (arr <= 0).any():
            idx = np.argwhere(arr <= 0)[0]
            raise ValueError(
                f"{name} must be > 0{(' ' + unit) if unit else ''}; got {arr[tuple(idx)]}"
            )
        return x
    return eqx.error_if(x, jnp.any(x <= 0), f"{name} must be > 0 {unit}".rstrip())


def finite_number(name: str, x, unit: str) -> float:
    """`x` (a Python, NumPy or 0-d array number) as a finite float, or a one-line error
    naming `name` and its `unit`: `TypeError` for a non-number, `ValueError` for NaN or inf."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        if not (isinstance(x, (np.ndarray, jax.Array)) and np.shape(x) == ()):
            raise TypeError(f"{name} must be a number [{unit}]; got {type(x).__name__}")
    x = float(x)
    if not np.isfinite(x):
        raise ValueError(f"{name} must be finite [{unit}]; got {x}")
    return x


def vec3(owner: str, name: str, unit: str):
    """An `eqx.field` converter for the field `name` of `owner`: a scalar (every axis) or 3
    values, as a (3,) float array; a one-line `ValueError` naming `owner.name`, its `unit`
    and shape (3,) for any other shape."""

    def convert(x):
        x = jnp.asarray(x, float)
        if x.shape not in ((), (1,), (3,)):
            raise ValueError(f"{owner}.{name} must be a scalar (every axis) or 3 values "
                             f"[{unit}], shape (3,); got shape {x.shape}")  # fmt: skip
        return jnp.broadcast_to(x, (3,))

    return convert


ROUND_OFF = 1e-9
"""Relative tolerance of the covariance checks: asymmetry up to this share of the largest
entry, and (semi-definite matrices) a smallest eigenvalue down to minus this share of the
largest variance, are round-off."""


def host_value(x) -> np.ndarray | None:
    """`x` as a float64 NumPy array when its value is known on the host, else None (traced)."""
    value = concrete_value(x)
    return None if value is None else np.asarray(value, dtype=float)


def _at(index: str, i: int, batched: bool) -> str:
    return f" at {index} {i}" if batched else ""


def check_finite_host(name: str, x):
    """Refuse a concrete `x` with a NaN or inf in one line naming `name`, the value and where
    (its first bad index); a traced `x` passes."""
    v = host_value(x)
    if v is None or np.isfinite(v).all():
        return
    where = tuple(int(i) for i in np.argwhere(~np.isfinite(v))[0])
    at = f" at index {where}" if v.ndim else ""
    raise ValueError(f"{name} must be finite; it has {v[where]}{at}")


def check_covariance(name: str, a, *, definite: bool = False, form: str = "(n, n)",
                     index: str = "step"):  # fmt: skip
    """Refuse a concrete covariance `a` (n, n), or a stack (…, n, n) of them, that is not
    finite, not symmetric or not positive (semi-)definite, in one line naming `name`, the
    expected `form` and, for a stack, the first bad `index`. `definite` (a measurement noise
    R) needs every eigenvalue > 0. A traced `a` passes (no run-time check).

    The tests run on the correlation form D⁻¹AD⁻¹ (D = √diag, 1 where a variance is 0), so
    they do not depend on the states' units (a position variance of 100 m² beside a bias
    variance of −1e-14 is refused; a valid R whose σ span 12 decades is not): a negative
    variance is refused as such, then asymmetry and a negative eigenvalue beyond round-off
    (`ROUND_OFF`) — one batched Cholesky on the host, eigenvalues only to name a bad one."""
    v = host_value(a)
    if v is None or v.size == 0:
        return
    kind = "positive-definite" if definite else "positive semi-definite"
    head = f"{name} must be a symmetric {kind} {form} covariance"
    mats = v.reshape((-1,) + v.shape[-2:])
    batched = v.ndim > 2
    finite = np.isfinite(mats).all(axis=(-2, -1))
    if not finite.all():
        i = int(np.argmin(finite))
        raise ValueError(
            f"{head}; it has {mats[i][~np.isfinite(mats[i])][0]}{_at(index, i, batched)}"
        )
    var = np.diagonal(mats, axis1=-2, axis2=-1)
    bad = (var <= 0) if definite else (var < 0)
    if bad.any():
        i, j = (int(x) for x in np.argwhere(bad)[0])
        raise ValueError(f"{head}; its variance [{j}, {j}] is {var[i, j]:.6g}"
                         f"{_at(index, i, batched)}")  # fmt: skip
    d = np.where(var > 0, np.sqrt(np.where(var > 0, var, 1.0)), 1.0)
    c = mats / (d[:, :, None] * d[:, None, :])
    trans = np.swapaxes(c, -1, -2)
    asym = np.abs(c - trans).max(axis=(-2, -1))
    skew = asym > ROUND_OFF * np.maximum(np.abs(c).max(axis=(-2, -1)), 1.0)
    if skew.any():
        i = int(np.argmax(skew))
        raise ValueError(
            f"{head}; it is not symmetric{_at(index, i, batched)} (|A - A^T| reaches "
            f"{asym[i]:.3g} of the entries' scale √(A_ii A_jj))"
        )
    sym = 0.5 * (c + trans)
    shift = 0.0 if definite else ROUND_OFF
    try:
        np.linalg.cholesky(sym + shift * np.eye(sym.shape[-1]))
        return
    except np.linalg.LinAlgError:
        pass
    low = np.linalg.eigvalsh(sym)[:, 0]
    bad = ~(low > 0) if definite else low < -shift
    if not bad.any():  # the factorisation failed at round-off the eigenvalues do not show
        return
    i = int(np.argmax(bad))
    sym_a = 0.5 * (mats[i] + mats[i].T)
    raise ValueError(f"{head}; its smallest eigenvalue is {np.linalg.eigvalsh(sym_a)[0]:.6g}"
                     f"{_at(index, i, batched)}")  # fmt: skip


# -- one-line descriptions of bad values, and the 1-D check (Allan estimators, Kalman filters)

_SHORT = 60
"""The longest repr `describe` shows whole; a longer one is cut."""


def describe(x) -> str:
    """`x` for a one-line error message, whatever its size: a number (a 0-d array too) or a
    short value as its repr; an array, a list or a tuple of any length as its type and shape
    (never its values); anything else as its repr cut to `_SHORT` characters."""
    if hasattr(x, "shape") and hasattr(x, "dtype"):  # NumPy, JAX (a tracer too)
        shape, dtype = tuple(x.shape), x.dtype
        if shape == () and getattr(dtype, "kind", None) in ("b", "i", "u", "f") and is_concrete(x):
            return f"{_kind(x)} {np.asarray(x).item()!r}"
        return f"{_kind(x)} of shape {shape} and dtype {dtype}"
    if isinstance(x, list | tuple) and len(x) > 0:
        try:
            shape = np.shape(x)
        except ValueError:  # ragged
            return f"ragged {type(x).__name__} of {len(x)} items"
        if len(repr(x)) > _SHORT or "\n" in repr(x):
            return f"{type(x).__name__} of shape {shape}"
    text = repr(x).replace("\n", " ")
    return text if len(text) <= _SHORT else f"{type(x).__name__} {text[:_SHORT]}…"


def _kind(x) -> str:
    return "jax.Array" if isinstance(x, jax.Array) else type(x).__name__


def is_finite_real(x) -> bool:
    """Whether `x` is one finite real number: a Python or NumPy one, or a concrete 0-d real
    array (not a bool, not a longer array, not a string)."""
    if isinstance(x, bool | np.bool_ | str | bytes):
        return False
    if hasattr(x, "shape") and hasattr(x, "dtype"):
        if x.shape != () or getattr(x.dtype, "kind", None) not in ("i", "u", "f"):
            return False
        if not is_concrete(x):
            return False
    elif not isinstance(x, int | float):
        return False
    return bool(np.isfinite(float(x)))


def check_1d(name: str, x, what: str = "") -> tuple:
    """The shape of `x` (an array, a list or a tracer: only its shape is read), or a
    one-line `ValueError` naming `name`, `what` it holds and the shape found unless it is
    1-D: several columns are refused, not flattened into one record."""
    try:
        shape = tuple(x.shape) if hasattr(x, "shape") else np.shape(x)
    except ValueError:  # a ragged list
        shape = None
    if shape is None or len(shape) != 1:
        found = f"shape {shape}" if shape is not None else describe(x)
        extra = ""
        if shape and len(shape) > 1:
            one = int(np.prod(shape[1:])) == 1
            extra = (" (one column: pass y[:, 0] or y.ravel())" if one
                     else " (several records: one call per record)")  # fmt: skip
        raise ValueError(f"{name} must be 1-D{', ' + what if what else ''}; got {found}{extra}")
    return shape


# --- types of numeric arguments (numbers, arrays of numbers, flags) ----------------------


def _numeric_kind(x, bools=False):
    """`(shape, problem)` of `x` as a real number or array of them: `problem` is None for
    one, else the words after "got" (its type, and for an array its dtype and shape — never
    the values). Arrays and tracers are judged by dtype and shape only; lists and tuples
    element by element (so a traced element is never converted)."""
    if type(x) is np.ndarray:  # the common case, first and cheap (the search asks ~10⁵ times)
        kind = x.dtype.kind
        if kind in "fiu" or (bools and kind == "b"):
            return x.shape, None
    if x is None:
        return (), "None"
    if isinstance(x, str | bytes):
        text = repr(x if len(x) <= 40 else x[:37] + "...")
        return (), f"{type(x).__name__} {text}"
    if isinstance(x, bool | np.bool_):
        return (), None if bools else f"bool {x}"
    if isinstance(x, list | tuple):
        try:  # the common case at once: plain numbers (a traced element raises)
            dtype = np.asarray(x).dtype
            if np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating):
                return np.shape(x), None
        except Exception:  # noqa: BLE001 — ragged, traced or odd: judged element by element
            pass
        kinds = [_numeric_kind(v, bools) for v in x]
        for _, problem in kinds:
            if problem is not None:
                return (len(x),), f"{type(x).__name__} holding {problem}"
        shapes = {shape for shape, _ in kinds}
        if len(shapes) > 1:
            return (len(x),), f"ragged {type(x).__name__} (elements of shapes {sorted(shapes)})"
        return (len(x),) + (shapes.pop() if shapes else ()), None
    dtype, shape = getattr(x, "dtype", None), getattr(x, "shape", None)
    if dtype is None or shape is None:
        if isinstance(x, int | float | np.integer | np.floating):
            return (), None
        if isinstance(x, complex | np.complexfloating):
            return (), f"complex {x}"
        return (), type(x).__name__
    shape = tuple(shape)
    if jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key):
        return shape, f"a JAX PRNG key (dtype {dtype}, shape {shape}), not a number"
    if bools and np.issubdtype(dtype, np.bool_):
        return shape, None
    if not (np.issubdtype(dtype, np.integer) or np.issubdtype(dtype, np.floating)):
        return shape, f"{_kind(x)} (dtype {dtype}, shape {shape})"
    return shape, None


def numeric_problem(x, bools: bool = False) -> str | None:
    """Why `x` is not a real number or array of real numbers (bool — unless `bools` —, str,
    None, a dict, a complex or ragged value, a PRNG key…), in words for "got …"; None when
    it is one."""
    return _numeric_kind(x, bools)[1]


def check_number(name: str, x, unit: str = ""):
    """Refuse `x` unless it is a single real number (a Python or NumPy number, a 0-d array or
    a traced scalar), in one line naming `name` and `unit`: `TypeError` for a bool, str,
    None, complex, PRNG key or other non-number, `ValueError` for an array of numbers (its
    type and shape). Returns `x`."""
    shape, problem = _numeric_kind(x)
    form = f"a single real number{f' [{unit}]' if unit else ''}"
    if problem is not None:
        raise TypeError(f"{name} must be {form}; got {problem}")
    if shape != ():
        raise ValueError(f"{name} must be {form}; got {_kind(x)} of shape {shape}")
    return x


def check_numbers(name: str, x, form: str, shape=None, bools: bool = False):
    """Refuse `x` unless it is real numbers (no bool — unless `bools` —, str, None, complex,
    PRNG key or ragged list), of `shape` when given (a tuple; None entries match any length),
    in one line naming `name` and the expected `form`. Returns `x`."""
    got, problem = _numeric_kind(x, bools)
    if problem is not None:
        raise TypeError(f"{name} must be {form}; got {problem}")
    if shape is not None and (
        len(got) != len(shape)
        or any(s is not None and s != g for s, g in zip(shape, got, strict=True))
    ):
        raise ValueError(f"{name} must be {form}; got {_kind(x)} of shape {got}")
    return x


def check_flag(name: str, x) -> bool:
    """`x` as a bool when it is one (Python `bool`, `np.bool_`, or a concrete 0-d NumPy/JAX
    array of dtype bool), else a one-line `TypeError` naming `name` (a truthy string such as
    "no", or a number, must not switch a feature on)."""
    if isinstance(x, bool | np.bool_):
        return bool(x)
    v = concrete_value(x) if hasattr(x, "dtype") else None
    if v is not None and np.ndim(v) == 0 and np.asarray(v).dtype == np.bool_:
        return bool(v)
    shown = (
        "None"
        if x is None
        else f"{type(x).__name__} {x!r}"
        if isinstance(x, str | int | float)
        else (
            f"{type(x).__name__}"
            + (f" of shape {tuple(np.shape(x))}" if hasattr(x, "shape") else "")
        )
    )
    raise TypeError(f"{name} must be True or False; got {shown}")


def int_as_float(x):
    """`x` as a Python float when it is an int or NumPy integer (not a bool), else as it is: a
    whole number written where a value is meant (`tau0=1`, `correlation_time=50`) then meets
    the compiled program of `1.0` (an int is another input type: another program)."""
    return float(x) if isinstance(x, int | np.integer) and not isinstance(x, bool) else x


def whole_number(name: str, value, what: str, minimum: int | None = None) -> int:
    """`value` as an int when it is a whole real number (a NumPy integer or 2.0 too) and, with
    `minimum`, not below it; else a one-line `ValueError` naming `name` (no truncation: 1.5
    is refused, not read as 1; `what` completes "… must be {what}")."""
    n = None
    if not isinstance(value, bool | np.bool_):
        try:
            n = operator.index(value)
        except TypeError:
            v = concrete_value(value) if hasattr(value, "dtype") and np.ndim(value) == 0 else None
            real = float(v) if v is not None and np.asarray(v).dtype.kind == "f" else value
            if isinstance(real, numbers.Real) and math.isfinite(real) and float(real).is_integer():
                n = int(real)
    if n is None or (minimum is not None and n < minimum):
        raise ValueError(f"{name} must be {what}; got {describe(value)}")
    return n


def check_key(name: str, key, batch_hint: str = "one call per key, or jax.vmap") -> None:
    """Refuse `key` unless it is one JAX PRNG key — a typed one (`jax.random.key`, shape ())
    or a legacy uint32 one (`jax.random.PRNGKey`, shape (2,)), traced or not — in one line
    naming `name` (JAX's own read "invalid PRNG key data"): `TypeError` for anything else (an
    int seed, None), `ValueError` for a batch of keys (`batch_hint` says what to do instead)."""
    dtype = getattr(key, "dtype", None)
    typed = dtype is not None and jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key)
    if not (typed or dtype == np.uint32):
        raise TypeError(f"{name} must be one JAX PRNG key, e.g. jax.random.key(0); got "
                        f"{describe(key)}")  # fmt: skip
    one = () if typed else (2,)
    if tuple(np.shape(key)) != one:
        raise ValueError(f"{name} must be one JAX PRNG key, e.g. jax.random.key(0); got a key "
                         f"array of shape {tuple(np.shape(key))} ({batch_hint})")  # fmt: skip


def FINITE_POSITIVE(v):
    """Rule for `check_values`: finite and > 0 (host arrays)."""
    return np.isfinite(v) & (v > 0)


def FINITE_NONNEGATIVE(v):
    """Rule for `check_values`: finite and >= 0 (host arrays)."""
    return np.isfinite(v) & (v >= 0)


def check_values(name: str, x, ok, form: str):
    """`x` (a number, a NumPy or JAX array; a list or tuple as a NumPy array) refused in one
    line naming `name` and the `form` expected unless it is real numbers each passing `ok`
    (e.g. `FINITE_POSITIVE`) where its value is known on the host; a traced value passes (no
    run-time check in a caller's program, which may differentiate through it)."""
    check_numbers(name, x, form)
    x = np.asarray(x, dtype=float) if isinstance(x, list | tuple) else x
    v = concrete_value(x)
    if v is not None:
        v = np.asarray(v, dtype=float)
        if not np.all(ok(v)):
            raise ValueError(f"{name} must be {form}; got {v[~ok(v)].flat[0]}")
    return x
