r"""Installation misalignment of a sensor triad (seed 003, step 2; PHYSICS.md §12).

Each sensor axis i of a non-orthogonal triad is tilted by two small angles towards the other
two body axes; the six angles $\theta_{ij}$ (axis i towards body axis j, $i \ne j$) form the
off-diagonal matrix E, and to first order a sensor triad reads

$$s = (I + E)\,b, \qquad b = (I + E)^{-1}s \approx (I - E)\,s,$$

with b the body-frame (orthogonal) quantity. The first-order inverse leaves an error of order
$E^2$. With scale factors k and biases β the static model is $s = \mathrm{diag}(1 + k)(I + E)b
+ \beta$ (the IMU's [`TriadCalibration`][hrgjax.imu.triad.TriadCalibration], re-exported
here), which [`calibrate`][hrgjax.fog.misalignment.calibrate] estimates from positions with
known body-frame inputs (a multi-position static test for accelerometers, rate-table
rotations plus Earth rate for gyros) by linear least squares, with standard errors. Those
come from the residual scatter of n positions with n − 4 degrees of freedom
([`dof`][hrgjax.fog.misalignment.dof]): an estimate over its standard error follows
Student's t with n − 4 dof, not N(0, 1), and an interval must use t's quantile
([`half_width`][hrgjax.fog.misalignment.half_width]) — ±1.96σ covers 70 % of the time with
1 dof, 92.2 % with 10 (the 14 positions of the study).

Angle order everywhere: `ANGLES` = (xy, xz, yx, yz, zx, zy)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

from .. import plausible

# The triad model is the IMU's (hrgjax.imu.triad); its names stay importable from here.
from ..imu.triad import ANGLE_AXES
from ..imu.triad import ANGLES as ANGLES
from ..imu.triad import TriadCalibration as TriadCalibration
from ..imu.triad import body_from_sensor as body_from_sensor
from ..imu.triad import misalignment_matrix as misalignment_matrix
from ..imu.triad import sensor_from_body as sensor_from_body
from ..units import G0


def calibrate(b, s) -> TriadCalibration:
    """Fit the static triad model to `n` positions: known body-frame inputs `b` (n, 3) and
    the averaged sensor outputs `s` (n, 3). Linear least squares per sensor axis for the row
    of M = diag(1 + k)(I + E) and the bias (4 unknowns per axis), then k_i = M_ii − 1 and
    θ_ij = M_ij / M_ii. Standard errors from the residual scatter (σ²(AᵀA)⁻¹, propagated to
    first order) — with n − 4 degrees of freedom ([`dof`][hrgjax.fog.misalignment.dof]):
    read them with Student's t ([`half_width`][hrgjax.fog.misalignment.half_width] gives
    an interval), not as Gaussian. Needs ≥ 5 positions whose inputs span all three axes with both signs —
    e.g. the six ±axis positions plus any tilted one.

    Runs on the host (NumPy least squares): `b` and `s` traced by `jit`, `vmap` or `grad`
    are refused in one line (loop over positions sets in Python).

    **Raises:** `ValueError` also where a fitted scale error k_i lies outside
    `hrgjax.plausible.RANGES["imu_scale"]` (|k| < 0.1, as `ImuModel`'s): a FOG's scale
    factor error is ppm, a MEMS sensor's a few 0.1 %, so an axis that reads 57.3× its input
    is `s` and `b` in two units — named where 1 + k is a unit ratio (57.3: ° and rad, 3600:
    per hour and per second, 206 265: °/h and rad/s, 9.81: m/s² and g, 1000: milli-units,
    and their inverses; −1: a reversed axis; ≈ 0: axes in another order). Raw counts against
    a rate in °/s (1 + k an LSB scale factor) are such a ratio too: calibrate them inside
    `hrgjax.plausible.relaxed(imu_scale=(lo, hi))`, or scale the counts first."""
    _host_only("calibrate", b=b, s=s)
    b = np.asarray(b, float)
    s = np.asarray(s, float)
    if b.ndim != 2 or b.shape[1] != 3 or s.shape != b.shape:
        raise ValueError(f"b and s must both have shape (n, 3); got {b.shape}, {s.shape}")
    if not (np.all(np.isfinite(b)) and np.all(np.isfinite(s))):
        raise ValueError("b and s must be finite")
    n = b.shape[0]
    a = np.concatenate([b, np.ones((n, 1))], axis=1)
    if n < 5 or np.linalg.matrix_rank(a) < 4:
        raise ValueError(
            f"calibrate needs >= 5 positions whose inputs span the three axes (and a bias); "
            f"got {n} with rank {np.linalg.matrix_rank(a)}"
        )
    coef, *_ = np.linalg.lstsq(a, s, rcond=None)  # (4, 3): column i is sensor i's row
    resid = s - a @ coef
    dof = max(n - 4, 1)
    sigma2 = np.sum(resid**2, axis=0) / dof  # per sensor axis
    cov = np.linalg.inv(a.T @ a)  # (4, 4), times sigma2[i]
    m = coef[:3].T  # (3, 3)
    bias = coef[3]
    scale = np.diag(m) - 1.0
    _check_scale(scale)
    angles, angles_std = np.zeros(6), np.zeros(6)
    for k, (i, j) in enumerate(ANGLE_AXES):
        angles[k] = m[i, j] / m[i, i]
        # d(θ)/d(M_ij) = 1/M_ii, d(θ)/d(M_ii) = −M_ij/M_ii²
        g = np.zeros(4)
        g[j], g[i] = 1.0 / m[i, i], -m[i, j] / m[i, i] ** 2
        angles_std[k] = np.sqrt(sigma2[i] * g @ cov @ g)
    scale_std = np.sqrt(sigma2 * np.diag(cov)[:3])
    bias_std = np.sqrt(sigma2 * cov[3, 3])
    return TriadCalibration(
        *(jnp.asarray(x) for x in (angles, scale, bias, angles_std, scale_std, bias_std)),
        jnp.asarray(np.sqrt(sigma2)),
    )


UNIT_RATIOS = {
    180.0 / np.pi: ("° (°/s)", "rad (rad/s)"),
    3600.0: ("°/h", "°/s"),
    3600.0 * 180.0 / np.pi: ("°/h", "rad/s"),
    G0: ("m/s²", "g"),
    1000.0: ("mg", "g"),
    1000.0 / G0: ("mg", "m/s²"),
}
"""Output-to-input ratios 1 + k, with (unit of `s`, unit of `b`), that
[`calibrate`][hrgjax.fog.misalignment.calibrate] names when a fitted 1 + k lies within 2 % of
one or of its inverse (the units the other way round)."""


def _check_scale(scale: np.ndarray) -> None:
    """Refuse fitted scale errors outside `plausible.RANGES["imu_scale"]` (bounds excluded),
    naming the unit ratio 1 + k looks like."""
    low, high, _ = plausible.RANGES["imu_scale"]
    bad = np.flatnonzero(~((scale > low) & (scale < high)))
    if not bad.size:
        return
    i = int(bad[0])
    ratio = 1.0 + scale[i]
    looks = {**UNIT_RATIOS, **{1.0 / r: (b, s) for r, (s, b) in UNIT_RATIOS.items()}}
    hint = next((f": s in {su} for b in {bu}? Give both in one unit" for r, (su, bu)
                 in looks.items() if abs(ratio / r - 1.0) < 0.02), "")  # fmt: skip
    if not hint and abs(ratio + 1.0) < 0.02:
        hint = ": a reversed axis? Check the signs of b and s"
    elif not hint and abs(ratio) < 0.5:
        hint = ": the axes of b and s in another order?"
    raise ValueError(
        f"calibrate: sensor axis {'xyz'[i]} reads {ratio:.6g} × its input (fitted scale k = "
        f"{scale[i]:.4g}, outside the plausible {low:g} … {high:g}: a scale-factor error is "
        f"ppm to %){hint} (hrgjax.plausible.relaxed(imu_scale=…) widens it)"
    )


def _host_only(what: str, **args) -> None:
    """One line for an argument of `what` traced by `jit`, `vmap` or `grad`: the fit and the
    t quantile run on the host (NumPy, SciPy); converting a tracer raised JAX's
    TracerArrayConversionError."""
    for name, x in args.items():
        if any(isinstance(v, jax.core.Tracer) for v in jax.tree_util.tree_leaves(x)):
            raise ValueError(
                f"{what} runs on the host (NumPy/SciPy), not inside jit, vmap or grad: {name} "
                "must be concrete; got a traced value (loop in Python instead)"
            )


def dof(n_positions: int) -> int:
    """Degrees of freedom of [`calibrate`][hrgjax.fog.misalignment.calibrate]'s standard
    errors from `n_positions` positions: n − 4 (four unknowns per sensor axis)."""
    _host_only("dof", n_positions=n_positions)
    n = int(n_positions)
    if n != n_positions or n < 5:
        raise ValueError(
            f"n_positions must be an integer >= 5 (calibrate's minimum); got {n_positions!r}"
        )
    return n - 4


def half_width(std, n_positions: int, level: float = 0.95):
    """Half-width of the two-sided `level` confidence interval of an estimate of
    [`calibrate`][hrgjax.fog.misalignment.calibrate] with standard error `std` from
    `n_positions` positions: Student's t quantile with n − 4 dof times `std`
    (2.23σ at 95 % for 14 positions, 12.7σ for 5). `std` may be traced (`jit`, `vmap`:
    a JAX array back, a negative or infinite σ refused at run time); `n_positions` and
    `level` set the quantile on the host and must be concrete."""
    _host_only("half_width", n_positions=n_positions, level=level)
    if isinstance(level, str | bytes) or not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1); got {level!r}")
    q = stats.t.ppf(0.5 + 0.5 * level, dof(n_positions))
    if any(isinstance(v, jax.core.Tracer) for v in jax.tree_util.tree_leaves(std)):
        t = jnp.asarray(std, float)
        t = eqx.error_if(t, jnp.any((t < 0) | jnp.isinf(t)),
                         "std must be standard errors >= 0 (or NaN)")  # fmt: skip
        return q * t
    s = np.asarray(std)
    if s.dtype.kind not in "iuf":
        raise ValueError(f"std must be standard errors >= 0 (or NaN); got {std!r}"[:200])
    bad = (s < 0) | np.isinf(s)  # a NaN σ (an estimate without one) gives a NaN half-width
    if bad.any():
        raise ValueError(f"std must be standard errors >= 0 (or NaN); got {s[bad].flat[0]}")
    return q * s
