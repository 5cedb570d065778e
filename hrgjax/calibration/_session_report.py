"""A [`Comparison`][hrgjax.calibration.Comparison] as a report: its JSON, its text and its
figure (the definitions are [`session`][hrgjax.calibration.session]'s module docstring).

Two caveats travel with every form of the report, not only the CLI's stdout:

- **different constants**: a pair whose own offsets differ by more than could decide their
  paired test alone ([`OffsetDifference`][hrgjax.calibration.OffsetDifference]) is judged
  after each one's own offset, "beyond a constant" (after the one offset where
  `offset_from` was named), and the report says so;
- **the temperature domain**: each compensator's calibrated range and the samples of the
  session outside it (its `temperature_domain`); the tables mark a group holding such runs
  with `*`, the figure draws it hollow.

It also holds what `compare_corrected` builds a comparison with: its arguments' checks
(`check_arguments`, and `check_same_runs`: every entry compensates one session's runs), the least-σ choice of an offset
(`least_sigma`), residuals after another offset (`after_offset`) and the domains.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping

import numpy as np

from ._azimuth import AZIMUTH_MIN_SPREAD, azimuth_groups, azimuth_spread, static_azimuths
from ._compensator import Corrected
from .evaluate import SEED_TABLE

UNIT = {"static_residual_dph": "°/h", "angle_error_deg": "°", "max_angle_error_deg": "°"}
"""The figures [`Comparison`][hrgjax.calibration.Comparison] tabulates and their units:
static residual rate after the offset, end-of-run angle error of rotation runs after it, and
the largest angle error during a rotation run after it."""
ERROR_KEY = {
    "static_residual_dph": "drift_error_dph",
    "angle_error_deg": "angle_error_deg",
    "max_angle_error_deg": "max_angle_error_deg",
}
"""Figure → its column of [`corrected_run_errors`][hrgjax.calibration.corrected_run_errors]."""
SEED_KEY = {"static_residual_dph": "static_drift_dph", "angle_error_deg": "angle_error_deg"}
"""Figure → its row of [`SEED_TABLE`][hrgjax.calibration.evaluate.SEED_TABLE]."""
CONSTANTS_NOTE = "the compensators carry different constants (calibrated on different switch-ons?)"
"""What the report says of a pair whose own offsets differ by more than could decide their
paired test alone (`OffsetDifference.differ`)."""


def rms(values) -> float:
    """RMS of the finite values (NaN when none)."""
    v = values[np.isfinite(values)]
    return float(np.sqrt(np.mean(v**2))) if v.size else math.nan


def json_number(x):
    """JSON number: NaN and ±inf as null."""
    return float(x) if math.isfinite(x) else None


def keyed(d: dict) -> dict:
    """{T or θ: value} → {"-40": value}: JSON keys as the shortest decimal."""
    return {f"{k:g}": json_number(v) for k, v in d.items()}


def domain_json(domain: dict | None) -> dict | None:
    """A compensator's temperature domain on the session (`Comparison.domains` entry) as
    JSON: `{"calibrated_range_c": [T_min, T_max] | null (unknown), "margin_c",
    "extrapolated", "n_samples", "n_out_of_range", "out_of_range_by_temperature": {T: n},
    "runs_out_of_range": [run ids]}`; None when the data carried no domain (a file)."""
    if domain is None:
        return None
    span = domain["calibrated_range"]
    return {
        "calibrated_range_c": None if span is None else [float(span[0]), float(span[1])],
        "margin_c": float(domain["margin_c"]),
        "extrapolated": bool(domain["extrapolated"]),
        "n_samples": int(domain["n_samples"]),
        "n_out_of_range": int(domain["n_out_of_range"]),
        "out_of_range_by_temperature": {
            f"{t:g}": int(n) for t, n in domain["by_temperature"].items()
        },
        "runs_out_of_range": [int(r) for r in domain["runs"]],
    }


def check_arguments(corrected, offset_from, temperature_bin_c, angle_bin_deg) -> tuple:
    """`compare_corrected`'s arguments checked (one-line errors); returns the labels."""
    if not isinstance(corrected, Mapping):
        raise TypeError(f"compare_corrected: corrected must be a dict {{label: compensated "
                        f"data}}; got {type(corrected).__name__}")  # fmt: skip
    labels = tuple(corrected)
    if not labels:
        raise ValueError("give at least one compensator")
    for name, width in (("temperature_bin_c", temperature_bin_c), ("angle_bin_deg", angle_bin_deg)):
        number = isinstance(width, int | float | np.integer | np.floating) and not isinstance(
            width, bool | np.bool_
        )
        if not number or not width > 0 or not math.isfinite(width):
            raise ValueError(f"{name} must be a number > 0; got {width!r}")
    if offset_from is not None and offset_from not in labels:
        raise ValueError(f"offset_from {offset_from!r} is not one of the labels {list(labels)}")
    return labels


