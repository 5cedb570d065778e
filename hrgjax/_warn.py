"""Where a library warning points: the user's line, not the library's."""

from __future__ import annotations

import os
import sys

import equinox as eqx

_ROOTS = tuple(os.path.dirname(os.path.abspath(f)) + os.sep for f in (__file__, eqx.__file__))
"""hrgjax's folder and equinox's: a method of an `eqx.Module` is called through equinox's
bound-method wrapper, a frame that is no more the user's than hrgjax's own."""


def user_stacklevel() -> int:
    """`stacklevel` for a `warnings.warn` issued by the function that calls this: the first
    frame outside hrgjax and equinox, the user's call however deep the library's own calls go
    (`correct`'s warning pointed at equinox's `_prebuilt.py` with `stacklevel=2`)."""
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(_ROOTS):
        frame, level = frame.f_back, level + 1
    return level
