"""The three compensators of the study (DESIGN.md layout): Fourier, MLP, physical."""

from ._compensator import AbstractCompensator as AbstractCompensator
from .evaluate import NoCompensation as NoCompensation
from .fourier import FourierCompensator as FourierCompensator
from .mlp import MLPCompensator as MLPCompensator
from .physical import PhysicalCompensator as PhysicalCompensator
