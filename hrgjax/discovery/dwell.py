r"""Discovery on dwell-grid data (DISCOVERY.md §2.2 a): the catalogue as regressor columns,
and [`DwellProblem`][hrgjax.discovery.dwell.DwellProblem], the dwell-grid side of
[`AbstractProblem`][hrgjax.discovery.problem.AbstractProblem].

Each window of a dwell run (static or constant rate, constant temperature) gives a measured
pattern rate $y = \dot\theta_{\rm meas} = -k_{e,\rm nom}\,\Omega_{\rm meas}$ [rad/s]. Around the
nominal model every catalogue term is linear in its parameters at the window's covariates
(mean wave angle, table rate, temperature, …), so a model is a design matrix and the fit is
weighted least squares; the score test of a candidate
([`score`][hrgjax.discovery.stats.score]) is then exact (DISCOVERY.md §2.4 S3), χ²_q under
the null in whitened units. A readout term g(θ) enters through
$\dot\theta_{\rm meas} = (1+\partial g/\partial\theta)\,\dot\theta$ (for the gain mismatch
$1+\varepsilon_1\cos2\theta-\varepsilon_2\sin2\theta$), linearised at the nominal rate −k_e,nom Ω; a window in which the pattern turns sees every 2θ
harmonic times the gain its least-squares slope has for it over the window's own samples
(`dwell.sampled_gain`; the continuous
[`window_gain`][hrgjax.discovery.effects.window_gain] of the arc is 5·10⁻⁴ too large at
6 samples); `angular_gain_temperature` and
`rate_scale_factor` likewise at k_e,nom. Nonregular time constants are held at their typical
size here.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._progress import bar
from ..calibration.reduce import RateWindows, reduce
from ..data import MeasuredData
from ..units import DEG, DEG_PER_H, T_REF_C
from . import leftover
from .effects import CATALOGUE, Covariates, window_rate
from .noise import NOISE_GIVEN, NOISE_STILL, NoiseModel
from .problem import OPTIONAL, AbstractProblem, Fit, candidates_for, covariates_in
from .stats import (  # dwell.score, dwell.chi2_sf etc.: deprecated, see stats
    chi2_sf,
    covariance,
    level_test,
    score,
    wls,
)


def covariates(w: RateWindows, extra: dict | None = None) -> Covariates:
    """Covariates of each window: mean angle [rad], table rate [rad/s], temperature [°C];
    `extra` may give `amplitude`, `quadrature`, `accel_z`, `t_run` and `harmonic_gain`
    (the window average of a 2θ harmonic) per window."""
    extra = extra or {}
    kw = {k: jnp.asarray(v) for k, v in extra.items()}
    return Covariates(
        theta=jnp.asarray(w.wave_angle_deg * DEG),
        rate=jnp.asarray(w.table_rate_dps * DEG),
        temperature=jnp.asarray(w.temperature_c),
        temperature_lagged=jnp.asarray(w.temperature_c),
        **kw,
    )


def columns(name: str, c: Covariates, k_e: float) -> np.ndarray:
    """Regressor columns (W, q) of effect `name`: ∂(window rate)/∂p at the null
    ([`Effect.columns`][hrgjax.discovery.effects.Effect.columns])."""
    return CATALOGUE[name].columns(c, k_e)


def design(names, c: Covariates, k_e: float) -> tuple[np.ndarray, list[tuple[str, int]]]:
    """Stacked columns of several effects and the (effect, column) labels."""
    blocks, labels = [], []
    for n in names:
        g = columns(n, c, k_e)
        blocks.append(g)
        labels += [(n, j) for j in range(g.shape[1])]
    return np.concatenate(blocks, axis=1), labels


def _split(names, beta, every=False):
    """{effect: full parameter vector} from the regular parameters `beta` in `design` order
    (nonregular ones at their typical size), or from every parameter (`every`)."""
    out, i = {}, 0
    for n in names:
        full = []
        for p in CATALOGUE[n].params:
            if p.regular or every:
                full.append(beta[i])
                i += 1
            else:
                full.append(jnp.asarray(p.scale, dtype=float))
        out[n] = jnp.stack(full)
    return out


def model_rate(names, beta, c: Covariates, k_e: float, every: bool = False):
    """A window's measured pattern rate [rad/s] under the model `names` at parameters
    `beta` (the order of `design`; with `every`, all parameters, nonregular ones too), to
    all orders in the readout terms ([`window_rate`][hrgjax.discovery.effects.window_rate];
    the terms that scale the angular gain read the nominal `k_e`, as in `design`, which is
    this function's Jacobian at the null)."""
    return window_rate(_split(names, beta, every), c, k_e)


_SUPERSET = tuple(CATALOGUE)


def _positions(names) -> np.ndarray:
    """Where `design`'s regular parameters of `names` sit in the whole catalogue's vector."""
    where, i = {}, 0
    for n in _SUPERSET:
        for p in CATALOGUE[n].params:
            where[(n, p.name)] = i
            i += 1
    return np.asarray([where[(n, p.name)] for n in names for p in CATALOGUE[n].params if p.regular])


@jax.jit
def _model_and_jacobian(full, c, k_e):
    """The window rate over the whole catalogue (effects outside the model at their null,
    where their terms vanish exactly) and its Jacobian: one program per data shape for
    every model the search tries."""
    f = lambda v: model_rate(_SUPERSET, v, c, k_e, every=True)
    return f(full), jax.jacfwd(f)(full)


def refine(names, beta, c: Covariates, y, sigma, train, k_e: float, iterations: int = 3):
    """Gauss–Newton steps from the linear fit `beta` on the exact
    [`model_rate`][hrgjax.discovery.dwell.model_rate] (weighted, training rows `train`):
    the readout terms' second-order part (ε²/2 of the rate for a gain mismatch ε: 2·10⁻⁴ at
    a 2 % mismatch) is systematic, and a ripple of 1 % makes it visible at 5 °/s.

    **Returns:** `(beta, model rate, Jacobian)` at the refined parameters."""
    at = _positions(names)
    full = np.concatenate(
        [[0.0 if p.regular else p.scale for p in CATALOGUE[n].params] for n in _SUPERSET]
    )
    c = jax.tree.map(jnp.asarray, c)
    beta = np.asarray(beta, dtype=float)
    for _ in range(iterations + 1):
        full[at] = beta
        f, jac = _model_and_jacobian(jnp.asarray(full), c, k_e)
        f, jac = np.asarray(f), np.asarray(jac)[:, at]
        if _ == iterations:
            break
        jw = jac[train] / sigma[train][:, None]
        rw = (y[train] - f[train]) / sigma[train]
        step, *_ = np.linalg.lstsq(jw, rw, rcond=None)
        beta = beta + step
    return beta, f, jac


def target(w: RateWindows, k_e: float) -> np.ndarray:
    """Measured pattern rate of each window [rad/s]."""
    return -k_e * w.rate_dps * DEG


# -- the dwell-grid problem ----------------------------------------------------


def sampled_gain(t, theta) -> float:
    r"""What the least-squares slope over the samples at times `t` [s] sees of a 2θ harmonic
    while the pattern turns at the samples' own slope v = slope of `theta` [rad] on `t`:
    with τᵢ = tᵢ − t̄, a term A·sin 2θ(t) of the angle gives the slope
    $2A\cos 2\bar\theta\cdot v\,G$ (and a rate term ∝ sin 2θ its window value times G), with
    $G = \sum_i \tau_i \sin(2v\tau_i) / (2v\sum_i\tau_i^2)$ — the discrete sum the slope
    really forms, not the continuous $3(\sin x - x\cos x)/x^3$ of
    [`window_gain`][hrgjax.discovery.effects.window_gain], which at 6 samples of a 3-s window
    is 5·10⁻⁴ too large (a 2θ term fitted on moving windows came out that much too small).
    The in-phase part is exact for any sampling; uneven sampling adds an out-of-phase part
    $\propto \sum_i\tau_i(\cos 2v\tau_i - 1)$ that vanishes for times symmetric about t̄ (the
    windows of [`reduce`][hrgjax.calibration.reduce] on a regular log). 1 for fewer than
    two samples."""
    t = np.asarray(t, float)
    if t.size < 2:
        return 1.0
    tau = t - t.mean()
    s_tt = float(tau @ tau)
    if s_tt == 0.0:
        return 1.0
    v = float(tau @ (np.asarray(theta, float) - np.mean(theta))) / s_tt
    # τ sin(2vτ)/(2v) = τ² sinc(2vτ/π): exact, and 1 at v = 0
    return float(np.sum(tau**2 * np.sinc(2.0 * v * tau / np.pi)) / s_tt)


def window_extras(data: MeasuredData, w: RateWindows) -> dict:
    """Per-window means of the optional columns (and `t_run`, the 2θ `harmonic_gain` and the
    `arc` [rad] the pattern sweeps)."""
    extra: dict[str, list] = {"t_run": [], "harmonic_gain": [], "arc": []}
    for key, col in OPTIONAL.items():
        if col in data:
            extra[key] = []
    starts = {int(data.run[idx[0]]): idx for idx in data.run_indices()}
    for run, a, b, tm in zip(w.run, w.start, w.stop, w.t_mid, strict=True):
        idx = starts[int(run)]
        extra["t_run"].append(tm - data["time_s"][idx[0]])
        t, theta = data["time_s"][idx[a:b]], data["wave_angle_deg"][idx[a:b]] * DEG
        arc = np.ptp(theta) if b - a > 1 else 0.0
        extra["harmonic_gain"].append(sampled_gain(t, theta))
        extra["arc"].append(arc)
        for key, col in OPTIONAL.items():
            if key in extra:
                extra[key].append(float(np.mean(data[col][idx[a:b]])))
    return {k: np.asarray(v) for k, v in extra.items()}


def rate_windows(data: MeasuredData, k_e: float, window_s: float):
    """The dwell runs of `data` as windows of `window_s` [s]
    ([`reduce`][hrgjax.calibration.reduce]): `(windows, measured pattern rate [rad/s],
    covariates, arc [rad] the pattern sweeps in each)` — the rows of the dwell regression,
    on dwell grids and in a mixed log alike."""
    w = reduce(data, k_e, window_s=window_s)
    extra = window_extras(data, w)
    arc = extra.pop("arc")
    return w, target(w, k_e), covariates(w, extra), arc


def output_gain(parameters: dict, k_e: float) -> float:
    """The angular gain that turns a fit's pattern rates into input rates: the fit's own
    `angular_gain` where the data determine it (rotations: within 10 %), else the nominal
    `k_e` (static data leave it free) — the gain `discover` reports its parameters at, so
    the gaps and the noise floor are on the same scale as the parameters (a nominal 0.277
    passed for 0.554 once doubled them)."""
    p = parameters.get("angular_gain", {}).get("k_e")
    if p is None or not np.isfinite(p["value"]) or p["value"] <= 0:
        return float(k_e)
    std = p.get("std")
    if std is None:  # no σ where σ_b is not pinned (`trust.honest`): its σ at σ̂_b decides
        std = p.get("std_textbook")
    if std is None or not np.isfinite(std) or std > 0.1 * p["value"]:
        return float(k_e)
    return float(p["value"])


def _gap(resid, w: RateWindows, runs, k_e):
    """RMS over `runs` of the run-mean equivalent-input-rate residual [°/h] (`k_e`: the
    fit's `output_gain`)."""
    means = [np.mean(resid[w.run == r]) for r in runs]
    return float(np.sqrt(np.mean(np.square(means)))) / k_e / DEG_PER_H


def _floor(sigma, w: RateWindows, runs, k_e):
    return float(np.sqrt(np.mean(_mean_variances(sigma, w, runs)))) / k_e / DEG_PER_H


def _mean_variances(sigma, w: RateWindows, runs):
    """The variance each run's mean window residual has from the noise [rad²/s²]."""
    return np.asarray([np.mean(sigma[w.run == r] ** 2) / np.sum(w.run == r) for r in runs])


GAP_LEVEL = 0.01
"""How rare under the noise alone a held-out gap must be before an effect that widens it is
refused (`DwellProblem.widens`)."""


class DwellProblem(AbstractProblem):
    """Dwell-grid discovery (module docstring): every run's windows
    ([`reduce`][hrgjax.calibration.reduce]) give rates [rad/s of pattern rate], fitted by
    weighted least squares on the catalogue's columns (Gauss–Newton on the exact window rate
    where readout terms are in the model), with each window's σ from the noise model
    (`_noise_scale`: the one given, or the still stretches', or the rotation runs').

    **Arguments:** `data` ([`hrgjax.MeasuredData`][] of dwell runs), `k_e` (nominal angular
    gain), `window_s` (window length [s]), `held` (held-out run ids), `noise` (a known
    [`hrgjax.Noise`][], or None: estimated from the data).
    """

    def __init__(self, data, k_e, window_s, held, noise=None):
        self.k_e, self.held = k_e, held
        self.k_out = float(k_e)  # the current model's output_gain, once one is fitted
        w, self.y, self.c, self.arc = rate_windows(data, k_e, window_s)
        self.w = w
        self.have = covariates_in(data)
        self.train = ~np.isin(w.run, held)
        self.sigma, self.nm, self.noise_source = _noise_scale(data, w, k_e, noise, window_s)

    @classmethod
    def from_data(cls, data, held, *, nominal, catalogue, k_e, window_s, noise, block_s):
        """The dwell problem of `data` (`nominal`, `catalogue` and `block_s` are the
        continuous records'; `noise`: a known [`hrgjax.Noise`][] or None)."""
        return cls(data, k_e, window_s, held, noise)

    def candidates(self, nominal):
        return candidates_for(self.have, nominal)

    def fit(self, model):
        fit = _fit(model, self.c, self.y, self.sigma, self.train, self.w, self.held, self.k_e)
        self.k_out = output_gain(fit.parameters, self.k_e)
        return fit

    def floor(self):
        """The held-out gap the noise alone gives [°/h], at the current model's angular gain
        (`k_out`: the one the report states)."""
        return _floor(self.sigma, self.w, self.held, self.k_out)

    def after_accept(self, fit):
        self.k_out = output_gain(fit.parameters, self.k_e)
        return self, fit

    def consistency(self, fit, name):
        """Not defined on dwell grids (one run is one grid point)."""
        return None

    def widens(self, gap, gap_after):
        """Whether an effect that moves the held-out gap from `gap` to `gap_after` [°/h]
        widens it beyond the noise: it rises, and the noise alone gives a gap that large in
        fewer than [`GAP_LEVEL`][hrgjax.discovery.dwell.GAP_LEVEL] of sessions (the gap² is
        a sum of the held-out runs' χ²₁ weighted by their mean's variance: ν·(gap/floor)²
        against χ²_ν, ν by Satterthwaite). A rise within the noise says nothing against the
        effect: refusing every rise left a `bias_temperature` of −0.0012 °/h/°C (ΔBIC 30 to
        800) unnamed on 13 of 60 grids (`benchmarks/discovery_gap_guard.py`)."""
        if not np.isfinite(gap_after):  # no gap to judge by: refused, as before
            return True
        if not gap_after > gap:
            return False
        v = _mean_variances(self.sigma, self.w, self.held)  # the floor's, read once
        nu = float(np.sum(v) ** 2 / np.sum(v**2))
        floor = float(np.sqrt(np.mean(v))) / self.k_out / DEG_PER_H  # = self.floor()
        return chi2_sf(nu * (gap_after / floor) ** 2, nu) < GAP_LEVEL

    def structure_left(self, fit, floor):
        """The held-out gap is more than twice the noise floor."""
        return fit.gap > 2.0 * floor

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
            self.row_classes(),
        )

    def residuals(self, fit):
        """What the figure draws of `fit`: every window's drift residual [°/h] (as input
        rate) with its wave angle [°], temperature [°C] and whether it is static."""
        w = self.w
        return {
            "wave_angle_deg": np.asarray(w.wave_angle_deg),
            "temperature_c": np.asarray(w.temperature_c),
            "static": np.asarray(w.static),
            "drift_dph": -np.asarray(fit.resid) / output_gain(fit.parameters, self.k_e) / DEG_PER_H,
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
            "arc": self.arc[tr],
        }
        return {k: g / self.sigma[tr][:, None] for k, g in leftover.columns(cov).items()}

    def leftover(self, fit):
        """The strongest shape left in `fit`'s training residual
        ([`describe`][hrgjax.discovery.leftover.describe])."""
        k = output_gain(fit.parameters, self.k_e)
        return leftover.describe(fit.r, fit.j, self.shape_columns, k, classes=self.row_classes())

    def run_order_column(self):
        """A bias rising linearly from the first training run to the last (runs in id
        order: a dwell grid shares one switch-on, so a drift through the session is not a
        run bias), whitened, on the training windows."""
        run = np.asarray(self.w.run)[self.train]
        runs = np.unique(run)
        return np.searchsorted(runs, run) / max(runs.size - 1, 1) / self.sigma[self.train]

    def row_classes(self):
        """Static (1) and moving (0) training windows: their σ come from different parts of
        the noise model."""
        return np.asarray(self.w.static)[self.train].astype(int)

    def noise_report(self):
        k_e, w = self.k_out, self.w
        out = dict.fromkeys(NoiseModel(0.0).report(k_e)) if self.nm is None else self.nm.report(k_e)
        out.pop("run_bias_dph")  # one switch-on: its bias is the fitted `bias`
        return out | {
            "sigma_static_dph": _sigma_dph(self.sigma, w.static, k_e),
            "sigma_moving_dph": _sigma_dph(self.sigma, ~w.static, k_e),
            "source": self.noise_source,
        }


