"""Discovery's held-out gap guard on dwell grids: refusing every rise of the gap, or only a
rise beyond what the noise gives (`DwellProblem.widens`, since 2026-12-03).

An effect must not widen the held-out gap (the RMS over held-out runs of the run-mean
residual, [°/h]). Where the gap is already at the noise floor, a true effect's refit moves it
up or down by chance, and the strict rule ("any rise refuses") threw away effects with ΔBIC in
the hundreds. The rule now refuses a rise only where the noise alone gives a gap that large in
fewer than 1 % of sessions (ν·(gap/floor)² against χ²_ν).

Side by side in one run, the whole `discover` on each grid of
`hidden_effect_dataset(effect, size, key=PRNGKey(seed))` (5 temperatures × 9 wave angles × 60 s,
static and 5 °/s) under both rules ("before" swaps in a `DwellProblem` whose `widens` is the
strict rule):

- **null grids** (nothing hidden): any verdict but `none` is false — the false-find rate;
- **weak effects at the floor**: `bias_temperature` −0.0012 °/h/°C and
  `damping_anisotropy_temperature` 0.002 /°C, where the gap before sits near the floor: the
  rate at which the hidden effect is named.

Usage: `.venv/bin/python benchmarks/discovery_gap_guard.py [--seeds N] [--start S]` (default 40
seeds from 400; ≈ 1 s a grid and rule after the first compile).
"""

import argparse
import time

import jax
from _common import machine, report

from hrgjax.discovery import discover, search
from hrgjax.discovery.dwell import DwellProblem
from hrgjax.discovery.generate import hidden_effect_dataset

CASES = (
    ("null", None, 0.0),
    ("bias_temperature", "bias_temperature", -0.0012),
    ("damping_anisotropy_temperature", "damping_anisotropy_temperature", 0.002),
)


class StrictGap(DwellProblem):
    """The rule up to 2026-12-02: any rise of the held-out gap refuses the effect."""

    def widens(self, gap, gap_after):
        return gap_after > gap


def run(data, strict: bool):
    saved = search.PROBLEMS["dwell"]
    search.PROBLEMS["dwell"] = StrictGap if strict else saved
    try:
        return discover(data)
    finally:
        search.PROBLEMS["dwell"] = saved


def main(n: int, start: int):
    print(f"machine: {machine()}")
    t0 = time.perf_counter()
    for label, effect, size in CASES:
        hits = {"before": 0, "after": 0}
        for seed in range(start, start + n):
            data = hidden_effect_dataset(effect, size, key=jax.random.PRNGKey(seed))
            line = []
            for rule, strict in (("before", True), ("after", False)):
                d = run(data, strict)
                ok = d.verdict == "none" if effect is None else d.missing_effect == effect
                hits[rule] += ok
                line.append(f"{rule} {d.verdict:>12} {d.missing_effect or '-':>30}")
            print(f"{label:>30} seed {seed}: " + " | ".join(line), flush=True)
        what = "verdict none" if effect is None else "effect named"
        print(f"{label}: {what} {hits['before']}/{n} before, {hits['after']}/{n} after")
        report(f"gap guard, {label}: {what}", 100 * hits["after"] / n, "%", "before",
               100 * hits["before"] / n)  # fmt: skip
    print(f"{time.perf_counter() - t0:.0f} s in all")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--start", type=int, default=400)
    args = ap.parse_args()
    main(args.seeds, args.start)
