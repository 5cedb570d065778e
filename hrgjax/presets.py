"""Ready-made gyros."""

from __future__ import annotations

import math

from ._checks import check_flag
from .gyro import Gyro
from .noise import Noise
from .resonator.control import Control
from .resonator.params import Resonator, TemperatureLaw
from .resonator.readout import Readout
from .units import DEG, DEG_PER_H, DEG_PER_SQRT_H, K_BRYAN, T_REF_C


def ideal(resonator: Resonator) -> Gyro:
    """A gyro with perfect loops (a = a₀, q = 0, φ = 0 held exactly), a perfect readout and no
    noise: the averaged model then integrates $\\dot\\theta = -k_e\\Omega +
    \\tfrac12\\Delta(1/\\tau)\\sin2(\\theta-\\theta_\\tau)$ alone."""
    return Gyro(resonator=resonator, control=Control(ideal=True), readout=Readout(), noise=None)


# Targets of PHYSICS.md §11 that the laws below are built from; tests *measure* them from
# simulated bench data instead of reading these numbers back.
_DRIFT_PP_M40 = 3.5  # °/h, peak-to-peak equivalent input rate at −40 °C
_DRIFT_PP_P60 = 0.7  # °/h at +60 °C
_AXIS_SHIFT = 16.0  # ° (electrical wave angle) over −40…+60 °C
_SF_RIPPLE_0 = 1.3e-2  # amplitude of SF(θ) at 0 °C
_SF_RIPPLE_60 = 0.15e-2  # at +60 °C


def tvg3_like(
    temperature_laws: bool = True,
    noise: bool = True,
) -> Gyro:
    r"""A plausible TVG-3-like HRG tuned to the bench figures of MISSION.md §1 (PHYSICS.md §11).

    No public TVG-3 specification exists; these are the laws (T in °C, ΔT = T − 20 °C):

    | quantity | law |
    |---|---|
    | f₀ | 5 kHz · (1 + 80 ppm/°C · ΔT) |
    | τ | 640 s · (1 − 0.15 %/°C · ΔT)  (Q ≈ 1e7 at 20 °C) |
    | k_e | 0.554 (K = 0.277), temperature independent |
    | Δ(1/τ) | $k_e\,p(T)$ with drift peak-to-peak $p(T) = 3.5\,°/h\cdot5^{-(T+40)/100}$: 3.5 °/h at −40 °C, 0.7 °/h at +60 °C (exponential) |
    | θ_τ | 25° + 0.16 °/°C · ΔT (electrical): the drift curve shifts 16° over −40…+60 °C |
    | Δω, θ_ω | 2π · 0.5 mHz, 10° |
    | χ | 5000 rad²/s² (Duffing shift ≈ 0.01 Hz at a = 1) |
    | drive | parametric pump (isotropic), pump phase error γ_e = 0.01 rad |
    | readout gain mismatch g | linear: 0.65 % at 0 °C → 0.075 % at 60 °C, so SF(θ) = 1 − 2g cos 2θ has ripple amplitude 1.3 % → 0.15 % |
    | rate bias | 0.3 °/h + 0.005 °/h/°C · ΔT |
    | g-sensitivity | (0.005, 0.005, 0.01) °/h per g along case x, y, z |
    | noise | readout 1″ (electrical, per sample), ARW 0.002 °/√h, Gauss–Markov 0.003 °/h with T_c = 600 s, switch-on bias σ 0.2 °/h, amplitude/quadrature 1e-4 |

    Loops: PLL 2 rad/s, AGC 1 rad/s, quadrature 2 rad/s (slow-time bandwidths).

    **Tuned range: −40…+60 °C** (the bench figures; the gain mismatch 0…60 °C). Outside it
    the laws are extrapolated as written, not tuned: the linear gain mismatch crosses zero at
    67.8 °C and changes sign (−0.79 % at 150 °C; +1.6 % at −100 °C, an SF ripple of 3.2 %),
    and Δ(1/τ) keeps growing ×5 per 100 °C colder (9.2 °/h peak-to-peak at −100 °C).
    `simulate` refuses only temperatures outside the plausible −100…150 °C
    (`hg.plausible.RANGES["temperature_c"]`) and laws that leave their limits there (|g| <
    0.5, τ > 0); between the tuned and the plausible range it runs the
    extrapolated laws without a warning.

    **Arguments:**

    - `temperature_laws`: `False` freezes every law at 20 °C.
    - `noise`: `False` gives the noise-free gyro.

    Both flags must be `True` or `False` (a string such as "no" is refused, not taken as true).
    """
    temperature_laws = check_flag("presets.tvg3_like: temperature_laws", temperature_laws)
    noise = check_flag("presets.tvg3_like: noise", noise)
    k_e = 2 * K_BRYAN
    lam = -math.log(_DRIFT_PP_M40 / _DRIFT_PP_P60) / 100.0
    pp20 = _DRIFT_PP_M40 * math.exp(lam * (T_REF_C + 40.0))
    omega0 = 2 * math.pi * 5000.0
    g_slope = (_SF_RIPPLE_60 - _SF_RIPPLE_0) / 2 / 60.0
    g20 = _SF_RIPPLE_0 / 2 + g_slope * T_REF_C

    def law(p0, p1=0.0, lam=0.0):
        return TemperatureLaw(p0, p1, 0.0, lam) if temperature_laws else p0

    res = Resonator(
        omega=law(omega0, omega0 * 80e-6),
        tau=law(640.0, -640.0 * 1.5e-3),
        k_e=k_e,
        delta_omega=2 * math.pi * 0.5e-3,
        theta_omega=10.0 * DEG,
        delta_inv_tau=law(k_e * pp20 * DEG_PER_H, lam=lam),
        theta_tau=law(25.0 * DEG, _AXIS_SHIFT / 100.0 * DEG),
        chi=5000.0,
    )
    control = Control(amplitude=1.0, drive="parametric", excitation_phase=0.01)
    readout = Readout(gain_mismatch=law(g20, g_slope))
    nz = (
        Noise(
            angle_white=1.0 / 3600 * DEG,
            angle_random_walk=0.002 * DEG_PER_SQRT_H,
            bias_instability=0.003 * DEG_PER_H,
            correlation_time=600.0,
            run_bias=0.2 * DEG_PER_H,
            amplitude_white=1e-4,
        )
        if noise
        else None
    )
    return Gyro(
        resonator=res,
        control=control,
        readout=readout,
        noise=nz,
        rate_bias=law(0.3 * DEG_PER_H, 0.005 * DEG_PER_H),
        g_sensitivity=[0.005 * DEG_PER_H, 0.005 * DEG_PER_H, 0.01 * DEG_PER_H],
    )
