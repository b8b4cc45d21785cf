"""The segment condition store: rows written at publish (both databases), alignment, replacement."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from sqlalchemy import func, select

from app.db import crud
from app.db.models import (
    ConditionFlag,
    ConditionLine,
    ConditionRun,
    Job,
    JobStatus,
    Run,
    SegmentCondition,
    utcnow,
)
from app.simulate.fleet import FleetNoise, FleetPlan, FleetSimulator, PlantedStep
from app.simulate.track import generate_line
from tests.condition.support import DAY0, profile_frame_of, publish_history, publish_tracks

LINE = generate_line(12_000.0, 15_000.0, seed=7)
QUIET = FleetNoise(segment_sd=0.02, run_sd=0.01, speed_spread=0.03, speed_wobble=0.02)


def _sim(plan: FleetPlan | None = None, noise: FleetNoise = QUIET) -> FleetSimulator:
    return FleetSimulator(LINE, plan or FleetPlan(), noise, grid_m=0.25)


def _rows(db, run_id: int, seg_m: int, wheel: str) -> list[SegmentCondition]:
    with db.read() as s:
        return list(s.scalars(select(SegmentCondition).where(
            SegmentCondition.run_id == run_id, SegmentCondition.seg_m == seg_m, SegmentCondition.wheel == wheel)
            .order_by(SegmentCondition.seg)))


def test_publish_writes_segment_rows_of_every_wheel_and_length(any_db):
    _, tracks = _sim().run(0.0, 1)
    run_id, job_id, summary = publish_tracks(any_db, tracks, DAY0)
    assert summary["stored"] and summary["condition_index"] == "ln_amplitude"
    assert summary["shift_m"] == 0.0 and summary["history_runs"] == 0 and summary["flags"] == 0
    frame = profile_frame_of(tracks)
    w = frame[frame["wheel"] == "12"].sort_values("bin")
    pos = (w["bin"].to_numpy() + 0.5) * 0.25
    amp = w["sleeper_amp"].to_numpy()
    keep = (pos >= pos.min() + 50.0) & (pos <= pos.max() - 50.0)  # the run's ends are left out
    for seg_m in (10, 100):
        rows = _rows(any_db, run_id, seg_m, "12")
        assert len(rows) > 0 and all(r.job_id == job_id for r in rows)
        r = rows[len(rows) // 2]
        inside = keep & (np.floor(pos / seg_m) == r.seg)
        assert r.n_valid == inside.sum() == seg_m * 4
        assert r.condition_index == pytest.approx(np.log(amp[inside]).mean(), rel=1e-5)  # single precision
        assert r.amp_mean == pytest.approx(amp[inside].mean(), rel=1e-5)
        assert r.amp_p95 == pytest.approx(np.percentile(amp[inside], 95), rel=1e-5)
        assert r.speed_mean == pytest.approx(w["speed_mean"].to_numpy()[inside].mean(), rel=1e-5)
        assert r.condition_index_sd is None  # the rows state no 1-sigma: none known (not 0)
        assert r.n_history == 0 and r.change_z is None
        assert min(x.seg for x in rows) * seg_m >= pos.min() + 50.0 - seg_m
    with any_db.read() as s:
        assert s.scalar(select(func.count()).select_from(SegmentCondition)) == summary["segments"]
        assert {r.wheel for r in s.scalars(select(SegmentCondition))} == {"11", "12", "41", "42"}
        line = s.scalars(select(ConditionLine)).one()
        assert (line.line_id, line.track, line.ref_run_id) == ("L1", "1", run_id)
        assert 12.0 < line.km_min < 12.2 and 14.8 < line.km_max < 15.0
        entry = s.get(ConditionRun, run_id)
        assert entry.job_id == job_id and entry.n_segments == summary["segments"]


def test_a_planted_step_is_flagged_once_as_new(any_db):
    step = PlantedStep(13_400.0, 13_420.0, day=10.0, factor=1.2)
    published = publish_history(any_db, _sim(FleetPlan(steps=(step,))), 12)
    before = [s for _, s in published[:10]]
    assert all(s["flags"] == 0 for s in before), [s["flags"] for s in before]
    (run10, s10), (run11, _) = published[10], published[11]
    assert s10["history_runs"] == 10 and s10["new_flag_ids"]
    with any_db.read() as s:
        flags = list(s.scalars(select(ConditionFlag).order_by(ConditionFlag.id)))
    at_step = [f for f in flags if f.kind == "step" and f.seg_m == 10 and f.direction == 1
               and f.seg * 10 < 13_420 and 13_400 < (f.seg + 1) * 10]
    assert at_step and {f.run_id for f in at_step} <= {run10, run11}
    first = [f for f in at_step if f.run_id == run10]
    assert first and all(f.is_new for f in first) and all(f.n_wheels >= 3 for f in first)
    assert all(f.score >= 4.5 and f.change == pytest.approx(np.log(1.2), abs=0.06) for f in first)
    assert not any(f.is_new for f in at_step if f.run_id == run11)  # flagged again: not new
    assert [f.id for f in flags] == sorted(f.id for f in flags)
    away = [f for f in flags if not (13_300 <= f.seg * f.seg_m <= 13_500)]
    assert len(away) <= 2, [(f.seg_m, f.seg, f.kind, f.score) for f in away]


def test_reprocessing_replaces_the_rows_and_deleting_the_run_removes_them(db):
    sim = _sim()
    _, tracks = sim.run(0.0, 3)
    run_id, _, first = publish_tracks(db, tracks, DAY0)
    _, tracks2 = sim.run(0.0, 4)
    _, job2, again = publish_tracks(db, tracks2, DAY0, run_id=run_id)
    assert again["segments"] == first["segments"]
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(SegmentCondition)) == first["segments"]
        assert {r.job_id for r in s.scalars(select(SegmentCondition))} == {job2}
    with db.write() as s:
        assert crud.delete_run(s, run_id)
    with db.read() as s:
        for table in (SegmentCondition, ConditionRun, ConditionFlag):
            assert s.scalar(select(func.count()).select_from(table)) == 0


def test_a_run_without_line_has_no_condition_rows(db):
    _, tracks = _sim().run(0.0, 5)
    _, _, summary = publish_tracks(db, tracks, DAY0, line_id=None)
    assert summary == {"stored": False, "reason": "the run has no line_id"}
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(SegmentCondition)) == 0


def test_a_run_with_an_odometry_error_is_aligned_onto_the_line(db):
    sim = _sim()
    _, tracks = sim.run(0.0, 6)
    publish_tracks(db, tracks, DAY0)
    _, tracks2 = sim.run(1.0, 7)
    run2, _, summary = publish_tracks(db, tracks2, DAY0 + dt.timedelta(days=1), shift_m=13.4)
    assert summary["shift_m"] == pytest.approx(-13.4, abs=0.5)
    assert summary["shift_confidence"] > 0.2
    first, second = _rows(db, 1, 10, "11"), _rows(db, run2, 10, "11")
    common = {r.seg for r in first} & {r.seg for r in second}
    a = np.array([r.condition_index for r in first if r.seg in common])
    b = np.array([r.condition_index for r in second if r.seg in common])
    assert np.corrcoef(a, b)[0, 1] > 0.9  # the same places on the ground


def test_a_metadata_correction_moves_the_runs_rows_to_the_corrected_line(client, tmp_path):
    """PATCH /runs/{id} queues a reprocessing; its publish replaces the run's condition rows under
    the corrected line, and the old line, left without runs, is gone from the store's answers."""
    from app import publish
    from app.db import queue
    from app.db.session import Database
    from tests.api import runfiles

    path = runfiles.write_hdf5(tmp_path / "r.h5", runfiles.channels(10_000))  # line 4010 track 1
    with open(path, "rb") as fh:
        run_id = client.post("/api/v1/runs", files={"file": (path.name, fh)}).json()["id"]
    db = Database(client.settings.database_url)
    try:
        def publish_seed(seed: int) -> int:
            job_id = queue.claim_next_job(db, "test", 30)
            assert job_id is not None
            _, tracks = _sim().run(0.0, seed)
            assert publish.publish_job(db, job_id, run_id, profile_frame_of(tracks), [], {}, worker_id="test")
            return job_id

        publish_seed(1)
        assert [x["line_id"] for x in client.get("/api/v1/condition/lines").json()["items"]] == ["4010"]
        r = client.patch(f"/api/v1/runs/{run_id}", json={"metadata": {"line_id": "4020"}})
        assert r.status_code == 200, r.text
        # until the reprocessing is published, the rows of the old metadata stay
        assert [x["line_id"] for x in client.get("/api/v1/condition/lines").json()["items"]] == ["4010"]
        job2 = publish_seed(2)

        items = client.get("/api/v1/condition/lines").json()["items"]
        assert [(x["line_id"], x["n_runs"], x["reference_run_id"]) for x in items] == [("4020", 1, run_id)]
        gone = client.get("/api/v1/condition/heatmap", params={"line_id": "4010"})
        assert gone.status_code == 404 and gone.json()["field"] == "line_id"
        assert client.get("/api/v1/condition/heatmap", params={"line_id": "4020"}).status_code == 200
        with db.read() as s:
            keys = {line.line_id: line for line in s.scalars(select(ConditionLine))}
            assert [r.line_key for r in s.scalars(select(ConditionRun))] == [keys["4020"].id]
            assert {r.job_id for r in s.scalars(select(SegmentCondition))} == {job2}
            assert keys["4010"].ref_signature is None and keys["4010"].ref_run_id is None  # not its reference
    finally:
        db.dispose()


