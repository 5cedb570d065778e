"""Issue 18: bad input gets one clear error naming the field; nothing is accepted silently,
altered, or lost (the data contract, simulate's settings, compensator files, the CLI)."""

import os
import re
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import pytest
from helpers import cli_fails
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hrgjax as hg

HEADER = "time_s,run,temperature_c,table_rate_dps,wave_angle_deg"


def _csv(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def _cols(n=4, **extra):
    cols = {
        "time_s": np.arange(n, dtype=float),
        "temperature_c": np.full(n, 20.0),
        "table_rate_dps": np.zeros(n),
        "wave_angle_deg": np.linspace(0.0, 1.0, n),
    }
    cols.update(extra)
    return cols


# --- the data contract, run by run ----------------------------------------------------------


@pytest.mark.parametrize(
    "times,what", [([0, 0, 1, 0.5], "time goes backwards"), ([0, 0, 1, 1], "duplicate")]
)
def test_time_is_checked_within_each_run_even_when_runs_interleave(times, what):
    cols = _cols(time_s=np.array(times, float), run=np.array([0, 1, 0, 0]))
    with pytest.raises(ValueError, match=f"row 3 .*run 0.*row 2.*{what}"):
        hg.MeasuredData(cols)


@pytest.mark.parametrize(
    "column,value,match",
    [
        ("time_s", np.arange(4).astype("datetime64[s]"), "datetime64.*plain numbers in \\[s\\]"),
        ("time_s", np.arange(4).astype("timedelta64[s]"), "timedelta64.*timedelta64\\(1, 's'\\)"),
        ("temperature_c", np.array([20, 20, 20, 20 + 1j]), "complex"),
        ("temperature_c", np.array([True, False, True, True]), "booleans"),
        ("temperature_c", np.array([1, 2, 3, 2**60 + 1]), "row 3.*too large.*2\\*\\*53"),
        ("temperature_c", np.array([1.0, 2.0, "x", 3.0], dtype=object), "row 2 has 'x'"),
        ("temperature_c", np.array(["20", "20", "21", "x"]), "numbers in \\[°C\\].*text"),
        ("run", np.array([0, 0, 1.5, 2]), "integers; row 2"),
        ("run", np.array([0.0, 0.0, 1.0, 2.0**60]), "row 3.*2\\*\\*53"),
        ("run", np.array([0, 0, 1, 2**64 - 1], dtype=np.uint64), "row 3.*int64"),
    ],
)
def test_column_types_are_exact_or_refused(column, value, match):
    with pytest.raises(ValueError, match=f"{column}.*{match}|{match}"):
        hg.MeasuredData(_cols(**{column: value}))


def test_large_integer_run_ids_are_kept_exactly(tmp_path):
    big = 2**53 + 1  # not a float64
    p = _csv(tmp_path, f"{HEADER}\n0,{big},20,0,1\n1,{big},20,0,1\n")
    data = hg.load(p)
    assert data.run.dtype == np.int64 and int(data.run[0]) == big
    assert hg.load(data.save(tmp_path / "again.csv")) == data


# --- CSV --------------------------------------------------------------------------------------


def test_csv_accepts_a_byte_order_mark_and_comment_lines(tmp_path):
    p = _csv(tmp_path, f"\ufeff# bench log\n{HEADER}\n0,0,20,0,1\n# pause\n\n1,0,20,0,2\n")
    data = hg.load(p)
    assert data.names == HEADER.split(",") and len(data) == 2
    np.testing.assert_array_equal(data["wave_angle_deg"], [1.0, 2.0])


@pytest.mark.parametrize(
    "row,match",
    [
        ("0,1_001,20,0,1", "'run' row 0 \\(line 2\\).*'1_001' is not a number"),
        ("0,0,20,1e,1", "table_rate_dps.*'1e' is not a number"),
        ("0,0,20,,1", "table_rate_dps.*empty field"),
        ("0,99999999999999999999,20,0,1", "run.*int64"),
        ("0,0,20,0,9007199254740993", "wave_angle_deg.*too large"),
        ("0,0,20,0," + "1" * 140_000, "line 2: not a readable CSV row"),
        ("0,0,20,0", "line 2 has 4 fields, the header has 5"),
    ],
)
def test_csv_errors_name_the_column_and_the_line(tmp_path, row, match):
    p = _csv(tmp_path, f"{HEADER}\n{row}\n")
    with pytest.raises(ValueError, match=match) as err:
        hg.load(p)
    assert str(err.value).startswith(str(p)) and "\n" not in str(err.value)


def test_csv_that_is_not_utf8_is_refused(tmp_path):
    p = tmp_path / "latin.csv"
    p.write_bytes(f"{HEADER},operator\n0,0,20,0,1,J\xfcrgen\n".encode("latin-1"))
    with pytest.raises(ValueError, match="line 2: not UTF-8"):
        hg.load(p, allow_extra=True)


@pytest.mark.parametrize("ext", ["csv", "nc"])
def test_text_extra_columns_are_kept_as_text_and_written_back(tmp_path, ext):
    p = _csv(
        tmp_path,
        f'{HEADER},operator,stamp\n0,0,20,0,1,ann,2024-01-01T00:00:00\n1,0,20,0,1,"b,ob",x\n',
    )
    with pytest.raises(ValueError, match="unknown column"):
        hg.load(p)
    data = hg.load(p, allow_extra=True)
    assert data["operator"].tolist() == ["ann", "b,ob"]
    assert data["stamp"][0] == "2024-01-01T00:00:00"
    back = hg.load(data.save(tmp_path / f"out.{ext}"), allow_extra=True)
    assert back == data


# --- NetCDF -----------------------------------------------------------------------------------


def _nc(tmp_path, name="d.nc", coords=None, **attrs):
    pytest.importorskip("h5netcdf", reason="netCDF needs the data extra")
    import xarray as xr

    var = lambda k, v: ("sample", v, attrs.get(k, {}))
    ds = xr.Dataset({k: var(k, v) for k, v in _cols().items()}, coords=coords)
    p = tmp_path / name
    ds.to_netcdf(p, engine="h5netcdf")
    return p


@pytest.mark.parametrize(
    "units,factor", [("seconds since 2000-01-01", 1.0), ("minutes since 2000-01-01 00:00", 60.0)]
)
def test_netcdf_cf_time_units_are_honoured(tmp_path, units, factor):
    data = hg.load(_nc(tmp_path, time_s={"units": units}))
    np.testing.assert_array_equal(data["time_s"], np.arange(4.0) * factor)


@pytest.mark.parametrize(
    "attrs,match",
    [
        ({"temperature_c": {"units": "K"}}, "'temperature_c' has units 'K'.*°C"),
        ({"time_s": {"units": "fortnights since 2000-01-01"}}, "time_s.*'fortnights since"),
        ({"wave_angle_deg": {"units": "rad"}}, "wave_angle_deg.*'rad'"),
    ],
)
def test_netcdf_units_must_agree_with_the_contract(tmp_path, attrs, match):
    p = _nc(tmp_path, **attrs)
    with pytest.raises(ValueError, match=match) as err:
        hg.load(p)
    assert str(err.value).startswith(str(p))


def test_netcdf_extra_coordinates_are_columns_not_dropped(tmp_path):
    p = _nc(tmp_path, coords={"lat_deg": ("sample", np.arange(4.0))})
    with pytest.raises(ValueError, match="unknown column.*lat_deg"):
        hg.load(p)
    np.testing.assert_array_equal(hg.load(p, allow_extra=True)["lat_deg"], np.arange(4.0))


def test_damaged_netcdf_is_a_clear_error(tmp_path):
    good = hg.MeasuredData(_cols()).save(tmp_path / "good.nc")
    blob = Path(good).read_bytes()
    bad = tmp_path / "bad.nc"
    bad.write_bytes(blob[: len(blob) // 2])
    with pytest.raises(ValueError, match="bad.nc: not a readable NetCDF"):
        hg.load(bad)


# --- writes are atomic ------------------------------------------------------------------------


def test_an_interrupted_save_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    from hrgjax import _data_files

    path = tmp_path / "d.csv"
    hg.MeasuredData(_cols()).save(path)
    before = path.read_bytes()

    def half(data, fh):
        fh.write("time_s,run\n0,")
        raise KeyboardInterrupt

    monkeypatch.setattr(_data_files, "write_csv", half)
    with pytest.raises(KeyboardInterrupt):
        hg.MeasuredData(_cols(n=7)).save(path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["d.csv"]


# --- compensator files ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def eqx_file(tmp_path_factory):
    from hrgjax.calibration import FourierCompensator, save_compensator

    comp = FourierCompensator(drift_coef=np.ones((1, 5)), sf_coef=np.ones((1, 5)))
    return save_compensator(comp, tmp_path_factory.mktemp("m") / "m.eqx")


@pytest.mark.parametrize(
    "damage,match",
    [
        (lambda b: b[:-9], "truncated or damaged"),
        (lambda b: b[:-3] + bytes([b[-3] ^ 0x10]) + b[-2:], "checksum mismatch"),
        (lambda b: b.replace(b'"format": 3', b'"format": 9'), "format 9.*update hrgjax"),
        (lambda b: b.replace(b'"format": 3', b'"format": 1'), "carries a checksum but says"),
        (lambda b: b.replace(b'"harmonics": 2', b'"harmonics": 1'), "edited .checksum mismatch"),
        (lambda b: b.replace(b'"k_e": 0.554', b'"k_e": 0.654'), "checksum mismatch over the head"),
        (lambda b: b.replace(b"FourierCompensator", b"Bogus"), "unknown compensator class"),
        (lambda b: b"\x00\x01garbage", "not an hrgjax compensator"),
    ],
)
def test_damaged_compensator_files_are_named(eqx_file, tmp_path, damage, match):
    from hrgjax.calibration import load_compensator

    bad = tmp_path / "bad.eqx"
    bad.write_bytes(damage(Path(eqx_file).read_bytes()))
    with pytest.raises(ValueError, match=match) as err:
        load_compensator(bad)
    assert str(bad) in str(err.value)


def test_a_header_of_another_class_is_named_not_a_traceback(eqx_file, tmp_path):
    import json

    from hrgjax.calibration import load_compensator
    from hrgjax.calibration.export import checksum

    first, payload = Path(eqx_file).read_bytes().split(b"\n", 1)
    header = json.loads(first)
    header.update({"class": "PhysicalCompensator", "hyper": {"k_e": 0.554, "window_s": 3.0,
                   "max_steps": 5, "stats": []}})  # fmt: skip
    header["sha256"] = checksum(header, payload)
    bad = tmp_path / "other.eqx"
    bad.write_bytes(json.dumps(header).encode() + b"\n" + payload)
    with pytest.raises(ValueError, match="do not match a PhysicalCompensator"):
        load_compensator(bad)


# --- simulate's settings and parameters -------------------------------------------------------


@pytest.mark.parametrize(
    "kw,match",
    [
        (dict(angle_white=np.nan), "Noise.angle_white must be finite"),
        (dict(angle_random_walk=-1e-6), "Noise.angle_random_walk must be >= 0"),
        (dict(correlation_time=0.0), "Noise.correlation_time must be > 0"),
        (dict(run_bias=-1.0), "Noise.run_bias must be >= 0"),
        # a datasheet's unit typed as SI: its unit named (1″ as rad, 34 °/√h, 620 °/h …)
        (dict(angle_white=1.0), r"Noise.angle_white = 1 is outside .* ″ → ×hrgjax.units.ARC"),
        (dict(angle_random_walk=0.01), r"angle_random_walk = 0.01 is .* °/√h → ×hrgjax.units"),
        (dict(bias_instability=0.03), r"Noise.bias_instability = 0.03 is outside .* °/h → "),
        (dict(run_bias=1.0), r"Noise.run_bias = 1 is outside .* 0 … 0.05 rad/s"),
        (dict(amplitude_white=2.0), r"Noise.amplitude_white = 2 is outside .* % → ×1e-2"),
        # the preset's own figures (0.002 °/√h, 0.003 °/h, 0.2 °/h) typed as SI: a gyro's
        # ranges, not a consumer IMU's (`imu_*`: these passed)
        (dict(angle_random_walk=0.002), r"= 0.002 is outside .* 0 … 0.001 rad/√s — °/√h"),
        (dict(bias_instability=0.003), r"= 0.003 is outside .* 0 … 0.001 rad/s — °/h"),
        (dict(run_bias=0.2), r"Noise.run_bias = 0.2 is outside .* 0 … 0.05 rad/s — °/h"),
        (dict(bias_instability=0.001), r"= 0.001 is outside .*, its bounds excluded"),
    ],
)
def test_noise_parameters_are_checked(kw, match):
    with pytest.raises(ValueError, match=match):
        hg.Noise(**kw)
    quantity = hg.noise.PLAUSIBLE.get(next(iter(kw)))
    if "outside" in match:  # and `relaxed` takes it
        with hg.plausible.relaxed(**{quantity: (0.0, 10.0)}):
            hg.Noise(**kw)


def test_noise_ranges_take_every_gyro_from_an_hrg_to_a_mems_one():
    """An HRG's noise and a tactical or consumer MEMS gyro's pass `Noise`'s ranges: ARW
    0.1–1 °/√h and 0.015 °/s/√Hz, bias instability 100 °/h, a switch-on bias of 2 °/s."""
    from hrgjax.units import DEG, DEG_PER_H, DEG_PER_SQRT_H

    for arw in (1e-4 * DEG_PER_SQRT_H, 0.1 * DEG_PER_SQRT_H, 1.0 * DEG_PER_SQRT_H, 0.015 * DEG):
        hg.Noise(angle_random_walk=arw, bias_instability=100 * DEG_PER_H, run_bias=2.0 * DEG)
    assert hg.presets.tvg3_like().noise is not None


@pytest.mark.parametrize(
    "build,match",
    [  # the preset's 0.3 °/h, 0.01 °/h/g, … typed as SI (0.3 rad/s ≈ 62 000 °/h ran silently)
        (
            lambda r: hg.Gyro(r, rate_bias=0.3),
            r"^Gyro.rate_bias = 0.3 is outside the plausible "
            r"range -0.1 … 0.1 rad/s — °/h → ×hrgjax.units.DEG_PER_H; °/s → ×hrgjax.units.DEG "
            r"\(hrgjax.plausible.relaxed\(gyro_rate_bias=…\) widens it\)$",
        ),
        (lambda r: hg.Gyro(r, rate_bias=-0.1), r"-0.1 is outside .*, its bounds excluded"),
        (
            lambda r: hg.Gyro(r, g_sensitivity=[0.005, 0.005, 0.01]),
            r"^Gyro.g_sensitivity = 0.005 at index 0 is outside .* rad/s per g — °/h per g → ",
        ),
        (lambda r: hg.DriftTerms(warmup=0.5), r"^DriftTerms.warmup = 0.5 is outside .* rad/s"),
        (lambda r: hg.DriftTerms(lag=0.005), r"^DriftTerms.lag = 0.005 .* rad/s per °C — °/h per"),
        (lambda r: hg.DriftTerms(temperature_rate=0.5), r"rad/s per °C/s — °/h per °C/s → "),
        (lambda r: hg.DriftTerms(rate_cubic=10.0), r"-1 … 1 s² — ppm per \(rad/s\)² → ×1e-6"),
    ],
)
def test_gyro_rates_in_another_unit_are_refused_and_relaxed_takes_them(build, match):
    res = hg.Resonator(omega=3e4, tau=500.0)
    with pytest.raises(ValueError, match=match):
        build(res)
    quantity = re.search(r"relaxed\((\w+)=", str(pytest.raises(ValueError, build, res).value))
    with hg.plausible.relaxed(**{quantity.group(1): (-20.0, 20.0)}):
        build(res)


def test_gyro_ranges_take_real_gyros_and_simulate_holds_them_where_init_did_not_run(gyro):
    """A broken gyro's 2 °/s bias, a MEMS gyro's 0.2 °/s/g and the preset pass; a value put
    in with `eqx.tree_at` (no `__check_init__`) or a law that leaves the range over the run's
    temperatures is refused by `simulate` before any work, naming the field."""
    from hrgjax.units import DEG

    hg.Gyro(gyro.resonator, rate_bias=2.0 * DEG, g_sensitivity=0.2 * DEG)
    hg.DriftTerms(temperature_rate=1e-3, lag=1e-4, warmup=1e-3, rate_cubic=1e-3)
    with pytest.raises(ValueError, match=r"^gyro.rate_bias = 0.3 is outside the plausible"):
        hg.simulate(eqx.tree_at(lambda g: g.rate_bias, gyro, 0.3), PROFILE)
    with pytest.raises(ValueError, match=r"^gyro.noise.run_bias = 0.2 is outside .* 0.05 rad/s"):
        noisy = eqx.tree_at(lambda g: g.noise, gyro, hg.Noise(), is_leaf=lambda x: x is None)
        hg.simulate(eqx.tree_at(lambda g: g.noise.run_bias, noisy, 0.2), PROFILE,
                    key=jax.random.key(0))  # fmt: skip
    law = eqx.tree_at(lambda g: g.rate_bias, gyro, hg.TemperatureLaw(0.0, 2e-3))  # 0.14 at 90
    ramp = hg.Profile.piecewise([0.0, 1.0], 0.0, [20.0, 90.0])
    with pytest.raises(ValueError, match=r"^the temperature law of gyro.rate_bias at (6|7|8|9)"
                       r"\d.* °C \(inside the profile's temperatures \[20, 90\] °C\) = 0.1"):  # fmt: skip
        hg.simulate(law, ramp)


@pytest.fixture(scope="module")
def gyro():
    return hg.presets.tvg3_like(noise=False)


PROFILE = hg.Profile.constant_rate(5.0, 1.0, 20.0)


@pytest.mark.parametrize(
    "kw,match",
    [
        (dict(rtol=-1.0), "rtol must be a positive number"),
        (dict(atol=np.nan), "atol must be a positive number"),
        (dict(run=1.5), "run must be an integer run id"),
        (dict(max_steps=0), "max_steps must be a positive integer"),
        (dict(fixed_step=-0.1), "fixed_step must be a positive number"),
        # the estimate at the run's peak (scale audit: "≈ 100 bytes each" was 4× low; 1e9 × 400 B)
        (
            dict(dt_out=1e-9),
            "dt_out=1e-09 s on a 1-s profile gives 1e\\+09 output samples, .*"
            "≈ 400 bytes each at the run's peak, ≈ 373 GiB",
        ),
        (dict(dt_out=0.0), "dt_out must be a positive number"),
    ],
)
def test_simulate_refuses_bad_settings_before_any_work(gyro, kw, match):
    with pytest.raises(ValueError, match=match):
        hg.simulate(gyro, PROFILE, **kw)


def test_a_quadrature_at_or_beyond_the_amplitude_set_point_is_refused(gyro):
    """Audit: quadrature0 = a₀ ran the averaged solver out of steps ("max_steps"); beyond it
    the averaged run went on silently to an amplitude of 138 and the full model started the
    wave 90° off. The quadrature is the ellipse's minor semi-axis, the amplitude its major
    one: |q₀| < a₀ (a law's set point at the start temperature; a traced one unchecked)."""
    from hrgjax._simulate_options import check_quadrature0

    check_quadrature0(-0.999, gyro, PROFILE)
    for q0 in (1.0, -3.0, np.float64(10.0)):
        with pytest.raises(ValueError, match=r"^quadrature0 must be a finite number \(readout "
                           r"units\) .* set point a₀ = gyro.control.amplitude = 1, "
                           r"\|quadrature0\| < a₀: the quadrature is the minor semi-axis .*; got -?\d"):  # fmt: skip
            check_quadrature0(q0, gyro, PROFILE)
    law = eqx.tree_at(lambda g: g.control.amplitude, gyro, hg.TemperatureLaw(2.0, 0.1))
    check_quadrature0(1.5, law, PROFILE)  # a₀ = 2 at 20 °C, 1 at 10 °C
    with pytest.raises(ValueError, match=r"= 1 at the start temperature, 10 °C, \|quadrature0\|"):
        check_quadrature0(1.5, law, hg.Profile.piecewise([0.0, 1.0], 0.0, [10.0, 30.0]))
    with pytest.raises(ValueError, match=r"^quadrature0 must .*; got 2\b"):  # an eager grad
        jax.grad(lambda q: check_quadrature0(q, gyro, PROFILE) or q)(2.0)
    for model in ("averaged", "full"):  # `simulate` asks it before any work
        with pytest.raises(ValueError, match=r"^quadrature0 must .* a₀ = gyro.control.amplitude"):
            hg.simulate(gyro, PROFILE, model, quadrature0=3.0)


def test_temperature_laws_are_checked_over_the_profiles_temperatures(gyro):
    law = hg.TemperatureLaw(640.0, p1=-10.0)  # τ = 0 at 84 °C
    hot = eqx.tree_at(lambda g: g.resonator.tau, gyro, law)
    ramp = hg.Profile.piecewise([0.0, 1.0], 0.0, [20.0, 90.0])
    with pytest.raises(ValueError, match="gyro.resonator.tau gives .* s at 8[4-9].* must be > 0"):
        hg.simulate(hot, ramp)
    noisy = eqx.tree_at(
        lambda g: g.noise, gyro, hg.Noise(angle_random_walk=hg.TemperatureLaw(1e-6, p1=-1e-7)),
        is_leaf=lambda x: x is None,
    )  # fmt: skip
    with pytest.raises(ValueError, match="noise.angle_random_walk .* must be >= 0"):
        hg.simulate(noisy, ramp, key=jax.random.key(0))


# --- the CLI: one line, exit status, outputs checked before work --------------------------------


def test_cli_refuses_outputs_before_any_work(tmp_path, capsys):
    data = _csv(tmp_path, f"{HEADER}\n0,0,20,0,1\n1,0,20,0,1\n", "bench.csv")
    before = data.read_bytes()
    model = tmp_path / "m.eqx"
    model.write_bytes(b"x")
    cli_fails(["correct", str(data), "--model", str(model), "--out", str(data)], capsys,
              "--out .*bench.csv is also the input DATA")  # fmt: skip
    assert data.read_bytes() == before
    cli_fails(["simulate", "--out", str(tmp_path / "x.txt")], capsys, "must end in .csv or .nc")
    (tmp_path / "afile").write_text("")
    cli_fails(["simulate", "--out", str(tmp_path / "afile" / "d.csv")], capsys, "afile is a file")
    cli_fails(
        ["simulate", "--duration", "-5"], capsys, "--duration: expected a number of seconds > 0"
    )
    # an option of another plan is refused, not ignored
    cli_fails(["simulate", "--plan", "static", "--precession", "0.5"], capsys,
              "--precession does not apply to --plan static .it applies to --plan precession")  # fmt: skip
    cli_fails(["simulate", "--plan", "seed", "--duration", "60"], capsys,
              "--duration does not apply to --plan seed")  # fmt: skip
    cli_fails(["calibrate", str(tmp_path / "none.csv")], capsys, "none.csv: no such file")
    cli_fails(
        ["calibrate", str(data), "--out", str(tmp_path / "m.txt")], capsys, "must end in .eqx"
    )


def test_cli_exit_statuses_and_debug(tmp_path, capsys, monkeypatch):
    import hrgjax.cli as cli

    def interrupted(args):
        raise KeyboardInterrupt

    def failing(args):
        raise RuntimeError("the solver failed:\nmax steps")

    monkeypatch.setattr(cli, "cmd_simulate", interrupted)
    line = cli_fails(["simulate"], capsys, "interrupted", code=130)
    assert line.startswith("hrgjax simulate")
    monkeypatch.setattr(cli, "cmd_simulate", failing)
    cli_fails(["simulate"], capsys, "failed: the solver failed: max steps .*--debug", code=1)
    with pytest.raises(RuntimeError, match="solver failed"):
        cli.main(["simulate", "--debug"])


def test_cli_relax_widens_a_plausibility_range_for_the_run(tmp_path, capsys, monkeypatch):
    """No command could take a file beyond a plausibility range (a steady 9.8 g centrifuge
    hold, a shaker): `--relax QUANTITY=LOW,HIGH` widens it for that run only, before or
    after the command, and a 1 g log in m/s² is still refused without it."""
    import hrgjax.cli as cli

    rows = "".join(f"{i},20.0,0.0,0,0,9.8,0.0\n" for i in range(64))
    log = tmp_path / "hold.csv"
    log.write_text("time_s,temperature_c,table_rate_dps,accel_x_g,accel_y_g,accel_z_g,"
                   "wave_angle_deg\n" + rows)  # fmt: skip
    seen = []

    def loads(args):
        seen.append(len(hg.load(str(log))))
        return 0

    monkeypatch.setattr(cli, "cmd_simulate", loads)
    cli_fails(["simulate"], capsys, r"as 1 g written in m/s² has: .* \(a run that holds "
              r"9\.6–10\.0 g: --relax specific_force_g=LOW,HIGH takes it\)$")  # fmt: skip
    assert cli.main(["simulate", "--relax", "specific_force_g=-40,40"]) == 0
    assert seen == [64] and hg.plausible.RANGES["specific_force_g"][:2] == (-20.0, 20.0)
    # before the command too, and both together (review of eebf8fe: the subcommand's list
    # replaced the one given before it)
    assert cli.main(["--relax", "specific_force_g=-40,40", "simulate"]) == 0
    assert cli.main(["--relax", "specific_force_g=-40,40", "simulate", "--relax",
                     "temperature_c=-200,200"]) == 0  # fmt: skip
    assert seen == [64, 64, 64] and hg.plausible.RANGES["specific_force_g"][:2] == (-20.0, 20.0)
    cli_fails(
        ["simulate", "--relax", "specific_force=-1,1"],
        capsys,
        r"argument --relax: 'specific_force' is not a plausibility range; known: .*",
    )
    cli_fails(
        ["simulate", "--relax", "specific_force_g=40,-40"],
        capsys,
        r"argument --relax: 'specific_force_g=40,-40': give QUANTITY=LOW,HIGH",
    )


# --- fuzzing the loaders ----------------------------------------------------------------------

_FIELDS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(2**70), 2**70).map(str),
    st.sampled_from(["", " ", "nan", "1_0", "1e", "0x10", "1,5", '"', "a", "∞", "1.0e-3", "-0"]),
    st.text(max_size=6),
)
_NAMES = st.sampled_from(
    ["time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg", "amplitude", "note"]
)


def _check_outcome(path, tmp_dir):
    """Loaded and round-trips exactly, or a one-line ValueError naming the file."""
    try:
        data = hg.load(path, allow_extra=True)
    except ValueError as err:
        assert str(err).startswith(str(path)) or str(path) in str(err), err
        return "error"
    again = hg.load(data.save(os.path.join(tmp_dir, "again" + os.path.splitext(path)[1])),
                    allow_extra=True)  # fmt: skip
    assert again == data
    return "loaded"


@settings(
    max_examples=950, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    header=st.lists(_NAMES, min_size=1, max_size=7),
    rows=st.lists(st.lists(_FIELDS, min_size=0, max_size=8), max_size=6),
    prefix=st.sampled_from(["", "\ufeff", "# c\n"]),
)
def test_fuzzed_csv_loads_exactly_or_fails_clearly(tmp_path, header, rows, prefix):
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    path = tmp_path / "fuzz.csv"
    path.write_text(prefix + buf.getvalue(), encoding="utf-8")
    _check_outcome(str(path), str(tmp_path))


@settings(
    max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    n=st.integers(1, 5),
    dtypes=st.fixed_dictionaries(
        {
            k: st.sampled_from(["f8", "f4", "i8", "u8", "i2", "bool", "c16", "U3", "M8[s]"])
            for k in ("time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg")
        }
    ),  # fmt: skip
    seed=st.integers(0, 2**32 - 1),
    units=st.sampled_from([None, "s", "seconds since 2001-01-01", "K", "degC", "weeks since 1"]),
)
def test_fuzzed_netcdf_loads_exactly_or_fails_clearly(tmp_path, n, dtypes, seed, units):
    pytest.importorskip("h5netcdf", reason="netCDF needs the data extra")
    import xarray as xr

    rng = np.random.default_rng(seed)
    cols = {}
    for k, dt in dtypes.items():
        raw = rng.integers(-3, 1000, n) if dt[0] in "iuMb" else rng.normal(0, 100, n)
        cols[k] = np.sort(raw).astype(dt) if k == "time_s" and dt != "bool" else raw.astype(dt)
    attrs = {"time_s": {"units": units}} if units else {}
    ds = xr.Dataset({k: ("sample", v, attrs.get(k, {})) for k, v in cols.items()})
    path = tmp_path / "fuzz.nc"
    try:
        ds.to_netcdf(path, engine="h5netcdf")
    except Exception:  # a dtype h5netcdf cannot write: nothing to load
        return
    _check_outcome(str(path), str(tmp_path))


def test_no_command_writes_over_its_inputs_or_its_other_outputs(tmp_path, capsys):
    """Issue 44: `--plot S` naming the sections input, `--json X --write-sections X`, `--out`
    naming the data: refused before any work, the file left as it was."""
    sections = tmp_path / "sections.json"
    sections.write_text("{}")
    log = tmp_path / "imu.csv"
    log.write_text("t,gyr_x\n0,0\n")
    before = sections.read_bytes()
    cli_fails(["imu-calibrate", str(log), "--sections", str(sections), "--plot", str(sections)],
              capsys, r"--plot .* is also the input --sections")  # fmt: skip
    assert sections.read_bytes() == before
    out = tmp_path / "cal.json"
    cli_fails(["imu-calibrate", str(log), "--json", str(out), "--write-sections", str(out)],
              capsys, r"--write-sections .* is also the output --json")  # fmt: skip
    cli_fails(["correct", str(log), "--model", "m.eqx", "--out", str(log)], capsys,
              r"--out .* is also the input DATA")  # fmt: skip
    assert log.read_text() == "t,gyr_x\n0,0\n"


def test_physically_impossible_numbers_are_refused_with_a_hint():
    """Issue 44: −273 °C plans, kelvin temperature columns and radian wave angles are
    refused, naming the field (and the unit they look like); `plausible.relaxed` widens a
    range for a block of code."""
    t = np.arange(0.0, 60.0, 0.5)
    cols = dict(time_s=t, temperature_c=np.full(t.size, 20.0), table_rate_dps=np.full(t.size, 5.0),
                wave_angle_deg=-0.554 * 5.0 * t)  # fmt: skip
    hg.MeasuredData(cols)  # degrees, °C: fine
    with pytest.raises(ValueError, match=r"'temperature_c' = 293.15 .* look like kelvin"):
        hg.MeasuredData(cols | dict(temperature_c=np.full(t.size, 293.15)))
    with pytest.raises(ValueError, match=r"'wave_angle_deg' turns -0.0096.* radians"):
        hg.MeasuredData(cols | dict(wave_angle_deg=np.radians(cols["wave_angle_deg"])))
    # the wave turns −k_e × the table: a rate in rad/s, a table angle in radians, time in
    # ms, a wave 10× too large or a jump of degrees between samples cannot be (each passed)
    for bad, match in [
        (dict(table_rate_dps=np.full(t.size, np.radians(5.0))), r"turns -31.7.* table angle in "
         r"radians .* give 'table_rate_dps' in °/s"),
        (dict(table_angle_deg=np.radians(5.0 * t)), r"^column 'table_angle_deg' turns 0.01745 × "
         r"the integral .* radians"),
        (dict(table_rate_dps=np.full(t.size, np.radians(5.0)), table_angle_deg=5.0 * t),
         r"^column 'table_angle_deg' turns 57.3 × the integral .* 'table_rate_dps' is in rad/s"),
        (dict(time_s=1000 * t), r"turns -0.000554 × the table .* time stamps in milliseconds"),
        (dict(time_s=1000 * t, table_angle_deg=5.0 * t), r"^column 'table_angle_deg' turns 0.001 "
         r"× the integral .*: it looks like 'time_s' is in milliseconds \(÷ 1000\)$"),
        (dict(time_s=t / 60, table_angle_deg=5.0 * t), r"^column 'table_angle_deg' turns 60 × the"
         r" integral .*: it looks like 'time_s' is in minutes \(× 60\)$"),  # not rad/s (57.3)
        (dict(time_s=t / 60), r"turns -33.24 × the table .* table angle in radians would "
         r"\(-31.74\) or .* in minutes would \(-33.24\) .* give 'table_rate_dps' in °/s .* or "
         r"give 'time_s' in seconds$"),
        (dict(wave_angle_deg=-5.54 * 5.0 * t), r"turns -5.54 × the table .* check the units"),
        (dict(wave_angle_deg=cols["wave_angle_deg"] + np.where(t > 30, 10.0, 0.0)),
         r"^column 'wave_angle_deg' jumps \+8.615° from row 60 to row 61 of run 0"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=match):
            hg.MeasuredData(cols | bad)
    hour = np.r_[t, t + 3600.0]  # a run with an hour cut out: the wave drifted meanwhile
    hg.MeasuredData(dict(time_s=hour, temperature_c=np.full(hour.size, 20.0),
                         table_rate_dps=np.zeros(hour.size),
                         wave_angle_deg=-0.554 * 10.6 / 3600.0 * hour))  # fmt: skip
    held = np.zeros(t.size)  # force-to-rebalance holds the wave; a precession moves it
    hg.MeasuredData(cols | dict(wave_angle_deg=held, rebalance_rate_dps=np.full(t.size, 5.0)))
    hg.MeasuredData(cols | dict(wave_angle_deg=20.0 * t, precession_dps=np.full(t.size, 20.0)))
    hg.MeasuredData(cols | dict(wave_angle_deg=0.554 * 5.0 * t))  # the other sign: a convention
    with pytest.raises(ValueError, match=r"Plan.temperature_c = -273 .* -100 … 150 °C"):
        hg.calibration.static_plan((-273.0,), (0.0,), duration_s=10.0)
    with pytest.raises(ValueError, match=r"Plan.wave_angle0_deg = 1e\+300"):
        hg.calibration.static_plan((20.0,), (1e300,), duration_s=10.0)
    with pytest.raises(ValueError, match=r"Plan.duration_s = 1e\+09"):
        hg.calibration.static_plan((20.0,), (0.0,), duration_s=1e9)
    with pytest.raises(ValueError, match=r"Profile.temperature = nan|must be finite"):
        hg.Profile.static(10.0, np.nan)
    with hg.plausible.relaxed(temperature_c=(-200.0, 200.0)):
        hg.calibration.static_plan((-150.0,), (0.0,), duration_s=10.0)
    with pytest.raises(ValueError, match="outside the plausible range"):  # restored
        hg.calibration.static_plan((-150.0,), (0.0,), duration_s=10.0)


def test_rate_in_rad_per_s_is_refused_on_runs_shorter_than_a_radian():
    """Audit: a table rate in rad/s integrates to < 1 over a run shorter than 57.3°, and
    only runs whose table turned ≥ 1 in the file's units were read, so a 10-s run at 5 °/s
    written as 0.0873 loaded (calibrate then fitted a scale factor of 57.3). A run now counts
    too where its wave turns beyond any drift; a slow table under drift still loads."""
    t = np.arange(21) * 0.5
    k_e = 0.554
    cols = dict(time_s=t, temperature_c=np.full(t.size, 20.0), table_rate_dps=np.full(t.size, 5.0),
                wave_angle_deg=-k_e * 5.0 * t)  # fmt: skip
    hg.MeasuredData(cols)
    rads = dict(table_rate_dps=np.full(t.size, np.radians(5.0)))
    with pytest.raises(ValueError, match=r"^column 'wave_angle_deg' turns -31.7\d × the table "
                       r"over the rotation runs, as a table angle in radians would"):  # fmt: skip
        hg.MeasuredData(cols | rads)
    with pytest.raises(ValueError, match=r"^column 'table_angle_deg' turns 57.3 × the integral "
                       r".* 'table_rate_dps' is in rad/s$"):  # fmt: skip
        hg.MeasuredData(cols | rads | dict(table_angle_deg=5.0 * t))
    # the wave drifting at the most RANGES allows (100 °/h) on top: still −k_e, loads
    hg.MeasuredData(cols | dict(wave_angle_deg=-k_e * 5.0 * t + 100.0 / 3600.0 * t))
    # a table turning 0.5° under 50 °/h of drift: no run to read, no refusal
    hg.MeasuredData(cols | dict(table_rate_dps=np.full(t.size, 0.05),
                                wave_angle_deg=-k_e * 0.05 * t + 50.0 / 3600.0 * t))  # fmt: skip


def test_wave_angle_in_mechanical_degrees_is_named():
    """Audit (s30): a wave angle logged in mechanical degrees (the n = 2 pattern's angle,
    half the electrical one) turns −k_e/2 = −0.277 × the table and passed (the drifts then
    came out half-size). It is named where the ratio lies within 15 % of k_e/2 plus its own
    drift error; other gyros' gains load, and `relaxed(wave_table_ratio=…)` takes a gyro
    whose k_e truly is ≈ 0.28."""
    t = np.arange(0.0, 72.5, 0.5)  # one turn at 5 °/s
    cols = dict(time_s=t, temperature_c=np.full(t.size, 20.0), table_rate_dps=np.full(t.size, 5.0),
                wave_angle_deg=-0.554 * 5.0 * t)  # fmt: skip
    mech = r"^column 'wave_angle_deg' turns -0.277 × the table .* in mechanical degrees would "
    for gain in (0.277, -0.277, 0.25, 0.315):  # either sign (a convention), K ≈ 0.25–0.3
        with pytest.raises(ValueError, match=r"in mechanical degrees would \([−+]k_e/2 = -?0.277;"
                           r" .* must be in electrical degrees, 2× the mechanical angle .*: multiply "
                           r"it by 2 \(a gyro whose k_e truly is .*relaxed\(wave_table_ratio=…\)"
                           r" takes it\)$"):  # fmt: skip
            hg.MeasuredData(cols | dict(wave_angle_deg=-gain * 5.0 * t))
    for gain in (0.34, 0.4, 0.554, 0.8, 1.0, 1.108):  # micro-shells, a ring, a pendulum, 2·k_e
        hg.MeasuredData(cols | dict(wave_angle_deg=-gain * 5.0 * t))
    with hg.plausible.relaxed(wave_table_ratio=(0.05, 2.0)):  # a gyro whose k_e is 0.277
        data = hg.MeasuredData(cols | dict(wave_angle_deg=-0.277 * 5.0 * t))
    assert len(list(data.runs())) == 1  # its runs are not checked again outside the block
    with pytest.raises(ValueError, match=mech):
        hg.MeasuredData(cols | dict(wave_angle_deg=-0.277 * 5.0 * t))
    # a table at 0.05 °/s for 10 min: 100 °/h of drift could make the wave turn by twice
    # what the table does (error 200 %), so the ratio cannot tell mechanical from electrical
    slow = np.arange(0.0, 600.5, 0.5)
    hg.MeasuredData(dict(time_s=slow, temperature_c=np.full(slow.size, 20.0),
                         table_rate_dps=np.full(slow.size, 0.05),
                         wave_angle_deg=-0.277 * 0.05 * slow))  # fmt: skip
    with hg.plausible.relaxed(wave_table_ratio=(0.5, 0.6)):  # the range itself is relaxable
        with pytest.raises(ValueError, match=r"turns -0.8 × .* \|ratio\| in 0.5 … 0.6\): check"
                           r" .*relaxed\(wave_table_ratio=…\) widens it\)$"):  # fmt: skip
            hg.MeasuredData(cols | dict(wave_angle_deg=-0.8 * 5.0 * t))


def test_table_in_degrees_per_minute_and_wrapped_table_angles_are_named():
    """Audit (s30): a table rate in °/min (and its angle in arc-minutes) gives −k_e/60 =
    −0.009233, 4.5 % from a wave angle in radians (−0.009669), and only radians was named;
    a `table_angle_deg` wrapped to [0, 360) or (−180, 180] was "0 × the integral" with no
    word of the wrap."""
    t = np.arange(0.0, 120.0, 0.5)  # 600° at 5 °/s
    cols = dict(time_s=t, temperature_c=np.full(t.size, 20.0), table_rate_dps=np.full(t.size, 5.0),
                table_angle_deg=5.0 * t + 100.0, wave_angle_deg=-0.554 * 5.0 * t)  # fmt: skip
    hg.MeasuredData(cols)
    both = (r"radians would \(-0.009669\) or as a table rate in °/min \(and a table angle in "
            r"arc-minutes\) would \(-0.009233\) .*: give the wave angle in degrees \(np.degrees\) "
            r"or give 'table_rate_dps' in °/s \(÷ 60; 'table_angle_deg' in degrees\)$")  # fmt: skip
    per_min = dict(table_rate_dps=60.0 * cols["table_rate_dps"],
                   table_angle_deg=60.0 * cols["table_angle_deg"])  # fmt: skip
    with pytest.raises(ValueError, match=r"^column 'wave_angle_deg' turns -0.009233 × .*" + both):
        hg.MeasuredData(cols | per_min)
    with pytest.raises(ValueError, match=r"^column 'wave_angle_deg' turns -0.009669 × .*" + both):
        hg.MeasuredData(cols | dict(wave_angle_deg=np.radians(cols["wave_angle_deg"])))
    with pytest.raises(ValueError, match=r"^column 'table_angle_deg' turns 0.01667 × the integral"
                       r" .*: it looks like 'table_rate_dps' is in °/min \(÷ 60\)$"):  # fmt: skip
        hg.MeasuredData(cols | dict(table_rate_dps=per_min["table_rate_dps"]))
    for wrap, form in ((np.mod(cols["table_angle_deg"], 360.0), r"\[0, 360\)"),
                       ((cols["table_angle_deg"] + 180.0) % 360.0 - 180.0, r"\(−180, 180\]")):  # fmt: skip
        with pytest.raises(ValueError, match=r"^column 'table_angle_deg' steps -357.5° from row "
                           r"\d+ to row \d+ of run 0 \(times .* s\), -360° off the integral of "
                           rf"'table_rate_dps' over them: it looks wrapped to {form} .* must be "
                           r"unwrapped \(np.unwrap\(a, period=360.0\) run by run\)"):  # fmt: skip
            hg.MeasuredData(cols | dict(table_angle_deg=wrap))
        unwrapped = np.degrees(np.unwrap(np.radians(wrap)))
        hg.MeasuredData(cols | dict(table_angle_deg=unwrapped))  # the fix the message gives
    # a table at rest on 0°, its encoder flickering to 359.99: a wrap too (the windows'
    # table rate would read 360° a sample)
    rest = cols | dict(table_rate_dps=np.zeros(t.size), wave_angle_deg=np.zeros(t.size),
                       table_angle_deg=np.where(np.arange(t.size) % 7 == 3, 359.99, 0.0))  # fmt: skip
    with pytest.raises(ValueError, match=r"steps \+360° from row 2 to row 3 of run 0 .* wrapped "
                       r"to \[0, 360\)"):  # fmt: skip
        hg.MeasuredData(rest)


def test_impossible_bench_plans_are_refused():
    """Issue 44: a bench starting at NaN °C, a 1e9-h budget, a segment at +300 °C."""
    from hrgjax.calibration import design

    with pytest.raises(ValueError, match="BenchModel.start_temperature_c must be finite"):
        design.BenchModel(start_temperature_c=float("nan"))
    with pytest.raises(
        ValueError, match=r"budget_h \(as seconds\) = 3.6e\+12 .*30 days|2.592e\+06"
    ):
        design.design(1e9)
    seg = dict(kind="static", temperature_c=300.0, wave_angle_deg=0.0,
               duration_s=60.0)  # fmt: skip
    with pytest.raises(ValueError, match=r"BenchPlan.temperature_c = 300 .* kelvin"):
        design.BenchPlan.from_segments([seg])


def test_values_swapped_in_after_construction_are_checked_where_simulate_starts():
    """Issue 44: `eqx.tree_at` (as sweeps do) skips the constructor's checks; `simulate`
    names the field itself. Allan: complex samples and negative τ are refused."""
    g = hg.presets.tvg3_like()
    prof = hg.Profile.static(5.0, 20.0)
    for where, value, match in (
        (lambda g: g.noise.angle_random_walk, -1e-6, r"gyro.noise.angle_random_walk = -1e-06"),
        (lambda g: g.noise.angle_white, np.nan, r"gyro.noise.angle_white = nan"),
        (lambda g: g.resonator.k_e, np.nan, r"gyro.resonator.k_e|finite"),
        (lambda g: g.resonator.k_e, 55.4, r"gyro.resonator.k_e = 55.4 .*must be in \(0, 1\]"),
    ):
        with pytest.raises(ValueError, match=match):
            hg.simulate(eqx.tree_at(where, g, value), prof, key=jax.random.key(0), dt_out=1.0)
    with pytest.raises(ValueError, match="y holds complex numbers"):
        hg.allan.deviation(np.ones(100) * (1 + 1j), rate_hz=1.0)
    with pytest.raises(ValueError, match=r"taus must be > 0 s; got -1"):
        hg.allan.deviation(np.ones(100), rate_hz=1.0, taus=[-1.0, 2.0])


def test_allan_refuses_a_bool_sample_rate():
    """Audit: `identify_noise(y, True)` took True as 1 Hz (a bool is a numbers.Real)."""
    y = np.random.default_rng(0).normal(size=256)
    for call in (hg.allan.deviation, hg.allan.identify_noise):
        with pytest.raises(ValueError, match=r"^rate_hz must be a positive sample rate \[Hz\]; "
                           r"got True$"):  # fmt: skip
            call(y, True)
    with pytest.raises(
        ValueError, match=r"^rate_hz must be a positive sample rate \[Hz\]; got True$"
    ):
        hg.allan.to_uniform(np.arange(256.0), y, rate_hz=True)


@pytest.mark.parametrize(
    "text,match",
    [
        ('{"a": 1e400}', r"1e400 is beyond float64's range"),
        ('{"a": 123456789012345678901234}', r"integer 1234567890123456789012.* too large"),
        ('{"a": NaN}', r"NaN is not a JSON number"),
        ("[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ],
)
def test_json_numbers_python_cannot_hold_are_named(tmp_path, text, match):
    """Issue 44: plan, sections and calibration JSON share one reader; what Python's own
    json would turn into inf, a bignum or a RecursionError is a one-line error naming the
    file."""
    from hrgjax._io import read_json

    f = tmp_path / "x.json"
    f.write_text(text)
    with pytest.raises(ValueError, match=match) as err:
        read_json(f)
    assert str(f) in str(err.value)


def test_a_header_only_imu_csv_is_named_without_numpy_warnings(tmp_path, recwarn):
    f = tmp_path / "h.csv"
    f.write_text("t,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z\n")
    with pytest.raises(ValueError, match=r"h.csv: gyro has 0 samples"):
        hg.imu.load(f, {"gyro": ["gyr_x", "gyr_y", "gyr_z"], "accel": ["acc_x", "acc_y", "acc_z"]},
                    {"gyro": "deg/s", "accel": "m/s^2"}, rate_hz=100.0)  # fmt: skip
    assert not [w for w in recwarn if "numpy" in w.filename or "loadtxt" in str(w.message)]


def test_plans_too_large_to_hold_are_refused_before_any_work():
    """Issue 44: the size is estimated from the plan before anything is allocated."""
    from hrgjax.calibration import design

    gyro = hg.presets.tvg3_like(noise=False)
    seg = dict(kind="static", temperature_c=20.0, wave_angle_deg=0.0, duration_s=3600.0)
    plan = design.BenchPlan.from_segments([seg] * 20_000)  # 20 000 h at 1 s: 7.2e7 samples
    with pytest.raises(ValueError, match=r"simulate_plan: 20000 runs hold 7.2e\+07 output "
                                         r"samples \(≈ 6.71 GiB"):  # fmt: skip
        design.simulate_plan(gyro, plan)
    big = hg.calibration.static_plan(tuple(np.linspace(-40.0, 60.0, 1000)), (0.0,),
                                     duration_s=86400.0, dt_out=1.0)  # fmt: skip
    with pytest.raises(ValueError, match=r"run_plan: 1000 runs hold 8.64e\+07"):
        hg.calibration.run_plan(gyro, big)


def test_a_failing_plan_names_its_point_and_segment():
    """Issue 44: a solver failure inside a vmapped chunk names the plan point or the bench
    segment (an absurd nonlinearity makes every solve give up)."""
    from hrgjax.calibration import design

    bad = eqx.tree_at(lambda g: g.resonator.chi, hg.presets.tvg3_like(noise=False), 1e12)
    plan = hg.calibration.static_plan((0.0, 20.0), (30.0,), duration_s=20.0)
    with pytest.raises(RuntimeError, match=r"^run_plan: point \d \(\d+ °C, 30°, 0 °/s\) failed: "
                                           r"the solver failed"):  # fmt: skip
        hg.calibration.run_plan(bad, plan)
    seg = dict(kind="rotation", temperature_c=20.0, wave_angle_deg=0.0, rate_dps=5.0,
               duration_s=20.0)  # fmt: skip
    with pytest.raises(RuntimeError, match=r"^simulate_plan: segment 0 \(rotation, 20 °C, 5 °/s, "
                                           r"20 s\) failed: the solver failed"):  # fmt: skip
        design.simulate_plan(bad, design.BenchPlan.from_segments([seg]))


def test_discover_refuses_a_log_whose_wave_angle_never_moves():
    """Issue 44: an all-constant log gave LAPACK's 'DLASCL parameter number 4' lines and
    'SVD did not converge'; now one line before any fit."""
    from hrgjax.discovery import discover

    t = np.arange(0.0, 60.0, 1.0)
    cols = {k: [] for k in ("time_s", "run", "temperature_c", "table_rate_dps", "wave_angle_deg")}
    for run in range(12):
        for k, v in (("time_s", t), ("run", run), ("temperature_c", 20.0),
                     ("table_rate_dps", 0.0), ("wave_angle_deg", 10.0)):  # fmt: skip
            cols[k].append(np.broadcast_to(v, t.shape))
    data = hg.MeasuredData({k: np.concatenate(v) for k, v in cols.items()})
    with pytest.raises(ValueError, match="'wave_angle_deg' never changes within a run"):
        discover(data)


# --- issue 44: fuzzed plan, sections and calibration files and IMU CSVs ----------------------
#
# Each file is a valid document with one mutation; the outcome must be "loaded" or a one-line
# ValueError naming the file, with no warning printed (benchmarks/fuzz_loaders.py runs the same
# families by the thousand: --plans, --sections, --calibrations, --imu).

_JSON_JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**18), 10**18),
    st.floats(allow_nan=False, allow_infinity=False),
    st.sampled_from(["", "abc", "1.5", "nan", "NaN", "inf", "-1", "0x1f"]),
    st.lists(st.lists(st.integers(-3, 3), max_size=2), max_size=3),
    st.dictionaries(st.sampled_from(["start", "end", "x"]), st.integers(-3, 3), max_size=2),
)
_RAW_JSON = ["NaN", "Infinity", "-Infinity", "1e400", "-1e400", "123456789012345678901234",
             "[" * 3000 + "]" * 3000, "[" * 200 + "1" + "]" * 200, "1E+308", "-0"]  # fmt: skip
_JSON_OPS = ["replace", "drop", "duplicate", "rename", "wrap", "negate", "huge", "text", "raw"]


def _mutated_json(doc, path, op, value, raw):
    """`doc`'s JSON text after `op` at the node `path` leads to (each index picks a key or an
    item, modulo their number; an empty path or a leaf stops the walk: `op` then replaces the
    whole document by `value`, a wrong type at the top level)."""
    import copy
    import json

    doc = copy.deepcopy(doc)
    parent, key, node = None, None, doc
    for i in path:
        if not isinstance(node, dict | list) or not node:
            break
        key = list(node)[i % len(node)] if isinstance(node, dict) else i % len(node)
        parent, node = node, node[key]
    if parent is None:
        return json.dumps(value)
    if op == "replace":
        parent[key] = value
    elif op == "drop":
        del parent[key]
    elif op == "duplicate":  # a list item twice, a key twice (the later one wins in JSON)
        if isinstance(parent, list):
            parent.insert(key, copy.deepcopy(node))
        else:
            text = json.dumps(parent)
            parent.clear()
            parent["\x00DUP\x00"] = None
            return json.dumps(doc).replace(
                '{"\\u0000DUP\\u0000": null}', text[:-1] + f", {json.dumps(key)}: "
                f"{json.dumps(value)}}}" if len(text) > 2 else text)  # fmt: skip
    elif op == "rename" and isinstance(parent, dict):
        parent[key + "_"] = parent.pop(key)
    elif op == "wrap":
        parent[key] = [node]
    elif op == "negate":
        is_number = isinstance(node, int | float) and not isinstance(node, bool)
        parent[key] = -node if is_number else -1
    elif op == "huge":
        parent[key] = 1e308 if isinstance(node, float) else 10**18
    elif op == "text":
        parent[key] = str(node)
    elif op == "raw":
        parent[key] = "\x00RAW\x00"
        return json.dumps(doc).replace('"\\u0000RAW\\u0000"', raw)
    return json.dumps(doc)


def _loaded_or_named(load, path):
    """Call `load(path)`: it loads, or raises a one-line ValueError naming `path`; no
    other exception and no warning."""
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            load(path)
        except ValueError as err:
            text = str(err)
            assert str(path) in text and "\n" not in text, text
    assert not caught, [f"{w.category.__name__}: {w.message}" for w in caught]


@pytest.fixture(scope="module")
def documents():
    """Valid plan, sections and calibration documents (one small Ferraris fit, reused)."""
    from hrgjax.calibration import design
    from hrgjax.imu.sections import sections_to_json

    segs = design.seed_bench_plan(quick=True).segments()[::19]
    segs.append({"kind": "ramp", "temperature_start_c": 20.0, "temperature_end_c": 25.0,
                 "wave_angle_deg": 10.0, "rate_dps": 5.0, "duration_s": 600.0})  # fmt: skip
    plan = design.plan_to_json(
        design.BenchPlan.from_segments(segs),
        resolution={"temperature_c": 0.1, "wave_angle_deg": 0.1, "duration_s": 1.0},
    )
    truth = hg.imu.ImuCalibration.known(gyro_bias=np.array([0.01, -0.02, 0.005]))
    data, sections = hg.imu.ferraris_session(
        truth, jax.random.key(0), rate_hz=20.0, repeats=2, static_s=3.0
    )
    cal = hg.imu.ferraris(data, sections)
    return {"plan": plan, "sections": sections_to_json(sections), "n": len(data),
            "calibration": cal.to_json()}  # fmt: skip


def _json_loader(kind, n):
    from hrgjax.calibration.design import load_plan

    return {
        "plan": load_plan,
        "sections": lambda p: hg.imu.parse_sections(p, n),
        "calibration": hg.imu.load_calibration,
    }[kind]


def test_the_valid_documents_load(documents, tmp_path):
    import json

    for kind in ("plan", "sections", "calibration"):
        p = tmp_path / f"{kind}.json"
        p.write_text(json.dumps(documents[kind]), encoding="utf-8")
        _json_loader(kind, documents["n"])(p)


@pytest.mark.parametrize("kind", ["plan", "sections", "calibration"])
@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    path=st.lists(st.integers(0, 200), max_size=4),
    op=st.sampled_from(_JSON_OPS),
    value=_JSON_JUNK,
    raw=st.sampled_from(_RAW_JSON),
)
def test_fuzzed_json_files_load_or_name_the_file(documents, tmp_path, kind, path, op, value, raw):
    p = tmp_path / f"{kind}.json"
    p.write_text(_mutated_json(documents[kind], path, op, value, raw), encoding="utf-8")
    _loaded_or_named(_json_loader(kind, documents["n"]), p)


IMU_HEADER = ["time_s", "gx", "gy", "gz", "ax", "ay", "az", "temperature_c"]
IMU_COLUMNS = {"time": "time_s", "gyro": ["gx", "gy", "gz"], "accel": ["ax", "ay", "az"],
               "temperature": "temperature_c"}  # fmt: skip
_IMU_TEXT = ["", " ", "abc", "nan", "inf", "-inf", "1_000", "1,000", "1e", "1e400", "1e308",
             "-1e308", "1e-320", "0x1f", "99999999999999999999999", "True", "½", "١٢", '"',
             "\x00", "2024-01-01", "0"]  # fmt: skip
_IMU_FIELDS = st.one_of(
    st.sampled_from(_IMU_TEXT),
    st.floats().map(repr),
    st.integers(-(10**30), 10**30).map(str),
)


def _imu_rows(n):
    rng = np.random.default_rng(0)
    rows = []
    for i in range(n):
        g = rng.normal(0, 0.01, 3)
        a = np.array([0.0, 0.0, 9.81]) + rng.normal(0, 0.01, 3)
        rows.append([repr(i * 0.01), *map(repr, g.tolist()), *map(repr, a.tolist()), "20.5"])
    return rows


def _is_float(text):
    try:
        float(text)
    except ValueError:
        return False
    return True


@settings(
    max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    n=st.integers(0, 8),
    edits=st.lists(st.tuples(st.integers(0, 7), st.integers(0, 7), _IMU_FIELDS), max_size=3),
    header=st.one_of(
        st.none(), st.tuples(st.integers(0, 7), st.sampled_from(["drop", "dup", "typo"]))
    ),
    cut=st.one_of(st.none(), st.tuples(st.integers(0, 7), st.integers(0, 9))),
    scale=st.one_of(st.none(), st.tuples(st.integers(0, 7), st.sampled_from([1e306, 1e-320]))),
    units=st.sampled_from([{"gyro": "rad/s", "accel": "m/s^2"}, {"gyro": "deg/s", "accel": "g"}]),
    truncate=st.one_of(st.none(), st.integers(0, 800)),
    no_time=st.booleans(),
)
def test_fuzzed_imu_csv_loads_or_names_the_file(
    tmp_path, n, edits, header, cut, scale, units, truncate, no_time
):
    """Text, empty fields, huge or tiny values, missing, duplicated or misspelt columns,
    short or long rows, a truncated file, no time column (rate_hz given)."""
    rows = _imu_rows(n)
    names = list(IMU_HEADER)
    for r, c, text in edits:
        if rows:
            rows[r % len(rows)][c] = text
    if header is not None:
        c, how = header
        if how == "drop":
            names.pop(c)
        else:
            names[c] = names[(c + 1) % 8] if how == "dup" else names[c] + "x"
    if cut is not None and rows:
        r, k = cut
        rows[r % len(rows)] = (rows[r % len(rows)] + ["1"])[:k]
    if scale is not None:
        c, factor = scale
        for row in rows:
            if c < len(row) and _is_float(row[c]):
                with np.errstate(all="ignore"):
                    row[c] = repr(float(row[c]) * factor)
    text = ",".join(names) + "\n" + "".join(",".join(r) + "\n" for r in rows)
    blob = text.encode("utf-8")[:truncate]
    p = tmp_path / "imu.csv"
    p.write_bytes(blob)
    columns = {k: v for k, v in IMU_COLUMNS.items() if not (no_time and k == "time")}
    _loaded_or_named(
        lambda path: hg.imu.load(path, columns, units, rate_hz=100.0 if no_time else None), p
    )


# what the fuzzing found (issue 44), each a one-line ValueError naming the file and the field


def _imu_file(tmp_path, row1="0.01,0.01,0,0,0,0,9.81", times=None):
    n = 4 if times is None else len(times)
    rows = [f"{i * 0.01 if times is None else times[i]},0.01,0,0,0,0,9.81" for i in range(n)]
    rows[1] = row1 if times is None else rows[1]
    return _csv(tmp_path, "time_s,gx,gy,gz,ax,ay,az\n" + "\n".join(rows) + "\n", "imu.csv")


@pytest.mark.parametrize(
    "row1,times,units,match",
    [  # "1_000": Python's float() reads it, the CSV reader does not: was a bare StopIteration
        ("0.01,1_000,0,0,0,0,9.81", None, "m/s^2", "column 'gx' row 1 .*'1_000' is not a number"),
        # 1e308 g is beyond float64 in m/s²: was NumPy's overflow warning, then 'not finite'
        ("0.01,0.01,0,0,0,0,1e308", None, "g", "accel row 1.*axis z: 1e\\+308 g is beyond"),
        # time steps of 1e-320 s: was loaded at 'inf Hz'
        (None, [0, 1e-320, 2e-320, 3e-320], "m/s^2", "time: the step .* no finite"),
        # steps beyond 1.8e308 s: was NumPy's overflow warning
        (None, [-1e308, 1e308], "m/s^2", "time: the step inf s"),
    ],
)
def test_imu_csv_fields_found_by_fuzzing_are_named(tmp_path, recwarn, row1, times, units, match):
    p = _imu_file(tmp_path, row1, times)
    cols = {"time": "time_s", "gyro": ["gx", "gy", "gz"], "accel": ["ax", "ay", "az"]}
    with pytest.raises(ValueError, match=match) as err:
        hg.imu.load(p, cols, {"gyro": "rad/s", "accel": units}, check_units=False)
    assert str(err.value).startswith(str(p)) and "\n" not in str(err.value)
    assert not recwarn.list, [str(w.message) for w in recwarn.list]


@pytest.mark.parametrize(
    "kind,edit,match",
    [  # float() read these as numbers: "inf" gave an infinite settle time, true gave 1.0
        ("plan", ("bench", "settle_s", "inf"), "'bench': 'settle_s' must be a finite number"),
        ("plan", ("bench", "slew_c_per_min", True), "'bench': 'slew_c_per_min' must be a finite"),
        ("plan", ("bench", "reposition_s", "60"), "'bench': 'reposition_s' must be a finite"),
        # a matrix of booleans or text read as 1.0 / 1.5
        ("calibration", ("accel_matrix", 0, [True, False, False]), "'accel_matrix' must be .*boo"),
        ("calibration", ("gyro_bias_rad_s", 1, "0.01"), "'gyro_bias_rad_s' must be .*got text"),
        ("calibration", ("noise_std", "gyro_rad_s", [True, True, True]), "'noise_std' must be"),
        # any value was turned into text by str()
        ("calibration", ("sigma_source", None, [1, 2]), "'sigma_source' must be text"),
    ],
)
def test_json_fields_found_by_fuzzing_are_named(documents, tmp_path, kind, edit, match):
    import copy
    import json

    doc = copy.deepcopy(documents[kind])
    field, key, value = edit
    if key is None:
        doc[field] = value
    else:
        doc[field][key] = value
    p = tmp_path / f"{kind}.json"
    p.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ValueError, match=match) as err:
        _json_loader(kind, documents["n"])(p)
    assert str(err.value).startswith(str(p)) and "\n" not in str(err.value)


