"""The domain of the linear strapdown error model ([`ins.strapdown`]): how far its horizontal
position error departs from an independent nonlinear NED mechanisation as the initial
attitude error, the gyro bias × duration and the accelerometer bias grow.

Truth: two runs of the nonlinear mechanisation (the same ODE as
`tests/test_ins_errors._mechanise`: attitude matrix, velocity, latitude and longitude,
altitude held), one from the true attitude with the ideal IMU output, one from
exp(−[φ×]) C_b^n (exact Rodrigues initial error) or with a constant body-frame gyro or
accelerometer bias added; their difference is the error the linear model should give.
Figure: max over the window of |linear − nonlinear| horizontal position / max |nonlinear|,
on a 2-h (and 1-h) window, stationary at 45° and moving east at 200 m/s at 45° (sphere).

Also prints, from the linear run, a = max |φ_N|, |φ_E|, |φ_D|, |δφ| [rad] over each window:
the size the model's domain check (`strapdown.MAX_ANGLE` = 0.2 rad) reads.

Usage: `.venv/bin/python benchmarks/ins_linear_domain.py` (≈ 40 s on two cores).
"""

import time
import warnings

import diffrax
import jax
import jax.numpy as jnp
import numpy as np
from _common import machine

from hrgjax.ins import constants as C
from hrgjax.ins import strapdown as sd
from hrgjax.ins import trajectory as tr
from hrgjax.units import DEG_PER_H

HOURS = 2.0
N_OUT = 121  # one output a minute


def skew(w):
    return jnp.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def rotation(phi):
    """exp(−[φ×]): the exact rotation behind the attitude error φ (Ĉ = exp(−[φ×]) C)."""
    phi = np.asarray(phi, float)
    a = np.linalg.norm(phi)
    if a == 0:
        return np.eye(3)
    k = np.asarray(skew(phi / a))
    return np.eye(3) - np.sin(a) * k + (1 - np.cos(a)) * k @ k


def mechanise(traj, c0s, dws, das, hours):
    """Nonlinear runs (K of them, vmapped) from attitudes `c0s` (K, 3, 3) with constant
    body-frame gyro / accelerometer errors `dws`, `das` (K, 3); (ts, (K, N_OUT, 14))."""
    earth = traj.earth
    f_b, w_b = (x[0] for x in traj.imu())
    h = traj.h[0]
    ts = jnp.linspace(0.0, hours * 3600.0, N_OUT)

    def field(t, y, args):
        dw, da = args
        lat, v, c = y[0], y[2:5], y[5:14].reshape(3, 3)
        w_ie, w_en = earth.earth_rate(lat), earth.transport_rate(lat, h, v)
        dc = c @ skew(w_b + dw) - skew(w_ie + w_en) @ c
        dv = c @ (f_b + da) - jnp.cross(2 * w_ie + w_en, v) + earth.gravity_ned(lat, h)
        dv = dv.at[2].set(0.0)
        return jnp.concatenate([earth.position_rate(lat, h, v)[:2], dv, dc.reshape(9)])

    @jax.jit
    @jax.vmap
    def solve(c0, dw, da):
        y0 = jnp.concatenate([jnp.stack([traj.lat[0], traj.lon[0]]), traj.v_ned[0], c0.reshape(9)])
        return diffrax.diffeqsolve(
            diffrax.ODETerm(field),
            diffrax.Tsit5(),
            0.0,
            ts[-1],
            None,
            y0,
            args=(dw, da),
            saveat=diffrax.SaveAt(ts=ts),
            stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-13),
            max_steps=400_000,
        ).ys

    return ts, solve(jnp.asarray(c0s), jnp.asarray(dws), jnp.asarray(das))


def cases():
    """(group, label, φ0 (3,) [rad], gyro (3,) [rad/s], accel (3,) [m/s²]) per case."""
    z = np.zeros(3)
    out = []
    for p in (0.05, 0.1, 0.2, 0.5, 1.0):
        out.append(("heading", f"{p:g} rad", np.array([0, 0, p]), z, z))
    for p in (0.05, 0.1, 0.2):
        out.append(("tilt (north)", f"{p:g} rad", np.array([p, 0, 0]), z, z))
    for axis, name in ((2, "z"), (0, "x")):
        for dph in (1.0, 5.0, 10.0, 30.0, 100.0):
            out.append(
                (f"gyro bias {name}", f"{dph:g} °/h", z, np.eye(3)[axis] * dph * DEG_PER_H, z)
            )
    for g in (0.01, 0.05, 0.1, 0.2):
        out.append(("accel bias x", f"{g:g} g", z, z, np.eye(3)[0] * g * C.G0))
    return out


