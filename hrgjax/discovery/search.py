r"""`discover`: find, name, add, shrink — on dwell-grid data (DISCOVERY.md §2.4, first tier).

Steps, all on the windows of [`reduce`][hrgjax.calibration.reduce]:

1. **Split** by run: every `holdout_every`-th run is held out (never split within a run),
   but no static wave angle or table rate of the dwell runs leaves the training runs
   altogether ([`held_out_runs`][hrgjax.discovery.problem.held_out_runs]).
2. **Noise model first**, before any drift model: one
   [`NoiseModel`][hrgjax.pattern_noise.NoiseModel] (white angle noise, angle random walk,
   a Gauss–Markov rate where the data can show it) estimated from every still stretch of the
   log ([`noise_model`][hrgjax.discovery.noise.noise_model]) gives every window's standard
   error and every continuous record's whitening, so the tests are in whitened units.
3. **Baseline**: weighted least squares of the nominal model (`bias`, `angular_gain`,
   `damping_anisotropy`).
4. **Screen** every other catalogue effect the data can carry with the exact score test
   ([`score`][hrgjax.discovery.stats.score]); p-values from χ²_q.
5. **Refit** the best candidates with the model; **accept** the best one only if its p-value
   passes Bonferroni at `alpha`, its ΔBIC exceeds `min_delta_bic`, it is identifiable (aliasing
   index < `max_aliasing`: what is left of its signature once the model has absorbed what
   it can is still more than 0.1 %, and the score test says that rest is significant), it
   lowers the held-out whitened χ² by more than `min_heldout_gain`, it does not widen the
   held-out gap beyond what the noise gives (dwell grids only: `DwellProblem.widens`), it still passes Bonferroni in the fit its reported σ
   comes from (`p_stat`: the leftover shapes fitted beside it, the noise level the residual
   shows and, continuous records, σ_b's own uncertainty —
   [`statistical_p_value`][hrgjax.discovery.trust.statistical_p_value]; tested last), and
   (continuous records) it repeats run by run: its
   parameters refitted on each training run alone point the same way as the pooled fit in
   at least `min_agreement` of the runs whose own data resolve it — or, when fewer than two
   do, of groups of consecutive runs pooled until each resolves it (the χ² of their scatter
   is reported in `consistency`). Each screening row names the first rule it fails
   (`refused_by`, `REFUSALS`). Repeat for a second or third effect.
6. **Report** the DESIGN.md keys: the gap is the RMS over held-out runs of the run-mean
   equivalent-input-rate residual [°/h]; the noise floor is what noise alone gives it. The
   gaps before (nominal model) and after are read under one noise model, the final one
   (`AbstractProblem.baseline`: continuous records re-estimate σ_b as effects are accepted).
   Verdicts: `found`; `ambiguous` (a rival passes the same rule with nearly the same ΔBIC);
   `none`; `unexplained` (nothing accepted, yet the held-out residual is above the noise, or a
   leftover shape is significant at the noise level left once it is fitted: `trust.honest`).

Continuous records (some run changes its temperature or rate) go through the same steps
with the model simulated ([`continuous`][hrgjax.discovery.continuous.ContinuousProblem]).
Every step talks to the data through
[`AbstractProblem`][hrgjax.discovery.problem.AbstractProblem] alone: the shape picks the
implementation (`PROBLEMS`), which builds itself from the data.
"""

from __future__ import annotations

import math

import numpy as np

from .._checks import describe, is_concrete, is_finite_real, numeric_problem, whole_number
from ..calibration.reduce import K_E_NOMINAL, WINDOW_S
from ..data import MeasuredData
from ..noise import Noise
from ..units import K_E_WANTED
from . import leftover, stats, trust
from .continuous import BLOCK_S, ContinuousProblem
from .dwell import DwellProblem, output_gain
from .effects import CATALOGUE, NOMINAL
from .noise import NoiseModel as NoiseModel
from .noise import noise_model as noise_model
from .problem import NEEDS_CONTINUOUS as NEEDS_CONTINUOUS
from .problem import OPTIONAL as OPTIONAL
from .problem import AbstractProblem, dwell_runs, held_out_runs
from .problem import candidates_for as candidates_for
from .problem import rates_in as rates_in
from .result import Discovery

METRIC = "rms_run_mean_rate_residual_dph"


