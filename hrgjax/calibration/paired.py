r"""Two compensators on the same runs: is one's residual smaller, at a stated confidence?

Two compensators of one session correct the same runs, so their residuals share the
sensor's noise; an RMS over $n$ runs carries a sampling error of about
$\mathrm{RMS}/\sqrt{2n}$ (≈ 0.0024 °/h on 57 runs at 0.025 °/h), as large as the
differences between good compensators. Compared run by run, the shared noise cancels.

**The paired difference.** For compensators A and B with residuals $e_{A,i}$, $e_{B,i}$
after the session's offset on the $n$ runs where both are finite (static runs' residual
rate [°/h] or rotation runs' end-of-run angle error [°]),

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
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import stats


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
        pct = f"{100 * self.level:g} %"
        if self.verdict == "a":
            return f"{self.a} better than {self.b} at {pct}"
        if self.verdict == "b":
            return f"{self.b} better than {self.a} at {pct}"
        return f"{self.a} and {self.b} not told apart at {pct}"

    def to_json(self) -> dict:
        """`{"a", "b", "key", "unit", "n_runs", "dof", "rms_a", "rms_b",
        "mean_square_difference", "stderr", "low", "high", "level", "p_value", "verdict",
        "statement"}` (NaN as `null`; the difference in unit²)."""

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
        }

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
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1); got {level}")
    ea = np.asarray(residual_a, dtype=float).ravel()
    eb = np.asarray(residual_b, dtype=float).ravel()
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
    r"""Do two compensators carry the same constant? Their own offsets on one session
    ([`Offset`][hrgjax.calibration.Offset]s $b_a \pm \sigma_a$, $b_b \pm \sigma_b$) compared:
    $\Delta = b_a - b_b$ against $\sigma = \sqrt{\sigma_a^2 + \sigma_b^2}$, Student's t with the
    Welch–Satterthwaite degrees of freedom.

    A change of switch-on bias is the same for every compensator of a session, so a
    difference is each one's constant from its own calibration: calibrated on different
    switch-ons (or one of them with a constant error), and one session cannot say whose is
    right. (σ treats the two offsets as independent; measured on the same runs they are
    positively correlated, so σ errs large and the test says "differ" less often than its
    level: docs/calibration.md.)

    - `a`, `b`: labels; `value_dph` = $\Delta$ [°/h]; `sigma_dph` [°/h] (NaN: a σ unknown);
      `dof`; `p_value` (two-sided; NaN: untested); `level`.
    """

    a: str
    b: str
    value_dph: float
    sigma_dph: float
    dof: float
    p_value: float
    level: float = 0.95

    @property
    def differ(self) -> bool:
        """Whether the constants differ at `level` (False when untested: a σ unknown)."""
        return bool(self.p_value < 1.0 - self.level)

    def to_json(self) -> dict:
        """`{"a", "b", "difference", "sigma", "unit": "°/h", "dof", "p_value", "level",
        "differ"}` (NaN as `null`)."""

        def num(x):
            return float(x) if math.isfinite(x) else None

        return {"a": self.a, "b": self.b, "difference": num(self.value_dph),
                "sigma": num(self.sigma_dph), "unit": "°/h", "dof": num(self.dof),
                "p_value": num(self.p_value), "level": float(self.level),
                "differ": self.differ}  # fmt: skip

    def __str__(self) -> str:
        head = f"{self.a} − {self.b}: {self.value_dph:+.4f}"
        if not math.isfinite(self.p_value):
            return f"{head} °/h (not tested: σ unknown)"
        word = "differ" if self.differ else "agree"
        return (f"{head} ± {self.sigma_dph:.4f} °/h (1σ, t with {self.dof:.0f} dof, "
                f"p = {self.p_value:.2g}): {word} at {100 * self.level:g} %")  # fmt: skip


def offset_difference(
    a: str, value_a: float, sigma_a: float, dof_a: int,
    b: str, value_b: float, sigma_b: float, dof_b: int, *, level: float = 0.95,
) -> OffsetDifference:  # fmt: skip
    """Compare two own offsets (values and 1σ [°/h], σ's degrees of freedom): an
    [`OffsetDifference`][hrgjax.calibration.OffsetDifference]. **Raises:** `ValueError` when
    `level` is not in (0, 1)."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1); got {level}")
    diff = float(value_a) - float(value_b)
    var_a, var_b = float(sigma_a) ** 2, float(sigma_b) ** 2
    if not (math.isfinite(var_a + var_b) and dof_a >= 1 and dof_b >= 1 and var_a + var_b > 0):
        return OffsetDifference(a, b, diff, math.nan, math.nan, math.nan, level)
    dof = (var_a + var_b) ** 2 / (var_a**2 / dof_a + var_b**2 / dof_b)
    sigma = math.sqrt(var_a + var_b)
    p = float(2 * stats.t.sf(abs(diff) / sigma, dof))
    return OffsetDifference(a, b, diff, sigma, dof, p, level)
