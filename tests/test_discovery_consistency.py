"""Per-run consistency ("evidence must repeat", DISCOVERY.md §2.1) on logs whose runs do not
resolve the effect one by one, and runs whose refit does not converge.

Each run's refit is set by hand (`records.fit_each_run` replaced by known estimates and
informations) on a problem of small continuous runs, so that the truth — what each run and
each group of runs says of the effect — is known without a fit."""

import inspect
import math

import numpy as np
import pytest
from helpers import still_ramps

from hrgjax.discovery import NoiseModel, continuous, generate, records
from hrgjax.discovery.search import discover

K_E = 0.554
NAME = "thermal_rate"  # one regular parameter, c_Tdot
MIN_AGREEMENT = inspect.signature(discover).parameters["min_agreement"].default


def _problem(n_runs):
    """A continuous problem of `n_runs` short temperature ramps, every run training."""
    data = still_ramps([5.0] * n_runs)
    noise = NoiseModel.from_gyro(generate.base_gyro().noise, K_E)
    return continuous.ContinuousProblem(data, ["bias", "angular_gain", NAME], K_E, [], noise)


class _Fit:
    def __init__(self, z):
        self.z = z


def _consistency(monkeypatch, estimates, infos, pooled, converged=None):
    """`consistency` of NAME at the pooled scaled value `pooled`, each run `i`'s own refit
    giving `estimates[i]` with information `infos[i]` (converged unless `converged[i]` is
    False)."""
    problem = _problem(len(estimates))
    (i,) = problem.layout.index(NAME, which=True)
    z = problem.z_null.copy()
    z[i] = pooled
    ok = np.ones(len(estimates), bool) if converged is None else np.asarray(converged)

    def fit_each_run(layout, basis, z0, group):
        runs = list(group.run)
        zs = np.tile(np.asarray(z0), (len(runs), 1))
        zs[:, i] = [estimates[r] for r in runs]
        js = np.sqrt(np.asarray([infos[r] for r in runs], float))[:, None, None]
        return zs, ok[runs], js

    monkeypatch.setattr(records, "fit_each_run", fit_each_run)
    # these fits have no residual to read a noise level from: the χ² tail (`records.repeats`)
    monkeypatch.setattr(continuous.ContinuousProblem, "level", lambda self, fit, idx: (1.0, 0))
    return problem.consistency(_Fit(z), NAME)


def test_many_weak_runs_of_a_real_effect_are_pooled_into_groups_that_agree(monkeypatch):
    """Twelve runs, none resolving the effect (p̄ᵀC_i p̄ = 0.3: 0.55σ each), half of them
    pointing the wrong way alone; every four consecutive runs together put it at 1.1σ and
    their information-weighted estimate is the true one. Once no run resolved it, the
    check was skipped (agreement None): now three groups of four are compared, all agree."""
    estimates = np.tile([2.5, -0.5], 6)  # the truth is 1.0 in every run: noise ±1.5
    infos = np.full(12, 0.3)
    cons = _consistency(monkeypatch, estimates, infos, pooled=1.0)
    assert cons["agreement"] == 1.0
    assert cons["units"] == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]]
    assert cons["reason"] is None
    # each group's estimate is the information-weighted mean: exactly the truth, χ² = 0
    assert cons["dof"] == 2 and cons["p_value"] == pytest.approx(1.0)
    assert cons["unconverged"] == []
    assert len(cons["per_run"]) == 12  # every run's own refit still listed


def test_an_effect_whose_sign_flips_between_halves_is_refused(monkeypatch):
    """Eight weak runs (0.55σ each), the first four at +3, the last four at −1: pooled
    (+1) the effect looks real, but it does not repeat — the halves disagree. The old rule
    saw no run resolving it and let it pass unchecked; the groups now refuse it."""
    estimates = np.r_[np.full(4, 3.0), np.full(4, -1.0)]
    infos = np.full(8, 0.3)
    pooled = np.average(estimates, weights=infos)
    assert pooled == pytest.approx(1.0)
    cons = _consistency(monkeypatch, estimates, infos, pooled=pooled)
    assert cons["agreement"] is not None and cons["agreement"] < MIN_AGREEMENT
    assert cons["agreement"] == 0.5 and cons["units"] == [[0, 1, 2, 3], [4, 5, 6, 7]]
    # χ² of the two groups about the pooled value: 1.2·(3−1)² + 1.2·(−1−1)² = 9.6 on 1 dof
    assert cons["dof"] == 1
    assert cons["p_value"] == pytest.approx(math.erfc(math.sqrt(9.6 / 2)), rel=1e-6)


def test_runs_that_resolve_the_effect_are_compared_alone(monkeypatch):
    """Two runs resolve it (4σ, 3σ): as before, only they count (the weak runs' signs are
    noise), each its own unit — with one weak run pointing the wrong way."""
    estimates = np.array([-2.0, 1.1, 0.3, 0.9])
    infos = np.array([0.1, 16.0, 0.2, 9.0])
    cons = _consistency(monkeypatch, estimates, infos, pooled=1.0)
    assert cons["units"] == [[1], [3]] and cons["agreement"] == 1.0
    assert cons["dof"] == 1
    # χ² about the pooled value: 16·0.1² + 9·0.1² = 0.25 on 2 − 1 dof; χ²₁ tail = erfc(√(x/2))
    assert cons["p_value"] == pytest.approx(math.erfc(math.sqrt(0.25 / 2)), rel=1e-6)


def test_where_no_two_parts_resolve_it_the_check_says_why(monkeypatch):
    """One run carries all the evidence: no split of the runs into two parts each resolving
    it exists, so there is nothing to repeat — agreement None, with the reason (the held-out
    rule is then what asks it to repeat). With runs that do not even resolve it together,
    the reason says so."""
    cons = _consistency(monkeypatch, [0.2, 1.0, 0.1, 0.4], [0.1, 30.0, 0.1, 0.1], pooled=1.0)
    assert cons["agreement"] is None and cons["units"] == []
    assert "one part carries it" in cons["reason"]
    cons = _consistency(monkeypatch, [0.2, 1.0, 0.1], [0.1, 0.2, 0.1], pooled=1.0)
    assert cons["agreement"] is None and "do not resolve it" in cons["reason"]


def test_unconverged_runs_are_reported_and_do_not_vote(monkeypatch):
    """Two of six runs' refits did not converge: they were dropped silently; now they are
    listed, and neither agree nor disagree (the four others, each resolving it, decide)."""
    estimates = np.array([1.2, -5.0, 0.8, 1.1, -5.0, 0.9])
    infos = np.full(6, 4.0)
    converged = [True, False, True, True, False, True]
    cons = _consistency(monkeypatch, estimates, infos, pooled=1.0, converged=converged)
    assert cons["unconverged"] == [1, 4]
    assert set(cons["per_run"]) == {0, 2, 3, 5}
    assert cons["units"] == [[0], [2], [3], [5]] and cons["agreement"] == 1.0
    # where the converged runs alone cannot make the check, the reason counts the others
    cons = _consistency(
        monkeypatch, [1.0, 1.0, 1.0], [4.0, 4.0, 4.0], pooled=1.0, converged=[True, False, False]
    )
    assert cons["agreement"] is None and "2 runs' refits did not converge" in cons["reason"]
