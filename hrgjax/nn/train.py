"""Training loops in one `lax.scan` (no Python loop over steps): full-batch Rprop, and Adam
on shuffled mini-batches ([`adam_epochs`][hrgjax.nn.train.adam_epochs])."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax

from .. import _upstream
from .._checks import check_finite_host, describe, host_value, numeric_problem, whole_number
from .._compiled import Check, device, program, tracing_callback_free
from .._progress import bar

DIVERGED = (
    "training diverged: the loss or the weights became NaN or inf (NaN or inf in the data, "
    "a solve inside the loss failed, or the learning rate is too large)"
)
"""The one-line error of every training loop here when the loss or the weights are not
finite at the end."""


def check_steps(steps) -> int:
    """`steps` as an int >= 1, or a one-line `ValueError` naming it."""
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps must be an integer >= 1 (Rprop updates); got {steps!r}")
    return int(steps)


def check_rates(**rates) -> None:
    """Refuse a step size (`learning_rate`, `max_step`) that is not a number, or a concrete
    one that is not finite and > 0, in one line naming it (0 left the weights where they
    started, a negative one or `max_step` <= 0 returned weights that had not descended: no
    error either way); a traced one passes."""
    for name, v in rates.items():
        if numeric_problem(v) is not None or np.ndim(v) != 0:
            raise TypeError(f"{name} must be a number > 0 (a step size); got {describe(v)}")
        value = host_value(v)
        if value is not None and not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a finite number > 0 (a step size); got {value:g}")


def check_fit_data(who: str, net, x, y, weights=None) -> None:
    """Refuse, in one line starting with `who`, data a scalar network `net` cannot be fitted
    to: `x` (n, d), or (n, J, d) with `weights` (J,) (each target `net` averaged over its J
    rows), n >= 1; `y` (n,), one target per row; `net` mapping a row (d,) to a scalar. A
    target column (n, 1) broadcast against the (n,) outputs to an (n, n) residual and trained
    the network to the targets' mean without a word; zero rows trained on a NaN loss ("training
    diverged"); a row of the wrong width, or `y` of another length, raised a raw JAX error.
    A concrete NaN or inf in `x` or `y` is refused, naming its index; traced data pass."""
    xs, ys = tuple(jnp.shape(x)), tuple(jnp.shape(y))
    ws = None if weights is None else tuple(jnp.shape(weights))
    rank = 2 if weights is None else 3
    if len(xs) != rank or xs[0] < 1 or (ws is not None and ws != (xs[1],)):
        raise ValueError(f"{who}: x must be (n, d), or (n, J, d) with weights (J,), n >= 1; "
                         f"got x {xs}, weights {ws}")  # fmt: skip
    if ys != (xs[0],):
        raise ValueError(f"{who}: y must have shape ({xs[0]},), one target per row of x; got {ys}")
    check_finite_host(f"{who}: x (training inputs)", x)
    check_finite_host(f"{who}: y (training targets)", y)
    row = jax.ShapeDtypeStruct(xs[-1:], jnp.result_type(x))
    try:
        out = jax.eval_shape(net, row)
    except (TypeError, ValueError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ValueError(f"{who}: net does not take a row of x, shape {xs[-1:]} (x's last axis "
                         f"must be the net's input width): {first}") from None  # fmt: skip
    if getattr(out, "shape", None) != ():
        raise ValueError(f"{who}: net must map a row of x to a scalar; it returns shape "
                         f"{getattr(out, 'shape', type(out).__name__)}")  # fmt: skip


def check_trained(params, losses=None) -> None:
    """Refuse (`RuntimeError`, `DIVERGED` naming the first non-finite loss's step) trained
    `params` or `losses` that are not finite; traced values (under `jit`) pass."""
    if losses is not None:
        v = host_value(losses)
        if v is not None and not np.isfinite(v).all():
            step = int(np.argmax(~np.isfinite(v)))
            raise RuntimeError(f"{DIVERGED}; the loss is not finite from step {step}")
    for leaf in jax.tree_util.tree_leaves(params):
        v = host_value(leaf) if eqx.is_inexact_array(leaf) else None
        if v is not None and not np.isfinite(v).all():
            raise RuntimeError(DIVERGED)


def rprop(loss, params, steps: int, learning_rate: float = 1e-3, max_step: float = 50.0,
          *, compile_once: bool = False):  # fmt: skip
    """`steps` full-batch resilient-backpropagation updates (`optax.rprop`) of the pytree
    `params` on the scalar `loss(params)`, in one `lax.scan`; `learning_rate` is the initial
    step size, `max_step` the largest one (a sigmoid/tanh network saturates, and stops
    learning, when a weight's step grows too large). **Returns** the parameters.

    By default the training is traced afresh on every call, so it trains on what `loss`
    reads now, whatever `loss` is (a closure, a bound method, a callable object).
    **`compile_once=True`** (an opt-in: it is a promise about `loss`) keeps one compiled
    program per `loss`'s function and static fields, the structure and shapes of `params`
    and of `loss`'s arrays, `steps`, `learning_rate` and `max_step`: `loss` must be an
    `equinox.Module` — e.g. `equinox.Partial(f, x=data)` of a module-level `f` — whose data
    are all array leaves (traced arguments, so a later call with new data of the same shapes
    compiles nothing and trains on the new data), and whose function reads nothing else that
    changes between calls (a global, an object in a closure, a static field: fixed in the
    program, and kept alive by its cache). Under the caller's `jit`/`vmap`/`grad`, or where
    the loss needs a traced value as a concrete one (`int(n)`, a shape), it trains as by
    default. A user's `eqx.error_if` inside `loss` raises its own message either way.

    **Raises:** `ValueError` for `steps` < 1, or `compile_once` with a loss that is not an
    `equinox.Module`; `RuntimeError` ("training diverged") when the loss or the trained
    weights are not finite (checked on the host after training; under `jit` the traced
    result passes unchecked)."""
    steps = check_steps(steps)
    check_rates(learning_rate=learning_rate, max_step=max_step)
    trained, losses = _run(_call_loss, params, loss, loss, steps, learning_rate, max_step,
                           compile_once)  # fmt: skip
    check_trained(trained, losses)
    return trained


def train_module(module, loss, steps: int, learning_rate: float = 1e-3, max_step: float = 50.0,
                 *, compile_once: bool = False):  # fmt: skip
    """Rprop on the inexact-array leaves of an equinox `module`; `loss(module)` → scalar.
    `compile_once` as in [`rprop`][hrgjax.nn.train.rprop] (its promise covers `module`'s
    other leaves too: a module holding an integer array trains as by default, its integer
    read as a constant); raises as `rprop`."""
    steps = check_steps(steps)
    check_rates(learning_rate=learning_rate, max_step=max_step)
    params, static = eqx.partition(module, eqx.is_inexact_array)
    trained, losses = _run(_call_combined, params, loss, (loss, static), steps,
                           learning_rate, max_step, compile_once)  # fmt: skip
    check_trained(trained, losses)
    return eqx.combine(trained, static)


def _call_loss(params, loss):
    return loss(params)


def _call_combined(params, loss_static):
    loss, static = loss_static
    return loss(eqx.combine(params, static))


def _rate(x):
    """A checked step size as a program's traced argument (a new value compiles nothing):
    a weakly typed array, so float32 weights stay float32; a traced one as it is."""
    return x if isinstance(x, jax.core.Tracer) else jnp.asarray(float(host_value(x)))


def _rprop_run(loss_fn, params, data, length: int, learning_rate, max_step):
    """`length` Rprop updates from a fresh optimiser state: (params, losses)."""
    state = optax.rprop(learning_rate, max_step_size=max_step).init(params)
    params, _, losses = _rprop_scan(loss_fn, params, state, data, length, learning_rate, max_step)
    return params, losses


_rprop_program = eqx.filter_jit(_rprop_run)
"""`_rprop_run` as one compiled program per loss function, data structure and shapes
(`compile_once=True`; `rprop` and `train_module` check its outputs on the host, naming the
first non-finite loss's step). A plain `filter_jit`, not `program`: `program` traces
equinox's checks in their NaN form (for the persistent cache), which turned a user's
`eqx.error_if` inside the loss into NaN weights."""

# the loss needs a concrete value of a traced array (`int(n)`, `if x > 0`, `np.asarray`, a
# shape: "Shapes must be 1D sequences of concrete values")
_NEEDS_CONCRETE = (
    jax.errors.ConcretizationTypeError,
    jax.errors.TracerArrayConversionError,
    jax.errors.TracerIntegerConversionError,
    TypeError,
)


def _run(loss_fn, params, loss, data, steps, learning_rate, max_step, compile_once):
    """Train traced afresh (`_rprop_run`, the default), or with the cached program where
    `compile_once` promises it sees all that `loss` reads (`rprop`'s docstring)."""
    if compile_once is not True and compile_once is not False:
        raise ValueError(f"compile_once must be True or False; got {compile_once!r}")
    if compile_once:
        if not isinstance(loss, eqx.Module):
            raise ValueError(
                "compile_once=True needs an equinox.Module loss whose data are its array "
                f"leaves (e.g. equinox.Partial(f, x=data)); got {type(loss).__name__}"
            )
        traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(data))
        if not (traced or tracing_callback_free() or not _upstream.trace_state_clean()):
            try:
                return _rprop_program(loss_fn, params, data, steps, _rate(learning_rate),
                                      _rate(max_step))  # fmt: skip
            except _NEEDS_CONCRETE:
                pass  # the loss reads its data as concrete values: it trains as by default
    return _rprop_run(loss_fn, params, data, steps, learning_rate, max_step)


def _block_length(steps: int, blocks: int = 20) -> int:
    """The length of a progress block: the largest divisor of `steps` that is at most
    steps/blocks (≥ 1), so that one compiled block serves the whole run, unless that makes
    more than 4·`blocks` blocks; then steps // blocks, and `rprop_with_progress` ends with
    one shorter block (a second program). A prime `steps` had only 1: 997 Rprop steps ran as
    997 one-step programs, 5.4 s against 0.06 s for 1000 (a 30-unit MLP on 108 points)."""
    target = max(steps // blocks, 1)
    divisor = max(d for d in range(1, target + 1) if steps % d == 0)
    return divisor if steps // divisor <= 4 * blocks else target


def _rprop_scan(loss_fn, params, state, data, length: int, learning_rate, max_step):
    """`length` Rprop updates from optimiser `state` in one `lax.scan` on
    `loss_fn(params, data)`: (params, state, the loss before each update)."""
    opt = optax.rprop(learning_rate, max_step_size=max_step)

    def step(carry, _):
        p, s = carry
        value, grad = jax.value_and_grad(loss_fn)(p, data)
        updates, s = opt.update(grad, s, p)
        return (optax.apply_updates(p, updates), s), value

    (params, state), losses = jax.lax.scan(step, (params, state), None, length=length)
    return params, state, losses


_rprop_block = program(
    _rprop_scan,
    check=Check(
        "training",
        nonfinite=DIVERGED,
    ),
)
"""`_rprop_scan` as a compiled program (one per loss function and shapes)."""


def rprop_with_progress(
    loss_fn,
    params,
    data,
    steps: int,
    learning_rate: float = 1e-3,
    max_step: float = 50.0,
    *,
    desc: str = "training",
):
    """[`rprop`][hrgjax.nn.train.rprop] run as blocks of compiled steps (equal, but for a
    shorter last one where `steps` has no fitting divisor), with a progress bar showing the
    loss between blocks.

    `loss_fn(params, data)` must be a module-level function (not a fresh closure), so that
    its compiled block is reused by every later call with the same shapes. The updates are
    exactly those of `rprop(lambda p: loss_fn(p, data), params, steps, …)`.

    **Returns:** `(params, losses)`: the trained parameters and the loss before each step,
    shape (steps,).

    **Raises:** `ValueError` for `steps` < 1; `RuntimeError` when the loss or the weights
    become non-finite.
    """
    steps = check_steps(steps)
    check_rates(learning_rate=learning_rate, max_step=max_step)
    learning_rate, max_step = _rate(learning_rate), _rate(max_step)
    state = optax.rprop(learning_rate, max_step_size=max_step).init(params)
    length = _block_length(steps)
    lengths = [length] * (steps // length) + [steps % length] * (steps % length > 0)
    losses = []
    with bar(steps, desc) as progress:
        for n in lengths:
            params, state, chunk = _rprop_block(
                loss_fn, params, state, data, n, learning_rate, max_step
            )
            losses.append(np.asarray(chunk))  # on the host: no eager device programs
            progress.update(n)
            progress.set_postfix_str(f"loss {float(losses[-1][-1]):.4g}")
    return params, device(np.concatenate(losses))


def adam_epochs(
    loss_fn, eval_fn, params, data, n_items: int, *, key: jax.Array, epochs: int,
    batch_size: int, learning_rate,
):  # fmt: skip
    """`epochs` passes of Adam (optax, gradients clipped to global norm 1) over `n_items`
    items in shuffled mini-batches of `batch_size` (at most `n_items`; each epoch's last
    partial batch is left out). The learning rate warms up linearly over the first
    `total // 20 + 1` of the `total` updates, then decays along a cosine to 2 % of the peak
    `learning_rate` (dimensionless, per update).

    `loss_fn(params, data, idx)` → scalar loss on the items `idx` (batch_size,) int;
    `eval_fn(params, data)` → (m,) values recorded after each epoch. **Returns**
    `(params, history)`, `history` (epochs, m).

    **Compiled once:** one program per `loss_fn`, `eval_fn`, the structure and shapes of
    `params` and `data` (its non-array leaves are static), `n_items`, `epochs` and
    `batch_size`; `params`, `data`'s arrays, `key` and `learning_rate` are traced, so a later
    call with other values of the same shapes compiles nothing. `loss_fn` and `eval_fn` must
    therefore be module-level functions, not fresh closures (each would compile anew).

    **Items and rows.** Where all of `data`'s array leaves of rank >= 1 share one leading
    length (the items' axis), `n_items` above it is refused before any training: JAX clamps
    an index beyond an array's end, so the extra items silently re-read its last row. Where
    the leaves' leading lengths differ (items beside other arrays, e.g. a test set or model
    constants) the check is skipped and `n_items` is trusted; scalar leaves are ignored.

    **Raises:** `ValueError` for `epochs`, `batch_size` or `n_items` not an integer >= 1,
    `n_items` beyond the rows of `data` (see below), or a concrete `learning_rate` not finite
    and > 0; `RuntimeError` ("training diverged") when
    the trained weights are not finite (NaN data; checked on the host, concrete results
    only)."""
    for name, v in (("epochs", epochs), ("batch_size", batch_size)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name} must be an integer >= 1; got {v!r}")
    whole_number("n_items", n_items, "an integer >= 1 (items)", minimum=1)
    _check_items(data, int(n_items))
    check_rates(learning_rate=learning_rate)
    batch_size = min(int(batch_size), int(n_items))
    # optax's Adam bias correction mixes int and float: traced under standard promotion
    # whatever the caller's setting
    with jax.numpy_dtype_promotion("standard"):
        params, history = _adam_program(loss_fn, eval_fn, params, data, key,
                                        device(learning_rate, float), int(n_items),
                                        int(epochs), batch_size)  # fmt: skip
    check_trained(params)
    return params, history


def _check_items(data, n_items: int) -> None:
    """Refuse `n_items` beyond the one leading length of `data`'s array leaves of rank >= 1
    (their shapes are static, traced ones too); leaves of differing lengths skip it."""
    lengths = {np.shape(x)[0] for x in jax.tree_util.tree_leaves(data)
               if eqx.is_array(x) and np.ndim(x) >= 1}  # fmt: skip
    if len(lengths) == 1 and n_items > (rows := lengths.pop()):
        raise ValueError(f"n_items must be <= {rows}, the rows (leading axis) of data's arrays; "
                         f"got {n_items} (an index past the end reads the last row again)")  # fmt: skip


@eqx.filter_jit
def _adam_program(loss_fn, eval_fn, params, data, key, learning_rate, n_items, epochs, batch):
    n_batches = n_items // batch
    total = epochs * n_batches
    warm = total // 20 + 1

    def schedule(count):  # linear warm-up, cosine decay to 2 % (dtype-explicit)
        c = jnp.asarray(count).astype(learning_rate.dtype)
        frac = jnp.clip((c - warm) / max(total - warm, 1), 0.0, 1.0)
        decay = learning_rate * (0.02 + 0.98 * 0.5 * (1.0 + jnp.cos(jnp.pi * frac)))
        return jnp.where(c < warm, learning_rate * c / warm, decay)

    opt = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(schedule))

    def epoch(carry, k):
        p, state = carry
        order = jax.random.permutation(k, n_items)[: n_batches * batch]

        def step(carry, idx):
            p, state = carry
            g = jax.grad(loss_fn)(p, data, idx)
            updates, state = opt.update(g, state, p)
            return (optax.apply_updates(p, updates), state), None

        (p, state), _ = jax.lax.scan(step, (p, state), order.reshape(n_batches, batch))
        return (p, state), eval_fn(p, data)

    (p, _), hist = jax.lax.scan(epoch, (params, opt.init(params)), jax.random.split(key, epochs))
    return p, hist