def least_sigma(labels, own: dict) -> str:
    """The label among `labels` whose [`Offset`][hrgjax.calibration.Offset] in `own` has the
    smallest σ (the first on a tie; the first label when no σ is finite)."""
    sig = np.array([own[lab].sigma_dph for lab in labels], float)
    return labels[int(np.nanargmin(sig))] if np.any(np.isfinite(sig)) else labels[0]


def after_offset(errors: dict, value_dph: float) -> dict:
    """Per-run errors taken with no offset (`corrected_run_errors`' output) after an offset
    [°/h], derived: the static rates less it, the end-of-run angles less it times the run's
    duration; the largest angle errors NaN (they need the samples)."""
    e = errors
    return {**e, "drift_error_dph": e["drift_error_dph"] - value_dph,
            "angle_error_deg": e["angle_error_deg"] - value_dph * e["duration_s"] / 3600.0,
            "max_angle_error_deg": np.full(e["run"].shape, np.nan)}  # fmt: skip


RUN_FIELDS = (("start time", "s"), ("end time", "s"), ("duration", "s"),
              ("mean temperature", "°C"), ("start wave angle", "°"),
              ("end wave angle", "°"))  # fmt: skip
"""What [`compare_corrected`][hrgjax.calibration.compare_corrected] compares run by run: one
session's rows give every entry the same values."""


def check_same_runs(corrected: dict, errors: dict) -> None:
    """Refuse, in one line, compensated data that are not one session's: other run ids than
    the first entry's, or a run whose start or end time [s], duration [s], mean temperature
    [°C] or measured wave angle at its start or end [°] differs from its by more than
    round-off (the first such run and what differs are named; one session's rows are equal,
    `correct` keeps them). `errors`: each entry's `corrected_run_errors`."""
    first = None
    for lab, data in corrected.items():
        idx, t, wave = data.run_indices(), data["time_s"], data["wave_angle_deg"]
        e = errors[lab]
        values = (np.array([t[i[0]] for i in idx]), np.array([t[i[-1]] for i in idx]),
                  e["duration_s"], e["temperature_c"], e["wave_angle0_deg"],
                  np.array([wave[i[-1]] for i in idx]))  # fmt: skip
        if first is None:
            first = (lab, e["run"], values)
            continue
        if not np.array_equal(e["run"], first[1]):
            raise ValueError(f"{lab!r}: compensated data hold other runs than {first[0]!r}'s")
        for (what, unit), ours, theirs in zip(RUN_FIELDS, values, first[2], strict=True):
            bad = ~np.isclose(ours, theirs, rtol=1e-9, atol=1e-9, equal_nan=True)
            if bad.any():
                k = int(np.flatnonzero(bad)[0])
                raise ValueError(
                    f"{lab!r}: run {int(e['run'][k])} differs from that of {first[0]!r}: {what} "
                    f"{ours[k]:.10g} {unit} against {theirs[k]:.10g} {unit} (compensated data "
                    "of another session? every entry must compensate the same session)"
                )


def domain_of(corrected, bin_c: float) -> dict | None:
    """`Comparison.domains`' entry from `correct`'s output (None: plain data, no domain)."""
    if not isinstance(corrected, Corrected):
        return None
    outside = ~corrected.in_range
    return {
        "calibrated_range": corrected.temperature_range,
        "margin_c": corrected.margin_c,
        "extrapolated": corrected.extrapolated,
        "n_samples": len(corrected),
        "n_out_of_range": corrected.n_out_of_range,
        "by_temperature": corrected.out_of_range_by_temperature(bin_c),
        "runs": np.unique(corrected.run[outside]),
    }


def domain_line(label: str, domain: dict) -> str | None:
    """One line on the samples outside the calibrated range (None: none outside, or the
    range unknown): the CLI's wording."""
    span = domain["calibrated_range"]
    if span is None or not domain["n_out_of_range"]:
        return None
    where = ", ".join(f"{n} at {t:+g} °C" for t, n in domain["by_temperature"].items())
    how = ("extrapolated (the model applied beyond its range)" if domain["extrapolated"]
           else "passed through uncompensated")  # fmt: skip
    return (f"{label}: {domain['n_out_of_range']} samples outside the calibrated temperature "
            f"range {span[0]:+.1f} … {span[1]:+.1f} °C (± {domain['margin_c']:g} °C): {where} "
            f"— {how}")  # fmt: skip


