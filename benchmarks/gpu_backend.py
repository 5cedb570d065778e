"""The GPU beside the same machine's CPU, batch by batch (issue 20): where does each pay?

Each backend runs in its own process: the GPU (one device) and the CPU with one forced device
per core (`hg.sweep` shards a batch over them, so the CPU side uses every core). Per backend:

- averaged model, 60-s runs at rates 0.1–400 °/s × temperatures −40…60 °C through `hg.sweep`,
  batches of 64, 1 024 and 10 000 members;
- one averaged run of 180 s at 10 °/s: `simulate` under `eqx.filter_jit` with 0.1-s outputs,
  and `hg.simulate` called eagerly (hrgjax runs it, set-up included, on the CPU beside an
  accelerator: `hrgjax._compiled.single_run_entry`);
- the full (carrier-resolving) model: one run of 0.05 s on fixed steps, and batches of 256
  runs of 0.05 s (rates 0.1–400 °/s): the default call (fixed steps, every stage
  demodulating), held loops and adaptive (Dopri8); the held batch again with 4, 16 and 64
  steps per iteration of the compiled step loop (`hrgjax.resonator.carrier.UNROLL`).

Printed: compile + first call and the best later call, the GPU / CPU speed-up of each row and
the largest difference between the backends' results (relative to the largest value).
Without a GPU only the CPU column is printed.

Usage: `.venv/bin/python benchmarks/gpu_backend.py [--quick] [--no-large]` (`--quick`:
smaller batches, to check the script; `--no-large`: without the 10 000-run sweep, whose CPU
side takes about a minute — for a device lease that also runs the test suite).
"""

import json
import os
import subprocess
import sys
import tempfile

import numpy as np

QUICK = "--quick" in sys.argv
AVG_SIZES = ((4, 16), (8, 32)) if QUICK else ((4, 16), (16, 64), (100, 100))  # T × rate
if "--no-large" in sys.argv:
    AVG_SIZES = AVG_SIZES[:2]
FULL_MEMBERS = 16 if QUICK else 256
FULL_S, AVG_S, SINGLE_S = 0.05, 60.0, 180.0  # run lengths [s]
UNROLLS = (4,) if QUICK else (4, 16, 64)  # carrier steps per loop iteration tried


def child(out_path):
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np
    from _common import best_of, first_call, machine

    import hrgjax as hg
    from hrgjax.resonator import carrier

    gyro = hg.presets.tvg3_like(noise=False)
    rows, results = {}, {}

    def timed(name, fn, repeat=3):
        first, value = first_call(fn)
        repeat = min(repeat, 2) if first > 5.0 else repeat  # slow rows: device time is short
        rows[name] = {"first_s": first, "wall_s": best_of(fn, repeat)}
        results[name] = np.asarray(jax.tree_util.tree_leaves(value)[0]).ravel()
        print(f"  {name}: {rows[name]['wall_s']:.4f} s (first {first:.1f} s)", flush=True)

    def averaged(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, AVG_S, temperature_c)
        return hg.simulate(gyro, prof, dt_out=AVG_S).wave_angle[-1]

    for n_t, n_w in AVG_SIZES:
        T = jnp.linspace(-40.0, 60.0, n_t)
        W = jnp.geomspace(0.1, 400.0, n_w)
        run = lambda T=T, W=W: hg.sweep(averaged, temperature_c=T, rate_dps=W)  # noqa: E731
        # 10 000 runs take ~25 s a call on the CPU side: timed once after the first
        timed(f"averaged × {n_t * n_w}", run, repeat=1 if n_t * n_w > 5000 else 3)

    single = eqx.filter_jit(
        lambda g, rate: hg.simulate(g, hg.Profile.constant_rate(rate, SINGLE_S, 20.0)).wave_angle
    )
    timed("averaged, one run of 180 s", lambda: single(gyro, jnp.asarray(10.0)), repeat=5)
    prof = hg.Profile.constant_rate(10.0, SINGLE_S, 20.0)
    timed("  the same, eager hg.simulate", lambda: hg.simulate(gyro, prof).wave_angle, repeat=5)

    ts = np.array([FULL_S])

    def full(rate_dps, path):
        prof = hg.Profile.constant_rate(rate_dps, FULL_S, wave_angle0_deg=10.0)
        return hg.simulate(gyro, prof, "full", ts=ts, fixed_step=path).wave_angle[-1]

    one_full = eqx.filter_jit(lambda rate: full(rate, "held"))
    timed("full, one run of 0.05 s, held loops", lambda: one_full(jnp.asarray(10.0)))
    R = jnp.geomspace(0.1, 400.0, FULL_MEMBERS)
    for path, label in (("auto", "default (fixed steps)"), ("held", "held loops"),
                        (None, "adaptive")):  # fmt: skip
        f = lambda rate_dps, path=path: full(rate_dps, path)  # noqa: E731
        timed(f"full × {FULL_MEMBERS}, {label}", lambda f=f: hg.sweep(f, rate_dps=R), repeat=2)
    # steps per iteration of the carrier's compiled step loop (carrier.UNROLL, by backend):
    # a fresh function per setting traces anew (no exported program: it is the caller's code)
    backend = jax.default_backend()
    default_unroll = carrier.UNROLL.get(backend, 1)
    for u in UNROLLS:
        carrier.UNROLL[backend] = u
        f = lambda rate_dps: full(rate_dps, "held")  # noqa: E731
        timed(f"full × {FULL_MEMBERS}, held, {u} steps per loop iteration", lambda f=f: hg.sweep(f, rate_dps=R),
              repeat=2)  # fmt: skip
    carrier.UNROLL[backend] = default_unroll

    dev = jax.devices()[0]
    meta = {"machine": machine(), "platform": dev.platform, "kind": dev.device_kind,
            "devices": jax.device_count()}  # fmt: skip
    with open(out_path, "w") as fh:
        json.dump({"meta": meta, "rows": rows}, fh)
    np.savez(out_path + ".npz", **{str(i): v for i, v in enumerate(results.values())})


