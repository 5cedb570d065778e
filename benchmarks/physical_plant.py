"""What modelling the PI loops costs the physical grey box (issue 43), side by side in one run.

- One 120-s rotation run at 10 °/s on the default gyro: the averaged model with the PI loops
  integrated as states against ideal loops (the solver steps the loops need).
- `PhysicalCompensator().fit` (ideal loops) against `PhysicalCompensator(plant=gyro).fit`
  (the PI loops' pull simulated and taken off, two passes) on the quick seed plan: first call
  (compile + run) and a second call with the same shapes (run only).

Usage: `.venv/bin/python benchmarks/physical_plant.py`.
"""

import sys
import time

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
from _common import best_of, machine, report

import hrgjax as hg
from hrgjax.calibration import PhysicalCompensator, run_plan, seed_plan
from hrgjax.data import concat


def one_run() -> None:
    gyro = hg.presets.tvg3_like(noise=False)
    ideal = eqx.tree_at(lambda g: g.control, gyro, hg.Control(ideal=True))
    prof = hg.Profile.constant_rate(10.0, 120.0, temperature_c=20.0)
    ts = jnp.linspace(0.0, 120.0, 241)
    sim = eqx.filter_jit(lambda g: hg.simulate(g, prof, ts=ts, adjoint=diffrax.ForwardMode(),
                                               rtol=1e-9, atol=1e-12).wave_angle)  # fmt: skip
    t_pi = best_of(lambda: sim(gyro))
    t_ideal = best_of(lambda: sim(ideal))
    report("120-s rotation run, PI loops", t_pi * 1e3, "ms",
           f"ideal loops {t_ideal * 1e3:.2f} ms", ratio=t_pi / t_ideal)  # fmt: skip


def fits() -> None:
    gyro = hg.presets.tvg3_like()
    key = jax.random.key(2000)
    static, rotation = seed_plan(quick=True)
    a = run_plan(gyro, static, key=key, bias_key=key)
    b = run_plan(gyro, rotation, key=jax.random.fold_in(key, 1), bias_key=key,
                 first_run=static.size)  # fmt: skip
    data = concat([a, b])
    out = {}
    for name, comp in (("ideal loops", PhysicalCompensator()),
                       ("plant=gyro", PhysicalCompensator(plant=gyro))):  # fmt: skip
        times = []
        for _ in range(2):
            t0 = time.perf_counter()
            comp.fit(data)
            times.append(time.perf_counter() - t0)
        out[name] = times
        print(f"  {name}: first fit {times[0]:.1f} s, second {times[1]:.1f} s", flush=True)
    report("physical fit with plant=, second call", out["plant=gyro"][1], "s",
           f"ideal loops {out['ideal loops'][1]:.2f} s",
           ratio=out["plant=gyro"][1] / out["ideal loops"][1])  # fmt: skip


def main() -> int:
    print(f"physical_plant.py on {machine()}")
    one_run()
    fits()
    return 0


if __name__ == "__main__":
    sys.exit(main())
