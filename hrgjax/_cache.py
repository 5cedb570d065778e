"""The persistent compile cache: where it lives, how it is switched on, how it stays sound.

JAX can keep compiled programs on disk (its "persistent compilation cache"), so that a second
process that builds the same program loads it instead of compiling it again. hrgjax puts that
cache in one folder per user, turns it on for the CLI, and offers `enable_cache` to library
users. JAX's own file store writes entries in place and never replaces a damaged one; the
store here writes each entry to a temporary file and renames it (several processes may share
the folder), and a damaged entry is dropped with a warning and rebuilt by the next compile.
Results never depend on the cache: an entry is the compiled form of the very same program.
"""

from __future__ import annotations

import logging
import os
import tempfile
import warnings
from pathlib import Path

_log = logging.getLogger("hrgjax.cache")
_SUFFIX = "-cache"


def cache_dir() -> Path:
    """Where the cache lives: `$HRGJAX_CACHE_DIR`, else `$XDG_CACHE_HOME/hrgjax`, else
    `~/.cache/hrgjax`. Compiled programs go in its `xla/` folder."""
    if os.environ.get("HRGJAX_CACHE_DIR"):
        return Path(os.environ["HRGJAX_CACHE_DIR"]).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "hrgjax"


def cache_disabled() -> bool:
    """True when `HRGJAX_NO_CACHE` is set to anything but "", "0", "false" or "no"."""
    return os.environ.get("HRGJAX_NO_CACHE", "").strip().lower() not in ("", "0", "false", "no")


class _AtomicStore:
    """JAX's cache interface (`get`, `put`) over one folder: atomic writes, checked reads."""

    def __init__(self, path: Path):
        self.path = self._path = Path(path)
        self.path.mkdir(parents=True, exist_ok=True)

    def _file(self, key: str) -> Path:
        if not key or "/" in key or key.startswith("."):
            raise ValueError(f"bad compile-cache key {key!r}")
        return self.path / f"{key}{_SUFFIX}"

    def get(self, key: str) -> bytes | None:
        f = self._file(key)
        try:
            value = f.read_bytes()
        except FileNotFoundError:
            return None
        except OSError as err:
            warnings.warn(
                f"hrgjax: cannot read compile-cache entry {f.name} ({err}); compiling",
                stacklevel=2,
            )
            return None
        if not _intact(value):
            warnings.warn(
                f"hrgjax: ignoring a damaged compile-cache entry {f.name} in {self.path}; "
                "it is rebuilt by this compile",
                stacklevel=2,
            )
            try:
                f.unlink()
            except OSError:
                pass
            return None
        return value

    def put(self, key: str, value: bytes) -> None:
        f = self._file(key)
        if f.exists():
            return
        # Write beside the target and rename: a reader in another process sees either no
        # entry or the whole entry, never a part of one.
        fd, tmp = tempfile.mkstemp(dir=self.path, prefix=".tmp-")
        try:
            with os.fdopen(fd, "wb") as out:
                out.write(value)
            os.replace(tmp, f)
        except OSError as err:
            _log.debug("compile-cache write of %s failed: %s", f.name, err)
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _intact(value: bytes) -> bool:
    """Whether a stored entry decompresses (zlib and zstd frames both carry checksums of
    their content, so truncation and flipped bits are caught here)."""
    from . import _upstream

    try:
        return len(_upstream.decompress_executable(value)) > 4
    except Exception:
        return False


_enabled: Path | None = None
_warned: set[Path] = set()


def enabled_folder() -> Path | None:
    """The folder of compiled programs `enable_cache` switched on in this process (its
    `xla/`), or None while the cache is off."""
    return _enabled


def _unusable(folder: Path) -> str | None:
    """Why `folder` cannot hold the cache (it cannot be made, or written), else None."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        return f"cannot make {folder}: {err.strerror or err}"
    try:  # a real write: permissions alone do not say it (root, read-only mounts)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        return f"{folder} is not writable: {err.strerror or err}"
    return None


def enable_cache(path: str | os.PathLike | None = None) -> Path | None:
    """Keep compiled programs on disk, so a later process does not compile them again.

    Call it once, early (before the first JAX computation is best; later also works).
    The CLI calls it for you.

    **Arguments:**

    - `path`: the cache folder; default `hrgjax._cache.cache_dir()`
      (`$HRGJAX_CACHE_DIR`, else `$XDG_CACHE_HOME/hrgjax`, else `~/.cache/hrgjax`).
      Compiled programs are kept in its `xla/` sub-folder; hrgjax's own programs also in
      traced form (`jax.export`) in `export/`, so a later process skips tracing them.

    **Returns:** the folder of compiled programs, or `None` when `HRGJAX_NO_CACHE=1` switches
    the cache off.

    Several processes may share one folder. A damaged entry is dropped with a warning and
    rebuilt; entries of another JAX version never match (JAX's keys include its version and
    the device). Clear the cache by deleting the folder.
    """
    global _enabled
    if cache_disabled():
        return None
    import jax

    root = Path(path).expanduser() if path is not None else cache_dir()
    folder = (root / "xla").resolve()
    if _enabled == folder:
        return folder
    problem = _unusable(folder)
    if problem is not None:
        if folder not in _warned:  # once per folder and process
            _warned.add(folder)
            warnings.warn(f"hrgjax: no compile cache ({problem}); running without it, "
                          "compiling as usual (set HRGJAX_CACHE_DIR to a writable folder, or "
                          "HRGJAX_NO_CACHE=1 to silence this)", stacklevel=2)  # fmt: skip
        return None
    jax.config.update("jax_compilation_cache_dir", str(folder))
    # Small programs too: loading one (~ms) is cheaper than compiling it (~20–40 ms).
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    from . import _upstream

    if not _upstream.install_compile_cache_store(_AtomicStore(folder)):
        _log.debug("using JAX's own compile-cache store")  # a future JAX: its own still works
    _enabled = folder
    return folder
