"""The other units each of [`hrgjax.plausible`][hrgjax.plausible]'s ranges names in its
message, with the factor from each to SI: a value beyond its range is most often one typed
in a datasheet's or a textbook's unit (°/h for rad/s, km for m). `hrgjax.plausible`
re-exports them; and the per-run turns (`run_turns`) its unit checks of the wave and table
angles compare."""

from __future__ import annotations

import numpy as np

IMU_HINTS = {
    "imu_gyro_bias": "°/h → ×hrgjax.units.DEG_PER_H; °/s → ×hrgjax.units.DEG",
    "imu_gyro_bias_instability": "°/h → ×hrgjax.units.DEG_PER_H; °/s → ×hrgjax.units.DEG",
    "imu_accel_bias": "µg → ×hrgjax.ins.sensors.MICRO_G; mg → ×9.80665e-3",
    "imu_accel_bias_instability": "µg → ×hrgjax.ins.sensors.MICRO_G; mg → ×9.80665e-3",
    "imu_scale": "ppm → ×1e-6; % → ×1e-2",
    "imu_misalignment": "mrad → ×1e-3; µrad → ×1e-6; ° → ×hrgjax.units.DEG",
    "imu_arw": "°/√h → ×hrgjax.units.DEG_PER_SQRT_H; °/s/√Hz → ×hrgjax.units.DEG",
    "imu_vrw": (
        "µg/√Hz → ×hrgjax.ins.sensors.MICRO_G; mg/√Hz → "
        "×hrgjax.ins.sensors.MG_PER_SQRT_HZ; m/s/√h → ÷60"
    ),
    "imu_gyro_rate_random_walk": (
        "°/h/√h → ×hrgjax.units.DEG_PER_H / 60; °/h/√s → ×hrgjax.units.DEG_PER_H"
    ),
    "imu_accel_random_walk": "µg/√s → ×hrgjax.ins.sensors.MICRO_G; mg/√s → ×9.80665e-3",
}
"""The datasheet units each `imu_*` range's message names, with the factor from each to SI."""

EARTH_HINTS = {
    "gravity_mps2": "cm/s² (Gal) → ÷100; ft/s² → ×0.3048",
    "earth_radius_m": "km → ×1000",
    "earth_rate_radps": "°/h → ×hrgjax.units.DEG_PER_H; rad/h → ÷3600",
}
"""The other units an Earth model's gravity, radius and rotation rate are written in (a
textbook's 981 cm/s², 6371 km, 15.04 °/h), with the factor from each to SI: local gravity
lies in 9.78–9.83 m/s² and Earth's radius in 6.36–6.38·10⁶ m; the ranges are wide enough
for a round textbook value (g = 10, R = 6.4·10⁶ m) and a rotation rate of 0 (no Earth
rate)."""

NOISE_HINTS = {
    "noise_angle_white": "″ → ×hrgjax.units.ARCSEC; ° → ×hrgjax.units.DEG",
    "noise_arw": IMU_HINTS["imu_arw"],
    "noise_bias_instability": IMU_HINTS["imu_gyro_bias_instability"],
    "noise_run_bias": IMU_HINTS["imu_gyro_bias"],
    "noise_amplitude_white": "% → ×1e-2; ppm → ×1e-6",
}
"""The other units an [`hrgjax.Noise`][hrgjax.Noise]'s fields are written in (a datasheet's
arc-seconds of angle noise, °/√h of ARW, °/h of bias instability), with the factor from each
to SI. The rate ranges are a gyro's, narrower than the `imu_*` ones (`ImuModel`'s, sized for
a consumer IMU): an HRG's ARW is 10⁻⁵–10⁻² °/√h (≤ 2.9·10⁻⁶ rad/√s), its bias instability
10⁻⁴–10⁻¹ °/h, far inside, and a tactical or consumer MEMS gyro's 0.1–1 °/√h and 10–100 °/h
inside too, while the same HRG figures typed as SI lie beyond (`hrgjax/_plausible_ranges.py`);
an angle noise of 0.1 rad (5.7°) per sample is far beyond any readout (1″ typed as rad is 1)."""

GNSS_HINTS = {"gnss_lever_arm_m": "cm → ÷100; mm → ÷1000"}
"""The units a [`Gnss`][hrgjax.ins.gnss.Gnss] lever arm beyond a vehicle's size (100 m per
axis) is most often typed in, with the factor from each to metres."""

