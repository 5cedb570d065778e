"""hrgjax: differentiable simulation and fitting of HRGs, FOGs and INS errors in JAX."""

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

__version__ = "0.1.0"
