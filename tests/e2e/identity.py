"""Fingerprints of what a processed data set stores and answers, for the refactor identity test.

:func:`canonical` turns an answer (JSON, CSV text, table rows) into canonical bytes: keys
sorted, wall-clock values (when a row was written, how long a step took, which process did it)
replaced by ``"<volatile>"`` so that their presence still counts, floats written with
:data:`FLOAT_DIGITS` significant digits (the last bits of a float may differ between CPUs; a
refactor that changes a stored number changes far more than the 12th digit).

:class:`Fingerprint` holds one sha256 per answer and one per part of it (a top-level key of a
JSON object, a column of a table), so a failing comparison says which answer and which field
changed; :func:`compare` says it in words. ``TRACKVKF_IDENTITY_DUMP=<dir>`` writes every
canonical answer to ``<dir>/<name>.json`` as well: dump on both commits and ``diff -r`` them
to see the values.
"""

from __future__ import annotations

import csv
import datetime as dt
import hashlib
import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["FLOAT_DIGITS", "VOLATILE_KEYS", "canonical", "csv_rows", "Fingerprint", "compare", "DUMP_ENV"]

#: significant digits of a float in the canonical form
FLOAT_DIGITS = 12
#: keys whose values are wall-clock facts of the test run, not results
VOLATILE_KEYS = frozenset({
    "created_at", "started_at", "finished_at", "heartbeat_at", "computed_at", "compute_s", "published_at",
    "assemble_s", "store_s", "worker_id", "imported_at", "updated_at", "last_used_at", "next_attempt_at",
    "locked_until", "last_attempt_at", "delivered_at", "secret", "key_hash", "expires_at",
    "places_updated_at", "status_at",
})
#: environment variable naming a directory to write the canonical answers into
DUMP_ENV = "TRACKVKF_IDENTITY_DUMP"


_FLOAT_FORMAT = f".{FLOAT_DIGITS}g"


def _norm(value: Any) -> Any:
    # the exact built-in types first (a table of the processed demo is a few million values): the
    # same result as the general cases of _norm_any, without their abstract-class checks
    t = type(value)
    if t is float:
        return float(format(value, _FLOAT_FORMAT)) if math.isfinite(value) else repr(value)
    if t is str or t is int or t is bool or value is None:
        return value
    if t is list or t is tuple:
        return [_norm(v) for v in value]
    if t is dict and all(type(k) is str for k in value):  # sorted by the keys themselves = by str(key)
        return {k: ("<volatile>" if k in VOLATILE_KEYS and value[k] is not None else _norm(value[k]))
                for k in sorted(value)}
    return _norm_any(value)


def _norm_any(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): ("<volatile>" if str(k) in VOLATILE_KEYS and v is not None else _norm(v))
                for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, list | tuple):
        return [_norm(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    if isinstance(value, float):
        if not math.isfinite(value):
            return repr(value)
        return float(f"{value:.{FLOAT_DIGITS}g}")
    if isinstance(value, bytes | bytearray | memoryview):
        return "sha256:" + hashlib.sha256(bytes(value)).hexdigest()
    if isinstance(value, dt.datetime | dt.date):
        return value.isoformat()
    if hasattr(value, "item"):  # numpy scalar
        return _norm(value.item())
    return str(value)


def _dumps(norm: Any) -> bytes:
    """JSON bytes of an already normalised value (:func:`_norm`: its objects' keys are in sorted order
    already, as ``sort_keys`` would write them)."""
    return json.dumps(norm, separators=(",", ":"), ensure_ascii=False).encode()


def canonical(value: Any) -> bytes:
    """Canonical JSON bytes of ``value`` (see the module docstring)."""
    return _dumps(_norm(value))


def csv_rows(text: str) -> list[dict[str, Any]]:
    """Rows of a CSV answer with numbers as floats (so they are rounded like every other float)."""
    out = []
    for row in csv.DictReader(io.StringIO(text)):
        parsed: dict[str, Any] = {}
        for k, v in row.items():
            try:
                parsed[k] = float(v)
            except (TypeError, ValueError):
                parsed[k] = v
        out.append(parsed)
    return out


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _part(norm: Any) -> str:
    return _sha(_dumps(norm))[:16]


def _parts(norm: Any) -> dict[str, str]:
    """A (short) sha256 per top-level key of an object, or per column of a list of row objects
    (``norm``: the answer normalised once by :func:`_norm`, which a second pass would not change)."""
    if isinstance(norm, dict):
        return {k: _part(v) for k, v in norm.items()}
    if isinstance(norm, list) and norm and all(isinstance(r, dict) for r in norm):
        columns = sorted({k for r in norm for k in r})
        parts = {c: _part([r.get(c) for r in norm]) for c in columns}
        parts["<rows>"] = str(len(norm))
        return parts
    return {}


@dataclass
class Fingerprint:
    """One sha256 per named answer and per part of it."""

    answers: dict[str, dict[str, Any]] = field(default_factory=dict)
    #: write the canonical answers to :data:`DUMP_ENV` when it is set
    dump: bool = True

    def add(self, name: str, value: Any) -> None:
        """Fingerprint ``value`` as ``name`` (and dump it when :data:`DUMP_ENV` is set)."""
        if name in self.answers:
            raise ValueError(f"{name}: fingerprinted twice")
        norm = _norm(value)
        data = _dumps(norm)
        self.answers[name] = {"sha256": _sha(data), "parts": _parts(norm)}
        dump = os.environ.get(DUMP_ENV) if self.dump else None
        if dump:
            path = Path(dump) / f"{name.replace('/', '_')}.json"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(json.loads(data), indent=1, sort_keys=True) + "\n")

    def to_json(self) -> dict[str, Any]:
        return {"float_digits": FLOAT_DIGITS, "answers": dict(sorted(self.answers.items()))}


def compare(golden: Mapping[str, Any], now: Fingerprint) -> list[str]:
    """What differs between a golden fingerprint and ``now``, one line per answer (empty: identical)."""
    lines: list[str] = []
    old: Mapping[str, Any] = golden.get("answers", {})
    for name in sorted(set(old) | set(now.answers)):
        a, b = old.get(name), now.answers.get(name)
        if a is None:
            lines.append(f"{name}: new answer (not in the golden file)")
        elif b is None:
            lines.append(f"{name}: missing (in the golden file, not fingerprinted now)")
        elif a["sha256"] != b["sha256"]:
            pa, pb = a.get("parts", {}), b.get("parts", {})
            changed = sorted(k for k in set(pa) & set(pb) if pa[k] != pb[k])
            added, removed = sorted(set(pb) - set(pa)), sorted(set(pa) - set(pb))
            what = []
            if changed:
                what.append("changed " + ", ".join(changed[:12]) + (" …" if len(changed) > 12 else ""))
            if added:
                what.append("new " + ", ".join(added[:12]))
            if removed:
                what.append("gone " + ", ".join(removed[:12]))
            lines.append(f"{name}: differs ({'; '.join(what) or 'order or nesting'})")
    return lines


def table_rows(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Rows as plain dicts (SQL rows, ``_mapping``)."""
    return [dict(r) for r in rows]
