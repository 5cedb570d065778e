"""Do the Allan deviation's intervals cover the truth at long τ? Monte Carlo with known truth.

Records of white rate noise (angle random walk, N) plus rate random walk (K), 1 Hz, 20 000 s
(a gyro's overnight log), whose true overlapping Allan variance is N²/τ + K²τ/3. For each
record `hg.allan.deviation(y, 1 Hz, "oadev")` on its octave grid (m = 1 … 8 192); at every τ
the estimate is standardised through its own χ² law: with u = edf·σ̂²/σ² and p its χ²(edf)
probability, z = Φ⁻¹(p) is a standard normal when the EDF is right, and |z| < 1 exactly when
the ±1σ interval covers the truth. Three balances: the random walk overtaking the white rate
noise at τ = 300 s (the long τ are pure random walk) and at 2 000 s (white up to the last τ
the lag-1 autocorrelation can read, random walk beyond), and overtaking white angle
(readout) noise, σ_x per sample, at 1 000 s (true AVAR 3σ_x²/τ² + K²τ/3).

"before": the noise type of the last τ with ≥ 30 decimated points carried to every longer τ
(hrgjax until issue 46); "after": what `deviation` reports now (the B1 and R(n) ratios
beyond that reach, `hrgjax.allan.noise_id`). Same estimates, only the EDF differs.

Targets (issue 46): at the longest τ, 68 ± 8 % within ±1σ.

`--noise-rule stable32` puts Stable32's rule (B1 on the drift-removed rate down to 2
averages) in the "after" column instead.

`--fit-noise`: the IEEE 952 line fit `hg.allan.fit_noise` instead — do its coefficients'
σ and intervals cover the truth? Records of 20 000 s at 1 Hz, oadev on the octave grid:
white rate noise N = 1 plus a rate random walk K (overtaking N at 300 s), fitted with N and
K; white rate noise, flicker rate noise B (0.6643·B = 0.15, a sum of first-order
Gauss–Markov rates with correlation times 2× apart from 0.5 s to 2.6·10⁵ s, equal σ² — an
Allan variance flat within 2 % from 2 s to 8 192 s, 17 % higher at 1 s where the white
noise is 44× larger; B read off its mean) and a rate random walk overtaking B at 1 000 s,
fitted with N, B and K; and N + B fitted
with N and B. For each coefficient: the share of records whose truth lies within value ± σ
and within the 68.27 % and 95 % intervals (each record fitted at both levels), the z-RMS of
(value − truth)/σ, the median width of the 95 % interval over the symmetric one's, and
fit_noise's mean time per call. Intervals: "pre-58" the fit as it was until issue 58 (EDF
weights, the τ points taken as independent, re-computed here); "sym" the GLS fit's
symmetric interval on the coefficient², c² ± zσ(c²) (fit_noise's until the skewed one,
re-computed here from its value and σ); "now" what `fit_noise` reports (the estimate's
skewed law inverted). Run against an older hrgjax (PYTHONPATH) the "now" column is its own.

Usage: `.venv/bin/python benchmarks/coverage_allan.py [--n 200] [--seed 0]
[--noise-rule hrgjax|stable32] [--fit-noise] [--gaps 0.02]` (200 records per balance:
about 15 s on 2 cores; `--fit-noise`: 4–7 min on 2 busy cores, `--n 400` 13 min; `--gaps`:
white angle, white rate and random-walk records with that share of rates missing, the noise
type read before and after the gap-free R(n) arbitration, ≈ 1 min: `main_gaps`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402

LENGTH = 20_000  # samples at 1 Hz
WHITE = 1.0  # N: the white noise σ per 1-s sample [rate unit]
ANGLE_WHITE = 30.0  # σ_x: white angle (readout) noise per sample [rate unit × s]
ONE_SIGMA = 0.682689  # the ±1σ level of a normal law
BALANCES = (("rate", 300.0), ("rate", 2000.0), ("angle", 1000.0))
"""(the white noise, τ [s] where the random walk overtakes it)."""


def _carried(x, ms):
    """The noise type before issue 46: lag-1 autocorrelation where the decimated phase has
    ≥ 30 points, the last such α carried beyond."""
    out, last = [], None
    for m in ms:
        if x[:: int(m)].size >= hg.allan.ACF_POINTS:
            last = int(hg.allan.noise_id(x, [int(m)])[0])
        out.append(last)
    return np.asarray(out)


def _z(dev, truth, edf):
    from scipy import stats

    u = edf * (dev / truth) ** 2
    p = np.clip(stats.chi2.cdf(u, edf), 1e-12, 1 - 1e-12)
    return stats.norm.ppf(p)


def run(n: int, white: str, crossover: float, seed: int, noise_rule: str = "hrgjax"):
    """z (records, τ) before and after, the α identified, and the τ grid. `white`: "rate"
    (N²/τ) or "angle" (white phase noise, 3σ_x²/τ² at 1 Hz)."""
    rng = np.random.default_rng(seed)
    if white == "rate":
        k = math.sqrt(3.0) * WHITE / crossover
    else:
        k = 3.0 * ANGLE_WHITE / crossover**1.5
    before, after, alphas = [], [], []
    for _ in range(n):
        walk = k * np.cumsum(rng.normal(size=LENGTH))
        if white == "rate":
            y = WHITE * rng.normal(size=LENGTH) + walk
        else:
            y = ANGLE_WHITE * np.diff(rng.normal(size=LENGTH + 1)) + walk
        r = hg.allan.deviation(y, 1.0, kind="oadev", taus="octave", noise_rule=noise_rule)
        floor = WHITE**2 / r.taus if white == "rate" else 3 * ANGLE_WHITE**2 / r.taus**2
        truth = np.sqrt(floor + k**2 * r.taus / 3)
        x = np.concatenate([[0.0], np.cumsum(y)])
        old = _carried(x, r.m)
        edf_old = np.asarray([
            hg.allan.edf_greenhall(max(int(a), -2), 2, int(m), x.size, True, False)
            for a, m in zip(old, r.m, strict=True)
        ])  # fmt: skip
        before.append(_z(r.dev, truth, edf_old))
        after.append(_z(r.dev, truth, r.edf))
        alphas.append(r.alpha)
    return np.asarray(before), np.asarray(after), np.asarray(alphas), r.taus


def figures(z):
    return {
        "within_1sigma": float(np.mean(np.abs(z) < 1.0)),
        "within_2sigma": float(np.mean(np.abs(z) < 2.0)),
        "z_rms": float(np.sqrt(np.mean(z**2))),
    }


FIT_CASES = (
    ("N + K", ("angle_random_walk", "rate_random_walk"), 0.0, math.sqrt(3.0) / 300.0),
    ("N + B + K", ("angle_random_walk", "bias_instability", "rate_random_walk"),
     0.15 / 0.6643, 0.15 * math.sqrt(3.0 / 1000.0)),
    ("N + B", ("angle_random_walk", "bias_instability"), 0.15 / 0.6643, 0.0),
)  # fmt: skip
"""(case, terms fitted, B, K) with N = WHITE."""
FLICKER_T = 0.5 * 2.0 ** np.arange(20)  # the flicker's Gauss–Markov correlation times [s]


def _flicker_unit_level(taus):
    """σ² of each of the flicker's Gauss–Markov rates giving B = 1: the mean of their exact
    Allan variance over `taus` (1 Hz samples) equal to 2 ln 2/π — point samples of AR(1)
    rates, as `_flicker` makes them (`sampling="point"`)."""
    from hrgjax.allan.octave_covariance import unit_avar

    avar = unit_avar("gauss_markov", taus, 1.0, 1.0 / FLICKER_T, sampling="point").sum(0)
    return 2 * math.log(2) / math.pi / float(np.exp(np.mean(np.log(avar)))), avar


def _flicker(rng, s2):
    """A sum of first-order Gauss–Markov rates, σ² = s2 each, started stationary."""
    from scipy.signal import lfilter

    out = np.zeros(LENGTH)
    for t in FLICKER_T:
        phi = math.exp(-1.0 / t)
        e = rng.normal(size=LENGTH) * math.sqrt(s2 * (1 - phi * phi))
        e[0] = rng.normal() * math.sqrt(s2)
        out += lfilter([1.0], [1.0, -phi], e)
    return out


def _independent(result, terms):
    """fit_noise until issue 58: EDF weights, the τ points independent (value, σ, low, high)."""
    from statistics import NormalDist

    from hrgjax._nnls import nnls

    names = [n for n, *_ in hg.allan.NOISE_TERMS]
    t, var, edf = result.taus, result.dev**2, result.edf
    basis = np.stack([f(t) for n, _, _, f in hg.allan.NOISE_TERMS if n in terms], axis=1)
    model = var.copy()
    for _ in range(5):
        w = np.sqrt(edf / 2.0) / model
        a = basis * w[:, None]
        scale = np.linalg.norm(a, axis=0)
        coef = nnls(a / scale, var * w) / scale
        model = np.maximum(basis @ coef, 1e-300)
    a = basis * w[:, None] / scale
    cov = np.linalg.pinv(a.T @ a) / np.outer(scale, scale)
    z = NormalDist().inv_cdf(0.5 + result.ci / 2)
    out = {}
    for i, n in enumerate(n for n in names if n in terms):
        c, sc = coef[i], math.sqrt(max(cov[i, i], 0.0))
        out[n] = (math.sqrt(c), sc / (2 * math.sqrt(c)) if c > 0 else math.sqrt(sc),
                  math.sqrt(max(c - z * sc, 0.0)), math.sqrt(c + z * sc))  # fmt: skip
    return out


def _symmetric(value, sigma, z):
    """fit_noise's interval before the skewed one (GLS, from issue 58): c² ± z·σ(c²)
    (σ(c²) = 2cσ_c), a negative end at 0, the ends' square roots."""
    sc = 2 * value * sigma
    return np.sqrt(np.maximum(value**2 - z * sc, 0.0)), np.sqrt(value**2 + z * sc)


