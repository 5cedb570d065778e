"""Network building blocks shared by the calibration, diagnosis and FOG work: tapped-delay
inputs, multilayer perceptrons, Elman recurrent networks, probabilistic neural networks, self-organising maps, and
full-batch Rprop training."""

from . import elman as elman
from . import mlp as mlp
from . import pnn as pnn
from . import som as som
from . import tapped_delay as tapped_delay
from . import train as train
