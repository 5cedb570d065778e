"""A long eager `hg.simulate` solves in parts behind a progress bar (`hrgjax._solve_parts`)
with the same results (the same steps; values bit for bit with XLA's default flags), noise
included; here forced on a short run by lowering
the thresholds. Under a caller's trace: one program, no bar."""

import functools
import importlib
import types

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

import hrgjax as hg
import hrgjax._solve_parts as parts

jax.config.update("jax_enable_x64", True)
simulate_module = importlib.import_module("hrgjax.simulate")


class _Recorder:
    """A stand-in for `hrgjax._progress.bar` that records what it was told."""

    calls = []

    def __init__(self, total, desc, unit="step"):
        self.total, self.n, self.updates = total, 0.0, 0
        _Recorder.calls.append(self)

    def update(self, n=1):
        self.n += n
        self.updates += 1

    def set_postfix_str(self, text):
        self.postfix = text

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        pass


@pytest.fixture(scope="module")
def run():
    """A noisy 3-knot run of the default gyro (a rate step: clipped steps at the knots)."""
    gyro = hg.presets.tvg3_like()
    profile = hg.Profile.piecewise([0.0, 40.0, 90.0, 200.0], [0.0, 20.0, 20.0, -5.0], 25.0)
    key = jax.random.key(7)
    whole = simulate_module.simulate_with_stats(gyro, profile, key=key, dt_out=0.05)
    return gyro, profile, key, whole


def test_simulate_in_parts_gives_the_same_record_and_shows_progress(run, monkeypatch):
    gyro, profile, key, whole = run
    monkeypatch.setattr(parts, "STEPPED_FROM", 1)
    monkeypatch.setattr(parts, "PART_STEPS", 40)
    monkeypatch.setattr(parts, "PART_OUTPUTS", 256)
    monkeypatch.setattr(parts, "bar", _Recorder)
    _Recorder.calls.clear()
    stepped = simulate_module.simulate_with_stats(gyro, profile, key=key, dt_out=0.05)
    held = []  # the parts' outputs, as run_parts joins them

    def concatenate(arrays, *args, **kwargs):
        if len(arrays) > 2:  # not a window padded (2 arrays)
            held.extend(arrays)
        return np.concatenate(arrays, *args, **kwargs)

    monkeypatch.setattr(
        parts, "np", types.SimpleNamespace(**{**vars(np), "concatenate": concatenate})
    )
    with CompileCounter() as counter:  # the same shapes again: nothing compiled
        again = simulate_module.simulate_with_stats(gyro, profile, key=key, dt_out=0.05)
    assert counter.compiles == 0, counter.names
    # each part's outputs copied: a view pins the part's whole window buffer (12 parts of a
    # run needing 160 KB held 3.1 MB; a 2^20-sample full-model run would hold ~25 GB)
    assert len(held) > 5 and all(a.base is None for a in held), [a.base for a in held[:3]]
    np.testing.assert_array_equal(again[0].wave_angle, stepped[0].wave_angle)
    (progress, _) = _Recorder.calls
    assert progress.updates > 5 and progress.n == progress.total == 200.0
    assert progress.postfix == "readout and noise"  # shown while the record is computed
    assert int(stepped[1]) == int(whole[1]) and bool(stepped[2] == whole[2])
    for name, a in vars(whole[0]).items():
        if isinstance(a, jax.Array):  # the record's arrays, noise and all
            b = getattr(stepped[0], name)
            # bit for bit with XLA's defaults (benchmarks/simulate_progress.py; rechecked
            # with rtol and atol as the programs' values, 2026-12-02); the tests' quick
            # compile flags leave round-off between the programs, which the adaptive solve
            # carries on (to 2.3e-7 in the quadrature force here, 1.1e-6 of it, where the
            # tolerances were constants folded into both programs 8e-8)
            np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-9, err_msg=name)


