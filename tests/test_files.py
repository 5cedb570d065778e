"""Files in and out (auditor's findings C1–C10): the CSV reader's comments, blank and empty
rows and header hints, NetCDF coordinates and NetCDF-3, compensator files (`.eqx`
hyperparameters, checked JSON), atomic exports that make their folder, and exact numbers in
motion files. Small synthetic files in `tmp_path`; no simulation."""

import json
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
from hrgjax._data_files import read_csv_table
from hrgjax.calibration import export

N = 4
HEADER = "time_s,temperature_c,table_rate_dps,wave_angle_deg"


def base(n=N):
    return {
        "time_s": np.arange(n) * 0.1,
        "temperature_c": np.full(n, 20.0),
        "table_rate_dps": np.zeros(n),
        "wave_angle_deg": np.linspace(0.0, 1e-3, n),
    }


def write(path, text):
    path.write_text(text, encoding="utf-8")
    return path


# --- C1: '#' inside quotes or as a first field is data; a '#' line begins a comment --------


def test_hash_lines_inside_quotes_and_hash_first_fields_round_trip(tmp_path):
    """Text with a line break followed by '#', and a first column whose fields begin with
    '#', read back row for row (the old reader dropped those lines as comments)."""
    note = np.array(["ok\n#1 see log", "b", "  # c", "d"])
    d = hg.MeasuredData(base() | {"note": note}, allow_extra=True)
    assert hg.load(d.save(tmp_path / "ml.csv"), allow_extra=True) == d
    tag = np.array(["#1", "#2", "ok", " #x"])
    d = hg.MeasuredData({"tag": tag} | base(), allow_extra=True)
    back = hg.load(d.save(tmp_path / "first.csv"), allow_extra=True)
    assert back == d and back["tag"].tolist() == tag.tolist()


def test_hash_lines_that_begin_a_record_are_comments(tmp_path):
    text = f"# a comment\n{HEADER}\n0,20,0,0\n  # another\n0.1,20,0,0\n#,1,2,3\n"
    cols, lines = read_csv_table(str(write(tmp_path / "c.csv", text)))
    assert cols["time_s"].tolist() == [0.0, 0.1] and lines.tolist() == [3, 5]


# --- C2: only blank lines are skipped; a row of empty fields is a gap or an error -----------


def test_empty_rows_are_gaps_or_errors_never_skipped(tmp_path):
    """A `,,,` row is NaN with `empty_as_nan` (the time base keeps its place), an error naming
    the line otherwise; a line of spaces is blank and skipped (old: the row vanished)."""
    path = write(tmp_path / "gap.csv", f"{HEADER}\n0,20,0,0\n,,,\n   \n0.2,20,0,0\n")
    cols, lines = read_csv_table(str(path), empty_as_nan=True)
    assert np.isnan(cols["time_s"][1]) and lines.tolist() == [2, 3, 5]
    with pytest.raises(ValueError, match=r"^\S*gap.csv: line 3: every field is empty"):
        hg.load(path)
    # rows of empty fields after the last sample (a spreadsheet's export) hold no sample
    tail = write(tmp_path / "tail.csv", f"{HEADER}\n0,20,0,0\n0.2,20,0,0\n,,,\n,,,\n")
    assert len(hg.load(tail)["time_s"]) == 2
    cols, lines = read_csv_table(str(tail), empty_as_nan=True)
    assert lines.tolist() == [2, 3] and not np.isnan(cols["time_s"]).any()
    imu = write(tmp_path / "imu.csv", "t,gx,gy,gz,ax,ay,az\n0,0,0,0,0,0,9.8\n,,,,,,\n"
                "0.02,0,0,0,0,0,9.8\n0.03,0,0,0,0,0,9.8\n")  # fmt: skip
    with pytest.raises(ValueError, match=r"imu.csv: line 3: every field is empty"):
        hg.imu.load(imu, columns={"time": "t", "gyro": ["gx", "gy", "gz"],
                                  "accel": ["ax", "ay", "az"]},
                    units={"gyro": "rad/s", "accel": "m/s^2"})  # fmt: skip


# --- C3: .eqx keeps window_s and MLP's mode ------------------------------------------------


