"""`simulate`: drive a gyro with a profile and read what the electronics would read."""

from __future__ import annotations

import contextlib
import inspect
import sys
import types

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import _solve_parts as parts
from . import plausible
from ._checks import is_concrete, traceable
from ._compiled import (
    Check,
    Unchecked,
    device,
    fused,
    one_line_failures,
    program,
    single_run_entry,
)
from ._cost import MAX_STEPS as MAX_STEPS
from ._cost import default_max_steps as default_max_steps
from ._cost import report as report_cost
from ._run_checks import LAW_LIMITS as _LAW_LIMITS  # its old name here
from ._run_checks import check_bandwidths, check_traced
from ._run_checks import check_laws as _check_laws
from ._simulate_options import check_options, check_quadrature0, forward_mode_hint, output_grid
from ._x64 import require_x64
from .gyro import Gyro, check_one
from .noise import draw_run_bias, rate_noise_angle
from .profiles import Profile
from .record import Record, warn_saturated
from .record import SaturationWarning as SaturationWarning
from .resonator.averaged import (
    averaged_problem,
    canonical_angle,
    held_angle,
    input_rate,
    measured_estimates,
    pattern_forces,
)
from .resonator.carrier import (
    AUTO_RTOL_FLOOR as AUTO_RTOL_FLOOR,  # the rule's floor, documented here
)
from .resonator.carrier import AUTO_STEP_TEMPERATURES_C as AUTO_STEP_TEMPERATURES_C
from .resonator.carrier import (
    carrier_solve,
    looped_stages,
    steps_per_interval,
    takes_fixed_steps,
)
from .resonator.control import (
    IDEAL_LIMIT,
    drive_vectors,
    ftr_rate,
    loop_outputs,
    max_step,
    steady_integrators,
)
from .resonator.full import full_estimates, full_initial_state, full_vector_field, held_command
from .resonator.readout import continue_angle, wrap_half_pi

MODELS = ("averaged", "full")
AVERAGED_CHECKPOINTS = 256


def _default_solver(model):
    return diffrax.Tsit5() if model == "averaged" else diffrax.Dopri8()


def output_times(profile: Profile, dt_out: float):
    """Output grid t[0], t[0] + dt_out, … to the profile's end (inclusive to the knots' float64
    resolution, else its last whole multiple of `dt_out`: pass `ts=` to have the end). Refused:
    a `dt_out` longer than the profile, or below twice the knots' resolution."""
    if not is_concrete(profile.t):
        raise ValueError(
            "simulate needs concrete profile knot times to build its output grid from dt_out, "
            "but they are traced values here: an outer jax.jit (hg.sweep jits too) or a vmap "
            "over the profile's times makes them abstract (jax.vmap over temperature or rate "
            "alone does not). Build the profile's times from Python numbers, or pass the "
            "output times explicitly with ts=."
        )
    t = np.asarray(profile.t)
    if not _is_number(dt_out) or not (np.isfinite(dt_out) and dt_out > 0):
        raise ValueError(f"dt_out must be a positive number of seconds; got {dt_out!r}")
    span = float(t[-1] - t[0])
    if dt_out > span * (1 + 1e-9):
        raise ValueError(
            f"dt_out = {dt_out:g} s is longer than the profile ({span:g} s): the output would "
            "be its start alone; give dt_out ≤ the profile's length, or ts= (output times)"
        )
    ulp = np.spacing(np.abs(t[[0, -1]]))  # the knots' float64 resolution (an epoch's: 2.4e-7 s)
    if dt_out < 2 * ulp.max():
        raise ValueError(f"dt_out = {dt_out:g} s is finer than the profile's times resolve "
                         f"({ulp.max():.2g} s): shift them to start near 0")  # fmt: skip
    slack = 1e-9 + min(0.5 * ulp.sum() / dt_out, 0.25)  # the span's own rounding, at most
    n = int(np.floor(span / dt_out + slack)) + 1
    if n > plausible.MAX_OUTPUT_SAMPLES:
        peak = plausible.PEAK_BYTES_PER_SAMPLE
        raise ValueError(f"dt_out={dt_out:g} s on a {span:g}-s profile gives {n:.3g} output samples, more "
                         f"than the {plausible.MAX_OUTPUT_SAMPLES:.0e} hrgjax allocates at once (≈ {peak} "
                         f"bytes each at the run's peak, ≈ {n * peak / 2**30:.3g} GiB); choose a larger "
                         "dt_out or split the profile into runs")  # fmt: skip
    with jax.ensure_compile_time_eval():  # concrete under jit too: the fixed-step path counts on it
        return device(np.minimum(t[0] + dt_out * np.arange(n), t[-1]))  # no rounding past the end


