"""Corporate sign-in pages (public): ``GET /login/oidc`` and ``GET /login/oidc/callback``.

``/login/oidc?next=/condition`` sends the browser to the provider (authorization code flow
with PKCE, :mod:`app.oidc.flow`); the provider sends it back to ``/login/oidc/callback``,
where the code is exchanged, the ID token checked, the account created or updated and a
session begun (:mod:`app.oidc.accounts`). The callback answers a short page that goes on to
``next`` itself: the session cookie is ``SameSite=Strict``, which a browser sends only on a
navigation that begins on this site, not on the redirect from the provider.

Whatever fails answers a page that says what and offers the way back to the login page: the
provider cannot be reached (503), the sign-in could not be verified (400), trackvkf refuses the
user (403).
"""

from __future__ import annotations

import logging
from typing import Annotated

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from app.api.auth import set_session_cookies
from app.api.deps import SESSION_COOKIE, client_ip, public
from app.api.language import request_language
from app.api.login_page import TEMPLATES_DIR, safe_next
from app.core.i18n import Msg, _, jinja_environment
from app.oidc import flow
from app.oidc.accounts import SignInRefused, sign_in
from app.oidc.config import OidcConfig
from app.oidc.flow import CALLBACK_PATH, START_PATH, callback_url
from app.oidc.provider import ProviderUnavailable, provider_of_settings
from app.oidc.tokens import TokenRejected
from app.settings import Settings

__all__ = ["router"]

log = logging.getLogger(__name__)

_PAGE_HEADERS = {"Cache-Control": "no-store"}

router = APIRouter(include_in_schema=False, dependencies=[Depends(public)])

def _page(request: Request, status: int, *, title: Msg, message: Msg, detail: str = "", provider: str = "",
           next_path: str | None = None) -> HTMLResponse:
    """The sign-in's page in the browser's language (``detail``, the provider's or the check's own
    words, as it is)."""
    lang = request_language(request).code
    html = jinja_environment(str(TEMPLATES_DIR), lang).get_template("signin.html").render(
        title=title.in_language(lang), message=message.in_language(lang), detail=detail, provider=provider,
        next_path=next_path)
    return HTMLResponse(html, status_code=status, headers=_PAGE_HEADERS)


def _not_configured(request: Request) -> HTMLResponse:
    return _page(request, 404, title=_("No corporate sign-in"),
                 message=_("Corporate sign-in is not configured on this server; log in with a local account."))


def _unavailable(request: Request, config: OidcConfig, exc: ProviderUnavailable) -> HTMLResponse:
    log.warning("OpenID provider %s unavailable: %s", config.issuer, exc.reason)
    return _page(request, 503, title=_("Sign-in unavailable"), provider=config.provider_name,
                 message=_("Sign-in with {provider} is not available at the moment: the provider cannot be "
                           "reached. Try again later; local accounts can still log in.",
                           provider=config.provider_name),
                 detail=exc.reason)


def _clear_pending(response: Response, settings: Settings) -> None:
    response.delete_cookie(flow.PENDING_COOKIE, path=CALLBACK_PATH, httponly=True, samesite="lax",
                           secure=settings.cookie_secure or settings.is_production)


@router.get(START_PATH)
def oidc_start(request: Request, next: Annotated[str | None, Query(max_length=2000)] = None  # noqa: A002
               ) -> Response:
    """Send the browser to the provider's sign-in (a cookie remembers state, nonce and verifier)."""
    settings: Settings = request.app.state.settings
    provider = provider_of_settings(settings)
    if provider is None:
        return _not_configured(request)
    try:
        url, pending = flow.begin(provider, redirect_uri=callback_url(provider.config, str(request.base_url)),
                                  next_path=safe_next(next), secret_key=settings.secret_key)
    except ProviderUnavailable as exc:
        return _unavailable(request, provider.config, exc)
    response = RedirectResponse(url, status_code=303, headers=_PAGE_HEADERS)
    # Lax, not Strict: the browser must send it on the provider's redirect back to the callback
    response.set_cookie(flow.PENDING_COOKIE, pending, max_age=flow.PENDING_TTL_S, path=CALLBACK_PATH,
                        httponly=True, samesite="lax", secure=settings.cookie_secure or settings.is_production)
    return response


@router.get(CALLBACK_PATH)
def oidc_callback(
    request: Request,
    code: Annotated[str | None, Query(max_length=4096)] = None,
    state: Annotated[str | None, Query(max_length=1024)] = None,
    error: Annotated[str | None, Query(max_length=200)] = None,
    error_description: Annotated[str | None, Query(max_length=1000)] = None,
) -> Response:
    """Finish the sign-in: code exchanged, ID token checked, account and session, then on to ``next``."""
    settings: Settings = request.app.state.settings
    provider = provider_of_settings(settings)
    if provider is None:
        return _not_configured(request)
    config = provider.config
    pending = flow.unseal(request.cookies.get(flow.PENDING_COOKIE), settings.secret_key)
    if error:
        response = _page(request, 400, title=_("Sign-in not completed"), provider=config.provider_name,
                         message=_("{provider} did not sign you in.", provider=config.provider_name),
                         detail=f"{error}: {error_description}" if error_description else error)
        _clear_pending(response, settings)
        return response
    try:
        signed = flow.finish(provider, pending, state=state, code=code,
                             redirect_uri=callback_url(config, str(request.base_url)))
        result = sign_in(db=request.app.state.db, provider=provider, signed=signed, address=client_ip(request),
                         ttl_s=settings.session_ttl_s, previous_session=request.cookies.get(SESSION_COOKIE))
    except ProviderUnavailable as exc:
        response = _unavailable(request, config, exc)
    except TokenRejected as exc:
        log.warning("OpenID sign-in from %s not verified: %s",
                    request.client.host if request.client else "?", exc.reason)
        response = _page(request, 400, title=_("Sign-in not verified"), provider=config.provider_name,
                         message=_("The answer of {provider} could not be verified; nobody was signed in. "
                                   "Start again from the login page.", provider=config.provider_name),
                         detail=exc.reason)
    except SignInRefused as exc:
        response = _page(request, 403, title=_("No access"), provider=config.provider_name,
                         message=_("{provider} signed you in, but trackvkf does not let this account in. "
                                   "Ask an administrator.", provider=config.provider_name), detail=exc.reason)
    else:
        next_path = pending.next_path if pending else "/"
        response = _page(request, 200, title=_("Signed in"), provider=config.provider_name, next_path=next_path,
                         message=_("Signed in as {name} ({role}).", name=result.principal.name,
                                   role=result.principal.role))
        set_session_cookies(response, settings, result.token)
    _clear_pending(response, settings)
    return response
