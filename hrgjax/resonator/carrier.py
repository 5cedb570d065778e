r"""Fixed-step integration of the carrier-resolving model (`simulate(model="full")`'s
default where it meets `rtol`, or `fixed_step=…`), built for speed on long runs and large
batches.

Each step of length h is one step of Dormand–Prince 8(7) (its 8th-order solution, 13
stages, no error estimate) of the full model's equations:

- the profile gives the table's rate at each stage (linear over the step: exact, as the
  profile is piecewise linear and no step straddles a knot), the angular acceleration and
  the specific force; the temperature laws are evaluated at each step's midpoint
  temperature (held over the step: a relative error ≈ (h·d ln p/dt)²/24 for a parameter p,
  whatever the carrier frequency; interpolating the laws' values linearly over chunks of
  `CHUNK` steps instead, as before, was off by (t_chunk·d ln p/dt)²/8 — 1.8e-2 rad on the
  wave angle of a steep Δ(1/τ) law over 4 s at 40 Hz, where a chunk spans 0.5 s, 0.22 rad
  on tests/test_carrier.py's 1-s ramp);
- **loops closed** (`_step_continuous`): every stage demodulates its state and runs the
  loop laws (`carrier_rhs`, the adaptive solve's right-hand side), so the path differs from
  adaptive stepping of the same equations only by its truncation error (8th order in h) and
  meets `rtol` as adaptive stepping does (tests/test_carrier.py): on a gyro with a
  frequency split, excitation-phase error and pick-off mismatch, the pattern's drift rate
  within 1.5e-10 rad/s of a tight reference at 10 steps per cycle (adaptive Dopri8 at rtol
  1e-8: 1.9e-10);
- **free-running, or `fixed_step="held"`** (`_step`): the electronics sample the state at
  the step's start (demodulation, whole-angle estimates, loop laws: the electrode force
  $\mathbf u\cos\psi_r + \mathbf v\sin\psi_r$, the pump depth and phase, the PLL frequency
  ω_r and the integrators' rates), which then **hold over the step** — a digital controller
  updating at 1/h. The resonator and the reference phasor $(\cos\psi_r, \sin\psi_r)$
  advance together at the held ω_r, so the stages need no trigonometry and each is one
  fused kernel: 3–5× faster than the continuous step with the loops closed; ψ_r then advances
  by ω_r·h, the integrators by their held rates times h. Free-running (no efforts) this is
  exact. With the loops closed the held loops lag the continuous ones by h/2 and miss their
  response to the carrier-frequency ripple of the demodulated state: first order in h, a
  drift error of 1.4e-6 rad/s at 10 steps per cycle on the gyro above (0.3 °/h; 1.8e-7 with
  the efforts extrapolated linearly across the step, which made the recorded frequency 80×
  worse on a ramp and was not kept).

ψ_r is kept in [0, 2π).

Output times: the steps run between the output times and the profile's knots (no step
straddles a knot, where the rate's slope jumps); each such interval takes the same number of
equal steps (the longest interval over the requested step, rounded up to equal chunks), so a
uniform output grid is stepped uniformly. Reverse-mode gradients recompute each interval's
steps from its start (checkpointing by chunks of at most `CHUNK` steps), so memory grows
with the number of outputs, not of steps."""

from __future__ import annotations

import functools
import math

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import finite_number, is_concrete
from .._stepped import scan_states, tangent_states
from .averaged import sampled_input_rate
from .full import carrier_rhs, full_estimates, held_command, loop_efforts, mechanics
from .params import TemperatureLaw, evaluate_at
from .readout import wrap_half_pi

