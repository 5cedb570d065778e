"""HRG resonator physics: parameters, full and averaged dynamics, loops, readout."""

from .control import Control as Control
from .params import Resonator as Resonator
from .params import TemperatureLaw as TemperatureLaw
from .readout import Readout as Readout
