"""The matched-speed rule (app/analysis/speed_match.py): symmetric in log speed, one tolerance."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.speed_match import (
    DEFAULT_SPEED_TOLERANCE,
    log_speed_tolerance,
    log_speeds_matched,
    speeds_matched,
)
from app.settings import Settings


def test_matched_within_a_factor_one_plus_tol_either_way():
    v0 = 100.0
    v = np.array([100 / 1.1 * 0.999, 100 / 1.1 * 1.001, 95.0, 100.0, 109.9, 110.1])
    assert speeds_matched(v, v0, 0.1).tolist() == [False, True, True, True, True, False]


def test_symmetric_unlike_the_relative_difference():
    """0.905 · v0 is within 10 % of v0 (|v/v0 − 1| = 0.095) but v0 is not within 10 % of 0.905 · v0
    (|v0/v − 1| = 0.105): the log rule answers the same both ways (here: not matched)."""
    a, b = 90.5, 100.0
    assert abs(a / b - 1) <= 0.1 < abs(b / a - 1)
    assert speeds_matched(a, b, 0.1) == speeds_matched(b, a, 0.1) == np.False_
    rng = np.random.default_rng(3)
    x, y = rng.uniform(20, 200, 1000), rng.uniform(20, 200, 1000)
    np.testing.assert_array_equal(speeds_matched(x, y, 0.15), speeds_matched(y, x, 0.15))


def test_log_form_and_speed_form_agree_and_missing_speeds_never_match():
    v, v0 = np.array([52.0, 60.0, np.nan, 0.0, -3.0]), np.array([55.0, 50.0, 50.0, 50.0, 50.0])
    np.testing.assert_array_equal(speeds_matched(v, v0, 0.1), [True, False, False, False, False])
    with np.errstate(invalid="ignore", divide="ignore"):
        np.testing.assert_array_equal(log_speeds_matched(np.log(v / v0), 0.1), speeds_matched(v, v0, 0.1))
    assert log_speed_tolerance(0.1) == math.log1p(0.1)


@pytest.mark.parametrize("tol", [0.0, -0.1, float("nan"), float("inf"), "0.1"])
def test_the_tolerance_is_checked(tol):
    with pytest.raises(ValueError, match="tolerance"):
        log_speed_tolerance(tol)


def test_the_setting_defaults_to_the_rule_s_default():
    """TRACKVKF_ANALYTICS_SPEED_TOLERANCE (app.core imports nothing of the analysis) has the default of the rule."""
    assert Settings(_env_file=None).analytics_speed_tolerance == DEFAULT_SPEED_TOLERANCE