_TABLEAU = diffrax.Dopri8.tableau
_A = [np.asarray(a, dtype=float) for a in _TABLEAU.a_lower]
_C = np.asarray(_TABLEAU.c, dtype=float)
_B = np.asarray(_TABLEAU.b_sol, dtype=float)[: len(_A) + 1]
CHUNK = 256
"""Steps recomputed together in reverse mode (checkpoint granularity)."""
STORE_STEPS = 2**15
"""Runs of at most this many steps (all intervals; 0.65 s at 5 kHz and 10 steps per cycle)
take their derivatives from stored states (`hrgjax._stepped`); longer ones through the step
loop, checkpointed by chunks. Reverse mode keeps ≈ 6 kB a step free-running and ≈ 12 kB
with the loops closed (XLA's temporaries, `benchmarks/README.md`): ≈ 380 MB at the bound per
trajectory, times the batch under `vmap`."""
UNROLL = {"cpu": 1}
"""Steps per iteration of the compiled step loop, by JAX backend (default 1 for a backend
not named): on a GPU each loop iteration is a launch and a host round trip, so several
steps per iteration pay there (benchmarks/gpu_backend.py)."""
LOOPED_STAGES_STEPS = {"cpu": 2**17}
"""By JAX backend (0 for a backend not named: on a GPU each loop iteration is a launch, as
for `UNROLL`): runs with the loops closed of at most this many steps per trajectory (all
intervals; 2.6 s at 5 kHz and 10 steps per cycle) evaluate the 13 stages of each step in a
loop (`_rk_step_looped`), longer ones unrolled (`looped_stages`). On the default gyro (XLA's
default flags, 2 cores, `benchmarks/carrier_stages.py`, 2 750 steps) the loop's program
compiles about 2.5–3× faster (3.1–3.7 against 8.4–10.1 s; the first gradient through it
22–27 against 83–100 s) and runs ≈ 1.8× slower (six runs on a noisy machine: 170–212
against 74–137 ms; 16 trajectories under `vmap` 1.26–1.37×, the gradient 1.4–1.5×). One
trajectory's first call gains while it has fewer than ≈ 2–5·10⁵ steps (at the bound:
≤ ≈ 4.5 s more run time, ≈ 6 s of compiling saved). Under `vmap` the extra run time grows
with the batch and the saving does not (a batch gains below ≈ 3–4·10⁶ trajectory-steps).
For large batches, or many calls of one program with the compile cache on
(`hg.enable_cache`), set it to 0 before the call: it is a static argument of the
simulator's program, so each setting compiles and exports its own."""
STEPS_PER_CYCLE_AT_1E8 = 10.0
"""Steps per carrier cycle that match adaptive Dopri8 at rtol 1e-8 on the final state (the
8th-order error scales as (steps per cycle)⁻⁸; `steps_per_cycle`)."""


def steps_per_cycle(rtol: float) -> int:
    """Steps per carrier cycle whose error matches adaptive stepping at `rtol`:
    10 × (1e-8 / rtol)^(1/8), at least 6 (8 at rtol 1e-6, 18 at 1e-10)."""
    if finite_number("rtol", rtol, "a solver tolerance") <= 0:  # 0 divided by zero
        raise ValueError(f"rtol must be a positive number (a solver tolerance); got {rtol!r}")
    return max(6, math.ceil(STEPS_PER_CYCLE_AT_1E8 * (1e-8 / float(rtol)) ** 0.125 - 1e-9))


def _rk_step(f, w, h):
    """One step of the Dormand–Prince 8th-order solution (explicit, fixed h); `f(c, w)` with
    c the stage's fraction of the step."""
    ks = [f(0.0, w)]
    for a, c in zip(_A, _C, strict=True):
        inc = sum(float(a[j]) * ks[j] for j in range(a.size) if a[j] != 0.0)
        ks.append(f(float(c), w + h * inc))
    return w + h * sum(float(_B[j]) * ks[j] for j in range(len(ks)) if _B[j] != 0.0)


_STAGES = int(np.flatnonzero(_B)[-1]) + 1  # 13: the 14th stage has no weight in b_sol
_A_FULL = np.zeros((_STAGES, _STAGES))
for _s, _a in enumerate(_A[: _STAGES - 1], start=1):
    _A_FULL[_s, : _a.size] = _a
_C_FULL = np.concatenate([[0.0], _C[: _STAGES - 1]])


def _rk_step_looped(f, w, h):
    """`_rk_step` with the stages in a loop (`f(c, w)`, c traced): `f` is traced and
    compiled once, not 13 times (`LOOPED_STAGES_STEPS`)."""
    ks = jnp.zeros((_STAGES,) + w.shape, w.dtype).at[0].set(f(0.0, w))
    a, c = jnp.asarray(_A_FULL, w.dtype), jnp.asarray(_C_FULL, w.dtype)

    def stage(s, ks):
        inc = jnp.sum(a[s][:, None] * ks, axis=0)
        return ks.at[s].set(f(c[s], w + h * inc))

    ks = jax.lax.fori_loop(1, _STAGES, stage, ks)
    b = jnp.asarray(_B[:_STAGES], w.dtype)
    return w + h * jnp.sum(b[:, None] * ks, axis=0)


