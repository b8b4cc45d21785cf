"""All migrations on PostgreSQL (the Procrastinate schema included) and on SQLite
(where the Procrastinate revision does nothing); down and up again."""

from __future__ import annotations

import pytest
import sqlalchemy as sa

from app.db import migrate


def _head(url: str) -> str:
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(migrate.alembic_config(url)).get_current_head()


def _procrastinate_objects(url: str) -> dict[str, int]:
    engine = sa.create_engine(url)
    try:
        with engine.connect() as conn:
            return {
                "tables": conn.execute(sa.text(
                    "SELECT count(*) FROM pg_tables WHERE tablename LIKE 'procrastinate%'")).scalar(),
                "functions": conn.execute(sa.text(
                    "SELECT count(*) FROM pg_proc WHERE proname LIKE 'procrastinate%'")).scalar(),
                "types": conn.execute(sa.text(
                    "SELECT count(*) FROM pg_type WHERE typname LIKE 'procrastinate%' "
                    "AND typtype IN ('e', 'c')")).scalar(),
                "service": conn.execute(sa.text(
                    "SELECT count(*) FROM pg_tables WHERE tablename IN "
                    "('runs', 'jobs', 'job_chunks', 'profile_bins', 'wheel_oor')")).scalar(),
            }
    finally:
        engine.dispose()


def test_postgresql_upgrade_downgrade_with_procrastinate_schema(pg_cluster):
    if isinstance(pg_cluster, str):
        pytest.skip(pg_cluster)
    url = pg_cluster.create_database()
    migrate.upgrade(url)
    assert migrate.current_revision(url) == _head(url)
    objs = _procrastinate_objects(url)
    assert objs["tables"] == 4 and objs["functions"] > 10 and objs["types"] >= 3
    assert objs["service"] == 5
    # the schema works: Procrastinate can defer into it
    from app.settings import Settings
    from worker.hosting import make_app
    from worker.tasks import TASK_PLAN

    app = make_app(Settings(database_url=url))
    with app.open():
        job_id = app.configure_task(TASK_PLAN).defer(job_id=1)
    assert job_id >= 1

    migrate.downgrade(url, "0001_service_tables")
    assert _procrastinate_objects(url) == {"tables": 0, "functions": 0, "types": 0, "service": 5}
    migrate.downgrade(url)
    assert _procrastinate_objects(url)["service"] == 0
    migrate.upgrade(url)
    assert _procrastinate_objects(url)["tables"] == 4


def test_sqlite_migrations_skip_procrastinate(tmp_path):
    url = f"sqlite:///{tmp_path / 'm.sqlite'}"
    migrate.upgrade(url)
    assert migrate.current_revision(url) == _head(url)
    engine = sa.create_engine(url)
    try:
        names = set(sa.inspect(engine).get_table_names())
    finally:
        engine.dispose()
    assert {"runs", "jobs", "job_chunks", "profile_bins", "wheel_oor"} <= names
    assert not any(n.startswith("procrastinate") for n in names)
    migrate.downgrade(url)
    assert migrate.current_revision(url) is None
