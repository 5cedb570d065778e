"""Network building blocks shared by the calibration, diagnosis and FOG work: tapped-delay
inputs, probabilistic neural networks, and full-batch Rprop training."""

from . import pnn as pnn
from . import tapped_delay as tapped_delay
from . import train as train
