r"""Ferraris calibration of a six-axis IMU (Ferraris et al. 1995, *Procedure for effortless
in-field calibration of three-axis rate gyros and accelerometers*; imucal's implementation).

**Model** (SI; a = specific force, ω = angular rate, both along orthogonal body axes):

$$a_s = M_a\,a + b_a, \qquad \omega_s = M_g\,\omega + G\,a + b_g,$$

M_a, M_g (3 × 3) scale and misalignment, b_a [m/s²] and b_g [rad/s] biases, G
[rad/s per m/s²] the gyros' g-sensitivity.

**Estimates.** With $u^\pm_i$ the mean accelerometer output on face $i_\pm$ (a = ±g e_i) and
$w^\pm_i$ the gyros' (ω = 0 in the original method; on a real bench, the Earth's rate,
see below):

- $M_a e_i = (u^+_i - u^-_i) / 2g$; each accelerometer's bias from its own ± pair,
  $b_{a,i} = (u^+_{i,i} + u^-_{i,i}) / 2$ (the axis along gravity, insensitive to small
  tilts of the face);
- $G e_i = (w^+_i - w^-_i) / 2g$; $b_g = \frac13\sum_i (w^+_i + w^-_i)/2$ (G cancels in each
  pair);
- a turn of angle φ about axis i (that axis vertical) integrates to
  $\sum_k (\omega_{s,k} - b_g - G\,\hat a_k)\,\Delta t_k = M_g\,\varphi\,e_i$ with
  $\hat a_k = M_a^{-1}(a_{s,k} - b_a)$, which gives M_g column by column.

**The Earth's rate** (Ω = 7.292115e-5 rad/s; `hrgjax.imu._earth`) flips with each face
pair and so enters G: Ω sin φ / g on the diagonal, up to Ω cos φ / g across it (5.26e-6 rad/s
per m/s² at 45°, far above a tactical session's σ(G) ≈ 3e-8 and above a MEMS one's 3e-6).
Its vertical part is along the specific force, a g-sensitivity (Ω sin φ / g) M_g that the
turns remove with G; with `lat_deg` it is then taken out of G exactly. Its horizontal part
depends on the faces' headings, which the procedure leaves free: a systematic in the
statistics' covariance (into G through the pair differences, into b_g through the pair
sums); so is the vertical part where the latitude is not given. The gyros' drift
intensity q is then measured within the faces too, which the Earth's rate cannot reach.
`earth_rate=0` declares a record without it (a simulation), the method's textbook σ.

Everything is a function of each section's sums, so the standard errors follow by linear
propagation (`jax.jacfwd` of the estimator) of those sums' covariance, formed as follows
(`sigma_source` names the parts used):

- **"repeats"**: a key with ≥ 2 ranges contributes the scatter of its repeats / R (which
  holds whatever changes when the IMU is put down again);
- **"white noise"**: a key with one range, white noise of the static faces' per-sample
  scatter (σ²/n for a face mean, σ²ΣΔt² for a turn's sums);
- **"bias drift"**: where every key has one range, an in-run random walk of each
  channel's bias from the session's start, q² min(s − t₀, t − t₀), propagated exactly
  into every section sum (`hrgjax.imu._drift`); q (one for the gyros, one for the
  accelerometers, `bias_walk`) is measured by the twelve combinations of face means that
  vanish for any calibration (each channel's three ± pair sums are equal) and, for the
  gyros, by each face's first-half-minus-second-half means (the pair sums hold the
  Earth's horizontal rate, the halves of a face do not). Six
  contrasts per sensor pin q down poorly — its maximum-likelihood value is exactly 0 in
  about 6 % of sessions that do drift, and σ built on it missed a gyro bias by 11σ — so
  `bias_walk` is q's posterior mean (Jeffreys prior, `_drift.walk_posterior_mean`),
  which holds what the contrasts allow of q. It is positive on any noisy session (the
  source is then "white noise and bias drift"), 0 on noise-free data. The biases are
  those at the session's start (its earliest section's first row).

Monte Carlo with known truth (`benchmarks/coverage_ferraris.py`; figures in docs/imu.md)
checks the coverage with white noise, a random walk and a Gauss–Markov drift of the
biases, pooled and per parameter. Not covered: the repeats' σ (Student-t with R − 1
degrees of freedom, and blind to the drift common to all repeats); face tilts (inexact
flips), which the accelerometers' q absorbs only in part. The turn angles are exact unless
`turn_deg_std` says otherwise (then added analytically: M_g's column i scales as 1/φ_i).
A gyro clipped in a turn, or an accelerometer on a face, is refused
(`hrgjax.imu.sections.saturation`): its sums are wrong by far more than any σ.

This module is the method: the section statistics and their covariance
(`session_statistics`), the estimates and `ferraris`. What it returns,
[`ImuCalibration`][hrgjax.imu.ImuCalibration] with its file (`load_calibration`), lives in
`hrgjax.imu._calibration` and is re-exported here."""

