"""Does `detect_sections` hold every turn whole? The Ferraris calibration on the sections it
finds against the same on the true sections, for slow and uneven turns.

Until 2026-12, a rest was where the smoothed rate stayed under a fixed 3 °/s, and a turn
kept only 0.33 s beyond that: a turn whose rate ramps softly lost its slow ends (M_g −0.6 %
at 20 s, −8.6 % at 80 s, hundreds of σ). Now a rest is measured against its own noise
(hrgjax/imu/sections.py) and a turn section reaches into the rests on either side.

Sessions (`hg.imu.ferraris_session`, 100 Hz, 30-s faces, 2-s rests around each turn, no
Earth's rate, calibrated with `earth_rate=0`):

- `1-cos T s`: the simulator's turn, rate ∝ 1 − cos(2πt/T), T = 4, 20, 40, 80 s, white
  noise 1e-3 rad/s (0.06 °/s) per sample;
- `hand 8 s`: each turn's rows replaced by an imucal-style hand turn of −360° in 8 s
  (0.4-s smooth-step ramps, a plateau uneven by ±30 % at 0.8–1.6 s and 0.3–0.6 s periods),
  its gyro readings `truth.sensor` of that rate (the axis vertical: the specific force stays
  g along it) plus fresh white noise;
- `soft-start 30 s`, `soft-start 60 s tactical`: a turntable's soft start, rate sin²-ramped
  over 10 s (20 s), constant between; the second with 2e-5 rad/s noise per sample;
- `warm-up, 4 s` and `sway 0.2 Hz, 4 s`: a bias that wanders in the rests, no motion (the
  first slow-turn detection, whose rests' level was a constant, raised, shrank faces or
  faked repeats here): a consumer MEMS's warm-up, every gyro's bias rising by
  (1, −0.7, 0.4) °/s with τ 120 s on 0.1 °/s noise; a bench sway of 0.03 °/s × (1, −0.7, 0.4) at 0.2 Hz on
  1e-3 rad/s noise (2.6σ of a 0.25-s mean).

Per kind: the mean and RMS of (M_g,ii found − M_g,ii true sections) / σ (true sections), the
RMS of (M_g,ii found − truth) / σ (found), σ found / σ true, the shortest face found as a
share of its true rows, how many sessions the detection failed (none expected) and how many
`TurnCutWarning`s (none expected). `.venv/bin/python benchmarks/ferraris_slow_turns.py [--n 20]`."""

import argparse
import time
import warnings

import _common  # noqa: F401  (x64, thread pool)
import jax
import numpy as np
from _common import report

import hrgjax as hg
from hrgjax.imu import TURNS

RATE = 100.0
HALF_REST = int(2.0 * RATE) // 2


def _truth():
    rng = np.random.default_rng(1)
    return hg.imu.ImuCalibration.known(
        accel_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)), accel_bias=[0.1, -0.05, 0.2],
        gyro_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        gyro_bias=np.deg2rad([0.5, -0.3, 0.1]),
    )  # fmt: skip


def _hand(n, rng):
    t = np.arange(n) / RATE
    up, down = np.clip(t / 0.4, 0, 1), np.clip((t[-1] - t) / 0.4, 0, 1)
    env = (3 * up**2 - 2 * up**3) * (3 * down**2 - 2 * down**3)
    wobble = (0.3 * np.sin(2 * np.pi * t / rng.uniform(0.8, 1.6) + rng.uniform(0, 6))
              + 0.15 * np.sin(2 * np.pi * t / rng.uniform(0.3, 0.6)))  # fmt: skip
    return env * np.clip(1 + wobble, 0.05, None)


def _soft(n, ramp_s):
    t = np.arange(n) / RATE
    up, down = np.clip(t / ramp_s, 0, 1), np.clip((t[-1] - t) / ramp_s, 0, 1)
    return np.sin(np.pi * up / 2) ** 2 * np.sin(np.pi * down / 2) ** 2


