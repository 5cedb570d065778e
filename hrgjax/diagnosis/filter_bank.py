r"""Multiple-model (multi-alternative) filtering for fault diagnosis (seed 002, eqs. 9–13).

One linear-Gaussian model per hypothesis $S^0$ (healthy) … $S^{n}$ (fault in INS i), all of
the same state size (a hypothesis switches its fault state on through its prior and
dynamics), run side by side as one `vmap`. Each step every filter predicts and updates, its
innovation likelihood $\rho^i_k = N(\nu^i_k; 0, S^i_k)$ updates the hypothesis probabilities

$$g^i_k \propto \rho^i_k \sum_j p^{ji} g^j_{k-1},$$

**in log space**, and each probability is then held above a floor (`floor`) and the set
renormalised, so no hypothesis can lock at exactly 0 or 1 — the known failure of multiple-
model adaptive estimation, where a hypothesis driven to 0 can never come back. Decision
(eq. 10): $i^* = \arg\max_i g^i_k$ when $g^{i^*}_k > A$, else undecided (−1).

This is the bank of independent filters with Markov hypothesis transitions; the thesis's
optimal algorithm (eq. 9) also mixes the filters' estimates across transitions — the
sub-optimal poly-Gaussian version of it is the interacting multiple model, which
[`run_bank`][hrgjax.diagnosis.filter_bank.run_bank] gives with `interacting=True`.

**The probabilities are conditional on the bank's model.** Each step also gives every
filter's normalised innovation squared (NIS) $\nu^\top S^{-1} \nu$, which under a model
that fits the data is $\chi^2(m)$ and white; [`model_fit`][hrgjax.diagnosis.filter_bank.model_fit]
sums it over a sliding window and tests it against $\chi^2$. With `fit_level` set (e.g.
`FIT_LEVEL`), a step whose most probable hypothesis fails that test is not decided:
decision −2, "the model does not fit" (measurement noise 3× `meas_sigma`, or sensor errors
2× the model's, made the bank name a fault at p ≈ 0.99; `docs/diagnosis.md`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaincc, logsumexp

from .._checks import describe, whole_number
from .._linalg import cho_logdet, cho_solve, cholesky
from ..kalman import LOG_2PI, Gaussian, predict, update
from ._bank_inputs import check_bank, check_model, check_scale, check_zs, concrete


class Bank(eqx.Module):
    """A bank of linear-Gaussian models, stacked on a leading hypothesis axis M.

    **Fields:** `phi` (M, n, n), `qd` (M, n, n), `h` (M, m, n), `r` (M, m, m), `x0` (M, n),
    `p0` (M, n, n); `log_trans` (M, M): log of the hypothesis transition matrix $p^{ji}$
    (row j = from, column i = to); `z_offset` (M, m): a known measurement offset per
    hypothesis, z = H x + offset + v (what a hypothesis predicts beyond its states);
    `reset` (M, n) bool: states that belong to a hypothesis alone (a fault's size) and
    restart from that hypothesis's prior (`x0`, `p0`) when the interacting bank enters it
    from another one — the fault's onset; `scale` (M, n) (or None: 1): the states' units —
    the models are written for x' = x / `scale` (fault_bank: each state in units of its own
    spread, so the covariances keep their definiteness), and `run_bank` returns the
    physical x = `scale` · x'."""

    phi: jax.Array
    qd: jax.Array
    h: jax.Array
    r: jax.Array
    x0: jax.Array
    p0: jax.Array
    log_trans: jax.Array
    z_offset: jax.Array
    reset: jax.Array
    scale: jax.Array | None = None

    @classmethod
    def build(cls, models, switch_prob: float = 0.0, z_offsets=None, reset=None, scale=None):
        """From a list of `(phi, qd, h, r, x0, p0)` tuples (and optional `z_offsets`, one (m,)
        per model, `reset` masks, one (n,) per model, and `scale`, the states' units, (n,)
        for all or (M, n), finite and > 0); hypotheses stay put with
        probability 1 − `switch_prob` per step and otherwise move to any other one
        uniformly (`switch_prob` may be traced). Each model is refused in one line when its shapes do not fit or (concrete
        values) a value is not finite, `qd` or `p0` is not symmetric positive
        semi-definite, or `r` is not positive-definite."""
        m = len(models)
        if m < 1:
            raise ValueError("a bank needs at least one model")
        known = concrete(switch_prob)  # a traced one (a sweep over it) is not checked
        if known is not None and not 0.0 <= float(known) < 1.0:
            raise ValueError(f"switch_prob must be in [0, 1); got {switch_prob}")
        for i, mod in enumerate(models):
            check_model(i, mod, models[0])
        parts = [jnp.stack([jnp.asarray(mod[k], float) for mod in models]) for k in range(6)]
        if m == 1:
            trans = jnp.ones((1, 1))
        else:
            off = switch_prob / (m - 1)
            trans = jnp.full((m, m), off) + jnp.eye(m) * (1.0 - switch_prob - off)
        with jax.numpy_dtype_promotion("standard"):
            log_trans = jnp.log(trans)
        if z_offsets is None:
            offs = jnp.zeros((m, parts[2].shape[1]))
        else:
            offs = jnp.stack([jnp.asarray(o, float) for o in z_offsets])
            if offs.shape != (m, parts[2].shape[1]):
                raise ValueError(f"z_offsets must be {m} vectors of length {parts[2].shape[1]}")
        n = parts[0].shape[1]
        if reset is None:
            mask = jnp.zeros((m, n), bool)
        else:
            mask = jnp.stack([jnp.asarray(x, bool) for x in reset])
            if mask.shape != (m, n):
                raise ValueError(f"reset must be {m} masks of length {n}")
        if scale is not None:
            if np.ndim(scale) not in (1, 2) or np.shape(scale)[-1] != n:
                raise ValueError(f"scale must be (n,) = ({n},) or (M, n) = ({m}, {n}) (the "
                                 f"states' units); got shape {np.shape(scale)}")  # fmt: skip
            scale = jnp.broadcast_to(jnp.asarray(scale, float), (m, n))
            check_scale("scale", scale, (m, n))
        return cls(*parts, log_trans, offs, mask, scale)

    @property
    def size(self) -> int:
        return self.phi.shape[0]


