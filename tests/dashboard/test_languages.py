"""Every page in German, French and Italian in a real Chromium, checked for English left over.

The browser asks for the language as a person's browser does (Accept-Language, the context's
locale); the user keeps no language of its own. On each page of the walk (the navigation, a run's
stiffness map and spectrogram, the login page) the check reads the text a person sees — every
visible text node, Plotly's SVG text (axis titles, legends, annotations, colour bars) included —
leaving out what is data, not the page's own words (elements marked ``translate="no"``: ids,
file names, user comments). A word is English left over when it is a word of the English message
ids of the catalogue (``app/locale``, the page's own vocabulary) that no translation of that
language uses: "the", "runs", "stiffness", "Download" on a German page are leftovers, "km", "Z11",
"Webhook" are not. Any message id of the catalogue whose English text appears on the page as a
whole (a sentence the page forgot to translate) is reported too. No console error, no failed
request; the pages' numbers and dates in the locale (15.01.2025, 1'234.5 in de-CH).

With TRACKVKF_SCREENSHOT_DIR set, the German walk writes the README's screenshots of a second
language (``<dir>/de/<page>.png``).
"""

from __future__ import annotations

import os
import re
from functools import cache
from pathlib import Path

import pytest

from tests.dashboard.conftest import PageLog, save_screenshot
from tests.dashboard.test_walk import walk_pages

pytestmark = pytest.mark.timeout(900)

LOCALE_DIR = Path(__file__).resolve().parents[2] / "app" / "locale"
#: the languages walked and the locale the browser asks for
LANGUAGES = {"de": "de-CH", "fr": "fr-CH", "it": "it-CH"}
_WORD = re.compile(r"[A-Za-z]{3,}")
#: what is not language in a message: markup, fields, entities and URL paths (``/runs/``)
_MARKUP = re.compile(r"<[^>]+>|\{[^{}]*\}|%\(\w+\)[sd]|&\w+;|(?:/[A-Za-z_][\w.-]*)+/")

#: the visible text of the page: text nodes of visible elements (HTML and SVG), option texts,
#: outside anything marked translate="no" and outside scripts and styles
_TEXT = """() => {
  const out = [];
  const skip = (el) => el.closest('[translate="no"], script, style, noscript, template');
  const visible = (el) => {
    if (el.closest('[hidden]')) return false;
    const r = el.getBoundingClientRect();
    if (r.width === 0 && r.height === 0) return false;
    const s = getComputedStyle(el);
    return s.visibility !== 'hidden' && s.display !== 'none' && Number(s.opacity) !== 0;
  };
  const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
  for (let n = walker.nextNode(); n; n = walker.nextNode()) {
    const el = n.parentElement;
    if (!el || !n.textContent.trim() || skip(el)) continue;
    if (el.tagName === 'OPTION') { if (!skip(el.parentElement)) out.push(n.textContent); continue; }
    if (visible(el)) out.push(n.textContent);
  }
  for (const el of document.querySelectorAll('[placeholder], button[title], th[title]')) {
    if (!skip(el)) out.push(el.getAttribute('placeholder') || el.getAttribute('title') || '');
  }
  out.push(document.title);
  return out.join('\\n');
}"""


@cache
def _catalogue(lang: str):
    from babel.messages.pofile import read_po

    with (LOCALE_DIR / lang / "LC_MESSAGES" / "messages.po").open("rb") as fh:
        return read_po(fh, locale=lang)


def _texts(value) -> list[str]:
    return [value] if isinstance(value, str) else [v for v in value if v]