def test_stated_sd_is_stored_as_the_segments_index_sd(db):
    """index_sd of a run whose profile states sleeper_amp_sd: the store's one rule (segment_sd over the mean
    amplitude), positive and finite on every segment, and for 10 m about sd_rel·sqrt(l/L)."""
    from app.condition.index import store_index_sd

    _, tracks = _sim().run(0.0, 1)
    run_id, _, summary = publish_tracks(db, tracks, DAY0, sd_rel=0.4)
    frame = profile_frame_of(tracks, sd_rel=0.4)
    w = frame[frame["wheel"] == "11"].sort_values("bin")
    pos = (w["bin"].to_numpy() + 0.5) * 0.25
    amp = w["sleeper_amp"].to_numpy().copy()
    amp[(pos < pos.min() + 50.0) | (pos > pos.max() - 50.0)] = np.nan  # the run's ends are left out
    for seg_m in (10, 100):
        rows = _rows(db, run_id, seg_m, "11")
        got = np.array([r.condition_index_sd for r in rows], dtype=float)
        assert np.all(np.isfinite(got)) and np.all(got > 0)
        want = store_index_sd(pos, amp, w["sleeper_amp_sd"].to_numpy(), w["sleeper_amp_sd_shared"].to_numpy(),
                              np.array([r.seg for r in rows]), segment_m=seg_m, bin_length_m=0.25)
        np.testing.assert_allclose(got, want, rtol=1e-5)  # single precision
    ten = np.array([r.condition_index_sd for r in _rows(db, run_id, 10, "11")], dtype=float)
    # half shared over ~20 m, half correlated over ~4 m: well below the bins' 0.4, well above 0.4/sqrt(40)
    assert 0.4 / np.sqrt(40) < np.median(ten) < 0.4


