"""audit_log: index of failed logins per user name.

The login endpoint counts a user name's failed logins of the last hour
(``auth.login``, outcome ``denied``) to refuse brute force against it from
browsers without that user's device cookie; the index ``(action, target, at)``
makes that count a range scan of the name's own entries.

Revision ID: 0008_audit_login_failures
Revises: 0007_channel_maps
Create Date: 2026-11-23
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0008_audit_login_failures"
down_revision: str | None = "0007_channel_maps"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_index("ix_audit_log_action_target_at", "audit_log", ["action", "target", "at"])


def downgrade() -> None:
    op.drop_index("ix_audit_log_action_target_at", table_name="audit_log")
