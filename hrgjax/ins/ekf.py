r"""Loosely-coupled GNSS/INS: an error-state extended Kalman filter with closed-loop
correction and a Rauch–Tung–Striebel smoother; their consistency figures (NEES, NIS) are in
[`hrgjax.ins.consistency`][hrgjax.ins.consistency] (also importable from here).

**States** (15; + 6 with `scale_factors=True`; + 6 with `gauss_markov=True`): the strapdown
error model's position, velocity and attitude errors
([`hrgjax.ins.strapdown.STATES`][hrgjax.ins.strapdown]: δφ, δλ [rad], δh [m], δv [m/s, NED],
φ [rad]), then the residual gyro and accelerometer biases $b - \hat b$ [rad/s, m/s²] (body),
then the residual scale factors $s - \hat s$, then the residual gyro and accelerometer
Gauss–Markov biases $g - \hat g$ [rad/s, m/s²] (body). Each is *estimate minus truth* for
the navigation states and *truth minus estimate* for the sensor states, so that the gyro
error left after correction is
$\delta\omega = \delta b + \delta g + \mathrm{diag}(\omega)\,\delta s$ as the error model
expects.

**Per GNSS interval** T (a block of IMU steps):

1. the increments, corrected with the current sensor estimates
   ($\Delta\theta \leftarrow (\Delta\tilde\theta - (\hat b_g + \bar g_g)\Delta t)/(1 + \hat s_g)$,
   $\bar g_g$ the Gauss–Markov estimate's mean over the step as it decays, same for Δv),
   run through [`mechanize`][hrgjax.ins.mechanization]'s step;
2. the covariance is propagated with $\Phi, Q_d$ of the error model
   ([`discretise`][hrgjax.ins.discretisation.discretise]: the Van Loan integrals by series and
   squaring, at any T/τ; its rounding grows with T/τ, 1e-10 of the states' σ at 1e5)
   (F at the block's middle state with the block's mean specific force and rate; white gyro and
   accelerometer noise densities `arw`, `vrw`; bias random walks; Gauss–Markov decay
   −1/τ driven by 2σ²/τ) — the same exact
   linearisation as [`hrgjax.ins.strapdown`][hrgjax.ins.strapdown];
3. at a valid fix the innovation (INS antenna position and velocity minus the fix, the
   longitude difference wrapped to ±π, with the lever arm's attitude sensitivity in H)
   updates the error state (Joseph form, [`hrgjax.kalman.update`][hrgjax.kalman.update]);
4. the estimate is fed back — position and velocity subtracted, attitude
   $q \leftarrow q(\hat\phi)\otimes q$, sensor estimates accumulated (the Gauss–Markov ones
   decayed by $e^{-T/\tau}$ first) — and reset to zero.

The smoother runs the RTS recursion on these reset error states backwards:
$s_k = C_k\,(\hat x^+_{k+1} + s_{k+1})$, $C_k = P^+_k\Phi_k^\top(P^-_{k+1})^{-1}$,
$P^s_k = P^+_k + C_k(P^s_{k+1} - P^-_{k+1})C_k^\top$, and applies $s_k$ to the filtered
state at k.

Sensor model behind the filter: the fixed biases are random constants with σ the
`ImuModel`'s `gyro_bias`/`accel_bias`, plus its bias random walks. The bias instability
(σ, τ): with `gauss_markov=True` a first-order Gauss–Markov state per axis (prior σ, decay
rate 1/τ, driving density 2σ²/τ: stationary); without, folded into the fixed bias's prior
(σ² added) and its random walk (density $2\sigma^2/\tau$: exact over times ≪ τ,
conservative beyond; on the tests' 120-s flight with 1-s fixes the attitude and gyro-bias σ
came out 2.6× and 3.6× too large at τ = 0.1 s, 2.1×, 2.5× at 1 s, 1.4× at 10 s, 1.1× at
100 s; with the Gauss–Markov states the errors' RMS over σ is 0.96–1.09 in every state
group from τ = 0.1 s to 10⁵ s: docs/navigation.md). Misalignments are not estimated. Every
sensor state needs a prior σ > 0 (a zero makes the covariance singular): the model's values are the sizes
the filter assumes. Its σ are honest only if that model and P0 bound the real sensor and
initial error: if not, σ are several times too small
([`nis_check`][hrgjax.ins.consistency.nis_check]).

**Small-angle limit.** The error state (F, H linear in the attitude error φ) holds for
attitude errors of a few degrees: an initial heading σ of 0.1 rad leaves the attitude σ
1.25× too small, 0.2 rad 1.3×, 0.5 rad 1.7–2× for a whole straight flight, with the NIS
unchanged (Monte Carlo); `attitude_sigma` above `MAX_ATTITUDE_SIGMA` is refused.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _checks, kalman
from .._checks import host_value, is_concrete
from .._compiled import Check, program
from .._linalg import cho_solve, cholesky, whiten
from .._x64 import require_x64
from ._fix_checks import check_fixes
from .consistency import error_states as error_states
from .consistency import nees as nees
from .consistency import nees_band as nees_band
from .consistency import nis_check
from .consistency import whitened_errors as whitened_errors
from .constants import WGS84, Earth
from .discretisation import discretise as discretise
from .gnss import Gnss, GnssData, antenna, body_rate_wrt_earth
from .mechanization import (
    UNROLL,
    NavState,
    check_increments,
    check_state,
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
    `accel_scale` (M, 3) [-] (zeros without scale-factor states); `gyro_gm`, `accel_gm`
    (M, 3) the Gauss–Markov bias estimates [rad/s, m/s²] (zeros without Gauss–Markov states;
    the total bias estimate is `gyro_bias + gyro_gm`); `P` (M, n, n) error covariance; `nis`
    (M,) normalised innovation squared (NaN where no fix); `innovation_dim` the number of
    measured components per fix; `earth` the filter's Earth model; `scale_factors`,
    `gauss_markov` (static) which sensor states `P` holds."""

    t: jax.Array
    nav: NavState
    gyro_bias: jax.Array
    accel_bias: jax.Array
    gyro_scale: jax.Array
    accel_scale: jax.Array
    gyro_gm: jax.Array
    accel_gm: jax.Array
    P: jax.Array
    nis: jax.Array
    innovation_dim: int = eqx.field(static=True)
    # the forward pass's terms the smoother needs
    x_update: jax.Array
    P_prior: jax.Array
    Phi: jax.Array
    earth: Earth = eqx.field(static=True, default=WGS84)
    scale_factors: bool = eqx.field(static=True, default=False)
    gauss_markov: bool = eqx.field(static=True, default=False)

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
        """[`nis_check`][hrgjax.ins.consistency.nis_check] of this pass's `nis` (host; runs pooled)."""
        return nis_check(self.nis, self.innovation_dim, level, early)


