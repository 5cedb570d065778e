"""The Earth's rate in a Ferraris session (`hrgjax.imu.ferraris`).

On a bench at latitude φ the gyros sense the Earth's rate Ω (7.292115e-5 rad/s): Ω sin φ
along the local vertical and Ω cos φ north. Each face pair's difference (w⁺ − w⁻)/2g, the
estimate of G, takes it up: the vertical part (the axis flips with the face) as Ω sin φ / g
on G's diagonal, the horizontal part as up to Ω cos φ / g across it (both 5.26e-6 rad/s per
m/s² at 45°), against a σ(G) of ~3e-6 for a MEMS session and ~3e-8 for a tactical one.

- **The vertical part** is along the specific force at every sample of a static face and of
  a turn about the vertical axis: ω_E,up = (Ω sin φ / g) a. It acts as a g-sensitivity
  (Ω sin φ / g) M_g on top of G, which the face pairs measure and the turns then subtract
  with it, so that M_g is free of it; `ferraris` removes it from G exactly where the
  latitude is known (G = G_eff − (Ω sin φ / g) M_g), whatever the faces' headings.
- **The horizontal part** depends on each face's heading, which the procedure leaves free:
  on face i± the gyros read a body vector h± ⟂ e_i, |h±| = Ω cos φ; the pair difference
  takes (h⁺ − h⁻)/2 into G's column i (over g), the pair sum (h⁺ + h⁻)/2 into b_g, which
  reads M_g Σh/6 over the six faces; per pair |(h⁺ − h⁻)/2|² + |(h⁺ + h⁻)/2|² = Ω² cos² φ.
  It enters the covariance of the section statistics as a systematic: on a face with axis
  i vertical, each horizontal body component of the rate with σ = Ω cos φ, faces
  independent; a turn section's gyro sums take Ω cos φ |Σ Δt e^{iθ}|, θ the angle turned
  so far (the rate turns with the body: a whole smooth turn averages it out, the rests at
  the section's ends do not). That σ is **neither a bound nor an average**: it is the
  variance of a pair flipped about a horizontal axis at a uniformly random heading (the
  rate along the axis stays, into b_g, the rest reverses, into G: Ω² cos² φ / 2 each, on
  average), twice that of faces at independent uniform headings (Ω² cos² φ / 2 per
  component and face: the σ of G and b_g √2 too wide, RMS z ≈ 0.7), and particular
  placements exceed it: z = √2 on one element of each G column where every pair
  reverses the rate (`ferraris_session`'s faces), z = 2 on b_g where two pairs keep it
  along one axis (a tumble about north: b_g takes 2Ω cos φ / 3; `face_headings_deg`).
- **The gyros' bias drift** (`hrgjax.imu._drift`): the pair sums, which measure it, hold
  the horizontal rate too; the gyros' q therefore comes from within the faces as well,
  and the pair contrasts carry this covariance besides the noise.
- **An unknown latitude** (`lat_deg=None`): φ is taken as anywhere on the globe (area-
  uniform, E sin²φ = 1/3): the vertical part is a systematic of σ Ω/√3, common to all
  faces, and the horizontal one has Ω² cos²φ → 2Ω²/3. On a bench at latitude φ the
  vertical part then sits at z = √3 |sin φ| on G's diagonal — 1.22 at 45°, 1.5 at 60°,
  1.73 at the poles — in every session at that bench (it is the same rate each time):
  give `lat_deg` where the σ matter."""

from __future__ import annotations

import jax
import numpy as np

from .. import plausible
from ..units import DEG, DEG_PER_H, EARTH_RATE
from .data import ImuData
from .sections import FACES, TURNS, Sections


def check_lat_deg(lat_deg, name: str = "lat_deg") -> float:
    """The bench's latitude [°] as a float in [−90, 90] (north positive)."""
    form = "the bench's latitude in degrees, -90 to 90 (north positive), or None"
    return _number(lat_deg, name, form, lambda v: -90.0 <= v <= 90.0)


