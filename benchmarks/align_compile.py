"""Stationary alignment of records of different lengths in one process: what each first call
compiles (`hrgjax.ins.alignment.align`, the fine filter padded to a power-of-two bucket of
steps). Before the padding every length compiled its own scan (7–9.5 s each); now a length
in a bucket already compiled compiles nothing.

Aligns the first N samples of the PSINS log (`tests/data/psins_lasergyro.imu`, 100 Hz) for
each N given (default 180 000, 170 000, 160 000: three lengths, one bucket of 2 048 steps),
then the first N again (warm: the run time alone), and prints per call the wall time, the
XLA compiles and their compile time (no persistent cache unless one is configured).

Usage: `.venv/bin/python benchmarks/align_compile.py [N ...]`; for the tree before a change,
`PYTHONPATH=<an archived hrgjax> .venv/bin/python benchmarks/align_compile.py`.
"""

import sys
import time
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.monitoring
from _common import machine, report

from hrgjax.ins import alignment as al

PSINS = Path(__file__).resolve().parents[1] / "tests" / "data" / "psins_lasergyro.imu"
_compiles: list[float] = []


def _listen(event, duration, **kwargs):
    if event == "/jax/core/compile/backend_compile_duration":
        _compiles.append(duration)


def _align(log, n):
    cut = eqx.tree_at(lambda g: (g.t, g.dtheta, g.dvel), log, (log.t[:n], log.dtheta[:n],
                                                                log.dvel[:n]))  # fmt: skip
    _compiles.clear()
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", al.AlignmentWarning)  # the log's sway note
        result = al.align(cut)
    return time.perf_counter() - t0, len(_compiles), sum(_compiles), result


def main():
    jax.monitoring.register_event_duration_secs_listener(_listen)
    lengths = [int(x) for x in sys.argv[1:]] or [180_000, 170_000, 160_000]
    print(machine(), "|", al.__file__)
    log = al.load_psins(PSINS)
    for i, n in enumerate([*lengths, lengths[0]]):
        wall, count, secs, r = _align(log, n)
        tag = "warm" if i == len(lengths) else "first"
        print(f"N = {n:7d} ({tag}): {wall:6.2f} s, {count:2d} compiles ({secs:5.2f} s), "
              f"heading {r.heading_deg:.12f}°")  # fmt: skip
        if 0 < i < len(lengths):
            report(f"align, a new length N = {n} (first call)", wall, "s")


if __name__ == "__main__":
    main()
