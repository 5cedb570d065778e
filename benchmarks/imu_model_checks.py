"""Cost of `ImuModel`'s run-time checks (docs/ins.md; trace audit of 2ec03ab, F2).

`ImuModel.apply` holds a model's traced fields (inside `jit`, `vmap`, `hg.sweep`) to the
eager rules — finite, densities >= 0, the `imu_*` plausibility ranges — by one
`eqx.branched_error_if` (`hrgjax.ins.sensors.traced_checks`). This times, in one process,
the same programs with the checks and without them (`traced_checks` patched to return none
while the second is traced; the arithmetic is otherwise the same):

1. `hg.sweep` of a still IMU's measured rate over 64 gyro biases × 4 ARW levels (256 points,
   every field of the model traced), `N` = 2000 intervals each, and over 256 × 4 (1024);
2. one jitted `apply` of 2000 intervals (all fields traced), per call.

and counts the traces and compiles of three further sweeps with other values (the checks
must not make a value static). Each answer is checked before its timing counts.

Usage: `.venv/bin/python benchmarks/imu_model_checks.py`
"""

import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.monitoring  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, report  # noqa: E402

import hrgjax as hg  # noqa: E402
from hrgjax.ins import sensors  # noqa: E402

N, DT = 2000, 0.01
KEY = jax.random.key(0)
TH, DV = jnp.zeros((N, 3)), jnp.zeros((N, 3))
BIASES = jnp.linspace(-1e-4, 1e-4, 64)
BIG = jnp.linspace(-1e-4, 1e-4, 256)  # × 4 ARW levels: 1024 points
ARWS = jnp.array([1e-6, 1e-5, 1e-4, 1e-3])


def _rate(gyro_bias, arw):
    th, _ = sensors.ImuModel(gyro_bias=gyro_bias, arw=arw).apply(KEY, TH, DV, DT)
    return th[:, 0].sum() / (N * DT)


def checked(gyro_bias, arw):
    return _rate(gyro_bias, arw)


def plain(gyro_bias, arw):
    return _rate(gyro_bias, arw)


def _apply(kw):
    return sensors.ImuModel(**kw).apply(KEY, TH, DV, DT)[0]


EVENTS = {"traces": 0, "compiles": 0}


def _listen(event, duration, **kwargs):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        EVENTS["traces"] += 1
    elif event == "/jax/core/compile/backend_compile_duration":
        EVENTS["compiles"] += 1


def main():
    print(machine())
    jax.monitoring.register_event_duration_secs_listener(_listen)
    sweep = {f: (lambda f=f: hg.sweep(f, gyro_bias=BIASES, arw=ARWS)) for f in (checked, plain)}
    apply_checked, apply_plain = jax.jit(_apply), jax.jit(_apply)
    kw = {"gyro_bias": jnp.asarray(2e-5), "arw": jnp.asarray(1e-4), "gyro_scale": jnp.asarray(0.0)}
    a = sweep[checked]()
    b1 = apply_checked(kw)
    own = sensors.traced_checks
    sensors.traced_checks = lambda imu: []  # `plain` and `apply_plain` trace without checks
    try:
        b = sweep[plain]()
        b2 = apply_plain(kw)
    finally:
        sensors.traced_checks = own
    # a still IMU: the mean measured rate is the bias plus the white noise's mean
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(b1), np.asarray(b2))
    noise = np.asarray(a) - np.asarray(BIASES)[:, None]
    assert np.all(np.abs(noise) < 6 * np.asarray(ARWS) / np.sqrt(N * DT) + 1e-15)
    try:
        hg.sweep(checked, gyro_bias=jnp.array([1e-5, 10.0]), arw=ARWS)
        raise AssertionError("a gyro bias of 10 rad/s was not refused")
    except RuntimeError as e:
        assert "ImuModel.gyro_bias [rad/s] is outside the plausible range" in str(e)

    def timed(calls: dict, rounds: int) -> dict:
        """Wall times [s] of each call, alternated round by round and in turn first (a shared
        machine's load then hits both alike): {call: (min, median)}, and "paired": the
        median over rounds of (with − without)."""
        t = {name: [] for name in calls}
        for i in range(rounds):
            for name, fn in list(calls.items())[:: 1 if i % 2 else -1]:
                t0 = time.perf_counter()
                jax.block_until_ready(fn())
                t[name].append(time.perf_counter() - t0)
        out = {name: (min(v), float(np.median(v))) for name, v in t.items()}
        out["paired"] = float(np.median(np.subtract(t["with"], t["without"])))
        return out

    big = {f: (lambda f=f: hg.sweep(f, gyro_bias=BIG, arw=ARWS)) for f in (checked, plain)}
    sensors.traced_checks = lambda imu: []
    try:
        big[plain]()  # traced without checks (`checked`'s trace at this size has them)
    finally:
        sensors.traced_checks = own
    big[checked]()
    rows = (("hg.sweep of ImuModel.apply, 256 points x 2000 intervals", 1e3, "ms",
             {"with": sweep[checked], "without": sweep[plain]}, 200),
            ("hg.sweep of ImuModel.apply, 1024 points x 2000 intervals", 1e3, "ms",
             {"with": big[checked], "without": big[plain]}, 60),
            ("jitted ImuModel.apply, 2000 intervals", 1e6, "µs",
             {"with": lambda: apply_checked(kw), "without": lambda: apply_plain(kw)}, 300))  # fmt: skip
    for what, scale, unit, calls, rounds in rows:
        t = timed(calls, rounds)
        print(f"{what}: median {t['with'][1] * scale:.4g} {unit} with the checks, "
              f"{t['without'][1] * scale:.4g} without; minima {t['with'][0] * scale:.4g} / "
              f"{t['without'][0] * scale:.4g} {unit}; median of the paired differences "
              f"{t['paired'] * scale:+.3g} {unit}")  # fmt: skip
        report(f"{what}: with the checks (best of {rounds})", t["with"][0] * scale, unit,
               "with / without, best", t["with"][0] / t["without"][0], "≈ 1")  # fmt: skip

    grids = [(BIASES * s, ARWS * abs(s)) for s in (0.5, 2.0, -1.0)]  # made before counting
    before = dict(EVENTS)
    for biases, arws in grids:
        jax.block_until_ready(hg.sweep(checked, gyro_bias=biases, arw=arws))
    traces, compiles = (EVENTS[k] - before[k] for k in ("traces", "compiles"))
    report("traces + compiles of 3 further sweeps with other values (checks on)",
           traces + compiles, "", target="0")  # fmt: skip


if __name__ == "__main__":
    main()
