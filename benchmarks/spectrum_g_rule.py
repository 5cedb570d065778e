"""The traced "accel in g" rule of `fog.spectrum` (review of 4216a16): jitted
`vibration_features` with the rule as it is (counts: `_median_within`), with it as 4216a16
wrote it (`jnp.median`, a sort) and with no rule, in one process, alternated round by round;
the best of `--calls` per round, the median over `--rounds`. Also: whether the counting rule
decides as NumPy's median on 2 000 random records of odd and even length.

    .venv/bin/python benchmarks/spectrum_g_rule.py [--n 65536 262144] [--rounds 5]
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from hrgjax.fog import spectrum as sp  # noqa: E402

FS = 200.0
COUNTS = sp._median_within
RULES = {
    "counts (now)": COUNTS,
    "jnp.median (4216a16)": lambda r, lo, hi: (lo < jnp.median(r)) & (jnp.median(r) < hi),
    "no rule": lambda r, lo, hi: jnp.zeros((), bool),
}


def _record(n):
    t = np.arange(n) / FS
    noise = 0.01 * np.random.default_rng(0).standard_normal(n)
    return np.c_[0.5 * 9.80665 * np.sin(2 * np.pi * 20 * t), noise, -9.80665 * np.ones(n)]


def _best(f, x, calls):
    ts = []
    for _ in range(calls):
        t0 = time.perf_counter()
        jax.block_until_ready(f(x))
        ts.append(time.perf_counter() - t0)
    return 1e3 * min(ts)


def _agreement():
    rng = np.random.default_rng(1)
    within = jax.jit(jax.vmap(lambda r: COUNTS(r, 0.5, 2.0)))
    bad = 0
    for n in (40, 41):
        r = np.concatenate([rng.choice([0.3, 0.5, 0.7, 1.9, 2.0, 2.1], (500, n)),
                            rng.uniform(0.0, 3.0, (500, n))])  # fmt: skip
        bad += int(np.sum(np.asarray(within(r)) != [0.5 < np.median(x) < 2.0 for x in r]))
    return bad


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, nargs="+", default=[65536, 262144])
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--calls", type=int, default=7)
    a = p.parse_args()
    print(f"decisions differing from NumPy's median over 2000 records: {_agreement()}")
    for n in a.n:
        x = jnp.asarray(_record(n))
        progs = {}
        for name, rule in RULES.items():
            sp._median_within = rule
            progs[name] = jax.jit(lambda x: sp.vibration_features(x, FS))
            jax.block_until_ready(progs[name](x))  # traced and compiled with this rule
        sp._median_within = COUNTS
        got = {name: [] for name in progs}
        for _ in range(a.rounds):
            for name, f in progs.items():
                got[name].append(_best(f, x, a.calls))
        print(f"N = {n}: " + "; ".join(f"{k} {np.median(v):.2f} ms (best {min(v):.2f})"
                                       for k, v in got.items()))  # fmt: skip


if __name__ == "__main__":
    main()