from __future__ import annotations

import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .. import plausible
from .._warn import user_stacklevel
from .._x64 import require_x64
from ..units import DEG, EARTH_RATE
from ._calibration import FORMAT as FORMAT
from ._calibration import G_RANGE_M_S2 as G_RANGE_M_S2
from ._calibration import PARAMETERS as PARAMETERS
from ._calibration import ImuCalibration as ImuCalibration
from ._calibration import check_g, check_turn_deg, flat_parameters, per_turn
from ._calibration import load_calibration as load_calibration
from ._drift import half_difference, walk_kernel, walk_posterior_mean
from ._earth import check_earth_rate, check_lat_deg, earth_parts, horizontal_covariance, turn_spin
from .data import ImuData
from .sections import (
    FACES,
    SECTION_KEYS,
    TURNS,
    Sections,
    TurnCutWarning,
    cut_turn,
    parse_sections,
    saturation,
)

G_DATA_TOLERANCE = 0.01
"""How far (relative) the declared `g` may be from what the static face pairs read, beyond
the plausible scale error (`hrgjax.plausible.RANGES["imu_scale"]`, ±10 %; `relaxed(imu_scale=…)`
widens both). The pairs' half-differences |u⁺ − u⁻|/2 = g |M_a e_i| are free of the biases
and carry the scale errors and, to second order, the misalignment (≤ 1 % within the
plausible ±0.1 rad), so any sensor `ImuCalibration.known` accepts passes, and a g or a unit
that the data contradict (×9.81, ×1000, ×3.28) is refused. Until 2026-12 the faces' mean
|u±| was held to 5 %: biases of 2.5 m/s² and scale errors of 7 % (both plausible) were
refused, with no way to widen it."""

# Flat layout of a session's section statistics: per face (x_p, x_a, …) mean accel (3) and
# mean gyro (3); per turn (x, y, z) Σ gyro·Δt (3), Σ accel·Δt (3) and Σ Δt (1).
_FACE_AT = {k: 6 * i for i, k in enumerate(FACES)}
_TURN_AT = {k: 36 + 7 * i for i, k in enumerate(TURNS)}
_FACE_AT_GYRO = {k: at + 3 for k, at in _FACE_AT.items()}
N_STATS = 57


def _estimate(stats, g, turn_rad, omega_up=0.0):
    """The Ferraris estimates (33 parameters, `PARAMETERS` order) from the section
    statistics (57,) — the textbook formulas, linear except for M_a⁻¹ and 1/φ. `omega_up`
    [rad/s]: the Earth's rate along the vertical, Ω sin φ, which the face pairs read as a
    g-sensitivity (Ω sin φ / g) M_g on top of G and the turns remove with it
    (`hrgjax.imu._earth`); G is that less (Ω sin φ / g) M_g."""
    face = stats[:36].reshape(6, 6)  # rows x_p, x_a, y_p, y_a, z_p, z_a; cols accel, gyro
    u_p, u_n = face[0::2, :3].T, face[1::2, :3].T  # columns: faces x, y, z
    w_p, w_n = face[0::2, 3:].T, face[1::2, 3:].T
    m_a = (u_p - u_n) / (2.0 * g)
    b_a = jnp.diag(u_p + u_n) / 2.0
    gsens = (w_p - w_n) / (2.0 * g)
    b_g = jnp.mean((w_p + w_n) / 2.0, axis=1)
    turn = stats[36:].reshape(3, 7)
    s_g, s_a, t = turn[:, :3], turn[:, 3:6], turn[:, 6]
    a_int = jnp.linalg.solve(m_a, (s_a - t[:, None] * b_a[None, :]).T)  # (3 comps, 3 turns)
    w_int = s_g.T - b_g[:, None] * t[None, :] - gsens @ a_int  # (3 comps, 3 turns)
    m_g = w_int / turn_rad[None, :]
    return flat_parameters(m_a, b_a, m_g, b_g, gsens - omega_up / g * m_g)