def _sigma(kind: str):  # LooselyCoupled.{kind}_sigma's converter: non-numbers in one line
    return lambda x: jnp.asarray(_checks.check_numbers(f"LooselyCoupled.{kind}_sigma", x,
                                                       "> 0 (1 or 3 values)"))  # fmt: skip


class LooselyCoupled(eqx.Module):
    """Filter settings (module docstring).

    **Fields:** `imu` the [`ImuModel`][hrgjax.ins.sensors.ImuModel] whose noise densities and
    bias sizes the filter assumes; `gnss` the [`Gnss`][hrgjax.ins.gnss.Gnss] receiver;
    `position_sigma` [m, NED], `velocity_sigma` [m/s], `attitude_sigma` [rad] (3,): initial
    uncertainty, bounding the real initial error, the attitude's ≤ `MAX_ATTITUDE_SIGMA`
    (module docstring); `scale_factors`: 6 scale-factor states; `gauss_markov`: 6
    Gauss–Markov bias states for the IMU's bias instability (σ, τ) instead of its fold into
    the fixed biases' prior and random walk (module docstring; it needs the fixed biases
    `gyro_bias`, `accel_bias` and the instabilities > 0: each is a state's prior σ);
    `earth`."""

    imu: ImuModel
    gnss: Gnss
    position_sigma: jax.Array = eqx.field(converter=_sigma("position"), default=(3.0, 3.0, 5.0))
    velocity_sigma: jax.Array = eqx.field(converter=_sigma("velocity"), default=(0.1, 0.1, 0.1))
    attitude_sigma: jax.Array = eqx.field(converter=_sigma("attitude"), default=(1e-3, 1e-3, 5e-3))
    scale_factors: bool = eqx.field(static=True, default=False)
    earth: Earth = eqx.field(static=True, default=WGS84)
    gauss_markov: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        for name, kind in (("imu", ImuModel), ("gnss", Gnss), ("earth", Earth)):
            if not isinstance(v := getattr(self, name), kind):
                raise TypeError(f"LooselyCoupled.{name} must be of type {kind.__name__}; got "
                                f"{_checks.describe(v)}")  # fmt: skip
        for name in ("scale_factors", "gauss_markov"):
            _checks.check_flag(f"LooselyCoupled.{name}", getattr(self, name))
        for name in ("position_sigma", "velocity_sigma", "attitude_sigma"):
            if (v := host_value(getattr(self, name))) is None:
                continue
            if v.shape not in ((), (1,), (3,)) or not np.all(np.isfinite(v) & (v > 0)):
                got = v.tolist() if v.size <= 3 else _checks.describe(getattr(self, name))
                raise ValueError(f"LooselyCoupled.{name} must be > 0 (1 or 3 values); got {got}")
            if name == "attitude_sigma" and np.any(v > MAX_ATTITUDE_SIGMA):
                raise ValueError(
                    f"LooselyCoupled.attitude_sigma {v} rad: above {MAX_ATTITUDE_SIGMA} rad the "
                    "small-angle error model reports σ too small; align first (hg.ins.alignment.align / "
                    "`hrgjax align`)"
                )
        imu = self.imu
        if self.gauss_markov:
            sizes = {"gyro_bias": imu.gyro_bias**2, "accel_bias": imu.accel_bias**2}
            sizes.update(
                gyro_bias_instability=imu.gyro_bias_instability**2,
                accel_bias_instability=imu.accel_bias_instability**2,
            )
        else:
            sizes = {
                "gyro_bias (or gyro_bias_instability)": imu.gyro_bias**2
                + imu.gyro_bias_instability**2,
                "accel_bias (or accel_bias_instability)": imu.accel_bias**2
                + imu.accel_bias_instability**2,
            }
        if self.scale_factors:
            sizes.update(gyro_scale=imu.gyro_scale**2, accel_scale=imu.accel_scale**2)
        for name, v in sizes.items():
            if is_concrete(v) and not np.all(np.asarray(v) > 0):
                hint = ""
                if self.gauss_markov and name in ("gyro_bias", "accel_bias"):
                    hint = (
                        f"; with gauss_markov=True the fixed-bias states no longer carry the bias "
                        f"instability: give {name} its own σ > 0 (e.g. 1e-3 × "
                        f"{name}_instability if the sensor has no fixed bias)"
                    )
                raise ValueError(
                    f"LooselyCoupled: the IMU model's {name} is the prior σ of the filter's "
                    f"states and must be > 0 on every axis; got {np.sqrt(np.asarray(v))} (a zero "
                    f"σ makes the covariance singular){hint}"
                )

    @property
    def n_states(self) -> int:
        """15, + 6 with scale factors, + 6 with Gauss–Markov states."""
        return 15 + 6 * self.scale_factors + 6 * self.gauss_markov

    @property
    def _gm_at(self) -> int:
        """The index of the first Gauss–Markov state."""
        return 21 if self.scale_factors else 15

    def _gm_decay(self, dt: float, m: int):
        """(m, 2) each IMU step's mean of exp(−t/τ) over a block of m steps of `dt` [s]
        (gyro τ, then accelerometer τ), and (2,) the decay over the block, exp(−m·dt/τ)."""
        r = dt / jnp.stack([self.imu.gyro_correlation_time, self.imu.accel_correlation_time])
        mean = (
            jnp.exp(-jnp.arange(m, dtype=r.dtype)[:, None] * r[None]) * (-jnp.expm1(-r) / r)[None]
        )
        return mean, jnp.exp(-m * r)

    def _metres_to_states(self, lat, h):
        r_m, r_n = self.earth.radii(lat)
        return jnp.stack([1.0 / (r_m + h), 1.0 / ((r_n + h) * jnp.cos(lat)), -jnp.ones_like(h)])

    def initial_covariance(self, nav: NavState):
        """(n, n) initial covariance at `nav`: the initial sigmas, the sensor biases' sizes
        (and bias instabilities, folded in without Gauss–Markov states), the scale factors'
        sizes, the bias instabilities (with Gauss–Markov states)."""
        d = self._metres_to_states(nav.lat, nav.h)
        imu = self.imu
        fold = 0.0 if self.gauss_markov else 1.0
        var = [
            (jnp.broadcast_to(self.position_sigma, (3,)) * d) ** 2,
            jnp.broadcast_to(self.velocity_sigma, (3,)) ** 2,
            jnp.broadcast_to(self.attitude_sigma, (3,)) ** 2,
            imu.gyro_bias**2 + fold * imu.gyro_bias_instability**2,
            imu.accel_bias**2 + fold * imu.accel_bias_instability**2,
        ]
        if self.scale_factors:
            var += [imu.gyro_scale**2, imu.accel_scale**2]
        if self.gauss_markov:
            var += [imu.gyro_bias_instability**2, imu.accel_bias_instability**2]
        return jnp.diag(jnp.concatenate(var))

    def _dynamics(self, nav: NavState, w_b, f_b, T):
        """Φ and Q_d over the block T [s] (module docstring, step 2)."""
        c = nav.c_bn
        f, gg, ga = error_matrices_at(self.earth, False, nav.lat, nav.h, nav.v_ned, c, c @ f_b)
        n = self.n_states
        cols = [f, gg, ga]
        if self.scale_factors:
            cols += [gg * w_b[None], ga * f_b[None]]
        if self.gauss_markov:
            cols += [gg, ga]  # a Gauss–Markov bias enters as the fixed one does
        top = jnp.concatenate(cols, -1)
        big = jnp.concatenate([top, jnp.zeros((n - 9, n))], 0)
        imu = self.imu
        g9 = lambda g: jnp.concatenate([g, jnp.zeros((n - 9, 3))], 0)
        q = g9(gg) @ jnp.diag(imu.arw**2) @ g9(gg).T + g9(ga) @ jnp.diag(imu.vrw**2) @ g9(ga).T
        tau_g, tau_a = imu.gyro_correlation_time, imu.accel_correlation_time
        # without Gauss–Markov states each (σ, τ) is folded into a walk of 2σ²/τ
        fold = 0.0 if self.gauss_markov else 1.0
        walk = lambda k, s, tau: k**2 + fold * 2 * s**2 / tau  # noqa: E731
        rw_g = walk(imu.gyro_rate_random_walk, imu.gyro_bias_instability, tau_g)
        rw_a = walk(imu.accel_random_walk, imu.accel_bias_instability, tau_a)
        q = q.at[9:12, 9:12].add(jnp.diag(rw_g)).at[12:15, 12:15].add(jnp.diag(rw_a))
        if not self.gauss_markov:
            return discretise(big, q, T)
        i, j = self._gm_at, self._gm_at + 3
        # τ below T·1e-15 decays as at T·1e-15: e^(−T/τ) is 0 and the driven variance σ²
        # either way, and the squarings stay within discretise's MAX_SQUARINGS
        tau_g, tau_a = jnp.maximum(tau_g, 1e-15 * T), jnp.maximum(tau_a, 1e-15 * T)
        rate = jnp.concatenate([jnp.full(3, 1.0 / tau_g), jnp.full(3, 1.0 / tau_a)])
        big = big.at[i : i + 6, i : i + 6].set(-jnp.diag(rate))
        drive = 2.0 * jnp.concatenate([imu.gyro_bias_instability**2 / tau_g,
                                       imu.accel_bias_instability**2 / tau_a])  # fmt: skip
        q = q.at[i : j + 3, i : j + 3].add(jnp.diag(drive))
        return discretise(big, q, T, fastest=jnp.maximum(1.0 / tau_g, 1.0 / tau_a))

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


