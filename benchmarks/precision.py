"""Precision of three computations an audit found losing digits, before and after, each
against an independent truth (tests/test_precision.py holds the quick checks):

1. the physical fit's covariance (`calibration.physical._covariance`): (JᵀJ)⁻¹ by inverting
   JᵀJ (before) and by the SVD of the column-scaled J (after), against the exact inverse of
   the same stored J in rational arithmetic, on synthetic J = U diag(s) Vᵀ D of condition
   1e6 … 1e12 (columns in units 2 decades apart);
2. `kalman.van_loan`: one exponential over the whole step (before, written out here) and
   sub-steps with doubling (after), against the closed-form Qd of an angle + first-order
   Gauss–Markov rate, dt/τ = 1 … 1e4; bit-identity on a slow F; the cost (compile, one call,
   `vmap` over 1000 steps of a 17-state model);
3. `discovery.stats.wls`: `lstsq` on unscaled columns (before) and scaled (after), β's
   distance from the truth it was drawn from in its σ, columns 1e6 … 1e14 apart.

Usage: `.venv/bin/python benchmarks/precision.py` (≈ 1 min on a loaded 2-core CPU).
"""

import time

import jax
import jax.numpy as jnp
import numpy as np
from _common import machine, report
from jax.scipy.linalg import expm

from hrgjax import kalman
from hrgjax.calibration import physical
from hrgjax.discovery import stats


def exact_inverse(jac: np.ndarray) -> np.ndarray:
    """(JᵀJ)⁻¹ of the float matrix `jac` in exact rational arithmetic, rounded at the end."""
    from fractions import Fraction

    exps = np.frexp(jac[jac != 0])[1]
    shift = int(exps.min()) - 53
    ints = np.array([[int(Fraction(float(x)) / Fraction(2) ** shift) for x in row] for row in jac],
                    dtype=object)  # fmt: skip
    m = [[Fraction(v) for v in row] for row in (ints.T @ ints)]
    p = len(m)
    inv = [[Fraction(int(i == j)) for j in range(p)] for i in range(p)]
    for c in range(p):  # Gauss–Jordan, exact
        piv = next(r for r in range(c, p) if m[r][c] != 0)
        m[c], m[piv], inv[c], inv[piv] = m[piv], m[c], inv[piv], inv[c]
        f = m[c][c]
        m[c] = [v / f for v in m[c]]
        inv[c] = [v / f for v in inv[c]]
        for r in range(p):
            if r != c and m[r][c] != 0:
                g = m[r][c]
                m[r] = [a - g * b for a, b in zip(m[r], m[c], strict=True)]
                inv[r] = [a - g * b for a, b in zip(inv[r], inv[c], strict=True)]
    return np.array([[float(v * Fraction(2) ** (-2 * shift)) for v in row] for row in inv])


def covariance_study():
    print("\n1. physical._covariance: σ / exact σ (rational (JᵀJ)⁻¹ of the same J)")
    p = len(physical.NAMES)
    rng = np.random.default_rng(0)
    u, _ = np.linalg.qr(rng.standard_normal((400, p)))
    v, _ = np.linalg.qr(rng.standard_normal((p, p)))
    d = 10.0 ** rng.uniform(-1, 1, p)
    scale = np.outer(physical.SCALE, physical.SCALE)
    for cond in (1e6, 1e7, 1e8, 1e9, 3e9, 1e10, 1e12):
        s = np.geomspace(1.0, 1.0 / cond, p)
        jac = ((u * s) @ v.T) * d
        truth = exact_inverse(jac)
        sig = np.sqrt(np.diag(truth))
        old = np.linalg.inv(jac.T @ jac)
        ratio_old = np.sqrt(np.abs(np.diag(old))) / sig
        negative = int(np.sum(np.diag(old) < 0))
        try:
            new = physical._covariance(jac, 1.0) / scale
            err = np.max(np.abs(np.sqrt(np.diag(new)) / sig - 1.0))
            cerr = np.max(np.abs(new - truth) / np.outer(sig, sig))
            after = f"after: max |σ/σ_exact − 1| {err:.1e}, |Δcov|/(σσ) ≤ {cerr:.1e}"
        except ValueError:
            after = "after: refused (SINGULAR_RCOND)"
            err = None
        cj = np.linalg.cond(jac)
        print(f"  cond(J) {cj:.1e}: before σ ratio {ratio_old.min():.3f}–{ratio_old.max():.3f}"
              f" ({negative} negative variances); {after}")  # fmt: skip
        if err is not None:
            report(f"covariance σ error at cond(J) {cj:.0e}", err, "relative")