def comparison_json(c) -> dict:
    """[`Comparison.to_json`][hrgjax.calibration.Comparison.to_json]'s body."""
    comps = []
    for lab in c.labels:
        by_angle = {k: keyed(c.figure(lab, k, "wave_angle")) for k in UNIT}
        before = {k: keyed(v) for k, v in c.before_offset()[lab].items()}
        comps.append(
            {
                "label": lab,
                "name": c.names[lab],
                "file": c.files.get(lab),
                "own_offset_dph": c.own_offsets[lab].to_json(),
                **{k: keyed(c.figure(lab, k)) for k in UNIT},
                "by_wave_angle": by_angle,
                "figure_of_merit": {k: json_number(v) for k, v in c.figure_of_merit(lab).items()},
                "before_offset": before,
                "temperature_domain": domain_json((c.domains or {}).get(lab)),
                "by_table_azimuth": {
                    "mean_static_residual_dph": {
                        f"{a:g}": json_number(m) for a, (m, _) in azimuth_means(c, lab).items()
                    },
                    "n_static_runs": {f"{a:g}": n for a, (_, n) in azimuth_means(c, lab).items()},
                },
                "table_azimuth_fit": None if (f := c.azimuth_fit(lab)) is None else f.to_json(),
            }
        )
    seed = {
        ours: {f"{t:g}": {"fourier": v[0], "mlp": v[1]} for t, v in SEED_TABLE[k].items()}
        for ours, k in SEED_KEY.items()
    }
    paired = []
    for key in c.paired_keys():
        for i, a in enumerate(c.labels):
            for b in c.labels[i + 1 :]:
                entry = c.paired(a, b, key).to_json()
                if entry["offsets"] != "session":  # the session's offset's verdict, for reference
                    entry["with_one_offset"] = c.paired(a, b, key, offsets="session").to_json()
                paired.append(entry)
    return {
        "data": c.data,
        "offset_dph": c.offset.to_json(),
        "temperature_bin_c": c.temperature_bin_c,
        "angle_bin_deg": c.angle_bin_deg,
        "runs": c.counts(),
        "compensators": comps,
        "seed_figures": seed,
        "units": dict(UNIT),
        "paired": paired,
        "offset_from": c.offset_from,
        "offset_differences": [d.to_json() for d in offset_differences(c)],
    }


def offset_differences(c, level: float = 0.95) -> list:
    """Every pair's [`OffsetDifference`][hrgjax.calibration.OffsetDifference] on every
    figure the reports test (`paired_keys`; none without static runs)."""
    return [d for key in c.paired_keys() for i, a in enumerate(c.labels)
            for b in c.labels[i + 1 :]
            if (d := c.offset_difference(a, b, key, level)) is not None]  # fmt: skip


def pair_sources(c, key: str, level: float = 0.95) -> list:
    """The labels whose offset some pair is judged after on `key` at `level` where that is not
    the session's (`offsets` `"pair"`), in label order."""
    used = {c.pair_offset_from(a, b) for i, a in enumerate(c.labels) for b in c.labels[i + 1 :]
            if c.offsets_for(a, b, key, level) == "pair"}  # fmt: skip
    return [lab for lab in c.labels if lab in used]


def differ_any(c) -> bool:
    """Whether some pair's constants differ by more than could decide its paired test at
    95 %."""
    return any(d.differ for d in offset_differences(c))


