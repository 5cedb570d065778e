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

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import closed_form_session

import hrgjax as hg
from hrgjax.calibration import (
    AbstractCompensator,
    FourierCompensator,
    TemperatureDomainWarning,
    compare,
    compare_corrected,
    paired_difference,
    reduce,
)
from hrgjax.calibration.compensators import Corrected, NoCompensation
from hrgjax.calibration.evaluate import SEED_TABLE, accuracy_table, format_table, out_of_range
from hrgjax.calibration.paired import constant_resolution, offset_difference
from hrgjax.units import DEG, DEG_PER_H, K_E_NOMINAL

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
    # the verdict: equal quality, not told apart beyond the constant whose owner this session
    # cannot name (one offset for both said one better, p = 9e-14)
    got = c.paired("A", "B")
    assert got.verdict == "none" and got.p_value > 0.2, str(got)
    assert got.offsets == "own" and got.beyond_constant
    assert got.statement().startswith("A and B not told apart beyond a constant at 95 % (their "
                                      "constants differ by +0.2")  # fmt: skip
    assert got.statement().endswith("°/h; this session cannot assign it)")
    # each after its own offset, recomputed by hand from the per-run errors
    e = {lab: c.errors[lab]["drift_error_dph"] - c.own_offsets[lab].value_dph for lab in "AB"}
    hand = paired_difference(e["A"], e["B"])
    assert got.mean == pytest.approx(hand.mean, rel=1e-9) and got.verdict == hand.verdict
    # own offsets: the test bias less each calibration's; they differ by b_B − b_A, far
    # beyond the size a constant needs to decide the paired test alone
    d = c.offset_difference("A", "B")
    assert d.value_dph == pytest.approx(SWITCH_ON_DPH[1] - SWITCH_ON_DPH[0], abs=0.02)
    assert d.differ and abs(d.value_dph) > 5 * d.resolution_dph
    assert c.offsets_for("A", "B") == "own"
    # one offset for both (the old verdict) charges 0.25 °/h to one of them, confidently
    one = c.paired("A", "B", offsets="session")
    assert one.verdict != "none" and one.p_value < 1e-10


def test_reports_say_the_constants_differ(compared):
    report = json.loads(json.dumps(compared.to_json()))
    diffs = report["offset_differences"]
    assert [d["key"] for d in diffs] == ["static_residual_dph", "angle_error_deg"]
    for d in diffs:
        assert d["differ"] is True and d["unit"] == "°/h" and d["resolution"] > 0
        assert "p_value" not in d and "sigma" not in d  # no sampling test: the noise cancels
    static = [p for p in report["paired"] if p["key"] == "static_residual_dph"]
    assert static[0]["offsets"] == "own" and static[0]["verdict"] == "none"
    assert static[0]["constants_differ"] is True
    assert static[0]["with_one_offset"]["verdict"] != "none"
    text = compared.format()
    assert (
        "the compensators carry different constants (calibrated on different switch-ons?)" in text
    )
    assert "A and B not told apart beyond a constant at 95 %" in text and "all, own offset" in text
    assert "p = 9e" not in text and "differ at 95 %" not in text


def test_a_named_offset_decides_the_verdict(switch_ons):
    """`offset_from` named: the user says whose constant is right, so the pair is judged
    after that one offset (the other carries the 0.25 °/h difference: the named one
    better), and the reports say so."""
    fa, fb, test = switch_ons
    verdicts = {}
    for src in ("A", "B"):
        c = compare({"A": fa, "B": fb}, test, offset_from=src)
        got = c.paired("A", "B")
        one = c.paired("A", "B", offsets="session")
        assert got.offsets == "session" and got.verdict == one.verdict and got.p_value < 1e-10
        assert got.constants.differ and not got.beyond_constant
        report = c.to_json()
        assert report["offset_from"] == src and report["paired"][0]["constants_differ"] is True
        assert f"the offset is {src}'s, as named" in c.format()
        verdicts[src] = got.verdict
    assert verdicts == {"A": "a", "B": "b"}
    assert compare({"A": fa, "B": fb}, test).to_json()["offset_from"] is None


def _shifted(corrected, c_dph):
    """`corrected` with a pure constant c [°/h] taken off its compensated rate and angle."""
    cols = corrected.columns
    cols["rate_corrected_dps"] = cols["rate_corrected_dps"] - c_dph / 3600.0
    angle = cols["angle_corrected_deg"].copy()
    for idx in corrected.run_indices():
        t = cols["time_s"][idx]
        angle[idx] -= c_dph / 3600.0 * (t - t[0])
    cols["angle_corrected_deg"] = angle
    return Corrected(cols, in_range=corrected.in_range, temperature_range=None, margin_c=1.0,
                     extrapolated=True)  # fmt: skip


