r"""The interface every compensator implements, and the correction it implies.

A compensator models what the gyro reports when it is not told the truth, as functions of the
measured electrical wave angle θ and temperature T:

- the drift $D(\theta, T)$: measured equivalent input rate at rest [rad/s];
- the scale factor $\mathrm{SF}(\theta, T)$: measured over true rate, drift removed.

With the nominal angular gain $k_{e,\rm nom}$ the measured rate is
$\Omega_{\rm meas} = -\dot\theta_{\rm meas}/k_{e,\rm nom} = \mathrm{SF}\,\Omega + D$, so the
compensated rate is

$$\hat\Omega = \frac{-(\dot\theta_{\rm meas} - s_T\,\dot T)/k_{e,\rm nom} - D(\theta,T)}
{\mathrm{SF}(\theta,T)}.$$

$s_T = \partial\hat\theta/\partial T$ is the readout's temperature sensitivity at a fixed true
angle: when the pickoff errors change with temperature, the measured angle moves while the
pattern does not (an apparent rate proportional to $\dot T$). Only a model that knows the
readout can supply it (the physical compensator); the others take $s_T = 0$.

**Temperature domain.** A fitted compensator records the range of temperatures it was
calibrated over (`temperature_range`, [°C]; `None`: unknown — not fitted, or loaded from a
file saved before the range was recorded). [`correct`][hrgjax.calibration.AbstractCompensator.correct]
applies every compensator beyond it by default — measured, each did better than none there
in most cases (docs/calibration.md, "Temperature domain"; the MLP's rotation error at
+60 °C, fitted on 0…40 °C, was the exception: 3.2× the raw gyro's) — and counts the samples
outside it (widened by `margin_c`) in the returned
[`Corrected`][hrgjax.calibration.compensators.Corrected] data; `extrapolate=False` passes
them through uncompensated.
"""

from __future__ import annotations

import abc
import dataclasses
import enum
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._checks import check_finite_host, check_numbers
from .._compiled import bucket_pad, bucket_size, device, program
from .._x64 import require_x64
from ..data import MeasuredData
from ..units import DEG, group_temperatures
from ._correction import CORRECTED_COLUMNS as CORRECTED_COLUMNS
from ._correction import DOMAIN_MARGIN_C as DOMAIN_MARGIN_C
from ._correction import Corrected as Corrected
from ._correction import TemperatureDomainWarning as TemperatureDomainWarning
from ._correction import arc_pieces, interval_rates, warn_outside
from ._raw import check_raw
from .reduce import (
    K_E_NOMINAL,
    WINDOW_S,
    RateWindows,
    check_data,
    check_k_e,
    check_whole_angle,
    reduce,
)