class _Module(types.ModuleType):
    """`MAX_OUTPUT_SAMPLES` moved to [`hrgjax.plausible`][hrgjax.plausible.MAX_OUTPUT_SAMPLES]
    (issue 45): reading or setting `hrgjax.simulate.MAX_OUTPUT_SAMPLES` reads or sets it there."""

    @property
    def MAX_OUTPUT_SAMPLES(self) -> int:
        return plausible.MAX_OUTPUT_SAMPLES

    @MAX_OUTPUT_SAMPLES.setter
    def MAX_OUTPUT_SAMPLES(self, value: int) -> None:
        plausible.MAX_OUTPUT_SAMPLES = value


sys.modules[__name__].__class__ = _Module


def _is_number(x) -> bool:
    """A concrete real scalar (Python, NumPy or jax), not a bool."""
    if isinstance(x, bool) or not is_concrete(x) or np.ndim(x) != 0:
        return False
    return np.asarray(x).dtype.kind in "iuf"


class _SimulateCheck(Check):
    """`Check` that also says where a failed or non-finite simulation stopped: the first
    output time whose sample is not finite (a vmapped batch: the first failing member)."""

    def host(self, out):
        message = super().host(out)
        if message is None:
            return None
        rec = out[0]
        t = np.asarray(rec.t)
        bad = np.zeros(t.shape, bool)
        for x in (rec.wave_angle, rec.amplitude, rec.quadrature, rec.true_wave_angle):
            bad |= ~np.isfinite(np.asarray(x))
        if bad.any():
            at = tuple(int(i) for i in np.argwhere(bad)[0])
            member = f" (batch member {at[:-1]})" if len(at) > 1 else ""
            message = message.rstrip(". ") + (
                f" (the outputs stop being finite at t = {t[at]:.6g} s{member}, "
                f"sample {at[-1]} of {t.shape[-1]})"
            )
        return message


@program(check=_SimulateCheck("simulate", result_index=2), single_run=True)
def _solve(model, gyro, profile, ts, solver, rtol, atol, max_steps, dt0, fixed, quadrature0,
           adjoint, key=None, bias_key=None, run=0, t_out=None, carrier=None):  # fmt: skip
    """`simulate` after its input checks as one program (times since the profile's start,
    `_from_start`; `t_out`: the record's): the solve, readout, noise and record. Returns
    (Record, accepted steps, solver result); a failure or a NaN record raises (`Check`)."""
    y0, field, args, extra = _problem(model, gyro, profile, quadrature0)
    if carrier is not None:  # the fixed-step carrier path (resonator/carrier.py)
        carrier_steps, held, looped = carrier
        ys = carrier_solve(gyro, profile, y0, extra, ts, carrier_steps, held, looped)
        read = _read_full(gyro, profile, ts, ys, extra)
        rec = _record(gyro, profile, ts, read, key, bias_key, run, t_out)
        steps = jnp.asarray(carrier_steps * ts.shape[0])
        return rec, steps, diffrax.RESULTS.successful
    controller = _controller(model, gyro, profile, rtol, atol, fixed)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        solver,
        t0=profile.t[0],
        t1=profile.t[-1],
        dt0=dt0,
        y0=y0,
        args=args,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=controller,
        max_steps=max_steps,
        adjoint=adjoint,
        throw=False,
    )
    read = _readout(model, gyro, profile, ts, sol.ys, extra)
    rec = _record(gyro, profile, ts, read, key, bias_key, run, t_out)
    return rec, sol.stats["num_steps"], sol.result


