r"""Loosely-coupled GNSS/INS: an error-state extended Kalman filter with closed-loop
correction, a Rauch–Tung–Striebel smoother, and their consistency figures (NEES, NIS).

**States** (15, or 21 with `scale_factors=True`): the strapdown error model's position,
velocity and attitude errors ([`hrgjax.ins.strapdown.STATES`][hrgjax.ins.strapdown]:
δφ, δλ [rad], δh [m], δv [m/s, NED], φ [rad]), then the residual gyro and accelerometer
biases $b - \hat b$ [rad/s, m/s²] (body), then the residual scale factors $s - \hat s$.
Each is *estimate minus truth* for the navigation states and *truth minus estimate* for the
sensor states, so that the gyro error left after correction is
$\delta\omega = \delta b + \mathrm{diag}(\omega)\,\delta s$ as the error model expects.

**Per GNSS interval** T (a block of IMU steps):

1. the increments, corrected with the current sensor estimates
   ($\Delta\theta \leftarrow (\Delta\tilde\theta - \hat b_g\Delta t)/(1 + \hat s_g)$, same for
   Δv), run through [`mechanize`][hrgjax.ins.mechanization]'s step;
2. the covariance is propagated with $\Phi, Q_d$ of the error model
   ([`discretise`][hrgjax.ins.ekf.discretise]: the Van Loan integrals by series)
   (F at the block's middle state with the block's mean specific force and rate; white gyro and
   accelerometer noise densities `arw`, `vrw`; bias random walks) — the same exact
   linearisation as [`hrgjax.ins.strapdown`][hrgjax.ins.strapdown];
3. at a valid fix the innovation (INS antenna position and velocity minus the fix, the
   longitude difference wrapped to ±π, with the lever arm's attitude sensitivity in H)
   updates the error state (Joseph form, [`hrgjax.kalman.update`][hrgjax.kalman.update]);
4. the estimate is fed back — position and velocity subtracted, attitude
   $q \leftarrow q(\hat\phi)\otimes q$, sensor estimates accumulated — and reset to zero.

The smoother runs the RTS recursion on these reset error states backwards:
$s_k = C_k\,(\hat x^+_{k+1} + s_{k+1})$, $C_k = P^+_k\Phi_k^\top(P^-_{k+1})^{-1}$,
$P^s_k = P^+_k + C_k(P^s_{k+1} - P^-_{k+1})C_k^\top$, and applies $s_k$ to the filtered
state at k.

Sensor model behind the filter: the fixed biases are random constants with σ the
`ImuModel`'s `gyro_bias`/`accel_bias`; the bias instability, with no Gauss–Markov state, is a
random walk of density $2\sigma^2/\tau$ (exact over times ≪ τ, conservative beyond: a
stationary Gauss–Markov bias's change from any start has a variance of at most 2σ², the
walk's grows as 2σ²t/τ; on the tests' 120-s flight with 1-s fixes, for τ of three fix
intervals or less, the attitude and bias σ came out 1.8–3.6× too large: docs/navigation.md); misalignments are not estimated. Every sensor state
needs a prior σ > 0 (a zero makes the covariance singular): the model's values are the sizes
the filter assumes. Its σ are honest only if that model and P0 bound the real sensor and
initial error: if not, σ are several times too small ([`nis_check`][hrgjax.ins.ekf.nis_check]).

**Small-angle limit.** The error state (F, H linear in the attitude error φ) holds for
attitude errors of a few degrees: an initial heading σ of 0.1 rad leaves the attitude σ
1.25× too small, 0.2 rad 1.3×, 0.5 rad 1.7–2× for a whole straight flight, with the NIS
unchanged (Monte Carlo); `attitude_sigma` above `MAX_ATTITUDE_SIGMA` is refused.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import kalman
from .._checks import is_concrete
from .._compiled import Check, fused, program
from .._linalg import cho_solve, cholesky, whiten
from .._x64 import require_x64
from .constants import WGS84, Earth
from .gnss import Gnss, GnssData, antenna, body_rate_wrt_earth
from .mechanization import (
    UNROLL,
    NavState,
    check_increments,
    check_state,
    navigation_errors,
    quat_multiply,
    rotvec_to_quat,
    skew,
    start_carry,
    step,
    wrap_angle,
)
from .sensors import ImuModel
from .strapdown import error_matrices_at

MAX_ATTITUDE_SIGMA = 0.2
"""The largest initial attitude σ [rad] accepted (the small-angle limit, module docstring):
beyond it align first ([`align`][hrgjax.ins.alignment.align])."""


class FilterResult(eqx.Module):
    """A filter or smoother pass, at the GNSS epochs (M of them, the start first).

    **Fields:** `t` (M,) [s]; `nav` the corrected [`NavState`][hrgjax.ins.mechanization.NavState]
    history; `gyro_bias`, `accel_bias` (M, 3) estimates [rad/s, m/s²]; `gyro_scale`,
    `accel_scale` (M, 3) [-] (zeros without scale-factor states); `P` (M, n, n) error
    covariance; `nis` (M,) normalised innovation squared (NaN where no fix);
    `innovation_dim` the number of measured components per fix; `earth` the filter's Earth
    model."""

    t: jax.Array
    nav: NavState
    gyro_bias: jax.Array
    accel_bias: jax.Array
    gyro_scale: jax.Array
    accel_scale: jax.Array
    P: jax.Array
    nis: jax.Array
    innovation_dim: int = eqx.field(static=True)
    # the forward pass's terms the smoother needs
    x_update: jax.Array
    P_prior: jax.Array
    Phi: jax.Array
    earth: Earth = eqx.field(static=True, default=WGS84)

    def position_sigma(self):
        """1σ position uncertainty (M, 3) [m, north east down], on the filter's Earth."""
        r_m, r_n = self.earth.radii(self.nav.lat)
        d = jnp.stack(
            [
                r_m + self.nav.h,
                (r_n + self.nav.h) * jnp.cos(self.nav.lat),
                jnp.ones_like(self.nav.h),
            ],
            -1,
        )
        return jnp.sqrt(jnp.diagonal(self.P, axis1=-2, axis2=-1)[..., :3]) * d

    def nis_check(self, level: float = 0.99, early: int = 5) -> dict:
        """[`nis_check`][hrgjax.ins.ekf.nis_check] of this pass's `nis` (host; runs pooled)."""
        return nis_check(self.nis, self.innovation_dim, level, early)


