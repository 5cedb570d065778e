"""Cost of the unit checks on concrete inputs (docs/ins.md, docs/data.md).

1. The Earth model's latitude check (`hrgjax.ins.constants.check_latitude_radians`, run by
   `gravity`, `radii`, `earth_rate_ned`, … on a concrete `lat`): an eager call of `gravity`
   with the check against the same compiled function without it (`gravity.__wrapped__`), in
   the same process, per kind of `lat` (a Python float, an np.float32, a 0-d JAX array, a
   JAX array of 10⁵ latitudes). Inside `jit` the check costs nothing (it is not traced).
2. The specific-force check of a loaded file (`hrgjax.plausible.check_specific_force` as
   `MeasuredData` runs it: unit rule and each column's middle half) on 10⁶ rows × 3 axes.

Each answer is checked before its timing counts. Usage:
`.venv/bin/python benchmarks/plausibility_cost.py`
"""

import timeit

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine, report  # noqa: E402

from hrgjax import plausible  # noqa: E402
from hrgjax.ins import constants as C  # noqa: E402


def per_call_us(fn, number, repeat=7):
    fn()
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number * 1e6


def main():
    print(machine())
    bare = C.gravity.__wrapped__  # the compiled function, no latitude check
    lats = {
        "a Python float": (0.5, 3000),
        "an np.float32": (np.float32(0.5), 3000),
        "a 0-d JAX array": (jnp.asarray(0.5), 3000),
        "10^5 latitudes (JAX array)": (jnp.linspace(-1.2, 1.2, 100_000), 100),
    }
    for what, (lat, number) in lats.items():
        np.testing.assert_array_equal(np.asarray(C.gravity(lat)), np.asarray(bare(lat)))
        checked = per_call_us(lambda lat=lat: jax.block_until_ready(C.gravity(lat)), number)
        plain = per_call_us(lambda lat=lat: jax.block_until_ready(bare(lat)), number)
        report(
            f"eager gravity(lat), lat {what}: with the latitude check",
            checked,
            "µs",
            f"without it {plain:.1f} µs; added",
            checked - plain,
        )
    try:
        C.gravity(45.0)
        raise AssertionError("gravity(45.0) was not refused")
    except ValueError:
        pass

    n = 1_000_000
    rng = np.random.default_rng(0)
    cols = [rng.normal(0.0, 0.1, n), rng.normal(0.0, 0.1, n), rng.normal(1.0, 0.1, n)]
    names = [f"column 'accel_{c}_g'" for c in "xyz"]

    def check(scale):
        accel = np.stack([scale * c for c in cols]).T  # as MeasuredData stacks its columns
        plausible.check_specific_force("columns", names, accel, samples=False)

    try:
        check(9.80665)  # the ride in m/s²
        raise AssertionError("a ride in m/s² was not refused")
    except ValueError as e:
        assert "as 1 g written in m/s²" in str(e)
    ms = per_call_us(lambda: check(1.0), 3) / 1e3
    report("check_specific_force, 10^6 rows x 3 axes (MeasuredData's call, a ride in g)", ms, "ms")


if __name__ == "__main__":
    main()