def check_earth_rate(earth_rate) -> float:
    """The rotation rate [rad/s] of the ground under the bench, a float ≥ 0 within
    `hrgjax.plausible.RANGES["earth_rate_radps"]` (0 … 1e-4 rad/s): the Earth's 15.04 °/h
    or 4.178e-3 °/s typed as rad/s is refused in one line naming the unit it reads as."""
    form = (f"the ground's rotation rate in rad/s >= 0 ({EARTH_RATE:g} on the Earth, 0 for a "
            "record without it, e.g. ferraris_session without lat_deg)")  # fmt: skip
    v = _number(earth_rate, "earth_rate", form, lambda v: v >= 0.0)
    try:
        plausible.check("earth_rate [rad/s]", v, "earth_rate_radps")
    except ValueError:  # the Earth's rate in another unit: say which, and its factor
        like = next((f"; {v:g} is the Earth's rate in {unit} ({fix})" for unit, rate, fix in
                     (("°/h", EARTH_RATE / DEG_PER_H, "×hrgjax.units.DEG_PER_H"),
                      ("°/s", EARTH_RATE / DEG, "×hrgjax.units.DEG"),
                      ("rad/h", EARTH_RATE * 3600.0, "÷3600"))
                     if abs(v / rate - 1.0) < 0.01), "")  # fmt: skip
        if not like:
            raise
        top = plausible.RANGES["earth_rate_radps"][1]
        raise ValueError(f"earth_rate [rad/s] = {v:g} is outside the plausible range 0 … "
                         f"{top:g} rad/s (hrgjax.plausible.relaxed(earth_rate_radps=…) widens "
                         f"it){like}") from None  # fmt: skip
    return v


def _number(value, name: str, form: str, inside) -> float:
    """`value` as a finite float for which `inside(v)` holds, else one `ValueError` naming
    `name` and `form` (a bool or a string is not a number here); a value traced by `jit`,
    `vmap` or `grad` is refused as such: the Ferraris calibration runs on the host (NumPy)."""
    if isinstance(value, jax.core.Tracer):  # float() would raise, and blame a valid value
        raise ValueError(
            f"{name} must be a concrete number: the Ferraris calibration and session run on the "
            "host (NumPy), not inside jit, vmap or grad; got a traced value"
        )
    try:
        v = None if isinstance(value, bool | np.bool_ | str) else float(value)
    except (TypeError, ValueError):
        v = None
    if v is None or not (np.isfinite(v) and inside(v)):
        raise ValueError(f"{name} must be {form}; got {value!r}")
    return v


def earth_parts(lat_deg: float | None, rate: float) -> tuple[float, float, float]:
    """`(omega_up, var_up, var_h)`: the known vertical rate [rad/s] to remove, the variance
    [(rad/s)²] of an unknown vertical rate, and the variance of each horizontal body
    component of the rate on a face (see the module notes)."""
    if lat_deg is None:
        return 0.0, rate**2 / 3.0, 2.0 * rate**2 / 3.0
    lat = lat_deg * DEG
    return rate * float(np.sin(lat)), 0.0, (rate * float(np.cos(lat))) ** 2


def turn_spin(data: ImuData, sections: Sections) -> np.ndarray:
    """(3,) |Σ_k Δt_k e^{iθ_k}| [s] of the x, y, z turn sections (mean over a key's
    ranges), θ_k the angle the raw gyro of the turn's own axis has integrated so far: what
    a horizontal rate fixed in the world integrates to, in the body, per unit rate."""
    out = np.zeros(3)
    for i, key in enumerate(TURNS):
        spins = []
        for s, e in sections[key]:
            dt = np.asarray(data.dt[s:e])
            step = np.asarray(data.gyro[s:e, i]) * dt
            theta = np.cumsum(step) - step  # turned before each sample
            spins.append(abs(np.sum(dt * np.exp(1j * theta))))
        out[i] = np.mean(spins)
    return out


def horizontal_covariance(m_g: np.ndarray, var_h: float, spin: np.ndarray, face_at: dict,
                          turn_at: dict, n_stats: int) -> np.ndarray:  # fmt: skip
    """(n_stats, n_stats): the horizontal Earth rate's covariance in the section statistics:
    on face i± the gyro means take var_h M_g P_i M_gᵀ (P_i the projector across axis i, the
    vertical one), on turn i the gyro sums var_h spin_i² M_g P_i M_gᵀ; sections independent.
    `face_at` / `turn_at` give where each key's gyro numbers start in the statistics."""
    out = np.zeros((n_stats, n_stats))
    for key in (*FACES, *TURNS):
        i = "xyz".index(key[0])
        proj = np.eye(3)
        proj[i, i] = 0.0
        block = var_h * m_g @ proj @ m_g.T
        at = face_at[key] if key in face_at else turn_at[key]
        if key in turn_at:
            block = block * spin[i] ** 2
        out[at : at + 3, at : at + 3] = block
    return out