class LooselyCoupled(eqx.Module):
    """Filter settings (module docstring).

    **Fields:** `imu` the [`ImuModel`][hrgjax.ins.sensors.ImuModel] whose noise densities and
    bias sizes the filter assumes; `gnss` the [`Gnss`][hrgjax.ins.gnss.Gnss] receiver;
    `position_sigma` [m, NED], `velocity_sigma` [m/s], `attitude_sigma` [rad] (3,): initial
    uncertainty, bounding the real initial error, the attitude's ≤ `MAX_ATTITUDE_SIGMA`
    (module docstring); `scale_factors`: 21 states instead of 15; `earth`."""

    imu: ImuModel
    gnss: Gnss
    position_sigma: jax.Array = eqx.field(converter=jnp.asarray, default=(3.0, 3.0, 5.0))
    velocity_sigma: jax.Array = eqx.field(converter=jnp.asarray, default=(0.1, 0.1, 0.1))
    attitude_sigma: jax.Array = eqx.field(converter=jnp.asarray, default=(1e-3, 1e-3, 5e-3))
    scale_factors: bool = eqx.field(static=True, default=False)
    earth: Earth = eqx.field(static=True, default=WGS84)

    def __check_init__(self):
        for name in ("position_sigma", "velocity_sigma", "attitude_sigma"):
            v = getattr(self, name)
            if not is_concrete(v):
                continue
            v = np.asarray(v)
            if v.size not in (1, 3) or not np.all(np.isfinite(v) & (v > 0)):
                raise ValueError(f"LooselyCoupled.{name} must be > 0 (1 or 3 values); got {v}")
            if name == "attitude_sigma" and np.any(v > MAX_ATTITUDE_SIGMA):
                raise ValueError(
                    f"LooselyCoupled.attitude_sigma {v} rad: above {MAX_ATTITUDE_SIGMA} rad the "
                    "small-angle error model reports σ too small; align first (hg.ins.alignment.align / "
                    "`hrgjax align`)"
                )
        imu = self.imu
        sizes = {
            "gyro_bias (or gyro_bias_instability)": imu.gyro_bias**2 + imu.gyro_bias_instability**2,
            "accel_bias (or accel_bias_instability)": imu.accel_bias**2
            + imu.accel_bias_instability**2,
        }
        if self.scale_factors:
            sizes.update(gyro_scale=imu.gyro_scale**2, accel_scale=imu.accel_scale**2)
        for name, v in sizes.items():
            if is_concrete(v) and not np.all(np.asarray(v) > 0):
                raise ValueError(
                    f"LooselyCoupled: the IMU model's {name} is the prior σ of the filter's "
                    f"states and must be > 0 on every axis; got {np.sqrt(np.asarray(v))} (a zero "
                    "σ makes the covariance singular)"
                )

    @property
    def n_states(self) -> int:
        """15, or 21 with scale factors."""
        return 21 if self.scale_factors else 15

    def _metres_to_states(self, lat, h):
        r_m, r_n = self.earth.radii(lat)
        return jnp.stack([1.0 / (r_m + h), 1.0 / ((r_n + h) * jnp.cos(lat)), -jnp.ones_like(h)])

    def initial_covariance(self, nav: NavState):
        """(n, n) initial covariance at `nav`: the initial sigmas, the sensor biases' sizes
        (and bias instabilities), the scale factors' sizes."""
        d = self._metres_to_states(nav.lat, nav.h)
        imu = self.imu
        var = [
            (jnp.broadcast_to(self.position_sigma, (3,)) * d) ** 2,
            jnp.broadcast_to(self.velocity_sigma, (3,)) ** 2,
            jnp.broadcast_to(self.attitude_sigma, (3,)) ** 2,
            imu.gyro_bias**2 + imu.gyro_bias_instability**2,
            imu.accel_bias**2 + imu.accel_bias_instability**2,
        ]
        if self.scale_factors:
            var += [imu.gyro_scale**2, imu.accel_scale**2]
        return jnp.diag(jnp.concatenate(var))

    def _dynamics(self, nav: NavState, w_b, f_b, T):
        """Φ and Q_d over the block T [s] (module docstring, step 2)."""
        c = nav.c_bn
        f, gg, ga = error_matrices_at(self.earth, False, nav.lat, nav.h, nav.v_ned, c, c @ f_b)
        n = self.n_states
        cols = [f, gg, ga]
        if self.scale_factors:
            cols += [gg * w_b[None], ga * f_b[None]]
        top = jnp.concatenate(cols, -1)
        big = jnp.concatenate([top, jnp.zeros((n - 9, n))], 0)
        imu = self.imu
        g9 = lambda g: jnp.concatenate([g, jnp.zeros((n - 9, 3))], 0)
        q = g9(gg) @ jnp.diag(imu.arw**2) @ g9(gg).T + g9(ga) @ jnp.diag(imu.vrw**2) @ g9(ga).T
        # each Gauss–Markov (σ, τ) folded into a walk of 2σ²/τ: no decay state (module docstring)
        walk = lambda k, s, tau: k**2 + 2 * s**2 / tau  # noqa: E731
        rw_g = walk(imu.gyro_rate_random_walk, imu.gyro_bias_instability, imu.gyro_correlation_time)
        rw_a = walk(imu.accel_random_walk, imu.accel_bias_instability, imu.accel_correlation_time)
        q = q.at[9:12, 9:12].add(jnp.diag(rw_g)).at[12:15, 12:15].add(jnp.diag(rw_a))
        return discretise(big, q, T)

    def _measurement(self, nav: NavState, w_eb, fix_pos, fix_vel):
        """Innovation (antenna minus fix, in state units; the longitude difference wrapped to
        ±π, so fixes may write longitude in (−180°, 180°]), H and R."""
        n = self.n_states
        c = nav.c_bn
        arm = self.gnss.lever_arm
        (la, lo, hh), v = antenna(self.earth, nav.lat, nav.lon, nav.h, nav.v_ned, c, w_eb, arm)
        d = self._metres_to_states(nav.lat, nav.h)
        h_pos = (
            jnp.zeros((3, n)).at[:, 0:3].set(jnp.eye(3)).at[:, 6:9].set(d[:, None] * skew(c @ arm))
        )
        nu = jnp.stack([la - fix_pos[0], wrap_angle(lo - fix_pos[1]), hh - fix_pos[2]])
        r = jnp.diag(d**2 * self.gnss.position_sigma**2)
        if not self.gnss.use_velocity:
            return nu, h_pos, r
        h_vel = (
            jnp.zeros((3, n))
            .at[:, 3:6]
            .set(jnp.eye(3))
            .at[:, 6:9]
            .set(skew(c @ jnp.cross(w_eb, arm)))
        )
        return (
            jnp.concatenate([nu, v - fix_vel]),
            jnp.concatenate([h_pos, h_vel]),
            jax.scipy.linalg.block_diag(r, jnp.diag(self.gnss.velocity_sigma**2)),
        )


