"""`correct`'s cost of integrating each sample interval over its arc, against the mid-angle rule
it replaced (fe79070): the same `correct` call, side by side in one run, with the old rule
reproduced here as the reference — each interval one piece (`arc_rad` = ∞) read by one
Gauss–Legendre node (`nodes=1`: the rate at the interval's mid angle), patched into
`correct` in place of the arc rule (4 nodes a piece of ≤ 22.5° electrical).

Data: the closed-form session (`tests/helpers.closed_form_session`: 0/20/40 °C, 6 start
angles, a static and a 5 °/s run each) sampled at 100 Hz for 60 s, 36 runs × 6001 = 216 036
samples (0.028° electrical a sample: one piece each, so the arc rule costs its 4 nodes); and,
to show the two rules apart, the same runs at 50 °/s logged at 1 Hz (27.7° a sample: 2
pieces): the largest difference of their end angles. Compensators: a Fourier fit (T², 2
harmonics), an MLP (the default widths, untrained, its outputs scaled to a 1e-5 rad/s drift
and a 1e-3 scale-factor spread: the cost of evaluating its networks) and `NoCompensation`.
Timings are the best of `--repeat` calls after a first (compiling) one.

Usage: `.venv/bin/python benchmarks/correct_arc_speed.py [--repeat 3]`.
"""

import argparse
import contextlib
import functools
import sys
import time
import warnings
from pathlib import Path
from unittest import mock

import equinox as eqx
import jax
import numpy as np
from _common import machine, report

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from helpers import closed_form_session  # noqa: E402

from hrgjax import calibration as cal  # noqa: E402
from hrgjax.calibration import _compensator, _correction  # noqa: E402


@contextlib.contextmanager
def mid_angle_rule():
    """`correct` with the rule before fe79070: one node at each interval's mid angle."""
    pieces = functools.partial(_correction.arc_pieces, arc_rad=np.inf)
    rates = functools.partial(_correction.interval_rates, nodes=1)
    with (
        mock.patch.object(_compensator, "arc_pieces", pieces),
        mock.patch.object(_compensator, "interval_rates", rates),
    ):
        yield


def best(fn, repeat: int) -> float:
    """Best wall time [s] of `repeat` calls of `fn` after a first one."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def end_angles(comp, data) -> np.ndarray:
    """`correct`'s case angle at each run's end [°]."""
    angle = comp.correct(data, warn=False)["angle_corrected_deg"]
    return np.array([angle[ix[-1]] for ix in data.run_indices()])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="timed calls per rule (best kept)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    print(machine())
    t0 = time.perf_counter()
    fit_data = closed_form_session(temps=(0.0, 20.0, 40.0))
    big = closed_form_session(temps=(0.0, 20.0, 40.0), dt=0.01, duration_s=60.0)
    coarse = closed_form_session(temps=(0.0, 20.0, 40.0), rate_dps=50.0, dt=1.0)
    print(f"data: {len(big)} samples (built in {time.perf_counter() - t0:.1f} s)")
    comps = {
        "Fourier": cal.FourierCompensator(temperature_degree=2).fit(fit_data),
        "MLP": eqx.tree_at(
            lambda c: (c.drift_scale, c.sf_scale),
            cal.MLPCompensator().init(jax.random.key(0)),
            (1e-5, 1e-3),
        ),
        "raw": cal.NoCompensation(),
    }
    print(f"{'compensator':>11} | {'arc s':>7} {'mid s':>7} {'arc/mid':>7} | "
          f"{'max |Δ end| °, 50 °/s at 1 Hz':>29}")  # fmt: skip
    for name, comp in comps.items():
        arc = best(lambda c=comp: c.correct(big, warn=False), args.repeat)
        end_arc = end_angles(comp, coarse)
        with mid_angle_rule():
            mid = best(lambda c=comp: c.correct(big, warn=False), args.repeat)
            apart = np.max(np.abs(end_angles(comp, coarse) - end_arc))
        print(f"{name:>11} | {arc:7.3f} {mid:7.3f} {arc / mid:7.2f} | {apart:29.2e}",
              flush=True)  # fmt: skip
        report(f"correct over {len(big)} samples, {name}, arc rule", arc, "s",
               "arc / mid-angle rule", arc / mid)  # fmt: skip


if __name__ == "__main__":
    main()
