"""Does `align`'s coarse-heading prior cover a swaying vehicle, without inflating a quiet one?

1. The PSINS log (`tests/data/psins_lasergyro.imu`, parked vehicle, engine on): the coarse
   heading of each disjoint 60-, 120- and 300-s window against the log's 90.6° (the gyros
   show the heading constant to ±0.01°: the errors are sway in the means). Printed: the error
   RMS and worst, and for the prior's heading σ before (5° ⊕ the grade's white noise) and now
   (5° ⊕ the larger of that and the span's own scatter, `coarse_scatter`): z-RMS, the share
   within ±1.96σ, beyond 3σ, and the median σ.
2. Simulated stationary logs (white noise only, the default grade; 1 Hz, 30 min, random
   attitude) at 45° and 88°: the start heading σ now / before (5° ⊕ the white noise ⊕ the
   bias part; the scatter's noise can only add, as the max of two estimates of one
   variance) and the final heading z-RMS (before: the same draws gave the same z to 1e-3).

3. `--windows`: `align` on the PSINS log's disjoint 150- and 300-s windows with
   `velocity_noise` 0.01 and 0.03 m/s: the headings' spread against the σ and its part
   beyond the bias floor, each window's heading, σ, north/east slow ratio
   (`AlignmentResult.sway`), whether `sway()` finds the innovations not white (a whiteness
   test; it does not follow the heading error: compare the window's heading with the others)
   and whether `align` warned, and how.

Usage: `.venv/bin/python benchmarks/coarse_sway.py [--n 30] [--windows]` (about 30 s on 2
shared cores; `--windows` about 1 minute more).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

from hrgjax.ins import alignment as al  # noqa: E402
from hrgjax.ins import trajectory as tr  # noqa: E402

DEG = np.pi / 180
PSINS = Path(__file__).resolve().parents[1] / "tests" / "data" / "psins_lasergyro.imu"
ARW, VRW, FLOOR_DEG = 0.01 * DEG / 60, 1e-4, 5.0


def real_windows() -> None:
    log = al.load_psins(PSINS)
    for span in (60.0, 120.0, 300.0):
        n = int(round(span / log.dt))
        err, old, new = [], [], []
        for k in range(log.t.shape[0] // n):
            dth, dv = log.dtheta[k * n : (k + 1) * n], log.dvel[k * n : (k + 1) * n]
            c0 = al.coarse_align(jnp.sum(dv, 0) / span, jnp.sum(dth, 0) / span, log.lat)
            jac, white = al.coarse_error_model(c0, log.lat, log.h, span, ARW, VRW)
            scatter = jnp.diag(jac @ al.coarse_scatter(dth, dv, log.dt) @ jac.T)
            old.append(np.hypot(FLOOR_DEG, np.sqrt(float(white[2])) / DEG))
            new.append(np.hypot(FLOOR_DEG, np.sqrt(float(jnp.maximum(white, scatter)[2])) / DEG))
            err.append((float(al.euler_deg(c0)[0]) - 90.6 + 180.0) % 360.0 - 180.0)
        err = np.array(err)
        print(f"{span:4.0f}-s windows ({len(err)}): coarse heading error RMS "
              f"{np.sqrt(np.mean(err**2)):.1f}°, worst {np.abs(err).max():.1f}°")  # fmt: skip
        for name, s in (("before", np.array(old)), ("now", np.array(new))):
            z = err / s
            print(f"  {name:>6}: σ median {np.median(s):5.1f}°, z-RMS {np.sqrt(np.mean(z**2)):.2f}, "
                  f"within ±1.96σ {np.mean(np.abs(z) < 1.96):.0%}, beyond 3σ "
                  f"{np.mean(np.abs(z) > 3):.0%}")  # fmt: skip


def simulated(n_draws: int) -> None:
    for lat in (45.0, 88.0):
        ratio, z = [], []
        for seed in range(n_draws):
            rng = np.random.default_rng(seed)
            traj = tr.stationary(lat, heading_deg=rng.uniform(0, 360), pitch_deg=rng.normal(0, 2),
                                 roll_deg=rng.normal(0, 2), duration_s=1800.0, dt=1.0)  # fmt: skip
            f_b, w_b = traj.imu()
            size = len(traj.t) - 1
            eps, nab = rng.normal(0, 0.05 * DEG / 3600, 3), rng.normal(0, 1e-3, 3)
            dth = np.asarray(w_b[1:]) + eps + ARW * rng.standard_normal((size, 3))
            dv = np.asarray(f_b[1:]) + nab + VRW * rng.standard_normal((size, 3))
            log = al.ImuLog(traj.t[1:], jnp.asarray(dth), jnp.asarray(dv), lat * DEG)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", al.AlignmentWarning)
                r = al.align(log)
            c0 = al.coarse_align(jnp.mean(log.dvel[:60], 0), jnp.mean(log.dtheta[:60], 0), log.lat)
            jac, white = al.coarse_error_model(c0, log.lat, 0.0, 60.0, ARW, VRW)
            var_b = np.repeat([(0.05 * DEG / 3600) ** 2, 1e-6], 3)  # the default grade
            before = (
                FLOOR_DEG**2 + (float(white[2]) + np.sum(np.asarray(jac[2]) ** 2 * var_b)) / DEG**2
            )
            ratio.append(r.coarse_std_deg[0] / np.sqrt(before))
            truth = float(al.euler_deg(traj.c_bn[0])[0])
            z.append(((r.heading_deg - truth + 180) % 360 - 180) / r.heading_std_deg)
        ratio, z = np.array(ratio), np.array(z)
        print(f"simulated {lat:g}° ({n_draws} draws): start σ now/before mean {ratio.mean():.3f}, "
              f"max {ratio.max():.3f}; final heading z-RMS {np.sqrt(np.mean(z**2)):.2f}, within "
              f"±1.96σ {np.mean(np.abs(z) < 1.96):.0%}")  # fmt: skip


def windows() -> None:
    log = al.load_psins(PSINS)
    floor = 0.05 * DEG / 3600 / (7.292115e-5 * np.cos(log.lat)) / DEG
    for span in (150.0, 300.0):
        m = int(round(span / log.dt))
        for vn in (0.01, 0.03):
            rows = []
            for k in range(log.t.shape[0] // m):
                sl = slice(k * m, (k + 1) * m)
                sub = al.ImuLog(log.t[sl], log.dtheta[sl], log.dvel[sl], log.lat, log.lon, log.h)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always", al.AlignmentWarning)
                    r = al.align(sub, velocity_noise=vn)
                sway = r.sway()
                note = " ".join(str(w.message) for w in caught)
                rows.append((r.heading_deg, r.heading_std_deg, *sway["slow_ratio"][:2],
                             sway["not_white"], 2 if "sways" in note else bool(note)))  # fmt: skip
            a = np.array(rows, dtype=float)
            print(f"{span:g}-s windows, velocity_noise {vn:g} m/s: spread {a[:, 0].std(ddof=1):.3f}°, "
                  f"σ {a[:, 1].mean():.3f}° (beyond the bias floor "
                  f"{np.sqrt(np.mean(a[:, 1] ** 2) - floor**2):.3f}°), not white "
                  f"{int(a[:, 4].sum())}, warned {int(np.sum(a[:, 5] > 0))} ({int(np.sum(a[:, 5] == 2))} "
                  f"a sway note) of {len(a)}")  # fmt: skip
            for row in a:
                h, sd, north, east, opt, warned = row
                z = (h - a[:, 0].mean()) / sd
                print(f"   heading {h:.3f}° ± {sd:.3f}° ({z:+.1f}σ from the windows' mean), slow "
                      f"ratio N {north:.2f} E {east:.2f}, not white {int(opt)}, warned "
                      f"{['no', 'yes', 'a sway note'][int(warned)]}")  # fmt: skip


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=30, help="simulated draws per latitude")
    parser.add_argument("--windows", action="store_true", help="part 3: align per window")
    args = parser.parse_args()
    real_windows()
    simulated(args.n)
    if args.windows:
        windows()
