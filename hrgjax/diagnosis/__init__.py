"""Three-INS fault diagnosis (seed 002): pairwise measurements and multiple-model filtering.
(In progress: the three-INS models, the neural detectors and the comparison come next.)"""

from . import complex as complex
from . import filter_bank as filter_bank
from . import measurements as measurements
