"""A batch of full-model runs through `hg.sweep`: 64 runs of 0.02 s (100 carrier cycles) at
rates 0.1–400 °/s on the default gyro (loops closed, laws on, noise off), adaptive Dopri8
(rtol 1e-8, `fixed_step=None`) vs the default call (`fixed_step="auto"`: the fixed-step
carrier path, the same accuracy) and the held-loop step (`fixed_step="held"`). A
vmapped adaptive solve steps every member until the slowest is done; fixed steps cost the
same for every member, and each step is a few fused kernels — the path issue 20 asks for on
a GPU as well. Prints both times, their ratio and the largest wave-angle difference.
"""

import jax.numpy as jnp
import numpy as np
from _common import best_of, first_call, machine, report

import hrgjax as hg

MEMBERS, SPAN = 64, 0.02


def main():
    gyro = hg.presets.tvg3_like(noise=False)
    rates = jnp.geomspace(0.1, 400.0, MEMBERS)
    ts = np.array([SPAN])  # concrete: the fixed-step path counts its steps from it

    def final_angle(rate_dps, path):
        prof = hg.Profile.constant_rate(rate_dps, SPAN, wave_angle0_deg=10.0)
        return hg.simulate(gyro, prof, "full", ts=ts, fixed_step=path).wave_angle[-1]

    runs = {
        name: lambda path=path: hg.sweep(
            lambda rate_dps: final_angle(rate_dps, path), rate_dps=rates
        )
        for name, path in (("adaptive", None), ("fixed", "auto"), ("held", "held"))
    }
    out = {}
    for name, fn in runs.items():
        c, value = first_call(fn)
        out[name] = (c, best_of(fn, 3), np.asarray(value))
    d = np.max(np.abs(out["fixed"][2] - out["adaptive"][2]))
    d_held = np.max(np.abs(out["held"][2] - out["adaptive"][2]))
    print(f"machine: {machine()}")
    print(f"{MEMBERS} full-model runs of {SPAN} s (rates 0.1–400 °/s, loops closed), hg.sweep")
    for name, (c, t, _) in out.items():
        print(f"  {name:8s}: {t * 1e3:8.1f} ms after compile (compile + first {c:.1f} s)")
    ratio = out["adaptive"][1] / out["fixed"][1]
    print(f"  default (fixed-step) call {ratio:.1f}× faster; max |Δθ| between them {d:.1e} rad")
    held = out["adaptive"][1] / out["held"][1]
    print(f"  held loops {held:.1f}× faster than adaptive; max |Δθ| to adaptive {d_held:.1e} rad")
    report(
        f"full model, {MEMBERS} × {SPAN} s batch, default call (fixed steps)",
        out["fixed"][1] * 1e3,
        "ms",
        "adaptive / fixed",
        ratio,
        "",
    )


if __name__ == "__main__":
    main()
