"""The SQL job queue: atomic claims, stale-heartbeat re-claims, guarded writes,
progress from chunk rows, results replaced (never duplicated)."""

from __future__ import annotations

import datetime as dt
import threading

import numpy as np
import pandas as pd
import pytest
from sqlalchemy import func, select, update

from app import publish
from app.db import crud, queue, results_reader
from app.db.models import Job, JobStatus, ProfileBin, Run, WheelOOR, utcnow
from app.db.session import Database


def _make_run(db: Database, sha: str = "a" * 64) -> tuple[int, int]:
    with db.write() as s:
        run = Run(
            sha256=sha, file_path="x", source_format="hdf5", size_bytes=1, fs=10_000.0,
            n_samples=10, duration_s=0.001, channels=["Z11"], meta={}, created_at=utcnow(),
        )
        s.add(run)
        s.flush()
        job = crud.create_job(s, run.id, {"n_wheel_orders": 11})
        return run.id, job.id


def _results(n_bins: int, value: float) -> tuple[pd.DataFrame, list[dict]]:
    rows = []
    for wheel in ("11", "12"):
        for b in range(n_bins):
            rows.append({"wheel": wheel, "bin": 40_000 + b, "km": (40_000 + b + 0.5) * 0.25 / 1000,
                         "n_samples": 100, "speed_mean": 20.0, "sleeper_amp": value,
                         **{f"order_amp_{i:02d}": value / i for i in range(1, 12)},
                         "residual_rms": 0.1, "sleeper_force_amp": np.nan})
    wheels = [{"wheel": w, "wheel_diameter_m": 0.92, "n_windows": 3,
               "orders": [{"order": 1, "radius_um": 10.0}], "angles_deg": [0.0, 1.0],
               "profile_um": [1.0, np.float64(2.0)], "profile_p05_um": None, "profile_p95_um": None}
              for w in ("11", "12")]
    return pd.DataFrame(rows), wheels


def test_claim_is_exclusive_under_races(db):
    _, job_id = _make_run(db)
    winners: list[int | None] = []
    barrier = threading.Barrier(6)

    def claim(i: int) -> None:
        barrier.wait()
        winners.append(queue.claim_next_job(db, f"w{i}", stale_after_s=30))

    threads = [threading.Thread(target=claim, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(w for w in winners if w is not None) == [job_id]
    with db.read() as s:
        job = s.get(Job, job_id)
        assert job.status == JobStatus.RUNNING and job.attempts == 1 and job.started_at


def test_oldest_job_first_and_nothing_when_empty(db):
    _, first = _make_run(db, "a" * 64)
    _, second = _make_run(db, "b" * 64)
    assert queue.claim_next_job(db, "w", 30) == first
    assert queue.claim_next_job(db, "w", 30) == second
    assert queue.claim_next_job(db, "w", 30) is None


def test_stale_job_is_reclaimed_and_old_worker_loses_it(db):
    run_id, job_id = _make_run(db)
    assert queue.claim_next_job(db, "dead", 30) == job_id
    assert queue.claim_next_job(db, "other", 30) is None  # heartbeat fresh
    with db.write() as s:
        s.execute(update(Job).values(heartbeat_at=utcnow() - dt.timedelta(seconds=60)))
    assert queue.claim_next_job(db, "other", 30) == job_id
    assert queue.heartbeat(db, job_id, "dead").owned is False
    assert queue.mark_chunk(db, job_id, 0, "done", worker_id="dead") is None
    profiles, wheels = _results(4, 1.0)
    assert not publish.publish_job(db, job_id, run_id, profiles, wheels, {}, worker_id="dead")
    assert publish.publish_job(db, job_id, run_id, profiles, wheels, {"v": 1}, worker_id="other")
    with db.read() as s:
        job = s.get(Job, job_id)
        assert job.status == JobStatus.DONE and job.attempts == 2 and job.progress == 1.0


def test_progress_counts_chunk_rows_not_events(db):
    _, job_id = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    specs = [(i, {"index": i}) for i in range(4)]
    assert queue.record_chunks(db, job_id, specs, worker_id="w")
    assert queue.record_chunks(db, job_id, specs, worker_id="w")  # idempotent
    assert queue.mark_chunk(db, job_id, 0, "done", worker_id="w") == pytest.approx(0.25)
    assert queue.mark_chunk(db, job_id, 0, "done", worker_id="w") == pytest.approx(0.25)
    assert queue.mark_chunk(db, job_id, 1, "done", worker_id="w") == pytest.approx(0.5)
    with db.read() as s:
        assert crud.chunk_counts(s, [job_id]) == {job_id: {"done": 2, "pending": 2}}
        assert s.get(Job, job_id).n_chunks == 4


def test_release_and_cancel(db):
    _, job_id = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    assert queue.release_job(db, job_id, "w")
    with db.read() as s:
        assert s.get(Job, job_id).status == JobStatus.QUEUED
    assert queue.claim_next_job(db, "w2", 30) == job_id
    with db.write() as s:
        assert crud.request_cancel(s, job_id) == "requested"
    lease = queue.heartbeat(db, job_id, "w2")
    assert lease.owned and lease.cancel_requested
    assert queue.finish_job(db, job_id, JobStatus.CANCELLED, "cancelled by request", worker_id="w2")
    with db.write() as s:
        assert crud.request_cancel(s, job_id) == "final"
        assert crud.request_cancel(s, 12345) is None


def test_cancel_requested_blocks_storing_results(db):
    run_id, job_id = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    with db.write() as s:
        crud.request_cancel(s, job_id)
    profiles, wheels = _results(2, 1.0)
    assert not publish.publish_job(db, job_id, run_id, profiles, wheels, {}, worker_id="w")
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(ProfileBin)) == 0


def test_results_are_replaced_not_duplicated(db):
    run_id, job_id = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    profiles, wheels = _results(10, 1.0)
    assert publish.publish_job(db, job_id, run_id, profiles, wheels, {}, worker_id="w")
    with db.write() as s:
        job2 = crud.create_job(s, run_id, {"n_wheel_orders": 11}).id
    assert queue.claim_next_job(db, "w", 30) == job2
    profiles2, wheels2 = _results(6, 2.0)
    assert publish.publish_job(db, job2, run_id, profiles2, wheels2, {}, worker_id="w")
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(ProfileBin)) == 12
        assert set(s.scalars(select(ProfileBin.sleeper_amp)).all()) == {2.0}
        assert s.scalar(select(func.count()).select_from(WheelOOR)) == 2
        assert s.scalar(select(ProfileBin.sleeper_force_amp).limit(1)) is None
        df = results_reader.profile_rows(s, run_id, wheel="12")
        assert list(df["bin"]) == list(range(40_000, 40_006))
        assert results_reader.results_job(s, run_id).id == job2
    with db.write() as s:
        assert crud.delete_run(s, run_id)
    with db.read() as s:
        for model in (ProfileBin, WheelOOR, Job, Run):
            assert s.scalar(select(func.count()).select_from(model)) == 0


