"""Authentication and its administration: login/logout/me, users, API keys.

Browser users log in with ``POST /auth/login``; the answer sets the HttpOnly
session cookie ``trackvkf_session`` and the readable CSRF cookie
``trackvkf_csrf`` (both ``SameSite=Strict``). Data systems send an API key.
Users and keys are administered by admins; every change and every login is
written to the audit log.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import functools
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Annotated

from fastapi import APIRouter, Body, Depends, Path, Request, Response, status
from fastapi.responses import JSONResponse

from app.api.deps import (
    CSRF_COOKIE,
    SESSION_COOKIE,
    Actor,
    AdminActor,
    AdminDep,
    DbDep,
    Principal,
    PrincipalDep,
    SettingsDep,
    ViewerActor,
    ViewerDep,
    client_ip,
    public,
    require_role,
)
from app.api.errors import ApiError
from app.api.schemas.auth import (
    KeyCreated,
    KeyIn,
    KeyList,
    KeyOut,
    LoginIn,
    LogoutOut,
    MeOut,
    PasswordChangeIn,
    UserIn,
    UserList,
    UserOut,
    UserPatch,
)
from app.audit import record
from app.core.config import Settings
from app.core.ratelimit import RateLimiter
from app.core.security import (
    csrf_token,
    device_cookie_id,
    hash_password,
    new_device_cookie,
    verify_password,
)
from app.db import auth_crud
from app.db.models import User, utcnow
from app.oidc.flow import end_session_url, post_logout_url
from app.oidc.provider import ProviderUnavailable, provider_of_settings

__all__ = ["router", "login_router", "set_session_cookies", "DEVICE_COOKIE"]

log = logging.getLogger(__name__)

router = APIRouter(prefix="/auth", tags=["auth"])
#: The public part (login), included without an authentication dependency.
login_router = APIRouter(prefix="/auth", tags=["auth"], dependencies=[Depends(public)])

UsernamePath = Annotated[
    str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9._@-]+$", description="User name")
]
#: marks a browser that logged in as a user before (exempt from the user name's failure budget)
DEVICE_COOKIE = "trackvkf_device"
DEVICE_COOKIE_MAX_AGE_S = 365 * 24 * 3600

KeyIdPath = Annotated[int, Path(ge=1, le=2**31 - 1, description="API key id")]


@functools.lru_cache(maxsize=1)
def _dummy_hash() -> str:
    """A hash to verify against for unknown users (same time as for known ones)."""
    return hash_password("not-a-password-of-anyone")


def _too_many(retry_after: float) -> ApiError:
    seconds = max(1, int(retry_after + 0.999))
    return ApiError(
        429, "rate_limit", f"too many attempts; retry in {seconds} s", {"Retry-After": str(seconds)}
    )


def set_session_cookies(response: Response, settings: Settings, token: str) -> None:
    """Set the session cookie (HttpOnly) and the CSRF cookie (readable by the page's JS)."""
    secure = settings.cookie_secure or settings.is_production
    max_age = int(settings.session_ttl_s)
    response.set_cookie(
        SESSION_COOKIE, token, max_age=max_age, path="/", secure=secure, httponly=True,
        samesite="strict",
    )
    response.set_cookie(
        CSRF_COOKIE, csrf_token(settings.secret_key, token), max_age=max_age, path="/",
        secure=secure, httponly=False, samesite="strict",
    )


def _set_device_cookie(response: Response, settings: Settings, username: str, path: str) -> None:
    """Mark this browser as one that logged in as ``username`` (sent to the login path only)."""
    response.set_cookie(
        DEVICE_COOKIE, new_device_cookie(settings.secret_key, username), max_age=DEVICE_COOKIE_MAX_AGE_S,
        path=path, secure=settings.cookie_secure or settings.is_production, httponly=True,
        samesite="strict",
    )


def _clear_cookies(response: Response) -> None:
    response.delete_cookie(SESSION_COOKIE, path="/", httponly=True, samesite="strict")
    response.delete_cookie(CSRF_COOKIE, path="/", samesite="strict")


@contextlib.contextmanager
def _auth_errors_as_422(field: str | None = None) -> Iterator[None]:
    """Answer an :class:`auth_crud.AuthError` with 422 naming its field (or ``field``)."""
    try:
        yield
    except auth_crud.AuthError as exc:
        raise ApiError(422, field or exc.field, exc.message) from None


def _me(principal: Principal) -> MeOut:
    return MeOut(name=principal.name, role=principal.role, kind=principal.kind)


@dataclass(frozen=True)
class _Account:
    """What a login needs of a user, read before the password is verified."""

    id: int
    username: str
    role: str
    password_hash: str
    active: bool


def _account(user: User | None) -> _Account | None:
    if user is None:
        return None
    return _Account(user.id, user.username, user.role, user.password_hash, bool(user.active))


def _check_login_rate(request: Request, username: str, device: str | None) -> None:
    """The in-process limits of :func:`login` (429 over them; not audited, logged).

    A browser with the user's device cookie counts per device; any other client
    per (address, user name) and per address: an attacker only ever uses up
    its own budgets, never the one of the user's browser.
    """
    limiter: RateLimiter = request.app.state.login_limiter
    ip = client_ip(request)
    name = username.lower()
    if device is not None:
        hits = [(limiter, f"device:{device}")]
    else:
        hits = [(limiter, f"ip-user:{ip}:{name}"), (request.app.state.login_address_limiter, f"ip:{ip}")]
    for each, key in hits:
        wait = each.hit(key)
        if wait is not None:
            # not audited: a flood must not grow the append-only log; the service log has it
            log.warning("login rate limit hit by %s for user %r", ip, username[:64])
            raise _too_many(wait)


@login_router.post(
    "/login",
    response_model=MeOut,
    summary="Log in (browser): sets the session and CSRF cookies",
    responses={401: {"description": "Wrong user name or password"}, 429: {"description": "Too many attempts"}},
)
def login(body: LoginIn, request: Request, response: Response, db: DbDep, settings: SettingsDep) -> MeOut:
    """Check the password and start a session.

    Limits: ``TRACKVKF_LOGIN_RATE_LIMIT`` attempts per (client address, user
    name) and ``TRACKVKF_LOGIN_ADDRESS_RATE_LIMIT`` per address within
    ``TRACKVKF_LOGIN_RATE_WINDOW_S`` (per API process), and at most
    ``TRACKVKF_LOGIN_NAME_FAILURE_LIMIT`` failures of one user name within
    ``TRACKVKF_LOGIN_NAME_FAILURE_WINDOW_S`` from browsers that never logged in
    as that user (the device cookie ``trackvkf_device`` exempts the others).

    The password is verified outside any transaction (Argon2 takes tens of
    milliseconds: on SQLite a write transaction would block every other
    writer that long); the audit entry, which is also the failure counter, and
    the session are written in one short transaction afterwards. Logging in
    again from the same browser ends its previous session.
    """
    device = device_cookie_id(settings.secret_key, request.cookies.get(DEVICE_COOKIE), body.username)
    _check_login_rate(request, body.username, device)
    with db.read() as session:
        account = _account(auth_crud.get_user(session, body.username))
        since = utcnow() - dt.timedelta(seconds=settings.login_name_failure_window_s)
        failures = 0 if device else auth_crud.count_failed_logins(session, body.username, since)
    if failures >= settings.login_name_failure_limit:
        log.warning("login of %r from %s refused: %d failed logins of the name within %g s",
                    body.username[:64], client_ip(request), failures, settings.login_name_failure_window_s)
        raise _too_many(settings.login_rate_window_s)
    ok = verify_password(account.password_hash if account else _dummy_hash(), body.password)
    with db.write() as session:
        user = auth_crud.get_user(session, body.username) if ok and account and account.active else None
        if user is None or not user.active or user.password_hash != account.password_hash:
            record(session, Actor(None, client_ip(request), claimed=body.username), "auth.login",
                   target=body.username, outcome="denied")
            failed = True
        else:
            old = request.cookies.get(SESSION_COOKIE)
            if old:  # the same browser logs in again: its previous session ends
                auth_crud.delete_session(session, old)
            token = auth_crud.create_session(
                session, user, dt.timedelta(seconds=settings.session_ttl_s), client_ip(request)
            )
            principal = Principal(name=user.username, role=user.role, kind="user", user_id=user.id)
            record(session, Actor(principal, client_ip(request)), "auth.login", target=user.username)
            failed = False
    if failed:
        raise ApiError(401, "credentials", "wrong user name or password")
    set_session_cookies(response, settings, token)
    if device is None:
        _set_device_cookie(response, settings, user.username, request.url.path)
    return _me(principal)


@router.post(
    "/logout",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Log out: end the session and clear its cookies",
    dependencies=[Depends(require_role("viewer"))],
    responses={200: {"model": LogoutOut,
                     "description": "Logged out here; sign out at the OpenID provider too at `end_session_url`"}},
)
def logout(request: Request, db: DbDep, principal: PrincipalDep, settings: SettingsDep) -> Response:
    """End the browser session (an API key request only gets its cookies cleared).

    A session begun at the OpenID provider whose provider offers RP-initiated logout answers
    200 with ``end_session_url``: the page sends the browser there to sign out at the provider
    too. Otherwise 204.
    """
    token = getattr(request.state, "session_token", None)
    with db.write() as session:
        id_token = auth_crud.session_id_token(session, token) if principal.kind == "user" and token else None
        if principal.kind == "user" and token:
            auth_crud.delete_session(session, token)
        record(session, Actor(principal, client_ip(request)), "auth.logout", target=principal.name,
               detail={"method": "oidc"} if id_token else None)
    end_session = _provider_sign_out(request, settings, id_token) if id_token else None
    if end_session:
        response: Response = JSONResponse(LogoutOut(end_session_url=end_session).model_dump())
    else:
        response = Response(status_code=status.HTTP_204_NO_CONTENT)
    _clear_cookies(response)
    return response


def _provider_sign_out(request: Request, settings: Settings, id_token: str) -> str | None:
    """The provider's sign-out URL for a session begun there (None: it offers none, or cannot
    be reached now: the local session has ended all the same)."""
    provider = provider_of_settings(settings)
    if provider is None:
        return None
    try:
        return end_session_url(provider, id_token=id_token,
                               post_logout_redirect_uri=post_logout_url(provider.config, str(request.base_url)))
    except ProviderUnavailable as exc:
        log.warning("sign-out at the OpenID provider skipped: %s", exc.reason)
        return None


@router.get("/me", response_model=MeOut, summary="Who am I")
def me(principal: ViewerDep) -> MeOut:
    """Name, role and kind (user, api_key) of the authenticated principal."""
    return _me(principal)


@router.post(
    "/password",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Change one's own password (users)",
    responses={401: {"description": "Wrong current password"}},
)
def change_password(body: PasswordChangeIn, db: DbDep, actor: ViewerActor) -> Response:
    principal = actor.principal
    """Change the logged-in user's password; all the user's sessions end (log in again)."""
    if principal.kind != "user":
        raise ApiError(409, "principal", "only users have passwords (this is an API key)")
    with db.read() as session:
        account = _account(auth_crud.get_user(session, principal.name))
    # verified outside any transaction (see login)
    if account is None or not verify_password(account.password_hash, body.current_password):
        raise ApiError(401, "current_password", "wrong password")
    with db.write() as session:
        user = auth_crud.get_user(session, principal.name)
        if user is None or user.password_hash != account.password_hash:
            raise ApiError(409, "current_password", "the password was changed meanwhile; try again")
        with _auth_errors_as_422(field="new_password"):
            auth_crud.update_user(session, principal.name, password=body.new_password)
        record(session, actor, "auth.password", target=principal.name)
    response = Response(status_code=status.HTTP_204_NO_CONTENT)
    _clear_cookies(response)
    return response


# --- users (admin) -------------------------------------------------------------------
@router.get("/users", response_model=UserList, summary="List users (admin)")
def list_users(db: DbDep, principal: AdminDep) -> UserList:
    """All users by name."""
    with db.read() as session:
        return UserList(items=[UserOut.model_validate(u) for u in auth_crud.list_users(session)])


@router.post(
    "/users", response_model=UserOut, status_code=status.HTTP_201_CREATED,
    summary="Create a user (admin)", responses={409: {"description": "The user exists"}},
)
def create_user(body: UserIn, db: DbDep, actor: AdminActor) -> UserOut:
    """Create a browser user with a role; the password is stored as an Argon2id hash."""
    with db.write() as session:
        if auth_crud.get_user(session, body.username) is not None:
            raise ApiError(409, "username", f"user {body.username!r} exists")
        with _auth_errors_as_422():
            user = auth_crud.create_user(
                session, body.username, body.password, body.role, created_by=actor.name
            )
        record(session, actor, "user.create", target=user.username, detail={"role": user.role})
        return UserOut.model_validate(user)


@router.patch("/users/{username}", response_model=UserOut, summary="Change a user (admin)")
def update_user(
    username: UsernamePath, db: DbDep, actor: AdminActor, body: Annotated[UserPatch, Body()],
) -> UserOut:
    principal = actor.principal
    """Change password, role or active flag; the user's sessions end."""
    if principal.kind == "user" and principal.name == username and (
        body.active is False or (body.role is not None and body.role != "admin")
    ):
        raise ApiError(409, "username", "an admin cannot deactivate or demote itself")
    with db.write() as session:
        with _auth_errors_as_422():
            user = auth_crud.update_user(
                session, username, password=body.password, role=body.role, active=body.active
            )
        if user is None:
            raise ApiError(404, "username", f"user {username!r} not found")
        changed = {k: v for k, v in body.model_dump(exclude_none=True).items() if k != "password"}
        if body.password is not None:
            changed["password"] = "changed"
        record(session, actor, "user.update", target=username, detail=changed)
        return UserOut.model_validate(user)


@router.delete("/users/{username}", status_code=status.HTTP_204_NO_CONTENT, summary="Delete a user (admin)")
def delete_user(username: UsernamePath, db: DbDep, actor: AdminActor) -> Response:
    principal = actor.principal
    """Delete a user and end its sessions (its audit entries stay)."""
    if principal.kind == "user" and principal.name == username:
        raise ApiError(409, "username", "an admin cannot delete itself")
    with db.write() as session:
        if not auth_crud.delete_user(session, username):
            raise ApiError(404, "username", f"user {username!r} not found")
        record(session, actor, "user.delete", target=username)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# --- API keys (admin) -------------------------------------------------------------------
@router.get("/keys", response_model=KeyList, summary="List API keys (admin)")
def list_keys(db: DbDep, principal: AdminDep) -> KeyList:
    """All API keys, newest first, with last use and revocation; never the keys themselves."""
    with db.read() as session:
        return KeyList(items=[KeyOut.model_validate(k) for k in auth_crud.list_api_keys(session)])


@router.post(
    "/keys", response_model=KeyCreated, status_code=status.HTTP_201_CREATED,
    summary="Create an API key (admin): shown once",
)
def create_key(body: KeyIn, db: DbDep, actor: AdminActor) -> KeyCreated:
    """Create a key scoped to a role. The answer's ``key`` is shown this once; only its hash is kept."""
    expires = utcnow() + dt.timedelta(days=body.expires_in_days) if body.expires_in_days else None
    with db.write() as session:
        with _auth_errors_as_422():
            row, key = auth_crud.create_api_key(
                session, body.name, body.role, created_by=actor.name, expires_at=expires
            )
        record(session, actor, "key.create", target=row.id,
               detail={"name": row.name, "role": row.role, "prefix": row.prefix})
        return KeyCreated(**KeyOut.model_validate(row).model_dump(), key=key)


@router.delete("/keys/{key_id}", status_code=status.HTTP_204_NO_CONTENT, summary="Revoke an API key (admin)")
def revoke_key(key_id: KeyIdPath, db: DbDep, actor: AdminActor) -> Response:
    """Revoke a key: requests with it get 401 from now on. It stays listed as revoked."""
    with db.write() as session:
        row = auth_crud.revoke_api_key(session, key_id)
        if row is None:
            raise ApiError(404, "key_id", f"API key {key_id} not found")
        record(session, actor, "key.revoke", target=key_id, detail={"name": row.name})
    return Response(status_code=status.HTTP_204_NO_CONTENT)