def test_a_real_constant_error_is_not_called_equal(switch_ons):
    """A against A with a constant error of 0.1 °/h (one calibration switch-on): after each
    one's own offset their residuals are identical, and the headline must not say plainly
    "not told apart" (5ad5c77 did): it says so beyond a constant, and names the constants'
    difference, which this session cannot assign."""
    fa, _, test = switch_ons
    base = fa.correct(test)
    c = compare_corrected({"A": base, "Ac": _shifted(base, 0.1)})
    for key in ("static_residual_dph", "angle_error_deg"):
        got = c.paired("A", "Ac", key)
        assert got.beyond_constant and got.constants.value_dph == pytest.approx(0.1, abs=1e-9)
        assert "not told apart beyond a constant at 95 % (their constants differ by +0.1000 °/h" \
            in got.statement()  # fmt: skip
        entry = got.to_json()
        assert entry["constants_differ"] is True and entry["offsets"] == "own"
        assert entry["constant_difference_dph"] == pytest.approx(0.1, abs=1e-9)
    assert c.paired("A", "Ac", offsets="session").verdict != "none"  # one offset: decided


def _first_change(pair, level=0.95):
    """Independent truth: the smallest c > 0 at which scipy's paired t test of `pair(c)`
    (two arrays of squared residuals) gives another verdict than at c = 0 (a grid scan of
    the verdict, then brentq on the p-value)."""
    from scipy import optimize, stats

    def verdict(c):
        r = stats.ttest_rel(*pair(c))
        return int(np.sign(r.statistic)) if r.pvalue < 1.0 - level else 0

    grid = np.geomspace(1e-7, 10.0, 400)
    hit = np.flatnonzero([verdict(c) != verdict(0.0) for c in grid])
    assert hit.size and hit[0] > 0
    f = lambda c: stats.ttest_rel(*pair(c)).pvalue - (1.0 - level)
    return optimize.brentq(f, grid[hit[0] - 1], grid[hit[0]], xtol=1e-15, rtol=1e-13)


def _charged(ea, eb, w, s):
    """The truth for a difference of sign `s`: A shifted by +s·c or B by −s·c [°/h]."""
    return min(_first_change(lambda c: ((ea + s * c * w) ** 2, eb**2)),
               _first_change(lambda c: (ea**2, (eb - s * c * w) ** 2)))  # fmt: skip


def test_the_resolution_is_where_a_constant_alone_decides_the_paired_test():
    """R is the constant at which scipy's paired t test, one compensator shifted by R w,
    first changes its verdict at 95 %: static runs of zero-mean residual (R = 2 t s / sqrt n),
    angle residuals that keep a rotation run's mean rate residual (a constant of that sign
    decides at 1/20 of the other's, 0.0023 against 0.045 °/h; the closed form off the static
    case said 0.023 for both: 10x the one), and a real pair. `differ` is the test at Δ."""
    from scipy import stats

    rng = np.random.default_rng(5)
    for n in (10, 57):
        e = rng.normal(0.0, 0.025, n)
        e -= e.mean()  # after its own offset (equal runs)
        r = constant_resolution(e, e + 0.0)
        assert r == pytest.approx(2 * stats.t.ppf(0.975, n - 1) * e.std(ddof=1) / np.sqrt(n))
        assert r == pytest.approx(_charged(e, e, np.ones(n), 1.0), rel=1e-9)
        for factor, decided in ((1.0 + 1e-6, True), (1.0 - 1e-6, False)):
            p = stats.ttest_rel(e**2, (e + factor * r) ** 2).pvalue
            assert (p < 0.05) == decided, (n, factor, p)
    # angle residuals [°] after the static-run offset: a mean rate residual of 0.01 °/h kept
    n = 30
    w = rng.uniform(60.0, 300.0, n) / 3600.0  # a constant of 1 °/h shifts run i by T_i/3600 [°]
    x = rng.normal(0.0, 0.025, n)
    e = w * (x - x.mean() + 0.01)
    # B = −A: B shifted by −c is A shifted by +c, so only the difference's sign counts
    truth = {s: _first_change(lambda c, s=s: ((e + s * c * w) ** 2, e**2)) for s in (1.0, -1.0)}
    assert truth[1.0] < 0.2 * truth[-1.0]  # the sign of the mean residual decides far sooner
    assert constant_resolution(e, e, w) == pytest.approx(truth[1.0], rel=1e-9)
    for s in (1.0, -1.0):
        assert constant_resolution(e, -e, w, difference=s) == pytest.approx(truth[s], rel=1e-9)
    # a real pair: B scatters more, its own mean rate residual of the other sign
    y = rng.normal(0.0, 0.04, n)
    eb = w * (y - y.mean() - 0.005)
    for s in (1.0, -1.0):
        want = _charged(e, eb, w, s)
        assert constant_resolution(e, eb, w, difference=s) == pytest.approx(want, rel=1e-9)
        # `differ` is the verdict's change at Δ itself: just beyond the threshold, not below
        for factor in (1.0 + 1e-6, 1.0 - 1e-6):
            delta = s * factor * want
            d = offset_difference("A", delta, "B", 0.0, e, eb, w, key="angle_error_deg")
            assert d.differ == (factor > 1.0), (s, factor, str(d))


