"""The command line's outputs: a file the user names, or one written beside it, that exists
is refused before any work unless `--force`; `out/` (every default output's folder) is the
tool's own. And what `simulate` says before it works."""

import time

import numpy as np
import pytest
from helpers import cli_fails

import hrgjax as hg
from hrgjax.cli import COMMANDS, main

PRECIOUS = "precious\n"
REFUSED = r"exists; give .*another path, or --force to replace it$"

# (command line, the output option to point at an existing file): every command that writes
# files the user names; the inputs need not exist, since outputs are checked first
NAMED_OUTPUTS = [
    (["simulate", "--duration", "5"], "--out", "csv"),
    (["design", "--budget-h", "2"], "--out", "json"),
    (["design", "--budget-h", "2"], "--plot", "png"),
    (["calibrate", "DATA.csv", "--method", "fourier"], "--out", "eqx"),
    (["calibrate", "DATA.csv"], "--json", "json"),
    (["correct", "DATA.csv", "--model", "m.eqx"], "--out", "csv"),
    (["correct", "DATA.csv", "--model", "m.eqx"], "--json", "json"),
    (["correct", "DATA.csv", "--model", "m.eqx"], "--plot", "png"),
    (["compare", "DATA.csv", "--models", "m.eqx"], "--json", "json"),
    (["compare", "DATA.csv", "--models", "m.eqx"], "--plot", "png"),
    (["discover", "DATA.csv"], "--json", "json"),
    (["discover", "DATA.csv"], "--plot", "png"),
    (["align", "log.imu"], "--json", "json"),
    (["align", "log.imu"], "--plot", "png"),
    (["diagnose"], "--json", "json"),
    (["diagnose"], "--plot", "png"),
    (["vibration"], "--json", "json"),
    (["vibration"], "--plot", "png"),
    (["navigate", "example"], "--json", "json"),
    (["navigate", "example"], "--plot", "png"),
    (["imu-calibrate", "log.csv"], "--json", "json"),
    (["imu-calibrate", "log.csv"], "--plot", "png"),
    (["imu-calibrate", "log.csv"], "--write-sections", "json"),
    (["allan", "log.csv"], "--json", "json"),
    (["allan", "log.csv"], "--csv", "csv"),
    (["allan", "log.csv"], "--plot", "png"),
    (["allan", "log.csv", "--unit", "deg/h"], "--kalibr", "yaml"),
]


@pytest.mark.parametrize(("argv", "option", "ext"), NAMED_OUTPUTS,
                         ids=[f"{a[0]} {o}" for a, o, _ in NAMED_OUTPUTS])  # fmt: skip
def test_an_existing_output_file_is_refused_before_any_work(argv, option, ext, tmp_path,
                                                            monkeypatch, capsys):  # fmt: skip
    """Audit: `simulate --out mine.csv`, `calibrate --out m2.eqx`, `correct --out corr.csv`
    replaced the user's existing file (exit status 0). Now one line naming the option, the
    file and --force, in well under a second (no input read, nothing simulated)."""
    monkeypatch.chdir(tmp_path)
    mine = tmp_path / f"mine.{ext}"
    mine.write_text(PRECIOUS)
    t0 = time.perf_counter()
    cli_fails([*argv, option, mine.name], capsys,
              rf"^hrgjax {argv[0]}: error: {option} mine\.{ext} {REFUSED}")  # fmt: skip
    assert time.perf_counter() - t0 < 10.0  # refused at the start, not after the work
    assert mine.read_text() == PRECIOUS