def _normalise(lp, log_floor):
    lp = lp - logsumexp(lp)
    lp = jnp.maximum(lp, log_floor)
    return lp - logsumexp(lp)


def _mix_weights(lp_prev, bank: Bank):
    """Mixing weights w[j, i] = P(came from j | now in i) and, per (to i, from j), the mask of
    states that restart at the target's prior."""
    lw = lp_prev[:, None] + bank.log_trans  # (from j, to i)
    lw = lw - logsumexp(lw, axis=0, keepdims=True)
    other = ~jnp.eye(bank.size, dtype=bool)  # (to i, from j)
    return jnp.exp(lw), bank.reset[:, None, :] & other[:, :, None]


def _mix(gs: Gaussian, lp_prev, bank: Bank):
    """IMM mixing: each filter starts from the mixture of all filters' estimates weighted by
    the probability of having come from them; a component coming from another hypothesis
    has the target's own (`reset`) states at the target's prior."""
    w, r = _mix_weights(lp_prev, bank)  # w columns sum to 1; r (i, j, n)
    xs = jnp.where(r, bank.x0[:, None, :], gs.x[None, :, :])  # component (i, j)
    rr = r[..., :, None] | r[..., None, :]
    both = r[..., :, None] & r[..., None, :]
    ps = jnp.where(rr, jnp.where(both, bank.p0[:, None], 0.0), gs.P[None, :])
    x = jnp.einsum("ji,ijn->in", w, xs)
    d = xs - x[:, None, :]
    p = jnp.einsum("ji,ijnk->ink", w, ps) + jnp.einsum("ji,ijn,ijk->ink", w, d, d)
    return Gaussian(x, p)


