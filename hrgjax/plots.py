"""Matplotlib figures used by the docs, the CLI and reports (needs `hrgjax[plot]`)."""

from __future__ import annotations

import numpy as np

from .units import DEG_PER_H, group_temperatures


class _Figures:
    """`pyplot`'s `subplots`, `get_cmap`, `close` on Agg-drawn `Figure`s pyplot never holds."""

    @staticmethod
    def subplots(nrows: int = 1, ncols: int = 1, **kw):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        grid = {k: kw.pop(k) for k in ("sharex", "sharey", "squeeze", "gridspec_kw") if k in kw}
        fig = FigureCanvasAgg(Figure(**kw)).figure
        return fig, fig.subplots(nrows, ncols, **grid)

    get_cmap = staticmethod(lambda name: __import__("matplotlib").colormaps[name])
    close = staticmethod(lambda fig=None: None)  # pyplot never held it


def pyplot() -> type[_Figures]:
    """`subplots`, `get_cmap`, `close` as in pyplot, never registered with it: the user's
    backend (a notebook's), open figures and rcParams stay as they were.

    **Raises:** `ImportError` naming the `hrgjax[plot]` extra when matplotlib is absent."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as err:  # pragma: no cover
        raise ImportError("plots need matplotlib: pip install hrgjax[plot]") from err
    return _Figures


def save(fig, path, dpi: int) -> str:
    """`fig.savefig(path, dpi=dpi)` under a temporary name, renamed when complete (an
    interrupted save leaves no partial image); makes the folder. Returns `path`."""
    from ._io import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return path


def drift_and_scale_factor(drift: dict, sf: dict, path: str, title: str = "") -> str:
    """Drift [°/h] and scale factor vs wave angle, one curve per temperature; saves `path`.

    `drift` is [`static_drift`][hrgjax.calibration.static_drift]'s output, `sf`
    [`scale_factor_vs_angle`][hrgjax.calibration.scale_factor_vs_angle]'s: the scale factor
    relative to the nominal k_e, drawn as SF − 1 [%] (0 is nominal; runs at different
    temperatures keep their different levels).
    """
    plt = pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    groups = group_temperatures(drift["temperature_c"])  # one curve per temperature
    temps = np.unique(groups)
    cmap = plt.get_cmap("coolwarm")
    norm = lambda T: (T - temps.min()) / max(np.ptp(temps), 1e-9)
    for T in temps:
        m = groups == T
        order = np.argsort(drift["wave_angle_deg"][m])
        ax1.plot(
            drift["wave_angle_deg"][m][order],
            drift["drift_dph"][m][order],
            "o-",
            ms=3,
            color=cmap(norm(T)),
            label=f"{T:+.0f} °C",
        )
    ax1.set_xlabel("wave angle [° electrical]")
    ax1.set_ylabel("drift, equivalent input rate [°/h]")
    ax1.set_title("static drift vs wave angle")
    ax1.grid(alpha=0.3)
    ax1.legend(fontsize=7, ncol=2)
    for T, row in zip(sf["temperature_c"], sf["scale_factor"], strict=True):
        ax2.plot(sf["wave_angle_deg"], (row - 1) * 100, "o-", ms=3, color=cmap(norm(T)),
                 label=f"{T:+.0f} °C")  # fmt: skip
    ax2.set_xlabel("wave angle [° electrical]")
    ax2.set_ylabel("scale factor − 1 [%]")  # relative to the nominal k_e: 0 is nominal
    rate = sf.get("rate_dps", np.nan)
    ax2.set_title(
        "scale factor vs wave angle" + (f" ({rate:.3g} °/s)" if np.isfinite(rate) else "")
    )
    ax2.grid(alpha=0.3)
    if len(sf["temperature_c"]) > 1:
        ax2.legend(fontsize=7, ncol=2)
    if title:
        fig.suptitle(title)
    return save(fig, path, dpi=120)


def compensation_residuals(windows, compensators: dict, path: str, title: str = "") -> str:
    """Static drift vs wave angle per temperature (first panel) and what is left after each
    compensator (one panel each); saves `path`.

    **Arguments:** `windows`, the reduced calibration data
    ([`RateWindows`][hrgjax.calibration.RateWindows]); `compensators`, {label: fitted
    compensator}.
    """
    plt = pyplot()
    static = windows.select(windows.static)
    labels = [k for k in compensators if k != "raw"]
    n = 1 + len(labels)
    cols, rows = min(n, 3), -(-n // min(n, 3))
    # a grid, three panels a row: readable at 100 % (one row of six was 2244 × 396 px)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows),
                             constrained_layout=True, sharex=True, squeeze=False)  # fmt: skip
    groups = group_temperatures(static.temperature_c)  # one curve per temperature
    temps = np.unique(groups)
    cmap = plt.get_cmap("coolwarm")
    norm = lambda T: (T - temps.min()) / max(np.ptp(temps), 1e-9)
    panels = [("measured drift", None)] + [(lab, compensators[lab]) for lab in labels]
    for ax in axes.ravel()[n:]:
        ax.set_visible(False)
    for ax, (name, comp) in zip(axes.ravel()[:n], panels, strict=True):
        for T in temps:
            m = groups == T
            ang = static.wave_angle_deg[m]
            y = static.drift_dph[m]
            if comp is not None:  # at each window's own temperature, not the group's
                y = y - comp.drift_dph(ang, static.temperature_c[m], warn=False)
            order = np.argsort(ang)
            ax.plot(
                ang[order], y[order], "o-", ms=2, lw=1, color=cmap(norm(T)), label=f"{T:+.0f} °C"
            )
        ax.set_title(name if comp is None else f"residual: {name}", fontsize=10)
        ax.set_xlabel("wave angle [° el.]")
        ax.grid(alpha=0.3)
    for r in range(rows):  # one y-label a row; the residual panels of a row share a scale
        axes[r, 0].set_ylabel("drift [°/h]" if r == 0 else "residual drift [°/h]")
        row = [ax for ax in axes[r] if ax.get_visible() and ax is not axes[0, 0]]
        if len(row) > 1:
            lo = min(ax.get_ylim()[0] for ax in row)
            hi = max(ax.get_ylim()[1] for ax in row)
            for ax in row:
                ax.set_ylim(lo, hi)
        for ax in row:
            if ax is not axes[r, 0]:  # row 0: the first residual panel is labelled
                ax.set_ylabel("residual drift [°/h]" if ax is row[0] and r == 0 else "")
    # one legend for the figure: the colours mean the same temperature in every panel
    handles, names = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside right upper", fontsize=8, title="temperature")
    if title:
        fig.suptitle(title)
    return save(fig, path, dpi=110)


def error_vs_temperature(table: dict, path: str, seed: dict | None = None) -> str:
    """Test errors vs temperature per method (log scale), seed 000's figures as stars.

    `table` is [`accuracy_table`][hrgjax.calibration.accuracy_table]'s output; `seed` its
    `SEED_TABLE`."""
    plt = pyplot()
    keys = [
        ("static_drift_dph", "static drift error [°/h]"),
        ("angle_error_deg", "angle error after the 5 °/s run [°]"),
        ("max_angle_error_deg", "largest angle error during the run [°]"),
    ]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4), constrained_layout=True)
    for ax, (key, ylabel) in zip(axes, keys, strict=True):
        for label, rows in table.items():
            temps = sorted(rows[key])
            ax.semilogy(temps, [rows[key][t] for t in temps], "o-", ms=3, label=label)
        if seed and key in seed:
            for i, (name, marker) in enumerate((("seed Fourier", "*"), ("seed MLP", "P"))):
                pts = seed[key]
                ax.semilogy(
                    list(pts),
                    [v[i] for v in pts.values()],
                    marker,
                    ms=11,
                    ls="none",
                    color="k",
                    label=name,
                )
        ax.set_xlabel("temperature [°C]")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, which="both")
    axes[0].legend(fontsize=7)
    return save(fig, path, dpi=110)


def alignment_figure(result, path: str, header_attitude_deg=None) -> str:
    """Heading, pitch and roll during fine alignment with their 1σ bands
    ([`AlignmentResult`][hrgjax.ins.alignment.AlignmentResult]); the file header's attitude
    as a dashed line when given. **Returns** the path written."""
    plt = pyplot()
    t = np.asarray(result.t) - float(result.t[0])
    hist, std = np.asarray(result.history_deg), np.asarray(result.std_history_deg)
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    names = ("heading", "pitch", "roll")
    for k, ax in enumerate(axes):
        ax.plot(t / 60, hist[:, k], lw=1.2, label="fine alignment")
        ax.fill_between(t / 60, hist[:, k] - std[:, k], hist[:, k] + std[:, k], alpha=0.25,
                        label="±1σ (filter)")  # fmt: skip
        if header_attitude_deg is not None:
            ref = header_attitude_deg[{0: 2, 1: 0, 2: 1}[k]]
            ax.axhline(ref, ls="--", color="k", lw=0.8, label="file header")
        final = hist[-1, k]
        pad = max(4 * std[-1, k], 0.05)
        ax.set_ylim(final - 10 * pad, final + 10 * pad)
        ax.set_ylabel(f"{names[k]} [°]")
    axes[0].legend(loc="lower right", fontsize=8)
    axes[-1].set_xlabel("time [min]")
    fig.suptitle("Stationary alignment: coarse start, Kalman fine alignment")
    fig.tight_layout()
    return save(fig, path, dpi=120)


def schuler_figure(t, position_m: dict, path: str) -> str:
    """Position-error histories [m] (label → (N,) array) against time [s]."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 3.5))
    for label, y in position_m.items():
        ax.plot(np.asarray(t) / 3600, np.asarray(y), label=label)
    ax.set_xlabel("time [h]")
    ax.set_ylabel("position error [m]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return save(fig, path, dpi=120)


def diagnosis_figure(traces: dict, path: str, title: str = "", span=(-20.0, 40.0)) -> str:
    """Decision traces like seed 002's Figs. 6–7: each method's decided state (0 = S0,
    i = fault in INS i) around the fault onset of one run
    ([`compare`][hrgjax.diagnosis.compare.compare] with `traces=True`), over `span` [s]
    around the onset. **Returns** the path written."""
    plt = pyplot()
    t = np.asarray(traces["t_s"])
    t_f = float(traces["t_fault_s"])
    names = [k for k in traces if k not in ("t_s", "truth", "t_fault_s")]
    sel = (t >= t_f + span[0]) & (t <= t_f + span[1])
    fig, axes = plt.subplots(len(names), 1, figsize=(7, 1.1 * len(names) + 1), sharex=True,
                             squeeze=False)  # fmt: skip
    for ax, name in zip(axes[:, 0], names, strict=True):
        ax.step(t[sel] - t_f, np.asarray(traces[name])[sel], where="post", lw=1.2)
        ax.axhline(traces["truth"], color="k", ls=":", lw=0.8)
        ax.set_yticks(range(4), ["S0", "S1", "S2", "S3"])
        ax.set_ylim(-0.3, 3.3)
        ax.set_ylabel(name, rotation=0, ha="right", va="center", fontsize=8)
        ax.axvline(0.0, color="r", lw=0.8)
    axes[-1, 0].set_xlabel("time from the fault onset [s]")
    fig.suptitle(f"Decided state, {title} (dotted: the faulty INS; red: onset)")
    fig.tight_layout()
    return save(fig, path, dpi=120)


def vibration_figure(figures: dict, path: str) -> str:
    """The seed-003 figures (patent Figs. 5–9) from
    [`fog.study.run`][hrgjax.fog.study.run]'s `"_figures"`: the compensated z accelerometer
    under vibration and its PSD against rest; the training curves; the held-out prediction
    of the east-equivalent (y) gyro's error; the heading during alignment, raw and
    compensated. **Returns** the path written."""
    plt = pyplot()
    fig, ax = plt.subplots(2, 3, figsize=(14, 7))
    t, a = figures["t"], figures["accel_z_g"]
    t0 = figures.get("vibration_start_s", 0.0)
    sel = (t >= t0) & (t < t0 + 1.0)
    ax[0, 0].plot(t[sel], a[sel], lw=0.8)
    ax[0, 0].set(xlabel="time [s]", ylabel="body z specific force [g]",
                 title="accelerometer z, first second of vibration")  # fmt: skip
    ax[0, 1].semilogy(figures["psd_f"], figures["psd"], label="vibrating", lw=0.8)
    ax[0, 1].semilogy(figures["psd_f"], figures["psd_rest"], label="at rest", lw=0.8)
    ax[0, 1].set(xlabel="frequency [Hz]", ylabel="PSD [g²/Hz]", title="PSD (Welch)")
    ax[0, 1].legend()
    # the normalised loss and the RMSE in °/h on their own axes (left and right)
    rmse_ax = ax[0, 2].twinx()
    lines = []
    for i, (name, h) in enumerate(figures["history"].items()):
        color = f"C{i}"
        lines += ax[0, 2].semilogy(h["train"], color=color, label=f"{name}: training loss")
        if "test_rmse" in h:
            lines += rmse_ax.semilogy(h["test_rmse"] / DEG_PER_H, color=color, ls="--",
                                      label=f"{name}: held-out RMSE")  # fmt: skip
    ax[0, 2].set(xlabel="epoch", ylabel="training loss (normalised)", title="training")
    rmse_ax.set_ylabel("held-out RMSE [°/h] (dashed)")
    ax[0, 2].legend(lines, [ln.get_label() for ln in lines], fontsize=7)
    w = figures["window_s"]
    for i, (f, amp) in enumerate(figures["test_conditions"][:2]):
        axx = ax[1, i]
        truth = figures["test_truth"][i, :, 1]
        tt = np.arange(truth.size) * w
        axx.plot(tt, truth, "k", lw=1.5, label="true error")
        for name, p in figures["test_pred"].items():
            axx.plot(tt, p[i, :, 1], lw=1, label=name)
        axx.set(xlabel="time [s]", ylabel="y gyro vibration error [°/h]",
                title=f"held out: {f:g} Hz, {amp:g} g")  # fmt: skip
        axx.legend(fontsize=7)
    true_h = figures["true_heading"]
    for name, h in figures["align_heading"].items():
        err = (h - true_h + 180.0) % 360.0 - 180.0
        ax[1, 2].plot(figures["align_t"], err, lw=1, label=name)
    ax[1, 2].axhline(figures["limit"]["remaining_drift"], color="k", ls=":",
                     label="limit, remaining drift")  # fmt: skip
    ax[1, 2].set(xlabel="time [s]", ylabel="heading error [°]",
                 title=f"alignment, {figures['scenario']}", ylim=(-3, 3))  # fmt: skip
    ax[1, 2].legend(fontsize=7)
    fig.tight_layout()
    return save(fig, path, dpi=110)


def allan_figure(result, path: str, fit=None, unit: str | None = None, title: str = "") -> str:
    """An Allan-family deviation with its confidence interval (error bars) and a fitted noise
    model: a [`NoiseFit`][hrgjax.allan.NoiseFit] (the IEEE 952 line fit; each term's slope:
    quantization −1, ARW −½, bias instability 0, rate random walk +½, rate ramp +1) or a
    [`CompositeNoise`][hrgjax.allan.CompositeNoise] (the identified model and each of its
    terms). Legends give each coefficient with its unit.

    The model is an Allan deviation: it is drawn over adev, oadev and totdev
    (`hrgjax.allan.curve_result.ALLAN_VARIANCE_KINDS`); over another
    kind (mdev, tdev, the Hadamard and modified total kinds, which estimate other
    variances) it is left out and the legend says so.

    - `result`: an [`AllanResult`][hrgjax.allan.AllanResult]; `unit`: the rate unit the
      deviation is taken in (coefficients' units; the axis names the kind's unit, for tdev
      and ttotdev the rate unit times a second); default the result's own
      (`AllanResult.rate_unit`, "rate unit" where it has none). Returns `path`.
    """
    from .allan import NOISE_TERMS, CompositeNoise
    from .allan.curve_result import ALLAN_VARIANCE_KINDS, deviation_unit

    if unit is None:
        unit = getattr(result, "rate_unit", "") or "rate unit"
    omitted = ""
    if fit is not None and result.kind not in ALLAN_VARIANCE_KINDS:  # σ(τ), not this kind's
        omitted = f"noise model not drawn: it gives the Allan deviation, not {result.kind}"
        fit = None

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 4.4), constrained_layout=True)
    t, d = np.asarray(result.taus), np.asarray(result.dev)
    err = np.stack([d - np.asarray(result.dev_low), np.asarray(result.dev_high) - d])
    ax.errorbar(t, d, yerr=err, fmt="o", ms=4, capsize=2, color="k",
                label=f"{result.kind} ± {100 * result.ci:.1f} % interval")  # fmt: skip
    grid = np.geomspace(t[0], t[-1], 200)
    styles = ("C0", "C1", "C2", "C4", "C5", "C6")
    if isinstance(fit, CompositeNoise):  # whole samples: the model is for sampled data
        grid = np.unique(np.maximum(np.round(grid * fit.rate_hz), 1.0)) / fit.rate_hz
        ax.loglog(grid, fit.adev(grid), "-", color="C3", lw=1.5,
                  label=f"identified model (J = {fit.chi2:.1f}, {fit.dof} dof)")  # fmt: skip
        for (name, spec), style in zip(fit.terms.items(), styles, strict=False):
            if "value" in spec:
                what = f"{spec['value']:.3g} {spec['unit']}"
            else:
                s, c = spec["sigma"], spec["correlation_time"]
                what = f"σ {s['value']:.3g} {s['unit']}, T {c['value']:.3g} s"
            ax.loglog(grid, np.sqrt(fit.term_avar(name, grid)), "--", color=style, lw=1,
                      label=f"{name.replace('_', ' ')}: {what}")  # fmt: skip
    elif fit is not None:
        ax.loglog(grid, fit.adev(grid), "-", color="C3", lw=1.5, label="fitted IEEE 952 model")
        for (name, sym, term_unit, f), style in zip(NOISE_TERMS, styles, strict=False):
            if fit.value[name] > 0:
                u = term_unit.replace("rate unit", unit)
                ax.loglog(grid, fit.value[name] * np.sqrt(f(grid)), "--", color=style, lw=1,
                          label=f"{name.replace('_', ' ')} {sym} = {fit.value[name]:.3g} {u}")  # fmt: skip
    if omitted:
        ax.plot([], [], " ", label=omitted)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("averaging time τ [s]")
    ax.set_ylabel(f"{result.kind} [{deviation_unit(result.kind, unit)}]")
    ax.set_title(title or f"{result.kind} with confidence intervals")
    ax.grid(which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return save(fig, path, dpi=110)


def imu_session_figure(data, sections, path: str, calibration=None, title: str = "") -> str:
    """A six-axis IMU session on one time line: specific force [m/s²] and rate [°/s] per axis
    with the Ferraris sections shaded and named; given a calibration, a third row shows
    |a| − g on the static faces before and after it (what the calibration fixed).

    - `data`: an [`ImuData`][hrgjax.imu.ImuData]; `sections`: `{key: [(start, end), …]}`
      ([`parse_sections`][hrgjax.imu.sections.parse_sections]); `calibration`: an
      [`ImuCalibration`][hrgjax.imu.ImuCalibration]. Returns `path`."""
    from .imu.sections import FACES, parse_sections

    plt = pyplot()
    sections = parse_sections(sections, len(data))
    rows = 3 if calibration is not None else 2
    fig, axes = plt.subplots(rows, 1, figsize=(9.0, 2.3 * rows + 0.6), sharex=True,
                             constrained_layout=True)  # fmt: skip
    t = np.asarray(data.time) - float(data.time[0])
    for k, name in enumerate("xyz"):
        axes[0].plot(t, data.accel[:, k], lw=0.8, color=f"C{k}", label=name)
        axes[1].plot(t, np.rad2deg(data.gyro[:, k]), lw=0.8, color=f"C{k}", label=name)
    for key, ranges in sections.items():
        color = "0.85" if key in FACES else "#fde3c8"
        for s, e in ranges:
            for ax in axes[:2]:
                ax.axvspan(t[s], t[e - 1], color=color, zorder=0)
            axes[0].annotate(key, ((t[s] + t[e - 1]) / 2, 0.97), xycoords=("data", "axes fraction"),
                             ha="center", va="top", fontsize=8)  # fmt: skip
    axes[0].set_ylabel("specific force [m/s²]")
    axes[0].set_title("accelerometers (raw), sections named", fontsize=10)
    axes[1].set_ylabel("rate [°/s]")
    axes[1].set_title("gyros (raw)", fontsize=10)
    handles, names = axes[0].get_legend_handles_labels()  # one legend: the same axes in both
    fig.legend(handles, names, loc="outside right upper", fontsize=8, title="sensor axis",
               title_fontsize=8)  # fmt: skip
    if calibration is not None:
        g = calibration.g
        raw = np.full(t.shape, np.nan)
        cal = np.full(t.shape, np.nan)
        _, a_cal = calibration.correct(data.gyro, data.accel)
        a_cal = np.asarray(a_cal)
        for key in FACES:
            for s, e in sections[key]:
                raw[s:e] = np.linalg.norm(data.accel[s:e], axis=1) - g
                cal[s:e] = np.linalg.norm(a_cal[s:e], axis=1) - g
        axes[2].plot(t, raw, lw=0.8, color="0.5", label="raw")
        axes[2].plot(t, cal, lw=0.8, color="C3", label="calibrated")
        axes[2].axhline(0.0, color="k", lw=0.5)
        axes[2].set_ylabel("|a| − g on faces [m/s²]")
        axes[2].set_title("specific-force magnitude on the faces, before and after", fontsize=10)
        axes[2].legend(fontsize=8)
    for ax in axes:
        ax.set_xlabel("time [s]")
        ax.grid(alpha=0.3)
    fig.suptitle(title or "Ferraris session: faces (grey) and turns (orange)", fontsize=11)
    return save(fig, path, dpi=110)


_KIND_COLORS = {"static": "C0", "rotation": "C3", "ramp": "C2"}


def plan_figure(plan, path: str, bench=None, title: str = "") -> str:
    """A bench plan on its time line: the chamber's temperature [°C] (top) and the wave
    angle of each segment [° electrical] (bottom) against bench time [h], segments coloured
    by kind, transitions (slew, soak, re-positioning) in grey.

    - `plan`: a [`BenchPlan`][hrgjax.calibration.BenchPlan]; `bench`: a
      [`BenchModel`][hrgjax.calibration.BenchModel] (default `BenchModel()`).
      Returns `path`."""
    bench = plan.bench_or_default(bench)
    plt = pyplot()
    tr = {k: np.asarray(v, float) for k, v in bench.transitions_s(plan).items()}
    t0 = np.asarray(plan.temperature_c, float)
    t1 = np.asarray(plan.temperature_end_c, float)
    angle = np.asarray(plan.wave_angle_deg, float)
    dur = np.asarray(plan.duration_s, float)
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10.0, 5.6), sharex=True,
                                   constrained_layout=True)  # fmt: skip
    now, prev = 0.0, float(bench.start_temperature_c)
    seen = set()
    for i, kind in enumerate(plan.kind):
        slew_end = now + tr["slew"][i]
        start = slew_end + tr["settle"][i] + tr["reposition"][i]
        h = lambda *x: np.array(x) / 3600.0
        ax1.plot(h(now, slew_end, start), [prev, t0[i], t0[i]], color="0.6", lw=1.0,
                 label="transition" if "transition" not in seen else None)  # fmt: skip
        seen.add("transition")
        label = kind if kind not in seen else None
        seen.add(kind)
        color = _KIND_COLORS[kind]
        ax1.plot(h(start, start + dur[i]), [t0[i], t1[i]], color=color, lw=3.0, label=label,
                 solid_capstyle="butt")  # fmt: skip
        ax2.plot(h(start, start + dur[i]), [angle[i], angle[i]], color=color, lw=3.0,
                 solid_capstyle="butt", marker="o", ms=2.5, markevery=[0])  # fmt: skip
        now, prev = start + dur[i], t1[i]
    hours = bench.breakdown_h(plan)
    ax1.set_ylabel("chamber temperature [°C]")
    ax1.set_title(
        f"{plan.size} segments, bench time {hours['total']:.1f} h: measuring "
        f"{hours['measuring']:.1f} h, slew {hours['slew']:.1f} h, soak {hours['settle']:.1f} h, "
        f"re-positioning {hours['reposition']:.1f} h",
        fontsize=10,
    )
    ax1.legend(fontsize=8, loc="best")
    ax2.set_ylabel("wave angle [° el.]")
    ax2.set_xlabel("bench time [h]")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.suptitle(title or "bench plan", fontsize=11)
    return save(fig, path, dpi=110)


