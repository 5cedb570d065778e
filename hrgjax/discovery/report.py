"""Writing the discovery report: JSON (DESIGN.md keys first) and a figure."""

from __future__ import annotations

import json
import math
import os

import numpy as np

from ..calibration.reduce import K_E_NOMINAL, WINDOW_S, reduce
from ..data import MeasuredData
from ..units import DEG, DEG_PER_H
from . import dwell
from .effects import NOMINAL


def _clean(x):
    """JSON-safe copy: NumPy scalars to floats, non-finite numbers to None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def write_json(report: dict, path: str | os.PathLike) -> str:
    """Write `report` as JSON (the DESIGN.md keys come first); returns the path."""
    path = os.fspath(path)
    d = os.path.dirname(path)
    if d:
        os.makedirs(d, exist_ok=True)
    first = ("missing_effect", "ranking", "gap_before", "gap_after", "noise_floor", "metric")
    ordered = {k: report[k] for k in first} | {k: v for k, v in report.items() if k not in first}
    from .._io import atomic_write

    with atomic_write(path, "w") as fh:
        json.dump(_clean(ordered), fh, indent=1)
    return path


def plot_report(
    data: MeasuredData,
    report: dict,
    path: str,
    *,
    nominal=NOMINAL,
    k_e: float = K_E_NOMINAL,
    window_s: float = WINDOW_S,
) -> str:
    """The report as one figure: residuals before (nominal) and after (with the accepted
    effects) — for dwell grids the static-window drift vs wave angle per temperature, for
    continuous records the angle residual of every run vs time —, the screening scores, and
    the gap before/after against the noise floor."""
    from ..plots import _plt

    plt = _plt()
    if report.get("shape") == "continuous":
        fig, axes = plt.subplots(1, 4, figsize=(17, 3.8), constrained_layout=True)
        _continuous_panels(axes, data, report, nominal, k_e)
        return _finish(fig, axes, report, path, plt)
    w = reduce(data, k_e, window_s=window_s)
    from .search import _noise_scale, _window_extras

    extra, _ = _window_extras(data, w)
    c = dwell.covariates(w, extra)
    y = dwell.target(w, k_e)
    sigma, _ = _noise_scale(data, w, k_e)
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.8), constrained_layout=True)
    temps = np.unique(w.temperature_c[w.static])
    cmap = plt.get_cmap("coolwarm")
    norm = lambda T: (T - temps.min()) / max(np.ptp(temps), 1e-9)
    for ax, names, title in (
        (axes[0], list(nominal), "residual, nominal model"),
        (axes[1], list(nominal) + list(report["accepted"]), "residual, with accepted effects"),
    ):
        g, _ = dwell.design(names, c, k_e)
        beta, _, _ = dwell.wls(g, y, sigma)
        resid = -(y - g @ beta) / k_e / DEG_PER_H
        for T in temps:
            m = w.static & (w.temperature_c == T)
            order = np.argsort(w.wave_angle_deg[m])
            ax.plot(
                w.wave_angle_deg[m][order],
                resid[m][order],
                "o-",
                ms=2,
                lw=1,
                color=cmap(norm(T)),
                label=f"{T:+.0f} °C",
            )
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("wave angle [° el.]")
        ax.set_ylabel("static drift residual [°/h]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=6, ncol=2)
    return _finish(fig, axes, report, path, plt)


def _continuous_panels(axes, data, report, nominal, k_e):
    """Angle residual (measured − model) of every run vs time, each run's own constant rate
    (its switch-on bias) removed, before and after."""
    from .continuous import ContinuousProblem, noise_model

    names = list(nominal) + [n for n in report["accepted"] if n not in nominal]
    problem = ContinuousProblem(data, names, k_e, held=[], noise=noise_model(data))
    groups = problem.train_groups
    for ax, model, title in (
        (axes[0], list(nominal), "angle residual, nominal model"),
        (axes[1], names, "angle residual, with accepted effects"),
    ):
        z = problem.fit(model, z0=problem.start_from(report["parameters"], model))["z"]
        raw = problem.raw_residuals(z)
        for g, r in zip(groups, raw, strict=True):
            tb = np.asarray(g.t[:, g.bidx])
            for i, run in enumerate(g.run):
                t = tb[i] - tb[i, 0]
                cum = np.concatenate([[0.0], np.cumsum(np.asarray(r[i]))])
                cum = cum - np.polyval(np.polyfit(t, cum, 1), t)
                ax.plot(t / 60, cum / DEG * 3600, lw=1, label=f"run {run}")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("time in run [min]")
        ax.set_ylabel("angle residual, run's mean rate removed [″]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=6, ncol=2)


def _finish(fig, axes, report, path, plt):
    rows = report["screening"]
    axes[2].barh([r["effect"] for r in rows][::-1], [max(r["score"], 1e-3) for r in rows][::-1])
    axes[2].set_xscale("log")
    axes[2].set_xlabel("score statistic (first round)")
    axes[2].tick_params(axis="y", labelsize=7)
    axes[3].bar(
        ["before", "after", "noise floor"],
        [report["gap_before"], report["gap_after"], report["noise_floor"]],
        color=["tab:red", "tab:green", "tab:gray"],
    )
    axes[3].set_ylabel("held-out gap [°/h]")
    axes[3].set_title(f"missing effect: {report['missing_effect']}", fontsize=9)
    d = os.path.dirname(path)
    if d:
        os.makedirs(d, exist_ok=True)
    from ..plots import _save

    _save(fig, path, dpi=110)
    plt.close(fig)
    return path
