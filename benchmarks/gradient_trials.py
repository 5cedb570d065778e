"""Three ways tried to cheapen the gradient of `gradient_cost.py`'s loss (19 rotation runs ×
60 s, 8 resonator parameters), none adopted — kept so that the figures in
benchmarks/README.md can be rerun:

1. **Parameters per member.** Under `vmap(lambda p: simulate(gyro, p))`, the shared gyro's
   cotangents must be summed over the batch; made per member before the solve (here: the
   parameters broadcast to the batch and vmapped with the profiles), the sums could move out
   of the step loop. Compared: the fusions (XLA:CPU kernels) in each compiled while-loop
   body, and gradient times, the variants interleaved.
2. **Tsit5 with its stages written out.** diffrax runs a Runge–Kutta step's stages in an
   inner checkpointed loop; `UnrolledTsit5` (below; diffrax's tableau and interpolation)
   writes the seven stages out. Compared: forward and gradient times against diffrax's.
3. **Parameters packed** (`--packed`, run alone): the gyro's inexact leaves passed into the
   solve as one vector and unpacked inside the vector field, so that a stage's parameter
   cotangents could leave as one array rather than a kernel per parameter. The solve is
   written here with diffrax (averaged model, Tsit5, the default adjoint), packed and not.

4. **The floor** (`--floor`, run alone): how fast could the gradient be with a perfect
   vector-field VJP? The same solve with the closed-loop vector field wrapped in a
   `jax.custom_vjp` whose backward pass is nearly free (cotangent `1e-3 · ct` for the state,
   `Σ ct` for one resonator leaf, nothing else: a wrong gradient, timed only), against plain autodiff;
   on the 19 × 60-s loss and on the 1-h warm-up run of `adjoint_memory.py` (one trajectory,
   temperature laws on). What is left is diffrax's: the forward, its recomputation in the
   reverse pass (recursive checkpointing re-runs each step to differentiate it) and the
   Runge–Kutta step's and the output interpolation's own VJPs. A hand-written VJP of the
   vector field cannot take the ratio below that.

Usage: `.venv/bin/python benchmarks/gradient_trials.py` (trials 1 and 2, ≈ 3 min on 2 cores);
`... gradient_trials.py --packed` (trial 3, ≈ 1 min); `... --floor` (trial 4, ≈ 2 min).
"""

import re
from typing import ClassVar

import diffrax
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.numpy as jnp
from _common import best_of, machine, report

import hrgjax as hg

_TABLEAU = diffrax.Tsit5.tableau
_A = tuple(tuple(float(x) for x in row) for row in _TABLEAU.a_lower)
_B = tuple(float(x) for x in _TABLEAU.b_sol)
_E = tuple(float(x) for x in _TABLEAU.b_error)
_C = tuple(float(x) for x in _TABLEAU.c)


def _combine(coeffs, ks, start=None):
    """start + Σ coeffs[i] · ks[i] over pytrees, skipping zero coefficients."""
    terms = [(c, k) for c, k in zip(coeffs, ks, strict=False) if c != 0.0]

    def leaf(s, *k):
        out = s
        for (c, _), x in zip(terms, k, strict=True):
            out = c * x if out is None else out + c * x
        return out

    if start is None:
        return jax.tree.map(lambda *k: leaf(None, *k), *[k for _, k in terms])
    return jax.tree.map(leaf, start, *[k for _, k in terms])


