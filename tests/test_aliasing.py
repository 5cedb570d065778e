"""Objects built from the user's NumPy arrays keep their own copy: on CPU `jax.device_put`
and `jnp.asarray` share a 64-byte-aligned buffer instead of copying, so a later edit of the
user's array (a buffer refilled per temperature level, a covariance reused) changed the
object after its checks ran. Each case forces an aligned buffer, builds, edits it, and
checks the object still holds what it was built with."""

import numpy as np

import hrgjax as hg
from hrgjax._compiled import device
from hrgjax.imu import ImuCalibration
from hrgjax.kalman import Gaussian


def _aligned(shape, fill):
    """A float64 array of `shape` filled with `fill`, its buffer 64-byte aligned."""
    n = int(np.prod(shape))
    raw = np.empty(n + 8)
    off = (-raw.ctypes.data % 64) // 8
    a = raw[off : off + n].reshape(shape)
    a[...] = fill
    assert a.ctypes.data % 64 == 0
    return a


def test_device_copies_an_aligned_buffer():
    a = _aligned((5,), 1.0)
    d = device(a, float)
    a[...] = 7.0
    np.testing.assert_array_equal(np.asarray(d), np.ones(5))


def test_profile_keeps_its_temperatures():
    t, rate, accel = np.array([0.0, 30.0, 60.0]), np.full(3, 0.1), np.zeros((3, 3))
    temp = _aligned((3,), -20.0)
    profile = hg.Profile(t, rate, temp, accel)
    temp[...] = 300.0  # kelvin: refused at construction, must not slip in afterwards
    np.testing.assert_array_equal(np.asarray(profile.temperature), np.full(3, -20.0))


def test_temperature_law_keeps_its_coefficients():
    p0 = _aligned((4,), [1.0, 2.0, 3.0, 4.0])
    law = hg.TemperatureLaw(p0=p0)
    p0[...] = 9.0
    np.testing.assert_array_equal(np.asarray(law.p0), [1.0, 2.0, 3.0, 4.0])


def test_imu_calibration_known_keeps_its_bias():
    b = _aligned((3,), 0.01)
    cal = ImuCalibration.known(gyro_bias=b)
    b[...] = 0.03
    np.testing.assert_array_equal(np.asarray(cal.gyro_bias), np.full(3, 0.01))


def test_gaussian_keeps_its_mean_and_covariance():
    x, P = _aligned((2,), 0.5), _aligned((2, 2), np.eye(2))
    g = Gaussian(x, P)
    x[...], P[...] = 0.0, -np.eye(2)  # would leave a non-PSD covariance
    np.testing.assert_array_equal(np.asarray(g.x), [0.5, 0.5])
    np.testing.assert_array_equal(np.asarray(g.P), np.eye(2))
    assert not np.asarray(g.P).flags.writeable
