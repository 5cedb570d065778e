"""The three compensators of the study (DESIGN.md layout): Fourier, MLP, physical."""

from ._compensator import DOMAIN_MARGIN_C as DOMAIN_MARGIN_C
from ._compensator import AbstractCompensator as AbstractCompensator
from ._compensator import Corrected as Corrected
from ._compensator import TemperatureDomainWarning as TemperatureDomainWarning
from .evaluate import NoCompensation as NoCompensation
from .fourier import FourierCompensator as FourierCompensator
from .mlp import MLPCompensator as MLPCompensator
from .physical import PhysicalCompensator as PhysicalCompensator
