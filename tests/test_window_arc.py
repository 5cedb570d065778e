"""A window's rate is the rate averaged over the arc the wave turns in it (audit of session 31:
the Fourier and MLP fits read it as the value at the window's mean angle, and recovered the
scale-factor ripple as 0.998 of the truth at 5 °/s, 0.967 at 20, 0.805 at 50 and 0.376 at
100 °/s on 3-s windows)."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import closed_form_session, session_scale_factor

import hrgjax as hg
from hrgjax import calibration as cal
from hrgjax.calibration import mlp
from hrgjax.calibration._correction import arc_pieces, interval_rates
from hrgjax.calibration._window_arc import (
    arc_rows,
    harmonic_gain,
    window_arc,
    window_average,
)
from hrgjax.calibration.reduce import K_E_NOMINAL as K
from hrgjax.units import DEG, DEG_PER_H

THETA = np.arange(-90.0, 90.0, 5.0)


def _windows(rate_dps, dt, n, count=1):
    """`count` hand-built windows of `n` samples `dt` apart at `rate_dps` (only the fields
    the gains read matter)."""
    z = np.zeros(count)
    return cal.RateWindows(
        run=np.arange(count), start=np.zeros(count, int), stop=np.full(count, n),
        t_mid=z, duration=np.full(count, (n - 1) * dt), temperature_c=z + 20.0,
        table_rate_dps=z + rate_dps, wave_angle_deg=z, rate_dps=z + rate_dps,
        stderr_dps=z + 1e-6, k_e=K,
    )  # fmt: skip


@pytest.mark.parametrize(("rate_dps", "dt", "n"), [(5.0, 0.5, 6), (50.0, 0.1, 30),
                                                   (50.0, 0.5, 6), (100.0, 0.1, 30)])  # fmt: skip
@pytest.mark.parametrize("k", [2, 4])
def test_harmonic_gain_is_the_least_squares_slope_of_the_turning_harmonic(rate_dps, dt, n, k):
    """The slope over n samples of ∫cos kθ dt while θ turns at v = k_e·rate is cos kθ̄ · G_k
    (brute force: the slope of the samples of sin kθ/(kv)); the continuous
    F(x) = 3(sin x − x cos x)/x³ at x = kv·T/2 is G to 1.5 % with T = dt·√(n² − 7/3)
    (`window_arc`), and the MLP's quadrature over that arc to 6 % (4θ at 100 °/s: a gain of
    −0.09) — the window's span (n − 1)·dt put F 1.4 % off at 30 samples and 50 °/s."""
    w = _windows(rate_dps, dt, n)
    v = K * rate_dps * DEG
    tau = (np.arange(n) - 0.5 * (n - 1)) * dt
    for centre in (0.3, 1.1, -0.7):
        y = np.sin(k * (centre + v * tau)) / (k * v)
        slope = tau @ (y - y.mean()) / (tau @ tau)
        np.testing.assert_allclose(slope, np.cos(k * centre) * harmonic_gain(w, k)[0],
                                   rtol=0, atol=1e-14)  # fmt: skip
    g = harmonic_gain(w, k)[0]
    x = k * window_arc(w)[0] / 2
    f = 3 * (np.sin(x) - x * np.cos(x)) / x**3
    assert abs(f - g) < 0.015 * max(abs(g), 0.1)
    rows, weights = arc_rows(lambda a, t: np.cos(k * a)[..., None], np.zeros(1), np.full(1, 20.0),
                             window_arc(w))  # fmt: skip
    quad = float(window_average(lambda r: r[0], jax.numpy.asarray(rows), weights)[0])
    assert abs(quad - g) < 0.06 * max(abs(g), 0.1)
    if (rate_dps, dt, n, k) == (50.0, 0.1, 30, 2):
        assert abs(f - g) < 3e-5 and abs(quad - g) < 3e-5 and abs(g - 0.8053) < 1e-4