def _session(truth, seed, turn_s, profile=None, turn_deg=360.0, noise=1e-3, wander=None):
    """A simulated session; with `profile` (rate shape of n samples), each turn's rows
    re-read through `truth` with that rate, scaled to `turn_deg`, and fresh noise; with
    `wander` (t [s] → rad/s), that added to every gyro × (1, −0.7, 0.4)."""
    data, true = hg.imu.ferraris_session(
        truth, jax.random.key(seed), rate_hz=RATE, static_s=30.0, turn_s=turn_s, gyro_noise=noise
    )
    if wander is not None:
        t = np.asarray(data.time)[:, None]
        gyro = np.asarray(data.gyro) + wander(t) * np.array([1.0, -0.7, 0.4])
        return hg.imu.ImuData(data.time, gyro, data.accel, rate_hz=RATE), true
    if profile is None:
        return data, true
    rng = np.random.default_rng(seed)
    gyro = np.array(data.gyro)
    for i, key in enumerate(TURNS):
        s, e = true[key][0]
        a, b = s + HALF_REST, e - HALF_REST
        rate = profile(b - a, rng)
        rate = np.deg2rad(turn_deg) * rate / (rate.sum() / RATE)
        omega = rate[:, None] * np.eye(3)[i]
        w_s, _ = truth.sensor(omega, np.tile(9.81 * np.eye(3)[i], (b - a, 1)))
        gyro[a:b] = np.asarray(w_s) + noise * rng.normal(size=(b - a, 3))
    return hg.imu.ImuData(data.time, gyro, data.accel, rate_hz=RATE), true


KINDS = {
    **{f"1-cos {t:g} s": dict(turn_s=t) for t in (4.0, 20.0, 40.0, 80.0)},
    "hand 8 s": dict(turn_s=8.0, profile=_hand, turn_deg=-360.0),
    "soft-start 30 s": dict(turn_s=30.0, profile=lambda n, _: _soft(n, 10.0)),
    "soft-start 60 s tactical": dict(turn_s=60.0, profile=lambda n, _: _soft(n, 20.0), noise=2e-5),
    "warm-up, 4 s": dict(turn_s=4.0, noise=np.deg2rad(0.1),
                         wander=lambda t: np.deg2rad(1.0) * (1 - np.exp(-t / 120.0))),
    "sway 0.2 Hz, 4 s": dict(turn_s=4.0, wander=lambda t: np.deg2rad(0.03)
                             * np.sin(2 * np.pi * 0.2 * t)),
}  # fmt: skip


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20, help="sessions per kind")
    args = parser.parse_args()
    truth = _truth()
    m_true = np.diag(np.asarray(truth.gyro_matrix))
    for name, kind in KINDS.items():
        t0, d, z, ratio, cut, short, failed = time.perf_counter(), [], [], [], 0, [], 0
        for seed in range(args.n):
            data, true = _session(truth, seed, **kind)
            turn_deg = kind.get("turn_deg", 360.0)
            try:
                found = hg.imu.detect_sections(data)
            except ValueError:
                failed += 1
                continue
            short.append(min(sum(e - s for s, e in found[k]) / (te - ts)
                             for k in hg.imu.FACES for ts, te in true[k]))  # fmt: skip
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", hg.imu.sections.TurnCutWarning)
                got = hg.imu.ferraris(data, found, turn_deg=turn_deg, earth_rate=0.0)
            cut += len(caught)
            ref = hg.imu.ferraris(data, true, turn_deg=turn_deg, earth_rate=0.0)
            m, sd = np.diag(np.asarray(got.gyro_matrix)), np.diag(np.asarray(got.gyro_matrix_std))
            m_ref = np.diag(np.asarray(ref.gyro_matrix))
            sd_ref = np.diag(np.asarray(ref.gyro_matrix_std))
            d.append((m - m_ref) / sd_ref)
            z.append((m - m_true) / sd)
            ratio.append(sd / sd_ref)
        if not d:
            print(f"{name:26s} ({args.n} sessions): detection failed in all", flush=True)
            continue
        d, z, ratio = (np.array(x) for x in (d, z, ratio))
        rms_d = float(np.sqrt(np.mean(d**2)))
        print(f"{name:26s} ({args.n} sessions, {time.perf_counter() - t0:.0f} s): (found − true "
              f"sections)/σ mean {d.mean():+.2f} RMS {rms_d:.2f} max |.| {np.abs(d).max():.2f}; "
              f"(found − truth)/σ RMS {np.sqrt(np.mean(z**2)):.2f}; σ found/true "
              f"{ratio.mean():.2f} (min {ratio.min():.2f}); shortest face {min(short):.2f}; "
              f"detection failed {failed}; TurnCutWarnings {cut}", flush=True)  # fmt: skip
        report(f"ferraris found sections, {name}: RMS of (M_g found − M_g true sections)/σ",
               rms_d, "", target="≤ 0.5")  # fmt: skip


if __name__ == "__main__":
    main()
