"""How far a tone's PSD peak must lie from DC and from Nyquist for `fog.spectrum` to measure
its amplitude and frequency (audit 2026-12, docs/fog.md "Edges").

A NumPy replica of `spectrum._peak` (one periodic-Hann segment of `m` samples, mean removed,
the power within ±3 bins of the peak, DC left out) measures the worst amplitude and
frequency errors of a unit tone against its peak bin, over tones stepped by 0.02 bin and 13
phases each; then `spectrum.tone` is checked to return NaN exactly where the peak lies at
bin 1–2 or at the last two bins (`EDGE_BINS`), and the right answer elsewhere.

Run: `.venv/bin/python benchmarks/fog_spectrum_edges.py` (about 10 s of CPU)."""

import warnings

import numpy as np
from _common import report  # x64 on

from hrgjax.fog.spectrum import EDGE_BINS, EdgeToneWarning, tone


def replica(x, fs, lobe=3):
    """Peak bin, frequency [Hz] and amplitude of the strongest tone (spectrum._peak's rule)."""
    m = x.size
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(m) / m)
    p = np.abs(np.fft.rfft((x - x.mean()) * w)) ** 2 / (fs * np.sum(w**2))
    p[1:] *= 2
    if m % 2 == 0:
        p[-1] /= 2
    f = np.fft.rfftfreq(m, 1 / fs)
    k = int(np.argmax(p[1:])) + 1
    b = np.arange(p.size)
    near = (np.abs(b - k) <= lobe) & (b > 0)
    return k, (p[near] * f[near]).sum() / p[near].sum(), np.sqrt(2 * p[near].sum() * f[1])


def scan(m, fs=100.0):
    """{signed peak bin: (max |A − 1|, max |f error| [bins], tone flags it)}; bins counted
    from DC (> 0) or from the last bin (≤ 0)."""
    t = np.arange(m) / fs
    df, last = fs / m, m // 2
    out = {}
    for b0 in np.arange(0.3, m / 2 - 0.01, 0.02):
        for ph in np.linspace(0.0, np.pi, 13):
            x = np.sin(2 * np.pi * b0 * df * t + ph)
            k, fe, a = replica(x, fs)
            key = k if k < last / 2 else k - last
            e_a, e_f = out.get(key, (0.0, 0.0))
            out[key] = (max(e_a, abs(a - 1)), max(e_f, abs(fe - b0 * df) / df))
    return out


def main():
    print(f"EDGE_BINS (DC side, Nyquist side) = {EDGE_BINS}")
    worst = 0.0
    for m in (100, 101, 200):
        res = scan(m)
        worst = max(
            worst,
            *(e[0] for k, e in res.items() if EDGE_BINS[0] < k or k < -EDGE_BINS[1]),
        )
        shown = [k for k in sorted(res) if k <= 5 or k >= -4]
        shown = [k for k in shown if k > 0] + [k for k in shown if k <= 0]
        print(f"segment {m} samples: peak bin → worst |A − 1|, worst |f error| [bins]")
        for k in shown:
            if -4 <= k <= 5:
                tag = "from DC" if k > 0 else "below the last bin"
                e_a, e_f = res[k]
                print(f"  {abs(k):2d} {tag:18s} {100 * e_a:7.3f} %  {e_f:6.3f}")
    # the library flags exactly bins 1..EDGE_BINS[0] and last-EDGE_BINS[1]..last
    fs, m = 100.0, 100
    t = np.arange(m) / fs
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EdgeToneWarning)
        for b0 in (1.0, 2.0, 2.6, 3.0, 25.0, 47.4, 48.0, 49.0, 50.0):
            x = np.sin(2 * np.pi * b0 * t + 0.3)
            f, a = (float(v) for v in tone(x, fs, nperseg=m))
            k = replica(x, fs)[0]
            flagged = k <= EDGE_BINS[0] or k >= m // 2 - EDGE_BINS[1]
            assert np.isnan(a) == flagged, (b0, k, a)
            assert flagged or abs(a - 1) < 0.011, (b0, a)
            print(f"tone at bin {b0:5.2f}: peak bin {k:2d}, tone() → f {f:8.4f} Hz, A {a:.4f}")
    report("worst amplitude error of a tone measured (not NaN), unit tone", 100 * worst, "%",
           target="about 1 % (the range margin)")  # fmt: skip


if __name__ == "__main__":
    main()
