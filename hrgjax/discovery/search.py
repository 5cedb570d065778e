r"""`discover`: find, name, add, shrink — on dwell-grid data (DISCOVERY.md §2.4, first tier).

Steps, all on the windows of [`reduce`][hrgjax.calibration.reduce]:

1. **Split** by run: every `holdout_every`-th run is held out (never split within a run).
2. **Noise model first**, before any drift model: white angle noise and angle random walk
   from the static runs ([`noise_model`][hrgjax.discovery.search.noise_model]) give every
   window's standard error, so the tests are in whitened units.
3. **Baseline**: weighted least squares of the nominal model (`bias`, `angular_gain`,
   `damping_anisotropy`).
4. **Screen** every other catalogue effect the data can carry with the exact score test
   ([`score`][hrgjax.discovery.dwell.score]); p-values from χ²_q.
5. **Refit** the best candidates with the model; **accept** the best one only if its p-value
   passes Bonferroni at `alpha`, its ΔBIC exceeds `min_delta_bic`, it is identifiable (aliasing
   index < `max_aliasing`: what is left of its signature once the model has absorbed what
   it can is still more than 0.1 %, and the score test says that rest is significant), it
   lowers the held-out whitened χ² by more than `min_heldout_gain`, it does not widen the
   held-out gap (dwell grids only), and (continuous records) it repeats run by run: its
   parameters refitted on each training run alone point the same way as the pooled fit in
   at least `min_agreement` of the runs that excite it (the χ² of their scatter is reported
   in `consistency`). Repeat for a second or third effect.
6. **Report** the DESIGN.md keys: the gap is the RMS over held-out runs of the run-mean
   equivalent-input-rate residual [°/h]; the noise floor is what noise alone gives it.
   Verdicts: `found`; `ambiguous` (a rival passes the same rule with nearly the same ΔBIC);
   `none`; `unexplained` (nothing accepted, yet the held-out residual is above the noise).

Continuous records (some run changes its temperature or rate) go through the same steps
with the model simulated by diffrax ([`continuous`][hrgjax.discovery.continuous.ContinuousProblem]).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from .._progress import bar
from ..calibration.reduce import K_E_NOMINAL, WINDOW_S, RateWindows, reduce
from ..data import MeasuredData
from ..noise import Noise
from ..units import DEG, DEG_PER_H, T_REF_C
from . import dwell, leftover
from .continuous import BLOCK_S, ContinuousProblem, Windows, dwell_runs, noise_from_gyro
from .continuous import noise_model as continuous_noise
from .effects import CATALOGUE, NOMINAL, window_gain
from .result import Discovery

METRIC = "rms_run_mean_rate_residual_dph"
OPTIONAL = {"amplitude": "amplitude", "quadrature": "quadrature", "accel_z": "accel_z_g"}
"""Covariates read from optional data columns."""
NEEDS_CONTINUOUS = tuple(n for n, e in CATALOGUE.items() if not e.on_dwell)
"""Effects a dwell grid (constant temperature per run, fresh runs) cannot reveal."""


def _rates_in(data: MeasuredData) -> set:
    """`{"rates"}` when the data turn the table at two or more distinct non-zero speeds
    (what separates a rate-dependent ripple from a readout ripple), else the empty set."""
    speeds = np.unique(np.round(np.abs(np.asarray(data["table_rate_dps"])), 6))
    return {"rates"} if np.count_nonzero(speeds) >= 2 else set()


def _window_extras(data: MeasuredData, w: RateWindows) -> tuple[dict, set]:
    """Per-window means of the optional columns, and which covariates the data carry."""
    extra: dict[str, list] = {"t_run": [], "harmonic_gain": []}
    have = set()
    for key, col in OPTIONAL.items():
        if col in data:
            extra[key] = []
            have.add(key)
    have |= _rates_in(data)
    starts = {int(data.run[idx[0]]): idx for idx in data.run_indices()}
    for run, a, b, tm in zip(w.run, w.start, w.stop, w.t_mid, strict=True):
        idx = starts[int(run)]
        extra["t_run"].append(tm - data["time_s"][idx[0]])
        arc = np.ptp(data["wave_angle_deg"][idx[a:b]]) * DEG if b - a > 1 else 0.0
        extra["harmonic_gain"].append(float(window_gain(arc)))
        for key, col in OPTIONAL.items():
            if key in extra:
                extra[key].append(float(np.mean(data[col][idx[a:b]])))
    return {k: np.asarray(v) for k, v in extra.items()}, have


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


def _gap(resid, w: RateWindows, runs, k_e):
    """RMS over `runs` of the run-mean equivalent-input-rate residual [°/h]."""
    means = [np.mean(resid[w.run == r]) for r in runs]
    return float(np.sqrt(np.mean(np.square(means)))) / k_e / DEG_PER_H


def _floor(sigma, w: RateWindows, runs, k_e):
    var = [np.mean(sigma[w.run == r] ** 2) / np.sum(w.run == r) for r in runs]
    return float(np.sqrt(np.mean(var))) / k_e / DEG_PER_H


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
      rival that passes the same rule with a ΔBIC within this of the winner's makes the
      verdict `ambiguous` (the winner stays `missing_effect`; rivals in `ambiguous_with`,
      the separating experiments in `discriminate`). `min_agreement`: continuous records
      only, the smallest share of the training runs that excite an effect in which its
      parameters, refitted on that run alone, point the same way as the pooled fit.
    - `shape`: `"auto"` (dwell when every run holds its rate and temperature, mixed when
      some do), `"dwell"`, `"continuous"` or `"mixed"` (the dwell runs as the dwell search's
      window rows, jointly with the other runs simulated as continuous records).
    - `noise`: a known [`hrgjax.Noise`][] for continuous records (default: estimated from the
      data's zero-rate stretches, run-to-run bias from the baseline fit).
    - `block_s`: block length of the continuous increments [s].

    **Returns:** a [`Discovery`][hrgjax.discovery.result.Discovery]: the verdict, the
    accepted effects with their parameters in user units (`.parameters`) and model units
    (`.fit_parameters`), the screening table, the gaps and the noise floor, `consistency`
    (continuous records: per-run refits of each accepted effect and their χ² p-value),
    `noise`, `split`, `shape`; `.to_json()` (DESIGN.md's keys first), `.equations()`,
    `.plot(path)`.

    **Raises:** `ValueError` for unknown effect names, a bad `shape`, or too few runs to hold
    any out; `RuntimeError` when a continuous fit does not converge.
    """
    unknown = [n for n in list(nominal) + list(catalogue or []) if n not in CATALOGUE]
    if unknown:
        raise ValueError(f"unknown effect(s) {unknown}; catalogue: {sorted(CATALOGUE)}")
    if "angular_gain" not in nominal:
        raise ValueError("the nominal model must contain 'angular_gain'")
    if shape not in SHAPES:
        raise ValueError(f"shape must be one of {SHAPES}; got {shape!r}")
    if not (np.isfinite(block_s) and block_s > 0):
        raise ValueError(f"block_s must be a positive number of seconds; got {block_s}")
    if noise is not None and not isinstance(noise, Noise):
        raise TypeError(f"noise must be an hrgjax.Noise or None; got {type(noise).__name__}")
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
    held = runs[holdout_every - 1 :: holdout_every]
    if shape == "dwell":
        problem = DwellProblem(data, k_e, window_s, held)
    else:
        problem = _continuous_problem(
            data, nominal, catalogue, k_e, held, noise, block_s,
            window_s if shape == "mixed" else None,
        )  # fmt: skip
    cands = list(catalogue) if catalogue is not None else problem.candidates(nominal)
    cands = [n for n in cands if n not in nominal]

    model = list(nominal)
    base = problem.fit(model)
    gap_before, floor = base["gap"], problem.floor()
    accepted, ranking, current = [], [], base
    n_cands = len(cands)

    def consistent(r):
        """Per-run agreement of the candidate's refit (computed once, only when needed)."""
        if "consistency" not in r:
            r["consistency"] = problem.consistency(r["refit"], r["effect"])
        c = r["consistency"]
        return c is None or c["agreement"] is None or c["agreement"] >= min_agreement

    def passes(r, fit):
        return (
            r["p_value"] < alpha / max(n_cands, 1)
            and r["delta_bic"] > min_delta_bic
            and r["aliasing"] < max_aliasing
            and r["heldout_gain"] > min_heldout_gain
            and (not problem.gap_guard or r["gap_after"] <= fit["gap"])
            and consistent(r)
            and not outshone(r)
        )

    def outshone(r):
        """The uncovered shape the candidate only imitates (computed when needed)."""
        if "outshone_by" not in r:
            r["outshone_by"] = r["_check"](r) if "_columns" in r else None
        return r["outshone_by"] is not None

    for _ in range(max_effects):
        rows = problem.screen(current, cands, model)
        check = _Outshone(problem, current, model + cands, min_delta_bic)
        for r in rows:
            r["_check"] = check
        if not ranking:
            ranking = rows
        ok = [r for r in rows if passes(r, current)]
        if not ok:
            break
        best = ok[0]
        accepted.append(best["effect"])
        model.append(best["effect"])
        cands.remove(best["effect"])
        current = problem.after_accept(best["refit"])
    floor = problem.floor()  # σ_b may have been re-estimated at the final model
    left = problem.structure_left(current, floor)
    if accepted:
        verdict = "found"
    elif problem.structure_left(base, floor):
        verdict = "unexplained"
    else:
        verdict = "none"
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
            and passes(r, base)
            and win["delta_bic"] - r["delta_bic"] < ambiguity_bic
        ]
        if ambiguous:
            verdict = "ambiguous"
    return Discovery(
        verdict=verdict,
        missing_effect=accepted[0] if accepted else None,
        accepted=tuple(accepted),
        ambiguous_with=tuple(ambiguous),
        discriminate={n: CATALOGUE[n].discriminate for n in accepted + ambiguous},
        gap_before=gap_before,
        gap_after=current["gap"],
        noise_floor=floor,
        metric=METRIC,
        structure_left=bool(left),
        fit_parameters=current["parameters"],
        k_e=_fitted_k_e(current["parameters"], k_e),
        ranking=tuple(
            {"effect": r["effect"], "score": r["score"], "params": r["params"]} for r in ranking
        ),
        screening=tuple({k: r.get(k) for k in SCREEN_KEYS} for r in ranking),
        consistency={n: problem.consistency(current, n) for n in accepted},
        noise=problem.noise_report(),
        split={"train_runs": int(runs.size - held.size), "heldout_runs": int(held.size)},
        shape=shape,
        residuals={"before": problem.residuals(base), "after": problem.residuals(current)},
        leftover=problem.leftover(current),
    )


