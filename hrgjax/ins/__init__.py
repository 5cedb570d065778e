"""Inertial navigation: WGS-84 constants, trajectories, the strapdown and platform error
models, stationary initial alignment (MISSION.md §2–§3, PHYSICS.md §12), and navigation
itself: the nonlinear strapdown mechanization, motion definitions with exact increments, IMU
error models, GNSS fixes, the loosely-coupled filter and smoother, Monte Carlo flights."""

from . import alignment as alignment
from . import consistency as consistency
from . import constants as constants
from . import ekf as ekf
from . import flights as flights
from . import gnss as gnss
from . import mechanization as mechanization
from . import motion as motion
from . import platform as platform
from . import sensors as sensors
from . import strapdown as strapdown
from . import trajectory as trajectory
from .mechanization import NavState as NavState
from .mechanization import mechanize as mechanize
