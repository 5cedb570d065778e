r"""The fine stage of stationary alignment ([`align`][hrgjax.ins.alignment.align]): a Kalman
filter on zero velocity ([`fine_align`][hrgjax.ins.fine_alignment.fine_align], importable
from `hrgjax.ins.alignment` too, with `euler_deg`), run as *one* compiled program for every
record length in a bucket.

Every `step_s` the attitude and velocity are integrated from the summed increments and a
12-state filter — velocity error, attitude error φ, gyro and accelerometer biases
(NED-frame: constant at rest, one constant model), the stationary φ-angle model of
[`strapdown`][hrgjax.ins.strapdown] discretised by Van Loan — takes the computed velocity as
a measurement of its error (the vehicle is at rest); its estimate is fed back and reset.

**One program per bucket of lengths.** Every log has its own length, and a scan over K
steps compiled afresh for each K (7–9.5 s for the PSINS log's slices of 160 000–180 000
samples; the disk cache never served a new log). The steps' increments are padded with
zeros to a power-of-two number of steps (`hrgjax._compiled.bucket_size`, at
least 64) and the steps past K leave the filter's state as it was (masked), so the K steps'
results are the unpadded ones (bit for bit from 64 steps up; round-off below) and a log of
any length in a bucket already compiled compiles nothing, whatever its sample rate or
`step_s` (only the small program summing each step's samples is per samples-a-step):
`benchmarks/align_compile.py`. The padded steps cost run time only (≤ 2×: 0.06 s for the
PSINS log's 1 740 steps on a CPU).
"""

from __future__ import annotations

import types

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _checks, plausible
from .._compiled import bucket_size, device, fused
from ..kalman import Gaussian, update, van_loan
from ..units import DEG, DEG_PER_H
from .constants import MAX_LAT_DEG, WGS84, earth_rate_ned
from .imu_log import ImuLog, wrap_heading_deg
from .mechanization import skew
from .strapdown import augmented, error_matrices_at
from .trajectory import dcm_to_euler

FINE_DEFAULTS = types.MappingProxyType({
    "arw": 0.01 * DEG / 60.0,
    "vrw": 1e-4,
    "velocity_noise": 0.01,
    "gyro_bias_std": 0.05 * DEG_PER_H,
    "accel_bias_std": 1e-3,
    "attitude_std_deg": (0.5, 0.5, 5.0),
})  # fmt: skip
"""`fine_align`'s (and `align`'s) defaults: angle random walk `arw` [rad/√s] (0.01 °/√h),
velocity random walk `vrw` [m/s/√s], zero-velocity noise `velocity_noise` [m/s], the
navigation-grade gyro-bias σ `gyro_bias_std` [rad/s] (0.05 °/h), `accel_bias_std` [m/s²],
and the start attitude σ `attitude_std_deg` (level, level, heading) [°] beyond the biases."""


def check_log(where: str, log) -> None:
    """A one-line `TypeError` naming `where` unless `log` is an `ImuLog`."""
    if not isinstance(log, ImuLog):
        raise TypeError(f"{where}: log must be an ImuLog (hrgjax.ins.alignment.ImuLog, or "
                        f"load_psins(path)); got {_checks.describe(log)}")  # fmt: skip


def check_gyrocompass_latitude(lat: float) -> None:
    """Refuse |`lat`| [rad] beyond [`MAX_LAT_DEG`][hrgjax.ins.constants.MAX_LAT_DEG]:
    gyrocompassing is impossible at the poles.

    **Raises:** `ValueError`, one line, naming `ImuLog.lat`."""
    if abs(lat) > MAX_LAT_DEG * DEG:
        raise ValueError(
            f"ImuLog.lat = {lat:.6g} rad ({lat / DEG:.4g}°) is within {90 - MAX_LAT_DEG:g}° of a "
            f"pole: gyrocompassing finds north from the horizontal Earth rate ω_ie·cos(lat), "
            f"which vanishes there; alignment needs |lat| <= {MAX_LAT_DEG:g}°"
        )


