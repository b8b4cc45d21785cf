"""The condition store's ``index`` column becomes ``condition_index`` (and ``index_sd`` ``condition_index_sd``).

The store keeps the condition index ``ln A`` (at matched speed); the places grade the stiffness index
``ln(A / A_ref(class, v))``. Named ``index`` alone, one word named both: the columns of
``segment_condition`` and ``condition_overview`` now say which index they hold. A rename in place
(``ALTER TABLE … RENAME COLUMN``: SQLite ≥ 3.25 and PostgreSQL), no row rewritten.

Revision ID: 0022_condition_index
Revises: 0021_oidc_sign_in
Create Date: 2026-11-27
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0022_condition_index"
down_revision: str | None = "0021_oidc_sign_in"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

#: (table, old name, new name)
_RENAMES = (
    ("segment_condition", "index", "condition_index"),
    ("segment_condition", "index_sd", "condition_index_sd"),
    ("condition_overview", "index", "condition_index"),
)


def _rename(table: str, old: str, new: str) -> None:
    op.execute(f'ALTER TABLE {table} RENAME COLUMN "{old}" TO "{new}"')


def upgrade() -> None:
    for table, old, new in _RENAMES:
        _rename(table, old, new)


def downgrade() -> None:
    for table, old, new in reversed(_RENAMES):
        _rename(table, new, old)
