"""The report for the planning meeting: a PDF per line and track (and date).

:func:`line_report` reads what the Condition page shows (:mod:`~app.places.report.data`) and
renders it (:mod:`~app.places.report.render`): the section classes in the railway's class scheme
and their change over the year, the work list (tier, extent, size ± 1σ, trend, time to limit,
status, assets), the rail findings (welds and joints: km, type, dip depth, runs seen, the depth's
trend; never ranked with the places), one sheet per open place (its history plot, where it is on the line and on the
map, the maintenance over it) and the maintenance effects, in the user's language. Served by
``GET /condition/report.pdf`` and the Condition page's "Report (PDF)" button.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from app.db.session import Database
from app.places.report.data import ReportData, gather
from app.places.report.render import ENGLISH, Speech, render_html, render_pdf

__all__ = ["line_report", "ReportData", "Speech", "gather", "render_html", "render_pdf"]


def line_report(db: Database, settings: Any, line_id: str, track: str | None, *, date: dt.date | None = None,
                speech: Speech | None = None) -> tuple[ReportData, bytes]:
    """The report of a line and track as PDF (and what it shows).

    Parameters
    ----------
    db : Database
    settings : Settings
    line_id, track : str
        The line (404 naming ``line_id`` without runs; 422 naming ``track`` when ambiguous).
    date : datetime.date, optional
        The meeting's date the report is made for (default: today, UTC); printed on it.
    speech : Speech, optional
        The report's language and its catalogue (the class scheme's names follow ``speech.lang``).
    """
    data = gather(db, settings, line_id, track, date=date or dt.datetime.now(dt.UTC).date(), lang=(speech or ENGLISH).lang)
    return data, render_pdf(data, speech=speech)
