r"""Error bars that cover the truth (issue 43): the σ `discover` reports for the final model.

A fit's textbook covariance $(J^\top J)^{-1}$ (in whitened units) is right only when the
whitening is right and the model is. Neither holds off the paved path: the noise model is read
from short still stretches (a 60-s dwell cannot tell its angle random walk from white noise,
and the windows' σ swing by 2–4× between sessions), and a model with structure left is
biased by it. Two corrections, both from the fit's own residual:

1. **Noise scale** (Birge ratio). Each class of rows (static and moving dwell windows,
   continuous blocks) has its whitened residual's mean square $s_g^2 = \sum r_g^2/\nu_g$,
   $\nu_g = n_g - \sum_{i\in g} h_{ii}$ (h the fit's leverages: the parameters a class
   fixes are taken from its own degrees of freedom): the noise level the data show, not
   the one the noise model guessed. The
   reported values keep the noise model's weights, so their variance is the sandwich
   $(A^\top A)^{-1}A^\top \mathrm{diag}(s^2)A(A^\top A)^{-1}$ (which is $s^2(A^\top
   A)^{-1}$ when one scale fits all rows). $s_g$ is read after the structure left (2.) is
   fitted, and the shapes are judged at that level (twice round: a shape inflates the level
   it is judged at). A class with fewer than `MIN_ROWS` rows (the ≈ 19 static windows of
   a 5 × 5 dwell grid, whose 60-s runs leave the angle random walk unresolved and their σ
   2× small) reads its level from its own rows with the small-sample allowance of a level
   estimated from ν_g degrees of freedom, $s_g^2 = \sum r_g^2/(\nu_g - 2)$ (the variance
   of Student's t), or, with `SMALL_DOF` or fewer, pooled with the other classes; either
   way never below 1 (too few rows to vouch for a noise model that is *too pessimistic*).
2. **Structure left** (model uncertainty). The generic shapes of
   [`leftover`][hrgjax.discovery.leftover] that are still significant (Bonferroni over the
   shapes tried, p < `alpha`) are fitted beside the model, strongest first, up to
   `MAX_SHAPES`. Each shape is judged at the noise level the residual shows once *it* is
   fitted, with the F(q, ν) tail of a level read from ν degrees of freedom (the classes'
   own, pooled by where the shape is seen: Satterthwaite): structure inflates the level it
   would otherwise be judged at (audit 2026-11-30: a ΔT³ drift raised the static windows'
   level ×5, nothing was significant at ×5, and b1 came out 11σ wrong, unflagged). A class
   whose level the shapes bring down is named in `info["excess"]`, and
   `info["structure_left"]` is set. Each parameter's σ is then the augmented fit's (wider:
   it no longer borrows what the shapes take) plus its shift $\delta$ when they are fitted:
   $\sigma = \sigma_{\rm sandwich} + |\delta_i|$, $A = [J\;G]$. The reported value
   stays the named model's, so its error is the noise's plus the pull: added linearly, the
   ±1σ interval holds the truth at least as often as the noise alone would put it there
   when δ is the pull (added in quadrature, a pull much larger than the noise would sit at
   the interval's edge, half the time outside). A parameter the leftover pulls is reported
   with that pull in its σ, never with a confident, wrong one. A shape too weak to be
   structure left (Bonferroni p between `alpha` and `alpha_sigma`, 10⁻³ and 0.05) is fitted
   beside for the σ all the same (`info["suggested"]`): a weak shape can pull a parameter
   by many of its σ (a 2θ·ΔT² at 2.6σ held b₁ 5.6σ off; `SIGMA_ALPHA`), and where it is
   noise its pull is small.

Continuous records add a third, from outside the residual level: the run-to-run bias σ_b
is read from a few run means, and its own uncertainty is carried into every parameter's
variance (`spread`, [`run_bias.spread`][hrgjax.discovery.run_bias.spread]).

The corrected σ replace `std` in the fit's parameters; the untouched textbook value is kept
as `std_textbook`, the shift as `std_model`, and the returned `basis` says in words what was
done (the report's "± are 1σ: …" line). `benchmarks/coverage.py` measures how often the truth falls
within ±1σ and ±2σ.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping

import numpy as np

from .. import _checks
from . import leftover, stats
from .effects import CATALOGUE, regular_parameters

MAX_SHAPES = 3
"""The most leftover shapes fitted beside the model for its model uncertainty."""
SIGMA_ALPHA = 0.05
"""Significance (Bonferroni over the shapes tried) at which a leftover shape is fitted beside
the model *for the σ* ([`honest`][hrgjax.discovery.trust.honest]'s `alpha_sigma`), though too
weak to count as structure left (`alpha`, 10⁻³): a weak shape can pull a parameter by many of
its σ (a damping law exponential in ΔT, linear in the catalogue: its 2θ·ΔT² at 2.6σ held
b₁ 5.6σ high on the six-ramp records; `benchmarks/coverage_continuous.py --laws`)."""
CLASS_NAMES = {0: "moving windows", 1: "static windows", 2: "continuous blocks"}
"""What the row classes of [`row_classes`][hrgjax.discovery.problem.AbstractProblem.row_classes]
are, for the report."""
MIN_ROWS = stats.MIN_ROWS
"""Fewest rows of a class whose noise scale is read from its own residual as it is; a
smaller class reads it with a small-sample allowance and never below the noise model's
(module docstring; [`class_levels`][hrgjax.discovery.stats.class_levels])."""
NOT_PINNED = "σ_b not pinned"
"""How a parameter's `why_no_sigma` begins where σ_b's posterior leaves its σ unbounded
(too few continuous runs: [`run_bias.spread`][hrgjax.discovery.run_bias.spread])."""
SMALL_DOF = stats.SMALL_DOF
"""A class below `MIN_ROWS` with at most this many degrees of freedom pools its noise level
with the other classes'."""


def _inputs(owner, fit, shape_columns, classes, alpha, spread):
    """`honest`'s and `statistical_p_value`'s arguments checked, before any fit: `(r, j,
    labels, the shape columns on r's rows, classes)`, or one line naming `owner` and the
    argument (a NaN in the residual read as a noise level of ×1, classes 0.5 and 1.5 as
    "all rows", alpha 1.5 fitting every shape beside the model, a raw LinAlgError…)."""
    if not all(hasattr(fit, k) for k in ("model", "parameters", "r", "j")):
        raise TypeError(f"{owner}: fit must be a discovery Fit (its model, parameters, r and "
                        f"j); got {type(fit).__name__}")  # fmt: skip
    if isinstance(fit.model, str) or any(n not in CATALOGUE for n in fit.model):
        raise ValueError(f"{owner}: fit.model must be effect names of the catalogue; got "
                         f"{_checks.describe(fit.model)}")  # fmt: skip
    r = stats.real_array(owner, "fit.r", fit.r, (None,), "the whitened residual, shape (N,)")
    j = stats.real_array(owner, "fit.j", fit.j, None, "the whitened Jacobian, shape (N, p)")
    if j.ndim == 2 and j.shape[0] != r.size:
        raise ValueError(f"{owner}: fit.j must be the whitened Jacobian, shape (N, p) with N = "
                         f"{r.size} (fit.r's rows); got shape {j.shape}")  # fmt: skip
    labels = regular_parameters(fit.model)
    classes = stats.check_classes(owner, classes, r.size)
    _checks.check_number(f"{owner}: alpha", alpha)
    _checks.check_values(f"{owner}: alpha", alpha, lambda v: (v >= 0) & (v <= 1),
                         "a significance level in [0, 1]")  # fmt: skip
    if spread is not None:
        if not (isinstance(spread, tuple | list) and len(spread) == 2
                and isinstance(spread[1], Mapping)):  # fmt: skip
            raise TypeError(f"{owner}: spread must be None or (factors, info) with info a "
                            f"dict; got {_checks.describe(spread)}")  # fmt: skip
        form = f"a variance factor >= 0 (or inf) per regular parameter, shape ({len(labels)},)"
        _checks.check_numbers(f"{owner}: spread's factors", spread[0], form, (len(labels),))
        f = np.asarray(spread[0], float)
        if not np.all(f >= 0):
            raise ValueError(f"{owner}: spread's factors must be {form}; got {f[~(f >= 0)][0]}")
    if not isinstance(shape_columns, Mapping):
        raise TypeError(f"{owner}: shape_columns must be a dict of whitened columns (N, k) by "
                        f"shape name; got {_checks.describe(shape_columns)}")  # fmt: skip
    cols = {}
    for k, v in shape_columns.items():
        name, form = f"shape_columns[{k!r}]", "whitened columns, shape (N, k)"
        _checks.check_numbers(f"{owner}: {name}", v, form)
        if np.ndim(v) >= 1 and np.shape(v)[0] == r.size:  # the training rows' (others: unread)
            cols[k] = stats.real_array(owner, name, v, (r.size, None), form)
    return r, j, labels, cols, classes


def _sandwich(a, s, p):
    """Covariance of the first `p` coefficients of the least-squares fit on the whitened
    columns `a` when row i's whitened noise has standard deviation `s[i]`:
    (AᵀA)⁻¹ Aᵀ diag(s²) A (AᵀA)⁻¹ (the fit keeps the noise model's weights; only the
    noise level is read from the residual). Columns the data never excite or do not
    determine (`stats.gram_inverse`): ∞ variance."""
    out = np.zeros((p, p))
    out[np.diag_indices(p)] = np.inf
    live = np.linalg.norm(a, axis=0) > 0
    if not live.any():
        return out
    al = a[:, live]
    c, determined = stats.gram_inverse(al)
    meat = (al * (s**2)[:, None]).T @ al
    v = c @ meat @ c
    where = np.flatnonzero(live)
    keep = np.flatnonzero(where < p)
    rows = where[keep]
    out[np.ix_(rows, rows)] = v[np.ix_(keep, keep)]
    out[rows, rows] = np.where(determined[keep], np.maximum(np.diag(v)[keep], 0.0), np.inf)
    return out


def _sandwich_diag(a, s, p):
    """The variances of [`_sandwich`][hrgjax.discovery.trust._sandwich]."""
    return np.diag(_sandwich(a, s, p)).copy()


def _levels(r, j, cols, classes, alpha):
    """The noise level per row the residual shows once the significant leftover shapes are
    fitted beside the model (module docstring, 1. and 2.): `(s, a, shapes, bare)` — the
    levels, the columns `[j, shapes]`, the shapes' names, the levels without them."""
    s = bare = stats.class_levels(r, j, classes)  # `bare`: the level without the shapes
    for _ in range(2):  # the shapes judged at the noise level the data show, and back
        chosen = _shapes_left(r, j, cols, classes, s, alpha)
        shapes = [name for name, _ in chosen]
        a = np.concatenate([j, *(cols[k] for k in shapes)], axis=1) if shapes else j
        step, *_ = np.linalg.lstsq(a / s[:, None], r / s, rcond=None)
        s = stats.class_levels(r - a @ step, a, classes, s)  # the noise the shapes leave
    return s, a, shapes, bare


def _shapes_left(r, j, cols, classes, s, alpha):
    """Significant leftover shapes, strongest first, each chosen given the ones before, as
    `(name, Bonferroni p)`.

    Each shape is judged at the noise level the residual shows *once it is fitted* (its
    own Birge ratio per class, `stats.class_levels`), with the F(q, ν) tail of a level read from ν
    degrees of freedom (`stats.effective_dof`): structure that inflates the level it is
    judged at (a static window's drift over temperature raising its class's ratio ×5) no
    longer hides itself; Bonferroni over the shapes tried."""
    chosen, jj = [], j
    cols = leftover.distinct(cols)
    for _ in range(MAX_SHAPES):
        tried = []  # (F statistic, q, ν, score, name) of each shape that adds something
        for name, g in cols.items():
            if name in (c for c, _ in chosen):
                continue
            a = np.concatenate([jj, g], axis=1)
            step, *_ = np.linalg.lstsq(a / s[:, None], r / s, rcond=None)
            h = stats.leverage(a / s[:, None])
            s1 = stats.class_levels(r - a @ step, a, classes, s, h)
            q_j, _ = np.linalg.qr(jj / s1[:, None])
            g_w = g / s1[:, None]
            score, alias, _ = stats.score(r / s1, jj / s1[:, None], g_w, q_j)
            if alias >= 0.999 or score <= 0:
                continue
            q = int(g.shape[1])
            g_t = g_w - q_j @ (q_j.T @ g_w)
            tried.append((score / q, q, int(stats.effective_dof(h, g_t, classes)), score, name))
        if not tried:
            break
        # the tails in one call; the smallest p wins, the larger score on a tie, then the first
        p = stats.f_sf_many(*(np.array([t[k] for t in tried]) for k in range(3)))
        i = min(range(len(tried)), key=lambda i: (p[i], -tried[i][3], i))
        best = (p[i], -tried[i][3], tried[i][4])
        if min(1.0, best[0] * len(cols)) >= alpha:
            break
        chosen.append((best[2], min(1.0, best[0] * len(cols))))
        jj = np.concatenate([jj, cols[best[2]]], axis=1)
    return chosen


def honest(
    fit, shape_columns, classes=None, alpha: float = 1e-3, spread=None,
    alpha_sigma: float | None = None,
):  # fmt: skip
    """The fit's parameters with error bars that cover the truth (module docstring).

    **Arguments:** `fit` (a [`Fit`][hrgjax.discovery.problem.Fit]), `shape_columns` (the
    problem's whitened generic-shape columns on the training rows), `classes` (an integer
    class per training row — static / moving windows — or None for one class), `alpha`
    (significance of a leftover shape as structure left), `alpha_sigma` (the weaker
    significance at which a shape is fitted beside for the σ alone; None: the larger of
    `alpha` and `SIGMA_ALPHA`; a shape
    that weak is listed in `info["suggested"]`, not as structure left), `spread` (None, or
    `(factors, info)`: a factor per
    regular parameter on its statistical variance for an estimated part of the noise model's
    own uncertainty, `info["basis"]` saying which in words — continuous records' σ_b,
    [`noise_spread`][hrgjax.discovery.problem.AbstractProblem.noise_spread]).

    **Returns:** `(parameters, info)`: a copy of `fit.parameters` whose `std` are the
    corrected ones (`std_textbook` and `std_model` beside them; `std` None with
    `why_no_sigma` for a parameter σ_b is not pinned for, `spread`'s `"not_pinned"`), and `info` =
    `{"noise_scale": {class: s}, "shapes": [names], "suggested": [names], "structure_left":
    bool, "basis": words}` (`shapes`: significant at `alpha`; `suggested`: at `alpha_sigma`
    only; both fitted beside)
    (with `spread`, `"run_bias"`: its info less the words; `structure_left`: a shape was
    fitted beside the model, and with it `"excess"`:
    `{class: s without the shapes}` for the classes whose level they bring down by more than
    10 %: a residual far above the noise model that the shapes explain is structure, not noise).
    """
    r, j, labels, cols, classes = _inputs("honest", fit, shape_columns, classes, alpha, spread)
    if spread is not None and "basis" not in spread[1]:
        raise TypeError("honest: spread must be None or (factors, info) with info['basis'] its "
                        "words for the report; got no 'basis'")  # fmt: skip
    if alpha_sigma is None:
        alpha_sigma = max(alpha, SIGMA_ALPHA)
    _checks.check_values("honest: alpha_sigma", alpha_sigma, lambda v: (v >= alpha) & (v <= 1),
                         f"a significance in [alpha = {alpha:g}, 1]")  # fmt: skip
    params = copy.deepcopy(fit.parameters)
    if j.ndim != 2 or j.shape[1] != len(labels) or r.size <= j.shape[1]:
        return params, {"noise_scale": {}, "shapes": [], "suggested": [], "structure_left":
                        False, "basis": "textbook (no correction)"}  # fmt: skip
    n, p = j.shape
    s, a, fitted, bare = _levels(r, j, cols, classes, alpha_sigma)
    # structure left as judged at `alpha` alone (the weaker shapes admitted first could make
    # a later one look strong given them); the rest of what is fitted is only suggested
    shapes = _levels(r, j, cols, classes, alpha)[2] if fitted else []
    suggested = [name for name in fitted if name not in shapes]
    # the reported values are the noise model's weighted fit: the shift and the sandwich
    # variance are that estimator's (with the shapes beside it), at the noise level s
    step, *_ = np.linalg.lstsq(a, r, rcond=None)
    var = _sandwich_diag(a, s, p)
    old = np.sqrt(np.diag(stats.covariance(j)))
    if spread is not None:  # σ_b's (or another estimated noise part's) own uncertainty
        var = var * np.asarray(spread[0], float)
    shift = step[:p] if fitted else np.zeros(p)
    for i, (name, pname) in enumerate(labels):
        entry = params[name][pname]
        std = entry.get("std")
        if std is None or not np.isfinite(std) or not np.isfinite(old[i]) or old[i] == 0:
            continue
        unit = std / old[i]  # Jacobian column → model units
        if spread is not None and i in spread[1].get("not_pinned", ()):
            entry["std_textbook"], entry["std"] = std, None
            entry["why_no_sigma"] = (
                f"{NOT_PINNED} by {spread[1]['runs']} runs ({spread[1]['dof']:.1f} degrees "
                "of freedom): this parameter's variance keeps growing with σ_b, so its "
                "σ_b-integrated value would rest on the prior's tail and the grid's range"
            )
            continue
        if not np.isfinite(var[i]):
            continue
        stat = math.sqrt(var[i]) * unit
        model = abs(float(shift[i])) * unit
        entry["std_textbook"] = std
        entry["std_model"] = model
        entry["std"] = stat + model
    scale, without = {}, {}
    for c in np.unique(classes) if classes is not None else [None]:
        m = classes == c if classes is not None else slice(None)
        scale[CLASS_NAMES.get(c, "all rows")] = float(np.median(s[m]))
        without[CLASS_NAMES.get(c, "all rows")] = float(np.median(bare[m]))
    words = (
        "noise level from the fit's residual ("
        + ", ".join(f"{k} ×{v:.2g}" for k, v in scale.items())
        + " of the noise model's σ)"
    )
    info = {"noise_scale": scale, "shapes": shapes, "suggested": suggested,
            "structure_left": bool(shapes)}  # fmt: skip
    if spread is not None:
        info["run_bias"] = {k: v for k, v in spread[1].items() if k != "basis"}
        words += "; " + spread[1]["basis"]
    if shapes:
        info["excess"] = {k: without[k] for k in scale if without[k] > 1.1 * scale[k]}
        words += "; structure left (" + ", ".join(shapes) + ") fitted beside the model"
        if info["excess"]:
            words += " (without it: " + ", ".join(
                f"{k} ×{v:.2g}" for k, v in info["excess"].items()) + ")"  # fmt: skip
    if suggested:
        words += ("; " + ", ".join(suggested) + f" (weak: p < {alpha_sigma:g}, not structure "
                  "left) fitted beside the model")  # fmt: skip
    if fitted:
        words += ", each parameter's shift when it is fitted added to its σ"
    return params, info | {"basis": words}


def statistical_p_value(fit, name: str, shape_columns, classes=None, alpha: float = 1e-3,
                        spread=None, descent: float = 1.0) -> float | None:  # fmt: skip
    r"""The p-value of effect `name` in `fit` in the fit its reported σ comes from: the
    named model with the significant leftover shapes fitted beside it
    ([`honest`][hrgjax.discovery.trust.honest]), read at the noise level its residual
    shows per class of rows and with `spread`'s factors ($\sqrt{f_i f_j}$: continuous
    records' σ_b posterior). The candidate's estimate in that fit, $\hat\theta + \delta$
    (δ: its shift when the shapes are fitted), against that fit's sandwich covariance:
    $W = (\hat\theta+\delta)^\top C^{-1}(\hat\theta+\delta)$ over the parameters σ_b
    pins, with the F(q, ν) tail of a level read from ν degrees of freedom (the classes' own,
    pooled by where the candidate is seen: `stats.effective_dof`).

    The acceptance rule's score p-value and ΔBIC read the noise model as given and the
    model as complete; where the residual is far above the noise model (a mixed log's static
    windows ×52 where laws are missing), a candidate is pinned only by run means that a few
    runs' σ_b cannot vouch for, or its value is a leftover shape's pull, an effect can pass
    them and be reported at 1σ (audit bench2: the designed mixed log's thermal rate, 48σ by
    the noise model, 1.0σ reported). Arguments as [`honest`][hrgjax.discovery.trust.honest];
    `descent`: the sign that turns `lstsq(fit.j, fit.r)` into a parameter step (+1 where
    `j` is the model's derivative, as the dwell fits'; −1 where it is the residual's, as the
    continuous fits': `AbstractProblem.descent`).

    **Returns** the p-value, 1.0 where no parameter of `name` has a finite variance (the
    data do not excite it, or σ_b pins none of them), None where `name` has no regular
    parameter in `fit` or there are too few rows to read a level."""
    owner = "statistical_p_value"
    if not isinstance(name, str) or name not in CATALOGUE:
        raise (ValueError if isinstance(name, str) else TypeError)(
            f"{owner}: name must be an effect name of the catalogue; got {_checks.describe(name)}"
        )
    if not (_checks.is_finite_real(descent) and abs(float(descent)) == 1.0):
        raise (ValueError if _checks.numeric_problem(descent) is None else TypeError)(
            f"{owner}: descent must be +1 or -1 (AbstractProblem.descent); got "
            f"{_checks.describe(descent)}"
        )
    r, j, labels, cols, classes = _inputs(owner, fit, shape_columns, classes, alpha, spread)
    idx = [i for i, (n, _) in enumerate(labels) if n == name]
    if not idx or j.ndim != 2 or j.shape[1] != len(labels) or r.size <= j.shape[1]:
        return None
    old = np.diag(stats.covariance(j))
    theta = []
    for i in idx:
        std = fit.parameters[name][labels[i][1]].get("std")
        if not (std and np.isfinite(std) and np.isfinite(old[i]) and old[i] > 0):
            return None
        theta.append(fit.parameters[name][labels[i][1]]["value"] / std * math.sqrt(old[i]))
    s, a, shapes, _ = _levels(r, j, cols, classes, alpha)
    theta = np.asarray(theta)  # in the Jacobian's (whitened) units
    if shapes:  # the estimate in the fit with the shapes
        step, *_ = np.linalg.lstsq(a, r, rcond=None)
        theta = theta + descent * step[idx]
    # the test's level, as `stats.level_test` reads it: each class's own, without the
    # small-class allowance — the F tail below carries the level's uncertainty (with the
    # allowance a 7-row class pooled and floored at 1 was charged its own ν ≈ 2: a 43σ
    # damping law on a 3 × 3 grid refused, review of b018dc5)
    h = stats.leverage(a)
    norm = np.linalg.norm(a, axis=0)
    a_n = a / np.where(norm > 0, norm, 1.0)
    coef, *_ = np.linalg.lstsq(a_n, r, rcond=None)
    s = stats.class_levels(r - a_n @ coef, a, classes, None, h, allowance=False)
    cov = _sandwich(a, s, j.shape[1])[np.ix_(idx, idx)]
    if spread is not None:
        f = np.asarray(spread[0], float)[idx]
        keep = np.isfinite(f)  # the parameters σ_b pins
        cov = cov[np.ix_(keep, keep)] * np.sqrt(np.outer(f[keep], f[keep]))
        theta, idx = theta[keep], [i for i, k in zip(idx, keep, strict=True) if k]
    live = np.isfinite(np.diag(cov)) if idx else np.zeros(0, bool)
    if not live.any():
        return 1.0
    cov, theta = cov[np.ix_(live, live)], theta[live]
    idx = [i for i, k in zip(idx, live, strict=True) if k]
    u, sv, vt = np.linalg.svd(cov)
    rank = int(np.sum(sv > sv[0] * len(sv) * np.finfo(float).eps)) if sv[0] > 0 else 0
    if rank == 0:
        return 1.0
    proj = u[:, :rank].T @ theta
    wald = float(np.sum(proj**2 / sv[:rank]))  # a pseudo-inverse: collinear columns
    aw = a / s[:, None]
    q_o, _ = np.linalg.qr(np.delete(aw, idx, axis=1))  # the candidate beside the rest
    g = aw[:, idx]
    nu = stats.effective_dof(h, g - q_o @ (q_o.T @ g), classes)
    return stats.f_sf(wald / rank, rank, max(int(math.floor(nu)), 1))


UPPER_Z = 1.959963984540054
"""Two-sided 95 % normal quantile: an upper limit is |value| + `UPPER_Z`·σ."""


def upper_limits(fits: Mapping, shape_columns, classes=None, spread=None) -> dict:
    """95 % upper limits on the size of each effect the model did not take (DISCOVERY.md
    §2.6 `upper_limits`, the main content of a `none` verdict): `fits` maps an effect name
    to the model refitted with it added (a screening row's refit; None is skipped), and each
    of its regular parameters gets `{"value", "std", "ci95_upper"}` in model units, `std`
    the corrected σ of [`honest`][hrgjax.discovery.trust.honest] (noise level from that
    refit's residual, leftover shapes' pull added) and `ci95_upper` = |value| + `UPPER_Z`·σ:
    |θ| lies below it at least 95 % of the time where |θ − value| ≤ 1.96σ does (infinite
    where the data do not determine the parameter). `spread`: None or a callable `fit →`
    `honest`'s `spread` (continuous records' σ_b uncertainty)."""
    out = {}
    for name, fit in fits.items():
        if fit is None or name not in fit.parameters:
            continue
        params, _ = honest(fit, shape_columns, classes,
                           spread=None if spread is None else spread(fit))  # fmt: skip
        out[name] = {}
        for pname, v in params[name].items():
            if pname not in CATALOGUE[name].regular_names:  # a scanned time constant
                continue
            std = v.get("std")
            std = math.inf if std is None or not math.isfinite(std) else float(std)
            value = float(v["value"])
            out[name][pname] = {
                "value": value,
                "std": std,
                "ci95_upper": abs(value) + UPPER_Z * std,
            }
    return out


CONFOUND_SHARE = 0.9
"""Share of a run-order drift (what the nominal model leaves of it) that an accepted effect
takes, above which the report says the two cannot be told apart on these runs."""


def _left_of(a: np.ndarray, c: np.ndarray) -> np.ndarray:
    """What the columns `a` leave of the column `c` (least squares, columns scaled to unit
    norm: a model's columns lie orders of magnitude apart)."""
    if a.shape[1] == 0:
        return c
    norm = np.linalg.norm(a, axis=0)
    a_n = a[:, norm > 0] / norm[norm > 0]
    coef, *_ = np.linalg.lstsq(a_n, c, rcond=None)
    return c - a_n @ coef


def run_order_confound(fit, column, names) -> dict:
    """For each effect of `names` in `fit`'s model, the share of a bias drifting linearly
    with run order (`column`: that drift's whitened column on `fit`'s rows, runs in id
    order, i.e. session time) that the effect takes of what the rest of the model leaves of
    it: 1 − ‖(I − P)c‖² / ‖(I − P₋)c‖² (P the model's projector, P₋ without the effect's
    columns). Near 1: the runs cannot tell the effect from such a drift (a dwell grid run
    temperature by temperature reads a session drift of 0.3 °/h as a bias law 10σ off);
    `{effect: share}`, only for effects with columns."""
    c = np.asarray(column, float)
    j = np.asarray(fit.j, float)
    labels = regular_parameters(fit.model)
    if j.ndim != 2 or j.shape[0] != c.size or j.shape[1] != len(labels):
        return {}
    left = _left_of(j, c)
    out = {}
    for name in names:
        mine = np.asarray([n == name for n, _ in labels])
        if not mine.any():
            continue
        rest = _left_of(j[:, ~mine], c)
        total = float(rest @ rest)
        out[name] = 1.0 - float(left @ left) / total if total > 0 else 0.0
    return out