def _table(c, key, by, title):
    unit = UNIT[key]
    head = "T [°C]" if by == "temperature" else "θ [°]"
    seed = SEED_TABLE.get(SEED_KEY.get(key, ""), {}) if by == "temperature" else {}
    width = max(12, *(len(lab) + 1 for lab in c.labels))
    figures = {lab: c.figure(lab, key, by) for lab in c.labels}
    marked = {lab: c.groups_out_of_range(lab, by) for lab in c.labels}
    mark = any(marked.values())  # a column of marks only where a group has one

    def cell(lab, g):
        v = figures[lab].get(g, math.nan)
        if not mark:
            return f"{v:>{width}.4g}"
        return f"{v:>{width - 1}.4g}" + ("*" if g in marked[lab] else " ")

    groups = c.temperatures_c if by == "temperature" else c.wave_angles_deg
    rows = [f"{title} [{unit}]" + (" (*: runs outside the calibrated range)" if mark else "")]
    alls = []  # every run, after the offset (each its own where constants differ; a pair's
    if by == "temperature":  # where it judged a pair) and with it kept
        alls = [("all", c.residuals)]
        if differ_any(c):
            alls.append(("all, own offset", {lab: c.own_residuals_of(lab) for lab in c.labels}))
        alls += [(f"all, {src}'s offset", {lab: c.residuals_after(src, lab) for lab in c.labels})
                 for src in pair_sources(c, key)]  # fmt: skip
        alls.append(("all, offset kept", c.errors))
    w0 = max(16, *(len(name) for name, _ in alls)) if alls else 7  # "all, offset kept"
    line = f"{head:>{w0}} " + " ".join(f"{lab:>{width}}" for lab in c.labels)
    rows.append(line + (f" {'seed Fourier':>13} {'seed MLP':>9}" if seed else ""))
    for g in groups:
        row = f"{g:>{w0}g} " + " ".join(cell(lab, g) for lab in c.labels)
        if g in seed:
            row += f" {seed[g][0]:>13.3g} {seed[g][1]:>9.3g}"
        rows.append(row)
    for name, e in alls:
        cells = (rms(e[lab][ERROR_KEY[key]]) for lab in c.labels)
        rows.append(f"{name:>{w0}} " + " ".join(f"{v:>{width}.4g}" for v in cells))
    return rows


MAX_AZIMUTH_ROWS = 12
"""More start azimuths than this: the text gives the cos/sin fit without a row each."""
AZIMUTH_NOTE = ("a resolved term is a rate turning with the table: the gyro's axis tilted "
                "from the table's (the horizontal Earth rate Ω cos φ sin δ, 0.186 °/h at 1° and "
                "45° N), or a drift with the lateral specific force on a tilted table")  # fmt: skip
"""What the text says a resolved cos/sin(azimuth) term names."""


def azimuth_means(c, label: str) -> dict:
    """{start table azimuth [°]: (mean static residual after the offset [°/h], runs)} over the
    static runs with a finite residual (NaN and 0 where an azimuth has none for `label`)."""
    e = c.residuals[label]
    keys = azimuth_groups(e.get("table_angle0_deg", np.zeros(e["run"].shape)))
    d = np.asarray(e["drift_error_dph"], float)
    ok = np.asarray(e["static"], bool) & np.isfinite(d)
    out = {}
    for a in c.table_azimuths_deg:
        sel = ok & (keys == a)
        out[float(a)] = (float(np.mean(d[sel])) if sel.any() else math.nan, int(sel.sum()))
    return out


def _no_fit_reason(c) -> str:
    """Why no compensator has an azimuth fit: too few azimuths, or too narrow an arc."""
    e = c.residuals[c.labels[0]]
    if "table_angle0_deg" in e:
        az, _, w = static_azimuths(e)
        spread = azimuth_spread(az, w)
        if np.unique(azimuth_groups(az)).size >= 3 and spread < AZIMUTH_MIN_SPREAD:
            return (f"  (no cos/sin fit: the start azimuths span too narrow an arc, spread "
                    f"{spread:.2g} < {AZIMUTH_MIN_SPREAD:g}; 0.5 spread evenly round the "
                    "turn)")  # fmt: skip
    return "  (a cos/sin fit needs static runs at 3 azimuths or more)"


def _azimuth_table(c) -> list[str]:
    """The static residual by start table azimuth (mean, signed) and each compensator's
    cos/sin(azimuth) fit, where the static runs stand at two azimuths or more."""
    width = max(12, *(len(lab) + 1 for lab in c.labels))
    means = {lab: azimuth_means(c, lab) for lab in c.labels}
    rows = ["static residual after the offset by start table azimuth, mean over the runs [°/h]"]
    azimuths = c.table_azimuths_deg
    if len(azimuths) <= MAX_AZIMUTH_ROWS:
        rows.append(f"{'az [°]':>7} " + " ".join(f"{lab:>{width}}" for lab in c.labels)
                    + f" {'runs':>5}")  # fmt: skip
        for a in azimuths:
            n = means[c.labels[0]][a][1]
            rows.append(f"{a:>7g} " + " ".join(f"{means[lab][a][0]:>+{width}.4f}"
                                               for lab in c.labels) + f" {n:>5d}")  # fmt: skip
    else:
        rows.append(f"  ({len(azimuths)} start azimuths: the fit only)")
    fits = {lab: c.azimuth_fit(lab) for lab in c.labels}
    if all(f is None for f in fits.values()):
        rows.append(_no_fit_reason(c))
        return rows
    rows.append("cos/sin fit on the start azimuth a, r = m + c·cos a + s·sin a "
                "(duration-weighted; σ from the runs' scatter):")  # fmt: skip
    rows += [f"  {lab}: {f}" for lab, f in fits.items() if f is not None]
    if any(f is not None and f.resolved() for f in fits.values()):
        rows.append(f"  {AZIMUTH_NOTE}")
    return rows


