"""Who a request is, and the sessions of browser users: login, logout, a password change.

Passwords are verified outside any transaction (Argon2 takes tens of milliseconds: on SQLite a
write transaction would block every other writer that long); what follows (the audit entry,
which is also the failure counter of a user name, and the session) is one short transaction.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import functools
import logging
from collections.abc import Iterator
from dataclasses import dataclass, replace

from app.audit import record
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.security import Actor, PasswordCost, Principal, hash_password, verify_password
from app.db import auth_crud
from app.db.models import User, utcnow
from app.db.session import Database
from app.settings import Settings

__all__ = [
    "StartedSession",
    "auth_errors_as_422",
    "change_password",
    "key_principal",
    "login",
    "logout",
    "session_principal",
    "set_language",
    "too_many_attempts",
]

log = logging.getLogger(__name__)


def too_many_attempts(retry_after_s: float) -> ApiError:
    """The 429 of a login over its limits, with ``Retry-After`` in whole seconds."""
    seconds = max(1, int(retry_after_s + 0.999))
    return ApiError(429, "rate_limit", _("too many attempts; retry in {seconds} s", seconds=seconds), {"Retry-After": str(seconds)})


@contextlib.contextmanager
def auth_errors_as_422(field: str | None = None) -> Iterator[None]:
    """Answer an :class:`app.db.auth_crud.AuthError` with 422 naming its field (or ``field``)."""
    try:
        yield
    except auth_crud.AuthError as exc:
        raise ApiError(422, field or exc.field, exc.message) from None


def key_principal(db: Database, token: str) -> Principal:
    """The principal of an API key (its last use refreshed at most once a minute).

    Raises
    ------
    ApiError
        401 (``authorization``) for a wrong, revoked or expired key.
    """
    with db.read() as session:
        key = auth_crud.api_key_by_token(session, token)
        if key is None:
            raise ApiError(401, "authorization", _("invalid, revoked or expired API key"),
                           {"WWW-Authenticate": 'Bearer realm="trackvkf"'})
        principal = Principal(name=f"key:{key.name}", role=key.role, kind="api_key", key_id=key.id)
        stale = auth_crud.needs_touch(key)
    if stale:
        with db.write() as session:
            auth_crud.touch_api_key(session, key.id)
    return principal


def session_principal(db: Database, token: str) -> Principal | None:
    """The user of a live session token, or None (unknown, expired, or the user inactive)."""
    with db.read() as session:
        user = auth_crud.session_user(session, token)
        if user is None:
            return None
        return Principal(name=user.username, role=user.role, kind="user", user_id=user.id, language=user.language)


@functools.lru_cache(maxsize=4)
def _dummy_hash(cost: PasswordCost) -> str:
    """A hash at ``cost`` to verify against for unknown users (same time as for known ones)."""
    return hash_password("not-a-password-of-anyone", cost)


@dataclass(frozen=True)
class _Account:
    """What a login needs of a user, read before the password is verified."""

    username: str
    password_hash: str
    active: bool


def _account(user: User | None) -> _Account | None:
    return None if user is None else _Account(user.username, user.password_hash, bool(user.active))


@dataclass(frozen=True)
class StartedSession:
    """A session a login started: its token (the session cookie) and who it is."""

    token: str
    principal: Principal


def login(db: Database, settings: Settings, username: str, password: str, address: str | None, *,
          known_device: bool, previous_token: str | None = None) -> StartedSession:
    """Check a user's password and start a session (audited ``auth.login``, ok or denied).

    ``known_device``: the browser logged in as ``username`` before (its device cookie): its
    attempts do not count against the user name's failure budget
    (``TRACKVKF_LOGIN_NAME_FAILURE_LIMIT`` within ``…_WINDOW_S``). ``previous_token``: the
    browser's current session, which ends.

    Raises
    ------
    ApiError
        429 (``rate_limit``) over the user name's failure budget; 401 (``credentials``) for a
        wrong user name or password or an inactive user.
    """
    with db.read() as session:
        account = _account(auth_crud.get_user(session, username))
        since = utcnow() - dt.timedelta(seconds=settings.login_name_failure_window_s)
        failures = 0 if known_device else auth_crud.count_failed_logins(session, username, since)
    if failures >= settings.login_name_failure_limit:
        log.warning("login of %r from %s refused: %d failed logins of the name within %g s",
                    username[:64], address, failures, settings.login_name_failure_window_s)
        raise too_many_attempts(settings.login_rate_window_s)
    ok = verify_password(account.password_hash if account else _dummy_hash(settings.password_cost), password)
    started: StartedSession | None = None
    with db.write() as session:
        user = auth_crud.get_user(session, username) if ok and account and account.active else None
        if user is None or not user.active or user.password_hash != account.password_hash:
            record(session, Actor(None, address, claimed=username), "auth.login", target=username,
                   outcome="denied")
        else:
            if previous_token:  # the same browser logs in again: its previous session ends
                auth_crud.delete_session(session, previous_token)
            token = auth_crud.create_session(session, user, dt.timedelta(seconds=settings.session_ttl_s), address)
            principal = Principal(name=user.username, role=user.role, kind="user", user_id=user.id,
                                  language=user.language)
            record(session, Actor(principal, address), "auth.login", target=user.username)
            started = StartedSession(token, principal)
    if started is None:
        raise ApiError(401, "credentials", _("wrong user name or password"))
    return started


def logout(db: Database, actor: Actor, token: str | None) -> str | None:
    """End a user's browser session ``token`` (an API key has none); audited ``auth.logout``.

    Returns the ID token the session began with at the OpenID provider (None for a local
    login): the provider's sign-out is asked with it (:func:`app.oidc.flow.end_session_url`).
    """
    id_token = None
    with db.write() as session:
        if actor.principal is not None and actor.principal.kind == "user" and token:
            id_token = auth_crud.session_id_token(session, token)
            auth_crud.delete_session(session, token)
        record(session, actor, "auth.logout", target=actor.name, detail={"method": "oidc"} if id_token else None)
    return id_token


def change_password(db: Database, settings: Settings, actor: Actor, current: str, new: str) -> None:
    """Change the acting user's own password (the new one hashed at ``settings.password_cost``); all
    its sessions end (audited ``auth.password``).

    Raises
    ------
    ApiError
        409 (``principal``) for an actor that is not a user, 401 (``current_password``) for a
        wrong current password, 409 when it was changed meanwhile, 422 (``new_password``) for
        an unacceptable new one.
    """
    if actor.principal is None or actor.principal.kind != "user":
        raise ApiError(409, "principal", _("only users have passwords (this is an API key)"))
    with db.read() as session:
        account = _account(auth_crud.get_user(session, actor.name))
    # verified outside any transaction (see the module's docstring)
    if account is None or not verify_password(account.password_hash, current):
        raise ApiError(401, "current_password", _("wrong password"))
    with db.write() as session:
        user = auth_crud.get_user(session, actor.name)
        if user is None or user.password_hash != account.password_hash:
            raise ApiError(409, "current_password", _("the password was changed meanwhile; try again"))
        with auth_errors_as_422(field="new_password"):
            auth_crud.update_user(session, actor.name, password=new, password_cost=settings.password_cost)
        record(session, actor, "auth.password", target=actor.name)


def set_language(db: Database, actor: Actor, language: str | None) -> Principal:
    """Keep ``language`` (en, de, fr, it; None: the browser's) with the acting user's account.

    A preference of one's own, not an administrative change: not audited. Returns the actor's
    principal with the language.

    Raises
    ------
    ApiError
        409 (``principal``) for an actor that is not a user (an API key, a provider's token).
    """
    principal = actor.principal
    if principal is None or principal.kind != "user" or principal.user_id is None:
        raise ApiError(409, "principal", _("only users keep a language (this is an API key)"))
    with db.write() as session, auth_errors_as_422(field="language"):
        auth_crud.set_language(session, principal.user_id, language)
    return replace(principal, language=language)
