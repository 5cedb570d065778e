"""HRG compensators and their calibrated temperature domain (audit of the compensators beyond
their calibration): the MLP refuses a bench at one temperature; every fit records its
temperature range; `correct` applies every compensator beyond it by default and counts the
samples outside, or passes them through uncompensated (bit for bit the raw output) with
`extrapolate=False`; saved files keep the range and older files load without it."""

import dataclasses
import json
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import closed_form_session

import hrgjax as hg
from hrgjax.calibration import (
    FourierCompensator,
    MLPCompensator,
    NoCompensation,
    PhysicalCompensator,
    PrecessionCompensator,
    export_json,
    load_compensator,
    load_json,
    reduce,
    save_compensator,
)
from hrgjax.calibration.compensators import DOMAIN_MARGIN_C, Corrected
from hrgjax.calibration.physical import initial_values

pytestmark = pytest.mark.filterwarnings(  # every test here extrapolates on purpose; the
    "ignore::hrgjax.calibration.TemperatureDomainWarning"  # warning: test_session_constants
)

CAL_TEMPS = (0.0, 20.0, 40.0)
TEST_TEMPS = (-20.0, 20.0, 60.0)  # −20 and +60 °C lie outside 0 … 40 °C (± 1 °C)


@pytest.fixture(scope="module")
def calibration():
    return closed_form_session(temps=CAL_TEMPS, duration_s=20.0)


@pytest.fixture(scope="module")
def test_session():
    return closed_form_session(temps=TEST_TEMPS, duration_s=20.0)


@pytest.fixture(scope="module")
def fitted(calibration):
    windows = reduce(calibration)
    return {
        "fourier": FourierCompensator(temperature_degree=1).fit(windows),
        "mlp": MLPCompensator(steps=30, drift_width=4, sf_width=3).fit(
            windows, key=jax.random.key(0)
        ),
    }


@pytest.fixture(scope="module")
def raw(test_session):
    return NoCompensation().correct(test_session)


def _outside(data):
    """Independent truth: the samples whose temperature the session put outside 0 … 40 °C."""
    return np.isin(data["temperature_c"], [-20.0, 60.0])


def test_mlp_at_one_temperature_is_refused():
    """Audit item 1: at one level the temperature input never moves and its weights keep
    their random start (1 °C away the rotation error was 60–200× the in-range one)."""
    one = closed_form_session(temps=(20.0,), duration_s=20.0)
    with pytest.raises(ValueError, match=r"^MLPCompensator.fit needs at least 2 distinct "
                       r"temperatures in the calibration data's static runs; got 1 \(\+20\.0 "
                       r"°C"):  # fmt: skip
        MLPCompensator(steps=5).fit(one, key=jax.random.key(0))
    # static runs at two levels, rotations at one: the scale-factor network is refused too
    two = closed_form_session(temps=(0.0, 20.0), duration_s=20.0)
    keep = (two["table_rate_dps"] == 0) | (two["temperature_c"] == 20.0)
    rot_one = hg.MeasuredData({k: v[keep] for k, v in two.columns.items()})
    with pytest.raises(ValueError, match=r"^MLPCompensator.fit needs at least 2 .* rotation "
                       r"runs; got 1 "):  # fmt: skip
        MLPCompensator(steps=5).fit(rot_one, key=jax.random.key(0))


def test_fits_record_the_calibrated_temperature_range(fitted):
    for name, comp in fitted.items():
        assert comp.temperature_range == (0.0, 40.0)
        assert comp.n_temperature_levels == 3
        assert comp.calibrated_range == (0.0, 40.0)
        assert comp.extrapolates, name  # the default: applied beyond, counted
    assert FourierCompensator().extrapolates  # the seed's base algorithm: constant in T
    assert PhysicalCompensator().extrapolates
    assert PrecessionCompensator().extrapolates  # held at its end temperatures


