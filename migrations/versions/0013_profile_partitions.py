"""Retention of the 25 cm rows: runs.profiles_swept_at; on PostgreSQL profile_bins partitioned.

PostgreSQL: ``profile_bins`` becomes a table partitioned by range of ``job_id``
(partitions of 1000 jobs, created ahead by the writers,
:func:`app.db.partitions.ensure_for_job`, plus a default partition), so the
retention sweep drops the partitions of old jobs instead of deleting their
rows one by one. The rows already stored are not copied: the old table is
attached as the first partition (``MINVALUE`` … the next multiple of 1000
above the highest job id) after a CHECK constraint proved its range, so the
upgrade costs one scan of the old rows, no rewrite. SQLite is unchanged (the
sweep deletes rows there). The downgrade copies the rows back into a plain
table.

Revision ID: 0013_profile_partitions
Revises: 0012_condition_webhooks
Create Date: 2026-11-24
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0013_profile_partitions"
down_revision: str | None = "0012_condition_webhooks"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: app.db.partitions.PARTITION_JOBS when this revision was written (a migration keeps its own copy)
_SIZE = 1000
_COARSE = "display_level >= 2"


def upgrade() -> None:
    op.add_column("runs", sa.Column("profiles_swept_at", sa.DateTime(), nullable=True))
    bind = op.get_bind()
    if bind.dialect.name != "postgresql":
        return
    top = int(bind.execute(sa.text("SELECT COALESCE(MAX(id), 0) FROM jobs")).scalar())
    first = (top // _SIZE + 1) * _SIZE
    op.execute("ALTER TABLE profile_bins RENAME TO profile_bins_legacy")
    op.execute("ALTER TABLE profile_bins_legacy RENAME CONSTRAINT pk_profile_bins TO pk_profile_bins_legacy")
    op.execute("ALTER INDEX ix_profile_bins_coarse_display RENAME TO ix_profile_bins_legacy_coarse_display")
    op.execute("CREATE TABLE profile_bins (LIKE profile_bins_legacy INCLUDING DEFAULTS) PARTITION BY RANGE (job_id)")
    op.execute("ALTER TABLE profile_bins ADD CONSTRAINT pk_profile_bins PRIMARY KEY (job_id, wheel, bin)")
    op.execute(f"CREATE INDEX ix_profile_bins_coarse_display ON profile_bins (job_id, wheel, km, display_level) "
               f"WHERE {_COARSE}")
    op.execute(f"ALTER TABLE profile_bins_legacy ADD CONSTRAINT ck_profile_bins_legacy_range "
               f"CHECK (job_id < {first}) NOT VALID")
    op.execute("ALTER TABLE profile_bins_legacy VALIDATE CONSTRAINT ck_profile_bins_legacy_range")
    op.execute(f"ALTER TABLE profile_bins ATTACH PARTITION profile_bins_legacy FOR VALUES FROM (MINVALUE) TO ({first})")
    op.execute("CREATE TABLE profile_bins_default PARTITION OF profile_bins DEFAULT")
    op.execute(f"CREATE TABLE profile_bins_j{first:010d} PARTITION OF profile_bins "
               f"FOR VALUES FROM ({first}) TO ({first + _SIZE})")


def downgrade() -> None:
    bind = op.get_bind()
    if bind.dialect.name == "postgresql":
        op.execute("CREATE TABLE profile_bins_plain (LIKE profile_bins INCLUDING DEFAULTS)")
        op.execute("INSERT INTO profile_bins_plain SELECT * FROM profile_bins")
        op.execute("DROP TABLE profile_bins")
        op.execute("ALTER TABLE profile_bins_plain RENAME TO profile_bins")
        op.execute("ALTER TABLE profile_bins ADD CONSTRAINT pk_profile_bins PRIMARY KEY (job_id, wheel, bin)")
        op.execute(f"CREATE INDEX ix_profile_bins_coarse_display ON profile_bins (job_id, wheel, km, display_level) "
                   f"WHERE {_COARSE}")
    op.drop_column("runs", "profiles_swept_at")
