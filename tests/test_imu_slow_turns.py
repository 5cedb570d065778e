"""`detect_sections` holds a slow turn whole, and a turn section cut short is named.

A turn whose rate ramps softly (the simulator's 1 − cos profile, a hand turn, a soft-start
turntable) lost its slow ends under the fixed 3 °/s rest threshold: M_g read −0.6 % at 20 s
(z ≈ −80), −8.6 % at 80 s (z ≈ −650), and the 330° left passed the 360° ± 45° check.
Truth: the analytic share of a (1 − cos) turn outside a range, u − sin(2πu)/2π at each end
(u the cut fraction of the turn), and the calibration on the simulator's true sections."""

import json

import jax
import numpy as np
import pytest

import hrgjax as hg
from hrgjax.imu import TURNS, ImuCalibration
from hrgjax.imu.sections import TurnCutWarning, cut_turn

RATE = 100.0
HALF_REST = int(2.0 * RATE) // 2  # ferraris_session's true turn: the turn ± half a 2-s rest


@pytest.fixture(scope="module")
def truth():
    rng = np.random.default_rng(1)
    return ImuCalibration.known(
        accel_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        accel_bias=[0.1, -0.05, 0.2],
        gyro_matrix=np.eye(3) + rng.normal(0, 0.01, (3, 3)),
        gyro_bias=np.deg2rad([0.5, -0.3, 0.1]),
    )


def _lost_share(found, true, n_turn):
    """The share of a (1 − cos) turn's angle outside the rows `found`, analytic."""
    (s, e), (ts, te) = found, true
    start, end = ts + HALF_REST, te - HALF_REST  # the turn's own rows
    u = np.array([max(s - start, 0), max(end - e, 0)]) / n_turn
    return float(np.sum(u - np.sin(2 * np.pi * u) / (2 * np.pi)))


@pytest.mark.parametrize(
    ("turn_s", "gyro_noise"),
    [(4.0, 1e-3), (40.0, 1e-3), (80.0, 2e-5)],  # MEMS-like 0.06 °/s, tactical 1e-3 °/s
)
def test_detected_turns_are_whole_and_calibrate_as_the_true_sections(truth, turn_s, gyro_noise):
    data, true = hg.imu.ferraris_session(truth, jax.random.key(3), rate_hz=RATE, static_s=6.0,
                                         turn_s=turn_s, gyro_noise=gyro_noise)  # fmt: skip
    found = hg.imu.detect_sections(data)
    for key in TURNS:  # the old detection lost 0.62 % at 20 s, 8.6 % at 80 s
        assert _lost_share(found[key][0], true[key][0], turn_s * RATE) < 1e-6, (key, found[key])
    got = hg.imu.ferraris(data, earth_rate=0.0)  # sections found by itself; no warning
    ref = hg.imu.ferraris(data, true, earth_rate=0.0)
    m, m_ref = np.diag(np.asarray(got.gyro_matrix)), np.diag(np.asarray(ref.gyro_matrix))
    sd, sd_ref = np.diag(np.asarray(got.gyro_matrix_std)), np.diag(np.asarray(ref.gyro_matrix_std))
    assert np.all(np.abs(m - m_ref) < sd_ref), (m - m_ref) / sd_ref
    assert np.all(np.abs(m - np.diag(np.asarray(truth.gyro_matrix))) < 4 * sd)
    assert np.all(sd < 1.25 * sd_ref)  # the rest inside a found turn costs little noise


def test_a_turn_cut_short_is_named(truth, tmp_path, capsys):
    from hrgjax.cli import main

    data, true = hg.imu.ferraris_session(truth, jax.random.key(4), rate_hz=RATE, static_s=6.0,
                                         turn_s=20.0)  # fmt: skip
    assert cut_turn(data, true) is None
    hg.imu.ferraris(data, true, earth_rate=0.0)  # whole turns: no warning (warnings fail here)
    s, e = true["x_rot"][0]
    cut = {**true, "x_rot": [(s + HALF_REST + 300, e - HALF_REST - 300)]}  # 3 s off each end
    match = (
        r"^hrgjax\.imu\.ferraris: turn 'x_rot' rows \[\d+, \d+\): the gyro still turns "
        r"before it \(\+\d.*°/s about x.*leaves out motion with the turn \(M_g reads low\)"
    )
    with pytest.warns(TurnCutWarning, match=match):
        short = hg.imu.ferraris(data, cut, earth_rate=0.0)
    share = 2 * (0.15 - np.sin(0.3 * np.pi) / (2 * np.pi))  # u = 0.15 at both ends: 2.6 %
    assert float(short.gyro_matrix[0, 0]) == pytest.approx(
        float(truth.gyro_matrix[0, 0]) * (1 - share), abs=5 * float(short.gyro_matrix_std[0, 0])
    )
    # imu-calibrate: the warning in one line on stderr, the calibration still printed
    log = tmp_path / "log.csv"
    table = np.column_stack([data.time, np.rad2deg(data.gyro), data.accel])
    np.savetxt(log, table, delimiter=",", header="t,gx,gy,gz,ax,ay,az", comments="", fmt="%.17g")
    (tmp_path / "s.json").write_text(json.dumps(hg.imu.sections_to_json(cut)))
    rc = main(["imu-calibrate", str(log), "--sections", str(tmp_path / "s.json"),
               "--gyro-columns", "gx,gy,gz", "--accel-columns", "ax,ay,az", "--time-column", "t",
               "--gyro-unit", "deg/s", "--accel-unit", "m/s^2", "--no-earth-rate"])  # fmt: skip
    assert rc == 0
    out, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if "still turns" in line]
    assert len(lines) == 1 and lines[0].startswith("hrgjax imu-calibrate: turn 'x_rot' rows")
    assert "gyro matrix" in out