ROTATION_TOL = 1e-6
"""The largest |CᵀC − I| entry of a start attitude `c0` that `fine_align` takes as a rotation
(float32 round-off is 1e-7); beyond it, or with det C < 0 (a reflection), it is refused: the
filter turns `c0` and never makes it orthonormal again."""

_NOISE = {
    "arw": ("a finite number >= 0 [rad/√s]", _checks.FINITE_NONNEGATIVE, "imu_arw"),
    "vrw": ("a finite number >= 0 [m/s/√s]", _checks.FINITE_NONNEGATIVE, "imu_vrw"),
    "velocity_noise": ("a finite number > 0 [m/s] (R = its square)", _checks.FINITE_POSITIVE,
                       None),
    "gyro_bias_std": ("a finite number >= 0 [rad/s]", _checks.FINITE_NONNEGATIVE,
                      "imu_gyro_bias"),
    "accel_bias_std": ("a finite number >= 0 [m/s²]", _checks.FINITE_NONNEGATIVE,
                       "imu_accel_bias"),
}  # fmt: skip
"""The forms and rules of `fine_align`'s noise options (`check_fine_options`), and the
`hrgjax.plausible.RANGES` entry each is held to where concrete — `ImuModel`'s (bounds
excluded, the message naming the datasheet units it may be in: `arw=0.01` is °/√h typed as
rad/√s)."""


def check_fine_options(where: str, *, step_s=1.0, start_s=0.0,
                       attitude_std_deg=FINE_DEFAULTS["attitude_std_deg"],
                       start_bias_jacobian=None, **noise) -> None:  # fmt: skip
    """Refuse, in one line naming `where` and the option, a `step_s` [s] not a finite number
    > 0, a `start_s` [s] not one >= 0, a noise option (`arw`, `vrw`, `velocity_noise`,
    `gyro_bias_std`, `accel_bias_std`: `FINE_DEFAULTS`) not one real number, or where
    concrete not finite and >= 0 (`velocity_noise` > 0) or outside its `ImuModel` range
    (`_NOISE`: `arw` 2.5e-3 rad/√s, `vrw` 0.05 m/s/√s, `gyro_bias_std` 0.75 rad/s,
    `accel_bias_std` 3 m/s², bounds excluded), an `attitude_std_deg` not 3 such
    values [°], a `start_bias_jacobian` not numbers or with a NaN. Traced values pass
    unchecked (`fine_align` is differentiable in them)."""
    for name, x, ok in (("step_s", step_s, _checks.FINITE_POSITIVE),
                        ("start_s", start_s, _checks.FINITE_NONNEGATIVE)):  # fmt: skip
        form = f"a finite number {'> 0' if name == 'step_s' else '>= 0'} [s]"
        _checks.check_number(f"{where}: {name}", x, "s")
        _checks.check_values(f"{where}: {name}", x, ok, form)
    for name, x in noise.items():
        form, ok, quantity = _NOISE[name]
        _checks.check_number(f"{where}: {name}", x)
        _checks.check_values(f"{where}: {name}", x, ok, form)
        if quantity is not None:  # concrete values only: plausible.check passes a tracer
            plausible.check(f"{where}: {name} [{form.split('[')[1]}", x, quantity)
    form = "(level, level, heading) [°], 3 finite numbers >= 0"
    _checks.check_numbers(f"{where}: attitude_std_deg", attitude_std_deg, form, shape=(3,))
    _checks.check_values(f"{where}: attitude_std_deg", attitude_std_deg,
                         _checks.FINITE_NONNEGATIVE, form)  # fmt: skip
    if start_bias_jacobian is not None:
        name = f"{where}: start_bias_jacobian"
        _checks.check_numbers(name, start_bias_jacobian, "(3, 6) [rad per (rad/s, m/s²)]")
        _checks.check_finite_host(name, start_bias_jacobian)


