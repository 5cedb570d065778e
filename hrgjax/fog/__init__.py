"""Strapdown FOG IMU of seed 003 (in progress): installation misalignment and its
calibration; vibration error model, spectrum, Elman compensation and alignment come next."""

from . import misalignment as misalignment
