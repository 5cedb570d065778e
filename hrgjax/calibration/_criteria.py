"""Design criteria: what a plan's posterior leaves of the drift, the warm-up's input-angle
(tilt) error and the position error of a flight, one number to minimise. The angle
errors here are of the input (case) angle, the compensated rate integrated: 1/k_e of the
electrical wave angle. The flights' gyros are the two level ones (x forward, y right,
`hrgjax.calibration.ins_impact`), so the angle is a tilt (roll, pitch), not heading."""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._x64 import require_x64
from ..units import DEG, DEG_PER_H
from ._information import (
    NODES,
    information_source,
    precision_factor,
    prior_scale_array,
    scaled_solve,
)
from ._models import GREY_BOX, as_model, model_values, noise_vector
from ._plan import BenchPlan
from .ins_impact import FLIGHTS, Flight

CRITERIA = ("drift+warmup", "drift", "warmup", "ins", "d", "a")
"""Design criteria: `drift+warmup` (the default: the input-angle (tilt) error an hour of
operation leaves — the static drift's over the flight's length and the warm-up's own, in
quadrature [°]), `drift` (RMS of the compensated static drift's standard deviation over the
operating grid [°/h]), `warmup` (RMS input-angle (tilt) error at the end of the warm-up
flights [°]), `ins`
(RMS horizontal position error after the warm-up flights [km]), `d` (log-determinant of the
scaled posterior covariance), `a` (trace of the scaled posterior covariance)."""

CRITERION_UNITS = {"drift+warmup": "°", "drift": "°/h", "warmup": "°", "ins": "km", "d": "",
                   "a": ""}  # fmt: skip
"""The unit each criterion is printed in."""

OPERATING_TEMPERATURES = tuple(float(t) for t in range(-40, 61, 5))
"""Temperatures of the `drift` criterion's operating grid [°C] (the seed's test range)."""
OPERATING_ANGLES = tuple(float(a) for a in range(-90, 91, 5))
"""Wave angles of its operating grid [° electrical] (the seed's 5° test steps)."""


def _inputs(plan, values, arw, gauss_markov, angle_white, model):
    """What every public criterion starts from: the model (`as_model`), its values, the
    noise vector and `plan`'s information source with its panels."""
    model = as_model(model)
    values = model_values(values, model)
    noise = noise_vector(arw, gauss_markov, angle_white)
    source, panels = information_source(plan, values, noise, model)
    return model, values, noise, source, panels


def _flight_criterion(kind, plan, values, arw, prior_scale, flight, gauss_markov, angle_white,
                      model):  # fmt: skip
    """`ins_error` or `warmup_error` (`kind`: `ins`, `warmup`) of `plan` after `flight`: one
    criterion of the flights, its arguments checked as every public criterion's."""
    require_x64(f"hrgjax.calibration.design.{kind}_error")
    model, values, noise, source, panels = _inputs(
        plan, values, arw, gauss_markov, angle_white, model
    )
    return evaluate_criterion(source, kind, values, noise, prior_scale_array(prior_scale),
                              flight_nodes(flight), model, panels)  # fmt: skip


def drift_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                temperatures_c=OPERATING_TEMPERATURES, angles_deg=OPERATING_ANGLES,
                gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    """Predicted standard deviation of the compensated static drift [°/h of input rate],
    RMS over the operating grid (`temperatures_c` × `angles_deg`): √(mean hᵀ C h) with
    h = ∂(static drift)/∂values and C the posterior covariance (noise arguments and `model`
    as [`information`][hrgjax.calibration.design.information])."""
    require_x64("hrgjax.calibration.design.drift_error")
    grid = _grid("temperatures_c", temperatures_c, "°C"), _grid("angles_deg", angles_deg, "°")
    prior_scale = prior_scale_array(prior_scale)
    model, values, noise, source, panels = _inputs(
        plan, values, arw, gauss_markov, angle_white, model
    )
    return _drift_error_program(source, values, noise, prior_scale, *grid, model, panels)