def _step(env, omega_scale, y, h, scheduled=False):
    """One held-loop step over h [s] from state y (8,) ((10,) in FTR mode) in the environment
    `env` = (gyro with its temperature laws evaluated, Ω [rad/s], Ω̇ [rad/s²] at the step's
    midpoint, the profile's command at the step's start, the commanded precession at its
    midpoint); `scheduled`: the profile switches the rebalance loop."""
    g, omega_in, omega_dot, command, rho_mid = env
    res = g.resonator
    eff = loop_efforts(g, omega_in, y, omega_scale, command)
    cp2, sp2 = jnp.cos(eff.pump_phase2), jnp.sin(eff.pump_phase2)
    psi = y[4]

    def field(c, w):  # w = (x, y, ẋ/ω_s, ẏ/ω_s, cos ψ_r, sin ψ_r); c: unused (all held)
        z, zdot = w[0:2], w[2:4] * omega_scale
        cos_r, sin_r = w[4], w[5]
        force = eff.u * cos_r + eff.v * sin_r
        pump = eff.pump * ((cos_r * cos_r - sin_r * sin_r) * cp2 - 2.0 * cos_r * sin_r * sp2)
        zddot = mechanics(res, omega_in, omega_dot, z, zdot, force, pump)  # P cos(2ψ + 2γ) z
        return jnp.concatenate(
            [zdot, zddot / omega_scale, jnp.stack([-sin_r, cos_r]) * eff.omega_r]
        )

    w = jnp.concatenate([y[0:4], jnp.stack([jnp.cos(psi), jnp.sin(psi)])])
    w = _rk_step(field, w, h)
    psi = jnp.remainder(psi + eff.omega_r * h, 2 * jnp.pi)
    n = eff.d_int.shape[0]
    out = jnp.concatenate([w[0:4], jnp.reshape(psi, (1,)), y[5 : 5 + n] + h * eff.d_int])
    if g.control.mode != "ftr":
        return out
    cmd = held_command(g, y, command)
    hold = y[-1] + h * rho_mid  # held: turned by the commanded precession (exact: ρ is linear)
    if scheduled:  # off: the held angle is the estimate at the step's end (sample and hold)
        read = full_estimates(g, jnp.concatenate([out, y[-1:]]), omega_scale, omega_in,
                              command=cmd).theta  # fmt: skip
        hold = cmd[2] * hold + (1.0 - cmd[2]) * (y[-1] + wrap_half_pi(read - y[-1]))
    return jnp.concatenate([out, jnp.reshape(hold, (1,))])


def _step_continuous(env, omega_scale, y, h, d_rate, scheduled=False, looped=False):
    """One step over h [s] of the full model's own right-hand side (`carrier_rhs`: the loops
    demodulate the state at every stage, as in the adaptive solve), Ω linear over the step
    (`d_rate` [rad/s]: its change over the step; exact for the piecewise-linear profile).
    In FTR mode under a schedule, while the rebalance loop is off the held angle is the
    estimate at the step's end (sample and hold: what the continuous hold tracks).
    `looped`: the stages in a loop (`_rk_step_looped`; the same arithmetic, summed in
    another order)."""
    g, omega_in, omega_dot, command, rho_mid = env
    angle0, rho0, on = command

    def field(c, w):
        rate = omega_in + (c - 0.5) * d_rate
        # the commanded precession is linear over the step (ρ piecewise linear, no knot
        # inside), its angle quadratic: both exact at the stage's time
        rho = rho0 + 2.0 * c * (rho_mid - rho0)
        angle = angle0 + c * h * (rho0 + c * (rho_mid - rho0))
        return carrier_rhs(g, rate, omega_dot, w, omega_scale, (angle, rho, on), False)

    out = (_rk_step_looped if looped else _rk_step)(field, y, h)
    out = out.at[4].set(jnp.remainder(out[4], 2 * jnp.pi))
    if g.control.mode != "ftr" or not scheduled:
        return out
    cmd = held_command(g, y, command)
    read = full_estimates(g, out, omega_scale, omega_in, command=cmd).theta
    hold = cmd[2] * out[-1] + (1.0 - cmd[2]) * (y[-1] + wrap_half_pi(read - y[-1]))
    return out.at[-1].set(hold)


