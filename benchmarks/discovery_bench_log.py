"""Discovery on one campaign's bench log (issue 19's speed target: ≤ 60 s on 2 cores).

`generate.bench_log`: 62 runs in one file — 6 temperatures × 7 wave angles of 180-s static
dwells at 1 Hz, ±5 °/s rotations (one turn, 10 Hz) at each temperature, eight 1-h
temperature ramps at 0.2 Hz — of the base gyro with one effect hidden. Prints the rows, the
wall time of `discover` (first call in the process, warm compile cache unless
`HRGJAX_NO_CACHE=1`), the time of a second call on new data of the same shapes, and the
verdict. Usage: `.venv/bin/python benchmarks/discovery_bench_log.py [EFFECT SIZE]`
(default: thermal_lag 0.01 °/h/°C).
"""

import sys
import time

import jax
from _common import machine

import hrgjax as hg
from hrgjax.discovery import discover
from hrgjax.discovery.generate import bench_log

if __name__ == "__main__":
    jax.config.update("jax_enable_x64", True)
    hg.enable_cache()
    effect = sys.argv[1] if len(sys.argv) > 1 else "thermal_lag"
    size = float(sys.argv[2]) if len(sys.argv) > 2 else 0.01
    print(machine())
    for seed in (0, 1):
        t0 = time.perf_counter()
        data = bench_log(effect, size, key=jax.random.key(seed))
        t_gen = time.perf_counter() - t0
        t0 = time.perf_counter()
        found = discover(data)
        wall = time.perf_counter() - t0
        print(f"seed {seed}: {len(data)} rows, {len(set(data.run.tolist()))} runs "
              f"(generated in {t_gen:.1f} s); discover {wall:.1f} s ({found.shape} data)")  # fmt: skip
        print(found.equations())
