"""Speed profiles: analytic distance, continuity, limits."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from app.simulate.speed import SpeedProfile


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_profile_is_realistic(seed: int) -> None:
    p = SpeedProfile.random(seed, length_m=20_000.0)
    t = np.linspace(0, p.end_time, 200_001)
    v, a, s = p.evaluate(t)
    assert 40 / 3.6 - 1e-9 <= v.min() and v.max() <= 200 / 3.6 + 1e-9
    assert 0.5 - 1e-9 <= p.max_abs_acceleration() <= 0.9 + 1e-9
    assert np.abs(a).max() <= p.max_abs_acceleration() + 1e-9
    assert a.max() > 0.3 and a.min() < -0.3  # accelerates and brakes
    assert s[-1] >= 20_000.0
    # analytic distance = integral of speed, analytic acceleration = derivative of speed
    np.testing.assert_allclose(s, cumulative_trapezoid(v, t, initial=0.0), atol=1e-3)
    np.testing.assert_allclose(np.gradient(v, t), a, atol=2e-3)


def test_long_random_profile_has_a_slow_section() -> None:
    p = SpeedProfile.random(4, duration_s=1800.0)
    v = p.speed(np.linspace(0, 1800.0, 100_000))
    assert v.min() < 72 / 3.6 and v.max() > 168 / 3.6


def test_time_at_distance_inverts_distance() -> None:
    p = SpeedProfile.random(5, length_m=8000.0)
    t = np.sort(np.random.default_rng(0).uniform(0, p.end_time + 30.0, 1000))
    np.testing.assert_allclose(p.time_at_distance(p.distance(t)), t, atol=1e-9)


def test_constant_and_validation() -> None:
    p = SpeedProfile.constant(30.0)
    v, a, s = p.evaluate(np.array([0.0, 0.5, 10.0]))
    np.testing.assert_array_equal(v, 30.0)
    np.testing.assert_array_equal(a, 0.0)
    np.testing.assert_allclose(s, [0.0, 15.0, 300.0])
    with pytest.raises(ValueError, match="speeds"):
        SpeedProfile.constant(0.0)
    with pytest.raises(ValueError, match="exactly one"):
        SpeedProfile.random(0)