def _sigma_dph(sigma, mask, k_e):
    return float(np.median(sigma[mask])) / k_e / DEG_PER_H if np.any(mask) else None


NOISE_TURNING = (
    "the rotation runs' angles (no still stretch: second differences up to the window's "
    "length, each run's turn removed; noise= gives it instead)"
)
"""The dwell problem's noise `source` (its `noise_report`): where the windows' σ come from."""


def _noise_scale(data: MeasuredData, w: RateWindows, k_e, noise=None, window_s=None):
    """Standard error of each window's pattern rate [rad/s]: the exact least-squares slope
    error under a [`NoiseModel`][hrgjax.pattern_noise.NoiseModel]: the known `noise`
    ([`hrgjax.Noise`][]) where given, else the one of the data's still stretches, else
    (every run turns) the one of the rotation runs' angles (`turning_noise_model`). The
    windows' own batch-means errors, the fallback once, rest on 1 degree of freedom each at
    6 samples a window: weights up to 10³× off, and false finds on rotation-only grids.

    **Returns:** (σ per window, the noise model, its source in words)."""
    if noise is not None:
        nm = NoiseModel.from_gyro(noise, k_e)
        return window_sigma(nm, data, w), nm, NOISE_GIVEN
    try:
        nm, source = NoiseModel.estimate(data), NOISE_STILL
    except ValueError:
        nm, source = turning_noise_model(data, window_s), NOISE_TURNING
    return window_sigma(nm, data, w), nm, source


