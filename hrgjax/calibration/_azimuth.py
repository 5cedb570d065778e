r"""The static residual against the table's azimuth: a rate that turns with the table.

A gyro whose sensitive axis is tilted by δ from the table's axis sees the horizontal Earth
rate $\Omega\cos\varphi\,\sin\delta$ ($\varphi$ the latitude) along it, turning with the
table: at rest a bias $\Omega\cos\varphi\,\sin\delta\cos(a - a_0)$ that depends on the
table azimuth $a$ the run stands at (0.186 °/h at 1° and 45° N), in a rotation a ripple once
per turn. A drift sensitive to a lateral specific force on a tilted table turns the same way.
Static runs at one azimuth fold it into the bias; static runs at several azimuths show it,
but only against the azimuth: by temperature or wave angle it reads as scatter, or as a
wave-angle pattern where the azimuths and the wave angles go together.

[`table_azimuth_fit`][hrgjax.calibration.table_azimuth_fit] fits the static runs' residual
rates $r_i$ [°/h] (`drift_error_dph` of
[`corrected_run_errors`][hrgjax.calibration.corrected_run_errors]) at their start azimuths
$a_i$ (`table_angle0_deg`: the table angle column at the run's start, as the bench reports it)
by weighted least squares,

$$r_i = m + c\cos a_i + s\sin a_i + e_i, \qquad w_i = T_i,$$

the duration weighting of the session's offset ([`session_offset`][hrgjax.calibration.session_offset]:
white rate noise, a run's variance $\sigma^2/T_i$), with $\sigma^2$ from the runs' own
scatter, $\hat\sigma^2 = \sum_i T_i \hat e_i^2/(n - 3)$, and the covariance
$\hat\sigma^2 (X^\top W X)^{-1}$ (what `scipy.optimize.curve_fit` gives with
`sigma = 1/√T`, `absolute_sigma=False`; the test checks it). The amplitude
$A = \sqrt{c^2 + s^2}$ and the azimuth $a_0 = \operatorname{atan2}(s, c)$ of the largest
residual carry first-order σ; whether $(c, s)$ differ from 0 is the F test with 2 and $n - 3$
degrees of freedom, $p = (1 + 2F/\nu)^{-\nu/2}$ with $F = \beta^\top C^{-1}\beta / 2$. The
scatter holds what the compensation leaves at each temperature and wave angle, so σ errs
large where that dominates. A fitted compensator may already have absorbed part of the term
where the calibration's static runs stood at several azimuths too (1° of tilt at 45° N: the
static runs' cos coefficient 0.15 °/h of the 0.186 °/h injected).

**Spread.** With $z_i = (\cos a_i, \sin a_i)$ and $\bar z$ their $T$-weighted mean, the
spread $\lambda$ is the smallest eigenvalue of the weighted covariance
$\sum_i T_i (z_i - \bar z)(z_i - \bar z)^\top / \sum_i T_i$: the fit's covariance of
$(c, s)$ is $\hat\sigma^2 / \sum_i T_i$ times its inverse, and a residual pattern that is not
an azimuth term, of weighted RMS $U$ (a temperature curvature the compensation left, say),
enters $(c, s)$ by up to $U/\sqrt{\lambda}$. Runs spread evenly round the turn (0/120/240°,
0/90/180/270°) give $\lambda = 0.5$ (the audit plan's 18 runs at 90°·(run mod 4): 0.494);
three equal groups at 0/90/180°: 0.22; at 0/45/90°: 0.019; at 0/30/60°: 0.004; runs
parked at one azimuth whose logged angle creeps or scatters by tenths of a degree: ~1e-9,
where the fit read 1153 °/h, "resolved", off a temperature curvature the calibration had
not seen (≤ 0.18 °/h).
`table_azimuth_fit` refuses (None) below `AZIMUTH_MIN_SPREAD` = 0.05: the weakest
direction's σ at most √10 ≈ 3.2 times a balanced design's with the same runs, a foreign
pattern's leak into $A$ at most 4.5 times its RMS (√2 ≈ 1.4 balanced); for three equal
groups that is an arc of 116° or more.

**Bias.** $A$ is biased up where it is not resolved: $E[\hat A^2] = A^2 + \sigma_c^2 +
\sigma_s^2$, so with no azimuth term at all (Rayleigh) $\hat A$ averages
$\sigma\sqrt{\pi/2} \approx 1.25\,\sigma$ ($c$ and $s$ of one σ; about 1.32 times the
printed σ, estimated on 15 degrees of freedom), and about $1.55\,A$ at $A = \sigma$. Read
$A$ and $a_0$ only where the F test resolves them: the text prints the azimuth only then.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._checks import check_number
from ._grouping import nearest_multiples

AZIMUTH_BIN_DEG = 5.0
"""Width of the table-azimuth groups [°]: a run's start table angle rounded to the nearest
multiple and folded to [0°, 360°) (5°, as the wave angles: a table parked "at 0°" whose
logged angle scatters or creeps by tenths of a degree is one azimuth, not 359/0/1°)."""

AZIMUTH_MIN_SPREAD = 0.05
"""Smallest spread λ of the start azimuths (the smallest eigenvalue of the duration-weighted
covariance of (cos a, sin a); 0.5 spread evenly round the turn) that
[`table_azimuth_fit`][hrgjax.calibration.table_azimuth_fit] fits on: below it c and s are an
extrapolation over a narrow arc (the module docstring)."""


def azimuth_groups(table_angle_deg, width: float = AZIMUTH_BIN_DEG) -> np.ndarray:
    """Table angles [°] binned to multiples of `width` and folded to [0°, 360°)."""
    return nearest_multiples(np.asarray(table_angle_deg, dtype=float) % 360.0, width) % 360.0 + 0.0


def static_azimuths(errors: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The static runs with a finite residual, start azimuth and duration: (`table_angle0_deg`
    [°], `drift_error_dph` [°/h], `duration_s` [s])."""
    az, r, w = (np.asarray(errors[k], float) for k in ("table_angle0_deg", "drift_error_dph",
                                                       "duration_s"))  # fmt: skip
    keep = np.asarray(errors["static"], bool) & np.isfinite(az) & np.isfinite(r) & np.isfinite(w)
    return az[keep], r[keep], w[keep]