def _fitted_k_e(parameters: dict, k_e: float) -> float:
    """The fitted angular gain where the data determine it (rotations: within 10 %), else
    the nominal `k_e` (static data leave it free)."""
    p = parameters.get("angular_gain", {}).get("k_e")
    if p is None or not np.isfinite(p["value"]) or p["value"] <= 0:
        return float(k_e)
    std = p.get("std")
    if std is None or not np.isfinite(std) or std > 0.1 * p["value"]:
        return float(k_e)
    return float(p["value"])


SHAPES = ("auto", "dwell", "continuous", "mixed")
SCREEN_KEYS = (
    "effect", "score", "p_value", "delta_bic", "aliasing", "heldout_gain", "gap_after",
    "outshone_by",
)  # fmt: skip


class _Outshone:
    """Whether a candidate only imitates part of something out of the catalogue: a generic
    shape ([`leftover.SHAPES`][hrgjax.discovery.leftover.SHAPES]) that no available effect
    is and that explains the residual better than the candidate (score test, BIC), after
    which the candidate adds no more than `margin` in BIC (its score given the shape). A
    readout ripple that matches a temperature-dependent drift on the rotation runs but not
    at rest is such a part; a second true effect beside an imperfect first one is not (its
    score survives the shape)."""

    def __init__(self, problem, fit, available, margin):
        covered = {sh for n in available for sh in CATALOGUE[n].shapes}
        self.cols = {k: v for k, v in problem.shape_columns.items() if k not in covered}
        self.fit, self.margin = fit, margin
        self.log_n = math.log(max(len(fit["r"]), 2))
        self.scores = leftover.scores(fit["r"], fit["j"], self.cols)

    def __call__(self, row) -> str | None:
        q_c = sum(p.regular for p in CATALOGUE[row["effect"]].params)
        own = row["score"] - q_c * self.log_n
        r, j = self.fit["r"], self.fit["j"]
        stronger = sorted(
            ((sc - q * self.log_n, name) for name, (sc, q) in self.scores.items()),
            reverse=True,
        )
        for bic, name in stronger:
            if bic - own <= self.margin:
                break
            g_s = self.cols[name]
            jj = np.concatenate([j, g_s], axis=1)
            q_j, _ = np.linalg.qr(jj)
            r_s = r - q_j @ (q_j.T @ r)  # the residual once the shape is fitted too
            s_cond, _, _ = dwell.score(r_s, jj, row["_columns"]())
            if s_cond - q_c * self.log_n < self.margin:
                return name
        return None


