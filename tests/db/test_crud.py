"""Runs and jobs (app/db/crud.py) on a real SQLite database: filters, pages, newest
jobs, deletion of a run with everything it owns."""

from __future__ import annotations

import datetime as dt

import pytest
from sqlalchemy import func, select

from app.db import crud, results_writer
from app.db.models import Job, JobChunk, JobStatus, ProfileBin, Run, WheelOOR
from app.db.session import Database
from tests.db.support import add_run, profile_table

T0 = dt.datetime(2024, 5, 1, 8, 0, tzinfo=dt.UTC)


def _runs(db: Database) -> dict[str, int]:
    """Four runs on two lines and two vehicles, a day apart (r0 oldest)."""
    spec = [("L1", "V1", "1"), ("L1", "V2", "2"), ("L2", "V1", "1"), ("L2", "V2", "1")]
    return {
        f"r{i}": add_run(db, sha=f"{i:064x}", line_id=line, vehicle_id=vehicle, track=track,
                         start_time=T0 + dt.timedelta(days=i))
        for i, (line, vehicle, track) in enumerate(spec)
    }


def _job(db: Database, run_id: int, status: str = JobStatus.QUEUED) -> int:
    with db.write() as s:
        job = crud.create_job(s, run_id, {"bin_length_m": 0.25}, created_by="tests")
        job.status = status
        return job.id


def test_list_runs_filters_newest_first_and_counts_all_pages(db):
    r = _runs(db)
    with db.read() as s:
        runs, total = crud.list_runs(s)
        assert [x.id for x in runs] == [r["r3"], r["r2"], r["r1"], r["r0"]] and total == 4
        runs, total = crud.list_runs(s, line_id="L1")
        assert [x.id for x in runs] == [r["r1"], r["r0"]] and total == 2
        runs, total = crud.list_runs(s, vehicle_id="V1", track="1")
        assert [x.id for x in runs] == [r["r2"], r["r0"]] and total == 2
        runs, total = crud.list_runs(s, start_from=T0 + dt.timedelta(days=1), start_to=T0 + dt.timedelta(days=2))
        assert [x.id for x in runs] == [r["r2"], r["r1"]] and total == 2  # both ends inclusive
        runs, total = crud.list_runs(s, limit=2, offset=1)
        assert [x.id for x in runs] == [r["r2"], r["r1"]] and total == 4
        assert crud.list_runs(s, line_id="none") == ([], 0)
        assert crud.get_run_by_sha256(s, f"{2:064x}").id == r["r2"]
        assert crud.get_run_by_sha256(s, "f" * 64) is None


@pytest.mark.parametrize(("kwargs", "message"), [({"limit": 0}, "limit"), ({"offset": -1}, "offset")])
def test_list_pages_reject_bad_limits(db, kwargs, message):
    with db.read() as s:
        for lister in (crud.list_runs, crud.list_jobs):
            with pytest.raises(ValueError, match=message):
                lister(s, **kwargs)


def test_list_jobs_by_run_and_status(db):
    r = _runs(db)
    a = _job(db, r["r0"], JobStatus.DONE)
    b = _job(db, r["r0"], JobStatus.FAILED)
    c = _job(db, r["r1"], JobStatus.DONE)
    with db.read() as s:
        jobs, total = crud.list_jobs(s)
        assert [j.id for j in jobs] == [c, b, a] and total == 3
        jobs, total = crud.list_jobs(s, run_id=r["r0"])
        assert [j.id for j in jobs] == [b, a] and total == 2
        jobs, total = crud.list_jobs(s, status=JobStatus.DONE, limit=1)
        assert [j.id for j in jobs] == [c] and total == 2
        assert crud.list_jobs(s, run_id=r["r0"], status=JobStatus.QUEUED) == ([], 0)
        with pytest.raises(ValueError, match="status must be one of"):
            crud.list_jobs(s, status="sleeping")
        assert crud.queue_counts(s) == {JobStatus.DONE: 2, JobStatus.FAILED: 1}
        assert crud.get_job(s, a).created_by == "tests"


def test_latest_and_active_jobs(db):
    r = _runs(db)
    _job(db, r["r0"], JobStatus.DONE)
    new = _job(db, r["r0"], JobStatus.RUNNING)
    other = _job(db, r["r1"], JobStatus.CANCELLED)
    with db.read() as s:
        assert crud.latest_job(s, r["r0"]).id == new
        assert crud.latest_job(s, r["r2"]) is None
        latest = crud.latest_jobs(s, [r["r0"], r["r1"], r["r2"]])
        assert {k: v.id for k, v in latest.items()} == {r["r0"]: new, r["r1"]: other}  # r2 has none
        assert crud.latest_jobs(s, []) == {}
        assert crud.active_job(s, r["r0"]).id == new
        assert crud.active_job(s, r["r1"]) is None


def test_request_cancel_of_a_queued_job_is_final_at_once(db):
    run_id = add_run(db)
    job_id = _job(db, run_id)
    with db.write() as s:
        assert crud.request_cancel(s, job_id) == "cancelled"
    with db.read() as s:
        job = crud.get_job(s, job_id)
        assert job.status == JobStatus.CANCELLED and job.cancel_requested and job.finished_at is not None
    with db.write() as s:
        assert crud.request_cancel(s, job_id) == "final"


def test_delete_run_removes_everything_it_owns_and_nothing_else(db):
    keep, gone = add_run(db, sha="1" * 64), add_run(db, sha="2" * 64)
    for run_id in (keep, gone):
        job_id = _job(db, run_id, JobStatus.DONE)
        with db.write() as s:
            s.add(JobChunk(job_id=job_id, chunk_index=0, status="done", spec={}))
            results_writer.store_profile_rows(s, run_id, job_id, profile_table(n_bins=5))
            results_writer.publish_results(s, run_id, job_id, [{"wheel": "11"}])

    def counts() -> dict[str, int]:
        with db.read() as s:
            return {m.__tablename__: s.scalar(select(func.count()).select_from(m))
                    for m in (Run, Job, JobChunk, ProfileBin, WheelOOR)}

    assert counts() == {"runs": 2, "jobs": 2, "job_chunks": 2, "profile_bins": 20, "wheel_oor": 2}
    with db.write() as s:
        assert crud.delete_run(s, gone)
    assert counts() == {"runs": 1, "jobs": 1, "job_chunks": 1, "profile_bins": 10, "wheel_oor": 1}
    with db.write() as s:
        assert not crud.delete_run(s, gone)
        assert crud.get_run(s, keep) is not None
        assert {b.run_id for b in s.scalars(select(ProfileBin))} == {keep}
