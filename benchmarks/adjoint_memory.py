"""Peak memory of the gradient through a long averaged simulation vs the forward run.

A warm-up run: 5 °/s with the temperature ramping −40 → +20 °C over the run (tvg3_like, noise
off), lengths 225 s … 2 h. Loss: the mean square wave angle over 1-s outputs (`dt_out`
loss), or the final angle only (`final` loss). Gradient w.r.t. all resonator parameters.

Memory is XLA's own account of the compiled program (`compiled.memory_analysis()`: the peak
of live temporaries plus arguments and outputs, the same on any backend); on a GPU the
allocator's measured peak is printed too. Adjoints compared:

- the default: recursive checkpointing with 256 checkpoints (`simulate`'s default);
- store every step: `RecursiveCheckpointAdjoint(checkpoints=n_steps)`, what plain
  backpropagation through the step loop keeps (memory ∝ steps);
- `BacksolveAdjoint`: the continuous adjoint, O(1) in steps but solves backwards.

Target (issue 8): the gradient of a 1-hour averaged simulation in ≤ 2× the forward's memory.
Usage: `.venv/bin/python benchmarks/adjoint_memory.py [--quick]`.
"""

import sys

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _common import best_of, machine, report

import hrgjax as hg
from hrgjax.simulate import AVERAGED_CHECKPOINTS, _default_solver, _solve, output_times

QUICK = "--quick" in sys.argv
LENGTHS = (225.0, 900.0, 3600.0) if QUICK else (225.0, 450.0, 900.0, 1800.0, 3600.0, 7200.0)


def profile(length):
    return hg.Profile.piecewise([0.0, length], [5.0, 5.0], [-40.0, 20.0])


def n_steps(gyro, prof, ts):
    """Accepted steps of `simulate`'s default solve (the step loop's length)."""
    adjoint = diffrax.RecursiveCheckpointAdjoint(AVERAGED_CHECKPOINTS)
    solver, zero = _default_solver("averaged"), jnp.asarray(0.0)
    args = (1e-8, 1e-10, 2**16, 1e-2, False, zero, adjoint)  # rtol, atol, max_steps, dt0, …
    return int(_solve("averaged", gyro, prof, ts, solver, *args)[1])


def make_loss(gyro, static, prof, ts):
    """Mean square wave angle at `ts` as a function of the resonator's array parameters."""

    def loss(params, adjoint=None, max_steps=None):
        g = eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(params, static))
        r = hg.simulate(g, prof, ts=ts, adjoint=adjoint, max_steps=max_steps)
        return jnp.mean(r.wave_angle**2)

    return loss


def peak_bytes(fn, params):
    """XLA's peak for the compiled fn: live temporaries + arguments + outputs [bytes]."""
    m = jax.jit(fn).lower(params).compile().memory_analysis()
    return m.temp_size_in_bytes + m.argument_size_in_bytes + m.output_size_in_bytes


def measured_peak(fn, params):
    """The allocator's peak on a GPU after one call [bytes]; None where not reported (CPU)."""
    stats = jax.devices()[0].memory_stats()
    if not stats or "peak_bytes_in_use" not in stats:
        return None
    jax.block_until_ready(jax.jit(fn)(params))
    return jax.devices()[0].memory_stats()["peak_bytes_in_use"]


