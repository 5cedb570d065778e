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

from .._io import read_json

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
    out = {}
    for key, ranges in sections.items():
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

    Candidate rests are where the magnitude of the gyro's rate vector (median over the record
    removed, moving mean over `window_s` of each axis, so that white noise averages down)
    stays below `motion_threshold_dps` [°/s] for at least `min_static_s` [s]. Each is then
    measured against its own noise: its level is the mode of its window means (where the
    rate dwells), and it is still only as far as every axis's window mean stays within
    `REST_NOISE_K` (5) σ of that level, σ the window mean's noise measured in the rests — a
    slow end of a turn (a soft start, a hand turn, the simulator's 1 − cos ramp), under
    `motion_threshold_dps` for seconds, is motion, not rest. Each motion between two rests
    reaches out into both by `trim_s` [s] + `window_s` / 2, and by as long again as its rate
    took to rise from the rest noise to `RAMP_FACTOR` (10) times it (for a ramp ∝ t², the
    part under the noise and more), at most to each rest's middle; what is left of a rest
    is the face whose accelerometer axis carries most of the specific force (at least 80 %,
    by sign `p` or `a`). A motion whose gyro, less the rests' level, integrates to a full
    turn (360° within `turn_tolerance_deg`, at least 90 % of it about one axis) is that
    axis's `*_rot`: the whole turn, with a little rest at both ends (the Ferraris sums take
    the bias × duration off, so rest inside a turn section costs only noise; a turn cut
    short reads M_g low). The rests on either side of a turn count as a face only where
    no other rest holds that face. A face or a turn found more than once is a repeat.

    **Returns:** `{key: [(start, end), …]}` for every key of
    [`SECTION_KEYS`][hrgjax.imu.sections.SECTION_KEYS].

    **Raises:** `ValueError` listing the keys not found (with what was found), so that a
    user can pass them by hand."""
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
    coarse = [(s, e) for s, e in _runs(still) if e - s >= min_static_s * rate]
    rests, sigma = _still_rests(rel, smooth, coarse, w)
    pad = int(round(trim_s * rate)) + w // 2
    moves = [_motion(smooth, sigma, r0, r1, pad) for r0, r1 in zip(rests, rests[1:], strict=False)]
    found: dict[str, list[tuple[int, int]]] = {k: [] for k in SECTION_KEYS}
    beside_turn = set()
    dt = data.dt
    for j, (a, b) in enumerate(moves):
        level = (rests[j][2] + rests[j + 1][2]) / 2.0
        turn = np.rad2deg(((rel[a:b] - level) * dt[a:b, None]).sum(axis=0))
        i = int(np.argmax(np.abs(turn)))
        full = abs(abs(turn[i]) - 360.0) <= turn_tolerance_deg
        if full and abs(turn[i]) >= 0.9 * np.linalg.norm(turn):
            found[f"{'xyz'[i]}_rot"].append((a, b))
            beside_turn |= {j, j + 1}
    faces: dict[str, list[tuple[int, bool]]] = {k: [] for k in FACES}
    rest_rows = []
    for j, (s, e, _) in enumerate(rests):
        s = moves[j - 1][1] if j > 0 else s + pad
        e = moves[j][0] if j < len(moves) else e - pad
        rest_rows.append((s, e))
        if e - s < 2:
            continue
        f = accel[s:e].mean(axis=0)
        i = int(np.argmax(np.abs(f)))
        if abs(f[i]) >= 0.8 * np.linalg.norm(f):
            faces[f"{'xyz'[i]}_{'p' if f[i] > 0 else 'a'}"].append((j, j in beside_turn))
    for key, rows in faces.items():
        # the rests that hold a turn's axis up count as that face only where no other does
        keep = [j for j, beside in rows if not beside] or [j for j, _ in rows]
        found[key] = [rest_rows[j] for j in keep]
    missing = [k for k in SECTION_KEYS if not found[k]]
    if missing:
        have = {k: len(v) for k, v in found.items() if v}
        clipped = saturation(data, moves or [(0, n)])
        hint = f"; {clipped} (the turns cannot be measured)" if clipped else ""
        raise ValueError(
            f"detect_sections: found no {', '.join(missing)} in {n} samples (found {have}); "
            f"pass the sections by hand, or change min_static_s / motion_threshold_dps{hint}"
        )
    return found


REST_NOISE_K = 5.0
"""A rest ends where one axis's rate, averaged over `window_s`, leaves the rest's level by
this many standard deviations of that average (measured in the rests): `detect_sections`."""
RAMP_FACTOR = 10.0
"""`detect_sections` widens a motion into each rest by as long as its rate took to rise from
`REST_NOISE_K` σ to this many times that: for a ramp ∝ t² (a smooth start) √10 − 1 = 2.2
times as long as it spent under the noise, for a ramp ∝ t 9 times, for a step nothing."""
_SIGMA_FLOOR = 1e-9
"""[rad/s]: the least window-mean noise taken (noise-free records: round-off is not motion)."""


def _still_rests(rel, smooth, coarse, w):
    """The still part of each candidate rest, `[(start, end, level (3,))]`, and the window
    mean's noise σ (3,) [rad/s]: from the rests' window means `w` samples apart (their
    difference is √2 σ, a slow ramp barely moves it), median absolute value (a ramp's part
    does not pull it), at least half the data's resolution (a quantised record's flat rest)
    and `_SIGMA_FLOOR`. A rest's level is the mode of its window means (`_mode`: where the
    rate dwells; a ramp's slow end inside the candidate passes through), its still part the
    longest run within `REST_NOISE_K` σ of it on every axis."""
    if not coarse:
        return [], np.full(3, _SIGMA_FLOOR)
    lag = w if all(e - s > w for s, e in coarse) else 1
    diffs = np.concatenate([smooth[s + lag : e] - smooth[s : e - lag] for s, e in coarse])
    steps = np.abs(np.concatenate([np.diff(rel[s:e], axis=0) for s, e in coarse]))
    resolution = np.array([np.min(c[c > 0], initial=np.inf) for c in steps.T])
    resolution[~np.isfinite(resolution)] = 0.0
    sigma = np.maximum(np.median(np.abs(diffs), axis=0) * (1.4826 / np.sqrt(2.0)), resolution / 2)
    sigma = np.maximum(sigma, _SIGMA_FLOOR)
    out = []
    for s, e in coarse:
        level = np.array([_mode(smooth[s:e, i]) for i in range(3)])
        ok = np.all(np.abs(smooth[s:e] - level) < REST_NOISE_K * sigma, axis=1)
        runs = _runs(ok)
        if runs:
            a, b = max(runs, key=lambda r: r[1] - r[0])
            if b - a >= 2:
                out.append((s + a, s + b, level))
    return out, sigma


def _mode(x: np.ndarray) -> float:
    """The half-sample mode (Bickel & Frühwirth 2006): the shortest interval holding half
    the values, again within it, down to three."""
    x = np.sort(x)
    while x.size > 3:
        h = (x.size + 1) // 2
        i = int(np.argmin(x[h - 1 :] - x[: x.size - h + 1]))
        x = x[i : i + h]
    return float(x.mean())


def _motion(smooth, sigma, before, after, pad) -> tuple[int, int]:
    """The rows `[start, end)` of the motion between two still rests `(start, end, level)`,
    widened into each by `pad` and by the time its rate took from the rest's noise to
    `RAMP_FACTOR` times it, at most to the rest's middle."""
    (s0, e0, level0), (s1, e1, level1) = before, after
    if s1 <= e0:
        return e0, e0
    z0 = np.max(np.abs(smooth[e0:s1] - level0) / sigma, axis=1)
    z1 = np.max(np.abs(smooth[e0:s1] - level1) / sigma, axis=1)
    high = RAMP_FACTOR * REST_NOISE_K
    up = np.flatnonzero(z0 >= high)
    down = np.flatnonzero(z1 >= high)
    rise = int(up[0]) if up.size else int(np.argmax(z0))
    fall = (s1 - e0 - 1 - int(down[-1])) if down.size else (s1 - e0 - 1 - int(np.argmax(z1)))
    return max(e0 - rise - pad, (s0 + e0) // 2), min(s1 + fall + pad, (s1 + e1) // 2)


class TurnCutWarning(UserWarning):
    """A turn section starts or ends while the IMU still turns
    ([`cut_turn`][hrgjax.imu.sections.cut_turn]): the section leaves out motion, and M_g is
    off by more than its σ holds (low for a turn cut short).
    `warnings.simplefilter("ignore", TurnCutWarning)` silences it."""


def cut_turn(data, sections, *, window_s: float = 0.25, walk: float = 0.0) -> str | None:
    """The first turn section that the gyro still turns beyond, as one line of text, or None.

    Over `window_s` [s] just before a turn section and just after it, the rate about the
    turn's axis should be the rest's: the gyro mean of the face that holds that axis
    vertical the same way (`x_p` or `x_a`, … by the accelerometer's sign in the turn; its
    range nearest in time), which reads the same bias, g-sensitivity and vertical Earth
    rate. A window mean more than `REST_NOISE_K` (5) σ from it is motion the section leaves
    out: a turn cut short (M_g reads low) or a settling back (high). σ: the faces' own
    `window_s` means about each face's mean (the noise as measured, coloured or white), that
    of the face mean, and a bias random walk of intensity `walk` [rad/s/√s] over the time
    between the two.

    **Arguments:** `data`: the session ([`ImuData`][hrgjax.imu.ImuData]); `sections`: as
    [`parse_sections`][hrgjax.imu.sections.parse_sections] takes them."""
    sections = parse_sections(sections, len(data))
    gyro, time, n = np.asarray(data.gyro), np.asarray(data.time), len(data)
    w = max(int(round(window_s * data.rate_hz)), 1)
    devs, dof = [], 0
    for s, e in (r for key in FACES for r in sections[key] if r[1] - r[0] >= w):
        blocks = gyro[s : s + (e - s) // w * w].reshape(-1, w, 3).mean(axis=1)
        devs.append(blocks - blocks.mean(axis=0))
        dof += max(len(blocks) - 1, 0)
    var = np.maximum(sum((d**2).sum(axis=0) for d in devs) / max(dof, 1), _SIGMA_FLOOR**2)
    for i, key in enumerate(TURNS):
        for s, e in sections[key]:
            face = f"{'xyz'[i]}_{'p' if np.asarray(data.accel)[s:e, i].mean() > 0 else 'a'}"
            for side, (a, b) in (("before", (max(s - w, 0), s)), ("after", (e, min(e + w, n)))):
                if b <= a:
                    continue
                mid = time[(a + b - 1) // 2]
                fs, fe = min(sections[face], key=lambda r: abs(time[(r[0] + r[1] - 1) // 2] - mid))
                gap = abs(time[(fs + fe - 1) // 2] - mid)
                level = gyro[fs:fe, i].mean()
                rate = gyro[a:b, i].mean() - level
                sd = np.sqrt(var[i] * (w / (b - a) + w / (fe - fs)) + walk**2 * gap)
                if abs(rate) > REST_NOISE_K * sd:
                    along = rate * (gyro[s:e, i] - level).sum() > 0  # the turn's own sense
                    span = (b - a) / data.rate_hz
                    return (
                        f"turn {key!r} rows [{s}, {e}): the gyro still turns {side} it "
                        f"({np.rad2deg(rate):+.3g} °/s about {'xyz'[i]} over {span:.3g} s, "
                        f"{abs(rate) / sd:.0f}σ of the rest noise off the {face!r} rest): the "
                        "section leaves out motion "
                        f"{'with the turn (M_g reads low)' if along else 'back (M_g reads high)'}"
                        "; widen it into the rests on either side"
                    )
    return None


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
