"""Files written by hrgjax read back as the object that wrote them: every value bit for bit,
None kept as None, no column dropped, and no silent float32 with JAX's float64 mode off
(audit of 2026-11-30: `load_calibration` and `load_plan` rounded to float32, a bias walk of
None came back as [0, 0], and `ImuData.save`'s temperature column was not read back)."""

import json
import pathlib

import jax
import numpy as np
import pytest

import hrgjax as hg
from hrgjax import calibration as C

try:  # a context: JAX's float32 mode (its default) for one block
    from jax import enable_x64
except ImportError:  # older JAX
    from jax.experimental import enable_x64

# a value float32 cannot hold: −40.123455 in float32
ODD = -40.123456789012344


def _calibration(bias_walk) -> hg.imu.ImuCalibration:
    """A small calibration whose every number needs float64 (no float32 rounding of them is
    exact), with a diagonal covariance."""
    rng = np.random.default_rng(7)
    eye = np.eye(3)
    return hg.imu.ImuCalibration(
        accel_matrix=jax.numpy.asarray(eye + 1e-3 * rng.standard_normal((3, 3))),
        accel_bias=jax.numpy.asarray(1e-2 * rng.standard_normal(3)),
        gyro_matrix=jax.numpy.asarray(eye + 1e-3 * rng.standard_normal((3, 3))),
        gyro_bias=jax.numpy.asarray(np.array([1.234567890123e-4, -2.3456789e-5, 7.1e-6])),
        gyro_g_sensitivity=jax.numpy.asarray(1e-5 * rng.standard_normal((3, 3))),
        covariance=jax.numpy.asarray(np.diag(1e-10 * (1 + rng.random(33)))),
        noise_std=jax.numpy.asarray(1e-4 * (1 + rng.random(6))),
        g=9.80665,
        turn_deg=(360.0, -360.0, 360.0),
        sigma_source="white noise",
        bias_walk=bias_walk,
    )


def _same(a, b) -> None:
    """`a` and `b` are the same pytree (static fields included) with bit-identical leaves."""
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        x, y = np.asarray(x), np.asarray(y)
        assert x.dtype == y.dtype == np.float64
        np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("walk", [None, np.array([2.5e-5, 3.1e-4])], ids=["none", "measured"])
def test_imu_calibration_round_trip_bit_for_bit(tmp_path, walk):
    cal = _calibration(None if walk is None else jax.numpy.asarray(walk))
    back = hg.imu.load_calibration(cal.save(tmp_path / "cal.json"))
    _same(cal, back)
    assert (back.bias_walk is None) == (walk is None)
    doc = json.loads((tmp_path / "cal.json").read_text())
    if walk is None:
        assert doc["bias_walk"] is None  # null, not a measured zero walk


def test_imu_calibration_old_files_keep_their_bias_walk(tmp_path):
    doc = _calibration(None).to_json()
    doc["bias_walk"] = {"gyro_rad_s_per_sqrt_s": 0.0, "accel_m_s2_per_sqrt_s": 0.0}
    (tmp_path / "zero.json").write_text(json.dumps(doc))
    np.testing.assert_array_equal(hg.imu.load_calibration(tmp_path / "zero.json").bias_walk, 0.0)
    del doc["bias_walk"]  # written before the field existed: none measured
    (tmp_path / "absent.json").write_text(json.dumps(doc))
    assert hg.imu.load_calibration(tmp_path / "absent.json").bias_walk is None


def test_imu_calibration_loader_refuses_float32_mode(tmp_path):
    path = _calibration(None).save(tmp_path / "cal.json")
    with enable_x64(False):
        with pytest.raises(RuntimeError, match="load_calibration.*float64") as err:
            hg.imu.load_calibration(path)
    assert "\n" not in str(err.value)


