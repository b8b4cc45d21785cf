"""The report as HTML (Jinja2, ``frontend/templates/report.html``) and as PDF (WeasyPrint).

One title page (the line, the date, the section classes in the railway's scheme and their change
over the year), the work list, the rail findings (welds and joints the runs found: km, type, dip
depth, runs seen of runs passed, the depth's trend; listed apart, never ranked with the places), one
sheet per open place (its facts, its history plot, where it is on the line and on the map, the
maintenance over it) and the maintenance effects. The plots are
SVG drawn here (:mod:`app.places.report.svg`); WeasyPrint needs Pango (Debian: ``libpango-1.0-0``,
``libpangoft2-1.0-0``) and reads nothing from the network (every resource is inline or a
local file).
"""

from __future__ import annotations

import datetime as dt
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import jinja2
import numpy as np
from babel import Locale
from babel.dates import format_date, format_datetime, format_skeleton
from babel.numbers import format_decimal
from markupsafe import Markup

from app.analysis.condition.reading import amplitude_percent_per_year
from app.analysis.condition.tiers import TIER_ACTIONS
from app.core.errors import ApiError
from app.core.i18n import _
from app.places.report import svg
from app.places.report.data import ReportData

__all__ = ["ENGLISH", "Speech", "render_html", "render_pdf", "SYSTEM_PACKAGES", "TEMPLATES_DIR"]

#: the Debian packages WeasyPrint needs (scripts/setup.sh installs them)
SYSTEM_PACKAGES = ("libpango-1.0-0", "libpangoft2-1.0-0", "libharfbuzz-subset0", "fonts-dejavu-core")

TEMPLATES_DIR = Path(__file__).resolve().parents[3] / "frontend" / "templates"
_STATIC = Path(__file__).resolve().parents[3] / "frontend" / "static"
_TIER_COLOURS = {"watch": "#607d8b", "alert": "#d49b00", "intervention": "#e65100", "immediate": "#c62828"}
_NO_CLASS = "#cfd8dc"


def _same(text: str) -> str:
    return text


def _plural(singular: str, plural: str, n: int) -> str:
    return singular if n == 1 else plural


def _words(kind: str, code: str) -> str:
    return TIER_ACTIONS.get(code, code) if kind == "tier action" else code.replace("_", " ")


@dataclass(frozen=True, eq=False)
class Speech:
    """How the report speaks: its language and the words of its catalogue.

    Attributes
    ----------
    lang : str
        The language (``<html lang>``).
    tag : str
        The locale of numbers and dates (``de-CH``: the language with the browser's region).
    catalogue : callable
        The catalogue's gettext: English message → the text in ``lang`` (identity: English).
    plural : callable
        The catalogue's ngettext: ``(singular, plural, n)`` → the text in ``lang``.
    label : callable
        ``(kind, code)`` → the words of a code (a tier, status, tendency, direction, maintenance
        or asset type, rail finding) in ``lang``; the kinds are the pages' (``tier``, ``tier action``,
        ``place status``, ``tendency``, ``direction``, ``maintenance type``, ``asset type``,
        ``rail finding``).
    """

    lang: str = "en"
    tag: str = "en"
    catalogue: Callable[[str], str] = _same
    plural: Callable[[str, str, int], str] = _plural
    label: Callable[[str, str], str] = _words

    @functools.cached_property
    def locale(self) -> Locale:
        """Babel's locale of :attr:`tag` (its language alone where CLDR lacks the region)."""
        try:
            return Locale.parse(self.tag.replace("-", "_"))
        except (ValueError, LookupError):
            return Locale.parse(self.lang)

    def num(self, value: Any, digits: int = 2, *, sign: bool = False) -> str:
        """``value`` with ``digits`` decimals in the locale ("–" for none or not finite)."""
        if value is None or (isinstance(value, float) and not math.isfinite(value)):
            return "–"
        pattern = ("+" if sign and value > 0 else "") + "#,##0" + ("." + "0" * digits if digits else "")
        return format_decimal(value, format=pattern, locale=self.locale)

    def date(self, value: Any) -> str:
        """A date (or the date of an ISO date or time string) in the locale's medium form."""
        if value is None or value == "":
            return "–"
        if isinstance(value, str):
            value = dt.datetime.fromisoformat(value) if len(value) > 10 else dt.date.fromisoformat(value)
        if isinstance(value, dt.datetime):
            value = value.date()
        return format_date(value, format="medium", locale=self.locale)

    def tick(self, value: float) -> str:
        """A plot's tick value in the locale (up to 2 decimals, none from 100 on)."""
        return format_decimal(value, format="#,##0.##" if abs(value) < 100 else "#,##0", locale=self.locale)

    def month(self, value: dt.date) -> str:
        """A plot's month tick in the locale (``Mar 2025``, ``März 2025``, ``mars 2025``)."""
        return format_skeleton("yMMM", value, locale=self.locale)

    def moment(self, value: dt.datetime) -> str:
        """A time (UTC) in the locale's short form, followed by ``UTC``."""
        return format_datetime(value, format="short", tzinfo=dt.UTC, locale=self.locale) + " UTC"

    def _(self, message: str, **params: Any) -> str:
        """``message`` in the report's language with its ``{name}`` fields filled (the name is
        gettext's, so that the catalogues' extraction finds the message)."""
        return self.catalogue(message).format(**params)


