"""`hg.sweep`: sharded over devices and processes, chunked, ordered by cost — each equal to
the one-batch result."""

import gc
import os
import subprocess
import sys
import textwrap
import weakref

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

import hrgjax as hg


@pytest.mark.skipif(sys.platform == "win32", reason="uses XLA_FLAGS in a subprocess")
def test_sweep_sharded_equals_single_device():
    """With 4 forced CPU devices the sharded sweep equals the unsharded result to round-off."""
    code = textwrap.dedent(
        """
        import jax
        jax.config.update("jax_enable_x64", True)
        import jax.numpy as jnp, numpy as np
        import hrgjax as hg
        assert jax.device_count() == 4
        gyro = hg.presets.ideal(hg.presets.tvg3_like().resonator)  # ideal loops: a light compile
        def f(temperature_c, rate_dps):
            prof = hg.Profile.constant_rate(rate_dps, 5.0, temperature_c)
            return hg.simulate(gyro, prof, dt_out=5.0).wave_angle[-1]
        T, W = jnp.array([-40.0, 0.0, 60.0]), jnp.array([0.1, 5.0])
        out = hg.sweep(f, temperature_c=T, rate_dps=W)
        chunked = hg.sweep(f, temperature_c=T, rate_dps=W, chunk_size=3)  # 2 chunks of 4
        ref = jax.jit(jax.vmap(lambda t: jax.vmap(lambda w: f(t, w))(W)))(T)  # one device
        np.save(__import__("sys").argv[1],
                np.stack([np.asarray(out), np.asarray(chunked), np.asarray(ref)]))
        """
    )
    out = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"sweep_{os.getpid()}.npy")
    env = dict(
        os.environ,
        XLA_FLAGS=f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=4",
        JAX_PLATFORMS="cpu",
    )
    subprocess.run([sys.executable, "-c", code, out], check=True, env=env, timeout=300)
    sharded, chunked, single = np.load(out)
    os.remove(out)
    assert sharded.shape == (3, 2)
    # A device's share (2 of 6 members) and a chunk are batches of other lengths, which
    # XLA:CPU may round differently by an ulp that the adaptive step control carries to the
    # end (measured: ≤ 1e-13 relative; equal to the bit with XLA's default emitters).
    np.testing.assert_allclose(sharded, single, rtol=1e-12, atol=0)
    np.testing.assert_allclose(chunked, single, rtol=1e-12, atol=0)


_TWO_PROCESS = textwrap.dedent(
    """
    import sys
    import jax
    jax.config.update("jax_enable_x64", True)
    rank, port, out = int(sys.argv[1]), sys.argv[2], sys.argv[3]
    try:
        jax.distributed.initialize(
            coordinator_address=f"127.0.0.1:{port}", num_processes=2, process_id=rank,
            initialization_timeout=60,
        )
        from jax.experimental import multihost_utils
        multihost_utils.process_allgather(jax.numpy.zeros(1), tiled=True)
    except Exception as exc:  # no multi-process CPU runtime or collectives here
        print(f"UNAVAILABLE: {type(exc).__name__}: {exc}", flush=True)
        sys.exit(77)
    import jax.numpy as jnp, numpy as np
    import hrgjax as hg
    assert jax.process_count() == 2 and jax.local_device_count() == 2
    gyro = hg.presets.tvg3_like(noise=False)
    def f(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 5.0, temperature_c)
        return hg.simulate(gyro, prof, dt_out=5.0).wave_angle[-1]
    T, W = jnp.array([-40.0, 0.0, 60.0]), jnp.array([0.1, 5.0, 100.0])
    whole = hg.sweep(f, temperature_c=T, rate_dps=W)        # 9 points: 5 + 5 (one padded)
    chunked = hg.sweep(f, temperature_c=T, rate_dps=W, chunk_size=2)
    np.save(out, np.stack([whole, chunked]))
    jax.distributed.shutdown()
    """
)


