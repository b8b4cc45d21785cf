"""A job queued on PostgreSQL notifies the workers at its commit (and only then), so
they plan it at once instead of at the periodic dispatcher's next run."""

from __future__ import annotations

import psycopg
import pytest

from app.db import crud, migrate
from app.db.models import Run, utcnow
from app.db.session import Database
from worker.hosting import libpq_url


def _notes(conn: psycopg.Connection) -> list[str]:
    return [n.payload for n in conn.notifies(timeout=0.5, stop_after=10)]


def test_job_commit_notifies_its_id_rollback_does_not(pg_cluster):
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    url = pg_cluster.create_database()
    migrate.upgrade(url)
    db = Database(url)
    try:
        with psycopg.connect(libpq_url(url), autocommit=True) as listener:
            listener.execute(f"LISTEN {crud.JOBS_CHANNEL}")
            with db.write() as s:
                run = Run(sha256="b" * 64, file_path="x", source_format="hdf5", size_bytes=1, fs=1e4,
                          n_samples=10, duration_s=1e-3, channels=["Z11"], meta={}, created_at=utcnow())
                s.add(run)
                s.flush()
                job_id = crud.create_job(s, run.id, {}).id
                run_id = run.id
            assert _notes(listener) == [str(job_id)]

            class Abort(Exception):
                pass

            with pytest.raises(Abort), db.write() as s:
                crud.create_job(s, run_id, {})
                raise Abort
            assert _notes(listener) == []
    finally:
        db.dispose()
