"""The persistent compile cache and the compiled programs it keeps: identical results with,
without and after damage to the cache; callback-free programs land in it; `--help` imports
no JAX; run-time failures still raise under a caller's own jit."""

import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest

import hrgjax as hg
from hrgjax._cache import _intact

_RUN = textwrap.dedent(
    """
    import sys, warnings
    import jax
    import jax.monitoring
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import hrgjax as hg
    traced = []
    jax.monitoring.register_event_duration_secs_listener(
        lambda e, d, **k: traced.append(k.get("fun_name"))
        if e.endswith("jaxpr_trace_duration") else None)
    print("cache:", hg.enable_cache())
    g = hg.presets.tvg3_like()  # its resonator and noise; ideal loops: a light compile
    gyro = hg.Gyro(g.resonator, control=hg.Control(ideal=True), noise=g.noise)
    rec = hg.simulate(gyro, hg.Profile.constant_rate(2.0, 4.0, -10.0, 20.0),
                      key=jax.random.key(3), dt_out=0.5)
    np.save(sys.argv[1], np.stack([rec.wave_angle, rec.amplitude, rec.quadrature]))
    print("simulator traced:", sum(f in ("_solve", "flat") for f in traced))
    """
)


def _run(out, **env):
    full = {k: v for k, v in os.environ.items() if not k.startswith("HRGJAX_")}
    full.update(env)
    proc = subprocess.run(
        [sys.executable, "-c", _RUN, str(out)],
        env=full,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return np.load(out), proc.stdout + proc.stderr


def test_cache_on_off_and_damaged_entries_give_identical_results(tmp_path):
    folder = tmp_path / "cache"
    off, log = _run(tmp_path / "off.npy", HRGJAX_NO_CACHE="1")
    assert "cache: None" in log
    assert "simulator traced: 1" in log  # the traced path
    cold, log = _run(tmp_path / "cold.npy", HRGJAX_CACHE_DIR=str(folder))
    assert "simulator traced: 1" in log  # traced once, to export it
    entries = sorted((folder / "xla").glob("*-cache"))
    # The whole simulate program is kept, traced and lowered (jax.export) and compiled:
    # it carries no host callback.
    exported = sorted((folder / "export").glob("*.exported"))
    assert len(exported) == 1, exported
    assert any(e.name.startswith("jit_run-") for e in entries), [e.name for e in entries]
    warm, log = _run(tmp_path / "warm.npy", HRGJAX_CACHE_DIR=str(folder))
    assert "simulator traced: 0" in log  # the exported program: no trace in a new process
    sizes = {e.name: e.stat().st_size for e in entries}
    for e in entries + exported:  # truncate every entry: each is dropped and rebuilt
        e.write_bytes(e.read_bytes()[: max(e.stat().st_size // 3, 1)])
    damaged, log = _run(tmp_path / "damaged.npy", HRGJAX_CACHE_DIR=str(folder))
    assert "damaged compile-cache entry" in log
    assert "damaged exported program" in log
    rebuilt = {e.name: e for e in (folder / "xla").glob("*-cache")}
    assert set(rebuilt) == set(sizes)  # every damaged entry was written anew, whole
    assert all(_intact(e.read_bytes()) for e in rebuilt.values())
    assert exported[0].stat().st_size > sizes[entries[0].name] // 1000  # written anew
    # Traced, exported and reloaded programs give the same bits.
    for result in (cold, warm, damaged):
        np.testing.assert_array_equal(result, off)
    for sub in ("xla", "export"):  # no half-written entries left
        assert not list((folder / sub).glob(".tmp-*"))


def test_cache_folder_resolution(monkeypatch, tmp_path):
    from hrgjax._cache import cache_dir, cache_disabled

    monkeypatch.delenv("HRGJAX_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "hrgjax"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_dir() == tmp_path / "home" / ".cache" / "hrgjax"
    monkeypatch.setenv("HRGJAX_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_dir() == tmp_path / "mine"
    for value, off in (("1", True), ("yes", True), ("0", False), ("", False)):
        monkeypatch.setenv("HRGJAX_NO_CACHE", value)
        assert cache_disabled() is off


@pytest.mark.parametrize("argv", [["--help"], ["simulate", "--help"], ["discover", "--help"]])
def test_help_imports_no_jax(argv):
    code = (
        "import sys\nfrom hrgjax.cli import main\n"
        f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
        "assert 'jax' not in sys.modules, 'jax was imported'\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "usage: hrgjax" in proc.stdout


def test_solver_failure_raises_a_readable_error_under_jit():
    """Under the caller's own jit the check stays inside the program, as before. (Eagerly,
    with the compile cache on as in every test here, the exported program's readable error:
    test_simulate.py::test_max_steps_raises_not_nan.)"""
    gyro = hg.presets.tvg3_like(noise=False)
    prof = hg.Profile.static(1.0)
    run = jax.jit(lambda: hg.simulate(gyro, prof, model="full", max_steps=50).wave_angle)
    with pytest.raises(Exception, match="maximum number of solver steps"):
        run().block_until_ready()


def test_package_names_resolve_lazily():
    assert callable(hg.simulate) and callable(hg.sweep) and callable(hg.enable_cache)
    import hrgjax.simulate  # noqa: F401  (the submodule import leaves hg.simulate a function)

    assert callable(hg.simulate)
    assert {"simulate", "Profile", "presets", "enable_cache"} <= set(dir(hg))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        hg.nope  # noqa: B018


def _user_function(x):
    return x


def test_export_keys_spell_out_static_values_and_refuse_unknown_code():
    """A program is exported only when its key pins everything its trace depends on."""
    from hrgjax import _export
    from hrgjax.calibration import mlp

    key = lambda *args: _export._signature("p", *jax.tree_util.tree_flatten((args, {})))
    x = np.zeros(3)
    # Static values and array shapes, dtypes and weak types all enter the key.
    assert key(x, 1.0)[0] != key(x, 2.0)[0]
    assert key(x, 1.0)[0] != key(np.zeros(4), 1.0)[0]
    assert key(x, 1.0)[0] != key(x.astype(np.float32), 1.0)[0]
    assert key(x, 1.0)[0] == key(np.ones(3), 1.0)[0]  # values of arrays do not
    assert key(jax.numpy.asarray(1.0), "a")[0] != key(jax.numpy.asarray(1.0, float), "a")[0]
    # hrgjax's and its libraries' functions have stable names; a closure is as stable as what
    # it captured; the user's own code (which the source hash cannot see) is refused.
    assert key(mlp._e2e_loss) is not None and key(jax.numpy.tanh) is not None
    assert key(jax.nn.relu) is not None
    assert key(_user_function) is None
    assert key(lambda v: v) is None
    captured = np.ones(2)
    assert _export._token(lambda: captured) is None
    assert key(hg.presets.tvg3_like()) is not None

    class Mine(hg.TemperatureLaw):  # a subclass of the user's: not hrgjax's code
        pass

    assert key(Mine(1.0)) is None
    # Key arrays cross the boundary as their key data.
    _, dynamic, impls = key(jax.random.key(0))
    assert dynamic == (0,) and impls[0] is not None


def test_an_exported_program_compiles_once_whatever_its_inputs_placement():
    """The exported program's runner is a `jax.jit` keyed on which inputs are committed: a
    committed input (`jax.device_put(x, device)`, or an exported program's own output, always
    committed) after a NumPy or `jnp.asarray` one compiled it a second time (a simulation:
    8-11 s in a cold cache). The inputs are placed first: one compile, the same numbers."""
    from helpers import CompileCounter

    from hrgjax import _export

    if _export.folder() is None:
        pytest.skip("the compile cache is off: nothing is exported")
    x = np.linspace(0.0, 1.0, 7)
    committed = jax.device_put(x, jax.devices()[0])
    assert committed.committed and not jax.numpy.asarray(x).committed
    with CompileCounter() as c:
        outs = [_export.call("placement-test", jax.numpy.sin, (v,), {})
                for v in (x, jax.numpy.asarray(x), committed, jax.numpy.asarray(x))]  # fmt: skip
    assert c.names.count("jit(run)") == 1, c.names  # was 2: again for the committed input
    for out in outs:
        np.testing.assert_array_equal(out, np.sin(x))


def test_single_simulations_run_on_the_cpu_beside_an_accelerator(monkeypatch):
    """Where an accelerator is JAX's default backend, an eager `simulate` (one sequential
    trajectory) runs on the CPU, its program exported for the CPU; under the caller's own
    trace, or inside the caller's `jax.default_device`, placement is left to the caller. Here
    the accelerator is pretended (`jax.default_backend` says "gpu"); the CPU machine runs the
    rest for real."""
    from hrgjax import _compiled, _export

    gyro = hg.presets.ideal(hg.presets.tvg3_like().resonator)  # ideal loops: a light compile
    prof = hg.Profile.constant_rate(2.0, 1.0)
    plain = hg.simulate(gyro, prof)
    seen = []
    real_call = _export.call

    def spy(name, fn, args, kwargs):
        seen.append((jax.config.jax_default_device, _export._platform()))
        return real_call(name, fn, args, kwargs)

    monkeypatch.setattr(_export, "call", spy)
    # the eager set-up before the program (argument checks, output grid) runs there too
    sim_module = sys.modules["hrgjax.simulate"]
    real_laws = sim_module._check_laws
    setup = []
    monkeypatch.setattr(sim_module, "_check_laws",
                        lambda *a: setup.append(jax.config.jax_default_device) or real_laws(*a))  # fmt: skip
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    cpu = jax.devices("cpu")[0]
    assert _compiled.single_run_device() == cpu
    rec = hg.simulate(gyro, prof)
    assert seen == [(cpu, "cpu")] and setup == [cpu]
    np.testing.assert_array_equal(rec.wave_angle, plain.wave_angle)
    assert rec.wave_angle.devices() == {cpu}
    # Under a jit whose inputs are all closed over, and inside the caller's own choice of
    # device, nothing is moved.
    asked = []
    real_device = _compiled.single_run_device
    monkeypatch.setattr(_compiled, "single_run_device", lambda: asked.append(1) or real_device())
    hg.simulate(gyro, prof)
    eager = len(asked)
    assert eager >= 1
    jax.jit(lambda: hg.simulate(gyro, prof).wave_angle).lower()  # traced: where it is decided
    jax.vmap(lambda r: hg.simulate(gyro, hg.Profile.constant_rate(r, 1.0)).wave_angle)(
        jax.numpy.array([1.0, 2.0])
    )
    assert len(asked) == eager
    with jax.default_device("cpu"):
        assert _compiled.single_run_device() is None
    # A default device that is not a CPU is traced, not exported (its platform is unknown to
    # the exported program).
    with jax.default_device("gpu"):
        assert _export._platform() is None


def test_cli_commands_that_follow_one_trajectory_run_on_the_cpu_beside_an_accelerator(
    monkeypatch, tmp_path
):
    """On an H200 the demo, a calibration fit and discovery each outran 180 s (their loops
    are launch-bound there); beside an accelerator the CLI runs every command that is not a
    wide batch on the CPU, and leaves `simulate` and `design` (vmapped plans) on the
    accelerator. The accelerator is pretended, as above."""
    import argparse

    from hrgjax import cli

    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    cpu, seen = jax.devices("cpu")[0], {}

    def func(args):
        seen[args.command] = jax.config.jax_default_device
        return 0

    for command in ("demo", "calibrate", "discover", "simulate", "design"):
        args = argparse.Namespace(command=command, func=func)
        assert cli._run(args) == 0
    assert seen == {"demo": cpu, "calibrate": cpu, "discover": cpu, "simulate": None,
                    "design": None}  # fmt: skip
    assert jax.config.jax_default_device is None  # restored after the command
    monkeypatch.setattr(jax, "default_backend", lambda: "cpu")
    cli._run(argparse.Namespace(command="demo", func=func))
    assert seen["demo"] is None  # on a CPU machine nothing is placed


def test_an_unusable_cache_folder_warns_once_and_runs_without(tmp_path, monkeypatch):
    """Issue 44: a cache path under a file (misplaced HRGJAX_CACHE_DIR) is one warning, then
    no cache — never a stopped command."""
    import warnings

    from hrgjax import _cache

    monkeypatch.setattr(_cache, "_warned", set())
    monkeypatch.delenv("HRGJAX_NO_CACHE", raising=False)
    blocker = tmp_path / "afile"
    blocker.write_text("")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _cache.enable_cache(blocker) is None
        assert _cache.enable_cache(blocker) is None
    lines = [str(w.message) for w in caught if "compile cache" in str(w.message)]
    assert len(lines) == 1 and "running without it" in lines[0], lines