FIT_WINDOW = 50
"""Default window (steps) of the model-fit test of `run_bank` / `run_gains`."""
FIT_LEVEL = 1e-3
"""Suggested `fit_level` of `run_bank` / `run_gains` (and `model_fit`'s default): the false
"does not fit" rate per step when the model is right (measured: `docs/diagnosis.md`,
`benchmarks/diagnosis_calibration.py`)."""


def run_bank(
    bank: Bank,
    zs,
    *,
    floor: float = 1e-6,
    prior=None,
    threshold: float = 0.9,
    interacting: bool = False,
    fit_window: int = FIT_WINDOW,
    fit_level: float | None = None,
    return_fit: bool = False,
):
    """Run `bank` over measurements `zs` (K, m).

    **Arguments:** `floor`: smallest probability a hypothesis may hold (> 0); `prior` (M,)
    initial probabilities (default: uniform for the independent bank, a healthy start for
    the interacting one — `HEALTHY_START` on each fault hypothesis, the rest on S0);
    `threshold`: A of eq. (10); `interacting`: mix the estimates across hypotheses each step
    (IMM) instead of independent filters — its probabilities are claims for records that
    start healthy: with a fault from the first sample under a uniform prior (`switch_prob`
    1e-4) ≈ half its steps above 0.99 name the wrong hypothesis (`docs/diagnosis.md`,
    "Measured limit");
    `fit_window`, `fit_level`: the model-fit test of
    [`model_fit`][hrgjax.diagnosis.filter_bank.model_fit] — a step whose most probable
    hypothesis fails it is decided −2 (`fit_level=None`, the default: no test, the
    decisions of eq. (10) alone; `FIT_LEVEL` = 1e-3 is the calibrated setting of
    `docs/diagnosis.md`); `return_fit`: also return the test's dict (its `fits` all True
    when `fit_level` is None; `p_value` is computed either way).

    `floor` and `threshold` may be traced (a `jax.vmap` over thresholds: an ROC curve);
    their ranges are checked where their values are known.

    **Returns:** `(probabilities (K, M), decisions (K,) int, means (K, M, n))`, and with
    `return_fit=True` a fourth item, `model_fit`'s dict plus `nis` (K, M). Decisions: the
    hypothesis index, −1 = undecided (no probability above `threshold`), −2 = the most
    probable hypothesis does not fit the data (its probability is not to be trusted). The
    means are each filter's posterior estimate in the model's physical units (`bank.scale`
    times the filter's state: `fault_bank`'s fault states in sensor units — g-units for an
    accelerometer, rad/s for a gyro)."""
    lp0, log_floor = _start(bank.size, floor, prior, threshold, interacting)
    _check_fit(fit_window, fit_level)
    check_bank(bank)
    zs = check_zs(zs, bank, (2,))
    probs, nis, means = _run(bank, zs, log_floor, lp0, interacting)
    means = means if bank.scale is None else means * bank.scale[None]
    m = bank.h.shape[1]
    decisions, fit = _decide_fit(probs, nis, m, threshold, int(fit_window), fit_level, return_fit)
    return (probs, decisions, means, fit) if return_fit else (probs, decisions, means)


def model_fit(nis, m: int, *, window: int = FIT_WINDOW, level: float = FIT_LEVEL):
    r"""The windowed NIS test of model fit, per step and hypothesis.

    `nis` (K, M): each filter's normalised innovation squared $\nu_k^\top S_k^{-1}\nu_k$
    for measurements of size `m`. When a filter's model is the one that made the data, its
    NIS is $\chi^2(m)$ and independent from step to step (exactly for a Kalman filter; for
    the interacting banks to the extent their mixing is). The statistic at step k is the sum
    over the last `window` steps (fewer at the start), $\chi^2$ with `dof` = m × (the steps
    summed) degrees of freedom; `p_value` is its upper tail and `fits` is
    `p_value > level` — so a model that is right fails on a share `level` of its steps
    (measured: `docs/diagnosis.md`). Only the upper tail is tested: too little scatter makes
    the probabilities cautious, not overconfident. After a real change of hypothesis the
    new leader's window still holds the steps before it: an independent filter that did
    not expect the change (no reset) fails for up to `window` steps. jit friendly; `vmap`
    it for a batch.

    **Returns** a dict: `stat` (K, M), `dof` (K,), `p_value` (K, M), `fits` (K, M) bool."""
    _check_fit(window, level, ("window", "level"), allow_none=False)
    m = whole_number("m", m, "an integer >= 1 (the measurement's size)", minimum=1)
    if jnp.ndim(nis) != 2:
        raise ValueError(f"nis must have shape (K, M) (steps, hypotheses); got {jnp.shape(nis)}")
    return _model_fit(nis, m, int(window), level)


