"""Strapdown FOG IMU of seed 003: installation misalignment and its calibration, the
vibration table and error model, the vibration spectrum, Elman-network compensation and
alignment with raw vs compensated outputs; `study` runs the whole pipeline."""

from . import compensation as compensation
from . import heading as heading
from . import misalignment as misalignment
from . import spectrum as spectrum
from . import study as study
from . import vibration as vibration
