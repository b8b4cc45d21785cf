"""The configuration reference (``docs/configuration.md``), generated from the settings groups.

Every setting is a field of one settings group (:class:`~app.core.config.SettingsGroup`, declared
by the package it configures) described in the numpydoc ``Attributes`` section of the group's
docstring. The reference has one section per group, in the order it is given (the composition's
:data:`app.settings.GROUPS`), each listing the group's settings in its order with the environment
variable, the default and the valid values (the field's constraints). Regenerate it after
changing a setting::

    .venv/bin/python scripts/configuration_doc.py

``tests/core/test_configuration_doc.py`` fails when the file is stale or a setting is not
described.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

from app.core.config import ENV_PREFIX, SettingsGroup

__all__ = ["setting_descriptions", "render_configuration_doc"]

_ENTRY = re.compile(r"^    (?P<names>\w+(?:, \w+)*) : (?P<type>[^\n]+)\n(?P<body>(?:        [^\n]*\n|\n)*)", re.M)
_GIB, _MIB = 1024**3, 1024**2
_ROLE = re.compile(r":\w+:`~?([^`]+)`")  # a Sphinx role: its target as code


def setting_descriptions(group: type[SettingsGroup]) -> dict[str, tuple[str, str]]:
    """Setting name → (type, description) from the ``Attributes`` section of a group's docstring."""
    doc = group.__doc__ or ""
    section = doc.split("Attributes\n    ----------\n", 1)[-1] + "\n"
    out: dict[str, tuple[str, str]] = {}
    for m in _ENTRY.finditer(section):
        body = " ".join(line.strip() for line in m.group("body").splitlines() if line.strip())
        body = _ROLE.sub(r"`\1`", body).replace("``", "`")
        for name in m.group("names").split(", "):
            out[name] = (m.group("type").strip(), body)
    return out


def _title(group: type[SettingsGroup]) -> tuple[str, str]:
    """(name, summary) from the docstring's first line ``Name: summary``."""
    first = (group.__doc__ or group.__name__).strip().splitlines()[0].rstrip(".")
    name, _, summary = first.partition(": ")
    return name, summary


def _default(value: Any) -> str:
    if value is None:
        return "(none)"
    if isinstance(value, bool):
        return f"`{str(value).lower()}`"
    if isinstance(value, int) and value >= _MIB and value % _MIB == 0:
        size = f"{value // _GIB} GiB" if value % _GIB == 0 else f"{value // _MIB} MiB"
        return f"`{value}` ({size})"
    if isinstance(value, float) and value.is_integer():
        return f"`{int(value)}`"
    return f"`{value}`" if value != "" else "(empty)"


def _valid(field: Any) -> str:
    parts = []
    for meta in field.metadata:
        for attr, sign in (("ge", "≥"), ("gt", ">"), ("le", "≤"), ("lt", "<")):
            bound = getattr(meta, attr, None)
            if bound is not None:
                parts.append(f"{sign} {bound:g}" if isinstance(bound, float) else f"{sign} {bound}")
    return ", ".join(parts)


def _own_fields(group: type[SettingsGroup]) -> list[str]:
    """The fields the group declares (not those of its bases)."""
    inherited = {n for base in group.__mro__[1:] for n in getattr(base, "model_fields", {})}
    return [n for n in group.model_fields if n not in inherited]


def render_configuration_doc(groups: Sequence[type[SettingsGroup]]) -> str:
    """The text of ``docs/configuration.md`` for ``groups`` (in their order).

    Raises
    ------
    ValueError
        If a setting is not described in its group's docstring, or two groups declare one name.
    """
    seen: dict[str, str] = {}
    for group in groups:
        described = setting_descriptions(group)
        missing = [n for n in _own_fields(group) if n not in described]
        if missing:
            raise ValueError(f"settings without a description in {group.__name__}'s docstring: {', '.join(missing)}")
        for n in _own_fields(group):
            if n in seen:
                raise ValueError(f"setting {n} declared by {seen[n]} and {group.__name__}")
            seen[n] = group.__name__
    lines = [
        "# Configuration reference",
        "",
        "<!-- generated from the settings groups (app/settings.py, GROUPS) by scripts/configuration_doc.py: "
        "do not edit -->",
        "",
        "Every setting of the API, the workers and the command line, read from the environment",
        f"(`{ENV_PREFIX}<NAME>`) or a `.env` file in the working directory; all processes of one service",
        f"read the same settings. {len(seen)} settings in {len(groups)} groups: each package declares the",
        "settings of what it does (its group, in its `settings.py`), with the numerics' constants as defaults.",
        "Production mode (`TRACKVKF_ENV=production`) checks some of them at start-up",
        "([security.md](security.md)); how the service is set up: [production.md](production.md).",
        "",
    ]
    for group in groups:
        name, summary = _title(group)
        lines.append(f"- [{name}](#{name.lower().replace(' ', '-').replace('(', '').replace(')', '')}): {summary}")
    for group in groups:
        name, summary = _title(group)
        path = group.__module__.replace(".", "/") + ".py"
        lines += ["", f"## {name}", "", f"{summary[:1].upper()}{summary[1:]}. Declared in `{path}` (`{group.__name__}`).",
                  "", "| variable | default | valid | meaning |", "| --- | --- | --- | --- |"]
        described = setting_descriptions(group)
        for n in _own_fields(group):
            field = group.model_fields[n]
            kind, text = described[n]
            default = field.default_factory() if field.default_factory is not None else field.default
            text = text.replace("|", "\\|")
            lines.append(f"| `{ENV_PREFIX}{n.upper()}` | {_default(default)} | {_valid(field)} | {text} ({kind}) |")
    return "\n".join(lines) + "\n"
