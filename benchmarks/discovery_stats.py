"""The search's scalar tail probabilities, eager against compiled, and what they cost
`trust.honest` (issue 45: `make test`'s time, and every `discover` call's).

`stats.f_sf` and `stats.chi2_sf` are asked thousands of times per search (every candidate's
score test, every leftover shape's F judgement, the error bars' levels). *Before* (up to
commit fff8f0a) each called `jax.scipy.special.betainc` / `gammaincc` eagerly: the special
function's primitives dispatched one at a time. *After*: one compiled program each. Both on
the same arguments in one run, with scipy's values as the reference; then `trust.honest` on a
5 × 7 dwell grid's windows with all 18 leftover shapes (tests/test_discovery_trust.py's toy),
per call, with each tail.

Then eighteen F tails (one round of `trust`'s leftover shapes) by `f_sf` each against one
`f_sf_many` call (since 2026-12-03 `trust` asks them that way: `trust.honest` 1.4–1.8×
faster on this toy, test_discovery_trust.py 57 → 39 CPU-s).

Usage: `.venv/bin/python benchmarks/discovery_stats.py`
"""

import time

import _common  # noqa: F401  (x64, thread pool)
import jax.numpy as jnp
import numpy as np
from _common import machine, report
from jax.scipy.special import betainc, gammaincc
from scipy import stats as sps

from hrgjax.discovery import dwell, leftover, stats, trust
from hrgjax.discovery.effects import Covariates, regular_parameters
from hrgjax.discovery.problem import Fit
from hrgjax.units import DEG, DEG_PER_H


def _eager_f_sf(f, d1, d2):  # the implementation before: eager primitives
    return 1.0 if not f > 0 else float(betainc(0.5 * d2, 0.5 * d1, d2 / (d2 + d1 * f)))


def _eager_chi2_sf(x, dof):
    return float(gammaincc(dof / 2.0, jnp.asarray(max(x, 0.0) / 2.0)))


def _per_call(fn, args, repeat=3):
    fn(*args[0])  # compile
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        for a in args:
            fn(*a)
        best = min(best, (time.perf_counter() - t0) / len(args))
    return best


def _grid_fit(rng):
    model = ["bias", "angular_gain", "damping_anisotropy", "bias_temperature"]
    temps = np.repeat([-40.0, -15.0, 10.0, 35.0, 60.0], 7)
    theta = (np.tile(np.arange(-60.0, 61.0, 20.0), 5) + np.repeat(np.arange(5) * 6.0, 7)) * DEG
    theta, temps = np.r_[theta, theta], np.r_[temps, temps]
    rate = np.r_[np.zeros(35), np.full(35, 5.0 * DEG)]
    c = Covariates(theta=jnp.asarray(theta), rate=jnp.asarray(rate),
                   temperature=jnp.asarray(temps), temperature_lagged=jnp.asarray(temps))  # fmt: skip
    g, _ = dwell.design(model, c, 0.554)
    z = np.zeros(theta.size)
    shapes = leftover.columns({"theta": theta, "dT": temps - 20.0, "Tdot": z, "rate": rate,
                               "accel_z": z, "t_run": z})  # fmt: skip
    sig = np.full(g.shape[0], 0.01 * DEG_PER_H)
    truth = np.zeros(g.shape[1])
    truth[1] = 0.554
    beta, r, cov = stats.wls(g, g @ truth + 3 * sig * rng.standard_normal(g.shape[0]), sig)
    params = {}
    for (name, p), b, e in zip(regular_parameters(model), beta, np.sqrt(np.diag(cov)),
                               strict=True):  # fmt: skip
        params.setdefault(name, {})[p] = {"value": b, "std": e}
    fit = Fit(tuple(model), params, r, g / sig[:, None], float(r @ r), 0.0, 0.0)
    return fit, {k: v / sig[:, None] for k, v in shapes.items()}, (rate == 0).astype(int)


def main():
    print(machine())
    rng = np.random.default_rng(0)
    f_args = [(float(f), int(d1), int(d2)) for f, d1, d2 in
              zip(rng.uniform(0.1, 8.0, 200), rng.integers(1, 6, 200), rng.integers(2, 80, 200),
                  strict=True)]  # fmt: skip
    c_args = [(float(x), int(k)) for x, k in
              zip(rng.uniform(0.0, 30.0, 200), rng.integers(1, 10, 200), strict=True)]  # fmt: skip
    ref_f = np.array([sps.f.sf(*a) for a in f_args])
    ref_c = np.array([sps.chi2.sf(*a) for a in c_args])
    for name, new, old, args, ref in (("f_sf", stats.f_sf, _eager_f_sf, f_args, ref_f),
                                      ("chi2_sf", stats.chi2_sf, _eager_chi2_sf, c_args, ref_c)):  # fmt: skip
        err = max(np.max(np.abs(np.array([fn(*a) for a in args]) - ref) / np.maximum(ref, 1e-300))
                  for fn in (new, old))  # fmt: skip
        t_old, t_new = _per_call(old, args), _per_call(new, args)
        print(f"{name}: largest relative difference from scipy, both ways: {err:.2e}")
        report(f"stats.{name} per call, eager (before)", t_old * 1e6, "µs")
        report(f"stats.{name} per call, compiled", t_new * 1e6, "µs", "eager / compiled",
               t_old / t_new)  # fmt: skip

    # the leftover shapes' tails, one round's eighteen: one call each against one call
    f18 = np.array([a[0] for a in f_args[:18]])
    d1, d2 = (np.array([a[k] for a in f_args[:18]]) for k in (1, 2))
    err = np.max(np.abs(stats.f_sf_many(f18, d1, d2) - ref_f[:18]) / ref_f[:18])
    t_loop = _per_call(lambda: [stats.f_sf(*a) for a in f_args[:18]], [()] * 20)
    t_many = _per_call(lambda: stats.f_sf_many(f18, d1, d2), [()] * 20)
    print(f"f_sf_many: largest relative difference from scipy: {err:.2e}")
    report("18 F tails, f_sf each (before)", t_loop * 1e6, "µs")
    report("18 F tails, f_sf_many", t_many * 1e6, "µs", "before / after", t_loop / t_many)

    fit, cols, classes = _grid_fit(rng)
    trust.honest(fit, cols, classes)
    times = {}
    for label, f_sf, chi2_sf in (("eager", _eager_f_sf, _eager_chi2_sf),
                                 ("compiled", stats.f_sf, stats.chi2_sf)):  # fmt: skip
        saved = stats.f_sf, stats.chi2_sf
        stats.f_sf, stats.chi2_sf = f_sf, chi2_sf  # trust and leftover call them through stats
        try:
            times[label] = _per_call(lambda: trust.honest(fit, cols, classes), [()] * 10)
        finally:
            stats.f_sf, stats.chi2_sf = saved
    report("trust.honest per call, tails eager (before)", times["eager"] * 1e3, "ms")
    report("trust.honest per call, tails compiled", times["compiled"] * 1e3, "ms",
           "before / after", times["eager"] / times["compiled"])  # fmt: skip


if __name__ == "__main__":
    main()
