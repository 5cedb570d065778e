"""The argument checks of `hrgjax.kalman`: shapes always (trace time, so under `jit` and
`vmap` too), values on the host when they are concrete. Each refusal is one line naming the
argument and its expected form."""

import equinox as eqx
import jax
import numpy as np

from ._checks import (
    check_covariance,
    check_finite_host,
    concrete_value,
    describe,
    host_value,
    whole_number,
)
from ._riccati import reached_states


def check_measurements(zs, mask):
    """Refuse a concrete NaN or inf in `zs` (K, m) at a step that has a measurement (`mask`
    True, or no mask): a missing measurement is a step with mask=False."""
    z = host_value(zs)
    if z is None:
        return
    if mask is None:
        on = np.ones(z.shape[0], bool)
    else:
        mv = concrete_value(mask)
        if mv is None:  # traced mask: which steps count is not known here
            return
        on = np.broadcast_to(np.asarray(mv, bool), z.shape[:1])
    bad = ~np.isfinite(z).reshape(z.shape[0], -1).all(axis=1) & on
    if bad.any():
        k = int(np.argmax(bad))
        value = z[k][~np.isfinite(z[k])].ravel()[0]
        text = "NaN" if np.isnan(value) else str(value)
        raise ValueError(f"zs has {text} at step {k}: mark a missing measurement with mask=False")


def stack_shape_ok(shape, n, k) -> bool:
    """`shape` is (n, n) or a per-step (K, n, n) (or (1, n, n), broadcast)."""
    return len(shape) in (2, 3) and tuple(shape[-2:]) == (n, n) and shape[:-2] in ((), (1,), (k,))


def check_prior(prior, name: str = "prior") -> int:
    """The state count n of a Gaussian `prior` with x (n,) and P (n, n), or one line."""
    x_shape, p_shape = np.shape(prior.x), np.shape(prior.P)
    if len(x_shape) != 1:
        raise ValueError(f"{name}.x must be a (n,) mean; got shape {x_shape}")
    n = x_shape[0]
    if p_shape != (n, n):
        raise ValueError(f"{name}.P must be (n, n) = ({n}, {n}) (n = len({name}.x)); got {p_shape}")
    return n


def check_steps(zs, m, R, qd, n, mask, what: str = "rows of H") -> int:
    """The step count K of `zs` (K, m) (at least one), with `R` (m, m), `qd` (n, n) or
    (K, n, n) and `mask` (K,) checked against it; `m` None: taken from `zs`."""
    z_shape = np.shape(zs)
    if len(z_shape) != 2 or (m is not None and z_shape[1] != m):
        hint = " (transposed? one row per step)" if len(z_shape) == 2 and z_shape[0] == m else ""
        form = (
            f"(K, {m}) (one row per step, m = {what})" if m is not None else "2-D, one row per step"
        )
        raise ValueError(f"zs must be (K, m) = {form}; got {z_shape}{hint}")
    k, m = z_shape
    if k == 0:
        raise ValueError(f"zs must have at least one step (K >= 1); got shape (0, {m})")
    if not stack_shape_ok(np.shape(qd), n, k):
        raise ValueError(f"qd must be (n, n) = ({n}, {n}) or per step (K, n, n) = "
                         f"({k}, {n}, {n}); got {np.shape(qd)}")  # fmt: skip
    if np.shape(R) != (m, m):
        raise ValueError(f"R must be (m, m) = ({m}, {m}) (m = {what}); got {np.shape(R)}")
    if mask is not None and np.shape(mask) != (k,):
        raise ValueError(f"mask must be (K,) = ({k},) booleans (False: no measurement at that "
                         f"step); got {np.shape(mask)}")  # fmt: skip
    return k


def check_values(prior, qd, R, zs, mask, us, n, m, **finite):
    """The concrete values: prior finite and PSD, `qd` PSD, `R` positive-definite, `us` and
    each of `finite` ({name: array}) finite, `zs` finite where a step has a measurement."""
    check_finite_host("prior.x", prior.x)
    check_covariance("prior.P", prior.P, form=f"(n, n) = ({n}, {n})")
    for name, a in finite.items():
        check_finite_host(name, a)
    check_covariance("qd", qd, form=f"(n, n) = ({n}, {n})")
    check_covariance("R", R, definite=True, form=f"(m, m) = ({m}, {m})")
    if us is not None:
        check_finite_host("us", us)
    check_measurements(zs, mask)


