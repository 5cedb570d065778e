"""Measured-data contract: round trips and validation."""

import numpy as np
import pytest

import hrgjax as hg


def table(n=5, **extra):
    cols = {
        "time_s": np.arange(n) * 0.1,
        "run": np.zeros(n, dtype=int),
        "temperature_c": np.full(n, 20.0),
        "table_rate_dps": np.full(n, 5.0),
        "wave_angle_deg": np.linspace(0, 1, n) * np.pi,
    }
    cols.update(extra)
    return cols


@pytest.fixture(scope="module")
def record():
    gyro = hg.presets.tvg3_like()
    prof = hg.Profile.constant_rate(5.0, 2.0, temperature_c=-10.0, wave_angle0_deg=12.5)
    import jax

    return hg.simulate(gyro, prof, key=jax.random.key(3), dt_out=0.1)


@pytest.mark.parametrize("ext", ["csv", "nc"])
def test_round_trip_exact(record, tmp_path, ext):
    if ext == "nc":
        pytest.importorskip(
            "h5netcdf", reason="netCDF needs the data extra: pip install hrgjax[data]"
        )
    data = record.to_data()
    path = data.save(tmp_path / f"run.{ext}")
    back = hg.load(path)
    assert back == data
    for k in data.names:
        assert np.array_equal(back[k], data[k]), k


def test_record_units(record):
    data = record.to_data()
    np.testing.assert_allclose(data["wave_angle_deg"], np.rad2deg(record.wave_angle))
    np.testing.assert_allclose(data["table_rate_dps"], 5.0)
    np.testing.assert_allclose(data["table_angle_deg"], 5.0 * np.asarray(record.t))
    assert set(hg.data.REQUIRED) <= set(data.names)


def test_absent_optional_columns_are_derived_not_added():
    cols = table()
    del cols["run"]
    d = hg.MeasuredData(cols)
    assert "run" not in d.names and "table_angle_deg" not in d.names
    np.testing.assert_array_equal(d.run, 0)
    np.testing.assert_allclose(d.table_angle_deg, 5.0 * np.arange(5) * 0.1)


def test_runs_may_restart_time():
    cols = table(6)
    cols["run"] = np.array([0, 0, 0, 1, 1, 1])
    cols["time_s"] = np.array([0.0, 1.0, 2.0, 0.0, 1.0, 2.0])
    d = hg.MeasuredData(cols)
    assert [len(r) for r in d.runs()] == [3, 3]


def test_input_arrays_not_altered():
    cols = table()
    before = {k: v.copy() for k, v in cols.items()}
    hg.MeasuredData(cols)
    for k in cols:
        assert np.array_equal(cols[k], before[k])


BAD = [
    ("missing", lambda c: c.pop("wave_angle_deg"), "wave_angle_deg"),
    ("unknown", lambda c: c.update(wave_angel_deg=np.zeros(5)), "wave_angel_deg"),
    ("nan", lambda c: c["temperature_c"].__setitem__(3, np.nan), "temperature_c.*row 3"),
    ("inf", lambda c: c["table_rate_dps"].__setitem__(1, np.inf), "table_rate_dps.*row 1"),
    ("unsorted", lambda c: c["time_s"].__setitem__(2, 0.05), "time_s.*row 2"),
    ("duplicate", lambda c: c["time_s"].__setitem__(2, 0.1), "time_s.*row 2"),
    ("length", lambda c: c.update(temperature_c=np.zeros(4)), "temperature_c.*4 rows"),
    ("run-float", lambda c: c.update(run=np.array([0, 0, 0.5, 1, 1])), "run.*integers"),
    ("2d", lambda c: c.update(amplitude=np.zeros((5, 2))), "amplitude.*1-D"),
]


@pytest.mark.parametrize("name,mutate,match", BAD, ids=[b[0] for b in BAD])
def test_bad_data_named(name, mutate, match):
    cols = {k: np.array(v, dtype=float) for k, v in table().items()}
    mutate(cols)
    with pytest.raises(ValueError, match=match):
        hg.MeasuredData(cols)


def test_extra_columns_allowed_when_asked():
    d = hg.MeasuredData(table(note=np.zeros(5)), allow_extra=True)
    assert "note" in d.names


@pytest.mark.parametrize("name", ["", "  ", " note", "note ", "x\t"])
def test_column_names_a_csv_header_would_change_are_refused(name, tmp_path):
    """The CSV reader strips a header's blanks: a name it would change (or find empty) is
    refused where the data are made, not after a save that does not read back."""
    import re

    with pytest.raises(ValueError, match=f"^column name {re.escape(repr(name))} (is empty|begins)"):
        hg.MeasuredData(table(**{name: np.zeros(5)}), allow_extra=True)
    d = hg.MeasuredData(table(**{"x": np.zeros(5), "x y": np.ones(5)}), allow_extra=True)
    assert hg.load(d.save(tmp_path / "n.csv"), allow_extra=True) == d


