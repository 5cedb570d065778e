r"""Two compensators on the same runs: is one's residual smaller, at a stated confidence?

Two compensators of one session correct the same runs, so their residuals share the
sensor's noise; an RMS over $n$ runs carries a sampling error of about
$\mathrm{RMS}/\sqrt{2n}$ (≈ 0.0024 °/h on 57 runs at 0.025 °/h), as large as the
differences between good compensators. Compared run by run, the shared noise cancels.

**The paired difference.** For compensators A and B with residuals $e_{A,i}$, $e_{B,i}$
after one offset (the session's, or the pair's: `Comparison.offsets_for`) on the $n$ runs
where both are finite (static runs' residual rate [°/h] or rotation runs' end-of-run angle
error [°]),

$$d_i = e_{A,i}^2 - e_{B,i}^2, \qquad \bar d = \mathrm{RMS}_A^2 - \mathrm{RMS}_B^2, \qquad
\mathrm{SE} = s_d/\sqrt n,$$

and the two-sided `level` interval $\bar d \pm t_{n-1}\,\mathrm{SE}$ (Student's t with
$n - 1$ degrees of freedom, the paired t test). An interval wholly below 0 says "A better
than B" at that level, wholly above 0 "B better than A"; one that holds 0 says "not told
apart". The runs are treated as exchangeable draws: what the statement is about is the mean
square a compensator leaves on runs like these (this grid of temperatures and wave angles,
this noise), not on another grid.

**Why t and not a bootstrap.** With equal compensators $d_i = (e_A - e_B)(e_A + e_B)$ is
symmetric but heavy-tailed (a product of two normal variables when the residuals are
normal: excess kurtosis 6). The t interval is robust to symmetric tails and errs
conservative, while a percentile bootstrap of a mean is too narrow with few runs
(it uses $n$ for $n - 1$ and no t quantile). `benchmarks/session_compare.py` measures the
false-"different" rate on equal compensators (Gaussian and t₃ residuals, 10 to 57 runs) and
the power on unequal ones.

**Several compensators.** Each pair is one test at `level`: with $k$ compensators,
$k(k-1)/2$ tests, and on equal compensators each says "different" 5 % of the time at 95 %.

**Different constants.** Each compensator's own offset $b_k$ (its mean rate at rest on the
session) is the session's change of switch-on bias plus the constant $c_k$ it brings from
its calibration, so $\Delta = b_a - b_b = (c_a - c_b) + \overline{(g_a - g_b)}$ ($g_k$: what
each leaves at a run's temperature and wave angle, averaged over the grid). The sensor's
noise is common to both and cancels: $\Delta$ has no sampling error on this session
(σ over redrawn test noise 2e-8 °/h; the Welch σ of the two offsets, 0.0085 °/h, described
nothing). What matters is whether $\Delta$ is large enough to decide the paired test
alone, charged to one of the two as one offset for both would charge it. With residuals
$e_{k,i}$ after each one's own offset and $w_i$ what a unit constant [°/h] shifts the figure
by (1 for a static run's rate, $T_i/3600$ [°] for a rotation run's angle), A shifted by
$+\delta$ or B by $-\delta$ gives

$$d_i(\delta) = d_{0,i} + 2\delta\,w_i e_{k,i} \pm \delta^2 w_i^2$$

($d_0$: the pair after their own offsets; $k$ the one shifted, $+$ for A, $-$ for B). Its
verdict changes where $n\,\bar d^2 - t_{n-1}^2 s_d^2$, a quartic in $\delta$, changes sign;
[`constant_resolution`][hrgjax.calibration.paired.constant_resolution] $R$ is the smallest
such $|\delta|$ of the sign $\Delta$ charges (exact against `scipy.stats.ttest_rel`). For
two equal residuals of zero mean on static runs of equal length it is the closed form
$R = 2\,t_{n-1}\,s_e/\sqrt n \approx 4\,e/\sqrt n$ (residual scatter $e$). Elsewhere the
first-order term has a mean: angle residuals after a static-run offset keep the rotation
runs' mean rate residual $m$, and a constant of one sign changes the verdict sooner than
the other (30 runs, $m$ = 0.005 °/h, scatter 0.025 and 0.04 °/h: 0.011 against 0.029 °/h,
where that closed form weighted by $w$ said 0.025 for both;
`benchmarks/constant_resolution.py`). The pair's own
scatter of $d_0$ enters too: a constant that would tell a compensator from itself (with
$m$ significant, any constant at all) need not change this pair's verdict.
[`OffsetDifference`][hrgjax.calibration.OffsetDifference] says whether $\Delta$ itself,
charged to either, changes it: a resolution, not a sampling test.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import optimize, stats

from .._checks import check_1d, check_numbers, finite_number


@dataclasses.dataclass(frozen=True)
class PairedDifference:
    """Paired comparison of two compensators on their shared runs (module docstring).

    - `a`, `b`: the labels; `key`: the figure (`"static_residual_dph"` [°/h] or
      `"angle_error_deg"` [°]); `unit`.
    - `n_runs`: runs where both residuals are finite; `dof` = `n_runs` − 1.
    - `rms_a`, `rms_b`: each one's RMS over those runs.
    - `mean`: $\\bar d$ = `rms_a`² − `rms_b`² [unit²]; `stderr`: its standard error;
      `low`, `high`: the two-sided `level` Student-t interval; `p_value`: two-sided, of the
      paired t test of mean 0 (NaN where undefined: under 2 runs, or every $d_i$ equal).
    - `level`: the interval's confidence.
    - `offsets`: which offsets the residuals are after, when a
      [`Comparison`][hrgjax.calibration.Comparison] formed them (`"session"`: the session's
      one; `"pair"`: one, the pair's own, its member's with the smaller σ, where the
      session's was measured with a third compensator; `"own"`: each its own); None:
      residuals given as they are. `offset_source`: the label whose offset (`"session"`,
      `"pair"`; None: `"own"`, or given as they are).
    - `constants`: the pair's [`OffsetDifference`][hrgjax.calibration.OffsetDifference]
      (None: not known); where it `differ`s and `offsets` is `"own"`, the verdict is about
      what each leaves beyond a constant, and `statement()` says so.
    """

    a: str
    b: str
    key: str
    unit: str
    n_runs: int
    rms_a: float
    rms_b: float
    mean: float
    stderr: float
    low: float
    high: float
    p_value: float
    level: float = 0.95
    offsets: str | None = None
    constants: OffsetDifference | None = None
    offset_source: str | None = None

    @property
    def beyond_constant(self) -> bool:
        """Whether the verdict is about what each leaves beyond a constant: judged after
        each one's own offset, their constants differing by more than could decide the
        test alone (which of them is right, this session cannot say)."""
        return self.offsets == "own" and self.constants is not None and self.constants.differ

    @property
    def dof(self) -> int:
        """Degrees of freedom of the t interval, `n_runs` − 1 (0 under 2 runs)."""
        return max(self.n_runs - 1, 0)

    @property
    def verdict(self) -> str:
        """`"a"` (A's mean square smaller: the interval wholly below 0), `"b"` (wholly above),
        or `"none"` (not told apart, or undefined)."""
        if self.high < 0:
            return "a"
        if self.low > 0:
            return "b"
        return "none"

    def statement(self) -> str:
        """The verdict in words: "A better than B at 95 %" or "A and B not told apart at
        95 %"."""
        pct = f"at {100 * self.level:g} %"
        if self.beyond_constant:
            pct = (f"beyond a constant {pct} (their constants differ by "
                   f"{self.constants.value_dph:+.4f} °/h; this session cannot assign it)")  # fmt: skip
        if self.verdict == "a":
            return f"{self.a} better than {self.b} {pct}"
        if self.verdict == "b":
            return f"{self.b} better than {self.a} {pct}"
        return f"{self.a} and {self.b} not told apart {pct}"

    def to_json(self) -> dict:
        """`{"a", "b", "key", "unit", "n_runs", "dof", "rms_a", "rms_b",
        "mean_square_difference", "stderr", "low", "high", "level", "p_value", "verdict",
        "statement", "offsets", "offset_source", "constants_differ",
        "constant_difference_dph", "constant_resolution_dph"}` (NaN as `null`; the difference
        in unit²; `offsets` (`"session"`, `"pair"`, `"own"`), `offset_source` null and
        `constants_differ` false for residuals given as they are; the constants' Δ and R
        [°/h] from `constants`)."""

        def num(x):
            return float(x) if math.isfinite(x) else None

        return {
            "a": self.a,
            "b": self.b,
            "key": self.key,
            "unit": self.unit,
            "n_runs": int(self.n_runs),
            "dof": int(self.dof),
            "rms_a": num(self.rms_a),
            "rms_b": num(self.rms_b),
            "mean_square_difference": num(self.mean),
            "stderr": num(self.stderr),
            "low": num(self.low),
            "high": num(self.high),
            "level": float(self.level),
            "p_value": num(self.p_value),
            "verdict": self.verdict,
            "statement": self.statement(),
            "offsets": self.offsets,
            "offset_source": self.offset_source,
            "constants_differ": bool(self.constants is not None and self.constants.differ),
            "constant_difference_dph": None if self.constants is None
            else num(self.constants.value_dph),
            "constant_resolution_dph": None if self.constants is None
            else num(self.constants.resolution_dph),
        }  # fmt: skip

    def __str__(self) -> str:
        u = f"({self.unit})²"
        pct = f"{100 * self.level:g} %"
        if not math.isfinite(self.stderr):
            return f"{self.statement()} ({self.n_runs} runs: too few or no scatter)"
        return (
            f"{self.statement()}: RMS {self.rms_a:.4g} vs {self.rms_b:.4g} {self.unit}, "
            f"mean square difference {self.mean:+.3g} {u}, {pct} [{self.low:+.3g}, "
            f"{self.high:+.3g}] (t, {self.dof} dof, p = {self.p_value:.2g}, {self.n_runs} runs)"
        )


def paired_difference(
    residual_a,
    residual_b,
    *,
    a: str = "A",
    b: str = "B",
    key: str = "static_residual_dph",
    unit: str = "°/h",
    level: float = 0.95,
) -> PairedDifference:
    """Paired t comparison of two compensators' residuals on the same runs (module docstring).

    **Arguments:**

    - `residual_a`, `residual_b`: per-run residuals of A and B on the same runs, in the same
      order (NaN: no such figure for that run; such runs are left out of both).
    - `a`, `b`: labels; `key`, `unit`: the figure's name and unit, kept in the result.
    - `level`: the interval's two-sided confidence, in (0, 1).

    **Returns:** a [`PairedDifference`][hrgjax.calibration.PairedDifference].

    **Raises:** `ValueError` when the residuals differ in shape or `level` is not in (0, 1).
    """
    check_level(level)
    ea = _per_run("residual_a", residual_a)
    eb = _per_run("residual_b", residual_b)
    if ea.shape != eb.shape:
        raise ValueError(f"residuals of {a!r} and {b!r} differ in size: {ea.size} and {eb.size}")
    ok = np.isfinite(ea) & np.isfinite(eb)
    ea, eb = ea[ok], eb[ok]
    n = int(ea.size)
    rms_a = float(np.sqrt(np.mean(ea**2))) if n else math.nan
    rms_b = float(np.sqrt(np.mean(eb**2))) if n else math.nan
    d = ea**2 - eb**2
    mean = float(np.mean(d)) if n else math.nan
    se = float(np.std(d, ddof=1) / math.sqrt(n)) if n >= 2 else math.nan
    if n >= 2 and se > 0:
        q = float(stats.t.ppf(0.5 + 0.5 * level, n - 1))
        low, high = mean - q * se, mean + q * se
        p = float(2 * stats.t.sf(abs(mean / se), n - 1))
    else:  # too few runs, or every d_i equal (identical compensators): undefined
        se, low, high, p = math.nan, math.nan, math.nan, math.nan
    return PairedDifference(a, b, key, unit, n, rms_a, rms_b, mean, se, low, high, p, level)


@dataclasses.dataclass(frozen=True)
class OffsetDifference:
    r"""Do two compensators carry constants that differ by enough to decide their paired test
    alone? $\Delta = b_a - b_b$, their own offsets on one session
    ([`Offset`][hrgjax.calibration.Offset]s), against the resolution $R$ of the paired test
    on `key` (module docstring: the smallest constant that, charged to either, changes its
    verdict at `level`). Not a sampling test: the sensor's noise cancels from $\Delta$, which is fixed
    by the two compensators.

    A change of switch-on bias is the same for every compensator of a session, so a
    difference is each one's constant from its own calibration (plus the grid average of
    what each leaves): calibrated on different switch-ons, or one of them with a constant
    error, and one session cannot say whose is right.

    - `a`, `b`: labels; `key`: the paired test's figure; `value_dph` = $\Delta$ [°/h];
      `resolution_dph` = $R$ [°/h], the smallest constant of $\Delta$'s sign (A shifted by
      it, or B by its opposite) that changes the test's verdict (NaN: under 2 runs or no
      scatter; inf: none does); `n_runs`; `level`.
    - `decides`: whether $\Delta$ itself changes it, A shifted by $+\Delta$ or B by
      $-\Delta$ (None: judged as $|\Delta| > R$).
    """

    a: str
    b: str
    key: str
    value_dph: float
    resolution_dph: float
    n_runs: int
    level: float = 0.95
    decides: bool | None = None

    @property
    def differ(self) -> bool:
        r"""Whether the constants' difference alone would change the paired test's verdict:
        `decides`, or $|\Delta| > R$ where that is None (False when $R$ is unknown). The
        two differ only where a band of constants beyond $R$ changes it and larger ones
        change it back."""
        if self.decides is not None:
            return bool(self.decides)
        return bool(abs(self.value_dph) > self.resolution_dph)

    def to_json(self) -> dict:
        """`{"a", "b", "key", "difference", "resolution", "unit": "°/h", "n_runs", "level",
        "differ"}` (NaN as `null`)."""

        def num(x):
            return float(x) if math.isfinite(x) else None

        return {"a": self.a, "b": self.b, "key": self.key, "difference": num(self.value_dph),
                "resolution": num(self.resolution_dph), "unit": "°/h",
                "n_runs": int(self.n_runs), "level": float(self.level),
                "differ": self.differ}  # fmt: skip

    def __str__(self) -> str:
        what = {"static_residual_dph": "static residual", "angle_error_deg": "end-of-run angle "
                "error", "max_angle_error_deg": "largest angle error"}.get(self.key, self.key)  # fmt: skip
        head = f"{self.a} − {self.b}: {self.value_dph:+.4f} °/h"
        if math.isnan(self.resolution_dph):
            return f"{head} (resolution unknown: {self.n_runs} runs)"
        tail = f"paired {what} test ({self.n_runs} runs, {100 * self.level:g} %)"
        if math.isinf(self.resolution_dph):
            return f"{head}: no constant alone changes the verdict of the {tail}"
        if not self.differ and abs(self.value_dph) > self.resolution_dph:
            return f"{head}, not deciding the {tail} alone (from {self.resolution_dph:.4f} °/h)"
        word = "beyond" if self.differ else "within"
        return f"{head}, {word} the {self.resolution_dph:.4f} °/h that alone decides the {tail}"


class _Shifted:
    """The paired test of one pair with one of them shifted by a constant c [°/h]:
    $d_i(c) = d_{0,i} + c\\,x_i + c^2 y_i$, its verdict (−1: A better, 0: none, +1: B better)
    where $n\\bar d^2 - t^2 s_d^2$ (a quartic in c) is positive, and the constants where the
    verdict changes (module docstring)."""

    def __init__(self, d0, x, y, q: float):
        self.n, self.q2 = d0.size, q * q
        self.m = np.array([np.mean(d0), np.mean(x), np.mean(y)])
        self.s = np.cov(np.stack([d0, x, y]), ddof=1)

    def mean(self, c):
        return self.m[0] + c * (self.m[1] + c * self.m[2])

    def var(self, c):
        s = self.s
        return (s[0, 0] + c * (2 * s[0, 1] + c * (s[1, 1] + 2 * s[0, 2] + c * (2 * s[1, 2]
                + c * s[2, 2]))))  # fmt: skip

    def verdict(self, c) -> int:
        m, v = self.mean(c), self.var(c)
        decided = v > 0.0 and self.n * m * m > self.q2 * v
        return int(np.sign(m)) if decided else 0

    def quartic(self) -> np.ndarray:
        """Coefficients of $n\\bar d^2 - t^2 s_d^2$ in c, highest first."""
        (m0, mx, my), s, n, q2 = self.m, self.s, self.n, self.q2
        return np.array([
            n * my * my - q2 * s[2, 2],
            2 * n * mx * my - 2 * q2 * s[1, 2],
            n * (mx * mx + 2 * m0 * my) - q2 * (s[1, 1] + 2 * s[0, 2]),
            2 * n * m0 * mx - 2 * q2 * s[0, 1],
            n * m0 * m0 - q2 * s[0, 0],
        ])  # fmt: skip

    def threshold(self, scale: float) -> float:
        """The smallest c > 0 [°/h] at which the verdict differs from c = 0's (0: at any
        c > 0; inf: at none). `scale`: a typical constant, to condition the roots."""
        p = self.quartic() * scale ** np.arange(4, -1, -1)
        f = lambda c: np.polyval(p, c / scale)
        if not np.any(p):
            roots = np.zeros(0)
        else:
            r = np.roots(np.trim_zeros(p, "f"))
            roots = np.sort(r.real[(np.abs(r.imag) <= 1e-7 * np.abs(r)) & (r.real > 1e-9)])
        edges = [0.0]
        for k in roots:  # polished on the quartic where it changes sign about k
            lo, hi = k * (1 - 1e-6), k * (1 + 1e-6)
            c = optimize.brentq(f, lo * scale, hi * scale, xtol=1e-300, rtol=1e-15) \
                if f(lo * scale) * f(hi * scale) < 0 else k * scale  # fmt: skip
            edges.append(max(c, edges[-1]))
        edges.append(math.inf)
        start = self.verdict(0.0)
        for lo, hi in zip(edges[:-1], edges[1:], strict=True):
            probe = math.sqrt(lo * hi) if lo > 0 and math.isfinite(hi) else (
                0.5 * hi if lo == 0 and math.isfinite(hi) else 2.0 * lo + scale)  # fmt: skip
            if self.verdict(probe) != start:
                return lo
        return math.inf


def check_level(level) -> None:
    """Refuse a confidence `level` that is not a number in (0, 1), in one line."""
    number = isinstance(level, int | float | np.integer | np.floating) and not isinstance(
        level, bool | np.bool_)  # fmt: skip
    if not (number and 0.0 < level < 1.0):
        raise ValueError(f"level must be in (0, 1); got {level!r}")


def _per_run(name: str, x) -> np.ndarray:
    """`x` (one value per run: real numbers, NaN for none) as a float array, or a one-line
    error: not numbers, not 1-D (a table of runs is not flattened) or ±inf."""
    check_numbers(name, x, "one value per run (real numbers; NaN: none)")
    check_1d(name, x, "one value per run")
    v = np.asarray(x, dtype=float)
    if np.isinf(v).any():
        i = int(np.flatnonzero(np.isinf(v))[0])
        raise ValueError(f"{name} must be finite or NaN (no figure for that run); got {v[i]} "
                         f"at index {i}")  # fmt: skip
    return v


def _shifts(residual_a, residual_b, weight, level: float, difference) -> tuple:
    """(n, scale [°/h], [(_Shifted, sign), …]): the pair's paired test with A shifted by
    +sign·c and B by −sign·c, for the signs `difference` charges (None or 0: both)."""
    check_level(level)
    ea = _per_run("residual_a", residual_a)
    eb = _per_run("residual_b", residual_b)
    w = np.ones(ea.shape) if weight is None else _per_run("weight", weight)
    if not ea.shape == eb.shape == w.shape:
        raise ValueError(f"residual_a, residual_b and weight differ in size: {ea.size}, "
                         f"{eb.size}, {w.size}")  # fmt: skip
    ok = np.isfinite(ea) & np.isfinite(eb) & np.isfinite(w)
    n = int(np.sum(ok))
    if n < 2:
        return n, 1.0, []
    ea, eb, w = ea[ok], eb[ok], w[ok]
    q = float(stats.t.ppf(0.5 + 0.5 * level, n - 1))
    d0, v = ea**2 - eb**2, w**2
    signs = (1.0, -1.0) if difference is None or float(difference) == 0.0 else (
        math.copysign(1.0, float(difference)),)  # fmt: skip
    tests = []
    for s in signs:  # A + s·c·w: d0 + 2 s c u_a + c² v; B − s·c·w: d0 + 2 s c u_b − c² v
        tests.append((_Shifted(d0, 2 * s * w * ea, v, q), s))
        tests.append((_Shifted(d0, 2 * s * w * eb, -v, q), s))
    scale = math.sqrt(float(np.mean(ea**2 + eb**2)) / (2 * float(np.mean(v))))
    return n, scale if scale > 0 else 1.0, tests


def _resolution(scale: float, tests: list) -> float:
    """The smallest threshold over the `tests` defined somewhere (NaN: none is, under 2 runs
    or with no scatter at any constant)."""
    return min((t.threshold(scale) for t, _ in tests if np.any(t.s)), default=math.nan)


def constant_resolution(
    residual_a, residual_b, weight=None, *, level: float = 0.95, difference=None
) -> float:
    r"""The smallest constant [°/h] that alone changes the paired test's verdict at `level`,
    charged to either compensator (module docstring: where a quartic in the constant
    changes sign; exact against the paired t test).

    **Arguments:** `residual_a`, `residual_b` (per run, each after its own offset; NaN: left
    out of both), `weight` (per run, what a constant of 1 °/h shifts the figure by: 1 for a
    static rate [°/h], $T_i/3600$ for an angle [°]; None: 1), `level` in (0, 1),
    `difference` ($\Delta = b_a - b_b$ [°/h]: only the sign it charges, A shifted by
    $+\Delta$ or B by $-\Delta$; None or 0: either sign).

    **Returns:** $R$ [°/h] (for equal residuals of zero mean on static runs of equal length,
    $2\,t_{n-1}\,s_e/\sqrt n$); 0 where any constant changes it; inf where none does; NaN
    under 2 runs or with no scatter.

    **Raises:** `ValueError` when the arrays differ in shape or `level` is not in (0, 1).
    """
    _, scale, tests = _shifts(residual_a, residual_b, weight, level, difference)
    return _resolution(scale, tests)


def offset_difference(
    a: str, value_a: float, b: str, value_b: float, residual_a, residual_b, weight=None, *,
    key: str = "static_residual_dph", level: float = 0.95,
) -> OffsetDifference:  # fmt: skip
    """Compare two own offsets (values [°/h]) with the paired test on their residuals after
    them ([`constant_resolution`][hrgjax.calibration.paired.constant_resolution]: `residual_a`,
    `residual_b`, `weight`, `level`, of the sign the difference charges): an
    [`OffsetDifference`][hrgjax.calibration.OffsetDifference] for `key`, `decides` whether
    the difference itself, charged to either, changes the verdict. **Raises:** `ValueError`
    as `constant_resolution`."""
    delta = finite_number("value_a", value_a, "°/h") - finite_number("value_b", value_b, "°/h")
    n, scale, tests = _shifts(residual_a, residual_b, weight, level, delta)
    resolution = _resolution(scale, tests)
    live = [t for t, _ in tests if np.any(t.s)]
    decides = any(t.verdict(abs(delta)) != t.verdict(0.0) for t in live) if live else None
    return OffsetDifference(a, b, key, delta, resolution, n, level, decides)
