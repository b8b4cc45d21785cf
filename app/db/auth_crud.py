"""Queries and changes of users, sessions, API keys and the audit log.

Every function takes an open :class:`~sqlalchemy.orm.Session`; the caller
decides the transaction. The audit log is only ever inserted into
(:func:`audit`); there is no function that updates or deletes it.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import delete, func, select, update
from sqlalchemy.orm import Session

from app.core.i18n import LANGUAGES, _, is_language
from app.core.security import (
    DEFAULT_PASSWORD_COST,
    ROLES,
    PasswordCost,
    api_key_prefix,
    hash_password,
    new_api_key,
    new_session_token,
    token_digest,
)
from app.db.models import ApiKey, AuditEntry, User, UserSession, utcnow

__all__ = [
    "AuthError",
    "create_user",
    "create_external_user",
    "get_user",
    "user_by_external_subject",
    "session_id_token",
    "list_users",
    "update_user",
    "delete_user",
    "create_session",
    "session_user",
    "delete_session",
    "create_api_key",
    "list_api_keys",
    "revoke_api_key",
    "api_key_by_token",
    "touch_api_key",
    "audit",
    "count_failed_logins",
    "list_audit",
    "active_demo_users",
]

#: last_used_at of an API key is refreshed at most this often (one write per minute).
LAST_USED_RESOLUTION = dt.timedelta(seconds=60)
_USERNAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-@")


class AuthError(ValueError):
    """A user or key change is not acceptable; ``field`` names the input at fault."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message


def _check_role(role: str) -> str:
    if role not in ROLES:
        raise AuthError("role", _("must be one of {items}, got {role!r}", items=', '.join(ROLES), role=role))
    return role


def _check_username(username: str) -> str:
    if not (1 <= len(username) <= 64) or not set(username) <= _USERNAME_CHARS:
        raise AuthError(
            "username", _("1 to 64 characters of letters, digits and . _ - @")
        )
    return username


def _hash(password: str, cost: PasswordCost) -> str:
    try:
        return hash_password(password, cost)
    except ValueError as exc:
        raise AuthError("password", exc.args[0] if exc.args and isinstance(exc.args[0], str) else str(exc)) from None


# --- users -----------------------------------------------------------------------
def create_user(
    session: Session,
    username: str,
    password: str,
    role: str,
    *,
    created_by: str | None = None,
    demo_credentials: bool = False,
    password_cost: PasswordCost = DEFAULT_PASSWORD_COST,
) -> User:
    """Insert a user with an Argon2id hash of ``password`` at ``password_cost`` (the service's:
    ``Settings.password_cost``).

    Raises
    ------
    AuthError
        For a bad user name, role or password, or a name already taken.
    """
    _check_username(username)
    _check_role(role)
    if get_user(session, username) is not None:
        raise AuthError("username", _("user {username!r} exists", username=username))
    user = User(
        username=username,
        password_hash=_hash(password, password_cost),
        role=role,
        active=True,
        demo_credentials=demo_credentials,
        created_by=created_by,
        created_at=utcnow(),
    )
    session.add(user)
    session.flush()
    return user


def create_external_user(
    session: Session, username: str, role: str, external_subject: str, *, created_by: str | None = None
) -> User:
    """Insert a user who signs in at the OpenID provider (``auth_source`` ``oidc``, no password).

    Raises
    ------
    AuthError
        For a bad user name or role, or a name already taken.
    """
    _check_username(username)
    _check_role(role)
    if get_user(session, username) is not None:
        raise AuthError("username", _("user {username!r} exists", username=username))
    user = User(
        username=username, password_hash="", role=role, active=True, demo_credentials=False,
        created_by=created_by, created_at=utcnow(), auth_source="oidc",
        external_subject=external_subject[:512],
    )
    session.add(user)
    session.flush()
    return user


def user_by_external_subject(session: Session, external_subject: str) -> User | None:
    """The user the provider knows as ``external_subject`` (``"<issuer> <sub>"``), or None."""
    return session.scalar(select(User).where(User.external_subject == external_subject[:512]))


def get_user(session: Session, username: str) -> User | None:
    """The user called ``username``, or None."""
    return session.scalar(select(User).where(User.username == username))


def list_users(session: Session) -> list[User]:
    """All users by name."""
    return list(session.scalars(select(User).order_by(User.username)))


