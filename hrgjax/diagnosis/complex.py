r"""A navigation complex of identical platform INS (seed 002) and its fault-diagnosis bank.

- [`simulate_complex`][hrgjax.diagnosis.complex.simulate_complex]: every INS of the complex
  simulated with its own noise key ([`hrgjax.ins.platform`][hrgjax.ins.platform]), a fault
  in any sensor of any one INS.
- [`measurements`][hrgjax.diagnosis.complex.measurements]: the pairwise measurements of
  eq. (7) or (8) on the navigation parameter that shows a sensor's fault, scaled by R/g
  (so a fault e in an accelerometer reads as e).
- [`fault_bank`][hrgjax.diagnosis.complex.fault_bank]: hypotheses S0 (healthy) and S_i
  (fault in INS i) for one sensor, as a [`Bank`][hrgjax.diagnosis.filter_bank.Bank] over the
  exact discretisation of the complex: every INS's 17 states, one fault state per INS (a
  random walk, coupled into its INS only under its hypothesis) and the last two increments
  of the navigation parameter, so that eqs. (7)–(8) are exactly linear in the state. The
  filters use the independent pairs (0, 1), (0, 2).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._x64 import require_x64
from ..ins.platform import FAULTS, NAV, Fault, PlatformINS, _simulate
from .filter_bank import Bank
from .measurements import first_difference_pairs, second_difference_pairs

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
    if fault_ins is not None and not 0 <= fault_ins < n_ins:
        raise ValueError(f"fault_ins must be in [0, {n_ins}); got {fault_ins}")
    fault = Fault() if fault is None else fault
    e = jnp.zeros((n_ins, 6))
    if fault_ins is not None:
        e = e.at[fault_ins].set(fault.e)
    faults = Fault(e, jnp.full(n_ins, fault.t_fault))
    keys = jax.random.split(key, n_ins)
    run = lambda k, f: _simulate(ins, jnp.asarray(float(dt)), int(n_steps), k, f, None)
    t, _, nav = jax.vmap(run)(keys, faults)
    return t[0], nav


def measurements(nav, dt: float, sensor: str, ins: PlatformINS | None = None, pairs=(0, 1)):
    """The diagnosis measurements for `sensor` from navigation errors `nav` (n_ins, K, 3):
    eq. (7) or (8) on its parameter (`CHANNEL`), scaled by R/g, for the pairs whose indices
    (into [`pairs`][hrgjax.diagnosis.measurements.pairs]) are given. **Returns** (K', len(pairs))
    where step k of the output is step k + 2 of `nav` (both equations, aligned)."""
    ins = PlatformINS() if ins is None else ins
    param, kind = _channel(sensor)
    z = nav[..., NAV.index(param)]
    if kind == "second":
        d = second_difference_pairs(z, dt)
    else:
        d = first_difference_pairs(z, dt)[..., 1:]
    return (d[..., list(pairs), :] * (ins.radius / ins.g)).swapaxes(-1, -2)


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
    fault_walk: float = 1e-8,
    meas_sigma: float = 1e-9,
    switch_prob: float = 1e-5,
) -> Bank:
    r"""The hypothesis bank S0 … S_n for faults in `sensor` (module docstring).

    Each INS carries, besides its 17 states, the increment $u_k = c(x_k - x_{k-1})$ of the
    navigation parameter $c\,x$ and the previous increment, so eq. (7) is
    $(u_k - u_{k-1})/\Delta t^2$ and eq. (8) is $u_k/\Delta t^2$ — exact for the discrete
    model, including the two-step onset of a fault, and well conditioned (increments cancel
    to $O(\omega\Delta t)$, where lagged values of the parameter itself would cancel to
    $O(\omega^2\Delta t^2)$ and lose the covariance's definiteness).

    **Arguments:** `fault_sigma`: prior standard deviation of a fault's size (sensor units:
    g-units for accelerometers, rad/s for gyros); `fault_walk`: its random-walk step
    standard deviation per `dt` (lets a fault that appears later be picked up);
    `meas_sigma`: measurement noise (R/g-scaled units) — the thesis's measurements are
    noise-free, a small value keeps the innovation covariance regular; `switch_prob`:
    hypothesis transition probability per step."""
    param, kind = _channel(sensor)
    col = FAULTS.index(sensor)
    phi1, gam1, qd1 = ins.discretise(dt)
    c = jax.jacfwd(ins.navigation_errors)(jnp.zeros(17))[NAV.index(param)]  # (17,)
    n1 = 19  # 17 states, increment u_k, previous increment u_{k-1}
    n = n_ins * n1 + n_ins  # + one fault state per INS
    i_f = n_ins * n1
    # one INS: [x; u; u_prev] ← [Φ x; c(Φ − I) x; u] (+ noise [w; c w])
    blk = jnp.zeros((n1, n1))
    blk = blk.at[:17, :17].set(phi1).at[17, :17].set(c @ (phi1 - jnp.eye(17))).at[18, 17].set(1.0)
    gq = jnp.zeros((n1, 17)).at[:17].set(jnp.eye(17)).at[17].set(c)
    blk_q = gq @ qd1 @ gq.T
    blk_g = jnp.zeros(n1).at[:17].set(gam1[:, col]).at[17].set(c @ gam1[:, col])
    scale = ins.radius / ins.g / dt**2
    row1 = jnp.zeros(n1).at[17].set(scale)
    if kind == "second":
        row1 = row1.at[18].set(-scale)
    base = jnp.zeros((n, n))
    q = jnp.zeros((n, n))
    p0 = jnp.zeros((n, n))
    rows = []
    for i in range(n_ins):
        s = slice(i * n1, (i + 1) * n1)
        base = base.at[s, s].set(blk).at[i_f + i, i_f + i].set(1.0)
        q = q.at[s, s].set(blk_q)
        p0 = p0.at[i * n1 : i * n1 + 17, i * n1 : i * n1 + 17].set(ins.stationary_covariance())
        rows.append(jnp.zeros(n).at[s].set(row1))
    h = jnp.stack([rows[0] - rows[1], rows[0] - rows[2]])
    r = jnp.eye(2) * meas_sigma**2
    models, reset = [], []
    for hyp in range(n_ins + 1):
        phi, qd, p = base, q, p0
        reset.append(jnp.zeros(n, bool).at[i_f + hyp - 1].set(hyp > 0))
        if hyp > 0:
            i = hyp - 1
            phi = phi.at[i * n1 : (i + 1) * n1, i_f + i].set(blk_g)
            qd = qd.at[i_f + i, i_f + i].set(fault_walk**2)
            p = p.at[i_f + i, i_f + i].set(fault_sigma**2)
        models.append((phi, qd, p))
    # the states span metres to 1e-10 rad: filter in units of each state's own spread (an
    # exact change of variables x = T x'), so the covariance keeps its definiteness
    t = _state_scale(base, q, p0 + jnp.diag(jnp.zeros(n).at[i_f:].set(fault_sigma**2)))
    ti = 1.0 / t
    # the increments before the first measurement are unknown: one spread each
    for i in range(n_ins):
        for j in (17, 18):
            k = i * n1 + j
            models = [(f, qq, pp.at[k, k].set(t[k] ** 2)) for f, qq, pp in models]
    scaled = [
        (ti[:, None] * f * t[None, :], ti[:, None] * qq * ti[None, :], h * t[None, :], r,
         jnp.zeros(n), ti[:, None] * pp * ti[None, :])
        for f, qq, pp in models
    ]  # fmt: skip
    return Bank.build(scaled, switch_prob=switch_prob, reset=reset)


def _state_scale(phi, qd, p0, steps: int = 200):
    """Standard deviation of every state after `steps` of prediction from `p0`, floored:
    the units the filters run in."""

    def step(p, _):
        return phi @ p @ phi.T + qd, None

    p, _ = jax.lax.scan(step, p0, None, length=steps)
    sd = jnp.sqrt(jnp.clip(jnp.diag(p), 0.0))
    return jnp.maximum(sd, 1e-6 * jnp.max(sd) + 1e-300)
