"""Discovery on pure-noise dwell grids: are the screening and leftover p-values calibrated?

`hidden_effect_dataset(None, key=PRNGKey(s))` (5 temperatures × 9 wave angles × 60 s, static
and 5 °/s, 0.5-s samples; nothing hidden: the nominal model is the truth). On each grid, the
nominal fit of [`DwellProblem`][hrgjax.discovery.dwell.DwellProblem] (every 4th run held out,
as `discover` does), its screening of the catalogue and its leftover shape
([`leftover.describe`][hrgjax.discovery.leftover.describe]). Printed side by side:

- **before** (the code up to 2026-11-30): the score read as χ²_q at the windows' σ from the
  estimated noise model — recomputed here from the same fit (`stats.score`, `chi2_sf`; the
  leftover's strongest shape by score, Bonferroni over the shapes), which reproduces the old
  code's figures exactly on the audit's seeds;
- **after**: the p-values `discover` now reports, judged at the level the residual shows per
  window class once the candidate / shape is fitted, F(q, ν) tail
  ([`stats.level_test`][hrgjax.discovery.stats.level_test]).

Rates: the leftover flagged `significant` (Bonferroni p < 1e-3: nominal ≤ 0.1 %), leftover
p < 0.05 (≤ 5 %), screening p-values below 0.05 / 0.01 (≈ 5 % / 1 %; within a grid they are
correlated), and grids where some candidate passes the acceptance rule's p-value gate
(p < 0.01 / candidates: ≤ 1 %). Also the estimated angle random walk and the static windows'
Birge ratio (whitened residual mean square), the cause of the old excess (audit 2026-11-30:
an ARW estimated at 0 on 60-s dwells leaves the static windows' σ 1.5–2.5× small).

Usage: `.venv/bin/python benchmarks/discovery_null.py [--seeds N] [--start S]` (default 20
seeds from 0; ≈ 4 s a grid on 2 CPUs).

**Continuous nulls** (`--continuous [--seeds N] [--start S] [--duration D]`): six records of
`continuous_dataset(None, key=PRNGKey(s), duration_s=D)` (default 12 seeds from 1000, 3100 s:
the audit's instance was seed 1010), the default gyro's own noise — white angle noise 1″,
angle random walk 0.002 °/√h, Gauss–Markov bias instability 0.003 °/h with T_c = 600 s,
switch-on bias 0.2 °/h per run — and nothing hidden; the whole `discover` on each. Printed:
the verdict (anything but `none` is false: a name is a false effect, `unexplained` a false
"structure left"), the leftover shape, and the noise model's estimated switch-on spread σ_b
and Gauss–Markov part against the truth. ≈ 15 s a log on 2 busy CPUs after a ≈ 60-s compile.
Measured 2026-11-30 on seeds 1000–1031 (`--continuous` and `--continuous --start 1012 --seeds
20`): not `none` 1/32 with σ_b's moment estimate (seed 1010: σ_b 0.04 °/h, `unexplained`),
0/32 with REML (`hrgjax.discovery.run_bias`; seed 1010: σ_b 0.135 °/h).
"""

import argparse
import time

import jax
import numpy as np
from _common import machine, report

from hrgjax.calibration.reduce import K_E_NOMINAL, WINDOW_S
from hrgjax.discovery import leftover, stats
from hrgjax.discovery.dwell import DwellProblem
from hrgjax.discovery.effects import NOMINAL
from hrgjax.discovery.generate import hidden_effect_dataset


def old_leftover_p(fit, cols) -> float:
    """The leftover's Bonferroni p as the code up to 2026-11-30 read it: the strongest shape
    by its score at the windows' σ, χ²_q tail."""
    sc = leftover.scores(fit.r, fit.j, cols)
    s, q = max(sc.values())
    return min(1.0, stats.chi2_sf(s, q) * len(leftover.distinct(cols)))


def one(seed: int) -> dict:
    data = hidden_effect_dataset(None, key=jax.random.PRNGKey(seed))
    runs = np.unique(data.run)
    problem = DwellProblem(data, K_E_NOMINAL, WINDOW_S, runs[3::4])
    model = list(NOMINAL)
    base = problem.fit(model)
    cands = [c for c in problem.candidates(model) if c not in model]
    rows = problem.screen(base, cands, model)
    old_p = [stats.chi2_sf(r["score"], r["_columns"]().shape[1]) for r in rows]
    new_p = [r["p_value"] for r in rows]
    left = problem.leftover(base)
    static = problem.row_classes() == 1
    r = np.asarray(base.r)
    return {
        "seed": seed,
        "n_cands": len(cands),
        "old_screen": old_p,
        "new_screen": new_p,
        "old_left": old_leftover_p(base, problem.shape_columns),
        "new_left": left["p_value"],
        "new_left_significant": left["significant"],
        "arw": problem.nm.angle_random_walk,
        "birge_static": float(np.mean(r[static] ** 2)),
        "birge_moving": float(np.mean(r[~static] ** 2)),
    }