def session_figure(comparison, path: str, title: str = "", seed: dict | None = None) -> str:
    """Compensators on one session, after its offset: the figure of
    [`Comparison.plot`][hrgjax.calibration.Comparison.plot] (its home since 2026-11-30;
    this name is kept for scripts that call it). `comparison`: a
    [`Comparison`][hrgjax.calibration.Comparison]; `seed`: seed 000's table to mark
    ([`SEED_TABLE`][hrgjax.calibration.evaluate.SEED_TABLE]; None: no marks, as before);
    saves `path` and returns it."""
    return comparison.plot(path, title=title, seed=seed)


def navigation_figure(truth, flights, path: str, title: str = "") -> str:
    """The motion's ground track with its GNSS gaps, the first run's horizontal position
    errors (free inertial with its height held, filter with its ±3σ, smoother) and the filter's and smoother's
    mean NEES against its 95 % band ([`hrgjax.ins.flights.fly`][hrgjax.ins.flights.fly]).
    **Returns** the path written."""
    from .ins.constants import radii
    from .ins.ekf import nees_band

    plt = pyplot()
    s = truth.states
    lat, lon = np.asarray(s.lat), np.asarray(s.lon)
    r_m, r_n = (np.asarray(r) for r in radii(lat[0]))
    # a truth written in (−180°, 180°] jumps by 2π at the antimeridian: unwrap the track
    east = np.unwrap(lon - lon[0]) * r_n * np.cos(lat[0]) / 1e3
    north = (lat - lat[0]) * r_m / 1e3
    t = np.asarray(flights.t)
    gap = ~np.asarray(flights.gnss_valid)
    gap[0] = False
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    ax = axes[0]
    ax.plot(east, north, lw=1.2, label="trajectory")
    every = max(1, int(round((t[1] - t[0]) / truth.dt)))
    k = np.flatnonzero(gap) * every
    if k.size:
        ax.plot(east[k], north[k], ".", color="C3", ms=3, label="GNSS gap")
    ax.set_xlabel("east [km]")
    ax.set_ylabel("north [km]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8)
    ax.set_title("ground track")
    ax = axes[1]
    hor = lambda d: np.linalg.norm(np.asarray(d["position"])[0, :, :2], axis=-1)
    sig = np.linalg.norm(np.asarray(flights.filter["sigma"])[0, :, :2], axis=-1)
    ax.semilogy(
        t / 60,
        np.maximum(hor(flights.free), 1e-3),
        color="0.6",
        lw=1,
        label="free inertial (height held)",
    )
    ax.semilogy(t / 60, np.maximum(hor(flights.filter), 1e-3), color="C0", lw=1, label="filter")
    ax.semilogy(t / 60, 3 * sig, color="C0", ls="--", lw=0.8, label="filter 3σ")
    ax.semilogy(t / 60, np.maximum(hor(flights.smoother), 1e-3), color="C2", lw=1, label="smoother")
    for a in np.flatnonzero(np.diff(np.concatenate([[0], gap.astype(int)])) == 1):
        b = a + np.argmin(gap[a:]) if not gap[a:].all() else gap.size - 1
        ax.axvspan(t[a] / 60, t[b] / 60, color="C3", alpha=0.12, lw=0)
    ax.set_xlabel("time [min]")
    ax.set_ylabel("horizontal position error [m] (run 1)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    ax = axes[2]
    lo, hi = nees_band(flights.n_states, flights.runs)
    for name, color in (("filter", "C0"), ("smoother", "C2")):
        ax.plot(t[1:] / 60, np.asarray(flights.__getattribute__(name)["nees"]).mean(0)[1:],
                color=color, lw=1, label=name)  # fmt: skip
    ax.axhspan(lo, hi, color="0.8", alpha=0.5, label="95 % band")
    ax.set_yscale("log")
    ax.set_xlabel("time [min]")
    ax.set_ylabel(f"mean NEES over {flights.runs} run(s)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    fig.suptitle(title or "Loosely-coupled GNSS/INS: errors against the truth")
    fig.tight_layout()
    return save(fig, path, dpi=120)
