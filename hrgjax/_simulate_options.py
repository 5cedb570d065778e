"""`simulate`'s arguments besides the gyro and the profile, checked before any work: the
settings (`check_options`), the keys, the output times (`output_grid`) and the starting
quadrature against the gyro's amplitude (`check_quadrature0`)."""

from __future__ import annotations

import contextlib
import numbers

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from . import _checks as checks
from ._checks import (
    check_finite,
    check_numbers,
    concrete_value,
    describe,
    is_concrete,
    numeric_problem,
)
from ._compiled import device
from .resonator.params import TemperatureLaw

_TOLERANCE = "a positive number (a solver tolerance)"
_QUADRATURE = "a finite number (readout units) of magnitude below the amplitude set point"
NUMBERS = {"rtol": _TOLERANCE, "atol": _TOLERANCE, "quadrature0": _QUADRATURE}
"""`simulate`'s settings that are one real number each, and what each must be."""

CLASSES = {
    "solver": (diffrax.AbstractSolver, "a diffrax solver, e.g. diffrax.Tsit5()"),
    "adjoint": (
        diffrax.AbstractAdjoint,
        "a diffrax adjoint, e.g. diffrax.RecursiveCheckpointAdjoint()",
    ),
}
"""`simulate`'s settings that are diffrax objects: (class, what it must be)."""


def check_key(name: str, k) -> None:
    """`_checks.check_key` for `simulate`'s `key`/`bias_key` (a batch: `jax.vmap` over it)."""
    checks.check_key(name, k, "a batch of runs: jax.vmap over simulate")


def check_options(o) -> None:
    """`simulate`'s keyword arguments `o`: their types always, their values where concrete
    (a traced value passes unchecked)."""
    for name in ("key", "bias_key"):
        if o[name] is not None:
            check_key(name, o[name])
    for name, form in NUMBERS.items():
        v = o[name]
        if (problem := numeric_problem(v)) is not None:
            raise TypeError(f"{name} must be {form}; got {problem}")
        positive = name != "quadrature0"
        if np.ndim(v) != 0 or (
            is_concrete(v) and not (np.isfinite(v) and (not positive or float(v) > 0))
        ):
            raise ValueError(f"{name} must be {form}; got {describe(v)}")
    for name, (cls, form) in CLASSES.items():
        if (v := o[name]) is not None and not isinstance(v, cls):
            got = f"the class {v.__name__} itself" if isinstance(v, type) else describe(v)
            raise TypeError(f"{name} must be {form}, or None; got {got}")
    v = o["max_steps"]
    if v is not None and not (
        isinstance(v, numbers.Integral) and not isinstance(v, bool) and v > 0
    ):
        raise ValueError(f"max_steps must be a positive integer or None; got {v!r}")
    v = o["fixed_step"]
    if isinstance(v, str):
        if v not in ("auto", "held"):
            raise ValueError(
                f'fixed_step must be "auto", "held", a positive number of seconds or None; '
                f"got {v!r}"
            )
    elif v is not None and (
        numeric_problem(v) is not None  # a bool is no step (True was a 1-s step)
        or (is_concrete(v) and not (np.ndim(v) == 0 and np.isfinite(v) and v > 0))
    ):
        raise ValueError(f"fixed_step must be a positive number of seconds or None; got {v!r}")
    v = o["run"]
    if hasattr(v, "dtype") and jax.dtypes.issubdtype(v.dtype, jax.dtypes.prng_key):
        raise ValueError("run must be an integer run id (e.g. 3); got a JAX PRNG key (key=)")
    if is_concrete(v):
        arr = np.asarray(v)
        if arr.ndim != 0 or arr.dtype.kind not in "iu" or isinstance(v, bool):
            raise ValueError(f"run must be an integer run id (e.g. 3); got {v!r}")


