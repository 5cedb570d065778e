"""What the slow manifold's program costs to compile: its Newton iterations as fixed-trip
`fori_loop`s (`hrgjax.resonator.slow`, today) against the same steps written out as Python
loops (`unrolled_rate` below: the form before 2026-12, every step traced and compiled anew),
side by side in one run. Both on the default gyro at 20 °C, 10 °/s, vmapped over 8 wave
angles (as `PhysicalCompensator.scale_factor_at` runs it): the rate θ̇ itself, and θ̇ with
its forward derivative in the input rate (the grey box's slow-rate-limit scale factor).
Per program: tracing + lowering + XLA compile (wall and process CPU seconds), the run
(best of 20) and the largest relative difference of the two forms' numbers.

Usage: `.venv/bin/python benchmarks/slow_manifold_compile.py` (≈ 1 min).
"""

import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import report

import hrgjax as hg
from hrgjax._linalg import solve
from hrgjax.resonator import slow
from hrgjax.resonator.control import steady_integrators


def unrolled_rate(g, omega_in, theta):
    """`slow.reduced_rate` with its Newton steps written out (the earlier form)."""
    theta = jnp.asarray(theta, dtype=float)
    n, d = slow.SAMPLES, jnp.asarray(slow._D)
    fields = lambda x, th: slow._fields(g, omega_in, x, th)

    def at_rest(th):
        a0 = g.control.amplitude
        x = jnp.concatenate([jnp.stack([a0, 0.0 * a0, 0.0 * a0]),
                             steady_integrators(g.control, g.resonator, a0, th)])  # fmt: skip
        fast = lambda x: fields(x, th)[0]
        for _ in range(slow.NEWTON):
            x = x - solve(jax.jacfwd(fast)(x), fast(x))
        return x, jax.jacfwd(fast)(x), fields(x, th)[1]

    thetas = theta + (jnp.pi / n) * jnp.arange(n, dtype=float)
    h0, jac, rate = jax.vmap(at_rest)(thetas)
    m = h0.shape[1]
    big_d = jnp.kron(rate[:, None] * d, jnp.eye(m))
    blocks = jax.scipy.linalg.block_diag(*[jac[j] for j in range(n)])
    h = h0 + solve(big_d - blocks, -big_d @ h0.reshape(-1)).reshape(n, m)
    for _ in range(slow.BALANCE_NEWTON):
        (f, r), (jf, jg) = jax.vmap(lambda x, th: (fields(x, th), jax.jacfwd(fields)(x, th)))(
            h, thetas
        )
        dh = d @ h
        big = jax.scipy.linalg.block_diag(*[(jf - dh[:, :, None] * jg[:, None, :])[j]
                                            for j in range(n)])  # fmt: skip
        big = big - jnp.kron(r[:, None] * d, jnp.eye(m))
        h = h - solve(big, (f - r[:, None] * dh).reshape(-1)).reshape(n, m)
    return fields(h[0], theta)[1]


def programs(rate_fn):
    plain = lambda g, w, th: jax.vmap(lambda x: rate_fn(g, w, x))(th)
    tangent = lambda g, w, th: jax.vmap(
        lambda x: jax.jvp(lambda w: rate_fn(g, w, x), (w,), (jnp.ones_like(w),))
    )(th)
    return {"θ̇": plain, "θ̇ and ∂θ̇/∂Ω": tangent}


def build(fn, *args):
    """(compiled, wall [s], CPU [s]) of tracing, lowering and compiling fn at args."""
    c0, t0 = time.process_time(), time.perf_counter()
    compiled = jax.jit(fn).trace(*args).lower().compile()
    return compiled, time.perf_counter() - t0, time.process_time() - c0


def run_time(compiled, *args, repeat=20):
    jax.block_until_ready(compiled(*args))
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(*args))
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    g = hg.presets.tvg3_like(noise=False).at(20.0)
    w = jnp.asarray(float(g.rate_bias) + np.deg2rad(10.0))
    th = jnp.linspace(-np.pi / 2, np.pi / 2, 8)
    new, old = programs(slow.reduced_rate), programs(unrolled_rate)
    print("| program (8 angles) | compile, loops: wall / CPU | written out | run, loops | "
          "written out | numbers differ by |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for name in new:
        c_new, wall_new, cpu_new = build(new[name], g, w, th)
        c_old, wall_old, cpu_old = build(old[name], g, w, th)
        out_new = np.concatenate([np.ravel(x) for x in jax.tree.leaves(c_new(g, w, th))])
        out_old = np.concatenate([np.ravel(x) for x in jax.tree.leaves(c_old(g, w, th))])
        diff = np.max(np.abs(out_new - out_old) / np.abs(out_old))
        assert diff < 1e-12, (name, diff)  # the same numbers, to round-off
        run_new, run_old = run_time(c_new, g, w, th), run_time(c_old, g, w, th)
        print(f"| {name} | {wall_new:.2f} s / {cpu_new:.2f} s | {wall_old:.2f} s / "
              f"{cpu_old:.2f} s | {run_new * 1e3:.2f} ms | {run_old * 1e3:.2f} ms | "
              f"{diff:.1e} |", flush=True)  # fmt: skip
        report(f"slow manifold compile ({name}, 8 angles)", cpu_new, "s CPU",
               f"written out {cpu_old:.2f} s CPU", ratio=cpu_new / cpu_old)  # fmt: skip


if __name__ == "__main__":
    main()
