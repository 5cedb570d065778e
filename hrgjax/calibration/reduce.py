"""Reduction of bench data to drift and scale factor per point."""

from __future__ import annotations

import numpy as np

from ..data import MeasuredData


def static_drift(data: MeasuredData, k_e: float = 0.554):
    """Drift of each static run as equivalent input rate [°/h]: −(wave-angle slope)/k_e minus
    the table rate; with the run's temperature [°C] and mean wave angle [°].

    **Returns:** dict of arrays `temperature_c`, `wave_angle_deg`, `drift_dph`, `run`.
    """
    out = {"temperature_c": [], "wave_angle_deg": [], "drift_dph": [], "run": []}
    for r in data.runs():
        t, th = r["time_s"], r["wave_angle_deg"]
        slope = np.polyfit(t - t.mean(), th, 1)[0]
        rate = -slope / k_e - np.mean(r["table_rate_dps"])
        out["drift_dph"].append(rate * 3600.0)
        out["temperature_c"].append(np.mean(r["temperature_c"]))
        out["wave_angle_deg"].append(np.mean(th))
        out["run"].append(int(r.run[0]))
    return {k: np.asarray(v) for k, v in out.items()}


def scale_factor_vs_angle(
    data: MeasuredData, k_e: float = 0.554, window_s: float = 2.0, bin_deg: float = 10.0
):
    """Local scale factor of rotation runs vs wave angle (folded to [−90°, 90°)), binned.

    SF = (Δθ_meas/Δt)/(−k_e Ω_table) over windows of `window_s`, relative to its run mean.

    **Returns:** dict `temperature_c` (T,), `wave_angle_deg` (B,), `scale_factor` (T, B).
    """
    temps = []
    rows = []
    edges = np.arange(-90.0, 90.0 + bin_deg / 2, bin_deg)
    centres = 0.5 * (edges[1:] + edges[:-1])
    by_temp: dict[float, list] = {}
    for r in data.runs():
        w = r["table_rate_dps"]
        if np.all(w == 0):
            continue
        t, th = r["time_s"], r["wave_angle_deg"]
        step = max(int(round(window_s / np.median(np.diff(t)))), 1)
        sf = (th[step:] - th[:-step]) / (t[step:] - t[:-step]) / (-k_e * w[step:])
        mid = 0.5 * (th[step:] + th[:-step])
        folded = (mid + 90.0) % 180.0 - 90.0
        by_temp.setdefault(round(float(np.mean(r["temperature_c"])), 6), []).append(
            (folded, sf / np.mean(sf))
        )
    for temp, parts in sorted(by_temp.items()):
        ang = np.concatenate([p[0] for p in parts])
        sf = np.concatenate([p[1] for p in parts])
        idx = np.digitize(ang, edges) - 1
        rows.append(
            [np.mean(sf[idx == b]) if np.any(idx == b) else np.nan for b in range(len(centres))]
        )
        temps.append(temp)
    return {
        "temperature_c": np.asarray(temps),
        "wave_angle_deg": centres,
        "scale_factor": np.asarray(rows),
    }


__all__ = ["static_drift", "scale_factor_vs_angle"]
