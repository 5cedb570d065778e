"""A temperature logged slower than the gyro and forward-filled onto its rows (step-like):
told apart from ramps, dwells and real steps, and read through its readings before the
continuous records use it. Audit 2026-11-30 (discgaps): with a 60-s hold, `discover` named
`thermal_lag`, `bias_temperature` and `frequency_split` for a hidden `thermal_rate` (the
model's Ṫ was a spike at each jump); read through its readings, `thermal_rate` at
0.0501 ± 0.0007 °/h per °C/min (0.05 hidden), as with the true temperature."""

import warnings

import jax
import numpy as np
import pytest
from helpers import SHORT_RAMPS

import hrgjax as hg
from hrgjax.discovery import NOMINAL, discover, generate
from hrgjax.discovery.continuous import ContinuousProblem
from hrgjax.units import DEG_PER_H

K_E = 0.554
T = np.arange(481.0)  # 1-s rows


def _true(t, kinks=(120.0, 360.0), temps=(10.0, 30.0)):
    """A hold, a ramp, a hold: the chamber's program, piecewise linear [°C]."""
    return np.interp(t, kinks, temps)


def _held(t, temp, hold):
    """`temp` read every `hold` s (from t = 0) and forward-filled onto every row."""
    return temp[np.searchsorted(t, np.floor(t / hold) * hold)]


def test_a_held_temperature_is_detected_and_read_through_its_readings():
    from hrgjax.discovery.thermometer import hold_interval, unheld

    # kinks on the logger's grid: the line through the readings is the program exactly
    truth = _true(T)
    stair = _held(T, truth, 30.0)
    assert np.abs(stair - truth).max() == pytest.approx(29.0 / 12.0)  # s·(h − 1 s)
    assert hold_interval(T, stair) == 30.0
    np.testing.assert_allclose(unheld(T, stair, 30.0), truth, atol=1e-12)
    # a kink between two readings, u s after the first: the chord's error is s·u(h−u)/h
    # at most, s·h/4 (s = 1/12 °C/s, h = 30 s); the held value's, s·h
    truth = _true(T, (125.0, 365.0))
    stair = _held(T, truth, 30.0)
    rec = unheld(T, stair, hold_interval(T, stair))
    slope = 20.0 / 240.0
    assert np.abs(rec - truth).max() <= slope * 30.0 / 4 + 1e-12
    assert np.abs(stair - truth).max() > 0.8 * slope * 30.0
    # a quantised slow ramp (0.1 °C steps every ~10 s): within a quantum, Ṫ right
    truth = 20.0 + 0.01 * T
    quantised = np.round(truth, 1)
    assert hold_interval(T, quantised) == pytest.approx(10.0, abs=1.0)  # 9–11 s: ties
    rec = unheld(T, quantised, hold_interval(T, quantised))
    assert np.abs(rec - truth).max() <= 0.1
    assert np.polyfit(T[20:-20], rec[20:-20], 1)[0] == pytest.approx(0.01, rel=1e-3)
    # not held: a ramp sampled at every row, a noisy one, one real step, a dwell and a
    # quantised dwell's flicker (three levels 0.1 °C apart: no move beyond two quanta)
    rng = np.random.default_rng(0)
    flicker = 20.0 + 0.1 * np.clip(np.cumsum(rng.choice([-1, 0, 0, 0, 0, 0, 1], T.size)), -1, 1)
    for temp in (_true(T), _true(T) + 0.01 * rng.standard_normal(T.size),
                 np.where(T < 240, 20.0, 30.0), np.full(T.size, 20.0), flicker):  # fmt: skip
        assert hold_interval(T, temp) is None


def _records(temperature):
    """Three still runs of 481 1-s rows sharing `temperature(t)`: the smallest continuous
    records `ContinuousProblem` takes."""
    n, runs = T.size, 3
    return hg.MeasuredData({
        "time_s": np.tile(T, runs), "run": np.repeat(np.arange(runs), n),
        "wave_angle_deg": np.zeros(n * runs), "table_rate_dps": np.zeros(n * runs),
        "temperature_c": np.tile(temperature, runs),
    })  # fmt: skip


@pytest.fixture(scope="module")
def noise():
    return generate.base_gyro().noise


def _problem(data, noise):
    return ContinuousProblem.from_data(data, [2], nominal=NOMINAL, catalogue=["thermal_rate"],
                                       k_e=K_E, noise=noise)  # fmt: skip


def test_the_continuous_records_read_a_forward_filled_temperature_through_its_readings(noise):
    truth = _true(T)
    held = _records(_held(T, truth, 30.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        problem = _problem(held, noise)
    for group in problem.train_groups + problem.held_groups:  # before: the held values
        np.testing.assert_allclose(np.asarray(group.temp), np.broadcast_to(truth, group.temp.shape),
                                   atol=1e-12)  # fmt: skip
    said = [str(w.message) for w in caught if w.category.__name__ == "HeldTemperatureWarning"]
    assert len(said) == 1 and said[0].startswith(
        "discover: temperature_c is step-like in 3 run(s) (0, 1, 2): held for 30 s between changes"
    )
    # the true temperature is taken as it is, without a word (warnings are errors here)
    problem = _problem(_records(truth), noise)
    np.testing.assert_array_equal(np.asarray(problem.train_groups[0].temp)[0], truth)


def test_a_dwell_is_left_alone():
    from hrgjax.discovery.thermometer import unhold_temperature

    data = _records(np.full(T.size, 20.0))
    assert unhold_temperature(data) is data


RAMPS = SHORT_RAMPS  # corners at 600, 800, 1000 and 1200 s


@pytest.mark.slow(
    "~50 s: a simulated log and the continuous search's programs; fast tier: the detection "
    "and reconstruction against the program's temperature, and the records built from it "
    "(the two tests above)"
)
def test_discover_names_the_thermal_rate_through_a_forward_filled_temperature():
    data = generate.continuous_dataset("thermal_rate", 0.15, key=jax.random.key(3),
                                       duration_s=1500.0, dt_out=2.0, ramps=RAMPS)  # fmt: skip
    c = {k: np.array(v) for k, v in data.columns.items()}
    for run in np.unique(c["run"]):  # the ramps' corners lie on the 40-s readings
        m = c["run"] == run
        c["temperature_c"][m] = _held(c["time_s"][m], c["temperature_c"][m], 40.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rep = discover(hg.MeasuredData(c), catalogue=["thermal_rate"])
    assert rep.missing_effect == "thermal_rate"
    user = rep.parameters["thermal_rate"]["c_Tdot"]
    assert abs(user["value"] - 0.15) < 4 * user["sigma"]  # before: 0.033 ± 0.002
    truth = -K_E * 0.15 * DEG_PER_H * 60.0
    assert rep.fit_parameters["thermal_rate"]["c_Tdot"]["value"] == pytest.approx(truth, rel=0.02)
    assert sum("held for 40 s between changes" in str(w.message) for w in caught) == 1
