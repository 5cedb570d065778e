r"""Discovery on continuous records (DISCOVERY.md §2.2 b): output-error fits through diffrax.

A continuous record is any run whose temperature or rate changes (ramps, rate profiles,
warm-ups). Nothing is differentiated from noisy data: the model's wave angle is *simulated*
— the reduced equation of PHYSICS.md §10 with every catalogue term in
[`pattern_rate`][hrgjax.discovery.effects.pattern_rate], solved by diffrax from the run's first
measured angle with the run's own rate and temperature samples as covariates — and compared
with the measured angle at block boundaries every `block_s` seconds:

$$r_k = \bigl(\theta_{\rm meas}(t_{k+1}) - \theta_{\rm meas}(t_k)\bigr)
      - \bigl(\hat\theta(t_{k+1}) - \hat\theta(t_k)\bigr),$$

increments, so the unknown initial angle drops out. Under the noise model (white angle noise
σ_w, angle random walk N, a first-order Gauss–Markov rate (σ_GM, T_c)) the increments of one
run have the exact covariance

$$\Sigma_{kl} = \sigma_w^2(2\delta_{kl} - \delta_{|k-l|,1}) + N^2\Delta\,\delta_{kl}
 + C_{\rm GM}(k,l) + \sigma_b^2\Delta^2,$$

$C_{\rm GM}(k,k) = 2\sigma^2T_c(\Delta - T_c(1-e^{-\Delta/T_c}))$,
$C_{\rm GM}(k,l) = \sigma^2T_c^2(1-e^{-\Delta/T_c})^2e^{-(|k-l|-1)\Delta/T_c}$, and the residual is
whitened by its Cholesky factor. Each run is its own switch-on: its constant bias
(run-to-run repeatability, spread σ_b) is a random effect, $\sigma_b^2\Delta^2$ added to every
element of Σ, with σ_b estimated by REML from the run means at the current model (`run_bias`) and
re-estimated after each accepted effect (its own uncertainty carried into the reported σ). Sensitivities to every parameter — fitted or still at its
null — are forward-mode derivatives through the solve (`diffrax.ForwardMode`, `jax.jacfwd`);
fits are `optimistix.LevenbergMarquardt` (finished where it stalls: `_continuous_fit`).
Nonregular time constants (`thermal_lag`'s τ_th, `warmup_transient`'s τ_w) are scanned on a
grid; the score test then takes the best grid point and pays for the grid in its Bonferroni level.
"""

from __future__ import annotations

import copy
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._progress import bar
from ..units import DEG, DEG_PER_H
from . import dwell, leftover, run_bias, stats, thermometer
from ._continuous_fit import converged_lm
from .effects import CATALOGUE
from .noise import NOISE_GIVEN, NOISE_STILL, NoiseModel, estimated
from .problem import AbstractProblem, Fit, candidates_for, covariates_in, dwell_runs
from .problem import is_dwell as is_dwell  # deprecated here (issue 45): see problem
from .records import STEP_S as STEP_S  # deprecated here (issue 45): see records
from .records import (
    Layout,
    Runs,
    Windows,
    per_run_fits,
    raw_residuals,
    repeats,
    residual_and_jacobian,
    run_covariates,
    run_level,
    stack_runs,
    whiten,
)  # fmt: skip

BLOCK_S = 10.0
"""Default block length of the increments [s]."""
REFIT_TOP = 3
"""Candidates refitted in full per screening pass (the short list)."""
TAU_GRID = (30.0, 100.0, 300.0, 1000.0, 3000.0)
"""Grid of nonregular time constants scanned in screening [s]."""
RUN_COVARIATE_ALPHA = 0.01
"""Significance at which a run covariate explains the run means' scatter (`with_run_bias`)."""
RESOLVES = 1.0
"""A training run (or, where fewer than two runs do, a group of consecutive ones) counts in an
effect's per-run consistency when its data put the pooled effect at this many σ at least
(`consistency`)."""


