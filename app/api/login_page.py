"""The login page (``GET /login``, public) and the access-protected API docs.

``/docs`` (Swagger UI) needs a logged-in browser (else 303 to the login page)
and ``/openapi.json`` an authenticated principal: the description of the API
is not public either. The schema declares the API-key schemes so that the
docs' "Authorize" button and API clients know how to authenticate.
"""

from __future__ import annotations

import re
from html import escape
from pathlib import Path
from typing import Annotated, Any
from urllib.parse import urlencode

from fastapi import APIRouter, Depends, FastAPI, Query, Request
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, JSONResponse
from fastapi.staticfiles import StaticFiles

from app.api.deps import API_KEY_HEADER, public, require_page_login, require_role
from app.api.errors import document_error_responses
from app.api.headers import content_security_policy, inline_script_hashes
from app.api.language import request_language
from app.core.i18n import N_, catalogue_digest, jinja_environment, translations

__all__ = [
    "router", "safe_next", "install_protected_docs", "docs_router", "swagger_ui_assets", "swagger_ui_dir",
    "TEMPLATES_DIR", "SWAGGER_ASSETS", "MIN_SWAGGER_UI_MAJOR",
]

#: URL prefix of the locally served Swagger UI assets (public static files)
SWAGGER_ASSETS = "/docs-assets"
#: Swagger UI renders OpenAPI 3.1 (what FastAPI serves) from major version 5 on
MIN_SWAGGER_UI_MAJOR = 5

TEMPLATES_DIR = Path(__file__).resolve().parents[2] / "frontend" / "templates"
#: the security headers (CSP, framing, ...) come from app.api.headers.SecurityHeadersMiddleware
_PAGE_HEADERS = {"Cache-Control": "no-store"}

router = APIRouter(include_in_schema=False, dependencies=[Depends(public)])


def safe_next(value: str | None) -> str:
    """A local path to go to after login; anything else (other sites, odd text) gives ``/``."""
    if not value or len(value) > 2000 or not value.startswith("/"):
        return "/"
    if value.startswith("//") or value.startswith("/\\") or not value.isprintable():
        return "/"
    return value


@router.get("/login", response_class=HTMLResponse)
def login_page(request: Request, next: Annotated[str | None, Query(max_length=2000)] = None) -> HTMLResponse:  # noqa: A002
    """The login form, in the browser's language; after login the browser goes to ``next`` (a local
    path). With corporate sign-in configured it offers "Sign in with <provider>" (``/login/oidc``) too."""
    settings = request.app.state.settings
    oidc_name = settings.oidc_provider_name if settings.oidc_enabled else None
    lang = request_language(request).code
    html = jinja_environment(str(TEMPLATES_DIR), lang).get_template("login.html").render(
        next_path=safe_next(next), i18n_js=f"/i18n/{lang}.js?v={catalogue_digest(lang)}", oidc_name=oidc_name,
        oidc_href="/login/oidc?" + urlencode({"next": safe_next(next)}))
    return HTMLResponse(html, headers=_PAGE_HEADERS)


def _security_schemes(schema: dict[str, Any], public_paths: set[str]) -> dict[str, Any]:
    components = schema.setdefault("components", {})
    components["securitySchemes"] = {
        "bearerKey": {"type": "http", "scheme": "bearer", "description": "API key"},
        "headerKey": {"type": "apiKey", "in": "header", "name": API_KEY_HEADER},
    }
    schema["security"] = [{"bearerKey": []}, {"headerKey": []}]
    for path, operations in schema.get("paths", {}).items():
        if path in public_paths:
            for operation in operations.values():
                if isinstance(operation, dict):
                    operation["security"] = []
    return schema