def test_simulate_in_parts_keeps_max_steps(run, monkeypatch):
    gyro, profile, key, whole = run
    monkeypatch.setattr(parts, "STEPPED_FROM", 1)
    monkeypatch.setattr(parts, "PART_STEPS", 40)
    monkeypatch.setattr(parts, "PART_OUTPUTS", 256)
    with pytest.raises(RuntimeError, match="maximum number of solver steps"):
        # a whole number of parts short of the run: no other program than the test above's
        hg.simulate(gyro, profile, key=key, dt_out=0.05, max_steps=40 * (int(whole[1]) // 40))


def test_traced_simulate_is_one_program_without_bar(monkeypatch):
    monkeypatch.setattr(parts, "STEPPED_FROM", 1)
    monkeypatch.setattr(parts, "bar", _Recorder)
    _Recorder.calls.clear()
    gyro = hg.presets.tvg3_like().without_noise()
    profile = hg.Profile.static(20.0)
    jaxpr = jax.make_jaxpr(lambda g: hg.simulate(g, profile).wave_angle)(gyro)
    assert _Recorder.calls == [] and "while" in str(jaxpr)


def _decay_in_parts(solver, controller, dt0, ts, steps, outputs, monkeypatch):
    """dy/dt = -y, y(0) = 1 on [0, 2] s solved in parts (`run_parts`, `solve_part`) and as
    one `diffeqsolve`: ((values at `ts`, steps, result) in parts, the one solution)."""
    monkeypatch.setattr(parts, "PART_STEPS", steps)
    monkeypatch.setattr(parts, "PART_OUTPUTS", outputs)
    monkeypatch.setattr(parts, "bar", _Recorder)
    term, y0, adjoint = (
        diffrax.ODETerm(lambda t, y, a: -y),
        jnp.ones(1),
        diffrax.RecursiveCheckpointAdjoint(),
    )

    @functools.partial(jax.jit, static_argnums=3)
    def part(window, stop, resume, steps):
        return parts.solve_part(term, solver, controller, 0.0, 2.0, dt0, y0, None, adjoint,
                                window, stop, resume, steps)  # fmt: skip

    stepped = parts.run_parts(part, ts, [0.0, 2.0], 4096, jnp.asarray)
    one = diffrax.diffeqsolve(term, solver, 0.0, 2.0, dt0, y0, saveat=diffrax.SaveAt(ts=ts),
                              stepsize_controller=controller, max_steps=4096)  # fmt: skip
    return stepped, one


def test_parts_save_the_outputs_within_the_first_step(monkeypatch):
    # a constant step (0.5 s) longer than the first part's window (4 outputs of 0.05 s): the
    # first step is checked against the window too (it was not: every later part saved
    # nothing, the outputs past 0.15 s were left inf and simulate raised "NaN or inf")
    ts = np.linspace(0.0, 2.0, 41)
    stepped, one = _decay_in_parts(diffrax.Tsit5(), diffrax.ConstantStepSize(), 0.5, ts, 40,
                                   4, monkeypatch)  # fmt: skip
    (values, steps, result) = stepped
    assert steps == int(one.stats["num_steps"]) == 4 and result == diffrax.RESULTS.successful
    np.testing.assert_allclose(values, one.ys, rtol=1e-12)
    np.testing.assert_allclose(values[:, 0], np.exp(-ts), rtol=1e-4)  # Tsit5 at h = 0.5 s


def test_parts_run_an_implicit_solver(monkeypatch):
    # the parts' controller stays adaptive, so diffeqsolve hands its rtol/atol/norm to
    # Kvaerno5's root finder (it refused: "A fixed step size controller is being used
    # alongside an implicit solver"); the same steps and values as the one solve
    ts = np.linspace(0.0, 2.0, 41)
    pid = diffrax.PIDController(rtol=1e-8, atol=1e-10)
    controller = diffrax.ClipStepSizeController(pid, jump_ts=jnp.array([1.0]))  # as simulate
    stepped, one = _decay_in_parts(diffrax.Kvaerno5(), controller, 0.01, ts, 4, 4, monkeypatch)
    (values, steps, result) = stepped
    assert steps == int(one.stats["num_steps"]) > 12 and result == diffrax.RESULTS.successful
    np.testing.assert_allclose(values, one.ys, rtol=1e-12)
    np.testing.assert_allclose(values[:, 0], np.exp(-ts), rtol=1e-6)  # rtol 1e-8, interpolated


def test_parts_give_way_where_a_part_ends_on_a_jump_knot(monkeypatch):
    # a part whose last step is the one clipped at a jump knot (1.0 s, an output) ends just
    # beyond it without saving that output, which no later part can save (review: every
    # output from the knot on was left inf and simulate raised "NaN or inf"); run_parts says
    # so and simulate solves in one program instead (the same results, no bar)
    ts = np.linspace(0.0, 2.0, 41)
    pid = diffrax.PIDController(rtol=1e-8, atol=1e-10)
    controller = diffrax.ClipStepSizeController(pid, jump_ts=jnp.array([1.0]))  # as simulate
    with pytest.raises(parts.Unresumable):
        _decay_in_parts(diffrax.Tsit5(), controller, 0.01, ts, 1, 4096, monkeypatch)
