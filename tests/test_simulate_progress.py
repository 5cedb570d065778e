"""A long eager `hg.simulate` solves in parts behind a progress bar (`hrgjax._solve_parts`)
with the same results (the same steps; values bit for bit with XLA's default flags), noise
included; here forced on a short run by lowering
the thresholds. Under a caller's trace: one program, no bar."""

import importlib

import jax
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
    with CompileCounter() as counter:  # the same shapes again: nothing compiled
        again = simulate_module.simulate_with_stats(gyro, profile, key=key, dt_out=0.05)
    assert counter.compiles == 0, counter.names
    np.testing.assert_array_equal(again[0].wave_angle, stepped[0].wave_angle)
    (progress, _) = _Recorder.calls
    assert progress.updates > 5 and progress.n == progress.total == 200.0
    assert progress.postfix == "readout and noise"  # shown while the record is computed
    assert int(stepped[1]) == int(whole[1]) and bool(stepped[2] == whole[2])
    for name, a in vars(whole[0]).items():
        if isinstance(a, jax.Array):  # the record's arrays, noise and all
            b = getattr(stepped[0], name)
            # bit for bit with XLA's defaults (benchmarks/simulate_progress.py); the tests'
            # quick compile flags leave round-off between the programs, which the adaptive
            # solve carries on (to 8e-8 in the loop outputs here; the solver's rtol is 1e-8)
            np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-9, err_msg=name)


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
