"""The command line: simulate writes contract data; demo --quick makes its outputs."""

import numpy as np
import pytest
from helpers import cli_fails

import hrgjax as hg
from hrgjax.cli import main


def test_simulate_writes_loadable_csv(tmp_path, capsys):
    out = tmp_path / "static.csv"
    assert main(["simulate", "--plan", "static", "--duration", "6", "--out", str(out)]) == 0
    data = hg.load(out)
    assert len(data.run_indices()) == 11 * 19
    assert set(hg.data.REQUIRED) <= set(data.names)
    assert np.all(data["table_rate_dps"] == 0.0)
    assert str(out) in capsys.readouterr().out


@pytest.mark.slow(
    "~85 s: the whole study (five fits, an INS flight, plots, exports) is `make demo`; "
    "fast tier: each compensator's fit (test_calibration), the Fourier baseline and "
    "correction on seed data (test_calibrate_and_correct_on_user_data), exports "
    "(test_export_round_trips)"
)
def test_demo_quick_runs_the_study(tmp_path, capsys):
    from hrgjax.cli.simulate import demo_files

    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    # the files it checks before the work (refused where they exist) are those it writes
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(demo_files())
    for name in (
        "calibration.csv",
        "drift_scale_factor.png",
        "drift_residuals.png",
        "error_vs_temperature.png",
        "model_mlp.eqx",
        "model_fourier_20_c.json",
        "model_physical.json",
    ):
        assert (tmp_path / name).stat().st_size > 0
    out = capsys.readouterr().out
    assert "seed Fourier" in out and "physical" in out
    # The seed's headline: neural and physical compensation ≥ 10× better than the +20 °C
    # Fourier baseline at −40 °C (static drift error on the test grid).
    rows = {
        line.split()[0]: line.split()
        for line in out.split("static drift error")[1].split("angle error")[0].splitlines()
        if line.strip().startswith("-40")
    }
    cold = [float(x) for x in rows["-40"][1:7]]
    raw, fourier, _, mlp, _, phys = cold
    assert raw > 0.5 and fourier > 0.3
    assert fourier / mlp >= 10 and fourier / phys >= 10


def _bench_csv(tmp_path):
    out = tmp_path / "bench.csv"
    args = ["simulate", "--plan", "seed", "--quick", "--out", str(out)]
    assert main(args) == 0
    return out


def test_calibrate_and_correct_on_user_data(tmp_path, capsys):
    data_path = _bench_csv(tmp_path)
    model = tmp_path / "fourier.eqx"
    argv = ["calibrate", str(data_path), "--method", "fourier", "--temperature-degree", "2"]
    assert main(argv + ["--out", str(model)]) == 0
    assert model.exists() and (tmp_path / "fourier.json").exists()
    corrected = tmp_path / "corrected.csv"
    assert main(["correct", str(data_path), "--model", str(model), "--out", str(corrected)]) == 0
    out = hg.load(corrected, allow_extra=True)
    assert {"rate_corrected_dps", "angle_corrected_deg"} <= set(out.names)
    data = hg.load(data_path)
    assert out["wave_angle_deg"].tolist() == data["wave_angle_deg"].tolist()
    # Static runs: the drift (±1.7 °/h raw at −40 °C) is compensated down to the noise.
    residual = []
    for idx in out.run_indices():
        if np.all(data["table_rate_dps"][idx] == 0):
            t = out["time_s"][idx]
            residual.append(out["angle_corrected_deg"][idx][-1] / (t[-1] - t[0]) * 3600)
    raw_drift = hg.calibration.static_drift(data)["drift_dph"]
    assert np.sqrt(np.mean(np.square(raw_drift))) > 0.5
    assert np.sqrt(np.mean(np.square(residual))) < 0.08
    raw = capsys.readouterr().out
    assert "residual rate RMS" in raw and str(corrected) in raw


def test_calibrate_reports_missing_rotation_runs(tmp_path, capsys):
    out = tmp_path / "static.csv"
    assert main(["simulate", "--plan", "static", "--duration", "6", "--out", str(out)]) == 0
    cli_fails(["calibrate", str(out), "--method", "fourier"], capsys, "no rotation runs")
    cli_fails(["calibrate", str(out), "--method", "fourier", "--plant", "tvg3"], capsys,
              "--plant is for --method physical")  # fmt: skip