def comparison_text(c, by_wave_angle: bool = True) -> str:
    """[`Comparison.format`][hrgjax.calibration.Comparison.format]'s body."""
    counts = c.counts()
    src = f" with {c.offset.source}" if c.offset.source else ""
    lines = [f"session offset{src}: {c.offset}"]
    if c.offset.estimated:
        lines.append(
            "  (duration-weighted mean compensated rate of the static runs, taken off every "
            "compensator below;\n   σ: this session's run-to-run scatter, without the error "
            "of the constant a compensator brings from its calibration)"
        )
    if len(c.labels) > 1:
        lines.append("  each compensator's own mean rate at rest:")
        for lab in c.labels:
            lines.append(f"    {lab:<{max(map(len, c.labels))}}  {c.own_offsets[lab]}")
    differ = [d for d in offset_differences(c) if d.differ]
    if differ:
        lines.append(f"  {CONSTANTS_NOTE}:")
        lines += [f"    {d}" for d in differ]
        lines.append("   this session cannot say whose constant is right (a change of switch-on "
                     "bias looks the same):")  # fmt: skip
        if c.offset_from is None:
            lines.append("   those pairs are told apart beyond a constant, each after its own "
                         "offset; the tables keep the one offset (and add 'all, own offset')")  # fmt: skip
        else:
            lines.append(f"   the offset is {c.offset_from}'s, as named: every pair is judged "
                         "after it, the constants' difference charged to the other")  # fmt: skip
    domain = [s for lab in c.labels if (s := domain_line(lab, (c.domains or {}).get(lab) or
                                                          {"calibrated_range": None}))]  # fmt: skip
    if domain:
        lines.append("  temperature domain:")
        lines += [f"    {s}" for s in domain]
    lines.append("")
    tables = []
    if counts["static"]:
        tables.append(("static_residual_dph", "temperature",
                       "static residual after the offset, RMS over wave angles"))  # fmt: skip
    if counts["rotation"]:
        tables.append(("angle_error_deg", "temperature",
                       "end-of-run angle error of the rotation runs after the offset "
                       "(offset × duration removed), RMS over wave angles"))  # fmt: skip
    if by_wave_angle and counts["static"]:
        tables.append(("static_residual_dph", "wave_angle",
                       "static residual after the offset by start wave angle, RMS over "
                       "temperatures"))  # fmt: skip
    if by_wave_angle and counts["rotation"]:
        tables.append(("angle_error_deg", "wave_angle",
                       "end-of-run angle error after the offset by start wave angle, RMS "
                       "over temperatures"))  # fmt: skip
    one_run = c.offset.estimated and c.offset.n_runs == 1 and c.offset.source
    for key, by, title in tables:
        lines += _table(c, key, by, title)
        if one_run and key == "static_residual_dph":  # its 0 read as a win
            lines.append(f"  (one static run: the offset is {c.offset.source}'s mean rate on it, "
                         f"so {c.offset.source}'s static residual is 0 by construction; static "
                         "runs tell compensators apart from two on)")  # fmt: skip
        lines.append("")
    if len(c.table_azimuths_deg) > 1:
        lines += _azimuth_table(c) + [""]
    for key in c.paired_keys() if len(c.labels) > 1 else []:
        what = "static residual" if key == "static_residual_dph" else "end-of-run angle error"
        lines.append(f"told apart? {what} after the offset, paired on the shared runs "
                     "(mean of e_A² − e_B², t interval):")  # fmt: skip
        for i, a in enumerate(c.labels):
            for b in c.labels[i + 1 :]:
                lines.append(f"  {c.paired(a, b, key)}")
                how = c.offsets_for(a, b, key)
                one = c.paired(a, b, key, offsets="session").statement() if how != "session" \
                    else ""  # fmt: skip
                if how == "own":
                    lines.append(f"    (after each one's own offset; with the one offset: "
                                 f"{one!r}, the constants' difference charged to one)")  # fmt: skip
                elif how == "pair":
                    src = c.pair_offset_from(a, b)
                    lines.append(f"    (after {src}'s offset, the pair's: row 'all, {src}'s "
                                 f"offset'; with the session's, {c.offset.source}'s: {one!r}, "
                                 f"{c.offset.source}'s constant charged to both)")  # fmt: skip
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def write_json(c, path: str | os.PathLike) -> str:
    """[`Comparison.write_json`][hrgjax.calibration.Comparison.write_json]'s body."""
    import json

    from .._io import atomic_write

    with atomic_write(path, "w", encoding="utf-8") as fh:
        fh.write(json.dumps(c.to_json(), indent=2, ensure_ascii=False))
    return os.fspath(path)