def _controller(model, gyro, profile, rtol, atol, fixed):
    """The step-size controller of `_solve`'s adaptive (or constant) steps."""
    controller = diffrax.ConstantStepSize()
    if not fixed:  # the loops' time constants bound the step (`max_step`)
        dtmax = max_step(gyro.control, model, profile.temperature)
        controller = diffrax.PIDController(rtol=rtol, atol=atol, dtmax=dtmax)
    if profile.t.shape[0] > 2 and not fixed:
        controller = diffrax.ClipStepSizeController(controller, jump_ts=profile.t[1:-1])
    return controller


def _readout(model, gyro, profile, ts, ys, states_or_scale):
    """What the electronics read from the solved states `ys` at `ts` (`_record`'s `read`)."""
    if model == "averaged":
        return _read_averaged(gyro, profile, ts, states_or_scale(ts, ys))
    return _read_full(gyro, profile, ts, ys, states_or_scale)


@program(check=Unchecked(), single_run=True)
def _part(model, gyro, profile, solver, rtol, atol, dt0, fixed, quadrature0, adjoint, *part):
    """One part (window, stop, resume, steps) of `_solve`'s solve (`_solve_parts.solve_part`)."""
    y0, field, args, _ = _problem(model, gyro, profile, quadrature0)
    controller = _controller(model, gyro, profile, rtol, atol, fixed)
    return parts.solve_part(diffrax.ODETerm(field), solver, controller, profile.t[0],
                            profile.t[-1], dt0, y0, args, adjoint, *part)  # fmt: skip


@program(check=Unchecked(), single_run=True)
def _finish(model, gyro, profile, ts, ys, quadrature0, key, bias_key, run, t_out):
    """`_solve`'s record from the states `ys` at `ts` solved in parts."""
    read = _readout(model, gyro, profile, ts, ys, _problem(model, gyro, profile, quadrature0)[3])
    return _record(gyro, profile, ts, read, key, bias_key, run, t_out)


def _problem(model, gyro, profile, quadrature0):
    """`_solve`'s y0, field, args, `_readout`'s states map (averaged: a residual) or ω scale."""
    if model == "averaged":
        y0, field, states = averaged_problem(gyro, profile, quadrature0)
        return y0, field, (gyro, profile), states
    y0, omega_scale = full_initial_state(gyro, profile, quadrature0)
    return y0, full_vector_field, (gyro, profile, omega_scale), omega_scale


def _solve_in_parts(model, gyro, profile, ts, solver, rtol, atol, max_steps, dt0, fixed,
                    quadrature0, adjoint, key, bias_key, run, t_out):  # fmt: skip
    """`_solve` of a long eager run: the same results, its solve in parts behind a bar."""
    part = (model, gyro, profile, solver, rtol, atol, dt0, fixed, quadrature0, adjoint)
    rest = (quadrature0, key, bias_key, run, t_out)
    rec, steps, result = parts.run_parts(lambda *a: _part(*part, *a), ts, profile.t, max_steps,
                                         lambda y: _finish(*part[:3], ts, device(y), *rest))  # fmt: skip
    out = (rec, device(np.asarray(steps, np.int64)), result)
    if message := _SimulateCheck("simulate", result_index=2).host(out):
        raise RuntimeError(message)
    return out


@fused
def _switch_on_key(key):
    """The switch-on key when no `bias_key` is given: the 4th of `_record`'s split of `key`."""
    return jax.random.split(key, 4)[3]


