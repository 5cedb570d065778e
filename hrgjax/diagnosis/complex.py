r"""A navigation complex of identical platform INS (seed 002) and its fault-diagnosis bank.

- [`simulate_complex`][hrgjax.diagnosis.complex.simulate_complex]: every INS of the complex
  simulated with its own noise key ([`hrgjax.ins.platform`][hrgjax.ins.platform]), a fault
  in any sensor of any one INS.
- [`measurements`][hrgjax.diagnosis.complex.measurements]: the pairwise measurements of
  eq. (7) or (8) on the navigation parameter that shows a sensor's fault, scaled by R/g
  (so a fault e in an accelerometer reads as e).
- [`fault_bank`][hrgjax.diagnosis.complex.fault_bank]: hypotheses S0 (healthy) and S_i
  (fault in INS i) for one sensor, as a [`Bank`][hrgjax.diagnosis.filter_bank.Bank] over the
  exact discretisation of the complex. Its state is the differences x₀ − x_j of the INS
  states that reach the measured parameter
  ([`relevant_states`][hrgjax.diagnosis.complex.relevant_states]), each with the last two
  increments of its parameter (so eqs. (7)–(8) are exactly linear in the state), and one
  fault state per INS (a random walk, coupled into the differences only under its
  hypothesis). The filters use the independent pairs (0, 1), (0, 2), …
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import (
    FINITE_NONNEGATIVE,
    FINITE_POSITIVE,
    check_number,
    check_values,
    concrete_value,
    describe,
    is_finite_real,
    numeric_problem,
    whole_number,
)
from .._compiled import fused
from .._x64 import require_x64
from ..ins.platform import FAULTS, NAV, Fault, PlatformINS, simulate
from .filter_bank import Bank
from .measurements import first_difference_pairs, second_difference_pairs
from .measurements import pairs as _pairs

CHANNEL = {
    "accel_x": ("departure", "second"),
    "accel_y": ("dlat", "second"),
    "gyro_xi": ("dlat", "second"),
    "gyro_zeta": ("departure", "second"),
    "gyro_eta": ("departure", "first"),
}
"""Navigation parameter and measurement (eq. 7 `second`, eq. 8 `first`) that show each
sensor's fault."""


def simulate_complex(
    ins: PlatformINS,
    *,
    dt: float,
    n_steps: int,
    key: jax.Array,
    n_ins: int = 3,
    fault_ins: int | None = None,
    fault: Fault | None = None,
):
    """Simulate `n_ins` identical INS with independent noise; `fault` hits INS `fault_ins`.

    **Returns:** `(t (K+1,), nav (n_ins, K+1, 3))` navigation errors (latitude, departure,
    heading) [rad]."""
    require_x64("diagnosis.simulate_complex")
    if (fault is None) != (fault_ins is None):
        raise ValueError("give both fault and fault_ins, or neither")
    n_ins = whole_number("n_ins", n_ins, "an integer >= 2 (the INS of the complex)", minimum=2)
    if fault_ins is not None:
        # 1.5 raised a raw indexing TypeError, True was read as INS 1
        fault_ins = whole_number("fault_ins", fault_ins, f"an INS index in [0, {n_ins})")
        if not 0 <= fault_ins < n_ins:
            raise ValueError(f"fault_ins must be an INS index in [0, {n_ins}); got {fault_ins}")
    fault = Fault() if fault is None else fault
    e = jnp.zeros((n_ins, 6))
    if fault_ins is not None:
        e = e.at[fault_ins].set(fault.e)
    faults = Fault(e, jnp.full(n_ins, fault.t_fault))
    keys = jax.random.split(key, n_ins)
    run = lambda k, f: simulate(ins, dt=dt, n_steps=n_steps, key=k, fault=f)
    t, _, nav = jax.vmap(run)(keys, faults)
    return t[0], nav


