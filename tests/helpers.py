"""Shared oracles and small resonators for the tests (PHYSICS.md §8 uses ω = 2π·40 rad/s)."""

import numpy as np

import hrgjax as hg

OMEGA = 2 * np.pi * 40.0


def slope(t, y):
    """Least-squares slope dy/dt."""
    return np.polyfit(np.asarray(t), np.asarray(y), 1)[0]


def local_rate(t, y):
    """Centred finite-difference derivative on the interior samples."""
    t, y = np.asarray(t), np.asarray(y)
    return (y[2:] - y[:-2]) / (t[2:] - t[:-2])


def resonator(**kw):
    base = dict(omega=OMEGA, tau=50.0, k_e=0.554)
    base.update(kw)
    return hg.Resonator(**base)


def bryan_factor(n, points=20001):
    """K = 2∫H V dA / (n ∫(U²+V²+W²) dA) for Rayleigh inextensional modes of a thin hemisphere."""
    phi = np.linspace(0.0, np.pi / 2, points)
    tn = np.tan(phi / 2) ** n
    u = v = np.sin(phi) * tn
    w = -(n + np.cos(phi)) * tn
    h = u * np.cos(phi) + w * np.sin(phi)
    da = np.sin(phi)
    num = np.trapezoid(2 * h * v * da, phi)
    den = n * np.trapezoid((u**2 + v**2 + w**2) * da, phi)
    return abs(num / den)


def noisy_model_gyro(values):
    """The physical compensator's ideal-loop model gyro for `values`, with 1″ white angle noise
    and 0.002 °/√h angle random walk (no bias instability, no switch-on bias)."""
    import equinox as eqx

    from hrgjax.calibration import physical
    from hrgjax.units import DEG, DEG_PER_SQRT_H

    noise = hg.Noise(
        angle_white=1.0 / 3600 * DEG,
        angle_random_walk=0.002 * DEG_PER_SQRT_H,
        bias_instability=0.0,
        correlation_time=600.0,
        run_bias=0.0,
    )
    return eqx.tree_at(
        lambda g: g.noise, physical.model_gyro(values), noise, is_leaf=lambda x: x is None
    )


def session_drift(theta, temp):
    """A 180°-periodic drift law [rad/s] whose offset, amplitude and phase change with T
    (°C): one cos 2θ, sin 2θ pair; θ [rad], T [°C]."""
    from hrgjax.units import DEG, DEG_PER_H

    amp = 1.5 * DEG_PER_H * np.exp(-0.016 * (temp - 20.0))
    phase = (25.0 + 0.16 * (temp - 20.0)) * DEG
    return 0.3 * DEG_PER_H + 0.005 * DEG_PER_H * (temp - 20) - amp * np.sin(2 * (theta - phase))


def session_scale_factor(theta, temp):
    """Scale factor 1 − 2g(T)·cos 2θ of the closed-form session (θ [rad], T [°C])."""
    return 1.0 - 2 * (0.0046 - 9.6e-5 * (temp - 20.0)) * np.cos(2 * theta)


SESSION_ANGLES = (-90.0, -60.0, -30.0, 0.0, 30.0, 60.0)
"""Start wave angles of the closed-form session [°]: whole periods of 2θ, so a constant rate
divided by the scale factor averages to itself."""