def _record(gyro, profile, ts, read, key, bias_key, run, t_out=None):
    """The Record (times `t_out`, default `ts`) of a solve at `ts` (since the profile's start):
    readout estimates plus the gyro's noise (when it has any)."""
    est, true_theta, loops, rebalance_rate = read
    theta = est.theta
    amplitude, quadrature = est.amplitude, est.quadrature

    def local(t, th):  # k_e; dθ̂/dθ, through which the rate noise's motion of the wave reads
        g = gyro.at(profile.temperature_at(t))
        return g.resonator.k_e, g.readout.angle_slope(th)

    k_e, slope = jax.vmap(local)(ts, true_theta)
    if gyro.noise is not None:
        k_rate, k_white, k_amp, _ = jax.random.split(key, 4)  # 4th: `_switch_on_key`'s
        nz = gyro.noise
        # from the switch-on (the profile's start), not the first output: a window late in
        # a run carries the noise and the bias's angle of the time before it
        start = profile.t[0]
        rate_angle = (rate_noise_angle(k_rate, ts, nz, start)
                      + draw_run_bias(bias_key, nz) * (ts - start))  # fmt: skip
        white = nz.angle_white * jax.random.normal(k_white, ts.shape)
        if rebalance_rate is None:
            theta = theta - k_e * slope * rate_angle + white
        elif ts.shape[0] > 1:  # FTR: while held, the rate noise is on the rate read out (the
            # mean rate of each output interval; the first sample: the first interval's);
            # where a schedule runs whole-angle it moves the wave, which is caught there.
            # The loop nulls the angle it reads, readout noise and all: the wave moves by
            # minus that noise, and the force that moves it reads as the rate −Δw/(k_e Δt)
            # (the rate a whole-angle reading of the same noise gives; a loop faster than the
            # output rate)
            on = (jnp.ones_like(ts) if profile.rebalance is None
                  else jax.vmap(profile.rebalance_at)(ts))  # fmt: skip
            inc = jnp.diff(rate_angle) - jnp.diff(white) / (0.5 * (k_e[1:] + k_e[:-1]))
            free = jnp.concatenate(
                [jnp.zeros(1), jnp.cumsum((1.0 - on[:-1]) * jnp.diff(rate_angle))]
            )
            held = on[:-1] * inc / jnp.diff(ts)
            rebalance_rate = rebalance_rate + jnp.concatenate([held[:1], held])
            theta = theta - k_e * slope * free + white
        else:
            theta = theta + white
        amp_noise = nz.amplitude_white * gyro.control.amplitude
        ka, kq = jax.random.split(k_amp)
        amplitude = amplitude + amp_noise * jax.random.normal(ka, ts.shape)
        quadrature = quadrature + amp_noise * jax.random.normal(kq, ts.shape)

    return Record(
        t=ts if t_out is None else t_out,
        wave_angle=theta,
        amplitude=amplitude,
        quadrature=quadrature,
        table_angle=jax.vmap(profile.table_angle_at)(ts),
        table_rate=jax.vmap(profile.rate_at)(ts),
        temperature=jax.vmap(profile.temperature_at)(ts),
        accel=jax.vmap(profile.accel_at)(ts),
        true_wave_angle=true_theta,
        frequency=loops.omega_r,
        drive=loops.force if gyro.control.drive == "force" else loops.pump,
        quadrature_force=loops.quad_force,
        k_e=k_e,
        run=run,
        rebalance_rate=rebalance_rate,
        rebalance_on=None if profile.rebalance is None else jax.vmap(profile.rebalance_at)(ts),
        rebalance_saturated=_saturated(gyro, profile, ts, loops),
        precession=None if profile.precession is None else jax.vmap(profile.precession_at)(ts),
        mode=gyro.control.mode,
    )


def _saturated(gyro, profile, ts, loops):
    """1.0 where the rebalance force sat at `Control.rebalance_limit` (at that sample's
    temperature; 1e-12 for the law's rounding), else 0.0; `None` without a limit."""
    if gyro.control.mode != "ftr" or gyro.control.rebalance_limit is None:
        return None
    limit = jax.vmap(lambda t: gyro.at(profile.temperature_at(t)).control.rebalance_limit)(ts)
    return (jnp.abs(loops.rebalance) >= limit * (1.0 - 1e-12)).astype(float)


