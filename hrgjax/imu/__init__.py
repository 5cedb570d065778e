"""Six-axis IMU data and the Ferraris calibration (a 3-axis gyro + 3-axis accelerometer).

- [`ImuData`][hrgjax.imu.ImuData], [`load`][hrgjax.imu.load]: records in SI, read from CSV
  with a column map and declared units;
- [`ferraris`][hrgjax.imu.ferraris] → [`ImuCalibration`][hrgjax.imu.ImuCalibration]
  (`accel_matrix`, `accel_bias`, `gyro_matrix`, `gyro_bias`, `gyro_g_sensitivity`, standard
  errors, `apply`, `save`), [`load_calibration`][hrgjax.imu.load_calibration];
- sections by hand ([`parse_sections`][hrgjax.imu.sections.parse_sections]) or found
  ([`detect_sections`][hrgjax.imu.detect_sections]);
- [`ferraris_session`][hrgjax.imu.ferraris_session]: a simulated session with a known truth.
"""

from .data import ACCEL_UNITS, GYRO_UNITS, SI_COLUMNS, SI_UNITS, ImuData, load
from .ferraris import PARAMETERS, ImuCalibration, ferraris, load_calibration, session_statistics
from .sections import (
    FACES,
    SECTION_KEYS,
    TURNS,
    detect_sections,
    parse_sections,
    sections_to_json,
)
from .session import face_attitude, ferraris_session

__all__ = [
    "ACCEL_UNITS",
    "FACES",
    "GYRO_UNITS",
    "PARAMETERS",
    "SECTION_KEYS",
    "SI_COLUMNS",
    "SI_UNITS",
    "TURNS",
    "ImuCalibration",
    "ImuData",
    "detect_sections",
    "face_attitude",
    "ferraris",
    "ferraris_session",
    "load",
    "load_calibration",
    "parse_sections",
    "sections_to_json",
    "session_statistics",
]
