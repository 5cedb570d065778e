r"""What [`correct`][hrgjax.calibration.AbstractCompensator.correct] returns and how it
integrates: the [`Corrected`][hrgjax.calibration.compensators.Corrected] data, the
temperature-domain warning, and the quadrature of each sample interval over its arc.

**Integration over the arc.** Between two samples the wave angle θ and the temperature T are
taken to move uniformly (θ̇ = Δθ/Δt, Ṫ = ΔT/Δt), and the compensated rate
$\hat\Omega(\theta, \dot\theta, T, \dot T)$ is integrated over the interval, not evaluated at
its middle: the arc is cut into ⌈|Δθ|/`ARC_RAD`⌉ equal pieces, each integrated by
Gauss–Legendre quadrature with the fewest nodes (≤ `NODES`, `node_count`) that meet the
`NODES`-node bound on a whole piece. The scale-factor term,
$-\frac{1}{k_{e,\rm nom}}\int d\theta/\mathrm{SF}(\theta, T)$, is then the integral over the
arc whatever the sample rate: the midpoint rule's error, $\frac{1}{24}\Delta\theta^3\,
\partial_\theta^2(1/\mathrm{SF})$ per interval, does not average out along a rotation (after
60 s at 50 °/s, with the exact law: 3.4e-2° logged at 1 Hz, 27.7° electrical a sample;
8.4e-3° at 2 Hz; now 6.8e-6° and 1.7e-6°, what the drift term's uniform motion leaves).
`NODES` = 4 integrates polynomials of degree 7 exactly; on a piece of
`ARC_RAD` = 22.5° electrical a 2nθ harmonic is integrated to ≈ 5.6e-10·(2n·ARC_RAD)⁸ of its
amplitude (n = 1: 8e-11; n = 4: 5e-6). `integrate_arcs` is the same rule traced, for the MLP's
end-to-end training (`mlp.integrate_compensated`: its midpoint sum was 3.4e-2° off above).

**Gaps.** An interval far longer than its run's others (samples lost) is integrated the same
way, over its arc — the angle is known at both ends, and no warning is given: at a fixed
temperature the scale-factor term depends on the two end angles only (∫dθ/SF(θ) is the same
for any motion between them); the drift term, ∫D/SF dt, assumes the uniform motion, off by
at most the gap's duration times the ripple of D/SF about its mean over the arc (a 20-s gap
in a 5 °/s run of the closed-form session, exact laws: 1.7e-5° at the run's end, against
0.13° with the midpoint rule). The temperature is taken as linear across the gap.
"""

from __future__ import annotations

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from .._compiled import bucket_pad, bucket_size, device, program
from .._warn import user_stacklevel
from ..data import MeasuredData

CORRECTED_COLUMNS = {
    "rate_corrected_dps": "equivalent input rate after compensation [°/s]",
    "angle_corrected_deg": "case rotation angle since the start of the run [°]",
}
"""Columns that `correct` adds to the data."""

DOMAIN_MARGIN_C = 1.0
"""How far beyond its calibrated temperature range [°C] a compensator is still applied by
`correct` (both ends): a test session's levels scatter by tenths of a degree about the
bench's, and the recorded range is that of the calibration windows' mean temperatures."""

NODES = 4
"""Gauss–Legendre nodes per piece of arc in `correct`'s integration (module docstring)."""

ARC_RAD = np.pi / 8
"""Largest piece of electrical arc [rad] (22.5°) one `NODES`-point rule integrates."""

HARMONIC = 8.0
"""Highest angular frequency in θ [1/rad] `node_count` sizes the rule for (the 2nθ terms up
to n = 4)."""


