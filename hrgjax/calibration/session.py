r"""Compensators on a bench session of their own: the session's offset apart from what the
compensation leaves.

A gyro switched on again starts with a new switch-on bias: a constant equivalent input rate,
the same at every temperature and wave angle, that no compensator fitted on another session
can know. On such a session every compensator's static residual is that change of bias
(≈ 0.43 °/h on two `hrgjax simulate --plan seed --quick` sessions, seeds 0 and 1) and says
nothing about the compensation. This module states the offset once, with its error, and
tabulates what each compensator leaves after it.

**The offset.** With a compensator, each static run $i$ of the session (table at rest
throughout, duration $T_i$) gives its mean compensated rate $r_i$ [°/h] (its
`drift_error_dph`, [`corrected_run_errors`][hrgjax.calibration.corrected_run_errors]). The
offset is their duration-weighted mean, its σ the standard error from the run-to-run
scatter in the model the weighting assumes (white rate noise: a run's variance $s^2/T_i$),

$$b = \frac{\sum_i T_i r_i}{\sum_i T_i}, \qquad
\sigma_b^2 = \frac{s^2}{\sum_i T_i}, \qquad s^2 = \frac{\sum_i T_i (r_i - b)^2}{n-1}$$

(the runs' standard deviation over $\sqrt n$ for equal runs; NaN with one static run).
$(b - \text{truth})/\sigma_b$ is Student-t with `Offset.dof` = $n - 1$ degrees of freedom
(±1σ holds 50 % with 2 runs, 58 % with 3); `Offset.half_width(level)` is the t interval's.
Where a run's error does not average down with its length (what the compensation leaves at
its temperature and wave angle) and the runs differ much in length, no σ from the scatter
sees the longest run's own error: keep the static runs equally long. σ is this session's
part only: it counts what the compensation leaves at a wave angle and temperature as
scatter (so with equal runs σ errs large) and leaves out the error of the constant each
compensator brings from its own calibration, the same on every test session. Against the
simulator's change of switch-on bias Δb (`benchmarks/session_offset.py`, 12 quick seed
sessions against one calibration, Fourier+T²): offset − Δb scattered 0.0026 °/h about its
mean against a mean σ of 0.0034 °/h, and that mean, the calibration's part, was +0.0007 °/h
(+0.0041 °/h with another calibration session): comparable to σ. σ does not say how the
offset would scatter between switch-ons: that is the bias repeatability, the size of $b$.

**One offset for the session.** Every compensator sees the same switch-on, so one value is
taken off all of them: the offset measured with the compensator whose static runs scatter
least (the smallest $\sigma_b$: it explains the grid best), or with the one named by
`offset_from` (the user knows whose constant is right: the pairs are then judged after it). Each compensator's own $b$ is reported too; its difference from the session's
is a constant the compensator brings (raw data: the mean drift). The tables remove the one
offset from all: a compensator that has a constant error keeps it. A pair's verdict does
not depend on the other compensators of the comparison: without `offset_from`, a pair whose
constants agree is judged after the offset of its own member with the smaller σ (the
session's when that member gave it; else `offsets` `"pair"`: a third compensator's
constant, taken off both, could decide the pair — with A and B 0.02 °/h apart in what they
leave, a third of +0.2 °/h constant turned "A better, p = 0.02" into "not told apart,
p = 0.7"); the temperature tables then add a row "all, X's offset".

**Different constants.** A compensator's own offset is $b_k = \Delta b + c_k$: the session's
change of switch-on bias plus the constant $c_k$ it brings from its calibration. One session
measures $c_a - c_b$ but not whose constant is right: compensators calibrated on different
switch-ons (or a self-calibration against a turntable's) differ by the change of bias
between their calibration sessions, which is no fault of either, and one offset for both
charges all of it to one (two Fourier+T² fits from seeds 1 and 3 on seed 2: own offsets
+0.3194 ± 0.0034 and +0.5143 ± 0.0033 °/h, each leaving 0.0258 and 0.0250 °/h after its own,
were "f2_s3 better, p = 1e-34", and the other way round with `offset_from` the other).
[`offset_difference`][hrgjax.calibration.Comparison.offset_difference] compares
$|b_a - b_b|$ with the paired test's resolution $R$, the smallest constant that alone
decides it (`hrgjax.calibration.paired`'s module docstring; no sampling test: the
sensor's noise cancels from $b_a - b_b$). Where $|b_a - b_b| > R$ and no `offset_from` was
named, the pair is judged after each one's own offset and the verdict says "… beyond a
constant (their constants differ by Δ; this session cannot assign it)": what each leaves
beyond a constant, the part one session can attribute. With `offset_from` named, every pair
is judged after that one offset (the constants' difference charged to the other, as the
user says). Below $R$ one offset is used (the pair's, above): the constant cannot decide the
verdict.
Own offsets remove a change of switch-on bias only to first order: it enters before the
division by the scale factor, so what is left is $\Delta b\,(1/k(\theta, T) - \overline{1/k})$,
which a paired test can still resolve (docs/calibration.md).

**After the offset** ([`corrected_run_errors`][hrgjax.calibration.corrected_run_errors] with
`offset_dph = b`): a static run's residual is $r_i - b$ [°/h]; a rotation run's end-of-run
angle error loses the angle the offset turns in the run, $b\,T_i$ (the compensated rate is
integrated over the run, so a constant rate $b$ adds $b\,T_i$ to its angle, whatever the
table does), and its largest angle error is taken after $b\,(t - t_0)$ is removed at every
sample.

**Groups.** A run's temperature is its mean temperature rounded to the nearest multiple of
`temperature_bin_c` (1 °C), its wave angle its measured start angle rounded to the nearest
multiple of `angle_bin_deg` (5°: the seed's grids are multiples of 5°, and the readout's
error at a run's start, ≤ 0.6° on `tvg3_like()`, stays inside the bin) and folded to
[−90°, 90°) electrical (θ and θ + 180° are one state of the pattern: −90° and +90° are one
group, as in `scale_factor_vs_angle` and the MLP). Each figure is the
RMS over the runs of a group: per temperature over the wave angles (the seed's accuracy
table, [`accuracy_table`][hrgjax.calibration.accuracy_table]), per wave angle over the
temperatures. Where the static runs start at several table azimuths (the absolute
`table_angle_deg` at a run's start, rounded to 5°), `format()` adds their mean residual per
azimuth and [`table_azimuth_fit`][hrgjax.calibration.table_azimuth_fit] (a rate turning with
the table: a tilted gyro axis). The **figure of merit** of a compensator is the RMS over every static run
(°/h) and every rotation run (°) after the offset.

**Told apart?** An RMS over $n$ runs carries a sampling error of about RMS/√(2n), as large as
the differences between good compensators: [`Comparison.paired`][hrgjax.calibration.Comparison.paired]
compares two run by run ([`paired_difference`][hrgjax.calibration.paired_difference]: mean
of $e_{A,i}^2 - e_{B,i}^2$, Student-t interval, "A better than B at 95 %" or "not told
apart"); `format()` and `to_json()` give it for every pair.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from typing import Any

import numpy as np

from .._warn import user_stacklevel
from ..data import MeasuredData
from ._azimuth import AzimuthFit, azimuth_groups, table_azimuth_fit
from ._compensator import AbstractCompensator, TemperatureDomainWarning
from ._grouping import nearest_multiples, wave_angle_groups
from ._offset import Offset as Offset
from ._offset import session_offset as session_offset
from ._session_report import (
    ERROR_KEY,
    UNIT,
    after_offset,
    check_arguments,
    check_same_runs,
    comparison_json,
    comparison_text,
    domain_line,
    domain_of,
    least_sigma,
    rms,
    session_figure,
    write_json,
)
from .evaluate import SEED_TABLE, check_compensators, corrected_run_errors
from .paired import OffsetDifference, PairedDifference, offset_difference, paired_difference


def _rms_groups(keys, values):
    """{key: RMS of the finite values with that key} over the sorted unique keys (NaN where
    a group has none)."""
    return {float(k): rms(values[keys == k]) for k in np.unique(keys)}


@dataclasses.dataclass(frozen=True)
class Comparison:
    """Compensators on one session (module docstring for every definition); from
    [`compare`][hrgjax.calibration.compare] or
    [`compare_corrected`][hrgjax.calibration.compare_corrected].

    - `labels`: the compensators' labels, in order; `names` ({label: compensator name}),
      `files` ({label: file or None}).
    - `offset`: the session's [`Offset`][hrgjax.calibration.Offset], removed from every
      compensator; `own_offsets`: {label: the offset measured with that compensator}.
    - `errors` ({label: per-run errors, offset kept}), `residuals` ({label: per-run errors
      after the session's offset}) and `own_residuals` ({label: after its own offset}; None:
      derived from `errors`, the largest angle errors then NaN), as
      [`corrected_run_errors`][hrgjax.calibration.corrected_run_errors] returns them.
    - `temperature_bin_c` [°C], `angle_bin_deg` [°]: the group widths; `data`: the session's
      name (a file) or None.
    - `domains`: {label: how the session stood to that compensator's calibrated temperature
      range, or None (unknown: compensated data without it, e.g. a file)}: a dict with
      `calibrated_range` ((T_min, T_max) [°C] or None), `margin_c` [°C], `extrapolated`,
      `n_samples`, `n_out_of_range`, `by_temperature` ({T [°C]: samples outside}) and `runs`
      (ids of the runs with samples outside).
    - `offset_from`: the label the user named for the session's offset (None: chosen, the
      smallest σ); named, every pair is judged after that one offset.
    - `pair_residuals`: {X: {label: per-run errors after X's own offset}} for the pairs
      judged after X's offset where that is not the session's (`offsets` `"pair"`); None or
      a missing entry: derived from `errors`, the largest angle errors then NaN.
    """

    labels: tuple[str, ...]
    names: dict
    files: dict
    offset: Offset
    own_offsets: dict
    errors: dict = dataclasses.field(repr=False)
    residuals: dict = dataclasses.field(repr=False)
    temperature_bin_c: float = 1.0
    angle_bin_deg: float = 5.0
    data: str | None = None
    own_residuals: dict | None = dataclasses.field(default=None, repr=False)
    domains: dict | None = dataclasses.field(default=None, repr=False)
    offset_from: str | None = None
    pair_residuals: dict | None = dataclasses.field(default=None, repr=False)

    def _keys(self, label, by):
        e = self.residuals[label]
        if by == "temperature":
            return nearest_multiples(e["temperature_c"], self.temperature_bin_c)
        if by == "wave_angle":
            return wave_angle_groups(e["wave_angle0_deg"], self.angle_bin_deg)
        if by == "table_azimuth":  # errors made without it (by hand): all at one azimuth
            return azimuth_groups(e.get("table_angle0_deg", np.zeros(e["run"].shape)))
        raise ValueError(f"by must be 'temperature', 'wave_angle' or 'table_azimuth'; got {by!r}")

    def figure(self, label: str, key: str, by: str = "temperature", after: bool = True) -> dict:
        """RMS of one figure per group: {T [°C] or θ [°]: RMS}.

        **Arguments:** `label` (a compensator's), `key` (one of
        [`UNIT`][hrgjax.calibration.session.UNIT]'s: `static_residual_dph` [°/h],
        `angle_error_deg` [°], `max_angle_error_deg` [°]), `by` (`"temperature"`: RMS over the
        wave angles at each temperature; `"wave_angle"`: over the temperatures at each start
        angle; `"table_azimuth"`: over the runs at each start table azimuth, [°] to
        `AZIMUTH_BIN_DEG`), `after` (False: the offset kept, as `accuracy_table`).
        """
        if key not in ERROR_KEY:
            raise ValueError(f"key must be one of {tuple(ERROR_KEY)}; got {key!r}")
        e = (self.residuals if after else self.errors)[label]
        return _rms_groups(self._keys(label, by), e[ERROR_KEY[key]])

    def groups_out_of_range(self, label: str, by: str = "temperature") -> set:
        """The groups (T [°C] or θ [°], as `figure`'s keys) holding a run with samples outside
        `label`'s calibrated temperature range (empty when none, or the range unknown)."""
        domain = (self.domains or {}).get(label)
        keys = self._keys(label, by)
        if domain is None or not len(domain["runs"]):
            return set()
        return {float(k) for k in keys[np.isin(self.residuals[label]["run"], domain["runs"])]}

    def figure_of_merit(self, label: str) -> dict:
        """{"static_residual_dph": RMS over every static run [°/h], "angle_error_deg": RMS
        over every rotation run's end-of-run error [°]}, after the offset (NaN: no such runs)."""
        e = self.residuals[label]
        return {
            "static_residual_dph": rms(e["drift_error_dph"]),
            "angle_error_deg": rms(e["angle_error_deg"]),
        }

    def offset_difference(
        self, a: str, b: str, key: str = "static_residual_dph", level: float = 0.95
    ) -> OffsetDifference | None:
        """`a`'s own offset less `b`'s [°/h] against the resolution of their paired test on
        `key` at `level` (an [`OffsetDifference`][hrgjax.calibration.OffsetDifference]:
        whether the constants' difference alone would decide it); None when the session has
        no static runs to measure them."""
        if key not in ERROR_KEY:
            raise ValueError(f"key must be one of {tuple(ERROR_KEY)}; got {key!r}")
        oa, ob = self.own_offsets[a], self.own_offsets[b]
        if not (oa.estimated and ob.estimated):
            return None
        ea, eb = (self.own_residuals_of(lab) for lab in (a, b))
        weight = None if key == "static_residual_dph" else ea["duration_s"] / 3600.0
        return offset_difference(a, oa.value_dph, b, ob.value_dph, ea[ERROR_KEY[key]],
                                 eb[ERROR_KEY[key]], weight, key=key, level=level)  # fmt: skip

    def offsets_for(
        self, a: str, b: str, key: str = "static_residual_dph", level: float = 0.95
    ) -> str:
        """Which offsets `paired(a, b, key, level)` judges after by default (module
        docstring), from `a` and `b` alone: `"session"` (the session's) when `offset_from`
        was named, or when the constants' difference is within the paired test's resolution
        and the pair's offset ([`pair_offset_from`][hrgjax.calibration.Comparison.pair_offset_from])
        is the session's; `"pair"` when within it and the session's offset was measured with
        a third compensator (the pair's then); `"own"` (each its own) when it is beyond."""
        if self.offset_from is not None:
            return "session"
        d = self.offset_difference(a, b, key, level)
        if d is not None and d.differ:
            return "own"
        source = self.own_offsets[self.pair_offset_from(a, b)]
        return "session" if source.value_dph == self.offset.value_dph else "pair"

    def pair_offset_from(self, a: str, b: str) -> str:
        """The label whose offset the pair `a`, `b` is judged after with one offset:
        `offset_from` where named, else whichever of the two has the smaller σ (the first in
        `labels` on a tie), whatever other compensators the comparison holds."""
        if self.offset_from is not None:
            return self.offset_from
        return least_sigma([lab for lab in self.labels if lab in (a, b)], self.own_offsets)

    def own_residuals_of(self, label: str) -> dict:
        """`label`'s per-run errors after its own offset (`own_residuals`' entry; derived
        from `errors` when None, the largest angle errors then NaN)."""
        if self.own_residuals is not None:
            return self.own_residuals[label]
        return after_offset(self.errors[label], self.own_offsets[label].value_dph)

    def residuals_after(self, source: str, label: str) -> dict:
        """`label`'s per-run errors after `source`'s own offset: `residuals` where that is
        the session's, `label`'s own where `source` is `label`, else `pair_residuals`' entry
        (derived from `errors` when absent, the largest angle errors then NaN)."""
        value = self.own_offsets[source].value_dph
        if value == self.offset.value_dph:
            return self.residuals[label]
        if label == source:
            return self.own_residuals_of(label)
        stored = (self.pair_residuals or {}).get(source, {}).get(label)
        return stored if stored is not None else after_offset(self.errors[label], value)

    def paired(
        self, a: str, b: str, key: str = "static_residual_dph", level: float = 0.95,
        offsets: str = "auto",
    ) -> PairedDifference:  # fmt: skip
        """Is `a`'s residual smaller than `b`'s, at `level`? The paired t test on the runs
        they share ([`paired_difference`][hrgjax.calibration.paired_difference]).

        **Arguments:** `a`, `b` (labels), `key` (one of
        [`UNIT`][hrgjax.calibration.session.UNIT]'s: `static_residual_dph` [°/h] on the static
        runs, `angle_error_deg` or `max_angle_error_deg` [°] on the rotation runs), `level`
        (two-sided confidence), `offsets` (`"session"`: after the session's offset;
        `"pair"`: after the pair's,
        [`pair_offset_from`][hrgjax.calibration.Comparison.pair_offset_from]'s; `"own"`:
        each after its own; `"auto"`: [`offsets_for`][hrgjax.calibration.Comparison.offsets_for]:
        one offset where `offset_from` was named (the session's) or the constants' difference
        is within the test's resolution at `level` (the pair's), else each its own, the
        difference charged to neither).

        **Returns:** a [`PairedDifference`][hrgjax.calibration.PairedDifference]: the mean of
        $e_{a,i}^2 - e_{b,i}^2$, its t interval and `statement()` ("… beyond a constant …"
        where judged after own offsets whose difference could decide it), with the `offsets`
        it used, their `offset_source` (the label whose offset; None: own) and the pair's
        `constants` (an [`OffsetDifference`][hrgjax.calibration.OffsetDifference] at
        `level`).
        """
        if key not in ERROR_KEY:
            raise ValueError(f"key must be one of {tuple(ERROR_KEY)}; got {key!r}")
        for lab in (a, b):
            if lab not in self.labels:
                raise ValueError(f"{lab!r} is not one of the labels {list(self.labels)}")
        if offsets not in ("auto", "session", "pair", "own"):
            raise ValueError(f"offsets must be 'auto', 'session', 'pair' or 'own'; got "
                             f"{offsets!r}")  # fmt: skip
        if offsets == "auto":
            offsets = self.offsets_for(a, b, key, level)
        source = {"session": self.offset.source or None, "own": None}.get(offsets)
        if offsets == "pair":
            source = self.pair_offset_from(a, b)
            res = lambda lab: self.residuals_after(source, lab)
        else:
            res = (lambda lab: self.residuals[lab]) if offsets == "session" else \
                self.own_residuals_of  # fmt: skip
        ea, eb = (res(lab)[ERROR_KEY[key]] for lab in (a, b))
        test = paired_difference(ea, eb, a=a, b=b, key=key, unit=UNIT[key], level=level)
        constants = self.offset_difference(a, b, key, level)
        return dataclasses.replace(test, offsets=offsets, constants=constants,
                                   offset_source=source)  # fmt: skip

    def paired_all(self, key: str = "static_residual_dph", level: float = 0.95) -> list:
        """[`paired`][hrgjax.calibration.Comparison.paired] for every pair of compensators
        (in label order, a before b): $k(k-1)/2$ tests, each at `level`."""
        return [
            self.paired(a, b, key, level)
            for i, a in enumerate(self.labels)
            for b in self.labels[i + 1 :]
        ]

    def paired_keys(self) -> list:
        """The figures the reports test pairwise: the static residual where the session has
        static runs, the end-of-run angle error where it has rotation runs."""
        counts = self.counts()
        return [k for k, kind in (("static_residual_dph", "static"),
                                  ("angle_error_deg", "rotation")) if counts[kind]]  # fmt: skip

    def before_offset(self) -> dict:
        """The seed's accuracy table with the offset kept, in
        [`accuracy_table`][hrgjax.calibration.accuracy_table]'s layout (the same numbers on
        whole-degree temperatures): {label: {"static_drift_dph" | "angle_error_deg" |
        "max_angle_error_deg": {T: RMS}}}."""
        return {
            lab: {
                "static_drift_dph": self.figure(lab, "static_residual_dph", after=False),
                "angle_error_deg": self.figure(lab, "angle_error_deg", after=False),
                "max_angle_error_deg": self.figure(lab, "max_angle_error_deg", after=False),
            }
            for lab in self.labels
        }

    @property
    def temperatures_c(self) -> list[float]:
        """Temperature groups of the session [°C], sorted."""
        keys = np.concatenate([self._keys(lab, "temperature") for lab in self.labels])
        return [float(k) for k in np.unique(keys)]

    @property
    def wave_angles_deg(self) -> list[float]:
        """Start wave-angle groups of the session [° electrical], sorted."""
        keys = np.concatenate([self._keys(lab, "wave_angle") for lab in self.labels])
        return [float(k) for k in np.unique(keys)]

    @property
    def table_azimuths_deg(self) -> list[float]:
        """Start table azimuths of the static runs with a finite residual [°, in [0, 360), to
        `AZIMUTH_BIN_DEG`], sorted: more than one where the bench logs absolute table angles
        and the static runs stand at several."""
        e = self.errors[self.labels[0]]
        ok = np.asarray(e["static"], bool) & np.isfinite(e["drift_error_dph"])
        return [float(k) for k in np.unique(self._keys(self.labels[0], "table_azimuth")[ok])]

    def azimuth_fit(self, label: str) -> AzimuthFit | None:
        """`label`'s static residuals after the offset fitted on 1, cos and sin of the start
        table azimuth ([`table_azimuth_fit`][hrgjax.calibration.table_azimuth_fit]; None with
        fewer than 3 azimuths or too narrow an arc of them, or errors without
        `table_angle0_deg`)."""
        e = self.residuals[label]
        return table_azimuth_fit(e) if "table_angle0_deg" in e else None

    def counts(self) -> dict:
        """{"static": static runs, "rotation": moving runs} of the session."""
        e = self.errors[self.labels[0]]
        n_static = int(np.sum(e["static"]))
        return {"static": n_static, "rotation": int(e["static"].size - n_static)}

    def to_json(self) -> dict:
        """The comparison as JSON-ready data (NaN as `null`; temperatures and angles as keys
        written `"-40"`, `"15"`):

        ```
        {"data": "test.csv" | null,
         "offset_dph": {"value", "sigma", "unit": "°/h", "n_static_runs", "from"},
         "temperature_bin_c", "angle_bin_deg",
         "runs": {"static": n, "rotation": n},
         "compensators": [
           {"label", "name", "file",
            "own_offset_dph": {"value", "sigma", "unit", "n_static_runs", "from"},
            "static_residual_dph": {T: RMS over wave angles, after the offset},
            "angle_error_deg": {T: …}, "max_angle_error_deg": {T: …},
            "by_wave_angle": {"static_residual_dph": {θ: RMS over temperatures},
                              "angle_error_deg": {θ: …}, "max_angle_error_deg": {θ: …}},
            "figure_of_merit": {"static_residual_dph", "angle_error_deg"},
            "before_offset": {"static_drift_dph": {T: …}, "angle_error_deg": {T: …},
                              "max_angle_error_deg": {T: …}},
            "temperature_domain": {"calibrated_range_c": [T_min, T_max] | null,
                                   "margin_c", "extrapolated", "n_samples",
                                   "n_out_of_range", "out_of_range_by_temperature": {T: n},
                                   "runs_out_of_range": [run]} | null,
            "by_table_azimuth": {"mean_static_residual_dph": {a: mean over the static runs
                                 at start table azimuth a [°], after the offset},
                                 "n_static_runs": {a: n}},
            "table_azimuth_fit": AzimuthFit.to_json() | null}],
         "seed_figures": {"static_residual_dph" | "angle_error_deg":
                          {T: {"fourier", "mlp"}}},
         "units": {"static_residual_dph": "°/h", "angle_error_deg": "°", …},
         "paired": [PairedDifference.to_json() (with "offsets": "session" | "pair" | "own",
                    "offset_source", "constants_differ", "constant_difference_dph",
                    "constant_resolution_dph") for every pair, static residual then end-of-run
                    angle error, where the session has such runs; with "pair" or "own", also
                    "with_one_offset": the test after the session's],
         "offset_from": the label named for the offset, or null (chosen),
         "offset_differences": [OffsetDifference.to_json() for every pair and figure]}
        ```

        `seed_figures` are seed 000's published figures
        ([`SEED_TABLE`][hrgjax.calibration.evaluate.SEED_TABLE]: its Fourier base algorithm
        and its network), to read beside each temperature's figures. `temperature_domain`
        null: the compensated data carried no domain (a file).
        """
        return comparison_json(self)

    def write_json(self, path: str | os.PathLike) -> str:
        """Write [`to_json`][hrgjax.calibration.Comparison.to_json] to `path` (atomically,
        folders made); returns the path."""
        return write_json(self, path)

    def format(self, by_wave_angle: bool = True) -> str:
        """The comparison as text: the offset (and, where two compensators' own offsets
        differ, that they carry different constants), the samples outside each compensator's
        calibrated temperature range, then per temperature (with seed 000's figures beside)
        and, with `by_wave_angle`, per start wave angle, the static residual [°/h] and the
        rotation runs' end-of-run angle error [°] after the offset (`*`: a group with runs
        outside the range); tables of kinds of run the session lacks are left out; with
        several compensators, last, the paired comparison of every pair
        ([`paired`][hrgjax.calibration.Comparison.paired])."""
        return comparison_text(self, by_wave_angle)

    def __str__(self) -> str:
        return self.format()

    def plot(self, path: str | os.PathLike, title: str = "", seed: dict | None = SEED_TABLE) -> str:
        """Figure of the residuals after the offset per temperature and per wave angle, one
        marker and colour per compensator (hollow: groups with runs outside its calibrated
        temperature range), `seed`'s figures beside (default seed 000's,
        [`SEED_TABLE`][hrgjax.calibration.evaluate.SEED_TABLE]; None: none), the offset in a
        text box; returns the path."""
        return session_figure(self, os.fspath(path), title=title, seed=seed)


def compare_corrected(
    corrected: dict[str, MeasuredData],
    *,
    names: dict | None = None,
    files: dict | None = None,
    offset_from: str | None = None,
    temperature_bin_c: float = 1.0,
    angle_bin_deg: float = 5.0,
    data: str | None = None,
) -> Comparison:
    """Compare compensators from their compensated data of one session.

    **Arguments:**

    - `corrected`: {label: the session compensated by that compensator} (the output of
      [`correct`][hrgjax.calibration.AbstractCompensator.correct], or a file written by
      `hrgjax correct`); every entry holds the same runs.
    - `names`, `files`: {label: compensator name}, {label: its file} (default: the label,
      None).
    - `offset_from`: the label whose offset is the session's (default: the one with the
      smallest σ; module docstring). Named, every pair is judged after it, whatever the
      constants' difference (`Comparison.offset_from`).
    - `temperature_bin_c` [°C], `angle_bin_deg` [°]: group widths (module docstring).
    - `data`: the session's name, kept for reports.

    **Returns:** a [`Comparison`][hrgjax.calibration.Comparison].

    **Raises:** `ValueError` when `corrected` is empty, `offset_from` is not a label, a bin
    width is not > 0, or the entries do not hold the same runs of one session (run ids, and
    each run's start and end time, duration, mean temperature and wave angle at its start and
    end, equal to round-off: the first run that differs is named).
    """
    labels = check_arguments(corrected, offset_from, temperature_bin_c, angle_bin_deg)
    errors = {lab: corrected_run_errors(corrected[lab]) for lab in labels}
    check_same_runs(corrected, errors)
    own = {lab: session_offset(errors[lab], lab) for lab in labels}
    offset_named = offset_from is not None
    if offset_from is None:
        offset_from = least_sigma(labels, own)
    offset = own[offset_from]
    after = lambda lab, b: corrected_run_errors(corrected[lab], offset_dph=b.value_dph)
    residuals = {lab: after(lab, offset) for lab in labels}
    own_residuals = {lab: residuals[lab] if own[lab] == offset else after(lab, own[lab])
                     for lab in labels}  # fmt: skip
    pair: dict = {}  # a pair judged after its member's offset, not the session's
    for i, a in enumerate(labels if not offset_named else ()):
        for b in labels[i + 1 :]:
            src = least_sigma((a, b), own)
            if own[src].value_dph != offset.value_dph:
                other = b if src == a else a
                pair.setdefault(src, {})[other] = after(other, own[src])
    named = offset_from if offset_named else None
    return Comparison(
        labels=labels,
        names={lab: (names or {}).get(lab, lab) for lab in labels},
        files={lab: (files or {}).get(lab) for lab in labels},
        offset=offset,
        own_offsets=own,
        errors=errors,
        residuals=residuals,
        temperature_bin_c=float(temperature_bin_c),
        angle_bin_deg=float(angle_bin_deg),
        data=data,
        own_residuals=own_residuals,
        domains={lab: domain_of(corrected[lab], temperature_bin_c) for lab in labels},
        offset_from=named,
        pair_residuals=pair,
    )


def compare(
    compensators: dict[str, AbstractCompensator],
    data: MeasuredData,
    *,
    files: dict | None = None,
    offset_from: str | None = None,
    temperature_bin_c: float = 1.0,
    angle_bin_deg: float = 5.0,
    name: str | None = None,
    warn: bool = True,
) -> Comparison:
    """Several compensators on one test session: the session's offset, and per temperature
    and wave angle what each compensator leaves after it (module docstring).

    **Arguments:**

    - `compensators`: {label: fitted compensator}.
    - `data`: the session (static and/or rotation runs), not yet corrected.
    - `files`: {label: the compensator's file}, kept for reports.
    - `offset_from`, `temperature_bin_c` [°C], `angle_bin_deg` [°]: as in
      [`compare_corrected`][hrgjax.calibration.compare_corrected].
    - `name`: the session's name (a file), kept for reports.
    - `warn`: False: no warning (a caller that applies compensators outside their range on
      purpose; the result records it either way).

    **Warns:** [`TemperatureDomainWarning`][hrgjax.calibration.TemperatureDomainWarning], one
    per compensator the session has samples outside the calibrated temperature range of
    (the result keeps them: `domains`, `to_json`, `format`, `plot`).

    **Returns:** a [`Comparison`][hrgjax.calibration.Comparison]; its
    `before_offset()` equals [`accuracy_table`][hrgjax.calibration.accuracy_table]`(compensators,
    data)` on whole-degree temperatures.
    """
    check_compensators("compare", compensators)
    # one warning per compensator below, naming its label
    corrected = {lab: comp.correct(data, warn=False) for lab, comp in compensators.items()}
    result = compare_corrected(
        corrected,
        names={lab: _name(comp) for lab, comp in compensators.items()},
        files=files,
        offset_from=offset_from,
        temperature_bin_c=temperature_bin_c,
        angle_bin_deg=angle_bin_deg,
        data=name,
    )
    for lab in result.labels if warn else ():
        if result.domains[lab] and (line := domain_line(lab, result.domains[lab])):
            warnings.warn(f"compare: {line}", TemperatureDomainWarning,
                          stacklevel=user_stacklevel())  # fmt: skip
    return result


def _name(comp: Any) -> str:
    name = getattr(comp, "name", None)
    return name if isinstance(name, str) else type(comp).__name__
