"""Allan statistics against Stable32's own tables on a real record: a 10 MHz OCXO.

The record and the tables are allantools' `tests/ocxo/` (A. Wallin, 2015): 19 982 readings
of a 10 MHz OCXO (53230A counter, 1 s gate, H-maser reference), one per second, in Hz, and
Stable32 1.60's octave tables of seven deviations over it. For each kind,
`hrgjax.allan.deviation(y, 1 Hz, kind, taus=<the table's τ>)` on y = (f − f₀)/f₀ against the
table: the number of terms, the noise type α (which sets the EDF and so the interval), the
deviation, and the interval's ends, where α agrees and everywhere.

Table layout (`KIND_octave.txt`): a `#` header (Stable32 version, file, "Frequency Data
Points 1 thru N of N", "Sigma Type: …", "Confidence Factor = 0.683", "Deadtime T/Tau"), then
one row per τ: AF (the averaging factor m), Tau [s], # (the number of analysis terms),
Alpha (the noise type, S_y ∝ f^α), Min Sigma, Sigma, Max Sigma (the interval at the
confidence factor, ±1σ; tdev in s, the others fractional frequency).

Two things in Stable32's numbers, checked here with NumPy:

- its overlapping estimators (oadev, mdev, tdev, ohdev, totdev) carry float64 round-off: it
  sums the phase from the normalised frequency f/f₀ ≈ 1, a ramp reaching 2·10⁴ s whose last
  bit (3.6 ps) is not small against the phase's second differences (≈ 76 ps at 1 s). Summed
  that way, the tables come out to their printed digits; hrgjax sums y = f/f₀ − 1 and
  differs by up to ≈ 2·10⁻³ (non-overlapping adev and hdev, from frequency averages, agree);
- its totdev is bias-corrected (NIST SP 1065 §5.2.11): Totvar/(1 − a·τ/T), T the record
  length, a = 0.481 for flicker FM (α = −1) and 0.750 for random-walk FM (α = −2), with the
  table's α. hrgjax's `deviation` applies it too (`bias_correction=True`, the default), with
  its own α: under `noise_rule="stable32"` that alone, as Stable32; under the default rule
  it also corrects white and flicker angle noise (`hrgjax.allan.totvar_bias`), which
  Stable32 and SP 1065 leave uncorrected.

Both of `deviation`'s noise rules run side by side; `--noise-rule` (default `stable32`
here, while the library's default is `hrgjax`) picks the one printed in detail and written.

Usage: `.venv/bin/python benchmarks/stable32_ocxo.py [--dir out/ocxo] [--json PATH]
[--noise-rule stable32|hrgjax]`.
The files are not in this repository; get them with
`git clone https://github.com/aewallin/allantools` and copy `tests/ocxo/ocxo_frequency.txt`
and `tests/ocxo/*_octave.txt` into `out/ocxo/` (git-ignored).
"""

import argparse
import json
import re
import sys
import time
from pathlib import Path

import numpy as np
from _common import machine, report

from hrgjax import allan

F0 = 10e6  # nominal frequency of the record [Hz]
KINDS = ("adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev")
TOTVAR_BIAS = {-1: 0.481, -2: 0.750}  # NIST SP 1065 §5.2.11: a by α (flicker, random-walk FM)
RECORD = "ocxo_frequency.txt"


def read_table(path: Path) -> dict:
    """A Stable32 octave table: its header fields and its columns (one row per τ)."""
    text = path.read_text()
    head = {
        "sigma_type": re.search(r"Sigma Type:\s*(.+)", text).group(1).strip(),
        "confidence": float(re.search(r"Confidence Factor\s*=\s*([\d.]+)", text).group(1)),
        "points": int(re.search(r"Data Points \d+ thru (\d+)", text).group(1)),
    }
    rows = np.loadtxt(path, comments="#", ndmin=2)
    cols = ("m", "tau", "n", "alpha", "min", "sigma", "max")
    return head | {c: rows[:, i] for i, c in enumerate(cols)}


def worst(rel, m):
    """(signed value, m) of the largest |rel|; (None, None) for none."""
    if rel.size == 0:
        return None, None
    i = int(np.argmax(np.abs(rel)))
    return float(rel[i]), int(m[i])


def fmt(pair):
    v, m = pair
    return "   —      " if v is None else f"{v:+.1e} m={m:<4d}"


