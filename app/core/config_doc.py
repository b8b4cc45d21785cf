"""The configuration reference (``docs/configuration.md``), generated from :class:`app.core.config.Settings`.

Every setting is a field of :class:`~app.core.config.Settings` described in its numpydoc
``Attributes`` section; the reference lists them all, in the class's order, with the
environment variable, the default and the valid values (the field's constraints). Regenerate
it after changing a setting::

    .venv/bin/python scripts/configuration_doc.py

``tests/core/test_configuration_doc.py`` fails when the file is stale or a setting is not
described.
"""

from __future__ import annotations

import re
from typing import Any

from app.core.config import Settings

__all__ = ["setting_descriptions", "render_configuration_doc"]

_ENTRY = re.compile(r"^    (?P<names>\w+(?:, \w+)*) : (?P<type>[^\n]+)\n(?P<body>(?:        [^\n]*\n|\n)*)", re.M)
_GIB, _MIB = 1024**3, 1024**2
_ROLE = re.compile(r":\w+:`~?([^`]+)`")  # a Sphinx role: its target as code


def setting_descriptions() -> dict[str, tuple[str, str]]:
    """Setting name → (type, description) from the ``Attributes`` section of the settings' docstring."""
    doc = Settings.__doc__ or ""
    section = doc.split("Attributes\n    ----------\n", 1)[-1]
    out: dict[str, tuple[str, str]] = {}
    for m in _ENTRY.finditer(section):
        body = " ".join(line.strip() for line in m.group("body").splitlines() if line.strip())
        body = _ROLE.sub(r"`\1`", body).replace("``", "`")
        for name in m.group("names").split(", "):
            out[name] = (m.group("type").strip(), body)
    return out


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


def render_configuration_doc() -> str:
    """The text of ``docs/configuration.md``.

    Raises
    ------
    ValueError
        If a setting is not described in the settings' docstring.
    """
    described = setting_descriptions()
    missing = [name for name in Settings.model_fields if name not in described]
    if missing:
        raise ValueError(f"settings without a description in Settings' docstring: {', '.join(missing)}")
    lines = [
        "# Configuration reference",
        "",
        "<!-- generated from app/core/config.py (Settings) by scripts/configuration_doc.py: do not edit -->",
        "",
        "Every setting of the API, the workers and the command line, read from the environment",
        "(`TRACKVKF_<NAME>`) or a `.env` file in the working directory; all processes of one service",
        f"read the same settings. {len(Settings.model_fields)} settings, in the order of",
        "`app/core/config.py`. Production mode (`TRACKVKF_ENV=production`) checks some of them at",
        "start-up ([security.md](security.md)); how the service is set up: [production.md](production.md).",
        "",
        "| variable | default | valid | meaning |",
        "| --- | --- | --- | --- |",
    ]
    for name, field in Settings.model_fields.items():
        kind, text = described[name]
        default = field.default_factory() if field.default_factory is not None else field.default
        text = text.replace("|", "\\|")
        lines.append(f"| `TRACKVKF_{name.upper()}` | {_default(default)} | {_valid(field)} | {text} ({kind}) |")
    return "\n".join(lines) + "\n"
