"""Compensators on a session of their own (hrgjax.calibration.session): the offset and what
is left after it.

Oracles: a closed-form session with a known switch-on bias (no noise); the exact invariance
of the residuals under a constant rate added to compensated data; the seed's accuracy table
computed by `accuracy_table`, and after the offset by a compensator that folds the offset
into its drift (a second path)."""

import json
import math

import equinox as eqx
import numpy as np
import pytest
from helpers import closed_form_session

import hrgjax as hg
from hrgjax.calibration import (
    AbstractCompensator,
    FourierCompensator,
    NoCompensation,
    accuracy_table,
    compare,
    compare_corrected,
    corrected_run_errors,
    reduce,
    session_offset,
)
from hrgjax.units import DEG_PER_H, K_E_NOMINAL

BIAS_DPH = 0.43
"""The test session's switch-on bias against the calibration session's [°/h] (the size the
issue measured between two simulated sessions)."""


@pytest.fixture(scope="module")
def sessions():
    """(calibration session, test session with BIAS_DPH more, Fourier fitted on the first)."""
    cal = closed_form_session(0.0)
    fourier = FourierCompensator(harmonics=1, temperature_degree=2).fit(reduce(cal))
    return cal, closed_form_session(BIAS_DPH), fourier


@pytest.fixture(scope="module")
def compared(sessions):
    _, test, fourier = sessions
    return compare({"raw": NoCompensation(), "Fourier": fourier}, test, name="test")


def test_offset_is_the_duration_weighted_mean_with_its_standard_error():
    rate = np.array([0.5, 0.2, 0.3, np.nan])
    duration = np.array([100.0, 300.0, 100.0, 60.0])
    errors = {"static": np.array([True, True, True, False]), "drift_error_dph": rate,
              "duration_s": duration}  # fmt: skip
    off = session_offset(errors, "x")
    w, r = duration[:3], rate[:3]
    b = np.sum(w * r) / np.sum(w)
    assert off.value_dph == pytest.approx(0.28, rel=1e-14) == pytest.approx(b, rel=1e-14)
    sigma = math.sqrt(np.sum(w * (r - b) ** 2) / 2 / np.sum(w))  # s²/ΣT, s² = ΣT(r−b)²/(n−1)
    assert off.sigma_dph == pytest.approx(sigma, rel=1e-14) and off.n_runs == 3
    equal = session_offset({**errors, "duration_s": np.full(4, 60.0)})
    assert equal.sigma_dph == pytest.approx(np.std(r, ddof=1) / math.sqrt(3), rel=1e-14)
    one = session_offset({**errors, "static": np.array([True, False, False, False])})
    assert one.value_dph == 0.5 and math.isnan(one.sigma_dph) and "σ unknown" in str(one)
    none = session_offset({**errors, "static": np.zeros(4, bool)})
    assert not none.estimated and none.value_dph == 0.0 and "not estimated" in str(none)
    assert none.to_json()["sigma"] is None


def test_offset_recovers_the_sessions_switch_on_bias(compared):
    """The compensator fitted on the first session sees the second's bias as its offset; it
    is the one whose static runs scatter least, so the session's offset is taken with it."""
    off = compared.offset
    assert off.source == "Fourier" and off.n_runs == 18
    assert abs(off.value_dph - BIAS_DPH) < max(3 * off.sigma_dph, 2e-3), off
    # before: the bias is all the static residual; after: what the fit leaves, 100× less
    before = compared.before_offset()["Fourier"]["static_drift_dph"]
    after = compared.figure("Fourier", "static_residual_dph")
    for temp in (-40.0, 20.0, 60.0):
        assert before[temp] == pytest.approx(BIAS_DPH, rel=0.03)
        assert after[temp] < 0.01 * BIAS_DPH * 2
    # a rotation run's end-of-run error loses the offset's b·T (60 s: 0.0072°)
    e, r = compared.errors["Fourier"], compared.residuals["Fourier"]
    moving = ~e["static"]
    turned = off.value_dph / 3600 * e["duration_s"][moving]
    np.testing.assert_allclose(
        r["angle_error_deg"][moving], e["angle_error_deg"][moving] - turned, atol=1e-14
    )


