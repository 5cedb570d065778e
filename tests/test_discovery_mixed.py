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
from hrgjax.discovery import NOMINAL, records
from hrgjax.discovery.continuous import ContinuousProblem
from hrgjax.discovery.problem import held_out_runs
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


def _plan_log():
    """The layout of a bench plan (audit bench, `tvg3_like`): at −40, 20 and 60 °C a 120-s
    static and a 72-s 5 °/s rotation at each of the wave angles −60°, 0° and 60° (the
    readout mismatch moves the held angle by ≈ 0.5° between temperatures), then four ramps
    (runs 18–21). Noise-free: only the run layout is read."""
    parts, run = [], 0
    for temp, shift in ((-40.0, 0.52), (20.0, 0.23), (60.0, 0.04)):
        for angle in (-60.0, 0.0, 60.0):
            a = angle + np.sign(angle) * shift
            parts.append(_run(run, np.arange(121.0), 0.0, temp, a, 0.0))
            parts.append(_run(run + 1, np.arange(145) * 0.5, 5.0, temp, a, 0.0))
            run += 2
    t = np.arange(601.0)
    for start, slope, angle in ((-40, 1, 30), (60, -1, 30), (-40, 1, -30), (60, -1, -30)):
        parts.append(_run(run, t, 0.0, start + slope * t / 60.0, angle, 0.0))
        run += 1
    return concat(parts)


def test_the_split_keeps_every_static_wave_angle_in_training():
    """Audit finding (F1, bench2): every third run of this plan is every θ = 0 static; with
    the dwell session's offset profiled out, the statics left (±60°: cos 2θ alike) no longer
    fixed the damping's cos 2θ, which took the rotations' readout ripple (−186 °/h, the
    readout mismatch's ΔBIC 1.2·10⁴ instead of 2.9·10⁶) and `discover` said `unexplained`.
    One θ = 0 static now stays in training, swapped for the next dwell run (a rotation,
    whose rate the other rotations keep); the ramps' split is the stride's."""
    data = _plan_log()
    held = held_out_runs(data, 3)
    np.testing.assert_array_equal(held, [3, 5, 8, 11, 14, 17, 20])
    statics = {r: float(data["wave_angle_deg"][data.run == r][0]) for r in range(0, 18, 2)}
    kept = {round(a / 5) * 5 for r, a in statics.items() if r not in held}
    assert kept == {-60, 0, 60}
    # a stride that already keeps every condition is the stride
    np.testing.assert_array_equal(held_out_runs(data, 4), [3, 7, 11, 15, 19])


def _statics(angles, temps=None, rates=None):
    """Layout-only dwell runs (noise-free, 61 s each) at start wave `angles` [° el.],
    temperatures `temps` [°C] and table `rates` [°/s]."""
    temps = [20.0] * len(angles) if temps is None else temps
    rates = [0.0] * len(angles) if rates is None else rates
    t = np.arange(61.0)
    return concat([_run(i, t, w, c, a, 0.0)
                   for i, (a, c, w) in enumerate(zip(angles, temps, rates, strict=True))])  # fmt: skip


@pytest.mark.parametrize(
    "angles, rates, every",
    [
        ((0.0, 45.0, 90.0, 135.0), None, 2),  # each static alone at its angle
        (tuple(22.5 * i for i in range(8)), None, 4),
        ((0.0,) * 8, tuple(1.0 + i for i in range(8)), 4),  # a scale-factor plan: 8 rates
        # 20 statics, the wave angles staggered 9° between 5 temperatures: every static
        # its own 5° bin (review of 7d623b7: split 20/0, NaN gap, bias_temperature refused)
        (tuple(a + 9.0 * k for k in range(5) for a in (0.0, 45.0, 90.0, 135.0)), None, 4),
    ],
)
def test_the_split_never_holds_out_less_than_the_stride(angles, rates, every):
    """Review of 7d623b7 (finding 1): a run alone at its 5° wave-angle bin or its table
    rate was never held out, so these plans held out nothing and no effect could be
    accepted. The rule is the conditioning of the training statics'
    [1, cos 2θ, sin 2θ] (neighbouring angles count) and, for a rate, a training run where
    the stride leaves one: these strides already keep what can be kept, so the split is the
    stride's."""
    temps = [20.0 + 25.0 * (k // 4) for k in range(len(angles))]
    held = held_out_runs(_statics(angles, temps, rates), every)
    np.testing.assert_array_equal(held, np.arange(len(angles))[every - 1 :: every])


def test_the_split_keeps_the_statics_cos_2theta_and_refuses_an_empty_stride():
    """Statics at 0° and 90° only, the stride holding every 90° one: the training statics
    would not separate the damping's cos 2θ from the bias, so one 90° static is swapped
    for the next run (a 0° one, which its peers keep); a stride longer than the plan is a
    `ValueError`, not an empty held-out set."""
    data = _statics((0.0, 90.0) * 4)
    held = held_out_runs(data, 2)
    assert held.size == 4 and 1 not in held and 2 in held
    with pytest.raises(ValueError, match="every must be"):
        held_out_runs(data, 9)


def _fits(strengths, signs, pooled=1.0):
    """Per-run refits (`records.per_run_fits`) of a one-parameter effect: run i's estimate
    points `signs[i]`, its information puts the pooled value at √strengths[i] σ."""
    return [(i, np.array([s * 3.0 * pooled]), np.array([[k / pooled**2]]))
            for i, (k, s) in enumerate(zip(strengths, signs, strict=True))]  # fmt: skip


def test_the_dwell_windows_evidence_is_not_outvoted_by_three_ramps():
    """Audit finding (F1, bench2): a readout mismatch the training dwell windows see at
    p̄ᵀC p̄ ≈ 10⁶ and three ramps at ≈ 2 each (their one-effect refits take what the
    missing temperature laws leave, signs at random) was refused with agreement 0. The
    windows are one session, not a run: where they hold more of the information than the
    runs together, the check is not made (`agreement` None, the reason says so); where the
    runs hold more, the runs decide as before."""
    fits = _fits([2.0, 3.0, 2.5], [-1, -1, 1])
    alone = records.repeats(fits, np.array([1.0]))
    assert alone["agreement"] == pytest.approx(1 / 3)  # refused at 0.75
    j_w = np.full((50, 1), np.sqrt(1e6 / 50))  # the windows' whitened rows: p̄ᵀC_w p̄ = 10⁶
    out = records.repeats(fits, np.array([1.0]), windows=j_w)
    assert out["agreement"] is None and out["units"] == []
    assert "dwell windows carry it" in out["reason"]
    weak = records.repeats(fits, np.array([1.0]), windows=j_w * 1e-3)  # 1 < 7.5: the runs'
    assert weak["agreement"] == pytest.approx(1 / 3) and weak["reason"] is None
