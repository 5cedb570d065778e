"""The discovery report's figure, drawn from a [`Discovery`][hrgjax.discovery.result.Discovery]
(its own fits: nothing is refitted here). `Discovery.plot` calls it; this module reads the
report's fields and imports nothing of `result`, so the two never import each other."""

from __future__ import annotations

import numpy as np

from ..units import group_temperatures


def plot_discovery(disc, path: str) -> str:  # disc: a Discovery (not imported: module docstring)
    """The report as one figure (see [`Discovery.plot`][hrgjax.discovery.result.Discovery.plot]):
    residuals before and after in the top row, the first-round scores and the held-out gap
    against the noise floor beneath. Returns `path`."""
    from ..plots import pyplot, save

    plt = pyplot()
    mixed = "records" in disc.residuals["before"]  # a mixed log: records and dwell windows
    fig, axes = plt.subplots(3 if mixed else 2, 2, figsize=(11, 11 if mixed else 7.5),
                             constrained_layout=True)  # fmt: skip
    after = "residual, with\n" + (", ".join(disc.accepted) if disc.accepted else "no effect added")
    panels = []  # (row, draw, residuals key)
    if mixed:
        panels += [(0, _continuous_panel, "records"), (1, _dwell_panel, "windows")]
    elif disc.shape in ("continuous", "mixed"):
        panels += [(0, _continuous_panel, None)]
    else:
        panels += [(0, _dwell_panel, None)]
    for row, draw, part in panels:
        for ax, which, title in (
            (axes[row, 0], "before", "residual,\nnominal model"),
            (axes[row, 1], "after", after),
        ):
            res = disc.residuals[which] if part is None else disc.residuals[which][part]
            draw(ax, res, plt)
            what = {"records": " (continuous records)", "windows": " (dwell runs)"}.get(part, "")
            ax.set_title(title + what, fontsize=10)
            ax.grid(alpha=0.3)
        # one y-range for both residual panels, so that the shrink reads at a glance
        lo = min(axes[row, 0].get_ylim()[0], axes[row, 1].get_ylim()[0])
        hi = max(axes[row, 0].get_ylim()[1], axes[row, 1].get_ylim()[1])
        for ax in axes[row]:
            ax.set_ylim(lo, hi)
        for ax in axes[row]:  # the same runs / temperatures in both
            ax.legend(fontsize=7, ncol=2)
    axes = axes[-2:]  # the bottom row: candidates and the gap

    rows = list(disc.screening)
    ax = axes[1, 0]
    names = [r["effect"] for r in rows][::-1]
    ax.barh(names, [max(r["score"], 1e-3) for r in rows][::-1],
            color=["tab:green" if n in disc.accepted else "tab:blue" for n in names])  # fmt: skip
    ax.set_xscale("log")
    ax.set_xlabel("score statistic, first round [χ²]")
    ax.set_title("candidates\n(accepted in green)", fontsize=10)
    ax.tick_params(axis="y", labelsize=8)
    ax = axes[1, 1]
    ax.bar(["before", "after", "noise floor"], [disc.gap_before, disc.gap_after, disc.noise_floor],
           color=["tab:red", "tab:green", "tab:gray"])  # fmt: skip
    ax.set_ylabel("held-out gap [°/h]")
    ax.set_xlabel("model [nominal | with the accepted effects | noise alone]")
    ax.set_title(f"verdict: {disc.verdict}\nmissing effect: {disc.missing_effect}", fontsize=10)
    fig.suptitle(f"discovery on {disc.shape} data", fontsize=11)
    return save(fig, path, dpi=110)  # makes the folder, closes the figure


def _dwell_panel(ax, res, plt):
    """Static-window drift residual against wave angle, one line per temperature."""
    groups = group_temperatures(res["temperature_c"])  # one line per temperature
    temps = np.unique(groups[res["static"]])
    cmap = plt.get_cmap("coolwarm")
    span = max(float(np.ptp(temps)), 1e-9) if temps.size else 1.0
    for T in temps:
        m = res["static"] & (groups == T)
        order = np.argsort(res["wave_angle_deg"][m])
        ax.plot(res["wave_angle_deg"][m][order], res["drift_dph"][m][order], "o-", ms=2, lw=1,
                color=cmap((T - temps.min()) / span), label=f"{T:+.0f} °C")  # fmt: skip
    ax.set_xlabel("wave angle [° el.]")
    ax.set_ylabel("static drift residual [°/h]")


def _continuous_panel(ax, res, plt=None):
    """Each run's angle residual against time (its mean rate removed), held-out dashed."""
    for run in res:
        ax.plot(run["t_min"], run["angle_arcsec"], "--" if run["held"] else "-", lw=1,
                label=f"run {run['run']}" + (" (held out)" if run["held"] else ""))  # fmt: skip
    ax.set_xlabel("time in run [min]")
    ax.set_ylabel("angle residual, run's mean rate removed [″]")