def test_eqx_keeps_window_and_mode_and_reads_files_without_them(tmp_path):
    """`save_compensator` → `load_compensator` is `eqx.tree_equal` for a Fourier compensator
    with `window_s=6` and an MLP with `mode="end_to_end"`, `window_s=6` (old: both came back
    at the defaults); a file written before these fields existed loads with the defaults."""
    four = hg.calibration.FourierCompensator(
        window_s=6.0, drift_coef=jnp.arange(5.0)[None], sf_coef=jnp.ones((1, 5))
    )
    mlp = hg.calibration.MLPCompensator(
        drift_width=3, sf_width=2, mode="end_to_end", window_s=6.0
    ).init(jax.random.key(0))
    for comp in (four, mlp):
        path = hg.calibration.save_compensator(comp, tmp_path / "c.eqx")
        assert eqx.tree_equal(hg.calibration.load_compensator(path), comp)
        json_path = hg.calibration.export_json(comp, tmp_path / "c.json")
        assert eqx.tree_equal(hg.calibration.load_json(json_path), comp)
    # an older file: the header without window_s / mode, its checksum made over that header
    with open(path, "rb") as fh:
        header, payload = json.loads(fh.readline()), fh.read()
    for key in ("window_s", "mode"):
        del header["hyper"][key]
    header["sha256"] = export.checksum(header, payload)
    with open(tmp_path / "old.eqx", "wb") as fh:
        fh.write((json.dumps(header) + "\n").encode() + payload)
    old = hg.calibration.load_compensator(tmp_path / "old.eqx")
    assert (old.window_s, old.mode) == (hg.calibration.MLPCompensator().window_s, "reduced")


def test_eqx_and_json_keep_the_mlp_prior_weights_and_old_files_load_without_a_prior(tmp_path):
    """`drift_t_curvature` / `sf_t_curvature` (the smoothness prior in T) round trip through
    `.eqx` and JSON (old: a loaded MLP came back with the defaults 10⁻³ / 0.1); a file saved
    before the prior existed loads with 0.0 / 0.0, how its networks were trained."""
    mlp = hg.calibration.MLPCompensator(
        drift_width=3, sf_width=2, drift_t_curvature=0.02, sf_t_curvature=0.0
    ).init(jax.random.key(0))
    path = hg.calibration.save_compensator(mlp, tmp_path / "p.eqx")
    json_path = hg.calibration.export_json(mlp, tmp_path / "p.json")
    for back in (hg.calibration.load_compensator(path), hg.calibration.load_json(json_path)):
        assert (back.drift_t_curvature, back.sf_t_curvature) == (0.02, 0.0)
        assert eqx.tree_equal(back, mlp)
    with open(path, "rb") as fh:
        header, payload = json.loads(fh.readline()), fh.read()
    assert header["hyper"]["drift_t_curvature"] == 0.02
    for key in ("drift_t_curvature", "sf_t_curvature"):
        del header["hyper"][key]
    header["sha256"] = export.checksum(header, payload)
    with open(tmp_path / "old.eqx", "wb") as fh:
        fh.write((json.dumps(header) + "\n").encode() + payload)
    old = hg.calibration.load_compensator(tmp_path / "old.eqx")
    assert (old.drift_t_curvature, old.sf_t_curvature) == (0.0, 0.0)
    d = json.loads((tmp_path / "p.json").read_text())
    for key in ("drift_t_curvature", "sf_t_curvature"):
        del d["hyper"][key]
    (tmp_path / "old.json").write_text(json.dumps(d))
    old = hg.calibration.load_json(tmp_path / "old.json")
    assert (old.drift_t_curvature, old.sf_t_curvature) == (0.0, 0.0)


# --- C4: NetCDF coordinates that are columns -----------------------------------------------


