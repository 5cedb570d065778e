"""What [`discover`][hrgjax.discovery.discover] returns: a
[`Discovery`][hrgjax.discovery.result.Discovery], with the fitted parameters in the units a
gyro engineer reads (°/h of input rate, ppm/°C, …) beside the model's own, the equations of
the fitted model, its JSON report and its figure — drawn from the very fits it reports."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
from typing import Any

import numpy as np

from .effects import CATALOGUE, NOMINAL
from .noise import NOISE_GIVEN, NOISE_STILL
from .trust import NOT_PINNED

DESIGN_KEYS = ("missing_effect", "ranking", "gap_before", "gap_after", "noise_floor", "metric")
"""The keys of DESIGN.md's discovery report, first in the JSON."""


def _clean(x):
    """JSON-safe copy: NumPy scalars to Python numbers, non-finite numbers to None."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    return x


def to_user_units(parameters: dict, k_e: float) -> dict:
    """`{effect: {param: {"value", "std"}}}` in model units → `{effect: {param: {"value",
    "sigma", "unit"}}}` in user units at angular gain `k_e` (see
    [`Param`][hrgjax.discovery.effects.Param]); a missing or `None` std stays `None`."""
    out = {}
    for name, ps in parameters.items():
        spec = {p.name: p for p in CATALOGUE[name].params}
        out[name] = {}
        for pname, v in ps.items():
            p = spec[pname]
            f = p.user_scale(k_e)
            std = v.get("std") if isinstance(v, dict) else None
            value = v["value"] if isinstance(v, dict) else v
            out[name][pname] = {
                "value": float(value) * f,
                "sigma": None if std is None else abs(f) * float(std),
                "unit": p.user_unit,
            }

    return out


SCREENING_SIGMA = (
    "a first-round refit's textbook sigma (sigma_textbook): it reads the noise model as exact "
    "and leaves out the structure and noise level the residual shows; an accepted effect's "
    "error bars are in 'parameters'"
)
"""Why the JSON ranking's parameters carry no `sigma` (on a grid whose damping law left a
2θ·ΔT² shape, the textbook σ was 35× below the reported one)."""


def _screening_sigma(params: dict) -> dict:
    """A ranking row's user-unit parameters with their σ moved to `sigma_textbook`, `sigma`
    None and `why_no_sigma` saying why (`SCREENING_SIGMA`)."""
    out = {}
    for name, v in params.items():
        out[name] = {"value": v["value"], "sigma": None, "sigma_textbook": v["sigma"],
                     "unit": v["unit"]}  # fmt: skip
        out[name]["why_no_sigma"] = SCREENING_SIGMA if v["sigma"] is not None else "scanned"
    return out


def _number(v: dict, why: str | None = None) -> str:
    """'0.301 ± 0.004 °/h' (three significant digits of the value); a value without σ says
    why in brief (`why`: its `why_no_sigma`): '600 s (scanned, no σ)', '0.3 °/h (no σ: σ_b
    not pinned)'."""
    unit = f" {v['unit']}" if v["unit"] else ""
    if v["sigma"] is not None and not math.isfinite(v["sigma"]):
        return f"{v['value']:.4g}{unit} (not determined by these data)"
    if v["sigma"] is None:
        note = ""
        if why:
            note = " (no σ: σ_b not pinned)" if why.startswith(NOT_PINNED) else " (scanned, no σ)"
        return f"{v['value']:.4g}{unit}" + note
    return f"({v['value']:.4g} ± {v['sigma']:.2g}){unit}"


_DOUBLE_SIGN = re.compile(r"([+−]) (½·)?(\(?)[-−]")


def tidy_signs(text: str) -> str:
    """'a − (-0.3 ± 0.1)' → 'a + (0.3 ± 0.1)', '+ ½·(-x)' → '− ½·(x)': one sign between
    terms."""
    return _DOUBLE_SIGN.sub(
        lambda m: ("−" if m[1] == "+" else "+") + " " + (m[2] or "") + m[3], text
    )