def _drift_error(plan, values, noise, prior_scale, temperatures_c=OPERATING_TEMPERATURES,
                 angles_deg=OPERATING_ANGLES, model=GREY_BOX, panels=None):  # fmt: skip
    factor = precision_factor(plan, values, noise, prior_scale, model, panels)
    tt, aa = np.meshgrid(np.asarray(temperatures_c, float), np.asarray(angles_deg, float))

    def drift(v, theta, temp):  # input-rate units [rad/s], nominal gain
        return model.rate(v, theta, temp, 0.0, 0.0) / model.gain(values)

    h = jax.vmap(lambda th, T: jax.grad(drift)(values, th, T))(
        jnp.asarray(aa.ravel() * DEG), jnp.asarray(tt.ravel())
    )
    z = scaled_solve(factor, h * model.scale()[None, :])
    return jnp.sqrt(jnp.mean(jnp.sum(z**2, axis=-1))) / DEG_PER_H


_drift_error_program = eqx.filter_jit(_drift_error)  # the grid static: one program per grid


def _grid(name: str, values, unit: str) -> tuple[float, ...]:
    """An operating grid's axis as a tuple of floats (static in the compiled criterion)."""
    try:
        axis = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        axis = np.asarray([np.nan])
    if axis.size == 0 or not np.isfinite(axis).all():
        raise ValueError(f"{name} must be a non-empty sequence of finite numbers [{unit}]; "
                         f"got {values!r}")  # fmt: skip
    return tuple(float(v) for v in axis)


INS_FLIGHTS = FLIGHTS
"""The `ins` criterion's default flights: the three 1-h warm-up flights of
[`study.FLIGHTS`][hrgjax.calibration.study.FLIGHTS] (level at 200 m/s, the IMU warming from
−40 °C to +20 °C with a 20-min time constant; wave-angle pairs 30°/−55°, −20°/70°, 80°/5°),
so that a design does not specialise to one pair of wave angles."""


def as_flights(flight) -> tuple[Flight, ...]:
    """`flight` (None, one `Flight` or a sequence of them) as a non-empty tuple of flights."""
    if flight is None:
        return INS_FLIGHTS
    flights = (flight,) if isinstance(flight, Flight) else flight
    try:
        flights = tuple(flights)
    except TypeError:
        flights = (flights,)
    if not flights or not all(isinstance(f, Flight) for f in flights):
        bad = next((type(f).__name__ for f in flights if not isinstance(f, Flight)), "empty")
        raise TypeError(
            f"flight must be an ins_impact.Flight or a non-empty sequence of them; got {bad}"
        )
    return flights


class FlightNodes(eqx.Module):
    """Flights as the criteria read them: row 2f is flight f's x gyro, row 2f + 1 its y gyro,
    each at the Gauss–Legendre nodes of the flight's length (R × N): `theta` its wave angle
    [rad], `temperature` [°C] and `temperature_rate` [°C/s] there, the weights of the plain
    integral over the flight `weight` [s] and of the Schuler response at its end
    `schuler_weight` [m·s]; `hours` the flights' mean length [h]. Arrays, not static fields,
    so flights that differ only in heading, angles, temperatures or length share one compiled
    criterion (a sweep over flights compiles once)."""

    theta: np.ndarray
    temperature: np.ndarray
    temperature_rate: np.ndarray
    weight: np.ndarray
    schuler_weight: np.ndarray
    hours: np.ndarray

    @property
    def count(self) -> int:
        """The number of flights F."""
        return self.theta.shape[0] // 2