def test_a_static_window_or_point_values_have_gain_one():
    """A drift of 1 °/h turns a 300-s static window by 0.046° (2θ gain 1 − 6.5·10⁻⁸, from the
    series, no sum over 30 000 samples: the sum's value to 1e-13); windows of no duration are
    point values (gain 1, no arc)."""
    static = _windows(1.0 / 3600.0, 0.01, 30_000)
    m = np.arange(30_000) - 14_999.5
    phase = 2 * K / 3600.0 * DEG * 0.01
    direct = np.sum(m * m * np.sinc(phase * m / np.pi)) / (m @ m)
    assert abs(harmonic_gain(static, 2)[0] - direct) < 1e-13
    assert 6e-8 < 1.0 - direct < 7e-8
    point = dataclasses.replace(_windows(50.0, 0.1, 30), duration=np.zeros(1))
    assert harmonic_gain(point, 4)[0] == 1.0 and window_arc(point)[0] == 0.0


def _ripple_ratio(comp):
    """Fitted / true peak-to-peak 2θ scale-factor ripple at +20 °C."""
    fitted = comp.scale_factor_at(THETA, np.full(THETA.size, 20.0))
    return np.ptp(fitted) / np.ptp(session_scale_factor(THETA * DEG, 20.0))


@pytest.mark.parametrize(("rate_dps", "before"), [(5.0, 0.998), (50.0, 0.805)])
def test_fourier_recovers_the_ripple_of_turning_windows(rate_dps, before):
    """Exact sessions at 0/20/40 °C, 3-s windows at 10 Hz: the ripple was read 0.998 (5 °/s)
    and 0.805 (50 °/s) of the truth as point values (the same windows with no duration
    still are); averaged over the arc 1.00000 at both (the rest is second order in the
    ripple: 11 ppm RMS of the scale factor at 50 °/s)."""
    data = closed_form_session(temps=(0.0, 20.0, 40.0), rate_dps=rate_dps, dt=0.1,
                               duration_s=36.0)  # fmt: skip
    w = cal.reduce(data)
    fourier = cal.FourierCompensator(temperature_degree=2)
    assert abs(_ripple_ratio(fourier.fit(w)) - 1.0) < 1e-3
    point = dataclasses.replace(w, duration=np.zeros(len(w)))
    assert abs(_ripple_ratio(fourier.fit(point)) - before) < 1e-3


def test_windows_do_not_straddle_a_time_gap_and_the_fit_reads_the_ripple_through_it():
    """20 s lost mid-run in every rotation run at 50 °/s (10 Hz): a window over the gap spanned
    23 s of a 3-s window's samples and averaged the rate over a different arc; the runs are now
    cut at the gap (`reduce.GAP_STEPS`), every window 2.9 s long, and the ripple still
    comes out 1.000 of the truth."""
    data = closed_form_session(temps=(0.0, 20.0, 40.0), rate_dps=50.0, dt=0.1, duration_s=60.0)
    cols = dict(data.columns)
    moving = cols["table_rate_dps"] != 0
    keep = ~(moving & (cols["time_s"] > 10.05) & (cols["time_s"] < 30.05))
    gapped = hg.MeasuredData({k: v[keep] for k, v in cols.items()})
    w = cal.reduce(gapped)
    turning = ~w.static
    np.testing.assert_allclose(w.duration[turning], 2.9, atol=1e-9)
    assert np.sum(turning) == 18 * (3 + 10)  # 101 samples: 3 windows, then 300: 10
    fourier = cal.FourierCompensator(temperature_degree=2).fit(gapped)
    assert abs(_ripple_ratio(fourier) - 1.0) < 1e-3


def test_the_mlp_window_model_averages_the_network_over_the_arc():
    """The MLP's scale-factor targets are compared with its network averaged over each
    window's arc (`arc_rows` + `window_average`, as `train_rprop(weights=…)` forms them): for
    a network that is cos 2θ of its input that average is G₂·cos 2θ̄ (3·10⁻⁵ at 50 °/s, 30
    samples); without any arc the rows are the points themselves (weights None)."""
    comp = cal.MLPCompensator()
    w = _windows(50.0, 0.1, 30, count=THETA.size)
    w = dataclasses.replace(w, wave_angle_deg=THETA.copy())
    rows, weights = arc_rows(lambda a, t: comp.features(a, t, np), THETA * DEG,
                             np.full(THETA.size, 20.0), window_arc(w))  # fmt: skip
    assert rows.shape == (THETA.size, 5, 3)
    model = window_average(lambda r: r[0], jax.numpy.asarray(rows), weights)  # cos 2θ input
    want = harmonic_gain(w, 2) * np.cos(2 * THETA * DEG)
    np.testing.assert_allclose(np.asarray(model), want, rtol=0, atol=3e-5)
    points, none = arc_rows(lambda a, t: comp.features(a, t, np), THETA * DEG,
                            np.full(THETA.size, 20.0), np.zeros(THETA.size))  # fmt: skip
    assert none is None and points.shape == (THETA.size, 3)


