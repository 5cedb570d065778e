"""The default ranges of [`hrgjax.plausible`][hrgjax.plausible]: (low, high, unit) of each
quantity it knows, and why each bound lies where it does. `hrgjax.plausible.RANGES` is what is
in force (these, with a `relaxed` block's on top); the units a value beyond a range is most
often typed in are `hrgjax._unit_hints`'."""

from __future__ import annotations

DEFAULTS: dict[str, tuple[float, float, str]] = {
    "temperature_c": (-100.0, 150.0, "°C"),
    "table_rate_dps": (-3600.0, 3600.0, "°/s"),
    "wave_angle_deg": (-1e7, 1e7, "° electrical"),
    "duration_s": (0.0, 30 * 86400.0, "s"),
    "wave_step_deg": (0.0, 5.0, "° electrical"),
    "wave_drift_dph": (0.0, 100.0, "°/h electrical"),
    "wave_table_ratio": (0.05, 2.0, "(|Δwave/Δtable|: k_e, electrical)"),
    "speed_mps": (0.0, 10_000.0, "m/s"),
    "median_specific_force_mps2": (0.0, 5.0 * 9.80665, "m/s²"),
    "specific_force_g": (-20.0, 20.0, "g"),
    "precession_dps": (-2e4, 2e4, "°/s electrical"),
    "gravity_mps2": (9.0, 10.5, "m/s²"),
    "earth_radius_m": (6.0e6, 6.6e6, "m"),
    "earth_rate_radps": (0.0, 1e-4, "rad/s"),
    # `hrgjax.Noise` (any single-axis gyro: an HRG, a FOG, a MEMS gyro's axis). ARW 1e-3
    # rad/√s = 3.4 °/√h = 0.057 °/s/√Hz: an HRG's ≤ 1e-2 °/√h lies 340× inside, a tactical
    # MEMS gyro's 0.1–1 °/√h and a consumer one's 0.005–0.015 °/s/√Hz 3–35× inside; a
    # datasheet's 0.001–0.01 °/√h typed as rad/√s (the preset's 0.002) is refused. Bias
    # instability 1e-3 rad/s = 206 °/h: a consumer MEMS gyro's 10–100 °/h inside, an
    # HRG's or FOG's 1e-4–1 °/h typed as rad/s beyond from 1e-3 (bounds excluded:
    # `EXCLUSIVE`). The switch-on bias σ 0.05 rad/s = 2.9 °/s: twice it stays within
    # `gyro_rate_bias`; 0.05–1 °/h typed as rad/s is refused from 0.05.
    "noise_angle_white": (0.0, 0.1, "rad electrical"),
    "noise_arw": (0.0, 1e-3, "rad/√s"),
    "noise_bias_instability": (0.0, 1e-3, "rad/s"),
    "noise_run_bias": (0.0, 0.05, "rad/s"),
    "noise_amplitude_white": (0.0, 0.5, "(relative to the amplitude set point)"),
    # `hrgjax.Gyro` and `hrgjax.DriftTerms`, as equivalent input rate. A rate bias of 0.1
    # rad/s = 5.7 °/s = 2·10⁴ °/h: an HRG's is ≤ 1 °/h, a broken gyro's or a MEMS axis's a few
    # °/s; the preset's 0.3 °/h typed as rad/s (62 000 °/h) is refused. The same bound holds
    # the warm-up transient b_w, and the thermal-rate coefficient over a chamber ramp of
    # 1 °C/s. The thermal-lag coefficient 2e-3 rad/s per °C = 0.11 °/s per °C: a MEMS gyro's
    # bias tempco (≤ 0.03 °/s per °C) inside, the preset's 0.005 °/h/°C typed as rad/s not.
    # g-sensitivity 4e-3 rad/s per g (0.23 °/s/g = 825 °/h/g: the worst MEMS datasheets'
    # 0.1–0.2 °/s/g inside, an HRG's 0.005–0.01 °/h/g typed as rad/s beyond). The rate-cubic
    # scale factor κ_Ω: 1 s² is a 100 % scale-factor change at 1 rad/s (57 °/s); a figure in
    # ppm per (rad/s)² typed as a fraction is refused.
    "gyro_rate_bias": (-0.1, 0.1, "rad/s"),
    "gyro_g_sensitivity": (-4e-3, 4e-3, "rad/s per g"),
    "gyro_temperature_rate": (-0.1, 0.1, "rad/s per °C/s"),
    "gyro_thermal_lag": (-2e-3, 2e-3, "rad/s per °C"),
    "gyro_warmup": (-0.1, 0.1, "rad/s"),
    "gyro_rate_cubic": (-1.0, 1.0, "s²"),
    "imu_gyro_bias": (-0.75, 0.75, "rad/s"),
    "imu_accel_bias": (-3.0, 3.0, "m/s²"),
    "imu_scale": (-0.1, 0.1, "(a fraction: 1e-6 = 1 ppm)"),
    "imu_misalignment": (-0.1, 0.1, "rad"),
    "imu_arw": (0.0, 2.5e-3, "rad/√s"),
    "imu_vrw": (0.0, 0.05, "m/s/√s"),
    "imu_gyro_bias_instability": (0.0, 0.01, "rad/s"),
    "imu_accel_bias_instability": (0.0, 0.1, "m/s²"),
    "imu_gyro_rate_random_walk": (0.0, 1e-4, "rad/s/√s"),
    "imu_accel_random_walk": (0.0, 0.01, "m/s²/√s"),
    # `hrgjax.ins.gnss.Gnss.lever_arm`, per body axis: the antenna sits on the vehicle that
    # carries the IMU, and the largest (an A380: 73 m long, 80 m span; a ship's mast and
    # bridge) keep it within 100 m; a lever arm of 1.5 m typed in cm or mm (150, 1500) is
    # refused, and 1e6 m (which ran: the fixes sat 1000 km from the vehicle) is.
    "gnss_lever_arm_m": (-100.0, 100.0, "m, body FRD"),
}
"""The default ranges; [`RANGES`][hrgjax.plausible.RANGES] is what is in force."""

EXCLUSIVE = frozenset(
    k
    for k in DEFAULTS
    if k.startswith(("imu_", "gyro_"))
    or k in ("noise_arw", "noise_bias_instability", "noise_run_bias")
)
"""Quantities whose nonzero bounds are refused too: each is a round number that a datasheet
value in the other unit equals (a scale factor of 0.1 %, a misalignment of 0.1° or 0.1 mrad,
a VRW of 0.05 mg/√Hz, a gyro bias instability of 0.01 °/h, a rate bias of 0.1 °/h, an ARW
of 0.001 °/√h, typed as SI)."""
