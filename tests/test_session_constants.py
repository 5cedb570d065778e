"""What a second-session comparison must not lose (audit of `compare` across switch-ons):

- two compensators of equal quality calibrated on different switch-ons carry different
  constants; one offset for both charged the difference to one ("better, p = 1e-34"). The
  verdict is now taken after each one's own offset and the reports say so;
- the calibrated temperature range and the samples outside it travel with the comparison
  (`domains`, `to_json`, `format`, `plot`) and `correct` / `compare` warn;
- `hrgjax calibrate --method mlp --window S` records `window_s = S`.

Oracles: closed-form sessions with a known switch-on bias and a white rate noise drawn here;
the own-offset paired test recomputed by hand from the per-run errors; the out-of-range
samples counted from the session's own temperatures."""

import functools
import json

import numpy as np
import pytest
from helpers import closed_form_session

import hrgjax as hg
from hrgjax.calibration import (
    FourierCompensator,
    TemperatureDomainWarning,
    compare,
    paired_difference,
    reduce,
)
from hrgjax.units import K_E_NOMINAL

SWITCH_ON_DPH = (0.0, 0.25, 0.43)
"""Switch-on biases [°/h] of calibration A, calibration B and the test session."""
RATE_NOISE_DPH = 0.02
"""White rate noise [°/h] of a 60-s run's mean rate (the size of the seed sessions' scatter)."""


def _noisy(data, seed):
    """`data` with white rate noise: an angle random walk added to the wave angle of every run,
    each run's mean rate scattering by about RATE_NOISE_DPH."""
    rng = np.random.default_rng(seed)
    cols = data.columns
    theta = cols["wave_angle_deg"].copy()
    for idx in data.run_indices():
        span = cols["time_s"][idx][-1] - cols["time_s"][idx][0]
        step = RATE_NOISE_DPH / 3600.0 * span / np.sqrt(idx.size - 1) * K_E_NOMINAL  # [°]
        theta[idx] += np.concatenate([[0.0], np.cumsum(rng.normal(0.0, step, idx.size - 1))])
    cols["wave_angle_deg"] = theta
    return hg.MeasuredData(cols)


@pytest.fixture(scope="module")
def switch_ons():
    """(Fourier from switch-on A, the same from switch-on B, the test session)."""
    fit = lambda bias, seed: FourierCompensator(harmonics=1, temperature_degree=2).fit(
        reduce(_noisy(closed_form_session(bias), seed))
    )
    a, b, test = SWITCH_ON_DPH
    return fit(a, 1), fit(b, 2), _noisy(closed_form_session(test), 3)


@pytest.fixture(scope="module")
def compared(switch_ons):
    fa, fb, test = switch_ons
    return compare({"A": fa, "B": fb}, test)


def test_equal_compensators_from_two_switch_ons_are_not_told_apart(compared):
    c = compared
    # the verdict: equal quality, not told apart (one offset for both said one better, p = 9e-14)
    got = c.paired("A", "B")
    assert got.verdict == "none" and got.p_value > 0.2, str(got)
    # each after its own offset, recomputed by hand from the per-run errors
    e = {lab: c.errors[lab]["drift_error_dph"] - c.own_offsets[lab].value_dph for lab in "AB"}
    hand = paired_difference(e["A"], e["B"])
    assert got.mean == pytest.approx(hand.mean, rel=1e-9) and got.verdict == hand.verdict
    # own offsets: the test bias less each calibration's; they differ by b_B − b_A
    d = c.offset_difference("A", "B")
    assert d.value_dph == pytest.approx(SWITCH_ON_DPH[1] - SWITCH_ON_DPH[0], abs=0.02)
    assert d.differ and d.p_value < 1e-10 and c.offsets_for("A", "B") == "own"
    # one offset for both (the old verdict) charges 0.25 °/h to one of them, confidently
    one = c.paired("A", "B", offsets="session")
    assert one.verdict != "none" and one.p_value < 1e-10