def stable32_like(kind: str, x, m: int) -> float:
    """`kind` (oadev, mdev, tdev, ohdev or totdev) at factor m as Stable32 computes it from
    its phase x in units of τ0 (NumPy, float64; totdev without its bias correction)."""
    d = x[2 * m :] - 2 * x[m:-m] + x[: -2 * m]
    if kind == "oadev":
        return np.sqrt(np.mean(d**2) / (2 * m**2))
    if kind in ("mdev", "tdev"):
        c = np.concatenate([[0.0], np.cumsum(d)])
        mod = np.sqrt(np.mean((c[m:] - c[:-m]) ** 2) / (2 * m**4))
        return mod * m / np.sqrt(3.0) if kind == "tdev" else mod
    if kind == "ohdev":
        d3 = x[3 * m :] - 3 * x[2 * m : -m] + 3 * x[m : -2 * m] - x[: -3 * m]
        return np.sqrt(np.mean(d3**2) / (6 * m**2))
    n = x.size  # totdev: the phase reflected at both ends, the n − 2 inner points
    j = np.arange(1, n - 1)
    xs = np.concatenate([2 * x[0] - x[j][::-1], x, 2 * x[-1] - x[n - 1 - j]])
    i = j + n - 2
    d = xs[i - m] - 2 * xs[i] + xs[i + m]
    return np.sqrt(np.sum(d**2) / (2 * m**2 * (n - 2)))


def totvar_bias(alpha, tau, record_s):
    """1/√(1 − a·τ/T): the factor by which a bias-corrected totdev exceeds the plain one."""
    a = np.asarray([TOTVAR_BIAS.get(int(k), 0.0) for k in alpha])
    return 1.0 / np.sqrt(1.0 - a * tau / record_s)


