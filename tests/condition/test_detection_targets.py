"""Change detection on generated histories (daily runs with the fleet's realistic noise): the
targets of issue 16 — at most 1 % of unchanged places flagged, a planted 20 % change over 20 m
found, a 10 %/year degradation found within 3 months. bench/bench_condition.py measures the
same on a 50 km line over a year and more seeds (BENCHMARKS.md)."""

from __future__ import annotations

import numpy as np
import pytest

from app.condition.fleet import fleet_history
from app.simulate.fleet import FleetSimulator, random_plan
from app.simulate.fleet_scoring import score_history
from app.simulate.track import generate_line

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def scored():
    line = generate_line(0.0, 6_000.0, seed=21)
    plan = random_plan(0.0, 6_000.0, 200, seed=21, n_steps=8, n_trends=2, n_actions=1)
    assert len(plan.steps) == 8 and len(plan.trends) == 2
    days = list(fleet_history(FleetSimulator(line, plan), 200, seed=23))
    return plan, days, score_history(plan, days)


def test_unchanged_places_are_rarely_flagged(scored):
    _, _, score = scored
    assert score.unchanged_tested > 30_000
    assert score.false_flag_rate <= 0.01
    assert score.newest_unchanged_rate <= 0.01


def test_planted_steps_of_20_percent_over_20_m_are_found(scored):
    _, _, score = scored
    assert score.steps_total == 8
    assert score.step_detection_rate >= 0.95


def test_a_degradation_of_10_percent_a_year_is_found_within_3_months(scored):
    _, _, score = scored
    assert score.trends_found_within(90.0) == 1.0, score.trend_delays_days


def test_the_speed_law_is_taken_out_of_the_history(scored):
    _, days, _ = scored
    exps = [e for e in days[-1].assessment.exponents[10.0].values()]
    assert np.allclose(exps, 1.5, atol=0.1)  # the simulator's amplitude grows with v ** 1.5