@pytest.mark.parametrize("command", ["calibrate", "self-calibrate"])
def test_the_json_written_beside_the_model_is_kept_too(command, tmp_path, monkeypatch, capsys):
    """Audit: `calibrate --out m3.eqx` wrote m3.json beside it over the user's m3.json, a
    file never named. Now refused, naming it and the --out it follows; `--force` goes on
    (to the data file, absent here)."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m3.json").write_text(PRECIOUS)
    data = "DATA.csv"
    if command == "self-calibrate":  # it reads the data first: sweeps at rest
        t = np.arange(0.0, 4.0)
        data = hg.MeasuredData({"time_s": t, "run": np.zeros(4), "temperature_c": np.full(4, 20.0),
                                "table_rate_dps": np.zeros(4), "wave_angle_deg": np.zeros(4),
                                "precession_dps": np.full(4, 0.5)}).save(tmp_path / "s.csv")  # fmt: skip
    cli_fails([command, str(data), "--out", "m3.eqx"], capsys,
              r"--json m3\.json \(written beside --out m3\.eqx\) exists; give --json another "
              r"path, or --force to replace it$")  # fmt: skip
    assert (tmp_path / "m3.json").read_text() == PRECIOUS
    assert not (tmp_path / "m3.eqx").exists()
    if command == "calibrate":
        cli_fails([command, data, "--out", "m3.eqx", "--force"], capsys, "DATA.csv: no such file")


def _log(path):
    rate = np.random.default_rng(0).normal(size=256)
    path.write_text("rate\n" + "".join(f"{v:.6f}\n" for v in rate))
    return str(path)


def test_force_replaces_and_out_is_the_tools_own(tmp_path, monkeypatch, capsys):
    """`--force` replaces a file that exists; a file in ./out/ (where every default output
    goes, and the docs' examples write) is replaced without it, so an example runs twice."""
    monkeypatch.chdir(tmp_path)
    log = _log(tmp_path / "gyro.csv")
    mine = tmp_path / "mine.json"
    mine.write_text(PRECIOUS)
    cli_fails(["allan", log, "--rate-hz", "10", "--json", str(mine)], capsys, REFUSED)
    assert main(["allan", log, "--rate-hz", "10", "--json", str(mine), "--force"]) == 0
    assert '"deviation"' in mine.read_text()
    (tmp_path / "out").mkdir()
    again = tmp_path / "out" / "allan.json"
    again.write_text(PRECIOUS)
    for _ in range(2):
        assert main(["allan", log, "--rate-hz", "10", "--json", "out/allan.json"]) == 0
        assert '"deviation"' in again.read_text()
    # a link in out/ to a file elsewhere is not the tool's: the file it names is the user's
    mine.write_text(PRECIOUS)
    (tmp_path / "out" / "link.json").symlink_to(mine)
    cli_fails(["allan", log, "--rate-hz", "10", "--json", "out/link.json"], capsys, REFUSED)
    assert mine.read_text() == PRECIOUS


def test_every_command_that_names_its_files_takes_force(capsys):
    """`--force` on every command, `demo` too (its files, in its --out folder, have names
    it chooses, but the folder is the user's: test_cli_run)."""
    for command in COMMANDS:
        with pytest.raises(SystemExit):
            main([command, "--help"])
        text = capsys.readouterr().out
        assert "--force" in text, command


def test_simulate_plan_file_names_a_folder(tmp_path, capsys):
    """Audit: `--plan-file DIR` said "no such file"."""
    cli_fails(["simulate", "--plan-file", str(tmp_path), "--out", str(tmp_path / "d.csv")],
              capsys, r"--plan-file .* is a folder; give a plan file")  # fmt: skip


def test_simulate_says_what_it_runs_before_it_runs(tmp_path, monkeypatch, capsys):
    """Audit: `simulate --plan rotation` printed its header, then nothing for ~15 s (the
    first call compiling) before "simulated 209 runs". A line says it before the work."""
    import hrgjax.calibration as cal

    said = []

    def run_plan(gyro, plan, **kw):  # the work, replaced: what was printed when it started
        said.append(capsys.readouterr().out)
        t = np.arange(3.0)
        return hg.MeasuredData({"time_s": t, "run": np.zeros(3), "temperature_c": np.full(3, 20.0),
                                "table_rate_dps": np.zeros(3), "wave_angle_deg": np.zeros(3)})  # fmt: skip

    monkeypatch.setattr(cal, "run_plan", run_plan)
    argv = ["simulate", "--plan", "rotation", "--duration", "5", "--out", str(tmp_path / "r.csv")]
    assert main(argv) == 0
    assert "simulating 209 runs × 5 s … (compiling the simulator first" in said[0]


def test_each_plan_kind_draws_its_own_noise_from_one_seed(tmp_path, monkeypatch):
    """`--plan static` and `--plan rotation` with one `--seed` are one switch-on (the same
    run-bias key) but not one noise realisation (they drew the same key, sample for sample);
    `--plan seed` draws its static and rotation halves from the single plans' keys."""
    import jax

    from hrgjax import calibration as cal

    keys = []

    def run_plan(gyro, plan, *, key, bias_key, **kw):  # the work, replaced: the keys it got
        keys.append((plan.size, jax.random.key_data(key), jax.random.key_data(bias_key)))
        t, run = np.arange(3.0), np.full(3, float(kw.get("first_run", 0)))
        return hg.MeasuredData({"time_s": t, "run": run, "temperature_c": np.full(3, 20.0),
                                "table_rate_dps": np.zeros(3), "wave_angle_deg": np.zeros(3)})  # fmt: skip

    monkeypatch.setattr(cal, "run_plan", run_plan)
    for plan in ("static", "rotation", "seed"):
        argv = ["simulate", "--plan", plan, "--seed", "3", "--out", str(tmp_path / f"{plan}.csv")]
        assert main(argv) == 0
    (_, k_static, b_static), (_, k_rot, b_rot), (_, k_s1, b_s1), (_, k_s2, b_s2) = keys
    assert not np.array_equal(k_static, k_rot)
    np.testing.assert_array_equal(b_static, b_rot)
    np.testing.assert_array_equal(k_s1, k_static)
    np.testing.assert_array_equal(k_s2, k_rot)
    np.testing.assert_array_equal(b_s1, b_static)
