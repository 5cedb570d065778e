"""INS alignment: one compiled fine filter per power-of-two bucket of steps
(hrgjax/ins/fine_alignment.py). A log of another length in the bucket compiles nothing (each
length compiled its own 7–9.5-s scan), and the padded filter gives the unpadded numbers; the
streamed PSINS loader reads what the whole-text one read."""

import warnings
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import CompileCounter

from hrgjax.ins import alignment as al
from hrgjax.ins import trajectory as tr

DEG = np.pi / 180
PSINS = Path(__file__).resolve().parent / "data" / "psins_lasergyro.imu"  # BSD-2, see data/

# align's (heading, pitch, roll) [°], their σ [°] and biases (gyro [rad/s], accel [m/s²]) by
# the unpadded filter (28b967a: one scan of exactly K steps; XLA's default flags)
UNPADDED = {
    "psins 170 000": (
        [90.55001889421176, 0.9901373269953803, 0.38251178399417324,
         0.2409723257697149, 0.005912049500775248, 0.005911808136016316],
        [9.242875548803994e-10, 4.0301389146296447e-08, -3.124519913903199e-08,
         -5.768857916638857e-07, -5.9327167709887395e-06, 3.00122015316223e-05],
    ),
    "simulated 1500 s": (
        [199.8086318937153, 1.0001275914974581, -1.998337183145563,
         0.2832563931510659, 0.005904842865404502, 0.005906348598942633],
        [4.5596891396001875e-08, -1.5770201957550077e-08, -1.6134526240585908e-08,
         -1.4179349667156355e-05, -1.5512482420738343e-05, 0.0005007123407142902],
    ),
}  # fmt: skip


def _cut(log, n):
    return eqx.tree_at(lambda g: (g.t, g.dtheta, g.dvel), log,
                       (log.t[:n], log.dtheta[:n], log.dvel[:n]))  # fmt: skip


def _simulated():
    """A stationary 1-Hz log at 45° with constant biases and white noise (seed 7)."""
    rng = np.random.default_rng(7)
    traj = tr.stationary(45.0, heading_deg=200.0, pitch_deg=1.0, roll_deg=-2.0,
                         duration_s=1500.0, dt=1.0)  # fmt: skip
    f_b, w_b = traj.imu()
    size = len(traj.t) - 1
    dth = (np.asarray(w_b[1:]) + np.array([0.02, -0.03, 0.04]) * DEG / 3600
           + 0.01 * DEG / 60 * rng.standard_normal((size, 3)))  # fmt: skip
    dv = np.asarray(f_b[1:]) + np.array([3e-4, -2e-4, 5e-4]) + 1e-4 * rng.standard_normal((size, 3))
    return al.ImuLog(traj.t[1:], jnp.asarray(dth), jnp.asarray(dv), 45.0 * DEG)


def _assert_unpadded(r, key):
    """Bit for bit under the same XLA flags; the tests' quick flags (conftest.py) move the
    round-off: 1e-13 relative in the attitude, 4e-9 in the biases the data barely observe
    (level accelerometer: 1e-13 m/s²)."""
    attitude, biases = UNPADDED[key]
    got = [r.heading_deg, r.pitch_deg, r.roll_deg, r.heading_std_deg, r.pitch_std_deg,
           r.roll_std_deg]  # fmt: skip
    np.testing.assert_allclose(got, attitude, rtol=1e-11, err_msg=key)
    np.testing.assert_allclose(np.asarray(r.biases), biases, rtol=1e-7, err_msg=key)


def test_another_length_in_the_bucket_compiles_nothing_and_pads_to_the_unpadded_numbers():
    log = al.load_psins(PSINS)
    shorter = _cut(log, 160_000)  # 1 540 steps (eager slicing compiles: not align's)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", al.AlignmentWarning)  # the log's sway note
        first = al.align(_cut(log, 170_000))  # 1 640 steps: the bucket of 2 048
        with CompileCounter() as c:
            second = al.align(shorter)
    assert c.compiles == 0, c.names  # was 16 programs (4.5–7 s) for each new length
    _assert_unpadded(first, "psins 170 000")
    k = second.t.shape[0]
    assert k == 1540 and first.t.shape[0] == 1640
    # the filter is causal: the shorter record's steps are the longer one's first steps
    np.testing.assert_array_equal(np.asarray(second.history_deg), np.asarray(first.history_deg)[:k])
    np.testing.assert_array_equal(np.asarray(second.innovations), np.asarray(first.innovations)[:k])
    # another rate and step (1 Hz, 1 sample a step): the scan is shared, only sums compile
    simulated = _simulated()
    with CompileCounter() as c:
        sim = al.align(simulated)  # 1 440 steps
    assert not [n for n in c.names if "_fine" in str(n)], c.names
    _assert_unpadded(sim, "simulated 1500 s")
    t, c_bn, p, biases = al.fine_align(simulated, sim.c_bn, start_s=60.0)
    assert t.shape == (1440,) and c_bn.shape == (1440, 3, 3) and p.shape == (1440, 12, 12)
    np.testing.assert_array_equal(np.asarray(t), np.asarray(sim.t))


def test_streamed_psins_loader_skips_comments_and_blank_lines_among_samples(tmp_path):
    head = ["% a comment", "0 0 -90.6 0 0 0", "34 108.9 380 0 10 9.78", "1 1 1 1 1 1"]
    rows = [" ".join(str(7 * i + j) for j in range(6)) for i in range(5)]
    plain, noted = tmp_path / "plain.imu", tmp_path / "noted.imu"
    plain.write_text("\n".join([*head, *rows]) + "\n")
    noted.write_text("\r\n".join([*head, rows[0], "", "% mid", *rows[1:3], "# hash",
                                  *rows[3:]]))  # fmt: skip
    a, b = al.load_psins(plain), al.load_psins(noted)
    assert a.t.shape == (5,) and a.header_attitude_deg == (0.0, 0.0, 90.6)
    for name in ("t", "dtheta", "dvel"):
        np.testing.assert_array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)))
    assert float(a.dtheta[1, 1]) == pytest.approx(7 * np.pi / 180 / 3600)  # right → y (FRD)


def test_fine_align_stays_differentiable_and_vmappable():
    """Review of f38354b: padding on the host made `fine_align` refuse traced inputs
    (TracerArrayConversionError under grad, vmap, jit). Traced, it pads in JAX (one path for
    all three): the heading σ's derivative in the assumed ARW equals a central difference."""
    import jax

    log = _simulated()  # its coarse/fine programs shared with the test above
    c0 = al.align(log, coarse_s=60.0).c_bn

    def heading_std(arw):
        _, _, p, _ = al.fine_align(log, c0, start_s=60.0, arw=arw)
        return jnp.sqrt(p[-1, 5, 5])

    arw, h = 3e-5, 1e-7
    fd = (heading_std(arw + h) - heading_std(arw - h)) / (2 * h)
    np.testing.assert_allclose(jax.grad(heading_std)(arw), fd, rtol=1e-5)
