"""FOG vibration features: the rest test at the spectrum's edges and the direction test.

1. A tone peaking at bin 1 (0.5 Hz in 1-s windows at 100 Hz): its amplitude read from the
   Hann lobe without DC (the mid-band measure), with the DC bin (the rest test's at an edge
   now), the whole periodogram and √2·std of the mean-removed window, over phases 0–π;
   and `vibration_features`' verdict for 0.1, 0.13 and 0.2 g (rest, or NaN: vibrating but
   not measurable).
2. λ₁/trace of the 3×3 cross-spectral matrix over the tone's lobe (`DIRECTIONAL_MIN` = 0.9)
   for isotropic white noise (2-s windows at 100 Hz) and for a tone along x in noise, and
   `vibration_direction`'s verdict on rest with 0.08 and 0.1 g of noise per axis.

Run: `.venv/bin/python benchmarks/fog_rest_and_direction.py` (a few seconds). docs/fog.md."""

import warnings

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from hrgjax.fog.spectrum import (  # noqa: E402
    EdgeToneWarning,
    vibration_direction,
    vibration_features,
)

G0 = 9.80665


def amplitudes(x, lobe=3):
    """Lobe without DC, with DC, all bins (one-sided Hann PSD), √2·std: amplitude units."""
    m = len(x)
    x = x - x.mean()
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(m) / m)
    p = np.abs(np.fft.rfft(x * w)) ** 2 / (m * np.sum(w**2))  # × fs·Δf = 1 per bin
    p[1 : (m + 1) // 2] *= 2.0  # one-sided (DC and an even m's Nyquist once)
    k = np.argmax(p[1:]) + 1
    b = np.arange(len(p))
    near = np.abs(b - k) <= lobe
    amp = lambda sel: np.sqrt(2.0 * p[sel].sum())  # noqa: E731
    return amp(near & (b > 0)), amp(near), amp(b >= 0), np.sqrt(2.0) * x.std()


def ratio(x, lobe=3):
    """λ₁/trace of the cross-spectral matrix over the lobe of each window of x (K, m, 3)."""
    m = x.shape[1]
    x = x - x.mean(1, keepdims=True)
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(m) / m)
    s = np.fft.rfft(x * w[None, :, None], axis=1)
    p = (np.abs(s) ** 2).sum(-1)
    k = p[:, 1:].argmax(1) + 1
    b = np.arange(p.shape[1])
    near = (np.abs(b[None] - k[:, None]) <= lobe) & (b[None] > 0)
    c = np.einsum("kn,kni,knj->kij", near.astype(float), s, s.conj()).real
    ev = np.linalg.eigvalsh(c)
    return ev[:, -1] / ev.sum(-1)


def main():
    fs, m = 100.0, 100
    t = np.arange(m) / fs
    print("1. 0.5-Hz unit tone in a 1-s window at 100 Hz (peak bin 1), phases 0–π:")
    r = np.array([amplitudes(np.sin(2 * np.pi * 0.5 * t + ph)) for ph in np.linspace(0, np.pi, 25)])
    for name, col in zip(("lobe, no DC", "lobe + DC", "all bins", "√2·std"), r.T, strict=True):
        print(f"   {name:12s} {col.min():.3f} – {col.max():.3f} A")
    n = np.random.default_rng(0).normal(size=(4000, m))
    rn = np.array([amplitudes(v) for v in n])
    print(f"   white noise σ = 1: lobe {rn[:, 0].mean():.2f}σ, lobe + DC {rn[:, 1].mean():.2f}σ, "
          f"all bins {rn[:, 2].mean():.2f}σ (means)")  # fmt: skip
    tt = np.arange(2000) / fs
    for amp in (0.1, 0.13, 0.2):
        a = np.zeros((2000, 3))
        a[:, 2] = -G0 + amp * G0 * np.sin(2 * np.pi * 0.5 * tt + 0.3)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", EdgeToneWarning)
            f = np.asarray(vibration_features(a, fs, 1.0, (0, 0, 1.0)))
        print(f"   {amp} g, phase 0.3: rest {int((f[:, 1] == 0).sum())}/20, "
              f"NaN {int(np.isnan(f[:, 1]).sum())}/20")  # fmt: skip

    print("2. λ₁/trace over the lobe, 2-s windows at 100 Hz:")
    rng = np.random.default_rng(1)
    q = ratio(rng.normal(size=(20000, 200, 3)))
    print(f"   isotropic noise: mean {q.mean():.3f}, 99th percentile {np.quantile(q, 0.99):.3f}, "
          f"max {q.max():.3f}; ≥ 0.9 in {100 * np.mean(q >= 0.9):.2f} % of 20000 windows")  # fmt: skip
    t2 = np.arange(200) / fs
    for snr in (1, 2, 3, 6):
        x = rng.normal(size=(5000, 200, 3))
        x[:, :, 0] += snr * np.sin(2 * np.pi * 10.3 * t2 + rng.uniform(0, 2 * np.pi, (5000, 1)))
        q = ratio(x)
        print(f"   tone along x, A/σ = {snr}: 1st percentile {np.quantile(q, 0.01):.3f}, "
              f"< 0.9 in {100 * np.mean(q < 0.9):.2f} %")  # fmt: skip
    for sigma in (0.08, 0.1):
        a = np.zeros((20000, 3))
        a[:, 2] = -G0
        a += np.random.default_rng(2).normal(size=a.shape) * sigma * G0
        d = np.asarray(vibration_direction(a, fs, 2.0))
        print(f"   rest + {sigma} g noise per axis: {int(np.any(d != 0, 1).sum())} of "
              f"{len(d)} windows given a direction")  # fmt: skip


if __name__ == "__main__":
    main()
