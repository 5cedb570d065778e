"""Files hrgjax writes: atomically, never over an input.

Every file is written under a temporary name in the folder it belongs to and renamed onto its
name once complete (`os.replace`, atomic on POSIX and Windows), so an interrupted write
(Ctrl-C, a full disk, a crash) leaves the old file or none, never a shorter one that still
loads. The temporary file is removed when the write fails.
"""

from __future__ import annotations

import contextlib
import os
import tempfile


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike):
    """Yield a temporary path beside `path` (same extension) for a writer that takes a path
    (NetCDF, matplotlib); on success it replaces `path`, on any error it is removed."""
    path = os.fspath(path)
    folder = os.path.dirname(path) or "."
    os.makedirs(folder, exist_ok=True)
    base, ext = os.path.splitext(os.path.basename(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{base}.", suffix=f".tmp{ext}")
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "w", **kwargs):
    """`open(path, mode)` through [`atomic_path`][hrgjax._io.atomic_path]: yields the open
    file; `path` appears, complete, when the block ends without an error."""
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


def same_file(a: str | os.PathLike, b: str | os.PathLike) -> bool:
    """Whether `a` and `b` name the same existing file (links and relative paths resolved)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def read_json(path: str | os.PathLike):
    """The JSON value in the file at `path`; `FileNotFoundError` or a one-line `ValueError`
    naming the file (and the line of a syntax error)."""
    import json

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"{path}: no such file")
    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh)
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not JSON ({err.msg} at line {err.lineno})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not UTF-8 text; save the file as UTF-8 JSON") from None