def test_csv_errors(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("time_s,temperature_c,table_rate_dps,wave_angle_deg\n0,20,5,abc\n")
    with pytest.raises(ValueError, match="wave_angle_deg.*row 0"):
        hg.load(p)
    with pytest.raises(ValueError, match="extension"):
        hg.load(tmp_path / "x.txt")


def test_stacked_runs_in_si():
    """`stacked` groups runs by (length, interval), in SI, each row the dataset's own."""
    rng = np.random.default_rng(3)
    # runs 7 and 2 interleaved (same length and interval), run 5 longer, run 9 as long as 7
    # but at a different interval: three stacks
    t7, t2, t5, t9 = np.arange(6.0), np.arange(6.0) + 100, np.arange(8.0), np.arange(6.0) * 0.1
    run = np.r_[[7, 2] * 6, [5] * 8, [9] * 6]
    t = np.r_[np.ravel(np.c_[t7, t2]), t5, t9]
    rate = np.r_[np.zeros(12), np.full(8, 2.0), np.full(6, -1.0)]
    data = hg.MeasuredData(
        {
            "time_s": t,
            "run": run,
            "temperature_c": rng.normal(20, 5, t.size),
            "table_rate_dps": rate,
            # turning at −k_e × the table, as a wave does (MeasuredData checks the units)
            "wave_angle_deg": 30
            + np.r_[np.zeros(12), -0.554 * 2.0 * t5, 0.554 * t9]
            + rng.normal(0, 0.1, t.size),
            "accel_z_g": rng.normal(1, 0.1, t.size),
        }  # fmt: skip
    )
    before = {k: v.copy() for k, v in data.columns.items()}
    stacks = data.stacked()
    assert [s.run.tolist() for s in stacks] == [[9], [7, 2], [5]]  # by length, then interval
    assert [s.dt for s in stacks] == pytest.approx([0.1, 1.0, 1.0])
    assert [s.static.tolist() for s in stacks] == [[False], [True, True], [False]]
    for s in stacks:
        for i, r in enumerate(s.run):
            idx = np.flatnonzero(data.run == r)
            np.testing.assert_array_equal(s.rows[i], idx)
            np.testing.assert_array_equal(s.t[i], data["time_s"][idx])
            np.testing.assert_allclose(s.wave_angle[i], np.deg2rad(data["wave_angle_deg"][idx]))
            np.testing.assert_allclose(s.rate[i], np.deg2rad(rate[idx]))
            # the reference angle since the run's start: the trapezoid of the rate
            np.testing.assert_allclose(
                s.table_angle[i], np.deg2rad(rate[idx][0]) * (t[idx] - t[idx][0])
            )
            np.testing.assert_array_equal(s.accel[i, :, 2], data["accel_z_g"][idx])
            assert not s.accel[i, :, :2].any()  # absent axes read 0
            np.testing.assert_array_equal(s.amplitude[i], 1.0)
        with pytest.raises(ValueError, match="read-only"):
            s.t[0, 0] = 1.0
    for k, v in before.items():
        np.testing.assert_array_equal(data.columns[k], v)


def test_stacked_pools_runs_whose_intervals_differ_by_their_jitter_only():
    """Logged stamps jitter: runs whose median intervals agree within 1e-5 or within 3× their
    own jitter (robust scatter of their steps, at most 1 %) share one interval — one stack per
    length, the same `dt` across lengths, short runs too (9 samples: their medians scatter by
    about the jitter) — each keeping its own stamps; a clean run 2 % off and a run at 0.1 s
    stay apart."""
    rng = np.random.default_rng(5)
    runs, times = [], []
    # (samples, interval [s], jitter rms [s]) of runs 0–7
    plan = [(121, 0.5, 1e-6), (121, 0.5, 1e-4), (121, 0.5, 1e-3), (121, 0.5, 0.0),
            (121, 0.5 + 4e-6, 0.0), (241, 0.5, 1e-4), (121, 0.51, 0.0), (121, 0.1, 1e-4),
            (9, 0.5, 1e-3), (9, 0.5, 1e-3), (9, 0.5, 1e-3)]  # fmt: skip
    for r, (n, dt, jitter) in enumerate(plan):
        times.append(100.0 * r + dt * np.arange(n) + jitter * rng.standard_normal(n))
        runs.append(np.full(n, r))
    t = np.concatenate(times)
    data = hg.MeasuredData(
        {
            "time_s": t,
            "run": np.concatenate(runs),
            "temperature_c": np.full(t.size, 20.0),
            "table_rate_dps": np.zeros(t.size),
            "wave_angle_deg": np.full(t.size, 30.0),
        }
    )
    stacks = data.stacked()
    assert [s.run.tolist() for s in stacks] == [[8, 9, 10], [7], [0, 1, 2, 3, 4], [6], [5]]
    assert stacks[0].dt == stacks[2].dt == stacks[4].dt == pytest.approx(0.5, abs=1e-5)
    assert stacks[3].dt == pytest.approx(0.51, rel=1e-12)
    assert stacks[1].dt == pytest.approx(0.1, abs=1e-4)
    for s in stacks:
        np.testing.assert_array_equal(s.t, t[s.rows])  # the runs' own stamps


def _two_runs(n=41):
    """A static run 0 and a rotation run 1 at 5 °/s over 20 s, as columns."""
    t = np.arange(n) * 0.5
    table = 5.0 * t
    return {
        "time_s": np.r_[t, t],
        "run": np.r_[np.zeros(n, int), np.ones(n, int)],
        "temperature_c": np.full(2 * n, 20.0),
        "table_rate_dps": np.r_[np.zeros(n), np.full(n, 5.0)],
        "table_angle_deg": np.r_[np.zeros(n), table],
        "wave_angle_deg": np.r_[np.full(n, 10.0), 10.0 - 0.554 * table],
    }


def test_runs_are_checked_once_with_the_dataset():
    """Audit (s30): `runs()` rebuilt and re-checked every run, so data loaded inside
    `plausible.relaxed(temperature_c=…)` failed in `reduce` outside the block, naming
    "index 0" (the row in the run). A dataset is checked once; its runs are its rows."""
    from hrgjax import calibration as cal

    cols = _two_runs() | {"temperature_c": np.full(82, -150.0)}
    with hg.plausible.relaxed(temperature_c=(-200.0, 200.0)):
        d = hg.MeasuredData(cols)
    runs = list(d.runs())  # outside the block
    assert [r.run[0] for r in runs] == [0, 1]
    np.testing.assert_array_equal(runs[1]["table_angle_deg"], cols["table_angle_deg"][41:])
    with pytest.raises(ValueError, match="read-only"):
        runs[0]["temperature_c"][0] = 0.0
    w = cal.reduce(d, window_s=5.0)
    np.testing.assert_allclose(w.temperature_c, -150.0)
    second = d.select(d.run == 1)  # a subset, as a mixed log's dwell runs: not re-checked
    np.testing.assert_array_equal(second["time_s"], cols["time_s"][41:])
    np.testing.assert_array_equal(d.select(np.arange(3))["run"], [0, 0, 0])
    for bad in (np.ones(5, bool), [5, 0], [3, 3], np.zeros(len(d), bool), [[0, 1], [2, 3]],
                [0.0, 1.0], [-1], [len(d)]):  # fmt: skip
        with pytest.raises(ValueError, match=r"^MeasuredData.select: rows must be a boolean "
                           r"mask of shape \(82,\) or increasing sample indices"):  # fmt: skip
            d.select(bad)
    with pytest.raises(ValueError, match=r"temperature_c' = -150 at index 0 "):
        hg.MeasuredData(cols)  # the range is back


def test_a_column_replaced_within_its_span_is_not_range_checked_again():
    """`discover` interpolates a held thermometer's readings (`unhold_temperature`); it
    rebuilt the dataset, so data loaded inside `plausible.relaxed(temperature_c=…)` was
    refused outside the block ("-120 at index 0 is outside … -100 … 150 °C")."""
    from hrgjax.discovery.thermometer import unhold_temperature

    t = np.arange(0.0, 60.0, 0.1)
    cols = {"time_s": t, "temperature_c": -120.0 + np.floor(t / 10.0) * 0.05,
            "table_rate_dps": np.zeros_like(t), "wave_angle_deg": np.zeros_like(t)}  # fmt: skip
    with hg.plausible.relaxed(temperature_c=(-200.0, 200.0)):
        d = hg.MeasuredData(cols)
    with pytest.warns(hg.discovery.thermometer.HeldTemperatureWarning):
        out = unhold_temperature(d)  # outside the block
    temp = out["temperature_c"]
    assert temp.min() == cols["temperature_c"].min() and temp.max() == temp[-1]
    assert np.all(np.diff(temp) >= 0) and np.unique(temp).size > 100  # interpolated, not held
    np.testing.assert_array_equal(d["temperature_c"], cols["temperature_c"])  # d kept
    with pytest.raises(ValueError, match=r"temperature_c' = -130 at index 0 .*-100 … 150"):
        d.with_column("temperature_c", cols["temperature_c"] - 10.0)  # beyond its span
    with pytest.raises(ValueError, match=r"^MeasuredData.with_column: temperature_c must be one "
                       r"value per row \(600 rows\); got shape \(5,\)"):  # fmt: skip
        d.with_column("temperature_c", np.zeros(5))
    with pytest.raises(KeyError, match="no column 'accel_x_g'"):
        d.with_column("accel_x_g", np.zeros(len(d)))
    with pytest.raises(ValueError, match=r"wave_angle_deg.*(finite|NaN)"):
        d.with_column("wave_angle_deg", np.full(len(d), np.nan))
    # the same for the noise model read from a rotation-only log's angles (it said "runs too
    # short to read it", quoting the range error)
    from hrgjax.discovery.dwell import turning_noise_model

    rng, t = np.random.default_rng(0), np.arange(0.0, 60.0, 0.01)
    runs = [{"time_s": t, "temperature_c": np.full(t.size, -120.0), "run": np.full(t.size, r),
             "table_rate_dps": np.full(t.size, w), "wave_angle_deg": -0.554 * w * t
             + 1e-5 * rng.standard_normal(t.size).cumsum()} for r, w in enumerate((10.0, -20.0))]  # fmt: skip
    with hg.plausible.relaxed(temperature_c=(-200.0, 200.0)):
        turning = hg.MeasuredData({k: np.concatenate([r[k] for r in runs]) for k in runs[0]})
    nm = turning_noise_model(turning)  # 1e-5° per √(0.01 s) step: 1e-4 °/√s of random walk
    np.testing.assert_allclose(nm.angle_random_walk, 1e-4 * hg.units.DEG, rtol=0.1)


def test_a_run_whose_table_angle_disagrees_is_named_with_its_dataset_rows():
    """Audit (s30): one run's azimuth wrapped (or in radians) among good runs passed the
    load (the median over runs) and failed in `reduce` naming no run. It is refused where
    the dataset is built, naming the run and the dataset's rows."""
    good = _two_runs()
    n = 41
    spin = {k: v[n:] for k, v in good.items()}
    cols = {k: np.r_[good[k], spin[k], spin[k]] for k in good}  # rotation runs 1, 2, 3
    cols["run"] = np.repeat([0, 1, 2, 3], n)
    hg.MeasuredData(cols)
    wrapped = cols["table_angle_deg"].copy()
    wrapped[2 * n : 3 * n] = np.mod(wrapped[2 * n : 3 * n] + 300.0, 360.0)  # run 2 only
    with pytest.raises(ValueError, match=r"^column 'table_angle_deg' steps -357.5° from row "
                       r"105 to row 106 of run 2 \(times 11.5 → 12 s\), -360° off .* wrapped to "
                       r"\[0, 360\)"):  # fmt: skip
        hg.MeasuredData(cols | {"table_angle_deg": wrapped})
    rad = cols["table_angle_deg"].copy()
    rad[3 * n :] = np.radians(rad[3 * n :])  # run 3 only
    with pytest.raises(ValueError, match=r"^column 'table_angle_deg' turns 0.01745 × the integral"
                       r" .* in run 3 \(from row 123 to row 163\), where the rotation runs' median "
                       r"is 1; .* in every run: it looks like radians"):  # fmt: skip
        hg.MeasuredData(cols | {"table_angle_deg": rad})


def test_traced_columns_and_records_are_refused_in_one_line(record):
    """Audit (s30): `MeasuredData` of traced columns and `Record.to_data()` of a traced
    record raised JAX's bare TracerArrayConversionError under `jax.jit`."""
    import jax
    import jax.numpy as jnp

    cols = {k: jnp.asarray(v) for k, v in table().items()}
    assert hg.MeasuredData(cols) == hg.MeasuredData(table())  # concrete JAX arrays: fine
    with pytest.raises(TypeError, match=r"^MeasuredData holds host data, and column "
                       r"'wave_angle_deg' is traced .*: build it outside them"):  # fmt: skip
        jax.jit(lambda w: hg.MeasuredData(cols | {"wave_angle_deg": w}).columns)(cols["time_s"])
    with pytest.raises(TypeError, match=r"^Record.to_data: MeasuredData holds host data, and "
                       r"this record is traced .* on the Record the jitted function returns"):  # fmt: skip
        jax.jit(lambda r: r.to_data().columns)(record)
    assert len(record.to_data()) == record.t.size
