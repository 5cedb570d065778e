"""Gradient / forward on hrgjax's two own fixed-step integrators (issue 50):

- the full model's fixed-step carrier path, 0.02 s at 5 kHz with 4 outputs, loss = Σ wave
  angles, gradient with respect to every resonator parameter and the table rate, steps of
  2e-5 s (10 per carrier cycle; a step in seconds, as the default `"auto"` falls back to
  adaptive steps when the resonator is traced): a free resonator and the default gyro with
  its loops closed (every stage demodulating); derivatives from the stored states
  (`hrgjax._stepped`, runs of ≤ `carrier.STORE_STEPS` steps; `--checkpointed`: through the
  step loop, each chunk of ≤ 256 steps recomputed, as longer runs and before issue 50);
- discovery's Bogacki–Shampine scan (`discovery.records.bosh3_path`, a plain `lax.scan`:
  reverse mode keeps every step's residuals, nothing recomputed) on a 1-h record of 20 000
  samples (5 000 steps, a covariate look-up per stage), loss = Σ model², four parameters;
  and its forward-mode Jacobian (what the fits take).

Each: the forward and the gradient compiled (`jax.jit`), best of 5 after the first call, and
their ratio. Target (issue 50): ≤ 2.5× on both.

Usage: `.venv/bin/python benchmarks/gradient_scans.py [--checkpointed]` (≈ 4 min on 2
cores, mostly compiling).
"""

import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _common import best_of, first_call, machine, report

import hrgjax as hg
from hrgjax.discovery.records import bosh3_path

SPAN = 0.02
FREE = hg.Gyro(
    hg.Resonator(omega=2 * np.pi * 5000.0, tau=640.0, k_e=0.554, delta_omega=2 * np.pi * 0.05,
                 theta_omega=0.2, delta_inv_tau=2e-3, theta_tau=0.5, chi=2e4),
    control=hg.Control.free(),
)  # fmt: skip


def timed(forward, gradient, args):
    out = []
    for fn in (forward, gradient):
        first, _ = first_call(lambda fn=fn: fn(*args))
        out.append((best_of(lambda fn=fn: fn(*args), 5), first))
    return out


def carrier_rows():
    if "--checkpointed" in sys.argv:
        hg.resonator.carrier.STORE_STEPS = 0
    ts = np.linspace(SPAN / 4, SPAN, 4)
    loops = hg.presets.tvg3_like(noise=False)
    for name, gyro, path in (("free resonator", FREE, 2e-5),
                             ("loops closed", loops, 2e-5)):  # fmt: skip

        def loss(res, rate, gyro=gyro, path=path):
            g = eqx.tree_at(lambda g: g.resonator, gyro, res)
            prof = hg.Profile.constant_rate(rate, SPAN, wave_angle0_deg=10.0)
            return jnp.sum(hg.simulate(g, prof, "full", ts=ts, fixed_step=path).wave_angle)

        fwd, grad = eqx.filter_jit(loss), eqx.filter_jit(eqx.filter_grad(loss))
        (tf, cf), (tg, cg) = timed(fwd, grad, (gyro.resonator, jnp.asarray(30.0)))
        print(f"  carrier, {name:27s} forward {tf * 1e3:7.1f} ms, gradient {tg * 1e3:7.1f} ms "
              f"({tg / tf:4.1f}×; compile {cf:.1f} / {cg:.1f} s)")  # fmt: skip
        report(f"carrier path gradient, {name}", tg * 1e3, "ms", "gradient / forward",
               tg / tf, "≤ 2.5×")  # fmt: skip


def bosh3_rows():
    n = 20000
    t = jnp.linspace(0.0, 3600.0, n)
    temp, rate = 20 + 5 * jnp.sin(t / 600.0), 0.01 * jnp.cos(t / 300.0)
    steps, blocks = jnp.arange(0, n, 4), jnp.arange(0, n, 100)

    def model(p):
        def field(s, y, _):
            i = jnp.clip(jnp.searchsorted(t, s, side="right") - 1, 0, n - 2)
            f = jnp.clip((s - t[i]) / (t[i + 1] - t[i]), 0.0, 1.0)
            lerp = lambda v: v[i] + (v[i + 1] - v[i]) * f  # noqa: E731
            return p[0] + p[1] * jnp.sin(2 * y) + p[2] * (lerp(temp) - 20) + p[3] * lerp(rate)

        return bosh3_path(field, t[steps], 0.3, t[blocks])

    loss = lambda p: jnp.sum(model(p) ** 2)  # noqa: E731
    p = jnp.array([1e-5, 2e-6, 3e-7, 0.5])
    (tf, _), (tg, _) = timed(jax.jit(loss), jax.jit(jax.grad(loss)), (p,))
    (tj, _), _ = timed(jax.jit(jax.jacfwd(model)), jax.jit(jax.grad(loss)), (p,))
    print(f"  Bosh3 scan, 5 000 steps: forward {tf * 1e3:6.1f} ms, gradient {tg * 1e3:6.1f} ms "
          f"({tg / tf:.1f}×), forward-mode Jacobian (4 columns) {tj * 1e3:6.1f} ms "
          f"({tj / tf:.1f}×)")  # fmt: skip
    report("Bosh3 scan gradient, 5 000 steps", tg * 1e3, "ms", "gradient / forward", tg / tf,
           "≤ 2.5×")  # fmt: skip


def main():
    print(f"machine: {machine()}")
    carrier_rows()
    bosh3_rows()


if __name__ == "__main__":
    main()