@dataclasses.dataclass(frozen=True)
class Discovery:
    """The outcome of [`discover`][hrgjax.discovery.discover] (immutable).

    - `verdict`: `"found"`, `"ambiguous"`, `"none"` (nothing is missing) or `"unexplained"`
      (structure is left that no catalogue effect explains); `missing_effect`: the first
      accepted effect or `None`; `accepted`: every accepted effect, in order;
      `ambiguous_with`, `discriminate`: rivals and the experiments that separate them.
    - `gap_before`, `gap_after`, `noise_floor` [°/h]: the held-out gap (DESIGN.md) of the
      nominal and the final model, both fitted under the final noise model, and what noise
      alone gives it; `metric` names it;
      `structure_left`: the final model still leaves significant structure.
    - `fit_parameters`: the final model's parameters in model units
      (`{effect: {param: {"value", "std"}}}`, rad/s of pattern rate, …); `parameters` (a
      property) gives them in user units; `k_e`: the angular gain used for that conversion
      (the fitted one when the model fits it).
    - `ranking` (first-round candidates by score, with the refit's parameters in model units,
      each `{"value", "std"}`; a scanned time constant is a plain value, with no σ),
      `screening` (their first-round test statistics, each row with `round` 1 and
      `accepted_in_round`: the round in which the effect was accepted, or None;
      `refused_by`: the first acceptance rule it fails, named as in
      [`REFUSALS`][hrgjax.discovery.search.REFUSALS], or None; `p_stat`: its p-value at
      the noise level the residual shows, σ_b's uncertainty carried in, where that was
      computed ([`statistical_p_value`][hrgjax.discovery.trust.statistical_p_value]); `agreement`: its per-run
      agreement share where that was computed; `agreement_note`: why it is None where the
      check was asked for but could not be made, e.g. no two parts of the training runs each
      resolve the effect),
      `consistency` (continuous records: per-run refits), `noise` (the noise model in report units), `split` (training and held-out
      runs), `shape` (`"dwell"` or `"continuous"`).
    - `residuals`: the residuals of the nominal (`"before"`) and the final (`"after"`) fit —
      what [`plot`][hrgjax.discovery.result.Discovery.plot] draws.
    - `leftover`: the strongest shape the final fit leaves (a harmonic of θ, a covariate),
      with its size in user units and its significance in words
      ([`describe`][hrgjax.discovery.leftover.describe]); None when no shape can be tried.
    - `uncertainty`: what the parameters' σ are ([`honest`][hrgjax.discovery.trust.honest]:
      the noise level read from the fit's residual, the structure left fitted beside the
      model and its pull added): `{"noise_scale", "shapes", "basis"}`, with continuous
      records `"run_bias"` (σ_b's uncertainty carried in,
      [`run_bias.spread`][hrgjax.discovery.run_bias.spread]: `{"runs", "dof", "sigma_b_dph",
      "not_pinned"}`); the JSON adds `sigma_model` (`{"effect.param": the pull's share of
      σ}`, user units) and `no_sigma` (`{"effect.param": why}`: a scanned time constant; a
      parameter the run means pin where too few runs leave σ_b unpinned).
    - `upper_limits`: where nothing was accepted (`none`, `unexplained`; else None), 95 %
      upper limits on each candidate, from the last round's refits (the model with that
      effect added; `trust.upper_limits`):
      `{effect: {param: {"value", "std", "ci95_upper"}}}` in model units; `user_limits`
      (a property) and the JSON's `upper_limits` give them in user units, and `equations()`
      prints them where the verdict is `none` or `unexplained`.
    - `run_order_confound`: `{effect: share}` for each accepted effect that takes more than
      `trust.CONFOUND_SHARE` of a bias drifting linearly through the session (runs in id
      order; dwell grids: `trust.run_order_confound`):
      its value holds any such drift, and `equations()` says so.
    """

    verdict: str
    missing_effect: str | None
    accepted: tuple[str, ...]
    ambiguous_with: tuple[str, ...]
    discriminate: dict
    gap_before: float
    gap_after: float
    noise_floor: float
    metric: str
    structure_left: bool
    fit_parameters: dict
    k_e: float
    ranking: tuple[dict, ...]
    screening: tuple[dict, ...]
    consistency: dict
    noise: dict
    split: dict
    shape: str
    residuals: dict = dataclasses.field(repr=False, compare=False)
    leftover: dict | None = None
    uncertainty: dict | None = None
    upper_limits: dict | None = None
    run_order_confound: dict | None = None

    @property
    def parameters(self) -> dict:
        """The final model's parameters in user units: `{effect: {param: {"value", "sigma",
        "unit"}}}` (a pattern-rate term as the input rate it imitates, °/h; gains in ppm)."""
        return to_user_units(self.fit_parameters, self.k_e)

    @property
    def user_limits(self) -> dict:
        """`upper_limits` in user units: `{effect: {param: {"value", "sigma", "ci95_upper",
        "unit"}}}` (`ci95_upper` bounds the parameter's size |value| at 95 %)."""
        out = {}
        for name, ps in (self.upper_limits or {}).items():
            user = to_user_units({name: ps}, self.k_e)[name]
            spec = {p.name: p for p in CATALOGUE[name].params}
            for pname, v in ps.items():
                f = abs(spec[pname].user_scale(self.k_e))
                user[pname]["ci95_upper"] = f * float(v["ci95_upper"])
            out[name] = user
        return out

    def to_json(self) -> dict:
        """The report as a JSON-ready dict: DESIGN.md's keys first (`ranking` parameters and
        `parameters` in user units, each `{"value", "sigma", "unit"}`; a ranking row's
        `sigma` is None, its screening refit's textbook σ beside it as `sigma_textbook` with
        `why_no_sigma`, `SCREENING_SIGMA`), then the rest; `model_parameters` keeps the fit in
        model units."""
        ranking = [
            {
                "effect": r["effect"],
                "score": r["score"],
                "params": _screening_sigma(
                    to_user_units({r["effect"]: r["params"]}, self.k_e)[r["effect"]]
                ),
            }
            for r in self.ranking
        ]
        out: dict[str, Any] = {
            "missing_effect": self.missing_effect,
            "ranking": ranking,
            "gap_before": self.gap_before,
            "gap_after": self.gap_after,
            "noise_floor": self.noise_floor,
            "metric": self.metric,
            "units": {"gap_before": "°/h", "gap_after": "°/h", "noise_floor": "°/h"},
            "verdict": self.verdict,
            "structure_left": self.structure_left,
            "accepted": list(self.accepted),
            "ambiguous_with": list(self.ambiguous_with),
            "discriminate": dict(self.discriminate),
            "parameters": self.parameters,
            "model_parameters": self.fit_parameters,
            "angular_gain_k_e": self.k_e,
            "leftover": self.leftover,
            "upper_limits": self.user_limits,
            "run_order_confound": dict(self.run_order_confound or {}),
            "uncertainty": self._uncertainty_json(),
            "gap_note": self.gap_note(),
            "screening": list(self.screening),
            "consistency": self.consistency,
            "noise": self.noise,
            "split": self.split,
            "shape": self.shape,
        }
        return _clean(out)

    def write_json(self, path: str | os.PathLike) -> str:
        """Write [`to_json`][hrgjax.discovery.result.Discovery.to_json] to `path`
        (atomically); returns the path."""
        from .._io import atomic_write

        path = os.fspath(path)
        with atomic_write(path, "w") as fh:  # makes the folder
            json.dump(self.to_json(), fh, indent=1, ensure_ascii=False)
        return path

    def equations(self) -> str:
        """The fitted model as equations in user units (as a fitted pysindy model prints):
        the apparent input rate each effect adds, then the readout terms, and the leftover
        shape where structure is left, the verdict is `unexplained` or the shape is
        significant."""
        user = self.parameters
        lines = [f"verdict: {self.verdict}"]
        if "angular_gain" in user:
            k_e = user["angular_gain"]["k_e"]
            sigma = k_e["sigma"]
            if sigma is not None and not (math.isfinite(sigma) and sigma < abs(k_e["value"])):
                # a σ as large as the value or infinite: no rotation run turns the wave, or
                # every one at one rate with no static run (k_e beside the bias)
                lines.append("angular gain k_e: not identified by these data (it needs "
                             "rotations beside static runs or at a second table rate)")  # fmt: skip
            else:
                why = self.fit_parameters["angular_gain"]["k_e"].get("why_no_sigma")
                lines.append(f"angular gain k_e = {_number(k_e, why)}")
        rate, readout = [], []
        nominal = [n for n in NOMINAL if n in user]
        for name in nominal + [n for n in user if n not in nominal]:
            ps = user[name]
            if name == "angular_gain":
                continue
            effect = CATALOGUE[name]
            # a parameter the fit held (the loop bandwidth of a dwell fit) reads at its value
            fields = {q.name: f"{q.scale:.4g} {q.unit} (held)" for q in effect.params}
            raw = self.fit_parameters.get(name, {})
            fields.update(
                {k: _number(v, raw.get(k, {}).get("why_no_sigma")) for k, v in ps.items()}
            )
            text = tidy_signs(effect.formula.format(**fields))
            (readout if effect.where == "readout" else rate).append(f"{text}    [{name}]")
        if rate:
            lines.append("apparent input rate − table rate [°/h] =")
            for i, t in enumerate(rate):
                # a term written with a leading minus continues the sum with it
                term = tidy_signs("− " + t[1:] if t.startswith("−") else "+ " + t)
                if i == 0:
                    term = term[2:] if term.startswith("+") else "−" + term[2:]
                lines.append(("    " if i == 0 else "  ") + term)
        if readout:
            lines.append("readout:")
            lines += ["    " + t for t in readout]
        lag = self.sensor_lag_s()
        if lag is not None:
            lines.append(
                f"c/b₁ = {lag:.4g} s: a thermometer lagging the gyro by that long gives "
                "thermal_rate exactly (c = b₁·τ); a second thermometer or its step response "
                "tells them apart"
            )
        left = self.leftover
        if left is not None and (
            self.structure_left or self.verdict == "unexplained" or left.get("significant")
        ):  # a significant shape is worth a line even where the gap is at the floor
            lines.append(f"left over: {left['words']}")
        if self.verdict in ("none", "unexplained") and self.upper_limits:
            lines.append("95 % upper limits on the effects not taken (|value| + 1.96σ):")
            for name, ps in self.user_limits.items():
                lines.append(f"    {name}: " + ", ".join(
                    f"|{k}| < {v['ci95_upper']:.2g} {v['unit']}".rstrip()
                    if math.isfinite(v["ci95_upper"]) else f"{k} not determined by these data"
                    for k, v in ps.items()
                ))  # fmt: skip
        for name, share in (self.run_order_confound or {}).items():
            lines.append(
                f"note: on these runs {name} is {100 * share:.0f} % the same as a bias "
                "drifting steadily through the session (runs in id order): its value holds "
                "any such drift; repeat a condition at the session's end or change the order"
            )
        lines.append(
            f"held-out gap {self.gap_before:.3g} → {self.gap_after:.3g} °/h "
            f"(noise floor {self.noise_floor:.3g} °/h); ΔT = T − 20 °C, θ electrical"
        )
        why = self.gap_note()
        if why:
            lines.append(why)
        if self.uncertainty:
            lines.append("± are 1σ: " + self.uncertainty["basis"])
        source = (self.noise or {}).get("source")
        if source and source not in (NOISE_STILL, NOISE_GIVEN):  # no still stretch: say so
            lines.append(f"noise model from {source}")
        return "\n".join(lines)

    def sensor_lag_s(self) -> float | None:
        """c/b₁ [s] where both `thermal_rate` (c) and `bias_temperature` (b₁) are in the
        model: the lag τ of a thermometer behind the gyro that would give that c alone
        (T_read = T − τṪ, so b₁·T = b₁·T_read + b₁τ·Ṫ); None otherwise."""
        p = self.fit_parameters
        if "thermal_rate" not in p or "bias_temperature" not in p:
            return None
        b1 = p["bias_temperature"]["b1"]["value"]
        return float(p["thermal_rate"]["c_Tdot"]["value"] / b1) if b1 else None

    def _uncertainty_json(self) -> dict | None:
        """`uncertainty` with, in user units, each parameter's share of its σ that the
        structure left puts there (`sigma_model`) and why a parameter has no σ (`no_sigma`);
        `parameters` keeps DESIGN.md's `{"value", "sigma", "unit"}`."""
        if self.uncertainty is None:
            return None
        model, none = {}, {}
        for name, ps in self.fit_parameters.items():
            spec = {p.name: p for p in CATALOGUE[name].params}
            for pname, v in ps.items():
                if v.get("std_model"):
                    f = abs(spec[pname].user_scale(self.k_e))
                    model[f"{name}.{pname}"] = f * float(v["std_model"])
                if v.get("why_no_sigma"):
                    none[f"{name}.{pname}"] = v["why_no_sigma"]
                elif v.get("std") is not None and not math.isfinite(v["std"]):
                    none[f"{name}.{pname}"] = (
                        "not determined by these data (its column is a combination of the "
                        "others', or the data never excite it)"
                    )
        return {**self.uncertainty, "sigma_model": model, "no_sigma": none}

    def gap_note(self) -> str | None:
        """Why the held-out gap rose although effects were accepted (None when it did not):
        on continuous records it is the RMS of the held-out runs' mean rate residuals, set by
        each run's switch-on bias (the floor), and the acceptance is judged on the held-out
        whitened χ², which the bias is part of."""
        if not self.accepted or not self.gap_after > self.gap_before:
            return None
        rise = self.gap_after - self.gap_before
        return (
            f"note: the held-out gap rose by {rise:.3g} °/h although "
            f"{', '.join(self.accepted)} {'was' if len(self.accepted) == 1 else 'were'} "
            f"accepted: the gap is a few held-out runs' mean rates, whose switch-on biases "
            f"alone give it {self.noise_floor:.3g} °/h (the floor; the rise is "
            f"{rise / self.noise_floor if self.noise_floor > 0 else float('inf'):.2g}× it); "
            "effects are accepted on the "
            "held-out whitened χ², which weighs that bias as noise"
        )

    def __str__(self) -> str:
        return self.equations()

    def plot(self, path: str | os.PathLike) -> str:
        """One figure of the report, from the reported fits: residuals of the nominal and of
        the final model (dwell grids: the window drift against wave angle per temperature;
        continuous records: each run's angle residual against time, held-out runs dashed),
        the first-round scores and the gap against the noise floor. Returns the path."""
        from .report import plot_discovery

        return plot_discovery(self, os.fspath(path))