def test_netcdf_time_coordinate_is_a_column_and_a_sample_column_is_refused(tmp_path):
    """A `time_s` dimension coordinate of 0, 1, 2, … s is data (old: dropped as a sample
    index, then "missing required column"); a column named like the sample dimension is
    refused on save (old: it came back elsewhere or not at all)."""
    xr = pytest.importorskip("xarray")
    t = np.arange(N, dtype=float)
    ds = xr.Dataset(
        {k: ("time_s", v) for k, v in base().items() if k != "time_s"},
        coords={"time_s": ("time_s", t, {"units": "s"})},
    )
    assert hg.MeasuredData.from_xarray(ds)["time_s"].tolist() == t.tolist()
    ds.to_netcdf(tmp_path / "tc.nc", engine="h5netcdf")
    assert hg.load(tmp_path / "tc.nc")["time_s"].tolist() == t.tolist()
    plain = xr.Dataset({k: ("sample", v) for k, v in base().items()},
                       coords={"sample": np.arange(N)})  # fmt: skip
    assert hg.MeasuredData.from_xarray(plain).names == list(base())
    d = hg.MeasuredData(base() | {"sample": np.arange(N) + 5.0}, allow_extra=True)
    with pytest.raises(ValueError, match=r"^column 'sample' has the name of the NetCDF sample"):
        d.save(tmp_path / "s.nc")
    assert not (tmp_path / "s.nc").exists()


# --- C5: load_json checks what it reads ----------------------------------------------------


@pytest.fixture
def fourier_json(tmp_path):
    comp = hg.calibration.FourierCompensator(
        drift_coef=jnp.arange(5.0)[None], sf_coef=jnp.ones((1, 5))
    )
    path = hg.calibration.export_json(comp, tmp_path / "f.json")
    with open(path, encoding="utf-8") as fh:
        return json.load(fh)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.pop("sf_coef"), r"missing key 'sf_coef'"),
        (lambda d: d.pop("hyper"), r"missing key 'hyper'"),
        (lambda d: d["drift_coef"][0].__setitem__(0, math.nan), r"NaN is not a JSON number"),
        (lambda d: d.__setitem__("drift_coef", [[1, 2]]),
         r"'drift_coef' has shape \(1, 2\); the FourierCompensator .* needs \(1, 5\)"),
        (lambda d: d.__setitem__("sf_coef", [["a"] * 5]), r"'sf_coef' must be an array of numbers"),
        (lambda d: d.__setitem__("format", 99), r"compensator file format 99; this hrgjax reads"),
        (lambda d: d.__setitem__("class", "Nope"), r"unknown compensator class 'Nope'"),
        (lambda d: d.__setitem__("k_e_nominal", 0.7),
         r"'k_e_nominal' = 0.7 disagrees with the value in 'hyper' \(0.554\)"),
        (lambda d: d.__setitem__("t_ref", -40), r"'t_ref' = -40 disagrees with the value in"),
        (lambda d: d["hyper"].__setitem__("bogus", 1), r"'hyper' does not describe a Fourier"),
    ],
)  # fmt: skip
def test_load_json_names_the_file_and_the_field(tmp_path, fourier_json, edit, message):
    """Each edit is one `ValueError` line naming the file (old: KeyError, NaN or a wrong
    shape loaded, format and disagreeing top-level copies ignored)."""
    edit(fourier_json)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(fourier_json))
    with pytest.raises(ValueError, match=rf"^{path}: {message}") as err:
        hg.calibration.load_json(path)
    assert "\n" not in str(err.value)


def test_load_json_refuses_a_binary_file(tmp_path):
    path = tmp_path / "m.json"
    path.write_bytes(b'{"class": "\xff\xfe"}')
    with pytest.raises(ValueError, match=rf"^{path}: not UTF-8 text"):
        hg.calibration.load_json(path)


# --- C6: exports are atomic and make their folder; motion files are exact ------------------


