"""The closed-loop plant the grey box takes as known: its resonator constants
(`PLANT_RESONATOR`) and PI loops, normalised to one fixed layout (`known_plant`) and its
JSON form (`plant_to_json`, `plant_from_json`)."""

from __future__ import annotations

from ..gyro import Gyro
from ..resonator.control import Control
from ..resonator.params import Resonator, TemperatureLaw
from ..resonator.readout import Readout
from ..resonator.slow import open_loop

PLANT_RESONATOR = ("omega", "tau", "delta_omega", "theta_omega", "chi")
"""What a plant (`PhysicalCompensator(plant=…)`) gives the grey box of its resonator, held
fixed in the fit: mean frequency ω [rad/s], decay time τ [s], frequency split Δω [rad/s]
and its axis θ_ω [rad, electrical], nonlinearity χ [rad²/s²] — each a number or a
[`TemperatureLaw`][hrgjax.TemperatureLaw]. Of its loops it takes what whole-angle mode reads
(`PLANT_CONTROL`)."""

PLANT_CONTROL = (
    "amplitude", "drive", "excitation_phase", "pll_bandwidth", "agc_bandwidth",
    "quadrature_bandwidth", "forcer_gain_mismatch", "forcer_gain", "forcer_angle",
)  # fmt: skip
"""What a plant gives the grey box of its `Control`: the AGC set point, the drive, the
excitation phase error [rad], the PI loops' bandwidths [rad/s] and the forcers' gain
mismatch, common gain error and angle error [rad] — everything whole-angle mode reads. The
rest (`rebalance_bandwidth`, `rebalance_limit`, `k_e_nominal`) is read only in
force-to-rebalance mode, which `known_plant` refuses."""
_PLANT_LAWS = ("excitation_phase", "forcer_gain_mismatch")
"""The `PLANT_CONTROL` fields always kept as [`TemperatureLaw`][hrgjax.TemperatureLaw]s."""
_PLANT_EITHER = ("forcer_gain", "forcer_angle")
"""The `PLANT_CONTROL` fields kept as given: a number (as files written before they were kept
hold them, so those files load) or a [`TemperatureLaw`][hrgjax.TemperatureLaw]."""

_LAW_FIELDS = ("p0", "p1", "p2", "lam", "t_ref")


def _as_law(x) -> TemperatureLaw:
    if isinstance(x, TemperatureLaw):
        return TemperatureLaw(*(getattr(x, f) for f in _LAW_FIELDS))
    return TemperatureLaw(x)


def known_plant(plant: Gyro | None) -> Gyro | None:
    """The part of a gyro the grey box takes as known (`PLANT_RESONATOR` and
    `PLANT_CONTROL`), in one fixed layout (each such parameter a
    [`TemperatureLaw`][hrgjax.TemperatureLaw], the forcers' `forcer_gain` and `forcer_angle`
    a number or a law as given) so a fitted compensator saves and loads; `None` stays `None`
    (ideal loops).

    **Raises:** `TypeError` for anything but a [`hrgjax.Gyro`][]; `ValueError` for a plant
    whose loops are ideal or free (nothing for the grey box to model: give `plant=None`), with
    a loop open (a bandwidth of 0: no slow manifold) or run in force-to-rebalance mode (the
    grey box models whole-angle data)."""
    if plant is None:
        return None
    if not isinstance(plant, Gyro):
        raise TypeError(f"plant must be a hrgjax.Gyro (its loops and resonator constants) or "
                        f"None; got {type(plant).__name__}")  # fmt: skip
    ctl = plant.control
    if ctl.ideal or not ctl.enabled:
        raise ValueError("plant.control: ideal or open loops have no lag to model; give "
                         "plant=None for the ideal-loop grey box")  # fmt: skip
    if (loop := open_loop(ctl)) is not None:
        raise ValueError(f"plant.control.{loop[0]}_bandwidth = {loop[1]:g} rad/s opens that "
                         "loop: the grey box models closed PI loops (an open one has no slow "
                         "manifold); give it one > 0, or plant=None for the ideal-loop grey "
                         "box")  # fmt: skip
    if ctl.mode != "wa":
        raise ValueError(f"plant.control.mode must be 'wa' (the grey box models whole-angle "
                         f"data); got {ctl.mode!r}: give plant.in_mode('wa')")  # fmt: skip
    res = Resonator(**{f: _as_law(getattr(plant.resonator, f)) for f in PLANT_RESONATOR})
    kept = {f: getattr(ctl, f) for f in PLANT_CONTROL}
    for f in _PLANT_LAWS + _PLANT_EITHER:
        if f in _PLANT_LAWS or isinstance(kept[f], TemperatureLaw):
            kept[f] = _as_law(kept[f])
    return Gyro(resonator=res, control=Control(**kept), readout=Readout(), noise=None)


def plant_to_json(plant: Gyro | None) -> dict | None:
    """A `known_plant` as JSON numbers (laws as [p0, p1, p2, λ, T_ref])."""
    if plant is None:
        return None
    law = lambda x: (
        [float(getattr(x, f)) for f in _LAW_FIELDS] if isinstance(x, TemperatureLaw) else float(x)
    )
    ctl = plant.control
    return {
        "resonator": {f: law(getattr(plant.resonator, f)) for f in PLANT_RESONATOR},
        "control": {f: ctl.drive if f == "drive" else law(getattr(ctl, f)) for f in PLANT_CONTROL},
    }  # fmt: skip


def plant_from_json(d: dict | None) -> Gyro | None:
    """Inverse of `plant_to_json`. A file written before `forcer_gain` and `forcer_angle` were
    kept has neither: they take `Control`'s defaults (0), as its fit did."""
    if d is None:
        return None
    law = lambda x: TemperatureLaw(*x)
    either = lambda k, v: k in _PLANT_EITHER and isinstance(v, list)
    c = {k: law(v) if k in _PLANT_LAWS or either(k, v) else v for k, v in d["control"].items()}
    res = Resonator(**{f: law(d["resonator"][f]) for f in PLANT_RESONATOR})
    return known_plant(Gyro(resonator=res, control=Control(**c), readout=Readout(), noise=None))
