"""The closed-loop plant the grey box takes as known: its resonator constants
(`PLANT_RESONATOR`) and PI loops, normalised to one fixed layout (`known_plant`) and its
JSON form (`plant_to_json`, `plant_from_json`)."""

from __future__ import annotations

from ..gyro import Gyro
from ..resonator.control import Control
from ..resonator.params import Resonator, TemperatureLaw
from ..resonator.readout import Readout

PLANT_RESONATOR = ("omega", "tau", "delta_omega", "theta_omega", "chi")
"""What a plant (`PhysicalCompensator(plant=…)`) gives the grey box of its resonator, held
fixed in the fit: mean frequency ω [rad/s], decay time τ [s], frequency split Δω [rad/s]
and its axis θ_ω [rad, electrical], nonlinearity χ [rad²/s²] — each a number or a
[`TemperatureLaw`][hrgjax.TemperatureLaw]. Of its loops it takes the whole `Control`."""

_LAW_FIELDS = ("p0", "p1", "p2", "lam", "t_ref")


def _as_law(x) -> TemperatureLaw:
    if isinstance(x, TemperatureLaw):
        return TemperatureLaw(*(getattr(x, f) for f in _LAW_FIELDS))
    return TemperatureLaw(x)


def known_plant(plant: Gyro | None) -> Gyro | None:
    """The part of a gyro the grey box takes as known (`PLANT_RESONATOR` and the loops), in
    one fixed layout (every such parameter a [`TemperatureLaw`][hrgjax.TemperatureLaw]) so a
    fitted compensator saves and loads; `None` stays `None` (ideal loops).

    **Raises:** `TypeError` for anything but a [`hrgjax.Gyro`][]; `ValueError` for a plant
    whose loops are ideal or open (nothing for the grey box to model: give `plant=None`)."""
    if plant is None:
        return None
    if not isinstance(plant, Gyro):
        raise TypeError(f"plant must be a hrgjax.Gyro (its loops and resonator constants) or "
                        f"None; got {type(plant).__name__}")  # fmt: skip
    ctl = plant.control
    if ctl.ideal or not ctl.enabled:
        raise ValueError("plant.control: ideal or open loops have no lag to model; give "
                         "plant=None for the ideal-loop grey box")  # fmt: skip
    res = Resonator(**{f: _as_law(getattr(plant.resonator, f)) for f in PLANT_RESONATOR})
    control = Control(
        amplitude=ctl.amplitude,
        drive=ctl.drive,
        excitation_phase=_as_law(ctl.excitation_phase),
        pll_bandwidth=ctl.pll_bandwidth,
        agc_bandwidth=ctl.agc_bandwidth,
        quadrature_bandwidth=ctl.quadrature_bandwidth,
        forcer_gain_mismatch=_as_law(ctl.forcer_gain_mismatch),
    )
    return Gyro(resonator=res, control=control, readout=Readout(), noise=None)


def plant_to_json(plant: Gyro | None) -> dict | None:
    """A `known_plant` as JSON numbers (laws as [p0, p1, p2, λ, T_ref])."""
    if plant is None:
        return None
    law = lambda x: [float(getattr(x, f)) for f in _LAW_FIELDS]
    ctl = plant.control
    return {
        "resonator": {f: law(getattr(plant.resonator, f)) for f in PLANT_RESONATOR},
        "control": {
            "amplitude": float(ctl.amplitude),
            "drive": ctl.drive,
            "excitation_phase": law(ctl.excitation_phase),
            "pll_bandwidth": float(ctl.pll_bandwidth),
            "agc_bandwidth": float(ctl.agc_bandwidth),
            "quadrature_bandwidth": float(ctl.quadrature_bandwidth),
            "forcer_gain_mismatch": law(ctl.forcer_gain_mismatch),
        },
    }


def plant_from_json(d: dict | None) -> Gyro | None:
    """Inverse of `plant_to_json`."""
    if d is None:
        return None
    law = lambda x: TemperatureLaw(*x)
    c = dict(d["control"])
    c["excitation_phase"] = law(c["excitation_phase"])
    c["forcer_gain_mismatch"] = law(c["forcer_gain_mismatch"])
    res = Resonator(**{f: law(d["resonator"][f]) for f in PLANT_RESONATOR})
    return known_plant(Gyro(resonator=res, control=Control(**c), readout=Readout(), noise=None))
