"""Rail roughness and a grinding through the real service (issue 26 items 3 and 5): a rough simulated line
(random roughness fixed to the track, the same in every run) passed 10 times at one speed, a grinding over
200 m between the 9th and the 10th run and a real −30 % support change over 20 m 250 m beside it. Uploaded,
processed by the local worker and published into the condition store and the places: the stored index_sd is
the profile's stated 1-σ, a recorded grinding is not read as a stiffness change while the same runs
without the record are, and the support change is still found."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import select

from app.simulate.history import grinding_history
from tests.condition.history_support import (
    history_service,
    places_without_sd,
    process_history,
    store_flags_without,
)

pytestmark = pytest.mark.slow

SPEC, INFO = grinding_history(seed=21)
N_RUNS = len(SPEC.runs)
GROUND, SOFT = INFO["ground"], INFO["soft"]


def _maintenance_csv(path) -> None:
    r = INFO["maintenance"]
    path.write_text("line_id,track,km_from,km_to,type,date\n"
                    f"{r['line_id']},{r['track']},{r['km_from']:.3f},{r['km_to']:.3f},{r['type']},{r['date']}\n")


def _inside(seg: int, extent: tuple[float, float], seg_m: float = 10.0) -> bool:
    return extent[0] <= (seg + 0.5) * seg_m < extent[1]


@pytest.fixture(scope="module")
def rough(tmp_path_factory):
    """The history processed; the grinding recorded (imported) before the last run is uploaded."""
    from app.db.session import Database

    spec = SPEC
    tmp = tmp_path_factory.mktemp("rough-history")
    with history_service(tmp) as client:
        first = process_history(client, spec, tmp / "files", runs=slice(0, N_RUNS - 1))
        csv = tmp / "grinding.csv"
        _maintenance_csv(csv)
        with open(csv, "rb") as fh:
            r = client.post("/api/v1/reference/maintenance", params={"mode": "append"}, files={"file": (csv.name, fh)})
        assert r.status_code in (200, 201), r.text
        last = process_history(client, spec, tmp / "files", runs=slice(N_RUNS - 1, N_RUNS), reference=False)
        db = Database(client.settings.database_url)
        try:
            yield spec, db, first.run_ids + last.run_ids, first.jobs + last.jobs, client
        finally:
            db.dispose()


def test_stored_index_sd_is_the_profiles_stated_uncertainty(rough):
    """(i) every 10 m row of a run with a stated 1-σ has a positive finite index_sd, equal to the store's rule
    applied to the job's profile rows (the writer's own valid bins and shift)."""
    from app.condition.index import store_index_sd
    from app.condition.writer import _job_bins, _valid, uncertainty_settings
    from app.db import results_reader
    from app.db.models import ConditionRun, Job
    from app.db.models import SegmentCondition as SC

    spec, db, run_ids, jobs, _ = rough
    run_id, job_id = run_ids[3], jobs[3]["id"]
    with db.read() as s:
        rows = s.execute(select(SC.wheel, SC.seg, SC.condition_index_sd).where(SC.run_id == run_id, SC.seg_m == 10)).all()
        assert rows and all(r.condition_index_sd is not None and np.isfinite(r.condition_index_sd)
                        and r.condition_index_sd > 0 for r in rows)
        bl = results_reader.job_bin_length(s, job_id)
        bins = _job_bins(s, job_id, None)["11"]
        shift = s.get(ConditionRun, run_id).shift_m
        res, q = uncertainty_settings(s.get(Job, job_id).settings)
    from app.condition.config import DEFAULT_CONDITION_CONFIG

    amp = _valid(bins, bl, DEFAULT_CONDITION_CONFIG)
    pos = (bins.bins + 0.5) * bl + shift
    mine = sorted((r.seg, r.condition_index_sd) for r in rows if r.wheel == "11")
    want = store_index_sd(pos, amp, bins.sd, bins.sd_shared, np.array([m[0] for m in mine]), segment_m=10.0,
                          bin_length_m=bl, resolution_m=res, filter_order=q)
    np.testing.assert_allclose([m[1] for m in mine], want, rtol=1e-5)
    # on rough rail one pass's 10 m mean is uncertain by tens of per cent (issue 26: RMS 40-50 %)
    assert 0.05 < float(np.median(want)) < 1.0


def _flags_of(db, run_id):
    from app.db.models import ConditionFlag

    with db.read() as s:
        return [(f.seg, f.direction, f.score) for f in s.scalars(select(ConditionFlag).where(
            ConditionFlag.run_id == run_id, ConditionFlag.kind == "step", ConditionFlag.seg_m == 10))]


def test_a_recorded_grinding_is_not_a_stiffness_change_and_a_real_change_still_is(rough):
    """(ii) without the record the grinding's new rail surface reads as step changes over its extent; with it
    (what the service did) none there; (iii) the −30 % support change beside it is flagged either way."""
    from app.db.models import SegmentCondition as SC

    spec, db, run_ids, jobs, _ = rough
    assert all(not [f for f in _flags_of(db, r) if _inside(f[0], GROUND)] for r in run_ids[:-1])
    with_record = _flags_of(db, run_ids[-1])
    without, z_all = store_flags_without(db, run_ids[-1], jobs[-1]["id"], line_id=SPEC.line_id, track=SPEC.track)
    z_without = [(seg, z) for seg, w, z in z_all if w == "11"]
    ground_without = [f for f in without if _inside(f[0], GROUND)]
    ground_with = [f for f in with_record if _inside(f[0], GROUND)]
    assert len(ground_without) >= 2, without  # the counterfactual: the test can fail
    assert not ground_with, with_record
    assert [f for f in with_record if _inside(f[0], SOFT) and f[1] == -1], with_record
    assert [f for f in without if _inside(f[0], SOFT) and f[1] == -1], without
    with db.read() as s:
        z_with = dict(s.execute(select(SC.seg, SC.change_z).where(SC.run_id == run_ids[-1], SC.seg_m == 10,
                                                                  SC.wheel == "11")).all())
    zw = {seg: z for seg, z in z_without}
    inside = [g for g in z_with if _inside(g, GROUND) and z_with[g] is not None and zw.get(g) is not None]
    assert inside and np.median([abs(z_with[g]) for g in inside]) < np.median([abs(zw[g]) for g in inside]) / 2


def test_no_new_step_place_over_the_recorded_grinding(rough):
    """The places of the last run (applied by the service with the record and the stated 1-σ): none with step
    evidence over the ground stretch, where the same rows without them give several; the support change is a
    place with step evidence; the rough line's roughness no longer makes anomalies all along it."""
    from app.db.models import Place, PlaceObservation

    spec, db, run_ids, _, _ = rough
    with db.read() as s:
        obs = list(s.scalars(select(PlaceObservation).where(PlaceObservation.run_id == run_ids[-1])))
        places = {p.id: p for p in s.scalars(select(Place))}
    before = places_without_sd(db, run_ids[-1])
    assert len([p for p in before if p[2] & 2 and p[0] < GROUND[1] and p[1] > GROUND[0]]) >= 2, before
    assert len(obs) < len(before) / 2, (len(obs), len(before))
    step = [o for o in obs if o.evidence & 2]
    assert not [o for o in step if o.start_m < GROUND[1] and o.end_m > GROUND[0]], \
        [(o.start_m, o.end_m, o.change) for o in step]
    soft = [o for o in step if o.start_m < SOFT[1] + 10 and o.end_m > SOFT[0] - 10]
    assert soft and all(o.change < 0 for o in soft)
    assert all(places[o.place_id].level_sd is not None for o in soft)


