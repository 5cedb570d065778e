"""Do the physical grey box's error bars cover a known truth? Monte Carlo (session 34).

The ideal-loop model gyro with injected laws (k_e, bias law, Δ(1/τ)(T), θ_τ(T), readout gain
mismatch g(T); cross-talk 0), 1″ white angle noise and 0.002 °/√h angle random walk, on a
small bench: 3 temperatures × 6 wave angles of 60-s static and 5 °/s rotation runs at 0.5 s
(36 runs, 126 windows; the tests' `_injected_session`). Every seed is fitted as a user fits
it (`PhysicalCompensator().fit`) and each parameter's pull z = (fit − truth)/σ recorded:
its mean and SD, and the pooled coverage at ±1σ and ±2σ (nominal 68 % and 95 %), both with
the σ the fit reports and with the textbook σ it reported before (the reported one less
`_physical_fit.t_factors`' widening).

Cases (`--case`, default all):

- `ideal`: the data as above.
- `gauss-markov`: plus a first-order Gauss–Markov rate, σ 0.1 °/h, correlation time 600 s
  (longer than a run: each run's own slowly moving bias, shared by a rotation's windows).
- `gaps`: 30 % of every run cut out of its middle (time stamps with a hole).
- `jitter`: 5 ms of white jitter on every time stamp (1 % of the 0.5-s interval).

The closed-loop cases — the grey box given the gyro's PI loops (`plant=`), and the ideal-loop
grey box on the same real gyro, whose g and cross-talk are then effective values — are
`benchmarks/coverage.py --only-physical`.

Usage: `.venv/bin/python benchmarks/coverage_physical.py [--n 60] [--case ideal|…]`
(`--n 100 --case ideal`: 70 s on the 2-core machine, most of it compiling).
"""

import argparse
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, report  # noqa: E402

import hrgjax as hg  # noqa: E402
from hrgjax.calibration import (  # noqa: E402
    PhysicalCompensator,
    physical,
    rotation_plan,
    run_plan,
    static_plan,
)
from hrgjax.units import DEG, DEG_PER_H, DEG_PER_SQRT_H  # noqa: E402

CASES = ("ideal", "gauss-markov", "gaps", "jitter")


def truth() -> np.ndarray:
    """The injected parameters (order of `physical.NAMES`, SI)."""
    t = dict.fromkeys(physical.NAMES, 0.0)
    t.update(k_e0=float(hg.presets.tvg3_like(noise=False).k_e), bias0=0.2 * DEG_PER_H,
             delta_inv_tau0=3e-6, delta_inv_tau_lam=-0.015, theta_tau0=0.45,
             theta_tau1=0.003, gain_mismatch0=3e-3, gain_mismatch1=-6e-5)  # fmt: skip
    return np.array([t[n] for n in physical.NAMES])


def model(values, gauss_markov_dph: float = 0.0):
    """The ideal-loop model gyro of `values` with the bench's noise."""
    noise = hg.Noise(angle_white=DEG / 3600, angle_random_walk=0.002 * DEG_PER_SQRT_H,
                     bias_instability=gauss_markov_dph * DEG_PER_H, correlation_time=600.0,
                     run_bias=0.0)  # fmt: skip
    return eqx.tree_at(lambda g: g.noise, physical.model_gyro(jnp.asarray(values)), noise,
                       is_leaf=lambda x: x is None)  # fmt: skip


def session(gyro, seed: int):
    temps, angles = (-40.0, 20.0, 60.0), tuple(range(-90, 90, 30))
    static = static_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    rotation = rotation_plan(temps, angles, duration_s=60.0, dt_out=0.5)
    key = jax.random.key(100 + seed)
    d1 = run_plan(gyro, static, key=key, bias_key=key)
    d2 = run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), first_run=static.size,
                  bias_key=key)  # fmt: skip
    return hg.data.concat([d1, d2])


def with_gaps(data, fraction: float = 0.3):
    """`data` with `fraction` of every run's samples cut out of its middle."""
    cols = {k: np.array(v) for k, v in data.columns.items()}
    keep = np.ones(data.run.size, bool)
    for r in np.unique(cols["run"]):
        m = np.flatnonzero(cols["run"] == r)
        a = int(0.4 * m.size)
        keep[m[a : a + int(fraction * m.size)]] = False
    return hg.MeasuredData({k: v[keep] for k, v in cols.items()})


def with_jitter(data, sigma_s: float, rng):
    cols = {k: np.array(v) for k, v in data.columns.items()}
    cols["time_s"] = cols["time_s"] + rng.normal(0.0, sigma_s, data.run.size)
    return hg.MeasuredData(cols)


def pulls(case: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(z with the reported σ, z with the textbook σ), each (n, parameters)."""
    factors = {}
    original = physical.t_factors

    def recorded(*args, **kw):  # the widening the fit applies, to undo it for "textbook"
        out = original(*args, **kw)
        factors["last"] = out[0]
        return out

    physical.t_factors = recorded
    tv = truth()
    gyro = model(tv, 0.1 if case == "gauss-markov" else 0.0)
    rng = np.random.default_rng(0)
    z, z_text = [], []
    try:
        for s in range(n):
            data = session(gyro, s)
            if case == "gaps":
                data = with_gaps(data)
            elif case == "jitter":
                data = with_jitter(data, 0.005, rng)
            fit = PhysicalCompensator().fit(data)
            e = np.sqrt(np.diag(np.asarray(fit.covariance)))
            z.append((np.asarray(fit.values) - tv) / e)
            z_text.append(z[-1] * factors["last"])
    finally:
        physical.t_factors = original
    return np.asarray(z), np.asarray(z_text)


def summary(z: np.ndarray) -> tuple[float, float, float]:
    return (
        float(np.mean(np.abs(z) < 1)),
        float(np.mean(np.abs(z) < 2)),
        float(np.sqrt(np.mean(z**2))),
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=60, help="seeds per case")
    ap.add_argument("--case", choices=CASES, default=None, help="one case (default: all)")
    args = ap.parse_args(argv)
    print(f"coverage_physical.py on {machine()}, {args.n} seeds per case")
    t0 = time.perf_counter()
    rows = []
    for case in (args.case,) if args.case else CASES:
        z, z_text = pulls(case, args.n)
        print(f"\n{case}: {'parameter':>18}  mean z  SD z  ±1σ  ±2σ  (reported σ; SD with the "
              "textbook σ)")  # fmt: skip
        for i, name in enumerate(physical.NAMES):
            c1, c2, _ = summary(z[:, i])
            print(
                f"  {name:>24}  {np.mean(z[:, i]):+5.2f}  {np.std(z[:, i], ddof=1):4.2f}  "
                f"{100 * c1:3.0f}  {100 * c2:3.0f}  ({np.std(z_text[:, i], ddof=1):4.2f})"
            )
        rows += [(f"{case}, textbook σ", summary(z_text)), (f"{case}, reported σ", summary(z))]
    print(f"\n{'case':<32} {'±1σ':>6} {'±2σ':>6} {'z-RMS':>6}")
    for name, (c1, c2, rms) in rows:
        print(f"{name:<32} {100 * c1:5.1f}% {100 * c2:5.1f}% {rms:6.3f}")
        report(f"physical z-RMS, {name}", rms, "", target="0.9–1.1")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