def closed_form_session(bias_dph=0.0, temps=(-40.0, 20.0, 60.0), angles=SESSION_ANGLES,
                        duration_s=60.0, dt=0.5, rate_dps=5.0):  # fmt: skip
    """A bench session with no noise: a static run and a `rate_dps` rotation from every
    (temperature, start angle), the wave angle integrated (RK4, 8 steps a sample) from
    θ̇ = −k_e,nom (SF(θ, T)·Ω + D(θ, T) + b), b = `bias_dph` the session's switch-on bias
    (added to the measured rate, as `simulate` adds it)."""
    from hrgjax.units import DEG, DEG_PER_H, K_E_NOMINAL

    tt, aa = np.meshgrid(np.asarray(temps, float), np.asarray(angles, float), indexing="ij")
    temp = np.concatenate([tt.ravel(), tt.ravel()])
    rate = np.concatenate([np.zeros(tt.size), np.full(tt.size, rate_dps)]) * DEG
    theta = np.concatenate([aa.ravel(), aa.ravel()]) * DEG
    t = np.arange(int(round(duration_s / dt)) + 1) * dt

    def f(th):
        b = bias_dph * DEG_PER_H
        return -K_E_NOMINAL * (session_scale_factor(th, temp) * rate + session_drift(th, temp) + b)

    out, h = [theta], dt / 8
    for _ in t[1:]:
        for _ in range(8):
            k1 = f(theta)
            k2 = f(theta + h / 2 * k1)
            k3 = f(theta + h / 2 * k2)
            k4 = f(theta + h * k3)
            theta = theta + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(theta)
    n_runs, n = temp.size, t.size
    return hg.MeasuredData(
        {
            "time_s": np.tile(t, n_runs),
            "run": np.repeat(np.arange(n_runs), n),
            "temperature_c": np.repeat(temp, n),
            "table_rate_dps": np.repeat(rate / DEG, n),
            "wave_angle_deg": np.stack(out, axis=1).ravel() / DEG,
        }
    )


AMPLITUDE_DPH = 0.186
"""Ω cos φ sin δ at 45° N and δ = 1° [°/h]: the tilt of the 2026-12-01 bench audit."""


def azimuth_session(amplitude_dph=AMPLITUDE_DPH):
    """The closed-form test session (0.43 °/h switch-on bias) with each run started at table
    azimuth 90°·(run mod 4) and `amplitude_dph`·cos(azimuth) added to its bias (exact for
    the static runs, whose table stays at that azimuth)."""
    n_runs = 36  # 18 static then 18 rotation runs (closed_form_session's grid)
    az = 90.0 * (np.arange(n_runs) % 4)
    bias = 0.43 + amplitude_dph * np.cos(np.deg2rad(az))
    data = closed_form_session(bias)
    cols = dict(data.columns)
    cols["table_angle_deg"] = data.table_angle_deg + az[data.run]
    return hg.MeasuredData(cols)


class CompileCounter:
    """Counts JAX traces and XLA compiles (jax.monitoring events) while active:
    `with CompileCounter() as c: …; c.compiles, c.traces`."""

    _active: list = []
    _registered = False

    def __enter__(self):
        import jax.monitoring

        if not CompileCounter._registered:
            jax.monitoring.register_event_duration_secs_listener(CompileCounter._listen)
            CompileCounter._registered = True
        self.compiles, self.traces, self.names = 0, 0, []
        CompileCounter._active.append(self)
        return self

    def __exit__(self, *exc):
        CompileCounter._active.remove(self)

    @staticmethod
    def _listen(event, duration, **kwargs):
        for c in CompileCounter._active:
            if event == "/jax/core/compile/backend_compile_duration":
                c.compiles += 1
                c.names.append(kwargs.get("fun_name"))
            elif event == "/jax/core/compile/jaxpr_trace_duration":
                c.traces += 1


def cli_fails(argv, capsys, match, code=2):
    """Run `hrgjax argv`, expect exit status `code` and one stderr line matching `match`;
    returns that line."""
    import re

    from hrgjax.cli import main

    capsys.readouterr()
    try:
        main(argv)
    except SystemExit as stop:
        status = stop.code
    else:
        status = 0
    err = capsys.readouterr().err.strip().splitlines()
    assert status == code, (status, err)
    assert err, "no message on stderr"
    assert re.search(match, err[-1]), err
    if code == 2:  # bad input: one line, argparse's own errors too (its usage block went first)
        assert len(err) == 1, err
    return err[-1]


LAPACK_PRIMITIVES = frozenset({"cholesky", "lu", "triangular_solve", "eigh", "eig", "svd", "qr",
                               "householder_product", "geqrf", "geqp3", "schur", "hessenberg",
                               "tridiagonal", "tridiagonal_solve"})  # fmt: skip