def test_fourier_refuses_a_harmonic_its_windows_average_out():
    """3-s windows at 77.5 °/s turn the wave 129° (electrical): the 4θ harmonic's gain is
    ≈ 0 and its coefficients would be noise over it; the fit says so and what to change, and
    fits with one harmonic or 1-s windows."""
    data = closed_form_session(temps=(0.0, 20.0, 40.0), rate_dps=77.5, dt=0.1, duration_s=36.0)
    with pytest.raises(
        ValueError,
        match=r"^scale factor \(rotation runs\): the windows average "
        r"the 4θ harmonic out \(RMS gain 0\.0\d\d < GAIN_FLOOR 0\.05.*window_s",
    ):
        cal.FourierCompensator(temperature_degree=2).fit(data)
    one = cal.FourierCompensator(harmonics=1, temperature_degree=2).fit(data)
    assert abs(_ripple_ratio(one) - 1.0) < 1e-3
    short = cal.FourierCompensator(temperature_degree=2, window_s=1.0).fit(data)
    assert abs(_ripple_ratio(short) - 1.0) < 1e-3


def _exact_at_20c():
    """The closed-form session's laws at +20 °C as a Fourier compensator (one 2θ harmonic, no
    law in T): exact there, so what is left is the integration's."""
    phase = 25.0 * DEG
    drift = jnp.asarray([[0.3, 1.5 * np.sin(2 * phase), -1.5 * np.cos(2 * phase)]]) * DEG_PER_H
    return eqx.tree_at(lambda c: (c.drift_coef, c.sf_coef), cal.FourierCompensator(harmonics=1),
                       (drift, jnp.asarray([[1.0, -2 * 0.0046, 0.0]])),
                       is_leaf=lambda x: x is None)  # fmt: skip


def test_end_to_end_training_integrates_as_correct_does():
    """`mlp.integrate_compensated` (what end-to-end training differentiates) used the midpoint
    rule while `correct` integrates over each interval's arc: logged at 1 Hz at 50 °/s (27.7°
    electrical a sample, 2 pieces of arc) the two end angles were up to 3.4e-2° apart after
    60 s with the exact laws (8.4e-3° at 2 Hz). It now runs `correct`'s code: the same end
    angle to 1e-11° (of 3000°), under `jit` too with the pieces `run_groups` counts."""
    comp = _exact_at_20c()
    data = closed_form_session(temps=(20.0,), rate_dps=50.0, dt=1.0, duration_s=60.0)
    angle = comp.correct(data)["angle_corrected_deg"]
    groups = mlp.run_groups(data, window_s=5.0)
    assert [g.pieces for g in groups] == [2]
    jitted = jax.jit(mlp.integrate_compensated, static_argnums=5)
    for ix in data.run_indices():
        t, th, tc = data["time_s"][ix], data["wave_angle_deg"][ix] * DEG, data["temperature_c"][ix]
        psi = np.asarray(mlp.integrate_compensated(comp, t, th, tc, t)) / DEG
        np.testing.assert_allclose(psi, angle[ix], rtol=0, atol=1e-11)
        traced = np.asarray(jitted(comp, t, th, tc, t, groups[0].pieces)) / DEG
        np.testing.assert_allclose(traced, psi, rtol=0, atol=1e-11)
        # the rule before: one node at the interval's mid angle
        mid = interval_rates(comp, arc_pieces(th[:-1], th[1:], tc[:-1], tc[1:], np.diff(t),
                                              arc_rad=np.inf), nodes=1)  # fmt: skip
        off = np.sum(mid * np.diff(t)) / DEG - angle[ix[-1]]
        assert abs(off) < 1e-11 if data["table_rate_dps"][ix[0]] == 0 else abs(off) > 4e-3
    with pytest.raises(ValueError, match=r"^integrate_compensated: pieces must be a whole "
                       r"number ≥ 1 .*traced.*got None"):  # fmt: skip
        jax.jit(mlp.integrate_compensated)(comp, t, th, tc, t)
    with pytest.raises(ValueError, match=r"pieces must be a whole number ≥ 2 .*; got 1$"):
        mlp.integrate_compensated(comp, t, th, tc, t, 1)  # would drop half of each arc


