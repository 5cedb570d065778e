"""One diffrax solve in host-side parts, bit for bit the single solve: progress on long runs.

A long eager [`hrgjax.simulate`][] (days of output) spent tens of seconds in one compiled
`diffeqsolve` with nothing shown. Here the same solve runs as a sequence of compiled calls,
each resuming exactly where the last stopped, so that a progress bar can move between them:

- every part calls `diffeqsolve` with the run's own `t1` (so no step is clipped at a part's
  end) and hands on the solver's whole state: the time and state reached, the next step's end,
  the solver's FSAL stage, the step-size controller's state and the jump flag. The step
  sequence, the accepted states and every output value are those of the one solve;
- a part saves a window of `PART_OUTPUTS` output times (more where its first step, already
  fixed, ends past them); it stops after `PART_STEPS` solver steps, or as soon as the next
  step would reach past its window (`Resumable` says so through the controller's result), so
  that no output time is stepped over unsaved. The run's first step is known only once taken:
  should it end past the first window, the first part runs again with a window covering it;
- `Resumable` wraps the run's step-size controller: it records the next step's end (which
  `diffeqsolve` does not return) and, on resuming, starts from it instead of `t0 + dt0`
  (which need not round back to it). Wrapping an adaptive controller, it is adaptive too
  (`AdaptiveResumable`), so that an implicit solver's root finder gets its tolerances;
- each part's saved outputs are copied to the host (a view would keep its window alive).

Not for traced values (`simulate` under a caller's `jit`/`vmap`/`grad` solves in one program).
"""

from __future__ import annotations

import diffrax
import jax
import jax.numpy as jnp
import numpy as np

from ._compiled import device
from ._progress import bar
from ._upstream import trace_state_clean

STEPPED_FROM = 1 << 20
"""Output samples from which an eager [`hrgjax.simulate`][] (adaptive or constant steps, not
the carrier path) solves in parts behind a progress bar, with the same results bit for bit
(29 h at the default 10 Hz: ≈ 12 s warm on 2 shared CPU cores, a 3-day run 18–19 s;
benchmarks/simulate_progress.py)."""
PART_STEPS = 1 << 14
"""Solver steps per part (≈ 7 h of the default gyro at rest)."""
PART_OUTPUTS = 1 << 17
"""Output samples per part's window (≈ 3.6 h at 10 Hz; wider where one step needs it)."""


def eager(tree) -> bool:
    """Called outside any trace, on concrete values only."""
    leaves = jax.tree_util.tree_leaves(tree)
    return trace_state_clean() and not any(isinstance(x, jax.core.Tracer) for x in leaves)


class Resumable(diffrax.AbstractStepSizeController):
    """`controller` that keeps the next step's end in its state and stops the solve (result
    `event_occurred`) once that end reaches `stop` [s]; with `tnext` [s] given, the first
    step ends there (a resumed solve: `diffeqsolve` is then given the controller state).
    Build it with `resumable`, which keeps an adaptive controller adaptive."""

    controller: diffrax.AbstractStepSizeController
    tnext: jax.Array | None
    stop: jax.Array

    def wrap(self, direction):
        return type(self)(self.controller.wrap(direction), self.tnext, self.stop)

    def init(self, terms, t0, t1, y0, dt0, args, func, error_order):
        if self.tnext is not None:  # resumed: diffeqsolve keeps the state it was given
            return self.tnext, None
        tnext, state = self.controller.init(terms, t0, t1, y0, dt0, args, func, error_order)
        return tnext, (state, jnp.asarray(tnext, float), jnp.asarray(True))

    def adapt_step_size(self, t0, t1, y0, y1_candidate, args, y_error, error_order, state):
        keep, tprev, tnext, jump, inner, result = self.controller.adapt_step_size(
            t0, t1, y0, y1_candidate, args, y_error, error_order, state[0]
        )
        ok = result == diffrax.RESULTS.successful
        result = diffrax.RESULTS.where(
            ok & (tnext >= self.stop), diffrax.RESULTS.event_occurred, result
        )
        return keep, tprev, tnext, jump, (inner, jnp.asarray(tnext, float), keep), result


class AdaptiveResumable(Resumable, diffrax.AbstractAdaptiveStepSizeController):
    """`Resumable` of an adaptive `controller`: adaptive too, with its `rtol`, `atol` and
    `norm`, which `diffeqsolve` hands to an implicit solver's root finder (as in the one
    solve; a plain `Resumable` made Kvaerno5 refuse to run)."""

    @property
    def rtol(self):
        return self.controller.rtol

    @property
    def atol(self):
        return self.controller.atol

    @property
    def norm(self):  # pyright: ignore[reportIncompatibleMethodOverride]
        return self.controller.norm


def resumable(controller, tnext, stop) -> Resumable:
    """`controller` wrapped in a `Resumable` (`AdaptiveResumable` for an adaptive one)."""
    if isinstance(controller, diffrax.AbstractAdaptiveStepSizeController):
        return AdaptiveResumable(controller, tnext, stop)
    return Resumable(controller, tnext, stop)


