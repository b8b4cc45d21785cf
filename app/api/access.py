"""Who makes a request, and what a route admits: API keys, session cookies, CSRF, roles.

Every route declares its access policy through a dependency (:func:`route_policy`):
``public`` (health, login), :func:`require_role` (API: 401/403 as JSON) or
:func:`require_page_login` (pages: 303 to the login page, 403). The checks use the
primitives of :mod:`app.core.security` and the accounts of :mod:`app.accounts.sessions`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, TypeVar
from urllib.parse import quote

from fastapi import Depends, HTTPException, Request

from app.accounts.sessions import key_principal, session_principal
from app.core.errors import ApiError
from app.core.i18n import _
from app.core.routing import iter_routes
from app.core.security import ROLES, Actor, Principal, csrf_matches, role_allows, role_rank
from app.db.session import Database
from app.oidc.accounts import bearer_principal
from app.oidc.provider import ProviderUnavailable, provider_of_settings
from app.oidc.tokens import TokenRejected, looks_like_jwt
from app.settings import Settings

__all__ = [
    "Principal",
    "Actor",
    "get_principal",
    "acting",
    "require_role",
    "require_page_login",
    "public",
    "route_policy",
    "iter_routes",
    "client_ip",
    "RoleRequirement",
    "PageLogin",
    "SESSION_COOKIE",
    "CSRF_COOKIE",
    "CSRF_HEADER",
    "API_KEY_HEADER",
]


SESSION_COOKIE = "trackvkf_session"
CSRF_COOKIE = "trackvkf_csrf"
CSRF_HEADER = "X-CSRF-Token"
API_KEY_HEADER = "X-API-Key"
_SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS", "TRACE"})
_BEARER = {"WWW-Authenticate": 'Bearer realm="trackvkf"'}


def client_ip(request: Request) -> str | None:
    """Address of the peer (the reverse proxy when there is one)."""
    return request.client.host if request.client else None


def _api_key_token(request: Request) -> str | None:
    header = request.headers.get("authorization")
    if header is not None:
        scheme, _sep, value = header.partition(" ")
        if scheme.lower() != "bearer" or not value.strip():
            raise ApiError(
                401, "authorization", _("expected 'Authorization: Bearer <API key>'"), _BEARER
            )
        return value.strip()
    key = request.headers.get(API_KEY_HEADER)
    if key is not None:
        return key.strip()
    return None


def _lookup(request: Request) -> Principal | None:
    """Authenticate a request by API key or session cookie; None without credentials.

    Raises
    ------
    ApiError
        401 for a wrong, revoked or expired API key (no fallback to the cookie).
    """
    settings: Settings = request.app.state.settings
    if settings.auth_disabled:
        return Principal(
            name=settings.anonymous_principal, role=settings.anonymous_role, kind="anonymous"
        )
    db: Database = request.app.state.db
    token = _api_key_token(request)
    if token is not None and looks_like_jwt(token) and settings.oidc_api_audience:
        return _provider_token_principal(request, settings, token)
    if token is not None:
        return key_principal(db, token)  # 401 for a bad key: no fallback to the cookie
    cookie = request.cookies.get(SESSION_COOKIE)
    if cookie:
        principal = session_principal(db, cookie)
        if principal is not None:
            request.state.session_token = cookie
            return principal
    return None


def _provider_token_principal(request: Request, settings: Settings, token: str) -> Principal:
    """The principal of an access token of the OpenID provider (:func:`app.oidc.accounts.bearer_principal`).

    Raises
    ------
    ApiError
        401 naming ``authorization`` for a token that fails a check, 503 when the provider's
        keys cannot be fetched.
    """
    provider = provider_of_settings(settings)
    if provider is None:  # pragma: no cover - oidc_api_audience needs an issuer to mean anything
        raise ApiError(401, "authorization", _("provider tokens are not accepted"), _BEARER)
    try:
        return bearer_principal(request.app.state.db, provider, token)
    except TokenRejected as exc:
        raise ApiError(401, "authorization", _("token of the OpenID provider refused: {reason}", reason=exc.reason),
                       _BEARER) from None
    except ProviderUnavailable as exc:
        raise ApiError(503, "authorization", _("the OpenID provider cannot be reached to check the token: {reason}", reason=exc.reason)) from None


def _authenticate(request: Request) -> Principal | None:
    cached = getattr(request.state, "principal", None)
    if cached is None:
        cached = _lookup(request)
        request.state.principal = cached
    return cached


def get_principal(request: Request) -> Principal:
    """The authenticated principal of a request.

    An API key (``Authorization: Bearer <key>`` or ``X-API-Key``) is checked
    first — or, with ``TRACKVKF_OIDC_API_AUDIENCE`` set, a JWT access token of the OpenID
    provider as ``Authorization: Bearer`` — then the session cookie ``trackvkf_session``. A state-changing
    request (POST/PUT/PATCH/DELETE) authenticated by the cookie must carry the
    session's CSRF token in ``X-CSRF-Token`` (the value of the
    ``trackvkf_csrf`` cookie). With ``auth_disabled`` (development only)
    every request runs as the anonymous principal of the settings.

    Raises
    ------
    ApiError
        401 without valid credentials, 403 for a missing or wrong CSRF token.
    """
    principal = _authenticate(request)
    if principal is None:
        raise ApiError(401, "authentication", _("log in or send an API key"), _BEARER)
    if principal.kind == "user" and request.method not in _SAFE_METHODS:
        settings: Settings = request.app.state.settings
        token = getattr(request.state, "session_token", "")
        if not csrf_matches(settings.secret_key, token, request.headers.get(CSRF_HEADER)):
            raise ApiError(
                403, "csrf", _("missing or wrong {header} header (value of the {cookie} cookie)", header=CSRF_HEADER, cookie=CSRF_COOKIE)
            )
    return principal


class _RoleGate:
    """What both access dependencies share: a role, and 403 for a principal below it."""

    def __init__(self, role: str) -> None:
        role_rank(role)  # validates
        self.role = role

    def _admit(self, principal: Principal) -> Principal:
        if not role_allows(principal.role, self.role):
            raise ApiError(
                403, "role", _("needs role {role} or higher; {name} is {has}", role=self.role, name=principal.name, has=principal.role)
            )
        return principal


_Gate = TypeVar("_Gate", bound=_RoleGate)


def _gate_of(gates: dict[str, _Gate], role: str) -> _Gate:
    """The dependency of ``role`` (one object per role); ValueError for an unknown role."""
    try:
        return gates[role]
    except KeyError:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}") from None


class RoleRequirement(_RoleGate):
    """Dependency: the request's principal must have at least ``role``.

    Use through :func:`require_role`. 401 without authentication, 403 for a
    role below ``role``.
    """

    def __call__(self, principal: Annotated[Principal, Depends(get_principal)]) -> Principal:
        return self._admit(principal)

    def __repr__(self) -> str:
        return f"require_role({self.role!r})"


_REQUIREMENTS: dict[str, RoleRequirement] = {role: RoleRequirement(role) for role in ROLES}


def require_role(role: str) -> RoleRequirement:
    """The dependency that admits principals with ``role`` or a higher one.

    Roles are ordered viewer < engineer < admin. Apply it per route or per
    router::

        @router.post("/x", dependencies=[Depends(require_role("engineer"))])
        APIRouter(dependencies=[Depends(require_role("viewer"))])

    or take the principal from it: ``principal: Annotated[Principal,
    Depends(require_role("admin"))]``.
    """
    return _gate_of(_REQUIREMENTS, role)


class PageLogin(_RoleGate):
    """Dependency of HTML pages: the principal, else a 303 redirect to the login page.

    Use through :func:`require_page_login`. A logged-in principal whose role
    is below ``role`` gets 403.
    """

    def __call__(self, request: Request) -> Principal:
        principal = _authenticate(request)
        if principal is None:
            target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
            location = f"/login?next={quote(target, safe='')}"
            raise HTTPException(
                status_code=303, detail="log in first", headers={"Location": location}
            )
        return self._admit(principal)

    def __repr__(self) -> str:
        return f"require_page_login({self.role!r})"


_PAGE_LOGINS: dict[str, PageLogin] = {role: PageLogin(role) for role in ROLES}


def require_page_login(role: str = "viewer") -> PageLogin:
    """Dependency of HTML pages: logged in (any role >= ``role``) or 303 → ``/login?next=``."""
    return _gate_of(_PAGE_LOGINS, role)


def _acting(requirement: RoleRequirement) -> Callable[..., Actor]:
    # the dependency in the default: a closure's name cannot be resolved from a string annotation
    def actor(request: Request, principal: Principal = Depends(requirement)) -> Actor:  # noqa: B008
        return Actor(principal, client_ip(request))

    actor.__name__ = f"acting_{requirement.role}"
    return actor


_ACTINGS: dict[str, Callable[..., Actor]] = {role: _acting(req) for role, req in _REQUIREMENTS.items()}


def acting(role: str) -> Callable[..., Actor]:
    """The dependency that answers the request's :class:`~app.core.security.Actor` (its principal,
    admitted with ``role`` or a higher one, and the client's address): what a service that
    writes takes. :func:`route_policy` sees the role inside it::

        def change(..., actor: Annotated[Actor, Depends(acting("admin"))]) -> ...
    """
    try:
        return _ACTINGS[role]
    except KeyError:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}") from None


def public() -> None:
    """Marker dependency of routes that need no authentication (health, login)."""


def route_policy(route: Any) -> tuple[str, str | None] | None:
    """The access policy a route declares through its dependencies.

    Returns
    -------
    tuple or None
        ``("public", None)``, ``("api", role)`` (401/403 JSON) or
        ``("page", role)`` (303 to the login page, 403), with the highest role
        required anywhere in the route's dependencies; None when the route
        declares nothing (a bug: every route must declare its policy).
    """
    found: list[tuple[str, str | None]] = []

    def walk(dependant) -> None:
        for dep in dependant.dependencies:
            call = dep.call
            if isinstance(call, RoleRequirement):
                found.append(("api", call.role))
            elif isinstance(call, PageLogin):
                found.append(("page", call.role))
            elif call is public:
                found.append(("public", None))
            walk(dep)

    dependant = getattr(route, "dependant", None)
    if dependant is None:
        return None
    walk(dependant)
    if not found:
        return None
    kinds = {k for k, _ in found}
    roles = [r for _, r in found if r is not None]
    if roles:
        kind = "page" if "page" in kinds else "api"
        return kind, max(roles, key=role_rank)
    return "public", None