def test_a_constant_rate_added_moves_the_offset_by_it_and_leaves_the_residuals(sessions):
    """Add c to the compensated rate of a corrected session (its angle gains c·(t − t₀)):
    the offset moves by exactly c, no residual after it changes; and the same through
    `correct` with raw data, where c is added to the measured wave-angle rate."""
    _, test, fourier = sessions
    c = 0.37
    corrected = fourier.correct(test)
    cols = corrected.columns
    t0 = np.concatenate([np.full(ix.size, cols["time_s"][ix[0]]) for ix in corrected.run_indices()])
    cols["angle_corrected_deg"] = cols["angle_corrected_deg"] + c / 3600 * (cols["time_s"] - t0)
    cols["rate_corrected_dps"] = cols["rate_corrected_dps"] + c / 3600
    shifted = hg.MeasuredData(cols, allow_extra=True)
    a = compare_corrected({"F": corrected})
    b = compare_corrected({"F": shifted})
    assert b.offset.value_dph - a.offset.value_dph == pytest.approx(c, abs=1e-12)
    assert b.offset.sigma_dph == pytest.approx(a.offset.sigma_dph, abs=1e-12)
    for key in ("drift_error_dph", "angle_error_deg", "max_angle_error_deg"):
        np.testing.assert_allclose(b.residuals["F"][key], a.residuals["F"][key], atol=1e-11)
    static = a.errors["F"]["static"]
    np.testing.assert_allclose(  # the errors before the offset do move (the test can fail)
        b.errors["F"]["drift_error_dph"][static] - a.errors["F"]["drift_error_dph"][static],
        c,
        atol=1e-11,
    )
    # raw data: NoCompensation's compensated rate is −θ̇/k_e,nom, so c enters exactly
    cols = test.columns
    cols["wave_angle_deg"] = cols["wave_angle_deg"] - K_E_NOMINAL * c / 3600 * (cols["time_s"])
    raw = {"raw": NoCompensation()}
    a, b = compare(raw, test), compare(raw, hg.MeasuredData(cols))
    assert b.offset.value_dph - a.offset.value_dph == pytest.approx(c, abs=1e-10)
    for key in ("static_residual_dph", "angle_error_deg"):
        for by in ("temperature", "wave_angle"):
            fa, fb = a.figure("raw", key, by), b.figure("raw", key, by)
            assert fa.keys() == fb.keys()
            np.testing.assert_allclose(list(fb.values()), list(fa.values()), rtol=1e-10)


class _Shifted(AbstractCompensator):
    """`inner` with a constant rate b taken off its compensated rate: drift D + b·SF."""

    k_e: float = eqx.field(static=True)
    inner: AbstractCompensator
    offset: float  # rad/s

    def fit(self, data, *, key=None, raw=None):
        return _Shifted(self.k_e, self.inner.fit(data, key=key, raw=raw), self.offset)

    def drift(self, theta, temperature_c):
        sf = self.inner.scale_factor(theta, temperature_c)
        return self.inner.drift(theta, temperature_c) + self.offset * sf

    def scale_factor(self, theta, temperature_c):
        return self.inner.scale_factor(theta, temperature_c)


def test_compare_equals_the_accuracy_table_before_and_after_the_offset(sessions, compared):
    _, test, fourier = sessions
    comps = {"raw": NoCompensation(), "Fourier": fourier}
    table = accuracy_table(comps, test)
    before = compared.before_offset()
    b = compared.offset.value_dph
    after = accuracy_table(
        {k: _Shifted(K_E_NOMINAL, c, b * DEG_PER_H) for k, c in comps.items()}, test
    )
    ours = {"static_drift_dph": "static_residual_dph", "angle_error_deg": "angle_error_deg",
            "max_angle_error_deg": "max_angle_error_deg"}  # fmt: skip
    for lab in comps:
        for key, mine in ours.items():
            assert table[lab][key].keys() == before[lab][key].keys()
            for temp, v in table[lab][key].items():
                assert before[lab][key][temp] == pytest.approx(v, rel=1e-10, abs=1e-12)
                got = compared.figure(lab, mine)[temp]
                assert got == pytest.approx(after[lab][key][temp], rel=1e-10, abs=1e-12)
    # per wave angle: the RMS over the temperatures of the runs started there
    e = compared.residuals["Fourier"]
    m = e["static"] & (np.abs(e["wave_angle0_deg"] + 30.0) < 2.5)
    rms = np.sqrt(np.mean(e["drift_error_dph"][m] ** 2))
    assert m.sum() == 3
    assert compared.figure("Fourier", "static_residual_dph", "wave_angle")[-30.0] == rms


