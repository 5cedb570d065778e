"""A window's rate is the least-squares slope of the wave angle over the window: the mean of
the rate over the arc the wave turns in it, weighted 6(T²/4 − τ²)/T³. Read as the value at the
window's mean angle (as the fits did before fe79070), a harmonic k of the drift or scale
factor comes out × 3(sin x − x cos x)/x³, x = k·arc/2: the 2θ scale-factor ripple at 0.805 of
the truth at 50 °/s. The fits now model the average (Fourier: each harmonic's exact sampled
gain; MLP: a 5-node quadrature across the arc).

Side by side on the same exact (noise-free) sessions (`tests/helpers.closed_form_session`:
0/20/40 °C, 3-s windows at 10 Hz, 36-s runs): the fitted / true peak-to-peak 2θ ripple at
+20 °C and the RMS scale-factor error over θ [ppm], with the windows as reduced (arc) and the
same windows read as point values (`duration` = 0: the old reading).

Usage: `.venv/bin/python benchmarks/calibration_window_arc.py [--mlp]` (Fourier: seconds;
`--mlp` adds the MLP fitted on the same two sets of windows, arc and points, ≈ 15 s a fit on
2 CPUs: its ripple before and after the arc quadrature).
"""

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from helpers import closed_form_session, session_scale_factor  # noqa: E402

from hrgjax import calibration as cal  # noqa: E402
from hrgjax.units import DEG  # noqa: E402

THETA = np.arange(-90.0, 90.0, 5.0)


def ripple(comp) -> tuple[float, float]:
    """(fitted / true peak-to-peak SF over θ at +20 °C, RMS SF error [ppm])."""
    truth = session_scale_factor(THETA * DEG, 20.0)
    sf = comp.scale_factor_at(THETA, np.full(THETA.size, 20.0), warn=False)
    return float(np.ptp(sf) / np.ptp(truth)), 1e6 * float(np.sqrt(np.mean((sf - truth) ** 2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mlp", action="store_true", help="add the MLP compensator")
    args = ap.parse_args()
    warnings.simplefilter("ignore")  # the point reading's fits extrapolate nothing; quiet
    head = f"{'rate °/s':>8} | {'Fourier arc':>11} {'ppm':>6} | {'as points':>9} {'ppm':>6}"
    print(
        head + (f" | {'MLP arc':>8} {'ppm':>6} | {'as points':>9} {'ppm':>6}" if args.mlp else "")
    )
    for rate in (5.0, 20.0, 50.0, 100.0):
        data = closed_form_session(temps=(0.0, 20.0, 40.0), rate_dps=rate, dt=0.1,
                                   duration_s=36.0)  # fmt: skip
        w = cal.reduce(data)
        point = dataclasses.replace(w, duration=np.zeros(len(w)))
        fourier = cal.FourierCompensator(temperature_degree=2)
        a, p = ripple(fourier.fit(w)), ripple(fourier.fit(point))
        line = f"{rate:8.0f} | {a[0]:11.5f} {a[1]:6.0f} | {p[0]:9.5f} {p[1]:6.0f}"
        if args.mlp:
            mlp = cal.MLPCompensator()
            m = ripple(mlp.fit(w, key=jax.random.key(3)))
            q = ripple(mlp.fit(point, key=jax.random.key(3)))
            line += f" | {m[0]:8.4f} {m[1]:6.0f} | {q[0]:9.4f} {q[1]:6.0f}"
        print(line, flush=True)


if __name__ == "__main__":
    main()