def run_fit_noise(n: int, seed: int):
    """{case: ({term: {"before"|"after": (records, 6) of value, σ, low, high at 95 % and low,
    high at 68.27 %}}, truth)}, the methods, the flicker's ripple and fit_noise's mean time
    per call [s] (the 95 % fit)."""
    taus = 2.0 ** np.arange(int(math.log2(LENGTH / 2)) + 1)
    unit_s2, flat = _flicker_unit_level(taus)
    ripple = float(np.max(np.abs(flat[1:] * unit_s2 / (2 * math.log(2) / math.pi) - 1)))
    out, methods, seconds = {}, set(), []
    for case, terms, b, k in FIT_CASES:
        rng = np.random.default_rng(seed)
        truth = {"angle_random_walk": WHITE, "bias_instability": b, "rate_random_walk": k}
        got = {t: {"before": [], "after": []} for t in terms}
        for _ in range(n):
            y = WHITE * rng.normal(size=LENGTH)
            if k:
                y += k * np.cumsum(rng.normal(size=LENGTH))
            if b:
                y += _flicker(rng, b * b * unit_s2)
            r = hg.allan.deviation(y, 1.0, kind="oadev", taus="octave", ci=0.95)
            t0 = time.perf_counter()
            fit = hg.allan.fit_noise(r, terms=terms)
            seconds.append(time.perf_counter() - t0)
            fit68 = hg.allan.fit_noise(dataclasses.replace(r, ci=ONE_SIGMA), terms=terms)
            methods.add(fit.method)
            old = _independent(r, terms)
            for t in terms:
                got[t]["before"].append(old[t] + (math.nan, math.nan))
                got[t]["after"].append((fit.value[t], fit.sigma[t], fit.low[t], fit.high[t],
                                        fit68.low[t], fit68.high[t]))  # fmt: skip
        out[case] = ({t: {w: np.asarray(v) for w, v in d.items()} for t, d in got.items()},
                     truth)  # fmt: skip
    return out, methods, ripple, float(np.mean(seconds))


