"""How long does fit_noise take on a long rate record with scattered gaps?

A record of `--n` samples at 100 Hz (white rate noise 1 plus a rate random walk 1e-3 per
sample), a fraction `--missing` of the samples NaN at random, oadev on the octave grid, the
default terms (flicker as Gauss–Markov terms). Each fit evaluates the gapped covariance 6–7
times over every distinct run length (`hrgjax.allan.octave_covariance.gapped_covariance`);
prints the runs, their distinct lengths, the wall times, the peak memory, the fitted σ and
the hrgjax it ran.

Usage: `.venv/bin/python benchmarks/gapped_fit_speed.py [--n 100000] [--missing 0.01]`
(this checkout's hrgjax, installed editable); another tree's:
`PYTHONPATH=/path/to/tree .venv/bin/python benchmarks/gapped_fit_speed.py …` (the script's
own folder, first on `sys.path`, holds no `hrgjax`, so PYTHONPATH's comes before the
installed one; the line `hrgjax from …` says which ran).
"""

from __future__ import annotations

import argparse
import resource
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=100_000, help="samples (100 000)")
    p.add_argument("--missing", type=float, default=0.01, help="fraction missing (0.01)")
    args = p.parse_args()
    rng = np.random.default_rng(0)
    y = rng.normal(size=args.n) + 1e-3 * np.cumsum(rng.normal(size=args.n))
    y[rng.uniform(size=args.n) < args.missing] = np.nan
    start = time.perf_counter()
    r = hg.allan.deviation(y, 100.0, taus="octave")
    middle = time.perf_counter()
    fit = hg.allan.fit_noise(r)
    end = time.perf_counter()
    runs = r.segments
    print(f"n {args.n}, missing {args.missing:g}: {len(runs)} runs, "
          f"{len(np.unique(runs[:, 1]))} distinct lengths, {len(r.taus)} τ; deviation "
          f"{middle - start:.2f} s, fit_noise {end - middle:.2f} s ({fit.method}); max RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")  # fmt: skip
    print("  σ:", {k: float(f"{v:.6g}") for k, v in fit.sigma.items()})
    print(f"  hrgjax from {hg.__file__}")


if __name__ == "__main__":
    main()
