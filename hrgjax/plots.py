"""Matplotlib figures used by the docs, the CLI and reports (needs `hrgjax[plot]`)."""

from __future__ import annotations

import numpy as np


def _plt():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:  # pragma: no cover
        raise ImportError("plots need matplotlib: pip install hrgjax[plot]") from err
    return plt


def drift_and_scale_factor(drift: dict, sf: dict, path: str, title: str = "") -> str:
    """Drift [°/h] and scale factor vs wave angle, one curve per temperature; saves `path`.

    `drift` is [`static_drift`][hrgjax.calibration.static_drift]'s output, `sf`
    [`scale_factor_vs_angle`][hrgjax.calibration.scale_factor_vs_angle]'s.
    """
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    temps = np.unique(drift["temperature_c"])
    cmap = plt.get_cmap("coolwarm")
    norm = lambda T: (T - temps.min()) / max(np.ptp(temps), 1e-9)
    for T in temps:
        m = drift["temperature_c"] == T
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
        ax2.plot(sf["wave_angle_deg"], (row - 1) * 100, "o-", ms=3, color=cmap(norm(T)))
    ax2.set_xlabel("wave angle [° electrical]")
    ax2.set_ylabel("scale factor − 1 [%]")
    ax2.set_title("scale factor vs wave angle (5 °/s)")
    ax2.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
