"""Progress bars for long work: tqdm on stderr, shown only to a person at a terminal.

A bar is off when stderr is not a terminal (logs, CI, tests), when `HRGJAX_QUIET` is set
(the CLI's `--quiet` sets it), or when tqdm is not installed.
"""

from __future__ import annotations

import os
import sys


def quiet() -> bool:
    """Whether progress output is switched off (`HRGJAX_QUIET` set to anything but "", "0")."""
    return os.environ.get("HRGJAX_QUIET", "").strip() not in ("", "0")


class _Silent:
    def __init__(self, total=None, **_):
        self.total, self.n = total, 0

    def update(self, n=1):
        self.n += n

    def set_postfix_str(self, *_args, **_kwargs):
        pass

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def bar(total: int | None, desc: str, unit: str = "step"):
    """A progress bar over `total` units (a context manager with `update(n)` and
    `set_postfix_str(text)`); silent where nobody watches (module docstring)."""
    if quiet() or not _stderr_is_terminal():
        return _Silent(total)
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return _Silent(total)
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False, dynamic_ncols=True)


def _stderr_is_terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False