def azimuth_spread(table_angle_deg, weights) -> float:
    """Spread λ of azimuths [°] under `weights` (durations [s]): the smallest eigenvalue of
    the weighted covariance of (cos a, sin a) [dimensionless; 0.5 spread evenly round the
    turn, 0 at one azimuth; NaN with no weight]."""
    a = np.deg2rad(np.asarray(table_angle_deg, float))
    w = np.asarray(weights, float)
    if not a.size or not np.sum(w) > 0.0:
        return math.nan
    z = np.stack([np.cos(a), np.sin(a)], axis=1)
    zc = z - (w @ z) / np.sum(w)
    return max(float(np.linalg.eigvalsh((w[:, None] * zc).T @ zc / np.sum(w))[0]), 0.0)


@dataclasses.dataclass(frozen=True)
class AzimuthFit:
    """The static residual's once-per-turn dependence on the table azimuth
    ([`table_azimuth_fit`][hrgjax.calibration.table_azimuth_fit]; the definitions are in
    docs/calibration.md): $r = m + c\\cos a + s\\sin a = m + A\\cos(a - a_0)$ [°/h].

    - `mean_dph`, `cos_dph`, `sin_dph` [°/h]: $m$, $c$, $s$; `sigma_mean_dph`,
      `sigma_cos_dph`, `sigma_sin_dph` their σ [°/h] and `cov_cos_sin` the covariance of
      $c$ and $s$ [(°/h)²], from the runs' scatter (NaN with 3 runs: no scatter left).
    - `amplitude_dph` $A$ and `sigma_amplitude_dph` [°/h]; `azimuth_deg` $a_0$, where the
      residual is largest, and `sigma_azimuth_deg` [°] (first order).
    - `p_value`: the F test that $c = s = 0$ (NaN with 3 runs); `n_runs`, `n_azimuths`
      (distinct start azimuths, `AZIMUTH_BIN_DEG` groups); `dof` = n − 3; `spread`: λ of
      the start azimuths (≥ `AZIMUTH_MIN_SPREAD`; 0.5 spread evenly round the turn).

    $A$ is biased up where not resolved (≈ 1.25 σ on noise alone: the module docstring);
    `str()` names $a_0$ only where the F test resolves the term.
    """

    mean_dph: float
    cos_dph: float
    sin_dph: float
    sigma_mean_dph: float
    sigma_cos_dph: float
    sigma_sin_dph: float
    cov_cos_sin: float
    amplitude_dph: float
    sigma_amplitude_dph: float
    azimuth_deg: float
    sigma_azimuth_deg: float
    p_value: float
    n_runs: int
    n_azimuths: int
    dof: int
    spread: float

    def resolved(self, level: float = 0.95) -> bool:
        """Whether $(c, s)$ differ from 0 at `level` (the F test; False with σ unknown)."""
        return bool(self.p_value < 1.0 - level)

    def __str__(self) -> str:
        head = (f"c = {self.cos_dph:+.4f} ± {self.sigma_cos_dph:.4f}, s = {self.sin_dph:+.4f} ± "
                f"{self.sigma_sin_dph:.4f} °/h; amplitude {self.amplitude_dph:.4f} ± "
                f"{self.sigma_amplitude_dph:.4f} °/h")  # fmt: skip
        if self.resolved():  # rounded, then folded: 359.7° reads 0°
            where = (f"largest at azimuth {round(self.azimuth_deg) % 360:.0f}° ± "
                     f"{self.sigma_azimuth_deg:.0f}°")  # fmt: skip
        else:  # a null fit's a_0 is noise, and A is biased up (≈ 1.25 σ on noise alone)
            where = "azimuth undetermined"
        runs = f"{self.n_runs} runs at {self.n_azimuths} azimuths"
        if not math.isfinite(self.p_value):
            return f"{head}, {where} (σ unknown: {runs} for 3 terms)"
        verdict = "resolved" if self.resolved() else "not resolved"
        return f"{head}, {where}; {verdict} at 95 % (p = {self.p_value:.2g}; {runs})"

    def to_json(self) -> dict:
        """The fit as JSON-ready data (NaN as None), with `"unit": "°/h"`."""
        out = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = v if isinstance(v, int) else (float(v) if math.isfinite(v) else None)
        return out | {"unit": "°/h"}


