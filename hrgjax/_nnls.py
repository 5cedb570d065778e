"""Non-negative least squares for a handful of columns (NumPy)."""

from __future__ import annotations

import numpy as np


def nnls(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """argmin ‖a x − b‖ subject to x ≥ 0, by trying every subset of the columns (exact, for
    the ≤ 5 columns of a noise model; 2^q least-squares solves)."""
    q = a.shape[1]
    best, best_cost = np.zeros(q), np.inf
    for mask in range(1, 2**q):
        cols = [j for j in range(q) if mask >> j & 1]
        x, *_ = np.linalg.lstsq(a[:, cols], b, rcond=None)
        if np.all(x >= 0):
            cost = float(np.sum((a[:, cols] @ x - b) ** 2))
            if cost < best_cost:
                best = np.zeros(q)
                best[cols] = x
                best_cost = cost
    return best
