r"""Name the shape of what a model leaves (DISCOVERY.md §2.1 "say I don't know", issue 19):
the residual of the final fit tested against generic shapes of the pattern rate — harmonics
1θ … 4θ of the electrical wave angle (constant, growing with ΔT = T − 20 °C or with ΔT², and in
proportion to the rate Ω: a scale factor that varies with the wave angle; 2θ also with Ω²: a
closed loop's lag turns a 2θ ripple's axis with the rate), ΔT, ΔT², ΔT³ and ΔT³ with ΔT⁴ (a
drift over temperature that no polynomial law of the catalogue follows: a cubic, a step, a
kink; on a five-level dwell grid with bias, ΔT and ΔT² fitted, the pair spans any function
of temperature),
dT/dt, the table rate Ω (and Ω·ΔT, Ω³), the specific force a_z and the time since switch-on.

Each shape is a set of pattern-rate columns evaluated at the data's covariates (dwell
windows, or the 10-s blocks of continuous records, where a shape's column is its value times
the block's length: the angle it adds); its score statistic against the fitted model's
whitened residual and Jacobian is the same test as the catalogue's screening
([`score`][hrgjax.discovery.stats.score]), read at the noise level the residual shows per
row class once the shape is fitted (F(q, ν):
[`level_test`][hrgjax.discovery.stats.level_test]), not at the estimated noise model's. The
strongest shape is reported with its size in user units (the input rate it imitates) and
its significance in words. The columns use each point's mean covariates; on dwell windows a
kθ harmonic is seen through the window's sweep, as the catalogue's 2θ terms are.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import numpy as np

from ..units import DEG, DEG_PER_H, HOUR, T_REF_C
from . import stats
from .effects import window_gain

SHAPES = (
    *(f"{k}θ" for k in (1, 2, 3, 4)),
    *(f"{k}θ·ΔT" for k in (1, 2, 3, 4)),
    *(f"{k}θ·ΔT²" for k in (1, 2, 3, 4)),
    *(f"{k}θ·Ω" for k in (1, 2, 3, 4)),
    "2θ·Ω²",
    "ΔT",
    "ΔT²",
    "ΔT³",
    "ΔT³+ΔT⁴",
    "dT/dt",
    "Ω",
    "Ω·ΔT",
    "Ω³",
    "a_z",
    "t_run",
)
"""The shapes tried, by name."""

_SCALAR = {  # shape: (words, user unit, factor from pattern-rate coefficient per input)
    "ΔT": ("a drift that follows temperature", "°/h/°C", 1 / DEG_PER_H),
    "ΔT²": ("a drift curving with temperature", "°/h/°C²", 1 / DEG_PER_H),
    "ΔT³": ("a drift with the cube of temperature", "°/h/°C³", 1 / DEG_PER_H),
    "ΔT³+ΔT⁴": (
        "a drift following temperature beyond ΔT² (ΔT³ and ΔT⁴ terms)",
        "°/h/°C³",
        1 / DEG_PER_H,
    ),
    "dT/dt": ("a drift that follows the temperature rate", "°/h per °C/min", 1 / (60 * DEG_PER_H)),
    "Ω": ("a scale-factor error", "ppm", 1e6),
    "Ω·ΔT": ("a scale factor changing with temperature", "ppm/°C", 1e6),
    "Ω³": ("a scale factor changing with rate", "ppm/(°/s)²", 1e6 * DEG**2),
    "a_z": ("a drift that follows the specific force along the axis", "°/h/g", 1 / DEG_PER_H),
    "t_run": ("a drift changing with time since switch-on", "°/h per h", HOUR / DEG_PER_H),
}


def columns(cov: dict, drop: bool = True) -> dict[str, np.ndarray]:
    """Pattern-rate columns (N, q) of every shape at covariates `cov` (arrays of N points:
    `theta` [rad], `dT` [°C from 20 °C], `Tdot` [°C/s], `rate` [rad/s], `accel_z` [g],
    `t_run` [s], and optionally `arc` [rad]: the arc the pattern sweeps in a dwell window,
    through which a slope sees a kθ harmonic times
    [`window_gain`][hrgjax.discovery.effects.window_gain](k·arc/2)); with `drop`, shapes whose
    columns vanish on these points are left out."""
    th, dT = cov["theta"], cov["dT"]
    arc = cov.get("arc")
    out = {}
    for k in (1, 2, 3, 4):
        h = np.stack([np.cos(k * th), np.sin(k * th)], axis=-1)
        if arc is not None:  # a window's slope sees kθ through its sweep (window_gain)
            h = h * np.asarray(window_gain(0.5 * k * np.asarray(arc)))[:, None]
        out[f"{k}θ"] = h
        out[f"{k}θ·ΔT"] = h * dT[:, None]
        out[f"{k}θ·ΔT²"] = h * dT[:, None] ** 2
        out[f"{k}θ·Ω"] = h * cov["rate"][:, None]
        if k == 2:  # a 2θ scale factor whose axis turns with the rate: a loop's lag
            out["2θ·Ω²"] = h * cov["rate"][:, None] ** 2
    rate = cov["rate"]
    scalar = {
        "ΔT": dT,
        "ΔT²": dT**2,
        "ΔT³": dT**3,
        "dT/dt": cov["Tdot"],
        "Ω": rate,
        "Ω·ΔT": rate * dT,
        "Ω³": rate**3,
        "a_z": cov["accel_z"],
        "t_run": cov["t_run"],
    }
    out |= {k: v[:, None] for k, v in scalar.items()}
    out["ΔT³+ΔT⁴"] = np.stack([dT**3, dT**4], axis=-1)  # on five temperature levels with
    # bias, ΔT and ΔT² fitted: any function of temperature (a step, a kink)
    return {k: np.asarray(v, float) for k, v in out.items() if np.any(v) or not drop}


def _sigmas(p: float, s: float) -> float:
    """Two-sided normal equivalent of a p-value (√S where p underflows)."""
    if p <= 0.0 or not math.isfinite(p):
        return math.sqrt(max(s, 0.0))
    return -NormalDist().inv_cdf(min(p, 1.0) / 2.0) if p < 1.0 else 0.0


def _size(shape: str, coef: np.ndarray, cov: np.ndarray, k_e: float) -> dict:
    """Size of a shape's fitted coefficients (pattern rate) in user units, and words."""
    f = -1.0 / k_e  # a pattern-rate term f imitates −f/k_e of input rate
    if "θ" in shape:
        k = int(shape[0])
        per_t2, per_rate = "·ΔT²" in shape, "·Ω" in shape
        per_rate2 = "·Ω²" in shape
        per_t = "·ΔT" in shape and not per_t2
        unit = "°/h/°C²" if per_t2 else "°/h/°C" if per_t else "°/h"
        unit, scale = ("ppm", 1e6) if per_rate else (unit, 1 / DEG_PER_H)
        unit, scale = ("ppm/(°/s)", 1e6 * DEG) if per_rate2 else (unit, scale)
        a, b = f * coef * scale
        amp = math.hypot(a, b)
        # Jacobian of the amplitude for its σ
        grad = np.array([a, b]) / max(amp, 1e-300) * abs(f) * scale
        sigma = float(np.sqrt(max(grad @ cov @ grad, 0.0)))
        axis = math.degrees(math.atan2(b, a)) / k
        if per_rate2:
            kind = f"a scale factor varying as {k}θ that grows with the rate (a loop's lag)"
        elif per_rate:
            kind = f"a scale factor varying as {k}θ"
        else:
            kind = f"a {k}θ harmonic" + (
                " whose size curves with temperature" if per_t2
                else " whose size changes with temperature" if per_t else ""
            )  # fmt: skip
        words = f"{kind} of {amp:.3g} {unit} (axis at {axis:.1f}° el.)"
        return {"size": amp, "sigma": sigma, "unit": unit, "axis_deg": axis, "words": words}
    what, unit, factor = _SCALAR[shape]
    value = float(coef[0]) * factor * f  # Ω terms: Ω_apparent = Ω·(1 − c/k_e), so −c/k_e too
    sigma = float(math.sqrt(max(cov[0, 0], 0.0))) * abs(factor * f)
    words = f"{what}: {value:.3g} {unit}"
    if shape == "ΔT³+ΔT⁴":  # the size is the cubic's; the quartic beside it
        words += f", {float(coef[1]) * factor * f:.3g} °/h/°C⁴"
    return {"size": value, "sigma": sigma, "unit": unit, "words": words}


