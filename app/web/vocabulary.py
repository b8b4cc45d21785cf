"""The words of the codes the pages show: tiers, statuses, events, maintenance and asset types, ...

The API answers codes (``"rail_replacement"``, ``"false_alarm"``, ``"intervention"``): what a
program reads. The pages show them as words of the reader's language. The codes come from
where they are defined (the enumerations of the models and the condition analysis); their
English words are the code with spaces (or the text the code stands for, as a tier's action),
and those words are the message ids of the catalogue, with the kind as context
(``pgettext("maintenance type", "other")`` and ``pgettext("asset type", "other")`` are two
messages). ``scripts/i18n.py`` extracts them from :func:`messages` with the rest.
"""

from __future__ import annotations

import functools
from typing import Any

from app.analysis.condition.discontinuities import ASSET_TYPES
from app.analysis.condition.identity import TENDENCIES
from app.analysis.condition.section_class import SECTION_CLASSES
from app.analysis.condition.tiers import TIER_ACTIONS, TIER_NAMES
from app.analysis.impacts.findings import FINDING_KINDS
from app.analysis.stiffness.speed_norm import METHODS
from app.core.i18n import translations
from app.io.reference import MAINTENANCE_TYPES
from app.places.answers import EVIDENCE_NAMES, PLACE_ACTION_RELATIONS, PLACE_EVENT_KINDS
from app.places.workflow import PLACE_STATUSES
from app.runs.jobs import JOB_STATUSES

__all__ = ["KINDS", "messages", "labels", "SECTION_CLASS_MEANINGS"]

#: what each section class means (the classes' rule, docs/condition.md); "" is no class
SECTION_CLASS_MEANINGS: dict[str, str] = {
    "A": "best fifth of healthy track", "B": "typical healthy track", "C": "the rest of healthy track",
    "D": "beyond anything healthy measured", "E": "reaches a place's alert limit", "": "not enough data",
}


#: how a reference curve's speed dependence was fitted (app.analysis.stiffness.speed_norm)
CURVE_METHODS: dict[str, str] = {
    "within": "speed dependence fitted within locations passed at several speeds",
    "pooled": "speed dependence fitted over all locations together",
    "none": "no speed dependence fitted",
}


def _words(codes: tuple[str, ...] | list[str]) -> dict[str, str]:
    return {c: c.replace("_", " ") for c in codes}


#: the kinds of codes (the context of their messages) and their codes' English words
KINDS: dict[str, Any] = {
    "tier": lambda: _words(TIER_NAMES),
    "tier action": lambda: {t: TIER_ACTIONS[t] for t in TIER_NAMES},
    "place status": lambda: _words(PLACE_STATUSES),
    "place event": lambda: _words(PLACE_EVENT_KINDS),
    "action relation": lambda: _words(PLACE_ACTION_RELATIONS),
    "evidence": lambda: _words([name for _bit, name in EVIDENCE_NAMES]),
    "tendency": lambda: _words(TENDENCIES),
    "maintenance type": lambda: _words(MAINTENANCE_TYPES),
    "asset type": lambda: _words(ASSET_TYPES),
    "rail finding": lambda: _words(FINDING_KINDS),
    "job status": lambda: _words(JOB_STATUSES),
    "section class": lambda: {c: SECTION_CLASS_MEANINGS[c] for c in (*SECTION_CLASSES, "")},
    "direction": lambda: {"soft": "soft", "hard": "hard"},
    "curve method": lambda: {m: CURVE_METHODS[m] for m in METHODS},
}


def messages() -> dict[str, dict[str, str]]:
    """Kind → code → English words (the message ids, with the kind as their context)."""
    return {kind: make() for kind, make in KINDS.items()}


@functools.cache
def labels(lang: str) -> dict[str, dict[str, str]]:
    """Kind → code → the words in ``lang`` (a page's boot data: ``T.label(kind, code)``)."""
    t = translations(lang)
    return {kind: {code: t.pgettext(kind, english) for code, english in words.items()}
            for kind, words in messages().items()}