def turning_noise_model(data: MeasuredData, window_s=None) -> NoiseModel:
    """The noise model of a log with no still stretch, from its rotation runs: each run's
    angle less its straight line (the constant turn; second differences remove it anyway)
    read as a still stretch by [`NoiseModel.estimate`][hrgjax.pattern_noise.NoiseModel.estimate]
    with lags up to `window_s` [s] (None: its default) — the lags a window's slope error
    rests on, and short enough that the 2θ drift terms swept as the pattern turns stay out
    (at all lags up to 15 s they raised the windows' σ 15 %; up to the 3-s window, within
    1–10 % of the still stretches' model on 5–40 °/s grids).

    **Raises:** `ValueError` in one line when the runs are too short to read it."""
    cols = {k: np.array(data[k], float) for k in ("time_s", "temperature_c", "wave_angle_deg")}
    for idx in data.run_indices():
        t, th = cols["time_s"][idx], cols["wave_angle_deg"][idx]
        if idx.size > 1 and np.ptp(t) > 0:
            cols["wave_angle_deg"][idx] = th - np.polyval(np.polyfit(t - t.mean(), th, 1),
                                                          t - t.mean())  # fmt: skip
    cols["table_rate_dps"] = np.zeros(len(data))
    if "run" in data:
        cols["run"] = np.asarray(data["run"])
    lag = 1024.0 if window_s is None else float(window_s)
    low, high, _ = plausible.RANGES["temperature_c"]  # data's own passed when it was built
    temp = cols["temperature_c"]  # (perhaps in a plausible.relaxed block that has ended)
    with plausible.relaxed(temperature_c=(min(low, temp.min()), max(high, temp.max()))):
        still = MeasuredData(cols)
    try:
        return NoiseModel.estimate(still, max_lag_s=lag)
    except ValueError as e:
        raise ValueError(
            "the log has no still stretch for the noise model, and its runs are too short to "
            f"read it from their angles ({e}); add static runs or pass noise=hrgjax.Noise(...)"
        ) from None