def update_user(
    session: Session,
    username: str,
    *,
    password: str | None = None,
    role: str | None = None,
    active: bool | None = None,
    password_cost: PasswordCost = DEFAULT_PASSWORD_COST,
) -> User | None:
    """Change a user's password (hashed at ``password_cost``), role or active flag; None if there
    is no such user.

    A new password clears ``demo_credentials``. Changing the password, the
    role or deactivating the user ends the user's sessions.
    """
    user = get_user(session, username)
    if user is None:
        return None
    if role is not None:
        user.role = _check_role(role)
    if password is not None:
        if user.auth_source != "local":
            raise AuthError("password", _("{username} signs in at the OpenID provider and has no password here", username=username))
        user.password_hash = _hash(password, password_cost)
        user.demo_credentials = False
    if active is not None:
        user.active = bool(active)
    if password is not None or role is not None or active is False:
        session.execute(delete(UserSession).where(UserSession.user_id == user.id))
    user.updated_at = utcnow()
    session.flush()
    return user


def set_language(session: Session, user_id: int, language: str | None) -> None:
    """Keep ``language`` (one of :data:`app.core.i18n.LANGUAGES`, None: the browser's) with a user.

    Raises
    ------
    AuthError
        ``language`` is not one the service speaks.
    """
    if language is not None and not is_language(language):
        raise AuthError("language", _("must be one of {items} or null, got {language!r}", items=', '.join(LANGUAGES), language=language))
    session.execute(update(User).where(User.id == user_id).values(language=language, updated_at=utcnow()))


def delete_user(session: Session, username: str) -> bool:
    """Delete a user and its sessions; whether it existed."""
    user = get_user(session, username)
    if user is None:
        return False
    session.execute(delete(UserSession).where(UserSession.user_id == user.id))
    session.delete(user)
    session.flush()
    return True


def active_demo_users(session: Session) -> list[str]:
    """Names of active users whose demo credentials were printed and never changed."""
    rows = session.scalars(
        select(User.username).where(User.demo_credentials.is_(True), User.active.is_(True))
    )
    return list(rows)


def count_users(session: Session) -> int:
    """Number of users."""
    return int(session.scalar(select(func.count()).select_from(User)) or 0)


# --- sessions ----------------------------------------------------------------------
def create_session(
    session: Session, user: User, ttl: dt.timedelta, client_ip: str | None = None,
    *, id_token: str | None = None,
) -> str:
    """Start a browser session for ``user``; returns the token (stored hashed).

    ``id_token``: the OpenID provider's ID token the session began with (kept for the
    provider's sign-out). Expired sessions of all users are removed on the way.
    """
    now = utcnow()
    session.execute(delete(UserSession).where(UserSession.expires_at < now))
    token = new_session_token()
    session.add(
        UserSession(
            token_hash=token_digest(token),
            user_id=user.id,
            created_at=now,
            expires_at=now + ttl,
            client_ip=(client_ip or None) and client_ip[:64],
            id_token=id_token,
        )
    )
    user.last_login_at = now
    session.flush()
    return token


def session_user(session: Session, token: str) -> User | None:
    """The active user of an unexpired session token, or None."""
    if not token or len(token) > 256:
        return None
    row = session.execute(
        select(User, UserSession.expires_at)
        .join(UserSession, UserSession.user_id == User.id)
        .where(UserSession.token_hash == token_digest(token))
    ).first()
    if row is None:
        return None
    user, expires_at = row
    if expires_at <= utcnow() or not user.active:
        return None
    return user


def session_id_token(session: Session, token: str) -> str | None:
    """The ID token a session began with at the OpenID provider; None for a local login."""
    if not token or len(token) > 256:
        return None
    return session.scalar(select(UserSession.id_token).where(UserSession.token_hash == token_digest(token)))


def delete_session(session: Session, token: str) -> None:
    """End the session of ``token`` (nothing if unknown)."""
    session.execute(delete(UserSession).where(UserSession.token_hash == token_digest(token)))


# --- API keys -------------------------------------------------------------------------
def create_api_key(
    session: Session,
    name: str,
    role: str,
    *,
    created_by: str | None = None,
    expires_at: dt.datetime | None = None,
) -> tuple[ApiKey, str]:
    """Insert a new API key; returns the row and the key (to show once).

    Raises
    ------
    AuthError
        For an empty or too long name or an unknown role.
    """
    name = (name or "").strip()
    if not (1 <= len(name) <= 64) or not name.isprintable():
        raise AuthError("name", _("1 to 64 printable characters"))
    _check_role(role)
    generated = new_api_key()
    row = ApiKey(
        name=name,
        prefix=generated.prefix,
        key_hash=generated.digest,
        role=role,
        created_by=created_by,
        created_at=utcnow(),
        expires_at=expires_at,
    )
    session.add(row)
    session.flush()
    return row, generated.key