def test_compensators_are_ordered_after_the_offset(compared):
    """Raw data leave the drift (≈ 1–3 °/h), the fitted Fourier what its fit misses: after
    the one offset, the better compensator is ahead at every temperature and wave angle."""
    for key in ("static_residual_dph", "angle_error_deg"):
        for by in ("temperature", "wave_angle"):
            raw = compared.figure("raw", key, by)
            fourier = compared.figure("Fourier", key, by)
            assert all(fourier[g] < 0.05 * raw[g] for g in raw), (key, by)
    merit = {lab: compared.figure_of_merit(lab) for lab in compared.labels}
    assert merit["Fourier"]["static_residual_dph"] < 0.01 * merit["raw"]["static_residual_dph"]
    # raw's own mean rate is the mean drift plus the bias: not the session's offset
    assert abs(compared.own_offsets["raw"].value_dph - compared.offset.value_dph) > 0.1


def test_json_layout_and_text(compared, sessions, tmp_path):
    path = compared.write_json(tmp_path / "c.json")
    with open(path, encoding="utf-8") as fh:
        report = json.load(fh)
    assert set(report["offset_dph"]) >= {"value", "sigma", "unit", "n_static_runs", "from"}
    assert report["offset_dph"]["unit"] == "°/h" and report["offset_dph"]["from"] == "Fourier"
    assert report["runs"] == {"static": 18, "rotation": 18}
    assert [c["label"] for c in report["compensators"]] == ["raw", "Fourier"]
    f = report["compensators"][1]
    assert f["name"] == "Fourier+T^2" and f["file"] is None
    assert list(f["static_residual_dph"]) == ["-40", "20", "60"]
    assert (
        f["static_residual_dph"]["-40"] == compared.figure("Fourier", "static_residual_dph")[-40.0]
    )
    assert list(f["by_wave_angle"]["angle_error_deg"]) == ["-90", "-60", "-30", "0", "30", "60"]
    assert set(f["before_offset"]) == {"static_drift_dph", "angle_error_deg",
                                       "max_angle_error_deg"}  # fmt: skip
    assert set(f["figure_of_merit"]) == {"static_residual_dph", "angle_error_deg"}
    assert report["seed_figures"]["static_residual_dph"]["-40"] == {"fourier": 1.28, "mlp": 0.054}
    json.dumps(report, allow_nan=False)  # no NaN: missing figures are null
    text = compared.format()
    assert "session offset with Fourier: +0.4" in text and "seed Fourier" in text
    assert "by start wave angle" in text and "all, offset kept" in text
    assert "by construction" not in text  # 18 static runs
    # one static run: the offset's source reads 0 there by construction, and the text says so
    _, test, fourier = sessions
    static = [i[0] for i in test.run_indices() if test["table_rate_dps"][i[0]] == 0.0][0]
    keep = (test.run == test.run[static]) | (test["table_rate_dps"] != 0.0)
    one = hg.MeasuredData({k: np.asarray(v)[keep] for k, v in test.columns.items()})
    one_text = compare({"Fourier": fourier, "raw": NoCompensation()}, one).format()
    assert (
        "(one static run: the offset is Fourier's mean rate on it, so Fourier's static "
        "residual is 0 by construction" in one_text
    )


