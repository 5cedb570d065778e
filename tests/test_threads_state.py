"""Process-wide state that one caller's action must not change for another: `plausible.relaxed`
is per thread and ends with its block, `sweep(obj.method, …)` reuses its compiled batch, and
drawing a figure leaves the user's matplotlib backend as it was."""

import gc
import threading
import weakref

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

import hrgjax as hg
from hrgjax import plausible, plots


def test_relaxed_is_per_thread_and_ends_with_its_block():
    """A enters, B enters, A leaves, B leaves: B never sees A's widened range (a kelvin
    column is refused in B), and both ranges are the defaults afterwards."""
    default = dict(plausible.RANGES)
    a_in, b_checked, a_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def a():
        with plausible.relaxed(temperature_c=(-200.0, 400.0)):
            seen["A inside"] = plausible.RANGES["temperature_c"]
            a_in.set()
            b_checked.wait(10)
        a_out.set()

    def b():
        a_in.wait(10)
        with plausible.relaxed(speed_mps=(0.0, 1e6)):
            seen["B temperature"] = plausible.RANGES["temperature_c"]
            try:
                plausible.check("temperature_c", [300.15, 310.0])
                seen["B kelvin"] = "accepted"
            except ValueError:
                seen["B kelvin"] = "refused"
            b_checked.set()
            a_out.wait(10)
            seen["B speed"] = plausible.RANGES["speed_mps"]

    threads = [threading.Thread(target=a), threading.Thread(target=b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen["A inside"][:2] == (-200.0, 400.0)
    assert seen["B temperature"] == default["temperature_c"]
    assert seen["B kelvin"] == "refused"
    assert seen["B speed"][:2] == (0.0, 1e6)  # A leaving does not end B's block
    assert dict(plausible.RANGES) == default
    with pytest.raises(ValueError, match="kelvin"):
        plausible.check("temperature_c", [300.15, 310.0])


def test_relaxed_nests_and_keys_sweep_batches():
    """Blocks nest in one thread; `RANGES.items()` (the key `sweep` compiles per) follows."""
    default = tuple(sorted(plausible.RANGES.items()))
    with plausible.relaxed(temperature_c=(-200.0, 200.0)):
        with plausible.relaxed(speed_mps=(0.0, 1e6)):
            assert plausible.RANGES["temperature_c"][:2] == (-200.0, 200.0)
            assert tuple(sorted(plausible.RANGES.items())) != default
        assert plausible.RANGES["speed_mps"] == dict(default)["speed_mps"]
    assert tuple(sorted(plausible.RANGES.items())) == default


class _Study:
    def __init__(self, gain):
        self.gain = gain

    def scaled(self, x):
        return self.gain * jnp.sin(x)


def test_sweep_of_a_bound_method_compiles_once():
    """`hg.sweep(obj.method, …)` (a new bound-method object at each access) reuses the
    compiled batch; the cache does not keep `obj` alive."""
    study = _Study(2.0)
    grid = np.linspace(0.0, 1.0, 3)
    first = hg.sweep(study.scaled, x=grid)
    with CompileCounter() as c:
        again = hg.sweep(study.scaled, x=grid)
    assert c.traces == 0 and c.compiles == 0
    np.testing.assert_allclose(again, 2.0 * np.sin(grid), rtol=1e-15)
    np.testing.assert_array_equal(first, again)
    other = _Study(3.0)  # another object: its own batch, its own gain
    np.testing.assert_allclose(hg.sweep(other.scaled, x=grid), 3.0 * np.sin(grid), rtol=1e-15)
    gone = weakref.ref(study)
    del study
    gc.collect()
    assert gone() is None


def test_drawing_leaves_the_users_backend(tmp_path):
    """A user on a non-Agg backend (a notebook's, here "svg") keeps it after a figure is drawn,
    and pyplot's open figures are untouched."""
    matplotlib = pytest.importorskip("matplotlib")
    import matplotlib.pyplot as plt

    before = matplotlib.get_backend()
    try:
        matplotlib.use("svg")
        open_before = plt.get_fignums()
        t = np.linspace(0.0, 3600.0, 5)
        path = plots.schuler_figure(t, {"north": t * 1e-3}, str(tmp_path / "s.png"))
        assert matplotlib.get_backend() == "svg"
        assert plt.get_fignums() == open_before
        assert (tmp_path / "s.png").stat().st_size > 0 and path.endswith("s.png")
    finally:
        matplotlib.use(before)
