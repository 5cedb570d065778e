"""Files hrgjax writes: atomically, never over an input.

Every file is written under a temporary name in the folder it belongs to and renamed onto its
name once complete (`os.replace`, atomic on POSIX and Windows), so an interrupted write
(Ctrl-C, a full disk, a crash) leaves the old file or none, never a shorter one that still
loads. The temporary file is removed when the write fails.
"""

from __future__ import annotations

import contextlib
import math
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

    def number(text: str):
        value = float(text)
        if not math.isfinite(value):
            raise ValueError(f"{path}: the number {text} is beyond float64's range (±1.8e308)")
        return value

    def constant(name: str):
        raise ValueError(f"{path}: {name} is not a JSON number; give a finite number")

    try:
        with open(path, encoding="utf-8") as fh:
            return json.load(fh, parse_float=number, parse_int=_json_int(path),
                             parse_constant=constant)  # fmt: skip
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not JSON ({err.msg} at line {err.lineno})") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not UTF-8 text; save the file as UTF-8 JSON") from None
    except RecursionError:
        raise ValueError(f"{path}: JSON nested too deeply to be an hrgjax file") from None


def _json_int(path: str):
    def parse(text: str):
        if len(text.lstrip("-")) > 18:  # beyond int64: no hrgjax field holds such a count
            raise ValueError(f"{path}: the integer {text[:24]}{'…' if len(text) > 24 else ''} "
                             "is too large for any field (int64)")  # fmt: skip
        return int(text)

    return parse
