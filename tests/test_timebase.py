"""Time stamps at an epoch: a uniform 10-kHz record stamped in epoch seconds (float64 moves in
2.4e-7-s steps there) is read as uniform at 10 000 Hz — its median step read 10 010 Hz and
the record was resampled, its shortest-τ Allan deviation 29 % low (audit of long records)."""

import numpy as np
import pytest

import hrgjax as hg
from hrgjax._timebase import is_uniform, rate_from_stamps, regular_step
from hrgjax.cli import main

EPOCH = 1.7e9


def _stamps(rate=1e4, n=20_000, t0=EPOCH):
    return t0 + np.arange(n) / rate


@pytest.mark.parametrize("t0", [0.0, 1e6, EPOCH])
def test_uniform_stamps_at_any_offset_are_uniform_at_their_rate(t0):
    t = _stamps(t0=t0)
    step = regular_step(t)
    assert is_uniform(t, step)
    assert rate_from_stamps(t, step) == 1e4
    # what the old rule saw at the epoch: a median step 0.1 % off
    if t0 == EPOCH:
        assert abs(1 / np.median(np.diff(t)) / 1e4 - 1) > 5e-4


def test_jitter_and_gaps_are_not_uniform():
    rng = np.random.default_rng(0)
    t = _stamps(t0=0.0)
    assert not is_uniform(t + 0.01 / 1e4 * rng.standard_normal(t.size), 1e-4)
    gap = np.delete(t, np.arange(5000, 5010))  # ten samples missing
    step = regular_step(gap)
    assert step == pytest.approx(1e-4, rel=1e-9)  # a gap does not move the step
    assert not is_uniform(gap, step)


def test_allan_cli_reads_epoch_stamped_10khz_record_as_uniform(tmp_path, capsys):
    t = _stamps()
    y = 0.1 * np.random.default_rng(1).standard_normal(t.size)
    path = tmp_path / "epoch.csv"
    np.savetxt(path, np.column_stack([t, y]), delimiter=",", header="time_s,gyro_dps",
               comments="", fmt="%.17g")  # fmt: skip
    assert main(["allan", str(path), "--time-column", "time_s", "--column", "gyro_dps",
                 "--unit", "deg/s"]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert "20000 samples at 10000 Hz" in out and "resampled" not in out


def test_imu_rate_from_epoch_stamps():
    t = _stamps(n=2000)
    data = hg.imu.ImuData(t, np.zeros((t.size, 3)), np.tile([0.0, 0.0, 9.8], (t.size, 1)))
    resolution = 2 * np.spacing(t[-1]) / (t[-1] - t[0])  # two stamps' rounding over the span
    assert data.rate_hz == pytest.approx(1e4, rel=resolution)  # the median step read 10 010 Hz


@pytest.mark.parametrize("rate, tick, t0", [(100.0, 32768.0, 0.0), (100.0, 32768.0, EPOCH),
                                            (200.0, 32768.0, 0.0), (3000.0, 1e6, 0.0),
                                            (60.0, 1e3, 0.0), (1000.0, 16384.0, 0.0)])  # fmt: skip
def test_a_clock_counted_in_crystal_ticks_reads_its_mean_rate(rate, tick, t0):
    """100 Hz from a 32 768-Hz crystal steps 327 or 328 ticks (32 % / 68 %): the rate is the
    mean step's, the stamps' span over their count (the 328-tick steps alone read
    99.902 439 Hz, and the CLI resampled white noise at that rate into a Gauss–Markov);
    `millis()` at 60 Hz steps 16 or 17 ms, a tick 6 % of a step, and is no stall."""
    n = 4000
    t = t0 + np.floor(np.arange(n) * tick / rate) / tick
    truth = (n - 1) / (t[-1] - t[0])  # the clock's own mean rate (100.000 024 Hz here)
    assert len(set(np.round(np.diff(t - t0) * tick))) == 2
    assert 1.0 / regular_step(t) == pytest.approx(truth, rel=1e-9)
    assert hg.allan.to_uniform(t, np.zeros(n)).rate_hz == pytest.approx(truth, rel=1e-9)


@pytest.mark.parametrize("stamp", [1e-6, 1e-3])
def test_a_sleep_loop_reads_its_own_mean_rate(stamp):
    """Review of 2ad719e: a `time.sleep(0.01)` logger steps 10 ms plus an overshoot, only ever
    longer (here exponential, 0.3 ms on average: 97.1 Hz); stamped in ms, 10, 11 or 12 ms.
    Every step longer than 5 % over the median was taken for a stall: the rate read 100 Hz
    (7e-3 fast in µs stamps, 3e-2 in ms) and `ImuData(..., rate_hz=97.12)` was refused. The
    longer steps fill the band above the typical step, so they are the clock's own; the
    rate is its mean, the stamps' span over their count."""
    n = 6000
    dt = 0.01 + np.random.default_rng(3).exponential(0.3e-3, n - 1)
    t = np.round(np.r_[0.0, np.cumsum(dt)] / stamp) * stamp
    truth = (n - 1) / (t[-1] - t[0])  # 97.12 Hz
    assert 1.0 / regular_step(t) == pytest.approx(truth, rel=1e-12)
    gyro, accel = np.zeros((n, 3)), np.tile([0.0, 0.0, 9.8], (n, 1))
    assert hg.imu.ImuData(t, gyro, accel).rate_hz == pytest.approx(truth, rel=1e-12)
    assert hg.imu.ImuData(t, gyro, accel, rate_hz=round(truth, 2)).rate_hz == round(truth, 2)


def test_stalls_beyond_a_one_tick_pattern_are_left_out():
    """A stall is told by the empty band under it: on a `millis()` clock at 98 Hz (10 or
    11 ms, the 11-ms steps evenly spread: the clock's own pattern, not stalls), 2 % of
    1.4-step stalls (14 or 15 ms) are left out (their mean read 8.8e-3 slow)."""
    n = 6000
    ticks = np.floor(np.arange(n) / 98.0 / 1e-3 + 0.5)
    truth = (n - 1) / (ticks[-1] - ticks[0]) * 1e3  # the clock's own mean rate, 98 Hz
    assert 1.0 / regular_step(ticks * 1e-3) == pytest.approx(truth, rel=1e-12)
    dt = np.diff(ticks)
    dt[np.random.default_rng(4).random(n - 1) < 0.02] += 4.0  # 2 % of 1.4-step stalls
    stalled = 1.0 / regular_step(np.r_[0.0, np.cumsum(dt)] * 1e-3)
    assert stalled == pytest.approx(truth, rel=5e-4)  # 5e-5: which steps the stalls hit