def test_wheels_stored_one_by_one_are_published_at_once(db):
    """Fan-out mode: a new job's rows are written wheel by wheel beside the published ones;
    readers switch at the publishing commit; a failed job leaves the published rows alone."""
    run_id, job1 = _make_run(db)
    queue.claim_next_job(db, "w", 30)
    old, old_wheels = _results(4, 1.0)
    assert publish.publish_job(db, job1, run_id, old, old_wheels, {}, worker_id="w")

    def amps() -> set[float]:
        with db.read() as s:
            return set(results_reader.profile_rows(s, run_id)["sleeper_amp"])

    with db.write() as s:
        job2 = crud.create_job(s, run_id, {"n_wheel_orders": 11}).id
    assert queue.claim_next_job(db, "w", 30) == job2
    new, new_wheels = _results(6, 2.0)
    for wheel in ("11", "12"):
        part = new[new["wheel"] == wheel]
        assert publish.store_wheel_rows(db, job2, run_id, part)
        assert publish.store_wheel_rows(db, job2, run_id, part)  # a retried task: replaced, not doubled
        assert amps() == {1.0}  # readers still see the published job
    with db.read() as s:
        assert results_reader.stored_profile_wheels(s, job2) == ["11", "12"]
        assert results_reader.results_job_id(s, run_id) == job1
    assert publish.publish_job(db, job2, run_id, None, new_wheels, {"v": 2}, worker_id=None)
    assert amps() == {2.0}
    with db.read() as s:
        assert s.scalar(select(func.count()).select_from(ProfileBin)) == 12  # job 1's rows dropped
        assert results_reader.results_job_id(s, run_id) == job2
    assert not publish.store_wheel_rows(db, job2, run_id, new)  # done: nothing more is written

    with db.write() as s:
        job3 = crud.create_job(s, run_id, {"n_wheel_orders": 11}).id
    assert queue.claim_next_job(db, "w", 30) == job3
    assert publish.store_wheel_rows(db, job3, run_id, _results(3, 5.0)[0])
    assert queue.finish_job(db, job3, JobStatus.FAILED, "boom", worker_id="w")
    assert amps() == {2.0}
    with db.read() as s:
        assert results_reader.stored_profile_wheels(s, job3) == []  # the failed job's rows are gone