def _model_fit(nis, m, window, level):
    """`model_fit` without its argument checks (`level` 1.0: every step fits)."""
    nis = jnp.asarray(nis, float)
    c = jnp.concatenate([jnp.zeros_like(nis[:1]), jnp.cumsum(nis, axis=0)])  # c[j]: j steps
    steps = jnp.arange(nis.shape[0])
    first = jnp.maximum(steps + 1 - window, 0)
    stat = c[steps + 1] - c[first]
    dof = m * (steps + 1 - first)
    with jax.numpy_dtype_promotion("standard"):
        p_value = gammaincc(0.5 * dof[:, None], 0.5 * jnp.maximum(stat, 0.0))
    return {"stat": stat, "dof": dof, "p_value": p_value, "fits": p_value > level}


def _check_fit(window, level, names=("fit_window", "fit_level"), allow_none=True):
    """`window` an integer >= 1 and `level` a number in (0, 1) (or None where allowed), each
    refused in one line naming it (a text '5' passed as 5, an array raised NumPy's truth-value
    error, a window of 0 gave NaN p-values, a level of 2 failed every step)."""
    whole_number(names[0], window, "an integer >= 1 (steps)", minimum=1)
    if level is None and allow_none:
        return
    known = None if isinstance(level, str | bytes | bool) else _known_number(level)
    if known is None or known.shape != () or not 0.0 < float(known) < 1.0:
        form = "a number in (0, 1)" + (" or None" if allow_none else "")
        raise ValueError(f"{names[1]} must be {form}; got {describe(level)}")


def _decide_fit(probs, nis, m, threshold, window, level, want_fit):
    """Decisions from the probabilities and the model-fit test: −2 where the most probable
    hypothesis fails it, else eq. (10). The test is computed only when asked for."""

    def one(probs, nis):
        best = jnp.argmax(probs, axis=-1)[:, None]
        p_best = jnp.take_along_axis(probs, best, axis=-1)[:, 0]
        dec = jnp.where(p_best > threshold, best[:, 0], -1)
        if level is None and not want_fit:
            return dec, None
        fit = _model_fit(nis, m, window, 1.0 if level is None else level)
        if level is None:
            fit["fits"] = jnp.ones_like(fit["fits"])
        fits = jnp.take_along_axis(fit["fits"], best, axis=-1)[:, 0]
        return jnp.where(fits, dec, -2), {**fit, "nis": nis}

    return one(probs, nis) if probs.ndim == 2 else jax.vmap(one)(probs, nis)


HEALTHY_START = 0.01
"""Each fault hypothesis's prior probability in the interacting banks' default prior (S0, the
healthy complex, holds the rest: 0.97 with three INS, as `compare` runs them): a record that
starts healthy, the claim the IMM's probabilities are for (docs/diagnosis.md). Under a
uniform prior the IMM named a fault before any (pre-onset S0 on 0–20 % of the steps) and
the wrong INS after an onset on some records (`fault_bank` defaults, 2e-7 at 100 s)."""


