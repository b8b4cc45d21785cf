"""docs/configuration.md is generated from the settings class and must be current (app/core/config_doc.py)."""

from __future__ import annotations

from pathlib import Path

from app.core.config import Settings
from app.core.config_doc import render_configuration_doc, setting_descriptions

DOC = Path(__file__).resolve().parents[2] / "docs" / "configuration.md"


def test_every_setting_is_described():
    described = setting_descriptions()
    assert [n for n in Settings.model_fields if n not in described] == []
    assert all(text for _, text in described.values())


def test_the_configuration_reference_is_current():
    """Fails when a setting changed and docs/configuration.md was not regenerated:
    run `.venv/bin/python scripts/configuration_doc.py`."""
    assert DOC.read_text(encoding="utf-8") == render_configuration_doc(), (
        "docs/configuration.md is stale: run .venv/bin/python scripts/configuration_doc.py")
    for name in Settings.model_fields:
        assert f"`TRACKVKF_{name.upper()}`" in DOC.read_text(encoding="utf-8")
