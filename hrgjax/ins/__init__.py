"""Inertial navigation: WGS-84 constants, trajectories, the strapdown and platform error
models, and stationary initial alignment (MISSION.md §2–§3, PHYSICS.md §12)."""

from . import alignment as alignment
from . import constants as constants
from . import platform as platform
from . import strapdown as strapdown
from . import trajectory as trajectory