def _start(m, floor, prior, threshold, interacting=False):
    """The start's log probabilities and log floor; `floor` and `threshold` checked where
    their values are known (a traced one, a sweep under `vmap` or `jit`, passes)."""
    for name, v, ok, form in (("floor", floor, lambda f: 0.0 < f < 1.0 / m, f"in (0, 1/{m})"),
                              ("threshold", threshold, lambda a: 0.0 <= a < 1.0,
                               "a probability in [0, 1)")):  # fmt: skip
        known = _known_number(v)
        if known is not None and not (known.shape == () and ok(float(known))):
            raise ValueError(f"{name} must be {form}; got {v}")
    with jax.numpy_dtype_promotion("standard"):
        if prior is None and interacting and m > 1:  # a healthy start (`HEALTHY_START`)
            faults = min(HEALTHY_START, 0.5 / (m - 1))
            lp0 = jnp.log(jnp.asarray(np.r_[1.0 - faults * (m - 1), np.full(m - 1, faults)]))
        elif prior is None:
            lp0 = jnp.full(m, -jnp.log(float(m)))
        elif (p := concrete(prior)) is None:  # traced: checked by the caller's trace
            lp0 = jnp.log(jnp.asarray(prior, float))
        else:
            if p.shape != (m,) or not np.all(np.isfinite(p)) or np.any(p < 0) or p.sum() <= 0:
                raise ValueError(
                    f"prior must be {m} finite probabilities >= 0, not all 0 (one per "
                    f"hypothesis S0 … S{m - 1}); got {np.asarray(prior).tolist()}"
                )
            lp0 = jnp.log(jnp.asarray(p / p.sum()))
    return lp0, jnp.log(jnp.asarray(floor, float))


def _known_number(v):
    """`v`'s value as an array where it is known (NaN for one that is not a number), else
    None (traced)."""
    try:
        return concrete(v)
    except (TypeError, ValueError):
        return np.array(np.nan)


def _probabilities(lp, ll, log_trans, log_floor):
    """One step of eq. (9) for the probabilities, in log space, then the floor."""
    lp = logsumexp(lp[:, None] + log_trans, axis=0) + ll
    return _normalise(lp, log_floor)