_RULE = {  # discover's acceptance-rule arguments: (the range in words, the test)
    "alpha": ("a significance level in (0, 1)", lambda v: 0.0 < v < 1.0),
    "min_delta_bic": ("a number >= 0 (a BIC drop)", lambda v: v >= 0.0),
    "min_heldout_gain": ("a number >= 0 (a held-out χ² drop)", lambda v: v >= 0.0),
    "max_aliasing": ("a share in (0, 1]", lambda v: 0.0 < v <= 1.0),
    "ambiguity_bic": ("a number >= 0 (a ΔBIC margin)", lambda v: v >= 0.0),
    "min_agreement": ("a share in [0, 1]", lambda v: 0.0 <= v <= 1.0),
}


def _check_rule(*, max_effects, **rule) -> None:
    """Refuse an acceptance-rule argument of `discover` that is not a finite number in its
    range (`_RULE`), or a `max_effects` that is not an integer >= 1, in one line naming it
    (alpha = 2 or NaN, max_effects = 0, a negative ΔBIC bar: a silent verdict)."""
    for name, value in rule.items():
        form, ok = _RULE[name]
        if not is_finite_real(value):
            kind = TypeError if numeric_problem(value) else ValueError
            raise kind(f"{name} must be {form}; got {describe(value)}")
        if not ok(float(value)):
            raise ValueError(f"{name} must be {form}; got {float(value):g}")
    whole_number("max_effects", max_effects, "an integer >= 1", minimum=1)


def _names(name: str, names) -> None:
    """Refuse a single string (or a non-iterable) where `name` takes effect names: a string
    was read letter by letter ("unknown effect(s) ['a', 'n', …]")."""
    if isinstance(names, str | bytes) or not hasattr(names, "__iter__"):
        raise TypeError(f"{name} must be a list of effect names; got {describe(names)}")


def _check_arguments(data, nominal, catalogue, holdout_every, block_s) -> int | None:
    """`discover`'s argument types: `data` a `MeasuredData`, `nominal` and `catalogue` lists
    of names, `holdout_every` a whole number (returned as an int) or None, `block_s` a
    finite number > 0."""
    if not isinstance(data, MeasuredData):
        raise TypeError(f"data must be an hrgjax.MeasuredData; got {type(data).__name__}")
    _names("nominal", nominal)
    if catalogue is not None:
        _names("catalogue", catalogue)
    if not (is_finite_real(block_s) and block_s > 0):
        kind = TypeError if numeric_problem(block_s) else ValueError
        raise kind(f"block_s must be a positive number of seconds; got {describe(block_s)}")
    if holdout_every is None:
        return None
    return whole_number("holdout_every", holdout_every, "an integer >= 2 (runs) or None")


def _check_informative(data: MeasuredData) -> None:
    """Refuse a log with nothing to fit: a wave angle that never moves within any run (a
    stuck or constant column — a live gyro's angle moves by its noise at least), or no table
    rate and no temperature change at all (nothing separates the effects). Without this the
    fit divides by a zero noise level and LAPACK prints its own lines before the error."""
    wave, run = np.asarray(data["wave_angle_deg"], float), np.asarray(data.run)
    order = np.argsort(run, kind="stable")
    w, r = wave[order], run[order]
    same = r[1:] == r[:-1]
    if not np.any(same & (np.diff(w) != 0.0)):
        raise ValueError(
            f"column 'wave_angle_deg' never changes within a run (constant {wave[0]:g}° "
            "throughout): a gyro's wave angle moves by its drift and noise at least; check "
            "the column (a stuck or copied value)"
        )


def _check_gain_and_bias(data: MeasuredData, nominal) -> None:
    """Refuse a log whose every sample turns the table at one and the same rate (no static
    run, no second rate) while `nominal` fits a `bias`: k_e·Ω and the bias then shift every
    window's rate alike, and no fit can tell them apart (the fit once reported k_e = 0 ±
    8·10⁻⁷ beside a bias of 18 000 ± 0.67 °/h)."""
    if "bias" not in nominal:
        return
    rates = np.unique(np.round(np.asarray(data["table_rate_dps"], float), 6))
    if rates.size == 1 and rates[0] != 0.0:
        raise ValueError(
            f"every run turns the table at the one rate {rates[0]:g} °/s and none is static: "
            "the angular gain k_e and the bias cannot be told apart (each shifts every "
            "window's rate alike); add static runs or runs at a second table rate"
        )


