"""The grey box's parameters and equations: the fitted laws (`PARAMETERS`), the model gyro
they make (`model_gyro`) and its readout map (`readout_angle`, `true_angle`)."""

from __future__ import annotations

import math

import numpy as np

from ..gyro import Gyro
from ..resonator.averaged import measured_estimates
from ..resonator.control import Control
from ..resonator.params import Resonator, TemperatureLaw
from ..resonator.readout import Readout
from ..units import DEG_PER_H, T_REF_C
from ._plant import PLANT_RESONATOR

PARAMETERS = (
    ("k_e0", "", 1e-4),
    ("k_e_tc", "1/°C", 1e-6),
    ("bias0", "rad/s", 0.01 * DEG_PER_H),
    ("bias1", "rad/s/°C", 1e-4 * DEG_PER_H),
    ("bias2", "rad/s/°C²", 1e-6 * DEG_PER_H),
    ("delta_inv_tau0", "1/s", 0.01 * DEG_PER_H),
    ("delta_inv_tau_lam", "1/°C", 1e-3),
    ("theta_tau0", "rad", 1e-2),
    ("theta_tau1", "rad/°C", 1e-4),
    ("gain_mismatch0", "", 1e-5),
    ("gain_mismatch1", "1/°C", 1e-7),
    ("cross_talk", "", 1e-5),
)
"""Fitted parameters: (name, unit, typical uncertainty used to scale the LM problem)."""
NAMES = tuple(p[0] for p in PARAMETERS)
SCALE = np.array([p[2] for p in PARAMETERS])
"""Each parameter's typical uncertainty (`PARAMETERS`): one unit of the fit's scaled
parameters."""

MODEL_OMEGA = 2 * math.pi * 5000.0
"""Mean natural angular frequency of the model gyro [rad/s] (not fitted: with ideal loops the
averaged pattern rate does not depend on it)."""
MODEL_TAU = 640.0
"""Mean decay time of the model gyro [s] (not fitted: the ideal amplitude loop holds the
amplitude whatever τ is; the damping *anisotropy* Δ(1/τ) is fitted)."""


def model_gyro(
    values, omega: float = MODEL_OMEGA, tau: float = MODEL_TAU, plant: Gyro | None = None
) -> Gyro:
    """The model gyro of the parameter vector `values` (order of `PARAMETERS`): with ideal
    loops, mean frequency `omega` [rad/s] and decay time `tau` [s]; or, given a `plant`
    (`known_plant`), with the plant's resonator constants (`PLANT_RESONATOR`) and its PI
    loops."""
    v = {name: values[i] for i, name in enumerate(NAMES)}
    law = lambda p0, p1=0.0, p2=0.0, lam=0.0: TemperatureLaw(p0, p1, p2, lam, T_REF_C)
    known = {"omega": omega, "tau": tau}
    if plant is not None:
        known = {f: getattr(plant.resonator, f) for f in PLANT_RESONATOR}
    res = Resonator(
        **known,
        k_e=law(v["k_e0"], v["k_e0"] * v["k_e_tc"]),
        delta_inv_tau=law(v["delta_inv_tau0"], lam=v["delta_inv_tau_lam"]),
        theta_tau=law(v["theta_tau0"], v["theta_tau1"]),
    )
    readout = Readout(
        gain_mismatch=law(v["gain_mismatch0"], v["gain_mismatch1"]), cross_talk=v["cross_talk"]
    )
    return Gyro(
        resonator=res,
        control=Control(ideal=True) if plant is None else plant.control,
        readout=readout,
        rate_bias=law(v["bias0"], v["bias1"], v["bias2"]),
    )


def readout_angle(gyro_t: Gyro, theta):
    """The readout map at one temperature: the measured pattern angle θ̂ [rad] of the true
    pattern angle `theta` [rad] under ideal loops (the amplitude at the AGC set point, no
    quadrature), `gyro_t` a gyro at that temperature (`gyro.at(T)`)."""
    a0 = gyro_t.control.amplitude
    return measured_estimates(gyro_t, a0, 0.0 * a0, theta, 0.0 * a0).theta


def true_angle(gyro_t: Gyro, theta_meas, iterations: int = 4):
    """Invert the readout map at one temperature: θ with θ̂(θ) = `theta_meas` [rad]."""
    theta = theta_meas
    for _ in range(iterations):
        theta = theta - (readout_angle(gyro_t, theta) - theta_meas)
    return theta