def _powers(F, order=8):
    """I, F, F², …, F^order stacked: (order + 1, n, n)."""
    out = [jnp.eye(F.shape[-1], dtype=F.dtype)]
    for _ in range(order):
        out.append(out[-1] @ F)
    return jnp.stack(out)


def _taylor(powers, s: float):
    """Σ_k F^k s^k / k! from the stacked powers of F."""
    c = np.array([s**k / math.factorial(k) for k in range(powers.shape[0])])
    return jnp.einsum("k,kij->ij", c, powers)


def discretise(F, q, T: float):
    r"""$(\Phi, Q_d)$ of $\dot x = Fx + w$, $E[ww^\top] = q\,\delta$, over a GNSS interval
    `T` [s]: $\Phi(s)$ by its Taylor series to eighth order, and
    $Q_d = \int_0^T\Phi(s)\,q\,\Phi(s)^\top ds$ by three-point Gauss–Legendre (exact for the
    integrand's polynomial of degree ≤ 5). The error model's F is a slow, nearly nilpotent
    chain (attitude → velocity → position, rates ≲ 1e-3 s⁻¹), so for T ≤ 10 s both agree with
    the exact Van Loan exponential ([`hrgjax.kalman.van_loan`][hrgjax.kalman.van_loan]):
    Φ to 1e-14, $Q_d$ in units of the states' σ to 3e-11 at 1 s and 4e-8 at 10 s
    (tests/test_navigation_filter.py), at a fraction of its cost batched over flights
    (benchmarks/navigation.py). A longer interval is k = ⌈T / 10 s⌉ such steps of h = T/k
    composed ($\Phi = \phi_h^k$, $Q_d$ by $Q \leftarrow \phi_h Q \phi_h^\top + Q_h$; 6e-10 at
    30 s): no matrix exponential, so no LAPACK kernel in a batched flight
    (hrgjax/_threads.py)."""
    k = max(1, math.ceil(T / 10.0 - 1e-12))
    h = T / k
    x, w = np.polynomial.legendre.leggauss(3)
    powers = _powers(F)
    qd = 0.0
    for xi, wi in zip(x, w, strict=True):
        p = _taylor(powers, 0.5 * h * (1.0 + xi))
        qd = qd + (0.5 * h * wi) * (p @ q @ p.T)
    phi, qd = _taylor(powers, h), 0.5 * (qd + qd.T)
    if k == 1:
        return phi, qd

    def compose(_, pq):
        p, qq = pq
        qq = phi @ qq @ phi.T + qd
        return phi @ p, 0.5 * (qq + qq.T)

    return jax.lax.fori_loop(1, k, compose, (phi, qd))


