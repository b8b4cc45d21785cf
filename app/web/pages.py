"""HTML pages of the dashboard, static files and the local Plotly.js bundle.

Each page is rendered in the request's language (:func:`app.api.language.request_language`:
the user's choice, else the browser's): its templates through the gettext of that language,
its scripts with the script catalogue of :mod:`app.web.i18n`, the language's code and locale
in the page's boot data.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Depends, FastAPI, Request
from fastapi.responses import FileResponse, HTMLResponse
from fastapi.staticfiles import StaticFiles

from app.analysis.condition import FINE_SEGMENT_M, OVERVIEW_SEGMENT_M, SEGMENT_LENGTHS_M
from app.analysis.condition.section_class import SECTION_CLASSES
from app.analysis.condition.tiers import TIER_NAMES
from app.analysis.stiffness.alignment import DEFAULT_SEGMENT_M
from app.api import API_PREFIX
from app.api.deps import RunId, public, require_page_login
from app.api.language import request_language
from app.core.i18n import LANGUAGE_NAMES, LANGUAGES, N_, jinja_environment, translations
from app.io.reference import MAINTENANCE_TYPES
from app.maps.indicator import DEFAULT_MAP_SEGMENT_M
from app.places.config import PlacesConfig
from app.places.workflow import PLACE_STATUSES
from app.places.worklist import CLOSED_STATUSES
from app.web.i18n import boot_language, build_i18n_router, catalogue_url
from app.web.vocabulary import labels

__all__ = [
    "FRONTEND_DIR", "PLOTLY_JS", "FAVICON", "build_pages_router", "build_public_router",
    "install_pages", "plotly_js_path",
]

#: templates/ and static/ of the dashboard
FRONTEND_DIR = Path(__file__).resolve().parents[2] / "frontend"
#: URL of the Plotly.js bundle served from the installed plotly package
PLOTLY_JS = "/vendor/plotly.min.js"
#: the icon browsers ask for at ``/favicon.ico`` on their own (pages also link the SVG)
FAVICON = FRONTEND_DIR / "static" / "img" / "favicon.ico"

#: nav bar: (page key, URL, label)
NAV = (
    ("runs", "/", N_("Runs")),
    ("lines", "/lines", N_("Line view")),
    ("condition", "/condition", N_("Condition")),
    ("map", "/map", N_("Map")),
    ("wheels", "/wheels", N_("Wheels")),
    ("correlations", "/correlations", N_("Correlations")),
)
#: the templates of the pages
TEMPLATES_DIR = str(FRONTEND_DIR / "templates")


def plotly_js_path() -> Path:
    """``plotly.min.js`` shipped in the installed plotly package."""
    import plotly

    path = Path(plotly.__file__).resolve().parent / "package_data" / "plotly.min.js"
    if not path.is_file():
        raise FileNotFoundError(f"plotly.min.js not found in the plotly package ({path})")
    return path


def build_pages_router() -> APIRouter:
    """Router of the HTML pages (not in the OpenAPI schema).

    Every page needs a logged-in browser (viewer or higher; else 303 to
    ``/login?next=...``); the API calls of the pages are authorised by the
    same session cookie.
    """
    router = APIRouter(include_in_schema=False, dependencies=[Depends(require_page_login("viewer"))])

    def page(request: Request, template: str, key: str, title: str, **context: Any) -> HTMLResponse:
        """``template`` in the request's language; ``title`` is a message id (%-fields from context)."""
        language = request_language(request)
        env = jinja_environment(TEMPLATES_DIR, language.code)
        title = translations(language.code).gettext(title) % context
        words = labels(language.code)
        boot = {"api": API_PREFIX, "page": key, "segment_m": DEFAULT_SEGMENT_M, **boot_language(language),
                "labels": words, **context}
        html = env.get_template(template).render(
            request=request, title=title, active=key, nav=NAV, boot_json=json.dumps(boot),
            plotly_js=PLOTLY_JS, i18n_js=catalogue_url(language.code), locale=language.tag,
            label=lambda kind, code: words.get(kind, {}).get(code, code),
            languages=[(code, LANGUAGE_NAMES[code]) for code in LANGUAGES],
            chosen_language=getattr(getattr(request.state, "principal", None), "language", None), **context,
        )
        return HTMLResponse(html)

    @router.get("/", response_class=HTMLResponse)
    def runs_page(request: Request) -> HTMLResponse:
        return page(request, "runs.html", "runs", N_("Runs"))

    @router.get("/runs/{run_id}", response_class=HTMLResponse)
    def run_page(request: Request, run_id: RunId) -> HTMLResponse:
        return page(request, "run.html", "runs", N_("Run %(run_id)s · stiffness map"), run_id=run_id)

    @router.get("/runs/{run_id}/spectrogram", response_class=HTMLResponse)
    def spectrogram_page(request: Request, run_id: RunId) -> HTMLResponse:
        return page(request, "spectrogram.html", "runs", N_("Run %(run_id)s · spectrogram"), run_id=run_id)

    @router.get("/lines", response_class=HTMLResponse)
    def lines_page(request: Request) -> HTMLResponse:
        return page(request, "lines.html", "lines", N_("Line view"))

    @router.get("/map", response_class=HTMLResponse)
    def map_page(request: Request) -> HTMLResponse:
        settings = request.app.state.settings
        tiles = {"url": settings.map_tile_url, "attribution": settings.map_tile_attribution}
        return page(request, "map.html", "map", N_("Map"), tiles=tiles if settings.map_tile_url else None,
                    map_segment_m=int(DEFAULT_MAP_SEGMENT_M))

    @router.get("/condition", response_class=HTMLResponse)
    def condition_page(request: Request) -> HTMLResponse:
        # the page's rules, as the services state them (the page's scripts restate none)
        places = PlacesConfig.from_settings(request.app.state.settings)
        return page(request, "condition.html", "condition", N_("Condition"),
                    segment_lengths=[int(s) for s in SEGMENT_LENGTHS_M], overview_segment_m=int(OVERVIEW_SEGMENT_M),
                    fine_segment_m=int(FINE_SEGMENT_M), tiers=list(reversed(TIER_NAMES)), statuses=list(PLACE_STATUSES),
                    open_statuses=[s for s in PLACE_STATUSES if s not in CLOSED_STATUSES],
                    section_classes=list(SECTION_CLASSES), tier_limits=places.levels.to_dict())

    @router.get("/wheels", response_class=HTMLResponse)
    def wheels_page(request: Request) -> HTMLResponse:
        return page(request, "wheels.html", "wheels", N_("Wheels"))

    @router.get("/correlations", response_class=HTMLResponse)
    def correlations_page(request: Request) -> HTMLResponse:
        return page(request, "correlations.html", "correlations", N_("Correlations"),
                    maintenance_types=list(MAINTENANCE_TYPES))

    @router.get(PLOTLY_JS)
    def plotly_bundle() -> FileResponse:
        return FileResponse(
            plotly_js_path(),
            media_type="text/javascript",
            headers={"Cache-Control": "public, max-age=86400"},
        )

    return router


def build_public_router() -> APIRouter:
    """Router of what a browser fetches before anyone logs in: ``/favicon.ico``."""
    router = APIRouter(include_in_schema=False, dependencies=[Depends(public)])

    @router.get("/favicon.ico")
    def favicon() -> FileResponse:
        return FileResponse(
            FAVICON, media_type="image/x-icon", headers={"Cache-Control": "public, max-age=86400"}
        )

    return router


def install_pages(app: FastAPI) -> None:
    """Mount the dashboard on ``app``: pages, ``/favicon.ico``, ``/static`` and the Plotly.js bundle."""
    app.include_router(build_pages_router())
    app.include_router(build_public_router())
    app.include_router(build_i18n_router())
    app.mount("/static", StaticFiles(directory=str(FRONTEND_DIR / "static")), name="static")
