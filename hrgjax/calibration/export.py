"""Saving compensators: `.eqx` (equinox serialisation) and a plain JSON for embedded code.

`.eqx` files start with one JSON line (class and hyperparameters, enough to rebuild the
skeleton) followed by `eqx.tree_serialise_leaves` of the fitted module.

The JSON export lists every number a C program needs, in SI units, with the formula in
words; [`load_json`][hrgjax.calibration.load_json] rebuilds the same compensator from it (the
round trip is tested).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._io import atomic_write, read_json
from .._x64 import require_x64
from ._compensator import DOMAIN_MARGIN_C
from .evaluate import NoCompensation
from .fourier import T_SCALE, FourierCompensator
from .mlp import MLPCompensator
from .physical import NAMES, PARAMETERS, PhysicalCompensator, plant_from_json, plant_to_json
from .self_calibration import PrecessionCompensator

FORMAT_VERSION = 3
"""Version of the `.eqx` and JSON files (2: the `.eqx` header holds the payload's length and
SHA-256; 3: the SHA-256 covers the header too, so an edited hyperparameter is caught)."""
_CLASSES = {
    c.__name__: c
    for c in (
        FourierCompensator, MLPCompensator, PhysicalCompensator, NoCompensation,
        PrecessionCompensator,
    )
}  # fmt: skip


_HYPER_FIELDS = {
    FourierCompensator: (
        "harmonics", "temperature_degree", "fit_temperature_c", "tolerance_c", "k_e", "window_s"
    ),
    MLPCompensator: (
        "drift_width", "sf_width", "encoding", "steps", "learning_rate", "bin_deg", "e2e_steps",
        "k_e", "mode", "window_s", "drift_t_curvature", "sf_t_curvature",
    ),
}  # fmt: skip
"""The fields that `_hyper` saves, in this order, of the compensators whose hyperparameters
are plain fields (`window_s` [s] and MLP's `mode` were added later: older files without them load
with the class defaults; so were `temperature_range` and `n_temperature_levels`, saved after
these when recorded: older files load with the range unknown). MLP's `drift_t_curvature` and
`sf_t_curvature` (the smoothness prior in T, commit ab7af6e) too, but an older file loads
with 0.0 (`_MLP_BEFORE_PRIOR`), not the defaults: its networks were trained without the
prior, and a re-fit of the loaded compensator should train as it was."""
_MLP_BEFORE_PRIOR = {"drift_t_curvature": 0.0, "sf_t_curvature": 0.0}
_PLANT_BALANCE = "newton"
"""How a grey box with a plant solves its loops' slow-manifold balance, saved beside the plant
(`hyper["balance"]`): `"newton"` since commit a0eb9e0 (the nonlinear balance). A file with a
plant and no such key was fitted under the linearised balance: it loads with the same numbers,
but its drift and scale factor are now evaluated with the nonlinear balance and differ from
what was fitted (≈ 7e-4 of the scale factor at a 50 mHz split), so loading it warns."""


_FITTED_FIELD = {
    FourierCompensator: "drift_coef",
    MLPCompensator: "drift_net",
    PhysicalCompensator: "values",
    PrecessionCompensator: "drift_coef",
}
"""The field each compensator's `fit` fills (None before): what saving and exporting check."""
_STD_FIELDS = ("drift_std", "gain_std")
"""`PrecessionCompensator`'s standard errors, saved when set (listed in `hyper["std"]`, the
`.eqx` payload and the JSON export holding their arrays); a file without the key (written
before session 34) loads with them `None`."""


def _require_fitted(comp) -> None:
    for cls, field in _FITTED_FIELD.items():
        if isinstance(comp, cls) and getattr(comp, field) is None:
            raise ValueError(
                f"this {cls.__name__} is not fitted; fit it before saving (comp = comp.fit(data))"
            )