def node_count(half_arc) -> int:
    r"""Fewest Gauss–Legendre nodes m (1 … `NODES`) whose error bound on a harmonic of
    `HARMONIC` over pieces of half arc ≤ max |`half_arc`| [rad], $c_m(\omega h)^{2m}$ with
    $c_m = 4^m(m!)^4/((2m+1)((2m)!)^3)$ (of its amplitude), is within what `NODES` nodes
    leave on a whole `ARC_RAD` piece (5e-6): the arc rule's accuracy for no more
    evaluations than the arc needs — a 100-Hz log at 5 °/s takes one node (the mid-angle
    rule, 6e-7), 50 °/s at 1 Hz four."""
    h = float(np.max(np.abs(half_arc), initial=0.0))

    def bound(m, x):
        return (
            4.0**m
            * math.factorial(m) ** 4
            / ((2 * m + 1) * math.factorial(2 * m) ** 3)
            * x ** (2 * m)
        )

    target = bound(NODES, HARMONIC * ARC_RAD / 2)
    return next(m for m in range(1, NODES + 1) if bound(m, HARMONIC * h) <= target * (1 + 1e-12))


def arc_rule(d_theta) -> tuple[int, int]:
    """`(pieces, nodes)` for sample intervals turning `d_theta` [rad] (NumPy, any shape): the
    most `piece_counts` of any interval and the `node_count` of the longest piece."""
    d = np.abs(np.asarray(d_theta, float))
    counts = piece_counts(d)
    return int(counts.max(initial=1)), node_count(d / counts / 2 if d.size else d)


class TemperatureDomainWarning(UserWarning):
    """Data compensated outside the compensator's calibrated temperature range (widened by
    `DOMAIN_MARGIN_C`): [`correct`][hrgjax.calibration.AbstractCompensator.correct],
    [`drift_dph`][hrgjax.calibration.AbstractCompensator.drift_dph],
    [`scale_factor_at`][hrgjax.calibration.AbstractCompensator.scale_factor_at] and
    [`compare`][hrgjax.calibration.compare] name how many samples (points), where, and
    whether they were extrapolated or passed through. The result keeps them
    (`Corrected.in_range`, `Comparison.domains`); `warn=False`, or
    `warnings.simplefilter("ignore", TemperatureDomainWarning)`, silences it where
    extrapolating is meant."""


def by_temperature(temperature_c, bin_c: float = 1.0) -> dict[float, int]:
    """{temperature [°C], rounded to a multiple of `bin_c`: count}, for the temperatures
    given (NumPy), sorted."""
    keys = np.round(np.asarray(temperature_c, dtype=float).ravel() / bin_c) * bin_c + 0.0
    values, counts = np.unique(keys, return_counts=True)
    return {float(v): int(c) for v, c in zip(values, counts, strict=True)}


def warn_outside(who: str, temperature_c, inside, span, margin_c: float, how: str, what: str,
                 tail: str) -> None:  # fmt: skip
    """Warn `TemperatureDomainWarning` in one line (pointing at the user's call) when some
    of `temperature_c` [°C] lie outside (`inside` False): "<who>: N of M <what> outside the
    calibrated temperature range <span> (± margin_c °C): k at T °C, … — <how><tail>".
    Nothing when all are inside."""
    inside = np.asarray(inside, dtype=bool)
    n_out = int(np.sum(~inside))
    if not n_out:
        return
    temp = np.broadcast_to(np.asarray(temperature_c, dtype=float), inside.shape)
    where = ", ".join(f"{n} at {t:+g} °C" for t, n in by_temperature(temp[~inside]).items())
    warnings.warn(f"{who}: {n_out} of {inside.size} {what} outside the calibrated temperature "
                  f"range {span[0]:+.1f} … {span[1]:+.1f} °C (± {margin_c:g} °C): {where} — "
                  f"{how}{tail}", TemperatureDomainWarning,
                  stacklevel=user_stacklevel())  # fmt: skip