def compare(y, x_s32, where: Path, rule: str, verbose: bool):
    """Every kind against its table with `noise_rule=rule`: (per-kind figures, noise types
    equal, τ in all, seconds in `deviation`); the details printed when `verbose`."""
    n = y.size
    say = print if verbose else (lambda *a, **k: None)
    out, alpha_eq, alpha_all, seconds = {}, 0, 0, 0.0
    for kind in KINDS:
        t = read_table(where / f"{kind}_octave.txt")
        tau0 = t["tau"] / t["m"]
        if not np.allclose(tau0, tau0[0]) or t["points"] != n:
            sys.exit(f"{kind}_octave.txt: τ/AF not constant or N = {t['points']} ≠ {n}")
        rate_hz = 1.0 / float(tau0[0])
        t0 = time.perf_counter()
        # "Confidence Factor = 0.683" is ±1σ rounded: 0.6827 fits its small-EDF rows better
        ci = allan.ONE_SIGMA if abs(t["confidence"] - allan.ONE_SIGMA) < 5e-4 else t["confidence"]
        r = allan.deviation(y, rate_hz, kind=kind, taus=t["tau"], ci=ci, noise_rule=rule)
        seconds += time.perf_counter() - t0
        m = t["m"].astype(int)
        if r.m.tolist() != m.tolist():
            sys.exit(f"{kind}: hrgjax's factors {r.m.tolist()} ≠ the table's {m.tolist()}")
        same = r.alpha == t["alpha"]
        rel = {
            "dev": r.dev / t["sigma"] - 1,
            "low": r.dev_low / t["min"] - 1,
            "high": r.dev_high / t["max"] - 1,
        }
        s32_rel = None  # the overlapping kinds as Stable32 computes them (from its phase)
        if kind not in ("adev", "hdev"):
            s32 = np.asarray([stable32_like(kind, x_s32, int(k)) for k in m])  # phase in τ0
            if kind == "tdev":
                s32 = s32 / rate_hz  # × m·τ0, not m
            if kind == "totdev":
                s32 = s32 * totvar_bias(t["alpha"], t["tau"], n / rate_hz)
            s32_rel = worst(s32 / t["sigma"] - 1, m)[0]
        row = {
            "sigma_type": t["sigma_type"],
            "n_tau": int(m.size),
            "m": m.tolist(),
            "n_terms_equal": int(np.sum(r.n_terms == t["n"])),
            "alpha_equal": int(same.sum()),
            "alpha_differs": [
                {"m": int(k), "alpha_stable32": int(a), "alpha_hrgjax": int(b), "n_over_m": n / k}
                for k, a, b, s in zip(m, t["alpha"], r.alpha, same, strict=True)
                if not s
            ],
            "stable32_arithmetic_max_rel": s32_rel,
        }
        for key, v in rel.items():
            row[f"max_rel_{key}"] = worst(v, m)
            row[f"max_rel_{key}_alpha_equal"] = worst(v[same], m[same])
        row["rel_dev"] = rel["dev"].tolist()
        out[kind] = row
        alpha_eq += row["alpha_equal"]
        alpha_all += m.size

        say(f"{kind} (Stable32 \"{t['sigma_type']}\"): {m.size} τ, m = {m[0]}…{m[-1]}; "
              f"terms equal {row['n_terms_equal']}/{m.size}; "
              f"noise type equal {row['alpha_equal']}/{m.size}")  # fmt: skip
        say(f"  max rel. diff, α equal:  dev {fmt(row['max_rel_dev_alpha_equal'])}"
              f"  low {fmt(row['max_rel_low_alpha_equal'])}"
              f"  high {fmt(row['max_rel_high_alpha_equal'])}")  # fmt: skip
        say(f"  max rel. diff, all τ:    dev {fmt(row['max_rel_dev'])}"
              f"  low {fmt(row['max_rel_low'])}  high {fmt(row['max_rel_high'])}")  # fmt: skip
        if row["alpha_differs"]:
            say("  α differs: " + ", ".join(
                f"m={d['m']} (Stable32 {d['alpha_stable32']:+d}, hrgjax {d['alpha_hrgjax']:+d}, "
                f"N/m {d['n_over_m']:.1f})" for d in row["alpha_differs"]))  # fmt: skip
        if kind not in ("adev", "hdev"):
            what = ", bias-corrected" if kind == "totdev" else ""
            say(f"  Stable32's arithmetic (phase summed from f/f₀ ≈ 1{what}), NumPy: "
                  f"max rel. diff {row['stable32_arithmetic_max_rel']:+.1e}")  # fmt: skip

        if kind == "totdev":
            raw = allan.deviation(
                y, rate_hz, kind=kind, taus=t["tau"], bias_correction=False, noise_rule=rule
            )
            pred = totvar_bias(t["alpha"], t["tau"], n / rate_hz)
            say(f"  the bias correction 1/√(1 − a·τ/T), T = {n / rate_hz:.0f} s (a: 0.481 at "
                  "α = −1, 0.750 at α = −2), each with its own α:")  # fmt: skip
            say(f"  {'m':>6} {'α S32':>6} {'α ours':>6} {'raw/S32':>9} {'S32 factor':>11} "
                  f"{'ours/S32 − 1':>13}")  # fmt: skip
            rows = zip(m, t["alpha"], r.alpha, raw.dev / t["sigma"], pred, rel["dev"], strict=True)
            for k, a, b, q, p, e in rows:
                say(f"  {k:>6d} {int(a):>+6d} {int(b):>+6d} {q:>9.5f} {p:>11.5f} {e:>+13.1e}")
            row["totdev_raw_ratio"] = (raw.dev / t["sigma"]).tolist()
            row["totdev_bias_factor_stable32"] = pred.tolist()
        say()

    return out, alpha_eq, alpha_all, seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dir", default="out/ocxo", help="the record and tables (out/ocxo)")
    parser.add_argument("--json", metavar="PATH", help="write the per-kind figures here")
    parser.add_argument("--noise-rule", default="stable32", choices=allan.NOISE_RULES,
                        help="the rule whose details are printed and written (both are "
                        "summed up)")  # fmt: skip
    args = parser.parse_args()
    where = Path(args.dir)
    needed = (RECORD, *(f"{k}_octave.txt" for k in KINDS))
    missing = [f for f in needed if not (where / f).is_file()]
    if missing:
        sys.exit(
            f"stable32_ocxo.py: {where}/ lacks {', '.join(missing)}; get them from "
            "https://github.com/aewallin/allantools (git clone, then cp tests/ocxo/"
            f"{{ocxo_frequency,*_octave}}.txt {where}/)"
        )

    f_hz = np.loadtxt(where / RECORD, comments="#")
    y = (f_hz - F0) / F0
    n = y.size
    x_s32 = np.concatenate([[0.0], np.cumsum(f_hz / F0)])  # Stable32's phase: f/f₀ summed
    print(machine())
    print(f"{RECORD}: {n} readings, f₀ = {F0:.0f} Hz\n")

    runs = {}
    for rule in sorted(allan.NOISE_RULES, key=lambda r: r != args.noise_rule):
        if rule == args.noise_rule:
            print(f"noise_rule={rule!r}:\n")
        runs[rule] = compare(y, x_s32, where, rule, verbose=rule == args.noise_rule)
    for rule, (out, alpha_eq, alpha_all, seconds) in runs.items():
        print(f"noise_rule={rule!r}: noise type {alpha_eq}/{alpha_all} equal; "
              f"hrgjax.allan.deviation, 7 kinds: {seconds:.2f} s")  # fmt: skip
        report(f"Stable32 OCXO, noise_rule={rule}: noise types equal", alpha_eq,
               f"of {alpha_all}", target="90 of 90")  # fmt: skip
        dev_max = max(abs(out[k]["max_rel_dev"][0]) for k in ("adev", "hdev"))
        report(f"Stable32 OCXO, noise_rule={rule}: max |dev/σ − 1|, adev and hdev", dev_max, "")
        for where_, suffix in (("where α agrees", "_alpha_equal"), ("at every τ", "")):
            tot = out["totdev"][f"max_rel_dev{suffix}"][0]
            report(f"Stable32 OCXO, noise_rule={rule}: totdev |dev/σ − 1| {where_}", abs(tot), "",
                   target="≤ 2e-3")  # fmt: skip
            ends = max(
                abs(out[k][f"max_rel_{b}{suffix}"][0]) for k in KINDS for b in ("low", "high")
            )
            report(f"Stable32 OCXO, noise_rule={rule}: interval ends {where_}, max |rel|", ends,
                   "", target="≤ 5e-3")  # fmt: skip
    out = runs[args.noise_rule][0]
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(
            json.dumps({"noise_rule": args.noise_rule} | out, indent=2) + "\n"
        )
        print(f"figures written to {args.json}")


if __name__ == "__main__":
    main()