def _continuous_problem(data, nominal, catalogue, k_e, held, noise, block_s, window_s=None):
    """Build the continuous problem over the superset (nominal + candidates); without a known
    noise model, estimate it and then the run-to-run bias from the baseline's run means.
    With `window_s` (a mixed log), the dwell runs join it as windows of that length (the
    dwell search's regression rows) and only the other runs are simulated."""
    have = {k for k, col in OPTIONAL.items() if col in data} | _rates_in(data)
    cands = list(catalogue) if catalogue is not None else candidates_for(have, nominal, True)
    names = list(nominal) + [n for n in cands if n not in nominal]
    known = noise is not None
    nz = noise_from_gyro(noise, k_e) if known else continuous_noise(data)
    windows, records = None, data
    dwell_ids = np.asarray(sorted(dwell_runs(data))) if window_s is not None else []
    if len(dwell_ids):
        in_dwell = np.isin(data.run, dwell_ids)
        part = lambda m: (
            MeasuredData({k: v[m] for k, v in data.columns.items()}) if m.any() else None
        )
        sub, records = part(in_dwell), part(~in_dwell)
        w = reduce(sub, k_e, window_s=window_s)
        extra, _ = _window_extras(sub, w)
        sigma, _ = _noise_scale(sub, w, k_e)
        win = Windows(y=dwell.target(w, k_e), sigma=sigma, cov=dwell.covariates(w, extra),
                      run=tuple(np.asarray(w.run).tolist()))  # fmt: skip
        windows = (win, np.isin(w.run, held))
    problem = ContinuousProblem(records, names, k_e, held, nz, block_s, windows=windows)
    problem.noise_known = known
    if not known:
        problem.estimate_run_bias(problem.fit(list(nominal))["z"])
    return problem