def _read_averaged(gyro, profile, ts, ys):
    def one(t, y):
        g = gyro.at(profile.temperature_at(t))
        ctl, res = g.control, g.resonator
        command = profile.command_at(t)
        if ctl.ideal and ctl.mode == "ftr":
            est, true_theta, loops = _ideal_ftr(g, input_rate(g, profile, t), y[0], command)
        elif ctl.ideal:
            a0 = ctl.amplitude
            est = measured_estimates(g, a0, 0.0 * a0, y[0], 0.0 * a0)
            integ = steady_integrators(ctl, res, a0, y[0])
            true_theta = y[0]
            loops = loop_outputs(ctl, res.omega, est, integ, command)
        else:
            est = measured_estimates(g, y[0], y[1], y[2], y[3])
            true_theta = canonical_angle(y[0], y[1], y[2])  # the antinode, as the full model
            if ctl.mode == "ftr":  # the held angle is the state's
                command = (y[8], command[1], command[2])
            loops = loop_outputs(ctl, res.omega, est, y[4:], command)
        return est, true_theta, loops

    est, true_theta, loops = jax.vmap(one)(ts, ys)
    ftr = ftr_rate(gyro.control, loops, est) if gyro.control.mode == "ftr" else None  # FTR's output
    return est, true_theta, loops, ftr


def _ideal_ftr(g, omega_in, theta_cmd, command):
    """Ideal loops in FTR mode: the wave held exactly where the estimate reads the commanded
    angle (`held_angle`), a = a₀, q = 0, and the rebalance force that holds it there through
    the forcers' own gain and angle: (estimates, true angle, loop outputs)."""
    ctl, res = g.control, g.resonator
    a0 = ctl.amplitude
    theta = held_angle(g, a0, theta_cmd)
    est = measured_estimates(g, a0, 0.0 * a0, theta, 0.0 * a0)
    loops = loop_outputs(ctl, res.omega, est, steady_integrators(ctl, res, a0, theta), command)
    unit = eqx.tree_at(lambda lo: (lo.force, lo.quad_force, lo.rebalance, lo.precession_force),
                       loops, (0.0 * a0, 0.0 * a0, 1.0 + 0.0 * a0, 0.0 * a0))  # fmt: skip
    node_gain = pattern_forces(*drive_vectors(ctl, unit, est.theta), 0.0 * a0, theta)[3]
    drift = 0.5 * res.delta_inv_tau * jnp.sin(2 * (theta - res.theta_tau))
    held = 2.0 * res.omega * a0 * (drift - res.k_e * omega_in) / node_gain
    return est, theta, eqx.tree_at(lambda lo: lo.rebalance, loops, held)


def _read_full(gyro, profile, ts, ys, omega_scale):
    def one(t, y):
        g = gyro.at(profile.temperature_at(t))
        omega_in = input_rate(g, profile, t)
        command = held_command(g, y, profile.command_at(t))
        est = full_estimates(g, y, omega_scale, omega_in, command=command)
        true = full_estimates(g, y, omega_scale, omega_in, readout=False, command=command)
        loops = loop_outputs(g.control, g.resonator.omega, est, y[5:], command)
        cmd = command[0] if g.control.enabled else 0.0 * t  # no loops: no precession
        turn = (g.resonator.k_e, g.rate_bias, profile.table_angle_at(t), cmd, y[-1])
        return est, true.theta, loops, turn

    est, true_theta, loops, (k_e, bias, table, cmd, hold) = jax.vmap(one)(ts, ys)
    if gyro.control.mode == "ftr":  # held at θ_hold (a state; while off, it follows θ̂)
        true_theta = hold + wrap_half_pi(true_theta - hold)
    else:  # θ mod π, continued along the turn the table and the precession command expect
        mean = lambda x: 0.5 * (x[1:] + x[:-1])  # noqa: E731
        turn = jnp.diff(cmd) - mean(k_e) * (jnp.diff(table) + mean(bias) * jnp.diff(ts))
        true_theta = continue_angle(true_theta, profile.wave_angle0, turn)
    est = eqx.tree_at(lambda e: e.theta, est, true_theta + wrap_half_pi(est.theta - true_theta))
    ftr = ftr_rate(gyro.control, loops, est) if gyro.control.mode == "ftr" else None  # FTR's output
    return est, true_theta, loops, ftr