@pytest.mark.slow(
    "~45 s: two JAX processes under jax.distributed, each compiling the simulation cold; "
    "fast tier: the sharded sweep on 4 devices (test_sweep_sharded_equals_single_device), "
    "the process split's ordering "
    "(test_sweep_orders_members_by_estimated_steps_and_returns_the_grid_order)"
)
@pytest.mark.skipif(sys.platform == "win32", reason="uses XLA_FLAGS in subprocesses")
def test_two_process_sweep_equals_one_process():
    """Two processes on localhost (127.0.0.1 coordinator, two forced CPU devices each) run
    one sweep under jax.distributed: both return the same whole grid, equal to one process's
    jitted vmap to the last bits. Skipped, with the reason printed by the worker, only where this JAX
    build has no multi-process CPU runtime or CPU collectives (gloo)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    tmp = os.environ.get("TMPDIR", "/tmp")
    outs = [os.path.join(tmp, f"sweep2p_{os.getpid()}_{r}.npy") for r in (0, 1)]
    env = dict(
        os.environ,
        XLA_FLAGS=f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=2",
        JAX_PLATFORMS="cpu",
    )
    procs = [
        subprocess.Popen(
            [sys.executable, "-c", _TWO_PROCESS, str(r), str(port), outs[r]],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for r in (0, 1)
    ]
    try:
        logs = [p.communicate(timeout=300)[0] for p in procs]
    finally:
        for p in procs:
            p.kill()
    codes = [p.returncode for p in procs]
    if 77 in codes:
        reason = next(line for log in logs for line in log.splitlines() if "UNAVAILABLE" in line)
        pytest.skip(f"two-process CPU run not possible with this JAX build: {reason}")
    assert codes == [0, 0], "\n".join(log[-3000:] for log in logs)
    results = [np.load(o) for o in outs]
    for o in outs:
        os.remove(o)

    gyro = hg.presets.tvg3_like(noise=False)

    def f(t, w):
        return hg.simulate(gyro, hg.Profile.constant_rate(w, 5.0, t), dt_out=5.0).wave_angle[-1]

    T, W = jnp.array([-40.0, 0.0, 60.0]), jnp.array([0.1, 5.0, 100.0])
    single = np.asarray(jax.jit(jax.vmap(lambda t: jax.vmap(lambda w: f(t, w))(W)))(T))
    # Every process gathers the same whole result, bit for bit.
    np.testing.assert_array_equal(results[0], results[1])
    for whole, chunked in results:
        assert whole.shape == (3, 3)
        # Equal to one process up to the last bits: XLA:CPU's code for a vmapped batch
        # depends on the batch's length (here 3 points per device, 9 in one process), and
        # a batch of 3 rounds some points differently from one of 9 (measured: ≤ 1e-13).
        np.testing.assert_allclose(whole, single, rtol=1e-12, atol=0)
        np.testing.assert_allclose(chunked, single, rtol=1e-12, atol=0)


def test_chunked_sweep_equals_one_batch_and_reports_progress(capsys):
    """Memory-bounded chunks (the last one padded) give the one-batch result bit for bit,
    pytrees included; a bad chunk size is an error naming it."""

    def f(a, b):
        return {"x": jnp.sin(a) * jnp.exp(-b), "y": jnp.stack([a + b, a * b])}

    a, b = jnp.linspace(0.0, 3.0, 7), jnp.array([0.5, 1.0, 2.0])
    whole = hg.sweep(f, a=a, b=b)
    for chunk in (1, 4, 21, 50):
        # progress 0/1 (ints) are False/True, as before the flag check
        part = hg.sweep(f, a=a, b=b, chunk_size=chunk, progress=int(chunk == 4))
        assert part["x"].shape == (7, 3) and part["y"].shape == (7, 3, 2)
        np.testing.assert_array_equal(part["x"], whole["x"])
        np.testing.assert_array_equal(part["y"], whole["y"])
    assert "sweep" in capsys.readouterr().err
    with pytest.raises(ValueError, match="chunk_size must be a positive"):
        hg.sweep(f, a=a, b=b, chunk_size=0)
    for bad in ("no", 2, 1.0):
        with pytest.raises(TypeError, match=r"^sweep: progress must be True or False"):
            hg.sweep(f, a=a, b=b, progress=bad)


def test_a_sweep_differentiates_and_compiles_in_the_callers_transformations():
    """d/dc Σ c·a²·b over the grid is Σ a²·b, whole, chunked (whose chunks went through the
    host: TracerArrayConversionError) and ordered by a cost, under `jax.grad` and `jax.jit`."""
    a, b = jnp.linspace(0.0, 1.0, 30), jnp.linspace(1.0, 2.0, 3)
    exact = float(jnp.sum(a[:, None] ** 2 * b[None]))

    def total(c, **kw):
        return jnp.sum(hg.sweep(lambda a, b: c * a**2 * b, a=a, b=b, **kw))

    for kw in ({}, {"chunk_size": 7}, {"cost": lambda a, b: -a}):
        assert float(jax.grad(total)(0.7, **kw)) == pytest.approx(exact, rel=1e-12), kw
        jitted = jax.jit(lambda c, kw=kw: total(c, **kw))
        assert float(jitted(0.7)) == pytest.approx(0.7 * exact, rel=1e-12), kw


def test_a_chunked_sweep_compiles_its_chunk_once_and_a_second_sweep_nothing():
    """The chunks of one sweep (the last padded) share one compiled program, and a second
    sweep of the same `fn` on grids of the same sizes compiles nothing — also when `fn` is a
    callable equinox Module, which cannot be hashed (it was compiled afresh every sweep)."""
    import equinox as eqx

    class Scaled(eqx.Module):
        k: jax.Array

        def __call__(self, a, b):
            return jnp.sin(a) * self.k + b

    def plain(a, b):
        return jnp.cos(a) - b

    a, b = jnp.linspace(0.0, 1.0, 5), jnp.array([0.5, 2.0])  # 10 points: chunks 3+3+3+1
    for fn in (plain, Scaled(jnp.asarray(2.0))):
        with CompileCounter() as first:
            one = hg.sweep(fn, a=a, b=b, chunk_size=3)
        assert first.names.count("jit(<lambda>)") == 1, first.names
        with CompileCounter() as again:
            two = hg.sweep(fn, a=a, b=b, chunk_size=3)
        assert again.compiles == 0, again.names
        np.testing.assert_array_equal(two, one)
        np.testing.assert_allclose(
            one, jax.vmap(jax.vmap(fn, (None, 0)), (0, None))(a, b), rtol=1e-15
        )
    # the kept programs do not keep the swept function (and the arrays it holds) alive
    gone = []
    for fn in (lambda a, b: a - b, Scaled(jnp.ones(1000))):
        hg.sweep(fn, a=a, b=b)
        gone.append(weakref.ref(fn))
        del fn
    gc.collect()
    assert [r() for r in gone] == [None, None]


def test_a_bad_grid_or_a_failed_check_inside_is_one_line(caplog):
    """A grid with NaN is refused before anything runs; a check that fails inside `fn` (an
    `eqx.error_if`, as `simulate` puts on traced parameters) is raised as one line, and JAX
    logs no callback traceback for it."""
    import equinox as eqx

    def f(a):
        return eqx.error_if(a, a > 1.0, "a must be at most 1")

    with pytest.raises(ValueError, match=r"sweep grid 'a' must be finite; a\[1\] is nan"):
        hg.sweep(f, a=jnp.array([0.0, jnp.nan]))
    with caplog.at_level("ERROR"), pytest.raises(RuntimeError) as err:
        hg.sweep(f, a=jnp.array([0.0, 2.0]))
    assert str(err.value) == "sweep: at one or more grid points, a must be at most 1"
    assert not [r for r in caplog.records if r.name.startswith("jax")]
    np.testing.assert_array_equal(hg.sweep(f, a=jnp.array([0.0, 0.5])), [0.0, 0.5])
    # the compiled batch run again (a repeat sweep; a later chunk): JAX's fast path reports
    # the failed check as a ValueError ("INTERNAL: CpuCallback error"), still one line here
    for chunks in ({}, {"chunk_size": 1}):
        with caplog.at_level("ERROR"), pytest.raises(RuntimeError) as err:
            hg.sweep(f, a=jnp.array([0.0, 2.0]), **chunks)
        assert str(err.value) == "sweep: at one or more grid points, a must be at most 1"
    assert not [r for r in caplog.records if r.name.startswith("jax")]
    # 1 000 points of 10⁶ float64 each (8 GB): refused from the output shapes alone
    big = lambda a: jnp.full(1_000_000, a)  # noqa: E731
    with pytest.raises(ValueError, match=r"take 7.45 GiB \(8000000 bytes a point\)"):
        hg.sweep(big, a=jnp.arange(1000.0), chunk_size=10)


def test_sweep_orders_members_by_estimated_steps_and_returns_the_grid_order():
    """Members of very different cost (rate innermost, shuffled) are sorted by the solver
    steps `simulate` is estimated to take and chunked; results come back in the grid's order,
    equal to the unordered sweep to round-off (the same program computes each member; XLA:CPU
    may round it by an ulp differently at another place in the batch), and the estimate
    follows the steps the solver really takes."""
    from hrgjax import _cost
    from hrgjax.simulate import simulate_with_stats

    gyro = hg.presets.tvg3_like(noise=False)

    def f(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 10.0, temperature_c)
        return hg.simulate(gyro, prof, dt_out=10.0).wave_angle[-1]

    T, W = jnp.array([-40.0, 60.0]), jnp.array([400.0, 0.1, 100.0, 1.0, 20.0, 5.0])
    tt, ww = (m.ravel() for m in jnp.meshgrid(T, W, indexing="ij"))
    from hrgjax.sweep import member_costs

    costs = member_costs(f, "auto", {"temperature_c": tt, "rate_dps": ww})
    assert costs is not None  # the probe reached simulate
    # under the caller's jit the estimate is traced: grid order that time, and `f` keeps
    # its estimate for eager sweeps (it was switched off for good)
    grid = {"temperature_c": tt, "rate_dps": ww}
    assert jax.jit(lambda: (member_costs(f, "auto", grid), 0.0)[1])() == 0.0
    np.testing.assert_array_equal(member_costs(f, "auto", grid), costs)
    order, chunk = _cost.plan(costs, 1, "cpu")
    assert np.all(np.diff(np.abs(np.asarray(ww))[order]) >= 0)  # cheapest (slowest) first
    # the chunk size follows the number of members, not their costs (one compiled batch per
    # grid size): 12 members run as one batch, 256 in chunks of 52
    assert chunk == _cost.plan(np.ones(12), 1, "cpu")[1] == 12
    assert _cost.chunk_length(256, 1, "cpu") == 52 and _cost.chunk_length(256, 1, "gpu") == 256
    # the estimate against the solver's accepted steps (10-s runs)
    for w in (0.1, 5.0, 400.0):
        prof = hg.Profile.constant_rate(w, 10.0, 20.0)
        steps = int(simulate_with_stats(gyro, prof, dt_out=10.0)[1])
        assert 0.5 < float(_cost.steps_estimate(gyro, prof)) / steps < 2.0, (w, steps)

    plain = hg.sweep(f, cost=None, temperature_c=T, rate_dps=W, chunk_size=4)
    ordered = hg.sweep(f, temperature_c=T, rate_dps=W, chunk_size=4)
    reverse = hg.sweep(f, cost=lambda temperature_c, rate_dps: -rate_dps, temperature_c=T,
                       rate_dps=W, chunk_size=4)  # fmt: skip
    np.testing.assert_allclose(ordered, plain, rtol=1e-12, atol=0)
    np.testing.assert_allclose(reverse, plain, rtol=1e-12, atol=0)
    auto = hg.sweep(f, temperature_c=T, rate_dps=W)  # chunks of its own choosing
    np.testing.assert_allclose(auto, plain, rtol=1e-12, atol=0)
    assert float(auto[1, 0]) == pytest.approx(float(f(60.0, 400.0)), rel=1e-12)
    # rates of alike cost on a grid of the same sizes: nothing compiles (the estimate picked
    # the chunk size, and one batch of 12 was a new program after chunks of 4)
    T2, W2 = np.asarray(T) + 1.0, np.linspace(1.0, 1.5, 6)
    with CompileCounter() as again:
        alike = hg.sweep(f, temperature_c=T2, rate_dps=W2)
    assert again.compiles == 0, again.names
    assert alike.shape == (2, 6)
    with pytest.raises(ValueError, match="cost must be"):
        hg.sweep(f, cost="fast", temperature_c=T, rate_dps=W)
    with pytest.raises(ValueError, match="one per point"):
        hg.sweep(f, cost=lambda **_: 1.0, temperature_c=T, rate_dps=W)


def test_new_costs_on_a_grid_of_the_same_sizes_compile_nothing():
    """The chunk size of a sweep ordered by cost depends on the grid's size only: grids of the
    same sizes whose members cost alike, then 10⁴× apart, then in the other order, run
    through one compiled batch, with no eager program for ordering or slicing the chunks
    (the estimate picked the chunk size: one batch of 16, then chunks of 4, each compiled,
    with 11 small eager programs a chunk shape). Results in the grid's order."""

    def f(a, b):
        return jnp.sin(a) * b

    b = jnp.array([1.0, 2.0])
    costs = (lambda a, b: 1.0 + 0 * a, lambda a, b: 10.0 ** (4 * a), lambda a, b: -a)
    hg.sweep(f, cost=costs[0], a=jnp.linspace(0.0, 1.0, 8), b=b)  # compiles its batch
    for i, cost in enumerate(costs):
        a = jnp.linspace(0.0, 1.0, 8) + 0.1 * i
        with CompileCounter() as c:
            out = hg.sweep(f, cost=cost, a=a, b=b)
        assert c.compiles == 0, (i, c.names)
        np.testing.assert_allclose(out, jnp.sin(a)[:, None] * b[None, :], rtol=1e-15)