#: the report in English (the messages as written)
ENGLISH = Speech()


#: An amplitude's change a year above this (per cent) is printed as "> +999": the page's rule
#: (``frontend/static/js/condition/common.js``). The end of a rate's 95 % interval fitted over a few runs
#: weeks apart can be tens of ln units a year (issue 33's real line, seed 4: a place's 3 runs over 45 days,
#: −38.6 … +34.9), which as 100 · expm1 is a number of 19 digits on the printed list.
AMPLITUDE_PERCENT_SHOWN = 999.0


def amplitude_percent_text(speech: Speech, value: float | None) -> str:
    """An amplitude's change a year (per cent) as printed: signed, no decimals, ``> +999`` above
    :data:`AMPLITUDE_PERCENT_SHOWN`, "–" for none."""
    if value is None or math.isnan(value):
        return "–"
    if value > AMPLITUDE_PERCENT_SHOWN:
        return "> " + speech.num(AMPLITUDE_PERCENT_SHOWN, 0, sign=True)
    return speech.num(value, 0, sign=True)


def _environment(speech: Speech) -> jinja2.Environment:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES_DIR)), autoescape=True,
                             undefined=jinja2.StrictUndefined, extensions=["jinja2.ext.i18n"])
    env.install_gettext_callables(speech.catalogue, speech.plural, newstyle=True)  # type: ignore[attr-defined]
    env.filters["num"] = speech.num
    env.filters["signed"] = lambda value, digits=2: speech.num(value, digits, sign=True)
    env.filters["date"] = speech.date
    # a rate in ln units a year as the amplitude's change a year, per cent (100 · expm1), as the page shows it
    env.filters["amp_rate"] = lambda rate: amplitude_percent_per_year(1, rate)
    env.filters["amp_pct"] = lambda value: amplitude_percent_text(speech, value)
    env.globals["label"] = lambda kind, code: speech.label(kind, code) if code else "–"
    return env


def _time(value: str | None) -> dt.datetime | None:
    return dt.datetime.fromisoformat(value) if value else None


def _section_spans(data: ReportData) -> list[tuple[float, float, str]]:
    colours = {k["code"]: k["colour"] for k in data.sections["scheme"]["classes"]}
    return [(s["km_from"], s["km_to"], colours.get(s["scheme_class"], _NO_CLASS)) for s in data.sections["sections"]]