def swagger_ui_dir() -> Path:
    """Directory of the newest Swagger UI (>= 5) shipped by the installed ``swagger-ui-bundle-v2``.

    The package installs as ``swagger_ui_bundle/vendor/swagger-ui-<version>``; an older
    ``swagger-ui-bundle`` (Swagger UI 4, which cannot render OpenAPI 3.1) left in the same
    environment shares that directory, so the version is chosen here, not taken from the
    package's ``__init__``.

    Raises
    ------
    RuntimeError
        No Swagger UI >= 5 is installed.
    """
    import swagger_ui_bundle

    vendor = Path(swagger_ui_bundle.__file__).resolve().parent / "vendor"
    found: list[tuple[tuple[int, ...], Path]] = []
    for path in vendor.glob("swagger-ui-*"):
        m = re.fullmatch(r"swagger-ui-(\d+)\.(\d+)\.(\d+)", path.name)
        if m and path.is_dir() and (path / "swagger-ui-bundle.js").is_file():
            found.append((tuple(int(g) for g in m.groups()), path))
    usable = [item for item in found if item[0][0] >= MIN_SWAGGER_UI_MAJOR]
    if not usable:
        have = ", ".join(p.name for _, p in sorted(found)) or "none"
        raise RuntimeError(
            f"Swagger UI >= {MIN_SWAGGER_UI_MAJOR} not found in {vendor} (found: {have}); "
            "install the package `swagger-ui-bundle-v2`"
        )
    return max(usable)[1]


_BACK = N_("← Back to the dashboard")
_BACK_TITLE = N_("The pages of trackvkf (the API's documentation is in English, as its field names)")


def _with_way_back(html: str, lang: str) -> str:
    """The Swagger UI page with a bar at its top that leads back to the dashboard (in ``lang``)."""
    t = translations(lang)
    bar = (f'<nav id="back-to-dashboard" style="font: 14px system-ui, sans-serif; padding: 10px 20px; '
           f'background: #1f3b57;"><a href="/" style="color: #fff; text-decoration: none;" '
           f'title="{escape(t.gettext(_BACK_TITLE))}">{escape(t.gettext(_BACK))}</a></nav>')
    return html.replace("<body>", "<body>\n" + bar, 1)


def install_protected_docs(app: FastAPI, public_paths: set[str]) -> None:
    """Give ``app`` the schema that ``/openapi.json`` and ``/docs`` (:data:`docs_router`) serve.

    Build the app with ``docs_url=None, redoc_url=None, openapi_url=None``.
    ``public_paths`` are the schema paths that need no authentication; the others name the
    API-key schemes.
    """
    original = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            app.openapi_schema = document_error_responses(_security_schemes(original(), public_paths))
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]


#: ``/openapi.json`` (viewer) and ``/docs`` (logged-in page): the schema of the app that
#: answers (:func:`install_protected_docs`); the Swagger UI's assets are :func:`swagger_ui_assets`
docs_router = APIRouter(include_in_schema=False)


@docs_router.get("/openapi.json", dependencies=[Depends(require_role("viewer"))])
def openapi_json(request: Request) -> JSONResponse:
    """The OpenAPI schema of the app (viewer or higher)."""
    return JSONResponse(request.app.openapi())


@docs_router.get("/docs", dependencies=[Depends(require_page_login("viewer"))])
def docs(request: Request) -> HTMLResponse:
    """Swagger UI on the schema (a logged-in browser), with a way back to the dashboard."""
    page = get_swagger_ui_html(
        openapi_url="/openapi.json",
        title=f"{request.app.title} API",
        swagger_js_url=f"{SWAGGER_ASSETS}/swagger-ui-bundle.js",
        swagger_css_url=f"{SWAGGER_ASSETS}/swagger-ui.css",
        swagger_favicon_url=f"{SWAGGER_ASSETS}/favicon-32x32.png",
    )
    html = _with_way_back(page.body.decode("utf-8"), request_language(request).code)
    # the page's one inline script (SwaggerUIBundle setup) is allowed by its hash
    csp = content_security_policy(inline_script_hashes(html))
    return HTMLResponse(html, headers={**_PAGE_HEADERS, "Content-Security-Policy": csp})


def swagger_ui_assets() -> StaticFiles:
    """Swagger UI's assets from the installed swagger-ui-bundle package (public static files at
    :data:`SWAGGER_ASSETS`), not a CDN: the docs page must work on a closed network like every
    other page."""
    return StaticFiles(directory=swagger_ui_dir())
