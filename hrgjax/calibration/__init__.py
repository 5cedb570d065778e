"""The HRG calibration study of seed 000: plans, reduction, compensators, evaluation."""

from ._compensator import AbstractCompensator as AbstractCompensator
from .evaluate import NoCompensation as NoCompensation
from .evaluate import accuracy_table as accuracy_table
from .evaluate import format_table as format_table
from .evaluate import run_errors as run_errors
from .experiment import Plan as Plan
from .experiment import rotation_plan as rotation_plan
from .experiment import run_plan as run_plan
from .experiment import seed_plan as seed_plan
from .experiment import static_plan as static_plan
from .experiment import test_plan as test_plan
from .export import export_json as export_json
from .export import load_compensator as load_compensator
from .export import load_json as load_json
from .export import save_compensator as save_compensator
from .fourier import FourierCompensator as FourierCompensator
from .mlp import MLPCompensator as MLPCompensator
from .physical import PhysicalCompensator as PhysicalCompensator
from .reduce import RateWindows as RateWindows
from .reduce import reduce as reduce
from .reduce import scale_factor_vs_angle as scale_factor_vs_angle
from .reduce import static_drift as static_drift
from .study import Study as Study
from .study import run_study as run_study