class GainBank(eqx.Module):
    """A [`Bank`][hrgjax.diagnosis.filter_bank.Bank] with its filters' gains computed ahead.

    The covariance recursion of a linear-Gaussian filter does not depend on the data, so
    the gain $K_k$ and innovation covariance $S_k$ of every step are the same for every
    Monte Carlo run: compute them once (`n_steps` of them; afterwards the last is held,
    which for a time-invariant model is the converged gain), and a run costs a few
    matrix–vector products per hypothesis and step. For the independent bank this is
    exact.

    The interacting bank (IMM) mixes covariances too, which depends on the data. Its
    gain-schedule form keeps two things of the mixing:

    - a fault hypothesis (one with `reset` states, a fault's size) restarts them at its
      prior when it is entered, so it has an *onset* schedule too — the recursion started
      from the healthy filter's converged covariance with its reset states at their prior —
      indexed by the number of steps it has been the most probable hypothesis (0 while it
      is not: it is re-entered from the leading one at every step). The first `warmup`
      steps (the filters' start-up transient) use the plain schedules;
    - a hypothesis without reset states (S0) steps from its own schedule while its own
      covariance dominates its mixed one (own mixing weight × m against the other weights
      × m plus the spread of the mixed estimates through its S), else from the covariance
      of the hypothesis it is mixed from most (that one's schedule at that step): the
      leader's after an onset, when the IMM's mixing starts it mostly from the leader's
      estimate. Kept on its own healthy schedule always, S0 named a fault and then took
      the decision back within ≈ 35 s while the fault persisted (its healthy gain absorbs
      the step into its sensor-error state). Stepped from the leader's covariance whenever
      it did not lead, it lost healthy records under a uniform prior: the hypotheses start
      level, a fault hypothesis leads for a step, S0's S (determinant ≈ e⁵ larger) cost it
      ≈ 2.7 nats a step and it never led again — 4 of 5 healthy 400-s records decided a
      fault on ≈ 92 % of their steps where the full IMM decides S0.

    The estimates are mixed exactly; the covariances are those of the schedules. Agreement
    with the full IMM: `docs/diagnosis.md`.

    **Fields:** `bank`; `gain` (M, L, n, m), `s_inv` (M, L, m, m) and `logdet` (M, L):
    each filter's schedule from `p0` (the independent bank); `from_gain`
    (2, M, M, L, n, m), `from_s_inv` (2, M, M, L, m, m), `from_logdet` (2, M, M, L):
    [schedule (0 plain, 1 onset), source hypothesis j, hypothesis i, step] — i's step from
    j's covariance before step τ of j's schedule, with i's reset states at their prior
    when i ≠ j (the diagonal is each hypothesis's own schedule); `warmup`. Memory grows as
    M² L: 4 hypotheses of 21 states over 1000 steps take 12 MB."""

    bank: Bank
    gain: jax.Array
    s_inv: jax.Array
    logdet: jax.Array
    from_gain: jax.Array
    from_s_inv: jax.Array
    from_logdet: jax.Array
    warmup: int = eqx.field(static=True)

    @classmethod
    def from_bank(cls, bank: Bank, n_steps: int, healthy: int = 0, warmup: int | None = None):
        """Run every filter's covariance recursion from its `p0` for `n_steps` steps, the
        onset recursions from the covariance of hypothesis `healthy` after them, and every
        hypothesis's step from each of these covariances (class docstring); the
        interacting bank uses the plain schedules for its first `warmup` steps (default
        min(50, `n_steps`); checked before any computation: 0 ≤ warmup ≤ n_steps)."""
        if isinstance(n_steps, bool) or not float(n_steps).is_integer() or int(n_steps) < 1:
            raise ValueError(f"n_steps must be an integer >= 1; got {n_steps!r}")
        if not 0 <= int(healthy) < bank.size:
            raise ValueError(
                f"healthy must be a hypothesis index in [0, {bank.size}); got {healthy}"
            )
        n_steps = int(n_steps)
        warmup = min(50, n_steps) if warmup is None else warmup
        if isinstance(warmup, bool) or not 0 <= int(warmup) <= n_steps:
            raise ValueError(f"warmup must be an integer in [0, n_steps={n_steps}]; got {warmup!r}")
        check_bank(bank)
        return cls(bank, *_schedules(bank, n_steps, int(healthy)), int(warmup))


@eqx.filter_jit
def _schedules(bank: Bank, n_steps: int, healthy: int):
    """`GainBank`'s arrays from `bank`: one program per bank shape, `n_steps` and `healthy`
    (run eagerly, every call traced and compiled its two scans anew)."""
    track = jax.vmap(lambda *a: _track(*a, n_steps))
    k, s, plain = track(bank.phi, bank.qd, bank.h, bank.r, bank.p0)
    p_on = _restart(bank.reset, bank.p0, plain[healthy, -1][None])
    _, _, onset = track(bank.phi, bank.qd, bank.h, bank.r, p_on)
    # each track's covariance before its step τ: its start, then its posteriors
    src = jnp.stack([
        jnp.concatenate([bank.p0[:, None], plain[:, :-1]], axis=1),
        jnp.concatenate([p_on[:, None], onset[:, :-1]], axis=1),
    ])  # fmt: skip
    cross, s_from = jax.vmap(lambda p: _from_each(bank, p))(src)
    s_inv, logdet = _inv_logdet(s_from)
    gain = jnp.einsum("...nc,...cd->...nd", cross, s_inv)
    return k, *_inv_logdet(s), gain, s_inv, logdet


def _restart(reset, p0, p):
    """`p` (…, n, n) with the `reset` states (M, n) at their prior `p0` (M, n, n) and
    uncorrelated with the rest: a hypothesis entered from another one."""
    both = reset[:, :, None] | reset[:, None, :]
    diag = reset[:, :, None] & reset[:, None, :]
    return jnp.where(both, jnp.where(diag, p0, 0.0), p)