@pytest.mark.parametrize("which", ["fourier", "mlp"])
def test_samples_out_of_range_are_counted_and_can_pass_through(fitted, test_session, raw, which):
    comp = fitted[which]
    default = comp.correct(test_session)  # applied beyond its range, and counted
    assert default.extrapolated and default.n_out_of_range == 2 * 2 * 6 * 41
    out = comp.correct(test_session, extrapolate=False)
    outside = _outside(test_session)
    assert isinstance(out, Corrected) and isinstance(out, hg.MeasuredData)
    assert set(out.names) == set(test_session.names) | {"rate_corrected_dps",
                                                         "angle_corrected_deg"}  # fmt: skip
    assert out.n_out_of_range == int(outside.sum()) == 2 * 2 * 6 * 41
    np.testing.assert_array_equal(out.in_range, ~outside)
    assert out.out_of_range_by_temperature() == {-20.0: 492, 60.0: 492}
    assert out.temperature_range == (0.0, 40.0) and not out.extrapolated
    for col in ("rate_corrected_dps", "angle_corrected_deg"):
        np.testing.assert_array_equal(out[col][outside], raw[col][outside])  # bit for bit
    # extrapolate=True compensates them (as before); inside nothing changes
    ex = comp.correct(test_session, extrapolate=True)
    assert ex.extrapolated and ex.n_out_of_range == out.n_out_of_range
    np.testing.assert_array_equal(default["angle_corrected_deg"], ex["angle_corrected_deg"])
    np.testing.assert_array_equal(ex["angle_corrected_deg"][~outside],
                                  out["angle_corrected_deg"][~outside])  # fmt: skip
    assert np.all(ex["rate_corrected_dps"][outside] != raw["rate_corrected_dps"][outside])
    # the margin widens the range: 20 °C of it takes −20 and +60 °C in
    wide = comp.correct(test_session, margin_c=20.0)
    assert wide.n_out_of_range == 0
    np.testing.assert_array_equal(wide["angle_corrected_deg"], ex["angle_corrected_deg"])


def test_precession_compensator_holds_beyond_its_temperatures_and_counts(test_session, raw):
    coef = jnp.zeros((2, 5)).at[:, 0].set(jnp.array([1e-5, 2e-5])).at[:, 1].set(3e-6)
    comp = eqx.tree_at(lambda c: (c.drift_coef, c.gain_coef),
                       PrecessionCompensator(temperatures_c=(0.0, 40.0)),
                       (coef, jnp.ones((2, 5))), is_leaf=lambda x: x is None)  # fmt: skip
    out = comp.correct(test_session, extrapolate=False)
    outside = _outside(test_session)
    assert comp.calibrated_range == (0.0, 40.0) and out.n_out_of_range == int(outside.sum())
    np.testing.assert_array_equal(out["angle_corrected_deg"][outside],
                                  raw["angle_corrected_deg"][outside])  # fmt: skip
    held = comp.correct(test_session)  # the default (and the old behaviour): held beyond
    assert held.extrapolated and held.n_out_of_range == out.n_out_of_range
    assert np.all(held["angle_corrected_deg"][outside][1::41] != 0.0)
    assert np.all(held["rate_corrected_dps"][outside] != raw["rate_corrected_dps"][outside])


def test_physical_model_extrapolates_and_counts(calibration, test_session):
    values = jnp.asarray(initial_values(reduce(calibration, window_s=10.0), 0.554))
    n = values.shape[0]
    comp = PhysicalCompensator(values=values, covariance=jnp.eye(n),
                               temperature_range=(0.0, 40.0), n_temperature_levels=3)  # fmt: skip
    before = dataclasses.replace(comp, temperature_range=None, n_temperature_levels=None)
    out, old = comp.correct(test_session), before.correct(test_session)
    assert out.extrapolated and out.n_out_of_range == int(_outside(test_session).sum())
    assert old.n_out_of_range == 0 and old.temperature_range is None
    for col in ("rate_corrected_dps", "angle_corrected_deg"):
        np.testing.assert_array_equal(out[col], old[col])  # unchanged: it extrapolates
    passed = comp.correct(test_session, extrapolate=False)
    np.testing.assert_array_equal(passed["angle_corrected_deg"][_outside(test_session)],
                                  NoCompensation().correct(test_session)["angle_corrected_deg"][
                                      _outside(test_session)])  # fmt: skip