def solve_part(terms, solver, controller, t0, t1, dt0, y0, args, adjoint, window, stop,
               resume, steps: int):  # fmt: skip
    """One part (module docstring): `diffeqsolve` from `t0` (or from `resume`, a previous
    part's state and its next step's end) towards the run's end `t1`, saving at the times
    `window` [s], at most `steps` steps. Returns `(window values, times saved, state,
    num_steps, result)`; `state` is what the next part resumes from: (t reached, y there,
    solver state, controller state, jump flag)."""
    kwargs = dict(dt0=dt0, y0=y0)
    if resume is not None:
        t0, y, solver_state, controller_state, made_jump, tnext = resume
        kwargs = dict(dt0=None, y0=y, solver_state=solver_state,
                      controller_state=controller_state, made_jump=made_jump)  # fmt: skip
        controller = resumable(controller, tnext, stop)
    else:
        controller = resumable(controller, None, stop)
    saveat = diffrax.SaveAt(
        subs=[diffrax.SubSaveAt(ts=window), diffrax.SubSaveAt(t1=True)],
        solver_state=True,
        controller_state=True,
        made_jump=True,
    )
    sol = diffrax.diffeqsolve(terms, solver, t0, t1, args=args, saveat=saveat,
                              stepsize_controller=controller, max_steps=steps, adjoint=adjoint,
                              throw=False, **kwargs)  # fmt: skip
    state = (sol.ts[1][0], jax.tree_util.tree_map(lambda y: y[0], sol.ys[1]), sol.solver_state,
             sol.controller_state, sol.made_jump)  # fmt: skip
    saved = jnp.sum(sol.ts[0] < jnp.inf)
    return sol.ys[0], saved, state, sol.stats["num_steps"], sol.result


def next_step_end(state, t1: float) -> np.float64:
    """Where the loop's next step ends after a part (host): the controller's proposal as the
    loop clips it near `t1` (within 100 ulp: to `t1`, or halfway after a rejected step)."""
    tprev, proposal, keep = np.float64(state[0]), np.float64(state[3][1]), bool(state[3][2])
    t1 = np.float64(t1)
    floor = t1
    for _ in range(100):
        floor = np.nextafter(floor, -np.inf) if floor != 0 else -np.finfo(float).tiny
    if proposal > floor:
        return t1 if keep else tprev + 0.5 * (t1 - tprev)
    return proposal


class Unresumable(Exception):
    """A part stopped past an output time it did not save (its last step ended on a jump
    knot, just beyond it, with that knot's output outside its window): the caller solves in
    one program instead (the same results, no bar)."""


def run_parts(part, ts, knots, max_steps: int, finish, desc: str = "simulate"):
    """The values at every output time `ts` (increasing, within the `knots` [s] of the run's
    profile) of one solve run in parts (module docstring) behind a progress bar over the
    simulated time: `part(window, stop, resume, steps)` runs `solve_part` with these. A part
    takes at most `PART_STEPS` steps, the run `max_steps` (as the one solve). Returns
    `(finish(values (N, …) on the host), num_steps, result)`, `finish` called with the bar
    still shown; values not reached (a failed solve) are inf, as the one solve leaves them."""
    knots = np.asarray(knots, dtype=float)
    t0, t1 = float(knots[0]), float(knots[-1])
    ts = np.asarray(ts, dtype=float)
    n, done, taken, values, resume, shown = ts.size, 0, 0, [], None, 0
    with bar(int(np.ceil(t1 - t0)), desc, unit="s") as progress:  # simulated whole seconds
        end = -np.inf  # where the part's first step ends, as far as known
        while True:
            size = PART_OUTPUTS  # a window wide enough for the part's first step
            while done + size < n and ts[done + size] <= end:
                size *= 2
            times = ts[done : done + size]
            times = np.concatenate([times, np.full(size - times.size, float(t1))])
            stop = ts[done + size] if done + size < n else np.inf
            budget = min(PART_STEPS, max_steps - taken)
            if resume is not None:
                resume = (*resume[:-1], device(resume[-1], float))
            out, saved, state, count, result = part(device(times), device(stop, float), resume,
                                                    budget)  # fmt: skip
            if resume is None and float(state[0]) >= stop:
                # the first step (never checked against `stop`) passed the first window:
                # the same first part again, its window wide enough for that step
                end = float(state[0])
                continue
            saved = min(int(saved), n - done)
            values.append(np.asarray(out)[:saved].copy())  # not a view pinning the window
            done, taken = done + saved, taken + int(count)
            reached = int(np.ceil(float(state[0]) - t0))
            progress.update(max(reached - shown, 0))
            shown = max(reached, shown)
            go_on = bool(result == diffrax.RESULTS.event_occurred) or (
                bool(result == diffrax.RESULTS.max_steps_reached) and taken < max_steps
            )
            if not go_on:  # on to the run's end, past the last output (as the one solve)
                break
            if done < n and ts[done] < float(state[0]):  # a part that ended on a jump knot
                raise Unresumable  # steps past an output unsaved: no later part can save it
            resume = (*state, next_step_end(state, t1))
            end = resume[-1]
        out = np.concatenate(values)
        if done < n:  # outputs not reached (a failed solve): inf, as diffrax leaves them
            out = np.concatenate([out, np.full((n - done, *out.shape[1:]), np.inf)])
        progress.set_postfix_str("readout and noise")
        return jax.block_until_ready(finish(out)), taken, result
