"""Ferraris sections: which rows of a session are which static face or which turn.

A Ferraris session holds the IMU still on each of its six faces — `x_p` (sensor x axis up,
the x accelerometer reads +g), `x_a` (x down), `y_p`, `y_a`, `z_p`, `z_a` — and turns it once
(360°) about each sensor axis — `x_rot`, `y_rot`, `z_rot`, each from the position with that
axis up, so that gravity stays on the turning axis. Sections are half-open row ranges
`[start, end)` (imucal's convention), given

- as a mapping `{"x_p": {"start": 540, "end": 1271}, …}` (imucal's section-list JSON reads
  as is), a key's value may also be `[start, end]` or a list of such ranges: repeated
  positions, which give the calibration's standard errors from their scatter;
- as the path of a JSON file holding that mapping;
- or found in the data by [`detect_sections`][hrgjax.imu.detect_sections]."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np

from .._checks import describe, finite_number, whole_number
from .._io import read_json
from .data import ImuData

FACES = ("x_p", "x_a", "y_p", "y_a", "z_p", "z_a")
"""Static faces: sensor axis up (`p`, that accelerometer reads +g) or down (`a`)."""
TURNS = ("x_rot", "y_rot", "z_rot")
"""One full turn about each sensor axis, that axis vertical."""
SECTION_KEYS = FACES + TURNS
"""Every key a Ferraris session needs."""

Sections = dict[str, list[tuple[int, int]]]


def parse_sections(sections, n_samples: int) -> Sections:
    """Sections as `{key: [(start, end), …]}` (one or more half-open row ranges per key),
    validated against a record of `n_samples` rows.

    **Arguments:** `sections`: a mapping or the path of a JSON file (see the module notes);
    `n_samples`: the record's length.

    **Raises:** `ValueError` naming the key for a missing or unknown key, a range that is
    not `{"start": i, "end": j}` / `[i, j]` with 0 ≤ i < j ≤ n_samples, a face shorter
    than 2 samples, a key whose ranges repeat or overlap (a repeat must be another
    stretch of the record: the same rows twice would fake a repeat whose scatter is 0), or
    ranges of two keys that share rows."""
    n_samples = whole_number("n_samples", n_samples, "the record's number of rows, ≥ 1")
    if n_samples < 1:  # 7800.5 was read as is, -1 named every range instead
        raise ValueError(f"n_samples must be the record's number of rows, ≥ 1; got {n_samples}")
    where = "sections"
    if isinstance(sections, str | os.PathLike):
        where = os.fspath(sections)
        sections = read_json(where)
    if not isinstance(sections, Mapping):
        raise ValueError(
            f'{where} must map the keys {", ".join(SECTION_KEYS)} to {{"start": i, "end": j}}; '
            f"got {type(sections).__name__}"
        )
    unknown = sorted(set(sections) - set(SECTION_KEYS))
    if unknown:
        raise ValueError(f"{where}: unknown key {unknown[0]!r}; keys are {', '.join(SECTION_KEYS)}")
    missing = [k for k in SECTION_KEYS if k not in sections]
    if missing:
        raise ValueError(
            f"{where}: no section {missing[0]!r} (a Ferraris session needs {', '.join(SECTION_KEYS)}"
            "; detect_sections finds them in the data)"
        )
    out: Sections = {}
    for key in SECTION_KEYS:
        value = sections[key]
        ranges = value if _is_list_of_ranges(value) else [value]
        if not ranges:
            raise ValueError(f"{where}: {key!r} lists no range")
        out[key] = [_range(where, key, r, n_samples) for r in ranges]
        _check_repeats(where, key, out[key])
    _check_disjoint(where, out)
    return out


def _check_disjoint(where: str, sections: Sections) -> None:
    """Different keys must be different stretches of the record: the same rows cannot be
    two faces, or a face and a turn, at once."""
    rows = sorted((s, e, key) for key, ranges in sections.items() for s, e in ranges)
    s0, e0, k0 = rows[0]
    for s1, e1, k1 in rows[1:]:
        if s1 < e0:  # (a key's own ranges are disjoint: _check_repeats)
            same = "the same rows" if (s0, e0) == (s1, e1) else "overlapping rows"
            raise ValueError(
                f"{where}: {k0!r} [{s0}, {e0}] and {k1!r} [{s1}, {e1}] are {same}: each "
                "section must be its own stretch of the record (ranges [i, j) of different "
                "keys may touch but not overlap)"
            )
        if e1 > e0:
            s0, e0, k0 = s1, e1, k1


def _check_repeats(where: str, key: str, ranges: list[tuple[int, int]]) -> None:
    """A key's repeats must be other stretches of the record: a range listed twice, or two
    that share rows, would count the same samples as two positions (their scatter, the
    standard errors, shrinks toward zero)."""
    order = sorted(ranges)
    for (s0, e0), (s1, e1) in zip(order, order[1:], strict=False):
        if s1 < e0:
            what = "lists the range" if (s0, e0) == (s1, e1) else "lists overlapping ranges"
            twice = (
                f"[{s0}, {e0}] twice" if (s0, e0) == (s1, e1) else f"[{s0}, {e0}] and [{s1}, {e1}]"
            )
            raise ValueError(
                f"{where}: {key!r} {what} {twice}: repeats must be separate row ranges "
                f"[[i1, j1], [i2, j2], …] with j1 <= i2 (list a position once)"
            )


def _is_list_of_ranges(value) -> bool:
    if isinstance(value, Mapping) or isinstance(value, str) or not isinstance(value, Sequence):
        return False
    return all(isinstance(v, Mapping) or (isinstance(v, Sequence) and not isinstance(v, str))
               for v in value) and len(value) > 0 and not _is_pair(value)  # fmt: skip


def _is_pair(value) -> bool:
    return len(value) == 2 and all(isinstance(v, int | np.integer) for v in value)


def _pairs(rows) -> list[tuple[int, int]] | None:
    """`rows` — (start, end) pairs of integers (tuples, lists or (2,) arrays) in a list or
    tuple, or an integer array (k, 2) — as a list of int pairs; None for anything else."""
    if isinstance(rows, np.ndarray):
        ok = rows.ndim == 2 and rows.shape[1] == 2 and np.issubdtype(rows.dtype, np.integer)
        return [(int(s), int(e)) for s, e in rows] if ok else None
    if not isinstance(rows, Sequence) or isinstance(rows, str | bytes):
        return None
    out = []
    for r in rows:
        if isinstance(r, np.ndarray) and r.shape == (2,) and np.issubdtype(r.dtype, np.integer):
            r = r.tolist()
        if not (isinstance(r, Sequence) and not isinstance(r, str) and _is_pair(r)):
            return None
        out.append((int(r[0]), int(r[1])))
    return out


def _range(where: str, key: str, r, n: int) -> tuple[int, int]:
    form = f'{{"start": i, "end": j}} or [i, j] with 0 <= i < j <= {n} (rows, end excluded)'
    if isinstance(r, Mapping):
        if set(r) - {"start", "end"} or "start" not in r or "end" not in r:
            raise ValueError(f"{where}: {key!r} must be {form}; got {dict(r)!r}")
        start, end = r["start"], r["end"]
    elif isinstance(r, Sequence) and not isinstance(r, str) and len(r) == 2:
        start, end = r
    else:
        raise ValueError(f"{where}: {key!r} must be {form}; got {r!r}")
    ok = all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in (start, end))
    if not ok or not (0 <= start < end <= n):
        raise ValueError(f"{where}: {key!r} must be {form}; got [{start!r}, {end!r}]")
    if key in FACES and end - start < 2:
        raise ValueError(f"{where}: face {key!r} has {end - start} sample; need at least 2")
    return int(start), int(end)


def sections_to_json(sections: Sections) -> dict:
    """Sections as JSON-ready `{key: {"start", "end"}}`, or a list of those for a key with
    repeats (the form `parse_sections` reads)."""
    pairs = {k: _pairs(r) for k, r in sections.items()} if isinstance(sections, Mapping) else {}
    if not isinstance(sections, Mapping) or any(r is None for r in pairs.values()):
        # was an AttributeError or "'int' object is not iterable"
        raise ValueError("sections must be {key: [(start, end), …]} as parse_sections and "
                         f"detect_sections give them; got {describe(sections)}")  # fmt: skip
    out = {}
    for key, ranges in pairs.items():
        rows = [{"start": int(s), "end": int(e)} for s, e in ranges]
        out[key] = rows[0] if len(rows) == 1 else rows
    return out


def detect_sections(
    data,
    *,
    min_static_s: float = 2.0,
    motion_threshold_dps: float = 3.0,
    window_s: float = 0.25,
    trim_s: float = 0.2,
    turn_tolerance_deg: float = 45.0,
) -> Sections:
    """Find the Ferraris sections of a session in its data.

    Rests are where the magnitude of the gyro's rate vector (median over the record removed,
    moving mean over `window_s` of each axis, so that white noise averages down) stays below
    `motion_threshold_dps` [°/s] for at least `min_static_s` [s]; each motion between two
    rests reaches `trim_s` [s] + `window_s` / 2 into both. A motion whose gyro, less the
    rests' level, integrates to a full turn (360° within `turn_tolerance_deg`, at least 90 %
    of it about one axis) is that axis's `*_rot`, and reaches further, by its ramp: a slow
    end of a turn (a soft start, a hand turn, the simulator's 1 − cos ramp) stays under
    `motion_threshold_dps` for seconds. Beside a turn, the rest's level is a robust line
    through its `window_s` means over `LEVEL_SPAN_S` (4 s) just before the ramp (so that a
    bias drifting or swaying in the rest is not motion), σ the scatter of the rests' window
    means about such lines (white noise, sway and wander together); the ramp starts where
    the rate leaves that line by `REST_NOISE_K` (5) σ, and the turn section reaches out by as
    long again as the rate took from there to `RAMP_FACTOR` (10) times that (for a ramp ∝
    t², the part under the noise and more), at most to the still rest's middle. A motion
    that is no turn keeps the short reach: a face is the rest less `trim_s` +
    `window_s` / 2 at a move. What is left of a rest is the face whose accelerometer axis
    carries most of the specific force (at least 80 %, by sign `p` or `a`). A turn section
    holds the whole turn with a little rest at both ends (the Ferraris sums take the bias ×
    duration off, so rest inside a turn section costs only noise; a turn cut short reads
    M_g low). The rests on either side of a turn count as a face only where no other rest
    holds that face. A face or a turn found more than once is a repeat.

    **Returns:** `{key: [(start, end), …]}` for every key of
    [`SECTION_KEYS`][hrgjax.imu.sections.SECTION_KEYS].

    **Raises:** `ValueError` listing the keys not found (with what was found), so that a
    user can pass them by hand; naming an argument that is not a positive number (`trim_s`
    ≥ 0); `TypeError` for `data` not an `ImuData`."""
    _check_data("detect_sections", data)
    for name, value, unit in (("min_static_s", min_static_s, "s"), ("window_s", window_s, "s"),
                              ("motion_threshold_dps", motion_threshold_dps, "°/s"),
                              ("turn_tolerance_deg", turn_tolerance_deg, "°"),
                              ("trim_s", trim_s, "s")):  # fmt: skip
        _at_least(name, value, unit, strict=name != "trim_s")  # ≤ 0: nothing found, or wrong
    n = len(data)
    rate = data.rate_hz
    gyro = np.asarray(data.gyro)
    accel = np.asarray(data.accel)
    w = max(int(round(window_s * rate)), 1)
    rel = gyro - np.median(gyro, axis=0)
    # the rate vector averaged, then its norm: white noise averages down (the mean of |noise|
    # would not: ≈ 1.6 σ per sample, splitting a noisy face into fake repeats)
    smooth = np.stack([_moving_mean(rel[:, i], w) for i in range(3)], 1)
    still = np.linalg.norm(smooth, axis=1) < np.deg2rad(motion_threshold_dps)
    rests = [(s, e) for s, e in _runs(still) if e - s >= min_static_s * rate]
    pad = int(round(trim_s * rate)) + w // 2
    levels = [np.array([_mode(smooth[s:e, i]) for i in range(3)]) for s, e in rests]
    dt = data.dt

    def full_turn(a, b, level):
        turn = np.rad2deg(((rel[a:b] - level) * dt[a:b, None]).sum(axis=0))
        i = int(np.argmax(np.abs(turn)))
        return abs(abs(turn[i]) - 360.0) <= turn_tolerance_deg and abs(turn[i]) >= 0.9 * (
            np.linalg.norm(turn)
        )

    pairs = list(zip(rests, rests[1:], strict=False))
    coarse = [(e0 - pad, s1 + pad) for (_, e0), (s1, _) in pairs]
    near = [(levels[j] + levels[j + 1]) / 2.0 for j in range(len(pairs))]
    turning = {j for j, (a, b) in enumerate(coarse) if full_turn(a, b, near[j])}
    quiet = [r for j, r in enumerate(rests) if not {j - 1, j} & turning] or rests
    sigma = _rest_sigma(rel, smooth, quiet, w, pad)
    span = int(round(LEVEL_SPAN_S * rate))
    # each motion's ramp: the row where it leaves the rest on either side, and its rise [rows]
    ramps = {}
    ref = [(s + pad, e - pad) for s, e in rests]  # each rest's still rows, as far as known
    for _ in range(2):  # the second time, a ramp on the rest's other side is out of its line
        for j, ((s0, e0), (s1, e1)) in enumerate(pairs):
            p, rise = _ramp(smooth[s0:s1], e0 - s0, sigma, levels[j], span, w, ref[j][0] - s0)
            ramps[j, 0] = (s0 + p, rise)
            back = smooth[e0:e1][::-1]
            p, rise = _ramp(back, e1 - s1, sigma, levels[j + 1], span, w, e1 - ref[j + 1][1])
            ramps[j, 1] = (e1 - p, rise)
        ref = [(max(s + pad, sum(ramps[j - 1, 1])) if j else s + pad,
                min(e - pad, ramps[j, 0][0] - ramps[j, 0][1]) if j < len(pairs) else e - pad)
               for j, (s, e) in enumerate(rests)]  # fmt: skip

    def reach(j, turns):
        """Motion j's rows reaching to its ramps' starts, at most to the middle of the still
        rest between it and a neighbour in `turns` (which reaches as far from its side)."""
        (s0, _), (_, e1) = pairs[j]
        (p0, rise0), (p1, rise1) = ramps[j, 0], ramps[j, 1]
        lo = ramps[j - 1, 1][0] if j - 1 in turns else s0 + pad
        hi = ramps[j + 1, 0][0] if j + 1 in turns else e1 - pad
        a = min(max(p0 - rise0 - pad, (lo + p0) // 2, lo), coarse[j][0])
        b = max(min(p1 + rise1 + pad, (p1 + hi) // 2, hi), coarse[j][1])
        level = (_line_at(smooth, s0 + pad, p0 - rise0, span, w, p0 - rise0 - 1)
                 + _line_at(smooth, p1 + rise1, e1 - pad, span, w, p1 + rise1, head=True)) / 2  # fmt: skip
        return a, b, level

    # only a turn reaches out by its ramp; the caps from the turns as they then are
    turning = {j for j in range(len(pairs)) if full_turn(*reach(j, turning))}
    moves = [reach(j, turning)[:2] if j in turning else r for j, r in enumerate(coarse)]
    found: dict[str, list[tuple[int, int]]] = {k: [] for k in SECTION_KEYS}
    for j in sorted(turning):
        a, b = moves[j]
        turn = ((rel[a:b] - near[j]) * dt[a:b, None]).sum(axis=0)
        found[f"{'xyz'[int(np.argmax(np.abs(turn)))]}_rot"].append((a, b))
    faces: dict[str, list[tuple[int, bool]]] = {k: [] for k in FACES}
    rest_rows = []
    for j, (s, e) in enumerate(rests):
        s = moves[j - 1][1] if j > 0 else s + pad
        e = moves[j][0] if j < len(moves) else e - pad
        rest_rows.append((s, e))
        if e - s < 2:
            continue
        f = accel[s:e].mean(axis=0)
        i = int(np.argmax(np.abs(f)))
        if abs(f[i]) >= 0.8 * np.linalg.norm(f):
            faces[f"{'xyz'[i]}_{'p' if f[i] > 0 else 'a'}"].append((j, bool({j - 1, j} & turning)))
    for key, rows in faces.items():
        # the rests that hold a turn's axis up count as that face only where no other does
        keep = [j for j, beside in rows if not beside] or [j for j, _ in rows]
        found[key] = [rest_rows[j] for j in keep]
    missing = [k for k in SECTION_KEYS if not found[k]]
    if missing:
        have = {k: len(v) for k, v in found.items() if v}
        clipped = saturation(data, [m for m in moves if m[1] > m[0]] or [(0, n)])
        hint = f"; {clipped} (the turns cannot be measured)" if clipped else ""
        raise ValueError(
            f"detect_sections: found no {', '.join(missing)} in {n} samples (found {have}); "
            f"pass the sections by hand, or change min_static_s / motion_threshold_dps{hint}"
        )
    return found


REST_NOISE_K = 5.0
"""A turn's ramp leaves the rest where one axis's rate, averaged over `window_s`, is this
many standard deviations of that average (measured in the rests) off the rest's level
line: `detect_sections`."""
RAMP_FACTOR = 10.0
"""`detect_sections` widens a turn into each rest by as long as its rate took to rise from
`REST_NOISE_K` σ to this many times that: for a ramp ∝ t² (a smooth start) √10 − 1 = 2.2
times as long as it spent under the noise, for a ramp ∝ t 9 times, for a step nothing."""
LEVEL_SPAN_S = 4.0
"""[s]: the stretch of rest just before a turn's ramp through whose window means
`detect_sections` lays the rest's level line (a drifting bias is followed, a sway of a
few seconds' period averages out)."""
_SIGMA_FLOOR = 1e-9
"""[rad/s]: the least window-mean noise taken (noise-free records: round-off is not motion)."""


def _rest_sigma(rel, smooth, rests, w, pad):
    """σ (3,) [rad/s] of a rest's window mean about its level: the larger of the white
    part (window means `w` apart: their difference is √2 σ) and the scatter of the window
    means about each rest's robust line (`_line_at`: sway, flicker and a wandering bias
    included), median absolute values pooled over `rests` less `pad` at both ends; at least
    half the data's resolution (a quantised record's flat rest) and `_SIGMA_FLOOR`."""
    if not rests:
        return np.full(3, _SIGMA_FLOOR)
    inner = [(s + pad, e - pad) if e - s > 2 * pad + 2 * w else (s, e) for s, e in rests]
    lag = w if all(e - s > w for s, e in inner) else 1
    diffs = np.concatenate([smooth[s + lag : e] - smooth[s : e - lag] for s, e in inner])
    white = np.median(np.abs(diffs), axis=0) * (1.4826 / np.sqrt(2.0))
    resid = np.concatenate([smooth[s:e:w] - _line_at(smooth, s, e, e - s, w, np.arange(s, e, w))
                            for s, e in inner])  # fmt: skip
    scatter = np.median(np.abs(resid), axis=0) * 1.4826
    steps = np.abs(np.concatenate([np.diff(rel[s:e], axis=0) for s, e in rests]))
    resolution = np.array([np.min(c[c > 0], initial=np.inf) for c in steps.T])
    resolution[~np.isfinite(resolution)] = 0.0
    return np.maximum.reduce([white, scatter, resolution / 2, np.full(3, _SIGMA_FLOOR)])


def _line_at(smooth, s, e, span, w, at, head=False):
    """The rest's level line at rows `at` [rad/s]: Theil–Sen through the window means
    (every `w`-th row) of the last `span` rows of `[s, e)` (`head`: the first), (3,) per
    row of `at`; the median of the means where fewer than eight."""
    a, e = (s, min(e, s + span)) if head else (max(s, e - span), e)
    rows = np.arange(a, e, max(w, (e - a) // 64))
    if rows.size == 0:  # no rows left between the motions: the one past the other motion
        rows = np.array([min(max(e - 1 if head else s, 0), len(smooth) - 1)])
    y = smooth[rows]
    if rows.size < 8:  # under 2 s of 0.25-s means: no slope to trust
        return np.broadcast_to(np.median(y, axis=0), np.shape(at) + (3,)).copy()
    i, j = np.triu_indices(rows.size, 1)
    slope = np.median((y[j] - y[i]) / (rows[j] - rows[i])[:, None], axis=0)
    base = np.median(y - slope * (rows - rows[0])[:, None], axis=0)
    return base + slope * (np.asarray(at) - rows[0])[..., None]


def _ramp(seg, m, sigma, level, span, w, start) -> tuple[int, int]:
    """`(row, rise)` in `seg` (a rest of `m` rows, then the motion after it): where the
    motion's rate leaves the rest's level by `REST_NOISE_K` σ (the crossing nearest the
    motion), and how many rows it took from there to `RAMP_FACTOR` times that. The level:
    at first the rest's mode `level`, then a line through the `span` rows of rest before the
    ramp's reach, from row `start` on (past the motion before: `_line_at`, a drifting bias),
    three times; where a long rest's bias drifted off its mode, so that the rise reaches
    back beyond its start, first a line through the rows before the band was left."""
    high = RAMP_FACTOR * REST_NOISE_K
    idx = np.arange(seg.shape[0])
    line = np.broadcast_to(level, seg.shape)
    p5, rise, drifted = m, 0, False
    for _ in range(4):
        z = np.max(np.abs(seg - line) / sigma, axis=1)
        up = np.flatnonzero(z[m:] >= high)
        p50 = m + int(up[0]) if up.size else m + int(np.argmax(z[m:])) if seg.shape[0] > m else m
        below = np.flatnonzero(z[:p50] < high)  # back to the start of that run ≥ 50σ …
        p50 = int(below[-1]) + 1 if below.size else 0
        quiet = np.flatnonzero(z[:p50] < REST_NOISE_K)  # … and on to the last row under 5σ
        p5 = int(quiet[-1]) + 1 if quiet.size else 0
        rise = p50 - p5
        end = p5 - rise
        if end - start < 4 * w:  # too little rest before the ramp to lay a line through …
            if drifted or p5 - start < span:
                break
            end, drifted = p5, True  # … unless a long rest drifted off its mode: the rows
            # before it left the band, a line that follows the drift to the motion
        line = _line_at(seg, start, end, span, w, idx)
    return p5, rise


def _mode(x: np.ndarray) -> float:
    """The half-sample mode (Bickel & Frühwirth 2006): the shortest interval holding half
    the values, again within it, down to three."""
    x = np.sort(x)
    while x.size > 3:
        h = (x.size + 1) // 2
        i = int(np.argmin(x[h - 1 :] - x[: x.size - h + 1]))
        x = x[i : i + h]
    return float(x.mean())


class TurnCutWarning(UserWarning):
    """A turn section starts or ends while the IMU still turns
    ([`cut_turn`][hrgjax.imu.sections.cut_turn]): the section leaves out motion, and M_g is
    off by more than its σ holds (low for a turn cut short).
    `warnings.simplefilter("ignore", TurnCutWarning)` silences it."""


def cut_turn(data, sections, *, window_s: float = 0.25, walk: float = 0.0) -> str | None:
    """Every turn section that the gyro still turns beyond, named in one line of text, or
    None.

    Over `window_s` [s] just before a turn section and just after it, the rate about the
    turn's axis should be the rest's. It is compared with two rests: the gyro mean of the
    face that holds that axis vertical the same way (`x_p` or `x_a`, … by the
    accelerometer's sign in the turn; its range nearest in time), which reads the same
    bias, g-sensitivity and vertical Earth rate, and the `NEXT_REST_S` (1 s) of record just
    beyond the window (the same bias, however it drifts or sways). A window mean more than
    `REST_NOISE_K` (5) σ from both is motion the section leaves out: a turn cut short (M_g
    reads low) or a settling back (high). σ: the faces' own `window_s` means about each
    face's mean (the noise as measured, coloured or white, sway included), that of the
    other mean, and a bias random walk of intensity `walk` [rad/s/√s] over the time between
    the window and the face.

    **Arguments:** `data`: the session ([`ImuData`][hrgjax.imu.ImuData]); `sections`: as
    [`parse_sections`][hrgjax.imu.sections.parse_sections] takes them."""
    _check_data("cut_turn", data)
    _at_least("window_s", window_s, "s", strict=True)  # ≤ 0 was read as one sample
    _at_least("walk", walk, "rad/s/√s", strict=False)
    sections = parse_sections(sections, len(data))
    gyro, time, n = np.asarray(data.gyro), np.asarray(data.time), len(data)
    w = max(int(round(window_s * data.rate_hz)), 1)
    beyond = max(int(round(NEXT_REST_S * data.rate_hz)), w)
    devs, dof = [], 0
    for s, e in (r for key in FACES for r in sections[key] if r[1] - r[0] >= w):
        blocks = gyro[s : s + (e - s) // w * w].reshape(-1, w, 3).mean(axis=1)
        devs.append(blocks - blocks.mean(axis=0))
        dof += max(len(blocks) - 1, 0)
    var = np.maximum(sum((d**2).sum(axis=0) for d in devs) / max(dof, 1), _SIGMA_FLOOR**2)
    cut = []
    for i, key in enumerate(TURNS):
        for s, e in sections[key]:
            face = f"{'xyz'[i]}_{'p' if np.asarray(data.accel)[s:e, i].mean() > 0 else 'a'}"
            sides, ways = [], []
            for side, (a, b), (c, d) in (
                ("before", (max(s - w, 0), s), (max(s - w - beyond, 0), max(s - w, 0))),
                ("after", (e, min(e + w, n)), (min(e + w, n), min(e + w + beyond, n))),
            ):
                if b <= a:
                    continue
                mid = time[(a + b - 1) // 2]
                fs, fe = min(sections[face], key=lambda r: abs(time[(r[0] + r[1] - 1) // 2] - mid))
                gap = abs(time[(fs + fe - 1) // 2] - mid)
                level = gyro[fs:fe, i].mean()
                rate = gyro[a:b, i].mean() - level
                sd = np.sqrt(var[i] * (w / (b - a) + w / (fe - fs)) + walk**2 * gap)
                z = abs(rate) / sd
                if d > c:  # the rest just beyond: a drifting bias moves both windows alike
                    near = gyro[a:b, i].mean() - gyro[c:d, i].mean()
                    z = min(z, abs(near) / np.sqrt(var[i] * (w / (b - a) + w / (d - c))))
                if z > REST_NOISE_K:
                    along = rate * (gyro[s:e, i] - level).sum() > 0  # the turn's own sense
                    sides.append(f"{side} it ({np.rad2deg(rate):+.3g} °/s about {'xyz'[i]} "
                                 f"over {(b - a) / data.rate_hz:.3g} s, {z:.0f}σ of the rest "
                                 f"noise off the {face!r} rest and the rest beyond)")  # fmt: skip
                    way = "with the turn (M_g reads low)" if along else "back (M_g reads high)"
                    ways += [way] if way not in ways else []
            if sides:
                cut.append(f"turn {key!r} rows [{s}, {e}): the gyro still turns "
                           f"{' and '.join(sides)}: the section leaves out motion "
                           f"{' and '.join(ways)}")  # fmt: skip
    if not cut:
        return None
    them = "it" if len(cut) == 1 else "them"
    return f"{'; '.join(cut)}; widen {them} into the rests on either side"


NEXT_REST_S = 1.0
"""[s]: the stretch of record just beyond `cut_turn`'s window that it also compares with."""


SATURATION_MIN_S = 0.05
"""The shortest flat top [s] (and at least `SATURATION_MIN_SAMPLES` samples) that
[`saturation`][hrgjax.imu.sections.saturation] calls a clipped channel."""
SATURATION_MIN_SAMPLES = 5
"""The fewest consecutive samples at a channel's extreme that make a flat top."""


def saturation(data, ranges, *, sensor: str = "gyro", limit: float | None = None,
               noise_ranges=None, above: float = 0.0) -> str | None:  # fmt: skip
    """The first clipped channel of `sensor` ("gyro" or "accel") within the row `ranges`
    [(start, end), …], as one line of text, or None.

    A channel is clipped where it sits flat at its extreme: at least `SATURATION_MIN_SAMPLES`
    consecutive samples, and `SATURATION_MIN_S` [s], equal (to 1e-9 relative: round-off of
    a unit conversion) to the channel's largest or smallest value in the whole record. A
    genuine record reaches its extreme once (noise); a saturated one holds it. With `limit`
    (SI: [rad/s] or [m/s²]), only a sample with |value| ≥ 0.999 `limit` is clipped (the range
    is known: a flat top below it is genuine — a turntable's constant rate, a quantised
    face). `noise_ranges` [(start, end), …]: look for flat tops only in a channel that
    varies within one of these ranges (the static faces of noise-free data are flat
    everywhere, those of noisy data are not); `above` (SI): only flat tops beyond it (an
    accelerometer's face reads 1 g, and no part's range is below 2 g)."""
    _check_data("saturation", data)
    if not isinstance(sensor, str) or sensor not in ("gyro", "accel"):  # was an AttributeError
        raise ValueError(f"sensor must be 'gyro' or 'accel'; got {describe(sensor)}")
    if limit is not None:
        _at_least("limit", limit, "rad/s or m/s²", strict=True)  # < 0: "its range ±-57.3"
    _at_least("above", above, "rad/s or m/s²", strict=False)
    checked = []
    for name, rows in (("ranges", ranges), ("noise_ranges", noise_ranges)):
        pairs = None if rows is None else _pairs(rows)
        if rows is not None and (pairs is None or not all(0 <= s < e <= len(data)
                                                          for s, e in pairs)):  # fmt: skip
            raise ValueError(f"{name} must be row ranges [(start, end), …] with 0 <= start < "
                             f"end <= {len(data)}; got {describe(rows)}")  # fmt: skip
        checked.append(pairs)
    ranges, noise_ranges = checked
    x_all = np.asarray(getattr(data, sensor))
    rate = float(data.rate_hz)
    min_run = max(SATURATION_MIN_SAMPLES, int(np.ceil(SATURATION_MIN_S * rate)))
    unit, scale = ("°/s", np.rad2deg(1.0)) if sensor == "gyro" else ("m/s²", 1.0)
    if noise_ranges is not None:
        noisy = [c for c in range(3) if any(np.ptp(x_all[s:e, c]) > 0 for s, e in noise_ranges)]
    else:
        noisy = [0, 1, 2]
    for c in range(3):
        x = x_all[:, c]
        for s, e in ranges:
            part = x[s:e]
            if limit is not None:
                over = np.flatnonzero(np.abs(part) >= 0.999 * limit)
                if over.size:
                    return (f"{sensor} {'xyz'[c]} reads {part[over[0]] * scale:+.4g} {unit} at row "
                            f"{s + over[0]}, at its range ±{limit * scale:.4g} {unit}")  # fmt: skip
            if c not in noisy or limit is not None:
                continue
            for extreme in (x.max(), x.min()):
                if abs(extreme) <= above:
                    continue
                at = np.isclose(part, extreme, rtol=1e-9, atol=0.0)
                runs = [(a, b) for a, b in _runs(at) if b - a >= min_run]
                if runs:
                    a, b = max(runs, key=lambda r: r[1] - r[0])
                    return (f"{sensor} {'xyz'[c]} saturates: {b - a} consecutive samples (rows "
                            f"{s + a}–{s + b - 1}) read its extreme {extreme * scale:+.4g} {unit} "
                            f"exactly, so it clips at about ±{abs(extreme) * scale:.4g} {unit}")  # fmt: skip
    return None


def _check_data(where: str, data) -> None:
    if not isinstance(data, ImuData):
        raise TypeError(f"{where} takes an hg.imu.ImuData (hg.imu.load); got {type(data).__name__}")


def _at_least(name: str, value, unit: str, strict: bool) -> float:
    """`value` a finite number > 0 (`strict`) or ≥ 0 [`unit`], else one line naming `name`."""
    v = finite_number(name, value, unit)
    if v < 0 or (strict and v == 0):
        raise ValueError(f"{name} must be {'> 0' if strict else '>= 0'} [{unit}]; got {v}")
    return v


def _moving_mean(x: np.ndarray, w: int) -> np.ndarray:
    if w <= 1:
        return x
    c = np.cumsum(np.concatenate([[0.0], x]))
    half = w // 2
    lo = np.clip(np.arange(x.size) - half, 0, x.size)
    hi = np.clip(np.arange(x.size) - half + w, 0, x.size)
    return (c[hi] - c[lo]) / (hi - lo)


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open ranges where `mask` is true."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))