def feedback(nav: NavState, x):
    """`nav` less the estimated navigation errors `x` (the filter's error state: δlat, δlon
    [rad], δh [m], δv_ned [m/s], attitude error [rad] first)."""
    q = quat_multiply(rotvec_to_quat(x[6:9]), nav.q_bn)
    return NavState(
        nav.lat - x[0], nav.lon - x[1], nav.h - x[2], nav.v_ned - x[3:6], q / jnp.linalg.norm(q)
    )


def loosely_coupled(
    settings: LooselyCoupled, initial: NavState, dtheta, dv, dt: float, fixes: GnssData
) -> FilterResult:
    """Run the filter (module docstring) from `initial` over IMU increments `dtheta`,
    `dv` (N, 3) [rad, m/s] at interval `dt` [s] with GNSS `fixes`
    ([`measure`][hrgjax.ins.gnss.measure]; their epochs must be every m-th IMU epoch,
    starting at m). **Returns** a [`FilterResult`][hrgjax.ins.ekf.FilterResult] at the start
    and every fix epoch."""
    require_x64("ins.loosely_coupled")
    check_state(initial)
    dtheta, dv = check_increments(dtheta, dv, dt)
    n, blocks = dtheta.shape[0], fixes.lat.shape[0]
    m = n // blocks if blocks else 0
    index = fixes.index
    if (
        m < 1
        or n % blocks
        or (is_concrete(index) and not np.array_equal(np.asarray(index), np.arange(m, n + 1, m)))
    ):
        raise ValueError(
            f"fixes: {blocks} fixes for {n} IMU intervals; they must fall every m-th IMU epoch "
            "from m to the end (as gnss.measure makes them for these increments)"
        )
    settings = eqx.tree_at(lambda s: s.gnss, settings, settings.gnss.without_outages())
    shape = lambda a: a.reshape((blocks, m) + a.shape[1:])
    res = _filter(settings, initial, shape(jnp.asarray(dtheta)), shape(jnp.asarray(dv)), dt, fixes)
    valid = jnp.concatenate([jnp.zeros(1, bool), jnp.asarray(fixes.valid)])
    return eqx.tree_at(lambda r: r.nis, res, jnp.where(valid, res.nis, jnp.nan))