def window_sigma(nm: NoiseModel, data: MeasuredData, w: RateWindows) -> np.ndarray:
    """Standard error [rad/s] of each window's pattern rate under the noise model `nm`: the
    exact least-squares slope error over the window's samples."""
    sigma = np.empty(len(w))
    times = {int(data.run[idx[0]]): data["time_s"][idx] for idx in data.run_indices()}
    seen: dict[tuple, float] = {}  # windows of one sampling share their σ
    for i, (run, a, b) in enumerate(zip(w.run, w.start, w.stop, strict=True)):
        t = times[int(run)][a:b]
        key = np.round(t - t[0], 9).tobytes()
        if key not in seen:
            seen[key] = nm.slope_sigma(t)
        sigma[i] = seen[key]
    return sigma


def _fit(model, c, y, sigma, train, w, held, k_e):
    g, labels = design(model, c, k_e)
    beta, r, cov = wls(g[train], y[train], sigma[train])
    resid = y - g @ beta
    if any(CATALOGUE[n].where == "readout" for n in model):
        # The readout terms' higher orders, where they matter (a 1 % ripple at 5 °/s).
        beta2, f, jac = refine(model, beta, c, y, sigma, train, k_e)
        if np.max(np.abs(f - g @ beta2) / sigma) > 0.1:
            beta, g = beta2, jac
            resid = y - f
            r = resid[train] / sigma[train]
            cov = covariance(g[train] / sigma[train][:, None])
    held_mask = np.isin(w.run, held)
    heldout_chi2 = float(np.sum((resid[held_mask] / sigma[held_mask]) ** 2))
    err = np.sqrt(np.diag(cov))
    params = {}
    for (name, j), b, e in zip(labels, beta, err, strict=True):
        pname = CATALOGUE[name].regular_names[j]
        params.setdefault(name, {})[pname] = {"value": float(b), "std": float(e)}
    return Fit(
        model=tuple(model),
        parameters=params,
        r=r,
        j=g[train] / sigma[train][:, None],
        chi2=float(r @ r),
        heldout_chi2=heldout_chi2,
        gap=_gap(resid, w, held, output_gain(params, k_e)),
        resid=resid,
    )