def test_allan_and_noise_exports_make_their_folder(tmp_path):
    """`AllanResult.to_json/to_csv`, `CompositeNoise.to_json/to_kalibr` into a folder that
    does not exist yet (old: FileNotFoundError), leaving no temporary file behind."""
    one = np.array([1.0, 2.0])
    r = hg.allan.AllanResult(
        kind="adev", ci=0.683, taus=one, m=one, dev=one, dev_low=one, dev_high=one, edf=one,
        n_terms=np.array([9, 4]), alpha=one,
    )  # fmt: skip
    r.to_json(tmp_path / "a" / "r.json")
    r.to_csv(tmp_path / "b" / "r.csv")
    assert json.loads((tmp_path / "a" / "r.json").read_text())["dev"] == [1.0, 2.0]
    spec = {"value": 0.1, "low": 0.09, "high": 0.11, "unit": "°/√h"}
    from hrgjax.allan.composite import CompositeNoise

    model = CompositeNoise(
        terms={"angle_random_walk": spec, "rate_random_walk": spec}, unit="°/h", rate_hz=100.0,
        n=1000, ci=0.683, taus=one, avar=one, covariance=np.eye(2), chi2=1.0, dof=1, p_value=0.5,
    )  # fmt: skip
    model.to_json(tmp_path / "c" / "m.json")
    k = model.to_kalibr(tmp_path / "out" / "imu.yaml")
    assert f"update_rate: {k['update_rate']!r}" in (tmp_path / "out" / "imu.yaml").read_text()
    leftovers = [p.name for p in tmp_path.rglob(".*")]
    assert leftovers == []


def test_motion_csv_round_trips_exactly(tmp_path):
    """`Motion.from_csv(to_csv(m)) == m` for numbers that 12 significant digits round (old:
    1/3 came back as 0.333333333333), written into a new folder."""
    from hrgjax.ins.motion import Motion, Segment

    m = Motion(
        1 / 3, 2 / 7, 100.1 + 1e-9, (0.1 + 0.2, 0.0, 0.0), 10 / 3, 0.0, 0.0,
        (Segment(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 1 / 3),
         Segment(5, (1 / 7, 0.0, 0.0), (0.0, 0.0, 0.0), 2.5, False)),
    )  # fmt: skip
    path = tmp_path / "new" / "m.csv"
    m.to_csv(path)
    assert Motion.from_csv(path) == m


# --- C7: text that looks like numbers cannot be written to CSV as text ---------------------


def test_numeric_looking_text_column_is_refused_on_csv_save(tmp_path):
    """["nan", "1", "2"] as text: refused on save, naming the column (old: saved to a file
    that then could not be loaded); NetCDF keeps it as text."""
    d = hg.MeasuredData(base() | {"note": np.array(["nan", "1", "2", "3"])}, allow_extra=True)
    with pytest.raises(ValueError, match=r"^column 'note' is text whose every field looks like"):
        d.save(tmp_path / "tn.csv")
    assert not (tmp_path / "tn.csv").exists()
    pytest.importorskip("xarray")
    assert hg.load(d.save(tmp_path / "tn.nc"), allow_extra=True) == d


# --- C8: messages that say what is wrong ---------------------------------------------------


@pytest.mark.parametrize(
    "text, message",
    [
        ("# " + HEADER + "\n0,20,0,0\n0.1,20,0,0\n",
         r"line 2, the header row, holds numbers .* commented out with '#'"),
        ("," + HEADER + "\n0,0,20,0,0\n", r"header field 1 is empty; .* index=False"),
        (HEADER.replace(",", ";") + "\n0;20;0;0\n",
         r"the header has one field .* separated by ';'"),
    ],
)  # fmt: skip
def test_header_messages_name_the_likely_cause(tmp_path, text, message):
    """np.savetxt's commented header, a pandas index column and a semicolon-separated file
    (old: duplicate column names / no hint / missing required columns)."""
    path = write(tmp_path / "h.csv", text)
    with pytest.raises(ValueError, match=rf"^{path}: {message}"):
        hg.load(path)


def test_netcdf3_is_read_or_named(tmp_path):
    """A NetCDF-3 classic file is read through scipy (old: "not a readable NetCDF (HDF5)")."""
    xr = pytest.importorskip("xarray")
    pytest.importorskip("scipy")
    ds = xr.Dataset({k: ("sample", v) for k, v in base().items()})
    ds.to_netcdf(tmp_path / "n3.nc", format="NETCDF3_CLASSIC", engine="scipy")
    assert hg.load(tmp_path / "n3.nc") == hg.MeasuredData(base())


def test_psins_log_that_is_not_utf8_is_one_line(tmp_path):
    path = tmp_path / "log.imu"
    path.write_bytes(b"0 0 0 0 0 0\n\xff\xfe 1\n")
    with pytest.raises(ValueError, match=rf"^{path}: line 2: not UTF-8 text"):
        hg.ins.alignment.load_psins(path)


