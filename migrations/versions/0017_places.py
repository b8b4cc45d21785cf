"""Places (issue 25): places, place_observations, place_events, place_status_history, place_actions,
place_runs (app/db/models/places.py). Places are made by the publish step from the runs published
after this revision; earlier runs give theirs when they are reprocessed.

Revision ID: 0017_places
Revises: 0015_track_impacts
Create Date: 2026-11-26
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0017_places"
down_revision: str | None = "0015_track_impacts"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table("place_runs",
    sa.Column("run_id", sa.Integer(), autoincrement=False, nullable=False),
    sa.Column("line_key", sa.Integer(), nullable=False),
    sa.Column("run_time", sa.DateTime(), nullable=False),
    sa.Column("method_version", sa.String(length=80), nullable=False),
    sa.Column("start_m", sa.Float(), nullable=False),
    sa.Column("end_m", sa.Float(), nullable=False),
    sa.Column("n_places", sa.Integer(), nullable=False),
    sa.Column("n_events", sa.Integer(), nullable=False),
    sa.Column("applied_at", sa.DateTime(), nullable=False),
    sa.PrimaryKeyConstraint("run_id", name=op.f("pk_place_runs"))
    )
    with op.batch_alter_table("place_runs", schema=None) as batch_op:
        batch_op.create_index("ix_place_runs_line_key_run_time", ["line_key", "run_time"], unique=False)

    op.create_table("places",
    sa.Column("id", sa.Integer(), nullable=False),
    sa.Column("line_key", sa.Integer(), nullable=False),
    sa.Column("direction", sa.SmallInteger(), nullable=False),
    sa.Column("start_m", sa.Float(), nullable=False),
    sa.Column("end_m", sa.Float(), nullable=False),
    sa.Column("peak_m", sa.Float(), nullable=False),
    sa.Column("centre_m", sa.Float(), nullable=False),
    sa.Column("cls", sa.String(length=64), nullable=True),
    sa.Column("baseline", sa.Float(), nullable=True),
    sa.Column("explained_by", sa.Integer(), nullable=True),
    sa.Column("tier", sa.SmallInteger(), nullable=False),
    sa.Column("listed", sa.Boolean(), nullable=False),
    sa.Column("active", sa.Boolean(), nullable=False),
    sa.Column("misses", sa.Integer(), nullable=False),
    sa.Column("lower_runs", sa.Integer(), nullable=False),
    sa.Column("level", sa.Float(), nullable=False),
    sa.Column("change", sa.Float(), nullable=True),
    sa.Column("severity", sa.Float(), nullable=False),
    sa.Column("evidence", sa.Integer(), nullable=False),
    sa.Column("wheels", sa.Integer(), nullable=False),
    sa.Column("wheel_labels", sa.String(length=200), nullable=False),
    sa.Column("runs_confirming", sa.Integer(), nullable=False),
    sa.Column("tendency", sa.String(length=16), nullable=False),
    sa.Column("rate_per_year", sa.Float(), nullable=True),
    sa.Column("rate_low", sa.Float(), nullable=True),
    sa.Column("rate_high", sa.Float(), nullable=True),
    sa.Column("next_limit", sa.Float(), nullable=True),
    sa.Column("days_to_next", sa.Float(), nullable=True),
    sa.Column("first_run_id", sa.Integer(), nullable=False),
    sa.Column("last_run_id", sa.Integer(), nullable=False),
    sa.Column("first_seen", sa.DateTime(), nullable=False),
    sa.Column("last_confirmed", sa.DateTime(), nullable=False),
    sa.Column("method_version", sa.String(length=80), nullable=False),
    sa.Column("status", sa.String(length=16), nullable=False),
    sa.Column("status_comment", sa.Text(), nullable=True),
    sa.Column("status_by", sa.String(length=128), nullable=True),
    sa.Column("status_at", sa.DateTime(), nullable=True),
    sa.Column("created_at", sa.DateTime(), nullable=False),
    sa.Column("updated_at", sa.DateTime(), nullable=False),
    sa.PrimaryKeyConstraint("id", name=op.f("pk_places")),
    sqlite_autoincrement=True
    )
    with op.batch_alter_table("places", schema=None) as batch_op:
        batch_op.create_index("ix_places_line_key_listed_active", ["line_key", "listed", "active"], unique=False)

    op.create_table("place_actions",
    sa.Column("place_id", sa.Integer(), nullable=False),
    sa.Column("action_id", sa.Integer(), autoincrement=False, nullable=False),
    sa.Column("relation", sa.String(length=16), nullable=False),
    sa.Column("kind", sa.String(length=32), nullable=False),
    sa.Column("date", sa.Date(), nullable=False),
    sa.Column("km_from", sa.Float(), nullable=False),
    sa.Column("km_to", sa.Float(), nullable=False),
    sa.ForeignKeyConstraint(["place_id"], ["places.id"], name=op.f("fk_place_actions_place_id_places"), ondelete="CASCADE"),
    sa.PrimaryKeyConstraint("place_id", "action_id", name=op.f("pk_place_actions"))
    )
    op.create_table("place_events",
    sa.Column("id", sa.Integer(), nullable=False),
    sa.Column("place_id", sa.Integer(), nullable=False),
    sa.Column("run_id", sa.Integer(), nullable=True),
    sa.Column("kind", sa.String(length=16), nullable=False),
    sa.Column("old_tier", sa.SmallInteger(), nullable=True),
    sa.Column("new_tier", sa.SmallInteger(), nullable=True),
    sa.Column("action_id", sa.Integer(), nullable=True),
    sa.Column("alerted", sa.Boolean(), nullable=False),
    sa.Column("time", sa.DateTime(), nullable=False),
    sa.Column("created_at", sa.DateTime(), nullable=False),
    sa.ForeignKeyConstraint(["place_id"], ["places.id"], name=op.f("fk_place_events_place_id_places"), ondelete="CASCADE"),
    sa.PrimaryKeyConstraint("id", name=op.f("pk_place_events")),
    sqlite_autoincrement=True
    )
    with op.batch_alter_table("place_events", schema=None) as batch_op:
        batch_op.create_index("ix_place_events_place_id_id", ["place_id", "id"], unique=False)

    op.create_table("place_observations",
    sa.Column("id", sa.Integer(), nullable=False),
    sa.Column("place_id", sa.Integer(), nullable=False),
    sa.Column("run_id", sa.Integer(), nullable=False),
    sa.Column("run_time", sa.DateTime(), nullable=False),
    sa.Column("day", sa.Float(), nullable=False),
    sa.Column("start_m", sa.Float(), nullable=False),
    sa.Column("end_m", sa.Float(), nullable=False),
    sa.Column("centre_m", sa.Float(), nullable=False),
    sa.Column("peak_m", sa.Float(), nullable=False),
    sa.Column("level", sa.Float(), nullable=False),
    sa.Column("change", sa.Float(), nullable=True),
    sa.Column("tier", sa.SmallInteger(), nullable=False),
    sa.Column("severity", sa.Float(), nullable=False),
    sa.Column("evidence", sa.Integer(), nullable=False),
    sa.Column("wheels", sa.Integer(), nullable=False),
    sa.Column("wheel_labels", sa.String(length=200), nullable=False),
    sa.Column("speed_kmh", sa.Float(), nullable=True),
    sa.Column("method_version", sa.String(length=80), nullable=False),
    sa.ForeignKeyConstraint(["place_id"], ["places.id"], name=op.f("fk_place_observations_place_id_places"), ondelete="CASCADE"),
    sa.PrimaryKeyConstraint("id", name=op.f("pk_place_observations"))
    )
    with op.batch_alter_table("place_observations", schema=None) as batch_op:
        batch_op.create_index("ix_place_observations_place_id_day", ["place_id", "day"], unique=False)
        batch_op.create_index(batch_op.f("ix_place_observations_run_id"), ["run_id"], unique=False)

    op.create_table("place_status_history",
    sa.Column("id", sa.Integer(), nullable=False),
    sa.Column("place_id", sa.Integer(), nullable=False),
    sa.Column("by", sa.String(length=128), nullable=False),
    sa.Column("at", sa.DateTime(), nullable=False),
    sa.Column("old", sa.String(length=16), nullable=False),
    sa.Column("new", sa.String(length=16), nullable=False),
    sa.Column("comment", sa.Text(), nullable=False),
    sa.ForeignKeyConstraint(["place_id"], ["places.id"], name=op.f("fk_place_status_history_place_id_places"), ondelete="CASCADE"),
    sa.PrimaryKeyConstraint("id", name=op.f("pk_place_status_history"))
    )
    with op.batch_alter_table("place_status_history", schema=None) as batch_op:
        batch_op.create_index("ix_place_status_history_place_id_id", ["place_id", "id"], unique=False)



def downgrade() -> None:
    with op.batch_alter_table("place_status_history", schema=None) as batch_op:
        batch_op.drop_index("ix_place_status_history_place_id_id")

    op.drop_table("place_status_history")
    with op.batch_alter_table("place_observations", schema=None) as batch_op:
        batch_op.drop_index(batch_op.f("ix_place_observations_run_id"))
        batch_op.drop_index("ix_place_observations_place_id_day")

    op.drop_table("place_observations")
    with op.batch_alter_table("place_events", schema=None) as batch_op:
        batch_op.drop_index("ix_place_events_place_id_id")

    op.drop_table("place_events")
    op.drop_table("place_actions")
    with op.batch_alter_table("places", schema=None) as batch_op:
        batch_op.drop_index("ix_places_line_key_listed_active")

    op.drop_table("places")
    with op.batch_alter_table("place_runs", schema=None) as batch_op:
        batch_op.drop_index("ix_place_runs_line_key_run_time")

    op.drop_table("place_runs")
