"""The railway's own class scheme: the section classes A … E shown and exported as its classes.

trackvkf classes every section A (best) … E from the rms of its stiffness index
(:mod:`app.analysis.condition.section_class`); a railway plans with its own condition classes
(e.g. five classes 1–5 with their names, per language). ``TRACKVKF_PLACES_CLASS_SCHEME`` maps
each of A … E to exactly one class of the scheme (several may map to one)::

    {"name": {"en": "Condition class", "de": "Zustandsklasse", "fr": "Classe d'état",
              "it": "Classe di stato"},
     "classes": [
       {"code": "1", "of": ["A"], "name": {"en": "as new", "de": "neuwertig", ...}},
       {"code": "2", "of": ["B"], "name": {...}},
       ...]}

Names are given per language (``en`` is required: the fallback). Without the setting the
scheme is trackvkf's own (:data:`DEFAULT_SCHEME`: A … E). The API, the CSV, the Condition page
and the planning report show the scheme's codes and names beside the internal class.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from app.analysis.condition.section_class import SECTION_CLASSES

__all__ = ["SchemeClass", "ClassScheme", "DEFAULT_SCHEME", "class_scheme", "parse_scheme"]

#: the colour of a scheme class holding A … E (its best class) unless the scheme gives one
_COLOURS = ("#2e7d32", "#8bc34a", "#e6c619", "#fb8c00", "#c62828")


@dataclass(frozen=True)
class SchemeClass:
    """One class of the railway's scheme: its code, the internal classes it holds, its names."""

    code: str
    of: tuple[str, ...]
    names: Mapping[str, str]
    colour: str

    def name(self, lang: str) -> str:
        """Its name in ``lang`` (else English)."""
        return self.names.get(lang) or self.names["en"]


@dataclass(frozen=True)
class ClassScheme:
    """The railway's classes, best first; every internal class A … E in exactly one."""

    title: Mapping[str, str]
    classes: tuple[SchemeClass, ...]

    def __post_init__(self) -> None:
        seen = [c for k in self.classes for c in k.of]
        if sorted(seen) != sorted(SECTION_CLASSES):
            raise ValueError("classes: every class of A, B, C, D, E must be in exactly one class of the "
                             f"scheme, got {', '.join(seen) or 'none'}")
        codes = [k.code for k in self.classes]
        if len(set(codes)) != len(codes):
            raise ValueError(f"classes: codes must differ, got {codes}")

    def name(self, lang: str) -> str:
        """The scheme's name in ``lang`` (else English)."""
        return self.title.get(lang) or self.title["en"]

    def of(self, internal: str) -> SchemeClass | None:
        """The scheme class holding internal class ``internal`` (None for ``""``: no class)."""
        for k in self.classes:
            if internal in k.of:
                return k
        return None

    def code(self, internal: str) -> str:
        """The scheme's code of internal class ``internal`` (``""`` for no class)."""
        k = self.of(internal)
        return k.code if k is not None else ""

    def lengths(self, by_class: Mapping[str, float] | None) -> dict[str, float] | None:
        """Length per scheme class (``""``: no class) from the length per internal class."""
        if by_class is None:
            return None
        out = {k.code: float(sum(by_class.get(c, 0.0) for c in k.of)) for k in self.classes}
        out[""] = float(by_class.get("", 0.0))
        return out

    def describe(self, lang: str) -> dict[str, Any]:
        """The scheme for an answer: its name and classes (code, name, internal classes, colour)."""
        return {"name": self.name(lang),
                "classes": [{"code": k.code, "name": k.name(lang), "of": list(k.of), "colour": k.colour}
                            for k in self.classes]}


def _names(value: Any, where: str) -> dict[str, str]:
    if isinstance(value, str):
        value = {"en": value}
    if not isinstance(value, Mapping) or not isinstance(value.get("en"), str) or not value["en"].strip():
        raise ValueError(f"{where}: names per language with at least 'en', got {value!r}")
    out = {}
    for lang, text in value.items():
        if not isinstance(lang, str) or not isinstance(text, str) or not (1 <= len(text.strip()) <= 80):
            raise ValueError(f"{where}[{lang!r}]: 1 to 80 characters, got {text!r}")
        out[lang] = text.strip()
    return out


def parse_scheme(value: Mapping[str, Any]) -> ClassScheme:
    """The scheme of a ``TRACKVKF_PLACES_CLASS_SCHEME`` document.

    Raises
    ------
    ValueError
        Naming the part at fault.
    """
    if not isinstance(value, Mapping) or not isinstance(value.get("classes"), list) or not value["classes"]:
        raise ValueError("classes: a list of the scheme's classes, best first")
    classes = []
    for i, item in enumerate(value["classes"]):
        where = f"classes[{i}]"
        if not isinstance(item, Mapping):
            raise ValueError(f"{where}: an object with code, of, name")
        code = item.get("code")
        if not isinstance(code, str | int) or not (1 <= len(str(code).strip()) <= 16):
            raise ValueError(f"{where}.code: 1 to 16 characters, got {code!r}")
        of = item.get("of")
        if isinstance(of, str):
            of = [of]
        if not isinstance(of, list) or not of or any(c not in SECTION_CLASSES for c in of):
            raise ValueError(f"{where}.of: classes of {', '.join(SECTION_CLASSES)}, got {of!r}")
        colour = item.get("colour") or _COLOURS[min(SECTION_CLASSES.index(min(of)), len(_COLOURS) - 1)]
        if not isinstance(colour, str) or not colour.startswith("#") or len(colour) not in (4, 7):
            raise ValueError(f"{where}.colour: #rgb or #rrggbb, got {colour!r}")
        classes.append(SchemeClass(str(code).strip(), tuple(of), _names(item.get("name", str(code)), f"{where}.name"),
                                   colour))
    return ClassScheme(_names(value.get("name", "Class"), "name"), tuple(classes))


#: trackvkf's own classes A … E (what a section's rms says: docs/places.md)
DEFAULT_SCHEME = parse_scheme({
    "name": {"en": "Class", "de": "Klasse", "fr": "Classe", "it": "Classe"},
    "classes": [
        {"code": "A", "of": ["A"], "name": {"en": "A: very good", "de": "A: sehr gut", "fr": "A: très bon",
                                            "it": "A: molto buono"}},
        {"code": "B", "of": ["B"], "name": {"en": "B: good", "de": "B: gut", "fr": "B: bon", "it": "B: buono"}},
        {"code": "C", "of": ["C"], "name": {"en": "C: fair", "de": "C: mittel", "fr": "C: moyen", "it": "C: medio"}},
        {"code": "D", "of": ["D"], "name": {"en": "D: poor", "de": "D: schlecht", "fr": "D: mauvais",
                                            "it": "D: scarso"}},
        {"code": "E", "of": ["E"], "name": {"en": "E: very poor", "de": "E: sehr schlecht", "fr": "E: très mauvais",
                                            "it": "E: molto scarso"}},
    ],
})


def class_scheme(settings: Any) -> ClassScheme:
    """The scheme of the settings (``TRACKVKF_PLACES_CLASS_SCHEME``), else :data:`DEFAULT_SCHEME`.

    Raises
    ------
    ValueError
        Naming ``TRACKVKF_PLACES_CLASS_SCHEME`` and the part at fault.
    """
    value = getattr(settings, "places_class_scheme", None)
    if not value:
        return DEFAULT_SCHEME
    try:
        return parse_scheme(value)
    except ValueError as exc:
        raise ValueError(f"TRACKVKF_PLACES_CLASS_SCHEME: {exc}") from None