def test_the_work_list_answers_each_places_uncertainty(rough):
    """The API, the CSV and the GeoJSON answer the 1-σ of each place's size (peak_sd, change_sd, severity_sd),
    and a place's observations their level_sd; the support change is answered with a change within
    a few 1-σ of its truth (−0.36)."""
    import csv
    import io

    _, _, _, _, client = rough
    url = "/api/v1/condition/places"
    r = client.get(url, params={"line_id": SPEC.line_id, "include_closed": True, "limit": 1000})
    assert r.status_code == 200, r.text
    items = r.json()["items"]
    assert items and all(p["peak_sd"] is not None and p["peak_sd"] > 0 for p in items)
    soft = [p for p in items if p["km_from"] * 1000 < SOFT[1] + 10 and p["km_to"] * 1000 > SOFT[0] - 10]
    assert soft and soft[0]["change_sd"] is not None and soft[0]["severity_sd"] is not None
    assert abs(soft[0]["change"] + 0.36) < 3 * soft[0]["change_sd"] + 0.05
    h = client.get(f"{url}/{soft[0]['id']}").json()
    assert h["observations"][-1]["level_sd"] is not None
    rows = list(csv.DictReader(io.StringIO(client.get(f"{url}.csv", params={"line_id": SPEC.line_id,
                                                                            "include_closed": True}).text)))
    assert rows and all(row["peak_sd"] != "" for row in rows) and "severity_sd" in rows[0]
    geo = client.get(f"{url}.geojson", params={"line_id": SPEC.line_id, "include_closed": True}).json()
    assert all("peak_sd" in f["properties"] for f in geo["features"])