def discover(
    data: MeasuredData,
    *,
    nominal=NOMINAL,
    catalogue=None,
    k_e: float = K_E_NOMINAL,
    window_s: float = WINDOW_S,
    holdout_every: int | None = None,
    alpha: float = 0.01,
    min_delta_bic: float = 10.0,
    min_heldout_gain: float = 10.0,
    max_effects: int = 6,
    max_aliasing: float = 0.999,
    ambiguity_bic: float = 6.0,
    min_agreement: float = 0.75,
    shape: str = "auto",
    noise: Noise | None = None,
    block_s: float = BLOCK_S,
) -> Discovery:
    """Name the effect missing from `nominal` in `data` (module docstring).

    **Arguments:**

    - `data`: [`hrgjax.MeasuredData`][]: dwell runs (static and/or constant rate, constant
      temperature) or continuous records (ramps, rate profiles).
    - `nominal`: effect names of the starting model (default `base`).
    - `catalogue`: candidate names (default: every effect the data can carry).
    - `k_e`: nominal angular gain; `window_s`: moving-run window of dwell data [s].
    - `holdout_every`: hold out every n-th run (default 4 for dwell grids, 3 for continuous
      records); `alpha`, `min_delta_bic`, `min_heldout_gain` (drop of the held-out whitened
      χ²), `max_effects`, `max_aliasing` (the largest share of a candidate's signature the
      fitted model may already absorb): the acceptance rule. `ambiguity_bic`: a first-round
      rival that passes the same rule with a ΔBIC within this (or within `TIE_FRACTION`
      of the winner's ΔBIC, where that is more) of the winner's makes the verdict
      `ambiguous` (the winner stays `missing_effect`; rivals in `ambiguous_with`, the
      separating experiments in `discriminate`). Of candidates whose ΔBIC ties within
      `TIE_FRACTION`, the one with the fewest parameters is accepted. `min_agreement`: continuous records
      only, the smallest share of the training runs that resolve an effect (put its pooled
      value at ≥ 1σ) in which its parameters, refitted on that run alone, point the same way
      as the pooled fit; when fewer than two runs resolve it, of groups of consecutive runs
      pooled until each does (`records.repeats`).
    - `shape`: `"auto"` (dwell when every run holds its rate and temperature, mixed when
      some do), `"dwell"`, `"continuous"` or `"mixed"` (the dwell runs as the dwell search's
      window rows, jointly with the other runs simulated as continuous records).
    - `noise`: a known [`hrgjax.Noise`][] (default: estimated from the data's zero-rate
      stretches — a dwell grid with none, from its rotation runs' angles, said in
      `noise["source"]` — and, continuous records, the run-to-run bias from the baseline
      fit).
    - `block_s`: block length of the continuous increments [s].

    **Returns:** a [`Discovery`][hrgjax.discovery.result.Discovery]: the verdict, the
    accepted effects with their parameters in user units (`.parameters`) and model units
    (`.fit_parameters`), the screening table, the gaps and the noise floor, `consistency`
    (continuous records: per-run refits of each accepted effect and their χ² p-value),
    `noise`, `split`, `shape`; `.to_json()` (DESIGN.md's keys first), `.equations()`,
    `.plot(path)`.

    **Raises:** `ValueError` for unknown effect names, a bad `shape`, too few runs to hold
    any out, or every run at one table rate with no static run (k_e and the bias inseparable); `RuntimeError` when a continuous fit does not converge.
    """
    holdout_every = _check_arguments(data, nominal, catalogue, holdout_every, block_s)
    if numeric_problem(k_e) is not None:  # its value is checked where it is used
        raise TypeError(f"k_e must be {K_E_WANTED}; got {describe(k_e)}")
    if np.ndim(k_e) == 0 and is_concrete(k_e):  # np.float64(0.554) and 0.554: one program
        k_e = float(k_e)
    _check_rule(alpha=alpha, min_delta_bic=min_delta_bic, min_heldout_gain=min_heldout_gain,
                max_effects=max_effects, max_aliasing=max_aliasing, ambiguity_bic=ambiguity_bic,
                min_agreement=min_agreement)  # fmt: skip
    unknown = [n for n in list(nominal) + list(catalogue or []) if n not in CATALOGUE]
    if unknown:
        raise ValueError(f"unknown effect(s) {unknown}; catalogue: {sorted(CATALOGUE)}")
    if "angular_gain" not in nominal:
        raise ValueError("the nominal model must contain 'angular_gain'")
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {SHAPES}; got {shape!r}")
    if noise is not None and not isinstance(noise, Noise):
        raise TypeError(f"noise must be an hrgjax.Noise or None; got {type(noise).__name__}")
    _check_informative(data)
    _check_gain_and_bias(data, nominal)
    if shape == "auto":
        n_dwell = len(dwell_runs(data))
        n_runs = np.unique(data.run).size
        shape = "dwell" if n_dwell == n_runs else "mixed" if n_dwell else "continuous"
    if holdout_every is None:
        holdout_every = 4 if shape == "dwell" else 3
    runs = np.unique(data.run)
    need = 2 * holdout_every if shape == "dwell" else max(holdout_every, 2)
    if holdout_every < 2 or runs.size < need:
        raise ValueError(
            f"discover needs at least {need} runs to hold every {holdout_every}-th out "
            f"(holdout_every >= 2); got {runs.size} runs"
        )
    held = held_out_runs(data, holdout_every)  # no dwell condition left out altogether
    problem: AbstractProblem = PROBLEMS[shape].from_data(
        data, held, nominal=nominal, catalogue=catalogue, k_e=k_e, noise=noise,
        block_s=block_s, window_s=None if shape == "continuous" else window_s,
    )  # fmt: skip
    cands = list(catalogue) if catalogue is not None else problem.candidates(nominal)
    cands = [n for n in cands if n not in nominal]

    model = list(nominal)
    base = problem.fit(model)
    accepted, ranking, current = [], [], base
    n_cands = len(cands)

    def consistent(r):
        """Per-run agreement of the candidate's refit (computed once, only when needed).
        Passes where the check cannot be made — dwell grids (None), or no split of the
        training runs into two parts that each resolve the effect (`agreement` None, the
        consistency's `reason` says why): its evidence then lies in one part of the runs or in
        a mixed log's dwell windows, and repeating is left to the held-out rule (it must lower
        the held-out χ² of other runs by `min_heldout_gain`), which comes first."""
        if "consistency" not in r:
            r["consistency"] = problem.consistency(r["refit"], r["effect"])
        c = r["consistency"]
        r["agreement"] = None if c is None else c["agreement"]
        r["agreement_note"] = None if c is None else c.get("reason")
        return r["agreement"] is None or r["agreement"] >= min_agreement

    def significant(r):
        """Still significant at the noise level the residual shows and with σ_b's own
        uncertainty (`trust.statistical_p_value`), computed once, only when needed: the
        score test reads the noise model as given."""
        if "p_stat" not in r:
            fit = r["refit"]
            r["p_stat"] = trust.statistical_p_value(
                fit, r["effect"], problem.shape_columns, problem.row_classes(),
                spread=problem.noise_spread(fit), descent=problem.descent,
            )  # fmt: skip
        return r["p_stat"] is None or r["p_stat"] < alpha / max(n_cands, 1)

    def refusal(r, fit, last=None):
        """The first rule of the acceptance rule that `r` fails against `fit` (its
        `REFUSALS` name), or None; kept in the row as `refused_by`. `last`: the rules up to
        it only (the rest may pass or not)."""
        checks = (
            ("p_value", lambda: r["p_value"] < alpha / max(n_cands, 1)),
            ("delta_bic", lambda: r["delta_bic"] > min_delta_bic),
            ("aliasing", lambda: r["aliasing"] < max_aliasing),
            ("refit", lambda: r.get("refit") is not None),
            ("heldout_gain", lambda: r["heldout_gain"] > min_heldout_gain),
            ("gap_after", lambda: not problem.widens(fit.gap, r["gap_after"])),
            ("consistency", lambda: consistent(r)),
            ("outshone_by", lambda: not outshone(r)),
            ("p_stat", lambda: significant(r)),  # the costliest: last
        )
        if last is not None:
            checks = checks[: [n for n, _ in checks].index(last) + 1]
        r["refused_by"] = next((name for name, ok in checks if not ok()), None)
        return r["refused_by"]

    def passes(r, fit):
        return refusal(r, fit) is None

    def best_passing(rows, fit):
        """`simplest_of_the_tied` of the rows that pass every rule, `rows` passing all
        but `p_stat`: that test is made best ΔBIC first, and only down to the tie margin of
        the best row that passes it (the rest could not be chosen; their `p_stat` stays
        unset) — the same choice as testing every row (review of 24bc489: testing all of
        them made the default gyro's seed plan 6× slower)."""
        passed, top = [], None
        for r in sorted(rows, key=lambda r: -r["delta_bic"]):
            if top is not None and not _within_tie(top, r["delta_bic"]):
                break
            if passes(r, fit):
                passed.append(r)
                top = r["delta_bic"] if top is None else top
        return simplest_of_the_tied(passed) if passed else None

    def outshone(r):
        """The uncovered shape the candidate only imitates (computed when needed)."""
        if "outshone_by" not in r:
            r["outshone_by"] = r["_check"](r) if "_columns" in r else None
        return r["outshone_by"] is not None

    rows: list[dict] = []
    for _ in range(max_effects):
        rows = problem.screen(current, cands, model)
        check = Outshone(problem, current, model + cands, min_delta_bic, not accepted)
        for r in rows:
            r["_check"] = check
        if not ranking:
            ranking = rows
        ok = [r for r in rows if refusal(r, current, last="outshone_by") is None]
        best = best_passing(ok, current)
        if best is None:
            break
        accepted.append(best["effect"])
        model.append(best["effect"])
        cands.remove(best["effect"])
        problem, current = problem.after_accept(best["refit"])
    floor = problem.floor()  # σ_b may have been re-estimated at the final model
    # the gap before under that noise model too: at the nominal fit REML counts the misfit a
    # missing effect leaves inside the runs as switch-on bias (σ_b 1.7 °/h for 0.2), the run
    # means float, and the nominal parameters take up the misfit (`gap_before` 5.1 °/h)
    try:
        before = problem.baseline(nominal, base) if accepted else base
    except RuntimeError:  # that refit did not converge: the nominal fit as it was
        before = base
    parameters, uncertainty = trust.honest(current, problem.shape_columns, problem.row_classes(),
                                           spread=problem.noise_spread(current))  # fmt: skip
    # where nothing is accepted (a null report's main content; ≈ 0.8 s on a 5 × 9 grid, so
    # not for found effects): the last round's refits, the model with each candidate added
    limits = None if accepted else trust.upper_limits(
        {r["effect"]: r.get("refit") for r in rows}, problem.shape_columns,
        problem.row_classes(), problem.noise_spread)  # fmt: skip
    # structure left: the held-out gap above the floor, or a leftover shape the residuals
    # needed (trust.honest: judged at the noise level left once it is fitted)
    left = problem.structure_left(current, floor) or bool(uncertainty["structure_left"])
    if accepted:
        verdict = "found"
    elif left:  # nothing accepted: the current model is the base
        verdict = "unexplained"
    else:
        verdict = "none"
    # an accepted effect the runs cannot tell from a drift through the session (a grid run
    # temperature by temperature: a bias law); `trust.run_order_confound`
    column = problem.run_order_column() if accepted else None
    confound = {} if column is None else trust.run_order_confound(current, column, accepted)
    ambiguous = []
    if accepted:
        # first-round rivals that pass the same rule and whose evidence is not decisively
        # weaker (ΔBIC within `ambiguity_bic`, "strong" on the Kass–Raftery scale)
        win = next(r for r in ranking if r["effect"] == accepted[0])
        ambiguous = [
            r["effect"]
            for r in ranking
            if r is not win
            and r["refit"] is not None
            and win["delta_bic"] - r["delta_bic"] < tolerance(ambiguity_bic, win["delta_bic"])
            and passes(r, base)  # after the margin: `p_stat` only where it can matter
        ]
        if ambiguous:
            verdict = "ambiguous"
    return Discovery(
        verdict=verdict,
        missing_effect=accepted[0] if accepted else None,
        accepted=tuple(accepted),
        ambiguous_with=tuple(ambiguous),
        discriminate={n: CATALOGUE[n].discriminate for n in accepted + ambiguous},
        gap_before=before.gap,
        gap_after=current.gap,
        noise_floor=floor,
        metric=METRIC,
        structure_left=bool(left),
        fit_parameters=parameters,
        k_e=output_gain(parameters, k_e),
        ranking=tuple(
            {"effect": r["effect"], "score": r["score"], "params": r["params"]} for r in ranking
        ),
        screening=tuple(
            {k: r.get(k) for k in SCREEN_KEYS}
            | {
                "round": 1,  # every row is the first round's: each against the nominal model
                "accepted_in_round": accepted.index(r["effect"]) + 1
                if r["effect"] in accepted
                else None,
            }
            for r in ranking
        ),
        consistency={n: problem.consistency(current, n) for n in accepted},
        noise=problem.noise_report(),
        split={"train_runs": int(runs.size - held.size), "heldout_runs": int(held.size)},
        shape=shape,
        residuals={"before": problem.residuals(before), "after": problem.residuals(current)},
        leftover=problem.leftover(current),
        uncertainty=uncertainty,
        upper_limits=limits,
        run_order_confound={n: v for n, v in confound.items() if v > trust.CONFOUND_SHARE},
    )