def check_step(where: str, step_s: float, dt: float) -> None:
    """A one-line `ValueError` naming `where` for a `step_s` [s] under half the log's sample
    interval `dt` [s] (to 1e-9 relative): a filter step sums whole samples, at least one
    (exactly half a sample runs one a step)."""
    if step_s / dt < 0.5 * (1.0 - 1e-9):
        raise ValueError(f"{where}: step_s = {float(step_s)!r} s is under half the log's sample "
                         f"interval ({dt:.4g} s): a filter step sums whole samples")  # fmt: skip


def check_start_attitude(where: str, c0) -> None:
    """Refuse, in one line naming `where`, a start attitude `c0` that is not a (3, 3)
    body-to-NED rotation matrix: not numbers, another shape, where concrete a NaN, |CᵀC − I|
    beyond `ROTATION_TOL` or det C < 0."""
    form = "a (3, 3) body-to-NED rotation matrix"
    _checks.check_numbers(f"{where}: c0", c0, form, shape=(3, 3))
    _checks.check_finite_host(f"{where}: c0", c0)
    c = _checks.host_value(c0)
    if c is None:
        return
    off = float(np.abs(c.T @ c - np.eye(3)).max())
    if off > ROTATION_TOL or np.linalg.det(c) < 0:
        why = (f"|CᵀC − I| reaches {off:.3g} (over {ROTATION_TOL:g})" if off > ROTATION_TOL
               else f"det C = {np.linalg.det(c):.6g}: a reflection")  # fmt: skip
        raise ValueError(f"{where}: c0 must be {form}; {why} (orthonormalise it: U Vᵀ of its "
                         "SVD)")  # fmt: skip


@fused
def _rotation(v):
    """exp([v×]) (Rodrigues)."""
    a2 = v @ v
    a = jnp.sqrt(a2 + 1e-300)
    small = a2 < 1e-12
    s = jnp.where(small, 1.0 - a2 / 6.0, jnp.sin(a) / a)
    c = jnp.where(small, 0.5 - a2 / 24.0, (1.0 - jnp.cos(a)) / (a2 + 1e-300))
    k = skew(v)
    return jnp.eye(3) + s * k + c * (k @ k)


@fused
def euler_deg(c):
    """(heading [0, 360), pitch, roll) [°] of the body-to-NED matrix `c` (3, 3) (a heading
    within 1e-9° below 360 is 0: [`wrap_heading_deg`][hrgjax.ins.imu_log.wrap_heading_deg])."""
    roll, pitch, heading = dcm_to_euler(c)
    return jnp.stack([wrap_heading_deg(heading / DEG), pitch / DEG, roll / DEG])


@fused
def euler_std_deg(c, p_phi):
    """1σ of (heading, pitch, roll) [°] of the body-to-NED matrix `c` (3, 3) for the attitude
    error covariance `p_phi` (3, 3) [rad²] (φ = rotation of the computed frame,
    C_true = (I + [φ×]) C), linearised."""
    jac = jax.jacfwd(lambda phi: jnp.stack(dcm_to_euler(_rotation(phi) @ c)[::-1]))(jnp.zeros(3))
    cov = jac @ p_phi @ jac.T
    return jnp.sqrt(jnp.clip(jnp.diag(cov), 0.0)) / DEG


class FineRun(eqx.Module):
    """[`fine_run`][hrgjax.ins.fine_alignment.fine_run]'s result over the K filter steps.

    **Fields:** `t` (K,) [s] (each step's end); `c_bn` (K, 3, 3) the body-to-NED matrix;
    `p` (K, 12, 12) the covariance of velocity error (NED) [m/s], φ [rad], gyro [rad/s] and
    accelerometer [m/s²] biases (NED frame); `biases` (6,) the estimated biases, body frame
    (mapped by the final Ĉ); `innovations` (K, 3) [m/s], `innovation_std` (K, 3) [m/s] their
    predicted σ (√diag S), `nis` (K,) νᵀS⁻¹ν; `history_deg` (K, 3) (heading, pitch, roll)
    [°] and `std_history_deg` (K, 3) their 1σ [°]."""

    t: jax.Array
    c_bn: jax.Array
    p: jax.Array
    biases: jax.Array
    innovations: jax.Array
    innovation_std: jax.Array
    nis: jax.Array
    history_deg: jax.Array
    std_history_deg: jax.Array


