"""The HRG calibration study of seed 000: bench plans, reduction (more in later work)."""

from .experiment import Plan as Plan
from .experiment import rotation_plan as rotation_plan
from .experiment import run_plan as run_plan
from .experiment import seed_plan as seed_plan
from .experiment import static_plan as static_plan
from .reduce import scale_factor_vs_angle as scale_factor_vs_angle
from .reduce import static_drift as static_drift
