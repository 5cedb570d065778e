"""The other units each of [`hrgjax.plausible`][hrgjax.plausible]'s ranges names in its
message, with the factor from each to SI: a value beyond its range is most often one typed
in a datasheet's or a textbook's unit (°/h for rad/s, km for m). `hrgjax.plausible`
re-exports them."""

from __future__ import annotations

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
to SI. The rate ranges are the `imu_*` ones (`ImuModel`'s): an HRG's ARW is 10⁻⁵–10⁻² °/√h,
its bias instability 10⁻⁴–10⁻¹ °/h, far inside; an angle noise of 0.1 rad (5.7°) per sample
is far beyond any readout (1″ typed as rad is 1)."""