def test_gnss_rate_that_is_not_a_number_and_a_lever_arm_beyond_a_vehicle_are_named():
    """`Gnss(rate_hz=None)` raised `TypeError: must be real number, not NoneType` (no field);
    `Gnss(lever_arm=1e6)` passed (fixes 1000 km from the vehicle): a lever arm beyond 100 m
    on an axis, or 1.5 m typed in cm, is refused naming the axis, the units and `relaxed`."""
    from hrgjax.ins.gnss import Gnss

    for bad in (None, "1", True, 0.0, float("nan")):
        with pytest.raises(ValueError, match=r"^Gnss.rate_hz must be a number > 0 \[Hz\]; got "):
            Gnss(rate_hz=bad)
    tail = r" is outside the plausible range -100 … 100 m, body FRD — cm → ÷100; mm → ÷1000 "
    for arm, where in ((1e6, "1e\\+06 at index 0"), ((1.5, -0.3, -150.0), "-150 at index 2")):
        with pytest.raises(ValueError, match=rf"^Gnss.lever_arm = {where}{tail}\(hrgjax.plausible"
                           r"\.relaxed\(gnss_lever_arm_m=…\) widens it\)$"):  # fmt: skip
            Gnss(lever_arm=arm)
    np.testing.assert_array_equal(Gnss(lever_arm=(99.0, -3.0, 0.0)).lever_arm, [99.0, -3.0, 0.0])
    with hg.plausible.relaxed(gnss_lever_arm_m=(-1e3, 1e3)):  # a lever arm as given
        np.testing.assert_array_equal(Gnss(lever_arm=(0.0, 0.0, -150.0)).lever_arm, [0, 0, -150])


def test_mechanize_every_is_shown_as_given():
    """Audit: `mechanize(…, every="2")` said "got 2" (the quotes lost: it looked valid)."""
    from hrgjax import ins

    n0 = ins.NavState.from_euler(0.5, 0.1, 0.0, np.zeros(3), 0.0, 0.0, 0.0)
    z = np.zeros((10, 3))
    for bad, shown in (("2", "'2'"), (2.5, "2.5"), (np.arange(10), "ndarray of shape (10,)")):
        with pytest.raises(ValueError) as err:
            ins.mechanize(n0, z, z, 0.01, every=bad)
        assert str(err.value).startswith(
            f"every must be a positive divisor of the 10 intervals; got {shown}"
        ), str(err.value)
