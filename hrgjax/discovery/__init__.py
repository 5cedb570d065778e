"""Model-discrepancy workflow (find, name, add, shrink): the effect catalogue and the search
on dwell grids and continuous records."""

from .effects import CATALOGUE as CATALOGUE
from .effects import NOMINAL as NOMINAL
from .effects import Covariates as Covariates
from .effects import Effect as Effect
from .effects import Param as Param
from .effects import null_params as null_params
from .effects import pattern_rate as pattern_rate
from .effects import rate_term as rate_term
from .effects import readout_term as readout_term
from .effects import window_gain as window_gain
from .noise import NoiseModel as NoiseModel
from .result import Discovery as Discovery
from .search import discover as discover
from .search import noise_model as noise_model
