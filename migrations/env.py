"""Alembic environment: SQLite (batch mode) and PostgreSQL.

The URL is taken from the Alembic config's ``sqlalchemy.url`` when a caller set
it (tests, ``trackvkf migrate``), else from the service settings
(``TRACKVKF_DATABASE_URL``).
"""

from __future__ import annotations

from alembic import context

from app.db.models import Base
from app.db.session import make_engine

config = context.config
target_metadata = Base.metadata


def _url() -> str:
    url = config.get_main_option("sqlalchemy.url")
    if url:
        return url
    from app.core.config import CoreSettings  # the database URL is a core setting

    return CoreSettings().database_url


def run_migrations_offline() -> None:
    """Emit SQL to stdout instead of running it."""
    url = _url()
    context.configure(
        url=url,
        target_metadata=target_metadata,
        literal_binds=True,
        dialect_opts={"paramstyle": "named"},
        render_as_batch=url.startswith("sqlite"),
    )
    with context.begin_transaction():
        context.run_migrations()


def run_migrations_online() -> None:
    """Run the migrations on a live connection."""
    # SQLite batch operations copy and drop tables: enforcing foreign keys
    # meanwhile would cascade deletes into child tables.
    engine = make_engine(_url(), sqlite_foreign_keys=False)
    try:
        with engine.connect() as conn:
            _run(conn)
    finally:
        engine.dispose()


def include_name(name, type_, parent_names) -> bool:  # noqa: ARG001 - Alembic's signature
    """Leave the partitions of profile_bins (PostgreSQL, app.db.partitions) out of comparisons."""
    return not (type_ == "table" and name is not None and name.startswith("profile_bins_"))


def _run(connection) -> None:
    context.configure(
        connection=connection,
        target_metadata=target_metadata,
        render_as_batch=connection.dialect.name == "sqlite",
        compare_type=True,
        include_name=include_name,
    )
    with context.begin_transaction():
        context.run_migrations()


if context.is_offline_mode():
    run_migrations_offline()
else:
    run_migrations_online()
