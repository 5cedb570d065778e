"""Writing the discovery report: JSON (DESIGN.md keys first) and a figure."""

from __future__ import annotations

import json
import math
import os

import numpy as np

from ..calibration.reduce import K_E_NOMINAL, WINDOW_S, reduce
from ..data import MeasuredData
from ..units import DEG_PER_H
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
    with open(path, "w") as fh:
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
    """Static-window residual vs wave angle per temperature, before (nominal) and after (with
    the accepted effects); the screening scores; the gap before/after against the floor."""
    from ..plots import _plt

    plt = _plt()
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
