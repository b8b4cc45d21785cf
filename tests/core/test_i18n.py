"""The languages: which one a request gets, messages that remember what to translate, and
catalogues that hold every message of the code in every language (no entry missing, fuzzy or
untranslated, no placeholder lost) — the extraction of scripts/i18n.py (babel.cfg) run afresh."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from app.core.errors import ApiError, not_found
from app.core.i18n import (
    LANGUAGES,
    Msg,
    _,
    negotiate,
    ngettext,
    parse_accept_language,
    restored_message,
    stored_message,
    translate,
    translations,
)

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("i18n_script", ROOT / "scripts" / "i18n.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("header", "chosen", "code", "tag"), [
    (None, None, "en", "en"),
    ("", None, "en", "en"),
    ("de-CH,de;q=0.9,en;q=0.5", None, "de", "de-CH"),
    ("fr-ch, fr;q=0.9", None, "fr", "fr-CH"),
    ("es-ES,it;q=0.8,de;q=0.9", None, "de", "de"),   # the first language we speak, by weight
    ("it;q=0,fr;q=0.3", None, "fr", "fr"),            # q=0: not wanted
    ("de-CH", "it", "it", "it"),                      # the account's choice wins; no region for it
    ("it-CH,de", "it", "it", "it-CH"),
    ("xx, *;q=0.1, ;;, de-DE-1996", None, "de", "de"),  # odd entries skipped
    ("de-CH", "klingon", "de", "de-CH"),              # an unknown choice is no choice
    ("a" * 5000, None, "en", "en"),
])
def test_negotiate(header, chosen, code, tag):
    lang = negotiate(header, chosen)
    assert (lang.code, lang.tag) == (code, tag)


def test_accept_language_order():
    assert parse_accept_language("en;q=0.5, de-CH, fr;q=0.9") == ["de-CH", "fr", "en"]


def test_messages_are_english_until_translated():
    m = _("run {ident} not found", ident=7)
    assert m == "run 7 not found" and isinstance(m, str)
    assert m.in_language("de") == "Messfahrt 7 nicht gefunden"
    assert m.in_language("fr") == "parcours 7 introuvable"
    assert m.in_language("it") == "corsa 7 non trovata"
    assert translate("plain text", "de") == "plain text"
    runs = [ngettext("{n} run", "{n} runs", n) for n in (1, 3)]
    assert runs == ["1 run", "3 runs"]
    # the translation of a message that is no script message: the plural rules of the language
    assert translations("fr").ngettext("{n} run", "{n} runs", 0) == "{n} parcours"


def test_an_api_error_keeps_its_message_to_translate():
    err = not_found("run", 12)
    assert err.message == "run 12 not found" and err.field == "run_id"
    assert err.message_in("de") == "Messfahrt 12 nicht gefunden"
    assert ApiError(422, "x", "as it is").message_in("it") == "as it is"
    nested = Msg("{message} (got {value})", message=_("must be a number"), value="'a'")
    assert nested.in_language("de") == "muss eine Zahl sein (erhalten: 'a')"


def test_a_stored_message_is_read_later_in_any_language():
    """A message kept in a JSON column (a run's ingest warnings) comes back as a message: its
    parameters, a nested message, a plural, another library's English wording; plain text as it was."""
    import json

    kept = _("reading {what} needs more than {mib:.0f} MiB of memory (TRACKVKF_PARSE_MEMORY_BYTES)",
             what=_("the {format} file", format="csv"), mib=512.4)
    back = restored_message(json.loads(json.dumps(stored_message(kept))))
    assert isinstance(back, Msg) and back == kept
    assert back.in_language("de") == ("die csv-Datei braucht zum Lesen mehr als 512 MiB Speicher "
                                      "(TRACKVKF_PARSE_MEMORY_BYTES)")
    runs = restored_message(json.loads(json.dumps(stored_message(ngettext("{n} run", "{n} runs", 3)))))
    assert runs == "3 runs" and runs.in_language("fr") == "3 parcours"
    worded = Msg.worded("Input should be a valid number", "must be a number")
    again = restored_message(stored_message(worded))
    assert again == "Input should be a valid number" and again.in_language("it") == worded.in_language("it")
    assert restored_message(stored_message("as it is")) == "as it is"
    assert restored_message("an old text") == "an old text"
    # a message whose fields changed since it was stored: its words as stored, not an error
    assert restored_message({"id": "run {ident} not found", "params": {}}) == "run {ident} not found"


def test_account_and_webhook_rejections_are_marked():
    """Beyond the run files: a password too short, an unknown role, a webhook URL with credentials or
    aimed at a private address answer in the reader's language (the API's 422 takes the message)."""
    from app.core.security import check_password_strength
    from app.core.url_policy import AddressPolicy, UrlError, check_url, resolve
    from app.db.auth_crud import AuthError, _check_role

    with pytest.raises(ValueError) as exc:
        check_password_strength("short")
    assert isinstance(exc.value.args[0], Msg) and exc.value.args[0].in_language("de").startswith(
        "das Passwort muss mindestens ")
    with pytest.raises(AuthError) as err:
        _check_role("boss")
    assert err.value.field == "role" and err.value.message.in_language("fr").startswith("doit être l'un de ")
    with pytest.raises(UrlError) as url:
        check_url("https://user:secret@example.org/hook")
    assert url.value.args[0].in_language("it").startswith("le credenziali nell'URL (user:password@) non sono")
    with pytest.raises(UrlError) as url:
        resolve("https://hooks.example.org/hook", AddressPolicy(), lambda host, port: ["10.1.2.3"])
    assert str(url.value).startswith("resolves to 10.1.2.3, a private address: ")
    assert url.value.args[0].in_language("de").startswith("wird zu 10.1.2.3 aufgelöst, eine private Adresse: ")


def test_a_processing_setting_out_of_range_reads_in_the_users_language():
    """The 422 of a reprocessing request's settings names the setting and says its range in German,
    French or Italian (the analysis raises a SettingError with the message to translate)."""
    from app.runs.jobs import settings_from_request

    with pytest.raises(ApiError) as exc:
        settings_from_request(None, {"bin_length_m": 20})
    assert exc.value.field == "bin_length_m" and exc.value.message == "bin_length_m must be in [0.05, 10] m, got 20"
    assert exc.value.message_in("de") == "bin_length_m muss in [0.05, 10] m liegen, erhalten: 20"
    with pytest.raises(ApiError) as exc:
        settings_from_request({"filter_order": 2}, {"colour": "red"})
    assert exc.value.field == "settings"
    assert exc.value.message_in("it") == "impostazione/i di elaborazione sconosciuta/e: colour"


def test_a_spectrogram_window_too_slow_reads_in_the_users_language():
    """The spectrogram's 422 for a window slower than min_speed_kmh: the analysis keeps the message
    to translate (its English unchanged)."""
    import numpy as np

    from app.analysis.settings import ProcessingSettings, SettingError
    from app.analysis.spectrogram import window_spectrograms

    n = 4096
    with pytest.raises(SettingError) as exc:
        window_spectrograms(np.zeros(n), 2000.0, np.full(n, 1.0), core=(0, n), wheel_diameter=0.92,
                            sleeper_spacing=0.6, settings=ProcessingSettings())
    assert str(exc.value).startswith("speed: the mean speed in the window (3.6 km/h) is below min_speed_kmh = ")
    german = Msg(exc.value.message, **exc.value.params).in_language("de")
    assert german.startswith("speed: die mittlere Geschwindigkeit im Fenster (3.6 km/h) liegt unter min_speed_kmh = ")


def test_every_message_is_in_every_catalogue():
    """The test of the catalogues: a message of the code (Python, templates, the pages' scripts,
    the words of the codes) missing from a language, left fuzzy or untranslated, a translation
    that lost or invented a placeholder, or an entry the code no longer has: each is named."""
    script = _script()
    template = script.extract()
    assert len(template) > 150
    assert script.problems(template) == []


def test_the_check_finds_what_is_wrong(tmp_path, monkeypatch):
    script = _script()
    from babel.messages.catalog import Catalog

    template = Catalog(locale=None)
    template.add("Runs")
    template.add("one {x}")
    template.add("new message")
    for lang in LANGUAGES[1:]:
        cat = Catalog(locale=lang)
        cat.add("Runs", "Läufe", flags=("fuzzy",))
        cat.add("one {x}", "eins {y}")
        cat.add("gone", "weg")
        path = tmp_path / lang / "LC_MESSAGES" / "messages.po"
        path.parent.mkdir(parents=True)
        script._write(cat, path)
    monkeypatch.setattr(script, "LOCALE_DIR", tmp_path)
    found = "\n".join(script.problems(template))
    for lang in LANGUAGES[1:]:
        assert f"{lang}: fuzzy 'Runs'" in found
        assert f"{lang}: missing 'new message'" in found
        assert f"{lang}: obsolete 'gone'" in found
        assert f"{lang}: placeholders of 'one {{x}}'" in found


def test_the_extraction_reads_every_call():
    """Every literal message a page script, template or module passes to the translation functions
    is in the extraction: a construct the extractor misreads (a regular expression with a quote,
    say) would otherwise hide the rest of its file from the catalogues without an error."""
    import re

    script = _script()
    template = script.extract()
    ids = {m.id if isinstance(m.id, str) else m.id[0] for m in template if m.id}
    call = re.compile(r"""(?<![\w.])(?:T\.)?(?:_|N_|ngettext|pgettext\("[^"]*",)\s*\(\s*"((?:[^"\\]|\\.)+)"|"""
                      r"""\b(?:T\._|T\.ngettext)\(\s*"((?:[^"\\]|\\.)+)\"""")
    missing = []
    # (Python is read by its syntax tree, which misses nothing; the pages' scripts and templates by lexers)
    for pattern in ("frontend/static/js/**/*.js", "frontend/templates/*.html"):
        for path in ROOT.glob(pattern):
            for m in call.finditer(path.read_text(encoding="utf-8")):
                text = (m.group(1) or m.group(2)).encode().decode("unicode_escape") if "\\" in (m.group(1) or m.group(2)) \
                    else (m.group(1) or m.group(2))
                if text not in ids:
                    missing.append(f"{path.relative_to(ROOT)}: {text!r}")
    assert not missing, "\n".join(missing)


def test_no_function_hides_the_marker():
    """``_`` marks a message: a function of a module that uses it must not assign ``_`` (a throwaway
    name there would make every ``_("...")`` of the function fail with UnboundLocalError)."""
    import ast

    bad = []
    for path in sorted((ROOT / "app").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        if not any(isinstance(n, ast.Call) and getattr(n.func, "id", None) == "_" for n in ast.walk(tree)):
            continue
        for f in ast.walk(tree):
            if not isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            inner = {id(n) for c in ast.walk(f) if isinstance(c, ast.ListComp | ast.SetComp | ast.DictComp | ast.GeneratorExp)
                     for n in ast.walk(c)}
            bad += [f"{path.relative_to(ROOT)}:{n.lineno} ({f.name})" for n in ast.walk(f)
                    if isinstance(n, ast.Name) and n.id == "_" and isinstance(n.ctx, ast.Store) and id(n) not in inner]
    assert not bad, bad
