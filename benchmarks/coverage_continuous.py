"""Do continuous-record discovery's error bars and consistency p-values hold? Monte Carlo with
known truth (audit 2026-11-30, F3 and F4).

The design of the tests' fast tier (`tests/helpers.SHORT_RAMPS`): six 1500-s records at 2 s
(three static, three turning at 2 °/s; temperature ramps of 200–600 s), each its own
switch-on (σ_b 0.2 °/h), a thermal rate of 0.15 °/h per °C/min hidden, searched with the
catalogue `["thermal_rate"]`. For every seed: z = (value − truth)/σ of the angular gain k_e
(pinned by the turning runs' mean rate against the static ones': its σ ∝ σ_b, which REML
reads from six run means, ≈ 4 degrees of freedom) and of c_Tdot (pinned inside the runs),
with the σ `discover` reports and with the textbook σ (σ̂_b plugged in as known,
`std_textbook`: without `honest`'s residual-level correction, so not the σ reported before
31987e6 — k_e z-RMS 1.42 here against the recorded before 1.34); and the per-run consistency's p-value, which under a true, exactly
catalogued effect should be uniform.

Usage: `.venv/bin/python benchmarks/coverage_continuous.py [--n 100] [--seed0 200]`
(≈ 4 s a seed once compiled; 2-core machine).

**Two laws, one of them not the catalogue's form** (`--laws [--n 12] [--seed0 100]`):
`continuous_dataset` (six 3100-s ramps, 600-s holds) with a bias law of 0.02 °/h/°C and a
damping law Δ(1/τ)(T) = Δ₂₀e^{λΔT}, λ = −0.01 /°C, hidden — the catalogue's damping term
is linear in ΔT, so its ΔT² part (2θ·ΔT², a few % of it) is structure the model lacks —
searched with the catalogue `["bias_temperature", "damping_anisotropy_temperature"]`. z of
b₁ (truth 0.02) and b₂ (truth 0) with the σ `discover` reports and with the σ of the rule
before 2026-12-03 (leftover shapes fitted beside only at Bonferroni p < 10⁻³; here the
same fits' `trust.honest(…, alpha_sigma=1e-3)`), side by side.
**Other hidden effects and the null** (`--effect bias_temperature|warmup_transient|none
[--n 40] [--seed0 300]`; audit contcov, 2026-12-03): the fast tier's design
(`tests/test_discovery_continuous._short`: thermal rate, readout gain mismatch and bias law
injected at 0 beside the one hidden), a bias law of 0.005 °/h/°C (b₁; b₂ truth 0) or a
warm-up of 0.5 °/h with τ_w = 600 s hidden, searched with the catalogue of that one effect;
`none` hides nothing and searches `NULL_CATALOGUE` (how often a false effect is named). Per
parameter: z with the reported σ and the textbook σ, and how often the effect is found;
for the warm-up also the scanned τ_w (no σ: held where the scan put it).
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
from _common import machine, report  # noqa: E402

from hrgjax.discovery import discover  # noqa: E402
from hrgjax.discovery.generate import base_gyro, continuous_dataset  # noqa: E402

SHORT_RAMPS = (  # tests/helpers.py
    (-20.0, 40.0, 600.0, 0.0, 0.0),
    (40.0, -20.0, 600.0, 2.0, 0.0),
    (-20.0, 40.0, 200.0, 0.0, 45.0),
    (40.0, -20.0, 200.0, 2.0, 30.0),
    (0.0, 60.0, 400.0, 0.0, -30.0),
    (60.0, 0.0, 400.0, 2.0, 60.0),
)
SIZE = 0.15  # °/h per °C/min


def _row(name, z):
    z = np.asarray(z)
    one, two = np.mean(np.abs(z) < 1) * 100, np.mean(np.abs(z) < 2) * 100
    rms = float(np.sqrt(np.mean(z**2)))
    worst = z[np.argmax(np.abs(z))]
    print(f"| {name} | {one:.0f} % | {two:.0f} % | {rms:.2f} | {worst:+.2f} |")
    return rms


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="seeds")
    ap.add_argument("--seed0", type=int, default=200, help="first seed (the audit's: 200)")
    args = ap.parse_args()
    k_true = float(base_gyro(noise=False).k_e)
    z = {k: [] for k in ("k_e", "k_e textbook", "c_Tdot", "c_Tdot textbook")}
    p, dof, missed = [], [], 0
    t0 = time.time()
    for seed in range(args.seed0, args.seed0 + args.n):
        data = continuous_dataset("thermal_rate", SIZE, key=jax.random.key(seed),
                                  duration_s=1500.0, dt_out=2.0, ramps=SHORT_RAMPS)  # fmt: skip
        rep = discover(data, catalogue=["thermal_rate"])
        if "thermal_rate" not in rep.parameters:
            missed += 1
            continue
        for key, effect, param, truth in (("k_e", "angular_gain", "k_e", k_true),
                                          ("c_Tdot", "thermal_rate", "c_Tdot", SIZE)):  # fmt: skip
            v = rep.parameters[effect][param]
            raw = rep.fit_parameters[effect][param]
            z[key].append((v["value"] - truth) / v["sigma"])
            # the textbook σ in user units: the reported one scaled by textbook / corrected
            z[key + " textbook"].append(z[key][-1] * raw["std"] / raw["std_textbook"])
        p.append(rep.consistency["thermal_rate"]["p_value"])
        dof.append(rep.uncertainty["run_bias"]["dof"])
    print(f"{machine()}; {args.n} seeds from {args.seed0} in {time.time() - t0:.0f} s "
          f"({missed} without the thermal rate found)")  # fmt: skip
    print("\n| parameter, σ | ±1σ | ±2σ | z-RMS | worst z |\n|---|---|---|---|---|")
    rms = {k: _row(k, v) for k, v in z.items()}
    p = np.asarray([q for q in p if q is not None], float)
    print(f"\nconsistency p: n = {p.size}, < 0.01: {np.mean(p < 0.01) * 100:.0f} %, "
          f"< 0.05: {np.mean(p < 0.05) * 100:.0f} %, < 0.5: {np.mean(p < 0.5) * 100:.0f} %; "
          f"σ_b's degrees of freedom {np.median(dof):.2f} (median)")  # fmt: skip
    report("continuous k_e z-RMS (reported σ)", rms["k_e"], "", target="0.85–1.15")
    report("continuous c_Tdot z-RMS (reported σ)", rms["c_Tdot"], "", target="0.85–1.15")
    report("continuous consistency p < 0.01", np.mean(p < 0.01) * 100, "%", target="≈ 1 %")


LAWS = {"bias_temperature": 0.02, "damping_anisotropy_temperature": -0.01}


def laws(n: int, seed0: int):
    """`--laws` (module docstring): b₁ and b₂'s z under the reported σ and the old rule's."""
    from hrgjax.discovery import search, trust

    honest, before = trust.honest, []

    def both(*args, **kwargs):  # the same fit under the rule before, kept aside
        before.append(honest(*args, **kwargs, alpha_sigma=kwargs.get("alpha", 1e-3))[0])
        return honest(*args, **kwargs)

    z = {k: [] for k in ("b1", "b1 before", "b2", "b2 before")}
    t0 = time.time()
    search.trust.honest = both
    try:
        for seed in range(seed0, seed0 + n):
            data = continuous_dataset(LAWS, key=jax.random.key(seed), duration_s=3100)
            rep = discover(data, catalogue=list(LAWS))
            if "bias_temperature" not in rep.parameters:
                print(f"seed {seed}: bias law not named ({rep.verdict})")
                continue
            old = before[-1]["bias_temperature"]
            for name, truth in (("b1", LAWS["bias_temperature"]), ("b2", 0.0)):
                v = rep.parameters["bias_temperature"][name]
                z[name].append((v["value"] - truth) / v["sigma"])
                raw = rep.fit_parameters["bias_temperature"][name]["std"]  # the same units
                z[name + " before"].append(z[name][-1] * raw / old[name]["std"])
            print(f"seed {seed}: b1 z {z['b1'][-1]:+.2f} (before {z['b1 before'][-1]:+.2f}), "
                  f"shapes {rep.uncertainty['shapes']} suggested "
                  f"{rep.uncertainty.get('suggested')}", flush=True)  # fmt: skip
    finally:
        search.trust.honest = honest
    print(f"{machine()}; {n} seeds from {seed0} in {time.time() - t0:.0f} s")
    print("\n| parameter, σ | ±1σ | ±2σ | z-RMS | worst z |\n|---|---|---|---|---|")
    rms = {k: _row(k, v) for k, v in z.items()}
    report("two laws: b1 z-RMS (reported σ)", rms["b1"], "", "before", rms["b1 before"],
           target="0.85–1.15")  # fmt: skip


EFFECTS = {  # effect: (size, {parameter: truth in user units})
    "bias_temperature": (0.005, {"b1": 0.005, "b2": 0.0}),
    "warmup_transient": (0.5, {"b_w": 0.5}),
}
NULL_CATALOGUE = ["thermal_rate", "bias_temperature", "warmup_transient"]
_ZEROED = ("thermal_rate", "readout_gain_mismatch", "bias_temperature")  # the tests' _short


def effect_case(effect: str, n: int, seed0: int):
    """`--effect` (module docstring): z of the found effect's parameters, or the null's
    false findings."""
    size, truths = EFFECTS.get(effect, (0.0, {}))
    hidden = dict.fromkeys(_ZEROED, 0.0) | ({} if effect == "none" else {effect: size})
    catalogue = NULL_CATALOGUE if effect == "none" else [effect]
    z = {k: [] for p in truths for k in (p, p + " textbook")}
    found, named, taus = 0, [], []
    t0 = time.time()
    for seed in range(seed0, seed0 + n):
        data = continuous_dataset(hidden, key=jax.random.key(seed), duration_s=1500.0,
                                  dt_out=2.0, ramps=SHORT_RAMPS)  # fmt: skip
        rep = discover(data, catalogue=catalogue, shape="continuous")
        named += [rep.verdict] if effect == "none" and rep.verdict != "none" else []
        if effect == "none" or effect not in rep.parameters:
            continue
        found += 1
        taus += [rep.parameters[effect].get("tau_w", {}).get("value")]
        for param, truth in truths.items():
            v, raw = rep.parameters[effect][param], rep.fit_parameters[effect][param]
            z[param].append((v["value"] - truth) / v["sigma"])
            z[param + " textbook"].append(z[param][-1] * raw["std"] / raw["std_textbook"])
    print(f"{machine()}; {effect}, {n} seeds from {seed0} in {time.time() - t0:.0f} s")
    if effect == "none":
        print(f"a verdict other than none on {len(named)} of {n} logs: {named}")
        report("continuous null: false verdicts", len(named) / n * 100, "%", target="≤ 5 %")
        return
    print(f"found in {found} of {n}")
    if taus and taus[0] is not None:
        print(
            f"tau_w (truth 600 s): median {np.median(taus):.0f} s, {min(taus):.0f}–{max(taus):.0f}"
        )
    print("\n| parameter, σ | ±1σ | ±2σ | z-RMS | worst z |\n|---|---|---|---|---|")
    for k, v in z.items():
        if v:
            _row(k, v)
    print("mean z: " + ", ".join(f"{k} {np.mean(v):+.2f}" for k, v in z.items()))


if __name__ == "__main__":
    import sys

    if "--laws" in sys.argv:
        ap = argparse.ArgumentParser()
        ap.add_argument("--laws", action="store_true")
        ap.add_argument("--n", type=int, default=12)
        ap.add_argument("--seed0", type=int, default=100)
        a = ap.parse_args()
        laws(a.n, a.seed0)
    elif "--effect" in sys.argv:
        ap = argparse.ArgumentParser()
        ap.add_argument("--effect", choices=[*EFFECTS, "none"], required=True)
        ap.add_argument("--n", type=int, default=40)
        ap.add_argument("--seed0", type=int, default=300)
        a = ap.parse_args()
        effect_case(a.effect, a.n, a.seed0)
    else:
        main()
