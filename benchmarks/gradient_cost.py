"""Reverse-mode gradient of a loss through a simulation vs the forward simulation.

Loss: squared wave-angle error of 19 vmapped 5 °/s rotation runs (60 s, averaged model,
tvg3_like loops) against reference data, differentiated w.r.t. all resonator parameters.
Gradient is checked against a central finite difference before timing. Target ≤ 3×."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from _common import best_of, first_call, machine, report

import hrgjax as hg


def main():
    gyro = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    plan = hg.calibration.rotation_plan((20.0,), duration_s=60.0)
    ts = jnp.arange(0.0, 60.0 + 0.5, 1.0)
    profiles = plan.profiles()
    target = jax.vmap(lambda p: hg.simulate(gyro, p, ts=ts).wave_angle)(profiles) + 1e-4
    params, static = eqx.partition(gyro.resonator, eqx.is_inexact_array)

    def loss(params):
        res = eqx.combine(params, static)
        g = eqx.tree_at(lambda g: g.resonator, gyro, res)
        out = jax.vmap(lambda p: hg.simulate(g, p, ts=ts).wave_angle)(profiles)
        return jnp.mean((out - target) ** 2)

    fwd = jax.jit(loss)
    grad = jax.jit(jax.grad(loss))
    c_f, value = first_call(lambda: fwd(params))
    c_g, g = first_call(lambda: grad(params))
    h = 1e-9
    up = eqx.tree_at(lambda r: r.delta_inv_tau, params, params.delta_inv_tau + h)
    dn = eqx.tree_at(lambda r: r.delta_inv_tau, params, params.delta_inv_tau - h)
    fd = (fwd(up) - fwd(dn)) / (2 * h)
    rel = abs(float(g.delta_inv_tau) - float(fd)) / abs(float(fd))
    assert rel < 1e-3, rel
    t_f = best_of(lambda: fwd(params), 15)
    t_g = best_of(lambda: grad(params), 15)
    print(f"machine: {machine()}")
    print(
        f"loss over {plan.size} rotation runs × 60 s (averaged model, loops closed); "
        f"gradient w.r.t. {len(jax.tree_util.tree_leaves(params))} resonator parameters"
    )
    print(f"check: ∂loss/∂Δ(1/τ) reverse mode vs central difference, rel. diff {rel:.1e}")
    print(f"compile: forward {c_f:.1f} s, gradient {c_g:.1f} s")
    print(
        f"forward {t_f * 1e3:.1f} ms, gradient {t_g * 1e3:.1f} ms, ratio {t_g / t_f:.2f}× "
        f"(target ≤ 3×)"
    )
    assert np.isfinite(float(value))
    report(
        f"gradient of a {plan.size}-run × 60 s loss (8 parameters)",
        t_g * 1e3,
        "ms",
        "gradient / forward",
        t_g / t_f,
        "≤ 3×",
    )

    import diffrax

    print("other adjoints (gradient / forward):")
    for name, adjoint, steps in [
        ("RecursiveCheckpointAdjoint(16)", diffrax.RecursiveCheckpointAdjoint(16), None),
        ("BacksolveAdjoint", diffrax.BacksolveAdjoint(), None),
        ("DirectAdjoint (max_steps 1024)", diffrax.DirectAdjoint(), 1024),
    ]:

        def loss_a(params, adjoint=adjoint, steps=steps):
            res = eqx.combine(params, static)
            g = eqx.tree_at(lambda g: g.resonator, gyro, res)
            sim = lambda p: hg.simulate(g, p, ts=ts, adjoint=adjoint, max_steps=steps)
            return jnp.mean((jax.vmap(sim)(profiles).wave_angle - target) ** 2)

        grad_a = jax.jit(jax.grad(loss_a))
        jax.block_until_ready(grad_a(params))
        ratio = best_of(lambda g=grad_a: g(params), 5) / t_f
        print(f"  {name:32s} {ratio:.2f}×")
        report(f"gradient, {name}", ratio * t_f * 1e3, "ms", "gradient / forward", ratio)

    # Forward mode: 8 tangents pushed through the solve at once (jax.jacfwd with diffrax's
    # ForwardMode adjoint), checked against the reverse-mode gradient above. Each tangent
    # adds a step's arithmetic, so even with 8 parameters it measured slower than reverse.
    def loss_f(params):
        res = eqx.combine(params, static)
        g = eqx.tree_at(lambda g: g.resonator, gyro, res)
        sim = lambda p: hg.simulate(g, p, ts=ts, adjoint=diffrax.ForwardMode())
        return jnp.mean((jax.vmap(sim)(profiles).wave_angle - target) ** 2)

    jac = jax.jit(jax.jacfwd(loss_f))
    gf = jax.block_until_ready(jac(params))
    agree = max(
        abs(float(a) - float(b)) / max(abs(float(a)), 1e-300)
        for a, b in zip(jax.tree_util.tree_leaves(g), jax.tree_util.tree_leaves(gf), strict=True)
    )
    assert agree < 1e-6, agree
    ratio = best_of(lambda: jac(params), 5) / t_f
    name = "ForwardMode + jax.jacfwd"
    print(f"  {name:32s} {ratio:.2f}×  (equals reverse mode to {agree:.0e})")
    report(f"gradient, {name}", ratio * t_f * 1e3, "ms", "gradient / forward", ratio)


if __name__ == "__main__":
    main()