def _grinding_history(db, *, record: bool, sd_rel: float | None) -> list[dict]:
    """12 runs; between runs 10 and 11 the amplitude of 200 m falls by 25 % (as a grinding's new, smoother
    rail reads on a single wheel) and a real 20 m support change of -30 % appears 300 m away; the grinding
    recorded (or not) in the maintenance records. Summaries of the runs."""
    from app.db.reference_crud import insert_reference

    ground = PlantedStep(13_000.0, 13_200.0, day=10.5, factor=0.75)
    soft = PlantedStep(13_500.0, 13_520.0, day=10.5, factor=0.7)
    if record:
        with db.write() as s:
            insert_reference(s, "maintenance", [{"line_id": "L1", "track": "1", "km_from": 13.0, "km_to": 13.2,
                                                 "type": "grinding", "date": (DAY0 + dt.timedelta(days=10.5)).date()}])
    sim = _sim(FleetPlan(steps=(ground, soft)), FleetNoise(segment_sd=0.03, run_sd=0.01, speed_spread=0.0))
    out = []
    for i in range(12):
        _, tracks = sim.run(float(i), np.random.default_rng([0, i]))
        out.append(publish_tracks(db, tracks, DAY0 + dt.timedelta(days=i), sd_rel=sd_rel)[2])
    return out


def _step_flags(db) -> list[ConditionFlag]:
    with db.read() as s:
        return list(s.scalars(select(ConditionFlag).where(ConditionFlag.kind == "step", ConditionFlag.seg_m == 10)))