# --- C10: the numeric fast path reads what the validating reader reads ---------------------


def test_fast_path_gives_the_validating_readers_columns(tmp_path, monkeypatch):
    """A plain numeric file (comments, blank lines, CRLF, odd but valid number forms, run
    ids) takes the fast path and returns the same columns, dtypes and lines as the
    validating reader; so does one with `nan` (a gap: tests/test_csv_gaps.py), while a file
    with a quote goes to the validating reader."""
    from hrgjax import _data_files

    text = (
        "# made by hand\r\n\r\nrun, time_s ,temperature_c,table_rate_dps,wave_angle_deg,x\r\n"
        "+3,0,20,0,-0.0, 1.\r\n  # a note\r\n   \r\n-0,.5,20.25,1e-300,5e-324,\t2E+3\r\n"
        "7,1.0,2e1,0,12345.678,1.7976931348623157e308\r\n"
    )
    path = str(write(tmp_path / "n.csv", text))
    taken = []
    real = _data_files._numeric_table
    monkeypatch.setattr(
        _data_files, "_numeric_table", lambda p, *a: taken.append(real(p, *a)) or taken[-1]
    )
    fast_cols, fast_lines = read_csv_table(path)
    assert taken[-1] is not None
    monkeypatch.setattr(_data_files, "_numeric_table", lambda p, *a: None)
    slow_cols, slow_lines = read_csv_table(path)
    assert fast_lines.tolist() == slow_lines.tolist() == [4, 7, 8]
    assert list(fast_cols) == list(slow_cols)
    for k in slow_cols:
        assert fast_cols[k].dtype == slow_cols[k].dtype, k
        np.testing.assert_array_equal(fast_cols[k], slow_cols[k])
    assert np.signbit(fast_cols["wave_angle_deg"][0])
    monkeypatch.setattr(
        _data_files, "_numeric_table", lambda p, *a: taken.append(real(p, *a)) or taken[-1]
    )
    read_csv_table(str(write(tmp_path / "o.csv", text.replace("-0.0", "nan"))))
    assert taken[-1] is not None and np.isnan(taken[-1][0]["wave_angle_deg"][0])
    read_csv_table(str(write(tmp_path / "o.csv", text.replace(" 1.", '"1"'))))
    assert taken[-1] is None


def test_numpy_accepts_exactly_the_readers_numbers_over_the_fast_alphabet():
    """Every field of up to 4 characters from digits, `.eE+-`, the letters of `nan`, `inf`
    and `infinity` and a blank (and every case of `nan`, `inf`, `infinity` with a sign) that
    NumPy's parser takes as a float is a number to `is_number`, so the fast path accepts
    nothing the validating reader refuses."""
    import io
    import itertools
    import warnings

    from hrgjax.data import is_number

    words = ["".join(c) for w in ("nan", "inf", "infinity", "infinit", "nana")
             for c in itertools.product(*((x, x.upper()) for x in w))]  # fmt: skip
    fields = [s + w for w in words for s in ("", "+", "-", " ")]
    for n in range(1, 5):
        fields += ["".join(c) for c in itertools.product("1.eE+- ", repeat=n)]
    for n in range(1, 4):
        fields += ["".join(c) for c in itertools.product("1.e+- naifty", repeat=n)]
        fields += ["".join(c) for c in itertools.product("1.E-NAIFTY", repeat=n)]
    for field in fields:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                np.loadtxt(io.StringIO(field + ",1\n"), delimiter=",", dtype=float,
                           comments=None)  # fmt: skip
        except ValueError:
            continue
        assert is_number(field), field


