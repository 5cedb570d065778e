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
    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import hrgjax as hg
    print("cache:", hg.enable_cache())
    gyro = hg.presets.tvg3_like()
    rec = hg.simulate(gyro, hg.Profile.constant_rate(2.0, 4.0, -10.0, 20.0),
                      key=jax.random.key(3), dt_out=0.5)
    np.save(sys.argv[1], np.stack([rec.wave_angle, rec.amplitude, rec.quadrature]))
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
    cold, log = _run(tmp_path / "cold.npy", HRGJAX_CACHE_DIR=str(folder))
    entries = sorted((folder / "xla").glob("*-cache"))
    # The whole simulate program is kept: it carries no host callback.
    assert any(e.name.startswith("jit__solve-") for e in entries), [e.name for e in entries]
    warm, _ = _run(tmp_path / "warm.npy", HRGJAX_CACHE_DIR=str(folder))
    sizes = {e.name: e.stat().st_size for e in entries}
    for e in entries:  # truncate every entry: each is dropped with a warning and rebuilt
        e.write_bytes(e.read_bytes()[: max(e.stat().st_size // 3, 1)])
    damaged, log = _run(tmp_path / "damaged.npy", HRGJAX_CACHE_DIR=str(folder))
    assert "damaged compile-cache entry" in log
    rebuilt = {e.name: e for e in (folder / "xla").glob("*-cache")}
    assert set(rebuilt) == set(sizes)  # every damaged entry was written anew, whole
    assert all(_intact(e.read_bytes()) for e in rebuilt.values())
    for result in (cold, warm, damaged):
        np.testing.assert_array_equal(result, off)
    assert not list((folder / "xla").glob(".tmp-*"))  # no half-written entries left


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


def test_solver_failure_raises_a_readable_error_eagerly_and_under_jit():
    gyro = hg.presets.tvg3_like(noise=False)
    prof = hg.Profile.static(1.0)
    with pytest.raises(RuntimeError, match="maximum number of solver steps"):
        hg.simulate(gyro, prof, model="full", max_steps=50)
    # Under the caller's own jit the check stays inside the program, as before.
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