def test_the_verdict_does_not_hang_on_offset_from(switch_ons):
    fa, fb, test = switch_ons
    verdicts = {compare({"A": fa, "B": fb}, test, offset_from=src).paired("A", "B").statement()
                for src in ("A", "B")}  # fmt: skip
    old = {compare({"A": fa, "B": fb}, test, offset_from=src).paired("A", "B", offsets="session")
           .verdict for src in ("A", "B")}  # fmt: skip
    assert verdicts == {"A and B not told apart at 95 %"} and old == {"a", "b"}


def test_reports_say_the_constants_differ(compared):
    report = json.loads(json.dumps(compared.to_json()))
    (diff,) = report["offset_differences"]
    assert diff["differ"] is True and diff["unit"] == "°/h"
    static = [p for p in report["paired"] if p["key"] == "static_residual_dph"]
    assert static[0]["offsets"] == "own" and static[0]["verdict"] == "none"
    assert static[0]["with_one_offset"]["verdict"] != "none"
    text = compared.format()
    assert (
        "the compensators carry different constants (calibrated on different switch-ons?)" in text
    )
    assert "A and B not told apart at 95 %" in text and "all, own offset" in text


def test_same_constants_keep_the_one_offset(switch_ons):
    fa, _, test = switch_ons
    c = compare({"A": fa, "A2": fa}, test)
    assert not c.offset_difference("A", "A2").differ and c.offsets_for("A", "A2") == "session"
    assert "different constants" not in c.format() and "all, own offset" not in c.format()


@pytest.fixture(scope="module")
def narrow(switch_ons):
    """A Fourier fitted on −40 and +20 °C only; the test session reaches +60 °C."""
    cal = closed_form_session(0.0, temps=(-40.0, 20.0))
    return FourierCompensator(harmonics=1, temperature_degree=1).fit(reduce(cal))


def test_samples_outside_the_range_travel_with_the_comparison(narrow, switch_ons, tmp_path):
    test = switch_ons[2]
    hot = np.abs(test["temperature_c"] - 60.0) < 1e-9  # independent: the session's own levels
    with pytest.warns(TemperatureDomainWarning, match=rf"^FourierCompensator.correct: "
                      rf"{hot.sum()} of {len(test)} samples outside the calibrated temperature "
                      r"range -40\.0 … \+20\.0 °C"):  # fmt: skip
        out = narrow.correct(test)
    assert out.n_out_of_range == hot.sum()
    with pytest.warns(TemperatureDomainWarning, match=rf"^compare: F: {hot.sum()} samples "):
        c = compare({"F": narrow}, test)
    dom = c.to_json()["compensators"][0]["temperature_domain"]
    assert dom["calibrated_range_c"] == [-40.0, 20.0] and dom["extrapolated"] is True
    assert dom["n_out_of_range"] == hot.sum() and dom["out_of_range_by_temperature"] == {
        "60": int(hot.sum())}  # fmt: skip
    assert dom["runs_out_of_range"] == sorted(set(test.run[hot].tolist()))
    assert c.groups_out_of_range("F") == {60.0}
    text = c.format()
    assert f"F: {hot.sum()} samples outside the calibrated temperature range" in text
    assert "(*: runs outside the calibrated range)" in text
    assert c.plot(tmp_path / "c.png") == str(tmp_path / "c.png")


def test_cli_mlp_records_its_window(switch_ons, tmp_path, monkeypatch):
    import hrgjax.calibration as cal
    from hrgjax.cli import main

    monkeypatch.setattr(cal, "MLPCompensator", functools.partial(cal.MLPCompensator, steps=5))
    path = closed_form_session(0.0, temps=(-40.0, 20.0), duration_s=20.0).save(tmp_path / "c.csv")
    out = str(tmp_path / "m.eqx")
    assert main(["calibrate", path, "--method", "mlp", "--window", "6", "--out", out]) == 0
    assert cal.load_compensator(out).window_s == 6.0
