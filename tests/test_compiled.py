"""Callback-free programs: host errors, errors under a caller's trace, no leak of the NaN
form of a check into code that expects it to raise, and the stepwise least squares."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

from hrgjax._checks import check_finite
from hrgjax._compiled import bucket_pad, bucket_size, device, fused, program
from hrgjax._least_squares import least_squares, least_squares_with_jacobian


@program
def _doubled(x):
    return 2.0 * check_finite("probe", x)


def test_program_raises_on_the_host_and_under_a_callers_trace():
    np.testing.assert_array_equal(_doubled(jnp.ones(3)), 2.0 * np.ones(3))
    bad = jnp.array([1.0, jnp.nan, 1.0])
    with pytest.raises(RuntimeError, match="doubled produced NaN or inf"):
        _doubled(bad)
    with pytest.raises(Exception, match="doubled produced NaN or inf"):
        jax.jit(_doubled)(bad).block_until_ready()
    with pytest.raises(Exception, match="doubled produced NaN or inf"):
        jax.vmap(_doubled)(bad[None]).block_until_ready()


def test_a_check_traced_inside_a_program_still_raises_outside():
    """The same check (message and shapes) traced in NaN form inside a program is not
    reused by code outside our programs, which expects it to raise."""
    _doubled(jnp.ones(3))
    bad = jnp.array([[1.0, jnp.nan, 1.0]])
    with pytest.raises(Exception, match="probe must be finite"):
        jax.vmap(lambda x: check_finite("probe", x))(bad)
    with pytest.raises(Exception, match="probe must be finite"):
        jax.jit(lambda x: check_finite("probe", x))(bad[0]).block_until_ready()


def _rosenbrock(y, args):
    a, b = args
    return jnp.stack([a * (y[0] - 1.0), b * (y[1] - y[0] ** 2), y[2] - 0.3 * y[0]])


def test_stepwise_least_squares_takes_optimistix_steps():
    solver = optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)
    args = (jnp.asarray(1.0), jnp.asarray(10.0))
    y0 = jnp.array([-1.2, 1.0, 0.0])
    ref = optx.least_squares(_rosenbrock, solver, y0, args=args, max_steps=200, throw=False)
    y, steps, result = least_squares(_rosenbrock, solver, y0, args, max_steps=200)
    np.testing.assert_array_equal(y, ref.value)
    assert steps == int(ref.stats["num_steps"]) and result == optx.RESULTS.successful
    _, steps, result = least_squares(_rosenbrock, solver, y0, args, max_steps=3)
    assert steps == 3 and result == optx.RESULTS.nonlinear_max_steps_reached
    # optimistix's own compiled loop through the same driver
    y, steps, result = least_squares(_rosenbrock, solver, y0, args, max_steps=200, stepwise=False)
    np.testing.assert_array_equal(y, ref.value)
    assert steps == int(ref.stats["num_steps"]) and result == optx.RESULTS.successful


def test_least_squares_fed_a_jacobian_takes_the_same_steps():
    """The solver stepped on r + J(y − y_eval) from the caller's (r, J) at each point it
    evaluates reaches optimistix's own solution in the same number of steps, and returns
    the residuals and Jacobian at that solution."""
    solver = optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8)
    args = (jnp.asarray(1.0), jnp.asarray(10.0))
    y0 = jnp.array([-1.2, 1.0, 0.0])
    ref = optx.least_squares(_rosenbrock, solver, y0, args=args, max_steps=200, throw=False)
    calls = []

    def rj(y):
        calls.append(np.asarray(y))
        return _rosenbrock(y, args), jax.jacfwd(_rosenbrock)(y, args)

    y, steps, result, (r, jac) = least_squares_with_jacobian(rj, solver, y0, max_steps=200)
    np.testing.assert_allclose(y, ref.value, rtol=0, atol=1e-12)
    assert steps == int(ref.stats["num_steps"]) and result == optx.RESULTS.successful
    np.testing.assert_allclose(r, _rosenbrock(y, args), atol=1e-15)
    np.testing.assert_allclose(jac, jax.jacfwd(_rosenbrock)(y, args), atol=1e-15)
    assert len(calls) <= steps + 1  # one evaluation per step, none repeated
    _, steps, result, _ = least_squares_with_jacobian(rj, solver, y0, max_steps=3)
    assert steps == 3 and result == optx.RESULTS.nonlinear_max_steps_reached


def test_buckets():
    assert [bucket_size(n) for n in (1, 64, 65, 1000, 1024, 1025)] == [
        64,
        64,
        128,
        1024,
        1024,
        2048,
    ]
    np.testing.assert_array_equal(bucket_pad(np.array([1.0, 2.0]), 4), [1.0, 2.0, 2.0, 2.0])


def test_host_values_reach_the_device_without_eager_programs():
    """`device` and the profile constructors on host values copy instead of staging a small
    XLA program per new shape (what made a warm `demo --quick` spend seconds compiling),
    and give what `jnp.asarray` and the traced constructors give."""
    from helpers import CompileCounter

    import hrgjax as hg
    from hrgjax._compiled import device

    x = np.linspace(0.0, 1.0, 37)  # shapes no other test uses
    knots, temps = np.linspace(0.0, 10.0, 41), np.linspace(-40.0, 20.0, 41)
    with CompileCounter() as c:
        on_device = device(x)
        prof = hg.Profile.constant_rate(5.0, 37.0, -12.0, 33.0, (0.0, 0.1, 1.0))
        piece = hg.Profile.piecewise(knots, 2.0, temps, wave_angle0_deg=7.0)
    assert (c.compiles, c.traces) == (0, 0), c.names
    assert isinstance(on_device, jax.Array) and on_device.dtype == jnp.asarray(x).dtype
    np.testing.assert_array_equal(on_device, x)
    # the same constructors with a traced argument take the jnp path: same values
    traced = jax.jit(lambda r: hg.Profile.constant_rate(r, 37.0, -12.0, 33.0, (0.0, 0.1, 1.0)))
    leaves = jax.tree_util.tree_leaves
    for a, b in zip(leaves(prof), leaves(traced(5.0)), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-15)
    np.testing.assert_array_equal(piece.t, knots)
    np.testing.assert_array_equal(piece.temperature, temps)
    np.testing.assert_allclose(piece.rate, np.full(41, np.deg2rad(2.0)), rtol=1e-15)
    assert piece.accel.shape == (41, 3) and float(piece.wave_angle0) == np.deg2rad(7.0)


def test_a_weakly_typed_argument_reuses_the_strong_arguments_program():
    """`jnp.asarray(2.0)` and `jnp.full(n, 2.0)` are weakly typed and a compiled program is
    kept by its arguments' weak types: a gyro with one such leaf compiled `simulate`'s whole
    solve again. `program` makes concrete weak floats strong (same values, placement kept),
    so they meet the program compiled for strong ones; traced arguments pass as they are."""
    from helpers import CompileCounter

    @program(export=False)
    def scaled(x, pair):
        return x * pair[0] + pair[1]

    n = 29  # a length no other test uses
    strong = (jnp.asarray(np.full(n, 2.0)), (np.float64(3.0), jnp.asarray(np.float64(0.5))))
    expected = scaled(*strong)
    weak = (jnp.full(n, 2.0), (jnp.asarray(3.0), jnp.asarray(0.5)))
    assert all(x.weak_type for x in jax.tree_util.tree_leaves(weak))
    with CompileCounter() as c:
        got = scaled(*weak)
    assert c.compiles == 0, c.names
    np.testing.assert_array_equal(got, expected)
    assert all(x.weak_type for x in jax.tree_util.tree_leaves(weak))  # the caller's, untouched
    single = jnp.ones(n, jnp.float32)  # beside float32 a weak float keeps float32 (review)
    assert scaled(single, (jnp.asarray(3.0), jnp.asarray(0.5))).dtype == jnp.float32
    ints = jnp.asarray(3)  # weak integers are left alone (a count, not a value)
    assert scaled(ints, (ints, ints)).dtype == jnp.asarray(3).dtype
    grad = jax.grad(lambda a: scaled(jnp.full(n, 2.0), (a, 0.5)).sum())(3.0)
    np.testing.assert_allclose(grad, 2.0 * n, rtol=1e-15)


def test_fused_functions_compile_one_program_eagerly_and_inline_under_a_trace():
    """A `fused` function called on concrete arrays compiles one program for a new shape
    (not one per operation: `navigation_errors` is ≈ 50 operations, ≈ 100 eager programs
    before) and none for the same shape again; under a caller's `jit`, `grad` and `vmap` it
    is inlined (no nested call in the caller's program) and gives the same values as the
    formulas written out: the position error in metres from the radii of curvature."""
    from helpers import CompileCounter

    from hrgjax.ins import mechanization as me
    from hrgjax.ins.constants import radii

    n = 23  # a length no other test uses
    lat = np.linspace(0.1, 1.2, n)
    q = me.euler_to_quat(np.zeros(n), np.zeros(n), np.linspace(0.0, 1.0, n))
    truth = me.NavState(jnp.asarray(lat), jnp.zeros(n), jnp.zeros(n), jnp.zeros((n, 3)), q)
    nav = me.NavState(truth.lat + 1e-6, truth.lon - 2e-6, truth.h + 3.0, truth.v_ned, q)
    with CompileCounter() as first:
        pos, vel, att = me.navigation_errors(nav, truth)
    with CompileCounter() as again:
        me.navigation_errors(nav, truth)
    assert first.names == ["jit(navigation_errors)"], first.names
    assert again.compiles == 0

    # a NumPy scalar (read from a file, `np.diff(t)[0]`) meets the program of a Python one
    scaled = fused(lambda x, a, flag: jnp.where(flag, a * x, x))
    xs = jnp.asarray(np.linspace(0.0, 1.0, n))
    expected = scaled(xs, 2.5, True)
    with CompileCounter() as numpy_scalars:
        got = scaled(xs, np.float64(2.5), np.bool_(True))
        scaled(xs, np.asarray(3.5), np.True_)
    assert numpy_scalars.compiles == 0, numpy_scalars.names
    np.testing.assert_array_equal(got, expected)
    with jax.numpy_dtype_promotion("standard"):  # beside float32 the NumPy float64 stays strong
        single = jnp.ones(n, jnp.float32)
        assert scaled(single, np.float64(2.5), True).dtype == jnp.float64  # (as jax.jit gives)
        assert jax.vmap(lambda x: x * device(2.0))(single).dtype == jnp.float64  # (review)
    r_m, r_n = (np.asarray(r) for r in radii(lat))
    np.testing.assert_allclose(pos[:, 0], 1e-6 * r_m, rtol=1e-9)
    np.testing.assert_allclose(pos[:, 1], -2e-6 * r_n * np.cos(lat), rtol=1e-9)
    np.testing.assert_allclose(pos[:, 2], -3.0, rtol=1e-12)
    np.testing.assert_allclose(att, 0.0, atol=1e-15)

    north = lambda dlat: me.navigation_errors(
        me.NavState(truth.lat + dlat, truth.lon, truth.h, truth.v_ned, q), truth
    )[0][:, 0]
    jaxpr = jax.make_jaxpr(north)(1e-6)
    ours = {"navigation_errors", "radii", "quat_multiply", "quat_conjugate", "quat_to_rotvec"}
    nested = [e.params.get("name") for e in jaxpr.eqns if e.primitive.name in ("pjit", "jit")]
    assert not ours & set(nested), nested  # (jnp's own helpers, e.g. `cross`, stay jitted)
    np.testing.assert_allclose(jax.jit(north)(1e-6), pos[:, 0], rtol=1e-9)  # (lat + d) − lat
    np.testing.assert_allclose(jax.grad(lambda d: north(d).sum())(0.0), r_m.sum(), rtol=1e-12)
    np.testing.assert_allclose(jax.vmap(north)(jnp.asarray([1e-6, 2e-6]))[1], 2.0 * pos[:, 0],
                               rtol=1e-9)  # fmt: skip


_IMPORT_ALL_IN_A_TRACE = """
import importlib, pkgutil, sys
import jax
import hrgjax

def import_all(x):
    for m in pkgutil.walk_packages(hrgjax.__path__, "hrgjax."):
        importlib.import_module(m.name)
    return x

jax.jit(import_all)(1.0)
print([f"{name}.{k}" for name, mod in list(sys.modules.items()) if name.startswith("hrgjax")
       for k, v in vars(mod).items() if isinstance(v, (jax.Array, jax.core.Tracer))])
"""


def test_no_module_holds_a_jax_array_even_when_first_imported_inside_a_trace():
    """hrgjax imports its modules on first use, which may be inside the user's `jit` (e.g.
    `hg.simulate` first reached in a traced loss). A module-level JAX array would then be
    a tracer leaked into a global (the docs build once failed this way: `full._J`) — and even
    outside a trace it would fix its dtype at import. Module constants are NumPy."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _IMPORT_ALL_IN_A_TRACE], capture_output=True,
                         text=True, check=True)  # fmt: skip
    assert out.stdout.strip() == "[]", out.stdout + out.stderr