def check_linear(prior, phi, qd, H, R, zs, mask, us):
    """The arguments of `kalman_filter` / `rts_smoother`."""
    n = check_prior(prior)
    h_shape = np.shape(H)
    if len(h_shape) != 2 or h_shape[1] != n:
        raise ValueError(f"H must be (m, n) = (m, {n}) (n = len(prior.x)); got {h_shape}")
    m = h_shape[0]
    k = check_steps(zs, m, R, qd, n, mask)
    if not stack_shape_ok(np.shape(phi), n, k):
        raise ValueError(f"phi must be (n, n) = ({n}, {n}) or per step (K, n, n) = "
                         f"({k}, {n}, {n}); got {np.shape(phi)}")  # fmt: skip
    if us is not None:
        try:
            fits = np.broadcast_shapes(np.shape(us), (k, n)) == (k, n)
        except ValueError:
            fits = False
        if not fits:
            raise ValueError(f"us must be (K, n) = ({k}, {n}) (or (n,), the same every step); "
                             f"got {np.shape(us)}")  # fmt: skip
    check_values(prior, qd, R, zs, mask, us, n, m, phi=phi, H=H)


def check_model(f, h):
    """The model functions of the EKF/UKF: callables (one line naming the one that is not)."""
    for name, fn, form in (("f", f, "f(x, u) -> x"), ("h", h, "h(x) -> z")):
        if not callable(fn):
            raise ValueError(f"{name} must be a function {form}; got {type(fn).__name__}")


def check_nonlinear(prior, f, qd, h, R, zs, mask, us):
    """The arguments of the EKF / UKF: `check_linear`'s, the model functions' output shapes
    (by `jax.eval_shape`: nothing is computed) against `prior.x` and `zs`."""
    check_model(f, h)
    n = check_prior(prior)
    k = check_steps(zs, None, R, qd, n, mask, what="columns of zs")
    m = np.shape(zs)[1]
    if us is not None and (len(np.shape(us)) != 2 or np.shape(us)[0] != k):
        raise ValueError(f"us must be (K, p) = ({k}, p) (one row of inputs per step, passed to "
                         f"f); got {np.shape(us)}")  # fmt: skip
    dtype = getattr(prior.x, "dtype", None)
    if dtype is None or not np.issubdtype(dtype, np.floating):
        dtype = jax.dtypes.canonicalize_dtype(np.float64)
    x = jax.ShapeDtypeStruct((n,), dtype)
    u = jax.ShapeDtypeStruct((0,) if us is None else np.shape(us)[1:], x.dtype)
    for name, fn, args, want in (("f(x, u)", f, (x, u), (n,)), ("h(x)", h, (x,), (m,))):
        got = getattr(jax.eval_shape(fn, *args), "shape", None)
        if got != want:
            of = "n = len(prior.x)" if want == (n,) else "m = columns of zs"
            raise ValueError(f"{name} must return shape {want} ({of}); got {got}")
    check_values(prior, qd, R, zs, mask, us, n, m)


def check_unscented(n: int, alpha, beta, kappa):
    """Concrete `alpha` > 0, `beta` finite and `kappa` > −n (λ + n = α²(n + κ) > 0: the
    sigma points' spread and weights), or one line; traced values pass."""
    values = [host_value(v) for v in (alpha, beta, kappa)]
    for name, v in zip(("alpha", "beta", "kappa"), values, strict=True):
        if v is not None and (v.shape != () or not np.isfinite(v)):
            raise ValueError(f"{name} must be one finite number; got {describe(v)}")
    a, _, kap = values
    if a is not None and not a > 0:
        raise ValueError(f"alpha must be > 0 (the sigma points' spread); got {float(a)}")
    if kap is not None and not n + kap > 0:
        raise ValueError(f"kappa must be > -n = {-n} (n + λ = α²(n + κ) > 0); got {float(kap)}")