def spawn(platform, tmp):
    path = os.path.join(tmp, f"{platform}.json")
    env = dict(os.environ, JAX_PLATFORMS=platform)
    if platform == "cpu":
        env["XLA_FLAGS"] = (
            f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={os.cpu_count()}"
        )
    print(f"{platform}:", flush=True)
    flags = [f for f in ("--quick", "--no-large") if f in sys.argv]
    args = [sys.executable, __file__, "--child", path] + flags
    subprocess.run(args, env=env, check=True)
    import numpy as np

    res = json.load(open(path))
    arrays = np.load(path + ".npz")
    res["results"] = [arrays[str(i)] for i in range(len(arrays.files))]
    return res


def main():
    from _common import report

    probe = "import jax; print(jax.default_backend())"
    backend = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    gpu = backend.stdout.strip() == "gpu"
    with tempfile.TemporaryDirectory() as tmp:
        runs = {"cpu": spawn("cpu", tmp)}
        if gpu:
            runs["gpu"] = spawn("cuda", tmp)
    cpu = runs["cpu"]
    for name, r in runs.items():
        print(f"{name}: {r['meta']['machine']}")
    head = f"{'run':42s} {'CPU [s]':>9} {'(first)':>8}"
    if gpu:
        head += f" {'GPU [s]':>9} {'(first)':>8} {'GPU/CPU':>8} {'max rel. Δ':>11}"
    print(head)
    for i, (name, c) in enumerate(cpu["rows"].items()):
        line = f"{name:42s} {c['wall_s']:9.4f} {c['first_s']:8.1f}"
        if gpu:
            g = runs["gpu"]["rows"][name]
            a, b = cpu["results"][i], runs["gpu"]["results"][i]
            delta = float(np.max(np.abs(a - b)) / np.max(np.abs(a)))
            speed = c["wall_s"] / g["wall_s"]
            line += f" {g['wall_s']:9.4f} {g['first_s']:8.1f} {speed:7.2f}× {delta:11.1e}"
            report(f"{name} on {runs['gpu']['meta']['kind']}", g["wall_s"], "s",
                   f"speed-up vs {cpu['meta']['devices']} CPU cores", speed)  # fmt: skip
        print(line)


if __name__ == "__main__":
    from _common import child_or_main

    child_or_main(child, main)
