"""Discovery on a designed bench plan of the default gyro: dwell runs and ramps in one log
(audit 2026-12-01, bench2 F1; docs/discovery.md, "A designed plan on the default gyro").

`hg.presets.tvg3_like()` (its readout gain mismatch −9197 ppm at 20 °C, 191.7 ppm/°C) at
−40, 20 and 60 °C: a 120-s static and a 72-s 5 °/s rotation at each of −60°, 0° and 60° el.,
then four 6000-s ramps at 1 °C/min (−40 → 60 and back at 30° el., the same pair at −30°):
22 runs, `calibration.simulate_plan` with key 0. Prints the held-out split, the verdict, the
equations, the first-round screening rows and each accepted effect's consistency, and the
same dwell runs alone (the dwell search) for comparison. Before the split kept every static
wave angle in training and the dwell windows' evidence was counted: `unexplained`, gap
183 °/h, damping cos 2θ −186 ± 16 °/h; and until the acceptance rule read `p_stat` a third
effect, `thermal_rate` −18 ± 18 °/h per °C/min, was accepted (48σ by the noise model). Usage: `nice -n 10 .venv/bin/python
benchmarks/discovery_mixed_plan.py` (≈ 6 min on 2 shared cores).
"""

import time

import jax
import numpy as np
from _common import machine

import hrgjax as hg
from hrgjax import calibration as cal
from hrgjax.data import MeasuredData
from hrgjax.discovery import discover


def plan_log() -> MeasuredData:
    """The 22-run log (noise and all, key 0)."""
    segs = []
    for temp in (-40.0, 20.0, 60.0):
        for angle in (-60.0, 0.0, 60.0):
            common = {"temperature_c": temp, "wave_angle_deg": angle}
            segs.append({"kind": "static", "duration_s": 120.0, **common})
            segs.append({"kind": "rotation", "rate_dps": 5.0, "duration_s": 72.0, **common})
    for t0, t1, angle in ((-40, 60, 30), (60, -40, 30), (-40, 60, -30), (60, -40, -30)):
        segs.append({"kind": "ramp", "temperature_start_c": float(t0),
                     "temperature_end_c": float(t1), "wave_angle_deg": float(angle),
                     "duration_s": 6000.0})  # fmt: skip
    plan = cal.BenchPlan.from_segments(segs)
    return cal.simulate_plan(hg.presets.tvg3_like(), plan, key=jax.random.key(0))


def show(found, seconds):
    print(f"{found.shape}: {found.verdict}, accepted {found.accepted}, split {found.split}, "
          f"{seconds:.0f} s")  # fmt: skip
    print(found.equations())
    for r in found.screening[:6]:
        keep = ("effect", "delta_bic", "heldout_gain", "p_stat", "agreement", "refused_by")
        print({k: round(r[k], 4) if isinstance(r[k], float) else r[k] for k in keep})
    for name, c in found.consistency.items():
        if c is None:  # dwell grids: one run is one grid point
            continue
        print(name, "agreement", c["agreement"], "units", c["units"], "|", c["reason"])


if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    hg.enable_cache()
    print(machine())
    data = plan_log()
    run = np.asarray(data.run)
    dwell = MeasuredData({k: np.asarray(v)[run < 18] for k, v in data.columns.items()})
    for log in (dwell, data):
        t0 = time.perf_counter()
        found = discover(log)
        show(found, time.perf_counter() - t0)