def test_saved_files_keep_the_range_and_older_files_load_without_it(fitted, tmp_path,
                                                                     test_session):  # fmt: skip
    for name, comp in fitted.items():
        back = load_compensator(save_compensator(comp, tmp_path / f"{name}.eqx"))
        assert back.temperature_range == (0.0, 40.0) and back.n_temperature_levels == 3
        again = load_json(export_json(comp, tmp_path / f"{name}.json"))
        assert again.temperature_range == (0.0, 40.0)
        doc = json.loads((tmp_path / f"{name}.json").read_text())
        assert doc["temperature_domain"]["range_c"] == [0.0, 40.0]
        # a file written before the range was recorded: no key in the header
        old = dataclasses.replace(comp, temperature_range=None, n_temperature_levels=None)
        path = save_compensator(old, tmp_path / f"{name}_old.eqx")
        with open(path, "rb") as fh:
            header = json.loads(fh.readline())
        assert "temperature_range" not in header["hyper"]
        loaded = load_compensator(path)
        assert loaded.temperature_range is None and loaded.calibrated_range is None
        out = loaded.correct(test_session)  # behaves as before: every sample compensated
        assert out.n_out_of_range == 0
        np.testing.assert_array_equal(
            out["angle_corrected_deg"],
            comp.correct(test_session, extrapolate=True)["angle_corrected_deg"],
        )


@pytest.mark.parametrize("which", ["fourier", "mlp"])
def test_pointwise_laws_warn_beyond_the_range_as_correct_does(fitted, which):
    """`drift_dph` and `scale_factor_at` extrapolated silently where `correct` warned: they
    now warn the same `TemperatureDomainWarning` (count, where, at the caller's line), not
    within the range ± 1 °C, not with `warn=False`; the values are the same either way."""
    comp = fitted[which]
    who = type(comp).__name__
    theta, temp = np.array([0.0, 30.0, 60.0, -45.0]), np.array([-20.0, 41.0, 60.0, 60.0])
    for method in ("drift_dph", "scale_factor_at"):
        law = getattr(comp, method)
        with pytest.warns(hg.calibration.TemperatureDomainWarning) as caught:
            values = law(theta, temp)
        assert len(caught) == 1 and caught[0].filename == __file__
        assert str(caught[0].message) == (
            f"{who}.{method}: 3 of 4 points outside the calibrated temperature range "
            "+0.0 … +40.0 °C (± 1 °C): 1 at -20 °C, 2 at +60 °C — extrapolated "
            "(warn=False: no warning)"
        )
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            np.testing.assert_array_equal(law(theta, temp, warn=False), values)
            law(theta, np.array([-1.0, 0.0, 40.0, 41.0]))  # within the margin: no warning
            law(0.0, 20.0)
        with pytest.raises(ValueError, match=rf"^{who}\.{method}: warn must be True or False; "
                           "got 'no'$"):  # fmt: skip
            law(theta, temp, warn="no")
    unknown = dataclasses.replace(comp, temperature_range=None)  # a file saved before it
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        unknown.drift_dph(theta, temp)


def test_bad_domain_arguments_are_refused_in_one_line(fitted, test_session):
    comp = fitted["fourier"]
    with pytest.raises(ValueError, match=r"^FourierCompensator: margin_c must be a finite "
                       r"number ≥ 0 \[°C\]; got -1\.0$"):  # fmt: skip
        comp.correct(test_session, margin_c=-1.0)
    with pytest.raises(ValueError, match=r"^extrapolate must be True, False or None"):
        comp.correct(test_session, extrapolate="yes")
    with pytest.raises(ValueError, match=r"^temperature_range must be \(T_min, T_max\) \[°C\]"):
        FourierCompensator(temperature_range=(40.0, 0.0))


def test_cli_says_how_many_samples_lie_outside(fitted, test_session, tmp_path, capsys):
    from hrgjax.cli import main

    data = test_session.save(tmp_path / "test.csv")
    model = save_compensator(fitted["mlp"], tmp_path / "m.eqx")
    fourier = save_compensator(fitted["fourier"], tmp_path / "f.eqx")
    old = save_compensator(dataclasses.replace(fitted["mlp"], temperature_range=None,
                                               n_temperature_levels=None),
                           tmp_path / "old.eqx")  # fmt: skip
    capsys.readouterr()
    argv = ["correct", data, "--model", model, "--out", str(tmp_path / "c.csv"), "--no-angles",
            "--no-extrapolate", "--json", str(tmp_path / "c.json")]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    # the offset and tables are the compensated runs' alone: the runs at +20 °C (in range), as
    # the API gives them — passed-through runs at −20 and +60 °C would pull the offset raw
    assert "run(s) with samples outside it are left out of the offset" in out
    from hrgjax.calibration import compare_corrected

    corrected = fitted["mlp"].correct(test_session)
    inside = corrected.in_range
    api = compare_corrected({"MLP": hg.MeasuredData(
        {k: v[inside] for k, v in corrected.columns.items()}, allow_extra=True)})  # fmt: skip
    written = json.loads((tmp_path / "c.json").read_text(encoding="utf-8"))["offset_dph"]
    assert written["value"] == pytest.approx(api.offset.value_dph, rel=1e-12)
    assert written["n_static_runs"] == api.offset.n_runs
    assert ("984 samples outside the calibrated temperature range +0.0 … +40.0 °C (± 1 °C): "
            "492 at -20 °C, 492 at +60 °C — passed through uncompensated") in out  # fmt: skip
    assert "(984 of them outside the calibrated temperature range, uncompensated" in out
    assert main(["compare", data, "--models", fourier, old, "--no-angles"]) == 0
    out = capsys.readouterr().out
    assert "Fourier+T^1: 984 samples outside" in out and "— extrapolated" in out
    assert "MLP: calibrated temperature range unknown" in out
    assert DOMAIN_MARGIN_C == 1.0