def fine_align(log: ImuLog, c0, *, step_s: float = 1.0, start_s: float = 0.0,
               arw: float = FINE_DEFAULTS["arw"], vrw: float = FINE_DEFAULTS["vrw"],
               velocity_noise: float = FINE_DEFAULTS["velocity_noise"],
               gyro_bias_std: float = FINE_DEFAULTS["gyro_bias_std"],
               accel_bias_std: float = FINE_DEFAULTS["accel_bias_std"],
               attitude_std_deg=FINE_DEFAULTS["attitude_std_deg"],
               start_bias_jacobian=None):  # fmt: skip
    """Kalman fine alignment from the body-to-NED start `c0` (module docstring).

    **Arguments:** `step_s`: filter step [s] (increments summed over it); `start_s`: time
    from the log's start at which the fine stage begins; `arw` [rad/√s], `vrw` [m/s/√s]:
    sensor white noise; `velocity_noise` [m/s]: measurement noise of the zero-velocity
    update (sway of a parked vehicle); `gyro_bias_std` [rad/s], `accel_bias_std` [m/s²]:
    the assumed sensor grade (the heading σ ends at `gyro_bias_std / (ω_ie cos lat)`);
    `attitude_std_deg` (level, level, heading) [°]: the start attitude's error σ — with
    `start_bias_jacobian` (3, 6), A = ∂φ/∂(gyro, accel bias) of `c0`'s error
    ([`coarse_bias_jacobian`][hrgjax.ins.alignment.coarse_bias_jacobian] for a coarse
    start), the part of it the biases do not explain: the prior is then φ = A b + that, its
    correlation with the bias states kept (without it a start whose error comes from the
    biases counts that information twice). `align` adds the coarse means' white noise to it.
    Defaults: [`FINE_DEFAULTS`][hrgjax.ins.fine_alignment.FINE_DEFAULTS].

    **Returns:** `(t (K,), C_bn (K, 3, 3), P (K, 12, 12), biases (6,))`: P's states are
    velocity error (NED) [m/s], φ [rad], gyro [rad/s] and accelerometer [m/s²] biases in
    the NED frame; `biases` in the body frame (mapped by the final Ĉ).

    **Raises:** `ValueError` for a log within 1° of a pole (no gyrocompassing there); one
    line (`TypeError` for a non-number) for an option out of its range
    ([`check_fine_options`][hrgjax.ins.fine_alignment.check_fine_options]), a `c0` that is
    not a rotation ([`check_start_attitude`][hrgjax.ins.fine_alignment.check_start_attitude]),
    a `step_s` under half a sample, a `start_s` leaving fewer than 2 steps."""
    run = fine_run(log, c0, step_s=step_s, start_s=start_s, arw=arw, vrw=vrw,
                   velocity_noise=velocity_noise, gyro_bias_std=gyro_bias_std,
                   accel_bias_std=accel_bias_std, attitude_std_deg=attitude_std_deg,
                   start_bias_jacobian=start_bias_jacobian)  # fmt: skip
    return run.t, run.c_bn, run.p, run.biases


