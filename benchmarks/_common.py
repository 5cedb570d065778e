"""Shared benchmark helpers: x64 on, timing with warm-up and block_until_ready."""

import platform
import time

import jax

jax.config.update("jax_enable_x64", True)


def machine() -> str:
    dev = jax.devices()[0]
    return f"{platform.processor() or platform.machine()}, {jax.device_count()}× {dev.device_kind}, jax {jax.__version__}"


def best_of(fn, repeat=5):
    """Best wall time [s] of `repeat` calls of fn (already compiled), each blocked until ready."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        times.append(time.perf_counter() - t0)
    return min(times)


def first_call(fn):
    """Wall time [s] of the first call (compile + run) and its result."""
    t0 = time.perf_counter()
    out = jax.block_until_ready(fn())
    return time.perf_counter() - t0, out
