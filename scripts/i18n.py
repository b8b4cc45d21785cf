#!/usr/bin/env python3
"""The catalogues of the languages (app/locale), kept with Babel.

    python scripts/i18n.py extract   # the message ids of the code into app/locale/messages.pot
    python scripts/i18n.py update    # extract, then merge the template into each language's .po
    python scripts/i18n.py check     # every message translated in every language (exit 1 if not)

What is extracted is configured in ``babel.cfg`` (Python, the Jinja2 templates, the pages'
scripts) with the keywords of :data:`KEYWORDS`. A new message appears untranslated in each
``app/locale/<lang>/LC_MESSAGES/messages.po``: translate it there (no ``fuzzy`` flag left),
then ``check``. The service compiles the ``.po`` files when it reads them (no ``.mo`` to keep).
tests/test_i18n_catalogues.py runs the same extraction and check.
"""

from __future__ import annotations

import io
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOCALE_DIR = ROOT / "app" / "locale"
TEMPLATE = LOCALE_DIR / "messages.pot"
MAPPING = ROOT / "babel.cfg"
#: Babel's keywords plus ours: N_ marks a message without translating it (app.core.i18n)
KEYWORDS = {"_": None, "N_": None, "gettext": None, "ngettext": (1, 2), "pgettext": ((1, "c"), 2)}
#: where the messages are (relative to the repository: the locations in the catalogues)
SOURCES = ("app", "frontend")
LANGUAGES = ("de", "fr", "it")
_FIELD = re.compile(r"\{(\w*)(?:![rsa])?(?::[^{}]*)?\}|%\((\w+)\)[sd]")

sys.path.insert(0, str(ROOT))


def extract():
    """The catalogue of every marked message of the sources (a Babel ``Catalog``)."""
    from babel.messages.catalog import Catalog
    from babel.messages.extract import extract_from_dir
    from babel.messages.frontend import parse_mapping_cfg

    with MAPPING.open(encoding="utf-8") as fh:
        method_map, options_map = parse_mapping_cfg(fh)
    catalog = Catalog(project="trackvkf", msgid_bugs_address="", charset="utf-8")
    def wanted(dirname: str) -> bool:  # the sources, not the environment, the tests or var/
        rel = Path(dirname).resolve().relative_to(ROOT).parts
        return not rel or (rel[0] in SOURCES and not any(p.startswith((".", "_")) for p in rel))

    for filename, _lineno, message, comments, context in extract_from_dir(
        ROOT, method_map, options_map, keywords=KEYWORDS, strip_comment_tags=True, directory_filter=wanted,
    ):
        catalog.add(message, None, [(filename.replace("\\", "/"), None)], auto_comments=comments, context=context)
    # the words of the codes the pages show (their English comes from the code's own tables)
    from app.web import vocabulary

    for kind, words in vocabulary.messages().items():
        for english in words.values():
            catalog.add(english, None, [("app/web/vocabulary.py", None)], context=kind)
    return catalog


def _write(catalog, path: Path) -> None:
    from babel.messages.pofile import write_po

    buf = io.BytesIO()
    write_po(buf, catalog, width=100, sort_output=False, include_lineno=False, omit_header=False)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(buf.getvalue())


def read(lang: str):
    """The catalogue of ``lang`` as it is on disk."""
    from babel.messages.pofile import read_po

    with (LOCALE_DIR / lang / "LC_MESSAGES" / "messages.po").open("rb") as fh:
        return read_po(fh, locale=lang)


def update() -> None:
    """Extract, write the template, merge it into each language (new messages untranslated)."""
    from babel.messages.catalog import Catalog

    template = extract()
    _write(template, TEMPLATE)
    for lang in LANGUAGES:
        path = LOCALE_DIR / lang / "LC_MESSAGES" / "messages.po"
        catalog = read(lang) if path.is_file() else Catalog(locale=lang, project="trackvkf", charset="utf-8")
        catalog.update(template, no_fuzzy_matching=True, update_header_comment=False)
        catalog.obsolete.clear()
        _write(catalog, path)


def fields(text: str) -> set[str]:
    """The placeholder names of a message: ``{name}``, ``{name:.1f}``, ``%(name)s``."""
    return {a or b for a, b in _FIELD.findall(text)}


def problems(template=None) -> list[str]:
    """What is wrong with the catalogues against ``template`` (default: a fresh extraction)."""
    template = template if template is not None else extract()
    wanted = {(m.context, m.id if isinstance(m.id, str) else m.id[0]) for m in template if m.id}
    out: list[str] = []
    for lang in LANGUAGES:
        try:
            catalog = read(lang)
        except FileNotFoundError:
            out.append(f"{lang}: no catalogue")
            continue
        have = {}
        for m in catalog:
            if m.id:
                have[(m.context, m.id if isinstance(m.id, str) else m.id[0])] = m
        for key in sorted(wanted - have.keys(), key=str):
            out.append(f"{lang}: missing {key[1]!r}" + (f" (context {key[0]!r})" if key[0] else ""))
        for key, m in have.items():
            if key not in wanted:
                out.append(f"{lang}: obsolete {key[1]!r} (no longer in the code)")
                continue
            strings = [m.string] if isinstance(m.string, str) else list(m.string)
            if m.fuzzy:
                out.append(f"{lang}: fuzzy {key[1]!r}")
            if not all(strings):
                out.append(f"{lang}: untranslated {key[1]!r}")
                continue
            ids = [m.id] if isinstance(m.id, str) else list(m.id)
            need = set().union(*(fields(i) for i in ids))
            for s in strings:
                if fields(s) - need or (isinstance(m.id, str) and fields(s) != need):
                    out.append(f"{lang}: placeholders of {key[1]!r}: {sorted(fields(s))} != {sorted(need)}")
    return out


def main(argv: list[str]) -> int:
    cmd = argv[1] if len(argv) > 1 else "check"
    if cmd == "extract":
        _write(extract(), TEMPLATE)
        return 0
    if cmd == "update":
        update()
        return 0
    if cmd == "check":
        found = problems()
        for p in found:
            print(p)
        print(f"{len(found)} problem(s)" if found else "catalogues complete")
        return 1 if found else 0
    print(__doc__)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
