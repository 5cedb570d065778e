"""The filter bank's input checks (`hrgjax.diagnosis.filter_bank`): each model of
`Bank.build`, a bank's concrete values, and the measurements, refused in one line naming the
model, the field or the step."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._checks import check_covariance, check_finite_host, is_concrete

FIELDS = ("phi", "qd", "h", "r", "x0", "p0")


def check_model(i, mod, first):
    """Model `i` of `Bank.build`: a `(phi, qd, h, r, x0, p0)` tuple whose shapes fit each other
    and the first model's (trace time), with finite values, `qd` and `p0` symmetric positive
    semi-definite and `r` positive-definite when they are concrete (one line naming the model
    and the field: a negative variance made every probability NaN, every decision undecided)."""
    if len(mod) != 6:
        raise ValueError(f"model {i} must be a (phi, qd, h, r, x0, p0) tuple; got {len(mod)} items")
    n_shape, h_shape = np.shape(first[0]), np.shape(first[2])
    n = n_shape[0] if len(n_shape) == 2 and n_shape[0] == n_shape[1] else None
    m = h_shape[0] if len(h_shape) == 2 else None
    if n is None or m is None:
        raise ValueError(
            f"model 0's phi must be (n, n) and h (m, n); got phi {n_shape}, h {h_shape}"
        )
    want = {"phi": (n, n), "qd": (n, n), "h": (m, n), "r": (m, m), "x0": (n,), "p0": (n, n)}
    form = {"phi": "(n, n)", "qd": "(n, n)", "h": "(m, n)", "r": "(m, m)", "x0": "(n,)",
            "p0": "(n, n)"}  # fmt: skip
    for name, a in zip(FIELDS, mod, strict=True):
        if np.shape(a) != want[name]:
            raise ValueError(f"model {i}'s {name} must be {form[name]} = {want[name]} (n = {n} "
                             f"states, m = {m} measurements); got {np.shape(a)}")  # fmt: skip
    phi, qd, h, r, x0, p0 = mod
    for name, a in (("phi", phi), ("h", h), ("x0", x0)):
        check_finite_host(f"model {i}'s {name}", a)
    check_covariance(f"model {i}'s qd", qd, form=f"(n, n) = ({n}, {n})")
    check_covariance(f"model {i}'s r", r, definite=True, form=f"(m, m) = ({m}, {m})")
    check_covariance(f"model {i}'s p0", p0, form=f"(n, n) = ({n}, {n})")


def check_bank(bank):
    """A bank's concrete values (a `Bank` made directly, or changed after `Bank.build`):
    finite, `qd` and `p0` symmetric positive semi-definite, `r` positive-definite, per
    hypothesis; traced fields pass (no run-time check)."""
    for name in ("phi", "h", "x0", "z_offset"):
        check_finite_host(f"bank.{name}", getattr(bank, name))
    n, m = bank.phi.shape[-1], bank.h.shape[-2]
    for name, definite, size in (("qd", False, n), ("r", True, m), ("p0", False, n)):
        check_covariance(f"bank.{name}", getattr(bank, name), definite=definite,
                         form=f"({size}, {size})", index="hypothesis")  # fmt: skip
    if bank.scale is not None:
        check_scale("bank.scale", bank.scale, np.shape(bank.x0))


def check_scale(name, scale, shape):
    """A bank's state units `scale`: shape `shape` (M, n), and (concrete) finite and > 0."""
    if np.shape(scale) != tuple(shape):
        raise ValueError(f"{name} must be (M, n) = {tuple(shape)} (the states' units); got "
                         f"{np.shape(scale)}")  # fmt: skip
    value = concrete(scale) if is_concrete(scale) else None
    bad = None if value is None else value[~(np.isfinite(value) & (value > 0))]
    if bad is not None and bad.size:
        raise ValueError(f"{name} must be finite and > 0 (the states' units); got {bad[0]}")


def concrete(x):
    """`x` as a float64 NumPy array, or None when it is traced (inside a caller's `jit`)."""
    return np.asarray(x, dtype=float) if is_concrete(x) else None


def check_zs(zs, bank, ndims):
    """`zs` as float64 (…, K, m), refused with a one-line error when its shape does not match
    the bank's measurement (m columns, one per pair) or when a value is not finite (one NaN
    would make every later probability NaN)."""
    m = bank.h.shape[1]
    shape = " or ".join({2: "(K, m)", 3: "(runs, K, m)"}[d] for d in ndims)
    z = concrete(zs)
    traced = z is None
    z = jnp.asarray(zs, float) if traced else z
    if z.ndim not in ndims or z.shape[-1] != m:
        hint = ""
        if z.ndim in ndims and z.shape[-2] == m:
            hint = " (transposed? time runs along the second-to-last axis)"
        raise ValueError(
            f"zs must have shape {shape} with m = {m} (one column per measured pair the bank "
            f"models; fault_bank: pairs (0, j), j = 1 … {m}, in order); got {z.shape}{hint}"
        )
    if z.shape[-2] == 0:
        raise ValueError(f"zs must have at least one step (K >= 1); got shape {z.shape}")
    if not traced:
        bad = ~np.isfinite(z)
        if bad.any():
            where = np.argwhere(bad)[0]
            at = f"step {where[-2]}" + (f" of run {where[0]}" if z.ndim == 3 else "")
            raise ValueError(
                f"zs has a non-finite value ({z[tuple(where)]}) at {at}, column {where[-1]}: "
                "the hypothesis probabilities would be NaN from there on; drop or fill it"
            )
    return jnp.asarray(z, float)