def _from_each(bank: Bank, src):
    """Every hypothesis i's predicted P Hᵀ and S = H P Hᵀ + R from every hypothesis j's
    covariance `src[j]` (M, L, n, n), with i's reset states at their prior when j ≠ i:
    (M_j, M_i, L, n, m) and (M_j, M_i, L, m, m)."""
    m = bank.size
    same = jnp.eye(m, dtype=bool)

    def one(j, i):
        rst = bank.reset[i] & ~same[j, i]
        p = _restart(rst[None], bank.p0[i][None], src[j])
        p = jnp.einsum("ab,lbc,dc->lad", bank.phi[i], p, bank.phi[i]) + bank.qd[i][None]
        cross = jnp.einsum("lab,mb->lam", p, bank.h[i])
        s = jnp.einsum("ma,lak->lmk", bank.h[i], cross) + bank.r[i][None]
        return cross, 0.5 * (s + s.swapaxes(-1, -2))

    j, i = jnp.meshgrid(jnp.arange(m), jnp.arange(m), indexing="ij")
    return jax.vmap(jax.vmap(one))(j, i)


def _inv_logdet(s):
    """S⁻¹ (symmetrised) and log det S of innovation covariances (..., m, m)."""

    def one(s):
        c = cholesky(s)
        s_inv = cho_solve(c, jnp.eye(s.shape[-1], dtype=s.dtype))
        return 0.5 * (s_inv + s_inv.T), cho_logdet(c)

    return jnp.vectorize(one, signature="(m,m)->(m,m),()")(s)


def _step(phi, qd, h, r, p):
    """One filter step's covariance from posterior `p`: (posterior, gain, S)."""
    g = predict(Gaussian(jnp.zeros(p.shape[0]), p), phi, qd)
    s = h @ g.P @ h.T + r
    s = 0.5 * (s + s.T)
    k = cho_solve(cholesky(s), h @ g.P).T
    post = update(g, jnp.zeros(h.shape[0]), h, r)[0]
    return post.P, k, s


def _track(phi, qd, h, r, p0, n_steps):
    """Gains (L, n, m), innovation covariances (L, m, m) and posterior covariances
    (L, n, n) of `n_steps` filter steps from `p0`."""

    def step(p, _):
        p, k, s = _step(phi, qd, h, r, p)
        return p, (k, s, p)

    _, (k, s, p) = jax.lax.scan(step, jnp.asarray(p0), None, length=n_steps)
    return k, s, p


def run_gains(
    gb: GainBank,
    zs,
    *,
    floor: float = 1e-6,
    prior=None,
    threshold: float = 0.9,
    interacting: bool = False,
    fit_window: int = FIT_WINDOW,
    fit_level: float | None = None,
    return_fit: bool = False,
):
    """[`run_bank`][hrgjax.diagnosis.filter_bank.run_bank] with the gain schedules of `gb`
    (no covariance recursion; see [`GainBank`][hrgjax.diagnosis.filter_bank.GainBank]).
    `zs` (K, m), or (B, K, m) for a batch of runs. **Returns** `(probabilities,
    decisions)` with the leading shape of `zs` (and, with `return_fit=True`, the model-fit
    dict of `run_bank`; the NIS uses each step's scheduled S)."""
    lp0, log_floor = _start(gb.bank.size, floor, prior, threshold, interacting)
    _check_fit(fit_window, fit_level)
    check_bank(gb.bank)
    zs = check_zs(zs, gb.bank, (2, 3))
    fn = lambda z: _run_gains(gb, z, log_floor, lp0, interacting)
    probs, nis = fn(zs) if zs.ndim == 2 else jax.vmap(fn)(zs)
    m = gb.bank.h.shape[1]
    decisions, fit = _decide_fit(probs, nis, m, threshold, int(fit_window), fit_level, return_fit)
    return (probs, decisions, fit) if return_fit else (probs, decisions)