# the estimates and their Jacobian in one compiled pass (the estimate is jacfwd's aux output)
_estimate_and_jacobian = jax.jit(
    jax.jacfwd(lambda s, g, turn, up=0.0: (_estimate(s, g, turn, up),) * 2, has_aux=True)
)
# the same with the derivative by the vertical Earth rate too: ((∂/∂stats, ∂/∂Ω_up), estimate)
_estimate_and_jacobians = jax.jit(
    jax.jacfwd(
        lambda s, g, turn, up: (_estimate(s, g, turn, up),) * 2, argnums=(0, 3), has_aux=True
    )  # fmt: skip
)


def _key_stats(data: ImuData, key: str, start: int, end: int) -> np.ndarray:
    if key in FACES:
        return np.concatenate([data.accel[start:end].mean(0), data.gyro[start:end].mean(0)])
    dt = data.dt[start:end, None]
    return np.concatenate([(data.gyro[start:end] * dt).sum(0), (data.accel[start:end] * dt).sum(0),
                           [dt.sum()]])  # fmt: skip


def session_statistics(data: ImuData, sections: Sections):
    """The section statistics the estimator needs: `(stats (57,), covariance (57, 57),
    noise_std (6,), sigma_source)`. A key with repeats contributes the mean of its repeats'
    statistics; its covariance is their scatter / R where R ≥ 2, else white noise of the
    static faces' per-sample scatter (σ²/n for a face mean, σ²ΣΔt² for a turn's sums) plus,
    where every key has one range, the in-run bias drift that the faces' disagreement allows
    (a random walk of the biases from the record's start, its intensity q's posterior
    mean, see `hrgjax.imu._drift`).

    The covariance is that of a record without the Earth's rate, as `ferraris(...,
    earth_rate=0)` takes it: neither the Earth's horizontal rate (the faces' headings)
    nor an unknown vertical one is in it, and the gyros' q reads what the Earth's rate
    puts in the ± pair sums as drift. `ferraris` adds both where `earth_rate` > 0 and
    measures the gyros' q within the faces (`hrgjax.imu._earth`)."""
    if not isinstance(data, ImuData):  # was an AttributeError
        raise TypeError(f"session_statistics takes an hg.imu.ImuData; got {type(data).__name__}")
    got = _statistics(data, parse_sections(sections, len(data)))
    return got.stats, got.white + got.drift, got.noise_std, got.source


class _Statistics(NamedTuple):
    stats: np.ndarray  # (57,)
    white: np.ndarray  # (57, 57): repeats' scatter or white noise
    drift: np.ndarray  # (57, 57): the bias random walk's part (zeros where not estimated)
    noise_std: np.ndarray  # (6,): per-sample σ, gyro xyz then accel xyz
    bias_walk: np.ndarray  # (2,): q of the gyros [rad/s/√s] and the accelerometers [m/s²/√s]
    source: str


def _statistics(data: ImuData, sections: Sections) -> _Statistics:
    return _with_drift(data, sections, *_section_sums(data, sections))


def _section_sums(data: ImuData, sections: Sections):
    """`(stats, white, noise_std, sources)`: the statistics, their repeats' or white-noise
    covariance, the per-sample noise and the names of the sources used."""
    stats = np.zeros(N_STATS)
    cov = np.zeros((N_STATS, N_STATS))
    # per-sample noise: deviations of every face sample from its own range's mean
    dev = np.concatenate([
        np.concatenate([data.gyro[s:e], data.accel[s:e]], axis=1)
        - np.concatenate([data.gyro[s:e], data.accel[s:e]], axis=1).mean(0)
        for k in FACES for s, e in sections[k]
    ])  # fmt: skip
    dof = dev.shape[0] - sum(len(sections[k]) for k in FACES)
    sample_cov = dev.T @ dev / max(dof, 1)  # (6, 6): gyro xyz, accel xyz
    c_g, c_a = sample_cov[:3, :3], sample_cov[3:, 3:]
    noise_std = np.sqrt(np.diag(sample_cov))
    sources = set()
    for key in SECTION_KEYS:
        ranges = sections[key]
        per = np.stack([_key_stats(data, key, s, e) for s, e in ranges])
        r = per.shape[0]
        at = _FACE_AT[key] if key in FACES else _TURN_AT[key]
        width = per.shape[1]
        stats[at : at + width] = per.mean(0)
        if r >= 2:
            d = per - per.mean(0)
            block = d.T @ d / (r - 1) / r
            sources.add("repeats")
        else:
            if key in FACES:
                n = ranges[0][1] - ranges[0][0]
                block = np.zeros((6, 6))
                block[:3, :3], block[3:, 3:] = c_a / n, c_g / n
            else:
                s, e = ranges[0]
                sum_dt2 = float((data.dt[s:e] ** 2).sum())
                block = np.zeros((7, 7))
                block[:3, :3], block[3:6, 3:6] = c_g * sum_dt2, c_a * sum_dt2
            sources.add("white noise")
        cov[at : at + width, at : at + width] = block
    return stats, cov, noise_std, sources