def test_the_level_states_the_offset_choice(switch_ons):
    """A constant between the 95 % and the 99 % resolutions decides the 95 % test but not
    the 99 %: the choice follows the test's level, and the result says which it used."""
    fa, _, test = switch_ons
    base = fa.correct(test)
    e = compare_corrected({"A": base}).own_residuals_of("A")["drift_error_dph"]
    r95, r99 = (constant_resolution(e, e, level=q) for q in (0.95, 0.99))
    c = compare_corrected({"A": base, "Ac": _shifted(base, 0.5 * (r95 + r99))})
    p95, p99 = c.paired("A", "Ac"), c.paired("A", "Ac", level=0.99)
    assert (p95.offsets, p99.offsets) == ("own", "session")
    assert p95.constants.level == 0.95 and p99.constants.level == 0.99
    assert p99.verdict == "none" and "beyond a constant" not in p99.statement()


def test_same_constants_keep_the_one_offset(switch_ons):
    """Two calibrations from one switch-on (independent noise): constants equal within
    what could decide the paired test, so the one offset; the pair is a real pair."""
    fa, _, test = switch_ons
    fa2 = FourierCompensator(harmonics=1, temperature_degree=2).fit(
        reduce(_noisy(closed_form_session(SWITCH_ON_DPH[0]), 4))
    )
    c = compare({"A": fa, "A2": fa2}, test)
    d = c.offset_difference("A", "A2")
    assert 1e-4 < abs(d.value_dph) < d.resolution_dph and not d.differ
    assert c.offsets_for("A", "A2") == "session" and c.paired("A", "A2").offsets == "session"
    assert "different constants" not in c.format() and "all, own offset" not in c.format()


class _Law(AbstractCompensator):
    """The closed-form session's own laws (tests/helpers.py `session_drift`,
    `session_scale_factor`, in jnp) with a known error added to the drift [°/h]:
    `const` + `a`·cos 2θ + `s`·sin 2θ."""

    k_e: float = eqx.field(static=True, default=K_E_NOMINAL)
    const: float = 0.0
    a: float = 0.0
    s: float = 0.0

    def fit(self, data, *, key=None, raw=None):
        return self

    def drift(self, theta, temperature_c):
        dt = temperature_c - 20.0
        amp = 1.5 * DEG_PER_H * jnp.exp(-0.016 * dt)
        law = (0.3 + 0.005 * dt) * DEG_PER_H - amp * jnp.sin(2 * (theta - (25.0 + 0.16 * dt) * DEG))
        err = self.const + self.a * jnp.cos(2 * theta) + self.s * jnp.sin(2 * theta)
        return law + err * DEG_PER_H

    def scale_factor(self, theta, temperature_c):
        return 1.0 - 2 * (0.0046 - 9.6e-5 * (temperature_c - 20.0)) * jnp.cos(2 * theta)