class Corrected(MeasuredData):
    """What [`correct`][hrgjax.calibration.AbstractCompensator.correct] returns: the
    [`hrgjax.MeasuredData`][] with `rate_corrected_dps` and `angle_corrected_deg` (the
    contract's columns, nothing else added), and how the samples stood to the compensator's
    temperature domain.

    **Attributes:** `in_range` (bool per sample): the sample's temperature lies within the
    compensator's `temperature_range` widened by `margin_c` (all True when the range is
    unknown); `temperature_range` ((T_min, T_max) [°C] or `None`: unknown, nothing checked);
    `margin_c` [°C]; `extrapolated` (bool): whether samples outside were compensated
    (`True`) or passed through uncompensated (`False`: their intervals' rate is the raw
    −θ̇/k_e,nom, as [`NoCompensation`][hrgjax.calibration.NoCompensation] gives).

    `save` writes the columns only (the measured-data format): a file of passed-through
    samples carries no mark of them — keep `in_range` beside it (`hrgjax correct --out`
    says how many rows of the file are uncompensated)."""

    def __init__(self, columns, *, in_range, temperature_range, margin_c, extrapolated):
        super().__init__(columns, allow_extra=True)
        self.in_range = np.asarray(in_range, dtype=bool)
        self.temperature_range = temperature_range
        self.margin_c = float(margin_c)
        self.extrapolated = bool(extrapolated)

    @classmethod
    def from_xarray(cls, ds, **kw) -> MeasuredData:
        """A plain [`hrgjax.MeasuredData`][] from a dataset (the domain is not in the file)."""
        return MeasuredData.from_xarray(ds, **kw)

    @property
    def n_out_of_range(self) -> int:
        """Samples outside the temperature domain (compensated only if `extrapolated`)."""
        return int(np.sum(~self.in_range))

    def out_of_range_by_temperature(self, bin_c: float = 1.0) -> dict[float, int]:
        """{temperature [°C], rounded to a multiple of `bin_c`: samples out of range there},
        only the temperatures that have some; `bin_c` a finite number > 0."""
        number = isinstance(bin_c, int | float | np.integer | np.floating)
        if isinstance(bin_c, bool) or not (number and np.isfinite(bin_c) and bin_c > 0):
            raise ValueError("Corrected.out_of_range_by_temperature: bin_c must be a finite "
                             f"number > 0 [°C]; got {bin_c!r}")  # fmt: skip
        return by_temperature(self["temperature_c"][~self.in_range], bin_c)


def piece_counts(d_theta, arc_rad: float | None = None, xp=np):
    """Pieces of arc of each sample interval: ⌈|Δθ|/`arc_rad`⌉, at least 1 (Δθ [rad], NumPy
    or, with `xp=jnp`, traced; `arc_rad` [rad] `None`: `ARC_RAD`). Float, whole values.
    Both ways multiply by the reciprocal (XLA turns a division by a constant into that: a
    NumPy division counted one piece fewer at 29·22.5°, 39·22.5° …, and the traced sum then
    lost a piece of arc)."""
    inverse = 1.0 / (ARC_RAD if arc_rad is None else arc_rad)
    return xp.maximum(xp.ceil(xp.abs(d_theta) * inverse), 1.0)


def piece_inputs(theta_a, d_theta, temp_a, d_temp, dt, index, count):
    """Piece `index` (from 0) of `count` equal pieces of arc of a sample interval starting at
    θ_a [rad], T_a [°C], turning Δθ [rad] and ΔT [°C] in `dt` [s] (arrays that broadcast,
    NumPy or JAX): its mid angle [rad], half arc [rad], angle rate [rad/s], mid temperature
    [°C], half temperature change [°C] and temperature rate [°C/s] (the interval's rates)."""
    frac = (index + 0.5) / count
    half = 0.5 / count
    return (theta_a + frac * d_theta, half * d_theta, d_theta / dt,
            temp_a + frac * d_temp, half * d_temp, d_temp / dt)  # fmt: skip


def arc_pieces(theta_a, theta_b, temp_a, temp_b, dt, arc_rad: float | None = None):
    """Cut each sample interval (NumPy arrays: wave angle [rad] and temperature [°C] at its
    two ends, duration [s]) into `piece_counts` equal pieces of arc (≤ `arc_rad` [rad] each,
    default `ARC_RAD`).

    **Returns:** `(inputs, starts, counts)`: `inputs`, per piece, its `piece_inputs`;
    `starts`, each interval's first piece; `counts`, its number of pieces (what
    `interval_rates` sums them back with)."""
    d_theta, d_temp = theta_b - theta_a, temp_b - temp_a
    counts = piece_counts(d_theta, arc_rad).astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    owner = np.repeat(np.arange(counts.size), counts)
    index = np.arange(owner.size) - starts[owner]
    inputs = piece_inputs(theta_a[owner], d_theta[owner], temp_a[owner], d_temp[owner],
                          dt[owner], index, counts[owner])  # fmt: skip
    return inputs, starts, counts