def measurements(nav, dt: float, sensor: str, ins: PlatformINS | None = None, pairs=None):
    """The diagnosis measurements for `sensor` from navigation errors `nav` (n_ins, K, 3):
    eq. (7) or (8) on its parameter (`CHANNEL`), scaled by R/g, for the pairs whose indices
    (into [`pairs`][hrgjax.diagnosis.measurements.pairs]) are given; the default is the
    pairs (0, j), j = 1 … n_ins − 1, in order — the ones [`fault_bank`][hrgjax.diagnosis.complex.fault_bank]
    models (another selection of as many pairs has the bank's shape but not its meaning).
    **Returns** (K', len(pairs)) where step k of the output is step k + 2 of `nav` (both
    equations, aligned)."""
    ins = PlatformINS() if ins is None else ins
    param, kind = _channel(sensor)
    n_ins = jnp.shape(nav)[-3] if jnp.ndim(nav) >= 3 else 0
    n_pairs = len(_pairs(n_ins)) if n_ins >= 2 else 0
    if n_ins < 2 or jnp.shape(nav)[-1] != len(NAV):
        raise ValueError(
            f"nav must have shape (n_ins >= 2, K, {len(NAV)}) ({', '.join(NAV)}); "
            f"got {jnp.shape(nav)}"
        )
    if jnp.shape(nav)[-2] < 3:
        raise ValueError(f"nav must have at least 3 samples (K >= 3: each measurement spans "
                         f"samples k … k + 2); got K = {jnp.shape(nav)[-2]}")  # fmt: skip
    if not (is_finite_real(dt) and dt > 0):
        kind = TypeError if numeric_problem(dt) is not None else ValueError
        raise kind(f"dt must be a finite number > 0 s; got {describe(dt)}")
    if pairs is None:
        pairs = tuple(range(n_ins - 1))
    pairs = tuple(pairs)
    if (not pairs or len(set(pairs)) != len(pairs)
            or not all(isinstance(i, (int, np.integer)) and 0 <= i < n_pairs for i in pairs)):  # fmt: skip
        raise ValueError(
            f"pairs must be distinct indices into {_pairs(n_ins)} (0 … {n_pairs - 1}); "
            f"got {pairs!r}"
        )
    # only the chosen pairs: all of a (K, n_ins, 3) array read as a complex of K INS (a
    # transposed nav) were K²/2 differences, minutes for K = 200
    chosen = [_pairs(n_ins)[i] for i in pairs]
    z = nav[..., NAV.index(param)]
    if kind == "second":
        d = second_difference_pairs(z, dt, chosen)
    else:
        d = first_difference_pairs(z, dt, chosen)[..., 1:]
    return (d * (ins.radius / ins.g)).swapaxes(-1, -2)


def _channel(sensor):
    if sensor not in CHANNEL:
        raise ValueError(
            f"no diagnosis channel for sensor {sensor!r}; choose from {tuple(CHANNEL)}"
        )
    return CHANNEL[sensor]