def _sheet(data: ReportData, place: dict[str, Any], spans: list[tuple[float, float, str]],
           speech: Speech) -> dict[str, Any]:
    history = data.histories[place["id"]]
    obs = history["observations"]
    maint = history["maintenance"]
    limits = []
    if place.get("next_limit") is not None:
        sign = 1.0 if place["direction"] == "hard" else -1.0
        limits.append((sign * place["next_limit"], speech._("limit {tier}", tier=speech.label("tier", place["next_tier"])),
                       _TIER_COLOURS.get(place["next_tier"], "#c62828")))
    pp = data.passes.get(place["id"])
    matched = [(_time(x["run_time"]), x["matched_index"]) for x in (pp or {}).get("passes", [])
               if x["matched_index"] is not None]
    tr = (pp or {}).get("trend")
    trend = ((_time(tr["from_time"]), tr["from_index"]), (_time(tr["to_time"]), tr["to_index"])) if tr else None
    plot = svg.history_plot([_time(o["run_time"]) for o in obs], [o["level"] for o in obs],
                            [o.get("level_sd") for o in obs], limits=limits, passes=matched, trend=trend,
                            markers=[(dt.date.fromisoformat(m["date"]), speech.label("maintenance type", m["kind"]))
                                     for m in maint],
                            y_label=speech._("index (ln units)"), label=speech._("Place {id}", id=place["id"]),
                            number=speech.tick, month=speech.month)
    strip = svg.line_strip(data.km_range, spans, highlight=(place["km_from"], place["km_to"]),
                           label=speech._("Place {id} on line {line}", id=place["id"], line=data.line_id),
                           number=speech.tick)
    mini = None
    if data.geometry is not None:
        g = data.geometry
        gx, gy = g.to_local(g.lon, g.lat)
        lon, lat = g.lonlat_at_km(np.linspace(place["km_from"], place["km_to"], 5))
        mx, my = g.to_local(lon, lat)
        mini = svg.mini_map(gx, gy, mx, my, label=speech._("Place {id} on the map", id=place["id"]),
                            number=speech.tick)
    return {"place": place, "history": history, "plot": Markup(plot), "strip": Markup(strip), "passes": pp if matched else None,
            "map": Markup(mini) if mini else None}


def render_html(data: ReportData, *, speech: Speech | None = None) -> str:
    """The report's HTML (self-contained: CSS and plots inline), in ``speech``'s language."""
    speech = speech or ENGLISH
    spans = _section_spans(data)
    strip = svg.line_strip(data.km_range, spans,
                           label=speech._("Section classes of line {line}", line=data.line_id), number=speech.tick)
    css = (_STATIC / "css" / "report.css").read_text(encoding="utf-8")
    return _environment(speech).get_template("report.html").render(
        d=data, lang=speech.lang, css=Markup(css), sections=data.sections, scheme=data.sections["scheme"],
        sections_strip=Markup(strip), sheets=[_sheet(data, p, spans, speech) for p in data.places],
        generated=speech.moment(dt.datetime.now(dt.UTC)), tier_colours=_TIER_COLOURS,
    )


def render_pdf(data: ReportData, *, speech: Speech | None = None) -> bytes:
    """The report as PDF bytes (WeasyPrint; no network: nothing is fetched).

    Raises
    ------
    ApiError
        503 naming ``report`` when WeasyPrint cannot load Pango (the system library it needs).
    """
    try:  # imported here: Pango is loaded only when a report is made
        from weasyprint import HTML
    except (ImportError, OSError) as exc:
        raise ApiError(503, "report", _("the PDF report needs WeasyPrint and its system libraries (Pango: Debian "
                                        "packages {packages}), which cannot be loaded: {error}",
                                        packages=" ".join(SYSTEM_PACKAGES), error=exc)) from exc
    html = render_html(data, speech=speech)

    def no_fetch(url: str, *args: Any, **kwargs: Any) -> dict:
        raise ValueError(f"the report fetches nothing ({url[:80]})")

    return HTML(string=html, url_fetcher=no_fetch).write_pdf()
