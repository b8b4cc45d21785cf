"""Reading the planning report back: its text (pdftotext) and the English left in a translated one."""

from __future__ import annotations

import re
import shutil
import subprocess

from babel.messages.pofile import read_po

from app.core.i18n import catalogue_path, translations

__all__ = ["pdf_text", "english_leftovers"]

#: where the report's messages come from (the catalogue's locations)
REPORT_SOURCES = ("frontend/templates/report.html", "app/places/report/")
_FIELD = re.compile(r"%\(\w+\)s|\{\w+\}|%%")


def pdf_text(pdf: bytes, *, layout: bool = False) -> str:
    """The PDF's text (pdftotext); without ``layout`` in reading order with its whitespace folded."""
    assert shutil.which("pdftotext"), "pdftotext missing: scripts/setup.sh --dev installs poppler-utils"
    text = subprocess.run(["pdftotext", *(["-layout"] if layout else []), "-", "-"], input=pdf, capture_output=True,
                          check=True).stdout.decode()
    return text if layout else " ".join(text.split())


def _report_messages() -> list[str]:
    with catalogue_path("de").open("rb") as fh:  # every catalogue holds every message id (test_i18n)
        catalogue = read_po(fh)
    return [m.id if isinstance(m.id, str) else m.id[0] for m in catalogue if m.id
            and any(path.startswith(REPORT_SOURCES) for path, _line in m.locations)]


def english_leftovers(text: str, lang: str) -> list[str]:
    """The English fragments of the report's messages (those the catalogue of ``lang`` words
    otherwise) and of the pages' words of codes (tiers, statuses, maintenance types, ...) that
    ``text`` still holds: each message's text between its fields, of 4 letters or more, matched as
    whole words."""
    from app.web.vocabulary import labels, messages

    t = translations(lang)
    fragments: set[str] = set()
    for msgid in _report_messages():
        if t.gettext(msgid) == msgid:
            continue
        fragments.update(f.strip(" :,.()·") for f in _FIELD.split(msgid))
    words = labels(lang)
    for kind, english in messages().items():
        fragments.update(e for code, e in english.items() if words[kind][code] != e)
    return sorted(f for f in fragments if sum(c.isalpha() for c in f) >= 4
                  and re.search(rf"(?<!\w){re.escape(f)}(?!\w)", text))