def distinct(cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """`cols` without 2θ·Ω² where the table turns at one rate (then it is 2θ·Ω, which
    keeps the name)."""
    lag, ripple = cols.get("2θ·Ω²"), cols.get("2θ·Ω")
    if lag is None or ripple is None:
        return cols
    coef, *_ = np.linalg.lstsq(ripple, lag, rcond=None)
    if np.linalg.norm(lag - ripple @ coef) > 1e-3 * np.linalg.norm(lag):
        return cols
    return {k: v for k, v in cols.items() if k != "2θ·Ω²"}


def scores(r, j, cols: dict[str, np.ndarray]) -> dict[str, tuple[float, int]]:
    """`{shape: (score S, degrees of freedom q)}` of every shape in `cols` (whitened columns)
    against the whitened residual `r` of a fit with whitened Jacobian `j` — the screening's
    score test, one QR of `j` for all; shapes the model already spans are left out."""
    q_j, _ = np.linalg.qr(j)
    out = {}
    for name, g in distinct(cols).items():
        s, alias, _ = stats.score(r, j, g, q_j)
        if alias < 0.999:
            out[name] = (s, int(g.shape[1]))
    return out


def describe(
    r, j, cols: dict[str, np.ndarray], k_e: float, alpha: float = 1e-3, classes=None
) -> dict | None:
    """The strongest shape left in the whitened residual `r` of a fit with whitened Jacobian
    `j`, given each shape's whitened columns `cols`. Each shape is judged at the noise level
    the residual shows once it is fitted, per row class (`classes`: an integer per row, e.g.
    static / moving dwell windows; None: one class), with the F(q, ν) tail
    ([`level_test`][hrgjax.discovery.stats.level_test]): the whitening comes from an
    estimated noise model, and where that is off (a 60-s dwell's angle random walk estimated
    at 0: static windows' residual mean square 2–6) a χ²_q reading called pure noise a
    5σ harmonic in 15 % of null grids. **Returns** `{"shape", "words", "size", "sigma",
    "unit", "score", "dof", "p_value", "sigmas", "significant", "runners_up"}` (`score`: at
    that level; `significant`: p below `alpha` after a Bonferroni factor for the shapes
    tried; a harmonic's `words` also say whether it changes with temperature), or None
    without shapes."""
    test = lambda jj, g: stats.level_test(r, jj, g, classes)
    rows = []
    cols = distinct(cols)
    for name, g in cols.items():
        s, alias, step, p, level = test(j, g)
        if alias >= 0.999:
            continue
        rows.append((p, -s, name, g, step, level))
    if not rows:
        return None
    # the largest score first, as the screening ranks (by p, a shape seen on the many moving
    # windows — Ω·ΔT — would beat the ΔT drift whose evidence sits on the static ones)
    rows.sort(key=lambda row: row[1])
    if "+" in rows[0][2]:
        # a shape holding another's columns (ΔT³+ΔT⁴ ⊃ ΔT³) fits at least as well: it is
        # named only where its extra columns add significantly to the smaller one's
        inner = next((row for row in rows if row[2] == rows[0][2].split("+")[0]), None)
        if inner is not None:
            k = inner[3].shape[1]
            extra = test(np.concatenate([j, inner[3]], axis=1), rows[0][3][:, k:])[3]
            if extra >= alpha:
                rows.remove(inner)
                rows.insert(0, inner)
    p, s, name, g, step, level = rows[0]
    s, p = -s, min(1.0, p * len(cols))
    q_j, _ = np.linalg.qr(j / level[:, None])  # the size's covariance at the shape's level
    g_s = g / level[:, None]
    g_t = g_s - q_j @ (q_j.T @ g_s)
    cov = np.linalg.pinv(g_t.T @ g_t)
    out = {"shape": name, **_size(name, step, cov, k_e)}
    z = _sigmas(p, s)
    significant = p < alpha
    out["words"] += f", {z:.0f}σ" if significant else f", not significant ({z:.1f}σ)"
    if significant and name.endswith("θ") and f"{name}·ΔT" in cols:
        # does its size change with temperature? the ΔT partner, given the harmonic
        changes = test(np.concatenate([j, g], axis=1), cols[f"{name}·ΔT"])[3] < alpha
        out["words"] += ", changing with temperature" if changes else ", constant over temperature"
    out |= {
        "score": float(s),
        "dof": int(g.shape[1]),
        "p_value": float(p),
        "sigmas": float(z),
        "significant": bool(significant),
        "runners_up": [{"shape": n, "score": float(-sc)} for _, sc, n, *_ in rows[1:4]],
    }
    return out


def group_columns(groups) -> dict:
    """Whitened columns of the generic shapes (`columns`) on the rows of a continuous
    problem's `groups` (records' `Runs` and a mixed log's dwell `Windows`): each shape's
    pattern rate at a block's mean covariates times the block's length, whitened as the
    residual is (dwell windows: divided by their σ). `{shape: column}`, all-zero ones left
    out."""
    from .records import Windows

    parts: dict[str, list] = {}
    for g in groups:
        if isinstance(g, Windows):
            c, n = g.cov, len(g.run)
            full = lambda v, n=n: np.broadcast_to(np.asarray(v, float), (n,))
            cov = {"theta": full(c.theta), "dT": full(c.temperature) - T_REF_C,
                   "Tdot": np.zeros(n), "rate": full(c.rate), "accel_z": full(c.accel_z),
                   "t_run": full(c.t_run), "arc": np.asarray(g.arc)}  # fmt: skip
            sigma = np.asarray(g.sigma)[:, None]
            for name, col in columns(cov, drop=False).items():
                parts.setdefault(name, []).append(col / sigma)
            continue
        b = np.asarray(g.bidx)
        t, temp = np.asarray(g.t), np.asarray(g.temp)
        for i in range(len(g.run)):
            span = np.diff(t[i, b])

            def mean(v, i=i, b=b):  # over each block's samples b[k] … b[k+1] − 1
                cs = np.concatenate([[0.0], np.cumsum(np.asarray(v)[i])])
                return (cs[b[1:]] - cs[b[:-1]]) / np.diff(b)

            cov = {
                "theta": mean(g.theta),
                "dT": mean(g.temp) - T_REF_C,
                "Tdot": np.diff(temp[i, b]) / span,
                "rate": mean(g.rate),
                "accel_z": mean(g.accel),
                "t_run": 0.5 * (t[i, b[1:]] + t[i, b[:-1]]) - t[i, 0],
            }
            w = np.asarray(g.whiten[i])
            for name, col in columns(cov, drop=False).items():
                parts.setdefault(name, []).append(w @ (col * span[:, None]))
    cols = {k: np.concatenate(v) for k, v in parts.items()}
    return {k: v for k, v in cols.items() if np.any(v)}
