"""Eager calls of the Kalman filter and smoother (eleventh session) and of `steady_state`
(twelfth): the second call on new data of the same shapes, fused (`hrgjax._compiled.fused`: one compiled program per shape)
against the plain function (`__wrapped__`, as before: its `lax.scan` traced and compiled on
every call, a new closure each time). Side by side in one process, best of `--repeat`.

The extended and unscented filters (thirteenth session): the first eager call (compile + run)
against the second on new data with the same `f`, `h`, fused (compiled once per shape and
model) and plain (before: compiled on every call); the ratio first / second is ≈ 1 before.

Usage: `.venv/bin/python benchmarks/kalman_calls.py [--steps K] [--repeat N]`.
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine  # noqa: E402

from hrgjax import kalman  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(machine())
    n, k = 4, args.steps
    rng = np.random.default_rng(0)
    phi = jnp.eye(n) + 0.01 * jnp.asarray(rng.normal(size=(n, n)))
    qd, h, r = 1e-3 * jnp.eye(n), jnp.eye(2, n), 0.1 * jnp.eye(2)
    prior = kalman.Gaussian(jnp.zeros(n), jnp.eye(n))
    for name in ("kalman_filter", "rts_smoother"):
        fused = getattr(kalman, name)
        plain = fused.__wrapped__
        best = {}
        for label, fn in (("fused", fused), ("plain (before)", plain)):
            fn(prior, phi, qd, h, r, jnp.asarray(rng.normal(size=(k, 2))))[2].block_until_ready()
            times = []
            for _ in range(args.repeat):
                zs = jnp.asarray(rng.normal(size=(k, 2)))
                t0 = time.perf_counter()
                fn(prior, phi, qd, h, r, zs)[2].block_until_ready()
                times.append(time.perf_counter() - t0)
            best[label] = min(times)
        _print(name, f"{k} steps, {n} states", best)
    best = {}
    for label, fn in (
        ("fused", kalman.steady_state),
        ("plain (before)", kalman.steady_state.__wrapped__),
    ):
        fn(phi, qd, h, r, jnp.eye(n))[2].block_until_ready()
        times = []
        for _ in range(args.repeat):
            r_new = r * (1.0 + rng.uniform())
            t0 = time.perf_counter()
            fn(phi, qd, h, r_new, jnp.eye(n))[2].block_until_ready()
            times.append(time.perf_counter() - t0)
        best[label] = min(times)
    doublings = f"at most {kalman.STEADY_DOUBLINGS} doublings (stops when converged)"
    _print("steady_state", f"{doublings}, {n} states", best)
    nonlinear(prior, qd, r, rng, k)


def nonlinear(prior, qd, r, rng, k) -> None:
    """First / second eager call of the EKF and UKF, fused and plain (before), one process."""
    f = lambda x, u: x + 0.01 * jnp.sin(x[::-1]) + u  # noqa: E731
    h = lambda x: jnp.stack([x[0], x[1] * x[2]])  # noqa: E731
    us = jnp.zeros((k, 4))
    for name in ("extended_kalman_filter", "unscented_kalman_filter"):
        fused = getattr(kalman, name)
        line = []
        for label, fn in (("fused", fused), ("plain (before)", fused.__wrapped__)):
            times = []
            for _ in range(2):
                zs = jnp.asarray(rng.normal(size=(k, 2)))
                t0 = time.perf_counter()
                fn(prior, f, qd, h, r, zs, us=us)[2].block_until_ready()
                times.append(time.perf_counter() - t0)
            line.append(f"{label} first {1e3 * times[0]:.1f} ms, second {1e3 * times[1]:.1f} ms "
                        f"(first / second {times[0] / times[1]:.1f}×)")  # fmt: skip
        print(f"{name}, {k} steps, 4 states, same f and h: " + "; ".join(line))


def _print(name, what, best):
    ratio = best["plain (before)"] / best["fused"]
    print(
        f"{name}, {what}, a later eager call: fused {1e3 * best['fused']:.1f} ms, "
        f"plain {1e3 * best['plain (before)']:.1f} ms (plain / fused {ratio:.0f}×)"
    )


if __name__ == "__main__":
    main()