def check_update(g, z, H, R, mask):
    """`update`'s arguments: shapes always (trace time), values when concrete."""
    x_shape, p_shape, h_shape = np.shape(g.x), np.shape(g.P), np.shape(H)
    if len(x_shape) != 1 or p_shape != x_shape * 2:
        raise ValueError(f"g must be a Gaussian with x (n,) and P (n, n); got x {x_shape}, "
                         f"P {p_shape}")  # fmt: skip
    n = x_shape[0]
    if len(h_shape) != 2 or h_shape[1] != n:
        raise ValueError(f"H must be (m, n) = (m, {n}) (n = len(g.x)); got {h_shape}")
    m = h_shape[0]
    if np.shape(z) != (m,):
        raise ValueError(f"z must be (m,) = ({m},) (m = rows of H); got {np.shape(z)}")
    if np.shape(R) != (m, m):
        raise ValueError(f"R must be (m, m) = ({m}, {m}) (m = rows of H); got {np.shape(R)}")
    if np.shape(mask) != ():
        raise ValueError(f"mask must be one boolean (False: no measurement); got shape "
                         f"{np.shape(mask)}")  # fmt: skip
    check_covariance("g.P", g.P, form=f"(n, n) = ({n}, {n})")
    check_finite_host("H", H)
    check_covariance("R", R, definite=True, form=f"(m, m) = ({m}, {m})")
    zv, on = host_value(z), concrete_value(mask)
    if zv is not None and on is not None and np.any(on) and not np.isfinite(zv).all():
        raise ValueError(f"z must be finite where mask is True (a missing measurement is "
                         f"mask=False); got {zv.tolist()}")  # fmt: skip


def check_predict(g, phi, qd, u):
    """`predict`'s arguments: shapes always, `phi` finite and `qd` PSD when concrete. `phi`
    is (m, n): it may map the state to a new size m; `qd` is (m, m), `u` (m,) or a scalar
    (anything that broadcasts to (m,))."""
    n = check_prior(g, "g")
    shape = np.shape(phi)
    if len(shape) != 2 or shape[1] != n:
        raise ValueError(f"phi must be (m, n) = (m, {n}) (n = len(g.x)); got {shape}")
    m = shape[0]
    if np.shape(qd) != (m, m):
        raise ValueError(f"qd must be (m, m) = ({m}, {m}) (m = rows of phi); got "
                         f"{np.shape(qd)}")  # fmt: skip
    if u is not None:
        try:
            fits = np.broadcast_shapes(np.shape(u), (m,)) == (m,)
        except ValueError:
            fits = False
        if not fits:
            raise ValueError(f"u must be (m,) = ({m},) (m = rows of phi) or a scalar; got "
                             f"{np.shape(u)}")  # fmt: skip
    check_finite_host("phi", phi)
    check_covariance("qd", qd, form=f"(m, m) = ({m}, {m})")


def square(name: str, a, n=None, what: str = "") -> int:
    """The size n of a square (n, n) `a` (of `n` when given), or one line naming `name`."""
    shape = np.shape(a)
    if len(shape) != 2 or shape[0] != shape[1] or (n is not None and shape[0] != n):
        form = "(n, n)" if n is None else f"(n, n) = ({n}, {n}){what}"
        raise ValueError(f"{name} must be a square {form} matrix; got shape {shape}")
    return shape[0]


def check_dt(name: str, dt):
    """Refuse a host `dt` that is not one finite real number >= 0, in one line naming `name`;
    a traced one (under `jit` or `vmap`) passes."""
    if isinstance(dt, jax.core.Tracer):
        return
    value = np.asarray(dt) if isinstance(dt, str) else concrete_value(dt)
    if value is None:
        return
    if not (value.ndim == 0 and value.dtype.kind in "iuf" and np.isfinite(value)):
        raise ValueError(f"{name} must be the step, one finite number [s]; got {describe(dt)}")
    if value < 0:
        raise ValueError(
            f"{name} must be the step, >= 0 [s] (time runs forward); got {float(value)}"
        )


def check_discretise(F, Q, dt, Q_name="Q"):
    """`van_loan`'s arguments: `F` and `Q` square (n, n), `dt` a step >= 0; values: `F`
    finite, `Q` a PSD spectral density, when concrete."""
    check_dt("dt", dt)
    n = square("F", F)
    square(Q_name, Q, n, " (n = rows of F)")
    check_finite_host("F", F)
    check_covariance(Q_name, Q, form=f"(n, n) = ({n}, {n})")