GYRO_HINTS = {
    "gyro_rate_bias": IMU_HINTS["imu_gyro_bias"],
    "gyro_warmup": IMU_HINTS["imu_gyro_bias"],
    "gyro_g_sensitivity": "°/h per g → ×hrgjax.units.DEG_PER_H; °/s per g → ×hrgjax.units.DEG",
    "gyro_thermal_lag": "°/h per °C → ×hrgjax.units.DEG_PER_H; °/s per °C → ×hrgjax.units.DEG",
    "gyro_temperature_rate": (
        "°/h per °C/s → ×hrgjax.units.DEG_PER_H; °/h per °C/min → ×hrgjax.units.DEG_PER_H × 60"
    ),
    "gyro_rate_cubic": "ppm per (rad/s)² → ×1e-6; per (°/s)² → ÷hrgjax.units.DEG**2",
}
"""The datasheet units of a [`hrgjax.Gyro`][hrgjax.Gyro]'s rate bias and g-sensitivity and its
[`DriftTerms`][hrgjax.DriftTerms] (equivalent input rate, SI), with the factor from each to
SI: an HRG's bias is 0.01–1 °/h, its g-sensitivity 0.005–0.05 °/h per g."""


def run_ends(run) -> tuple[np.ndarray, np.ndarray]:
    """Each run's first and last row (rows of a run may be interleaved)."""
    run = np.asarray(run)
    _, first = np.unique(run, return_index=True)
    _, last = np.unique(run[::-1], return_index=True)
    return first, run.size - 1 - last


def run_turns(numerator, denominator, run, moving, min_turn: float, min_numerator_turn=np.inf):
    """Per run (in the order of `np.unique(run)`): the numerator's and the denominator's
    change from the run's first row to its last (rows of a run may be interleaved), and
    whether the run counts: `moving`, its denominator changing by at least `min_turn` or its
    numerator by at least `min_numerator_turn` (a number, or one per run), and by > 0."""
    num, den = (np.asarray(x, dtype=float) for x in (numerator, denominator))
    first, last = run_ends(run)
    turn, num_turn = den[last] - den[first], num[last] - num[first]
    use = np.asarray(moving, bool)[first] & (turn != 0.0)
    use &= (np.abs(turn) >= min_turn) | (np.abs(num_turn) >= min_numerator_turn)
    return num_turn, turn, use


def wave_ratio_looks(k_e: float, integrated: bool) -> list[tuple[float, str, str]]:
    """The ratios Δwave/Δtable over rotation runs that a unit error gives, for a gyro of
    angular gain `k_e` (in degrees: −k_e), as `(ratio, "as … would", fix)`: a wave angle in
    radians (−k_e·π/180), a table in radians (−k_e·180/π), a table rate in °/min
    (−k_e/60, 4.5 % from radians: both are named where one is), and with `integrated` (the
    table angle is the rate's integral over `time_s`) time stamps in milliseconds or
    minutes."""
    looks = [(-k_e * np.pi / 180.0, "as an angle in radians would",
              "give the wave angle in degrees (np.degrees)"),
             (-k_e * 180.0 / np.pi, "as a table angle in radians would", "give "
              "'table_rate_dps' in °/s (and 'table_angle_deg', if given, in degrees)"),
             (-k_e / 60.0, "as a table rate in °/min (and a table angle in arc-minutes) "
              "would", "give 'table_rate_dps' in °/s (÷ 60; 'table_angle_deg' in "
              "degrees)")]  # fmt: skip
    if integrated:
        looks += [(-k_e / 1000.0, "as a table angle integrated over time stamps in "
                   "milliseconds would", "give 'time_s' in seconds"),
                  (-k_e * 60.0, "as a table angle integrated over time stamps in minutes "
                   "would", "give 'time_s' in seconds")]  # fmt: skip
    return looks


TABLE_ANGLE_HINTS = {
    np.pi / 180.0: ": it looks like radians (np.degrees)",
    180.0 / np.pi: ": it looks like 'table_rate_dps' is in rad/s",
    1.0 / 60.0: ": it looks like 'table_rate_dps' is in °/min (÷ 60)",
    1e-3: ": it looks like 'time_s' is in milliseconds (÷ 1000)",
    60.0: ": it looks like 'time_s' is in minutes (× 60)",
    1e3: ": it looks like 'table_rate_dps' is per millisecond, or 'time_s' in kiloseconds",
}
"""What a ratio of `table_angle_deg`'s turn to the integral of `table_rate_dps` (within 2 %
of a key) points at: 1/60 and π/180 are 4.5 % apart, told apart at 2 %."""