SHAPES = ("auto", "dwell", "continuous", "mixed")
PROBLEMS: dict[str, type[AbstractProblem]] = {
    "dwell": DwellProblem, "continuous": ContinuousProblem, "mixed": ContinuousProblem,
}  # fmt: skip
"""The problem each data shape is (a mixed log: the continuous records with the dwell runs
as windows)."""
SCREEN_KEYS = (
    "effect", "score", "p_value", "delta_bic", "aliasing", "heldout_gain", "gap_after",
    "p_stat", "outshone_by", "agreement", "agreement_note", "refused_by",
)  # fmt: skip
REFUSALS = {
    "p_value": "its score p-value misses Bonferroni at `alpha`",
    "delta_bic": "its ΔBIC is not above `min_delta_bic`",
    "aliasing": "the fitted model absorbs its signature (`max_aliasing`)",
    "refit": "not refitted (outside the short list of the best scores, or its fit failed)",
    "heldout_gain": "it lowers the held-out χ² by no more than `min_heldout_gain`",
    "gap_after": "it widens the held-out gap beyond what the noise gives (dwell grids)",
    "p_stat": "its p-value in the fit its reported σ comes from (`p_stat`: the leftover "
    "shapes fitted beside it, the noise level the residual shows, continuous records' σ_b "
    "uncertainty) misses Bonferroni at `alpha` (tested last, and only on rows that could "
    "be chosen: best ΔBIC first, down to the tie margin)",
    "consistency": "its per-run refits (or, when fewer than two runs resolve it, groups of "
    "consecutive runs pooled until each does) agree with the pooled one in under "
    "`min_agreement`",
    "outshone_by": "an uncovered generic shape explains the residual far better",
}
"""A screening row's `refused_by`: the first rule of the acceptance rule it fails against the
nominal model (None: it passes them all — accepted, or beaten by a better or simpler rival —
or, with `p_stat` None, all but `p_stat`, which is tested only down to the tie margin of the
best row that passes it: a row below was beaten before it could matter);
`agreement` is its per-run agreement share where that was computed (None: not computed, or
the check could not be made — `Discovery.consistency` gives the `reason`)."""


