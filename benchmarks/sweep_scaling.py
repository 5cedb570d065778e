"""`hg.sweep` across devices: a 10 000-member temperature × rate sweep of the averaged model
and a batch of full-model (carrier-resolving) runs, on 1, 2 and 4 devices.

On a CPU the devices are forced (`--xla_force_host_platform_device_count`), each count in its
own process; they share this machine's cores, so the honest ceiling is the core count
(2× on the 2-core development machine). On a GPU the same sweeps run on the GPU and, side
by side in the same run, on this machine's CPU (one process each). Every configuration's
result is compared with the one-device CPU result.

Usage: `.venv/bin/python benchmarks/sweep_scaling.py [--quick]`.
"""

import json
import os
import subprocess
import sys
import tempfile
import time

QUICK = "--quick" in sys.argv
N_T, N_W = (20, 25) if QUICK else (100, 100)  # temperature × rate members
DURATION_S = 60.0  # averaged-model run length [s]
FULL_MEMBERS, FULL_S = (16 if QUICK else 64), 0.02  # full-model batch, run length [s]


def child(out_path):
    """Run both sweeps on this process's devices; write timings and results."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    from _common import machine

    import hrgjax as hg

    gyro = hg.presets.tvg3_like(noise=False)

    def averaged(temperature_c, rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, DURATION_S, temperature_c)
        return hg.simulate(gyro, prof, dt_out=DURATION_S).wave_angle[-1]

    def full(rate_dps):
        prof = hg.Profile.constant_rate(rate_dps, FULL_S, 20.0)
        return hg.simulate(gyro, prof, "full", dt_out=FULL_S).wave_angle[-1]

    T = jnp.linspace(-40.0, 60.0, N_T)
    W = jnp.logspace(-1.0, np.log10(400.0), N_W)
    R = jnp.linspace(1.0, 100.0, FULL_MEMBERS)
    res = {
        "machine": machine(),
        "devices": jax.device_count(),
        "kind": jax.devices()[0].device_kind,
        "platform": jax.devices()[0].platform,
    }
    for name, run in (
        ("averaged", lambda: hg.sweep(averaged, temperature_c=T, rate_dps=W)),
        ("full", lambda: hg.sweep(full, rate_dps=R)),
    ):
        t0 = time.perf_counter()
        out = jax.block_until_ready(run())
        first = time.perf_counter() - t0
        walls = []
        for _ in range(3 if QUICK or name == "full" else 1):
            t0 = time.perf_counter()
            out = jax.block_until_ready(run())
            walls.append(time.perf_counter() - t0)
        res[name] = {"first_s": first, "wall_s": min(walls)}
        np.save(f"{out_path}.{name}.npy", np.asarray(out))
    if jax.device_count() == 1 and res["platform"] == "cpu":
        res["ordering"] = ordering(averaged)
    with open(out_path, "w") as f:
        json.dump(res, f)


def ordering(averaged):
    """A vmapped adaptive solve runs until its slowest member is done, so chunks of similar
    cost finish sooner: the same 500-run grid in chunks of 50, the costly axis (rate)
    innermost vs outermost in the flattened order."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import hrgjax as hg

    T = jnp.linspace(-40.0, 60.0, 20)
    W = jnp.logspace(-1.0, np.log10(400.0), 25)
    flip = lambda rate_dps, temperature_c: averaged(temperature_c, rate_dps)  # noqa: E731
    calls = {
        "rate innermost": lambda: hg.sweep(averaged, temperature_c=T, rate_dps=W, chunk_size=50),
        "rate outermost": lambda: hg.sweep(flip, rate_dps=W, temperature_c=T, chunk_size=50),
    }
    out, walls = {}, {}
    for name, call in calls.items():
        jax.block_until_ready(call())
        t0 = time.perf_counter()
        out[name] = np.asarray(jax.block_until_ready(call()))
        walls[name] = time.perf_counter() - t0
    np.testing.assert_allclose(out["rate outermost"].T, out["rate innermost"], rtol=1e-13)
    return walls


def spawn(devices, platform, tmp):
    path = os.path.join(tmp, f"{platform}{devices}.json")
    env = dict(os.environ, JAX_PLATFORMS=platform)
    if platform == "cpu":
        env["XLA_FLAGS"] = (
            f"{env.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={devices}"
        )
    args = [sys.executable, __file__, "--child", path] + (["--quick"] if QUICK else [])
    subprocess.run(args, env=env, check=True)
    import numpy as np

    res = json.load(open(path))
    for name in ("averaged", "full"):
        res[name]["result"] = np.load(f"{path}.{name}.npy")
    return res