def _hyper(comp) -> dict:
    _require_fitted(comp)
    for cls, names in _HYPER_FIELDS.items():
        if isinstance(comp, cls):
            hyper = {name: getattr(comp, name) for name in names}
            if cls is MLPCompensator and comp.st_width:
                hyper["st_width"] = comp.st_width
            return hyper | _domain(comp)
    if isinstance(comp, PhysicalCompensator):
        return {
            "k_e": comp.k_e,
            "window_s": comp.window_s,
            "max_steps": comp.max_steps,
            "stats": [list(p) for p in comp.stats],
        } | ({"plant": plant_to_json(comp.plant), "sf_rate": comp.sf_rate,
              "balance": _PLANT_BALANCE} if comp.plant is not None else {}) | _domain(comp)  # fmt: skip
    if isinstance(comp, NoCompensation):
        return {"k_e": comp.k_e}
    if isinstance(comp, PrecessionCompensator):
        std = [f for f in _STD_FIELDS if getattr(comp, f) is not None]
        hyper = {"harmonics": comp.harmonics, "settle_s": comp.settle_s,
                 "temperature_bin": comp.temperature_bin, "k_e": comp.k_e,
                 "temperatures_c": list(comp.temperatures_c)}  # fmt: skip
        return hyper | ({"std": std} if std else {})
    raise TypeError(f"cannot save a {type(comp).__name__}")


def _domain(comp) -> dict:
    """The fit's temperature domain for the header (`temperature_range` [°C] as a list,
    `n_temperature_levels`), when recorded: a file saved before it was recorded, or a
    compensator without one, has neither key and loads with the range unknown (`None`)."""
    out = {}
    if getattr(comp, "temperature_range", None) is not None:
        out["temperature_range"] = list(comp.temperature_range)
    if getattr(comp, "n_temperature_levels", None) is not None:
        out["n_temperature_levels"] = comp.n_temperature_levels
    return out


def _warn_linearised_balance(path, name: str, hyper: dict) -> None:
    """Warn where a loaded grey box's plant predates the nonlinear balance (no `balance` in
    its hyperparameters); refuse a `balance` this hrgjax does not know. Called once the file
    has loaded, so a damaged file reports its damage, not this."""
    if name != "PhysicalCompensator" or hyper.get("plant") is None:
        return
    balance = hyper.get("balance")
    if balance is None:
        warnings.warn(
            f"hrgjax: {path}: this grey box's plant was fitted under the linearised "
            "slow-manifold balance (files saved before 2026-11-30, commit a0eb9e0); its drift "
            "and scale factor are now evaluated with the nonlinear balance (≈ 7e-4 of the scale "
            "factor apart at a 50 mHz split): refit it on its data to compensate as fitted",
            UserWarning,
            stacklevel=3,
        )
    elif balance != _PLANT_BALANCE:
        raise ValueError(
            f"{path}: hyper.balance {balance!r} is not a slow-manifold balance this hrgjax "
            f"knows ({_PLANT_BALANCE!r}); the file was edited or written by a newer hrgjax"
        )


def _skeleton(name: str, hyper: dict):
    cls = _CLASSES[name]
    if cls is FourierCompensator:
        k = (hyper["temperature_degree"] or 0) + 1
        shape = (k, 2 * hyper["harmonics"] + 1)
        return cls(**hyper, drift_coef=jnp.zeros(shape), sf_coef=jnp.zeros(shape))
    if cls is MLPCompensator:
        return cls(**_MLP_BEFORE_PRIOR | hyper).init(jax.random.key(0))
    if cls is PhysicalCompensator:
        stats = tuple(tuple(p) for p in hyper.pop("stats"))
        plant = plant_from_json(hyper.pop("plant", None))
        hyper.pop("balance", None)  # `_warn_linearised_balance` has read it
        n = len(NAMES)
        return cls(**hyper, stats=stats, values=jnp.zeros(n), covariance=jnp.zeros((n, n)),
                   plant=plant)  # fmt: skip
    if cls is PrecessionCompensator:
        std = hyper.pop("std", [])
        hyper = hyper | {"temperatures_c": tuple(hyper["temperatures_c"])}
        shape = (len(hyper["temperatures_c"]), 2 * hyper["harmonics"] + 1)
        return cls(**hyper, drift_coef=jnp.zeros(shape), gain_coef=jnp.zeros(shape),
                   **{f: jnp.zeros(shape) for f in std})  # fmt: skip
    return cls(**hyper)


