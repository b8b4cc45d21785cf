"""Browser dashboard: HTML pages (Jinja2 templates in ``frontend/templates``), their
static JS/CSS (``frontend/static``) and Plotly.js from the installed ``plotly`` package.

Everything the pages show comes from the REST API through one fetch wrapper
(``frontend/static/js/api.js``); no page loads anything from outside the server.
"""

from app.web.pages import FRONTEND_DIR, build_pages_router, build_public_router, install_pages

__all__ = ["FRONTEND_DIR", "build_pages_router", "build_public_router", "install_pages"]
