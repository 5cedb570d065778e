"""Full (carrier-resolving) model on one trajectory, f₀ = 5 kHz, 0.2 s, rtol 1e-8:
hrgjax — the default call (`simulate(model="full")`: the fixed-step carrier path where it
meets rtol) and adaptive stepping (`fixed_step=None`, diffrax Dopri8, compiled) — vs scipy
solve_ivp RK45 and DOP853 on the same equations, the same scaled state and the same
tolerances. Prints the time ratios and each one's final-state error against a tight
reference (adaptive Dopri8, rtol 1e-13). Targets: ≥ 150× vs RK45, ≥ 40× vs DOP853
(issue 20, fixed-step path); the default call ≥ 100× vs RK45 at equal accuracy (issue 50).

Then the same comparison with the loops closed (the default gyro, laws on, 0.05 s): the
default call (every stage demodulating its state), the held-loop step
(`fixed_step="held"`) and adaptive stepping, each one's time and largest wave-angle,
amplitude and frequency error against adaptive stepping at rtol 1e-12 (no scipy script: the
loops are hrgjax's own).

The resonator runs free (loops off) so that the scipy side is the same ODE written in NumPy:
z̈ = −D ż − K z − 2k_eΩ J ż − χ|z|² z, with defects, rotation and Duffing term.
"""

import time

import numpy as np
from _common import best_of, first_call, machine, report
from scipy.integrate import solve_ivp

import hrgjax as hg

RTOL, ATOL = 1e-8, 1e-10
OMEGA = 2 * np.pi * 5000.0
PARAMS = dict(
    omega=OMEGA,
    tau=640.0,
    k_e=0.554,
    delta_omega=2 * np.pi * 0.05,
    theta_omega=0.2,
    delta_inv_tau=2e-3,
    theta_tau=0.5,
    chi=2e4,
)
RATE_DPS = 100.0
DURATION = 0.2


def numpy_rhs():
    p = PARAMS
    w, ws = p["omega"], p["omega"]

    def a_mat(b):
        return np.array([[np.cos(2 * b), np.sin(2 * b)], [np.sin(2 * b), -np.cos(2 * b)]])

    d = 2 / p["tau"] * np.eye(2) + p["delta_inv_tau"] * a_mat(p["theta_tau"])
    k = w**2 * np.eye(2) + w * p["delta_omega"] * a_mat(p["theta_omega"])
    j = np.array([[0.0, -1.0], [1.0, 0.0]])
    rate = np.deg2rad(RATE_DPS)

    def rhs(t, y):
        z, zd = y[0:2], y[2:4] * ws
        zdd = -d @ zd - k @ z - 2 * p["k_e"] * rate * (j @ zd) - p["chi"] * (z @ z) * z
        return np.concatenate([zd, zdd / ws, [w], np.zeros(3)])

    return rhs


