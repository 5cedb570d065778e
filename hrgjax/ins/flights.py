r"""Monte Carlo flights: a sampled motion flown by many IMUs of one grade, each navigated
free-inertially and by the loosely-coupled filter and smoother, against the truth.

Each run draws its own unit of the IMU's grade ([`random_unit`][hrgjax.ins.sensors.random_unit]:
biases, scale factors, misalignments), sensor noise, GNSS noise and initial navigation error
(from the filter's initial covariance), all from one key per run; the runs are vmapped in
chunks (one compiled program for every chunk) with a progress bar. The free-inertial baseline
is altitude aided (its height and vertical velocity held to the truth: the free vertical
channel diverges with a 570-s time constant and would swamp everything else).

The NEES compares each epoch's estimate with the truth there: for the sensor states, the
run's total bias of the interval ending at that epoch (fixed, Gauss–Markov, random walk,
extra rate error: all but the white noise) and its drawn scale factors; with Gauss–Markov
states (`LooselyCoupled(gauss_markov=True)`) the Gauss–Markov bias *at* the epoch is theirs
(the state is the bias at the fix, not its mean over the last IMU interval) and the rest's
interval mean the fixed-bias states' (`ImuModel.apply(..., return_bias="gauss_markov")`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _checks, _upstream, kalman
from .._progress import bar
from .._x64 import require_x64
from .consistency import error_states, nees_band, nis_check, whitened_errors
from .ekf import LooselyCoupled, feedback, loosely_coupled, smooth
from .gnss import measure
from .mechanization import mechanize, navigation_errors
from .motion import Truth
from .sensors import ImuModel, random_unit


class Flights(eqx.Module):
    """Errors of R Monte Carlo runs at the M GNSS epochs (the start first).

    **Fields:** `t` (M,) [s]; `gnss_valid` (M,) whether a fix was taken; for each of
    `filter`, `smoother`, `free` (free inertial, its height and vertical velocity held to the
    truth) a dict with `position` (R, M, 3) [m, north
    east down], `velocity` (R, M, 3) [m/s], `attitude` (R, M, 3) [rad]; for `filter` and
    `smoother` also `sigma` (R, M, 9) (position [m], velocity [m/s], attitude [rad], 1σ) and
    `nees` (R, M) of all the filter's states and `nees_navigation` (R, M) of the nine
    navigation states alone; `nis` (R, M) (NaN without a fix); `n_states`; `innovation_dim`."""

    t: jax.Array
    gnss_valid: jax.Array
    filter: dict
    smoother: dict
    free: dict
    nis: jax.Array
    n_states: int = eqx.field(static=True)
    innovation_dim: int = eqx.field(static=True)

    @property
    def runs(self) -> int:
        """The number of runs R."""
        return int(self.nis.shape[0])

    def summary(self) -> dict:
        """JSON-ready figures: horizontal position error RMS and maximum over runs and
        epochs [m] for the filter, smoother and free inertial; the largest horizontal error
        in GNSS gaps; the fraction of epochs whose mean NEES lies inside its 95 % band, for
        all states and for the nine navigation states, each with a verdict ("consistent",
        "conservative", "overconfident", "undefined": `verdict`); the mean NIS (its
        expectation is the innovation dimension; None when every fix fell in an outage) and
        `nis_check`, its truth-free verdict over all runs' fixes
        ([`nis_check`][hrgjax.ins.consistency.nis_check]: the 99 % χ² band of the mean, the first
        five fixes of each run against their 99.9 % point, and what to print when the filter's
        model does not fit the data)."""
        gap = ~np.asarray(self.gnss_valid)
        gap[0] = False
        out = {"runs": self.runs, "epochs": int(self.t.shape[0]), "duration_s": float(self.t[-1])}
        lo, hi = nees_band(self.n_states, self.runs)
        lo9, hi9 = nees_band(9, self.runs)
        for name in ("filter", "smoother", "free"):
            d = getattr(self, name)
            hor = np.linalg.norm(np.asarray(d["position"])[..., :2], axis=-1)
            row = {
                "horizontal_rms_m": float(np.sqrt(np.mean(hor**2))),
                "horizontal_max_m": float(hor.max()),
                "final_horizontal_median_m": float(np.median(hor[:, -1])),
            }
            if gap.any():
                row["gap_horizontal_max_m"] = float(hor[:, gap].max())
            if "nees" in d:
                m = np.asarray(d["nees"]).mean(0)[1:]
                row["nees_mean"] = float(m.mean())
                row["nees_inside_95_band"] = float(np.mean((m > lo) & (m < hi)))
                m9 = np.asarray(d["nees_navigation"]).mean(0)[1:]
                row["nees_navigation_mean"] = float(m9.mean())
                row["nees_navigation_inside_95_band"] = float(np.mean((m9 > lo9) & (m9 < hi9)))
                row["nees_verdict"] = verdict(m, lo, hi)
                row["nees_navigation_verdict"] = verdict(m9, lo9, hi9)
            out[name] = row
        out["nees_band_95"] = [float(lo), float(hi)]
        out["nees_navigation_band_95"] = [float(lo9), float(hi9)]
        out["n_states"] = self.n_states
        nis = np.asarray(self.nis)  # NaN where no fix: None when no epoch had one
        out["nis_mean"] = None if np.isnan(nis).all() else float(np.nanmean(nis))
        out["innovation_dim"] = self.innovation_dim
        out["nis_check"] = nis_check(self.nis, self.innovation_dim)
        return out


def verdict(mean_nees, lo, hi) -> str:
    """A filter's consistency from its mean NEES per epoch `mean_nees` [-] and the 95 % band
    (`lo`, `hi`) of that mean: "consistent" when the mean NEES is inside its 95 % band on ≥ 90 % of epochs; else
    "conservative" (σ larger than the errors: the mean below the band more often than above)
    or "overconfident"; "undefined" where the NEES is not finite at some epoch (a covariance
    that is not positive definite there: [`nees`][hrgjax.ins.consistency.nees])."""
    if not np.all(np.isfinite(mean_nees)):
        return "undefined"
    if np.mean((mean_nees > lo) & (mean_nees < hi)) >= 0.9:
        return "consistent"
    return (
        "conservative" if np.mean(mean_nees <= lo) > np.mean(mean_nees >= hi) else "overconfident"
    )


def _sigmas(res):
    d = jnp.sqrt(jnp.diagonal(res.P, axis1=-2, axis2=-1)[..., 3:9])
    return jnp.concatenate([res.position_sigma(), d], -1)


def _one_run(
    truth: Truth, imu: ImuModel, settings: LooselyCoupled, m, gnss_mask, key, gyro_rate_error
):
    k_unit, k_imu, k_gnss, k_init = jax.random.split(key, 4)
    sensor = random_unit(imu, k_unit)
    split = "gauss_markov" if settings.gauss_markov else True
    dth, dv, bias_g, bias_a, *gm = sensor.apply(
        k_imu, truth.dtheta, truth.dv, truth.dt, gyro_rate_error, return_bias=split
    )
    fixes = measure(truth, settings.gnss, k_gnss)
    fixes = eqx.tree_at(lambda f: f.valid, fixes, fixes.valid & gnss_mask)
    p0 = settings.initial_covariance(truth.initial)
    e0 = kalman.psd_factor(p0[:9, :9]) @ jax.random.normal(k_init, (9,))
    start = feedback(truth.initial, -e0)  # the truth plus the drawn error
    res = loosely_coupled(settings, start, dth, dv, truth.dt, fixes)
    sm = smooth(res)
    vertical = (truth.states.h[1:], truth.states.v_ned[1:, 2])
    free = mechanize(start, dth, dv, truth.dt, earth=truth.earth, every=m, vertical=vertical)
    tn = truth.states[::m]
    n = truth.dtheta.shape[0]
    at = jnp.concatenate([jnp.zeros(1, int), jnp.arange(m - 1, n, m)])  # each epoch's interval
    scales = (sensor.gyro_scale, sensor.accel_scale)

    def summary(r, with_cov):
        p, v, a = navigation_errors(r.nav if with_cov else r, tn, truth.earth)
        d = {"position": p, "velocity": v, "attitude": a}
        if with_cov:
            gms = [b[at] for b in gm]  # the Gauss–Markov parts, with Gauss–Markov states
            e = error_states(r, tn, bias_g[at], bias_a[at], truth.earth, *scales, *gms)
            d["sigma"] = _sigmas(r)
            w2 = whitened_errors(e, r.P) ** 2  # one factorisation for both NEES
            d["nees"] = jnp.sum(w2, -1)
            d["nees_navigation"] = jnp.sum(w2[..., :9], -1)
        return d

    return summary(res, True), summary(sm, True), summary(free, False), res.nis


def fly(
    truth: Truth,
    imu: ImuModel,
    settings: LooselyCoupled,
    *,
    key,
    runs: int = 1,
    chunk: int = 16,
    gyro_rate_error=None,
) -> Flights:
    """Fly `truth` `runs` times (module docstring).

    **Arguments:** `truth` a [`Truth`][hrgjax.ins.motion.Truth]; `imu` the
    [`ImuModel`][hrgjax.ins.sensors.ImuModel] of the simulated sensors (its fixed biases,
    scale factors and misalignments are the σ of each run's drawn ones); `settings` the
    [`LooselyCoupled`][hrgjax.ins.ekf.LooselyCoupled] filter (its `gnss` makes the fixes);
    `key` a PRNG key; `runs`; `chunk`: runs per vmapped batch; `gyro_rate_error`: an extra
    gyro error (N, 3) [rad/s] common to all runs (e.g. an hrgjax gyro's simulated drift).

    **Returns:** [`Flights`][hrgjax.ins.flights.Flights].

    **Raises:** `TypeError` or `ValueError`, one line, before any work, for a `truth`,
    `imu`, `settings` or `key` not of its type, `runs` or `chunk` not a whole number >= 1,
    a `gyro_rate_error` not finite numbers; `RuntimeError`, one line, when a run's filter or free-inertial solution stops
    being finite (the message of [`loosely_coupled`][hrgjax.ins.ekf.loosely_coupled] or
    [`mechanize`][hrgjax.ins.mechanization.mechanize]). `imu`'s values are held to
    `ImuModel`'s rules (finite, densities ≥ 0, the `imu_*` ranges) where it was built; each
    run's drawn unit only to be finite: a draw past a range's bound is a Gaussian tail, not
    a unit typo, and flies (σ 0.06 against |gyro_scale| < 0.1: 6 units of 16)."""
    require_x64("ins.fly")
    for name, x, kind in (("truth", truth, Truth), ("imu", imu, ImuModel),
                          ("settings", settings, LooselyCoupled)):  # fmt: skip
        if not isinstance(x, kind):
            raise TypeError(
                f"fly: {name} must be of type {kind.__name__}; got {_checks.describe(x)}"
            )
    _checks.check_key("fly: key", key, "one key: fly splits it into the runs' keys")
    for name, x in (("runs", runs), ("chunk", chunk)):  # 2.0 or np.int64(2) too; not True
        _checks.whole_number(f"fly: {name}", x, "a whole number >= 1", minimum=1)
    runs, chunk = int(runs), int(chunk)
    if gyro_rate_error is not None:  # its shape: ImuModel.apply's check
        _checks.check_numbers("fly: gyro_rate_error", gyro_rate_error, "(N, 3) or (3,) [rad/s]")
        _checks.check_finite_host("fly: gyro_rate_error", gyro_rate_error)
    n = truth.dtheta.shape[0]
    idx = settings.gnss.epochs(n, truth.dt)
    if idx.size == 0 or idx[-1] != n:
        raise ValueError(
            f"the motion's {n * truth.dt:g} s must be a whole number of GNSS intervals "
            f"(1/{settings.gnss.rate_hz} s)"
        )
    epochs = np.concatenate([[0], idx])
    t = idx * truth.dt
    mask = np.ones(idx.size, bool)
    for a, b in settings.gnss.outages:
        mask &= ~((t >= a) & (t <= b))
    # the fix rate stays static; the outages travel as a mask (no recompile per outage set)
    plain = eqx.tree_at(lambda s: s.gnss, settings, settings.gnss.without_outages())
    size = min(chunk, runs)
    keys = jax.random.split(key, -(-runs // size) * size)
    parts = []
    # a check failing inside the batched program (the filter's or the free inertial's
    # finiteness: a run that diverged) is raised as its one line, as loosely_coupled does
    try:
        # a batch is one compiled call (at 100 Hz ~20 s to compile, ~1.2 s a run): the bar
        # ticks so its clock moves, and says which runs fly (smaller batches cost 4×: 6 runs
        # vmapped 7.3 s warm, one at a time 31 s)
        ticking = bar(runs, "flights", unit="run", tick=True)
        with ticking as progress, _upstream.quiet_failed_checks():
            for i in range(0, keys.shape[0], size):
                batch = keys[i : i + size]
                progress.set_postfix_str(f"runs {i + 1}–{min(i + size, runs)}, one vmapped call")
                part = _run_batch(
                    truth, imu, plain, int(idx[0]), jnp.asarray(mask), batch, gyro_rate_error
                )
                parts.append(jax.block_until_ready(part))
                progress.update(min(size, runs - i))
    except (*_upstream.CHECK_ERRORS, eqx.EquinoxRuntimeError) as err:
        message = _upstream.failed_check_message(err)
        if message is None:
            raise
        raise RuntimeError(f"ins.fly: in one or more runs, {message}") from None
    out = jax.tree_util.tree_map(lambda *a: jnp.concatenate(a)[:runs], *parts)
    f, s, free, nis = out
    valid = np.concatenate([[False], np.asarray(truth.gnss)[idx] & mask])
    dim = 6 if settings.gnss.use_velocity else 3
    return Flights(
        jnp.asarray(epochs * truth.dt), jnp.asarray(valid), f, s, free, nis, settings.n_states, dim
    )


@eqx.filter_jit
def _run_batch(truth, imu, settings, m, gnss_mask, keys, gyro_rate_error):
    one = lambda k: _one_run(truth, imu, settings, m, gnss_mask, k, gyro_rate_error)
    return jax.vmap(one)(keys)
