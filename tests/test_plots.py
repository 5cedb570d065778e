"""The CLI's figures read at a glance (issue 23): checked on the matplotlib objects — every
panel has a title and axis labels with units, a legend where it draws several curves, and no
two quantities of different units share an axis."""

import numpy as np
import pytest

from hrgjax import plots
from hrgjax.calibration.reduce import RateWindows


@pytest.fixture
def figures(monkeypatch):
    """The figures the plotting functions save, kept open for inspection."""
    kept = []
    monkeypatch.setattr(plots, "save", lambda fig, path, dpi: kept.append(fig))
    monkeypatch.setattr(plots.pyplot(), "close", lambda fig=None: None)
    return kept


def _check(fig):
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        twin = any(o is not ax and o.bbox.bounds == ax.bbox.bounds for o in fig.axes)
        assert ax.get_title() or twin, "a panel without a title"
        assert _unit(ax.get_xlabel()) or twin, f"x label without a unit: {ax.get_xlabel()!r}"
        if ax.get_ylabel():
            assert _unit(ax.get_ylabel()), f"y label without a unit: {ax.get_ylabel()!r}"
        if len(ax.get_lines()) > 1 and not twin:  # its own legend, or the figure's
            assert ax.get_legend() is not None or fig.legends, f"{ax.get_title()}: no legend"


def _unit(label: str) -> bool:
    """A unit in brackets, or a count / normalised quantity said in words."""
    return "[" in label or label == "epoch" or "normalised" in label


class _Flat:
    def drift_dph(self, angle, temperature, warn=True):
        return 0.5 * np.sin(np.deg2rad(2 * angle)) + 0.01 * temperature


def test_compensation_residuals_is_a_readable_grid(figures):
    temps, angles = np.repeat([-40.0, 0.0, 40.0], 5), np.tile(np.linspace(-80, 80, 5), 3)
    n = temps.size
    temps = temps + 1e-13 * np.arange(n)  # last-bit differences: one curve per temperature
    drift = np.sin(np.deg2rad(2 * angles)) + 0.02 * temps  # °/h
    w = RateWindows(run=np.arange(n), start=np.zeros(n, int), stop=np.full(n, 10),
                    t_mid=np.full(n, 90.0), duration=np.full(n, 180.0), temperature_c=temps,
                    table_rate_dps=np.zeros(n), wave_angle_deg=angles,
                    rate_dps=drift / 3600.0, stderr_dps=np.full(n, 1e-5), k_e=0.554)  # fmt: skip
    comps = {name: _Flat() for name in ("fourier", "mlp", "physical", "a", "b")}
    plots.compensation_residuals(w, comps, "unused.png")
    (fig,) = figures
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 6
    width, height = fig.get_size_inches()
    assert width / height < 2.0  # a grid, not one long row (was 20.4 × 3.6 in)
    _check(fig)
    residual = visible[1:3]  # the residual panels of a row share one scale
    assert residual[0].get_ylim() == residual[1].get_ylim()
    (legend,) = fig.legends
    assert [x.get_text() for x in legend.get_texts()] == ["-40 °C", "+0 °C", "+40 °C"]


def test_vibration_training_panel_keeps_loss_and_rmse_on_separate_axes(figures):
    t = np.linspace(0.0, 10.0, 1001)
    hist = {"elman": {"train": np.geomspace(1, 0.01, 50),
                      "test_rmse": np.geomspace(1e-4, 1e-6, 50)},
            "mlp": {"train": np.geomspace(1, 0.02, 50)}}  # fmt: skip
    f = {
        "t": t, "accel_z_g": np.sin(t), "vibration_start_s": 1.0,
        "psd_f": np.linspace(1, 50, 50), "psd": np.ones(50), "psd_rest": np.full(50, 0.1),
        "history": hist, "window_s": 2.0, "test_conditions": [(10.0, 1.0), (20.0, 0.5)],
        "test_truth": np.zeros((2, 20, 3)), "test_pred": {"elman": np.zeros((2, 20, 3))},
        "true_heading": np.zeros(30), "align_heading": {"raw": np.ones(30)},
        "align_t": np.arange(30.0), "limit": {"remaining_drift": 0.1}, "scenario": "10hz_1g",
    }  # fmt: skip
    plots.vibration_figure(f, "unused.png")
    (fig,) = figures
    _check(fig)
    training = [ax for ax in fig.axes if ax.get_title() == "training"]
    assert len(training) == 1
    twins = [ax for ax in fig.axes if ax is not training[0]
             and ax.bbox.bounds == training[0].bbox.bounds]  # fmt: skip
    assert len(twins) == 1
    assert "normalised" in training[0].get_ylabel() and "°/h" in twins[0].get_ylabel()
    # the loss curves on the left axis, the RMSE (°/h) on the right
    assert len(training[0].get_lines()) == 2 and len(twins[0].get_lines()) == 1


