"""The shared interface of the two data shapes the search works on (issue 19, "one typed
core"): an immutable [`Fit`][hrgjax.discovery.problem.Fit] and
[`AbstractProblem`][hrgjax.discovery.problem.AbstractProblem], implemented by the dwell-grid
regression ([`DwellProblem`][hrgjax.discovery.dwell.DwellProblem]) and by the continuous
records, alone or with a mixed log's dwell windows
([`ContinuousProblem`][hrgjax.discovery.continuous.ContinuousProblem]).
[`discover`][hrgjax.discovery.discover] only talks to this interface: it picks the
implementation by the data's shape and builds it with
[`from_data`][hrgjax.discovery.problem.AbstractProblem.from_data]; everything after that
(fits, screening, the gap, the leftover shapes, the report's pieces) is a method here.
"""

from __future__ import annotations

import abc
import dataclasses

import numpy as np

from ..data import MeasuredData
from ..pattern_noise import STILL_RATE_DPS, TEMPERATURE_TOLERANCE_C
from .effects import CATALOGUE, NOMINAL


@dataclasses.dataclass(frozen=True)
class Fit:
    """One fitted model (immutable).

    - `model`: the effect names fitted; `parameters`: `{effect: {param: {"value", "std"}}}`
      in model units (rad/s of pattern rate, …).
    - `r`, `j`: the whitened training residual (N,) and Jacobian (N, p) — what the score
      tests and the leftover shapes read.
    - `chi2` = r·r; `heldout_chi2`: the whitened χ² of the held-out runs; `gap`: the
      held-out gap [°/h] (DESIGN.md).
    - `resid`: dwell grids, every window's rate residual [rad/s] (None otherwise);
      `z`: continuous records, the scaled parameter vector (None otherwise).
    """

    model: tuple[str, ...]
    parameters: dict
    r: np.ndarray = dataclasses.field(repr=False)
    j: np.ndarray = dataclasses.field(repr=False)
    chi2: float
    heldout_chi2: float
    gap: float
    resid: np.ndarray | None = dataclasses.field(default=None, repr=False)
    z: np.ndarray | None = dataclasses.field(default=None, repr=False)


class AbstractProblem(abc.ABC):
    """What [`discover`][hrgjax.discovery.discover] needs of a data shape: its candidates,
    fits of a model, the screening of candidates against a fit, the gap's noise floor, the
    leftover shapes, and the report's pieces. `widens`: whether an accepted effect widens the
    held-out gap (dwell grids, whose held-out runs are as quiet as the training ones)."""

    descent: float = 1.0
    """The sign that turns `lstsq(fit.j, fit.r)` into a parameter step: +1 where a fit's `j`
    is the model's derivative (dwell grids: r = y − Jβ), −1 where it is the residual's
    (continuous records)."""
    k_e: float

    @classmethod
    @abc.abstractmethod
    def from_data(
        cls, data: MeasuredData, held, *, nominal, catalogue, k_e: float, window_s: float | None,
        noise, block_s: float,
    ) -> AbstractProblem:  # fmt: skip
        """The problem of `data` with the runs `held` held out.

        **Arguments:** `nominal` (effect names of the starting model), `catalogue` (the
        candidates, or None for every effect the data can carry), `k_e` (nominal angular
        gain), `window_s` (window length of the dwell runs [s]; None: a continuous problem
        simulates every run, a mixed log's dwell runs included), `noise` (a known
        [`hrgjax.Noise`][] for continuous records, or None: estimated from the data),
        `block_s` (block length of the continuous increments [s])."""

    @abc.abstractmethod
    def candidates(self, nominal) -> list[str]:
        """Catalogue effects these data can reveal, beyond `nominal`."""

    @abc.abstractmethod
    def fit(self, model) -> Fit:
        """Fit the effects `model` (names) on the training runs."""

    @abc.abstractmethod
    def floor(self) -> float:
        """What noise alone gives the held-out gap [°/h]."""

    @abc.abstractmethod
    def screen(self, fit: Fit, cands, model) -> list[dict]:
        """Score test (and refit) of every candidate against `fit`, best first: rows with
        `effect`, `score`, `p_value`, `delta_bic`, `aliasing`, `heldout_gain`, `gap_after`,
        `params`, `refit` (a `Fit` or None) and `_columns` (the candidate's whitened
        columns, when called)."""

    def after_accept(self, fit: Fit) -> tuple[AbstractProblem, Fit]:
        """The problem and the fit to go on from once `fit`'s last effect is accepted
        (default: these; the continuous records re-estimate their run-to-run bias at the new
        model and return a new problem — a problem never changes once built)."""
        return self, fit

    def baseline(self, model, base: Fit) -> Fit:
        """The model `model` (the nominal one, whose fit on the problem that `discover`
        started from is `base`) fitted under this problem's noise model: the fit the held-out
        gap before is read from, so that the gaps before and after are read under one noise
        model (default: `base`; the continuous records refit it where σ_b was re-estimated)."""
        return base

    def noise_spread(self, fit: Fit) -> tuple[np.ndarray, dict] | None:
        """The uncertainty of the noise model's estimated parts in `fit`'s parameters, for
        [`honest`][hrgjax.discovery.trust.honest]: `(a factor on each regular parameter's
        variance, info with "basis" in words)`, or None (default: the dwell grids' noise
        enters through each class's level, read from the residual there). Continuous records:
        the run-to-run bias σ_b, from a few run means
        ([`run_bias.spread`][hrgjax.discovery.run_bias.spread])."""
        return None

    def run_order_column(self) -> np.ndarray | None:
        """The whitened column, on a fit's training rows, of a bias drifting linearly with
        run order (session time, runs in id order), for
        `trust.run_order_confound`; None where it
        does not apply (default; continuous records: each run's own switch-on bias takes
        any drift from run to run)."""
        return None

    def widens(self, gap: float, gap_after: float) -> bool:
        """Whether an effect that moves the held-out gap from `gap` to `gap_after` [°/h]
        widens it, which refuses the effect (default: never)."""
        return False

    @abc.abstractmethod
    def structure_left(self, fit: Fit, floor: float | None = None) -> bool:
        """Whether `fit` leaves significant structure in the held-out runs."""

    def consistency(self, fit: Fit, name: str) -> dict | None:
        """Per-run agreement of effect `name` in `fit` (None where it does not apply)."""
        return None

    @abc.abstractmethod
    def residuals(self, fit: Fit) -> dict:
        """What the report's figure draws of `fit`."""

    @property
    @abc.abstractmethod
    def shape_columns(self) -> dict[str, np.ndarray]:
        """Whitened columns of the generic leftover shapes on the training data."""

    @abc.abstractmethod
    def leftover(self, fit: Fit) -> dict | None:
        """The strongest shape `fit` leaves."""

    def row_classes(self) -> np.ndarray | None:
        """An integer class per training row of a fit's whitened residual (rows whose noise
        level is read together: static and moving windows, continuous blocks), or None for
        one class ([`honest`][hrgjax.discovery.trust.honest])."""
        return None

    @abc.abstractmethod
    def noise_report(self) -> dict:
        """The noise model, in report units."""


