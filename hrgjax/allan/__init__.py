r"""Allan-family deviations in JAX (NIST SP 1065 definitions).

Inputs are *rate* ("frequency") samples $y_k$ at interval $\tau_0$; the phase is
$x_k = \tau_0\sum_{j<k} y_j$ ($x_0 = 0$). The averaging factor `m` is a static integer
($\tau = m\tau_0$). Checked against the NBS14 data set (PHYSICS.md §12).

IEEE 952 noise terms on an Allan-deviation plot: quantisation $\sqrt3 Q/\tau$, angle random
walk $N/\sqrt\tau$, bias instability flat at $0.6643B$, rate random walk $K\sqrt{\tau/3}$,
rate ramp $R\tau/\sqrt2$.

Every name is importable from `hrgjax.allan` (it was one module until issue 45); inside:
`deviations` (the estimators and the compiled curve), `result` (`deviation`: that curve on
τ grids with its statistics, an `AllanResult` of `curve_result`), `mixture` (mtotdev's bias
and oadev's EDF under the record's fitted IEEE 952 noise mixture),
`total` (mtotdev and ttotdev, NumPy), `totvar` (totdev's bias and EDF by noise type),
`noise_ident` (noise identification), `uncertainty` (EDF, χ² intervals), `noise_terms` (the IEEE 952
line fit), `octave_covariance` (each noise term's Allan variance for sampled data and the
exact covariance of the octave estimates, for rate samples taken as interval means or as
point samples: an explicit `sampling` argument) and `composite` (a composite noise model fitted with
that covariance, with model selection: `identify_noise`), `kalibr` (the model's Gauss–Markov
terms in Kalibr's white noise and random walk, over the record's octaves) and `resample` (non-uniform time
stamps onto a uniform grid by the angle: `to_uniform`).
"""

from .composite import CompositeNoise as CompositeNoise
from .composite import identify_noise as identify_noise
from .curve_result import AllanResult as AllanResult
from .deviations import adev as adev
from .deviations import allan_deviation as allan_deviation
from .deviations import hdev as hdev
from .deviations import mdev as mdev
from .deviations import oadev as oadev
from .deviations import ohdev as ohdev
from .deviations import totdev as totdev
from .noise_ident import ACF_POINTS as ACF_POINTS
from .noise_ident import B1_AVERAGES as B1_AVERAGES
from .noise_ident import NOISE_RULES as NOISE_RULES
from .noise_ident import RHO_SPLIT as RHO_SPLIT
from .noise_ident import RHO_SPLIT_1 as RHO_SPLIT_1
from .noise_ident import RN_FACTOR as RN_FACTOR
from .noise_ident import b1_expected as b1_expected
from .noise_ident import noise_id as noise_id
from .noise_ident import noise_id_each as noise_id_each
from .noise_ident import rn_expected as rn_expected
from .noise_terms import NOISE_TERMS as NOISE_TERMS
from .noise_terms import NoiseFit as NoiseFit
from .noise_terms import fit_noise as fit_noise
from .resample import to_uniform as to_uniform
from .result import KINDS as KINDS
from .result import deviation as deviation
from .totvar import TOTVAR_BIAS as TOTVAR_BIAS
from .totvar import edf_totdev as edf_totdev
from .totvar import totvar_bias as totvar_bias
from .totvar import totvar_white_phase as totvar_white_phase
from .uncertainty import DISCRETE_EDF_M as DISCRETE_EDF_M
from .uncertainty import ONE_SIGMA as ONE_SIGMA
from .uncertainty import chi2_ppf as chi2_ppf
from .uncertainty import confidence_interval as confidence_interval
from .uncertainty import edf_discrete as edf_discrete
from .uncertainty import edf_greenhall as edf_greenhall