def test_a_mixed_logs_discovery_figure_draws_records_and_dwell_runs(figures):
    from hrgjax.discovery.report import plot_discovery
    from hrgjax.discovery.result import Discovery

    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 60.0, 50)
    records = [{"run": i, "held": i == 2, "t_min": t, "angle_arcsec": rng.normal(size=t.size)}
               for i in range(3)]  # fmt: skip
    n = 40
    windows = {"wave_angle_deg": np.tile(np.linspace(-90, 90, 10), 4),
               "temperature_c": np.repeat([-20.0, 0.0, 20.0, 40.0], 10) + 1e-13 * np.arange(n),
               "static": np.arange(n) % 2 == 0, "drift_dph": rng.normal(size=n)}  # fmt: skip
    res = {"records": records, "windows": windows}
    screen = {"effect": "bias_temperature", "score": 50.0, "p_value": 1e-9, "delta_bic": 40.0,
              "aliasing": 0.1, "heldout_gain": 30.0, "gap_after": 0.2, "outshone_by": None}  # fmt: skip
    disc = Discovery(
        verdict="found", missing_effect="bias_temperature", accepted=("bias_temperature",),
        ambiguous_with=(), discriminate={}, gap_before=0.5, gap_after=0.2, noise_floor=0.15,
        metric="rms_run_mean_rate_residual_dph", structure_left=False, fit_parameters={},
        k_e=0.554, ranking=(), screening=(screen,), consistency={}, noise={}, split={},
        shape="mixed", residuals={"before": res, "after": res},
    )  # fmt: skip
    plot_discovery(disc, "unused.png")
    (fig,) = figures
    assert len(fig.axes) == 6  # records, dwell runs (before | after), candidates | gap
    titles = [ax.get_title() for ax in fig.axes]
    assert sum("continuous records" in s for s in titles) == 2
    assert sum("dwell runs" in s for s in titles) == 2
    _check(fig)
    for ax in fig.axes:  # a temperature once in each legend, whatever its last bits
        if "dwell runs" in ax.get_title():
            labels = [x.get_text() for x in ax.get_legend().get_texts()]
            assert labels == ["-20 °C", "+0 °C", "+20 °C", "+40 °C"]


def test_allan_figure_reads_at_a_glance(figures):
    from hrgjax import allan

    rng = np.random.default_rng(0)
    r = allan.deviation(rng.normal(size=4000) + 0.01 * np.cumsum(rng.normal(size=4000)), 1.0)
    plots.allan_figure(r, "unused.png", fit=allan.fit_noise(r), unit="°/h")
    (fig,) = figures
    _check(fig)
    (ax,) = fig.axes
    assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("interval" in t for t in labels) and any("angle random walk" in t for t in labels)


