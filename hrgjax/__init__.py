"""hrgjax: differentiable simulation and fitting of HRGs, FOGs and INS errors in JAX.

Names are imported on first use (PEP 562), so `import hrgjax` — and `hrgjax --help` — do
not pay for importing JAX until something needs it.
"""

from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING

__version__ = "0.1.0"

_SUBMODULES = (
    "allan",
    "calibration",
    "data",
    "diagnosis",
    "discovery",
    "fog",
    "imu",
    "ins",
    "kalman",
    "nn",
    "noise",
    "pattern_noise",
    "plausible",
    "presets",
    "units",
)
_NAMES = {
    "adev": "allan",
    "allan_deviation": "allan",
    "hdev": "allan",
    "mdev": "allan",
    "oadev": "allan",
    "ohdev": "allan",
    "totdev": "allan",
    "enable_cache": "_cache",
    "widen_cpu_thread_pool": "_threads",
    "MeasuredData": "data",
    "load": "data",
    "DriftTerms": "gyro",
    "Gyro": "gyro",
    "Noise": "noise",
    "Profile": "profiles",
    "Record": "record",
    "Control": "resonator",
    "Readout": "resonator",
    "Resonator": "resonator",
    "TemperatureLaw": "resonator",
    "simulate": "simulate",
    "sweep": "sweep",
}

__all__ = sorted((*_SUBMODULES, *_NAMES))


def __getattr__(name: str):
    if name in _NAMES:
        value = getattr(importlib.import_module(f".{_NAMES[name]}", __name__), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module 'hrgjax' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted({*globals(), *__all__})


_SHADOWED = ("simulate", "sweep")
"""Functions named like the module that defines them."""


class _Package(types.ModuleType):
    def __setattr__(self, name, value):
        # Importing the submodule hrgjax.simulate sets the package attribute `simulate` to
        # the module; the package's `simulate` is the function, as an eager
        # `from .simulate import simulate` would leave it.
        if name in _SHADOWED and isinstance(value, types.ModuleType):
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


if TYPE_CHECKING:  # what static tools (type checkers, mkdocstrings) read
    from . import allan as allan
    from . import calibration as calibration
    from . import data as data
    from . import diagnosis as diagnosis
    from . import discovery as discovery
    from . import fog as fog
    from . import ins as ins
    from . import kalman as kalman
    from . import nn as nn
    from . import noise as noise
    from . import presets as presets
    from . import units as units
    from ._cache import enable_cache as enable_cache
    from ._threads import widen_cpu_thread_pool as widen_cpu_thread_pool
    from .allan import adev as adev
    from .allan import allan_deviation as allan_deviation
    from .allan import hdev as hdev
    from .allan import mdev as mdev
    from .allan import oadev as oadev
    from .allan import ohdev as ohdev
    from .allan import totdev as totdev
    from .data import MeasuredData as MeasuredData
    from .data import load as load
    from .gyro import DriftTerms as DriftTerms
    from .gyro import Gyro as Gyro
    from .noise import Noise as Noise
    from .profiles import Profile as Profile
    from .record import Record as Record
    from .resonator import Control as Control
    from .resonator import Readout as Readout
    from .resonator import Resonator as Resonator
    from .resonator import TemperatureLaw as TemperatureLaw
    from .simulate import simulate as simulate
    from .sweep import sweep as sweep
