"""The languages of the service: English, German, French and Italian, from gettext catalogues.

The catalogues are the ``.po`` files of ``app/locale/<lang>/LC_MESSAGES/messages.po`` (one
domain for the pages, their scripts, the messages and the error texts of the API), kept up
to date with Babel (``python scripts/i18n.py``, extraction configured in ``babel.cfg``). They
are compiled when first read (Babel's ``.mo`` writer into memory), so a compiled catalogue
is never older than its source; fuzzy entries are left out, as ``msgfmt`` does.

What the code marks for translation:

- :func:`_` and :func:`ngettext` make a :class:`Msg`: the English text (a ``str``, so it
  goes wherever a message went) that remembers its message id and parameters, so that
  whoever answers a request translates it (:func:`translate`). Parameters use
  ``str.format`` fields: ``_("run {run_id} not found", run_id=5)``.
- :meth:`Msg.in_language` gives it in a language at once.

Which language a request gets (:func:`negotiate`): the user's choice kept with the account,
else the browser's ``Accept-Language``, else English.
"""

from __future__ import annotations

import functools
import gettext as _gettext
import hashlib
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "LANGUAGES", "DEFAULT_LANGUAGE", "LANGUAGE_NAMES", "LOCALE_DIR", "DOMAIN", "Language", "Msg", "_", "N_",
    "ngettext", "translate", "translations", "parse_accept_language", "negotiate", "catalogue_path",
    "catalogue_digest", "is_language", "jinja_environment", "stored_message", "restored_message",
]

#: the languages the service speaks; English is the source language of every message
LANGUAGES: tuple[str, ...] = ("en", "de", "fr", "it")
DEFAULT_LANGUAGE = "en"
#: each language's name in itself (the language picker)
LANGUAGE_NAMES: dict[str, str] = {"en": "English", "de": "Deutsch", "fr": "Français", "it": "Italiano"}
#: where the catalogues are: ``<LOCALE_DIR>/<lang>/LC_MESSAGES/<DOMAIN>.po``
LOCALE_DIR = Path(__file__).resolve().parents[1] / "locale"
DOMAIN = "messages"

_TAG = re.compile(r"^[A-Za-z]{1,8}(-[A-Za-z0-9]{1,8})*$")
#: longest Accept-Language header read (characters) and most entries weighed
_MAX_HEADER = 1000
_MAX_ENTRIES = 20


def is_language(value: object) -> bool:
    """True when ``value`` is one of :data:`LANGUAGES`."""
    return isinstance(value, str) and value in LANGUAGES


class Msg(str):
    """A message to translate: the English text, with its message id and parameters kept.

    Parameters
    ----------
    msgid : str
        The English text with ``str.format`` fields (``"run {run_id} not found"``).
    plural : str, optional
        The plural form; then ``n`` chooses the form (and is a parameter too).
    n : int, optional
        The count of a plural message.
    **params
        The values of the fields (shown as given: quote them in the message if needed); a
        value that is a :class:`Msg` itself is translated with the message.
    """

    msgid: str
    plural: str | None
    n: int | None
    params: dict[str, Any]
    english: str | None

    def __new__(cls, msgid: str, plural: str | None = None, n: int | None = None, **params: Any) -> Msg:
        if plural is not None and n is None:
            raise ValueError("a plural message needs its count n")
        source = msgid if plural is None or n == 1 else plural
        fields = dict(params, n=n) if n is not None else params
        self = super().__new__(cls, source.format(**fields) if fields else source)
        self.msgid, self.plural, self.n, self.params, self.english = msgid, plural, n, fields, None
        return self

    @classmethod
    def worded(cls, english: str, msgid: str, **params: Any) -> Msg:
        """A message whose English is ``english`` as given (another library's wording) and whose
        other languages translate ``msgid``."""
        self = super().__new__(cls, english)
        self.msgid, self.plural, self.n, self.params, self.english = msgid, None, None, params, english
        return self

    def in_language(self, lang: str) -> str:
        """The message in ``lang`` (English where the catalogue has no translation)."""
        if lang == DEFAULT_LANGUAGE and self.english is not None:
            return self.english
        t = translations(lang)
        text = t.gettext(self.msgid) if self.plural is None else t.ngettext(self.msgid, self.plural, self.n or 0)
        if not self.params:
            return text
        fields = {k: v.in_language(lang) if isinstance(v, Msg) else v for k, v in self.params.items()}
        try:
            return text.format(**fields)
        except (KeyError, IndexError, ValueError):  # a translation with a wrong field: English, not an error
            return str(self)


def _(msgid: str, **params: Any) -> Msg:
    """Mark ``msgid`` for translation: a :class:`Msg` (the English text until translated)."""
    return Msg(msgid, **params)


def N_(msgid: str) -> str:
    """Mark ``msgid`` for the catalogues without translating it (a table of messages)."""
    return msgid


def ngettext(singular: str, plural: str, n: int, **params: Any) -> Msg:
    """Mark a message with a plural form: ``ngettext("{n} run", "{n} runs", n)``."""
    return Msg(singular, plural, n, **params)


def translate(message: str, lang: str) -> str:
    """``message`` in ``lang``: a :class:`Msg` translated, any other text as it is."""
    return message.in_language(lang) if isinstance(message, Msg) else message


