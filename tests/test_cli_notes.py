"""What the commands say beside their results (audit of the command line, session 32): a
wrong --k-e, options in the wrong unit, ms stamps, the library's Python names as the options
that set them, units on the diagnosis table, a capped --epochs."""

import json
import re
import warnings

import numpy as np
import pytest
from helpers import cli_fails

import hrgjax as hg
from hrgjax.cli import main


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A noise-free bench session at −40, +20, +60 °C (static and 5 °/s runs) and its static
    runs alone."""
    from helpers import closed_form_session

    folder = tmp_path_factory.mktemp("bench")
    data = closed_form_session(0.0, angles=(-60.0, 0.0, 45.0), duration_s=30.0)
    static = np.zeros(len(data), bool)
    for idx in data.run_indices():
        static[idx] = np.all(data["table_rate_dps"][idx] == 0)
    cols = {k: np.asarray(data[k])[static] for k in data.names}
    return data.save(folder / "bench.csv"), hg.MeasuredData(cols).save(folder / "static.csv")


def test_calibrate_prints_the_scale_factor_and_warns_of_a_wrong_k_e(session, tmp_path, capsys):
    """Audit: `--k-e 0.277` (K typed for 2K) fitted a scale factor of 2.0001, residuals doubled,
    exit 0 and not a word. The fitted scale factor at +20 °C is printed and, 100 % from 1,
    one stderr line names --k-e and the k_e the data imply. The residual table's temperatures
    beyond the calibrated range are marked, with no TemperatureDomainWarning (it leaked as
    two lines of Python's "…/bin/hrgjax:6: … sys.exit(main())")."""
    bench, _ = session
    out = ["--harmonics", "1", "--out", str(tmp_path / "m.eqx")]
    assert main(["calibrate", str(bench), "--k-e", "0.277", "--temperature-degree", "2", *out]) == 0
    said = capsys.readouterr()
    assert re.search(r"fitted scale factor at \+20\.0 °C: 2\.00\d+ \(mean over the wave angle; 1 "
                     r"= the rates as --k-e 0\.277 reads them\)", said.out), said.out  # fmt: skip
    (line,) = said.err.strip().splitlines()
    assert re.match(r"^hrgjax calibrate: --k-e looks wrong: fitted scale factor 2\.00\d\d, 100% "
                    r"from 1 — the data's k_e ≈ 2\.00\d\d × 0\.277 = 0\.554 .*calibrate again "
                    r"with --k-e 0\.554", line), line  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:  # the base algorithm: +20 °C only
        warnings.simplefilter("always")
        assert main(["calibrate", str(bench), *out, "--force"]) == 0
    assert not [w for w in caught if "TemperatureDomain" in w.category.__name__], caught
    said = capsys.readouterr()
    assert said.err == "" and re.search(r"scale factor at \+20\.0 °C: 1\.0000\d\d ", said.out)
    rows = said.out.split("per temperature [°/h]:")[1].splitlines()[1:4]
    assert [r.endswith("(beyond its range: extrapolated)") for r in rows] == [True, False, True]


def test_calibrate_on_static_runs_names_what_the_cli_user_can_do(session, capsys):
    _, static = session
    line = cli_fails(["calibrate", str(static), "--harmonics", "1"], capsys, "no rotation runs")
    assert "hrgjax simulate --plan rotation" in line and "rotation_plan" not in line


def test_self_calibrate_names_settle(tmp_path, capsys):
    """Audit: a sweep shorter than the settling time said `settle_s`, a Python name."""
    t = np.arange(0.0, 2.0, 0.5)
    cols = {"time_s": np.tile(t, 2), "run": np.repeat([0, 1], t.size),
            "temperature_c": np.full(2 * t.size, 20.0), "table_rate_dps": np.zeros(2 * t.size),
            "wave_angle_deg": np.zeros(2 * t.size), "precession_dps": np.full(2 * t.size, 0.5)}  # fmt: skip
    data = hg.MeasuredData(cols).save(tmp_path / "sweeps.csv")
    line = cli_fails(["self-calibrate", str(data), "--settle", "1000",
                      "--out", str(tmp_path / "s.eqx")], capsys,
                     r"after --settle 1000 s, fewer than \d+: give a --settle shorter")  # fmt: skip
    assert "settle_s" not in line


def test_allan_notes_stamps_in_ms_whose_step_is_not_whole(tmp_path, capsys):
    """Audit: a 400-Hz log stamped every 2.5 ms read as "20000 samples at 0.4 Hz" with no note
    (the note fired for whole-number steps only). A step above 1 that is a round number of ms
    now gets it, on stderr (as align's and imu-calibrate's notes); a step with a clock's
    sub-ms jitter does not. A 1-kHz log in whole ms (steps of 1) got none: it does."""
    y = np.random.default_rng(0).normal(size=64)
    for step, note in ((2.5, True), (1.25, True), (10.0, True), (2.5004321, False), (1.0, True)):
        path = tmp_path / "ms.csv"
        t = step * np.arange(64)
        path.write_text(
            "time,rate\n" + "".join(f"{float(a)!r},{v:.9f}\n" for a, v in zip(t, y, strict=True))
        )
        assert main(["allan", str(path), "--time-column", "time", "--column", "rate"]) == 0
        said = capsys.readouterr()
        assert f"64 samples at {1 / step:.6g} Hz" in said.out and "stamps in" not in said.out
        expected = (f"time column 'time' steps by {step:g}: read as seconds, {1 / step:.4g} Hz; "
                    "stamps in ms? give --time-unit ms")  # fmt: skip
        assert (expected in said.err) == note, said.err
    # what the note asks of the stamps: a 1-kHz log in whole ms (0, 1, 2, …; a dropped
    # sample's step of 2 kept) looks like ms too; stamps off the whole numbers, steps below 1
    # (seconds at 1 kHz) or a clock's jitter do not
    from hrgjax._time_units import seconds_look_like

    whole = np.arange(64.0)
    for stamps, unit in ((whole, "ms"), (np.delete(whole, 30) + 1e6, "ms"), (whole + 0.5, None),
                         (whole * 1e-3, None), (whole * 2.5, "ms"), (whole * 2.5004321, None),
                         (whole * 2e4, "us"), (whole * 2e7, "ns")):  # fmt: skip
        assert seconds_look_like(stamps) == unit, (stamps[:3], unit)


@pytest.mark.parametrize("option, match", [
    (["--velocity-noise", "10"], r"--velocity-noise 10 m/s is more than a vehicle at rest sways "
     r"\(≤ 1 m/s.*\(10 mm/s is --velocity-noise 0\.01\)$"),
    (["--arw", "30"], r"--arw 30 °/√h is beyond the plausible 8\.59 °/√h \(the option is in "
     r"°/√h: °/s/√Hz × 60 .*--relax imu_arw=LOW,HIGH, in rad/√s, widens it\)$"),
    (["--gyro-bias", "2e5"], r"--gyro-bias 200000 °/h is beyond the plausible 1\.55e\+05 °/h"),
])  # fmt: skip
def test_align_refuses_options_in_another_unit_naming_the_option(option, match, capsys):
    """Audit: `--velocity-noise 10` (mm/s meant) was read as 10 m/s; `--arw 30` was refused in
    rad/√s with the library's `×hrgjax.units.DEG_PER_SQRT_H`. Refused before the log is read,
    in the option's own unit."""
    line = cli_fails(["align", "no-such.imu", *option], capsys, match)
    assert "hrgjax.units" not in line and "rad/√s =" not in line


@pytest.fixture(scope="module")
def imu_log(tmp_path_factory):
    """A simulated Ferraris session, the gyro in rad/s."""
    import jax

    truth = hg.imu.ImuCalibration.known(gyro_bias=np.array([0.01, -0.02, 0.005]))
    data, _ = hg.imu.ferraris_session(truth, jax.random.key(0), rate_hz=20.0, repeats=1,
                                      static_s=3.0)  # fmt: skip
    log = tmp_path_factory.mktemp("imu") / "imu.csv"
    np.savetxt(log, np.concatenate([data.time[:, None], data.gyro, data.accel], axis=1),
               delimiter=",", header="t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z", comments="")  # fmt: skip
    return str(log)


@pytest.mark.parametrize("option, match", [
    ([], r"give their rows with --sections, or check --gyro-unit and --time-unit"),
    (["--gyro-unit", "rad/s", "--accel-unit", "g"], r"--accel-unit g makes the median \|accel\| "
     r".*give the file's unit"),
    (["--gyro-unit", "rad/s", "--turn-deg", "-360"], r"but --turn-deg is -360°; the turn went "
     r"the other way: give --turn-deg 360$"),
])  # fmt: skip
def test_imu_calibrate_names_the_options_not_python_parameters(imu_log, option, match, capsys):
    """Audit: a rad/s file read as deg/s said "change min_static_s / motion_threshold_dps",
    `--accel-unit g` on m/s² "pass check_units=False", a reversed turn "pass turn_deg=360"."""
    line = cli_fails(["imu-calibrate", imu_log, "--time-column", "t", *option], capsys, match)
    for name in ("min_static_s", "check_units", "turn_deg", "units["):
        assert name not in line, line


def test_discover_says_the_cli_has_no_noise_option(tmp_path, capsys, monkeypatch):
    """Audit: `discover` on records too short for the noise model ended "…or pass noise="."""
    import hrgjax.discovery

    message = (
        "the log has no still stretch for the noise model, and its runs are too short to "
        "read it from their angles (estimate: the noise model needs a stretch of at "
        "least 16 samples with the table still, e.g. a static run; or pass "
        "noise=hrgjax.Noise(...)); add static runs or pass noise=hrgjax.Noise(...)"
    )  # dwell.py's words

    def refuse(*args, **kwargs):
        raise ValueError(message)

    monkeypatch.setattr(hrgjax.discovery, "discover", refuse)
    t = np.arange(0.0, 2.0, 0.5)
    data = hg.MeasuredData({"time_s": t, "run": np.zeros(t.size), "temperature_c": t * 0 + 20,
                            "table_rate_dps": t * 0 + 5, "wave_angle_deg": -2.77 * t})  # fmt: skip
    path = data.save(tmp_path / "short.csv")
    line = cli_fails(["discover", str(path)], capsys, r"add static runs or holds \(the command "
                     r"line takes no noise model; in Python, .*noise=hrgjax\.Noise\(\.\.\.\)\) "
                     r"does\)$")  # fmt: skip
    assert line.count("noise=") == 1


def test_diagnose_gives_the_fault_sizes_their_unit(tmp_path, capsys, monkeypatch):
    """Audit: "sizes 1.5e-07–3e-07" with no unit, on screen and in the JSON (accelerometer
    faults in g, gyro faults in rad/s: hrgjax.ins.platform.Fault). The comparison is replaced
    by its result: the printing is under test."""
    from hrgjax.diagnosis import compare

    def result(scenario, **kwargs):
        sensor = "gyro_xi" if scenario == "gyro" else "accel_y"
        return {"scenario": scenario, "sensor": sensor, "thesis": "", "methods": [],
                "setup": {"fault_sizes": [1.5e-7, 3e-7], "nominal_sensor_error": 1e-7}}  # fmt: skip

    monkeypatch.setattr(compare, "compare", result)
    for scenario, unit in (("stationary", "g"), ("gyro", "rad/s")):
        out = tmp_path / f"{scenario}.json"
        assert main(["diagnose", "--scenario", scenario, "--json", str(out)]) == 0
        assert (f"sizes 1.5e-07–3e-07 {unit}, nominal sensor error 1e-07 {unit})"
                in capsys.readouterr().out)  # fmt: skip
        setup = json.loads(out.read_text())["setup"]
        assert setup["fault_sizes_unit"] == setup["nominal_sensor_error_unit"] == unit


def test_vibration_quick_says_it_caps_the_epochs(capsys, monkeypatch):
    """Audit: `vibration --quick --epochs 1000` trained 300 epochs without a word."""
    from hrgjax.fog import study

    runs = []

    def run(name, *, epochs, **kwargs):
        runs.append(epochs)
        return {"_figures": None}

    monkeypatch.setattr(study, "run", run)
    monkeypatch.setattr(study, "table", lambda result: "")
    for argv, epochs, note in ((["--quick", "--epochs", "500"], 300, True),
                               (["--quick"], 300, False), ([], 1000, False),
                               (["--quick", "--epochs", "120"], 120, False)):  # fmt: skip
        assert main(["vibration", *argv]) == 0
        err = capsys.readouterr().err
        assert runs.pop() == epochs
        assert ("--quick trains at most 300 epochs: --epochs 500 capped" in err) == note, err
