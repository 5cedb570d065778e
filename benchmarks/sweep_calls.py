"""A repeated chunked `hg.sweep` of one callable equinox Module (thirteenth session): the first
sweep (compile + run) against the second on the same grids, now and as before.

A Module with array fields cannot be hashed, so `sweep` kept no compiled batch for it: every
sweep traced and compiled its chunk program (and the cost probe) again, for the same shapes.
It is now kept by the Module's identity. "Before" is the same run with the old lookup (a
fresh program for an unhashable `fn`), side by side in one process; the ratio first / second
is ≈ 1 before.

Usage: `.venv/bin/python benchmarks/sweep_calls.py [--points N] [--chunk C]`.
"""

import argparse
import importlib
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from _common import machine  # noqa: E402

import hrgjax as hg  # noqa: E402

sweep_module = importlib.import_module("hrgjax.sweep")  # the module (hg.sweep: the function)


class FinalAngle(eqx.Module):
    """The swept function: a 5-s run of an ideal-loop gyro, its last wave angle."""

    gyro: hg.Gyro

    def __call__(self, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 5.0, 20.0)
        return hg.simulate(self.gyro, prof, dt_out=5.0).wave_angle[-1]


class _Fresh:
    """The lookup before: a fresh program for a `fn` that cannot be hashed."""

    def __init__(self, kept):
        self.kept = kept

    def get(self, fn, make):
        try:
            hash(fn)
        except TypeError:
            return make()
        return self.kept.get(fn, make)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10)
    ap.add_argument("--chunk", type=int, default=4)
    args = ap.parse_args()
    print(machine())
    rates = jnp.linspace(0.5, 50.0, args.points)
    gyro = hg.presets.ideal(hg.presets.tvg3_like().resonator)
    kept = (sweep_module._BATCHED, sweep_module._PROBES)
    for label, before in (("now", False), ("before", True)):
        fn = FinalAngle(gyro)  # a new object: nothing compiled for it yet
        if before:
            sweep_module._BATCHED, sweep_module._PROBES = (_Fresh(c) for c in kept)
        times = []
        try:
            for _ in range(2):
                t0 = time.perf_counter()
                jax.block_until_ready(hg.sweep(fn, rate_dps=rates, chunk_size=args.chunk))
                times.append(time.perf_counter() - t0)
        finally:
            sweep_module._BATCHED, sweep_module._PROBES = kept
        print(
            f"sweep of a Module, {args.points} points in chunks of {args.chunk}, {label}: "
            f"first {times[0]:.2f} s, second {times[1]:.3f} s "
            f"(first / second {times[0] / times[1]:.1f}×)"
        )


if __name__ == "__main__":
    main()
