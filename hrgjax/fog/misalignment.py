r"""Installation misalignment of a sensor triad (seed 003, step 2; PHYSICS.md §12).

Each sensor axis i of a non-orthogonal triad is tilted by two small angles towards the other
two body axes; the six angles $\theta_{ij}$ (axis i towards body axis j, $i \ne j$) form the
off-diagonal matrix E, and to first order a sensor triad reads

$$s = (I + E)\,b, \qquad b = (I + E)^{-1}s \approx (I - E)\,s,$$

with b the body-frame (orthogonal) quantity. The first-order inverse leaves an error of order
$E^2$. With scale factors k and biases β the static model is $s = \mathrm{diag}(1 + k)(I + E)b
+ \beta$, which [`calibrate`][hrgjax.fog.misalignment.calibrate] estimates from positions with
known body-frame inputs (a multi-position static test for accelerometers, rate-table
rotations plus Earth rate for gyros) by linear least squares, with standard errors.

Angle order everywhere: `ANGLES` = (xy, xz, yx, yz, zx, zy)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

ANGLES = ("xy", "xz", "yx", "yz", "zx", "zy")
"""Order of the six misalignment angles: sensor axis, then the body axis it leans towards."""
_IDX = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))


def misalignment_matrix(angles):
    """The off-diagonal matrix E (3, 3) from the six angles (6,) [rad] (`ANGLES` order)."""
    a = jnp.asarray(angles)
    if a.shape[-1:] != (6,):
        raise ValueError(f"angles must have shape (..., 6) in order {ANGLES}; got {a.shape}")
    e = jnp.zeros(a.shape[:-1] + (3, 3), a.dtype)
    for k, (i, j) in enumerate(_IDX):
        e = e.at[..., i, j].set(a[..., k])
    return e


def sensor_from_body(angles):
    """First-order map body → sensor axes, I + E (3, 3)."""
    return jnp.eye(3) + misalignment_matrix(angles)


def body_from_sensor(angles):
    """First-order map sensor → body axes, I − E (3, 3): the compensation of seed 003."""
    return jnp.eye(3) - misalignment_matrix(angles)


class TriadCalibration(eqx.Module):
    """Static model of a sensor triad, `s = diag(1 + scale) (I + E(angles)) b + bias`, with
    the standard errors of a fit (zero when set by hand).

    **Fields:** `angles` (6,) [rad], `scale` (3,) [-], `bias` (3,) [sensor units];
    `angles_std`, `scale_std`, `bias_std`; `residual_std` [sensor units]."""

    angles: jax.Array
    scale: jax.Array
    bias: jax.Array
    angles_std: jax.Array
    scale_std: jax.Array
    bias_std: jax.Array
    residual_std: jax.Array

    @classmethod
    def known(cls, angles, scale=None, bias=None) -> TriadCalibration:
        """A model set by hand (standard errors zero): `angles` (6,) [rad], `scale` (3,)
        and `bias` (3,) (zeros by default)."""
        angles = jnp.asarray(angles, float)
        if angles.shape != (6,):
            raise ValueError(f"angles must have shape (6,) in order {ANGLES}; got {angles.shape}")
        scale = jnp.zeros(3) if scale is None else jnp.asarray(scale, float)
        bias = jnp.zeros(3) if bias is None else jnp.asarray(bias, float)
        for name, x in (("scale", scale), ("bias", bias)):
            if x.shape != (3,):
                raise ValueError(f"{name} must have shape (3,); got {x.shape}")
        z3 = jnp.zeros(3)
        return cls(angles, scale, bias, jnp.zeros(6), z3, z3, z3)

    @property
    def matrix(self):
        """The linear part M = diag(1 + scale)(I + E) (3, 3): sensor = M body + bias."""
        return (1.0 + self.scale)[:, None] * sensor_from_body(self.angles)

    def sensor(self, b):
        """Sensor outputs (..., 3) for body-frame inputs `b` (..., 3)."""
        m = self.matrix
        b = jnp.asarray(b)
        return b @ m.T + self.bias.reshape((1,) * (b.ndim - 1) + (3,))

    def body(self, s):
        """Compensated body-frame values (..., 3) from sensor outputs `s` (..., 3): bias
        removed, scale divided out, misalignment undone (exact inverse of the model)."""
        m = self.matrix
        s = jnp.asarray(s)
        d = s - self.bias.reshape((1,) * (s.ndim - 1) + (3,))
        return d @ jnp.linalg.inv(m).T


def calibrate(b, s) -> TriadCalibration:
    """Fit the static triad model to `n` positions: known body-frame inputs `b` (n, 3) and
    the averaged sensor outputs `s` (n, 3). Linear least squares per sensor axis for the row
    of M = diag(1 + k)(I + E) and the bias (4 unknowns per axis), then k_i = M_ii − 1 and
    θ_ij = M_ij / M_ii. Standard errors from the residual scatter (σ²(AᵀA)⁻¹, propagated to
    first order). Needs ≥ 5 positions whose inputs span all three axes with both signs —
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
    for k, (i, j) in enumerate(_IDX):
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
