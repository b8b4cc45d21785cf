"""What the pages' scripts read of a language: their messages, plural rule and the number and
date formats, served as ``/i18n/<lang>.js`` from the same catalogues as everything else.

The script sets ``window.trackvkfI18n`` before the pages' own scripts run (``api.js`` builds
``T._`` and ``T.ngettext`` on it). It holds the translations of the messages whose source is a
page script (``frontend/static/js``) and of Plotly's own buttons, the CLDR plural categories
of the language (the browser's ``Intl.PluralRules`` picks one) and a Plotly locale (month and
day names, decimal and group separators, date order) from Babel's CLDR data. It changes only
with the catalogue: its URL carries the catalogue's digest and is cached for a day.
"""

from __future__ import annotations

import functools
import json
from typing import Any

from fastapi import APIRouter, Depends, Path
from fastapi.responses import Response

from app.api.deps import public
from app.core.i18n import (
    DEFAULT_LANGUAGE,
    LANGUAGES,
    N_,
    Language,
    catalogue_digest,
    catalogue_path,
)

__all__ = ["SCRIPT_SOURCES", "PLOTLY_STRINGS", "script_catalogue", "catalogue_url", "build_i18n_router",
           "number_locale", "boot_language"]

#: where the pages' scripts are (a message found there goes to the browser)
SCRIPT_SOURCES = "frontend/static/js/"
#: Plotly's own words on the pages (the mode bar's buttons): translated as Plotly locales do
PLOTLY_STRINGS: tuple[str, ...] = (
    N_("Download plot as a png"), N_("Zoom"), N_("Pan"), N_("Zoom in"), N_("Zoom out"), N_("Autoscale"),
    N_("Reset axes"), N_("Reset view"), N_("Toggle Spike Lines"), N_("Show closest data on hover"),
    N_("Compare data on hover"), N_("Box Select"), N_("Lasso Select"), N_("Double-click to zoom back out"),
    N_("Click to enter Colorscale title"), N_("Click to enter Component A title"),
    N_("Click to enter X axis title"), N_("Click to enter Y axis title"), N_("Click to enter Plot title"),
    N_("Taking snapshot - this may take a few seconds"), N_("Snapshot succeeded"),
    N_("Sorry, there was a problem downloading your snapshot!"), N_("Reset"), N_("Orbital rotation"),
    N_("Turntable rotation"), N_("trace"),
)


def _babel_locale(tag: str) -> Any:
    from babel import Locale

    try:
        return Locale.parse(tag.replace("-", "_"))
    except (ValueError, LookupError):
        return Locale.parse(tag.split("-")[0])


@functools.cache
def number_locale(tag: str) -> dict[str, Any]:
    """Plotly's locale format of ``tag`` (``de-CH``): names of months and days, separators, date order."""
    from babel.numbers import get_decimal_symbol, get_group_symbol

    loc = _babel_locale(tag)
    months, days = loc.months["format"], loc.days["format"]
    # CLDR numbers the days from Monday (0); Plotly's lists start on Sunday
    week = [6, 0, 1, 2, 3, 4, 5]
    short = loc.date_formats["short"].pattern
    order = "%d.%m.%Y" if short.startswith("dd.") else "%d/%m/%Y" if short.startswith("dd/") else "%Y-%m-%d"
    return {
        "decimal": get_decimal_symbol(loc), "thousands": get_group_symbol(loc), "grouping": [3],
        "months": [months["wide"][i] for i in range(1, 13)],
        "shortMonths": [months["abbreviated"][i] for i in range(1, 13)],
        "days": [days["wide"][i] for i in week], "shortDays": [days["abbreviated"][i] for i in week],
        "periods": ["AM", "PM"], "date": order, "time": "%H:%M:%S", "dateTime": f"{order} %H:%M:%S",
        "year": "%Y", "month": "%b %Y", "dayMonth": "%-d %b", "dayMonthYear": "%-d %b %Y",
        "currency": ["", ""],
    }


@functools.cache
def script_catalogue(lang: str) -> dict[str, Any]:
    """The pages' share of ``lang``'s catalogue (what ``/i18n/<lang>.js`` holds).

    ``messages`` maps a message id (``context\\u0004id`` with a context) to its translation, or
    to the list of its plural forms; untranslated and fuzzy entries are left out (the page
    shows the English). ``plural`` lists the CLDR plural categories in the order of the
    forms; ``plotly`` is the Plotly locale (its buttons' words and the formats).
    """
    from babel.messages.pofile import read_po
    from babel.plural import PluralRule

    messages: dict[str, Any] = {}
    plotly_words: dict[str, str] = {}
    path = catalogue_path(lang)
    if lang != DEFAULT_LANGUAGE and path.is_file():
        with path.open("rb") as fh:
            catalog = read_po(fh, locale=lang)
        wanted = set(PLOTLY_STRINGS)
        for msg in catalog:
            if not msg.id or msg.fuzzy or not msg.string:
                continue
            key = msg.id if isinstance(msg.id, str) else msg.id[0]
            text = msg.string if isinstance(msg.string, str) else list(msg.string)
            if (isinstance(text, str) and not text) or (isinstance(text, list) and not all(text)):
                continue
            if key in wanted and isinstance(text, str) and not msg.context:
                plotly_words[key] = text
            if any(str(loc).startswith(SCRIPT_SOURCES) for loc, _line in msg.locations):
                messages[f"{msg.context}\u0004{key}" if msg.context else key] = text
    loc = _babel_locale(lang)
    tags = set(PluralRule(loc.plural_form.rules).tags) | {"other"}
    categories = [c for c in ("zero", "one", "two", "few", "many", "other") if c in tags]
    return {"code": lang, "messages": messages, "plural": categories,
            "plotly": {"dictionary": plotly_words, "format": number_locale(lang)}}


def catalogue_url(lang: str) -> str:
    """The URL of ``lang``'s script catalogue (changes with the catalogue)."""
    return f"/i18n/{lang}.js?v={catalogue_digest(lang)}"


@functools.cache
def _script(lang: str) -> bytes:
    # "</" never ends a script element here, but JSON in a script stays safe that way
    data = json.dumps(script_catalogue(lang), ensure_ascii=False, separators=(",", ":")).replace("</", "<\\/")
    return f"window.trackvkfI18n = {data};\n".encode()


def build_i18n_router() -> APIRouter:
    """``GET /i18n/{lang}.js`` (public: the login page speaks the browser's language too)."""
    router = APIRouter(include_in_schema=False, dependencies=[Depends(public)])

    @router.get("/i18n/{lang}.js")
    def i18n_script(lang: str = Path(pattern="^(" + "|".join(LANGUAGES) + ")$")) -> Response:
        return Response(_script(lang), media_type="text/javascript; charset=utf-8",
                        headers={"Cache-Control": "public, max-age=86400"})

    return router


def boot_language(language: Language) -> dict[str, Any]:
    """What a page's boot data say of its language: the code, the locale of numbers and dates and
    that locale's separators (the region may differ from the catalogue's language)."""
    fmt = number_locale(language.tag)
    return {"lang": language.code, "locale": language.tag,
            "number_format": {"decimal": fmt["decimal"], "thousands": fmt["thousands"]},
            "date_order": fmt["date"]}
