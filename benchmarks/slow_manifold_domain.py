"""The slow manifold's domain (docs/resonator.md, "Its domain"): its mean defect drift against
a converged balance (15 angles, 12 Newton steps) and, with `--sim`, against the averaged run
with the PI loops integrated as states — as the frequency split grows against the quadrature
loop's bandwidth β_q (tvg3_like at 20 °C, only Δω changed; "β×0.5" halves every loop).
Columns: the loops' mean defect drift over a turn of 2θ as a fraction of the rate; the error
of the linearised balance (no Newton steps) and of the default (`BALANCE_NEWTON` steps), each
relative to that drift.

Usage: `.venv/bin/python benchmarks/slow_manifold_domain.py [--sim]` (minutes; `--sim` adds
one averaged run per row).
"""

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import hrgjax as hg  # noqa: E402
from hrgjax._progress import bar  # noqa: E402
from hrgjax.resonator import slow  # noqa: E402

ROWS = [(1.0, 0.05, 10.0), (1.0, 0.05, 100.0), (1.0, 0.2, 10.0), (0.5, 0.1, 10.0),
        (1.0, 0.2, 100.0), (1.0, 0.5, 10.0), (1.0, 0.5, 100.0), (1.0, 1.0, 10.0)]  # fmt: skip
"""(loop-bandwidth scale, split [Hz], table rate [°/s])."""


def mean_defect(g, w, samples, newton):
    """The loops' mean defect drift [rad/s] over a turn of 2θ: π/∫dθ/θ̇ + k_e·Ω."""
    saved = slow.SAMPLES, slow._D, slow.BALANCE_NEWTON
    slow.SAMPLES, slow._D = samples, slow._derivative_matrix(samples)
    slow.BALANCE_NEWTON, limit, slow.MAX_SPLIT_RATIO = newton, slow.MAX_SPLIT_RATIO, np.inf
    try:
        grid = jnp.linspace(0.0, jnp.pi, 46)[:-1]
        rates = eqx.filter_jit(lambda g, w: jax.vmap(lambda x: slow.reduced_rate(g, w, x))(grid))
        f = np.asarray(rates(g, w))
    finally:
        slow.SAMPLES, slow._D, slow.BALANCE_NEWTON = saved
        slow.MAX_SPLIT_RATIO = limit
    return 1.0 / np.mean(1.0 / f) + float(g.resonator.k_e) * float(w)


def simulated(gyro, rate_dps, ideal):
    """The averaged PI-loop run's mean defect drift [rad/s] over whole turns of 2θ after 20 s."""
    T = min(4 * 180.0 / (0.554 * rate_dps) + 20.0, 600.0)
    prof = hg.Profile.constant_rate(rate_dps, T, 20.0, wave_angle0_deg=30.0)
    rec = hg.simulate(gyro, prof, dt_out=T / 4000)
    t, th = np.asarray(rec.t), np.asarray(rec.true_wave_angle)
    i0 = np.searchsorted(t, 20.0)
    turned = np.abs(th[i0:] - th[i0])
    turns = int(turned[-1] // np.pi)
    if turns < 1:
        return np.nan
    return -turns * np.pi / (np.interp(turns * np.pi, turned, t[i0:]) - t[i0]) - ideal


def main():
    sim = "--sim" in sys.argv
    base = hg.presets.tvg3_like(temperature_laws=False, noise=False)
    print("| Δω/β_q | β | rate | defect/rate | error, linearised | error, Newton |"
          + (" truth vs averaged run |" if sim else ""))  # fmt: skip
    print("|---|---|---|---|---|---|" + ("---|" if sim else ""))
    with bar(len(ROWS), "slow-manifold domain", unit="row") as shown:
        for row in ROWS:
            print(one_row(base, *row, sim), flush=True)
            shown.update(1)


def one_row(base, scale, split_hz, rate_dps, sim):
    """One table row: loop-bandwidth `scale`, split [Hz], table rate [°/s]."""
    gyro = eqx.tree_at(
        lambda g: (g.resonator.delta_omega, g.control.pll_bandwidth,
                   g.control.agc_bandwidth, g.control.quadrature_bandwidth),
        base, (2 * np.pi * split_hz, 2.0 * scale, 1.0 * scale, 2.0 * scale))  # fmt: skip
    g = gyro.at(20.0)
    w = jnp.asarray(float(g.rate_bias) + np.deg2rad(rate_dps))
    ideal = -float(g.resonator.k_e) * float(w)
    truth = mean_defect(g, w, 15, 12)
    lin = mean_defect(g, w, slow.SAMPLES, 0)
    new = mean_defect(g, w, slow.SAMPLES, slow.BALANCE_NEWTON)
    row = (f"| {2 * np.pi * split_hz / (2.0 * scale):.2f} | ×{scale:g} | {rate_dps:g} °/s | "
           f"{truth / abs(ideal):.3g} | {abs(lin - truth) / abs(truth):.1e} | "
           f"{abs(new - truth) / abs(truth):.1e} |")  # fmt: skip
    if sim:
        row += f" {abs(simulated(gyro, rate_dps, ideal) - truth) / abs(truth):.1e} |"
    return row


if __name__ == "__main__":
    main()
