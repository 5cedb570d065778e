"""Progress bars for long work: tqdm on stderr, shown only to a person at a terminal.

A bar is off when stderr is not a terminal (logs, CI, tests), when `HRGJAX_QUIET` is set
(the CLI's `--quiet` sets it), or when tqdm is not installed. A bar over work whose units
are long (one compiled program: its compile, a vmapped batch) can `tick`: redrawn every few
seconds by a daemon thread, so its elapsed time moves while the count cannot.
"""

from __future__ import annotations

import os
import sys
import threading


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

    def refresh(self):
        pass

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


TICK_S = 1.0
"""Seconds between a ticking bar's redraws (`bar(..., tick=True)`)."""


def bar(total: int | None, desc: str, unit: str = "step", *, tick: bool = False):
    """A progress bar over `total` units (a context manager with `update(n)`,
    `set_postfix_str(text)`, `refresh()` and a settable `total`); silent where nobody
    watches (module docstring). `tick`: redrawn every `TICK_S` s until closed, for units
    that each take many seconds (its elapsed time moves between them)."""
    if quiet() or not _stderr_is_terminal():
        return _Silent(total)
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return _Silent(total)
    out = tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False, dynamic_ncols=True)
    if tick:
        _ticking(out)
    return out


def _ticking(progress) -> None:
    """Redraw `progress` every `TICK_S` s from a daemon thread until it is closed."""
    stop = threading.Event()

    def run():
        while not stop.wait(TICK_S):
            try:
                progress.refresh()
            except Exception:  # a bar torn down under us: stop redrawing, never raise
                return

    thread = threading.Thread(target=run, name="hrgjax-progress-tick", daemon=True)
    close = progress.close

    def closing():
        stop.set()
        if thread is not threading.current_thread():
            thread.join(TICK_S)
        close()

    progress.close = closing
    thread.start()


def _stderr_is_terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False