def fault_bank(
    ins: PlatformINS,
    sensor: str,
    dt: float,
    *,
    n_ins: int = 3,
    fault_sigma: float = 3e-7,
    fault_walk: float = 1e-9,
    meas_sigma: float = 1e-9,
    switch_prob: float = 1e-5,
) -> Bank:
    r"""The hypothesis bank S0 … S_n for faults in `sensor` (module docstring).

    Each difference of INS states carries the increment $u_k = c(x_k - x_{k-1})$ of the
    navigation parameter $c\,x$ and the previous increment, so eq. (7) is
    $(u_k - u_{k-1})/\Delta t^2$ and eq. (8) is $u_k/\Delta t^2$ — exact for the discrete
    model, including the two-step onset of a fault, and well conditioned (increments cancel
    to $O(\omega\Delta t)$, where lagged values of the parameter itself would cancel to
    $O(\omega^2\Delta t^2)$ and lose the covariance's definiteness). The filters' prior is
    the complex one step after the aligned state (navigation errors zero, sensor errors
    stationary): measurement 0 spans navigation samples 0–2, so its filter step predicts
    sample 2.

    **Arguments:** `fault_sigma`: prior standard deviation of a fault's size (sensor units:
    g-units for accelerometers, rad/s for gyros); `fault_walk`: its random-walk step
    standard deviation per `dt`. Keep it below the per-step change of the Markov sensor
    error it competes with, σ√(2Δt/τ) (2.4e-9 for 1e-7, τ = 3600 s, Δt = 1 s): the former
    default 1e-8 made a held fault hypothesis lose likelihood on every step the fault did
    not move, so a fault present from the first sample was reported healthy at p ≈ 1. At 0
    (a constant fault, the exact model of the simulator's) a fault hypothesis that is
    already probable (a uniform prior) cannot take up a later onset — the interacting bank
    restarts the fault state only when it enters a hypothesis of low probability — and
    `docs/diagnosis.md`'s example stayed undecided after its onset; the default 1e-9 does
    both (`docs/diagnosis.md`, "Calibration"); `meas_sigma`: measurement noise (R/g-scaled
    units) — a model parameter, not a harmless regulariser: the probabilities are
    conditional on it (and on the sensor errors' σ and τ), and measurement noise
    3× `meas_sigma` made the bank name a fault on most healthy steps at p ≈ 0.99 (check
    with `run_bank(..., fit_level=…)`); `switch_prob`: hypothesis transition probability
    per step.

    The bank's matrices are in units of each state's own spread (x = `scale` · x',
    `Bank.scale`): `run_bank` returns its means in the physical units.

    `dt`, `fault_sigma`, `fault_walk`, `meas_sigma` and `switch_prob` only set the models'
    values and may be traced (`jax.vmap` over a noise level: one bank per value, as built one
    by one); their ranges are checked where their values are known. `ins` (which states the
    bank keeps is read from its matrices' values), `sensor` and `n_ins` (the bank's
    structure) must be concrete; a traced `ins` or `n_ins` is refused in one line."""
    param, kind = _channel(sensor)
    n_ins = whole_number("n_ins", n_ins, "a concrete integer >= 2 (the INS of the complex: the "
                         "bank's size)", minimum=2)  # fmt: skip
    for name, v, ok, form in (
        ("dt", dt, FINITE_POSITIVE, "> 0 s"),
        ("fault_sigma", fault_sigma, FINITE_POSITIVE, "> 0"),
        ("meas_sigma", meas_sigma, FINITE_POSITIVE, "> 0"),
        ("fault_walk", fault_walk, FINITE_NONNEGATIVE, ">= 0"),
        ("switch_prob", switch_prob, lambda p: (p >= 0.0) & (p < 1.0), "in [0, 1)"),
    ):
        check_number(name, v)
        check_values(name, v, ok, form)  # where the value is known: a traced one passes
    col = FAULTS.index(sensor)
    with jax.ensure_compile_time_eval():  # the structure, from a concrete `ins`, under jit too
        c = jax.jacfwd(ins.navigation_errors)(jnp.zeros(17))[NAV.index(param)]  # (17,)
        f = ins.matrices()[0]
    if concrete_value(c) is None or concrete_value(f) is None:
        raise ValueError(
            "fault_bank: ins must be a concrete PlatformINS, not one traced under jit or vmap: "
            "which states the bank keeps (relevant_states) is read from its matrices' values; "
            "build one bank per INS outside the transformation"
        )
    keep = relevant_states(ins, c)
    phi1, gam1, qd1 = ins.discretise(dt)
    scaled, reset, scale = _bank_models(
        phi1[keep][:, keep], gam1[keep, col], qd1[keep][:, keep], c[keep],
        ins.stationary_covariance()[keep][:, keep], ins.radius / ins.g / dt**2, fault_sigma,
        fault_walk, meas_sigma, n_ins=n_ins, second=kind == "second",
    )  # fmt: skip
    return Bank.build(scaled, switch_prob=switch_prob, reset=reset, scale=scale)