def main():
    gyro = hg.presets.tvg3_like(noise=False)
    params, static = eqx.partition(gyro.resonator, eqx.is_inexact_array)
    print(f"machine: {machine()}")
    print("warm-up run at 5 °/s, −40 → +20 °C; gradient w.r.t. the resonator parameters")
    print(
        f"{'length':>8} {'steps':>6} {'loss':>6} {'forward':>10} {'gradient':>10} {'ratio':>6}"
        f" {'store-all':>10} {'backsolve':>10}"
    )
    rows = {}
    for length in LENGTHS:
        prof = profile(length)
        for kind in ("dt_out", "final"):
            ts = output_times(prof, 1.0) if kind == "dt_out" else jnp.array([0.0, length])
            steps = n_steps(gyro, prof, ts)
            loss = make_loss(gyro, static, prof, ts)

            fwd = peak_bytes(loss, params)
            grad = peak_bytes(jax.grad(loss), params)
            store_all = peak_bytes(
                jax.grad(lambda p, n=steps, f=loss: f(p, diffrax.RecursiveCheckpointAdjoint(n), n)),
                params,
            )
            back = peak_bytes(jax.grad(lambda p, f=loss: f(p, diffrax.BacksolveAdjoint())), params)
            rows[length, kind] = (steps, fwd, grad, store_all, back)
            print(
                f"{length:7.0f}s {steps:6d} {kind:>6} {fwd / 1e3:8.1f}kB {grad / 1e3:8.1f}kB "
                f"{grad / fwd:5.2f}× {store_all / 1e3:8.1f}kB {back / 1e3:8.1f}kB"
            )
            gpu = measured_peak(jax.grad(loss), params)
            if gpu is not None:
                print(f"{'':>8} GPU allocator peak, gradient: {gpu / 1e6:.2f} MB")

    # Headline figures: the 1-hour run.
    steps, fwd, grad, store_all, back = rows[3600.0, "dt_out"]
    report("1-h averaged run, 1-s outputs: forward peak memory", fwd / 1e3, "kB")
    report(
        "1-h averaged run, 1-s outputs: gradient peak memory",
        grad / 1e3,
        "kB",
        "gradient / forward",
        grad / fwd,
        "≤ 2×",
    )
    report(
        "1-h averaged run: gradient memory, every step stored",
        store_all / 1e3,
        "kB",
        "store-all / checkpointed",
        store_all / grad,
    )
    steps_f, fwd_f, grad_f, *_ = rows[3600.0, "final"]
    short = rows[LENGTHS[0], "final"][2]
    report(
        "1-h averaged run, final-angle loss: gradient peak memory",
        grad_f / 1e3,
        "kB",
        f"1 h / {LENGTHS[0]:.0f} s",
        grad_f / short,
    )

    # Time against memory on the 1-hour run: the number of checkpoints is the dial.
    prof = profile(3600.0)
    loss = make_loss(gyro, static, prof, output_times(prof, 1.0))

    f = jax.jit(loss)
    jax.block_until_ready(f(params))
    t_f = best_of(lambda: f(params))
    assert np.isfinite(float(f(params)))
    print(f"\n1-h run, 1-s outputs, {steps} steps: forward {t_f * 1e3:.0f} ms, {fwd / 1e3:.0f} kB")
    print(
        f"{'checkpoints':>12} {'gradient':>10} {'/ forward':>10} {'memory':>10} {'/ forward':>10}"
    )
    times = {}
    for n in (64, 256, 1024, 4096, steps) if not QUICK else (256, steps):
        adjoint = diffrax.RecursiveCheckpointAdjoint(n)
        fn = lambda p, a=adjoint, n=n: loss(p, a, steps if n == steps else None)
        g = jax.jit(jax.grad(fn))
        jax.block_until_ready(g(params))
        t_g = best_of(lambda g=g: g(params), 3)
        mem = peak_bytes(jax.grad(fn), params)
        times[n] = (t_g, mem)
        label = f"{n} (all)" if n == steps else str(n)
        print(
            f"{label:>12} {t_g * 1e3:8.0f}ms {t_g / t_f:9.1f}× {mem / 1e3:8.0f}kB {mem / fwd:9.2f}×"
        )
    report(
        "1-h averaged run: gradient time, 256 checkpoints (default)",
        times[256][0] * 1e3,
        "ms",
        "gradient / forward",
        times[256][0] / t_f,
    )
    report(
        "1-h averaged run: gradient time, every step stored",
        times[steps][0] * 1e3,
        "ms",
        "gradient / forward",
        times[steps][0] / t_f,
    )


if __name__ == "__main__":
    main()