def _screen(current, cands, model, c, sigma, train, y, w, held, k_e, classes=None):
    n = int(np.sum(train))
    rows = []
    with bar(len(cands), f"screening {len(cands)} candidates", unit="effect") as progress:
        for name in cands:
            progress.set_postfix_str(name)
            row = _screen_one(name, current, model, c, sigma, train, y, w, held, k_e, n, classes)
            progress.update(1)
            if row is not None:
                rows.append(row)
    rows.sort(key=lambda r: -r["score"])
    return rows


def _screen_one(name, current, model, c, sigma, train, y, w, held, k_e, n, classes=None):
    """Score test and refit of one candidate (None when it leaves the training data alone).
    `score` is at the windows' σ (it ranks the candidates and weighs them against the
    generic shapes); `p_value` judges it at the level the residual shows per window class
    (`classes`) once the candidate is fitted, F tail
    ([`level_test`][hrgjax.discovery.stats.level_test]): the σ come from a noise model
    estimated on 60-s still stretches, whose angle random walk is often read as 0 (static
    windows' residual mean square 2–6: a χ²_q p fell below the acceptance level in 15 % of
    null grids)."""
    g = columns(name, c, k_e)
    if not np.any(g[train]):
        return None
    gw = g[train] / sigma[train][:, None]
    s, alias, step = score(current.r, current.j, gw)
    q = g.shape[1]
    refit = _fit(model + [name], c, y, sigma, train, w, held, k_e)
    lam = current.chi2 - refit.chi2
    names = CATALOGUE[name].regular_names
    return {
        "effect": name,
        "score": float(s),
        "p_value": level_test(current.r, current.j, gw, classes)[3],
        "delta_bic": float(lam - q * math.log(n)),
        "aliasing": alias,
        "gap_after": refit.gap,
        "heldout_gain": current.heldout_chi2 - refit.heldout_chi2,
        # in model units, each {"value", "std"} (the JSON's ranking gives them in user units
        # with their σ: they were values only, so every σ there read null)
        "params": {
            k: {"value": v["value"], "std": v.get("std")}
            for k, v in refit.parameters[name].items()
            if k in names
        },
        "refit": refit,
        "_columns": lambda: gw,
    }