@eqx.filter_jit
def _run_gains(gb, zs, log_floor, lp0, interacting):
    b = gb.bank
    m = b.h.shape[1]
    last = gb.gain.shape[1] - 1
    hyp = jnp.arange(b.size)
    has_onset = jnp.any(b.reset, axis=1)
    hphi = jnp.einsum("hmi,hin->hmn", b.h, b.phi)  # each hypothesis's predicted z

    def step(carry, inp):
        x, lp, lead = carry
        z, k = inp
        if interacting:
            # a fault hypothesis runs its own schedule (the onset one from its entry). One
            # without reset states (S0) steps from its own covariance while that dominates its
            # mixed one, in the units of its own S: own weight × m against the others'
            # weights × m plus the spread of the mixed estimates (a level start: drawn from
            # itself, estimates agree); else from the covariance of the hypothesis it is
            # drawn from most (the leader's after an onset: drawn from it, or spread)
            w, r = _mix_weights(lp, b)
            xs = jnp.where(r, b.x0[:, None, :], x[None, :, :])  # component (to i, from j)
            x = jnp.einsum("ji,ijn->in", w, xs)
            dev = jnp.einsum("imn,ijn->ijm", hphi, xs - x[:, None, :])
            own = gb.s_inv[:, jnp.minimum(k, last)]  # each one's own schedule
            spread = jnp.einsum("ji,ijm,imc,ijc->i", w, dev, own, dev)
            w_own = jnp.diagonal(w)
            keep = w_own * m >= (1.0 - w_own) * m + spread
            other = jnp.argmax(jnp.where(jnp.eye(b.size, dtype=bool), -1.0, w), axis=0)
            drawn = jnp.where(keep, hyp, other)
            onset = has_onset & (k >= gb.warmup)
            src = jnp.where(has_onset, hyp, drawn)
            tau = jnp.minimum(jnp.where(onset[src], lead[src], k), last)
            pick = (onset[src].astype(int), src, hyp, tau)
            gain, s_inv, logdet = gb.from_gain[pick], gb.from_s_inv[pick], gb.from_logdet[pick]
        else:
            i = jnp.minimum(k, last)
            gain, s_inv, logdet = gb.gain[:, i], gb.s_inv[:, i], gb.logdet[:, i]
        x = jnp.einsum("hij,hj->hi", b.phi, x)
        nu = z[None, :] - b.z_offset - jnp.einsum("hij,hj->hi", b.h, x)
        x = x + jnp.einsum("hij,hj->hi", gain, nu)
        nis = jnp.einsum("hi,hij,hj->h", nu, s_inv, nu)
        ll = -0.5 * (nis + logdet + m * LOG_2PI)
        lp = _probabilities(lp, ll, b.log_trans, log_floor)
        lead = jnp.where(hyp == jnp.argmax(lp), lead + 1, 0)
        return (x, lp, lead), (lp, nis)

    steps = jnp.arange(zs.shape[0])
    carry = (b.x0, _normalise(lp0, log_floor), jnp.zeros(b.size, steps.dtype))
    _, (lps, nis) = jax.lax.scan(step, carry, (zs, steps))
    return jnp.exp(lps), nis


@eqx.filter_jit
def _run(bank, zs, log_floor, lp0, interacting):
    def one(g, phi, qd, h, r, off, z):
        g, nu, s, ll = update(predict(g, phi, qd), z - off, h, r)
        return g, ll, nu @ cho_solve(cholesky(s), nu)

    step_one = jax.vmap(one, in_axes=(0, 0, 0, 0, 0, 0, None))

    def step(carry, z):
        gs, lp = carry
        if interacting:
            gs = _mix(gs, lp, bank)
        gs, ll, nis = step_one(gs, bank.phi, bank.qd, bank.h, bank.r, bank.z_offset, z)
        lp = _probabilities(lp, ll, bank.log_trans, log_floor)
        return (gs, lp), (lp, nis, gs.x)

    gs0 = Gaussian(bank.x0, bank.p0)
    _, (lps, nis, means) = jax.lax.scan(step, (gs0, _normalise(lp0, log_floor)), zs)
    return jnp.exp(lps), nis, means