def test_bad_arguments_are_refused(sessions):
    _, test, fourier = sessions
    with pytest.raises(ValueError, match="angle_corrected_deg"):
        corrected_run_errors(test)
    corrected = fourier.correct(test)
    with pytest.raises(ValueError, match="at least one"):
        compare_corrected({})
    with pytest.raises(ValueError, match="offset_from 'x'"):
        compare_corrected({"F": corrected}, offset_from="x")
    with pytest.raises(ValueError, match="angle_bin_deg"):
        compare_corrected({"F": corrected}, angle_bin_deg=0.0)
    part = hg.MeasuredData({k: v[: len(v) // 2] for k, v in corrected.columns.items()},
                           allow_extra=True)  # fmt: skip
    with pytest.raises(ValueError, match="other runs"):
        compare_corrected({"F": corrected, "G": part})


def test_another_sessions_runs_under_the_same_ids_are_refused(sessions):
    """Compensated data of two sessions numbered alike passed (only the run ids were
    compared): each run's start and end time, duration, mean temperature and wave angle at
    its start and end must be the same session's, and the first that differs is named."""
    cal, test, fourier = sessions
    corrected = fourier.correct(test)
    other_temps = fourier.correct(closed_form_session(0.0, temps=(0.0, 20.0, 40.0)), warn=False)
    with pytest.raises(ValueError, match=r"^'G': run 0 differs from that of 'F': mean "
                       r"temperature 0 °C against -40 °C \(compensated data of another "
                       r"session\? every entry must compensate the same session\)$"):  # fmt: skip
        compare_corrected({"F": corrected, "G": other_temps})
    # the same plan at another switch-on: only the wave angles tell (run 0 is static)
    with pytest.raises(ValueError, match=r"^'G': run 0 differs from that of 'F': end wave angle"):
        compare_corrected({"F": corrected, "G": fourier.correct(cal)})
    cols = dict(corrected.columns)
    cols["time_s"] = cols["time_s"] + np.where(corrected.run == 5, 100.0, 0.0)
    late = hg.MeasuredData(cols, allow_extra=True)
    with pytest.raises(ValueError, match=r"^'late': run 5 differs from that of 'F': start time "
                       r"100 s against 0 s"):  # fmt: skip
        compare_corrected({"F": corrected, "late": late})
    # the same session's rows pass, whatever each compensator made of them
    c = compare_corrected({"F": corrected, "raw": NoCompensation().correct(test)})
    assert c.labels == ("F", "raw")


def test_measured_temperatures_and_wave_angles_a_half_turn_apart_group_as_one(sessions):
    """Temperatures that jitter by 0.05 °C make one row per chamber level (not one per
    sample, all NaN: 7180 rows on the auditor's session), in `accuracy_table` as in
    `compare`; wave angles θ and θ + 180° (one state of the pattern) one group."""
    _, test, _ = sessions
    cols = dict(test.columns)
    rng = np.random.default_rng(0)
    cols["temperature_c"] = cols["temperature_c"] + 0.05 * rng.standard_normal(len(test))
    half = np.isin(test.run, np.unique(test.run)[::2])
    cols["wave_angle_deg"] = np.where(half, cols["wave_angle_deg"] + 180.0, cols["wave_angle_deg"])
    moved = hg.MeasuredData(cols)
    raw = {"raw": NoCompensation()}
    table, exact = accuracy_table(raw, moved)["raw"], accuracy_table(raw, test)["raw"]
    assert list(table["static_drift_dph"]) == [-40.0, 20.0, 60.0]
    for key in exact:  # the raw gyro's errors do not depend on T or on a half turn
        np.testing.assert_allclose(list(table[key].values()), list(exact[key].values()), rtol=1e-9)
    same = compare(raw, moved).before_offset()["raw"]
    for key in table:
        assert same[key] == pytest.approx(table[key], rel=1e-12)
    before, after = compare(raw, test), compare(raw, moved)
    assert after.wave_angles_deg == before.wave_angles_deg
    for by in ("temperature", "wave_angle"):
        got = after.figure("raw", "static_residual_dph", by=by)
        assert got == pytest.approx(before.figure("raw", "static_residual_dph", by=by), rel=1e-9)