@pytest.mark.parametrize("record", [False, True])
def test_a_recorded_grinding_is_not_a_stiffness_change(db, record):
    """With stated roughness uncertainty, the change over a recorded grinding's extent is not flagged; the
    same runs without the record flag it; a real support change beside it is flagged either way."""
    summaries = _grinding_history(db, record=record, sd_rel=0.5)
    assert all(s["flags"] == 0 for s in summaries[:11])
    flags = _step_flags(db)
    ground = [f for f in flags if 1300 <= f.seg < 1320]
    soft = [f for f in flags if 1350 <= f.seg < 1352]
    assert soft and all(f.direction == -1 for f in soft)  # the real change is found
    if record:
        assert not ground
    else:
        assert len(ground) >= 15 and all(f.direction == -1 for f in ground)


def test_without_stated_sd_a_grinding_record_changes_nothing(db):
    """Runs that state no 1-sigma behave as before: the grinding record alone does not widen the test."""
    _grinding_history(db, record=True, sd_rel=None)
    ground = [f for f in _step_flags(db) if 1300 <= f.seg < 1320]
    assert len(ground) >= 15


def test_a_track_impacts_mask_is_kept_out_of_the_segment_rows(db):
    """Issue 33: the bins within a track impact's mask (the job's track_impacts) are no part of any 10 m or
    100 m row; a job without masks (older, or fan-out) masks around its profile's track_impact_mm bins."""
    from app import publish
    from app.analysis.impacts.mask import DEFAULT_RATIO, mask_half_width
    from app.condition.writer import store_run_condition

    _, tracks = _sim().run(0.0, 1)
    frame = profile_frame_of(tracks)
    pos = (frame["bin"].to_numpy() + 0.5) * 0.25
    x0 = float(np.median(pos))
    near = np.abs(pos - x0) <= 12.0
    clean = frame["sleeper_amp"].to_numpy().copy()
    frame.loc[near, "sleeper_amp"] *= 3.0  # what a weld 50× the sleeper signal leaves, bridged or not
    with db.write() as s:
        run = Run(sha256="impact-run", file_path="x", source_format="hdf5", size_bytes=1, fs=10_000.0, n_samples=10,
                  duration_s=1.0, channels=["Z11"], meta={}, line_id="L1", track="1", start_time=DAY0,
                  created_at=utcnow())
        s.add(run)
        s.flush()
        job = Job(run_id=run.id, status=JobStatus.RUNNING, worker_id="w", settings={"bin_length_m": 0.25},
                  created_at=utcnow())
        s.add(job)
        s.flush()
        run_id, job_id = run.id, job.id
    impacts = [{"track_m": x0, "length_m": 1.0, "depth_mm": 0.3, "ratio": 50.0, "mask_half_width_m": 12.5}]
    assert publish.publish_job(db, job_id, run_id, frame, [], {"track_impacts": impacts}, worker_id="w",
                               places_followup=None)
    for seg_m in (10, 100):
        for r in _rows(db, run_id, seg_m, "11"):
            lo, hi = r.seg * seg_m, (r.seg + 1) * seg_m
            inside = (pos >= lo) & (pos < hi) & (frame["wheel"].to_numpy() == "11")
            kept = inside & ~(np.abs(pos - x0) <= 12.5)
            assert r.n_valid <= int(kept.sum())
            if (inside & near).any():  # a row beside the impact: its undisturbed bins only, none of the tripled
                assert r.n_valid == int(kept.sum()) > 0
                assert r.amp_mean == pytest.approx(clean[kept].mean(), rel=1e-5)
    with db.read() as s:
        assert s.get(Job, job_id).meta["condition"]["impact_masked_bins"] >= 4 * 100
    # the same rows from the profile's impact bins where the job kept no masks
    frame2 = frame.copy()
    frame2["track_impact_mm"] = np.where(np.abs(pos - x0) <= 0.125, 0.3, np.nan)  # the two bins at x0
    with db.write() as s:
        s.get(Job, job_id).meta = {}
        rc = store_run_condition(s, run_id, job_id, profiles=frame2, track_impacts=None)
        s.rollback()
    assert rc.details["impact_masked_bins"] >= 4 * int(2 * mask_half_width(1.0, 3.0, DEFAULT_RATIO) / 0.25) - 8