class UnrolledTsit5(diffrax.AbstractAdaptiveSolver):
    """Tsitouras' 5(4) Runge–Kutta pair, diffrax's `Tsit5` with the stages written out: a
    drop-in for `diffrax.Tsit5()` on ODE terms (same tableau, error estimate, FSAL handling and
    dense output; diffrax's public `Tsit5.tableau` and `Tsit5.interpolation_cls`)."""

    term_structure: ClassVar = diffrax.AbstractTerm
    interpolation_cls: ClassVar = diffrax.Tsit5.interpolation_cls

    def order(self, terms):
        return 5

    def init(self, terms, t0, t1, y0, args):
        return terms.vf(t0, y0, args)

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        # After a jump in the vector field (a profile knot) the last stage of the previous
        # step is stale: evaluate afresh, as diffrax's FSAL solvers do.
        f0 = jax.lax.cond(eqxi.unvmap_any(made_jump), lambda: terms.vf(t0, y0, args),
                          lambda: solver_state)  # fmt: skip
        dt = terms.contr(t0, t1)
        ks = [terms.prod(f0, dt)]
        for i, row in enumerate(_A[:-1]):  # the last row is b (FSAL): y1 below
            ks.append(terms.vf_prod(t0 + _C[i] * dt, _combine(row, ks, y0), args, dt))
        y1 = _combine(_B, ks, y0)
        f1 = terms.vf(t1, y1, args)
        ks.append(terms.prod(f1, dt))
        dense = dict(y0=y0, y1=y1, k=jax.tree.map(lambda *k: jnp.stack(k), *ks))
        return y1, _combine(_E, ks), dense, f1, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


def loop_fusions(compiled) -> list[int]:
    """Fusions in each while-loop body of a compiled program's HLO."""
    text = compiled.as_text()
    bodies = set(re.findall(r"body=%?([\w.\-]+)", text))
    out = []
    for comp in re.split(r"\n(?=\S.*\{\n)", text):
        if comp.split()[0].lstrip("%") in bodies:
            out.append(len(re.findall(r"=\s*\S+\s+fusion\(", comp)))
    return sorted(out)


def main():
    gyro = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    plan = hg.calibration.rotation_plan((20.0,), duration_s=60.0)
    ts = jnp.arange(0.0, 60.0 + 0.5, 1.0)
    profiles = plan.profiles()
    n = plan.size
    target = jax.vmap(lambda p: hg.simulate(gyro, p, ts=ts).wave_angle)(profiles) + 1e-4
    params, static = eqx.partition(gyro.resonator, eqx.is_inexact_array)

    def with_params(p):
        return eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(p, static))

    def loss(params, solver=None):
        g = with_params(params)
        out = jax.vmap(lambda p: hg.simulate(g, p, ts=ts, solver=solver).wave_angle)(profiles)
        return jnp.mean((out - target) ** 2)

    def loss_per_member(params):
        per = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n, *x.shape)), params)
        one = lambda q, p: hg.simulate(with_params(q), p, ts=ts).wave_angle  # noqa: E731
        return jnp.mean((jax.vmap(one)(per, profiles) - target) ** 2)

    print(f"machine: {machine()}")
    fwd = jax.jit(loss)
    grads = {"shared": jax.jit(jax.grad(loss)), "per member": jax.jit(jax.grad(loss_per_member))}
    g_ref = grads["shared"](params)
    for name, g in grads.items():
        diff = jax.tree_util.tree_map(lambda a, b: float(abs(a - b) / abs(a)), g(params), g_ref)
        fusions = loop_fusions(g.lower(params).compile())
        print(f"{name:10s}: fusions per while-loop body {fusions}; gradient vs shared, max rel. "
              f"diff {max(jax.tree_util.tree_leaves(diff)):.1e}")  # fmt: skip
    print("interleaved timings (best of 11 each), gradient / forward:")
    ratios = {name: [] for name in grads}
    for rep in range(3):
        t_f = best_of(lambda: fwd(params), 11)
        line = []
        for name, g in grads.items():
            t_g = best_of(lambda g=g: g(params), 11)
            ratios[name].append(t_g / t_f)
            line.append(f"{name} {t_g * 1e3:.1f} ms ({t_g / t_f:.2f}×)")
        print(f"  run {rep}: forward {t_f * 1e3:.1f} ms; " + "; ".join(line))
    for name, r in ratios.items():
        report(f"gradient / forward, parameters {name}", min(r), "×", "worst of 3 runs", max(r))

    fwd_u = jax.jit(lambda p: loss(p, UnrolledTsit5()))
    grad_u = jax.jit(jax.grad(lambda p: loss(p, UnrolledTsit5())))
    print(f"loss: diffrax Tsit5 {float(fwd(params)):.6e}, unrolled {float(fwd_u(params)):.6e}")
    print("interleaved timings (best of 11 each):")
    f_ratio, g_ratio = [], []
    for rep in range(3):
        tf0, tf1 = best_of(lambda: fwd(params), 11), best_of(lambda: fwd_u(params), 11)
        tg0 = best_of(lambda: grads["shared"](params), 11)
        tg1 = best_of(lambda: grad_u(params), 11)
        f_ratio.append(tf1 / tf0)
        g_ratio.append(tg1 / tg0)
        print(f"  run {rep}: forward {tf0 * 1e3:.1f} → {tf1 * 1e3:.1f} ms ({tf1 / tf0:.2f}×), "
              f"gradient {tg0 * 1e3:.1f} → {tg1 * 1e3:.1f} ms ({tg1 / tg0:.2f}×)")  # fmt: skip
    report("forward, Tsit5 stages written out", min(f_ratio), "×", "/ diffrax Tsit5, worst",
           max(f_ratio))  # fmt: skip
    report("gradient, Tsit5 stages written out", min(g_ratio), "×", "/ diffrax Tsit5, worst",
           max(g_ratio))  # fmt: skip


