r"""`FourierCompensator`: the seed's base algorithm and its temperature-polynomial variant.

$$D(\theta, T) = \sum_{k=0}^{K}\tau^k\Big[c_{k0} + \sum_{n=1}^{N} c_{k,2n-1}\cos 2n\theta
+ c_{k,2n}\sin 2n\theta\Big],\qquad \tau = (T - T_{\rm ref})/50\,°C,$$

and SF(θ, T) in the same basis. Electrical θ: the harmonics 2nθ have period 180°/n. The seed's
base algorithm is K = 0 fitted only on the points at the fit temperature (+20 °C); the
variant with `temperature_degree=K ≥ 1` fits all temperatures by weighted linear least
squares.

A window's rate is the average of the rate over the arc the wave turns in it, weighted as
its least-squares slope weighs it, so the fit compares it with each harmonic's value at the
window's mean angle times that harmonic's gain G_{2n} over the window
(`hrgjax.calibration._window_arc`: 0.998 for 2θ on a 3-s window at 5 °/s, 0.805 at 50 °/s;
1 on static windows, which the drift barely turns). Read as point values, the 2θ scale-factor
ripple came out 0.97 of the truth at 20 °/s, 0.80 at 50 °/s, 0.38 at 100 °/s; now 1.0000,
1.0000 and 0.99997 (closed-form session, 0/20/40 °C, 3-s windows at 10 Hz; what is left is
second order in the ripple: 11 ppm RMS of the scale factor at 50 °/s, 79 at 100 °/s). A
harmonic whose RMS gain over the rotation windows is under `GAIN_FLOOR` is refused: the
windows average it out (the 4θ one of 3-s windows near 77 °/s).
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_finite_host
from .._compiled import device
from .._x64 import require_x64
from ..data import MeasuredData
from ..units import DEG, T_REF_C
from ._compensator import (
    FROM_FIELD,
    LEVEL_TOLERANCE_C,
    AbstractCompensator,
    FromField,
    as_levels,
    as_range,
    check_number,
    check_whole,
    domain_of,
    fit_windows,
    require_temperatures,
    setting,
    setting_field,
    temperature_levels,
)
from ._raw import check_raw
from ._window_arc import harmonic_gains, turning_rate, window_sampling
from .reduce import K_E_NOMINAL, WINDOW_S, RateWindows, check_k_e, check_window

T_SCALE = 50.0
"""Temperature scale of the polynomial basis [°C]."""


GAIN_FLOOR = 0.05
"""Smallest RMS gain (`hrgjax.calibration._window_arc.harmonic_gain`) over the rotation
windows of a harmonic the fit accepts: below it the windows average the harmonic out and
its fitted coefficient would carry their noise (and any second-order error) times ≥ 20."""


def _angle_basis(theta, harmonics: int, xp=jnp, gains=None):
    """Columns 1, cos 2θ, sin 2θ, …, sin 2Nθ; `gains` (…, N): each harmonic's window gain
    (the window's rate of it over its value at θ), None for point values."""
    cols = [xp.ones_like(theta)]
    for n in range(1, harmonics + 1):
        g = 1.0 if gains is None else gains[..., n - 1]
        cols += [g * xp.cos(2 * n * theta), g * xp.sin(2 * n * theta)]
    return xp.stack(cols, axis=-1)


def _temperature_basis(temperature_c, degree: int, t_ref: float, xp=jnp):
    x = (temperature_c - t_ref) / T_SCALE
    return xp.stack([x**k for k in range(degree + 1)], axis=-1)


_WHO = "FourierCompensator"


class FourierCompensator(AbstractCompensator):
    """Fourier series in wave angle, optionally polynomial in temperature.

    **Arguments:**

    - `harmonics`: N, number of 2nθ harmonics (2: terms in 2θ and 4θ).
    - `temperature_degree`: K; `None` is the seed's base algorithm (no temperature
      dependence, fitted at `fit_temperature_c` only).
    - `fit_temperature_c`, `tolerance_c`: for the base algorithm, the points used are those
      within `tolerance_c` of `fit_temperature_c` [°C].
    - `k_e`: nominal angular gain.
    - `drift_coef`, `sf_coef`: fitted coefficients, shape (K+1, 2N+1) (drift in rad/s);
      `None` before `fit`.
    - `window_s`: rotation-run window [s] of the reduction when `fit` is given
      `MeasuredData` (windows given to `fit` are used as they are).
    - `temperature_range` ((T_min, T_max) [°C]) and `n_temperature_levels`: the fitted
      windows' temperature span and level count, set by `fit` (`None`: unknown).
      [`correct`][hrgjax.calibration.AbstractCompensator.correct] applies it beyond the
      range too (beyond its levels T² was 2–6× its in-range error, 4–160× below raw) and
      counts those samples; `extrapolate=False` passes them through.

    **Raises:** `ValueError`, one line naming the field, when built with `harmonics` not a
    whole number ≥ 1, `temperature_degree` neither `None` nor a whole number ≥ 0,
    `fit_temperature_c` not finite, `tolerance_c` not finite and ≥ 0, `window_s` neither
    `None` nor finite and > 0, or `k_e` outside (0, 1].
    """

    harmonics: int = setting_field(_WHO, "harmonics", 2)
    temperature_degree: int | None = setting_field(_WHO, "temperature_degree", None)
    fit_temperature_c: float = setting_field(_WHO, "fit_temperature_c", T_REF_C)
    tolerance_c: float = setting_field(_WHO, "tolerance_c", 1.0)
    k_e: float = setting_field(_WHO, "k_e", K_E_NOMINAL)
    drift_coef: jax.Array | None = None
    sf_coef: jax.Array | None = None
    window_s: float | None = setting_field(_WHO, "window_s", WINDOW_S)
    temperature_range: tuple[float, float] | None = eqx.field(
        static=True, default=None, converter=as_range
    )
    n_temperature_levels: int | None = eqx.field(static=True, default=None, converter=as_levels)
    TRAINING_FIELDS = ("tolerance_c", "window_s")

    def __check_init__(self):
        check_k_e(self.k_e)
        who = "FourierCompensator"
        check_whole(who, "harmonics", self.harmonics, 1, " (number of 2nθ harmonics)")
        if self.temperature_degree is not None:
            check_whole(who, "temperature_degree", self.temperature_degree, 0,
                        " or None (the seed's base algorithm)")  # fmt: skip
        check_number(who, "fit_temperature_c", self.fit_temperature_c, " [°C]")
        check_number(who, "tolerance_c", self.tolerance_c, " [°C]", minimum=0.0)
        check_window(who, self.window_s)
        want = (self._degree + 1, 2 * self.harmonics + 1)
        for name in ("drift_coef", "sf_coef"):
            coef = getattr(self, name)
            if coef is None:
                continue
            if tuple(np.shape(coef)) != want:
                raise ValueError(f"{who}: {name} must have shape (temperature_degree + 1, "
                                 f"2·harmonics + 1) = {want}, or be None; got shape "
                                 f"{tuple(np.shape(coef))}")  # fmt: skip
            check_finite_host(f"{who}: {name}", coef)

    @property
    def extrapolates(self) -> bool:
        """`True`: a polynomial of low degree in T (or, the seed's base algorithm, none)
        continues beyond its levels with a bounded error — fitted on 0/20/40 °C, T² left
        2–6× its in-range error at −40 … +60 °C, 4–160× below the raw gyro's
        (docs/calibration.md); samples beyond are counted, `extrapolate=False` passes them
        through."""
        return True

    @property
    def _degree(self) -> int:
        return 0 if self.temperature_degree is None else self.temperature_degree

    @property
    def name(self) -> str:
        """Short label used in tables."""
        if self.temperature_degree is None:
            return f"Fourier @{self.fit_temperature_c:+.0f}°C"
        return f"Fourier+T^{self.temperature_degree}"

    def _basis(self, theta, temperature_c, xp=jnp, gains=None):
        a = _angle_basis(theta, self.harmonics, xp, gains)
        t = _temperature_basis(temperature_c, self._degree, self.fit_temperature_c, xp)
        return (t[..., :, None] * a[..., None, :]).reshape(*a.shape[:-1], -1)

    def _require_fitted(self, coef):
        if coef is None:
            raise ValueError("this FourierCompensator is not fitted; use comp = comp.fit(data)")

    def drift(self, theta, temperature_c):
        self._require_fitted(self.drift_coef)
        return self._basis(theta, temperature_c) @ self.drift_coef.ravel()

    def scale_factor(self, theta, temperature_c):
        self._require_fitted(self.sf_coef)
        return self._basis(theta, temperature_c) @ self.sf_coef.ravel()

    def fit(
        self,
        data,
        window_s: float | None | FromField = FROM_FIELD,
        *,
        key: jax.Array | None = None,
        raw: MeasuredData | None = None,
    ) -> FourierCompensator:
        """Fit drift on static windows, then SF on rotation windows with that drift removed
        ([`AbstractCompensator.fit`][hrgjax.calibration.AbstractCompensator.fit]).

        **Arguments:**

        - `data`: [`hrgjax.MeasuredData`][] or reduced
          [`RateWindows`][hrgjax.calibration.RateWindows].
        - `key`, `raw`: the common interface's; not used (the fit is linear least squares
          on the reduced windows), `raw` checked as every compensator's.
        - `window_s`: *deprecated*, give `FourierCompensator(window_s=…)`: the rotation-run
          window for the reduction [s] (default: the `window_s` field).

        **Returns:** a new fitted `FourierCompensator`.

        **Raises:** `ValueError` without static or rotation runs, with no points near the fit
        temperature (base algorithm), with fewer distinct temperatures (levels within 0.5 °C
        counted once) among the static or the rotation runs than the temperature polynomial
        has coefficients (`temperature_degree` + 1), with fewer points than coefficients, or
        with windows whose wave angles or temperature levels do not determine the
        coefficients (`CONDITION_LIMIT`; the message says which, and what to add).
        """
        require_x64("FourierCompensator.fit")
        check_raw("FourierCompensator.fit", data, raw)
        window_s = setting(self, "window_s", window_s)
        static, moving = fit_windows(data, self.k_e, window_s)
        if self.temperature_degree is None:
            static = _near(static, self.fit_temperature_c, self.tolerance_c, "static")
            moving = _near(moving, self.fit_temperature_c, self.tolerance_c, "rotation")
        else:
            for kind, w in (("static", static), ("rotation", moving)):
                _require_degree(self.temperature_degree, w.temperature_c, kind)
        domain = domain_of(np.concatenate([static.temperature_c, moving.temperature_c]))
        # each window's rate: the law averaged over the arc it turns (module docstring)
        g_s, g_m = (harmonic_gains(w, self.harmonics) for w in (static, moving))
        _require_gains(g_m, moving)
        th_s = static.wave_angle_deg * DEG
        drift = (static.rate_dps - static.table_rate_dps) * DEG
        d_coef = _lstsq(self._basis(th_s, static.temperature_c, np, g_s), drift,
                        "drift (static runs)", static, self)  # fmt: skip
        th_m = moving.wave_angle_deg * DEG
        basis_m = self._basis(th_m, moving.temperature_c, np, g_m)
        sf = (moving.rate_dps * DEG - basis_m @ d_coef) / (moving.table_rate_dps * DEG)
        s_coef = _lstsq(basis_m, sf, "scale factor (rotation runs)", moving, self)
        shape = (self._degree + 1, -1)
        fitted = eqx.tree_at(
            lambda c: (c.drift_coef, c.sf_coef),
            self,
            (device(d_coef.reshape(shape)), device(s_coef.reshape(shape))),
            is_leaf=lambda x: x is None,
        )
        return dataclasses.replace(fitted, **domain)


def _require_gains(gains, moving: RateWindows) -> None:
    """Refuse harmonics the rotation windows average out (`GAIN_FLOOR`), naming the arc the
    wave turns in a window and what to change."""
    rms = np.sqrt(np.mean(gains**2, axis=0))
    if np.all(rms >= GAIN_FLOOR):
        return
    n = int(np.argmax(rms < GAIN_FLOOR)) + 1
    count, dt = window_sampling(moving)
    arc = np.median(turning_rate(moving) * dt * count) / DEG
    raise ValueError(
        f"scale factor (rotation runs): the windows average the {2 * n}θ harmonic out (RMS "
        f"gain {rms[n - 1]:.3f} < GAIN_FLOOR {GAIN_FLOOR:g}: the wave turns ≈ {arc:.0f}° "
        f"electrical in a window at {np.median(np.abs(moving.table_rate_dps)):.3g} °/s); "
        "shorten the windows (FourierCompensator(window_s=…), CLI --window) or lower harmonics "
        "(CLI --harmonics)"
    )


def _require_degree(degree: int, temperature_c, kind: str) -> None:
    """Refuse a temperature polynomial of `degree` that the `kind` windows' temperatures do
    not determine: degree K needs K + 1 distinct temperatures (fewer leave the least squares
    rank-deficient: a minimum-norm fit, flat or wild between and beyond them)."""
    require_temperatures(
        temperature_c,
        degree + 1,
        f"temperature_degree {degree}",
        "; lower temperature_degree (CLI --temperature-degree) or add runs at other temperatures",
        where=f"the calibration data's {kind} runs",
    )


def _near(w: RateWindows, temperature_c: float, tol: float, kind: str) -> RateWindows:
    mask = np.abs(w.temperature_c - temperature_c) <= tol
    if not np.any(mask):
        raise ValueError(
            f"no {kind} calibration points within {tol} °C of the fit temperature "
            f"{temperature_c} °C (have {np.unique(np.round(w.temperature_c, 2))} °C)"
        )
    return w.select(mask)


CONDITION_LIMIT = 1e6
"""Largest condition number of the least squares' basis (columns scaled to unit length) a
Fourier fit accepts: beyond it the windows do not determine the coefficients (two distinct
wave angles for five coefficients put the drift at 10⁹ °/h; four temperature levels 0.6 °C
apart do not determine a cubic in T), and the fit says what to add instead of answering."""


def _condition(basis) -> float:
    """Condition number of `basis` with its columns scaled to unit length (inf if singular)."""
    scaled = basis / np.maximum(np.linalg.norm(basis, axis=0), 1e-300)
    sv = np.linalg.svd(scaled, compute_uv=False)
    return float(sv[0] / sv[-1]) if sv[-1] > 0 else np.inf


def _lstsq(basis, y, what: str, w: RateWindows | None = None, comp=None):
    """Ordinary least squares: the batch-means errors of single windows are too noisy to
    weight by, and windows of one kind have equal length. Refuses a basis the windows `w`
    do not determine (`CONDITION_LIMIT`), naming the cause (`_cause`)."""
    if basis.shape[0] < basis.shape[1]:
        raise ValueError(
            f"{what}: {basis.shape[0]} calibration points for {basis.shape[1]} coefficients; "
            "add points or lower harmonics / temperature_degree"
        )
    if not _condition(basis) < CONDITION_LIMIT and w is not None and comp is not None:
        raise ValueError(f"{what}: {_cause(w, comp, basis.shape[1])}")
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    return coef


def _cause(w: RateWindows, comp: FourierCompensator, n_coef: int) -> str:
    """Why the windows `w` do not determine `comp`'s `n_coef` coefficients: the temperature
    polynomial's basis alone over the windows' temperatures, or the Fourier basis alone over
    their wave angles, ill-conditioned (condition number above √`CONDITION_LIMIT`: the
    product basis's is about the product of the two), and the wave angles at each
    temperature level; the angles are named when the temperatures are not to blame."""
    limit = np.sqrt(CONDITION_LIMIT)
    temp_basis = _temperature_basis(w.temperature_c, comp._degree, comp.fit_temperature_c, np)
    temp_bad = comp._degree > 0 and not _condition(temp_basis) < limit
    angle_basis = _angle_basis(w.wave_angle_deg * DEG, comp.harmonics, np)
    short = any(n < 2 * comp.harmonics + 1 for n, _ in _angles_per_level(w))
    angle_bad = short or not _condition(angle_basis) < limit or not temp_bad
    causes = [_temperature_summary(w, comp._degree)] * temp_bad
    causes += [_angle_summary(w, comp.harmonics)] * angle_bad
    which = " and ".join(["temperatures"] * temp_bad + ["wave angles"] * angle_bad)
    return f"the windows' {which} do not determine the {n_coef} coefficients; " + "; ".join(causes)


def _temperature_summary(w: RateWindows, degree: int) -> str:
    """'4 temperature levels (+59.0, …, +60.8 °C) span 1.8 °C: temperature_degree=3 …'."""
    levels = temperature_levels(w.temperature_c)
    shown = ", ".join(f"{t:+.1f}" for t in levels[:8]) + (", …" if levels.size > 8 else "")
    return (
        f"{levels.size} temperature levels ({shown} °C; levels within {LEVEL_TOLERANCE_C:g} °C "
        f"count once) span {np.ptp(levels):.1f} °C, too close together for a polynomial of "
        f"temperature_degree={degree} in (T − T_ref)/{T_SCALE:g} °C — add runs at temperatures "
        "further apart or lower temperature_degree (CLI --temperature-degree)"
    )


def _angles_per_level(w: RateWindows) -> list[tuple[int, np.ndarray]]:
    """(count, distinct folded wave angles [°]) at each temperature level; angles within ≈ 1°
    count once."""
    out = []
    for level in temperature_levels(w.temperature_c):
        near = np.abs(w.temperature_c - level) <= LEVEL_TOLERANCE_C
        folded = (w.wave_angle_deg[near] + 90.0) % 180.0 - 90.0
        distinct = np.unique(np.round(folded)) + 0.0  # no −0
        out.append((distinct.size, distinct))
    return out


def _angle_summary(w: RateWindows, harmonics: int) -> str:
    """'at +20 °C 2 distinct wave angles (0, 45° electrical, mod 180°); …: harmonics=N needs
    ≥ 2N + 1 at each temperature — add runs at other wave angles or lower harmonics'."""
    parts = []
    levels = temperature_levels(w.temperature_c)
    for level, (count, distinct) in zip(levels, _angles_per_level(w), strict=True):
        shown = ", ".join(f"{a:g}" for a in distinct[:8]) + (", …" if distinct.size > 8 else "")
        parts.append(f"at {level:+.1f} °C {count} distinct wave angles ({shown}°)")
    return (
        "; ".join(parts) + f" (electrical, mod 180°): harmonics={harmonics} needs ≥ "
        f"{2 * harmonics + 1} distinct wave angles at each temperature — add runs at other wave "
        "angles or lower harmonics (CLI --harmonics)"
    )