def simulate(
    gyro: Gyro,
    profile: Profile,
    model: str = "averaged",
    *,
    key: jax.Array | None = None,
    bias_key: jax.Array | None = None,
    dt_out: float = 0.1,
    ts=None,
    rtol: float = 1e-8,
    atol: float = 1e-10,
    max_steps: int | None = None,
    solver: diffrax.AbstractSolver | None = None,
    fixed_step: float | str | None = "auto",
    quadrature0: float = 0.0,
    adjoint: diffrax.AbstractAdjoint | None = None,
    run: int = 0,
) -> Record:
    """Simulate a whole-angle HRG driven by a profile.

    **Arguments:**

    - `gyro`: the [`hrgjax.Gyro`][] (e.g. `hg.presets.tvg3_like()`).
    - `profile`: the [`hrgjax.Profile`][] of rate, temperature and specific force.
    - `model`: `"averaged"` (slow variables, PHYSICS.md §3; long runs and fits) or `"full"`
      (carrier-resolving, PHYSICS.md §2; short windows).
    - `key`: PRNG key; required when `gyro.noise` is not `None`. Deterministic for a key. The
      rate noise moves the wave: its angle reads through `Readout.angle_slope`.
    - `bias_key`: key of the switch-on bias; give the same one to several runs to simulate
      segments of one switch-on (defaults to a split of `key`).
    - `dt_out`: output interval [s], at most the profile's length (the grid ends at the last
      whole multiple of it: `hrgjax.simulate.output_times`); or `ts`,
      explicit output times [s] within the profile.
    - `rtol`, `atol`, `max_steps`, `solver`: diffrax settings (Tsit5 for averaged, Dopri8 for
      full by default; `max_steps` by default follows the run's expected steps,
      `hrgjax.simulate.default_max_steps`).
    - `fixed_step`: `"auto"` (default) lets hrgjax choose the fastest path that meets
      `rtol`: for `model="full"` the fixed-step carrier path (`hrgjax.resonator.carrier`:
      Dormand–Prince 8 on equal steps, the loops at every stage, no error control; at the
      same accuracy 1.9× faster than adaptive stepping with the loops closed and 422× a
      minimal scipy RK45 script on a free resonator, docs/resonator.md) with the step
      chosen from `rtol` and the highest carrier frequency over the profile's temperatures
      (10 steps per cycle at rtol 1e-8, the count rounded up to a ladder of ratio 2^(1/4):
      nearby values share a program; over −60 … 100 °C when those are traced) — wherever
      `rtol` ≥ 1e-9, no `solver`, `adjoint` or `max_steps` is given, and the output times,
      the profile's knot times and the resonator are concrete; otherwise, and for the
      averaged model, adaptive steps. `None`: adaptive steps always. A number: this
      constant step [s] (for the full model with the default solver, the carrier path).
      `"held"` (full model): the step of `"auto"` with the loops evaluated once per step and
      held over it (a digital controller at 1/h) — 3–4× faster with the loops closed, but
      first order in h in what the loops do (a drift error of 1.4e-6 rad/s on a gyro with a
      0.02 rad/s frequency split at 10 steps per cycle); for long runs whose question is
      coarser than that.
    - `quadrature0`: initial quadrature amplitude q₀ (readout units; a₀ is the AGC set point).
    - `adjoint`: how reverse-mode gradients pass through the solve (default: recursive
      checkpointing with 256 checkpoints for the averaged model, so memory stays bounded
      and little is recomputed; diffrax's default for the full model). It is reverse-mode
      only: `jax.jvp`/`jax.jacfwd` need `adjoint=diffrax.ForwardMode()`, `jax.hessian`
      `diffrax.DirectAdjoint()` (else a one-line `TypeError` says so; docs/simulate.md).
    - `run`: integer run id written to the record.

    **Returns:** a [`hrgjax.Record`][]. **Warns:** `SaturationWarning` (eager runs) where the
    force-to-rebalance force sat at `Control.rebalance_limit` (`Record.rebalance_saturated`).

    **Where it runs:** called outside any `jit`/`vmap`/`grad`, on a machine whose default JAX
    backend is an accelerator, the run goes to the CPU (one trajectory steps sequentially,
    and a GPU's kernel launches make that tens to hundreds of times slower; docs/scaling.md).
    Inside `jax.default_device(...)` it runs where that says; under a trace (`hg.sweep`,
    your own `jit`/`vmap`) JAX places the batch as usual.

    **Raises:** `RuntimeError` without float64; `ValueError` for a bad model name, a missing
    key or a bad output grid; a solver failure (max steps, non-finite state) raises too.
    Under your eager `jax.vmap` or `jax.grad`, a traced value that breaks a rule (a kelvin
    temperature, a NaN parameter) raises `RuntimeError("simulate: <the rule>")` in one line;
    under your `jax.jit` the check fails when your program runs, as JAX's
    `JaxRuntimeError` with the rule's line inside (`hg.sweep` says it in one line).
    """
    options = {k: v for k, v in locals().items() if k not in ("gyro", "profile", "model")}
    return simulate_with_stats(gyro, profile, model, **options)[0]


