"""Nonlinear least squares one compiled step at a time, so a person sees the fit progress.

`optimistix.least_squares` runs its whole iteration inside one compiled `while_loop`: right
for speed, but silent for minutes when every residual evaluation simulates a bench campaign.
`least_squares` here drives the same solver (`init`, `step`, `terminate`, exactly as
optimistix's own loop calls them) from Python: one compiled program per step, reused by
every step and every later fit of the same shapes, and a progress bar with the cost between
steps. The iterates are those of `optimistix.least_squares` with the same solver.

`least_squares_with_jacobian` is the same loop for residuals whose Jacobian the caller
computes in a compiled program of its own (a simulator's `jax.jacfwd`): the solver's step is
handed, for the one point it evaluates (the state's `y_eval`), the residuals and Jacobian
there, as the linear model r + J(y − y_eval) — exact at that point, with exactly that
Jacobian. The solver's program then holds no simulator at all, and the expensive program is
compiled once instead of twice (once in the caller, once inside the solver's step).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import _upstream
from ._compiled import Unchecked, program
from ._progress import bar

_TAGS: frozenset = frozenset()


class _WithAux(eqx.Module):
    """`fn(y, args) -> residuals` as optimistix's `(out, aux)` form (aux None)."""

    fn: object = eqx.field(static=True)

    def __call__(self, y, args):
        return jnp.asarray(self.fn(y, args)), None


def _status(y, state, solver, fn, args):
    done, result = solver.terminate(fn, y, args, {}, state, _TAGS)
    finite = jnp.all(jnp.asarray([jnp.all(jnp.isfinite(x)) for x in jax.tree.leaves(y)]))
    return done, optx.RESULTS.where(finite, result, optx.RESULTS.nonfinite)


def _state(solver, fn, y, args, f_struct):
    return solver.init(fn, y, args, {}, f_struct, None, _TAGS)


@program(check=Unchecked())
def _start(solver, fn, y, args, f_struct):
    state = _state(solver, fn, y, args, f_struct)
    done, result = _status(y, state, solver, fn, args)
    return eqx.filter(state, eqx.is_array), done, result


@program(check=Unchecked())
def _step(solver, fn, y, args, dynamic, f_struct):
    # The state's static part (closure-converted jaxprs) is rebuilt by tracing `init` here,
    # so only arrays cross the program boundary and one compiled step serves every call.
    static = eqx.filter(_state(solver, fn, y, args, f_struct), eqx.is_array, inverse=True)
    state = eqx.combine(dynamic, static)
    new_y, new_state, _ = solver.step(fn, y, args, {}, state, _TAGS)
    done, result = _status(y, new_state, solver, fn, args)
    residual = getattr(new_state.f_info, "residual", None)
    cost = jnp.nan if residual is None else 0.5 * jnp.sum(jnp.square(residual))
    return new_y, eqx.filter(new_state, eqx.is_array), done, result, cost


def _finite(y) -> bool:
    return bool(np.all([np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(y)]))


def _drive(solver, wrapped, y0, args, f_struct, max_steps, desc, args_at=None):
    """The stepping loop of both drivers: `(y, steps, result)`. `args_at(dynamic)`, when
    given, gives the arguments of each step from the state's arrays (default `args`)."""
    dynamic, done, result = _start(solver, wrapped, y0, args, f_struct)
    y, steps = y0, 0

    def going():  # neither converged nor failed
        return not bool(done) and bool(_upstream.succeeded(result, optx.RESULTS))

    # No total: the solver stops when it converges, usually long before max_steps.
    with bar(None, desc) as progress:
        while going() and steps < max_steps:
            step_args = args if args_at is None else args_at(dynamic)
            y, dynamic, done, result, cost = _step(solver, wrapped, y, step_args, dynamic, f_struct)
            steps += 1
            progress.update(1)
            progress.set_postfix_str(f"χ²/2 {float(cost):.6g}")
    if going():
        result = optx.RESULTS.nonlinear_max_steps_reached
    if not _finite(y):
        result = optx.RESULTS.nonfinite
    return y, steps, result


def least_squares(
    fn,
    solver,
    y0,
    args,
    *,
    max_steps: int,
    desc: str = "least squares",
    f_struct=None,
    stepwise: bool = True,
):
    """Minimise ½‖fn(y, args)‖² with an optimistix least-squares `solver` from `y0`.

    `fn` must be a module-level function (a fresh closure would compile anew each call).
    `f_struct`: the residuals' `jax.ShapeDtypeStruct` when the caller knows it (saves
    tracing `fn` once to find it). `stepwise=False` runs `optimistix.least_squares`' own
    compiled loop instead (no progress between steps: for fits whose steps take
    milliseconds; one program per shapes, named `least_squares`).

    **Returns:** `(y, steps, result)`: the solution, the number of steps taken and an
    `optimistix.RESULTS` item (`nonlinear_max_steps_reached` when `max_steps` ran out).
    """
    if not stepwise:
        sol = optx.least_squares(fn, solver, y0, args, max_steps=max_steps, throw=False)
        result = sol.result if _finite(sol.value) else optx.RESULTS.nonfinite
        return sol.value, int(sol.stats["num_steps"]), result
    wrapped = _WithAux(fn)
    if f_struct is None:
        out_struct = jax.eval_shape(fn, y0, args)
        f_struct = jax.ShapeDtypeStruct(out_struct.shape, out_struct.dtype)
    return _drive(solver, wrapped, y0, args, f_struct, max_steps, desc)


def _linear_model(y, args):
    """r + J (y − y_eval): the residual function the solver sees in
    `least_squares_with_jacobian` (evaluated by the solver at y_eval only)."""
    r, jac, y_eval = args
    return r + jac @ (y - y_eval)


def least_squares_with_jacobian(
    residuals_jacobian, solver, y0, *, max_steps: int, desc: str = "least squares"
):
    """Minimise ½‖r(y)‖² with an optimistix least-squares `solver` from `y0` (a 1-D array),
    where `residuals_jacobian(y) -> (r, J)` gives the residuals (m,) and their Jacobian (m, n)
    at `y` (host or device arrays; it is called once per solver step, at the point the step
    evaluates).

    The iterates are those of `least_squares` on r with the same solver, up to the round-off
    between the caller's Jacobian and the one the solver would form.

    **Returns:** `(y, steps, result, (r, J))`: the solution, the number of steps, an
    `optimistix.RESULTS` item, and the residuals and Jacobian at the solution.
    """
    y0 = jnp.asarray(y0)
    r, jac = residuals_jacobian(y0)
    at = (y0, jnp.asarray(r), jnp.asarray(jac))  # the point last evaluated, r and J there

    def evaluated(y_eval):
        nonlocal at
        if not np.array_equal(np.asarray(y_eval), np.asarray(at[0])):
            r, jac = residuals_jacobian(y_eval)
            at = (y_eval, jnp.asarray(r), jnp.asarray(jac))
        return at[1], at[2], at[0]

    f_struct = jax.ShapeDtypeStruct(at[1].shape, at[1].dtype)
    y, steps, result = _drive(
        solver,
        _WithAux(_linear_model),
        y0,
        (at[1], at[2], y0),
        f_struct,
        max_steps,
        desc,
        args_at=lambda dynamic: evaluated(dynamic.y_eval),
    )
    r, jac, _ = evaluated(y)
    return y, steps, result, (r, jac)