def test_sweep_of_a_gradient_through_simulate_orders_by_the_undifferentiated_estimate():
    """A `fn` that differentiates `simulate` (`jax.value_and_grad`) is swept with the default
    `cost="auto"`: the probe's estimate is the undifferentiated run's (no tracer of the
    gradient escapes it), the result equals `cost=None` bit for bit and a central difference
    of the values (the same compiled batch on a grid of the same size); a `fn` whose estimate
    cannot leave its own transformation (its own `jax.jit`) falls back to the grid's order."""
    from hrgjax.sweep import member_costs

    gyro = hg.presets.ideal(hg.presets.tvg3_like().resonator)  # ideal loops: a light compile

    def angle(rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, 5.0, 20.0)
        return hg.simulate(gyro, prof, dt_out=5.0).wave_angle[-1]

    def slope(rate_dps):  # the angle and its derivative
        return jax.value_and_grad(angle)(rate_dps)

    W = jnp.array([0.5, 5.0])
    flat = {"rate_dps": W}
    np.testing.assert_array_equal(
        member_costs(slope, "auto", flat), member_costs(angle, "auto", flat)
    )
    assert member_costs(lambda rate_dps: jax.jit(slope)(rate_dps), "auto", flat) is None
    _, auto = hg.sweep(slope, rate_dps=W)
    np.testing.assert_array_equal(auto, hg.sweep(slope, rate_dps=W, cost=None)[1])
    h = 1e-4
    (lo, hi), _ = hg.sweep(slope, rate_dps=W[1] + jnp.array([-h, h]), cost=None)
    assert float(auto[1]) == pytest.approx(float(hi - lo) / (2 * h), rel=1e-7)
