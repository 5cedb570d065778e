"""Mixed logs (dwell runs and continuous records in one dataset): the dwell session is a
switch-on of its own.

Audit finding (`bench_log({"bias_temperature": 0.005, "thermal_rate": 0.02,
"readout_gain_mismatch": 5e-4}, key 1)`): `discover` accepted a false `rate_scale_factor` of
2.6 ± 0.48 ppm/(°/s)² (truth 0). The readout mismatch was not the cause: without it the same
log gives 2.8 ± 0.44 (6σ), and on the noise-free log 0.01 ± 0.47. The mixed problem tied the
dwell session's switch-on bias to the records' shared `bias`, so the session's own draw of the
run-to-run spread (0.4 °/h here, σ_b = 0.2 °/h) stood as a common offset of every record, which
only `rate_scale_factor` could take: with k_e it shifts the records that turn at 2 °/s and
leaves the ±5 °/s windows. The session's bias is now profiled out of its windows
(`records.Windows.session`): 0.58 ± 0.73 on that log.
"""

import numpy as np
import pytest

import hrgjax as hg
from hrgjax.data import MeasuredData, concat
from hrgjax.discovery import NOMINAL
from hrgjax.discovery.continuous import ContinuousProblem
from hrgjax.units import DEG, DEG_PER_H

K_E = 0.554
SESSION_BIAS_DPH = 0.4  # the dwell session's switch-on bias, input rate [°/h]
RECORD_BIAS_DPH = (0.0, 0.0, 0.0, 0.0)  # each record's own [°/h]


def _run(run, t, rate_dps, temp_c, theta0_deg, bias_dph):
    """A noise-free run: the pattern turns at −k_e·(Ω + bias) and nothing else."""
    rate = np.broadcast_to(np.asarray(rate_dps, float), t.shape)
    theta = theta0_deg - K_E * (rate * t + bias_dph * DEG_PER_H / DEG * t)
    return MeasuredData({"time_s": t, "wave_angle_deg": theta, "table_rate_dps": rate,
                         "temperature_c": np.broadcast_to(temp_c, t.shape) + 0.0,
                         "run": np.full(t.shape, run)})  # fmt: skip


def _mixed_log():
    """One dwell session (static at four wave angles, ±5 °/s rotations; one switch-on, bias
    `SESSION_BIAS_DPH`) and four 10-min temperature ramps, two of them turning at 2 °/s,
    each its own switch-on (`RECORD_BIAS_DPH`)."""
    parts, run = [], 0
    for angle in (0.0, 45.0, 90.0, 135.0):
        parts.append(_run(run, np.arange(61.0), 0.0, 20.0, angle, SESSION_BIAS_DPH))
        run += 1
    for rate in (5.0, -5.0):
        parts.append(_run(run, np.arange(361) * 0.1, rate, 20.0, 0.0, SESSION_BIAS_DPH))
        run += 1
    t = np.arange(601.0)
    for rate, bias in zip((0.0, 2.0, 0.0, 2.0), RECORD_BIAS_DPH, strict=True):
        parts.append(_run(run, t, rate, 20.0 + t / 60.0, 10.0 * run, bias))
        run += 1
    return concat(parts)


@pytest.fixture(scope="module")
def problem():
    noise = hg.Noise(angle_white=1.0 / 3600 * DEG, angle_random_walk=0.002 * DEG / 60,
                     run_bias=0.2 * DEG_PER_H)  # fmt: skip
    data = _mixed_log()
    return ContinuousProblem.from_data(
        data, np.asarray([], int), nominal=NOMINAL, catalogue=["rate_scale_factor"], k_e=K_E,
        window_s=3.0, noise=noise,
    )  # fmt: skip


def test_the_dwell_sessions_own_bias_is_not_taken_for_a_rate_scale_factor(problem):
    """Noise-free: the nominal model fits the log exactly once the session's bias is its
    own; tied to the records' bias it left a 0.4 °/h offset that `rate_scale_factor` took
    (κ_Ω = 2.6 ppm/(°/s)² here, at σ 0.001)."""
    base = problem.fit(list(NOMINAL))
    fit = problem.fit([*NOMINAL, "rate_scale_factor"])
    kappa = fit.parameters["rate_scale_factor"]["kappa_Omega"]
    user = 1e6 * DEG**2  # s² → ppm/(°/s)²
    assert abs(kappa["value"]) * user < 1e-3 * kappa["std"] * user + 1e-6
    assert base.chi2 < 1e-6 and base.chi2 - fit.chi2 < 1e-6
    # the records' bias is the model's `bias`; the session's offset is not in it
    bias_dph = -base.parameters["bias"]["b"]["value"] / K_E / DEG_PER_H
    assert bias_dph == pytest.approx(np.mean(RECORD_BIAS_DPH), abs=1e-6)


def test_a_held_out_dwell_run_off_the_session_is_seen():
    """Held-out dwell windows take the training windows' session offset, not their own mean:
    de-meaned by their own, one held-out dwell run 5 °/h (25 σ_b) off the rest of its session
    read a held-out χ² of 4e-28 and no structure left (a reviewer's finding)."""
    noise = hg.Noise(angle_white=1.0 / 3600 * DEG, angle_random_walk=0.002 * DEG / 60,
                     run_bias=0.2 * DEG_PER_H)  # fmt: skip
    data = _mixed_log()
    off = np.asarray(data["run"]) == 3  # a static dwell run, held out
    t = np.asarray(data["time_s"])
    theta = np.asarray(data["wave_angle_deg"]) - off * K_E * 5.0 * DEG_PER_H / DEG * t
    shifted = MeasuredData({**data.columns, "wave_angle_deg": theta})
    for log, off_by in ((data, 0.0), (shifted, 5.0)):
        p = ContinuousProblem.from_data(
            log, np.asarray([3]), nominal=NOMINAL, catalogue=["rate_scale_factor"], k_e=K_E,
            window_s=3.0, noise=noise,
        )  # fmt: skip
        fit = p.fit(list(NOMINAL))
        # the held-out run's windows read its offset against the session: 5 °/h, in the gap
        assert fit.gap == pytest.approx(off_by, rel=1e-3, abs=1e-6), off_by
        assert p.structure_left(fit) == (off_by > 0)