def _gauss_markov(q, tau, T):
    f = np.array([[0.0, 1.0], [0.0, -1.0 / tau]])
    a, b = -np.expm1(-T / tau), -np.expm1(-2 * T / tau)
    qd = q * tau**2 * np.array([[T - 2 * tau * a + tau / 2 * b, a - b / 2],
                                [a - b / 2, b / (2 * tau)]])  # fmt: skip
    return f, np.diag([0.0, q]), qd


@jax.jit
def single_exponential(F, Q, dt):
    """`kalman.van_loan` before the sub-steps: Qd = Φ·(Φ⁻¹Qd) over the whole step."""
    n = F.shape[-1]
    e = expm(jnp.block([[-F, Q], [jnp.zeros_like(F), F.T]]) * dt)
    phi = e[n:, n:].T
    qd = phi @ e[:n, n:]
    return phi, 0.5 * (qd + qd.T)


def van_loan_study():
    print("\n2. kalman.van_loan: angle + Gauss–Markov rate (τ = 1 s), relative error of Qd")
    for ratio in (1.0, 10.0, 20.0, 30.0, 40.0, 60.0, 700.0, 1e4):
        f, q, exact = _gauss_markov(2.0, 1.0, ratio)
        before = np.asarray(single_exponential(f, q, ratio)[1])
        after = np.asarray(kalman.van_loan(f, q, ratio)[1])
        eb = np.max(np.abs(before - exact) / np.abs(exact))
        ea = np.max(np.abs(after - exact) / np.abs(exact))
        print(f"  dt/τ = {ratio:7g}: before {eb:.1e}, after {ea:.1e}")
        report(f"van_loan Qd error at dt/tau {ratio:g}", ea, "relative")
    rng = np.random.default_rng(1)
    same = 0
    for _ in range(20):
        f = 0.01 * rng.standard_normal((4, 4))
        lq = rng.standard_normal((4, 4))
        a = kalman.van_loan(f, lq @ lq.T, 7.3)
        b = single_exponential(f, lq @ lq.T, 7.3)
        same += all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    print(f"  slow F (‖F‖₁dt ≤ 1, no sub-steps): {same}/20 results bit-identical to before")
    report("van_loan slow-F results bit-identical", same / 20, "fraction")

    n = 17
    fq = (jnp.asarray(1e-2 * rng.standard_normal((n, n))), jnp.eye(n))
    batch = tuple(jnp.broadcast_to(x, (1000, n, n)) for x in fq) + (jnp.full(1000, 0.01),)
    for name, fn in (("before", single_exponential.__wrapped__), ("after", kalman._van_loan)):
        one = jax.jit(lambda F, Q, dt, fn=fn: fn(F, Q, dt))
        t0 = time.process_time()
        one = one.lower(*fq, 1.0).compile()
        compile_s = time.process_time() - t0
        calls = []
        for dt in (0.5, 40.0) * 10:
            t0 = time.perf_counter()
            jax.block_until_ready(one(*fq, dt))
            calls.append(time.perf_counter() - t0)
        many = jax.jit(jax.vmap(lambda F, Q, dt, fn=fn: fn(F, Q, dt))).lower(*batch).compile()
        runs = []
        for _ in range(5):
            t0 = time.process_time()
            jax.block_until_ready(many(*batch))
            runs.append(time.process_time() - t0)
        print(f"  {name}: {n} states: compile {compile_s:.2f} s CPU, call {min(calls) * 1e3:.3f}"
              f" ms; vmap × 1000 steps {min(runs) * 1e3:.0f} ms CPU")  # fmt: skip
        report(f"van_loan vmap x1000 17 states, {name}", min(runs), "s CPU")


def wls_study():
    print(
        "\n3. discovery.stats.wls: (β − β_true)/σ, third column 1e6 … 1e14 smaller, near-parallel"
    )
    rng = np.random.default_rng(0)
    n = 400
    t = np.linspace(-1, 1, n)
    for ratio in (1e6, 1e8, 1e10, 1e12, 1e14):
        g = np.stack([np.ones(n), t, (1 + 0.05 * t**2) / ratio], 1)
        truth = np.array([1e-6, 2e-7, 3e-7 * ratio])
        sigma = np.full(n, 1e-9)
        y = g @ truth + sigma * rng.standard_normal(n)
        beta, r, cov = stats.wls(g, y, sigma)
        err = np.sqrt(np.diag(cov))
        old = np.linalg.lstsq(g / sigma[:, None], y / sigma, rcond=None)[0]
        zb, za = np.abs(old - truth) / err, np.abs(beta - truth) / err
        print(f"  ratio {ratio:.0e}: before max |z| {zb.max():.2f}, after {za.max():.2f}")
        report(f"wls max |z| at column ratio {ratio:.0e}", za.max(), "σ")


def main() -> None:
    print(machine())
    covariance_study()
    van_loan_study()
    wls_study()


if __name__ == "__main__":
    main()
