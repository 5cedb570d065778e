"""Shared oracles and small resonators for the tests (PHYSICS.md §8 uses ω = 2π·40 rad/s)."""

import numpy as np

import hrgjax as hg

OMEGA = 2 * np.pi * 40.0


def slope(t, y):
    """Least-squares slope dy/dt."""
    return np.polyfit(np.asarray(t), np.asarray(y), 1)[0]


def local_rate(t, y):
    """Centred finite-difference derivative on the interior samples."""
    t, y = np.asarray(t), np.asarray(y)
    return (y[2:] - y[:-2]) / (t[2:] - t[:-2])


def resonator(**kw):
    base = dict(omega=OMEGA, tau=50.0, k_e=0.554)
    base.update(kw)
    return hg.Resonator(**base)


def bryan_factor(n, points=20001):
    """K = 2∫H V dA / (n ∫(U²+V²+W²) dA) for Rayleigh inextensional modes of a thin hemisphere."""
    phi = np.linspace(0.0, np.pi / 2, points)
    tn = np.tan(phi / 2) ** n
    u = v = np.sin(phi) * tn
    w = -(n + np.cos(phi)) * tn
    h = u * np.cos(phi) + w * np.sin(phi)
    da = np.sin(phi)
    num = np.trapezoid(2 * h * v * da, phi)
    den = n * np.trapezoid((u**2 + v**2 + w**2) * da, phi)
    return abs(num / den)