def test_load_refuses_integers_a_float_would_round_in_extra_columns_too(tmp_path, monkeypatch):
    """Two nanosecond stamps 2 ns apart read as one float: `hg.load` refuses them, on the
    fast path and on the validating reader's, as `MeasuredData` does in memory; a float
    written in scientific notation is kept (rounding is then the writer's choice)."""
    from hrgjax import _data_files

    text = f"{HEADER},stamp_ns\n0,20,0,0,1700000000000000001\n1,20,0,0,1700000000000000003\n"
    path = write(tmp_path / "ns.csv", text)
    want = r"ns.csv: column 'stamp_ns' row 0 \(line 2\): the integer 1700000000000000001 is too"
    with pytest.raises(ValueError, match=want):
        hg.load(path, allow_extra=True)
    with pytest.raises(
        ValueError, match=r"column 'stamp_ns' row 0: the integer 1700000000000000001"
    ):
        hg.MeasuredData(
            base(2) | {"stamp_ns": np.array([1700000000000000001, 3])}, allow_extra=True
        )
    assert read_csv_table(str(path))[0]["stamp_ns"][0] == 1.7e18  # not asked: nearest float
    monkeypatch.setattr(_data_files, "_numeric_table", lambda p, *a: None)
    with pytest.raises(ValueError, match=want):
        hg.load(path, allow_extra=True)
    monkeypatch.undo()
    d = hg.MeasuredData(base(2) | {"stamp_ns": np.array([1.7e18, -(2.0**60)])}, allow_extra=True)
    assert hg.load(d.save(tmp_path / "f.csv"), allow_extra=True) == d
    # an integer a float64 holds exactly (what "%.0f" writes of 1e20) is not refused, in a
    # file or in memory; without allow_extra the column is refused as unknown first
    exact = write(tmp_path / "exact.csv", f"{HEADER},big\n0,20,0,0,100000000000000000000\n"
                  "1,20,0,0,1700000000000000000\n")  # fmt: skip
    assert list(hg.load(exact, allow_extra=True)["big"]) == [1e20, 1.7e18]
    big = hg.MeasuredData(base(2) | {"big": np.array([2**60, -(2**62)])}, allow_extra=True)
    assert list(big["big"]) == [2.0**60, -(2.0**62)]
    with pytest.raises(ValueError, match=r"unknown column\(s\) \['stamp_ns'\]"):
        hg.load(path)
    # digits beyond float range, in a file or in memory near int64's end: named, no
    # OverflowError or cast warning
    huge = write(tmp_path / "huge.csv", f"{HEADER},big\n0,20,0,0,1{'0' * 400}\n1,20,0,0,1\n")
    with pytest.raises(ValueError, match=r"column 'big' row 0 \(line 2\): the integer 1000"):
        hg.load(huge, allow_extra=True)
    with pytest.raises(ValueError, match=r"column 'big' row 0: the integer 9223372036854775807"):
        hg.MeasuredData(base(2) | {"big": np.array([2**63 - 1, 0])}, allow_extra=True)


def test_every_contract_column_has_its_netcdf_units(tmp_path):
    """Each column of `COLUMNS` has its `units` (or takes any: `ANY_UNIT`): checked on load (a
    rate in rad/s is refused, not read as °/s) and written by `save`."""
    import xarray as xr

    from hrgjax import _data_files

    for col in ("rebalance_rate_dps", "precession_dps"):
        ds = xr.Dataset({k: ("sample", v) for k, v in base().items()})
        ds[col] = ("sample", np.full(N, 0.01), {"units": "rad/s"})
        ds.to_netcdf(tmp_path / "r.nc", engine="h5netcdf")
        with pytest.raises(ValueError, match=rf"r.nc: variable '{col}' has units 'rad/s'"):
            hg.load(tmp_path / "r.nc")
        ds[col].attrs["units"] = "deg s-1"
        ds.to_netcdf(tmp_path / "d.nc", engine="h5netcdf")
        assert hg.load(tmp_path / "d.nc")[col][0] == 0.01
    # an acceleration in UDUNITS' name for g (`g` alone is its gram) is read as g
    ds = xr.Dataset({k: ("sample", v) for k, v in base().items()})
    for unit in ("standard_free_fall", "gravity", "g"):
        ds["accel_z_g"] = ("sample", np.ones(N), {"units": unit})
        ds.to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
        assert hg.load(tmp_path / "a.nc")["accel_z_g"][0] == 1.0
    # the 0/1 flag takes whatever other tools call its unit
    ds = xr.Dataset({k: ("sample", v) for k, v in base().items()})
    for unit in ("dimensionless", "none", "bool", "1"):
        ds["rebalance_on"] = ("sample", np.ones(N), {"units": unit})
        ds.to_netcdf(tmp_path / "flag.nc", engine="h5netcdf")
        assert hg.load(tmp_path / "flag.nc")["rebalance_on"][0] == 1.0
    units, any_unit = _data_files.UNITS, _data_files.ANY_UNIT
    assert set(hg.data.COLUMNS) == set(units) | set(any_unit) and not set(units) & set(any_unit)
    cols = base() | {k: np.zeros(N, int if k == "run" else float) for k in hg.data.COLUMNS
                     if k not in base()}  # fmt: skip
    d = hg.MeasuredData(cols)
    with xr.open_dataset(d.save(tmp_path / "all.nc"), engine="h5netcdf") as ds:
        got = {k: ds[k].attrs.get("units") for k in hg.data.COLUMNS}
    assert got == {k: None if k in any_unit else units[k][0] for k in hg.data.COLUMNS}
    assert hg.load(tmp_path / "all.nc") == d