def fit_figures(rows, truth):
    value, sigma, low, high, low68, high68 = rows.T
    z = (value - truth) / np.maximum(sigma, 1e-300)
    sym_lo, sym_hi = _symmetric(value, sigma, 1.959964)
    sym68_lo, sym68_hi = _symmetric(value, sigma, 1.0)
    held = lambda lo, hi: float(np.mean((lo <= truth) & (truth <= hi)))  # noqa: E731
    return {"within_1sigma": float(np.mean(np.abs(z) < 1.0)),
            "within_95": held(low, high), "within_68": held(low68, high68),
            "symmetric_95": held(sym_lo, sym_hi), "symmetric_68": held(sym68_lo, sym68_hi),
            "width_ratio": float(np.median(((high - low) / (sym_hi - sym_lo))[value > 0])),
            "z_rms": float(np.sqrt(np.mean(z**2))), "bias": float(np.mean(value) / truth - 1)}  # fmt: skip


def main_fit_noise(args):
    from _common import report

    t0 = time.perf_counter()
    out, methods, ripple, per_fit = run_fit_noise(args.n, args.seed)
    print(f"fit_noise: {args.n} records of {LENGTH} s per case (seed {args.seed}), oadev octaves; "
          f"flicker's Allan variance flat within {100 * ripple:.1f} % for τ ≥ 2 s; method(s) "
          f"after: {sorted(methods)}; fit_noise {1e3 * per_fit:.0f} ms a call (mean)")  # fmt: skip
    print("intervals held (truth inside): 'pre-58' EDF weights, τ independent; 'symmetric' "
          "c² ± zσ(c²) of the GLS fit; 'now' what fit_noise reports (its interval at the "
          "result's ci, 95 % and 68.27 %); width: median (high − low) now / symmetric at 95 %")  # fmt: skip
    print(f"{'case':>10} {'term':>18} {'±1σ':>5} {'68% sym':>8} {'68% now':>8} "
          f"{'95% pre-58':>11} {'95% sym':>8} {'95% now':>8} {'width':>6} {'z-RMS':>6} "
          f"{'mean/truth−1':>13}")  # fmt: skip
    for case, (got, truth) in out.items():
        for t, d in got.items():
            b, a = fit_figures(d["before"], truth[t]), fit_figures(d["after"], truth[t])
            print(f"{case:>10} {t:>18} {100 * a['within_1sigma']:4.0f}% "
                  f"{100 * a['symmetric_68']:7.1f}% {100 * a['within_68']:7.1f}% "
                  f"{100 * b['within_95']:10.1f}% {100 * a['symmetric_95']:7.1f}% "
                  f"{100 * a['within_95']:7.1f}% {a['width_ratio']:6.2f} {a['z_rms']:6.2f} "
                  f"{a['bias']:+13.3f}")  # fmt: skip
            if t != "angle_random_walk":
                for when, f in (("before", b), ("after", a)):
                    report(f"fit_noise {t} z-RMS, {case}, {when}", f["z_rms"], "",
                           target="1 ± 0.15")  # fmt: skip
            report(f"fit_noise {t} 95 % interval held, {case}", 100 * a["within_95"], "%",
                   target="95 ± 2 %")  # fmt: skip
            report(f"fit_noise {t} 68 % interval held, {case}", 100 * a["within_68"], "%",
                   target="68 ± 4 %")  # fmt: skip
    print(f"\n{time.perf_counter() - t0:.0f} s")