def fine_run(log: ImuLog, c0, *, step_s: float = 1.0, start_s: float = 0.0,
             arw: float = FINE_DEFAULTS["arw"], vrw: float = FINE_DEFAULTS["vrw"],
             velocity_noise: float = FINE_DEFAULTS["velocity_noise"],
             gyro_bias_std: float = FINE_DEFAULTS["gyro_bias_std"],
             accel_bias_std: float = FINE_DEFAULTS["accel_bias_std"],
             attitude_std_deg=FINE_DEFAULTS["attitude_std_deg"],
             start_bias_jacobian=None) -> FineRun:  # fmt: skip
    """[`fine_align`][hrgjax.ins.fine_alignment.fine_align] (same arguments) with its
    diagnostics: a [`FineRun`][hrgjax.ins.fine_alignment.FineRun]. One compiled program per
    power-of-two bucket of steps (module docstring).

    **Raises:** `ValueError` for a log within 1° of a pole, one shorter than 2 steps after
    `start_s`, or a `start_bias_jacobian` not (3, 6); as `fine_align` for the rest."""
    check_log("fine_align", log)
    check_gyrocompass_latitude(log.lat)
    check_fine_options("fine_align", step_s=step_s, start_s=start_s, arw=arw, vrw=vrw,
                       velocity_noise=velocity_noise, gyro_bias_std=gyro_bias_std,
                       accel_bias_std=accel_bias_std, attitude_std_deg=attitude_std_deg,
                       start_bias_jacobian=start_bias_jacobian)  # fmt: skip
    check_start_attitude("fine_align", c0)
    dt = log.dt
    check_step("fine_align", step_s, dt)
    m = max(1, int(round(step_s / dt)))
    i0 = int(round(start_s / dt))
    k = (log.t.shape[0] - i0) // m
    if k < 2:
        raise ValueError(f"fine_align: the log ({log.t.shape[0] * dt:.4g} s) holds fewer than 2 "
                         f"steps of step_s = {step_s:g} s after start_s = {start_s:g} s")  # fmt: skip
    noise = [arw, vrw, velocity_noise, gyro_bias_std, accel_bias_std]
    inputs = (log.dtheta, log.dvel, log.t, c0, noise, attitude_std_deg, start_bias_jacobian)
    xp = jnp if any(isinstance(x, jax.core.Tracer) for x in jax.tree.leaves(inputs)) else np
    if start_bias_jacobian is None:
        jac = np.zeros((3, 6))
    else:
        jac = xp.asarray(start_bias_jacobian, dtype=float)
        if jac.shape != (3, 6):
            raise ValueError(
                f"fine_align start_bias_jacobian must have shape (3, 6) [rad per (rad/s, "
                f"m/s²)]; got {jac.shape}"
            )
    size = bucket_size(k)  # steps, padded: one program serves every K up to it
    sl = slice(i0, i0 + k * m)
    att_std = xp.asarray(attitude_std_deg, dtype=float) * DEG
    if xp is jnp:  # traced (grad, vmap, jit over the log, c0 or the noise): jnp throughout
        pad = jnp.zeros(((size - k) * m, 3))
        dth, dv = (_step_sums(jnp.concatenate([jnp.asarray(x)[sl], pad]), m)
                   for x in (log.dtheta, log.dvel))  # fmt: skip
        t = jnp.asarray(log.t)[sl].reshape(k, m)[:, -1]
        out = _fine(jnp.asarray(c0, dtype=float), dth, dv, jnp.asarray(k), m * dt, log.lat,
                    log.h, jnp.stack([jnp.asarray(v, dtype=float) for v in noise]), att_std,
                    jnp.asarray(jac))  # fmt: skip
        cs, ps, body, nu, nu_std, nis, hist, std = out
        return FineRun(t, cs[:k], ps[:k], body, *(x[:k] for x in (nu, nu_std, nis, hist, std)))
    # concrete: sliced and padded on the host, so no program depends on the log's length
    dth, dv = np.zeros((size * m, 3)), np.zeros((size * m, 3))
    dth[: k * m], dv[: k * m] = np.asarray(log.dtheta)[sl], np.asarray(log.dvel)[sl]
    dth, dv = _step_sums(device(dth), m), _step_sums(device(dv), m)  # a small program per m
    t = np.asarray(log.t)[sl].reshape(k, m)[:, -1]
    out = _fine(device(c0, float), device(dth), device(dv), device(k), device(m * dt),
                device(log.lat), device(log.h), device(noise, float), device(att_std),
                device(jac))  # fmt: skip
    cs, ps, body, nu, nu_std, nis, hist, std = (np.asarray(x) for x in out)
    return FineRun(device(t), *(device(x[:k]) for x in (cs, ps)), device(body),
                   *(device(x[:k]) for x in (nu, nu_std, nis, hist, std)))  # fmt: skip


