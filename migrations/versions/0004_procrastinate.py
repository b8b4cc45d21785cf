"""Procrastinate task-queue schema (PostgreSQL only; nothing on SQLite).

The production mode (PostgreSQL + Procrastinate workers, see worker/tasks.py)
needs Procrastinate's tables, types and functions. They are read at migration
time from the installed package's ``procrastinate/sql/schema.sql`` (the schema
of the pinned Procrastinate version), so ``alembic upgrade head`` is the only
schema step of a deployment. On SQLite (embedded mode) this revision does
nothing.

Revision ID: 0004_procrastinate
Revises: 0003_auth_audit
Create Date: 2026-11-22
"""

from collections.abc import Sequence
from importlib import resources

from alembic import op

revision: str = "0004_procrastinate"
down_revision: str | None = "0003_auth_audit"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def _is_postgresql() -> bool:
    return op.get_bind().dialect.name == "postgresql"


def upgrade() -> None:
    if not _is_postgresql():
        return
    sql = resources.files("procrastinate.sql").joinpath("schema.sql").read_text(encoding="utf-8")
    # Many statements, dollar-quoted function bodies, '%' and ':' characters:
    # run it as one simple-protocol script on the DBAPI cursor of the migration
    # transaction (no SQLAlchemy or driver parameter parsing).
    _script(sql)


def _script(sql: str) -> None:
    dbapi = op.get_bind().connection.dbapi_connection
    with dbapi.cursor() as cursor:
        cursor.execute(sql)


def downgrade() -> None:
    if not _is_postgresql():
        return
    _script(
        """
        DO $$
        DECLARE r record;
        BEGIN
            FOR r IN SELECT tablename FROM pg_tables
                     WHERE schemaname = current_schema() AND tablename LIKE 'procrastinate\\_%' LOOP
                EXECUTE format('DROP TABLE IF EXISTS %I CASCADE', r.tablename);
            END LOOP;
            FOR r IN SELECT p.oid::regprocedure AS sig FROM pg_proc p
                     JOIN pg_namespace n ON n.oid = p.pronamespace
                     WHERE n.nspname = current_schema() AND p.proname LIKE 'procrastinate\\_%' LOOP
                EXECUTE format('DROP FUNCTION IF EXISTS %s CASCADE', r.sig);
            END LOOP;
            FOR r IN SELECT t.typname FROM pg_type t
                     JOIN pg_namespace n ON n.oid = t.typnamespace
                     WHERE n.nspname = current_schema() AND t.typname LIKE 'procrastinate\\_%'
                       AND t.typtype IN ('e', 'c') LOOP
                EXECUTE format('DROP TYPE IF EXISTS %I CASCADE', r.typname);
            END LOOP;
        END $$;
        """
    )