def feedback(nav: NavState, x):
    """`nav` less the estimated navigation errors `x` (the filter's error state: δlat, δlon
    [rad], δh [m], δv_ned [m/s], attitude error [rad] first; (n,), n >= 9)."""
    if len(np.shape(x)) != 1 or np.shape(x)[0] < 9:
        raise ValueError(f"x must be (n,) error states, n >= 9 (navigation errors first); got "
                         f"shape {np.shape(x)}")  # fmt: skip
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
    if not isinstance(settings, LooselyCoupled):
        raise TypeError(f"loosely_coupled: settings must be a LooselyCoupled; got "
                        f"{_checks.describe(settings)}")  # fmt: skip
    check_state(initial)
    dtheta, dv = check_increments(dtheta, dv, dt)
    check_fixes(fixes, dt)
    n, blocks = dtheta.shape[0], fixes.lat.shape[0]
    m = n // blocks if blocks else 0
    index = fixes.index
    if (
        m < 1
        or n % blocks
        or (is_concrete(index) and not np.array_equal(np.asarray(index), np.arange(m, n + 1, m)))
    ):
        raise ValueError(
            f"loosely_coupled: fixes: {blocks} fixes for {n} IMU intervals; they must fall "
            "every m-th IMU epoch from m to the end (as gnss.measure makes them for these "
            "increments)"
        )
    settings = eqx.tree_at(lambda s: s.gnss, settings, settings.gnss.without_outages())
    settings = eqx.tree_at(lambda s: s.imu, settings, settings.imu.checked())  # traced fields
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
    sensors0 = (zeros3,) * 6
    gm_on, i_gm = settings.gauss_markov, settings._gm_at
    mean, decay = settings._gm_decay(dt, m) if gm_on else (np.zeros((m, 2)), np.ones(2))

    def block(carry, inp):
        mech, sens, p = carry
        dth, dv, lat_f, lon_f, h_f, v_f, valid = inp
        bg, ba, sg, sa, gg, ga = sens
        # the Gauss–Markov estimates decay as the biases' means do: each step's mean of them
        bg_k = bg[None] + mean[:, :1] * gg[None]
        ba_k = ba[None] + mean[:, 1:] * ga[None]
        dth_c = (dth - bg_k * dt) / (1.0 + sg)[None]
        dv_c = (dv - ba_k * dt) / (1.0 + sa)[None]
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
        gm = x[i_gm : i_gm + 3], x[i_gm + 3 : i_gm + 6]
        sens += (decay[0] * gg + gm[0], decay[1] * ga + gm[1]) if gm_on else (gg, ga)
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
        settings.scale_factors,
        gm_on,
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
    add = lambda a, k, on=True: a + s[:, k : k + 3] if on else a  # noqa: E731
    sf, gm = res.scale_factors, res.gauss_markov
    i = 21 if sf else 15
    return FilterResult(
        res.t,
        nav,
        add(res.gyro_bias, 9),
        add(res.accel_bias, 12),
        add(res.gyro_scale, 15, sf),
        add(res.accel_scale, 18, sf),
        add(res.gyro_gm, i, gm),
        add(res.accel_gm, i + 3, gm),
        ps,
        res.nis,
        res.innovation_dim,
        res.x_update,
        res.P_prior,
        res.Phi,
        res.earth,
        sf,
        gm,
    )