def checksum(header: dict, payload: bytes) -> str:
    """SHA-256 (hex) of a `.eqx` file's header (all but its `sha256`, keys sorted) and
    payload: what format 3 stores in `sha256`."""
    head = {k: v for k, v in header.items() if k != "sha256"}
    return hashlib.sha256(json.dumps(head, sort_keys=True).encode() + b"\n" + payload).hexdigest()


def save_compensator(comp, path: str | os.PathLike) -> str:
    """Write a fitted compensator to `path` (`.eqx`); returns the path.

    The file is one JSON header line (class, hyperparameters, format version, the payload's
    length and SHA-256) and the equinox serialisation of the module; it is written under a
    temporary name and renamed when complete."""
    path = os.fspath(path)
    _require_fitted(comp)
    buf = io.BytesIO()
    eqx.tree_serialise_leaves(buf, comp)
    payload = buf.getvalue()
    header = {
        "class": type(comp).__name__,
        "hyper": _hyper(comp),
        "format": FORMAT_VERSION,
        "bytes": len(payload),
    }
    header["sha256"] = checksum(header, payload)
    with atomic_write(path, "wb") as fh:
        fh.write((json.dumps(header) + "\n").encode())
        fh.write(payload)
    return path


def load_compensator(path: str | os.PathLike):
    """Read a compensator written by [`save_compensator`][hrgjax.calibration.save_compensator].

    **Raises:** `ValueError` naming the file if it is not an hrgjax compensator, was written by
    a newer hrgjax (format version), is truncated or damaged (length or checksum), or does not
    match the class its header names; `RuntimeError` (one line) when JAX's float64 mode is
    off (the saved float64 coefficients would come back float32, silently).
    """
    path = os.fspath(path)
    require_x64(f"load_compensator({path!r})")
    with open(path, "rb") as fh:
        first, payload = fh.readline(), fh.read()
    try:
        header = json.loads(first.decode())
        name, hyper, version = header["class"], header["hyper"], header.get("format", 1)
    except (ValueError, KeyError, TypeError, UnicodeDecodeError):
        raise ValueError(
            f"{path}: not an hrgjax compensator (.eqx from save_compensator)"
        ) from None
    if not isinstance(version, int) or version > FORMAT_VERSION:
        raise ValueError(
            f"{path}: compensator file format {version!r}; this hrgjax reads formats up to "
            f"{FORMAT_VERSION} (update hrgjax)"
        )
    if name not in _CLASSES:
        raise ValueError(
            f"{path}: unknown compensator class {name!r}; known are {sorted(_CLASSES)}"
        )
    if version < 2 and ("sha256" in header or "bytes" in header):
        raise ValueError(f"{path}: damaged or edited: the header carries a checksum but says "
                         f"format {version!r} (formats before 2 had none)")  # fmt: skip
    if version >= 2:  # format 1 (before the checksum) is read without one
        if len(payload) != header.get("bytes"):
            raise ValueError(
                f"{path}: truncated or damaged ({len(payload)} bytes of compensator data, the "
                f"header says {header.get('bytes')})"
            )
        # format 2's checksum covers the data; from 3 on the header as well
        digest = hashlib.sha256(payload).hexdigest() if version == 2 else checksum(header, payload)
        if digest != header.get("sha256"):
            raise ValueError(f"{path}: damaged or edited (checksum mismatch over the "
                             f"{'data' if version == 2 else 'header and data'}); save the "
                             "compensator again")  # fmt: skip
    try:
        comp = eqx.tree_deserialise_leaves(io.BytesIO(payload), _skeleton(name, dict(hyper)))
    except Exception as err:  # a hand-edited header: shapes or fields do not match
        raise ValueError(
            f"{path}: the data do not match a {name} with the header's hyperparameters "
            f"({type(err).__name__}: {err})"
        ) from None
    _warn_linearised_balance(path, name, hyper)
    return comp


def _mlp_layers(net: eqx.nn.MLP) -> list[dict]:
    return [
        {"weight": np.asarray(layer.weight).tolist(), "bias": np.asarray(layer.bias).tolist()}
        for layer in net.layers
    ]