def _has_laws(gyro) -> bool:
    is_law = lambda x: isinstance(x, TemperatureLaw)
    return any(is_law(x) for x in jax.tree_util.tree_leaves(gyro, is_leaf=is_law))


def _intervals(profile, ts) -> int:
    """Intervals the fixed-step path steps through: the outputs and the inner knots
    (`event_grid`)."""
    return ts.shape[0] + max(profile.t.shape[0] - 2, 0)


def looped_stages(gyro, profile, ts, steps: int, held: bool) -> bool:
    """Whether `carrier_solve` evaluates each step's stages in a loop (`LOOPED_STAGES_STEPS`,
    for the platform this call runs on: the CPU inside `jax.default_device(a CPU device)`,
    as an eager `hg.simulate` beside an accelerator). A static argument of the compiled
    program, so a change of the setting compiles (and exports) a program of its own."""
    if held or not gyro.control.enabled:
        return False  # the held step (`_step`) is small: its stages stay unrolled
    device = jax.config.jax_default_device
    if device is None:
        platform = jax.default_backend()
    else:
        platform = device if isinstance(device, str) else device.platform
    return steps * _intervals(profile, ts) <= LOOPED_STAGES_STEPS.get(platform, 0)


def carrier_solve(gyro, profile, y0, omega_scale, ts, steps: int, held: bool = False,
                  looped: bool = False):  # fmt: skip
    """States (len(ts), 8) ((len(ts), 10) in FTR mode) at the output times `ts` [s] (ts[0] ≥
    the profile's start), each interval of [`event_grid`][hrgjax.resonator.carrier.event_grid]
    (the first from the profile's start) in `steps` equal steps (`held`: the loops held over
    each step; `looped`: with the loops closed, the stages in a loop, `looped_stages`).
    Derivatives: from the stored states (`hrgjax._stepped`) for runs of at most
    `STORE_STEPS` steps, else through the step loop checkpointed by chunks. The step times
    are built from the knots: `simulate` passes times since the profile's first knot (at an
    epoch such as 1.7e9 s, float64's 2.4e-7 s read as a scale-factor error of ≈ −1e-5)."""
    if steps * _intervals(profile, ts) <= STORE_STEPS:
        return _stored(steps, held, looped, gyro, profile, y0, omega_scale, ts)
    return _streamed(gyro, profile, y0, omega_scale, ts, steps, held, looped)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1, 2))
def _stored(steps, held, looped, gyro, profile, y0, omega_scale, ts):
    return _streamed(gyro, profile, y0, omega_scale, ts, steps, held, looped)


@_stored.defjvp
def _stored_jvp(steps, held, looped, primals, tangents):
    gyro, profile, y0, omega_scale, ts = primals
    d_gyro, d_profile, dy0, d_scale, d_ts = tangents
    build = lambda g, p, s, t: _per_step(g, p, s, t, steps, held)  # noqa: E731
    (xs, theta, at), (dxs, d_theta, _) = jax.jvp(
        build, (gyro, profile, omega_scale, ts), (d_gyro, d_profile, d_scale, d_ts)
    )
    step = functools.partial(_flat_step, gyro.control.enabled and not held,
                             profile.rebalance is not None, looped)  # fmt: skip
    ys = scan_states(step, y0, xs, theta)
    dys = tangent_states(step, ys, xs, theta, dy0, dxs, d_theta)
    return ys[at], dys[at]


def _flat_step(continuous, scheduled, looped, y, x, theta):
    """One step of `_stored`'s flat layout: `x` = (gyro at the step or None, Ω, Ω̇, command,
    ρ at the midpoint, h, Ω's change over the step), `theta` = (ω_s, the gyro when it has no
    temperature laws). An empty interval's steps (h = 0) leave the state as it is."""
    g_n, omega_in, omega_dot, command, rho, h, d_rate = x
    omega_scale, g_fixed = theta
    env = (g_fixed if g_n is None else g_n, omega_in, omega_dot, command, rho)
    # h = 0 returns y itself (no step divides by h); a stand-in step would overflow, and its
    # inf would reach the reverse pass through the `where` (0 · inf)
    if continuous:
        y1 = _step_continuous(env, omega_scale, y, h, d_rate, scheduled, looped)
    else:
        y1 = _step(env, omega_scale, y, h, scheduled)
    return jnp.where(h > 0, y1, y)