def test_allan_figure_draws_the_model_only_over_the_allan_deviation_in_its_unit(figures):
    """Audit: a noise model (it predicts σ(τ)) was drawn over tdev points, 150× below it at
    long τ on a random walk, and the axis said °/h whatever the result's unit (a rad/s
    result got a °/h axis and °/h·√s coefficients; tdev's values are °/h·s). The model is
    now drawn over adev, oadev and totdev only (the legend says where it is left out), and
    the axis and coefficients follow the result's unit and kind."""
    from hrgjax import allan

    rng = np.random.default_rng(0)
    y = rng.normal(size=4000) + 0.01 * np.cumsum(rng.normal(size=4000))
    oadev = allan.deviation(y, 1.0, unit="°/h")
    fit = allan.fit_noise(oadev)
    plots.allan_figure(allan.deviation(y, 1.0, kind="tdev", unit="°/h"), "t.png", fit=fit)
    plots.allan_figure(oadev, "o.png", fit=fit)
    rad = allan.deviation(y, 1.0, unit="rad/s")
    plots.allan_figure(rad, "r.png", fit=allan.fit_noise(rad))
    plots.allan_figure(allan.deviation(np.cumsum(y), 1.0, data="phase", unit="°"), "p.png")
    for fig in figures:
        _check(fig)
    axes = [fig.axes[0] for fig in figures]
    labels = [[t.get_text() for t in ax.get_legend().get_texts()] for ax in axes]
    assert [ax.get_ylabel() for ax in axes] == ["tdev [°/h·s]", "oadev [°/h]",
                                                 "oadev [rad/s]", "oadev [°/s]"]  # fmt: skip
    assert "noise model not drawn: it gives the Allan deviation, not tdev" in labels[0]
    assert not any("IEEE 952" in t or "random walk" in t for t in labels[0])
    assert "fitted IEEE 952 model" in labels[1] and any("°/h·√s" in t for t in labels[1])
    assert any("rad/s·√s" in t for t in labels[2]) and not any("°" in t for t in labels[2])


def test_imu_session_and_allan_figures_read_at_a_glance(figures):
    import jax

    import hrgjax as hg

    truth = hg.imu.ImuCalibration.known(accel_bias=[0.1, -0.05, 0.2])
    data, sections = hg.imu.ferraris_session(truth, jax.random.key(0), static_s=2.5,
                                             move_s=1.0, turn_s=2.0, rate_hz=50.0)  # fmt: skip
    cal = hg.imu.ferraris(data, sections)
    plots.imu_session_figure(data, sections, "unused.png", calibration=cal)
    y = np.random.default_rng(0).normal(size=4096)
    result = hg.allan.deviation(y, 1.0)
    plots.allan_figure(result, "unused.png", fit=hg.allan.fit_noise(result))
    assert len(figures) == 2
    for fig in figures:
        _check(fig)


def test_scale_factor_panel_draws_the_scale_factor_relative_to_nominal(figures):
    """Rotation runs with scale factors 1.002 (−40 °C) and 0.998 (+60 °C) are drawn at
    +0.2 % and −0.2 % ("scale factor − 1"), not both at 0 (each run about its own mean)."""
    from hrgjax import MeasuredData
    from hrgjax.calibration import scale_factor_vs_angle, static_drift

    k_e, t = 0.554, np.arange(6000) * 0.01
    cols = []
    for run, (temp, sf, rate) in enumerate([(-40.0, 1.002, 5.0), (60.0, 0.998, 5.0),
                                            (-40.0, 1.0, 0.0), (60.0, 1.0, 0.0)]):  # fmt: skip
        cols.append(dict(time_s=t, wave_angle_deg=10.0 - k_e * sf * rate * t,
                         temperature_c=np.full(t.size, temp), table_rate_dps=np.full(t.size, rate),
                         run=np.full(t.size, run)))  # fmt: skip
    data = MeasuredData({k: np.concatenate([c[k] for c in cols]) for k in cols[0]})
    plots.drift_and_scale_factor(static_drift(data, k_e), scale_factor_vs_angle(data, k_e), "x.png")
    (fig,) = figures
    lines = fig.axes[1].get_lines()
    assert len(lines) == 2
    for line, percent in zip(lines, [0.2, -0.2], strict=True):
        y = np.asarray(line.get_ydata(), float)
        assert np.sum(np.isfinite(y)) >= 10
        np.testing.assert_allclose(y[np.isfinite(y)], percent, rtol=1e-9)
    _check(fig)  # and a legend for the two curves
    assert fig.axes[1].get_title() == "scale factor vs wave angle (5 °/s)"  # the data's rate


def test_plan_figure_draws_a_plan_without_a_bench_given(figures):
    """`plan_figure(plan, path)`: the bench defaults to `BenchModel()` through the plan
    (plots imports no study), and the title's bench time is the default bench's."""
    from hrgjax.calibration import BenchModel, bench_time_h, seed_bench_plan

    plan = seed_bench_plan()
    plots.plan_figure(plan, "unused.png")
    plots.plan_figure(plan, "unused.png", BenchModel())
    a, b = (f.axes[0].get_title() for f in figures)
    assert a == b and f"bench time {float(bench_time_h(plan)):.1f} h" in a, (a, b)
