"""Units and report helpers (hrgjax/units.py)."""

import numpy as np
import pytest

from hrgjax.units import group_temperatures


def test_group_temperatures_merges_last_bits_and_keeps_distinct_temperatures():
    """One report group per temperature: values within 0.05 °C share a label (2.6 and its
    last-bit neighbours, the calibrate table's "+2.6 °C" twice), values 0.1 °C apart keep
    their own, a slow ramp's values are not chained into one group, NaN stays NaN."""
    x = np.array([2.6, np.nextafter(2.6, 3.0), 2.6 - 1e-12, 2.7, -40.0, -39.9, np.nan,
                  -40.0 + 4e-15])  # fmt: skip
    g = group_temperatures(x)
    assert g[0] == g[1] == g[2] and g[0] == pytest.approx(2.6, abs=1e-11)
    assert g[4] == g[7] and len({g[0], g[3], g[4], g[5]}) == 4 and np.isnan(g[6])
    assert np.unique(g[np.isfinite(g)]).size == 4
    ramp = np.arange(0.0, 1.0, 0.03)  # 34 values 0.03 °C apart
    groups = np.unique(group_temperatures(ramp))
    assert groups.size == 17 and np.all(np.diff(groups) > 0.05)
    assert group_temperatures(x.reshape(2, 4)).shape == (2, 4)
    np.testing.assert_array_equal(group_temperatures([1.0, 1.0 + 1e-9], tol=0.0), [1.0, 1.0 + 1e-9])
    with pytest.raises(ValueError, match=r"tol must be a finite number ≥ 0 \[°C\]"):
        group_temperatures(x, tol=-1.0)