class DwellProblem:
    """Dwell-grid discovery: window rates as weighted linear regression (module docstring)."""

    gap_guard = True  # an accepted effect must not widen the held-out gap

    def __init__(self, data, k_e, window_s, held):
        self.k_e, self.held = k_e, held
        self.w = w = reduce(data, k_e, window_s=window_s)
        extra, self.have = _window_extras(data, w)
        self.c = dwell.covariates(w, extra)
        self.y = dwell.target(w, k_e)
        self.train = ~np.isin(w.run, held)
        self.sigma, self.nm = _noise_scale(data, w, k_e)

    def candidates(self, nominal):
        return candidates_for(self.have, nominal)

    def fit(self, model):
        return _fit(model, self.c, self.y, self.sigma, self.train, self.w, self.held, self.k_e)

    def floor(self):
        return _floor(self.sigma, self.w, self.held, self.k_e)

    def after_accept(self, fit):
        return fit

    def consistency(self, fit, name):
        """Not defined on dwell grids (one run is one grid point)."""
        return None

    def structure_left(self, fit, floor):
        """The held-out gap is more than twice the noise floor."""
        return fit["gap"] > 2.0 * floor

    def screen(self, current, cands, model):
        return _screen(
            current,
            cands,
            model,
            self.c,
            self.sigma,
            self.train,
            self.y,
            self.w,
            self.held,
            self.k_e,
        )

    def residuals(self, fit):
        """What the figure draws of `fit`: every window's drift residual [°/h] (as input
        rate) with its wave angle [°], temperature [°C] and whether it is static."""
        w = self.w
        return {
            "wave_angle_deg": np.asarray(w.wave_angle_deg),
            "temperature_c": np.asarray(w.temperature_c),
            "static": np.asarray(w.static),
            "drift_dph": -np.asarray(fit["resid"]) / self.k_e / DEG_PER_H,
        }

    @functools.cached_property
    def shape_columns(self) -> dict:
        """Whitened columns of the generic shapes on the training windows
        ([`leftover.columns`][hrgjax.discovery.leftover.columns])."""
        c, tr = self.c, self.train
        full = lambda v: np.broadcast_to(np.asarray(v, float), tr.shape)[tr]
        cov = {
            "theta": full(c.theta),
            "dT": full(c.temperature) - T_REF_C,
            "Tdot": np.zeros(int(tr.sum())),
            "rate": full(c.rate),
            "accel_z": full(c.accel_z),
            "t_run": full(c.t_run),
        }
        return {k: g / self.sigma[tr][:, None] for k, g in leftover.columns(cov).items()}

    def leftover(self, fit):
        """The strongest shape left in `fit`'s training residual
        ([`describe`][hrgjax.discovery.leftover.describe])."""
        return leftover.describe(fit["r"], fit["j"], self.shape_columns, self.k_e)

    def noise_report(self):
        nm, k_e, w = self.nm, self.k_e, self.w
        white, arw = nm["angle_white"], nm["angle_random_walk"]
        return {
            "angle_white_arcsec": None if white is None else white / DEG * 3600,
            "angle_random_walk_dph_per_sqrt_h": None if arw is None else arw / k_e / DEG * 60,
            "sigma_static_dph": _sigma_dph(self.sigma, w.static, k_e),
            "sigma_moving_dph": _sigma_dph(self.sigma, ~w.static, k_e),
        }