"""JAX primitives that XLA:CPU runs as jaxlib's LAPACK custom calls: batched, they split over
the CPU thread pool and can wedge it (hrgjax/_threads.py, hrgjax/_linalg.py)."""


def batched_lapack(fn, *args) -> set:
    """The LAPACK-backed primitives that `fn(*args)`'s program runs on a batch of matrices (an
    operand of rank > 2: what jaxlib splits over the pool), nested programs included. Traced
    only: nothing compiles."""
    import equinox as eqx
    from jax.extend.core import ClosedJaxpr, Jaxpr

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            if any(getattr(v.aval, "ndim", 0) > 2 for v in eqn.invars):
                yield eqn.primitive.name
            for value in eqn.params.values():
                for v in value if isinstance(value, (tuple, list)) else (value,):
                    if isinstance(v, ClosedJaxpr):
                        yield from walk(v.jaxpr)
                    elif isinstance(v, Jaxpr):
                        yield from walk(v)

    closed = eqx.filter_make_jaxpr(fn)(*args)[0]
    return set(walk(closed.jaxpr)) & LAPACK_PRIMITIVES


def still_ramps(intervals, n=41):
    """Runs of `n` samples every `intervals[i]` [s], the wave at 0, the table at rest, the
    temperature ramping 10 → 30 °C: the smallest continuous records discovery takes."""
    cols = {"time_s": [], "run": [], "wave_angle_deg": [], "temperature_c": [],
            "table_rate_dps": []}  # fmt: skip
    for run, dt in enumerate(intervals):
        cols["time_s"].append(np.arange(n) * dt)
        cols["run"].append(np.full(n, run))
        cols["wave_angle_deg"].append(np.zeros(n))
        cols["temperature_c"].append(np.linspace(10.0, 30.0, n))
        cols["table_rate_dps"].append(np.zeros(n))
    return hg.MeasuredData({k: np.concatenate(v) for k, v in cols.items()})


def modelled_imu(grade: str):
    """A `hrgjax.ins.sensors.preset(grade)`'s biases, bias instabilities and noise with no
    misalignment and a small rate random walk: what the loosely coupled filter's 15 states
    model exactly (its NEES/NIS are then honest)."""
    from hrgjax.ins import sensors
    from hrgjax.units import DEG_PER_H

    p = sensors.preset(grade)
    return sensors.ImuModel(
        gyro_bias=p.gyro_bias,
        accel_bias=p.accel_bias,
        arw=p.arw,
        vrw=p.vrw,
        gyro_bias_instability=p.gyro_bias_instability,
        accel_bias_instability=p.accel_bias_instability,
        gyro_misalignment=np.zeros((3, 3)),
        accel_misalignment=np.zeros((3, 3)),
        gyro_rate_random_walk=0.05 * DEG_PER_H / 10.0,
        gyro_correlation_time=p.gyro_correlation_time,
        accel_correlation_time=p.accel_correlation_time,
    )


def octave_pairs(ms, n: int):
    """Each pair a ≤ b of averaging factors `ms` over `n` samples, for the brute-force
    covariances of the overlapping Allan variance: `(a, b, m_a, m_b, n_a, n_b, ℓ, h_a, h_b)`
    — the second differences' counts n + 1 − 2m, the lags ℓ between them, and the filters h
    (−1 × m, +1 × m) that make them out of the rate samples."""
    for a, ma in enumerate(ms):
        for b, mb in enumerate(ms[a:], a):
            na, nb = n + 1 - 2 * ma, n + 1 - 2 * mb
            ell = np.arange(-(na - 1), nb)
            ha, hb = np.r_[-np.ones(ma), np.ones(ma)], np.r_[-np.ones(mb), np.ones(mb)]
            yield a, b, ma, mb, na, nb, ell, ha, hb