@pytest.mark.parametrize("margin", [jnp.asarray(2.0), np.asarray(2.0), np.float32(2.0),
                                    jnp.asarray(2)])  # fmt: skip
def test_correct_takes_a_numpy_or_jax_scalar_margin(margin):
    """`correct(margin_c=jnp.asarray(2.0))` was refused ("must be a finite number") while 2.0
    passed; a 0-d NumPy or concrete JAX scalar is now its Python number, as the settings'
    fields take them; an array of one element is still refused."""
    comp = dataclasses.replace(_exact_at_20c(), temperature_range=(0.0, 18.5))
    data = closed_form_session(temps=(20.0,), duration_s=2.0)
    out = comp.correct(data, margin_c=margin)  # 1.5 °C out: inside with 2, not with 1
    assert type(out.margin_c) is float and out.margin_c == 2.0 and out.n_out_of_range == 0
    assert comp.in_range(np.array([20.0]), margin).all()
    assert not comp.in_range(np.array([20.0]), margin / 2).any()
    with pytest.raises(ValueError, match=r"margin_c must be a finite number ≥ 0 \[°C\]; got"):
        comp.correct(data, margin_c=jnp.asarray([2.0]))


class _Sqrt(eqx.Module):
    """A law that is NaN above 40 °C: a piece evaluated past its interval would show it."""

    a: jax.Array

    def corrected_rate(self, theta, theta_dot, temp, temp_dot):
        return self.a * jnp.sqrt(40.0 - temp) * theta_dot


def test_traced_piece_counts_agree_and_padding_never_drops_or_leaves_the_arc():
    """Review (s32): XLA multiplies by 1/ARC_RAD where NumPy divided, so at 29·22.5°,
    39·22.5° … the traced count was one more than `run_groups` counted and the training's
    integral dropped a piece: 39.8° off `correct` after a 652.5° gap; a padded piece was
    evaluated beyond its interval (T extrapolated past a law's domain: a NaN gradient)."""
    from hrgjax.calibration._correction import ARC_RAD, integrate_arcs, piece_counts

    k = np.arange(1.0, 80.0)[:, None] * ARC_RAD
    arcs = (k + np.arange(-8, 9)[None, :] * np.spacing(k)).ravel()
    traced = jax.jit(lambda v: piece_counts(v, xp=jnp))(arcs)
    np.testing.assert_array_equal(piece_counts(arcs), traced)
    t, theta, temp = jnp.array([0.0, 1.0, 2.0]), jnp.array([0.0, 0.1, 3.0]), jnp.array(
        [39.0, 39.5, 39.99])  # fmt: skip
    psi = lambda a, pieces: integrate_arcs(_Sqrt(a), t, theta, temp, pieces)[-1]  # noqa: E731
    full = psi(1.0, 8)  # the second interval needs 8 pieces
    np.testing.assert_allclose(psi(1.0, 2), full, rtol=1e-3)  # too few: longer pieces
    gradient = jax.grad(psi)(1.0, 8)
    assert np.isfinite(gradient)
    np.testing.assert_allclose(gradient, full, rtol=1e-12)  # ψ is linear in a


def test_the_rule_takes_the_nodes_its_arcs_need():
    """`correct` and the end-to-end training evaluated 4 nodes on every piece: 2–3× the
    mid-angle rule's time in `correct`, the demo's end-to-end fit 51 s instead of ≈ 15 s, on
    arcs where one node already meets the 4-node bound on a whole 22.5° piece (5e-6)."""
    from hrgjax.calibration._correction import ARC_RAD, NODES, arc_rule, node_count

    assert node_count(ARC_RAD / 2) == NODES and node_count(0.0) == 1
    assert node_count(np.array([-2.4e-4, 1e-5])) == 1  # 100 Hz at 5 °/s: the mid-angle rule
    assert [node_count(h) for h in (0.005, 0.03, 0.1)] == [2, 3, 4]
    assert arc_rule(np.array([28.5 * ARC_RAD, -0.01])) == (29, NODES)
