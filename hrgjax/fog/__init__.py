"""Strapdown FOG IMU of seed 003 (in progress): installation misalignment and its
calibration, vibration spectrum; the vibration error model, Elman compensation and alignment
come next."""

from . import misalignment as misalignment
from . import spectrum as spectrum
