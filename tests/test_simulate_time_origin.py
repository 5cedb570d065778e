"""`simulate` reads no clock origin: a profile stamped at an epoch (t₀ = 1.7e9 s, a Unix time,
where float64 resolves 2.4e-7 s) gives the run whose knots are the same times less t₀.
Truth: physics is invariant under a shift of time, so the two runs must agree to round-off.
The full model's fixed carrier steps were built in absolute seconds, and the quantised step
times read as a scale-factor error: a 0.2-s run at 5 °/s was off by 1.4e-7 rad (−14 ppm)."""

import jax
import numpy as np
import pytest

import hrgjax as hg

EPOCH = 1.7e9


def _profile(t):
    return hg.Profile.piecewise(t, [5.0, 8.0, 8.0], [30.0, 30.0, 31.0], wave_angle0_deg=20.0)


@pytest.fixture(scope="module")
def runs():
    """The same 0.2-s run (a rate ramp, a temperature step, noise from one key) of the
    carrier-resolving model, stamped at the epoch and at 0: its knots are the epoch's knots
    less the epoch (exact in float64), so both describe the same physical run."""
    gyro = hg.presets.tvg3_like()
    knots = EPOCH + np.array([0.0, 0.1, 0.2])
    at_epoch, at_zero = _profile(knots), _profile(knots - EPOCH)
    run = lambda p: hg.simulate(gyro, p, "full", key=jax.random.key(7), dt_out=0.05)  # noqa: E731
    return at_epoch, run(at_epoch), run(at_zero)


def test_full_model_does_not_depend_on_the_time_origin(runs):
    """The wave angle turned (noise included), the true angle, the PLL frequency and the
    table's angle agree to 1e-12 (the old absolute step grid: 1.4e-7 rad)."""
    _, epoch, zero = runs
    for name in ("wave_angle", "true_wave_angle", "table_angle"):
        a, b = np.asarray(getattr(epoch, name)), np.asarray(getattr(zero, name))
        np.testing.assert_allclose(a - a[0], b - b[0], rtol=0, atol=1e-12, err_msg=name)
    np.testing.assert_allclose(epoch.frequency, zero.frequency, rtol=1e-13)
    turned = float(zero.true_wave_angle[-1] - zero.true_wave_angle[0])
    assert abs(turned) > 1e-2  # the run turns: 0.55 × 5–8 °/s over 0.2 s


def test_record_keeps_the_profiles_own_times(runs):
    """The record's times are the profile's (the epoch, not 0), on the `dt_out` grid from the
    first knot; the user's profile is left as given."""
    profile, epoch, zero = runs
    assert epoch.t.shape == (5,) and float(profile.t[0]) == EPOCH
    np.testing.assert_allclose(np.asarray(epoch.t) - EPOCH, np.asarray(zero.t), rtol=0, atol=5e-7)
    assert float(epoch.t[0]) == EPOCH


def test_averaged_model_does_not_depend_on_the_time_origin():
    """The averaged model's adaptive solve at the epoch: the same run to 1e-12 rad over 14 rad
    turned in 60 s of rate and temperature ramps (in absolute time: 4.7e-7 rad)."""
    gyro = hg.presets.tvg3_like()
    knots = EPOCH + np.array([0.0, 20.0, 40.0, 60.0])
    rate, temp = [100.0, 100.0, -50.0, -50.0], [-20.0, 0.0, 30.0, 30.0]
    a, b = (hg.simulate(gyro, hg.Profile.piecewise(t, rate, temp, wave_angle0_deg=20.0),
                        key=jax.random.key(1), dt_out=0.5).wave_angle
            for t in (knots, knots - EPOCH))  # fmt: skip
    np.testing.assert_allclose(a - a[0], b - b[0], rtol=0, atol=1e-12)
