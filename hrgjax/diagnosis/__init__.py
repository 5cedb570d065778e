"""Three-INS fault diagnosis (seed 002): pairwise measurements, the multiple-model filter
bank, neural detectors (PNN, SOM, tapped-delay MLPs) and their comparison."""

from . import compare as compare
from . import complex as complex
from . import filter_bank as filter_bank
from . import measurements as measurements
from . import neural as neural