OPTIONAL = {"amplitude": "amplitude", "quadrature": "quadrature", "accel_z": "accel_z_g"}
"""Covariates read from optional data columns."""


def dwell_runs(data: MeasuredData) -> set[int]:
    """Ids of the runs that hold their temperature and table rate constant (dwell runs):
    the temperature's peak-to-peak within
    [`TEMPERATURE_TOLERANCE_C`][hrgjax.pattern_noise.TEMPERATURE_TOLERANCE_C] and the table
    rate's within [`STILL_RATE_DPS`][hrgjax.units.STILL_RATE_DPS] — a thermometer's
    or a rate table's readback noise leaves a dwell a dwell; a temperature ramp (a degree
    over the run) or a change of table rate does not."""
    out = set()
    for idx in data.run_indices():
        if (
            np.ptp(data["temperature_c"][idx]) <= TEMPERATURE_TOLERANCE_C
            and np.ptp(data["table_rate_dps"][idx]) <= STILL_RATE_DPS
        ):
            out.add(int(data.run[idx[0]]))
    return out


def is_dwell(data: MeasuredData) -> bool:
    """True when every run holds its temperature and table rate constant (a dwell grid)."""
    return len(dwell_runs(data)) == len(np.unique(data.run))


NEEDS_CONTINUOUS = tuple(n for n, e in CATALOGUE.items() if not e.on_dwell)
"""Effects a dwell grid (constant temperature per run, fresh runs) cannot reveal."""


def rates_in(data: MeasuredData) -> set:
    """`{"rates"}` when the data turn the table at two or more distinct non-zero speeds
    (what separates a rate-dependent ripple from a readout ripple), else the empty set."""
    speeds = np.unique(np.round(np.abs(np.asarray(data["table_rate_dps"])), 6))
    return {"rates"} if np.count_nonzero(speeds) >= 2 else set()


def covariates_in(data: MeasuredData) -> set:
    """The covariates `data` carry beyond the wave angle, table rate, temperature and time:
    the [`OPTIONAL`][hrgjax.discovery.problem.OPTIONAL] columns present, and `"rates"`
    ([`rates_in`][hrgjax.discovery.problem.rates_in])."""
    return {k for k, col in OPTIONAL.items() if col in data} | rates_in(data)


def candidates_for(have: set, nominal=NOMINAL, continuous: bool = False) -> list[str]:
    """Catalogue effects the data can reveal, given the covariates they carry (and, for
    dwell grids, without the effects that need changing temperature or fresh switch-ons;
    `"rates"` in `have`: the table turns at two or more speeds)."""
    out = []
    for name, effect in CATALOGUE.items():
        if name in nominal or (name in NEEDS_CONTINUOUS and not continuous):
            continue
        derived = {"theta", "rate", "temperature"}
        if continuous:  # read off the temperature and time columns of the record
            derived |= {"temperature_rate", "temperature_lagged", "t_run"}
        needs = set(effect.needs) - derived
        if needs <= have:
            out.append(name)
    return out


