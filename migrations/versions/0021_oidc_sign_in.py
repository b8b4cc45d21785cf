"""Corporate sign-in (OpenID Connect): where a user comes from, and the ID token of a session.

users.auth_source       ``local`` (a password here) or ``oidc`` (signed in at the provider)
users.external_subject  ``<issuer> <sub>`` of an ``oidc`` user: the provider's stable id of them
sessions.id_token       the ID token a session of an ``oidc`` user began with (the provider's
                        sign-out is asked with it as ``id_token_hint``)

Revision ID: 0021_oidc_sign_in
Revises: 0020_place_uncertainty
Create Date: 2026-11-28
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0021_oidc_sign_in"
down_revision: str | None = "0020_place_uncertainty"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    with op.batch_alter_table("users") as batch:
        batch.add_column(sa.Column("auth_source", sa.String(16), nullable=False, server_default="local"))
        batch.add_column(sa.Column("external_subject", sa.String(512), nullable=True))
    op.create_index("ix_users_external_subject", "users", ["external_subject"], unique=True)
    with op.batch_alter_table("sessions") as batch:
        batch.add_column(sa.Column("id_token", sa.Text(), nullable=True))


def downgrade() -> None:
    with op.batch_alter_table("sessions") as batch:
        batch.drop_column("id_token")
    op.drop_index("ix_users_external_subject", table_name="users")
    with op.batch_alter_table("users") as batch:
        batch.drop_column("external_subject")
        batch.drop_column("auth_source")
