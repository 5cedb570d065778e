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

`--parts`: where the carrier gradient's time goes, each variant in a fresh process (≈ 5 min):
the stored-state derivative as it is (`full`); without the 8 × 8 Jacobians (`no-jacobians`:
the identity instead), without the input tangents (`no-inputs`), without either (`neither`:
the forward, the per-step inputs' derivatives and the recurrence); the stages written out
in the derivative while the forward keeps its stage loop (`stages-unrolled`, loops closed
only); and the reverse pass through the step loop checkpointed every step (`chunk-1`) or
every 256 steps (`chunk-256`); and the stored states' derivative without the batched
linearisation, each step's JVP rematerialised and transposed one step at a time
(`sequential`: a per-step hand-written VJP's work). The variants other than `full` and
`sequential` give wrong gradients: they time parts, nothing else.

Usage: `.venv/bin/python benchmarks/gradient_scans.py [--checkpointed | --parts]` (≈ 4 min on
2 cores, mostly compiling).
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


PARTS = ("full", "no-jacobians", "no-inputs", "neither", "stages-unrolled", "chunk-1",
         "chunk-256", "sequential")  # fmt: skip


def _variant(name):
    """Patch the carrier path for one `--parts` variant (this process only)."""
    import functools

    from hrgjax import _stepped
    from hrgjax.resonator import carrier as C

    if name.startswith("chunk-"):
        C.STORE_STEPS, C.CHUNK = 0, int(name[6:])
        return
    if name == "stages-unrolled":

        @functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
        def stored(steps, held, looped, gyro, profile, y0, omega_scale, ts):
            return C._streamed(gyro, profile, y0, omega_scale, ts, steps, held, looped)

        @stored.defjvp
        def stored_jvp(steps, held, looped, primals, tangents):  # carrier._stored_jvp, but
            gyro, profile, y0, omega_scale, ts = primals  # the tangents' stages written out
            d_gyro, d_profile, dy0, d_scale, d_ts = tangents
            build = lambda g, p, s, t: C._per_step(g, p, s, t, steps, held)  # noqa: E731
            (xs, theta, at), (dxs, d_theta, _) = jax.jvp(
                build, (gyro, profile, omega_scale, ts), (d_gyro, d_profile, d_scale, d_ts)
            )
            flags = (gyro.control.enabled and not held, profile.rebalance is not None)
            ys = _stepped.scan_states(
                functools.partial(C._flat_step, *flags, looped), y0, xs, theta
            )
            dys = _stepped.tangent_states(
                functools.partial(C._flat_step, *flags, False), ys, xs, theta, dy0, dxs, d_theta
            )
            return ys[at], dys[at]

        C._stored = stored
        return
    if name == "full":
        return
    if name == "sequential":  # no linearisation batch: each step's JVP, rematerialised,
        # transposed one step at a time (what a hand-written per-step VJP would run)

        def sequential(step, ys, xs, theta, dy0, dxs, dtheta, batch=_stepped.BATCH):
            @functools.partial(jax.checkpoint, policy=jax.checkpoint_policies.nothing_saveable)
            def body(dy, inp):
                y, x, dx = inp
                dx = jax.tree_util.tree_map(
                    _stepped._zero_if_none, x, dx, is_leaf=lambda v: v is None
                )
                dy1 = jax.jvp(step, (y, x, theta), (dy, dx, dtheta))[1]
                return dy1, dy1

            _, dys = jax.lax.scan(body, dy0, (ys[:-1], xs, _stepped._float_only(dxs)))
            return jnp.concatenate([dy0[None], dys])

        C.tangent_states = sequential
        return
    original = _stepped.tangent_states

    def tangent_states(step, ys, xs, theta, dy0, dxs, dtheta, batch=_stepped.BATCH):
        eye = jnp.eye(ys.shape[1], dtype=ys.dtype)
        zero_theta = jax.tree_util.tree_map(_stepped._zero_tangent, theta)

        def linear(y, x, dx):
            dx = jax.tree_util.tree_map(_stepped._zero_if_none, x, dx, is_leaf=lambda v: v is None)
            _, lin = jax.linearize(step, y, x, theta)
            zero_x = jax.tree_util.tree_map(_stepped._zero_tangent, x)
            if name in ("no-jacobians", "neither"):
                jn = eye
            else:
                jn = jax.vmap(lambda e: lin(e, zero_x, zero_theta), out_axes=1)(eye)
            if name in ("no-inputs", "neither"):
                return jn, jnp.zeros_like(y)
            return jn, lin(jnp.zeros_like(y), dx, dtheta)

        jacobians, inputs = _stepped._map(linear, (ys[:-1], xs, _stepped._float_only(dxs)), batch)
        _, dys = jax.lax.scan(lambda dy, ju: (ju[0] @ dy + ju[1],) * 2, dy0, (jacobians, inputs))
        return jnp.concatenate([dy0[None], dys])

    assert original is C.tangent_states
    C.tangent_states = tangent_states


def parts_row(name, which):
    _variant(name)
    ts = np.linspace(SPAN / 4, SPAN, 4)
    gyro = FREE if which == "free" else hg.presets.tvg3_like(noise=False)

    def loss(res, rate):
        g = eqx.tree_at(lambda g: g.resonator, gyro, res)
        prof = hg.Profile.constant_rate(rate, SPAN, wave_angle0_deg=10.0)
        return jnp.sum(hg.simulate(g, prof, "full", ts=ts, fixed_step=2e-5).wave_angle)

    fwd, grad = eqx.filter_jit(loss), eqx.filter_jit(eqx.filter_grad(loss))
    (tf, cf), (tg, cg) = timed(fwd, grad, (gyro.resonator, jnp.asarray(30.0)))
    print(f"  {which:5s} {name:16s} forward {tf * 1e3:6.1f} ms, gradient {tg * 1e3:6.1f} ms "
          f"({tg / tf:5.2f}×; compile {cf:.1f} / {cg:.1f} s)", flush=True)  # fmt: skip


def parts():
    import subprocess

    for which in ("free", "loops"):
        for name in PARTS:
            if name == "stages-unrolled" and which == "free":
                continue  # the free resonator's stages are written out already
            subprocess.run([sys.executable, __file__, "--part", name, which], check=True)


def main():
    if "--part" in sys.argv:
        i = sys.argv.index("--part")
        parts_row(sys.argv[i + 1], sys.argv[i + 2])
        return
    print(f"machine: {machine()}")
    if "--parts" in sys.argv:
        parts()
        return
    carrier_rows()
    bosh3_rows()


if __name__ == "__main__":
    main()
