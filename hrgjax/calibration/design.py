"""Bench plans and their design: the public namespace of `hrgjax.calibration.design`.

Re-exports, one concept per private module (issue 45 split the 1 967-line module):

- `_plan` — [`BenchPlan`][hrgjax.calibration.BenchPlan] (static, rotation and ramp segments
  as a differentiable pytree) and [`BenchModel`][hrgjax.calibration.BenchModel] (the bench
  time a plan costs);
- `_plan_file` — plan files (JSON, DESIGN.md's contract): `plan_to_json`, `save_plan`,
  `load_plan`;
- `_rounding` — a plan on the bench's resolution: `round_plan`, `quantise`,
  `wrap_wave_angle`;
- `_plan_simulation` — `simulate_plan`: a plan as one switch-on, segments grouped to share
  compiled simulators (the runner of `experiment.run_plan`, `_runs`);
- `_models` — what the calibration fits (`GreyBox`, `Empirical`, `measured_rate`) and the
  noise on the measured pattern angle (`pattern_arw`, …);
- `_information` — the Fisher `information` of a plan and its `posterior_covariance`;
- `_criteria` — the design `criterion` and its parts (`drift_error`, `warmup_error`,
  `ins_error`, …);
- `_search` — `design`: Adam over a plan's continuous quantities within a budget.

Import from here (or `hrgjax.calibration`), not from the private modules.
"""

from ._criteria import CRITERIA as CRITERIA
from ._criteria import CRITERION_UNITS as CRITERION_UNITS
from ._criteria import INS_FLIGHTS as INS_FLIGHTS
from ._criteria import OPERATING_ANGLES as OPERATING_ANGLES
from ._criteria import OPERATING_TEMPERATURES as OPERATING_TEMPERATURES
from ._criteria import criterion as criterion
from ._criteria import drift_error as drift_error
from ._criteria import drift_warmup_error as drift_warmup_error
from ._criteria import ins_error as ins_error
from ._criteria import ins_sensitivity as ins_sensitivity
from ._criteria import warmup_error as warmup_error
from ._criteria import warmup_sensitivity as warmup_sensitivity
from ._information import INFORMATION_CHUNK as INFORMATION_CHUNK
from ._information import PRECISION_FLOOR as PRECISION_FLOOR
from ._information import SWEEP_PER_NODE_DEG as SWEEP_PER_NODE_DEG
from ._information import gauss_markov_discount as gauss_markov_discount
from ._information import information as information
from ._information import posterior_covariance as posterior_covariance
from ._information import window_density as window_density
from ._information import window_transfer as window_transfer
from ._models import GREY_BOX as GREY_BOX
from ._models import MODELS as MODELS
from ._models import Empirical as Empirical
from ._models import GreyBox as GreyBox
from ._models import measured_rate as measured_rate
from ._models import nominal_values as nominal_values
from ._models import pattern_angle_white as pattern_angle_white
from ._models import pattern_arw as pattern_arw
from ._models import pattern_gauss_markov as pattern_gauss_markov
from ._plan import DT_OUT as DT_OUT
from ._plan import KINDS as KINDS
from ._plan import BenchModel as BenchModel
from ._plan import BenchPlan as BenchPlan
from ._plan import bench_time_h as bench_time_h
from ._plan import seed_bench_plan as seed_bench_plan
from ._plan_file import load_plan as load_plan
from ._plan_file import plan_to_json as plan_to_json
from ._plan_file import save_plan as save_plan
from ._plan_simulation import MERGED_STEPS_MAX as MERGED_STEPS_MAX
from ._plan_simulation import RUNS_PER_COMPILE as RUNS_PER_COMPILE
from ._plan_simulation import SIMULATOR_COMPILE_S as SIMULATOR_COMPILE_S
from ._plan_simulation import simulate_plan as simulate_plan
from ._rounding import ANGLE_STEP_DEG as ANGLE_STEP_DEG
from ._rounding import RATE_STEP_DPS as RATE_STEP_DPS
from ._rounding import RESOLUTION_KEYS as RESOLUTION_KEYS
from ._rounding import TEMPERATURE_STEP_C as TEMPERATURE_STEP_C
from ._rounding import TIME_STEP_S as TIME_STEP_S
from ._rounding import quantise as quantise
from ._rounding import round_plan as round_plan
from ._rounding import wrap_wave_angle as wrap_wave_angle
from ._search import ANGLE_UNIT_DEG as ANGLE_UNIT_DEG
from ._search import CHAMBER_RANGE_C as CHAMBER_RANGE_C
from ._search import DEFAULT_LEARNING_RATE as DEFAULT_LEARNING_RATE
from ._search import DEFAULT_LEVELS as DEFAULT_LEVELS
from ._search import DESIGN_RATE_DPS as DESIGN_RATE_DPS
from ._search import MIN_ROTATION_S as MIN_ROTATION_S
from ._search import MIN_STATIC_S as MIN_STATIC_S
from ._search import Design as Design
from ._search import design as design

# Names this module imported from its siblings before the split, still reachable here.
from .experiment import CHUNK as CHUNK
from .experiment import SEED_ANGLES as SEED_ANGLES
from .experiment import SEED_TEMPERATURES as SEED_TEMPERATURES
from .experiment import failed_member as failed_member
from .ins_impact import FLIGHTS as FLIGHTS
from .ins_impact import Flight as Flight
