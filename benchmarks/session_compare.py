"""Second-session comparison against known truth: the offset's σ and the paired test.

Pure numpy Monte Carlo of `hrgjax.calibration.session_offset` and
`hrgjax.calibration.paired_difference`, no simulator (seconds):

1. **Offset σ with unequal static runs.** White rate noise (a run's variance ∝ 1/T, the
   model the duration weighting assumes), a known offset: the share of sessions whose
   offset is within ±1σ, ±2σ and the 95 % t interval (`Offset.half_width`), against
   Student-t with n − 1 dof; the pre-2026-11-30 sandwich σ beside it.
2. **Paired test, equal compensators** (the false-"different" rate, nominal 5 % at 95 %)
   and **unequal ones** (power). A static run's residual is the session's offset plus the
   sensor's noise, shared by every compensator (0.022 °/h), plus what each compensator
   leaves at that point (0.012 °/h each when equal: RMS ≈ 0.025 °/h; 0.020 °/h for the
   worse one: RMS ≈ 0.030 °/h, the docs' table's spread; 0.030 °/h: RMS ≈ 0.037 °/h); Gaussian or t₃ tails. The offset
   is measured as `compare` does, with the compensator whose runs scatter least, and taken
   off both. Beside the t test: a percentile bootstrap of the mean of d_i (999 resamples),
   and the unpaired reading "the RMS differ by more than 2× their sampling errors".

`python benchmarks/session_compare.py [--sessions 4000] [--seed 0]` (≈ 20 s on 2 cores).
"""

import argparse
import math
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from hrgjax.calibration import paired_difference, session_offset  # noqa: E402


def offset_coverage(durations, n_sessions, rng, c=0.02, truth=0.43):
    """Share within ±1σ, ±2σ, 95 % t interval; the old sandwich's ±1σ, ±2σ."""
    T = np.asarray(durations, float)
    n = T.size
    z, inside, z_old = [], [], []
    for _ in range(n_sessions):
        r = truth + c * np.sqrt(300.0 / T) * rng.normal(size=n)
        off = session_offset({"static": np.ones(n, bool), "drift_error_dph": r, "duration_s": T})
        z.append((off.value_dph - truth) / off.sigma_dph)
        inside.append(abs(off.value_dph - truth) <= off.half_width(0.95))
        old = math.sqrt(n / (n - 1) * np.sum(T**2 * (r - off.value_dph) ** 2) / T.sum() ** 2)
        z_old.append((off.value_dph - truth) / old)
    z, z_old = np.abs(z), np.abs(z_old)
    t1, t2 = (2 * stats.t.cdf(k, n - 1) - 1 for k in (1, 2))
    return (
        np.mean(z < 1),
        np.mean(z < 2),
        np.mean(inside),
        t1,
        t2,
        np.mean(z_old < 1),
        np.mean(z_old < 2),
    )


def draw(rng, shape, tails):
    if tails == "normal":
        return rng.normal(size=shape)
    return rng.standard_t(3, size=shape) / math.sqrt(3.0)  # unit variance


def paired_rates(n_runs, sigma_a, sigma_b, tails, n_sessions, rng, boot=999):
    """Rates of "different" (t test, bootstrap, unpaired) and of "A better" (t test)."""
    noise = 0.022 * draw(rng, (n_sessions, n_runs), tails)
    ra = 0.43 + noise + sigma_a * draw(rng, (n_sessions, n_runs), tails)
    rb = 0.43 + noise + sigma_b * draw(rng, (n_sessions, n_runs), tails)
    t_diff = t_a = boot_diff = unpaired = 0
    for k in range(n_sessions):
        # the session's offset: from the compensator whose runs scatter least (equal runs)
        b = ra[k].mean() if ra[k].std() <= rb[k].std() else rb[k].mean()
        ea, eb = ra[k] - b, rb[k] - b
        p = paired_difference(ea, eb, level=0.95)
        t_diff += p.verdict != "none"
        t_a += p.verdict == "a"
        d = ea**2 - eb**2
        means = d[rng.integers(0, n_runs, size=(boot, n_runs))].mean(axis=1)
        lo, hi = np.quantile(means, [0.025, 0.975])
        boot_diff += hi < 0 or lo > 0
        sa, sb = p.rms_a / math.sqrt(2 * n_runs), p.rms_b / math.sqrt(2 * n_runs)
        unpaired += abs(p.rms_a - p.rms_b) > 2 * math.hypot(sa, sb)
    return t_diff / n_sessions, boot_diff / n_sessions, unpaired / n_sessions, t_a / n_sessions


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=4000, help="Monte Carlo sessions")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    n = args.sessions
    print(f"1. offset σ, white rate noise, {n} sessions per row (binomial 1σ ≈ 0.008)")
    print(f"{'static runs':<24} {'±1σ':>6} {'±2σ':>6} {'95% t':>6} {'(t: ±1σ':>8} {'±2σ)':>6}"
          f" {'old ±1σ':>8} {'old ±2σ':>8}")  # fmt: skip
    cases = {
        "1×3600 s + 10×60 s": [3600.0] + [60.0] * 10,
        "1×3600 s + 2×60 s": [3600.0, 60.0, 60.0],
        "12 runs, 30–3000 s": list(np.geomspace(30, 3000, 12)),
        "57 × 120 s": [120.0] * 57,
        "3 × 120 s": [120.0] * 3,
    }
    for name, T in cases.items():
        c1, c2, c95, t1, t2, o1, o2 = offset_coverage(T, n, rng)
        print(f"{name:<24} {c1:6.3f} {c2:6.3f} {c95:6.3f} {t1:8.3f} {t2:6.3f} {o1:8.3f} {o2:8.3f}")
    m = max(n // 4, 200)
    tol = math.sqrt(0.05 * 0.95 / m)
    print(f"\n2. paired test at 95 %, {m} sessions per row (binomial 1σ at 5 %: {tol:.3f})")
    print(f"{'case':<38} {'runs':>4} {'t: diff':>8} {'A better':>9} {'bootstrap':>10} "
          f"{'unpaired':>9}")  # fmt: skip
    for tails in ("normal", "t3"):
        for n_runs in (10, 18, 57):
            for label, sb in (
                ("equal (0.012, 0.012)", 0.012),
                ("B worse (0.012, 0.020)", 0.020),
                ("B much worse (0.012, 0.030)", 0.030),
            ):
                td, bd, up, ta = paired_rates(n_runs, 0.012, sb, tails, m, rng)
                print(f"{label + ', ' + tails:<38} {n_runs:>4} {td:8.3f} {ta:9.3f} {bd:10.3f} "
                      f"{up:9.3f}")  # fmt: skip
    print(f"\n{time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
