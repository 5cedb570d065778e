"""What does `hg.allan.deviation`'s noise-mixture fit cost (`hrgjax.allan.mixture`)?

CPU time (`time.process_time`, the minimum of `--repeat` calls after one warm-up: robust on
a loaded machine) of the default oadev call on 1 024 and 10⁵ samples at 100 Hz (white rate
noise, white angle noise and a rate random walk), mtotdev on 1 024, oadev with `taus="all"`
on 3 000 (more than 64 τ: the fit's result unused), `fit_mixture` alone at 10⁵, and, where
the tree has it, the same calls with `mixture=False`. Prints the hrgjax it ran.

Usage: `.venv/bin/python benchmarks/mixture_cost.py [--repeat 7]`; another tree's:
`PYTHONPATH=/path/to/tree .venv/bin/python benchmarks/mixture_cost.py` (the script's own
folder holds no `hrgjax`, so PYTHONPATH's comes before the installed one).
"""

import argparse
import inspect
import time

import jax

jax.config.update("jax_enable_x64", True)
import numpy as np  # noqa: E402

import hrgjax as hg  # noqa: E402
from hrgjax.allan import mixture  # noqa: E402


def best(f, k):
    """(CPU, wall) [ms], each the minimum over `k` calls after a warm-up (CPU counts every
    thread: XLA's curve and the NumPy fit may overlap, so wall time is printed beside it)."""
    f()
    cpu, wall = [], []
    for _ in range(k):
        t0, w0 = time.process_time(), time.perf_counter()
        f()
        cpu.append(time.process_time() - t0)
        wall.append(time.perf_counter() - w0)
    return 1e3 * min(cpu), 1e3 * min(wall)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=7)
    k = p.parse_args().repeat
    print("hrgjax from", hg.__file__)
    rng = np.random.default_rng(0)
    n = 100_000
    y = (rng.normal(size=n) + 3 * np.diff(rng.normal(size=n + 1))
         + 1e-3 * np.cumsum(rng.normal(size=n)))  # fmt: skip
    short, mid = y[:1024], y[:3000]
    opt = "mixture" in inspect.signature(hg.allan.deviation).parameters
    cases = [
        ("oadev octave, 1 024 samples", lambda **o: hg.allan.deviation(short, 100.0, **o)),
        ("oadev octave, 10⁵ samples", lambda **o: hg.allan.deviation(y, 100.0, **o)),
        ("mtotdev octave, 1 024 samples",
         lambda **o: hg.allan.deviation(short, 100.0, kind="mtotdev", **o)),
        ('oadev taus="all", 3 000 samples',
         lambda **o: hg.allan.deviation(mid, 100.0, taus="all", **o)),
    ]  # fmt: skip
    for name, f in cases:
        cpu, wall = best(f, k)
        line = f"{name:34s} {cpu:8.1f} ms CPU {wall:8.1f} ms wall"
        if opt:
            cpu0, wall0 = best(lambda f=f: f(mixture=False), k)
            line += (f"   mixture=False {cpu0:8.1f} ms CPU {wall0:8.1f} ms wall"
                     f"   default/off {cpu / cpu0:5.2f}× CPU {wall / wall0:5.2f}× wall")  # fmt: skip
        print(line, flush=True)
    x = np.concatenate([[0.0], np.cumsum(y - y.mean())]) * 0.01
    cpu, wall = best(lambda: mixture.fit_mixture(x, 0.01), k)
    print(f"{'fit_mixture alone, 10⁵ samples':34s} {cpu:8.1f} ms CPU {wall:8.1f} ms wall")


if __name__ == "__main__":
    main()
