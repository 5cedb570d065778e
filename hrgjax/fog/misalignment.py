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
1 dof, 93 % with 10 (the 14 positions of the study).

Angle order everywhere: `ANGLES` = (xy, xz, yx, yz, zx, zy)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from scipy import stats

# The triad model is the IMU's (hrgjax.imu.triad); its names stay importable from here.
from ..imu.triad import ANGLE_AXES
from ..imu.triad import ANGLES as ANGLES
from ..imu.triad import TriadCalibration as TriadCalibration
from ..imu.triad import body_from_sensor as body_from_sensor
from ..imu.triad import misalignment_matrix as misalignment_matrix
from ..imu.triad import sensor_from_body as sensor_from_body


def calibrate(b, s) -> TriadCalibration:
    """Fit the static triad model to `n` positions: known body-frame inputs `b` (n, 3) and
    the averaged sensor outputs `s` (n, 3). Linear least squares per sensor axis for the row
    of M = diag(1 + k)(I + E) and the bias (4 unknowns per axis), then k_i = M_ii − 1 and
    θ_ij = M_ij / M_ii. Standard errors from the residual scatter (σ²(AᵀA)⁻¹, propagated to
    first order) — with n − 4 degrees of freedom ([`dof`][hrgjax.fog.misalignment.dof]):
    read them with Student's t ([`half_width`][hrgjax.fog.misalignment.half_width] gives
    an interval), not as Gaussian. Needs ≥ 5 positions whose inputs span all three axes with both signs —
    e.g. the six ±axis positions plus any tilted one."""
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


def dof(n_positions: int) -> int:
    """Degrees of freedom of [`calibrate`][hrgjax.fog.misalignment.calibrate]'s standard
    errors from `n_positions` positions: n − 4 (four unknowns per sensor axis)."""
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
    (2.23σ at 95 % for 14 positions, 12.7σ for 5)."""
    if isinstance(level, str | bytes) or not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1); got {level!r}")
    s = np.asarray(std)
    if s.dtype.kind not in "iuf":
        raise ValueError(f"std must be standard errors >= 0 (or NaN); got {std!r}"[:200])
    bad = (s < 0) | np.isinf(s)  # a NaN σ (an estimate without one) gives a NaN half-width
    if bad.any():
        raise ValueError(f"std must be standard errors >= 0 (or NaN); got {s[bad].flat[0]}")
    return stats.t.ppf(0.5 + 0.5 * level, dof(n_positions)) * s