TIE_FRACTION = 1e-3
"""Evidence (ΔBIC, a score less its BIC penalty) that differs by less than this share of
itself cannot tell two descriptions apart: the catalogue's laws are linearised forms (a
readout gain mismatch ε is exact to first order, its ε² part ≈ 10⁻⁴ of a 1 % mismatch's
signature), so a large effect's evidence carries their approximations too. At 10⁴ ppm a
readout mismatch's ΔBIC of 2.8·10⁸ trailed `loop_ripple`'s by 1.3·10⁴ (5·10⁻⁵ of it),
and an absolute margin of 10 named the wrong one."""


def tolerance(margin: float, evidence: float) -> float:
    """The margin two descriptions' evidence must differ by to be told apart: `margin`, or
    `TIE_FRACTION` of the evidence where that is larger."""
    return max(margin, TIE_FRACTION * abs(evidence))


def _size(name: str) -> int:
    """Parameters of a catalogue effect, the scanned (nonregular) ones included."""
    return len(CATALOGUE[name].params)


def _within_tie(top: float, evidence: float) -> bool:
    """Whether a row of ΔBIC `evidence` ties with the best, `top`, in
    [`simplest_of_the_tied`][hrgjax.discovery.search.simplest_of_the_tied]."""
    if math.isfinite(top):
        return top - evidence <= tolerance(0.0, top)
    return evidence == top  # infinite evidence ties only with itself