def _sigma_dph(sigma, mask, k_e):
    return float(np.median(sigma[mask])) / k_e / DEG_PER_H if np.any(mask) else None


def noise_model(data: MeasuredData, max_lag: int = 64) -> dict:
    r"""White angle noise σ_w [rad] and angle random walk N [rad/√s] from the static runs.

    Lag-k second differences θ[i+k] − 2θ[i] + θ[i−k] remove a run's drift and have variance
    $6\sigma_w^2 + 2N^2 k\,\Delta t$; a least-squares line over k = 1, 2, 4, … `max_lag` (at most
    a quarter of the run) gives both.
    Static runs only: while the pattern turns, the smooth rate ripple would leak in.

    **Returns:** `{"angle_white": σ_w, "angle_random_walk": N}` (`None` without static runs).
    """
    lags, var = [], []
    for idx in data.run_indices():
        if not np.all(data["table_rate_dps"][idx] == 0.0) or idx.size < 8:
            continue
        th = data["wave_angle_deg"][idx] * DEG
        dt = float(np.median(np.diff(data["time_s"][idx])))
        ks = [2**i for i in range(7) if 2**i <= min(max_lag, idx.size // 4)]
        for k in ks:
            d2 = th[2 * k :] - 2 * th[k:-k] + th[: -2 * k]
            lags.append(k * dt)
            var.append(np.mean(d2**2))
    if not lags:
        return {"angle_white": None, "angle_random_walk": None}
    slope, icpt = np.polyfit(np.asarray(lags), np.asarray(var), 1)
    return {
        "angle_white": float(np.sqrt(max(icpt, 0.0) / 6.0)),
        "angle_random_walk": float(np.sqrt(max(slope, 0.0) / 2.0)),
    }


def _noise_scale(data: MeasuredData, w: RateWindows, k_e):
    """Standard error of each window's pattern rate [rad/s]: from the fitted white + random
    walk model (exact least-squares slope variance for white noise, 6N²/5T for the walk);
    windows of runs without a static reference fall back to their batch-means errors."""
    nm = noise_model(data)
    batch = k_e * DEG * w.stderr_dps
    if nm["angle_white"] is None:
        return batch, nm
    sigma = np.empty(len(w))
    times = {int(data.run[idx[0]]): data["time_s"][idx] for idx in data.run_indices()}
    for i, (run, a, b) in enumerate(zip(w.run, w.start, w.stop, strict=True)):
        t = times[int(run)][a:b]
        span = t[-1] - t[0]
        white = nm["angle_white"] ** 2 / np.sum((t - t.mean()) ** 2)
        walk = 1.2 * nm["angle_random_walk"] ** 2 / max(span, 1e-12)
        sigma[i] = np.sqrt(white + walk)
    return sigma, nm


def _fit(model, c, y, sigma, train, w, held, k_e):
    g, labels = dwell.design(model, c, k_e)
    beta, r, cov = dwell.wls(g[train], y[train], sigma[train])
    resid = y - g @ beta
    if any(CATALOGUE[n].where == "readout" for n in model):
        # The readout terms' higher orders, where they matter (a 1 % ripple at 5 °/s).
        beta2, f, jac = dwell.refine(model, beta, c, y, sigma, train, k_e)
        if np.max(np.abs(f - g @ beta2) / sigma) > 0.1:
            beta, g = beta2, jac
            resid = y - f
            r = resid[train] / sigma[train]
            cov = dwell.covariance(g[train] / sigma[train][:, None])
    held_mask = np.isin(w.run, held)
    heldout_chi2 = float(np.sum((resid[held_mask] / sigma[held_mask]) ** 2))
    err = np.sqrt(np.diag(cov))
    params = {}
    for (name, j), b, e in zip(labels, beta, err, strict=True):
        pname = [p.name for p in CATALOGUE[name].params if p.regular][j]
        params.setdefault(name, {})[pname] = {"value": float(b), "std": float(e)}
    return {
        "resid": resid,
        "r": r,
        "j": g[train] / sigma[train][:, None],
        "chi2": float(r @ r),
        "gap": _gap(resid, w, held, k_e),
        "heldout_chi2": heldout_chi2,
        "parameters": params,
        "model": list(model),
    }


def _screen(current, cands, model, c, sigma, train, y, w, held, k_e):
    n = int(np.sum(train))
    rows = []
    with bar(len(cands), f"screening {len(cands)} candidates", unit="effect") as progress:
        for name in cands:
            progress.set_postfix_str(name)
            row = _screen_one(name, current, model, c, sigma, train, y, w, held, k_e, n)
            progress.update(1)
            if row is not None:
                rows.append(row)
    rows.sort(key=lambda r: -r["score"])
    return rows


def _screen_one(name, current, model, c, sigma, train, y, w, held, k_e, n):
    """Score test and refit of one candidate (None when it leaves the training data alone)."""
    g = dwell.columns(name, c, k_e)
    if not np.any(g[train]):
        return None
    gw = g[train] / sigma[train][:, None]
    s, alias, step = dwell.score(current["r"], current["j"], gw)
    q = g.shape[1]
    refit = _fit(model + [name], c, y, sigma, train, w, held, k_e)
    lam = current["chi2"] - refit["chi2"]
    names = [p.name for p in CATALOGUE[name].params if p.regular]
    return {
        "effect": name,
        "score": float(s),
        "p_value": dwell.chi2_sf(s, q),
        "delta_bic": float(lam - q * math.log(n)),
        "aliasing": alias,
        "gap_after": refit["gap"],
        "heldout_gain": current["heldout_chi2"] - refit["heldout_chi2"],
        "params": {k: v["value"] for k, v in refit["parameters"][name].items() if k in names},
        "refit": refit,
        "_columns": lambda: gw,
    }