@single_run_entry
@one_line_failures("simulate")
def simulate_with_stats(gyro, profile, model="averaged", **options):
    """[`hrgjax.simulate`][] that also says how the solve went.

    **Arguments:** as `simulate` (`options`: its keyword arguments, same defaults).

    **Returns:** `(record, steps, result)`: the [`hrgjax.Record`][], the solver's accepted
    steps and its `diffrax.RESULTS` item."""
    unknown = set(options) - set(_OPTIONS)
    if unknown:
        raise TypeError(f"simulate got unknown keyword arguments {sorted(unknown)}")
    o = {**_OPTIONS, **options}
    key, bias_key, dt_out, ts = o["key"], o["bias_key"], o["dt_out"], o["ts"]
    rtol, atol, max_steps, solver = o["rtol"], o["atol"], o["max_steps"], o["solver"]
    fixed_step, quadrature0, adjoint = o["fixed_step"], o["quadrature0"], o["adjoint"]
    require_x64("hrgjax.simulate")
    if not isinstance(model, str) or model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}; got {model!r}")
    if not isinstance(gyro, Gyro):
        raise TypeError(f"gyro must be an hrgjax.Gyro; got {type(gyro).__name__}")
    check_one(gyro)  # a batch of gyros (without vmap) failed deep in the solve
    if getattr(profile, "rebalance", None) is not None and (
        gyro.control.mode != "ftr" or gyro.control.ideal
    ):
        raise ValueError(
            "Profile.rebalance switches the rebalance loop on and off: give the gyro "
            "Control(mode='ftr') (gyro.in_mode('ftr')) with its PI loops (ideal=False)"
        )
    ctl = gyro.control  # the averaged model's ideal FTR loops cannot saturate (full: PI)
    if model == "averaged" and ctl.mode == "ftr" and ctl.ideal and ctl.rebalance_limit is not None:
        raise ValueError(IDEAL_LIMIT)
    if not isinstance(profile, Profile):
        raise TypeError(f"profile must be an hrgjax.Profile; got {type(profile).__name__}")
    if gyro.noise is not None and key is None:
        raise ValueError(
            "this gyro has noise: pass key=jax.random.key(…), or use gyro.without_noise()"
        )
    check_options(o)
    check_quadrature0(quadrature0, gyro, profile)  # |q₀| < a₀: the ellipse's minor axis
    if gyro.noise is None:
        bias_key = None  # no switch-on bias to draw
    elif bias_key is None:  # drawn here as `_record` would: one program, given or not
        bias_key = _switch_on_key(key)
    _check_laws(gyro, profile)
    check_bandwidths(gyro, profile, model)  # the averaged model's loops: far below ω
    if ts is None:
        ts, dt_out = output_times(profile, dt_out), float(dt_out)
    else:
        ts, dt_out = output_grid(ts, profile), None
    report_cost(gyro, profile, model)  # only while `sweep` probes what its members cost
    if max_steps is None:
        max_steps = default_max_steps(gyro, profile, model)
    solver = _default_solver(model) if solver is None else solver
    if adjoint is None:
        adjoint = diffrax.RecursiveCheckpointAdjoint(
            checkpoints=AVERAGED_CHECKPOINTS if model == "averaged" else None
        )
    carrier = None
    if isinstance(fixed_step, str) and fixed_step == "held":
        if model != "full" or o["solver"] is not None:
            raise ValueError(
                'fixed_step="held" (loops held over each step) is for model="full" with the '
                "default solver"
            )
        if not is_concrete(rtol):
            raise ValueError(
                'fixed_step="held" chooses its step from rtol, which is traced here: give '
                "rtol as a Python number"
            )
        carrier = (steps_per_interval(gyro, profile, ts, fixed_step, rtol), True)
        fixed_step = None
    elif isinstance(fixed_step, str):  # "auto" (checked above)
        fixed_step = None  # adaptive, unless the rule below picks the carrier path
        if model == "full" and takes_fixed_steps(gyro, profile, ts, o):
            carrier = (steps_per_interval(gyro, profile, ts, "auto", rtol), False)
    elif model == "full" and fixed_step is not None and o["solver"] is None:
        carrier = (steps_per_interval(gyro, profile, ts, fixed_step, rtol), False)
    dt0 = fixed_step if fixed_step is not None else (1e-2 if model == "averaged" else 1e-5)
    stepping = (solver, rtol, atol, max_steps, dt0, fixed_step is not None)
    if carrier is not None:  # it reads none of diffrax's settings: one program per step count
        carrier = (*carrier, looped_stages(gyro, profile, ts, *carrier))
        stepping, adjoint = (_default_solver(model), 0.0, 0.0, 1, 0.0, True), None
    # rtol, atol and the first (or fixed) step are values in the program (arrays; as Python
    # floats they were static: a convergence study compiled the solve again per tolerance)
    stepping = (stepping[0], *(device(x, float) for x in stepping[1:3]), stepping[3],
                device(stepping[4], float), stepping[5])  # fmt: skip
    quadrature0, run = jnp.asarray(quadrature0, dtype=float), jnp.asarray(o["run"])
    gyro, profile = traceable("gyro", gyro, _LAW_LIMITS), traceable("profile", profile)
    # traced values: the eager rules, at run time (explicit output times: their span too)
    gyro, profile, ts = check_traced(gyro, profile, ts, explicit=dt_out is None)
    profile, rel = _from_start(profile, ts, dt_out)  # the clock's origin: no physics
    args = (model, gyro, profile, rel, *stepping, quadrature0, adjoint, key, bias_key, run, ts)
    out = None
    if carrier is None and ts.shape[0] >= parts.STEPPED_FROM and parts.eager(args):
        with contextlib.suppress(parts.Unresumable):  # (rare: then one program, no bar)
            out = _solve_in_parts(*args)  # a long run: progress shown, the same results
    with forward_mode_hint():  # jax.jvp on the default adjoint: one line naming the fix
        out = _solve(*args, carrier) if out is None else out
    warn_saturated(out[0], ctl.rebalance_limit)  # eager runs only (a traced record: no value)
    return out


def _from_start(profile, ts, dt_out):
    """The profile's knots at t − t[0], the output times `ts` [s] since t[0] (`dt_out` [s]:
    k·dt_out exactly): the solve reads no clock origin (an epoch's: docs/simulate.md)."""
    start = profile.t[0]
    shifted = eqx.tree_at(lambda p: p.t, profile, profile.t - start)
    if dt_out is None:
        return shifted, ts - start
    with jax.ensure_compile_time_eval():  # concrete as `output_times` (the carrier path)
        t = np.asarray(profile.t)
        return shifted, device(np.minimum(dt_out * np.arange(ts.shape[0]), t[-1] - t[0]))


_OPTIONS = {name: p.default for name, p in inspect.signature(simulate).parameters.items()
            if p.kind is inspect.Parameter.KEYWORD_ONLY}  # fmt: skip
"""`simulate`'s keyword arguments and their defaults (one source for `simulate_with_stats`)."""