def test_calibrate_table_shows_each_temperature_once(tmp_path, capsys):
    """Runs at 2.6 °C whose temperatures differ in the last bits (a temperature column's
    arithmetic) make one row of the in-sample table, not three (issue 43)."""
    cols = {k: [] for k in ("time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg")}
    t = np.arange(0.0, 60.1, 0.1)
    for T in (2.6, np.nextafter(2.6, 3.0), 2.6 + 3e-15, 20.0):
        for angle in np.arange(-90.0, 90.0, 20.0):
            for rate in (0.0, 5.0):
                drift = 0.3 * np.sin(np.radians(2 * angle)) / 3600.0  # input rate [°/s]
                for name, x in (("time_s", t), ("run", len(cols["run"])), ("temperature_c", T),
                                ("table_rate_dps", rate),
                                ("wave_angle_deg", angle - 0.554 * (rate + drift) * t)):  # fmt: skip
                    cols[name].append(np.broadcast_to(x, t.shape))
    path = hg.MeasuredData({k: np.concatenate(v) for k, v in cols.items()}).save(
        tmp_path / "jitter.csv"
    )
    argv = ["calibrate", str(path), "--method", "fourier", "--temperature-degree", "0",
            "--out", str(tmp_path / "f.eqx")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "temperatures [2.6, 20.0] °C" in out
    table = out.split("per temperature [°/h]:")[1]
    assert table.count("+2.6 °C") == 1 and table.count("+20.0 °C") == 1


def test_calibrate_physical_prints_the_rotation_windows_residual(tmp_path, capsys, monkeypatch):
    """Audit: a 0.1 % once-per-turn table-rate ripple made the rotation windows scatter 94×
    more (0.14 → 13.2 °/h) with χ²/dof 1.000 (by construction) and only the static drift
    printed. The grey box's fit now prints its at-rest and rotation-window RMS (the fit
    replaced by one that returns those statistics: the printing is under test)."""
    from hrgjax.calibration import PhysicalCompensator, physical

    stats = {"chi2_per_dof": 1.0, "static_rms_dph": 0.0170, "moving_rms_dph": 13.2067,
             "lm_steps": 18, "n_windows": 126}  # fmt: skip
    values = np.zeros(len(physical.NAMES))
    values[list(physical.NAMES).index("k_e0")] = 0.554
    fitted = PhysicalCompensator(values=values, covariance=np.eye(values.size) * 1e-12,
                                 stats=tuple(stats.items()))  # fmt: skip
    monkeypatch.setattr(PhysicalCompensator, "fit", lambda self, *a, **k: fitted)
    cols = {k: [] for k in ("time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg")}
    t = np.arange(0.0, 60.1, 0.5)
    for T in (-40.0, 20.0, 60.0):
        for angle in (-90.0, 0.0):
            for rate in (0.0, 5.0):
                run = (len(cols["run"]), T, rate, angle - 0.554 * rate * t)
                for name, x in zip(cols, (t, *run), strict=True):
                    cols[name].append(np.broadcast_to(x, t.shape))
    path = hg.MeasuredData({k: np.concatenate(v) for k, v in cols.items()}).save(tmp_path / "b.csv")
    argv = ["calibrate", str(path), "--method", "physical", "--out", str(tmp_path / "p.eqx")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    line = "fit residual RMS [°/h]: at-rest windows 0.0170, rotation windows 13.2067 (χ²/dof 1.000"
    assert line in out


def test_correct_reports_bad_model_file(tmp_path, capsys):
    data_path = tmp_path / "d.csv"
    assert main(["simulate", "--plan", "static", "--duration", "6", "--out", str(data_path)]) == 0
    bad = tmp_path / "m.eqx"
    bad.write_text("nonsense")
    cli_fails(["correct", str(data_path), "--model", str(bad)], capsys, "not an hrgjax compensator")


@pytest.mark.slow(
    "~30 s: the dwell search on seed-quick data; fast tier: the same search on the same "
    "data shapes, asserting more "
    "(test_discovery_search::test_the_default_gyros_own_bench_data_end_near_their_floor), "
    "the report's keys and units "
    "(test_discovery_search::test_hidden_temperature_dependent_damping_is_named)"
)
def test_discover_writes_the_contract_report(tmp_path, capsys):
    data_path = _bench_csv(tmp_path)
    js, png = tmp_path / "report.json", tmp_path / "report.png"
    assert main(["discover", str(data_path), "--json", str(js), "--plot", str(png)]) == 0
    import json

    with open(js) as fh:
        report = json.load(fh)
    keys = ["missing_effect", "ranking", "gap_before", "gap_after", "noise_floor", "metric"]
    assert list(report)[:6] == keys
    # tvg3_like's pickoff gain mismatch is by far the largest thing the nominal model lacks.
    assert report["missing_effect"] == "readout_gain_mismatch"
    assert report["gap_after"] < report["gap_before"]
    # every parameter in user units, with its σ and unit (the readout mismatch in ppm)
    for params in report["parameters"].values():
        for p in params.values():
            assert set(p) == {"value", "sigma", "unit"}, p
    for r in report["ranking"]:  # a screening refit's σ is textbook, and named so
        for p in r["params"].values():
            assert set(p) == {"value", "sigma", "sigma_textbook", "unit", "why_no_sigma"}, p
    eps = report["parameters"]["readout_gain_mismatch"]["eps_1"]
    model = report["model_parameters"]["readout_gain_mismatch"]["eps_1"]
    assert eps["unit"] == "ppm" and eps["value"] == pytest.approx(1e6 * model["value"])
    assert png.stat().st_size > 0
    out = capsys.readouterr().out
    assert "missing effect: readout_gain_mismatch" in out
    assert "[readout_gain_mismatch]" in out and "ppm" in out  # the fitted model's equations


def test_python_dash_m_hrgjax_is_the_command(capsys, monkeypatch):
    """`python -m hrgjax` runs the `hrgjax` command (it was "No module named hrgjax.__main__")."""
    import runpy

    monkeypatch.setattr("sys.argv", ["hrgjax", "--help"])
    with pytest.raises(SystemExit) as exit_:
        runpy.run_module("hrgjax", run_name="__main__", alter_sys=False)
    assert exit_.value.code == 0
    assert "usage: hrgjax" in capsys.readouterr().out


def test_every_option_has_help_and_its_default_is_shown():
    """Walk every subcommand's parser (no JAX needed): each option has help text, and the
    formatter prints the defaults."""
    import argparse

    from hrgjax.cli import build_parser

    parser = build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    assert set(subs.choices) >= {"demo", "simulate", "calibrate", "correct", "discover"}
    for name, sub in subs.choices.items():
        for action in sub._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            assert action.help, f"hrgjax {name} {action.option_strings or action.dest}: no help"
        text = sub.format_help()
        assert "(default:" in text, name
        # one example, on one line, that runs the command itself
        assert f"\nexample: hrgjax {name} " in text, name
    simulate = subs.choices["simulate"].format_help()
    assert "57 static and 57 rotation runs" in " ".join(simulate.split())
    # diagnose --methods lists the methods (restated in the CLI so that --help needs no JAX)
    from hrgjax.cli import DIAGNOSIS_METHODS
    from hrgjax.diagnosis.compare import METHODS

    assert DIAGNOSIS_METHODS == METHODS
    assert all(m in " ".join(subs.choices["diagnose"].format_help().split()) for m in METHODS)
    # the design criteria's angle is the input angle of the two level gyros (x forward, y
    # right): a tilt (roll, pitch), not heading (review of cc807d6); 1/k_e of the wave angle's
    design = " ".join(subs.choices["design"].format_help().split())
    assert "input-angle (tilt) error" in design and "wave-angle error" not in design
    assert "heading" not in design


@pytest.fixture(scope="module")
def two_sessions(tmp_path_factory):
    """Closed-form calibration and test sessions (the test one with a 0.43 °/h switch-on
    bias more), a Fourier fitted by `hrgjax calibrate` on the first and the raw gyro."""
    from helpers import closed_form_session

    from hrgjax.calibration import NoCompensation, save_compensator

    folder = tmp_path_factory.mktemp("sessions")
    cal, test = folder / "cal.csv", folder / "test.csv"
    closed_form_session(0.0).save(cal)
    closed_form_session(0.43).save(test)
    fourier = folder / "fourier.eqx"
    argv = ["calibrate", str(cal), "--method", "fourier", "--harmonics", "1"]
    assert main(argv + ["--temperature-degree", "2", "--out", str(fourier), "--quiet"]) == 0
    raw = save_compensator(NoCompensation(), folder / "raw.eqx")
    return folder, test, fourier, raw


def test_compare_round_trip_equals_the_python_evaluation(two_sessions, tmp_path, capsys):
    import json
    import shutil

    from hrgjax.calibration import compare, load_compensator

    folder, test, fourier, raw = two_sessions
    again = tmp_path / "again.eqx"  # the same compensator under another name: labels differ
    shutil.copy(fourier, again)
    js, png = tmp_path / "out" / "cmp.json", tmp_path / "out" / "cmp.png"
    models = [str(fourier), str(raw), str(again)]
    capsys.readouterr()
    argv = ["compare", str(test), "--models", *models, "--json", str(js), "--plot", str(png)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert f"wrote {js}" in out and f"wrote {png}" in out and png.stat().st_size > 0
    assert "session offset with Fourier+T^2 (fourier): +0.43" in out
    with open(js, encoding="utf-8") as fh:
        report = json.load(fh)
    labels = ["Fourier+T^2 (fourier)", "raw", "Fourier+T^2 (again)"]
    assert [c["label"] for c in report["compensators"]] == labels
    assert [c["file"] for c in report["compensators"]] == models
    comps = {lab: load_compensator(p) for lab, p in zip(labels, models, strict=True)}
    ours = compare(comps, hg.load(test))
    assert report["offset_dph"]["value"] == pytest.approx(ours.offset.value_dph, rel=1e-10)
    assert report["offset_dph"]["sigma"] == pytest.approx(ours.offset.sigma_dph, rel=1e-10)
    for c in report["compensators"]:
        for key in ("static_residual_dph", "angle_error_deg", "max_angle_error_deg"):
            for by, got in (("temperature", c[key]), ("wave_angle", c["by_wave_angle"][key])):
                want = ours.figure(c["label"], key, by)
                assert list(got) == [f"{g:g}" for g in want]
                np.testing.assert_allclose(list(got.values()), list(want.values()), rtol=1e-10)
        table = ours.before_offset()[c["label"]]
        for key, got in c["before_offset"].items():
            np.testing.assert_allclose(list(got.values()), list(table[key].values()), rtol=1e-10)
    # --offset-from by file; the raw gyro's own mean rate (mean drift + bias) is then removed
    js2 = tmp_path / "raw.json"
    argv = ["compare", str(test), "--models", str(fourier), str(raw), "--offset-from", str(raw)]
    assert main(argv + ["--json", str(js2), "--no-angles"]) == 0
    with open(js2, encoding="utf-8") as fh:
        assert json.load(fh)["offset_dph"]["from"] == "raw"
    assert "by start wave angle" not in capsys.readouterr().out


def test_compare_and_correct_refuse_bad_input(two_sessions, tmp_path, capsys):
    import shutil

    folder, test, fourier, raw = two_sessions
    as_json = tmp_path / "model.json"  # a compensator file that happens to end in .json
    shutil.copy(fourier, as_json)
    base = ["compare", str(test), "--models"]
    cli_fails(base + [str(as_json), "--json", str(as_json)], capsys,
              "--json .* is also the input --models")  # fmt: skip
    cli_fails(base + [str(fourier), "--plot", str(tmp_path / "f.txt")], capsys, "--plot .*must end")
    cli_fails(base + [str(tmp_path / "no.eqx")], capsys, r"--models .*no\.eqx: no such file")
    bad = tmp_path / "bad.eqx"
    bad.write_text("nonsense")
    cli_fails(base + [str(bad)], capsys, "--models: .*not an hrgjax compensator")
    cli_fails(base + [str(fourier), str(fourier)], capsys, "--models: .* the same file")
    cli_fails(base + [str(fourier), "--offset-from", "x"], capsys, "--offset-from 'x'")
    cli_fails(["compare", str(tmp_path / "none.csv"), "--models", str(fourier)], capsys,
              "none.csv: no such file")  # fmt: skip
    cli_fails(["correct", str(test), "--model", str(fourier), "--out", str(test)], capsys,
              "--out .* is also the input DATA")  # fmt: skip
    cli_fails(["correct", str(test), "--model", str(fourier), "--plot", str(fourier)], capsys,
              "--plot .* is also the input --model")  # fmt: skip
    cli_fails(["correct", str(test), "--model", str(fourier), "--plot", str(tmp_path / "p.eqx")],
              capsys, "--plot .*must end")  # fmt: skip


def test_correct_reports_the_offset_and_draws_it(two_sessions, tmp_path, capsys):
    folder, test, fourier, raw = two_sessions
    png, out = tmp_path / "c.png", tmp_path / "c.csv"
    capsys.readouterr()
    argv = ["correct", str(test), "--model", str(fourier), "--out", str(out), "--plot", str(png)]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "residual rate RMS 0.43" in text and "(offset kept)" in text
    assert "session offset with Fourier+T^2: +0.43" in text and "seed Fourier" in text
    assert f"wrote {png}" in text and png.stat().st_size > 0 and out.exists()


def test_calibrate_refuses_k_e_outside_zero_one_and_too_few_temperatures(tmp_path, capsys):
    """Audit items 1, 3 and 7: --k-e 55.4 was taken; --temperature-degree 2 on data at two
    temperatures gave SF 0.55 at +20 °C; --method physical at one temperature a bare
    'Singular matrix'. Each is now one line, before any fit."""
    cols = {k: [] for k in ("time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg")}
    t = np.arange(0.0, 30.1, 0.5)
    for T in (-40.0, 60.0):
        for angle in (-60.0, 0.0, 60.0):
            for rate in (0.0, 5.0):
                for name, x in (("time_s", t), ("run", len(cols["run"])), ("temperature_c", T),
                                ("table_rate_dps", rate),
                                ("wave_angle_deg", angle - 0.554 * rate * t)):  # fmt: skip
                    cols[name].append(np.broadcast_to(x, t.shape))
    path = hg.MeasuredData({k: np.concatenate(v) for k, v in cols.items()}).save(
        tmp_path / "two.csv"
    )
    out = ["--out", str(tmp_path / "m.eqx")]
    cli_fails(["calibrate", str(path), "--k-e", "55.4", *out], capsys,
              r"argument --k-e: expected the electrical angular gain k_e = 2K, a number in "
              r"\(0, 1\] \(≈ 0\.554\); got 55\.4 \(a gain in percent\?")  # fmt: skip
    cli_fails(["calibrate", str(path), "--k-e", "0", *out], capsys, r"--k-e: .*got 0 \(hrgjax")
    cli_fails(["discover", str(path), "--k-e", "55.4"], capsys, r"argument --k-e: .*percent")
    cli_fails(["calibrate", str(path), "--temperature-degree", "2", *out], capsys,
              r"temperature_degree 2 needs at least 3 distinct temperatures in the calibration "
              r"data's static runs; got 2 \(-40\.0, \+60\.0 °C")  # fmt: skip
    cli_fails(["calibrate", str(path), "--method", "physical", *out], capsys,
              r"the physical model's rate bias law \(quadratic in T\) needs at least 3 distinct "
              r"temperatures in the calibration data; got 2")  # fmt: skip
    assert not (tmp_path / "m.eqx").exists()


def _tiny_session(path, **extra):
    """Two short runs at rest (a bench file that is never fitted: the commands stop before)."""
    t = np.arange(0.0, 2.0, 0.5)
    cols = {"time_s": np.tile(t, 2), "run": np.repeat([0, 1], t.size),
            "temperature_c": np.full(2 * t.size, 20.0), "table_rate_dps": np.zeros(2 * t.size),
            "wave_angle_deg": np.zeros(2 * t.size)}  # fmt: skip
    cols.update({k: np.full(2 * t.size, v) for k, v in extra.items()})
    return str(hg.MeasuredData(cols).save(path))


def test_calibrate_refuses_options_its_method_does_not_read(tmp_path, capsys):
    """Audit: `calibrate --method fourier --mode end_to_end --st-width 4` and
    `--temperature-degree` with mlp or physical were ignored, `--temperature-degree -7` meant
    the base algorithm. Each is now one line naming the option and the methods that read it."""
    data = _tiny_session(tmp_path / "bench.csv")
    base = ["calibrate", data, "--out", str(tmp_path / "m.eqx")]
    for method, option, takes in (
        ("fourier", ["--mode", "end_to_end"], "--method mlp"),
        ("fourier", ["--st-width", "4"], "--method mlp"),
        ("fourier", ["--plant", "tvg3"], "--method physical"),
        ("mlp", ["--temperature-degree", "2"], "--method fourier"),
        ("physical", ["--temperature-degree", "-1"], "--method fourier"),
        ("physical", ["--harmonics", "2"], "--method fourier"),
        ("physical", ["--seed", "0"], "--method mlp"),  # its default value, given: refused too
    ):
        cli_fails(base + ["--method", method, *option], capsys,
                  rf"^hrgjax calibrate: error: {option[0]} is for {takes}: it does not apply "
                  rf"to --method {method}$")  # fmt: skip
    cli_fails(base + ["--temperature-degree", "-7"], capsys,
              r"--temperature-degree: expected a whole number ≥ 0 .* or -1 .*; got '-7'")  # fmt: skip
    assert not (tmp_path / "m.eqx").exists()


def test_self_calibrate_refuses_sweep_options_on_mode_reversal_data(tmp_path, capsys):
    """`--harmonics` and `--out` are the sweeps' fit's: on force-to-rebalance holds (which only
    write a table) they were ignored; now refused, naming the data they apply to."""
    data = _tiny_session(tmp_path / "holds.csv", rebalance_rate_dps=0.0)
    for option in (["--harmonics", "3"], ["--out", str(tmp_path / "s.eqx")]):
        cli_fails(["self-calibrate", data, *option], capsys,
                  rf"{option[0]} is for virtual-precession sweeps .*: it does not apply to "
                  r"force-to-rebalance holds")  # fmt: skip


def test_compare_offset_from_names_a_model_file_however_written(tmp_path, capsys, monkeypatch):
    """Audit: `--offset-from ./f0.eqx` was refused when the models were given as `f0.eqx`
    (the paths were compared as strings). Now the same file is found; the command then stops
    at the missing test session, before any work."""
    from hrgjax.calibration import NoCompensation, save_compensator

    monkeypatch.chdir(tmp_path)
    save_compensator(NoCompensation(), "f0.eqx")
    save_compensator(NoCompensation(k_e=0.5), "f1.eqx")
    argv = ["compare", "none.csv", "--models", "f0.eqx", "f1.eqx", "--offset-from"]
    cli_fails(argv + ["./f0.eqx"], capsys, "none.csv: no such file")
    cli_fails(argv + [str(tmp_path / "f1.eqx")], capsys, "none.csv: no such file")
    cli_fails(argv + ["./f2.eqx"], capsys, r"--offset-from './f2.eqx': give one of the --models")


def test_allan_refuses_noise_model_options_without_fit(tmp_path, capsys):
    """Audit: `allan --sensor accelerometer --gauss-markov 1 --drift` without `--fit` or
    `--kalibr` was accepted and ignored; each is now one line naming what reads it."""
    log = tmp_path / "gyro.csv"
    rate = np.random.default_rng(0).normal(size=64)
    log.write_text("rate\n" + "\n".join(f"{v:.6f}" for v in rate) + "\n")
    base = ["allan", str(log), "--rate-hz", "10", "--column", "rate"]
    for given, option, takes, them in (
        (["--sensor", "accelerometer", "--gauss-markov", "1", "--drift"], "--gauss-markov",
         "--fit and --kalibr", "them"),
        (["--gauss-markov", "2"], "--gauss-markov", "--fit and --kalibr", "them"),  # the default
        (["--drift"], "--drift", "--fit and --kalibr", "them"),
        (["--sensor", "accelerometer"], "--sensor", "--kalibr", "it"),
        (["--fit", "--sensor", "gyroscope"], "--sensor", "--kalibr", "it"),
    ):  # fmt: skip
        cli_fails(base + given, capsys,
                  rf"^hrgjax allan: error: {option} is for {takes}: it does not apply without "
                  rf"{them}$")  # fmt: skip


def test_allan_tdev_plot_leaves_the_noise_model_out(tmp_path, capsys, monkeypatch):
    """Audit: `allan --kind tdev --fit --plot` drew the Allan-deviation model over the tdev
    points and labelled them °/h (they are °/h·s). The one printed line now says the
    figure leaves the model out, the figure is asked for without it, and the JSON and CSV
    name tdev's unit (the JSON keys as before)."""
    import json

    from hrgjax import plots

    drawn = []
    monkeypatch.setattr(plots, "allan_figure", lambda result, path, fit=None, **kw: (
        drawn.append((result.kind, result.dev_unit, fit, kw)), path)[1])  # fmt: skip
    log = tmp_path / "gyro.csv"
    rate = np.random.default_rng(0).normal(size=512)
    log.write_text("rate\n" + "\n".join(f"{v:.6f}" for v in rate) + "\n")
    js, table = tmp_path / "t.json", tmp_path / "t.csv"
    argv = ["allan", str(log), "--rate-hz", "10", "--unit", "deg/h", "--kind", "tdev", "--fit",
            "--gauss-markov", "0", "--plot", str(tmp_path / "t.png"), "--json", str(js),
            "--csv", str(table)]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert ("  (the noise model is fitted to the overlapping Allan variance; --plot leaves it "
            "out: it gives the Allan deviation, not tdev)") in out.splitlines()  # fmt: skip
    assert "tdev [°/h·s]" in out
    ((kind, unit, fit, kw),) = drawn
    assert (kind, unit) == ("tdev", "°/h·s") and "unit" not in kw  # the result's own unit
    dev = json.loads(js.read_text())["deviation"]
    assert (dev["unit"], dev["units"]["dev"]) == ("°/h", "°/h·s")
    assert table.read_text(encoding="utf-8").startswith("tau_s,m,dev [°/h·s],")
    assert main(argv[:-4] + ["--kind", "totdev"]) == 0  # totdev estimates σ(τ): drawn
    assert ("  (the noise model is fitted to the overlapping Allan variance)"
            in capsys.readouterr().out.splitlines())  # fmt: skip


def test_imu_calibrate_table_labels_fit_their_column(tmp_path, capsys):
    """Audit: the label `gyro g-sens [°/s/(m/s²)]` ran into its numbers; every row's numbers
    now start in one column."""
    import jax

    truth = hg.imu.ImuCalibration.known(gyro_bias=np.array([0.01, -0.02, 0.005]))
    data, sections = hg.imu.ferraris_session(truth, jax.random.key(0), rate_hz=20.0,
                                             repeats=2, static_s=3.0)  # fmt: skip
    log = tmp_path / "imu.csv"
    np.savetxt(log, np.concatenate([data.time[:, None], data.gyro, data.accel], axis=1),
               delimiter=",", header="t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z", comments="")  # fmt: skip
    assert main(["imu-calibrate", str(log), "--time-column", "t", "--gyro-unit", "rad/s"]) == 0
    import re

    rows = [ln for ln in capsys.readouterr().out.splitlines() if re.search(r" [+-]\d.* ± ", ln)]
    assert any(ln.lstrip().startswith("gyro g-sens [°/s/(m/s²)] ") for ln in rows), rows
    assert len({re.search(r"[+-]\d", ln).start() for ln in rows}) == 1, rows


def test_allan_time_unit_and_stamps_that_are_not_seconds(tmp_path, capsys):
    """Audit: a 100-Hz log stamped in ms (0, 10, 20, …) was read as 0.1 Hz, its ARW √1000
    too large, without a word. `--time-unit ms` reads it (τ₀ = 0.01 s, the deviation at τ₀
    that of the samples: √(mean Δy²/2)); a name in another unit (`t_ms`) and an epoch in ms
    are refused in one line naming `--time-unit`; whole-number steps above 1 are read as
    seconds (HRG drift logs at 0.1 Hz in whole seconds, epoch seconds too: review of cc807d6,
    which refused them) with one note line naming `--time-unit ms`, a name in seconds
    (`elapsed_secs`) with none; ns epoch stamps (ROS, beyond 2**53) read exactly with
    `--time-unit ns` (they were refused as rounded integers even with it)."""
    import json
    import re

    y = np.random.default_rng(0).normal(size=64)
    k = np.arange(64)

    def log(name, column, t, fmt=lambda a: repr(float(a))):
        path = tmp_path / name
        rows = (f"{fmt(a)},{v:.9f}\n" for a, v in zip(t, y, strict=True))
        path.write_text(f"{column},rate\n" + "".join(rows), encoding="utf-8")
        return str(path)

    ms = log("ms.csv", "time", 10.0 * k)
    base = ["--column", "rate", "--time-column"]
    out = tmp_path / "ms.json"
    assert main(["allan", ms, *base, "time", "--time-unit", "ms", "--json", str(out)]) == 0
    assert "64 samples at 100 Hz (0.64 s)" in capsys.readouterr().out
    dev = json.loads(out.read_text())["deviation"]
    assert dev["tau_s"][0] == pytest.approx(0.01, rel=1e-12)
    assert dev["dev"][0] == pytest.approx(np.sqrt(np.mean(np.diff(y) ** 2) / 2), rel=1e-9)
    error = r"^hrgjax allan: error: .*\.csv: "
    note = ("time column 'time' steps by 10: read as seconds, 0.1 Hz; stamps in ms? give "
            "--time-unit ms")  # fmt: skip
    for t, fmt in ((10.0 * k, lambda a: f"{a:.0f}"), (10.0 * k, lambda a: f"{a:.3f}"),
                   (1.7e9 + 10.0 * k, lambda a: f"{a:.0f}")):  # fmt: skip
        assert main(["allan", log("drift.csv", "time", t, fmt), *base, "time"]) == 0
        said = capsys.readouterr()  # the note on stderr, as align's and imu-calibrate's
        assert note in said.err and "64 samples at 0.1 Hz (640 s)" in said.out
    cli_fails(["allan", ms, *base, "time", "--rate-hz", "100"], capsys,
              error + r"--rate-hz 100 contradicts the time column's 0\.1 Hz \(stamps in ms\? "
              r"give --time-unit ms\)$")  # fmt: skip
    named = log("named.csv", "t_ms", 10.0 * k)
    cli_fails(
        ["allan", named, *base, "t_ms"],
        capsys,
        error + r"the time column 't_ms' is named in ms: give --time-unit ms",
    )
    cli_fails(
        ["allan", named, *base, "t_ms", "--time-unit", "us"],
        capsys,
        error + r"--time-unit us contradicts the time column 't_ms', named in ms$",
    )
    epoch = log("epoch.csv", "time", 1.7e12 + 2.5 * k)
    cli_fails(["allan", epoch, *base, "time"], capsys,
              error + r"time column 'time' reaches 1\.7e\+12, .* stamps in ms\? give "
              r"--time-unit ms")  # fmt: skip
    cli_fails(
        ["allan", ms, "--column", "rate", "--rate-hz", "100", "--time-unit", "ms"],
        capsys,
        r"^hrgjax allan: error: --time-unit is the unit of --time-column",
    )
    ros = log("ros.csv", "stamp", [1_700_000_000_000_000_007 + 10_000_000 * i for i in k], str)
    cli_fails(["allan", ros, *base, "stamp"], capsys,
              error + r"column 'stamp' row 0 .*too large.* give --time-unit ns\)$")  # fmt: skip
    out = tmp_path / "ros.json"
    assert main(["allan", ros, *base, "stamp", "--time-unit", "ns", "--json", str(out)]) == 0
    said = capsys.readouterr().out
    assert "64 samples at 100 Hz (0.64 s)" in said and "resampled" not in said
    dev = json.loads(out.read_text())["deviation"]
    assert dev["dev"][0] == pytest.approx(np.sqrt(np.mean(np.diff(y) ** 2) / 2), rel=1e-9)
    # seconds: said so (no note), or stamps that are not whole steps above 1 (a 0.1-Hz drift
    # log with its clock's jitter, a 1-Hz log stamped 0, 1, 2 with --time-unit s)
    jitter = 10.0 * k + np.random.default_rng(1).uniform(-1e-3, 1e-3, 64)
    one = log("one.csv", "time", 1.0 * k)
    for path, column, extra, rate in (
        (ms, "time", ["--time-unit", "s"], 0.1),
        (ms, "time", ["--rate-hz", "0.1"], 0.1),
        (log("secs.csv", "elapsed_secs", 10.0 * k), "elapsed_secs", [], 0.1),
        (log("jitter.csv", "time", jitter), "time", [], 0.1),
        (one, "time", ["--time-unit", "s"], 1.0),
    ):
        assert main(["allan", path, *base, column, *extra]) == 0
        said = capsys.readouterr()
        found = re.search(r"64 samples at (\S+) Hz", said.out)
        assert float(found[1]) == pytest.approx(rate, rel=1e-5) and "stamps in" not in said.err
    # whole stamps stepping by 1 are read as seconds (1 Hz), with the note: a 1-kHz log in
    # whole ms reads the same, and read silently its τ were 1000× too long
    assert main(["allan", one, *base, "time"]) == 0
    said = capsys.readouterr()
    assert "64 samples at 1 Hz" in said.out and "stamps in ms? give --time-unit ms" in said.err


@pytest.mark.parametrize("name, unit", [
    ("t_\u03bcs", "us"), ("t_\u00b5s", "us"), ("time [\u00b5s]", "us"), ("elapsed_secs", "s"),
    ("time_seconds", "s"), ("Seconds", "s"), ("Time (sec)", "s"), ("time_s", "s"),
    ("t_milliseconds", "ms"), ("TimeMs", "ms"), ("t_millis", "ms"), ("timeUs", "us"),
    ("t_micros", "us"), ("stamp_nsec", "ns"), ("header.stamp_nanos", "ns"),
    ("timestamp_ns", "ns"), ("ElapsedNanoseconds", "ns"), ("time", None), ("timestamp", None),
    ("stamps", None), ("gyro_dps", None), ("Time (mS)", "ms"), ("Time_mS", "ms"),
    ("t_uS", "us"), ("Time(uS)", "us"), ("Time (nS)", "ns"), ("timeS", "s"), ("TimeSec", "s"),
])  # fmt: skip
def test_allan_time_column_names_give_a_time_unit(name, unit):
    """Review of cc807d6: 't_μs' (Greek mu) matched the micro sign and returned 'μs', no
    `TIME_UNITS` key (unreadable with or without --time-unit us); elapsed_secs, Seconds,
    t_milliseconds, TimeMs, timeUs were not read as named. Review of f0f7e34: the camelCase
    split made an Arduino logger's `Time (mS)` `time (m_s)`, seconds (1000x, and
    --time-unit ms refused as contradicting it): the casefolded name is matched first."""
    from hrgjax.cli.allan import TIME_UNITS, named_time_unit

    found = named_time_unit(name)
    assert found == unit and (found is None or found in TIME_UNITS)


def test_allan_names_the_line_of_a_stamp_that_does_not_increase(tmp_path, capsys):
    """Audit: one duplicated or backward stamp was refused as "the time column 'time_s' must
    increase", naming neither line nor kind (`hg.load` names both): now the line, both
    stamps and which it is."""
    t = [f"{0.01 * i:.2f}" for i in range(40)]
    for name, i, stamp, what in (("dup.csv", 20, t[19], "a duplicate time stamp"),
                                 ("back.csv", 30, "0.05", "time goes backwards")):  # fmt: skip
        rows = list(t)
        rows[i] = stamp
        (tmp_path / name).write_text("time_s,gyro\n" + "".join(f"{s},{k % 3}\n" for k, s in
                                                               enumerate(rows)))  # fmt: skip
        cli_fails(["allan", str(tmp_path / name), "--column", "gyro", "--time-column", "time_s"],
                  capsys, rf"^hrgjax allan: error: .*{name}: line {i + 2}: {what} in 'time_s' "
                  rf"\({float(stamp)!r} after {float(t[i - 1])!r} on line {i + 1}\); the time "
                  r"column must increase$")  # fmt: skip


def test_allan_refuses_integers_a_float_would_round(tmp_path, capsys):
    """Audit: `hrgjax allan` read nanosecond stamps 1700000000000000001, …003 as one time
    ("the time column must increase"; further apart they were rounded silently). The columns
    it reads — the time column, the column named or the one it picks — are checked, naming
    the file, column, row and line; integers a float64 holds exactly, and a column it does
    not read, still load."""
    rate = np.random.default_rng(0).normal(size=64)
    log = tmp_path / "ns.csv"
    log.write_text("t_ns,t_s,rate,serial\n" + "".join(
        f"{1700000000000000001 + 2 * i},{2**60 + 256 * i},{v:.6f},{2**53 + 1}\n"
        for i, v in enumerate(rate)))  # fmt: skip
    cli_fails(["allan", str(log), "--column", "rate", "--time-column", "t_ns"], capsys,
              r"^hrgjax allan: error: .*ns.csv: column 't_ns' row 0 \(line 2\): the integer "
              r"1700000000000000001 is too large to hold exactly as a float64; write it in "
              r"scientific notation if rounding is intended \(time stamps in ns\? give "
              r"--time-unit ns\)$")  # fmt: skip
    # with --time-unit ns each stamp less the first, exact: steps of 2 ns (review of cc807d6)
    assert main(["allan", str(log), "--column", "rate", "--time-column", "t_ns",
                 "--time-unit", "ns"]) == 0  # fmt: skip
    assert "64 samples at 5e+08 Hz" in capsys.readouterr().out
    assert main(["allan", str(log), "--column", "rate", "--time-column", "t_s"]) == 0
    assert "64 samples at 0.00390625 Hz" in capsys.readouterr().out
    picked = tmp_path / "count.csv"
    picked.write_text("t,count\n" + "".join(f"{i},{2**53 + 1 + 2 * i}\n" for i in range(64)))
    cli_fails(["allan", str(picked), "--rate-hz", "10"], capsys,
              r"^hrgjax allan: error: .*count.csv: column 'count' row 0 \(line 2\): the "
              r"integer 9007199254740993 is too large")  # fmt: skip


def test_correct_prints_the_residual_by_table_azimuth(two_sessions, tmp_path, capsys):
    """F3 of the 2026-12-01 bench audit: static runs started at four table azimuths with a
    tilted gyro axis (A·cos azimuth added, A = 0.186 °/h: 1° at 45° N) showed only as a
    wave-angle pattern; `correct` now prints the residual by start azimuth and the cos/sin
    fit, which recovers A."""
    from helpers import AMPLITUDE_DPH, azimuth_session

    folder, _, fourier, _ = two_sessions
    data = azimuth_session().save(tmp_path / "az.csv")
    capsys.readouterr()
    argv = ["correct", str(data), "--model", str(fourier), "--out", str(tmp_path / "c.csv")]
    assert main(argv + ["--no-angles"]) == 0
    text = capsys.readouterr().out
    assert "static residual after the offset by start table azimuth" in text
    rows = text[text.index("by start table azimuth") :].splitlines()
    assert [r.split()[0] for r in rows[2:6]] == ["0", "90", "180", "270"]
    line = next(r for r in rows if r.strip().startswith("Fourier+T^2: c = "))
    c, sigma = (float(x) for x in line.split("c = ")[1].split(",")[0].split(" ± "))
    assert abs(c - AMPLITUDE_DPH) < 3 * sigma and "resolved at 95 %" in line