def packed():
    from jax.flatten_util import ravel_pytree

    from hrgjax.resonator.averaged import averaged_initial_state, averaged_vector_field

    gyro = hg.presets.tvg3_like(noise=False, temperature_laws=False)
    profiles = hg.calibration.rotation_plan((20.0,), duration_s=60.0).profiles()
    ts = jnp.arange(0.0, 60.0 + 0.5, 1.0)

    def solve(g, prof, pack):
        if pack:
            dyn, static = eqx.partition(g, eqx.is_inexact_array)
            flat, unravel = ravel_pytree(dyn)
            field = lambda t, y, a: averaged_vector_field(  # noqa: E731
                t, y, (eqx.combine(unravel(a[0]), static), a[1])
            )
            args = (flat, prof)
        else:
            field, args = averaged_vector_field, (g, prof)
        controller = diffrax.PIDController(rtol=1e-8, atol=1e-10)  # as simulate's
        if prof.t.shape[0] > 2:
            controller = diffrax.ClipStepSizeController(controller, jump_ts=prof.t[1:-1])
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field), diffrax.Tsit5(), prof.t[0], prof.t[-1], 1e-2,
            averaged_initial_state(g, prof, 0.0), args=args, saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=controller, max_steps=2**16,
            adjoint=diffrax.RecursiveCheckpointAdjoint(256),
        )  # fmt: skip
        return sol.ys[:, 2]

    target = jax.vmap(lambda p: solve(gyro, p, False))(profiles) + 1e-4
    params, static = eqx.partition(gyro.resonator, eqx.is_inexact_array)

    def loss(params, pack):
        g = eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(params, static))
        return jnp.mean((jax.vmap(lambda p: solve(g, p, pack))(profiles) - target) ** 2)

    print(f"machine: {machine()}")
    fns = {}
    for pack in (False, True):
        fns[pack] = (jax.jit(lambda p, pack=pack: loss(p, pack)),
                     jax.jit(jax.grad(lambda p, pack=pack: loss(p, pack))))  # fmt: skip
    g0, g1 = (ravel_pytree(fns[pack][1](params))[0] for pack in (False, True))
    print(
        f"gradients packed vs not: max rel. diff {float(jnp.max(jnp.abs(g1 - g0) / jnp.abs(g0))):.1e}"
    )
    ratios = {False: [], True: []}
    for rep in range(3):  # interleaved
        for pack, (f, g) in fns.items():
            t_f, t_g = best_of(lambda f=f: f(params), 11), best_of(lambda g=g: g(params), 11)
            ratios[pack].append(t_g / t_f)
            print(f"  run {rep}, {'packed' if pack else 'as leaves'}: forward {t_f * 1e3:.1f} ms, "
                  f"gradient {t_g * 1e3:.1f} ms ({t_g / t_f:.2f}×)")  # fmt: skip
    for pack, r in ratios.items():
        name = "packed" if pack else "as leaves"
        report(f"gradient / forward, parameters {name}", min(r), "×", "worst of 3 runs", max(r))


