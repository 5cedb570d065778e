"""Nonlinear least squares one compiled step at a time, so a person sees the fit progress.

`optimistix.least_squares` runs its whole iteration inside one compiled `while_loop`: right
for speed, but silent for minutes when every residual evaluation simulates a bench campaign.
`least_squares` here drives the same solver (`init`, `step`, `terminate`, exactly as
optimistix's own loop calls them) from Python: one compiled program per step, reused by
every step and every later fit of the same shapes, and a progress bar with the cost between
steps. The iterates are those of `optimistix.least_squares` with the same solver.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

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


def least_squares(
    fn, solver, y0, args, *, max_steps: int, desc: str = "least squares", f_struct=None
):
    """Minimise ½‖fn(y, args)‖² with an optimistix least-squares `solver` from `y0`.

    `fn` must be a module-level function (a fresh closure would compile anew each call).
    `f_struct`: the residuals' `jax.ShapeDtypeStruct` when the caller knows it (saves
    tracing `fn` once to find it).

    **Returns:** `(y, steps, result)`: the solution, the number of steps taken and an
    `optimistix.RESULTS` item (`nonlinear_max_steps_reached` when `max_steps` ran out).
    """
    wrapped = _WithAux(fn)
    if f_struct is None:
        out_struct = jax.eval_shape(fn, y0, args)
        f_struct = jax.ShapeDtypeStruct(out_struct.shape, out_struct.dtype)
    dynamic, done, result = _start(solver, wrapped, y0, args, f_struct)
    y, steps = y0, 0
    # No total: the solver stops when it converges, usually long before max_steps.
    with bar(None, desc) as progress:
        while not bool(done) and int(result._value) == 0 and steps < max_steps:
            y, dynamic, done, result, cost = _step(solver, wrapped, y, args, dynamic, f_struct)
            steps += 1
            progress.update(1)
            progress.set_postfix_str(f"χ²/2 {float(cost):.6g}")
    if int(result._value) == 0 and not bool(done):
        result = optx.RESULTS.nonlinear_max_steps_reached
    if not np.all([np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(y)]):
        result = optx.RESULTS.nonfinite
    return y, steps, result