def check_steady(phi, qd, h, r, p0, n_iter) -> int:
    """`steady_state`'s arguments; returns `n_iter` as an int (>= 1)."""
    n = square("phi", phi)
    square("qd", qd, n, " (n = rows of phi)")
    square("p0", p0, n, " (n = rows of phi)")
    h_shape = np.shape(h)
    if len(h_shape) != 2 or h_shape[1] != n:
        raise ValueError(f"h must be (m, n) = (m, {n}) (n = rows of phi); got {h_shape}")
    m = square("r", r, h_shape[0], " (m = rows of h)")
    n_iter = whole_number("n_iter", n_iter, "a whole number of doublings >= 1")
    if n_iter < 1:
        raise ValueError(f"n_iter must be a whole number of doublings >= 1; got {n_iter}")
    for name, a in (("phi", phi), ("h", h)):
        check_finite_host(name, a)
    check_covariance("qd", qd, form=f"(n, n) = ({n}, {n})")
    check_covariance("p0", p0, form=f"(n, n) = ({n}, {n})")
    check_covariance("r", r, definite=True, form=f"(m, m) = ({m}, {m})")
    return n_iter


def check_converged(ok, p, n_iter: int):
    """`p` when `steady_state`'s doubling converged (`ok`); else one line: a `ValueError` when
    `ok` is concrete, an `eqx.error_if` on `p` when it is traced (the caller's `jit`)."""
    message = (f"steady_state: the Riccati recursion did not converge in n_iter = {n_iter} "
               "doublings (2^n_iter steps): no steady state — a state the measurements do not "
               "see grows without bound, or one without process noise that they see keeps "
               "an uncertain p0 (its gain falls as 1/k)")  # fmt: skip
    value = concrete_value(ok)
    if value is None:
        return eqx.error_if(p, ~ok, message)
    if not bool(value):
        raise ValueError(message)
    return p


def check_run(name: str, xs, ps, ll):
    """`(xs, ps, ll)` of a filter or smoother pass, or one line (`ValueError`) when their
    values are concrete and not finite, saying which is not — the state estimate, the
    covariance, the log-likelihood — and from which step (an unstable state the
    measurements do not see overflows: Φ = 1.5 for 2000 steps gave NaN silently). Traced
    results (the caller's `jit`) pass."""
    last = [concrete_value(a) for a in (ll, xs[-1], ps[-1])]
    if any(v is None for v in last) or all(np.isfinite(v).all() for v in last):
        return xs, ps, ll
    x, p = concrete_value(xs), concrete_value(ps)  # the primal values under an eager grad
    bad_x, bad_p = ~np.isfinite(x).all(axis=1), ~np.isfinite(p).all(axis=(1, 2))
    flags = (("state estimate", bad_x.any()), ("covariance", bad_p.any()),
             ("log-likelihood", not np.isfinite(last[0])))  # fmt: skip
    parts = [what for what, bad in flags if bad]
    what = ", the ".join(parts[:-1]) + " and the " + parts[-1] if len(parts) > 1 else parts[0]
    bad = bad_x | bad_p
    if not bad.any():  # the estimates are finite: an innovation overflowed νᵀS⁻¹ν
        raise ValueError(f"{name}: the log-likelihood is not finite ({float(last[0])}) though "
                         "the state estimate and covariance are: an innovation beyond the "
                         "float range of its covariance (zs in other units than the "
                         "model's?)")  # fmt: skip
    raise ValueError(f"{name}: the {what} {'are' if len(parts) > 1 else 'is'} not finite from "
                     f"step {int(np.argmax(bad))} of {len(bad)} on (log-likelihood "
                     f"{float(last[0])}): a state that grows without bound (an eigenvalue of phi "
                     "above 1 in size, unseen by H) overflowed; measure or bound it, or shorten "
                     "the record")  # fmt: skip


DETECTABLE_RTOL = 1e-10
"""`check_detectable`'s rank tolerance: a direction is unseen when the balanced observability
matrix maps it to less than this share of its largest singular value."""