class ContinuousProblem(AbstractProblem):
    """Everything `discover` needs on continuous records: fits, screening and the gap
    (the same interface as the dwell-grid problem)."""

    def __init__(
        self, data, names, k_e, held, noise, block_s=BLOCK_S, windows=None, noise_known=False
    ):
        self.data, self.k_e, self.block_s = data, k_e, block_s
        self.k_out = float(k_e)  # the current model's fitted angular gain (dwell.output_gain)
        self.noise_known = noise_known  # the noise model was given: σ_b is not re-estimated
        self.windows = windows  # (Windows, held mask): the dwell runs of a mixed log
        self.layout = Layout(names)
        self.held = set(int(r) for r in held)
        if not isinstance(noise, NoiseModel):
            raise TypeError(f"noise must be a NoiseModel; got {type(noise).__name__}")
        self.noise = noise
        self.z_null = self.layout.null(k_e)
        self._build()

    @classmethod
    def from_data(
        cls, data, held, *, nominal, catalogue=None, k_e, window_s=None, noise=None,
        block_s=BLOCK_S,
    ) -> ContinuousProblem:  # fmt: skip
        """The problem over the superset (`nominal` + candidates); without a known `noise`
        (an [`hrgjax.Noise`][]), the noise model is estimated, then σ_b from the run means.
        With `window_s` (a mixed log), the dwell runs join as windows of that length
        (`dwell.rate_windows`). A held temperature: `thermometer.unhold_temperature`."""
        data = thermometer.unhold_temperature(data)  # a forward-filled thermometer: warned
        have = covariates_in(data)
        cands = list(catalogue) if catalogue is not None else candidates_for(have, nominal, True)
        names = list(nominal) + [n for n in cands if n not in nominal]
        known = noise is not None
        nz, source = (NoiseModel.from_gyro(noise, k_e), NOISE_GIVEN) if known else estimated(data)
        windows, records = None, data
        dwell_ids = np.asarray(sorted(dwell_runs(data))) if window_s is not None else []
        if len(dwell_ids):
            in_dwell = np.isin(data.run, dwell_ids)
            part = lambda m: data.select(m) if m.any() else None  # checked with `data`
            sub, records = part(in_dwell), part(~in_dwell)
            w, y, cov, arc = dwell.rate_windows(sub, k_e, window_s)
            win = Windows(
                y=y,
                sigma=dwell.window_sigma(nz, sub, w),  # the one noise model of the whole log
                cov=cov,
                arc=arc,
                run=tuple(np.asarray(w.run).tolist()),
            )
            windows = (win, np.isin(w.run, held))
        problem = cls(records, names, k_e, held, nz, block_s, windows, known)
        problem.noise_source = source  # copied along with the problem
        if not known:
            problem = problem.with_run_bias(problem.fit(list(nominal)))
        return problem

    # -- data ----------------------------------------------------------------
    def _build(self):
        self.train_groups, self.held_groups = [], []
        self.__dict__.pop("shape_columns", None)  # whitened as the groups are: rebuild
        if self.windows is not None:
            w, held = self.windows
            for mask, groups in ((~held, self.train_groups), (held, self.held_groups)):
                if mask.any():
                    n = int(mask.sum())
                    pick = lambda a, mask=mask: jnp.asarray(np.asarray(a)[mask])
                    # every covariate per window (a default scalar broadcast), so that the
                    # compiled programs see arrays only
                    cov = jax.tree_util.tree_map(
                        lambda a, pick=pick, n=n: pick(a) if np.ndim(a) else jnp.full(n, a),
                        w.cov,
                    )
                    run = tuple(np.asarray(w.run)[mask].tolist())
                    ref = self.train_groups[0] if self.train_groups else None  # (held: train's)
                    groups.append(Windows(y=pick(w.y), sigma=pick(w.sigma), cov=cov,
                                          arc=pick(w.arc), run=run, reference=ref,
                                          session=self.data is not None))  # fmt: skip
        # runs are stacked by length *and* sample interval (`MeasuredData.stacked`): the
        # blocks and solver steps are set in samples from the stack's interval (a 721-sample
        # ramp at 5 s and a 721-sample rotation at 0.1 s must not share them)
        for stack in self.data.stacked() if self.data is not None else []:  # None: windows only
            held = np.isin(stack.run, list(self.held))
            for mask, groups in ((~held, self.train_groups), (held, self.held_groups)):
                if mask.any():
                    groups.append(stack_runs(stack, mask, self.noise, self.block_s))

    def with_run_bias(self, fit) -> ContinuousProblem:
        """A copy of this problem (left as it is) whose run-to-run bias spread σ_b [rad/s] is
        the REML estimate at `fit` (a fit of this problem; `run_bias.reml_at_fit`), the
        whitening rebuilt. A scatter that follows a run's covariate (mean dT/dt, table rate or
        specific force: an effect constant along each ramp, say c·Ṫ) is not a switch-on bias:
        the covariate that explains the run means significantly (F-test, p <
        `RUN_COVARIATE_ALPHA`, `stats.followed_covariates`) is a fixed effect there."""
        with bar(3, "run-to-run bias (REML)", tick=True) as progress:
            inputs = self._reml_inputs(fit, progress)  # each compiles once per shape
            new = copy.copy(self)
            if inputs is not None:  # else nothing to estimate it from
                sigma_b = run_bias.reml_run_bias(*inputs, self.noise.run_bias)
                new.noise = self.noise.replace(run_bias=sigma_b)
            progress.update(1)
            new._build()
            progress.update(1)
        return new

    def _reml_inputs(self, fit, progress=None):
        """`run_bias.reml_inputs` at `fit` (`with_run_bias`); None: under two runs."""
        # continuous runs only: each is its own switch-on (the dwell runs of a mixed log are
        # one session, whose own bias is profiled out of their residual: `Windows.session`)
        train = [g for g in self.train_groups if isinstance(g, Runs)]
        held = [g for g in self.held_groups if isinstance(g, Runs)]
        rates = self.run_rates(fit.z, train) | self.run_rates(fit.z, held)
        if len(rates) < 2:
            return None
        covs = run_covariates(train + held)
        x = np.asarray([covs[r] for r in rates])
        _, chosen = stats.followed_covariates(np.asarray(list(rates.values())), x,
                                              RUN_COVARIATE_ALPHA)  # fmt: skip
        held = residual_and_jacobian(  # the fit's parameters move the held-out runs
            self.layout, jnp.asarray(fit.z), self._basis(list(fit.model))[0], self.held_groups,
        ) if self.held_groups else None  # fmt: skip
        if progress is not None:
            progress.update(1)
        return run_bias.reml_inputs(fit, held, self.train_groups, self.held_groups,
                                    {r: c[chosen] for r, c in covs.items()})  # fmt: skip

    def noise_spread(self, fit):
        """σ_b's uncertainty carried into `fit`'s parameters
        ([`run_bias.spread`][hrgjax.discovery.run_bias.spread]); None when the noise was given."""
        inputs = None if self.noise_known else self._reml_inputs(fit)
        if inputs is None:
            return None
        return run_bias.spread(fit, *inputs, self.noise.run_bias, self.k_out * DEG_PER_H)

    def after_accept(self, fit):
        """Re-estimate σ_b at the new model (unless the noise was given) and refit: a new
        problem and its fit."""
        self.k_out = dwell.output_gain(fit.parameters, self.k_e)
        if self.noise_known:
            return self, fit
        new = self.with_run_bias(fit)
        return new, new.fit(list(fit.model), z0=fit.z)

    def baseline(self, model, base):  # under σ_b as last re-estimated: the final model's
        return base if self.noise_known else self._fit_model(list(model), z0=base.z)

    def structure_left(self, fit, floor=None, alpha=1e-3):
        """True when the held-out whitened χ² is too large for its degrees of freedom
        (p < `alpha`)."""
        dof = sum(
            len(g.run) if isinstance(g, Windows) else (int(g.bidx.shape[0]) - 2) * len(g.run)
            for g in self.held_groups
        )
        return stats.chi2_sf(fit.heldout_chi2, max(dof, 1)) < alpha

    # -- fits ----------------------------------------------------------------
    def _basis(self, names):
        """(P, m) columns picking the regular parameters of `names`."""
        idx = [i for n in names for i in self.layout.index(n, which=True)]
        return np.eye(self.layout.size)[:, idx], idx

    def fit(self, model, z0=None):
        """Fit the regular parameters of `model` (effect names) on the training runs from
        `z0`; the rest of the superset stays where it is (at its null by default). The fit
        becomes the current model: its angular gain converts the floor (`k_out`).
        **Returns:** a [`Fit`][hrgjax.discovery.problem.Fit]."""
        with bar(1, f"fitting the model of {len(model)} effects", unit="fit", tick=True) as b:
            fit = self._fit_model(model, z0)  # one compiled solve: the bar's clock ticks
            b.update(1)
        self.k_out = dwell.output_gain(fit.parameters, self.k_e)
        return fit

    def _fit_model(self, model, z0=None):
        """[`fit`][hrgjax.discovery.continuous.ContinuousProblem.fit] without making it the
        current model (the screening's refits)."""
        z0 = self.z_null if z0 is None else np.asarray(z0)
        basis, idx = self._basis(model)
        z, ok = converged_lm(self.layout, basis, jnp.asarray(z0), self.train_groups)
        if not bool(ok):
            raise RuntimeError(f"continuous discovery: the fit of {model} did not converge")
        z = np.asarray(z)
        r, j = residual_and_jacobian(self.layout, jnp.asarray(z), basis, self.train_groups)
        r, j = np.asarray(r), np.asarray(j)
        err = np.sqrt(np.diag(stats.covariance(j)))
        held_raw = self.raw_residuals(z, self.held_groups)
        held_r = whiten(held_raw, self.held_groups)
        params = {}
        for n in model:  # nonregular parameters: where the scan put them, no error bar
            for i in self.layout.index(n, which=False):
                pname = CATALOGUE[n].params[i - self.layout.slices[n].start].name
                params.setdefault(n, {})[pname] = {
                    "value": float(z[i] * self.layout.scale[i]),
                    "std": None,
                    "why_no_sigma": "a time constant scanned on a grid "
                    f"({', '.join(f'{t:g}' for t in TAU_GRID)} s, refined by a parabola in "
                    "log τ) and held there: the fit's other σ are given at it",
                }
        for i, e in zip(idx, err, strict=True):
            name = next(n for n in model if i in self.layout.index(n))
            pname = CATALOGUE[name].params[i - self.layout.slices[name].start].name
            params.setdefault(name, {})[pname] = {
                "value": float(z[i] * self.layout.scale[i]),
                "std": float(e * self.layout.scale[i]),
            }
        return Fit(
            model=tuple(model),
            parameters=params,
            r=r,
            j=j,
            chi2=float(r @ r),
            heldout_chi2=float(held_r @ held_r),
            gap=self._gap(held_raw, dwell.output_gain(params, self.k_e)),
            z=z,
        )

    def _run_means(self, raw, groups, k=None):
        """Run-mean equivalent-input-rate residual [°/h] of every run, from raw residuals
        (converted at the angular gain `k`; default: the current model's)."""
        k = self.k_out if k is None else k
        out = {}
        for g, r in zip(groups, raw, strict=True):
            if isinstance(g, Windows):  # the mean of the run's windows
                runs, r = np.asarray(g.run), np.asarray(r)
                for run in np.unique(runs):
                    out[int(run)] = float(-np.mean(r[runs == run]) / k / DEG_PER_H)
                continue
            span = np.asarray(g.t[:, g.bidx[-1]] - g.t[:, g.bidx[0]])
            means = -np.asarray(r).sum(axis=1) / (k * span) / DEG_PER_H
            out.update(zip(g.run, means, strict=True))
        return out

    def run_rates(self, z, groups):
        """Run-mean equivalent-input-rate residual of every run in `groups` [°/h]."""
        return self._run_means(self.raw_residuals(z, groups), groups)

    def consistency(self, fit, name):
        r"""Per-run consistency of an accepted effect (DISCOVERY.md §2.1, "evidence must
        repeat"): its regular parameters refitted on each training run alone (the rest held
        at the pooled fit $\bar p$), compared by `records.repeats` over the runs that
        *resolve* it ($\bar p^\top C_i\bar p$ ≥ `RESOLVES`², $C_i$ the run's information)
        or, when fewer than two do, over consecutive runs pooled until each group does: the
        χ² of their values about the pooled one (judged at the noise level the residual shows
        at the runs' scale, `records.run_level`) and the share pointing the same way. Another
        run's sign is noise (a readout mismatch seen by a static ramp's drift of θ alone, at
        10⁻⁴ σ, once outvoted its rotations); where a mixed log's training dwell windows hold
        more of its information than the runs together, the runs' signs do not test it and
        the check is not made. A run whose refit did not converge gives no estimate: it
        neither agrees nor disagrees, and is listed in `unconverged`.

        **Returns:** `{"p_value", "dof", "agreement", "units", "reason", "unconverged",
        "per_run": {run: {param: value}}}` (`records.repeats`; `per_run`: every converged
        training run's refit, resolving or not)."""
        basis, idx = self._basis([name])
        names, scale, pooled = CATALOGUE[name].regular_names, self.layout.scale[idx], fit.z[idx]
        with bar(1, f"per-run refits of {name}", unit="refit", tick=True) as progress:
            fits, unconverged = per_run_fits(self.layout, basis, fit.z, self.train_groups, idx)
            progress.update(1)
        own = lambda: [k for k, i in enumerate(self._basis(list(fit.model))[1]) if i in idx]
        jw = np.asarray(fit.j)[self.row_classes() < 2][:, own()] if self.windows else None
        out = repeats(fits, pooled, RESOLVES, self.level(fit, idx), jw)
        if out["reason"] is not None and unconverged:
            out["reason"] += f" ({len(unconverged)} runs' refits did not converge)"
        per_run = {
            run: {n: float(v * sc) for n, v, sc in zip(names, z, scale, strict=True)}
            for run, z, _ in fits
        }
        return out | {"unconverged": unconverged, "per_run": per_run}

    def level(self, fit, idx):
        """`records.run_level` of `fit` with the parameters `idx` refitted run by run."""
        own = [k for k, i in enumerate(self._basis(list(fit.model))[1]) if i in idx]
        return run_level(fit.r, fit.j, own, self.train_groups)

    def start_from(self, parameters, names):
        """Scaled vector at the null with a report's `parameters` of effects `names` put in."""
        z = self.z_null.copy()
        for name, ps in parameters.items():
            if name not in self.layout.slices or name not in names:
                continue
            for i, p in zip(self.layout.index(name), CATALOGUE[name].params, strict=True):
                if p.name in ps:
                    z[i] = ps[p.name]["value"] / self.layout.scale[i]
        return z

    def residuals(self, fit):
        """What the figure draws of `fit`: every run's angle residual [″] against time in the
        run [min], its mean rate removed (the switch-on bias), held-out runs marked; a mixed
        log's as `{"records": …, "windows": …}` with its dwell windows' drift residuals."""
        out = []
        for groups, held in ((self.train_groups, False), (self.held_groups, True)):
            groups = [g for g in groups if isinstance(g, Runs)]
            for g, r in zip(groups, self.raw_residuals(fit.z, groups), strict=True):
                tb = np.asarray(g.t[:, g.bidx])
                for i, run in enumerate(g.run):
                    t = tb[i] - tb[i, 0]
                    cum = np.concatenate([[0.0], np.cumsum(r[i])])
                    cum = cum - np.polyval(np.polyfit(t, cum, 1), t)
                    out.append({"run": int(run), "held": held, "t_min": t / 60,
                                "angle_arcsec": cum / DEG * 3600})  # fmt: skip
        out = sorted(out, key=lambda d: d["run"])
        if self.windows is None:
            return out
        return {"records": out, "windows": self._window_residuals(fit)}

    def _window_residuals(self, fit):
        """A mixed log's dwell windows as the dwell figure draws them: drift residual [°/h]
        (as input rate), wave angle [° el.], temperature [°C], static or not."""
        groups = [g for g in self.train_groups + self.held_groups if isinstance(g, Windows)]
        raw = self.raw_residuals(fit.z, groups)
        parts = [(g.cov, np.asarray(r)) for g, r in zip(groups, raw, strict=True)]
        col = lambda f: np.concatenate(
            [np.broadcast_to(np.asarray(f(c), float), r.shape) for c, r in parts]
        )
        return {
            "wave_angle_deg": col(lambda c: c.theta) / DEG,
            "temperature_c": col(lambda c: c.temperature),
            "static": col(lambda c: c.rate) == 0.0,
            "drift_dph": -np.concatenate([r for _, r in parts]) / self.k_e / DEG_PER_H,
        }

    @functools.cached_property
    def shape_columns(self) -> dict:
        """Whitened columns of the generic shapes on the training rows
        ([`leftover.group_columns`][hrgjax.discovery.leftover.group_columns])."""
        return leftover.group_columns(self.train_groups)

    def leftover(self, fit):
        """The strongest shape left in `fit`'s training residual, each row class at its level
        ([`describe`][hrgjax.discovery.leftover.describe])."""
        cls = self.row_classes()
        return leftover.describe(fit.r, fit.j, self.shape_columns, self.k_e, classes=cls)

    def raw_residuals(self, z, groups=None):
        """Unwhitened increment residuals [rad], one (R, K) array per group (default: the
        training runs)."""
        groups = self.train_groups if groups is None else groups
        return [np.asarray(r) for r in raw_residuals(self.layout, jnp.asarray(z), groups)]

    def gap(self, z):
        """RMS over held-out runs of the run-mean rate residual [°/h] (DESIGN.md; NaN: none)."""
        return self._gap(self.raw_residuals(z, self.held_groups))

    def _gap(self, held_raw, k=None):
        if not self.held_groups:
            return float("nan")
        rates = self._run_means(held_raw, self.held_groups, k)
        return float(np.sqrt(np.mean(np.square(list(rates.values())))))

    def floor(self, every=False, windows=True):
        """What noise alone gives the gap: RMS over held-out runs (`every`: all runs; without
        `windows`, the continuous runs only) of the standard deviation of the run-mean rate
        [°/h]."""
        if not (self.held_groups or every):
            return float("nan")
        var = []
        for g in self.held_groups + (self.train_groups if every else []):
            if isinstance(g, Windows):
                if windows:
                    runs, inv = np.asarray(g.run), 1.0 / np.asarray(g.sigma) ** 2
                    var += [1.0 / inv[runs == r].sum() / self.k_out**2 for r in np.unique(runs)]
                continue
            k = int(g.bidx.shape[0]) - 1
            for i in range(len(g.run)):
                span = float(g.t[i, g.bidx[-1]] - g.t[i, g.bidx[0]])
                cov = self.noise.increment_covariance(span / k, k)
                var.append(cov.sum() / (self.k_out * span) ** 2)
        return float(np.sqrt(np.mean(var))) / DEG_PER_H if var else float("nan")

    noise_source = NOISE_STILL  # `from_data` sets it (`noise.estimated`); no gap guard:
    # the run-mean gap is set by the switch-on bias (`widens` never): judge on χ² only
    descent = -1.0  # `j` is the whitened residual's derivative (records.residual_and_jacobian)

    def candidates(self, nominal):
        """Every effect of the superset that is not nominal."""
        return [n for n in self.layout.names if n not in nominal]

    def row_classes(self):
        """Training rows by class: a mixed log's static (1) and moving (0) dwell windows,
        the continuous records' whitened blocks (2)."""
        out = []
        for g in self.train_groups:
            if isinstance(g, Windows):
                out.append((np.broadcast_to(np.asarray(g.cov.rate), (len(g.run),)) == 0.0) * 1)
            else:
                out.append(np.full(len(g.run) * int(g.whiten.shape[1]), 2))
        return np.concatenate(out) if out else None

    def noise_report(self):
        """The noise model in report units, and its `source` in words."""
        gain = self.k_e if self.noise_known else self.k_out  # the fit's; a given one as given
        return self.noise.report(gain) | {"source": self.noise_source}

    # -- screening -----------------------------------------------------------
    def _columns(self, current, name, tau=None):
        """Whitened model sensitivities to `name`'s regular parameters at the current fit
        (with its nonregular parameter at `tau`)."""
        z = current.z.copy()
        nonreg = self.layout.index(name, which=False)
        if nonreg and tau is not None:
            z[nonreg[0]] = tau / self.layout.scale[nonreg[0]]
        basis, _ = self._basis([name])
        _, jac = residual_and_jacobian(self.layout, jnp.asarray(z), basis, self.train_groups)
        return -np.asarray(jac), z

    def _chunks(self, names) -> list:
        """`names` in consecutive chunks of ≤ 8 regular parameters (the refits' program
        width), one Jacobian each in `_shared_columns`."""
        chunks, chunk = [], []
        for name in names:
            width = sum(len(self.layout.index(n, which=True)) for n in chunk)
            if chunk and width + len(self.layout.index(name, which=True)) > 8:
                chunks, chunk = [*chunks, chunk], []
            chunk.append(name)
        return [*chunks, chunk] if chunk else chunks

    def _shared_columns(self, current, names, progress):
        """`_columns` of every effect of `names` (no nonregular parameters) from one
        Jacobian per `_chunks` chunk at the current fit, each counted on `progress`:
        {name: (columns, z)}."""
        out = {}
        for chunk in self._chunks(names):
            basis, idx = self._basis(chunk)
            _, jac = residual_and_jacobian(
                self.layout, jnp.asarray(current.z), basis, self.train_groups
            )
            jac, pos = -np.asarray(jac), {i: k for k, i in enumerate(idx)}
            for n in chunk:
                cols = [pos[i] for i in self.layout.index(n, which=True)]
                out[n] = (jac[:, cols], current.z.copy())
            progress.update(1)
        return out

    def _refine_tau(self, current, name, tried, best):
        """Parabola through the best grid point of the score and its neighbours in log τ;
        keep its vertex when it scores higher (still inside the grid)."""
        i = [b[4] for b in tried].index(best[4])
        if i == 0 or i == len(tried) - 1:
            return best
        near = tried[i - 1 : i + 2]
        tau = stats.log_parabola_peak([b[4] for b in near], [b[0] for b in near])
        if tau is None:
            return best
        g, z = self._columns(current, name, tau)
        s, alias, step = stats.score(current.r, current.j, g)
        return (s, alias, step, z, tau) if s > best[0] else best

    def screen(self, current, cands, model, top=REFIT_TOP, liberal=0.01):
        """Score test of every candidate; refit of the `top` best-scoring identifiable ones
        whose score p-value is below `liberal` (ΔBIC and held-out gain from the refit; the
        others keep the score's ΔBIC approximation and no held-out gain). Best first."""
        n = current.r.size
        rows = []
        # the candidates without a nonregular parameter share one Jacobian at the current fit
        regular = [c for c in cands if not self.layout.index(c, which=False)]
        # the shared Jacobians (one compiled call each), then each candidate's score test
        steps = len(self._chunks(regular)) + len(cands)
        desc = f"screening {len(cands)} candidates"
        with bar(steps, desc, unit="step", tick=True) as progress:
            progress.set_postfix_str("their shared Jacobian")
            shared = self._shared_columns(current, regular, progress)
            for name in cands:
                progress.set_postfix_str(name)
                grid = TAU_GRID if self.layout.index(name, which=False) else (None,)
                tried = []
                for tau in grid:
                    g, z = shared[name] if name in shared else self._columns(current, name, tau)
                    if np.any(g):
                        tried.append((*stats.score(current.r, current.j, g), z, tau))
                progress.update(1)  # its score tested (on the τ grid when it has one)
                if not tried:
                    continue
                best = max(tried, key=lambda b: b[0])
                if best[4] is not None:
                    best = self._refine_tau(current, name, tried, best)
                s, alias, step, z, tau = best
                q = len(self.layout.index(name, which=True)) + (tau is not None)
                rows.append(
                    {
                        "effect": name,
                        "score": float(s),
                        "p_value": min(1.0, stats.chi2_sf(s, q - (tau is not None)) * len(grid)),
                        "aliasing": alias,
                        "delta_bic": float(s - q * math.log(n)),
                        "gap_after": current.gap,
                        "heldout_gain": 0.0,
                        "params": {} if tau is None else {CATALOGUE[name].nonregular_name: tau},
                        "refit": None,
                        "_start": (z, step),
                        "_columns": (
                            (lambda g=g: g)
                            if tau is None
                            else (lambda name=name, tau=tau: self._columns(current, name, tau)[0])
                        ),  # fmt: skip
                    }
                )
        rows.sort(key=lambda r: -r["score"])
        short = [r for r in rows if r["aliasing"] < 0.999 and r["p_value"] < liberal][:top]
        with bar(len(short), f"refitting the {len(short)} best", unit="fit") as progress:
            for row in short:
                name, (z, step) = row["effect"], row["_start"]
                progress.set_postfix_str(name)
                progress.update(1)
                z_start = z.copy()
                z_start[self.layout.index(name, which=True)] += step
                try:
                    refit = self._fit_model(model + [name], z0=z_start)
                except RuntimeError:
                    continue
                q = CATALOGUE[name].size
                row.update(
                    delta_bic=float(current.chi2 - refit.chi2 - q * math.log(n)),
                    gap_after=refit.gap,
                    heldout_gain=current.heldout_chi2 - refit.heldout_chi2,
                    refit=refit,
                )
                row["params"] = {
                    k: {"value": v["value"], "std": v.get("std")}
                    for k, v in refit.parameters.get(name, {}).items()
                } | row["params"]
        for row in rows:
            del row["_start"]
        return rows