def _series(comp, coefs, **fields) -> dict:
    """A Fourier-series compensator's JSON fields: `fields`, its coefficient arrays `coefs` as
    lists and its hyperparameters."""
    return (
        fields | {c: np.asarray(getattr(comp, c)).tolist() for c in coefs} | {"hyper": _hyper(comp)}
    )


PARAMETER_UNITS = {
    name: (unit or "1").replace("°C", "degC").replace("²", "^2") for name, unit, _ in PARAMETERS
}
"""The unit of each `"parameters"` entry of a `PhysicalCompensator`'s JSON export (its
`"parameter_units"`, in the export's ASCII spelling: `rad/s/degC^2`, `1` for a pure number;
`"covariance"` is in the products of these units)."""


def to_json_dict(comp) -> dict:
    """Everything a C implementation needs, as plain lists and numbers (SI units)."""
    _require_fitted(comp)
    base = {
        "format": FORMAT_VERSION,
        "class": type(comp).__name__,
        "k_e_nominal": comp.k_e,
        "units": {
            "theta": "rad, electrical wave angle as measured",
            "temperature": "degC",
            "drift": "rad/s equivalent input rate",
        },
        "correction": "rate = (-dtheta_dt / k_e_nominal - drift(theta, T)) / sf(theta, T)",
    }
    span = comp.calibrated_range
    if span is not None:
        base["temperature_domain"] = {
            "range_c": list(span),
            "margin_c": DOMAIN_MARGIN_C,
            "outside": "extrapolate (the model's own form in T)" if comp.extrapolates else
            "pass through uncompensated: rate = -dtheta_dt / k_e_nominal",
        }  # fmt: skip
    if isinstance(comp, FourierCompensator):
        base.update(_series(
            comp, ("drift_coef", "sf_coef"),
            formula="x = (T - t_ref)/t_scale; f = sum_k x^k * (c[k][0] + "
            "sum_n c[k][2n-1] cos(2n theta) + c[k][2n] sin(2n theta))",
            t_ref=comp.fit_temperature_c, t_scale=T_SCALE, harmonics=comp.harmonics,
        ))  # fmt: skip
    elif isinstance(comp, MLPCompensator):
        base.update(
            formula="input = [cos 2theta, sin 2theta, (T - t_centre)/t_scale] (periodic) or "
            "[fold(theta)/(pi/2), (T - t_centre)/t_scale] (angle); h = tanh(W0 input + b0); "
            "out = W1 h + b1; drift = drift_offset + drift_scale*out_drift; "
            "sf = sf_offset + sf_scale*out_sf",
            encoding=comp.encoding,
            activation="tanh",
            t_centre=float(comp.t_centre),
            t_scale=float(comp.t_scale),
            drift_offset=float(comp.drift_offset),
            drift_scale=float(comp.drift_scale),
            sf_offset=float(comp.sf_offset),
            sf_scale=float(comp.sf_scale),
            drift_layers=_mlp_layers(comp.drift_net),
            sf_layers=_mlp_layers(comp.sf_net),
            hyper=_hyper(comp),
        )
        if comp.st_net is not None:
            from .mlp import ST_RATE_REF

            base.update(
                correction="rate = (-(dtheta_dt - s_T(theta, T) * dT_dt) / k_e_nominal "
                "- drift(theta, T)) / sf(theta, T)",
                st_formula="s_T = drift_scale * k_e_nominal / st_rate_ref * out_st [rad/degC]",
                st_rate_ref=ST_RATE_REF,
                st_layers=_mlp_layers(comp.st_net),
            )
    elif isinstance(comp, PhysicalCompensator):
        base.update(
            formula="see hrgjax.calibration.physical: averaged HRG with these laws and "
            + ("ideal loops" if comp.plant is None else "the PI loops of hyper.plant"),
            parameters={n: float(v) for n, v in zip(NAMES, np.asarray(comp.values), strict=True)},
            parameter_units=PARAMETER_UNITS,
            covariance=np.asarray(comp.covariance).tolist(),
            hyper=_hyper(comp),
        )
    elif isinstance(comp, PrecessionCompensator):
        base.update(_series(
            comp, ("drift_coef", "gain_coef"),
            formula="at each temperature_c[k]: drift_k = c[k][0] + sum_n c[k][2n-1] cos(2n theta) "
            "+ c[k][2n] sin(2n theta); linear in T between the temperatures, held beyond; "
            "sf = 1 (virtual precession does not calibrate the scale factor)",
            temperatures_c=list(comp.temperatures_c),
        ))  # fmt: skip
        std = [f for f in _STD_FIELDS if getattr(comp, f) is not None]
        if std:  # JSON has no NaN: null where the data gave no σ (fewer than 6 sweeps)
            base["standard_errors"] = ("drift_std [rad/s], gain_std [1]: 1 sigma of each "
                                       "coefficient; null where the data gave none")  # fmt: skip
            base.update({f: [[None if np.isnan(v) else float(v) for v in row]
                             for row in np.asarray(getattr(comp, f))] for f in std})  # fmt: skip
    else:
        base["hyper"] = _hyper(comp)
    return base