@fused(static_argnames=("n_ins", "second"))
def _bank_models(phi1, gam1, qd1, c, p_ins, scale, fault_sigma, fault_walk, meas_sigma, *,
                 n_ins, second):  # fmt: skip
    """`fault_bank`'s scaled models and reset masks from one INS's reduced matrices, as one
    compiled program (built operation by operation, a bank cost ≈ 150 small compiles)."""
    ns = phi1.shape[0]
    n1 = ns + 2  # the INS's states, increment u_k, previous increment u_{k-1}
    n = (n_ins - 1) * n1 + n_ins  # n − 1 differences, one fault state per INS
    i_f = (n_ins - 1) * n1
    # one INS: [x; u; u_prev] ← [Φ x; c(Φ − I) x; u] (+ noise [w; c w])
    blk = jnp.zeros((n1, n1))
    blk = blk.at[:ns, :ns].set(phi1).at[ns, :ns].set(c @ (phi1 - jnp.eye(ns)))
    blk = blk.at[ns + 1, ns].set(1.0)
    gq = jnp.zeros((n1, ns)).at[:ns].set(jnp.eye(ns)).at[ns].set(c)
    blk_q = gq @ qd1 @ gq.T
    blk_g = jnp.zeros(n1).at[:ns].set(gam1).at[ns].set(c @ gam1)
    row1 = jnp.zeros(n1).at[ns].set(scale)
    if second:
        row1 = row1.at[ns + 1].set(-scale)
    # the filters carry the differences d_j = x_0 − x_j (j = 1 … n−1), not the INS errors:
    # the pairwise measurements never see the complex's common error, which is undamped
    # (Schuler and Earth-rate oscillators driven by noise) and would grow without bound in
    # the filters' covariance. cov(w_0 − w_j, w_0 − w_k) = (1 + δ_jk) Q.
    nd = n_ins - 1
    mix = jnp.ones((nd, nd)) + jnp.eye(nd)
    base = jnp.zeros((n, n)).at[:i_f, :i_f].set(jnp.kron(jnp.eye(nd), blk))
    base = base.at[i_f:, i_f:].set(jnp.eye(n_ins))
    q = jnp.zeros((n, n)).at[:i_f, :i_f].set(jnp.kron(mix, blk_q))
    p_blk = jnp.zeros((n1, n1)).at[:ns, :ns].set(p_ins)
    p0 = jnp.zeros((n, n)).at[:i_f, :i_f].set(jnp.kron(mix, p_blk))
    h = jnp.kron(jnp.eye(nd), row1[None, :])
    h = jnp.concatenate([h, jnp.zeros((nd, n_ins))], axis=1)
    r = jnp.eye(nd) * meas_sigma**2
    models, reset = [], []
    for hyp in range(n_ins + 1):
        phi, qd, p = base, q, p0
        reset.append(jnp.zeros(n, bool).at[i_f + hyp - 1].set(hyp > 0))
        if hyp > 0:
            i = hyp - 1
            # a fault in INS 0 enters every difference with +1, one in INS j only d_j, −1
            sign = jnp.full(nd, 1.0) if i == 0 else -jnp.eye(nd)[i - 1]
            phi = phi.at[:i_f, i_f + i].set(jnp.kron(sign, blk_g))
            qd = qd.at[i_f + i, i_f + i].set(fault_walk**2)
            p = p.at[i_f + i, i_f + i].set(fault_sigma**2)
        models.append((phi, qd, p))
    # the states span m/s to 1e-10 rad: filter in units of each state's own spread (an
    # exact change of variables x = T x', T = `Bank.scale`), so the covariance keeps its
    # definiteness
    t = _state_scale(base, q, p0 + jnp.diag(jnp.zeros(n).at[i_f:].set(fault_sigma**2)))
    ti = 1.0 / t
    # `p0` is the complex at the first navigation sample (navigation errors zero, sensor
    # errors stationary, increments zero); measurement 0 is taken two samples later, so the
    # filters start one prediction on (their first step predicts the second)
    models = [(f, qq, f @ pp @ f.T + qq) for f, qq, pp in models]
    scaled = [
        (ti[:, None] * f * t[None, :], ti[:, None] * qq * ti[None, :], h * t[None, :], r,
         jnp.zeros(n), ti[:, None] * pp * ti[None, :])
        for f, qq, pp in models
    ]  # fmt: skip
    return scaled, reset, t


def relevant_states(ins: PlatformINS, c) -> np.ndarray:
    """Indices of the states of one INS that the navigation parameter `c @ x` depends on:
    the smallest set that holds the states `c` reads and every state that drives one of
    them (through the nonzero pattern of F). The rest (positions, the vertical channel, and
    the other level channel when there is no horizontal specific force) never reach the
    measurement; the set's dynamics are autonomous, so dropping the rest is exact, and it
    keeps unobservable unstable states (position, height) out of the filters' Riccati
    recursion, where their growing variance would cost the covariance its definiteness.

    `ins` and `c` must be concrete (the set is read from their values): traced ones (under
    jit or vmap) are refused in one line."""
    with jax.ensure_compile_time_eval():
        f, c = concrete_value(ins.matrices()[0]), concrete_value(c)
    if f is None or c is None:
        raise ValueError(
            "relevant_states: ins and c must be concrete, not traced under jit or vmap: the "
            "states kept are read from the nonzero pattern of their values"
        )
    f = f != 0.0
    keep = c != 0.0
    while True:
        grown = keep | f[keep].any(axis=0)
        if np.array_equal(grown, keep):
            return np.flatnonzero(keep)
        keep = grown


def _state_scale(phi, qd, p0, steps: int = 200):
    """Standard deviation of every state after `steps` of prediction from `p0`, floored:
    the units the filters run in."""

    def step(p, _):
        return phi @ p @ phi.T + qd, None

    p, _ = jax.lax.scan(step, p0, None, length=steps)
    sd = jnp.sqrt(jnp.clip(jnp.diag(p), 0.0))
    return jnp.maximum(sd, 1e-6 * jnp.max(sd) + 1e-300)