def _free_vjp_field():
    """The averaged vector field with a nearly free, deliberately wrong VJP (trial 4)."""
    from hrgjax.resonator.averaged import averaged_vector_field

    @jax.custom_vjp
    def core(t, y, k, args):
        return averaged_vector_field(t, y, args)

    def fwd(t, y, k, args):
        return averaged_vector_field(t, y, args), k

    def bwd(k, ct):
        return None, 1e-3 * ct, jnp.sum(ct) + 0.0 * k, None

    core.defvjp(fwd, bwd)

    def field(t, y, args):
        gyro, prof = args
        k = jax.tree.leaves(gyro.resonator)[0]  # the one leaf given a (wrong) cotangent
        return core(t, y, k, (jax.lax.stop_gradient(gyro), prof))

    return field


def floor():
    from hrgjax.resonator.averaged import averaged_initial_state, averaged_vector_field

    def solve(g, prof, ts, free):
        field = _free_vjp_field() if free else averaged_vector_field
        controller = diffrax.PIDController(rtol=1e-8, atol=1e-10)  # as simulate's
        if prof.t.shape[0] > 2:
            controller = diffrax.ClipStepSizeController(controller, jump_ts=prof.t[1:-1])
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field), diffrax.Tsit5(), prof.t[0], prof.t[-1], 1e-2,
            averaged_initial_state(g, prof, 0.0), args=(g, prof), saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=controller, max_steps=2**16,
            adjoint=diffrax.RecursiveCheckpointAdjoint(256),
        )  # fmt: skip
        return sol.ys[:, 2]

    cases = {
        "19 runs × 60 s (gradient_cost.py)": (
            hg.presets.tvg3_like(noise=False, temperature_laws=False),
            hg.calibration.rotation_plan((20.0,), duration_s=60.0).profiles(),
            jnp.arange(0.0, 60.0 + 0.5, 1.0),
        ),
        "1-h warm-up, one run (adjoint_memory.py)": (
            hg.presets.tvg3_like(noise=False),
            jax.tree.map(lambda x: x[None], hg.Profile.piecewise([0.0, 3600.0], [5.0, 5.0],
                                                                 [-40.0, 20.0])),
            jnp.arange(0.0, 3600.0 + 0.5, 1.0),
        ),
    }  # fmt: skip
    print(f"machine: {machine()}")
    for name, (gyro, profiles, ts) in cases.items():
        params, static = eqx.partition(gyro.resonator, eqx.is_inexact_array)

        def loss(params, free, gyro=gyro, static=static, profiles=profiles, ts=ts):
            g = eqx.tree_at(lambda g: g.resonator, gyro, eqx.combine(params, static))
            return jnp.mean(jax.vmap(lambda p: solve(g, p, ts, free))(profiles) ** 2)

        fns = {
            free: (jax.jit(lambda p, free=free: loss(p, free)),
                   jax.jit(jax.grad(lambda p, free=free: loss(p, free))))
            for free in (False, True)
        }  # fmt: skip
        for f, g in fns.values():
            jax.block_until_ready((f(params), g(params)))
        ratios = {False: [], True: []}
        print(name)
        for rep in range(3):  # interleaved
            for free, (f, g) in fns.items():
                t_f, t_g = (
                    best_of(lambda f=f, p=params: f(p), 11),
                    best_of(lambda g=g, p=params: g(p), 11),
                )
                ratios[free].append(t_g / t_f)
                label = "free vector-field VJP" if free else "autodiff (as simulate)"
                print(f"  run {rep}, {label:22s}: forward {t_f * 1e3:6.1f} ms, "
                      f"gradient {t_g * 1e3:6.1f} ms ({t_g / t_f:.2f}×)")  # fmt: skip
        for free, r in ratios.items():
            label = "free vector-field VJP" if free else "autodiff"
            report(f"{name}: gradient / forward, {label}", min(r), "×", "worst of 3 runs", max(r))


if __name__ == "__main__":
    import sys

    if "--packed" in sys.argv:
        packed()
    elif "--floor" in sys.argv:
        floor()
    else:
        main()
