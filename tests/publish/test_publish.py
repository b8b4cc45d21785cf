"""The publish step (app/publish.py): a job's results, condition rows and alerts made the run's in one
transaction guarded by the job's state; rows replaced, never duplicated; the fan-out mode's wheels
stored one by one and published at once."""

from __future__ import annotations

from sqlalchemy import func, select

from app import publish
from app.db import crud, queue, results_reader
from app.db.models import Job, JobStatus, ProfileBin, Run, WheelOOR
from tests.db.support import job_results as _results
from tests.db.support import make_run_with_job as _make_run


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
