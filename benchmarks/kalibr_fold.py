"""Kalibr's form of a Gauss–Markov rate over a record's octaves (`hrgjax.allan.kalibr`).

For T from Δt/4 to 10⁶Δt at 100 Hz, over the 15 octaves τ₀ = Δt … τ_max = 2¹⁴Δt (a
2¹⁷-sample record's fit), the ratio of the exported Allan deviation to the term's exact one
(lowest–highest over the octaves) under:

- the rule (`fold_gauss_markov`): white 2σ²T or walk 2σ²/T, the smaller worst;
- white alone and walk alone (the old export: white for T ≤ 4Δt, else the walk);
- the least-squares pair (N², K² ≥ 0) in log Allan variance over the octaves;
- the pair with the least worst ratio that still bounds the term (a linear programme).

No JAX computation: a second. Usage: `.venv/bin/python benchmarks/kalibr_fold.py
[--sampling point]`.
"""

import sys

import numpy as np
from scipy.optimize import least_squares, linprog

from hrgjax.allan.kalibr import fold_gauss_markov
from hrgjax.allan.octave_covariance import gm_white_level, unit_avar

SAMPLING = "point" if "point" in sys.argv else "interval"
DT = 0.01
MS = 2.0 ** np.arange(15)
STEPS = (0.25, 1, 2, 4, 8, 16, 64, 128, 256, 1024, 4096, 16384, 1e5, 1e6)


def span(r):
    return f"{np.sqrt(r.min()):.3g}–{np.sqrt(r.max()):.4g}"


def main():
    uw = unit_avar("angle_random_walk", MS, DT, sampling=SAMPLING)
    uk = unit_avar("rate_random_walk", MS, DT, sampling=SAMPLING)
    print(f"sampling {SAMPLING}; octaves {DT:g}–{MS[-1] * DT:g} s; ratios in Allan deviation")
    print("| T/Δt | rule | white | walk | least squares in log | least worst bound |")
    print("|---|---|---|---|---|---|")
    for steps in STEPS:
        t = steps * DT
        g = unit_avar("gauss_markov", MS, DT, DT / t, SAMPLING)
        w, k = gm_white_level(1.0, t, DT, SAMPLING) * uw / g, 2.0 / t * uk / g
        rule = fold_gauss_markov(1.0, t, MS * DT, DT, SAMPLING)
        # the least-squares pair: log(a·w + b·k) against 0, from three starts
        res = min(
            (least_squares(lambda p, w=w, k=k: np.log(np.exp(p[0]) * w + np.exp(p[1]) * k), p0,
                           bounds=([-80, -80], [5, 5])) for p0 in ([0, -30], [-30, 0], [0, 0])),
            key=lambda s: s.cost,
        )  # fmt: skip
        ls = np.exp(res.x[0]) * w + np.exp(res.x[1]) * k
        # min r with 1 ≤ a·w + b·k ≤ r at every octave
        a_ub = np.vstack([np.c_[w, k, -np.ones_like(g)], np.c_[-w, -k, np.zeros_like(g)]])
        lp = linprog([0, 0, 1], A_ub=a_ub, b_ub=np.r_[np.zeros_like(g), -np.ones_like(g)],
                     bounds=[(0, None)] * 3, method="highs")  # fmt: skip
        mm = lp.x[0] * w + lp.x[1] * k
        print(f"| {steps:g} | {rule['form']} {rule['worst']:.4g} | {span(w)} | {span(k)} | "
              f"{span(ls)} | {span(mm)} (walk {lp.x[1]:.2g}×2σ²/T) |")  # fmt: skip


if __name__ == "__main__":
    main()