def list_api_keys(session: Session, *, include_revoked: bool = True) -> list[ApiKey]:
    """API keys, newest first."""
    stmt = select(ApiKey).order_by(ApiKey.id.desc())
    if not include_revoked:
        stmt = stmt.where(ApiKey.revoked_at.is_(None))
    return list(session.scalars(stmt))


def revoke_api_key(session: Session, key_id: int) -> ApiKey | None:
    """Revoke a key (it stays listed, marked revoked); None if there is no such key."""
    row = session.get(ApiKey, key_id)
    if row is None:
        return None
    if row.revoked_at is None:
        row.revoked_at = utcnow()
        session.flush()
    return row


def api_key_by_token(session: Session, token: str) -> ApiKey | None:
    """The valid (not revoked, not expired) key ``token``, or None."""
    if not token or len(token) > 256 or api_key_prefix(token) is None:
        return None
    row = session.scalar(select(ApiKey).where(ApiKey.key_hash == token_digest(token)))
    if row is None or row.revoked_at is not None:
        return None
    if row.expires_at is not None and row.expires_at <= utcnow():
        return None
    return row


def touch_api_key(session: Session, key_id: int) -> None:
    """Record the use of a key (to the minute: at most one write per key and minute)."""
    row = session.get(ApiKey, key_id)
    if row is None:
        return
    now = utcnow()
    if row.last_used_at is None or now - row.last_used_at >= LAST_USED_RESOLUTION:
        row.last_used_at = now


def needs_touch(key: ApiKey) -> bool:
    """Whether the key's last use is older than the recording resolution."""
    return key.last_used_at is None or utcnow() - key.last_used_at >= LAST_USED_RESOLUTION


# --- audit log --------------------------------------------------------------------------
def audit(
    session: Session,
    *,
    actor: str,
    actor_kind: str,
    action: str,
    target: str | None = None,
    outcome: str = "ok",
    client_ip: str | None = None,
    detail: dict[str, Any] | None = None,
) -> AuditEntry:
    """Append one entry to the audit log (in the caller's transaction)."""
    entry = AuditEntry(
        at=utcnow(),
        actor=actor[:128],
        actor_kind=actor_kind[:16],
        action=action[:64],
        target=None if target is None else str(target)[:128],
        outcome=outcome[:16],
        client_ip=None if client_ip is None else client_ip[:64],
        detail=detail,
    )
    session.add(entry)
    session.flush()
    return entry


def count_failed_logins(session: Session, username: str, since: dt.datetime) -> int:
    """Failed logins (audited ``auth.login`` with outcome ``denied``) of ``username`` since ``since``.

    The audit log is the failure counter: one row per failed attempt, shared by
    every API process (index ``ix_audit_log_action_target_at``).
    """
    stmt = select(func.count()).select_from(AuditEntry).where(
        AuditEntry.action == "auth.login",
        AuditEntry.target == username[:128],
        AuditEntry.at >= since,
        AuditEntry.outcome == "denied",
    )
    return int(session.scalar(stmt) or 0)


def list_audit(
    session: Session,
    *,
    action: str | None = None,
    actor: str | None = None,
    since: dt.datetime | None = None,
    until: dt.datetime | None = None,
    limit: int = 100,
    offset: int = 0,
) -> tuple[list[AuditEntry], int]:
    """Audit entries, newest first, with the total count of the filter."""
    conditions = []
    if action:
        conditions.append(AuditEntry.action == action)
    if actor:
        conditions.append(AuditEntry.actor == actor)
    if since is not None:
        conditions.append(AuditEntry.at >= since)
    if until is not None:
        conditions.append(AuditEntry.at <= until)
    total = session.scalar(select(func.count()).select_from(AuditEntry).where(*conditions))
    rows = session.scalars(
        select(AuditEntry)
        .where(*conditions)
        .order_by(AuditEntry.id.desc())
        .limit(limit)
        .offset(offset)
    )
    return list(rows), int(total or 0)