def interval_rates(comp, pieces, nodes: int | None = None) -> np.ndarray:
    """Mean compensated input rate [rad/s] over each sample interval (NumPy): `comp` (a
    module with `corrected_rate`) integrated over the pieces of `arc_pieces` by `nodes`-point
    (default: `node_count` of the pieces' half arcs) Gauss–Legendre quadrature, one compiled
    call padded to a bucketed length (`nodes=1` with one piece an interval: the mid-angle
    rule before the arc's)."""
    inputs, starts, counts = pieces
    n = inputs[0].size
    nodes = node_count(inputs[1]) if nodes is None else nodes
    padded = [device(bucket_pad(x, bucket_size(n))) for x in inputs]
    means = np.asarray(_arc_means(comp, *padded, nodes))[:n]
    return np.add.reduceat(means, starts) / counts


def piece_means(comp, theta_mid, half_arc, theta_dot, temp_mid, half_temp, temp_dot,
                nodes: int = NODES):  # fmt: skip
    """Mean of `comp.corrected_rate` over each piece of arc [rad/s] (1-D arrays of
    `piece_inputs`): `nodes`-point Gauss–Legendre in θ (and T, linear in θ) about the mid
    angle [rad] and temperature [°C], at the piece's constant angle rate [rad/s] and
    temperature rate [°C/s]. Traceable (jit, grad, vmap)."""
    x, w = (jnp.asarray(v) for v in np.polynomial.legendre.leggauss(nodes))
    theta = theta_mid[:, None] + half_arc[:, None] * x[None, :]
    temp = temp_mid[:, None] + half_temp[:, None] * x[None, :]
    rate = jax.vmap(jax.vmap(comp.corrected_rate, in_axes=(0, None, 0, None)))(
        theta, theta_dot, temp, temp_dot
    )
    return 0.5 * rate @ w


@program
def _arc_means(comp, theta_mid, half_arc, theta_dot, temp_mid, half_temp, temp_dot, nodes):
    """`piece_means` compiled (`nodes` static: a Python int)."""
    return piece_means(comp, theta_mid, half_arc, theta_dot, temp_mid, half_temp, temp_dot,
                       nodes)  # fmt: skip


def integrate_arcs(comp, t, theta, temperature_c, pieces: int, nodes: int = NODES):
    """Case angle ψ [rad] at every sample of one run (ψ = 0 at `t[0]`) by `correct`'s rule,
    traceable (jit, grad, vmap over runs): each interval cut into `piece_counts` pieces and
    each piece integrated by `piece_means` (`nodes`: `arc_rule`'s for concrete data), from
    `t` [s], θ [rad] and T [°C] (N,).
    `pieces` (a Python int ≥ every interval's count) is the static width of the padded
    (N − 1, `pieces`) grid; pieces past an interval's count repeat its last one (inside its
    arc: no extrapolated θ or T, so no NaN gradient) and are dropped. An interval that needs
    more than `pieces` is cut into `pieces` longer ones (no arc is lost)."""
    dt, d_theta, d_temp = jnp.diff(t), jnp.diff(theta), jnp.diff(temperature_c)
    counts = jnp.minimum(piece_counts(d_theta, xp=jnp), pieces)[:, None]
    index = jnp.arange(pieces, dtype=dt.dtype)[None, :]
    col = lambda x: x[:, None]  # noqa: E731
    inputs = piece_inputs(col(theta[:-1]), col(d_theta), col(temperature_c[:-1]), col(d_temp),
                          col(dt), jnp.minimum(index, counts - 1.0), counts)  # fmt: skip
    shape = (dt.shape[0], pieces)
    means = piece_means(comp, *(jnp.broadcast_to(x, shape).ravel() for x in inputs), nodes)
    rate = jnp.sum(jnp.where(index < counts, means.reshape(shape), 0.0), axis=1) / counts[:, 0]
    return jnp.concatenate([jnp.zeros(1, rate.dtype), jnp.cumsum(rate * dt)])