def main():
    from _common import report  # imports jax without starting a backend here

    # The parent never starts a backend (a GPU one would take the memory the children need).
    probe = "import jax; print(jax.default_backend())"
    backend = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    gpu = backend.stdout.strip() == "gpu"
    n_avg = N_T * N_W
    with tempfile.TemporaryDirectory() as tmp:
        runs = {f"cpu×{n}": spawn(n, "cpu", tmp) for n in (1, 2, 4)}
        if gpu:
            runs["gpu"] = spawn(1, "cuda", tmp)
    base = runs["cpu×1"]
    print(f"machine: {base['machine']}")
    print(
        f"averaged: {N_T} temperatures × {N_W} rates = {n_avg} runs of {DURATION_S:.0f} s;"
        f" full: {FULL_MEMBERS} runs of {FULL_S} s at 5 kHz"
    )
    print(
        f"{'config':>8} {'averaged [s]':>13} {'runs/s':>9} {'speed-up':>9} {'max rel. Δ':>11}"
        f" {'full [s]':>9} {'sim s/s':>8} {'speed-up':>9} {'compile+1st [s]':>16}"
    )
    for name, r in runs.items():
        a, f = r["averaged"], r["full"]
        da, df = (
            float(abs(x["result"] - b["result"]).max() / abs(b["result"]).max())
            for x, b in ((a, base["averaged"]), (f, base["full"]))
        )
        print(
            f"{name:>8} {a['wall_s']:13.3f} {n_avg / a['wall_s']:9.0f} "
            f"{base['averaged']['wall_s'] / a['wall_s']:8.2f}× {max(da, df):11.1e} "
            f"{f['wall_s']:9.3f} {FULL_MEMBERS * FULL_S / f['wall_s']:8.3f} "
            f"{base['full']['wall_s'] / f['wall_s']:8.2f}× {a['first_s']:8.1f} / {f['first_s']:.1f}"
        )
        # CPU: equal up to rounding; GPU: another libm, adaptive steps, within the tolerances
        assert max(da, df) < (1e-12 if name.startswith("cpu") else 1e-6), (name, da, df)
    kind = runs["cpu×1"]["kind"]
    for n in (2, 4):
        r = runs[f"cpu×{n}"]
        report(
            f"averaged sweep ({n_avg} runs), {n} forced CPU devices",
            n_avg / r["averaged"]["wall_s"],
            "runs/s",
            f"speed-up vs 1 {kind} device",
            base["averaged"]["wall_s"] / r["averaged"]["wall_s"],
            f"≤ {os.cpu_count()}× (cores)",
        )
        report(
            f"full-model batch ({FULL_MEMBERS} runs), {n} forced CPU devices",
            FULL_MEMBERS * FULL_S / r["full"]["wall_s"],
            "simulated s per s",
            f"speed-up vs 1 {kind} device",
            base["full"]["wall_s"] / r["full"]["wall_s"],
        )
    order = base.get("ordering")
    if order:
        inner, outer = order["rate innermost"], order["rate outermost"]
        print(
            f"500-run grid in chunks of 50 (1 CPU device): rate innermost {inner:.2f} s, "
            f"rate outermost {outer:.2f} s ({inner / outer:.2f}× faster)"
        )
        report("chunked sweep, costly axis outermost", outer, "s", "innermost / outermost",
               inner / outer)  # fmt: skip
    if gpu:
        g = runs["gpu"]
        report(
            f"averaged sweep ({n_avg} runs) on {g['kind']}",
            n_avg / g["averaged"]["wall_s"],
            "runs/s",
            "speed-up vs 1 CPU device",
            base["averaged"]["wall_s"] / g["averaged"]["wall_s"],
        )
        report(
            f"full-model batch ({FULL_MEMBERS} runs) on {g['kind']}",
            FULL_MEMBERS * FULL_S / g["full"]["wall_s"],
            "simulated s per s",
            "speed-up vs 1 CPU device",
            base["full"]["wall_s"] / g["full"]["wall_s"],
        )


if __name__ == "__main__":
    from _common import child_or_main

    child_or_main(child, main)