@fused(static_argnames=("m",))
def _step_sums(x, m: int):
    """The sums of `x` (n·m, 3) over each m rows: (n, 3)."""
    return x.reshape(-1, m, 3).sum(1)


@eqx.filter_jit
def _fine(c0, dth, dv, count, h_step, lat, h, noise, att_std, jac):
    """The filter over the steps' increments `dth`, `dv` (size, 3) whose steps from `count`
    on are padding: they leave the state as it was."""
    size = dth.shape[0]
    arw, vrw, vnoise, bg_std, ba_std = (noise[i] for i in range(5))
    g_n = WGS84.gravity_ned(lat, h)
    w_ie = earth_rate_ned(lat)
    z3 = jnp.zeros(3)

    # NED-frame bias states (constant at rest): body-frame ones mapped by the moving Ĉ read
    # its turns as level accelerometer-bias information (z-RMS 1.3 at 88°)
    f, gg, ga = error_matrices_at(WGS84, False, lat, h, z3, jnp.eye(3), -g_n)
    fa = augmented(f, gg, ga)[3:, 3:]  # drop the (known) position states
    gw = jnp.concatenate([gg[3:], jnp.zeros((6, 3))])
    aw = jnp.concatenate([ga[3:], jnp.zeros((6, 3))])
    phi_k, qd = van_loan(fa, arw**2 * gw @ gw.T + vrw**2 * aw @ aw.T, h_step)
    jac = jac @ jnp.kron(jnp.eye(2), c0.T)  # ∂φ/∂(NED biases): b_body = c0ᵀ b_ned

    var_b = jnp.concatenate([jnp.full(3, bg_std**2), jnp.full(3, ba_std**2)])
    p0 = jnp.diag(jnp.concatenate([jnp.full(3, 0.1) ** 2, att_std**2, var_b]))
    cross = jac * var_b[None, :]  # A Σ_b
    p0 = p0.at[3:6, 6:].set(cross).at[6:, 3:6].set(cross.T)
    p0 = p0.at[3:6, 3:6].add(cross @ jac.T)  # φ = A b + independent part
    hm = jnp.zeros((3, 12)).at[:, :3].set(jnp.eye(3))
    r = jnp.eye(3) * vnoise**2

    def step(carry, inp):
        c, v, bias, p = carry  # bias: NED frame
        dth_k, dv_k, valid = inp
        dth_k = dth_k - c.T @ bias[:3] * h_step
        dv_k = dv_k - c.T @ bias[3:] * h_step
        c_new = _rotation(-w_ie * h_step) @ c @ _rotation(dth_k)
        c_mid = 0.5 * (c + c_new)
        v_new = v + c_mid @ dv_k + (g_n - 2.0 * jnp.cross(w_ie, v)) * h_step
        prior = Gaussian(jnp.zeros(12), phi_k @ p @ phi_k.T + qd)
        post, nu, s, _ = update(prior, v_new, hm, r)
        x = post.x
        c_new = _rotation(x[3:6]) @ c_new  # C ← (I + [φ×]) Ĉ
        new = (c_new, v_new - x[:3], bias + x[6:], post.P)
        carry = jax.tree.map(lambda a, b: jnp.where(valid, a, b), new, carry)  # padding: kept
        nis = nu @ jnp.linalg.solve(s, nu)
        return carry, (c_new, post.P, nu, jnp.sqrt(jnp.diag(s)), nis)

    valid = jnp.arange(size) < count
    (c, _, bias, _), (cs, ps, nu, nu_std, nis) = jax.lax.scan(
        step, (c0, z3, jnp.zeros(6), p0), (dth, dv, valid)
    )
    body = jnp.concatenate([c.T @ bias[:3], c.T @ bias[3:]])  # body frame
    hist = jax.vmap(euler_deg)(cs)
    std = jax.vmap(euler_std_deg)(cs, ps[:, 3:6, 3:6])
    return cs, ps, body, nu, nu_std, nis, hist, std
