"""The command line: simulate writes contract data; demo --quick makes its outputs."""

import numpy as np

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


def test_demo_quick(tmp_path):
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    for name in ("static.csv", "rotation.csv", "drift_scale_factor.png"):
        assert (tmp_path / name).stat().st_size > 0
    drift = hg.calibration.static_drift(hg.load(tmp_path / "static.csv"))
    cold = drift["drift_dph"][drift["temperature_c"] == -40.0]
    hot = drift["drift_dph"][drift["temperature_c"] == 60.0]
    assert np.ptp(cold) > 3 * np.ptp(hot)