def check_quadrature0(quadrature0, gyro, profile) -> None:
    """Refuse |`quadrature0`| ≥ a₀, the amplitude set point `gyro.control.amplitude` at the
    profile's first temperature, where the wave starts with amplitude a₀: the quadrature is
    the minor semi-axis of the wave's ellipse and the amplitude its major one, so |q| < a (at
    |q| = a the wave is a circle with no angle, and the averaged model's solver ran out of
    steps; beyond, the axes swap: the full model started the wave 90° off, the averaged one
    ran on to an amplitude of 138). Values known here only (concrete, or an eager `grad`'s):
    a traced q₀, set point or start temperature passes unchecked."""
    q, a = concrete_value(quadrature0), gyro.control.amplitude
    at = ""
    if isinstance(a, TemperatureLaw):
        law = jax.tree_util.tree_map(concrete_value, a)
        temp = concrete_value(profile.temperature)
        if temp is None or any(
            x is None for x in jax.tree_util.tree_leaves(law, is_leaf=lambda x: x is None)
        ):
            return
        temp = np.asarray(temp, dtype=float)[..., 0]
        a, at = law(temp, xp=np), f" at the start temperature, {np.ravel(temp)[0]:g} °C"
    else:
        a = concrete_value(a)
    if q is None or a is None:
        return
    q, a = float(q), np.asarray(a, dtype=float)
    if np.any(~(abs(q) < a)):
        a0 = float(np.ravel(a)[np.argmin(np.ravel(a))])
        raise ValueError(
            f"quadrature0 must be {_QUADRATURE} a₀ = gyro.control.amplitude = {a0:g}{at}, "
            "|quadrature0| < a₀: the quadrature is the minor semi-axis of the wave's ellipse, "
            f"the amplitude its major one (at |q| = a the wave is circular, with no angle); "
            f"got {q:g}"
        )


def output_grid(ts, profile) -> jax.Array:
    """`simulate`'s explicit output times `ts` [s] as a float array: real numbers, 1-D and
    not empty; concrete ones finite, strictly increasing and within the profile's knots."""
    check_numbers("ts", ts, "a 1-D array of output times [s]")
    if isinstance(ts, jax.Array):
        ts = jnp.asarray(ts, dtype=float)
    else:  # host values stay concrete under jit (the fixed-step path counts steps on them)
        with jax.ensure_compile_time_eval():
            ts = device(np.asarray(ts, dtype=float), float)
    if ts.ndim != 1 or ts.shape[0] < 1:
        raise ValueError(f"ts must be a 1-D array of output times [s]; got shape {ts.shape}")
    if is_concrete(ts):
        check_finite("ts", ts)  # a NaN passed the order checks and failed the solver
    if is_concrete(ts) and is_concrete(profile.t):
        arr, knots = np.asarray(ts), np.asarray(profile.t)
        if np.any(np.diff(arr) <= 0):
            raise ValueError("ts must be strictly increasing (unsorted or duplicate time)")
        if arr[0] < knots[0] or arr[-1] > knots[-1]:
            raise ValueError(
                f"ts must lie within the profile [{knots[0]}, {knots[-1]}] s; "
                f"got [{arr[0]}, {arr[-1]}]"
            )
    return ts


def traced_grid_checks(ts, profile) -> list:
    """`output_grid`'s order and span rules for output times `ts` [s] or knot times
    `profile.t` that are traced (a sweep over `duration_s` with fixed `ts`: an output time
    past the profile's end made the solver's "NaN or inf"): `[(bad, message), …]`, `bad` a
    traced boolean, the message the eager one line without the values; `[]` when both are
    concrete (`output_grid` judged them)."""
    if is_concrete(ts) and is_concrete(profile.t):
        return []
    checks = []
    if not is_concrete(ts):
        checks.append((jnp.any(jnp.diff(ts) <= 0),
                       "ts must be strictly increasing (unsorted or duplicate time)"))  # fmt: skip
    knots = jnp.asarray(profile.t, dtype=float)
    outside = (ts[0] < jnp.min(knots)) | (ts[-1] > jnp.max(knots))
    checks.append((outside, "ts must lie within the profile [its first, its last knot time] s "
                            "at one or more points: an output time before its start or past "
                            "its end (a swept duration_s: ts within the shortest)"))  # fmt: skip
    return checks


FORWARD_MODE = (
    "simulate: forward-mode derivatives (jax.jvp, jax.jacfwd, jax.hessian) need an adjoint "
    "that supports them: adjoint=diffrax.ForwardMode() for jvp/jacfwd, "
    "diffrax.DirectAdjoint() for jax.hessian (forward over reverse; slower); the default "
    "adjoint is reverse-mode only (jax.grad, jax.jacrev)"
)
"""The one line `simulate` raises for JAX's "can't apply forward-mode autodiff (jvp) to a
custom_vjp function": the default adjoint's checkpointed loop is a `custom_vjp`."""


@contextlib.contextmanager
def forward_mode_hint():
    """Around `simulate`'s solve: JAX's forward-mode `TypeError` on the default adjoint
    raised as `FORWARD_MODE` (any other error as it was)."""
    try:
        yield
    except TypeError as err:
        if "forward-mode autodiff" not in str(err):
            raise
        raise TypeError(FORWARD_MODE) from None