def rates(rows, which):
    scr = np.concatenate([row[f"{which}_screen"] for row in rows])
    left = np.asarray([row[f"{which}_left"] for row in rows])
    gate = [min(row[f"{which}_screen"]) < 0.01 / row["n_cands"] for row in rows]
    return {
        "leftover significant (p<1e-3)": np.mean(left < 1e-3),
        "leftover p<0.05": np.mean(left < 0.05),
        "screening p<0.05": np.mean(scr < 0.05),
        "screening p<0.01": np.mean(scr < 0.01),
        "a candidate passes the p gate": np.mean(gate),
    }


def main(n: int, start: int):
    print(f"machine: {machine()}")
    rows = []
    t0 = time.perf_counter()
    for seed in range(start, start + n):
        row = one(seed)
        rows.append(row)
        print(
            f"seed {seed:3d}: ARW {row['arw']:.2g}  static r² {row['birge_static']:.2f}  "
            f"moving r² {row['birge_moving']:.2f}  leftover p {row['old_left']:.2g} → "
            f"{row['new_left']:.2g}  min screening p {min(row['old_screen']):.2g} → "
            f"{min(row['new_screen']):.2g}",
            flush=True,
        )
    wall = (time.perf_counter() - t0) / n
    old, new = rates(rows, "old"), rates(rows, "new")
    n_p = sum(len(row["new_screen"]) for row in rows)
    print(f"\n{n} null grids, {n_p} screening p-values; {wall:.1f} s a grid")
    print(f"{'':>32} {'before':>8} {'after':>8}  nominal")
    nominal = ("≤ 0.1 %", "≤ 5 %", "5 %", "1 %", "≤ 1 %")
    for (k, a), b, nom in zip(old.items(), new.values(), nominal, strict=True):
        print(f"{k:>32} {100 * a:7.1f}% {100 * b:7.1f}%  {nom}")
    assert all(r["new_left_significant"] == (r["new_left"] < 1e-3) for r in rows)
    report("discovery null: leftover significant", 100 * new["leftover significant (p<1e-3)"],
           "%", "before", 100 * old["leftover significant (p<1e-3)"], "≤ 0.1 %")  # fmt: skip
    report("discovery null: screening p < 0.01", 100 * new["screening p<0.01"], "%",
           "before", 100 * old["screening p<0.01"], "≈ 1 %")  # fmt: skip


def continuous(n: int, start: int, duration_s: float):
    """False verdicts of `discover` on continuous null records (module docstring)."""
    from hrgjax.discovery import discover
    from hrgjax.discovery.generate import continuous_dataset

    print(f"machine: {machine()}")
    verdicts, times = [], []
    for seed in range(start, start + n):
        data = continuous_dataset(None, key=jax.random.PRNGKey(seed), duration_s=duration_s)
        t0 = time.perf_counter()
        rep = discover(data)
        times.append(time.perf_counter() - t0)
        verdicts.append(rep.verdict)
        left = rep.leftover["words"] if rep.leftover else "-"
        nz = rep.noise
        print(
            f"seed {seed:5d}: {rep.verdict:>11} {rep.missing_effect or '':>24}  σ_b "
            f"{nz['run_bias_dph']:.3f} °/h  GM {nz['gauss_markov_dph']:.4f} °/h "
            f"({nz['gauss_markov_time_s']:g} s)  leftover: {left}  [{times[-1]:.0f} s]",
            flush=True,
        )
    false = sum(v != "none" for v in verdicts)
    named = sum(v in ("found", "ambiguous") for v in verdicts)
    print(
        f"\n{n} continuous null logs ({duration_s:g} s): verdict not 'none' {false}/{n} "
        f"(a name {named}, 'unexplained' {verdicts.count('unexplained')}); truth σ_b 0.2 °/h, "
        f"GM 0.003 °/h (600 s); median {np.median(times):.0f} s a log"
    )
    report("discovery continuous null: verdict not none", 100 * false / n, "%", target="≤ 5 %")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--start", type=int, default=None)
    ap.add_argument("--continuous", action="store_true")
    ap.add_argument("--duration", type=float, default=3100.0)
    a = ap.parse_args()
    if a.continuous:
        continuous(a.seeds or 12, 1000 if a.start is None else a.start, a.duration)
    else:
        main(a.seeds or 20, a.start or 0)
