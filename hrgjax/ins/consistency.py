r"""The consistency figures of the loosely-coupled filter ([`hrgjax.ins.ekf`][hrgjax.ins.ekf]):
its true error states against a truth, the errors whitened by the reported covariance, the
NEES and its Monte Carlo band, and the truth-free NIS test. Every name is also importable from
`hrgjax.ins.ekf`, where they lived first."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._checks import whole_number
from .._compiled import fused
from .._linalg import cholesky, whiten
from .constants import WGS84
from .mechanization import navigation_errors, wrap_angle


@fused
def error_states(
    result,
    truth_nav,
    gyro_bias,
    accel_bias,
    earth=WGS84,
    gyro_scale=None,
    accel_scale=None,
    gyro_gm=None,
    accel_gm=None,
):
    """The true error state of `result` (a [`FilterResult`][hrgjax.ins.ekf.FilterResult]) at
    its epochs, in the filter's state order ([`hrgjax.ins.ekf`][hrgjax.ins.ekf]), given the
    true navigation states there and the true sensor errors: `gyro_bias` [rad/s],
    `accel_bias` [m/s²] the total biases ((3,) or (M, 3): all but the white noise, as
    [`ImuModel.apply`][hrgjax.ins.sensors.ImuModel.apply]`(..., return_bias=True)` gives
    them); the scale factors [-] for a filter with scale-factor states; for one with
    Gauss–Markov states (`LooselyCoupled(gauss_markov=True)`) `gyro_gm`, `accel_gm` the
    Gauss–Markov biases at the epochs, and the totals with them (both as
    `ImuModel.apply(..., return_bias="gauss_markov")` gives them): the fixed-bias states'
    truth is then total − Gauss–Markov part (fixed bias, random walk, extra rate error).

    **Raises:** `ValueError` when the filter has Gauss–Markov states and `gyro_gm` or
    `accel_gm` is missing."""
    nav = result.nav
    _, _, att = navigation_errors(nav, truth_nav, earth)
    shape = result.gyro_bias.shape
    bg, ba = jnp.broadcast_to(gyro_bias, shape), jnp.broadcast_to(accel_bias, shape)
    if result.gauss_markov:
        if gyro_gm is None or accel_gm is None:
            raise ValueError(
                "error_states: a filter with Gauss–Markov states needs gyro_gm and accel_gm, "
                "the Gauss–Markov parts of the true biases ((3,) or (M, 3) [rad/s, m/s²]; "
                'ImuModel.apply(..., return_bias="gauss_markov") returns them)'
            )
        gm_g, gm_a = jnp.broadcast_to(gyro_gm, shape), jnp.broadcast_to(accel_gm, shape)
        bg, ba = bg - gm_g, ba - gm_a
    parts = [
        jnp.stack(
            [nav.lat - truth_nav.lat, wrap_angle(nav.lon - truth_nav.lon), nav.h - truth_nav.h], -1
        ),
        nav.v_ned - truth_nav.v_ned,
        att,
        bg - result.gyro_bias,
        ba - result.accel_bias,
    ]
    if result.scale_factors:
        parts += [
            jnp.broadcast_to(gyro_scale, shape) - result.gyro_scale,
            jnp.broadcast_to(accel_scale, shape) - result.accel_scale,
        ]
    if result.gauss_markov:
        parts += [gm_g - result.gyro_gm, gm_a - result.accel_gm]
    return jnp.concatenate(parts, -1)


@fused
def whitened_errors(errors, P):
    """The error states in units of their reported covariance, decorrelated: $L^{-1}e$ per
    epoch (..., M, n), L the Cholesky factor of `P` (..., M, n, n) (symmetric positive
    definite; its lower triangle is read; NaN or inf where it is not positive definite).
    `errors` (..., M, n) are the true error states. The sum of their squares is the
    [`nees`][hrgjax.ins.consistency.nees], and that of the first k the NEES of the first k states
    alone (L's leading block is their covariance's factor): one factorisation for both."""
    n = errors.shape[-1] if errors.ndim else 0
    try:
        if errors.ndim < 1 or P.shape[-2:] != (n, n):
            raise ValueError
        batch = jnp.broadcast_shapes(errors.shape[:-1], P.shape[:-2])
    except ValueError:
        raise ValueError(
            f"errors (..., M, n) and P (..., M, n, n) must match; got errors {errors.shape}, "
            f"P {P.shape}"
        ) from None
    one = lambda p, e: whiten(cholesky(p), e)  # noqa: E731
    p, e = jnp.broadcast_to(P, batch + (n, n)), jnp.broadcast_to(errors, batch + (n,))
    return jnp.vectorize(one, signature="(n,n),(n)->(n)")(p, e)


@fused
def nees(errors, P):
    """Normalised estimation error squared $e^\\top P^{-1}e$ per epoch (..., M), from the
    true error states `errors` (..., M, n) and the reported covariance `P` (..., M, n, n):
    symmetric positive definite (its lower triangle is read, by Cholesky; NaN or inf where it
    is not positive definite).
    For a consistent filter its mean over R Monte Carlo runs lies inside
    [`nees_band`][hrgjax.ins.consistency.nees_band] 95 % of the time."""
    return jnp.sum(whitened_errors(errors, P) ** 2, -1)


def nees_band(n_states: int, n_runs: int, level: float = 0.95):
    """The two-sided `level` interval of the mean NEES over `n_runs` runs of a consistent
    filter with `n_states` states: $\\chi^2_{Rn}$ quantiles divided by R (Bar-Shalom
    §5.4).

    **Raises:** `ValueError` naming the argument unless `n_states`, `n_runs` are whole
    numbers >= 1 and 0 < `level` < 1."""
    for name, x in (("n_states", n_states), ("n_runs", n_runs)):
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
            raise ValueError(f"nees_band: {name} must be a whole number >= 1; got {x!r}")
    if isinstance(level, bool) or not isinstance(level, (int, float, np.number)):
        raise TypeError(f"nees_band: level must be a number in (0, 1); got {level!r}")
    if not 0.0 < level < 1.0:
        raise ValueError(
            f"nees_band: level must be a probability in (0, 1), e.g. 0.95; got {level}"
        )
    from ..allan.uncertainty import chi2_ppf

    a = 0.5 * (1.0 - level)
    dof = n_states * n_runs
    return chi2_ppf(a, dof) / n_runs, chi2_ppf(1.0 - a, dof) / n_runs


_DOES_NOT_FIT = (
    "the filter's model does not fit the data: its σ are not to be trusted (a better IMU grade "
    "than the sensor, or a P0 that does not bound the initial error)"
)
_TOO_LOW = (
    "the filter's model does not fit the data: its σ are not to be trusted (larger than the "
    "errors: an IMU model or GNSS σ worse than the real ones, or a Gauss–Markov bias "
    "instability with τ of a few fix intervals or less in a filter without "
    "Gauss–Markov states: it folds it into a random walk of density 2σ²/τ and is "
    "conservative, the more so the shorter τ; LooselyCoupled(gauss_markov=True) models it "
    "— docs/navigation.md)"
)


def nis_check(nis, innovation_dim: int, level=0.99, early: int = 5, tolerance=0.03) -> dict:
    """The truth-free consistency test of a filter's innovations, on the host: `nis` (..., M)
    (NaN where no fix; leading axes are runs, pooled) of `innovation_dim` components per fix.

    For a consistent filter the N valid fixes' NIS are independent $\\chi^2_d$, so their mean
    lies inside $[\\chi^2_{dN}(\\alpha/2), \\chi^2_{dN}(1-\\alpha/2)]/N$ (`band`, two-sided
    at `level`) but with probability 1 − `level`; the mean NIS of the first `early` valid
    fixes of each run (k in all) lies below $\\chi^2_{dk}(0.999)/k$ (`early_bound`) but with
    probability 0.001. A better IMU grade than the sensor's shows in the whole-run mean, a P0
    that does not bound the initial error mostly in the early fixes. An EKF's linearisation
    moves the mean by ~1 % (Monte Carlo, matched model), which the band of many pooled runs
    resolves: a mean off d by less than `tolerance` (relative) is not counted against it.

    **Returns** a JSON-ready dict: `nis_mean`, `fixes` (N), `level`, `band`, `verdict`
    ("consistent", "does not fit", or "undefined" without a fix), `early`, `early_fixes` (k),
    `early_nis_mean`, `early_level` (0.999), `early_bound`, `early_verdict`, `runs_outside`
    (the fraction of runs whose own mean NIS is outside its band: expected 1 − `level`), and
    `message` (the lines to print: "" when both verdicts are "consistent"), `tolerance`."""
    from ..allan.uncertainty import chi2_ppf

    if not (0 < level < 1 and isinstance(early, int) and early >= 1 and tolerance >= 0):
        raise ValueError("nis_check: needs 0 < level < 1, early >= 1, tolerance >= 0")
    d = whole_number("nis_check: innovation_dim", innovation_dim, "a whole number >= 1")
    if d < 1:
        raise ValueError(f"nis_check: innovation_dim must be a whole number >= 1; got {d}")
    v = np.asarray(nis, float)
    if v.size == 0 or np.isinf(v).any():  # an infinite NIS: a filter that broke
        raise ValueError("nis_check: nis must be finite values (NaN where no fix), not empty")
    # a squared norm: a negative one is not an NIS, beyond round-off of the largest
    floor = -1e-12 * max(float(np.nanmax(np.abs(v))) if np.isfinite(v).any() else 0.0, 1.0)
    if (v < floor).any():
        raise ValueError(f"nis_check: nis must be >= 0 (a squared norm); got {v[v < floor][0]}")
    v = v.reshape(-1, v.shape[-1]) if v.ndim else v.reshape(1, 1)
    ok, a = np.isfinite(v), 0.5 * (1.0 - level)
    band = lambda k: [chi2_ppf(a, d * k) / k, chi2_ppf(1.0 - a, d * k) / k]  # noqa: E731
    n = int(ok.sum())
    out = dict(nis_mean=None, fixes=n, level=level, band=None, verdict="undefined", early=early)
    out.update(early_fixes=0, early_nis_mean=None, early_level=0.999, early_bound=None)
    out.update(early_verdict="undefined", runs_outside=None, message="", tolerance=tolerance)
    if n == 0:
        return out
    mean, (lo, hi) = float(v[ok].mean()), band(n)
    first = np.concatenate([row[m][:early] for row, m in zip(v, ok, strict=True)])
    k, early_mean = first.size, float(first.mean())
    bound = chi2_ppf(0.999, d * k) / k
    rows = [(r[m].mean(), band(m.sum())) for r, m in zip(v, ok, strict=True) if m.any()]
    fits = lo <= mean <= hi or abs(mean / d - 1.0) <= tolerance
    early_fits = early_mean <= max(bound, (1.0 + tolerance) * d)
    lines = [
        f"NIS mean {mean:.3f} over {n} fixes is outside its {100 * level:g} % band "
        f"{lo:.3f}–{hi:.3f}: " + (_DOES_NOT_FIT if mean > hi else _TOO_LOW)
    ] * (not fits) + [
        f"NIS mean {early_mean:.2f} of each run's first {early} fixes ({k} in all) is beyond "
        f"its χ² 99.9 % point {bound:.2f}: " + _DOES_NOT_FIT
    ] * (not early_fits)
    verdict = lambda ok: "consistent" if ok else "does not fit"  # noqa: E731
    out.update(nis_mean=mean, band=[lo, hi], verdict=verdict(fits), early_fixes=k)
    out.update(early_nis_mean=early_mean, early_bound=bound, early_verdict=verdict(early_fits))
    outside = [not b[0] <= m <= b[1] for m, b in rows]
    out.update(runs_outside=float(np.mean(outside)), message="\n".join(lines))
    return out