def check_detectable(phi, qd, h, p0):
    r"""One line (`ValueError`) when the concrete model has no steady state because a mode the
    measurements never see grows: a combination $z = c^\top x$ of states with
    $c^\top\Phi = \mu c^\top$, $|\mu| \ge 1$, in the unobservable subspace (the null space of
    $[H; H\Phi; \dots; H\Phi^{n-1}]$, which Φ keeps), that the process noise drives (or,
    $|\mu| > 1$, the first prior): its variance grows without bound, and the doubling's
    round-off then stalls at a wrong P or a negative variance (two random walks driving one
    measured state only through their sum gave P[1,1] = 1677, or −6.9e13, "converged").
    Only on the states the noise or `p0` reach (`_riccati.reached_states`, shared with
    `steady_state`), balanced by their open-loop standard deviations from the first prior
    $\Phi p_0\Phi^\top + Q_d$ — not `_riccati.balancing`'s from $Q_d$ alone (powers of 2,
    1 where the noise leaves a state at 0): the rank test needs every reached state's scale
    > 0, a constant only `p0` makes uncertain included. An unseen constant
    that only `p0` makes uncertain keeps its variance: a steady state, passed. Traced values
    pass (the doubling's own convergence test stays)."""
    values = [host_value(a) for a in (phi, qd, h, p0)]
    if any(v is None for v in values):
        return
    phi, qd, h, p0 = (np.asarray(v, float) for v in values)
    x0 = phi @ p0 @ phi.T + qd
    idx = np.flatnonzero(reached_states(phi, x0))  # NumPy in, NumPy out: no program
    if idx.size == 0:
        return
    phi, qd, x0, h = phi[np.ix_(idx, idx)], qd[np.ix_(idx, idx)], x0[np.ix_(idx, idx)], h[:, idx]
    noise, start = qd.copy(), x0.copy()
    for _ in range(idx.size - 1):  # open-loop covariance: from the noise alone, from x0
        noise, start = phi @ noise @ phi.T + qd, phi @ start @ phi.T + qd
    d = np.sqrt(np.clip(np.diagonal(start), 0.0, None))
    if not np.isfinite(d).all() or (d <= 0.0).any():
        return  # overflowing: the doubling's convergence test refuses it
    phi_b, h_b = phi * (d[None, :] / d[:, None]), h * d[None, :]
    blocks, row = [], h_b
    for _ in range(idx.size):
        blocks.append(row)
        row = row @ phi_b
    sv, vt = np.linalg.svd(np.concatenate(blocks), full_matrices=True)[1:]
    rank = int(np.sum(sv > DETECTABLE_RTOL * sv[0])) if sv.size and sv[0] > 0 else 0
    unseen = vt[rank:].T  # orthonormal basis of the unobservable subspace (balanced units)
    if unseen.shape[1] == 0:
        return
    mu, w = np.linalg.eig((unseen.T @ phi_b @ unseen).T)  # left eigenvectors within it
    for k in np.argsort(-np.abs(mu)):
        c = unseen @ w[:, k]
        c = c / np.linalg.norm(c)
        grows = abs(mu[k]) > 1.0 + 1e-12
        if abs(mu[k]) < 1.0 - 1e-12:
            break
        driven = noise if not grows else start
        size = float(np.real(np.conj(c) @ (driven / np.outer(d, d)) @ c))
        if size > DETECTABLE_RTOL:  # the mode's own direction (right vector), in the model's units
            v = unseen @ np.linalg.svd(unseen.T @ phi_b @ unseen - mu[k] * np.eye(len(mu)))[2][-1]
            raise ValueError(f"steady_state: no steady state: states {_direction(v * d, idx)} "
                             f"{'grow by ' if grows else 'are a random walk (eigenvalue '}"
                             f"{abs(mu[k]):.6g}{' a step' if grows else ' of phi)'} that no row of h "
                             "sees, now or through phi, and the noise drives: their variance "
                             "grows without bound; measure them, give them a bounded model "
                             "(|eigenvalue| < 1), or drop them from the state")  # fmt: skip


def _direction(v, idx) -> str:
    """'x[i], x[j] moving as (a, b)': the largest entries of the direction `v` (state indices
    `idx`), scaled to the largest 1."""
    v = np.real(v * np.exp(-1j * np.angle(v[np.argmax(np.abs(v))])))
    v = v / np.max(np.abs(v))
    keep = sorted(int(j) for j in np.argsort(-np.abs(v))[:4] if abs(v[j]) > 1e-3)
    names = ", ".join(f"x[{int(idx[j])}]" for j in keep)
    if len(keep) == 1:
        return f"{names} alone"
    return f"{names} moving as ({', '.join(f'{v[j]:.3g}' for j in keep)})"