def test_rounded_integer_is_the_loaders_one_check():
    """`rounded_integer` (every loader's check): an integer beyond 2**53 that a float64
    would round, blanks and signs allowed; an integer a float64 holds (2**53, 2**60, 1e20 as
    "%.0f" writes it) and anything that is not an integer's digits are not."""
    from hrgjax._data_files import rounded_integer

    for text in ("9007199254740993", " -9007199254740993 ", "+1700000000000000001",
                 "1" + "0" * 400):  # fmt: skip
        assert rounded_integer(text), text
    for text in ("9007199254740992", str(2**60), "-" + str(2**62), "100000000000000000000",
                 "1.7e18", "1700000000000000001.0", "nan", "", "123"):  # fmt: skip
        assert not rounded_integer(text), text


def test_imu_load_refuses_integers_a_float_would_round_in_the_columns_it_reads(
    tmp_path, monkeypatch
):
    """Audit: `hg.imu.load` read nanosecond stamps 1 ns apart as one time ("time does not
    increase"; further apart they were rounded silently). The columns it reads are checked
    as `hg.load` checks an extra column, on the fast path and the validating reader's, naming
    the file, column, row and line; an integer a float64 holds exactly still loads, and a
    column it does not read (the file's other columns are ignored) is not checked."""
    from hrgjax import _data_files

    rows = [f"{1700000000000000001 + i},{2**60 + 256 * i},{2**53 + 1},1e-3,2e-3,3e-3,0,0,9.81"
            for i in range(4)]  # fmt: skip
    path = write(tmp_path / "imu.csv", "t_ns,t_exact,serial,gx,gy,gz,ax,ay,az\n" + "\n".join(rows))
    cols = {"gyro": ["gx", "gy", "gz"], "accel": ["ax", "ay", "az"]}
    units = {"gyro": "rad/s", "accel": "m/s^2"}
    want = (r"imu.csv: column 't_ns' row 0 \(line 2\): the integer 1700000000000000001 is too "
            r"large to hold exactly as a float64; write it in scientific notation if rounding is "
            r"intended$")  # fmt: skip
    for fast in (True, False):
        if not fast:
            monkeypatch.setattr(_data_files, "_numeric_table", lambda p, *a: None)
        with pytest.raises(ValueError, match=want):
            hg.imu.load(path, cols | {"time": "t_ns"}, units, check_units=False)
        # 2**60 s as seconds is an epoch in ns read as s, refused unless declared (2ec03ab)
        data = hg.imu.load(path, cols | {"time": "t_exact"}, units | {"time": "s"},
                           check_units=False)  # fmt: skip
        assert list(data.time) == [2.0**60 + 256 * i for i in range(4)]
    # a rounded integer in a gyro column is named the same way
    write(path, "t,gx,gy,gz,ax,ay,az\n0,1,2,3,0,0,9.81\n1,1,2,-9007199254740993,0,0,9.81\n")
    with pytest.raises(ValueError, match=r"column 'gz' row 1 \(line 3\): the integer -90071"):
        hg.imu.load(path, cols | {"time": "t"}, units, check_units=False)