def _plan() -> C.BenchPlan:
    return C.BenchPlan.from_segments([
        {"kind": "static", "temperature_c": ODD, "wave_angle_deg": 0.1 + 0.2, "duration_s": 180.1},
        {"kind": "ramp", "temperature_start_c": ODD, "temperature_end_c": 20.000000000000004,
         "wave_angle_deg": 30.0, "duration_s": 6000.000000000001},
    ])  # fmt: skip


def test_plan_round_trip_with_float64_off(tmp_path):
    path = C.save_plan(_plan(), tmp_path / "plan.json")  # written in float64
    with enable_x64(False):  # JAX's default: read (and written again) in float32 mode
        plan, bench = C.load_plan(path)
        again = C.save_plan(plan, tmp_path / "again.json", bench)
    assert float(np.asarray(plan.temperature_c)[0]) == ODD  # not float32's −40.123455
    first, second = (
        json.loads(p.read_text()) for p in (tmp_path / "plan.json", tmp_path / "again.json")
    )
    # `bench_time_h` is computed (in float32 here), for the reader; the plan is the data
    assert second.pop("bench_time_h") == pytest.approx(first.pop("bench_time_h"), rel=1e-6)
    assert second == first
    _same(plan, _plan())
    back, _ = C.load_plan(again)  # float64 on: device arrays, the same values
    _same(back, plan)
    with pytest.raises(ValueError, match="read-only"):  # as a device array's view: checked
        np.asarray(plan.duration_s)[0] = -400.0


def _record(temperature: bool) -> hg.imu.ImuData:
    n = 50
    rng = np.random.default_rng(3)
    t = np.arange(n) / 100.0 + 1e-9 * rng.random(n)
    gyro = 1e-4 * rng.standard_normal((n, 3))
    accel = np.array([0.0, 0.0, 9.80665]) + 1e-3 * rng.standard_normal((n, 3))
    temp = np.linspace(20.0, 25.0, n) + 1e-12 * rng.random(n) if temperature else None
    return hg.imu.ImuData(t, gyro, accel, temp, 100.0)


@pytest.mark.parametrize("temperature", [True, False], ids=["temperature", "none"])
def test_imu_data_documented_reload_is_the_same_record(tmp_path, temperature):
    data = _record(temperature)
    path = data.save(tmp_path / "log.csv")
    back = hg.imu.load(path, columns=hg.imu.SI_COLUMNS, units=hg.imu.SI_UNITS)
    for name in ("time", "gyro", "accel"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name))
    assert back.rate_hz == data.rate_hz
    if temperature:
        np.testing.assert_array_equal(back.temperature, data.temperature)
    else:
        assert back.temperature is None


def test_imu_data_reload_can_leave_the_temperature_out(tmp_path):
    path = _record(True).save(tmp_path / "log.csv")
    columns = {**hg.imu.SI_COLUMNS, "temperature": None}
    assert hg.imu.load(path, columns=columns, units=hg.imu.SI_UNITS).temperature is None
    columns = {**hg.imu.SI_COLUMNS, "temperature": "temperature_c"}  # the old, explicit recipe
    assert hg.imu.load(path, columns=columns, units=hg.imu.SI_UNITS).temperature is not None


def test_imu_data_other_files_temperature_column_stays_unread(tmp_path):
    """Only a file `ImuData.save` wrote (its `# rate_hz` line) gives its temperature unasked:
    another file with the SI column names and a `temperature_c` the caller did not ask for
    (NaN where the sensor was off) loads as before, without it."""
    data = _record(True)
    lines = pathlib.Path(data.save(tmp_path / "log.csv")).read_text(encoding="utf-8").splitlines()
    header = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    rows = [line.rsplit(",", 1)[0] + ",nan" for line in lines[header + 1 :]]
    other = tmp_path / "other.csv"
    other.write_text("\n".join([lines[header], *rows]) + "\n")
    back = hg.imu.load(other, columns=hg.imu.SI_COLUMNS, units=hg.imu.SI_UNITS, rate_hz=100.0)
    assert back.temperature is None
    np.testing.assert_array_equal(back.gyro, data.gyro)