def _is_number(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def check_whole(who: str, name: str, value, minimum: int, extra: str = "") -> None:
    """Refuse a compensator setting that is not a whole number ≥ `minimum`: one-line
    `ValueError` naming `who` (the class) and the field `name`; `extra` ends the expected
    form (e.g. " (number of 2nθ harmonics)")."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{who}: {name} must be a whole number ≥ {minimum}{extra}; got {value!r}")


def check_number(who: str, name: str, value, extra: str, *, minimum=None, strict=False) -> None:
    """Refuse a compensator setting that is not a finite number (≥ `minimum`, or > it with
    `strict`): one-line `ValueError` naming `who` and the field `name`; `extra` ends the
    expected form (its unit, e.g. " [°C]")."""
    ok = _is_number(value) and bool(np.isfinite(value))
    if ok and minimum is not None:
        ok = value > minimum if strict else value >= minimum
    if not ok:
        bound = "" if minimum is None else f" {'>' if strict else '≥'} {minimum:g}"
        raise ValueError(f"{who}: {name} must be a finite number{bound}{extra}; got {value!r}")


def plain_number(value):
    """A real NumPy scalar, 0-d array or concrete JAX scalar as the Python int or float it
    holds; anything else (a traced value, a bool array) as it is, for the checks to judge."""
    real = getattr(getattr(value, "dtype", None), "kind", None) in ("i", "u", "f")
    if real and isinstance(value, np.generic | np.ndarray | jax.Array) and value.ndim == 0:
        if not isinstance(value, jax.core.Tracer):
            return value.item()
    return value


def plain_setting(who: str, name: str):
    """An `eqx.field` converter for the numeric setting `name` of `who` (a static field): a
    real number given as a NumPy scalar, a 0-d array or a concrete JAX scalar becomes the
    Python int or float it holds (a static field keeps what it is given: an array there
    warned, and the checks refused it); a traced one is refused in one line (a setting is
    fixed when the compensator is built). Anything else is left to the field's check."""

    def convert(value):
        if isinstance(value, jax.core.Tracer):
            raise ValueError(f"{who}: {name} must be a number fixed when the compensator is "
                             "built; got a traced value (jit, vmap or grad)")  # fmt: skip
        return plain_number(value)

    return convert


def setting_field(who: str, name: str, default):
    """A static numeric setting of `who` named `name` with its `default` (`plain_setting`)."""
    return eqx.field(static=True, default=default, converter=plain_setting(who, name))


class FromField(enum.Enum):
    """The default of a deprecated `fit` keyword: the compensator's field of that name."""

    FIELD = "the compensator's field"

    def __repr__(self) -> str:
        return "FROM_FIELD"


FROM_FIELD = FromField.FIELD
"""Default of the deprecated per-call `fit` keywords (`window_s`, `mode`, `initial`): take
the setting from the compensator's field of that name."""


def setting(comp, name: str, value):
    """`value`, unless it is `FROM_FIELD`: then the compensator's field `name`."""
    return getattr(comp, name) if value is FROM_FIELD else value


class AbstractCompensator(eqx.Module):
    """Base class: subclasses give `drift`, `scale_factor` and `fit`; correction is shared.

    Subclasses also hold `k_e` (the nominal angular gain, static). Every setting of a method
    (harmonics, window length, training mode, starting values …) is a field given to the
    constructor, so every compensator is fitted by the same call:

    ```python
    comp = FourierCompensator(temperature_degree=3)  # or MLPCompensator(mode=…), …
    fitted = comp.fit(windows, key=key, raw=data)
    ```
    """

    k_e: eqx.AbstractVar[float]
    TRAINING_FIELDS: ClassVar[tuple[str, ...]] = ()
    """Static fields only `fit` reads (step counts, learning rates): the programs that
    evaluate a fitted compensator take them at their defaults, so they compile once."""

    @abc.abstractmethod
    def fit(self, data, *, key: jax.Array | None = None, raw: MeasuredData | None = None):
        """Fit the compensator to bench data; the same call for every compensator.

        **Arguments:**

        - `data`: [`hrgjax.MeasuredData`][] or reduced
          [`RateWindows`][hrgjax.calibration.RateWindows] (from
          [`reduce`][hrgjax.calibration.reduce] with this compensator's `k_e`).
        - `key`: PRNG key for compensators that draw random numbers (the MLP's initial
          weights; required there); the deterministic ones ignore it.
        - `raw`: the raw samples behind `data` when `data` are windows; compensators that
          need samples (the physical grey box, the MLP trained end to end) take them from
          here, the others do not use them. Every compensator checks them: refused beside
          `MeasuredData` (pass the samples once) and, beside windows, unless they are the
          windows' session (runs, and each window's mean time, temperature and wave angle).

        **Returns:** a new fitted compensator of the same class (the object is not changed).

        **Raises:** `ValueError` for data the method cannot fit (no static or no rotation
        runs, too few points …) or a `raw` refused as above; `TypeError` (or `ValueError`)
        when samples are needed and not given.
        """

    @abc.abstractmethod
    def drift(self, theta, temperature_c):
        """Drift D(θ, T): equivalent input rate at rest [rad/s]; θ electrical [rad], T [°C]."""

    @abc.abstractmethod
    def scale_factor(self, theta, temperature_c):
        """Scale factor SF(θ, T) (1 = nominal); θ electrical [rad], T [°C]."""

    def readout_temperature_sensitivity(self, theta, temperature_c):
        """s_T = ∂θ̂/∂T [rad/°C] at the measured angle θ [rad] and temperature [°C]; zero unless
        the compensator models the readout."""
        return jnp.zeros_like(theta)

    @property
    def calibrated_range(self) -> tuple[float, float] | None:
        """(T_min, T_max) [°C] of the calibration (the `temperature_range` field `fit` sets;
        `None`: unknown, or a compensator without one — nothing is checked)."""
        return getattr(self, "temperature_range", None)

    @property
    def extrapolates(self) -> bool:
        """Whether `correct` applies the compensator beyond its calibrated temperature range
        by default (`True` for every compensator here: the count, not a pass-through, is the
        default; `correct(extrapolate=False)` passes those samples through)."""
        return True

    def in_range(self, temperature_c, margin_c: float = DOMAIN_MARGIN_C) -> np.ndarray:
        """Mask (NumPy bool, the shape of `temperature_c` [°C]): True within
        `calibrated_range` widened by `margin_c` [°C] at both ends; all True when the range
        is unknown. **Raises:** `ValueError` for `margin_c` not a finite number ≥ 0 (a
        Python, NumPy or concrete JAX scalar)."""
        margin_c = plain_number(margin_c)
        check_number(type(self).__name__, "margin_c", margin_c, " [°C]", minimum=0.0)
        check_numbers(f"{type(self).__name__}.in_range: temperature_c", temperature_c,
                      "real numbers [°C]")  # fmt: skip
        temp = np.asarray(temperature_c, dtype=float)
        span = self.calibrated_range
        if span is None:
            return np.ones(temp.shape, bool)
        return (temp >= span[0] - margin_c) & (temp <= span[1] + margin_c)

    def corrected_rate(self, theta, theta_dot, temperature_c, temperature_rate=0.0):
        """Compensated equivalent input rate [rad/s] from the measured wave angle θ [rad],
        its rate θ̇ [rad/s], temperature [°C] and its rate [°C/s] (module docstring)."""
        s_t = self.readout_temperature_sensitivity(theta, temperature_c)
        measured = -(theta_dot - s_t * temperature_rate) / self.k_e
        drift, scale_factor = self._drift_and_scale_factor(theta, temperature_c)
        return (measured - drift) / scale_factor

    def _drift_and_scale_factor(self, theta, temperature_c):
        """(`drift`, `scale_factor`) at (θ [rad], T [°C]) for `corrected_rate`: a subclass
        whose two share their work (the grey box's slow manifold) computes them together."""
        return self.drift(theta, temperature_c), self.scale_factor(theta, temperature_c)

    def _program_form(self):
        """This compensator as the compiled programs of `drift_dph`, `scale_factor_at` and
        `correct` take it: a module with `drift`, `scale_factor` and `corrected_rate`. The
        programs compile once per static part, so a compensator whose fit stores numbers in
        static fields returns a form without them (the physical one does); here: itself,
        less its recorded temperature domain and with its `TRAINING_FIELDS` at their
        defaults (static fields the arithmetic does not use: a new learning rate compiled
        `drift_dph` again)."""
        fields = {f.name: f for f in dataclasses.fields(self)}
        reset = {n: None for n in DOMAIN_FIELDS if n in fields and getattr(self, n) is not None}
        reset |= {n: fields[n].default for n in self.TRAINING_FIELDS
                  if getattr(self, n) != fields[n].default}  # fmt: skip
        return dataclasses.replace(self, **reset) if reset else self

    def drift_dph(self, theta_deg, temperature_c, *, warn: bool = True) -> np.ndarray:
        """`drift` in the bench's units: θ [°] in, drift [°/h] out (NumPy). A temperature
        outside `hrgjax.plausible.RANGES` (kelvin for °C) is refused in one line; one outside
        `calibrated_range` ± `DOMAIN_MARGIN_C` is extrapolated with a
        [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning] naming how
        many points and where, as `correct` warns (`warn=False`: none)."""
        return self._pointwise("drift", theta_deg, temperature_c, warn) / DEG * 3600.0

    def scale_factor_at(self, theta_deg, temperature_c, *, warn: bool = True) -> np.ndarray:
        """`scale_factor` with θ in degrees (NumPy); temperatures checked and warned about as
        in `drift_dph`."""
        return self._pointwise("scale_factor", theta_deg, temperature_c, warn)

    def _pointwise(self, which: str, theta_deg, temperature_c, warn: bool = False) -> np.ndarray:
        """`which` ("drift" or "scale_factor") at every (θ [°], T [°C]) pair, as NumPy: one
        compiled program per compensator type and padded size (powers of two). A NaN or inf
        θ or T, or non-numbers, are refused in one line naming the argument, as is a T
        outside `plausible.RANGES["temperature_c"]` (kelvin: the hint says so); with `warn`,
        T outside the calibrated range warns (`drift_dph`)."""
        method = f"{type(self).__name__}.{'drift_dph' if which == 'drift' else 'scale_factor_at'}"
        if not isinstance(warn, bool | np.bool_):
            raise ValueError(f"{method}: warn must be True or False; got {warn!r}")
        for name, x, unit in (
            ("theta_deg", theta_deg, "°"),
            ("temperature_c", temperature_c, "°C"),
        ):
            check_numbers(f"{method}: {name}", x, f"real numbers [{unit}]")
            check_finite_host(f"{method}: {name}", np.asarray(x, dtype=float))
        plausible.check(f"{method}: temperature_c", temperature_c, "temperature_c")
        th = np.asarray(theta_deg, dtype=float) * DEG
        try:
            tc = np.broadcast_to(np.asarray(temperature_c, dtype=float), th.shape)
        except ValueError:
            raise ValueError(
                f"{method}: temperature_c of shape {np.shape(temperature_c)} does not broadcast "
                f"to theta_deg's {th.shape}"
            ) from None
        if warn and self.calibrated_range is not None:  # concrete values (checked above)
            warn_outside(method, tc, self.in_range(tc), self.calibrated_range, DOMAIN_MARGIN_C,
                         "extrapolated", "points", " (warn=False: no warning)")  # fmt: skip
        n = th.size
        if n == 0:  # nothing to evaluate (and no program to compile for it)
            return np.zeros(th.shape)
        size = bucket_size(n)
        pad = lambda x: device(bucket_pad(x.ravel(), size))
        out = np.asarray(_pointwise(self._program_form(), which, pad(th), pad(tc)))[:n]
        return out.reshape(th.shape)

    def correct(
        self, data: MeasuredData, *, extrapolate: bool | None = None,
        margin_c: float = DOMAIN_MARGIN_C, warn: bool = True,
    ) -> Corrected:  # fmt: skip
        """Compensate every run of `data`.

        Within each sample interval the wave angle and temperature move uniformly (θ̇ = Δθ/Δt,
        Ṫ = ΔT/Δt), and the compensated rate is integrated over the interval's arc by
        Gauss–Legendre quadrature (4 nodes a piece of ≤ 22.5° electrical: the midpoint
        rule's error grows with the arc a sample spans — 3.4e-2° after 60 s at 50 °/s logged
        at 1 Hz, 6.8e-6° now; `hrgjax.calibration._correction`); the intervals' integrals sum
        into `angle_corrected_deg`, which starts at 0 in each run. A gap (samples lost) is
        one interval integrated the same way, without a warning: the scale-factor term
        depends only on its end angles, the drift term assumes uniform motion across it.
        `rate_corrected_dps` at a sample is the mean of its neighbouring intervals' mean
        rates (one-sided at the ends).

        **Temperature domain.** A sample whose temperature lies outside `calibrated_range`
        widened by `margin_c` [°C] (default `DOMAIN_MARGIN_C`, 1 °C) is out of range; an
        interval with an out-of-range sample at either end is passed through uncompensated
        (the raw −θ̇/k_e,nom, bit for bit what
        [`NoCompensation`][hrgjax.calibration.NoCompensation] gives) unless `extrapolate`
        is `True`. `extrapolate=None` (default) takes the compensator's own `extrapolates`
        (`True` for every compensator here: beyond its range each did better than none in
        most cases measured, docs/calibration.md; `extrapolate=False` passes through). A
        sample inside the range beside one outside takes the mean of a compensated and a
        passed-through interval, and is not counted. The count is in
        the result either way (`Corrected.n_out_of_range`) and a
        [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning] says it,
        pointing at the caller's line (`warn=False`: no warning, for a caller that
        extrapolates on purpose and records the count itself, as `run_study` does; thread
        safe, unlike `warnings.catch_warnings`). A
        compensator whose range is unknown (a file saved before it was recorded) compensates
        every sample, as before.

        **Returns:** a [`Corrected`][hrgjax.calibration.compensators.Corrected] (a
        [`hrgjax.MeasuredData`][]) with the input columns unchanged plus
        `rate_corrected_dps` and `angle_corrected_deg`, and the out-of-range count.

        **Raises:** `RuntimeError` (one line) when JAX's float64 mode is off (the correction
        would run in float32: 5e-3 °/h off on a seed session); `ValueError` for `margin_c`
        not a finite number ≥ 0 (Python, NumPy or a concrete JAX scalar), `extrapolate`
        neither `None` nor a bool or `warn` not a bool, if the data already have those
        columns, a run has fewer than two samples, or the data are not whole-angle output the
        case turned: force-to-rebalance output or runs with a commanded precession
        ([`check_whole_angle`][hrgjax.calibration.reduce.check_whole_angle], as `calibrate`
        refuses them).
        """
        require_x64(f"{type(self).__name__}.correct")
        check_data(f"{type(self).__name__}.correct", data)
        if extrapolate is not None and not isinstance(extrapolate, bool | np.bool_):
            raise ValueError(f"extrapolate must be True, False or None (the compensator's "
                             f"own choice); got {extrapolate!r}")  # fmt: skip
        if not isinstance(warn, bool | np.bool_):
            raise ValueError(f"warn must be True or False; got {warn!r}")
        margin_c = plain_number(margin_c)  # a NumPy or concrete JAX scalar: its float
        inside = self.in_range(data["temperature_c"], margin_c)
        use_model = self.extrapolates if extrapolate is None else bool(extrapolate)
        check_whole_angle(data)
        for name in CORRECTED_COLUMNS:
            if name in data:
                raise ValueError(f"data already has a {name!r} column; correct raw data")
        runs = data.run_indices()
        for idx in runs:
            if idx.size < 2:
                raise ValueError(f"run {int(data.run[idx[0]])} has one sample; need ≥ 2")
        # Every interval of every run, integrated over its arc (`_correction`), in one
        # compiled call padded to a bucketed length: data of any size reuse a few programs.
        t = data["time_s"]
        th = data["wave_angle_deg"] * DEG
        temp = data["temperature_c"]
        first = np.concatenate([idx[:-1] for idx in runs])
        second = np.concatenate([idx[1:] for idx in runs])
        dt = t[second] - t[first]
        arcs = arc_pieces(th[first], th[second], temp[first], temp[second], dt)
        interval = interval_rates(self._program_form(), arcs)
        keep = inside[first] & inside[second]
        if not use_model and not keep.all():  # out of range: the raw rate, as NoCompensation
            interval = np.where(keep, interval, interval_rates(NoCompensation(k_e=self.k_e), arcs))
        rate_out = np.empty(len(data))
        angle_out = np.empty(len(data))
        start = 0
        for idx in runs:
            m = idx.size - 1
            rate_iv, dt_iv = interval[start : start + m], dt[start : start + m]
            start += m
            angle = np.concatenate([[0.0], np.cumsum(rate_iv * dt_iv)])
            rate = np.empty(idx.size)
            rate[0], rate[-1] = rate_iv[0], rate_iv[-1]
            rate[1:-1] = 0.5 * (rate_iv[1:] + rate_iv[:-1])
            rate_out[idx] = rate / DEG
            angle_out[idx] = angle / DEG
        cols = data.columns
        cols["rate_corrected_dps"] = rate_out
        cols["angle_corrected_deg"] = angle_out
        out = Corrected(cols, in_range=inside, temperature_range=self.calibrated_range,
                        margin_c=margin_c, extrapolated=use_model)  # fmt: skip
        if warn and out.n_out_of_range:
            how = "extrapolated" if use_model else "passed through uncompensated"
            warn_outside(f"{type(self).__name__}.correct", data["temperature_c"], inside,
                         self.calibrated_range, margin_c, how, "samples",
                         " (their mask: the result's in_range)")  # fmt: skip
        return out


DOMAIN_FIELDS = ("temperature_range", "n_temperature_levels")
"""The fields a `fit` fills with its calibration's temperature domain (static: saved in a
file's header, not its payload)."""


def as_range(value) -> tuple[float, float] | None:
    """The `temperature_range` field's converter: `None`, or (T_min, T_max) [°C] as a tuple
    of two floats (a JSON list loads as one). **Raises:** `ValueError` for anything else."""
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        lo = hi = np.nan
    if not (np.isfinite(lo) and np.isfinite(hi) and lo <= hi):
        raise ValueError(f"temperature_range must be (T_min, T_max) [°C], finite, T_min ≤ T_max, "
                         f"or None; got {value!r}")  # fmt: skip
    return (lo, hi)


def as_levels(value) -> int | None:
    """The `n_temperature_levels` field's converter: `None`, or a whole number ≥ 1 (a JSON
    number loads as one). **Raises:** `ValueError` for anything else (text, 2.5, True, 0)."""
    if value is None:
        return None
    whole = isinstance(value, int | np.integer | float | np.floating) and not isinstance(
        value, bool | np.bool_
    )
    if not (whole and float(value).is_integer() and value >= 1):
        raise ValueError(f"n_temperature_levels must be a whole number ≥ 1 or None; got {value!r}")
    return int(value)


def domain_of(temperature_c) -> dict:
    """The domain fields a `fit` stores: `temperature_range` (min, max of `temperature_c`
    [°C]) and `n_temperature_levels` (`temperature_levels`' count)."""
    temp = np.asarray(temperature_c, dtype=float)
    return {
        "temperature_range": (float(np.min(temp)), float(np.max(temp))),
        "n_temperature_levels": int(temperature_levels(temp).size),
    }


class NoCompensation(AbstractCompensator):
    """The raw gyro: D = 0, SF = 1 (only the nominal angular gain)."""

    k_e: float = setting_field("NoCompensation", "k_e", K_E_NOMINAL)

    def __check_init__(self):
        check_k_e(self.k_e)

    @property
    def name(self) -> str:
        """Short label used in tables."""
        return "raw"

    def fit(self, data, *, key=None, raw=None) -> NoCompensation:
        """Nothing to fit: returns `self` (the common interface's arguments are not used;
        `raw` is checked as every compensator's)."""
        check_raw("NoCompensation.fit", data, raw)
        return self

    def drift(self, theta, temperature_c):
        return jnp.zeros_like(theta)

    def scale_factor(self, theta, temperature_c):
        return jnp.ones_like(theta)


@program
def _pointwise(comp, which, theta, temperature_c):
    """`comp.<which>` [rad/s or dimensionless] at each θ [rad] and T [°C]."""
    return jax.vmap(getattr(comp, which))(theta, temperature_c)


def as_windows(
    data, k_e: float, window_s: float | None = WINDOW_S, ramp_window_s: float | None = None
) -> RateWindows:
    """Accept bench data (reduced with `window_s`, `ramp_window_s`) or already reduced
    windows (checked for the same k_e)."""
    if isinstance(data, RateWindows):
        if data.k_e != k_e:
            raise ValueError(f"windows were reduced with k_e = {data.k_e}, compensator has {k_e}")
        return data
    if isinstance(data, MeasuredData):
        return reduce(data, k_e, window_s=window_s, ramp_window_s=ramp_window_s)
    raise TypeError(f"expected MeasuredData or RateWindows; got {type(data).__name__}")


def split_targets(windows: RateWindows):
    """Static and moving windows; a clear error when either kind is missing."""
    static = windows.select(windows.static)
    moving = windows.select(~windows.static)
    if len(static) == 0:
        raise ValueError(
            "calibration data have no static runs (table_rate_dps = 0 throughout a run): "
            "the drift cannot be fitted"
        )
    if len(moving) == 0:
        raise ValueError(
            "calibration data have no rotation runs (non-zero table_rate_dps): the scale "
            "factor cannot be fitted; add rotation runs (e.g. calibration.rotation_plan)"
        )
    return static, moving


LEVEL_TOLERANCE_C = 0.5
"""Window temperatures closer than this are one temperature when a fit counts the distinct
temperatures its laws in T need [°C]: a bench holds a level to a few tenths of a degree, and
levels that close tell a law in T nothing."""


def temperature_levels(temperature_c) -> np.ndarray:
    """The distinct temperatures among windows' temperatures [°C], sorted: the values grouped
    within `LEVEL_TOLERANCE_C` ([`group_temperatures`][hrgjax.units.group_temperatures]),
    one number (the group's median) per group."""
    labels = group_temperatures(np.asarray(temperature_c, dtype=float), LEVEL_TOLERANCE_C)
    return np.unique(labels[np.isfinite(labels)])


def require_temperatures(
    temperature_c, needed: int, what: str, remedy: str, where: str = "the calibration data"
) -> None:
    """Refuse data whose windows hold fewer than `needed` distinct temperatures
    (`temperature_levels`): "<what> needs at least <needed> distinct temperatures in
    <where>; got N (…)", then `remedy`."""
    levels = temperature_levels(temperature_c)
    if levels.size < needed:
        shown = ", ".join(f"{t:+.1f}" for t in levels)
        raise ValueError(
            f"{what} needs at least {needed} distinct temperatures in {where}; got "
            f"{levels.size} ({shown} °C; levels within {LEVEL_TOLERANCE_C:g} °C count once)"
            f"{remedy}"
        )


def fit_windows(data, k_e: float, window_s: float | None, ramp_window_s: float | None = None):
    """`split_targets(as_windows(…))`: the static and moving windows a `fit` works on."""
    return split_targets(as_windows(data, k_e, window_s, ramp_window_s))