def main_gaps(args):
    """`--gaps SHARE`: rate records of 4 096 s at 1 Hz with each sample missing (NaN) with
    probability SHARE, three pure noises of known Allan variance (white angle noise σ_x = 1:
    3/τ²; white rate noise σ_y = 1: 1/τ; a rate random walk K = 0.01: K²τ/3 + K²/(6m), the
    discrete walk's), `deviation(..., "oadev", mixture=False)` on the octaves. "before": the
    noise type read on the bridged record alone (hrgjax until 2026-12-03,
    `hrgjax.allan.result.gapped_alpha` set to pass the bridged α through); "after": as
    reported, the bridged α arbitrated by R(n) of the gap-free windows
    (`hrgjax.allan.noise_ident.gapped_alpha`). Per τ: the noise types read and the ±1σ
    share. Two more for the type read alone (no ±1σ for flicker angle noise): white angle
    (σ_x = √(16/3)) + white rate noise (σ_y = 1), crossing at m = 16, and Kasdin's flicker
    angle noise."""
    import hrgjax.allan.result as result

    length, arbitrated = 4096, result.gapped_alpha
    from noise_id_table import kasdin

    truth = {"white angle": lambda m: 3.0 / m**2, "white rate": lambda m: 1.0 / m,
             "rate random walk": lambda m: 1e-4 * (m / 3.0 + 1.0 / (6.0 * m)),
             "white angle + white rate (crossing at m = 16)": lambda m: 16.0 / m**2 + 1.0 / m,
             "flicker angle": None}  # fmt: skip
    for name, sigma2 in truth.items():
        rows = {}
        for label, rule in (("before", lambda a, m, rn: a), ("after", arbitrated)):
            result.gapped_alpha = rule
            reads, held = {}, {}
            for seed in range(args.n):
                rng = np.random.default_rng(args.seed + seed)
                if name == "white angle":
                    y = np.diff(rng.normal(size=length + 1))
                elif name == "white rate":
                    y = rng.normal(size=length)
                elif name == "rate random walk":
                    y = 0.01 * np.cumsum(rng.normal(size=length))
                elif name == "flicker angle":  # Kasdin's, to f_h = 1/(2τ₀): type read only
                    y = np.diff(kasdin(1, length + 1, rng))
                else:
                    y = rng.normal(size=length) + np.diff(math.sqrt(16 / 3) * rng.normal(
                        size=length + 1))  # fmt: skip
                y[rng.random(length) < args.gaps] = np.nan
                r = hg.allan.deviation(y, 1.0, "oadev", "octave", mixture=False)
                for m, a, lo, hi in zip(r.m, r.alpha, r.dev_low, r.dev_high, strict=True):
                    reads.setdefault(int(m), []).append(int(a))
                    held.setdefault(int(m), []).append(
                        np.nan if sigma2 is None else lo**2 <= sigma2(int(m)) <= hi**2
                    )
            rows[label] = reads, held
        result.gapped_alpha = arbitrated
        print(f"\n{name} noise, {args.n} records of {length} rates, {args.gaps:.1%} missing")
        print(f"{'m':>5} {'records':>7} {'±1σ before':>11} {'±1σ after':>10}  α before → after")
        for m in sorted(rows["after"][0]):
            count = {k: np.unique(rows[k][0][m], return_counts=True) for k in rows}
            text = {k: ", ".join(f"{v:+d}: {c}" for v, c in zip(*count[k], strict=True))
                    for k in rows}  # fmt: skip
            print(f"{m:5d} {len(rows['after'][0][m]):7d} {100 * np.mean(rows['before'][1][m]):10.0f}% "
                  f"{100 * np.mean(rows['after'][1][m]):9.0f}%  {text['before']} → {text['after']}")  # fmt: skip


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=200, help="records per balance (200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise-rule", default="hrgjax", choices=hg.allan.NOISE_RULES,
                    help="deviation's noise_rule for the 'after' column (hrgjax)")  # fmt: skip
    ap.add_argument("--fit-noise", action="store_true",
                    help="the IEEE 952 line fit's σ and intervals instead (fit_noise)")  # fmt: skip
    ap.add_argument("--gaps", type=float, default=0.0,
                    help="share of missing rates: the gapped-record noise type study")  # fmt: skip
    args = ap.parse_args(argv)
    from _common import machine, report

    if args.gaps:
        print(f"coverage_allan.py --gaps {args.gaps} on {machine()}")
        main_gaps(args)
        return

    if args.fit_noise:
        print(f"coverage_allan.py --fit-noise on {machine()}")
        main_fit_noise(args)
        return

    print(f"coverage_allan.py on {machine()}: {args.n} records of {LENGTH} s per balance, "
          f"noise_rule={args.noise_rule!r}")  # fmt: skip
    t0 = time.perf_counter()
    for white, crossover in BALANCES:
        before, after, alphas, taus = run(args.n, white, crossover, args.seed, args.noise_rule)
        print(f"\nrate random walk overtakes white {white} noise at τ = {crossover:g} s")
        print(f"{'τ [s]':>7} {'±1σ before':>11} {'±1σ after':>10} {'±2σ after':>10} "
              f"{'z-RMS after':>12}  α after (share of records)")  # fmt: skip
        for i, t in enumerate(taus):
            if t < 256:
                continue
            b, a = figures(before[:, i]), figures(after[:, i])
            vals, counts = np.unique(alphas[:, i], return_counts=True)
            share = ", ".join(
                f"{v:+d}: {c / args.n:.0%}" for v, c in zip(vals, counts, strict=True)
            )
            print(f"{t:7.0f} {100 * b['within_1sigma']:10.0f}% {100 * a['within_1sigma']:9.0f}% "
                  f"{100 * a['within_2sigma']:9.0f}% {a['z_rms']:12.2f}  {share}")  # fmt: skip
        last_b, last_a = figures(before[:, -1]), figures(after[:, -1])
        report(f"Allan ±1σ coverage at τ = {taus[-1]:g} s, white {white}, crossover {crossover:g} s, before",
               100 * last_b["within_1sigma"], "%", target="68 ± 8 %")  # fmt: skip
        report(f"Allan ±1σ coverage at τ = {taus[-1]:g} s, white {white}, crossover {crossover:g} s, after ({args.noise_rule})",
               100 * last_a["within_1sigma"], "%", target="68 ± 8 %")  # fmt: skip
    print(f"\n{time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
