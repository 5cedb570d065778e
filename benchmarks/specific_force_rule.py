"""Which specific forces `hrgjax.plausible.check_specific_force` takes as 1 g written in m/s²,
against the rules it replaced or was weighed against (docs/data.md, physical plausibility).

Cases, |f| in the columns' unit: unit errors it must name (static logs in m/s² at local
gravity 9.780 / 9.832, a consumer accelerometer's ±1–3 % scale error, rides with 0.02–0.2 g
rms of vibration per axis written in m/s², a six-face tumble and a turnover in m/s²) and
real high-g runs in g it must take (holds at 9–10.5 g, a centrifuge's radial g with 1 g
vertical, a fighter's ramp, a rest at 1 g before a hold, step protocols, random vibration
whose |f| has a median of 9.8 g). Rules: `10 % on half` (055d919: |f| within 10 % of
9.80665 on ≥ half the rows), `median 2 %` (the review's proposal), `rows only` (607aeb8's
rule: median within 2 % and middle half within 15 %, on the rows as they are: the library
called without a rate), `hrgjax` (the library's rule on a data file at 100 Hz: the same on
the rows and on 0.5-s means of each axis, `plausible.SMOOTH_S`), and `median 3 % + q 10 %`.
Every case is rows of a data file at 100 Hz. Prints REFUSE / pass per case and the count
each rule gets right.

Usage: `.venv/bin/python benchmarks/specific_force_rule.py`
"""

import numpy as np
from _common import report

from hrgjax import plausible

G = 9.80665
rng = np.random.default_rng(0)
N = 20_000


def mags(f):
    m = np.linalg.norm(f, axis=1)
    return m[m > 0.5]


def ten_percent_on_half(f):
    m = mags(f)
    return 2 * np.count_nonzero(abs(m - G) <= 0.1 * G) >= m.size


def median_band(f, tol=0.02, spread=None):
    m = mags(f)
    q25, q50, q75 = np.percentile(m, (25, 50, 75))
    ok = abs(q50 - G) <= tol * G
    return ok and (spread is None or max(abs(q25 - G), abs(q75 - G)) <= spread * G)


def library(f, rate_hz=100.0):
    names = [f"c{j}" for j in range(f.shape[1])]
    try:
        plausible.check_specific_force("f", names, f, samples=False, rate_hz=rate_hz)
    except ValueError as e:  # the unit's refusal, not the range's
        return "as 1 g written in m/s²" in str(e)
    return False


RULES = {
    "10 % on half": ten_percent_on_half,
    "median 2 %": median_band,
    "rows only": lambda f: library(f, None),
    "hrgjax": library,
    "median 3 % + q 10 %": lambda f: median_band(f, 0.03, 0.10),
}


def ride(s, n=N):
    return np.c_[rng.normal(0, s, n), rng.normal(0, s, n), rng.normal(1, s, n)]


def cases():
    want = {}
    for s in (0.02, 0.05, 0.1, 0.12, 0.14, 0.17, 0.2, 0.3, 0.5, 1.0):
        want[f"ride {s} g rms/axis in m/s²"] = ride(s) * G
    turn = ride(0.05)
    turn[: N // 2, 0] += 0.3
    want["car: 0.3 g turns half the time, m/s²"] = turn * G
    th = 2 * np.pi * 1.0 * np.arange(N) / 100.0  # 1 rev/s about a level axis, 100 Hz
    want["table 1 rev/s, level axis, m/s²"] = G * np.c_[np.zeros(N), np.sin(th), np.cos(th)]
    for gl in (9.78, 9.832):
        want[f"static 1 g in m/s², local g {gl}"] = np.tile([0, 0, gl], (10, 1))
    for sf in (0.97, 0.99, 1.01, 1.03):
        want[f"static in m/s², scale error {sf - 1:+.0%}"] = np.tile([0, 0, G * sf], (10, 1))
    faces = np.vstack([np.eye(3), -np.eye(3)])
    want["six-face tumble in m/s²"] = np.repeat(faces, 2, axis=0) * G
    th = np.radians(np.arange(0, 361, 10.0))
    want["turnover in m/s²"] = G * np.c_[np.zeros_like(th), np.sin(th), np.cos(th)]
    take = {}
    for s in (0.05, 0.2, 0.5, 1.0):
        take[f"ride {s} g rms/axis in g"] = ride(s)
    for lvl in (9.0, 9.5, 9.7, 9.8, 10.0, 10.5):
        take[f"hold {lvl} g along z"] = np.tile([0, 0, lvl], (10, 1))
        take[f"centrifuge {lvl} g + 1 g (|f| {np.hypot(lvl, 1):.2f})"] = np.tile(
            [lvl, 0, 1.0], (10, 1)
        )
    for lvl in (9.0, 9.8):
        take[f"fighter ramp knots 1, {lvl} x3, 1"] = np.array(
            [[0, 0, 1], [0, 0, lvl], [0, 0, lvl], [0, 0, lvl], [0, 0, 1.0]]
        )
    take["rest 1 g 40 %, hold 9.8 g 60 %"] = np.array([[0, 0, 1.0]] * 4 + [[0, 0, 9.8]] * 6)
    take["rest 1 g, then 10 g radial (2 + 2 knots)"] = np.array(
        [[0, 0, 1], [0, 0, 1], [10, 0, 1], [10, 0, 1.0]]
    )
    take["steps 5, 10, 15 g radial + 1 g"] = np.repeat([[5, 0, 1], [10, 0, 1], [15, 0, 1.0]], 2, 0)
    take["random vibration 6.4 g rms/axis + 1 g"] = ride(6.4)
    take["launch ramp 1 … 12 g"] = np.c_[np.zeros(50), np.zeros(50), np.linspace(1, 12, 50)]
    return want, take


def main():
    want, take = cases()
    print(f"{'case':46s} " + " ".join(f"{k:>20s}" for k in RULES) + "  median |f|")
    for title, group, refuse in (("must REFUSE", want, True), ("must PASS", take, False)):
        print("--", title)
        right = dict.fromkeys(RULES, 0)
        for name, f in group.items():
            said = {k: r(f) for k, r in RULES.items()}
            for k, v in said.items():
                right[k] += v == refuse
            row = " ".join(f"{('REFUSE' if v else 'pass'):>20s}" for v in said.values())
            print(f"{name:46s} {row}  {np.median(mags(f)):.3f}")
        print(f"{'right':46s} " + " ".join(f"{f'{right[k]}/{len(group)}':>20s}" for k in RULES))
        report(f"specific-force unit rule, {title} cases right (hrgjax)", right["hrgjax"], "cases",
               f"of {len(group)}; 055d919's rule (607aeb8's: {right['rows only']})",
               right["10 % on half"])  # fmt: skip


if __name__ == "__main__":
    main()