STATIC_CONDITIONING = 0.25
r"""The share of the plan's conditioning of the statics' wave-angle design the training
statics must keep (`held_out_runs`): the smallest eigenvalue of their per-run mean
$\langle a a^\top\rangle$, $a = [1, \cos 2\theta, \sin 2\theta]$, within the span the
whole plan's statics resolve, at least this times the whole plan's."""


def _static_design(angles_deg) -> np.ndarray:
    r"""Rows $[1, \cos 2\theta, \sin 2\theta]$ of static runs' start wave angles [° el.]:
    what the damping's bias and its cos 2θ, sin 2θ are read through at rest."""
    two = 2.0 * np.deg2rad(np.asarray(angles_deg, float))
    return np.stack([np.ones_like(two), np.cos(two), np.sin(two)], axis=-1).reshape(-1, 3)


def _conditioned(design: np.ndarray, train: np.ndarray) -> bool:
    """Whether the training rows of `design` keep `STATIC_CONDITIONING` of the whole
    design's conditioning (per-run mean Gram, smallest eigenvalue within the whole's span)."""
    if not len(design):
        return True
    lam, vec = np.linalg.eigh(design.T @ design / len(design))
    span = vec[:, lam > 1e-9 * lam.max()]
    rows = design[train] @ span
    if not len(rows):
        return False
    kept = np.linalg.eigvalsh(rows.T @ rows / len(rows)).min()
    return bool(kept >= STATIC_CONDITIONING * lam[lam > 1e-9 * lam.max()].min())


def held_out_runs(data: MeasuredData, every: int) -> np.ndarray:
    r"""The runs held out [run ids, sorted]: every `every`-th run (sorted ids), with the
    dwell runs' held-out ones swapped where they would leave the training runs short of a
    condition the damping and the rate laws are read through:

    - the training statics must still fix the damping's $[1, \cos 2\theta, \sin 2\theta]$
      at rest (`STATIC_CONDITIONING` of the plan's conditioning, neighbouring angles
      counting: no bins);
    - every table rate that has a training run in the stride keeps one.

    A held-out dwell run that breaks a rule its return to training would keep is swapped for
    the nearest dwell run after it (else before it) whose holding breaks nothing new; where
    there is none it stays held — the held-out set is never smaller than the stride's (a
    run alone at its rate, or four statics at four angles, is held out as before).
    A stride that is a divisor of the plan's period otherwise holds out one condition
    everywhere: every third run of a plan of statics and rotations at three wave angles is
    every θ = 0 static, and with the dwell session's own offset profiled out the statics at
    ±60° (cos 2θ alike) no longer fix the damping's cos 2θ, which then took the rotations'
    readout ripple (−186 °/h; the readout mismatch, ΔBIC 2.9·10⁶ with the θ = 0 statics in
    training, fell to 1.2·10⁴). Temperature levels and ramp directions may be held out
    whole: the laws in T are what they test.

    **Raises:** `ValueError` when `every` < 2 or the stride holds nothing out (fewer than
    `every` runs)."""
    runs = np.unique(data.run)
    if int(every) < 2 or runs.size < int(every):
        raise ValueError(
            f"every must be an integer >= 2 and at most the number of runs ({runs.size}) "
            f"for a run to be held out; got {every}"
        )
    held = set(runs[every - 1 :: every].tolist())
    dwell = dwell_runs(data)
    rate, angle = {}, {}
    for i in data.run_indices():
        r = int(data.run[i[0]])
        if r in dwell:
            rate[r] = round(float(np.median(data["table_rate_dps"][i])), 3)
            if rate[r] == 0.0:
                angle[r] = float(data["wave_angle_deg"][i[0]])
    statics = sorted(angle)
    design = _static_design([angle[r] for r in statics])

    def broken(out) -> set:  # the rules broken when the runs `out` are held
        bad = {("rate", v) for v in set(rate.values()) - {0.0}}
        bad -= {("rate", rate[r]) for r in rate if r not in out}
        train = np.asarray([k for k, r in enumerate(statics) if r not in out], int)
        return bad if _conditioned(design, train) else bad | {"statics"}

    for r in sorted(r for r in held if r in rate):
        base = broken(held - {r})
        if broken(held) <= base:
            continue
        later = sorted(s for s in rate if s > r) + sorted((s for s in rate if s < r), reverse=True)
        swap = [s for s in later if s not in held and broken((held - {r}) | {s}) <= base]
        if swap:  # a dwell run for a dwell run: the records' split stays as it was
            held = (held - {r}) | {swap[0]}
    return np.asarray(sorted(held), dtype=runs.dtype)