def export_json(comp, path: str | os.PathLike) -> str:
    """Write [`to_json_dict`][hrgjax.calibration.export.to_json_dict] to `path`."""
    path = os.fspath(path)
    with atomic_write(path, "w") as fh:
        json.dump(to_json_dict(comp), fh, indent=1)
    return path


def load_json(path: str | os.PathLike):
    """Rebuild the compensator from its JSON export
    ([`export_json`][hrgjax.calibration.export_json]).

    **Raises:** `FileNotFoundError` for no file; `ValueError` naming the file and the field,
    in one line, for a file that is not UTF-8 JSON, a newer or unknown `format`, an unknown
    class, a missing key, numbers that are not finite or arrays of the wrong shape for the
    file's `hyper` (a `PrecessionCompensator`'s `drift_std`, `gain_std`: numbers ≥ 0 or
    null, read as NaN), or a top-level copy (`k_e_nominal`, `t_ref`, `harmonics`,
    `temperatures_c`) that disagrees with `hyper`; `RuntimeError` (one line) when JAX's
    float64 mode is off (the coefficients would come back float32, silently)."""
    path = os.fspath(path)
    require_x64(f"load_json({path!r})")
    d = read_json(path)
    if not isinstance(d, dict):
        raise ValueError(f"{path}: not an hrgjax compensator JSON (expected an object)")
    version = d.get("format", 1)
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version:
        raise ValueError(f"{path}: 'format' must be a positive integer; got {version!r}")
    if version > FORMAT_VERSION:
        raise ValueError(
            f"{path}: compensator file format {version}; this hrgjax reads formats up to "
            f"{FORMAT_VERSION} (update hrgjax)"
        )
    name = d.get("class")
    if name not in _CLASSES:
        raise ValueError(
            f"{path}: unknown compensator class {name!r}; known are {sorted(_CLASSES)}"
        )
    hyper = _key(path, d, "hyper", dict)
    try:
        comp = _skeleton(name, dict(hyper))
    except Exception as err:  # a hand-edited hyper: unknown or missing fields, wrong types
        raise ValueError(
            f"{path}: 'hyper' does not describe a {name} ({type(err).__name__}: "
            f"{' '.join(str(err).split())})"
        ) from None
    _same(path, d, "k_e_nominal", comp.k_e)
    if name == "FourierCompensator":
        _same(path, d, "t_ref", comp.fit_temperature_c)
    if name in ("FourierCompensator", "PrecessionCompensator"):
        _same(path, d, "harmonics", comp.harmonics)
    if name == "PrecessionCompensator":
        _same(path, d, "temperatures_c", list(comp.temperatures_c))
    span = comp.calibrated_range  # the embedded code reads the top-level copy: it must agree
    if "temperature_domain" in d:
        top = (
            d["temperature_domain"].get("range_c")
            if isinstance(d["temperature_domain"], dict)
            else None
        )
        if span is None or top is None or [float(v) for v in top] != list(span):
            raise ValueError(
                f"{path}: 'temperature_domain' range_c = {top!r} disagrees with the value in "
                f"'hyper' ({None if span is None else list(span)!r}); the file was edited: "
                "export the compensator again"
            )

    def f64(key, like, value=None, std=False):
        value = _key(path, d, key, list) if value is None else value
        try:
            a = np.asarray(value, dtype=float)
        except (ValueError, TypeError):
            raise ValueError(f"{path}: {key!r} must be an array of numbers") from None
        if a.shape != np.shape(like):
            raise ValueError(
                f"{path}: {key!r} has shape {a.shape}; the {name} of the file's 'hyper' needs "
                f"{np.shape(like)}"
            )
        if std and not np.all(np.isnan(a) | (np.isfinite(a) & (a >= 0))):  # null read as NaN
            raise ValueError(f"{path}: {key!r} must hold standard errors: finite numbers >= 0, "
                             "or null where there is none")  # fmt: skip
        if not std and not np.all(np.isfinite(a)):
            raise ValueError(f"{path}: {key!r} holds a value that is not finite")
        return jnp.asarray(a)

    if name == "FourierCompensator":
        coefs = (f64("drift_coef", comp.drift_coef), f64("sf_coef", comp.sf_coef))
        return eqx.tree_at(lambda c: (c.drift_coef, c.sf_coef), comp, coefs)
    if name == "MLPCompensator":
        for net, key in (
            (lambda c: c.drift_net, "drift_layers"),
            (lambda c: c.sf_net, "sf_layers"),
        ) + (((lambda c: c.st_net, "st_layers"),) if comp.st_net is not None else ()):
            layers, like = _key(path, d, key, list), net(comp).layers
            if len(layers) != len(like) or not all(isinstance(x, dict) for x in layers):
                raise ValueError(f"{path}: {key!r} must list {len(like)} layers, each "
                                 "{'weight': …, 'bias': …}")  # fmt: skip
            new = []
            for i, (lay, ref) in enumerate(zip(layers, like, strict=True)):
                for part in ("weight", "bias"):
                    where = f"{key}[{i}].{part}"
                    if part not in lay:
                        raise ValueError(f"{path}: missing key {where!r}")
                    new.append(f64(where, getattr(ref, part), lay[part]))
            comp = eqx.tree_at(
                lambda c, net=net: [x for lay in net(c).layers for x in (lay.weight, lay.bias)],
                comp,
                new,
            )
        names = ("t_centre", "t_scale", "drift_offset", "drift_scale", "sf_offset", "sf_scale")
        values = [f64(n, getattr(comp, n), _key(path, d, n, float)) for n in names]
        return eqx.tree_at(lambda c: [getattr(c, n) for n in names], comp, values)
    if name == "PhysicalCompensator":
        params = _key(path, d, "parameters", dict)
        missing = [n for n in NAMES if n not in params]
        if missing:
            raise ValueError(f"{path}: 'parameters' lacks {missing}; it needs {list(NAMES)}")
        values = f64("parameters", comp.values, [params[n] for n in NAMES])
        comp = eqx.tree_at(lambda c: (c.values, c.covariance), comp,
                           (values, f64("covariance", comp.covariance)))  # fmt: skip
        _warn_linearised_balance(path, name, hyper)
        return comp
    if name == "PrecessionCompensator":
        fields = ["drift_coef", "gain_coef"] + [f for f in _STD_FIELDS if f in hyper.get("std", [])]
        new = [f64(f, comp.drift_coef, std=f in _STD_FIELDS) for f in fields]
        return eqx.tree_at(lambda c: [getattr(c, f) for f in fields], comp, new)
    return comp


def _key(path: str, d: dict, key: str, kind: type):
    """`d[key]`, or a one-line error naming the file and the key; `kind` float takes ints."""
    if key not in d:
        raise ValueError(f"{path}: missing key {key!r}")
    value = d[key]
    ok = (
        isinstance(value, int | float) and not isinstance(value, bool)
        if kind is float
        else isinstance(value, kind)
    )
    if not ok:
        what = {float: "a number", list: "a list", dict: "an object"}[kind]
        raise ValueError(f"{path}: {key!r} must be {what}; got {type(value).__name__}")
    return value


def _same(path: str, d: dict, key: str, value) -> None:
    """Refuse a top-level copy of a hyperparameter that disagrees with `hyper`."""
    if key in d and d[key] != value:
        raise ValueError(
            f"{path}: {key!r} = {d[key]!r} disagrees with the value in 'hyper' ({value!r}); "
            "the file was edited: export the compensator again"
        )
