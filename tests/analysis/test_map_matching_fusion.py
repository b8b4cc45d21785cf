"""Map matching onto a polyline with km stations and odometry/GNSS fusion (pure numerics)."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.gnss_fusion import FusionSettings, fuse_odometry_gnss
from app.analysis.map_matching import Polyline, match_points


def test_match_points_on_a_bent_line() -> None:
    x = np.array([0.0, 100.0, 100.0])
    y = np.array([0.0, 0.0, 100.0])
    pl = Polyline(x, y, np.array([5000.0, 4900.0, 4800.0]))  # km decreasing along the vertices
    m = match_points(pl, np.array([30.0, 110.0, 95.0]), np.array([4.0, 50.0, 2.0]))
    np.testing.assert_allclose(m.chainage_m, [4970.0, 4850.0, 4905.0])
    np.testing.assert_allclose(np.abs(m.offset_m), [4.0, 10.0, 2.0])
    assert m.offset_m[0] < 0  # left of the vertex order is right of the km direction
    with pytest.raises(ValueError, match="strictly"):
        Polyline(x, y, np.array([1.0, 2.0, 2.0]))


def test_fusion_recovers_scale_and_rejects_outliers() -> None:
    rng = np.random.default_rng(4)
    s = np.linspace(0.0, 9000.0, 3000)
    truth = 20_000.0 - s  # km decreasing
    odo = 1.006 * s
    meas = truth + rng.normal(0.0, 3.0, s.size)
    meas[::97] += 150.0  # multipath jumps
    keep = (s < 3000) | (s > 4000)  # a 1 km outage
    fus = fuse_odometry_gnss(odo[keep], meas[keep], odo_range_m=(0.0, odo[-1]))
    assert fus.direction == -1 and fus.scale == pytest.approx(1 / 1.006, rel=1e-3)
    assert fus.n_used <= keep.sum() - (keep[::97]).sum()
    err = fus.chainage(odo) - truth
    assert np.abs(err).max() < 1.0
    with pytest.raises(ValueError, match="disagree"):
        fuse_odometry_gnss(odo, 2.0 * meas)
    with pytest.raises(ValueError, match="at least"):
        fuse_odometry_gnss(odo[:5], meas[:5], settings=FusionSettings(min_fixes=20))
