"""docs/configuration.md is generated from the settings groups and must be current (app/core/config_doc.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.core.config import CoreSettings, SettingsGroup
from app.core.config_doc import render_configuration_doc, setting_descriptions
from app.settings import GROUPS, Settings

DOC = Path(__file__).resolve().parents[2] / "docs" / "configuration.md"


def test_every_setting_is_described_in_its_group():
    for group in GROUPS:
        described = setting_descriptions(group)
        assert [n for n in group.model_fields if n not in described] == [], group.__name__
        assert all(text for _, text in described.values())


def test_the_configuration_reference_is_current():
    """Fails when a setting changed and docs/configuration.md was not regenerated:
    run `.venv/bin/python scripts/configuration_doc.py`."""
    text = DOC.read_text(encoding="utf-8")
    assert text == render_configuration_doc(GROUPS), (
        "docs/configuration.md is stale: run .venv/bin/python scripts/configuration_doc.py")
    for name in Settings.model_fields:
        assert f"`TRACKVKF_{name.upper()}`" in text


def test_the_reference_is_grouped_by_the_groups():
    """One section per group, each with the group's own settings in its order, declared where the group is."""
    text = DOC.read_text(encoding="utf-8")
    sections = text.split("\n## ")[1:]
    assert len(sections) == len(GROUPS)
    for group, section in zip(GROUPS, sections, strict=True):
        assert f"`{group.__module__.replace('.', '/')}.py` (`{group.__name__}`)" in section
        rows = [line.split("`")[1] for line in section.splitlines() if line.startswith("| `TRACKVKF_")]
        assert rows == group.env_names()


def test_an_undescribed_setting_or_a_name_in_two_groups_is_refused():
    class Undescribed(SettingsGroup):
        """Test: a group without the description of its setting."""

        undescribed_x: int = 1

    class Twice(SettingsGroup):
        """Test: a group that declares a core setting again.

        Attributes
        ----------
        database_url : str
            Again.
        """

        database_url: str = ""

    with pytest.raises(ValueError, match="undescribed_x"):
        render_configuration_doc([Undescribed])
    with pytest.raises(ValueError, match="database_url"):
        render_configuration_doc([CoreSettings, Twice])