def test_loaders_and_correct_refuse_float32_mode(fitted, test_session, tmp_path):
    """With JAX's float64 mode off a saved compensator came back float32 and `correct` ran in
    float32 (5e-3 °/h off on a seed session), silently: refused in one line."""
    try:
        from jax import enable_x64
    except ImportError:  # older JAX
        from jax.experimental import enable_x64
    from hrgjax.calibration import export_json, load_compensator, load_json

    eqx_path = save_compensator(fitted["fourier"], tmp_path / "f.eqx")
    json_path = export_json(fitted["mlp"], tmp_path / "m.json")
    with enable_x64(False):
        for call in (lambda: load_compensator(eqx_path), lambda: load_json(json_path),
                     lambda: fitted["fourier"].correct(test_session)):  # fmt: skip
            with pytest.raises(RuntimeError, match=r"needs float64 but JAX is in float32 mode"):
                call()


def test_an_edited_domain_in_the_json_export_is_refused(fitted, tmp_path):
    """The embedded code reads the top-level `temperature_domain`; `hyper` rebuilds the
    compensator: a file where they disagree, or with a level count that is not one, was
    edited (they loaded as they were)."""
    from hrgjax.calibration import export_json, load_json

    export_json(fitted["fourier"], tmp_path / "f.json")
    good = json.loads((tmp_path / "f.json").read_text(encoding="utf-8"))
    assert load_json(tmp_path / "f.json").temperature_range == (0.0, 40.0)
    for edit, match in [
        (lambda d: d["temperature_domain"].update(range_c=[-50.0, 90.0]), "temperature_domain"),
        (lambda d: d["hyper"].update(n_temperature_levels="three"), "n_temperature_levels"),
        (lambda d: d["hyper"].update(n_temperature_levels=2.5), "n_temperature_levels"),
    ]:
        d = json.loads(json.dumps(good))
        edit(d)
        path = tmp_path / "edited.json"
        path.write_text(json.dumps(d))
        with pytest.raises(ValueError, match=match):
            load_json(path)


def test_corrected_data_round_trip_through_xarray(fitted, test_session):
    out = fitted["fourier"].correct(test_session)
    back = type(out).from_xarray(out.to_xarray())
    assert type(back) is hg.MeasuredData
    np.testing.assert_array_equal(back["angle_corrected_deg"], out["angle_corrected_deg"])


def test_passing_every_run_through_still_writes_the_data(fitted, test_session, tmp_path, capsys):
    """`hrgjax correct --no-extrapolate` on a session wholly outside the range: no offset and
    no tables (no compensated run to judge), but the corrected file is written (it refused
    the command and wrote nothing)."""
    from hrgjax.cli import main

    outside = _outside(test_session)
    data = hg.MeasuredData({k: v[outside] for k, v in test_session.columns.items()})
    path = data.save(tmp_path / "cold_hot.csv")
    model = save_compensator(fitted["fourier"], tmp_path / "f.eqx")
    out_file = tmp_path / "c.csv"
    argv = ["correct", path, "--model", model, "--out", str(out_file), "--no-extrapolate"]
    assert main(argv) == 0
    assert "every run has samples outside it: no offset and no tables" in capsys.readouterr().out
    back = hg.load(out_file)
    raw = NoCompensation().correct(data)
    np.testing.assert_allclose(back["rate_corrected_dps"], raw["rate_corrected_dps"], rtol=1e-15)