def mechanise_ned(traj, c0s, hours, dws=None, rtol=1e-12, atol=1e-14, max_steps=200_000):
    """Nonlinear NED mechanisation with altitude held (aided), driven by the ideal IMU output
    of a constant-velocity trajectory (constant in the body frame) plus each constant
    body-frame gyro error of `dws` (K, 3) [rad/s] (None: none), from each initial attitude of
    `c0s` (K, 3, 3), in one vmapped solve: (ts [s] (61,), states (K, 61, 14): lat, lon [rad],
    v_ned [m/s], C_bn row-major)."""
    import diffrax
    import jax
    import jax.numpy as jnp

    earth, h = traj.earth, traj.h[0]
    f_b, w_b = (x[0] for x in traj.imu())
    dws = jnp.zeros((c0s.shape[0], 3)) if dws is None else dws
    skew = lambda w: jnp.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])  # noqa: E731

    def field(t, y, dw):
        lat, v, c = y[0], y[2:5], y[5:14].reshape(3, 3)
        w_ie, w_en = earth.earth_rate(lat), earth.transport_rate(lat, h, v)
        dc = c @ skew(w_b + dw) - skew(w_ie + w_en) @ c
        dv = c @ f_b - jnp.cross(2 * w_ie + w_en, v) + earth.gravity_ned(lat, h)
        pos = earth.position_rate(lat, h, v)
        return jnp.concatenate([pos[:2], dv.at[2].set(0.0), dc.reshape(9)])

    ts = jnp.linspace(0.0, hours * 3600.0, 61)

    @jax.vmap
    def solve(c0, dw):
        y0 = jnp.concatenate([jnp.stack([traj.lat[0], traj.lon[0]]), traj.v_ned[0], c0.reshape(9)])
        return diffrax.diffeqsolve(
            diffrax.ODETerm(field), diffrax.Tsit5(), 0.0, ts[-1], None, y0, args=dw,
            saveat=diffrax.SaveAt(ts=ts), max_steps=max_steps,
            stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
        ).ys  # fmt: skip

    return ts, solve(c0s, dws)


# The short continuous dataset's ramps, as `continuous_dataset(ramps=…)` takes them
# (test_discovery_continuous, test_discovery_held_temperature).
SHORT_RAMPS = (
    (-20.0, 40.0, 600.0, 0.0, 0.0),
    (40.0, -20.0, 600.0, 2.0, 0.0),
    (-20.0, 40.0, 200.0, 0.0, 45.0),
    (40.0, -20.0, 200.0, 2.0, 30.0),
    (0.0, 60.0, 400.0, 0.0, -30.0),
    (60.0, 0.0, 400.0, 2.0, 60.0),
)


def recording_bar(made: list):
    """A stand-in for `hrgjax._progress.bar` (monkeypatch it in) that records every bar it
    makes in `made`, each with its `total` and the count `n` it reached (the library's
    silent bar, which counts, and nothing drawn)."""
    from hrgjax._progress import _Silent  # no public name: the silent bar is internal

    class RecordingBar(_Silent):
        def __init__(self, total=None, desc=None, unit="step", **_):
            super().__init__(total)
            self.desc = desc
            made.append(self)

    return RecordingBar


def flight_motion():
    """The navigation tests' 120-s flight (tests/test_navigation_filter.py,
    test_ins_consistency.py, test_navigation_gauss_markov.py): a take-off run, a banked right
    turn, a climb, level flight; 40° N, 10° E, 200 m, 20 m/s north."""
    from hrgjax.ins import motion

    s, z = motion.Segment, (0.0, 0.0, 0.0)
    segs = (
        s(1, z, (2.0, 0.0, 0.0), 30.0),
        s(3, (0.0, 0.0, 20.0), z, 5.0),
        s(1, (3.0, 0.0, 0.0), z, 25.0),
        s(3, (0.0, 4.0, -20.0), z, 5.0),
        s(1, z, z, 55.0),
    )
    return motion.Motion(40.0, 10.0, 200.0, (20.0, 0.0, 0.0), 10.0, 0.0, 0.0, segs)