def simplest_of_the_tied(rows: list[dict]) -> dict:
    """The candidate to accept among `rows` (best score first) that pass the rule: of those
    whose ΔBIC is within [`tolerance`][hrgjax.discovery.search.tolerance] of the best,
    the one with the fewest parameters (a scanned time constant counts), then the best
    ΔBIC — parsimony where the evidence ties; the rest are reported as ambiguous rivals."""
    top = max(r["delta_bic"] for r in rows)
    tied = [r for r in rows if _within_tie(top, r["delta_bic"])]
    tied = tied or [max(rows, key=lambda r: r["delta_bic"])]
    return min(tied, key=lambda r: (_size(r["effect"]), -r["delta_bic"]))


DOMINANT = 10.0
"""A candidate whose evidence (score less its BIC penalty) is under 1/`DOMINANT` of an
uncovered generic shape's is refused (`Outshone`)."""


class Outshone:
    """Whether a candidate only imitates part of something out of the catalogue: generic
    shapes ([`leftover.SHAPES`][hrgjax.discovery.leftover.SHAPES]) that no available effect
    is explain the residual better than the candidate (score test, BIC, by more than
    `margin`, or `TIE_FRACTION` of the candidate's evidence: a named effect wins a
    near-tie with a generic shape), and either — for the first effect named (`first`) — the strongest has
    ≥ `DOMINANT` times its evidence, or, once they are all fitted, the candidate adds no more than `margin` or keeps less than a tenth of
    its score (its score given them); the strongest of them is reported. A
    readout ripple that matches a temperature-dependent drift on the rotation runs but not
    at rest is such a part; a second true effect beside an imperfect first one is not (its
    score survives the shape)."""

    def __init__(self, problem, fit, available, margin, first=False):
        covered = {sh for n in available for sh in CATALOGUE[n].shapes}
        cols = problem.shape_columns
        self.cols = {k: v for k, v in cols.items() if k not in covered}
        spanned = [cols[k] for k in covered if k in cols]
        if spanned:  # a shape the covered ones span on these data is covered too (2θ·Ω²
            # is 2θ·Ω where the table turns at one rate)
            u, sv, _ = np.linalg.svd(np.concatenate(spanned, axis=1), full_matrices=False)
            q = u[:, sv > sv[0] * 1e-10]  # their span (a rank-deficient set adds nothing)
            left = lambda v: np.linalg.norm(v - q @ (q.T @ v)) / max(np.linalg.norm(v), 1e-300)
            self.cols = {k: v for k, v in self.cols.items() if left(v) > 1e-3}
        self.fit, self.margin, self.first = fit, margin, first
        self.log_n = math.log(max(len(fit.r), 2))
        self.scores = leftover.scores(fit.r, fit.j, self.cols)

    def __call__(self, row) -> str | None:
        q_c = sum(p.regular for p in CATALOGUE[row["effect"]].params)
        own = row["score"] - q_c * self.log_n
        stronger = sorted(
            (
                (sc - q * self.log_n, name)
                for name, (sc, q) in self.scores.items()
                if sc - q * self.log_n - own > tolerance(self.margin, own)
            ),
            reverse=True,
        )
        if not stronger:
            return None
        if self.first and stronger[0][0] > DOMINANT * max(own, self.margin):
            # the first effect named is dwarfed: what no candidate names has ≥ 10× its
            # evidence, so it cannot be *the* missing effect, whatever it adds beside that
            # shape (later rounds keep the rule below: there the leftover curvature of an
            # accepted law may well dwarf a true small effect)
            return stronger[0][1]
        # the candidate's score once every stronger uncovered shape is fitted too
        r, j = self.fit.r, self.fit.j
        jj = np.concatenate([j, *(self.cols[name] for _, name in stronger)], axis=1)
        q_j, _ = np.linalg.qr(jj)
        r_s = r - q_j @ (q_j.T @ r)
        s_cond, _, _ = stats.score(r_s, jj, row["_columns"](), q_j)
        # it is a part of them when it adds nothing beyond them, or keeps less than a tenth
        # of its own evidence (what it still adds is then their imperfections: the shapes
        # are generic, the windows' arc averaging and the exact law are not in them)
        part = s_cond - q_c * self.log_n < self.margin or s_cond < 0.1 * row["score"]
        return stronger[0][1] if part else None
