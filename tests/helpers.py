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
    return err[-1]
