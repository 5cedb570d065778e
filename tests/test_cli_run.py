"""How a command runs and ends: Ctrl-C anywhere stops it (exit 130), a bug is not reported as
bad input, an output that cannot be written is named; `--help` shows each default once; the
checks made before any work (demo's folder, a sweep too fast, --rotations); navigate's gaps."""

import gc
import os
import signal
import sys
import threading
import time

import numpy as np
import pytest
from helpers import cli_fails

import hrgjax as hg
from hrgjax import cli
from hrgjax.cli import main


@pytest.fixture
def python_sigint():
    """Python's own SIGINT handler for the test, as a shell gives a command: pytest-xdist's
    workers ignore SIGINT (SIG_IGN), and the command then leaves it alone, as it should."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def test_ctrl_c_in_a_gc_callback_is_raised_again_outside_it(monkeypatch):
    """Audit: Ctrl-C 5–6 s into `simulate --duration 1200` was, 2 times in 8, raised inside
    JAX's garbage-collector callback, which drops exceptions ("Exception ignored in:
    _xla_gc_callback … KeyboardInterrupt"): the run went on, wrote its file, exit 0. The
    handler raises it as Python does elsewhere, and there delivers it again a moment later."""
    handler = cli.Interrupts()
    with pytest.raises(KeyboardInterrupt):
        handler(signal.SIGINT, sys._getframe())

    def _xla_gc_callback():  # JAX's name; the handler sees this frame or one it called
        def deeper():
            return handler(signal.SIGINT, sys._getframe())

        return deeper()

    sent = []
    monkeypatch.setattr(signal, "raise_signal", sent.append)
    assert _xla_gc_callback() is None  # not raised there
    handler.timer.join(1.0)
    assert sent == [signal.SIGINT]


def test_ctrl_c_during_garbage_collection_stops_the_command(monkeypatch, capsys, python_sigint):
    """End to end: a SIGINT that lands in a gc callback (any, not only JAX's) ends the
    command with exit status 130 within the moment; Python's handler is back after."""
    fired = []

    def callback(phase, info):
        if phase == "start" and not fired:
            fired.append(phase)
            signal.raise_signal(signal.SIGINT)  # its handler runs here, inside the callback

    def work(args):
        gc.callbacks.append(callback)
        try:
            gc.collect()
            t0 = time.perf_counter()
            while time.perf_counter() - t0 < 5.0:  # the work going on: 5 s, unless stopped
                time.sleep(0.001)
            return 0
        finally:
            gc.callbacks.remove(callback)

    monkeypatch.setattr(cli, "cmd_simulate", work)
    before = signal.getsignal(signal.SIGINT)
    cli_fails(["simulate"], capsys, "interrupted", code=130)  # not run to its end (exit 0)
    assert fired
    assert signal.getsignal(signal.SIGINT) is before


def test_ctrl_c_in_a_weakref_callback_or_at_the_very_end_still_stops(
    monkeypatch, capsys, python_sigint
):
    """Review (s32): a Ctrl-C in a weakref callback (JAX's caches use them) was dropped as an
    "Exception ignored" (now `sys.unraisablehook` hands it back); one in a gc callback
    within `REDELIVER_S` of the command's end was cancelled with its timer: exit 0."""
    import weakref

    class Thing:
        pass

    def dropped(_):
        signal.raise_signal(signal.SIGINT)  # raised in the callback, which Python drops

    def weak(args):
        ref = weakref.ref(Thing(), dropped)  # noqa: F841  (the object dies at once)
        t0 = time.perf_counter()
        while time.perf_counter() - t0 < 5.0:
            time.sleep(0.001)
        return 0

    def at_end(args):
        def callback(phase, info):
            if phase == "start":
                gc.callbacks.remove(callback)
                signal.raise_signal(signal.SIGINT)

        gc.callbacks.append(callback)
        gc.collect()
        return 0  # returns before the re-delivery fires

    hook = sys.unraisablehook  # pytest's own
    for work in (weak, at_end):
        monkeypatch.setattr(cli, "cmd_simulate", work)
        cli_fails(["simulate"], capsys, "interrupted", code=130)  # not exit 0 after the work
    assert sys.unraisablehook is hook


def test_a_bug_is_an_internal_error_and_a_refusal_bad_input(monkeypatch, capsys):
    """A `TypeError` Python raises (a bug) said "error:" and exit 2, as bad input; one that
    hrgjax's checks raise (a one-line refusal) still is bad input."""

    def bug(args):
        return None + 1

    def refusal(args):
        hg.calibration.run_study(key=0, methods="mlp")  # refused: methods must be a list

    monkeypatch.setattr(cli, "cmd_simulate", bug)
    cli_fails(["simulate"], capsys, r"internal error: TypeError: unsupported operand .*report",
              code=1)  # fmt: skip
    monkeypatch.setattr(cli, "cmd_simulate", refusal)
    cli_fails(["simulate"], capsys, r"^hrgjax simulate: error: run_study: methods must be")


def test_help_shows_each_default_once():
    """Audit: `--precession … (default 0.5) (default: None)`: argparse's default added to the
    one the help states. Every help line now says "default" at most once, and a None (the
    option not given) is not shown as a default."""
    import argparse

    parser = cli.build_parser()
    subs = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, sub in subs.choices.items():
        for action in sub._actions:
            text = " ".join(cli.HelpFormatter("x")._expand_help(action).split())
            assert text.lower().count("(default") <= 1, (name, text)
        assert "(default: None)" not in sub.format_help(), name
    simulate = " ".join(subs.choices["simulate"].format_help().split())
    assert "(default 0.5; at most 9" in simulate and "(default: 0)" in simulate  # --seed


def test_an_output_that_cannot_be_written_is_refused_first_and_named(tmp_path, capsys):
    """Audit: `simulate --out /proc/x.csv` passed the folder check (root may write anywhere,
    says os.access), simulated, then failed naming the temporary file beside it. Now refused
    before the work; and a write that fails after it names the user's path."""
    from hrgjax.cli._common import finish

    if os.path.isdir("/proc/self"):
        cli_fails(["simulate", "--out", "/proc/x.csv"], capsys, r"^hrgjax simulate: error: "
                  r"--out /proc/x\.csv: cannot write in /proc \(")  # fmt: skip

    def write(path):
        name = os.path.join(os.path.dirname(path), ".x.abc123.tmp.csv")
        raise FileNotFoundError(2, "No such file or directory", name)

    with pytest.raises(OSError, match=r"^cannot write .*/x\.csv: No such file or directory$"):
        finish((str(tmp_path / "x.csv"), write))


def test_demo_keeps_files_in_a_folder_it_was_given(tmp_path, monkeypatch, capsys):
    """Audit: `demo --quick --out mydata` replaced the user's calibration.csv and
    drift_residuals.png there (exit 0). Refused before any work, as every command refuses an
    output that exists outside out/; `--force` replaces them, and out/ (`make demo`) is the
    tool's own. The demo's work is replaced: reaching it is what is checked."""
    import hrgjax.calibration as calibration

    def reached(**kw):
        raise RuntimeError("the study started")

    monkeypatch.setattr(calibration, "run_study", reached)
    monkeypatch.chdir(tmp_path)
    for folder in ("mydata", "out/demo"):
        os.makedirs(folder)
        for name in ("calibration.csv", "drift_residuals.png"):
            (tmp_path / folder / name).write_text("precious\n")
    cli_fails(["demo", "--quick", "--out", "mydata"], capsys,  # not "the study started"
              r"^hrgjax demo: error: --out mydata holds calibration\.csv, drift_residuals\.png "
              r"already \(files the demo writes\); give another folder, or --force to replace "
              r"them$")  # fmt: skip
    assert (tmp_path / "mydata" / "calibration.csv").read_text() == "precious\n"
    for argv in (["--out", "mydata", "--force"], ["--out", "out/demo"]):
        cli_fails(["demo", "--quick", *argv], capsys, "failed: the study started", code=1)


def test_demo_files_name_every_compensator_the_study_fits():
    """`demo_files` (checked before the work) names the models `run_study` writes: one per
    method, labelled as the study labels them."""
    from hrgjax.calibration.study import METHODS
    from hrgjax.cli.simulate import DEMO_MODELS, demo_files

    assert len(DEMO_MODELS) == len(METHODS)
    assert {"calibration.csv", "model_fourier_20_c.eqx", "model_mlp_end_to_end.json",
            "model_physical.json"} <= set(demo_files())  # fmt: skip


def test_too_fast_a_precession_and_too_few_rotations_are_refused_first(tmp_path, capsys):
    """Audit: `simulate --plan precession --precession 500` simulated sweeps of 0.36 s at
    1 Hz (exit 0), which self-calibrate then refuses; `design --rotations -1` was refused
    after the header and a 5-s compile."""
    out = str(tmp_path / "s.csv")
    cli_fails(["simulate", "--plan", "precession", "--precession", "500", "--out", out], capsys,
              r"--precession 500: a sweep over 180° .* would last 0\.36 s, under 20 samples at "
              r"1 Hz, fewer than self-calibrate needs; give --precession 9 °/s or less$")  # fmt: skip
    cli_fails(["design", "--budget-h", "2", "--rotations", "-1"], capsys,
              r"argument --rotations: expected a whole number ≥ 0; got -1")  # fmt: skip
    assert not os.path.exists(out)


def test_navigate_names_the_outages_it_flew_and_no_gap_as_none(tmp_path, monkeypatch, capsys):
    """Audit: `navigate short.csv` (no GNSS gap) printed `nan` in the "in gaps" column, and
    `navigate example` wrote `"outages": []` though the example has its own 60-s outage. The
    flights are replaced (their figures made up): what is printed and written is checked."""
    import json

    from hrgjax.cli.navigate import used_outages
    from hrgjax.ins import flights, motion

    example = motion.example()
    assert used_outages(example, ()) == [(1530.0, 1590.0)]
    assert used_outages(example, [(100.0, 200.0), (1500.0, 1540.0)]) == [(100.0, 200.0),
                                                                         (1500.0, 1590.0)]  # fmt: skip
    row = {"horizontal_rms_m": 1.0, "horizontal_max_m": 2.0, "final_horizontal_median_m": 1.5,
           "nees_mean": 15.0, "nees_inside_95_band": 0.9, "nees_verdict": "consistent",
           "nees_navigation_mean": 9.0, "nees_navigation_inside_95_band": 0.9,
           "nees_navigation_verdict": "consistent"}  # fmt: skip

    class Flown:
        def summary(self):
            return {"filter": dict(row), "smoother": dict(row), "free": row, "n_states": 15,
                    "nees_band_95": [10.0, 20.0], "nees_navigation_band_95": [6.0, 12.0],
                    "nis_mean": None}  # fmt: skip

    monkeypatch.setattr(flights, "fly", lambda *a, **k: Flown())
    still = motion.Motion(45.0, 30.0, 100.0, (0.0, 0.0, 0.0), 0.0, 0.0, 0.0,
                          (motion.Segment(1, (0.0,) * 3, (0.0,) * 3, 20.0, True),))  # fmt: skip
    still.to_csv(tmp_path / "still.csv")
    report = tmp_path / "nav.json"
    argv = ["navigate", str(tmp_path / "still.csv"), "--rate-hz", "10", "--json", str(report)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "nan" not in out and "(outages: none)" in out
    assert out.split("filter")[1].split()[2] == "—"  # RMS, max, in gaps, final
    assert json.loads(report.read_text())["outages"] == []
    report.unlink()
    assert main([*argv, "--outage", "5:8"]) == 0
    assert json.loads(report.read_text())["outages"] == [[5.0, 8.0]]
    assert np.isfinite(json.loads(report.read_text())["filter"]["horizontal_rms_m"])