def table_azimuth_fit(
    errors: dict, width: float = AZIMUTH_BIN_DEG, min_spread: float = AZIMUTH_MIN_SPREAD
) -> AzimuthFit | None:
    r"""Fit the static runs' residual rates $r_i$ [°/h] on 1, cos and sin of their start table
    azimuths $a_i$: weighted least squares $r_i = m + c\cos a_i + s\sin a_i$ with weights
    $T_i$ (the runs' durations, as the session's offset weighs them), σ from the runs' own
    scatter, $\hat\sigma^2 = \sum_i T_i \hat e_i^2/(n - 3)$, covariance
    $\hat\sigma^2 (X^\top W X)^{-1}$; $A = \sqrt{c^2 + s^2}$ and $a_0 = \operatorname{atan2}(s, c)$
    with first-order σ; $p$ the F(2, n − 3) test of $c = s = 0$. A gyro axis tilted δ from the
    table's gives $c, s$ of size $\Omega\cos\varphi\sin\delta$ (the horizontal Earth rate).

    **Arguments:** `errors`: per-run errors as
    [`corrected_run_errors`][hrgjax.calibration.corrected_run_errors] returns them (`static`,
    `drift_error_dph` [°/h], `duration_s` [s], `table_angle0_deg` [°]; runs with a non-finite
    one are left out); `width`: the azimuth groups' width [°] that counts distinct azimuths;
    `min_spread`: the smallest spread λ of the azimuths fitted on (the smallest eigenvalue of
    the duration-weighted covariance of (cos a, sin a), dimensionless: 0.5 spread evenly round
    the turn; the module docstring for the default 0.05).

    **Returns:** an [`AzimuthFit`][hrgjax.calibration.AzimuthFit], or None where c and s are
    not both determined: the static runs stand at fewer than 3 distinct azimuths, or on too
    narrow an arc (spread below `min_spread`: a logged angle creeping or scattering by
    tenths of a degree about one parking azimuth gives ~1e-9).

    **Raises:** `ValueError` when `errors` has no `table_angle0_deg`, `width` is not a finite
    number > 0 or `min_spread` not a finite number ≥ 0.
    """
    check_number("table_azimuth_fit: width", width, "°")
    check_number("table_azimuth_fit: min_spread", min_spread)
    if not (math.isfinite(width) and width > 0):
        raise ValueError(f"table_azimuth_fit: width must be a finite number > 0 [°]; got {width!r}")
    if not (math.isfinite(min_spread) and min_spread >= 0):
        raise ValueError("table_azimuth_fit: min_spread must be a finite number >= 0 (0 fits any "
                         f"layout of 3 azimuths); got {min_spread!r}")  # fmt: skip
    if "table_angle0_deg" not in errors:
        raise ValueError("errors have no table_angle0_deg; compute them with "
                         "corrected_run_errors (the table angle at each run's start)")  # fmt: skip
    az, r, w = static_azimuths(errors)
    n_az = int(np.unique(azimuth_groups(az, width)).size)
    spread = azimuth_spread(az, w)
    if n_az < 3 or not spread >= min_spread:
        return None
    a = np.deg2rad(az)
    x = np.stack([np.ones_like(a), np.cos(a), np.sin(a)], axis=1)
    xtwx = x.T @ (w[:, None] * x)
    beta = np.linalg.solve(xtwx, x.T @ (w * r))
    dof = r.size - 3
    s2 = float(np.sum(w * (r - x @ beta) ** 2) / dof) if dof > 0 else math.nan
    cov = s2 * np.linalg.inv(xtwx)
    m, c, s = (float(v) for v in beta)
    amp = math.hypot(c, s)
    cs = cov[1:, 1:]
    if amp > 0.0:
        g_amp = np.array([c, s]) / amp
        g_az = np.array([-s, c]) / amp**2
        sig_amp = math.sqrt(max(float(g_amp @ cs @ g_amp), 0.0)) if dof > 0 else math.nan
        sig_az = math.degrees(math.sqrt(max(float(g_az @ cs @ g_az), 0.0))) if dof > 0 else math.nan
    else:
        sig_amp = sig_az = math.nan
    if dof > 0 and s2 > 0.0:
        f = float(beta[1:] @ np.linalg.solve(cs, beta[1:])) / 2.0
        p = (1.0 + 2.0 * f / dof) ** (-dof / 2.0)  # F(2, ν) survival function, closed form
    else:
        p = math.nan
    sd = np.sqrt(np.diag(cov)) if dof > 0 else np.full(3, math.nan)
    return AzimuthFit(
        mean_dph=m, cos_dph=c, sin_dph=s,
        sigma_mean_dph=float(sd[0]), sigma_cos_dph=float(sd[1]), sigma_sin_dph=float(sd[2]),
        cov_cos_sin=float(cov[1, 2]) if dof > 0 else math.nan,
        amplitude_dph=amp, sigma_amplitude_dph=sig_amp,
        azimuth_deg=math.degrees(math.atan2(s, c)) % 360.0, sigma_azimuth_deg=sig_az,
        p_value=p, n_runs=int(r.size), n_azimuths=n_az, dof=int(dof), spread=spread,
    )  # fmt: skip
