"""Tables of access control and audit: users, sessions, api_keys, audit_log.

users       browser users: name, Argon2id password hash, role, active flag;
            ``demo_credentials`` marks a user whose password was printed by
            ``trackvkf demo`` (production mode refuses to start while one is active);
            ``auth_source`` ``local`` (password here) or ``oidc`` (corporate sign-in:
            no password here, ``external_subject`` = ``<issuer> <sub>``)
sessions    browser sessions: SHA-256 of the session token, user, expiry; the ID
            token of a session begun at the OpenID provider (for its sign-out)
api_keys    keys of data systems: SHA-256 of the key, clear 8-character prefix,
            role, creator, last use, revocation
audit_log   append-only record of uploads, deletions, reprocessing, imports,
            logins and user/key changes (who, when, what). The migration adds
            triggers that abort any UPDATE or DELETE on it (SQLite and
            PostgreSQL), and no code path changes it.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import Boolean, ForeignKey, Index, Integer, String, Text
from sqlalchemy.orm import Mapped, mapped_column

from app.db.models.base import Base, JSONType, UTCDateTime, utcnow

__all__ = ["User", "UserSession", "ApiKey", "AuditEntry"]


class User(Base):
    """A browser user."""

    __tablename__ = "users"
    __table_args__ = (
        Index("ix_users_external_subject", "external_subject", unique=True),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    username: Mapped[str] = mapped_column(String(64), unique=True)
    password_hash: Mapped[str] = mapped_column(String(255))
    role: Mapped[str] = mapped_column(String(16))
    active: Mapped[bool] = mapped_column(Boolean, default=True)
    demo_credentials: Mapped[bool] = mapped_column(Boolean, default=False)
    created_by: Mapped[str | None] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    updated_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    last_login_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    auth_source: Mapped[str] = mapped_column(String(16), default="local", server_default="local")
    external_subject: Mapped[str | None] = mapped_column(String(512))
    #: the language of the pages and messages (en, de, fr, it); None: the browser's
    language: Mapped[str | None] = mapped_column(String(8))


class UserSession(Base):
    """A logged-in browser session (the token itself is never stored)."""

    __tablename__ = "sessions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id", ondelete="CASCADE"), index=True)
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    expires_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), index=True)
    client_ip: Mapped[str | None] = mapped_column(String(64))
    id_token: Mapped[str | None] = mapped_column(Text)


class ApiKey(Base):
    """An API key of a data system (stored hashed, shown once)."""

    __tablename__ = "api_keys"
    __table_args__ = ({"sqlite_autoincrement": True},)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64))
    prefix: Mapped[str] = mapped_column(String(16), unique=True)
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    role: Mapped[str] = mapped_column(String(16))
    created_by: Mapped[str | None] = mapped_column(String(128))
    created_at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow)
    expires_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    last_used_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())
    revoked_at: Mapped[dt.datetime | None] = mapped_column(UTCDateTime())


class AuditEntry(Base):
    """One line of the append-only audit log."""

    __tablename__ = "audit_log"
    __table_args__ = (
        Index("ix_audit_log_action_at", "action", "at"),
        # failed logins of one user name in a window (app.db.auth_crud.count_failed_logins)
        Index("ix_audit_log_action_target_at", "action", "target", "at"),
        {"sqlite_autoincrement": True},
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[dt.datetime] = mapped_column(UTCDateTime(), default=utcnow, index=True)
    actor: Mapped[str] = mapped_column(String(128), index=True)
    actor_kind: Mapped[str] = mapped_column(String(16))
    action: Mapped[str] = mapped_column(String(64))
    target: Mapped[str | None] = mapped_column(String(128))
    outcome: Mapped[str] = mapped_column(String(16), default="ok")
    client_ip: Mapped[str | None] = mapped_column(String(64))
    detail: Mapped[dict[str, Any] | None] = mapped_column(JSONType)