def _per_step(gyro, profile, omega_scale, ts, steps: int, held: bool):
    """`_streamed`'s per-step environment for every step at once (the same expressions,
    vectorised): per-step inputs, shared inputs and the flat index of each output's state."""
    events = event_grid(profile.t, ts)
    starts = jnp.concatenate([profile.t[:1], events[:-1]])
    n_chunks = -(-steps // CHUNK)
    chunk = -(-steps // n_chunks)
    steps = n_chunks * chunk
    h = (events - starts) / steps  # (I,)
    k = jnp.arange(n_chunks)
    first = starts[:, None] + (k * chunk).astype(h.dtype)[None, :] * h[:, None]  # (I, C)
    fi = jnp.arange(chunk).astype(h.dtype)
    t1 = first[..., None] + (fi + 1.0)[None, None, :] * h[:, None, None]  # (I, C, K)
    t0 = first[..., None] + fi[None, None, :] * h[:, None, None]
    hh = jnp.broadcast_to(h[:, None, None], t1.shape).ravel()
    t0, t1 = t0.ravel(), t1.ravel()
    safe_h = jnp.where(hh > 0, hh, 1.0)
    kin = jax.vmap(profile.kinematics_at)
    angle0, rate0, accel0 = kin(t0)
    angle1, rate1, accel1 = kin(t1)
    laws = _has_laws(gyro)
    if laws:
        temp_at = jax.vmap(profile.temperature_at)
        temp0 = temp_at(first.ravel())[:, None]  # (I·C, 1) chunk starts
        d_temp = temp_at((first + chunk * h[:, None]).ravel())[:, None] - temp0
        temps = (temp0 + d_temp * ((fi + 0.5) / chunk)[None, :]).ravel()  # steps' midpoints
        g_n = jax.vmap(gyro.at)(temps)
        g_fixed = None
        rate_in = jax.vmap(sampled_input_rate, in_axes=(0, None, 0, 0, 0))
        g_arg = g_n
    else:
        g_n, g_fixed = None, gyro.at(profile.temperature[0])
        rate_in = jax.vmap(sampled_input_rate, in_axes=(None, None, 0, 0, 0))
        g_arg = g_fixed
    mean_rate = (angle1 - angle0) / safe_h
    accel = 0.5 * (accel0 + accel1)
    omega_in = rate_in(g_arg, profile, t1 - 0.5 * hh, mean_rate, accel)
    command = jax.vmap(profile.command_at)(t1 - hh)
    rho = jax.vmap(profile.precession_at)(t1 - 0.5 * hh)
    xs = (g_n, omega_in, (rate1 - rate0) / safe_h, command, rho, hh, rate1 - rate0)
    # each output: the state at the end of the last event at its time
    at = (jnp.searchsorted(events, ts, side="right") - 1 + 1) * steps
    return xs, (omega_scale, g_fixed), at


def _streamed(
    gyro, profile, y0, omega_scale, ts, steps: int, held: bool = False, looped: bool = False
):
    """`carrier_solve` through the step loop: intervals, chunks of ≤ `CHUNK` steps (the
    steps' midpoint temperatures linear over each), steps; reverse mode recomputes each chunk."""
    events = event_grid(profile.t, ts)
    starts = jnp.concatenate([profile.t[:1], events[:-1]])
    n_chunks = -(-steps // CHUNK)
    chunk = -(-steps // n_chunks)  # equal chunks of ≤ CHUNK steps, adding < n_chunks steps
    steps = n_chunks * chunk

    continuous = gyro.control.enabled and not held
    laws = _has_laws(gyro)
    scheduled = profile.rebalance is not None
    fixed_gyro = None if laws else gyro.at(profile.temperature[0])

    def run_chunk(carry, k):
        y, t, h = carry
        first = t + (k * chunk).astype(h.dtype) * h
        safe_h = jnp.where(h > 0, h, 1.0)  # an output at a knot leaves an empty interval
        if laws:  # each step's midpoint temperature: linear over the chunk (module notes)
            temp0 = profile.temperature_at(first)
            d_temp = profile.temperature_at(first + chunk * h) - temp0

        def one(i, carry):
            yy, angle0, rate0, accel0 = carry
            fi = i.astype(h.dtype)
            if laws:
                g = gyro.at(temp0 + d_temp * ((fi + 0.5) / chunk))
            else:
                g = fixed_gyro
            t1 = first + (fi + 1.0) * h
            angle1, rate1, accel1 = profile.kinematics_at(t1)
            # the table's mean rate, angular acceleration and specific force over the step
            # (exact for the piecewise-linear profile: no step straddles a knot)
            mean_rate = (angle1 - angle0) / safe_h
            accel = 0.5 * (accel0 + accel1)
            omega_in = sampled_input_rate(g, profile, t1 - 0.5 * h, mean_rate, accel)
            env = (g, omega_in, (rate1 - rate0) / safe_h, profile.command_at(t1 - h),
                   profile.precession_at(t1 - 0.5 * h))  # fmt: skip
            if continuous:
                yy = _step_continuous(env, omega_scale, yy, h, rate1 - rate0, scheduled, looped)
            else:
                yy = _step(env, omega_scale, yy, h, scheduled)
            return yy, angle1, rate1, accel1

        start = (y, *profile.kinematics_at(first))
        unroll = max(1, min(chunk, UNROLL.get(jax.default_backend(), 1)))
        y = jax.lax.fori_loop(0, chunk, one, start, unroll=unroll)[0]
        return (y, t, h), None

    run_chunk = jax.checkpoint(run_chunk)  # reverse mode: each chunk recomputed

    def interval(y, span):
        start, end = span
        h = (end - start) / steps

        def run(y):
            return jax.lax.scan(run_chunk, (y, start, h), jnp.arange(n_chunks))[0][0]

        # an empty interval (an output at the start or at a knot) takes no steps
        y = jax.lax.cond(end > start, run, lambda y: y, y)
        return y, y

    _, ys = jax.lax.scan(interval, y0, (starts, events))
    # each output: the last event at its time (an output that is also a knot appears twice,
    # the zero-length interval between them changes nothing)
    at = jnp.searchsorted(events, ts, side="right") - 1
    return ys[at]


def event_grid(knots, ts, xp=jnp):
    """The times the fixed-step path steps between: the output times and the profile's
    interior knots (clipped into [knots[0], ts[-1]]), sorted — so that no step straddles a
    knot, where the profile's rate has a kink and the fixed-step solution would lose its
    order. `xp` = `jnp` (traced, static shapes) or `np`."""
    inner = xp.clip(knots[1:-1], knots[0], ts[-1])
    return xp.sort(xp.concatenate([ts, inner]))


AUTO_RTOL_FLOOR = 1e-9
"""The tightest `rtol` for which `fixed_step="auto"` takes the fixed-step carrier path: the
range over which the path has been measured to match adaptive stepping (1e-6 … 1e-9 on a
closed-loop gyro with a frequency split, docs/resonator.md); tighter requests — references,
mostly — solve adaptively."""


def takes_fixed_steps(gyro, profile, ts, o) -> bool:
    """The rule of `fixed_step="auto"` for the full model (docs/resonator.md): fixed steps
    where they meet `rtol` and the step can be chosen before the solve — the default solver,
    adjoint and step budget (a user who names one of those asks diffrax for adaptive steps),
    `rtol` ≥ `AUTO_RTOL_FLOOR`, and concrete output times, knot times, resonator and
    `rtol` (inside `jit` or `hg.sweep`, built from Python numbers or NumPy arrays)."""
    if any(o[name] is not None for name in ("solver", "adjoint", "max_steps")):
        return False
    rtol = o["rtol"]
    if not is_concrete(rtol) or float(rtol) < AUTO_RTOL_FLOOR:
        return False
    leaves = [ts, profile.t, *jax.tree_util.tree_leaves(gyro.resonator)]
    return all(is_concrete(x) for x in leaves)


def steps_per_interval(gyro, profile, ts, fixed_step, rtol) -> int:
    """Steps per interval of the fixed-step carrier path (between outputs and the profile's
    knots, `event_grid`): the longest interval over `fixed_step` [s], or with "auto" and
    "held" over 2π / (ω_max · steps_per_cycle(rtol)), ω_max the highest carrier frequency
    over the profile's temperatures (needs concrete values), rounded up to the step ladder
    (`ladder_steps`: the count is static in the compiled program, so nearby frequencies,
    temperatures and output grids share one)."""
    traced = [n for n, x in (("ts", ts), ("the profile's knot times", profile.t))
              if not is_concrete(x)]  # fmt: skip
    if traced:
        raise ValueError(
            f"the fixed-step carrier path chooses its step count from the output times and the "
            f"profile's knot times, but {' and '.join(traced)} are traced here (inside jit or "
            "hg.sweep): build them outside the traced function (a NumPy array or Python "
            "numbers; Profile constructors keep Python durations concrete)"
        )
    ts_c = np.asarray(ts)
    knots = np.asarray(profile.t, dtype=float)
    spans = np.diff(np.concatenate([knots[:1], event_grid(knots, ts_c, xp=np)]))
    longest = float(spans.max())
    res = gyro.resonator
    known = all(is_concrete(x) for x in jax.tree_util.tree_leaves(res))
    if isinstance(fixed_step, str) and not known:  # "auto" or "held" (checked on entry)
        raise ValueError(
            f"fixed_step={fixed_step!r} reads the carrier frequency from the gyro, which is "
            "traced here (a sweep over resonator parameters): give fixed_step in seconds"
        )
    omega = None
    if known:
        if is_concrete(profile.temperature):
            t = np.asarray(profile.temperature, dtype=float).ravel()
        else:  # temperatures traced (a sweep over them): the range a gyro is specified for
            t = np.asarray(AUTO_STEP_TEMPERATURES_C)
        grid = np.linspace(t.min(), t.max(), 9)
        with jax.ensure_compile_time_eval():  # concrete values, also under jit
            # unchecked: this span may lie outside a range the user narrowed
            omega = np.max(np.abs([np.max(np.asarray(evaluate_at(res, x).omega)) for x in grid]))
    if isinstance(fixed_step, str):
        h = 2 * np.pi / (omega * steps_per_cycle(float(rtol)))
        return ladder_steps(math.ceil(longest / h - 1e-9))
    h = float(fixed_step)
    if omega is not None and 2 * np.pi / (omega * h) < MIN_STEPS_PER_CYCLE:
        raise ValueError(
            f"fixed_step = {h:g} s is {2 * np.pi / (omega * h):.3g} steps per carrier cycle "
            f"({omega / (2 * np.pi):g} Hz); the full model needs at least "
            f"{MIN_STEPS_PER_CYCLE} (fixed_step ≤ {2 * np.pi / (MIN_STEPS_PER_CYCLE * omega):.3g}"
            ' s; fixed_step="auto" picks the step for rtol)'
        )
    return max(1, math.ceil(longest / h - 1e-9))


LADDER_PER_OCTAVE = 4
"""Rungs per doubling of the step ladder of `fixed_step="auto"` and `"held"`
(`ladder_steps`)."""


def ladder_steps(n: int) -> int:
    """The smallest ⌈2^(k/4)⌉ ≥ `n` (k = 0, 1, …; 4 = `LADDER_PER_OCTAVE`): 1, 2, 3, 4, 5, 6,
    7, 8, 10, 12, 14, 16, 20, 23, 27, 32, … The step count of the chosen step is static in
    the compiled program: without the ladder every new carrier frequency or temperature
    (a loop over temperatures) compiled a program of its own (7–13 s each). At most
    2^(1/4) − 1 ≈ 19 % more steps than the step asks for, and more steps only reduce the
    error (8th order: at most 1.19⁻⁸ ≈ 0.25 of the rule's)."""
    n = max(1, int(n))
    k = max(0, math.floor(LADDER_PER_OCTAVE * math.log2(n)) - 2)
    while math.ceil(2 ** (k / LADDER_PER_OCTAVE) - 1e-9) < n:
        k += 1
    return math.ceil(2 ** (k / LADDER_PER_OCTAVE) - 1e-9)


MIN_STEPS_PER_CYCLE = 6
"""Fewest fixed steps per carrier cycle `simulate(model="full", fixed_step=h)` accepts (the
fewest `steps_per_cycle` chooses, at rtol ≥ 1e-6): coarser, Dopri8 damps and dephases the
carrier itself (2 steps a cycle lost 87 % of the amplitude in 0.02 s)."""


AUTO_STEP_TEMPERATURES_C = (-60.0, 100.0)
"""Temperatures [°C] whose highest carrier frequency sets `fixed_step="auto"` when the
profile's temperatures are traced (inside `hg.sweep` over temperature)."""