@program(
    check=Check(
        "ins.loosely_coupled",
        nonfinite="ins.loosely_coupled: the filter diverged (NaN or inf); check the increments' "
        "units (rad, m/s), the fixes and the initial state",
    )
)
def _filter(settings, initial, dth_blocks, dv_blocks, dt, fixes):
    n_s = settings.n_states
    m = dth_blocks.shape[1]
    T = m * dt
    p0 = settings.initial_covariance(initial)
    zeros3 = jnp.zeros(3, p0.dtype)
    sensors0 = (zeros3, zeros3, zeros3, zeros3)

    def block(carry, inp):
        mech, sens, p = carry
        dth, dv, lat_f, lon_f, h_f, v_f, valid = inp
        bg, ba, sg, sa = sens
        dth_c = (dth - (bg * dt)[None]) / (1.0 + sg)[None]
        dv_c = (dv - (ba * dt)[None]) / (1.0 + sa)[None]
        mech, hist = jax.lax.scan(
            lambda c, x: step(settings.earth, dt, c, x), mech, (dth_c, dv_c), unroll=UNROLL
        )
        nav = mech[0]
        mid = hist[m // 2 - 1] if m > 1 else nav  # the state at the block's middle
        phi, qd = settings._dynamics(mid, jnp.sum(dth_c, 0) / T, jnp.sum(dv_c, 0) / T, T)
        prior = kalman.predict(kalman.Gaussian(jnp.zeros(n_s, p.dtype), p), phi, qd)
        w_eb = body_rate_wrt_earth(settings.earth, nav.lat, nav.c_bn, dth_c[-1], dt)
        nu, h, r = settings._measurement(nav, w_eb, (lat_f, lon_f, h_f), v_f)
        post, _, s, _ = kalman.update(prior, nu, h, r, mask=valid)
        w = whiten(cholesky(s), nu)  # ‖L⁻¹ν‖² = νᵀS⁻¹ν
        nis = jnp.where(valid, w @ w, 0.0)
        x = post.x
        nav = feedback(nav, x)
        lat2, h2, v2 = mech[1]
        prev2 = (lat2 - x[0], h2 - x[2], v2 - x[3:6])
        sens = (bg + x[9:12], ba + x[12:15]) + (
            (sg + x[15:18], sa + x[18:21]) if settings.scale_factors else (sg, sa)
        )
        out = (nav, sens, post.P, nis, x, prior.P, phi)
        return ((nav, prev2, mech[2]), sens, post.P), out

    inputs = (dth_blocks, dv_blocks, fixes.lat, fixes.lon, fixes.h, fixes.v_ned, fixes.valid)
    _, (nav, sens, ps, nis, xs, pp, phis) = jax.lax.scan(
        block, (start_carry(initial, p0.dtype), sensors0, p0), inputs
    )
    cat = lambda a0, a: jnp.concatenate([a0[None], a])
    nav = jax.tree_util.tree_map(cat, initial, nav)
    sens = [cat(zeros3, s) for s in sens]
    t = jnp.arange(dth_blocks.shape[0] + 1, dtype=p0.dtype) * T
    dim = 6 if settings.gnss.use_velocity else 3
    return FilterResult(
        t,
        nav,
        *sens,
        cat(p0, ps),
        cat(jnp.zeros((), p0.dtype), nis),
        dim,
        cat(jnp.zeros(n_s, p0.dtype), xs),
        cat(p0, pp),
        cat(jnp.eye(n_s, dtype=p0.dtype), phis),
        settings.earth,
    )


def smooth(result: FilterResult) -> FilterResult:
    """The RTS smoother of a forward pass (module docstring): the same epochs, every state
    given all the fixes; `nis` is NaN (no innovations)."""
    require_x64("ins.smooth")
    res = _smooth(eqx.tree_at(lambda r: r.nis, result, jnp.zeros_like(result.nis)))
    return eqx.tree_at(lambda r: r.nis, res, jnp.full_like(res.nis, jnp.nan))


@program(check=Check("ins.smooth"))
def _smooth(res):
    p_post, p_prior, phi, xu = res.P, res.P_prior, res.Phi, res.x_update

    def back(carry, k):
        s_next, ps_next = carry
        c = cho_solve(cholesky(p_prior[k + 1]), phi[k + 1] @ p_post[k]).T  # P Φᵀ P_prior⁻¹
        s = c @ (xu[k + 1] + s_next)
        ps = p_post[k] + c @ (ps_next - p_prior[k + 1]) @ c.T
        return (s, 0.5 * (ps + ps.T)), (s, ps)

    n = xu.shape[0]
    last = (jnp.zeros_like(xu[-1]), p_post[-1])
    _, (s, ps) = jax.lax.scan(back, last, jnp.arange(n - 1), reverse=True)
    s = jnp.concatenate([s, last[0][None]])
    ps = jnp.concatenate([ps, last[1][None]])
    nav = jax.vmap(feedback)(res.nav, s)
    scale = lambda a, k: a + s[:, k : k + 3] if s.shape[1] > k else a
    return FilterResult(
        res.t,
        nav,
        scale(res.gyro_bias, 9),
        scale(res.accel_bias, 12),
        scale(res.gyro_scale, 15),
        scale(res.accel_scale, 18),
        ps,
        res.nis,
        res.innovation_dim,
        res.x_update,
        res.P_prior,
        res.Phi,
        res.earth,
    )


@fused
def error_states(
    result: FilterResult,
    truth_nav: NavState,
    gyro_bias,
    accel_bias,
    earth=WGS84,
    gyro_scale=None,
    accel_scale=None,
):
    """The true error state of `result` at its epochs, in the filter's state order (module
    docstring), given the true navigation states there and the true sensor errors
    (biases (3,) or (M, 3); scale factors for 21 states)."""
    nav = result.nav
    _, _, att = navigation_errors(nav, truth_nav, earth)
    parts = [
        jnp.stack(
            [nav.lat - truth_nav.lat, wrap_angle(nav.lon - truth_nav.lon), nav.h - truth_nav.h], -1
        ),
        nav.v_ned - truth_nav.v_ned,
        att,
        jnp.broadcast_to(gyro_bias, result.gyro_bias.shape) - result.gyro_bias,
        jnp.broadcast_to(accel_bias, result.accel_bias.shape) - result.accel_bias,
    ]
    if result.P.shape[-1] == 21:
        parts += [
            jnp.broadcast_to(gyro_scale, result.gyro_scale.shape) - result.gyro_scale,
            jnp.broadcast_to(accel_scale, result.accel_scale.shape) - result.accel_scale,
        ]
    return jnp.concatenate(parts, -1)


@fused
def whitened_errors(errors, P):
    """The error states in units of their reported covariance, decorrelated: $L^{-1}e$ per
    epoch (..., M, n), L the Cholesky factor of `P` (..., M, n, n) (symmetric positive
    definite; its lower triangle is read; NaN or inf where it is not positive definite).
    `errors` (..., M, n) are the true error states. The sum of their squares is the
    [`nees`][hrgjax.ins.ekf.nees], and that of the first k the NEES of the first k states
    alone (L's leading block is their covariance's factor): one factorisation for both."""
    n = errors.shape[-1] if errors.ndim else 0
    try:
        if errors.ndim < 1 or P.shape[-2:] != (n, n):
            raise ValueError
        batch = jnp.broadcast_shapes(errors.shape[:-1], P.shape[:-2])
    except ValueError:
        raise ValueError(
            f"errors (..., M, n) and P (..., M, n, n) must match; got errors {errors.shape}, "
            f"P {P.shape}"
        ) from None
    one = lambda p, e: whiten(cholesky(p), e)  # noqa: E731
    p, e = jnp.broadcast_to(P, batch + (n, n)), jnp.broadcast_to(errors, batch + (n,))
    return jnp.vectorize(one, signature="(n,n),(n)->(n)")(p, e)


@fused
def nees(errors, P):
    """Normalised estimation error squared $e^\\top P^{-1}e$ per epoch (..., M), from the
    true error states `errors` (..., M, n) and the reported covariance `P` (..., M, n, n):
    symmetric positive definite (its lower triangle is read, by Cholesky; NaN or inf where it
    is not positive definite).
    For a consistent filter its mean over R Monte Carlo runs lies inside
    [`nees_band`][hrgjax.ins.ekf.nees_band] 95 % of the time."""
    return jnp.sum(whitened_errors(errors, P) ** 2, -1)


def nees_band(n_states: int, n_runs: int, level: float = 0.95):
    """The two-sided `level` interval of the mean NEES over `n_runs` runs of a consistent
    filter with `n_states` states: $\\chi^2_{Rn}$ quantiles divided by R (Bar-Shalom
    §5.4).

    **Raises:** `ValueError` naming the argument unless `n_states`, `n_runs` are whole
    numbers >= 1 and 0 < `level` < 1."""
    for name, x in (("n_states", n_states), ("n_runs", n_runs)):
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 1:
            raise ValueError(f"nees_band: {name} must be a whole number >= 1; got {x!r}")
    if isinstance(level, bool) or not isinstance(level, (int, float, np.number)):
        raise TypeError(f"nees_band: level must be a number in (0, 1); got {level!r}")
    if not 0.0 < level < 1.0:
        raise ValueError(
            f"nees_band: level must be a probability in (0, 1), e.g. 0.95; got {level}"
        )
    from ..allan.uncertainty import chi2_ppf

    a = 0.5 * (1.0 - level)
    dof = n_states * n_runs
    return chi2_ppf(a, dof) / n_runs, chi2_ppf(1.0 - a, dof) / n_runs


_DOES_NOT_FIT = (
    "the filter's model does not fit the data: its σ are not to be trusted (a better IMU grade "
    "than the sensor, or a P0 that does not bound the initial error)"
)
_TOO_LOW = (
    "the filter's model does not fit the data: its σ are not to be trusted (larger than the "
    "errors: an IMU model or GNSS σ worse than the real ones, or a Gauss–Markov bias "
    "instability with τ of a few fix intervals or less: the filter has no "
    "Gauss–Markov state, folds it into a random walk of density 2σ²/τ and is conservative, "
    "the more so the shorter τ — docs/navigation.md)"
)


def nis_check(nis, innovation_dim: int, level=0.99, early: int = 5, tolerance=0.03) -> dict:
    """The truth-free consistency test of a filter's innovations, on the host: `nis` (..., M)
    (NaN where no fix; leading axes are runs, pooled) of `innovation_dim` components per fix.

    For a consistent filter the N valid fixes' NIS are independent $\\chi^2_d$, so their mean
    lies inside $[\\chi^2_{dN}(\\alpha/2), \\chi^2_{dN}(1-\\alpha/2)]/N$ (`band`, two-sided
    at `level`) but with probability 1 − `level`; the mean NIS of the first `early` valid
    fixes of each run (k in all) lies below $\\chi^2_{dk}(0.999)/k$ (`early_bound`) but with
    probability 0.001. A better IMU grade than the sensor's shows in the whole-run mean, a P0
    that does not bound the initial error mostly in the early fixes. An EKF's linearisation
    moves the mean by ~1 % (Monte Carlo, matched model), which the band of many pooled runs
    resolves: a mean off d by less than `tolerance` (relative) is not counted against it.

    **Returns** a JSON-ready dict: `nis_mean`, `fixes` (N), `level`, `band`, `verdict`
    ("consistent", "does not fit", or "undefined" without a fix), `early`, `early_fixes` (k),
    `early_nis_mean`, `early_level` (0.999), `early_bound`, `early_verdict`, `runs_outside`
    (the fraction of runs whose own mean NIS is outside its band: expected 1 − `level`), and
    `message` (the lines to print: "" when both verdicts are "consistent"), `tolerance`."""
    from ..allan.uncertainty import chi2_ppf

    if not (0 < level < 1 and isinstance(early, int) and early >= 1 and tolerance >= 0):
        raise ValueError("nis_check: needs 0 < level < 1, early >= 1, tolerance >= 0")
    v = np.asarray(nis, float)
    if v.size == 0 or np.isinf(v).any():  # an infinite NIS: a filter that broke
        raise ValueError("nis_check: nis must be finite values (NaN where no fix), not empty")
    v = v.reshape(-1, v.shape[-1]) if v.ndim else v.reshape(1, 1)
    ok, d, a = np.isfinite(v), int(innovation_dim), 0.5 * (1.0 - level)
    band = lambda k: [chi2_ppf(a, d * k) / k, chi2_ppf(1.0 - a, d * k) / k]  # noqa: E731
    n = int(ok.sum())
    out = dict(nis_mean=None, fixes=n, level=level, band=None, verdict="undefined", early=early)
    out.update(early_fixes=0, early_nis_mean=None, early_level=0.999, early_bound=None)
    out.update(early_verdict="undefined", runs_outside=None, message="", tolerance=tolerance)
    if n == 0:
        return out
    mean, (lo, hi) = float(v[ok].mean()), band(n)
    first = np.concatenate([row[m][:early] for row, m in zip(v, ok, strict=True)])
    k, early_mean = first.size, float(first.mean())
    bound = chi2_ppf(0.999, d * k) / k
    rows = [(r[m].mean(), band(m.sum())) for r, m in zip(v, ok, strict=True) if m.any()]
    fits = lo <= mean <= hi or abs(mean / d - 1.0) <= tolerance
    early_fits = early_mean <= max(bound, (1.0 + tolerance) * d)
    lines = [
        f"NIS mean {mean:.3f} over {n} fixes is outside its {100 * level:g} % band "
        f"{lo:.3f}–{hi:.3f}: " + (_DOES_NOT_FIT if mean > hi else _TOO_LOW)
    ] * (not fits) + [
        f"NIS mean {early_mean:.2f} of each run's first {early} fixes ({k} in all) is beyond "
        f"its χ² 99.9 % point {bound:.2f}: " + _DOES_NOT_FIT
    ] * (not early_fits)
    verdict = lambda ok: "consistent" if ok else "does not fit"  # noqa: E731
    out.update(nis_mean=mean, band=[lo, hi], verdict=verdict(fits), early_fixes=k)
    out.update(early_nis_mean=early_mean, early_bound=bound, early_verdict=verdict(early_fits))
    outside = [not b[0] <= m <= b[1] for m, b in rows]
    out.update(runs_outside=float(np.mean(outside)), message="\n".join(lines))
    return out