def main():
    gyro = hg.Gyro(hg.Resonator(**PARAMS), control=hg.Control.free())
    prof = hg.Profile.constant_rate(RATE_DPS, DURATION, wave_angle0_deg=20.0)
    ts = np.array([0.0, DURATION])
    run = lambda: hg.simulate(
        gyro, prof, model="full", ts=ts, rtol=RTOL, atol=ATOL, fixed_step=None
    )
    compile_s, rec = first_call(run)
    adaptive_s = best_of(run, 5)
    default = lambda: hg.simulate(gyro, prof, model="full", ts=ts, rtol=RTOL, atol=ATOL)
    fixed_compile_s, rec_fixed = first_call(default)
    jax_s = best_of(default, 5)
    ref = hg.simulate(gyro, prof, model="full", ts=ts, rtol=1e-13, atol=1e-15, fixed_step=None)

    import diffrax

    from hrgjax.resonator.full import full_initial_state, full_vector_field

    y0, scale = full_initial_state(gyro, prof)
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(full_vector_field),
        diffrax.Dopri8(),
        0.0,
        DURATION,
        1e-5,
        y0,
        args=(gyro, prof, scale),
        stepsize_controller=diffrax.PIDController(rtol=RTOL, atol=ATOL),
        max_steps=2**20,
    )
    y_jax, steps = np.asarray(sol.ys[-1]), int(sol.stats["num_steps"])
    rhs = numpy_rhs()
    print(f"machine: {machine()}")
    print(
        f"full model, f0 = 5 kHz, {DURATION} s ({DURATION * 5000:.0f} cycles), rtol {RTOL}, "
        f"atol {ATOL}"
    )
    y_ref = np.asarray(
        diffrax.diffeqsolve(
            diffrax.ODETerm(full_vector_field), diffrax.Dopri8(), 0.0, DURATION, 1e-5, y0,
            args=(gyro, prof, scale), max_steps=2**22,
            stepsize_controller=diffrax.PIDController(rtol=1e-13, atol=1e-15),
        ).ys[-1]
    )  # fmt: skip

    def angle_err(r):
        return abs(float(r.wave_angle[-1] - ref.wave_angle[-1]))

    print(
        f"hrgjax adaptive Dopri8:  {adaptive_s * 1e3:8.1f} ms after compile "
        f"(compile + first run {compile_s:.1f} s), {int(steps)} steps; final-state max |Δ| "
        f"= {np.max(np.abs(y_jax[:4] - y_ref[:4])):.2e}, wave angle {angle_err(rec):.1e} rad"
    )
    print(
        f"hrgjax default call:    {jax_s * 1e3:8.1f} ms after compile "
        f"(compile + first run {fixed_compile_s:.1f} s), 10 steps per cycle; wave angle "
        f"{angle_err(rec_fixed):.1e} rad; {adaptive_s / jax_s:.1f}× the adaptive path"
    )
    for method in ("RK45", "DOP853"):
        t0 = time.perf_counter()
        sol = solve_ivp(rhs, (0.0, DURATION), np.asarray(y0), method=method, rtol=RTOL, atol=ATOL)
        sp_s = time.perf_counter() - t0
        dz = np.max(np.abs(sol.y[:4, -1] - y_ref[:4]))
        print(
            f"scipy {method:6s}:         {sp_s * 1e3:8.1f} ms, {sol.t.size - 1} steps; "
            f"final-state max |Δ| = {dz:.2e} (amplitude 1); ratio to the default call "
            f"{sp_s / jax_s:6.1f}×, to the adaptive path {sp_s / adaptive_s:5.1f}×"
        )
        target = "≥ 100× (default call), ≥ 150× (fixed steps)" if method == "RK45" else "≥ 40×"
        report(
            f"full model, 0.2 s at 5 kHz: scipy {method} time",
            sp_s * 1e3,
            "ms",
            f"scipy {method} / hrgjax default call ({jax_s * 1e3:.0f} ms)",
            sp_s / jax_s,
            target,
        )
    print(f"final wave angle (hrgjax record): {np.rad2deg(float(rec.wave_angle[-1])):.6f}°")
    closed_loops()


def closed_loops():
    gyro = hg.presets.tvg3_like(noise=False)
    prof = hg.Profile(
        t=np.array([0.0, 0.012, 0.05]),
        rate=np.deg2rad([0.0, 40.0, 40.0]),
        temperature=np.array([20.0, 20.5, 21.0]),
        accel=np.zeros((3, 3)),
        wave_angle0=np.deg2rad(30.0),
    )
    ts = np.linspace(0.005, 0.05, 10)
    sim = lambda **kw: hg.simulate(gyro, prof, model="full", ts=ts, **kw)  # noqa: E731
    ref = sim(fixed_step=None, rtol=1e-12, atol=1e-14)
    print(
        "loops closed, laws on (the default gyro), 0.05 s with a rate ramp and a knot, rtol 1e-8:"
    )
    times = {}
    for name, kw in (("adaptive", dict(fixed_step=None)), ("default call", {}),
                     ("held loops", dict(fixed_step="held"))):  # fmt: skip
        fn = lambda kw=kw: sim(**kw)  # noqa: E731
        c, rec = first_call(fn)
        times[name] = best_of(fn, 3)
        errs = ", ".join(
            f"{f} {np.max(np.abs(np.asarray(getattr(rec, f)) - np.asarray(getattr(ref, f)))):.1e}"
            for f in ("wave_angle", "amplitude", "quadrature", "frequency")
        )
        print(f"  {name:13s} {times[name] * 1e3:7.1f} ms (first {c:.1f} s); max |Δ|: {errs}")
    ratio = times["adaptive"] / times["default call"]
    print(f"  default call {ratio:.2f}× faster than adaptive stepping at equal or better accuracy")
    report("full model, loops closed, 0.05 s: default call", times["default call"] * 1e3, "ms",
           "adaptive / default call", ratio, "")  # fmt: skip


if __name__ == "__main__":
    import jax  # noqa: F401

    main()