def session_figure(c, path: str, title: str = "", seed: dict | None = SEED_TABLE) -> str:
    """Compensators on one session, after its offset: the static residual [°/h] (top row)
    and the rotation runs' end-of-run angle error [°] (bottom row), RMS per temperature
    (left; seed 000's figures as black stars and crosses) and per start wave angle (right),
    one marker and colour per compensator, hollow where the group holds runs outside that
    compensator's calibrated temperature range; the session's offset ± σ in a text box. A
    row for a kind of run the session lacks is left out; saves `path`. `seed`: the table of
    figures to mark ([`SEED_TABLE`][hrgjax.calibration.evaluate.SEED_TABLE]; None: no
    marks)."""
    from ..plots import pyplot, save

    plt = pyplot()
    counts = c.counts()
    rows = [(key, f"{what} after the offset [{UNIT[key]}]", SEED_KEY[key])
            for key, what, n in (("static_residual_dph", "static residual", counts["static"]),
                                 ("angle_error_deg", "end-of-run angle error", counts["rotation"]))
            if n]  # fmt: skip
    fig, axes = plt.subplots(len(rows), 2, figsize=(11, 3.6 * len(rows) + 0.8),
                             constrained_layout=True, squeeze=False)  # fmt: skip
    markers = "osD^vP X<>"
    colours = plt.get_cmap("tab10")
    hollow = False
    for r, (key, ylabel, seed_key) in enumerate(rows):
        for col, by in enumerate(("temperature", "wave_angle")):
            ax = axes[r, col]
            values = []
            for i, lab in enumerate(c.labels):
                fig_ = c.figure(lab, key, by)
                xs = np.array(sorted(fig_))
                ys = np.array([fig_[x] for x in xs])
                values.extend(ys[np.isfinite(ys) & (ys > 0)])
                style = dict(marker=markers[i % len(markers)], ms=5, color=colours(i % 10))
                ax.plot(xs, ys, ls="-", lw=1, label=lab, **style)
                out = np.isin(xs, sorted(c.groups_out_of_range(lab, by)))
                if out.any():  # outside the calibrated range: hollow
                    hollow = True
                    ax.plot(xs[out], ys[out], ls="none", mfc="white", **style)
            if by == "temperature":
                for j, (name, marker) in enumerate((("seed Fourier", "*"), ("seed MLP", "x"))):
                    pts = {} if seed is None else seed.get(seed_key, {})
                    if not pts:
                        continue

                    ax.plot(list(pts), [v[j] for v in pts.values()], marker, ms=10, ls="none",
                            color="k", label=name)  # fmt: skip
                    values.extend(v[j] for v in pts.values())
                ax.set_xlabel("temperature [°C]")
            else:
                ax.set_xlabel("start wave angle [° electrical]")
            if values and max(values) > 30 * min(values):
                ax.set_yscale("log")
            ax.set_ylabel(ylabel if col == 0 else "")
            ax.set_title(("RMS over wave angles" if by == "temperature" else
                          "RMS over temperatures"), fontsize=9)  # fmt: skip
            ax.grid(alpha=0.3, which="both")
    handles, names = axes[0, 0].get_legend_handles_labels()  # the same in every panel
    fig.legend(handles, names, loc="outside lower center", fontsize=8, ncol=min(len(names), 4))
    off = c.offset
    head = title or f"{c.data or 'test session'}: what the compensation leaves"
    text = f"session offset{' (with ' + off.source + ')' if off.source else ''}: {off}"
    if off.estimated:
        text += ", taken off every compensator"
    if hollow:
        text += "\nhollow: groups with runs outside the compensator's calibrated temperature range"
    if differ_any(c):
        text += f"\n{CONSTANTS_NOTE}: see the report"
    fig.suptitle(f"{head}\n{text}", fontsize=10)
    return save(fig, path, dpi=110)
