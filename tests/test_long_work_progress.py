"""Long work in host-side steps behind a progress bar gives the same results bit for bit:
`hg.allan.deviation` above `STEPPED_COST` of estimated work and `hg.ins.mechanize` above
`CHUNK_STEPS` steps, here forced on small cases; under a caller's trace, one scan, no bar."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hrgjax as hg
import hrgjax.allan.result as allan_result
import hrgjax.ins.mechanization as mech

jax.config.update("jax_enable_x64", True)


class _Recorder:
    """A stand-in for `hrgjax._progress.bar` that records what it was told."""

    calls = []

    def __init__(self, total, desc, unit="step"):
        self.total, self.n = total, 0
        _Recorder.calls.append(self)

    def update(self, n=1):
        self.n += n

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


def _fields(result):
    return [np.asarray(getattr(result, f)) for f in
            ("taus", "m", "dev", "dev_low", "dev_high", "edf", "n_terms", "alpha")]  # fmt: skip


@pytest.mark.parametrize("kind", ["oadev", "hdev"])
def test_allan_deviation_in_steps_equals_the_whole(monkeypatch, kind):
    rng = np.random.default_rng(3)
    y = rng.standard_normal(3000) * 0.01 + np.cumsum(rng.standard_normal(3000)) * 1e-3 + 5.0
    whole = hg.allan.deviation(y, 100.0, kind=kind)
    monkeypatch.setattr(allan_result, "STEPPED_COST", 1)
    monkeypatch.setattr(allan_result, "bar", _Recorder)
    _Recorder.calls.clear()
    stepped = hg.allan.deviation(y, 100.0, kind=kind)
    for a, b in zip(_fields(whole), _fields(stepped), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=0)  # one arithmetic, two programs
    (progress,) = _Recorder.calls
    assert progress.n == progress.total == 1 + 2 * whole.m.size


@pytest.mark.parametrize("kind", ["mtotdev", "ttotdev"])
def test_modified_total_kinds_step_by_their_cost_not_the_sample_count(monkeypatch, kind):
    """Audit: mtotdev's cost grows as N² (Σ 9m(N − 3m + 1) points: 3.7 s at 10⁴ samples, 58 s
    at 4·10⁴) and `deviation` went behind a bar only from 4·10⁶ samples. It now steps by the
    estimated work: one bar counting the points of each factor, the same values."""
    rng = np.random.default_rng(5)
    y = rng.standard_normal(400) + np.cumsum(rng.standard_normal(400)) * 0.05
    whole = hg.allan.deviation(y, 10.0, kind=kind)
    work = allan_result.work_estimate(kind, y.size + 1, whole.m)
    assert work == sum(9 * m * (y.size + 1 - 3 * m + 1) for m in whole.m.tolist())
    monkeypatch.setattr(allan_result, "bar", _Recorder)
    _Recorder.calls.clear()
    hg.allan.deviation(y, 10.0, kind=kind)
    assert _Recorder.calls == []  # ≈ 3·10⁵ points, a few ms: no bar
    # the cost, not the count: 10⁴ samples of mtotdev (≈ 5 s) step, 10⁶ of oadev (≈ 0.5 s) not
    octaves = lambda n: 2 ** np.arange(int(np.log2(n)))  # noqa: E731
    ms = octaves(10_001)[3 * octaves(10_001) < 10_001]
    assert allan_result.work_estimate(kind, 10_001, ms) > allan_result.STEPPED_COST
    ms = octaves(1_000_001)[2 * octaves(1_000_001) < 1_000_001]
    assert allan_result.work_estimate("oadev", 1_000_001, ms) < allan_result.STEPPED_COST
    monkeypatch.setattr(allan_result, "STEPPED_COST", work)
    stepped = hg.allan.deviation(y, 10.0, kind=kind)
    for a, b in zip(_fields(whole), _fields(stepped), strict=True):
        np.testing.assert_array_equal(a, b)
    (progress,) = _Recorder.calls
    assert progress.n == progress.total == 1 + whole.m.size + work


def test_curve_parts_equal_the_curve(monkeypatch):
    y = jnp.asarray(np.random.default_rng(4).standard_normal(500))
    ms = np.asarray([1, 2, 3, 5, 8, 13, 21])
    whole = np.asarray(hg.allan.deviations.curve(y, jnp.asarray(ms), 0.1, "oadev"))
    parts = hg.allan.deviations.curve_parts(y, ms, 0.1, "oadev", chunk=3)
    assert [p.shape for p in parts] == [(3,)] * 3
    np.testing.assert_allclose(
        np.concatenate([np.asarray(p) for p in parts])[:7], whole, rtol=1e-12
    )
    monkeypatch.setattr(hg.allan.deviations, "CURVE_STEPPED_FROM", 1)
    taus, devs = hg.allan.allan_deviation(y, 0.1, ms)
    assert isinstance(devs, jax.Array)
    np.testing.assert_allclose(np.asarray(devs), whole, rtol=1e-12)


def _increments(n, dt):
    t = np.arange(n) * dt
    dth = np.stack([1e-3 * np.sin(t), 2e-4 * np.cos(3 * t), np.full(n, 5e-5)], 1) * dt
    dv = np.stack([0.3 * np.sin(t / 5), 0.1 * np.cos(t), np.full(n, -9.79)], 1) * dt
    return dth, dv


def test_mechanize_in_chunks_is_bit_identical(monkeypatch):
    n, dt, every = 50, 0.01, 1  # chunks of 16 steps, the last one of 2 (< UNROLL)
    dth, dv = _increments(n, dt)
    init = mech.NavState.from_euler(0.7, 0.2, 100.0, jnp.array([1.0, 2.0, 0.0]), 0.01, -0.02, 1.0)
    whole = mech.mechanize(init, dth, dv, dt, every=every)
    monkeypatch.setattr(mech, "CHUNK_STEPS", 16)
    monkeypatch.setattr(mech, "bar", _Recorder)
    _Recorder.calls.clear()
    chunked = mech.mechanize(init, dth, dv, dt, every=every)
    for a, b in zip(jax.tree_util.tree_leaves(whole), jax.tree_util.tree_leaves(chunked),
                    strict=True):  # fmt: skip
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-12)
    (progress,) = _Recorder.calls
    assert progress.n == progress.total == n
    # under a caller's jit, vmap or grad: one scan, no bar (traced, not compiled here)
    _Recorder.calls.clear()
    run = lambda a: mech.mechanize(init, a, dv, dt, every=every).lat[-1]  # noqa: E731
    for traced, arg, scans in ((jax.jit(run), dth, 1), (jax.vmap(run), dth[None], 1),
                               (jax.grad(run), dth, 2)):  # fmt: skip
        assert str(jax.make_jaxpr(traced)(arg)).count("scan[") == scans  # one, not chunks
    assert _Recorder.calls == []


def test_a_ticking_bar_redraws_until_closed(monkeypatch):
    """A bar over units of many seconds (one compiled call: discovery's fits, a vmapped
    batch of flights) ticks: redrawn by a daemon thread every `TICK_S` s, so a terminal is
    never silent while its count cannot move; closing it stops the thread."""
    import threading
    import time

    from hrgjax import _progress

    monkeypatch.delenv("HRGJAX_QUIET", raising=False)
    monkeypatch.setattr(_progress, "_stderr_is_terminal", lambda: True)
    monkeypatch.setattr(_progress, "TICK_S", 0.02)
    with _progress.bar(1, "one long unit", tick=True) as progress:
        drawn = []
        refresh = progress.refresh
        progress.refresh = lambda *a, **k: (drawn.append(time.monotonic()), refresh(*a, **k))
        time.sleep(0.3)
        progress.update(1)
    assert len(drawn) >= 3  # ~15 redraws in 0.3 s; a loaded machine still gives a few
    time.sleep(0.1)
    assert not any(t.name == "hrgjax-progress-tick" for t in threading.enumerate())
    with _progress.bar(1, "plain") as plain:  # without tick: no thread
        assert not any(t.name == "hrgjax-progress-tick" for t in threading.enumerate())
        plain.update(1)