@functools.lru_cache(maxsize=8)
def _legendre(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss–Legendre nodes and weights on [−1, 1] (read-only: shared between calls)."""
    x, w = np.polynomial.legendre.leggauss(nodes)
    x.flags.writeable = w.flags.writeable = False
    return x, w


def flight_nodes(flight, nodes: int | None = None) -> FlightNodes:
    """`flight` (None: `INS_FLIGHTS`, one `Flight`, a sequence of them, or `FlightNodes`,
    returned as it is) at `nodes` Gauss–Legendre nodes each (None: `NODES`, or those a
    `FlightNodes` was built with), built on the host. Pass the result, not the flights, to a
    program compiled over flights: flights enter it as arrays, so a sweep compiles once."""
    if isinstance(flight, FlightNodes):
        built = flight.theta.shape[1]
        if nodes is not None and nodes != built:
            raise ValueError(
                f"nodes must match the FlightNodes given ({built} nodes per flight); got {nodes!r}"
            )
        return flight
    if nodes is None:
        nodes = NODES
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or nodes < 1:
        raise ValueError(
            f"nodes must be a positive integer (Gauss–Legendre nodes per flight); got {nodes!r}"
        )
    if flight is None and nodes == NODES:
        return _default_flight_nodes()
    return _build_flight_nodes(as_flights(flight), int(nodes))


@functools.lru_cache(maxsize=1)
def _default_flight_nodes() -> FlightNodes:
    """`INS_FLIGHTS` at `NODES` nodes: built once (every default criterion call reads it)."""
    return _build_flight_nodes(INS_FLIGHTS, NODES)


def _build_flight_nodes(flights: tuple[Flight, ...], nodes: int) -> FlightNodes:
    from .ins_impact import EARTH_RADIUS, GRAVITY

    x, w = _legendre(nodes)
    omega_s = math.sqrt(GRAVITY / EARTH_RADIUS)
    rows = {"theta": [], "temperature": [], "temperature_rate": [], "weight": [],
            "schuler_weight": []}  # fmt: skip
    for f in flights:
        length = float(f.duration_s)
        s = (x + 1.0) / 2.0 * length
        wt = w / 2.0 * length
        for angle in (f.wave_angle_x_deg, f.wave_angle_y_deg):
            rows["theta"].append(np.full(s.shape, float(angle) * DEG))
            rows["temperature"].append(np.asarray(f.temperature(s), float))
            rows["temperature_rate"].append(np.asarray(f.temperature_rate(s), float))
            rows["weight"].append(wt)
            rows["schuler_weight"].append(
                wt * EARTH_RADIUS * (1.0 - np.cos(omega_s * (length - s)))
            )
    hours = np.asarray(np.mean([float(f.duration_s) for f in flights]) / 3600.0)
    arrays = {k: np.stack(v) for k, v in rows.items()} | {"hours": hours}
    for a in arrays.values():
        a.flags.writeable = False
    return FlightNodes(**arrays)


def ins_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
              flight=None, gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    r"""Predicted horizontal position error [km] at the end of `flight` (a
    [`Flight`][hrgjax.calibration.ins_impact.Flight] or a sequence of them: RMS over the
    flights; default `INS_FLIGHTS`, the three 1-h warm-up flights) from the calibration's
    uncertainty after `plan` (of the physical grey box unless `model` says otherwise): each level gyro's compensated rate error along the flight is
    ε(t) = h(t)ᵀ δv, with h = ∂(measured rate)/∂values at its wave angle, the flight's
    temperature T(t) *and its rate* Ṫ(t) (the readout's temperature sensitivity, which only a
    plan with ramps can calibrate); ε drives the classical Schuler channels (PHYSICS.md §12:
    a rate error at time s moves the position at the end T by R(1 − cos ω_s(T − s))), so the
    error is δp = M δv with M = R ∫ (1 − cos ω_s(T − s)) h(s)ᵀ ds per gyro, and its expected
    squared length is tr(M C Mᵀ), C the posterior covariance (heading drops out: the two
    gyros' errors rotate into north and east together). Gauss–Legendre quadrature over the
    flight; noise arguments and `model` as
    [`information`][hrgjax.calibration.design.information].

    What it leaves out, by design (none of it depends on the plan): the flight's own noise
    (ARW, Gauss–Markov rate), the Earth-rate coupling of the full strapdown model
    ([`ins_impact`][hrgjax.calibration.ins_impact.ins_impact] keeps both), and model error
    outside the grey box's family."""
    return _flight_criterion("ins", plan, values, arw, prior_scale, flight, gauss_markov,
                             angle_white, model)  # fmt: skip


def ins_sensitivity(values=None, flight=None, nodes: int | None = None,
                    model=None) -> jax.Array:  # fmt: skip
    """M of [`ins_error`][hrgjax.calibration.design.ins_error] (2F × P for F flights, [m]
    per SI unit of each parameter): the end-of-flight position error of each flight's x and
    y gyros' channels per unit error of each grey-box parameter (classical Schuler response,
    input-rate units at nominal gain; `nodes`: Gauss–Legendre nodes per flight, default
    `NODES` = 64; `model` as [`information`][hrgjax.calibration.design.information])."""
    model = as_model(model)
    return _ins_sensitivity(model_values(values, model), flight_nodes(flight, nodes), model)


@eqx.filter_jit
def _ins_sensitivity(values, flights: FlightNodes, model=GREY_BOX, schuler=True):
    """M of `ins_sensitivity` (`schuler`), or of `warmup_sensitivity` (the plain integral of
    the rate error over each flight: the end-of-flight input-angle (tilt) error per unit
    error of each parameter [rad per SI unit])."""

    def rate(v, theta, t, t_rate):  # input-rate units [rad/s], nominal gain
        return model.rate(v, theta, t, 0.0, t_rate) / model.gain(values)

    # Every (flight, gyro, node) point in one vmapped gradient: one copy of the rate's
    # derivative in the compiled program however many flights (unrolled per flight and gyro,
    # six copies compiled in ~5 s; one in ~1 s), the sums per row by the nodes' weights.
    weight = flights.schuler_weight if schuler else flights.weight
    h = jax.vmap(jax.grad(rate), in_axes=(None, 0, 0, 0))(
        values,
        jnp.ravel(flights.theta),
        jnp.ravel(flights.temperature),
        jnp.ravel(flights.temperature_rate),
    )  # (rows × nodes, P)
    return jnp.einsum("rn,rnp->rp", weight, h.reshape(*weight.shape, -1))


def warmup_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                 flight=None, gauss_markov=None, angle_white=None, model=None):  # fmt: skip
    r"""Predicted input-angle (tilt) error [°] at the end of `flight` (default
    `INS_FLIGHTS`, the three 1-h warm-up flights; RMS over the flights and their x and y
    gyros) from the calibration's uncertainty after `plan`: the compensated rate error
    ε(t) = h(t)ᵀ δv of [`ins_error`][hrgjax.calibration.design.ins_error] — at the flight's
    temperature T(t) *and* its rate Ṫ(t) — integrated over the flight, m = ∫ h(s)ᵀ ds, with
    expected square mᵀ C m: the case (input) angle the gyro's output mis-states, 1/k_e of
    the electrical wave angle's error. What a gyro-compass or an attitude reference loses to
    the warm-up, before any Schuler dynamics. Noise arguments and `model` as
    [`information`][hrgjax.calibration.design.information]."""
    return _flight_criterion("warmup", plan, values, arw, prior_scale, flight, gauss_markov,
                             angle_white, model)  # fmt: skip


def warmup_sensitivity(values=None, flight=None, nodes: int | None = None,
                       model=None) -> jax.Array:  # fmt: skip
    """m of [`warmup_error`][hrgjax.calibration.design.warmup_error] (2F × P for F flights,
    [rad] per SI unit of each parameter): the end-of-flight input-angle (tilt) error of
    each flight's x and y gyros per unit error of each parameter (input-rate units at nominal
    gain; `nodes` and `model` as
    [`ins_sensitivity`][hrgjax.calibration.design.ins_sensitivity])."""
    model = as_model(model)
    return _ins_sensitivity(model_values(values, model), flight_nodes(flight, nodes), model, False)


def _warmup_error(plan, values, noise, prior_scale, flights, model=GREY_BOX, panels=None):
    factor = precision_factor(plan, values, noise, prior_scale, model, panels)
    m = _ins_sensitivity(values, flights, model, False)
    z = scaled_solve(factor, m * model.scale()[None, :])
    return jnp.sqrt(jnp.sum(z**2) / (2 * flights.count)) / DEG


def drift_warmup_error(plan: BenchPlan, values=None, arw=None, prior_scale: float = 100.0,
                       flight=None, gauss_markov=None, angle_white=None, model=None,
                       terms: bool = False):  # fmt: skip
    r"""The default design criterion [°]: the input-angle (tilt) error an hour of operation
    leaves, √((σ_drift · L)² + σ_warm-up²) —
    [`drift_error`][hrgjax.calibration.design.drift_error]
    (RMS over the operating grid, °/h) acting for the flights' mean length L [h], and
    [`warmup_error`][hrgjax.calibration.design.warmup_error] (°) after `flight` (default
    `INS_FLIGHTS`). The first rewards covering every temperature and angle, the second the
    temperatures and rates of change a warm-up passes through. Arguments as `ins_error`;
    `terms=True` returns `(total [°], drift [°/h], warm-up [°])` from one compiled program."""
    require_x64("hrgjax.calibration.design.drift_warmup_error")
    model, values, noise, source, panels = _inputs(
        plan, values, arw, gauss_markov, angle_white, model
    )
    flights = flight_nodes(flight)
    out = _drift_warmup_terms(
        source, values, noise, prior_scale_array(prior_scale), flights, model, panels
    )
    return out if terms else out[0]


def _drift_warmup_error(plan, values, noise, prior_scale, flights, model=GREY_BOX,
                        panels=None):  # fmt: skip
    hours = flights.hours
    drift = _drift_error(plan, values, noise, prior_scale, model=model, panels=panels)
    warm = _warmup_error(plan, values, noise, prior_scale, flights, model, panels)
    return jnp.sqrt((drift * hours) ** 2 + warm**2), drift, warm


_drift_warmup_terms = eqx.filter_jit(_drift_warmup_error)


def _ins_error(plan, values, noise, prior_scale, flights, model=GREY_BOX, panels=None):
    factor = precision_factor(plan, values, noise, prior_scale, model, panels)
    m = _ins_sensitivity(values, flights, model)
    z = scaled_solve(factor, m * model.scale()[None, :])
    return jnp.sqrt(jnp.sum(z**2) / flights.count) / 1000.0


def criterion(plan: BenchPlan, kind: str = "drift+warmup", values=None, arw=None,
              prior_scale: float = 100.0, gauss_markov=None, angle_white=None,
              flight=None, model=None):  # fmt: skip
    """The design criterion of `plan` (smaller is better; differentiable with respect to the
    plan's arrays): `drift+warmup` (the default) —
    [`drift_warmup_error`][hrgjax.calibration.design.drift_warmup_error] [°];
    `drift` — [`drift_error`][hrgjax.calibration.design.drift_error] [°/h];
    `warmup` — [`warmup_error`][hrgjax.calibration.design.warmup_error] [°];
    `ins` — [`ins_error`][hrgjax.calibration.design.ins_error] after `flight` (one or a
    sequence of flights; default `INS_FLIGHTS`) [km];
    `d` — log det of the posterior covariance in units of each parameter's typical
    uncertainty (D-optimal); `a` — its trace (A-optimal). Noise arguments and `model` (what
    the calibration fits: `MODELS`) as [`information`][hrgjax.calibration.design.information]."""
    if kind not in CRITERIA:
        raise ValueError(f"criterion kind must be one of {CRITERIA}; got {kind!r}")
    model, values, noise, source, panels = _inputs(
        plan, values, arw, gauss_markov, angle_white, model
    )
    flights = flight_nodes(flight)
    return evaluate_criterion(source, kind, values, noise, prior_scale_array(prior_scale), flights, model,
                              panels)  # fmt: skip


@eqx.filter_jit
def evaluate_criterion(plan, kind, values, noise, prior_scale, flights=None,
                       model=GREY_BOX, panels=None):  # fmt: skip
    """`criterion`, compiled once per plan length, kind, model (and number of flights, for
    `ins`, `warmup`, `drift+warmup`: `flights` a `FlightNodes` — `Flight`s, static here,
    would compile once per flight; `None` the default flights);
    `panels`: `ramp_panels`, for a plan with ramps that turn); `plan` a plan or its
    information matrix (`information_source`), `noise` a `noise_vector`."""
    flights = flight_nodes(flights)
    if kind == "drift+warmup":
        return _drift_warmup_error(plan, values, noise, prior_scale, flights, model, panels)[0]
    if kind == "drift":
        return _drift_error(plan, values, noise, prior_scale, model=model, panels=panels)
    if kind == "warmup":
        return _warmup_error(plan, values, noise, prior_scale, flights, model, panels)
    if kind == "ins":
        return _ins_error(plan, values, noise, prior_scale, flights, model, panels)
    chol, d = factor = precision_factor(plan, values, noise, prior_scale, model, panels)
    if kind == "d":  # log det A⁻¹
        return -2.0 * (jnp.sum(jnp.log(jnp.diagonal(chol))) + jnp.sum(jnp.log(d)))
    w = scaled_solve(factor, jnp.eye(d.shape[0]))
    return jnp.sum(w**2)
