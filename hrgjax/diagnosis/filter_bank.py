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
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.scipy.special import logsumexp

from ..kalman import Gaussian, predict, update


class Bank(eqx.Module):
    """A bank of linear-Gaussian models, stacked on a leading hypothesis axis M.

    **Fields:** `phi` (M, n, n), `qd` (M, n, n), `h` (M, m, n), `r` (M, m, m), `x0` (M, n),
    `p0` (M, n, n); `log_trans` (M, M): log of the hypothesis transition matrix $p^{ji}$
    (row j = from, column i = to); `z_offset` (M, m): a known measurement offset per
    hypothesis, z = H x + offset + v (what a hypothesis predicts beyond its states)."""

    phi: jax.Array
    qd: jax.Array
    h: jax.Array
    r: jax.Array
    x0: jax.Array
    p0: jax.Array
    log_trans: jax.Array
    z_offset: jax.Array

    @classmethod
    def build(cls, models, switch_prob: float = 0.0, z_offsets=None):
        """From a list of `(phi, qd, h, r, x0, p0)` tuples (and optional `z_offsets`, one (m,)
        per model); hypotheses stay put with probability 1 − `switch_prob` per step and
        otherwise move to any other one uniformly."""
        m = len(models)
        if m < 1:
            raise ValueError("a bank needs at least one model")
        if not 0.0 <= switch_prob < 1.0:
            raise ValueError(f"switch_prob must be in [0, 1); got {switch_prob}")
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
        return cls(*parts, log_trans, offs)

    @property
    def size(self) -> int:
        return self.phi.shape[0]


def _normalise(lp, log_floor):
    lp = lp - logsumexp(lp)
    lp = jnp.maximum(lp, log_floor)
    return lp - logsumexp(lp)


def _mix(gs: Gaussian, lp_prev, log_trans):
    """IMM mixing: each filter starts from the mixture of all filters' estimates weighted by
    the probability of having come from them."""
    lw = lp_prev[:, None] + log_trans  # (from j, to i)
    lw = lw - logsumexp(lw, axis=0, keepdims=True)
    w = jnp.exp(lw)  # columns sum to 1
    x = jnp.einsum("ji,jn->in", w, gs.x)
    d = gs.x[None, :, :] - x[:, None, :]  # (to i, from j, n)
    p = jnp.einsum("ji,jnk->ink", w, gs.P) + jnp.einsum("ji,ijn,ijk->ink", w, d, d)
    return Gaussian(x, p)


def run_bank(
    bank: Bank,
    zs,
    *,
    floor: float = 1e-6,
    prior=None,
    threshold: float = 0.9,
    interacting: bool = False,
):
    """Run `bank` over measurements `zs` (K, m).

    **Arguments:** `floor`: smallest probability a hypothesis may hold (> 0); `prior` (M,)
    initial probabilities (default uniform); `threshold`: A of eq. (10); `interacting`: mix
    the estimates across hypotheses each step (IMM) instead of independent filters.

    **Returns:** `(probabilities (K, M), decisions (K,) int, −1 = undecided, means (K, M, n))`
    (the means are each filter's posterior estimate)."""
    m = bank.size
    if not 0.0 < floor < 1.0 / m:
        raise ValueError(f"floor must be in (0, 1/{m}); got {floor}")
    with jax.numpy_dtype_promotion("standard"):
        lp0 = (
            jnp.full(m, -jnp.log(float(m))) if prior is None else jnp.log(jnp.asarray(prior, float))
        )
    return _run(
        bank,
        jnp.asarray(zs, float),
        jnp.log(jnp.asarray(floor)),
        lp0,
        jnp.asarray(threshold),
        interacting,
    )


@eqx.filter_jit
def _run(bank, zs, log_floor, lp0, threshold, interacting):
    step_one = jax.vmap(
        lambda g, phi, qd, h, r, off, z: update(predict(g, phi, qd), z - off, h, r)[::3],
        in_axes=(0, 0, 0, 0, 0, 0, None),
    )

    def step(carry, z):
        gs, lp = carry
        if interacting:
            gs = _mix(gs, lp, bank.log_trans)
        gs, ll = step_one(gs, bank.phi, bank.qd, bank.h, bank.r, bank.z_offset, z)
        lp = logsumexp(lp[:, None] + bank.log_trans, axis=0) + ll
        lp = _normalise(lp, log_floor)
        return (gs, lp), (lp, gs.x)

    gs0 = Gaussian(bank.x0, bank.p0)
    _, (lps, means) = jax.lax.scan(step, (gs0, _normalise(lp0, log_floor)), zs)
    probs = jnp.exp(lps)
    best = jnp.argmax(probs, axis=-1)
    decided = jnp.take_along_axis(probs, best[:, None], axis=-1)[:, 0] > threshold
    return probs, jnp.where(decided, best, -1), means