def test_a_third_compensator_does_not_decide_a_pair():
    """A leaves 0.02 cos 2θ °/h, B more; C leaves nothing but carries +0.2 °/h, so its static
    runs scatter least and the session's offset is C's. A and B agree on their constant:
    judged after C's offset (before: both carry C's 0.2 °/h) "A better" (p = 4e-4) read
    "not told apart" (p = 0.72). Judged after the pair's own offset, the verdict and p-value
    are those of A and B alone, bit for bit; with `offset_from="C"` named, C's as asked."""
    test = _noisy(closed_form_session(SWITCH_ON_DPH[2]), 0)
    comps = {"A": _Law(a=0.02), "B": _Law(a=0.03, s=0.01), "C": _Law(const=0.2)}
    corrected = {lab: comp.correct(test) for lab, comp in comps.items()}
    two = compare_corrected({lab: corrected[lab] for lab in "AB"})
    three = compare_corrected(corrected)
    assert two.offset.source == "A" and three.offset.source == "C"
    assert not three.offset_difference("A", "B").differ
    alone, got = two.paired("A", "B"), three.paired("A", "B")
    assert alone.verdict == "a" and alone.p_value < 1e-3 and alone.offsets == "session"
    assert (got.verdict, got.p_value, got.mean, got.rms_a, got.rms_b) == (
        alone.verdict, alone.p_value, alone.mean, alone.rms_a, alone.rms_b)  # fmt: skip
    assert three.offsets_for("A", "B") == "pair" and three.pair_offset_from("A", "B") == "A"
    assert (got.offsets, got.offset_source) == ("pair", "A")
    # after A's own offset, recomputed by hand from the per-run errors
    b = three.own_offsets["A"].value_dph
    e = {lab: three.errors[lab]["drift_error_dph"] - b for lab in "AB"}
    assert got.mean == pytest.approx(paired_difference(e["A"], e["B"]).mean, rel=1e-9)
    old = three.paired("A", "B", offsets="session")  # C's offset: the old verdict
    assert old.verdict == "none" and old.p_value > 0.5 and old.offset_source == "C"
    named = compare_corrected(corrected, offset_from="C")
    kept = named.paired("A", "B")
    assert (kept.offsets, kept.verdict, kept.p_value) == ("session", "none", old.p_value)
    # the pairs with C keep the session's offset (C's) or their own (constants 0.2 apart)
    assert {three.offsets_for("A", "C"), three.offsets_for("B", "C")} <= {"session", "own"}
    # the reports show the residuals the verdict used and name the offset
    report = json.loads(json.dumps(three.to_json(), allow_nan=False))
    entry = next(p for p in report["paired"] if (p["a"], p["b"], p["key"]) == (
        "A", "B", "static_residual_dph"))  # fmt: skip
    assert (entry["offsets"], entry["offset_source"], entry["verdict"]) == ("pair", "A", "a")
    assert entry["with_one_offset"]["verdict"] == "none"
    assert entry["with_one_offset"]["offset_source"] == "C"
    text = three.format(by_wave_angle=False)
    row = next(line for line in text.splitlines() if line.strip().startswith("all, A's offset"))
    cells = [float(x) for x in row.split()[3:]]
    assert cells[:2] == pytest.approx([got.rms_a, got.rms_b], rel=1e-3)
    assert "(after A's offset, the pair's: row 'all, A's offset'; with the session's, C's: " \
        "'A and B not told apart at 95 %'" in text  # fmt: skip
    assert "all, A's offset" not in named.format(by_wave_angle=False)


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


def test_the_warning_points_at_the_callers_line_and_warn_false_silences_it(narrow, switch_ons):
    import inspect
    import warnings

    test = switch_ons[2]
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        line = inspect.currentframe().f_lineno + 1
        narrow.correct(test)
        compare({"F": narrow}, test)
    assert [(w.category, w.filename, w.lineno) for w in seen] == [
        (TemperatureDomainWarning, __file__, line), (TemperatureDomainWarning, __file__, line + 1)]  # fmt: skip
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # anything said is a failure
        out = narrow.correct(test, warn=False)
        c = compare({"F": narrow}, test, warn=False)
        table = accuracy_table({"F": narrow}, test, warn=False)
    hot = np.abs(test["temperature_c"] - 60.0) < 1e-9
    assert out.n_out_of_range == hot.sum() and c.domains["F"]["n_out_of_range"] == hot.sum()
    assert set(table["F"]["static_drift_dph"]) == {-40.0, 20.0, 60.0}
    with pytest.raises(ValueError, match=r"^warn must be True or False; got 'no'$"):
        narrow.correct(test, warn="no")


def test_a_study_records_what_it_extrapolates(narrow, switch_ons):
    """`run_study` applies the +20 °C baseline at −40/+60 °C on purpose: the record
    (`out_of_range`, printed under `format_table`) counts the session's own samples."""
    test = switch_ons[2]
    rec = out_of_range({"F": narrow, "raw": NoCompensation()}, test["temperature_c"])
    hot = np.abs(test["temperature_c"] - 60.0) < 1e-9
    assert rec["F"] == {"calibrated_range_c": [-40.0, 20.0], "n_samples": len(test),
                        "n_out_of_range": int(hot.sum()), "extrapolated": True,
                        "temperatures_c": [60.0]}  # fmt: skip
    assert rec["raw"]["calibrated_range_c"] is None and rec["raw"]["n_out_of_range"] == 0
    text = format_table(accuracy_table({"F": narrow}, test, warn=False), domains=rec)
    assert (f"F: calibrated -40.0 … +20.0 °C, extrapolated on {hot.sum()} of {len(test)} test "
            "samples (+60 °C)") in text  # fmt: skip


def test_plots_session_figure_is_still_there(compared, tmp_path):
    from hrgjax.plots import session_figure

    path = str(tmp_path / "s.png")
    assert session_figure(compared, path, seed=SEED_TABLE) == path
    assert session_figure(compared, str(tmp_path / "t.png")) == str(tmp_path / "t.png")
