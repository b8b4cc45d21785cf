"""Authentication and its administration: login/logout/me, users, API keys.

Browser users log in with ``POST /auth/login``; the answer sets the HttpOnly
session cookie ``trackvkf_session`` and the readable CSRF cookie
``trackvkf_csrf`` (both ``SameSite=Strict``). Data systems send an API key.
Users and keys are administered by admins; every change and every login is
written to the audit log.
"""

from __future__ import annotations

import logging
from typing import Annotated

from fastapi import APIRouter, Body, Depends, Path, Request, Response, status
from fastapi.responses import JSONResponse

from app.accounts import admin, sessions
from app.accounts.sessions import too_many_attempts
from app.api.deps import (
    CSRF_COOKIE,
    SESSION_COOKIE,
    AdminActor,
    AdminDep,
    DbDep,
    Principal,
    SettingsDep,
    ViewerActor,
    ViewerDep,
    client_ip,
    public,
    require_role,
)
from app.api.language import request_language
from app.api.schemas.auth import (
    KeyCreated,
    KeyIn,
    KeyList,
    KeyOut,
    LoginIn,
    LogoutOut,
    MeOut,
    MePatch,
    PasswordChangeIn,
    UserIn,
    UserList,
    UserOut,
    UserPatch,
)
from app.core.ids import MAX_ID
from app.core.ratelimit import RateLimiter
from app.core.security import csrf_token, device_cookie_id, new_device_cookie
from app.oidc.flow import end_session_url, post_logout_url
from app.oidc.provider import ProviderUnavailable, provider_of_settings
from app.settings import Settings

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

KeyIdPath = Annotated[int, Path(ge=1, le=MAX_ID, description="API key id")]


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


def _me(principal: Principal, request: Request) -> MeOut:
    return MeOut(name=principal.name, role=principal.role, kind=principal.kind, language=principal.language,
                 answered_in=request_language(request).code)


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
            raise too_many_attempts(wait)


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
    started = sessions.login(db, settings, body.username, body.password, client_ip(request),
                             known_device=device is not None, previous_token=request.cookies.get(SESSION_COOKIE))
    set_session_cookies(response, settings, started.token)
    if device is None:
        _set_device_cookie(response, settings, started.principal.name, request.url.path)
    request.state.principal = started.principal
    return _me(started.principal, request)


@router.post(
    "/logout",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Log out: end the session and clear its cookies",
    dependencies=[Depends(require_role("viewer"))],
    responses={200: {"model": LogoutOut,
                     "description": "Logged out here; sign out at the OpenID provider too at `end_session_url`"}},
)
def logout(request: Request, db: DbDep, actor: ViewerActor, settings: SettingsDep) -> Response:
    """End the browser session (an API key request only gets its cookies cleared).

    A session begun at the OpenID provider whose provider offers RP-initiated logout answers
    200 with ``end_session_url``: the page sends the browser there to sign out at the provider
    too. Otherwise 204.
    """
    id_token = sessions.logout(db, actor, getattr(request.state, "session_token", None))
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
def me(principal: ViewerDep, request: Request) -> MeOut:
    """Name, role and kind (user, api_key) of the authenticated principal, the language the user
    chose and the one this request is answered in."""
    return _me(principal, request)


@router.patch("/me", response_model=MeOut, summary="Change my account: the language")
def update_me(body: MePatch, request: Request, db: DbDep, actor: ViewerActor) -> MeOut:
    """Keep the language of the pages, messages and error texts with the user's account (null:
    follow the browser). Only users have an account (API keys: 409)."""
    request.state.principal = sessions.set_language(db, actor, body.language)
    return _me(request.state.principal, request)


@router.post(
    "/password",
    status_code=status.HTTP_204_NO_CONTENT,
    summary="Change one's own password (users)",
    responses={401: {"description": "Wrong current password"}},
)
def change_password(body: PasswordChangeIn, db: DbDep, actor: ViewerActor, settings: SettingsDep) -> Response:
    """Change the logged-in user's password; all the user's sessions end (log in again)."""
    sessions.change_password(db, settings, actor, body.current_password, body.new_password)
    response = Response(status_code=status.HTTP_204_NO_CONTENT)
    _clear_cookies(response)
    return response


# --- users (admin) -------------------------------------------------------------------
@router.get("/users", response_model=UserList, summary="List users (admin)")
def list_users(db: DbDep, principal: AdminDep) -> UserList:
    """All users by name."""
    return UserList(items=[UserOut.model_validate(u) for u in admin.list_users(db)])


@router.post(
    "/users", response_model=UserOut, status_code=status.HTTP_201_CREATED,
    summary="Create a user (admin)", responses={409: {"description": "The user exists"}},
)
def create_user(body: UserIn, db: DbDep, actor: AdminActor, settings: SettingsDep) -> UserOut:
    """Create a browser user with a role; the password is stored as an Argon2id hash."""
    return UserOut.model_validate(admin.create_user(db, actor, body.username, body.password, body.role,
                                                    password_cost=settings.password_cost))


@router.patch("/users/{username}", response_model=UserOut, summary="Change a user (admin)")
def update_user(
    username: UsernamePath, db: DbDep, actor: AdminActor, body: Annotated[UserPatch, Body()], settings: SettingsDep,
) -> UserOut:
    """Change password, role or active flag; the user's sessions end."""
    return UserOut.model_validate(admin.update_user(db, actor, username, password=body.password, role=body.role,
                                                    active=body.active, password_cost=settings.password_cost))


@router.delete("/users/{username}", status_code=status.HTTP_204_NO_CONTENT, summary="Delete a user (admin)")
def delete_user(username: UsernamePath, db: DbDep, actor: AdminActor) -> Response:
    """Delete a user and end its sessions (its audit entries stay)."""
    admin.delete_user(db, actor, username)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


# --- API keys (admin) -------------------------------------------------------------------
@router.get("/keys", response_model=KeyList, summary="List API keys (admin)")
def list_keys(db: DbDep, principal: AdminDep) -> KeyList:
    """All API keys, newest first, with last use and revocation; never the keys themselves."""
    return KeyList(items=[KeyOut.model_validate(k) for k in admin.list_keys(db)])


@router.post(
    "/keys", response_model=KeyCreated, status_code=status.HTTP_201_CREATED,
    summary="Create an API key (admin): shown once",
)
def create_key(body: KeyIn, db: DbDep, actor: AdminActor) -> KeyCreated:
    """Create a key scoped to a role. The answer's ``key`` is shown this once; only its hash is kept."""
    row, key = admin.create_key(db, actor, body.name, body.role, body.expires_in_days)
    return KeyCreated(**KeyOut.model_validate(row).model_dump(), key=key)


@router.delete("/keys/{key_id}", status_code=status.HTTP_204_NO_CONTENT, summary="Revoke an API key (admin)")
def revoke_key(key_id: KeyIdPath, db: DbDep, actor: AdminActor) -> Response:
    """Revoke a key: requests with it get 401 from now on. It stays listed as revoked."""
    admin.revoke_key(db, actor, key_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