def relative(lin, nl):
    """max |lin − nl| / max |nl| over rows (horizontal position, metres)."""
    return np.max(np.hypot(*(lin - nl).T)) / max(np.max(np.hypot(*nl.T)), 1e-12)


def main():
    print(f"machine: {machine()}")
    # the table studies the linear model out of its domain on purpose
    warnings.simplefilter("ignore", sd.LinearisationWarning)
    t0 = time.perf_counter()
    cs = cases()
    trajs = [
        ("stationary 45°", tr.stationary(45.0, duration_s=HOURS * 3600, dt=60.0, earth=C.SPHERE)),
        (
            "east 200 m/s 45°",
            tr.constant_velocity(
                45.0, speed=200.0, heading_deg=90.0, duration_s=HOURS * 3600, dt=60.0,
                earth=C.SPHERE,
            ),
        ),
    ]  # fmt: skip
    results = {}
    for ti, (tname, traj) in enumerate(trajs):
        ct = np.asarray(traj.c_bn[0])
        c0s = [ct] + [rotation(phi) @ ct for _, _, phi, _, _ in cs]
        dws = [np.zeros(3)] + [dw for *_, dw, _ in cs]
        das = [np.zeros(3)] + [da for *_, da in cs]
        ts, ys = mechanise(traj, np.stack(c0s), np.stack(dws), np.stack(das), HOURS)
        ys = np.asarray(ys)
        idx = np.searchsorted(np.asarray(traj.t), np.asarray(ts))
        radius, lat0 = C.SPHERE.radius, float(traj.lat[0])
        scale = np.array([radius, radius * np.cos(lat0)])
        for k, (group, label, phi, dw, da) in enumerate(cs, start=1):
            # an initial attitude error past the domain is refused: the model is linear in
            # it, so run it at the edge and scale the result
            grow = max(np.abs(phi).max() / sd.MAX_ANGLE, 1.0)
            dx = grow * sd.propagate(
                traj, jnp.zeros(9).at[6:].set(jnp.asarray(phi / grow)), jnp.asarray(dw),
                jnp.asarray(da), altitude_aided=True,
            )  # fmt: skip
            lin = np.asarray(dx)[idx][:, :2] * scale
            nl = (ys[k] - ys[0])[:, :2] * scale
            half = len(ts) // 2 + 1  # the 1-h window
            dxs = np.asarray(dx)[idx]
            angle = np.abs(dxs[:, [6, 7, 8, 0]]).max(axis=1)  # what the domain check reads
            results[(group, label, ti)] = (
                relative(lin[:half], nl[:half]),
                angle[:half].max(),
                relative(lin, nl),
                angle.max(),
                np.max(np.hypot(*nl.T)),
            )
        print(f"  [{ti + 1}/{len(trajs)}] {tname} done ({time.perf_counter() - t0:.0f} s)")

    print(
        "\n|linear − nonlinear| / max |nonlinear|, horizontal position (max over the window), "
        "and a = max |φ_i|, |δφ| [rad] of the linear run"
    )
    head = f"{'input':>15} {'size':>10}"
    for tname, _ in trajs:
        head += f" | {tname:>20}: 1 h {'a':>6} {'2 h':>6} {'a':>6} {'max err':>9}"
    print(head)
    worst = 0.0
    for group, label, *_ in cs:
        row = f"{group:>15} {label:>10}"
        for ti in range(len(trajs)):
            r1, a1, r2, a2, m = results[(group, label, ti)]
            row += f" | {100 * r1:24.1f}% {a1:6.3f} {100 * r2:5.1f}% {a2:6.3f} {m / 1e3:7.0f}km"
            worst = max([worst] + [r / a for r, a in ((r1, a1), (r2, a2)) if a <= sd.MAX_ANGLE])
        print(row)
    print(f"\ninside the domain (a ≤ {sd.MAX_ANGLE} rad): error ≤ {worst:.2f} a")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
