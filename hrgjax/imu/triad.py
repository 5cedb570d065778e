r"""The static model of a sensor triad: scale, installation misalignment and bias
(PHYSICS.md §12), shared by every IMU calibration ([`ferraris`][hrgjax.imu.ferraris] and the
multi-position fit of seed 003, [`calibrate`][hrgjax.fog.misalignment.calibrate]).

Each sensor axis i of a non-orthogonal triad is tilted by two small angles towards the other
two body axes; the six angles $\theta_{ij}$ (axis i towards body axis j, $i \ne j$) form the
off-diagonal matrix E, and to first order a sensor triad reads

$$s = (I + E)\,b, \qquad b = (I + E)^{-1}s \approx (I - E)\,s,$$

with b the body-frame (orthogonal) quantity. With scale factors k and biases β the model is
$s = \mathrm{diag}(1 + k)(I + E)b + \beta$
([`TriadCalibration`][hrgjax.imu.triad.TriadCalibration]).

Angle order everywhere: `ANGLES` = (xy, xz, yx, yz, zx, zy)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import concrete_value

ANGLES = ("xy", "xz", "yx", "yz", "zx", "zy")
"""Order of the six misalignment angles: sensor axis, then the body axis it leans towards."""
ANGLE_AXES = ((0, 1), (0, 2), (1, 0), (1, 2), (2, 0), (2, 1))
"""`(i, j)` of each angle in `ANGLES` order: sensor axis i leans towards body axis j."""


def misalignment_matrix(angles):
    """The off-diagonal matrix E (3, 3) from the six angles (6,) [rad] (`ANGLES` order)."""
    a = jnp.asarray(angles)
    if a.shape[-1:] != (6,):
        raise ValueError(f"angles must have shape (..., 6) in order {ANGLES}; got {a.shape}")
    e = jnp.zeros(a.shape[:-1] + (3, 3), a.dtype)
    for k, (i, j) in enumerate(ANGLE_AXES):
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
        [-], the scale-factor errors k of diag(1 + k) (30e-6 = 30 ppm), and `bias` (3,)
        [sensor units] (zeros by default).

        **Raises:** `ValueError` for a wrong shape, a NaN or inf, or (concrete values) an
        angle or a scale error outside `hrgjax.plausible.RANGES` (`imu_misalignment`,
        `imu_scale`: |θ| < 0.1 rad, |k| < 0.1), named with the units it may be in (mrad,
        µrad or ° for rad; ppm or %); a scale near 1 is named as the factor 1 + k given for
        k. Traced values (`vmap` over the angles) pass unchecked."""
        angles = jnp.array(angles, float)  # copies (`jnp.asarray` may view the user's array)
        if angles.shape != (6,):
            raise ValueError(f"angles must have shape (6,) in order {ANGLES}; got {angles.shape}")
        scale = jnp.zeros(3) if scale is None else jnp.array(scale, float)
        bias = jnp.zeros(3) if bias is None else jnp.array(bias, float)
        for name, x in (("scale", scale), ("bias", bias)):
            if x.shape != (3,):
                raise ValueError(f"{name} must have shape (3,); got {x.shape}")
        for name, x in (("angles", angles), ("scale", scale), ("bias", bias)):
            v = concrete_value(x)
            if v is not None and not np.all(np.isfinite(v)):
                raise ValueError(f"{name} must be finite; got {v[~np.isfinite(v)][0]} at index "
                                 f"{int(np.argmax(~np.isfinite(v)))}")  # fmt: skip
        _check_triad(concrete_value(angles), concrete_value(scale))
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


def _check_triad(angles, scale) -> None:
    """`TriadCalibration.known`'s ranges on concrete `angles` [rad] and `scale` [-] (None:
    traced, not checked): `hrgjax.plausible`'s `imu_misalignment` and `imu_scale`."""
    if scale is not None:
        near_one = np.abs(scale - 1.0) < 0.5
        if np.any(near_one):
            i = int(np.argmax(near_one))
            raise ValueError(
                f"scale must be the scale-factor errors k of diag(1 + k) [-] (30e-6 = 30 ppm); "
                f"got {scale[i]:.9g} at index {i}: the factor 1 + k? pass scale − 1 = "
                f"{scale[i] - 1.0:.6g}"
            )
        plausible.check("scale [-]", scale, "imu_scale")
    if angles is not None:
        plausible.check("angles [rad]", angles, "imu_misalignment")
