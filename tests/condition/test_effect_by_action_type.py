"""The maintenance effect by action type on a line run at two speeds (issue 33 item 5, issue 34 item 5).

A generated fleet history written into the condition store (:func:`app.condition.fleet.ingest_fleet`, no
pipeline): a 3 km line of two superstructure classes whose amplitude follows speed differently (exponent 0.5
on the slab, 1.5 on the ballasted track), passed by a fast group (40 m/s) before the work and a slow group
(26 m/s) from a little before it on, so the windows around the work hold the speed groups in very different
proportions. A tamping of −20 % (the support) beside the change of class and a grinding whose rail surface's
response drops by 30 % (the support untouched) on the same day, both recorded.
"""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

from app.simulate.fleet import FleetPlan, FleetSimulator, PlantedAction
from app.simulate.track import TrackSection, generate_line

START = dt.datetime(2025, 3, 1, 8, 0, tzinfo=dt.UTC)
LINE = "SPD"
SECTIONS = (TrackSection(10_000.0, 10_700.0, "slab"), TrackSection(10_700.0, 13_000.0, "b91_no_pads"))
#: Day of the work (from START), the slow group's first day, the runs of either group.
WORK_DAY, SLOW_FROM, N_FAST, N_SLOW = 40.0, 31.0, 20, 30
TAMPING = (10_800.0, 11_000.0, 0.20)
GRINDING = (12_300.0, 12_600.0, 0.30)  # beyond the tamping's surroundings, and it beyond its


def _plan(offset: float) -> FleetPlan:
    day = WORK_DAY - offset  # the simulator's days count from its own first run
    return FleetPlan(actions=(
        PlantedAction(TAMPING[0], TAMPING[1], day=day, type="tamping", recovery=TAMPING[2], regrowth_per_year=0.0),
        PlantedAction(GRINDING[0], GRINDING[1], day=day, type="grinding", recovery=GRINDING[2],
                      regrowth_per_year=0.0),
    ))


@pytest.fixture(scope="module")
def effects(tmp_path_factory):
    """The service's effect items of the two actions, by type."""
    from app.condition.fleet import ingest_fleet
    from app.db import migrate
    from app.db.session import Database
    from app.places.config import default_places_config
    from app.places.effect import action_effects

    url = f"sqlite:///{tmp_path_factory.mktemp('speed-mix') / 'db.sqlite'}"
    migrate.upgrade(url)
    db = Database(url)
    line = generate_line(10_000.0, 13_000.0, seed=41, sections=SECTIONS, anomalies=())
    x = line.track_from_m + (np.arange(int(line.track_to_m - line.track_from_m)) + 0.5)
    alpha = np.where(x < 10_700.0, 0.5, 1.5)  # the classes' speed exponents on the simulator's 1 m grid
    for offset, n, kmh, seed in ((0.0, N_FAST, 144.0, 51), (SLOW_FROM, N_SLOW, 93.6, 52)):
        sim = FleetSimulator(line, _plan(offset), speed_kmh=kmh, alpha=alpha)
        ingest_fleet(db, sim, n, line_id=LINE, start=START + dt.timedelta(days=offset), every_days=2.0, seed=seed)
    try:
        got = action_effects(db, LINE, "1", types=None, since=None, km_from=None, km_to=None, before_days=90.0,
                             after_days=30.0, regain_fraction=0.5, config=default_places_config())
        yield {i["type"]: i for i in got["items"]}
    finally:
        db.dispose()


def test_a_tamping_reads_its_effect_whatever_the_speed_mix(effects):
    """−20 % within 5 percentage points, with n, the sign convention and a 1 σ interval holding it."""
    t = effects["tamping"]
    truth = 100.0 * -TAMPING[2]
    assert t["n_runs_before"] == 25 and t["n_runs_after"] == 15  # 20 fast + 5 slow before, slow after
    assert t["recovery_pct"] == pytest.approx(truth, abs=5.0)
    assert t["support_change"] == t["recovery"] and t["rail_surface"] is False
    assert t["rail_surface_change"] is None
    assert t["recovery_low"] < t["recovery"] < t["recovery_high"]
    assert t["recovery_high"] - t["recovery_low"] < 0.1
    assert t["sign_convention"].startswith("after - before") and t["interval"] == "1 sigma (68 %)"
    # held: no regrowth planted; the runs saw 49 days after it and nothing is said beyond them
    assert t["followed_days"] == pytest.approx(SLOW_FROM + 2 * (N_SLOW - 1) - WORK_DAY - 1 / 6, abs=0.01)
    assert t["lasted_days_observed"] is None
    assert t["lasted_days_projected"] is None or t["lasted_days_projected"] <= t["followed_days"]


def test_a_grinding_reports_the_rail_surface_and_the_support_apart(effects):
    """The change across the work is the rail surface's response (−30 %); the support's change ≈ 0."""
    g = effects["grinding"]
    assert g["rail_surface"] is True
    assert g["rail_surface_change_pct"] == pytest.approx(100.0 * -GRINDING[2], abs=5.0)
    assert g["rail_surface_change_low"] < g["rail_surface_change"] < g["rail_surface_change_high"]
    assert abs(g["support_change_pct"]) < 5.0 and g["recovery"] == g["support_change"]
    assert g["recovery_low"] < g["recovery"] < g["recovery_high"]
    assert math.isfinite(g["condition_index_before"])