def stored_message(message: str) -> dict[str, Any]:
    """A message in a form JSON keeps (a database column): a :class:`Msg` with its id and parameters
    (``{"id", "params"}``, and ``plural``/``n``/``english`` where it has them), so that it can be read
    later in any language (:func:`restored_message`); other text as ``{"text": ...}``.
    Parameters that are not JSON numbers or text are kept as their text."""
    if not isinstance(message, Msg):
        return {"text": str(message)}
    params: dict[str, Any] = {}
    for key, value in message.params.items():
        if key == "n" and message.plural is not None:
            continue
        if isinstance(value, Msg):
            params[key] = {"message": stored_message(value)}
        elif isinstance(value, bool) or not isinstance(value, int | float | str):
            params[key] = str(value)
        else:
            params[key] = value if not isinstance(value, str) else str(value)
    out: dict[str, Any] = {"id": message.msgid, "params": params}
    if message.plural is not None:
        out.update(plural=message.plural, n=message.n)
    if message.english is not None:
        out["english"] = message.english
    return out


def restored_message(data: Any) -> str:
    """The message :func:`stored_message` kept (a :class:`Msg` again); anything else as its text."""
    if not isinstance(data, dict):
        return str(data)
    if "id" not in data:
        return str(data.get("text", ""))
    raw = data.get("params") if isinstance(data.get("params"), dict) else {}
    params = {k: restored_message(v["message"]) if isinstance(v, dict) and "message" in v else v for k, v in raw.items()}
    try:
        if "english" in data:
            return Msg.worded(str(data["english"]), str(data["id"]), **params)
        if data.get("plural") is not None:
            return Msg(str(data["id"]), str(data["plural"]), int(data.get("n") or 0), **params)
        return Msg(str(data["id"]), **params)
    except (KeyError, IndexError, ValueError, TypeError):  # a message id changed since: its words as stored
        return str(data.get("english") or data["id"])


def catalogue_path(lang: str) -> Path:
    """The ``.po`` file of ``lang``."""
    return LOCALE_DIR / lang / "LC_MESSAGES" / f"{DOMAIN}.po"


@functools.cache
def catalogue_digest(lang: str) -> str:
    """A short digest of ``lang``'s catalogue (cache key of what is made from it)."""
    path = catalogue_path(lang)
    data = path.read_bytes() if path.is_file() else b""
    return hashlib.sha256(data).hexdigest()[:12]


@functools.cache
def translations(lang: str) -> _gettext.NullTranslations:
    """The compiled catalogue of ``lang`` (read once; English: the message ids themselves).

    Raises
    ------
    ValueError
        ``lang`` is not one of :data:`LANGUAGES`.
    """
    if not is_language(lang):
        raise ValueError(f"language must be one of {', '.join(LANGUAGES)}, got {lang!r}")
    path = catalogue_path(lang)
    if lang == DEFAULT_LANGUAGE or not path.is_file():
        return _gettext.NullTranslations()
    from babel.messages.mofile import write_mo
    from babel.messages.pofile import read_po

    with path.open("rb") as fh:
        catalog = read_po(fh, locale=lang, domain=DOMAIN)
    buf = io.BytesIO()
    write_mo(buf, catalog, use_fuzzy=False)
    buf.seek(0)
    return _gettext.GNUTranslations(buf)


def parse_accept_language(header: str | None) -> list[str]:
    """The language tags of an ``Accept-Language`` header, most wanted first (q = 0 left out).

    ``"de-CH,de;q=0.9,en;q=0.5"`` → ``["de-CH", "de", "en"]``. Malformed entries are skipped;
    a long header is read only in its first :data:`_MAX_HEADER` characters.
    """
    if not header:
        return []
    weighted: list[tuple[float, int, str]] = []
    for i, part in enumerate(header[:_MAX_HEADER].split(",")[:_MAX_ENTRIES]):
        tag, _sep, rest = part.strip().partition(";")
        tag = tag.strip()
        if not tag or tag == "*" or not _TAG.match(tag):
            continue
        q = 1.0
        rest = rest.strip()
        if rest.startswith("q="):
            try:
                q = float(rest[2:])
            except ValueError:
                continue
        if 0 < q <= 1:
            weighted.append((-q, i, tag))
    return [tag for _q, _i, tag in sorted(weighted)]


@dataclass(frozen=True)
class Language:
    """The language a request is answered in.

    Attributes
    ----------
    code : str
        One of :data:`LANGUAGES` (the catalogue).
    tag : str
        The locale of numbers and dates: ``code`` with the browser's region where it asked
        for this language with one (``de-CH``), else ``code``.
    """

    code: str
    tag: str


def negotiate(accept_language: str | None, chosen: str | None = None) -> Language:
    """The language of a request: ``chosen`` (the user's), else the browser's first one we speak.

    Parameters
    ----------
    accept_language : str or None
        The request's ``Accept-Language`` header.
    chosen : str or None
        The language kept with the user's account (None: follow the browser).
    """
    tags = parse_accept_language(accept_language)
    code = chosen if is_language(chosen) else None
    if code is None:
        code = next((t.split("-")[0].lower() for t in tags if t.split("-")[0].lower() in LANGUAGES),
                    DEFAULT_LANGUAGE)
    region = next((t for t in tags if t.split("-")[0].lower() == code and "-" in t), None)
    if region is not None:
        lang, _sep, rest = region.partition("-")
        region = f"{code}-{rest}" if rest.isalpha() and len(rest) == 2 else None
        if region is not None:
            region = region[:3] + region[3:].upper()
    return Language(code=code, tag=region or code)


@functools.cache
def jinja_environment(directory: str, lang: str) -> Any:
    """A Jinja2 environment of the templates in ``directory`` speaking ``lang``.

    Templates mark their text with ``{{ _("...") }}``, ``{% trans %}`` or ``ngettext`` (Jinja2's
    i18n extension, new-style: ``_("Run %(id)s", id=run_id)``, fields escaped). One environment
    per directory and language, made once.
    """
    import jinja2

    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(directory), autoescape=True, auto_reload=False,
        extensions=["jinja2.ext.i18n"],
    )
    env.install_gettext_translations(translations(lang), newstyle=True)  # type: ignore[attr-defined]
    env.globals["lang"] = lang
    return env