def _with_drift(data, sections, stats, cov, noise_std, sources, earth=None) -> _Statistics:
    """The statistics with the bias drift's part where every key has one range. `earth`
    (57, 57) or None: the Earth's horizontal rate's covariance in the statistics, which the
    gyros' pair contrasts carry besides the noise (`_drift_covariance`)."""
    sources = set(sources)
    drift, walk = np.zeros((N_STATS, N_STATS)), np.zeros(2)
    if "repeats" not in sources:
        drift, walk = _drift_covariance(data, sections, stats, cov, earth)
        if np.any(walk > 0):
            sources.add("bias drift")
    source = " and ".join(s for s in ("repeats", "white noise", "bias drift") if s in sources)
    return _Statistics(stats, cov, drift, noise_std, walk, source or "none")


def _drift_covariance(data: ImuData, sections: Sections, stats: np.ndarray, white: np.ndarray,
                      earth: np.ndarray | None = None):  # fmt: skip
    """The statistics' covariance from a random walk of the biases (one intensity for the
    gyros, one for the accelerometers) and the two intensities q [unit/√s]: q's posterior
    mean (`walk_posterior_mean`), not its maximum-likelihood value, which six contrasts
    make 0 in some drifting sessions. The accelerometers' q from the faces' ± pair sums;
    the gyros' from those, with the Earth's horizontal rate (`earth`) in their covariance,
    and from each face's first-half-minus-second-half means, which the Earth's rate at a
    fixed heading cannot reach (`hrgjax.imu._drift`)."""
    dt = data.dt
    pieces = [[(s, e, np.full(e - s, 1.0 / (e - s)) if key in FACES else dt[s:e], 1.0)]
              for key in SECTION_KEYS for s, e in sections[key][:1]]  # fmt: skip
    faces = [(s, e) for key in FACES for s, e in sections[key][:1] if e - s >= 2]
    origin = min(s for ranges in sections.values() for s, _ in ranges)
    per_key = walk_kernel(data.time, pieces + [half_difference(s, e) for s, e in faces], origin)
    n_aug = N_STATS + 3 * len(faces)  # the statistics, then each face's halves (x, y, z)
    kernels = [np.zeros((n_aug, n_aug)) for _ in range(2)]  # gyro, accel
    for c in range(3):
        h_at = [N_STATS + 3 * f + c for f in range(len(faces))]
        for sensor, (face_at, turn_at) in enumerate(((3 + c, c), (c, 3 + c))):
            idx = [_FACE_AT[k] + face_at for k in FACES] + [_TURN_AT[k] + turn_at for k in TURNS]
            kernels[sensor][np.ix_(idx + h_at, idx + h_at)] = per_key
    gyro = np.asarray(data.gyro)
    split = [(s, s + (e - s) // 2, e) for s, e in faces]
    halves = np.concatenate([gyro[s:m].mean(0) - gyro[m:e].mean(0) for s, m, e in split])
    (s0, e0), at = sections[FACES[0]][0], _FACE_AT_GYRO[FACES[0]]
    c_g = white[at : at + 3, at : at + 3] * (e0 - s0)  # the gyros' per-sample covariance
    h_white = np.zeros((3 * len(faces),) * 2)
    for f, (s, m, e) in enumerate(split):
        h_white[3 * f : 3 * f + 3, 3 * f : 3 * f + 3] = c_g * (1.0 / (m - s) + 1.0 / (e - m))
    walk = np.zeros(2)
    for sensor, offset in enumerate((3, 0)):
        pair = _pair_contrasts(offset)
        cov = white + (earth if sensor == 0 and earth is not None else 0.0)
        if sensor == 0 and faces:  # the gyros: the pair contrasts and the within-face ones
            contrasts = np.zeros((6 + len(halves), n_aug))
            contrasts[:6, :N_STATS] = pair
            contrasts[6:, N_STATS:] = np.eye(len(halves))
            residual = np.concatenate([pair @ stats, halves])
            c_white = np.block([[pair @ cov @ pair.T, np.zeros((6, len(halves)))],
                                [np.zeros((len(halves), 6)), h_white]])  # fmt: skip
        else:
            contrasts = np.zeros((6, n_aug))
            contrasts[:, :N_STATS] = pair
            residual, c_white = pair @ stats, pair @ cov @ pair.T
        walk[sensor] = walk_posterior_mean(residual, c_white,
                                           contrasts @ kernels[sensor] @ contrasts.T)  # fmt: skip
    k_g, k_a = (k[:N_STATS, :N_STATS] for k in kernels)
    return walk[0] ** 2 * k_g + walk[1] ** 2 * k_a, walk


def _pair_contrasts(offset: int) -> np.ndarray:
    """(6, 57): for each channel c of the sensor at `offset` in a face's six numbers (0:
    accel, 3: gyro), the x pair sum minus the y pair sum and y minus z (zero without
    noise for any calibration)."""
    out = np.zeros((6, N_STATS))
    for c in range(3):
        pair = np.zeros((3, N_STATS))
        for i in range(3):
            pair[i, [12 * i + offset + c, 12 * i + 6 + offset + c]] = 1.0
        out[2 * c], out[2 * c + 1] = pair[0] - pair[1], pair[1] - pair[2]
    return out


def ferraris(
    data: ImuData,
    sections=None,
    g: float = 9.81,
    turn_deg: float | tuple[float, float, float] = 360.0,
    *,
    turn_deg_std: float | tuple[float, float, float] = 0.0,
    gyro_range_dps: float | None = None,
    accel_range_g: float | None = None,
    lat_deg: float | None = None,
    earth_rate: float = EARTH_RATE,
) -> ImuCalibration:
    """Ferraris calibration of a six-axis IMU from one session (see the module notes).

    **Arguments:**

    - `data`: the session, an [`ImuData`][hrgjax.imu.ImuData] (SI inside).
    - `sections`: a mapping, a JSON file (imucal's section list reads as is) or None to find
      them with [`detect_sections`][hrgjax.imu.detect_sections]; a key may list repeated
      ranges (see [`parse_sections`][hrgjax.imu.sections.parse_sections]).
    - `g`: local gravity [m/s²] (9.81 as imucal; the local value, e.g. 9.8062 at 45° latitude
      at sea level, makes M_a absolute), within
      [`G_RANGE_M_S2`][hrgjax.imu.ferraris.G_RANGE_M_S2].
    - `turn_deg`: the angle of each turn [°], one number or (x, y, z); positive is
      right-handed about the axis (counter-clockwise seen from above with the axis up);
      imucal's default clockwise hand turn is −360.
    - `turn_deg_std`: the standard deviation [°] of each turn's true angle about `turn_deg`,
      one number or (x, y, z); 0 (the default) takes the turns as exact. M_g's column i
      is inversely proportional to turn i's angle, so its variance gains
      (M_g[:, i] · turn_deg_std_i / turn_deg_i)²: 1° on 360° is 0.28 % of each diagonal
      element, far above the noise part (~1e-4) of a MEMS session. Hand turns against a
      mark: about 1°; a turntable: its angle error.
    - `gyro_range_dps`, `accel_range_g`: the sensors' full-scale ranges [°/s] and [g]
      (optional): a turn sample of the gyros, or a face sample of the accelerometers,
      at 99.9 % of its range or beyond is refused as clipped. Without them clipping is
      still found where a channel sits flat at its extreme (`hrgjax.imu.sections.saturation`).
    - `lat_deg`: the bench's latitude [°], north positive. The gyros read the Earth's rate
      on every face, and each face pair's difference takes it into G (Ω sin φ / g on the
      diagonal, up to Ω cos φ / g across it: 5.26e-6 rad/s per m/s² at 45°, against a σ of
      ~3e-6 for a MEMS session, 3e-8 for a tactical one). Given, the vertical part is
      removed from G exactly; the horizontal part, which depends on the faces' headings,
      enters the covariance as a systematic (σ = Ω cos φ per horizontal component on each
      face: neither a bound nor an average — √2 wide for independent random headings,
      exceeded at z = √2 on G where every pair reverses the rate and z = 2 on b_g where two
      pairs keep it, a tumble about north), and the gyros' bias drift is measured within
      the faces, where it cannot reach. None (the default): the latitude is unknown, and
      both parts enter the covariance (a latitude anywhere on the globe: Ω/√3 vertical,
      which puts G's diagonal at z = √3 |sin φ| on a bench at φ: 1.22 at 45°, 1.73 at the
      poles). See `hrgjax.imu._earth`.
    - `earth_rate`: the rotation rate [rad/s] of the ground under the bench,
      [`EARTH_RATE`][hrgjax.units.EARTH_RATE] (the default); 0 declares a record without
      it — a simulation by [`ferraris_session`][hrgjax.imu.ferraris_session] without
      `lat_deg` — and gives the method's textbook σ.

    **Returns:** an [`ImuCalibration`][hrgjax.imu.ImuCalibration] with standard errors.

    **Raises:** `ValueError` for bad sections (overlapping keys included); for a `g` outside
    [`G_RANGE_M_S2`][hrgjax.imu.ferraris.G_RANGE_M_S2] or whose static face pairs read a
    scale |u⁺ − u⁻| / 2g beyond `hrgjax.plausible.RANGES["imu_scale"]` and
    `G_DATA_TOLERANCE` (1 %); for a turn whose measured angle has the other sign than
    `turn_deg` or differs from it by more than a quarter turn, or that integrates about
    another axis a fraction of its angle (M_g's off-diagonal) beyond
    `hrgjax.plausible.RANGES["imu_misalignment"]` (±0.1; naming it); for faces whose
    accelerometer readings do not put the ±g axis where the key says; for a gyro that
    saturates in a turn, or an accelerometer on a face (naming the channel and the section:
    a clipped turn integrates short, M_g reads low with a σ that knows nothing of it); for
    a negative or non-finite `turn_deg_std` or range; for a `lat_deg` outside [−90, 90],
    or an `earth_rate` that is negative or beyond
    `hrgjax.plausible.RANGES["earth_rate_radps"]` (1e-4 rad/s: 15.04 °/h or 4.18e-3 °/s
    typed as rad/s, named so).

    **Warns:** [`TurnCutWarning`][hrgjax.imu.sections.TurnCutWarning] where the gyro still
    turns just outside a turn section ([`cut_turn`][hrgjax.imu.sections.cut_turn], with
    the gyros' measured drift): the section leaves out motion and M_g is off by more than
    its σ."""
    require_x64("hg.imu.ferraris")
    if not isinstance(data, ImuData):
        raise TypeError(
            f"ferraris takes an hg.imu.ImuData (hg.imu.load); got {type(data).__name__}"
        )
    if sections is None:
        from .sections import detect_sections

        sections = detect_sections(data)
    else:
        sections = parse_sections(sections, len(data))
    g = check_g(g)
    turns = check_turn_deg(turn_deg, "turn_deg")
    turn_std = _check_turn_std(turn_deg_std)
    lat = None if lat_deg is None else check_lat_deg(lat_deg)
    omega_up, var_up, var_h = earth_parts(lat, check_earth_rate(earth_rate))
    _check_saturation(data, sections, g, gyro_range_dps, accel_range_g, np.broadcast_to(turns, 3))
    sums = _section_sums(data, sections)
    stats = sums[0]
    _check_faces(stats, g)
    _check_gravity(stats, g)
    (jac, d_up), params = _estimate_and_jacobians(
        jnp.asarray(stats), g, jnp.deg2rad(jnp.asarray(turns)), omega_up
    )
    jac, d_up, params = np.asarray(jac), np.asarray(d_up), np.asarray(params)
    _check_turns(params, turns)
    earth = np.zeros((N_STATS, N_STATS))
    if var_h > 0:  # the horizontal rate, heading unknown: a systematic of the statistics
        earth = horizontal_covariance(params[12:21].reshape(3, 3), var_h,
                                      turn_spin(data, sections), _FACE_AT_GYRO, _TURN_AT, N_STATS)  # fmt: skip
    got = _with_drift(data, sections, *sums, earth=earth)
    cut = cut_turn(data, sections, walk=float(got.bias_walk[0]))
    if cut:
        warnings.warn(f"hrgjax.imu.ferraris: {cut}", TurnCutWarning, stacklevel=user_stacklevel())
    cov = got.white + got.drift + earth
    p_cov = jac @ cov @ jac.T + _turn_covariance(params, turns, turn_std)
    p_cov = p_cov + var_up * np.outer(d_up, d_up)  # an unknown vertical rate, common to all
    source = got.source + (" and the Earth's rate" if var_h > 0 or var_up > 0 else "")
    source += " and turn angles" if np.any(turn_std > 0) else ""
    p = jnp.asarray(params)
    return ImuCalibration(
        p[:9].reshape(3, 3), p[9:12], p[12:21].reshape(3, 3), p[21:24], p[24:33].reshape(3, 3),
        jnp.asarray((p_cov + p_cov.T) / 2), jnp.asarray(got.noise_std), g=g,
        turn_deg=tuple(float(t) for t in turns), sigma_source=source,
        bias_walk=jnp.asarray(got.bias_walk),
    )  # fmt: skip


def _check_gravity(stats: np.ndarray, g: float) -> None:
    """The declared g against the static face pairs' mean half-difference |u⁺ − u⁻|/2
    (bias-free: g |M_a e_i|), within the plausible scale error plus `G_DATA_TOLERANCE`."""
    pairs = [stats[12 * i : 12 * i + 3] - stats[12 * i + 6 : 12 * i + 9] for i in range(3)]
    read = float(np.mean(np.linalg.norm(pairs, axis=1))) / 2.0
    low, high, _ = plausible.RANGES["imu_scale"]
    if not low - G_DATA_TOLERANCE <= read / g - 1.0 <= high + G_DATA_TOLERANCE:
        raise ValueError(
            f"g = {g:g} m/s² but the static face pairs read a mean |u⁺ − u⁻|/2 of {read:.4g} "
            f"m/s² (scale {read / g:.4g}, beyond the plausible scale error {low:g} … {high:g} "
            f"and {G_DATA_TOLERANCE:.0%}); give the local gravity [m/s²] and check the "
            "accelerometer unit and the sections (hrgjax.plausible.relaxed(imu_scale=…) "
            "widens it)"
        )


def _check_faces(stats: np.ndarray, g: float) -> None:
    for i, key in enumerate(FACES):
        a = stats[6 * i : 6 * i + 3]
        axis, sign = "xyz".index(key[0]), 1.0 if key.endswith("_p") else -1.0
        if sign * a[axis] < 0.5 * np.linalg.norm(a):
            raise ValueError(
                f"sections: face {key!r} reads accel {np.round(a, 3).tolist()} m/s²: its "
                f"{key[0]} axis is not {'up' if sign > 0 else 'down'} (expected about "
                f"{sign * g:+.2f} m/s² on {key[0]}); check the section's rows"
            )


def _check_turns(params: np.ndarray, turns: np.ndarray) -> None:
    m_g = params[12:21].reshape(3, 3)
    for i, key in enumerate(TURNS):
        measured = m_g[i, i] * turns[i]
        if m_g[i, i] < 0.75 or m_g[i, i] > 1.25:
            scale = abs(m_g[i, i])
            if 0.75 < scale < 1.25:
                hint = f"; the turn went the other way: pass turn_deg={-turns[i]:g}"
            elif 0.75 < scale * DEG < 1.25 and abs(turns[i]) < 8.0:
                hint = f"; turn_deg is in degrees: pass {np.rad2deg(turns[i]):.4g}, not radians"
            elif 0.75 < scale / DEG < 1.25 or 0.75 < scale * DEG < 1.25:
                hint = "; the gyro unit is declared wrong (deg/s read as rad/s or the other way)"
            elif 0.75 < scale / 1000.0 < 1.25 or 0.75 < scale * 1000.0 < 1.25:
                hint = ("; the time stamps' unit is wrong (milliseconds read as seconds or the "
                        "other way: 1000× off)")  # fmt: skip
            else:
                hint = (
                    "; check the section's rows, turn_deg, the gyro unit or the time stamps' unit"
                )
            raise ValueError(
                f"sections: turn {key!r} integrates to {measured:.1f}° about {key[0]} but "
                f"turn_deg is {turns[i]:g}°{hint}"
            )
        # about the other axes the turn reads M_g[j, i] φ_i: a misalignment, held to the
        # range ImuCalibration.known holds M_g to (a norm of 10 % of φ refused 4–5°)
        low, high, unit = plausible.RANGES["imu_misalignment"]
        angles = m_g[:, i] * turns[i]  # the turn's integral about x, y, z [°]
        off = np.delete(m_g[:, i], i)
        if np.any((off <= low) | (off >= high)):
            j = int(np.argmax(np.abs(off)))
            raise ValueError(
                f"sections: turn {key!r} integrates to {np.round(angles, 1).tolist()}° about "
                f"x, y, z: {off[j]:.3g} of turn_deg ({turns[i]:g}°) about "
                f"{np.delete(list('xyz'), i)[j]}, beyond the plausible misalignment {low:g} … "
                f"{high:g} {unit}; a turn section must hold one turn about its own axis (check "
                "the section's rows; hrgjax.plausible.relaxed(imu_misalignment=…) widens it)"
            )


def _turn_covariance(params: np.ndarray, turns: np.ndarray, turn_std: np.ndarray) -> np.ndarray:
    """(33, 33): the turn angles' uncertainty in the parameters. Only M_g depends on the
    angles, column i as 1/φ_i: ∂M_g[:, i]/∂φ_i = −M_g[:, i]/φ_i, independent turns."""
    m_g = params[12:21].reshape(3, 3)
    out = np.zeros((33, 33))
    for i in range(3):
        d = np.zeros(33)
        d[12 + 3 * np.arange(3) + i] = -m_g[:, i] * turn_std[i] / turns[i]
        out += np.outer(d, d)
    return out


def _check_turn_std(turn_deg_std) -> np.ndarray:
    form = "a standard deviation [°] ≥ 0, one or three (x, y, z turns), e.g. 1.0 for hand turns"
    return per_turn(turn_deg_std, "turn_deg_std", form, lambda v: v >= 0)


CLIPPED_SHORT = 0.02
"""A gyro's flat top at its extreme counts as clipping (no range given) where the turn's
integrated rate falls this share short of the declared turn angle."""


def _check_saturation(data: ImuData, sections: Sections, g: float, gyro_range_dps,
                      accel_range_g, turns=None) -> None:  # fmt: skip
    """Refuse a gyro clipped in a turn or an accelerometer clipped on a face (see
    `hrgjax.imu.sections.saturation`), naming the channel and the section. Without a range,
    a gyro's flat top counts only where its turn integrates `CLIPPED_SHORT` short of `turns`
    [°] (a turntable's constant rate is flat and whole; a clipped turn loses angle), an
    accelerometer's only beyond 1.5 g."""
    limits = []
    for name, value, to_si in (("gyro_range_dps", gyro_range_dps, DEG),
                               ("accel_range_g", accel_range_g, g)):  # fmt: skip
        ok = value is None or (isinstance(value, int | float | np.number)
                               and not isinstance(value, bool) and np.isfinite(value) and value > 0)  # fmt: skip
        if not ok:
            raise ValueError(f"{name} must be a positive full-scale range or None; got {value!r}")
        limits.append(None if value is None else float(value) * to_si)
    gyro = np.asarray(data.gyro)
    for i, key in enumerate(TURNS):
        got = saturation(data, sections[key], sensor="gyro", limit=limits[0])
        if got and limits[0] is None and turns is not None:
            turned = abs(sum(gyro[s:e, i].sum() for s, e in sections[key])) / float(data.rate_hz)
            got = got if turned < (1 - CLIPPED_SHORT) * np.deg2rad(abs(turns[i])) else None
        if got:
            raise ValueError(
                f"turn {key!r}: {got}: the turn integrates short and M_g would read low; turn "
                "more slowly (a 360° turn shaped like 1 − cos over T s peaks at 720/T °/s) or "
                "set the gyro to a wider range"
            )
    faces = [r for key in FACES for r in sections[key]]
    for key in FACES:
        got = saturation(data, sections[key], sensor="accel", limit=limits[1], noise_ranges=faces,
                         above=1.5 * g)  # fmt: skip
        if got:
            raise ValueError(
                f"face {key!r}: {got}: the face mean is biased; set the accelerometer to a "
                "wider range (a face reads 1 g)"
            )