@cache
def english_leftovers(lang: str) -> tuple[frozenset[str], tuple[tuple[str, str], ...]]:
    """(English words no translation of ``lang`` uses, (English phrase, its translation) pairs)."""
    english: set[str] = set()
    target: set[str] = set()
    phrases = []
    for m in _catalogue(lang):
        if not m.id:
            continue
        ids, strings = _texts(m.id), _texts(m.string)
        for text in strings:
            target.update(w.lower() for w in _WORD.findall(_MARKUP.sub(" ", text)))
        for text in ids:
            english.update(w.lower() for w in _WORD.findall(_MARKUP.sub(" ", text)))
        # a whole sentence of the page (no placeholder to fill) that the translation changes
        single = ids[0]
        if len(ids) == 1 and strings and strings[0] != single and " " in single and not _MARKUP.search(single) \
                and len(single) >= 16:
            phrases.append((single, strings[0]))
    # the locale's month and day names are its own words (Plotly's date axes: "set 2025" in Italian)
    from babel.dates import get_day_names, get_month_names

    where = LANGUAGES[lang].replace("-", "_")
    for width in ("abbreviated", "wide"):
        for names in (get_month_names(width, locale=where), get_day_names(width, locale=where)):
            target.update(w.lower() for name in names.values() for w in _WORD.findall(name))
    return frozenset(english - target), tuple(phrases)


def leftovers(text: str, lang: str) -> list[str]:
    """English words and sentences of the catalogue in ``text`` (the page's own text in ``lang``)."""
    words, phrases = english_leftovers(lang)
    found = sorted({w for w in _WORD.findall(text) if w.lower() in words})
    found += [f"sentence {p!r}" for p, _t in phrases if p in text]
    return found


def test_the_check_finds_english():
    """The check itself: English words and sentences are found, the translations and data are not."""
    assert leftovers("Gleisposition (km) · Messfahrt 12 · Z11 · SIM-1", "de") == []
    assert "Download" in leftovers("CSV Download", "de")
    assert "the" in leftovers("Stiffness index along the track", "de")
    assert "Runs" in leftovers("Runs", "fr") and leftovers("Parcours · km 1,2", "fr") == []
    assert "sentence 'Choose a run file to upload.'" in leftovers("Choose a run file to upload.", "it")


def _walk(browser, dashboard, login_state, lang: str, locale: str) -> None:
    shots = os.environ.get("TRACKVKF_SCREENSHOT_DIR")
    ctx = browser.new_context(base_url=dashboard.base_url, viewport={"width": 1280, "height": 900},
                              storage_state=login_state, locale=locale)
    ctx.set_default_timeout(60_000)
    problems = []
    try:
        for name, path in [p for p in walk_pages(dashboard) if p[0] != "api-docs"]:
            page = ctx.new_page()
            log = PageLog(origin=dashboard.base_url)
            log.attach(page)
            page.goto(path)
            page.wait_for_selector("body[data-ready='1']")
            page.wait_for_timeout(300)
            assert page.get_attribute("html", "lang") == lang, name
            assert not page.locator("#banner").is_visible(), f"{lang} {name}: {page.inner_text('#banner')}"
            left = leftovers(page.evaluate(_TEXT), lang)
            if left:
                problems.append(f"{lang} {name}: {left}")
            if name == "runs":
                dates = page.locator("#runs-body tr[data-run] td:nth-child(2)").all_inner_texts()
                # the dates in the locale's order: 15.01.2025 (de-CH, fr-CH, it-CH)
                assert dates and all(re.match(r"\d\d\.\d\d\.\d{4} \d\d:\d\d UTC$", d) for d in dates), dates
            if shots and lang == "de":
                save_screenshot(page, f"de/{name}")
            log.assert_clean()
            page.close()
        # the login page, before anyone logs in: the browser's language
        anon = browser.new_context(base_url=dashboard.base_url, locale=locale)
        try:
            page = anon.new_page()
            page.goto("/login")
            assert page.get_attribute("html", "lang") == lang
            left = leftovers(page.evaluate(_TEXT), lang)
            if left:
                problems.append(f"{lang} login: {left}")
        finally:
            anon.close()
    finally:
        ctx.close()
    assert not problems, "English left over:\n" + "\n".join(problems)


@pytest.mark.parametrize("lang", sorted(LANGUAGES))
def test_every_page_speaks_the_language(browser, dashboard, login_state, lang):
    _walk(browser, dashboard, login_state, lang, LANGUAGES[lang])
